// A layer driven frame by frame by the penetration method's loads:
// interpolation of frame loads in time, global equilibrium at every step
// (the force the layer passes to its bone equals the contact force of the
// interpolated frames), the factor-once counters over a whole sequence.
#include "biphasic/layer_problem.h"

#include <gtest/gtest.h>

#include "biphasic_fixtures.h"

namespace arthrosim::biphasic {
namespace {

SurfaceLoads loads(int nv, double traction_z, double p) {
  SurfaceLoads l;
  l.traction = Eigen::VectorXd::Zero(3 * nv);
  for (int v = 0; v < nv; ++v) l.traction[3 * v + 2] = traction_z;
  l.pressure = Eigen::VectorXd::Constant(nv, p);
  return l;
}

TEST(LayerProblem, LoadsAreInterpolatedLinearlyBetweenFrames) {
  const std::vector<double> t = {0.0, 0.1, 0.3};
  const std::vector<SurfaceLoads> f = {loads(2, 0.0, 0.0), loads(2, -10.0, 4.0), loads(2, -30.0, 2.0)};
  EXPECT_EQ(loads_at(t, f, 0.1).pressure[0], 4.0);
  EXPECT_NEAR(loads_at(t, f, 0.05).traction[2], -5.0, 1e-15);
  EXPECT_NEAR(loads_at(t, f, 0.2).pressure[1], 3.0, 1e-15);
  EXPECT_NEAR(loads_at(t, f, 0.25).traction[5], -25.0, 1e-14);
  EXPECT_EQ(loads_at(t, f, -1.0).pressure[0], 0.0);  // before the first frame: the first
  EXPECT_EQ(loads_at(t, f, 9.0).pressure[0], 2.0);   // after the last: the last
  EXPECT_THROW(loads_at({0.0, 0.0}, {f[0], f[1]}, 0.0), std::invalid_argument);
  EXPECT_THROW(loads_at({0.0}, {f[0], f[1]}, 0.0), std::invalid_argument);
}

TEST(LayerProblem, ForceOnTheBoneEqualsTheInterpolatedContactForce) {
  // Two flat layers whose overlap grows and shrinks over five frames (a
  // contact patch over part of A: B is smaller than A and offset), the
  // contact force given per frame. The layer is quasi-static, so at every
  // step the force it passes to its bone equals the applied traction, i.e.
  // the linear interpolation of the frames' |F| along -z (round-off: the sum
  // of the support reactions of ~500 dofs, relative 1e-9).
  const double W = 8e-3, h = 2e-3;
  common::QuadMesh sa = testing::grid_surface(8, 8, W, W, 0.0);
  sa.name = "A";
  const LayerMesh A = extrude_layer(sa, testing::constant_normals(81, Eigen::Vector3d::UnitZ()),
                                    Eigen::VectorXd::Constant(81, h), 2);
  const double H = 0.7e6;
  LayerProblem problem(assemble_layer(A, Material{H, 0.1, 2e-15}), {0.01, 0.5});
  const PlacedSurface placed_A = place_surface(A, H, Eigen::Isometry3d::Identity());
  const common::TriangleTree tree_A(placed_A.triangles);

  const std::vector<double> frame_t = {0.0, 0.05, 0.1, 0.15, 0.2};
  const std::vector<double> overlap = {0.05e-3, 0.1e-3, 0.15e-3, 0.1e-3, 0.0};
  const std::vector<double> force = {20.0, 60.0, 90.0, 40.0, 10.0};
  std::vector<SurfaceLoads> frames;
  std::vector<bool> skipped;
  for (size_t k = 0; k < frame_t.size(); ++k) {
    // B: a 4 x 4 mm patch centred over A, its surface at z = -overlap.
    common::QuadMesh sb = testing::grid_surface(4, 4, 4e-3, 4e-3, -overlap[k]);
    for (int v = 0; v < sb.num_nodes(); ++v) sb.V.row(v).head<2>() += Eigen::RowVector2d(2e-3, 2e-3);
    for (int q = 0; q < sb.num_quads(); ++q)
      sb.Q.row(q) = Eigen::RowVector4i(sb.Q(q, 0), sb.Q(q, 3), sb.Q(q, 2), sb.Q(q, 1));
    sb.name = "B";
    const LayerMesh B = extrude_layer(sb, testing::constant_normals(25, -Eigen::Vector3d::UnitZ()),
                                      Eigen::VectorXd::Constant(25, 1.5e-3), 1);
    const PlacedSurface placed_B = place_surface(B, H, Eigen::Isometry3d::Identity());
    const common::TriangleTree tree_B(placed_B.triangles);
    const ContactConditions c = penetration_conditions(placed_A, placed_B, tree_B, force[k]);
    skipped.push_back(c.skipped_no_overlap);
    frames.push_back(surface_loads(placed_A, {&c}, Eigen::Matrix3d::Identity()));
  }
  // The last frame has no overlap: skipped, zero loads.
  EXPECT_TRUE(skipped.back());
  EXPECT_FALSE(skipped[2]);
  const Eigen::VectorXd area = articular_node_areas(A);
  for (int i = 1; i <= 20; ++i) {
    const double t = i * 0.01;
    const SurfaceLoads l = loads_at(frame_t, frames, t);
    problem.step(l);
    // Expected force: the interpolated frame forces (0 for the skipped frame).
    const size_t k = std::min<size_t>(static_cast<size_t>(t / 0.05 + 1e-9), 3);
    const double s = (t - frame_t[k]) / 0.05;
    const double f0 = skipped[k] ? 0.0 : force[k], f1 = skipped[k + 1] ? 0.0 : force[k + 1];
    const double expected = (1 - s) * f0 + s * f1;
    const Eigen::Vector3d f = problem.force_on_bone();
    EXPECT_NEAR(f.z(), -expected, 1e-9 * 100.0) << "t = " << t;
    EXPECT_NEAR(f.head<2>().norm(), 0.0, 1e-9 * 100.0);
    EXPECT_TRUE(problem.integrator().p().allFinite());
  }
  EXPECT_EQ(problem.integrator().counters().factorizations, 1);
  EXPECT_EQ(problem.integrator().counters().solves, 20);
  // Off the contact patch the surface pressure is zero (free-draining).
  EXPECT_EQ(problem.integrator().p()[A.articular_node(1, 0)], 0.0);
}

TEST(LayerProblem, RefusesLoadsOfTheWrongSize) {
  common::QuadMesh s = testing::grid_surface(1, 1, 1e-3, 1e-3);
  const LayerMesh m = extrude_layer(s, testing::constant_normals(4, Eigen::Vector3d::UnitZ()),
                                    Eigen::VectorXd::Constant(4, 1e-3), 1);
  LayerProblem problem(assemble_layer(m, Material{0.7e6, 0.1, 2e-15}), {0.01, 1.0});
  EXPECT_THROW(problem.step(loads(3, 0.0, 0.0)), std::invalid_argument);
}

}  // namespace
}  // namespace arthrosim::biphasic
