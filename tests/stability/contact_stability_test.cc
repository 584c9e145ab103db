// Hard cases of deformable mesh contact (issue 8, label stability): a large
// rigid rotation of the whole contact configuration must not change the
// result; a contact stiffness a thousand times the surface stage's default
// should still converge to the springs-in-series state: it does when the
// smaller plate's rim nodes are penetrating vertices, or carry faded vertex
// weights; with the stage's defaults it does not yet (disabled, see the
// case).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>

#include "../cartilage/contact_test_helpers.h"
#include "../cartilage/shell_test_meshes.h"
#include "cartilage/coupled_system.h"
#include "cartilage/hht_integrator.h"
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
  Eigen::Vector3d force_on_lower_B = Eigen::Vector3d::Zero();  // in the configuration's own frame
  double max_penetration = 0;  // [m]
  IntegratorStatistics stats;
};

/// Two flat shells on foundations k1 (at rest) and k2 (its bone moving by d
/// along the upper plate's normal), pressed together; the whole
/// configuration placed by X (a rigid motion of the joint). Returns the
/// area-weighted mean deflections within 3 mm of the centre (not the
/// springs-in-series value: directors and corners are held here).
SeriesResult press_plates(const ContactOptions& o, const Eigen::Isometry3d& X, double residual_floor_N = 1e-8,
                          double increment_floor_m = IntegratorOptions().increment_atol_m) {
  const double k1 = 7e8, k2 = 2.1e9, d = 0.3e-3, s0 = 0.05e-3;
  common::QuadMesh lower = testing::plate_mesh(14, 14, 20e-3, 20e-3);
  lower.V.rowwise() += Eigen::RowVector3d(-10e-3, -10e-3, 0);
  common::QuadMesh upper = testing::plate_mesh(11, 11, 14e-3, 14e-3, 0.1);
  upper.V.rowwise() += Eigen::RowVector3d(-7.3e-3, -6.9e-3, 0);
  upper = testing::flipped(upper, s0);
  lower = placed(lower, X);
  upper = placed(upper, X);
  ShellMaterial mat;
  mat.youngs_modulus_Pa = 10e6;
  auto make = [&](const common::QuadMesh& m) {
    auto s = std::make_unique<ShellModel>(m, quad_mesh_vertex_normals(m), Eigen::VectorXd::Constant(m.num_nodes(), 0.5e-3), mat);
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
    m->fix_nodes("directors", all, {false, false, false, true, true, true});
    NodeConstraint c;
    c.name = "corners";
    c.nodes = {0, m->num_nodes() - 1};
    c.mask = {true, true, true, false, false, false};
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
  IntegratorOptions opt;
  opt.quasi_static = true;
  opt.dt_s = 1.0 / 3;
  opt.max_newton_iterations = 30;
  opt.line_search_halvings = 8;
  opt.residual_rtol = 1e-9;
  opt.residual_atol_N = residual_floor_N;
  opt.increment_atol_m = increment_floor_m;
  HhtIntegrator hht(sys, opt);
  hht.initialize(0.0, q);
  hht.advance_to(1.0);
  q = hht.q();
  EXPECT_TRUE(q.allFinite());
  SeriesResult r;
  r.stats = hht.statistics();
  r.k1 = k1;
  r.k2 = k2;
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
// 2e13 N/m^3, 3e4 x the upper foundation), with the stage's other contact
// defaults (docs/scenes.md: rim nodes are not penetrating vertices, contact
// fades to zero towards a rim). Reference: the centre deflections of the
// pressed plates against springs in series at the default stiffness and at
// 1000 x. The measured differences at the default stiffness, from the plate
// bending near the held corners and the upper plate's edge, are a few per
// cent, so 6 % is asked of both. The interpenetration must stay within the
// penalty's toe (its equilibrium value is sqrt(2 delta p / k) = 0.1 um).
// Newton's residual floor for the stiff case is 0.1 % of the contact force,
// the rule of the gait scenes (newton_residual_floor_n 2 N of about 2 kN):
// where a vertex's closest point moves from one facet to its neighbour
// across a concave kink the force direction turns by the kink angle, a jump
// of about p A theta (here a few mN) that no Newton iterate can remove.
// DISABLED (a known failure, docs/contact.md "Stiff contact", measured with
// an instrumented copy of this case): at 1000 x, Newton stalls at 86 % of the
// approach (t = 0.856 s, residual 0.025 N, rejected by the increment test at
// the step floor); the default-stiffness half converges. The stall is not a
// facet kink: no contact changes its feature during it and K matches finite
// differences; the upper plate's rim (its nodes are not penetrating vertices)
// has no support but the lower vertices' contacts faded towards that rim, so
// it sinks until one of them, 40 um deep with fade weight ~1e-5, holds it, a
// balance whose linear model is valid only over sub-micrometre moves. With
// rim nodes as penetrating vertices the case reaches t = 1 s only after 1195
// Newton iterations, stalling where a rim vertex alternates between two
// faces across a ridge (the gap's normal jumps there). Even converged, the
// penetration bound below could not hold with these options: the faded
// contacts holding that rim are 34-40 um deep at t = 0.86 s. Run it with
//   build/tests/contact_stability_test --gtest_also_run_disabled_tests --gtest_filter='*Thousand*'
// The pressed plates at the default contact stiffness and at 1000 x, with or
// without rim nodes as penetrating vertices; the assertions of both cases
// below. Returns the stiff run's statistics.
struct ThousandCase {
  bool rim_vertices = false;         // ContactOptions::rim_vertices (the stage's default: false)
  bool faded_weights = false;        // ContactOptions::faded_vertex_weights (default: false)
  double increment_floor_m = IntegratorOptions().increment_atol_m;  // of the stiff run
  double penetration_bound_m = 1e-6;  // of the stiff run
};
IntegratorStatistics press_at_thousand_times(const ThousandCase& tc) {
  SeriesResult r[2];
  const double kc[2] = {2e10, 2e13};
  for (int i = 0; i < 2; ++i) {
    ContactOptions o = with_stiffness(kc[i]);
    o.rim_vertices = tc.rim_vertices;
    o.faded_vertex_weights = tc.faded_weights;
    o.rim_max_depth_m = 0.5e-3;
    if (i == 0)
      r[i] = press_plates(o, Eigen::Isometry3d::Identity());
    else  // 0.1 % of the ~30 N contact force
      r[i] = press_plates(o, Eigen::Isometry3d::Identity(), 0.03, tc.increment_floor_m);
    const IntegratorStatistics& s = r[i].stats;
    std::printf("k_c %.0e N/m^3, rim vertices %s: %s, %ld steps, %ld rejected, %ld Newton iterations; w1 %.4e "
                "(p/k1 %.4e), w2 %.4e (p/k2 %.4e), force %.4f N, max penetration %.3e m\n",
                kc[i], tc.faded_weights ? "faded" : tc.rim_vertices ? "on" : "off",
                s.status == IntegratorStatus::kFailed ? "FAILED" : "converged",
                s.steps, s.rejected_steps, s.newton_iterations, r[i].w_lower, r[i].p_expected / r[i].k1,
                r[i].w_upper, r[i].p_expected / r[i].k2, r[i].force_on_lower_B.z(), r[i].max_penetration);
    EXPECT_NE(s.status, IntegratorStatus::kFailed);
    if (s.status == IntegratorStatus::kFailed) return r[1].stats;
    EXPECT_NEAR(r[i].w_lower, r[i].p_expected / r[i].k1, 0.06 * r[i].p_expected / r[i].k1);
    EXPECT_NEAR(r[i].w_upper, r[i].p_expected / r[i].k2, 0.06 * r[i].p_expected / r[i].k2);
    EXPECT_TRUE(std::isfinite(r[i].force_on_lower_B.norm()));
  }
  EXPECT_LT(r[1].max_penetration, tc.penetration_bound_m);
  // Stiffer contact, slightly larger deflections (less contact compliance).
  EXPECT_GT(r[1].w_lower, r[0].w_lower);
  EXPECT_GT(r[1].w_upper, r[0].w_upper);
  return r[1].stats;
}

TEST(ContactStability, DISABLED_ContactStiffnessThousandTimesTheDefault) { press_at_thousand_times({}); }

// The same with the upper plate's rim supported: its rim nodes are
// penetrating vertices (contact_rim_vertices, a scene option; off by default
// because stage 1 never samples a rim, docs/contact.md). Measured 2026-12-02:
// converges (88 steps, 23 rejected attempts, 1223 Newton iterations, 56 s on
// the 2-core machine), centre deflections -0.64 % and +2.5 % from springs in
// series, largest penetration 0.78 um. The many iterations are the ridge
// alternation of a rim vertex (docs/contact.md, "Stiff contact"); the bound
// below (1.5 x the measured count) catches a regression, not a target.
TEST(ContactStability, ContactStiffnessThousandTimesTheDefaultWithRimVertices) {
  ThousandCase tc;
  tc.rim_vertices = true;
  const IntegratorStatistics s = press_at_thousand_times(tc);
  EXPECT_LT(s.newton_iterations, 1850);
}

// The same with faded vertex weights (contact_vertex_weights: faded, an
// opt-in scene option): each node's weight as the penetrating vertex is the
// integral of the rim fade times its shape function, so rim nodes support
// the rim with a reduced weight (1/15 or 1/6 of a rim-row triangle's area
// per triangle, against 1/3 for a tributary area). Measured 2026-12-03: 31
// steps, 10 rejected attempts, 513 Newton iterations, centre deflections
// -0.64 % and +2.5 % from springs in series. It needs an increment floor:
// without one it stops at t = 0.761 s at the step floor, after an attempt
// that had reached a residual of 9e-13 N was rejected because its last
// increment, 3.9e-13 m, was above the increment test of that 5-us step (the
// round-off of the penalty-stiffened matrix). The floor is 1 um, 0.5 % of
// the lower plate's deflection, the proportion of the gait scenes'
// newton_increment_floor_mm. The deepest contacts are at the two upper
// corners held with their bone (their penetration is set by the constraint,
// not by balance), whose faded weight is a fifth of their tributary area:
// 2.0 um (the other rim nodes below 0.8 um); the bound is 3 um. Iterations:
// 1.5 x the measured count, a regression guard.
TEST(ContactStability, ContactStiffnessThousandTimesTheDefaultWithFadedVertexWeights) {
  ThousandCase tc;
  tc.faded_weights = true;
  tc.increment_floor_m = 1e-6;
  tc.penetration_bound_m = 3e-6;
  const IntegratorStatistics s = press_at_thousand_times(tc);
  EXPECT_LT(s.newton_iterations, 770);
}

}  // namespace
}  // namespace arthrosim::cartilage
