// Hard cases of deformable mesh contact (issue 8, label stability): a large
// rigid rotation of the whole contact configuration must not change the
// result; a contact stiffness a thousand times the surface stage's default
// converges to the springs-in-series state with the stage's defaults (its
// shell, contact options and Newton). With a shell 330 x less stiff in
// bending it does so only when the smaller plate's rim is supported (rim
// nodes as penetrating vertices, or faded vertex weights; the case with the
// stage's rim treatment is disabled, a documented limitation).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <optional>

#include "../cartilage/contact_test_helpers.h"
#include "../cartilage/shell_test_meshes.h"
#include "cartilage/coupled_system.h"
#include "numerics/hht_integrator.h"
#include "cartilage/shell_model.h"

namespace arthrosim::cartilage {
namespace {


common::QuadMesh placed(common::QuadMesh m, const Eigen::Isometry3d& X) {
  for (int i = 0; i < m.V.rows(); ++i) m.V.row(i) = (X * Eigen::Vector3d(m.V.row(i).transpose())).transpose();
  return m;
}

struct SeriesResult {
  double w_lower = 0, w_upper = 0, p_expected = 0;
  double k1 = 0, k2 = 0;  // the foundations [N/m^3]
  double approach_m = 0;  // the upper bone's travel less the initial gap, d - s0
  Eigen::Vector3d force_on_lower_B = Eigen::Vector3d::Zero();  // in the configuration's own frame
  double max_penetration = 0;  // [m]
  numerics::IntegratorStatistics stats;
};

/// The plates and their shells. The default is the soft set-up (10 MPa,
/// 0.5 mm: a bending length pi / lambda of 2.8 mm on the lower foundation, so
/// springs in series hold at the centre of small plates) with every director
/// fixed and two corners of each plate held with its bone.
struct PlateSetup {
  ShellMaterial material = [] {
    ShellMaterial m;
    m.youngs_modulus_Pa = 10e6;
    return m;
  }();
  double thickness_m = 0.5e-3;
  int lower_cells = 14, upper_cells = 11;
  double lower_size_m = 20e-3, upper_size_m = 14e-3;
  Eigen::Vector2d upper_origin{-7.3e-3, -6.9e-3};  // of the upper plate's corner
  bool fix_directors = true;
  bool hold_corners_along_normal = true;  // false: in-plane only (needs X = identity)
};

/// The quasi-static approach in three nominal steps, Newton as the surface
/// stage runs it with contact (8 line-search halvings), with the residual and
/// increment floors given.
numerics::IntegratorOptions plate_integrator(double residual_floor_N = 1e-8,
                                   double increment_floor_m = numerics::IntegratorOptions().increment_atol_m,
                                   int max_newton_iterations = 30, double rtol = 1e-9) {
  numerics::IntegratorOptions opt;
  opt.quasi_static = true;
  opt.dt_s = 1.0 / 3;
  opt.max_newton_iterations = max_newton_iterations;
  opt.line_search_halvings = 8;
  opt.residual_rtol = rtol;
  opt.residual_atol_N = residual_floor_N;
  opt.increment_atol_m = increment_floor_m;
  return opt;
}

/// Two flat shells on foundations k1 (at rest) and k2 (its bone moving by d
/// along the upper plate's normal), pressed together; the whole
/// configuration placed by X (a rigid motion of the joint). Returns the
/// area-weighted mean deflections within 3 mm of the centre (near, not at,
/// the springs-in-series values: the plates bend near their rims and where
/// PlateSetup holds them).
SeriesResult press_plates(const ContactOptions& o, const Eigen::Isometry3d& X,
                          const numerics::IntegratorOptions& opt = plate_integrator(), const PlateSetup& ps = PlateSetup()) {
  const double k1 = 7e8, k2 = 2.1e9, d = 0.3e-3, s0 = 0.05e-3;
  common::QuadMesh lower = testing::plate_mesh(ps.lower_cells, ps.lower_cells, ps.lower_size_m, ps.lower_size_m);
  lower.V.rowwise() += Eigen::RowVector3d(-0.5 * ps.lower_size_m, -0.5 * ps.lower_size_m, 0);
  common::QuadMesh upper = testing::plate_mesh(ps.upper_cells, ps.upper_cells, ps.upper_size_m, ps.upper_size_m, 0.1);
  upper.V.rowwise() += Eigen::RowVector3d(ps.upper_origin.x(), ps.upper_origin.y(), 0);
  upper = testing::flipped(upper, s0);
  lower = placed(lower, X);
  upper = placed(upper, X);
  EXPECT_TRUE(ps.hold_corners_along_normal || X.isApprox(Eigen::Isometry3d::Identity()));
  auto make = [&](const common::QuadMesh& m) {
    auto s = std::make_unique<ShellModel>(m, quad_mesh_vertex_normals(m),
                                          Eigen::VectorXd::Constant(m.num_nodes(), ps.thickness_m), ps.material);
    s->add_internal_forces();
    return s;
  };
  auto A = make(lower), B = make(upper);
  A->add_foundation_springs(k1, BoneMotion::fixed());
  const Eigen::Vector3d down = X.linear() * Eigen::Vector3d(0, 0, -d);
  const BoneMotion moving = testing::translating_bone(down);
  B->add_foundation_springs(k2, moving);
  // Directors fixed (the centre state has no slope) and two opposite corner
  // nodes of each plate carried with its bone: this removes the in-plane
  // rigid motions, which no term resists, in any orientation X.
  for (ShellModel* m : {A.get(), B.get()}) {
    std::vector<int> all(m->num_nodes());
    for (int i = 0; i < m->num_nodes(); ++i) all[i] = i;
    if (ps.fix_directors) m->fix_nodes("directors", all, {false, false, false, true, true, true});
    NodeConstraint c;
    c.name = "corners";
    c.nodes = {0, m->num_nodes() - 1};
    c.mask = {true, true, ps.hold_corners_along_normal, false, false, false};
    const Eigen::VectorXd r0 = m->reference_state();
    const Eigen::Vector3d shift = m == B.get() ? down : Eigen::Vector3d::Zero();
    c.value = [r0, shift](double t, int node, Eigen::Matrix<double, 6, 1>& q6) {
      q6.head<3>() = r0.segment<3>(6 * node) + t * shift;
    };
    m->add_constraint(std::move(c));
  }
  CoupledShellSystem sys({A.get(), B.get()}, {"lower", "upper"});
  sys.add_contact("lower-upper", 0, 1, o);
  Eigen::VectorXd q(sys.num_dofs());
  q << A->reference_state(), B->reference_state();
  numerics::HhtIntegrator hht(sys, opt);
  hht.initialize(0.0, q);
  hht.advance_to(1.0);
  q = hht.q();
  EXPECT_TRUE(q.allFinite());
  SeriesResult r;
  r.stats = hht.statistics();
  r.k1 = k1;
  r.k2 = k2;
  r.approach_m = d - s0;
  r.p_expected = (d - s0 - 0.5 * o.smoothing_m) / (1 / k1 + 1 / k2 + 1 / o.stiffness_N_m3);
  const Eigen::Vector3d n = X.linear() * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d c = X.translation();
  auto mean = [&](int m, const Eigen::Vector3d& bone_shift, double sign) {
    return testing::mean_normal_deflection(sys.model(m), sys.segment(m, q), c, n, 3e-3, bone_shift, sign);
  };
  r.w_lower = mean(0, Eigen::Vector3d::Zero(), -1.0);
  r.w_upper = mean(1, down, 1.0);
  const ContactPairReport rep = sys.contact_report(0, q);
  r.force_on_lower_B = X.linear().transpose() * rep.total_force_a;
  r.max_penetration = rep.counts.max_penetration_m;
  return r;
}

ContactOptions with_stiffness(double kc) {
  ContactOptions o;
  o.stiffness_N_m3 = kc;
  o.rim_vertices = true;  // the plates' rim nodes may be penetrating vertices
  o.rim_max_depth_m = 0;  // rim contacts (kRimContacts only) cut off at max_depth_m
  return o;
}

// The same pressed plates rotated by 170 degrees about an oblique axis and
// moved: the deflections and the contact force in the configuration's frame
// do not change (1e-6 relative: Newton tolerances, the broad phase's boxes
// are axis-aligned so they differ, the contacts must not).
TEST(ContactStability, LargeRigidRotationOfTheWholeContact) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(170 * M_PI / 180, Eigen::Vector3d(1, -2, 0.7).normalized()).toRotationMatrix();
  X.translation() << 0.05, -0.02, 0.11;
  const SeriesResult a = press_plates(with_stiffness(2e10), Eigen::Isometry3d::Identity());
  const SeriesResult b = press_plates(with_stiffness(2e10), X);
  std::printf("rotated: w1 %.8e vs %.8e, w2 %.8e vs %.8e, F %.6f vs %.6f N\n", a.w_lower, b.w_lower, a.w_upper,
              b.w_upper, a.force_on_lower_B.z(), b.force_on_lower_B.z());
  EXPECT_NEAR(b.w_lower, a.w_lower, 1e-6 * std::abs(a.w_lower));
  EXPECT_NEAR(b.w_upper, a.w_upper, 1e-6 * std::abs(a.w_upper));
  EXPECT_LT((b.force_on_lower_B - a.force_on_lower_B).norm(), 1e-6 * a.force_on_lower_B.norm());
}

// Contact stiffness 1000 x the surface stage's default (20 N/mm^3 ->
// 2e13 N/m^3, 3e4 x the upper foundation). Reference: springs in series at
// the plates' centres, at the default stiffness and at 1000 x, and the
// approach: the bone's travel less the initial gap is taken up by the two
// deflections and the penalty's interpenetration, w1 + w2 + pen(p) = d - s0,
// pen the inverse of the penalty law (inside the quadratic toe of width
// delta: sqrt(2 delta p / k), 0.1 um at 1000 x; beyond it p / k + delta / 2).
// That balance is independent of how bending splits the load between the two
// plates. Measured: within 0.015 % with the stage's shell, within 0.1 % with
// the soft set-up (its means over 3 mm sample the two plates' different
// nodes, and its held corners bend the plates), so 0.3 % of d - s0 (0.75 um)
// is asked, a ninth of the 6.9 um the penalty takes at the default
// stiffness. The interpenetration must stay within the penalty's toe (1 um).
struct ThousandCase {
  PlateSetup plates;                 // default: the soft set-up
  bool rim_vertices = false;         // ContactOptions::rim_vertices (the stage's default: false)
  bool faded_weights = false;        // ContactOptions::faded_vertex_weights (default: false)
  /// Newton of both runs; unset: the soft set-up's (30 iterations, relative
  /// tolerance 1e-9) with a residual floor of 0.1 % of the ~30 N contact
  /// force in the stiff run (the rule of the gait scenes,
  /// newton_residual_floor_n 2 N of about 2 kN: where a vertex's closest
  /// point moves from one facet to its neighbour across a concave kink the
  /// force direction turns by the kink angle, a jump of about p A theta, a
  /// few mN here, that no Newton iterate removes) and increment_floor_m.
  std::optional<numerics::IntegratorOptions> newton;
  double increment_floor_m = numerics::IntegratorOptions().increment_atol_m;  // of the stiff run
  double penetration_bound_m = 1e-6;      // of the stiff run
  double lower_tolerance = 0.06;          // relative, w1 against p / k1
  double upper_tolerance = 0.06;          // relative, w2 against p / k2
};
numerics::IntegratorStatistics press_at_thousand_times(const ThousandCase& tc) {
  SeriesResult r[2];
  const double kc[2] = {2e10, 2e13};
  for (int i = 0; i < 2; ++i) {
    ContactOptions o = with_stiffness(kc[i]);
    o.rim_vertices = tc.rim_vertices;
    o.faded_vertex_weights = tc.faded_weights;
    o.rim_max_depth_m = 0.5e-3;
    const numerics::IntegratorOptions newton =
        tc.newton ? *tc.newton : i == 0 ? plate_integrator() : plate_integrator(0.03, tc.increment_floor_m);
    r[i] = press_plates(o, Eigen::Isometry3d::Identity(), newton, tc.plates);
    const numerics::IntegratorStatistics& s = r[i].stats;
    const double p = r[i].p_expected, delta = o.smoothing_m;
    const double pen = p < 0.5 * kc[i] * delta ? std::sqrt(2 * delta * p / kc[i]) : p / kc[i] + 0.5 * delta;
    const double approach = r[i].w_lower + r[i].w_upper + pen;
    std::printf("k_c %.0e N/m^3, rim vertices %s: %s, %ld steps, %ld rejected, %ld Newton iterations; w1 %.4e "
                "(p/k1 %.4e), w2 %.4e (p/k2 %.4e), approach %.6e m (d - s0 %.6e), force %.4f N, max penetration "
                "%.3e m\n",
                kc[i], tc.faded_weights ? "faded" : tc.rim_vertices ? "on" : "off",
                s.status == numerics::IntegratorStatus::kFailed ? "FAILED" : "converged", s.steps, s.rejected_steps,
                s.newton_iterations, r[i].w_lower, p / r[i].k1, r[i].w_upper, p / r[i].k2, approach, r[i].approach_m,
                r[i].force_on_lower_B.z(), r[i].max_penetration);
    EXPECT_NE(s.status, numerics::IntegratorStatus::kFailed);
    if (s.status == numerics::IntegratorStatus::kFailed) return r[1].stats;
    EXPECT_NEAR(r[i].w_lower, p / r[i].k1, tc.lower_tolerance * p / r[i].k1);
    EXPECT_NEAR(r[i].w_upper, p / r[i].k2, tc.upper_tolerance * p / r[i].k2);
    EXPECT_NEAR(approach, r[i].approach_m, 3e-3 * r[i].approach_m);
    EXPECT_TRUE(std::isfinite(r[i].force_on_lower_B.norm()));
  }
  EXPECT_LT(r[1].max_penetration, tc.penetration_bound_m);
  // Stiffer contact, slightly larger deflections (less contact compliance).
  EXPECT_GT(r[1].w_lower, r[0].w_lower);
  EXPECT_GT(r[1].w_upper, r[0].w_upper);
  return r[1].stats;
}

// The surface stage's defaults throughout: its shell (1 mm, 400 MPa,
// nu 0.3), its contact options (rim nodes are not penetrating vertices,
// fade_inside, tributary weights), its Newton (15 iterations, relative
// tolerance 1e-8, floors 1e-10 N and 1e-14 m, 8 line-search halvings with
// contact); the lower foundation is the stage's 0.7 N/mm^3, the upper one
// three times that. Directors are free (the stage holds none) and two
// opposite corners of each plate are held in the plane only (the in-plane
// rigid motions, which no term resists), so nothing but the foundations
// carries the plates along the normal. The stage's shell bends (pi / lambda
// = 12 mm on the lower foundation, lambda = (k1 / 4D)^(1/4) = 263 /m, D =
// 0.037 N m), so the plates are 40 mm and 30 mm wide (1.4 mm elements): the
// centre lies a = 15 mm from the upper plate's rim, where the load ends, and
// the lower plate's centre deflection differs from p / k1 by about
// e^(-lambda a) = 1.9 %: 3 % is asked. The stiff contact fixes the sum of
// the two deflections, so the lower plate's difference reappears in the
// upper one times k2 / k1 = 3: 6 %. Measured 2026-12-03: at the default
// stiffness 3 steps, 16 Newton iterations, w1 +0.10 %, w2 -0.29 %; at 1000 x
// 10 steps, 3 rejected attempts, 96 Newton iterations, w1 +0.79 %, w2
// -1.7 %, largest interpenetration 0.77 um; the upper plate's rim is carried
// by the shell's bending stiffness. Iteration bound: 1.5 x the measured
// count, a regression guard.
TEST(ContactStability, ContactStiffnessThousandTimesTheDefault) {
  ThousandCase tc;
  tc.plates.material = ShellMaterial();
  tc.plates.thickness_m = 1e-3;
  tc.plates.lower_cells = 28;
  tc.plates.upper_cells = 21;
  tc.plates.lower_size_m = 40e-3;
  tc.plates.upper_size_m = 30e-3;
  tc.plates.upper_origin = {-15.3e-3, -14.9e-3};
  tc.plates.fix_directors = false;
  tc.plates.hold_corners_along_normal = false;
  // The library's Newton defaults, which are the stage's (docs/scenes.md:
  // max_newton_iterations, newton_tolerance, newton_residual_floor_n,
  // newton_increment_floor_mm), with the stage's line search for contact.
  numerics::IntegratorOptions stage;
  stage.quasi_static = true;
  stage.dt_s = 1.0 / 3;
  stage.line_search_halvings = 8;
  tc.newton = stage;
  tc.lower_tolerance = 0.03;
  const numerics::IntegratorStatistics s = press_at_thousand_times(tc);
  EXPECT_LT(s.newton_iterations, 145);
}

// The soft set-up (press_plates' default: 10 MPa, 0.5 mm, D = 1.1e-4 N m,
// 330 x less than the stage's shell; directors fixed, corners held with
// their bones) with the stage's contact options. Springs in series hold at
// the centre of these small plates (pi / lambda = 2.8 mm); the measured
// differences at the default stiffness, from the plate bending near the held
// corners and the upper plate's edge, are a few per cent, so 6 % is asked.
// DISABLED (a known limitation, docs/contact.md "Stiff contact", measured
// with an instrumented copy of this case): at 1000 x, Newton stalls at 86 %
// of the approach (t = 0.856 s, residual 0.025 N, rejected by the increment
// test at the step floor); the default-stiffness half converges. The stall
// is not a facet kink: no contact changes its feature during it and K
// matches finite differences. The upper plate's rim nodes are not
// penetrating vertices and this shell is too soft to carry the last row of
// elements over its foundation's push, so the rim sinks until one of the
// lower vertices' contacts faded towards that rim, 40 um deep with fade
// weight ~1e-5, holds it, a balance whose linear model is valid only over
// sub-micrometre moves; even converged, the penetration bound could not hold.
// The two cases after this one support that rim and pass. Run it with
//   build/tests/contact_stability_test --gtest_also_run_disabled_tests --gtest_filter='*SoftShell*'
TEST(ContactStability, DISABLED_SoftShellContactStiffnessThousandTimesTheDefault) { press_at_thousand_times({}); }

// The soft set-up with the upper plate's rim supported: its rim nodes are
// penetrating vertices (contact_rim_vertices, a scene option; off by default
// because stage 1 never samples a rim, docs/contact.md). Measured 2026-12-02:
// converges (88 steps, 23 rejected attempts, 1223 Newton iterations, 56 s on
// the 2-core machine), centre deflections -0.64 % and +2.5 % from springs in
// series, largest penetration 0.78 um. The many iterations are the ridge
// alternation of a rim vertex (docs/contact.md, "Stiff contact"); the bound
// below (1.5 x the measured count) catches a regression, not a target.
TEST(ContactStability, SoftShellContactStiffnessThousandTimesTheDefaultWithRimVertices) {
  ThousandCase tc;
  tc.rim_vertices = true;
  const numerics::IntegratorStatistics s = press_at_thousand_times(tc);
  EXPECT_LT(s.newton_iterations, 1850);
}

// The soft set-up with faded vertex weights (contact_vertex_weights: faded,
// an opt-in scene option): each node's weight as the penetrating vertex is
// the integral of the rim fade times its shape function, so rim nodes
// support the rim with a reduced weight (1/15 or 1/6 of a rim-row
// triangle's area per triangle, against 1/3 for a tributary area). Measured
// 2026-12-03: 31 steps, 10 rejected attempts, 513 Newton iterations, centre
// deflections -0.64 % and +2.5 % from springs in series. It needs an
// increment floor: without one it stops at t = 0.761 s at the step floor,
// after an attempt that had reached a residual of 9e-13 N was rejected
// because its last increment, 3.9e-13 m, was above the increment test of
// that 5-us step (the round-off of the penalty-stiffened matrix). The floor
// is 1 um, 0.5 % of the lower plate's deflection, the proportion of the gait
// scenes' newton_increment_floor_mm. The deepest contacts are at the two
// upper corners held with their bone (their penetration is set by the
// constraint, not by balance), whose faded weight is a fifth of their
// tributary area: 2.0 um (the other rim nodes below 0.8 um); the bound is
// 3 um. Iterations: 1.5 x the measured count, a regression guard.
TEST(ContactStability, SoftShellContactStiffnessThousandTimesTheDefaultWithFadedVertexWeights) {
  ThousandCase tc;
  tc.faded_weights = true;
  tc.increment_floor_m = 1e-6;
  tc.penetration_bound_m = 3e-6;
  const numerics::IntegratorStatistics s = press_at_thousand_times(tc);
  EXPECT_LT(s.newton_iterations, 770);
}

}  // namespace
}  // namespace arthrosim::cartilage
