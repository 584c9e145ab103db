// The penetration method against a monolithic two-layer biphasic reference
// with a tied interface, on the same problem: two flat layers of different
// modulus and thickness, bonded to rigid impermeable bones, pressed together
// by a known overlap d(t) (the upper bone moves down by d), laterally
// unconfined with free-draining side faces.
//
// Reference: one layered column (layer A below, B above, shared interface
// nodes: continuous displacement and pressure), bones prescribed. Its
// interface pressure and the total force F(t) on the bone are the "exact"
// contact answer. The penetration method is given the same overlap and the
// reference's |F(t)| (as the seed gives it a measured joint force) and
// produces the interface pressure p = F/A - H_A eta d / h_A (uniform for a
// uniform overlap). The difference is reported and bounded below.
#include <gtest/gtest.h>

#include <cstdio>

#include "biphasic/penetration.h"
#include "biphasic/trapezoidal.h"
#include "biphasic_fixtures.h"

namespace arthrosim::biphasic {
namespace {

constexpr double kHalf = 5e-3;                // quarter model of a 10 x 10 mm pair
constexpr double kHA = 2e-3, kHB = 1e-3;      // thicknesses [m]
const Material kA{0.6e6, 0.1, 2e-15}, kB{1.2e6, 0.1, 3e-15};
constexpr double kOverlap = 0.1e-3;           // final overlap d0 [m]
constexpr double kRamp = 1.0, kEnd = 100.0, kDt = 0.5;  // [s]

double overlap_at(double t) { return kOverlap * std::min(t, kRamp) / kRamp; }

TEST(TwoLayerReference, PenetrationPressureAgainstTiedBiphasicContact) {
  const int n = 4;
  const common::QuadMesh s = testing::grid_surface(n, n, kHalf, kHalf, kHB);  // top of the column
  const int nv = s.num_nodes();
  // 6 element layers of equal height: A (2 mm) gets 4, B (1 mm) gets 2; the
  // interface is corner level 4.
  const LayerMesh column_mesh = extrude_layer(s, testing::constant_normals(nv, Eigen::Vector3d::UnitZ()),
                                              Eigen::VectorXd::Constant(nv, kHA + kHB), 6);
  const LayerSystem sys = assemble_layer(column_mesh, std::vector<Material>{kA, kA, kA, kA, kB, kB});
  const common::Points3& X = sys.u_nodes();
  const double tol = 1e-9;
  std::vector<int> fixed_u, top_z;
  std::vector<char> is_top(sys.num_u_dofs(), 0);
  for (int a = 0; a < sys.num_u_nodes(); ++a) {
    const bool bottom = std::abs(X(a, 2) + kHA) < tol, top = std::abs(X(a, 2) - kHB) < tol;
    for (int c = 0; c < 3; ++c) {
      const bool symmetric = (c == 0 && std::abs(X(a, 0)) < tol) || (c == 1 && std::abs(X(a, 1)) < tol);
      if (bottom || top || symmetric) fixed_u.push_back(3 * a + c);
      if (top) is_top[3 * a + c] = 1;
    }
    if (top) top_z.push_back(3 * a + 2);
  }
  std::sort(fixed_u.begin(), fixed_u.end());
  // Free-draining outer side faces (x = 5 mm or y = 5 mm).
  const std::vector<int> drained = testing::nodes_where(sys.mesh.q1_nodes, [&](const Eigen::Vector3d& x) {
    return std::abs(x.x() - kHalf) < tol || std::abs(x.y() - kHalf) < tol;
  });
  TrapezoidalIntegrator integ(sys, fixed_u, drained, {kDt, 0.5});

  // The penetration method's layers (same in-plane mesh).
  common::QuadMesh sa = testing::grid_surface(n, n, kHalf, kHalf, 0.0);
  sa.name = "A";
  const LayerMesh A = extrude_layer(sa, testing::constant_normals(nv, Eigen::Vector3d::UnitZ()),
                                    Eigen::VectorXd::Constant(nv, kHA), 4);
  const Eigen::VectorXd area = articular_node_areas(A);
  const double total_area = area.sum();
  const PlacedSurface placed_A = place_surface(A, kA.aggregate_modulus_Pa, Eigen::Isometry3d::Identity());

  StepInput in;
  in.u_fixed = Eigen::VectorXd::Zero(fixed_u.size());
  double max_centre = 0.0, max_mean = 0.0, max_centre_diff = 0.0, max_mean_diff = 0.0;
  const int steps = static_cast<int>(std::lround(kEnd / kDt));
  for (int i = 1; i <= steps; ++i) {
    const double t = i * kDt, d = overlap_at(t);
    for (size_t k = 0; k < fixed_u.size(); ++k)
      in.u_fixed[k] = is_top[fixed_u[k]] && fixed_u[k] % 3 == 2 ? -d : 0.0;
    integ.step(in);
    const Eigen::VectorXd R = integ.reaction();
    double force = 0.0;
    for (int dof : top_z) force += R[dof];
    // Reference interface pressure: centre node and area-weighted mean.
    double mean = 0.0;
    for (int v = 0; v < nv; ++v) mean += area[v] * integ.p()[sys.mesh.q1_node(v, 4)];
    mean /= total_area;
    const double centre = integ.p()[sys.mesh.q1_node(0, 4)];
    // Penetration method with the same overlap and the reference's |F|:
    // B's surface at z = -d facing down.
    common::QuadMesh sb = testing::grid_surface(n, n, kHalf, kHalf, -d);
    for (int q = 0; q < sb.num_quads(); ++q) sb.Q.row(q) = Eigen::RowVector4i(sb.Q(q, 0), sb.Q(q, 3), sb.Q(q, 2), sb.Q(q, 1));
    sb.name = "B";
    const LayerMesh B = extrude_layer(sb, testing::constant_normals(nv, -Eigen::Vector3d::UnitZ()),
                                      Eigen::VectorXd::Constant(nv, kHB), 2);
    const PlacedSurface placed_B = place_surface(B, kB.aggregate_modulus_Pa, Eigen::Isometry3d::Identity());
    const common::TriangleTree tree_A(placed_A.triangles), tree_B(placed_B.triangles);
    const ContactConditions ca = penetration_conditions(placed_A, placed_B, tree_B, std::abs(force));
    const ContactConditions cb = penetration_conditions(placed_B, placed_A, tree_A, std::abs(force));
    ASSERT_EQ(ca.contact_nodes, nv);
    const double p_pen = ca.pressure[0];
    EXPECT_NEAR(cb.pressure[0], p_pen, 1e-9 * std::abs(p_pen));  // eq 18 between the two layers
    max_centre = std::max(max_centre, std::abs(centre));
    max_mean = std::max(max_mean, std::abs(mean));
    max_centre_diff = std::max(max_centre_diff, std::abs(p_pen - centre));
    max_mean_diff = std::max(max_mean_diff, std::abs(p_pen - mean));
    if (i == 2 || i == 10 || i == 40 || i == steps)
      std::printf("t %6.1f s: F %.3f N (quarter), p interface: reference centre %.0f Pa, mean %.0f Pa; "
                  "penetration %.0f Pa (sigma_E %.0f, total %.0f)\n",
                  t, force, centre, mean, p_pen, ca.sigma_E[0], ca.sigma_total[0]);
  }
  std::printf("max |p_pen - p_ref(centre)| = %.3f of max p_ref(centre); max |p_pen - mean p_ref| = %.3f of "
              "max mean p_ref\n",
              max_centre_diff / max_centre, max_mean_diff / max_mean);
  // Bounds. The penetration pressure is uniform for a uniform overlap while
  // the tied reference has the squeeze-film distribution of a thin bonded
  // layer (centre about twice the mean), so at the centre the method is off
  // by about half (measured 0.506 on this 4 x 4 mesh, 0.490 on 8 x 8). The
  // mean interface pressure differs only by the difference between the
  // reference's mean interface elastic stress and H_A eta d / h_A (the force
  // is matched): measured 0.036 (4 x 4) and 0.044 (8 x 8). Bounds 0.55 and
  // 0.06; the figures are in docs/biphasic.md (limits of the method).
  EXPECT_LT(max_centre_diff / max_centre, 0.55);
  EXPECT_LT(max_mean_diff / max_mean, 0.06);
  EXPECT_EQ(integ.counters().factorizations, 1);
  EXPECT_EQ(integ.counters().solves, steps);
}

}  // namespace
}  // namespace arthrosim::biphasic
