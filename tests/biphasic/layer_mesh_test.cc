// Extrusion of an articular quad surface into a layer volume mesh: geometry
// on flat and cylindrical layers (exact volumes), node numbering and sets,
// and the refusals of bad input.
#include "biphasic/layer_mesh.h"

#include <gtest/gtest.h>

#include <cmath>

#include "biphasic_fixtures.h"
#include "common/error.h"

namespace arthrosim::biphasic {
namespace {

using testing::constant_normals;
using testing::grid_surface;
using testing::kPi;

TEST(LayerMesh, FlatLayerCountsSetsAndVolume) {
  const int nx = 3, ny = 2, N = 4;
  const double lx = 6e-3, ly = 4e-3, h = 2e-3;
  const common::QuadMesh s = grid_surface(nx, ny, lx, ly, h);
  const LayerMesh m = extrude_layer(s, constant_normals(s.num_nodes(), Eigen::Vector3d::UnitZ()),
                                    Eigen::VectorXd::Constant(s.num_nodes(), h), N);
  const int nv = 12, nq = 6, ne = nx * (ny + 1) + ny * (nx + 1);
  EXPECT_EQ(m.num_edges(), ne);
  EXPECT_EQ(m.num_elements(), nq * N);
  EXPECT_EQ(m.num_q1_nodes(), nv * (N + 1));
  EXPECT_EQ(m.num_q2_nodes(), (nv + ne + nq) * (2 * N + 1));
  // Volume of a box: exact (trilinear elements, 2^3 Gauss), so round-off.
  EXPECT_NEAR(layer_volume(m), lx * ly * h, 1e-12 * lx * ly * h);
  // Articular node areas sum to the surface area; a corner vertex gets a quarter quad.
  const Eigen::VectorXd a = articular_node_areas(m);
  EXPECT_NEAR(a.sum(), lx * ly, 1e-15);
  EXPECT_NEAR(a[0], 0.25 * (lx / nx) * (ly / ny), 1e-18);
  // Node sets: bone nodes at z = 0, articular at z = h; outline has 10 vertices, 10 edges.
  for (int n : m.bone_nodes(2)) EXPECT_NEAR(m.q2_nodes(n, 2), 0.0, 1e-15);
  for (int n : m.articular_nodes(2)) EXPECT_NEAR(m.q2_nodes(n, 2), h, 1e-15);
  for (int n : m.bone_nodes(1)) EXPECT_NEAR(m.q1_nodes(n, 2), 0.0, 1e-15);
  for (int n : m.articular_nodes(1)) EXPECT_NEAR(m.q1_nodes(n, 2), h, 1e-15);
  EXPECT_EQ(m.periphery_vertices.size(), 10u);
  EXPECT_EQ(m.periphery_edges.size(), 10u);
  EXPECT_EQ(m.periphery_nodes(1).size(), 10u * (N + 1));
  EXPECT_EQ(m.periphery_nodes(2).size(), 20u * (2 * N + 1));
  for (int n : m.periphery_nodes(2)) {
    const double x = m.q2_nodes(n, 0), y = m.q2_nodes(n, 1);
    EXPECT_TRUE(std::abs(x) < 1e-15 || std::abs(x - lx) < 1e-15 || std::abs(y) < 1e-15 ||
                std::abs(y - ly) < 1e-15);
  }
  // The articular node of vertex v is the vertex itself; its bone node is h below.
  for (int v = 0; v < nv; ++v) {
    EXPECT_EQ((m.q2_nodes.row(m.articular_node(2, v)) - s.V.row(v)).norm(), 0.0);
    EXPECT_NEAR((m.q1_nodes.row(m.bone_node(1, v)) - s.V.row(v)).norm(), h, 1e-15);
  }
  // Element nodes follow the hex_basis order: local node (i, j, k) of the
  // quadratic element is at the parametric point (-1 + i, -1 + j, -1 + k) of
  // the trilinear map of the corners.
  for (int el = 0; el < m.num_elements(); ++el) {
    const auto X = element_corners(m, el);
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) {
          Eigen::Vector3d p = Eigen::Vector3d::Zero();
          for (int c = 0; c < 8; ++c) {
            const double wi = (c & 1) ? 0.5 * i : 0.5 * (2 - i);
            const double wj = (c & 2) ? 0.5 * j : 0.5 * (2 - j);
            const double wk = (c & 4) ? 0.5 * k : 0.5 * (2 - k);
            p += wi * wj * wk * X.row(c).transpose();
          }
          const int node = m.hex_q2(el, (k * 3 + j) * 3 + i);
          EXPECT_LT((m.q2_nodes.row(node).transpose() - p).norm(), 1e-15) << el;
        }
  }
}

// A patch of a cylinder of radius R about the z axis (angle theta, length L),
// normals radially outward; the layer extends inward to radius R - h.
common::QuadMesh cylinder_patch(int n_theta, int n_z, double R, double theta, double L) {
  common::QuadMesh m;
  m.name = "cylinder";
  m.V.resize((n_theta + 1) * (n_z + 1), 3);
  for (int j = 0; j <= n_z; ++j)
    for (int i = 0; i <= n_theta; ++i) {
      const double a = theta * i / n_theta;
      m.V.row(j * (n_theta + 1) + i) << R * std::cos(a), R * std::sin(a), L * j / n_z;
    }
  m.Q.resize(n_theta * n_z, 4);
  for (int j = 0; j < n_z; ++j)
    for (int i = 0; i < n_theta; ++i) {
      const int a = j * (n_theta + 1) + i;
      // Counter-clockwise seen from outside (+r): tangents d/dtheta x d/dz = +r.
      m.Q.row(j * n_theta + i) << a, a + 1, a + n_theta + 2, a + n_theta + 1;
    }
  return m;
}

TEST(LayerMesh, CylindricalLayerVolumeIsTheChordPolygonsExactly) {
  // Each element is a planar trapezoid (chords of the two arcs) times an axial
  // length, so the layer volume is L * n * (R^2 - r^2) sin(dtheta) / 2 exactly
  // (round-off); it converges to the annulus sector theta L (R^2 - r^2) / 2
  // at second order in dtheta.
  const double R = 20e-3, h = 3e-3, theta = kPi / 3, L = 10e-3;
  for (int n : {4, 8, 16}) {
    const common::QuadMesh s = cylinder_patch(n, 3, R, theta, L);
    common::Points3 normals(s.num_nodes(), 3);
    for (int v = 0; v < s.num_nodes(); ++v) normals.row(v) << s.V(v, 0), s.V(v, 1), 0.0;  // normalised inside
    const LayerMesh m = extrude_layer(s, normals, Eigen::VectorXd::Constant(s.num_nodes(), h), 3);
    const double r = R - h;
    const double polygon = L * n * (R * R - r * r) * std::sin(theta / n) / 2;
    EXPECT_NEAR(layer_volume(m), polygon, 1e-12 * polygon) << n;
    const double sector = theta * L * (R * R - r * r) / 2;
    std::printf("n = %2d: volume / sector - 1 = %.3e\n", n, layer_volume(m) / sector - 1);
    // Bone nodes on radius r.
    for (int b : m.bone_nodes(1)) EXPECT_NEAR(m.q1_nodes.row(b).head<2>().norm(), r, 1e-15);
  }
}

TEST(LayerMesh, GradedLevels) {
  // Heights 1 : r : r^2 from the surface: with r = 2 and 3 layers the levels
  // from the bone are 0, 4/7, 6/7, 1.
  const std::vector<double> l = graded_levels(3, 2.0);
  ASSERT_EQ(l.size(), 4u);
  EXPECT_EQ(l[0], 0.0);
  EXPECT_NEAR(l[1], 4.0 / 7.0, 1e-15);
  EXPECT_NEAR(l[2], 6.0 / 7.0, 1e-15);
  EXPECT_EQ(l[3], 1.0);
  const std::vector<double> u = graded_levels(4, 1.0);
  for (int i = 0; i <= 4; ++i) EXPECT_NEAR(u[i], i / 4.0, 1e-15);
  // A graded box keeps its volume, and its mid-levels sit half way.
  const common::QuadMesh s = grid_surface(1, 1, 1e-3, 1e-3, 2e-3);
  const LayerMesh m = extrude_layer(s, constant_normals(4, Eigen::Vector3d::UnitZ()), Eigen::VectorXd::Constant(4, 2e-3),
                                    3, l);
  EXPECT_NEAR(layer_volume(m), 2e-9, 1e-21);
  EXPECT_NEAR(m.q1_nodes(m.q1_node(0, 1), 2), 2e-3 * 4.0 / 7.0, 1e-18);
  EXPECT_NEAR(m.q2_nodes(m.q2_node(0, 3), 2), 2e-3 * 5.0 / 7.0, 1e-18);
  EXPECT_THROW(extrude_layer(s, constant_normals(4, Eigen::Vector3d::UnitZ()), Eigen::VectorXd::Constant(4, 2e-3), 3,
                             {0.0, 0.5, 0.4, 1.0}),
               common::InputError);
}

TEST(LayerMesh, RefusesBadThicknessNormalsAndLayers) {
  const common::QuadMesh s = grid_surface(2, 2, 1e-3, 1e-3);
  const auto n = constant_normals(9, Eigen::Vector3d::UnitZ());
  const Eigen::VectorXd h = Eigen::VectorXd::Constant(9, 1e-3);
  auto expect_error = [&](const common::Points3& normals, const Eigen::VectorXd& thickness, int layers,
                          const std::string& needle) {
    try {
      extrude_layer(s, normals, thickness, layers);
      ADD_FAILURE() << "no error for " << needle;
    } catch (const common::InputError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  Eigen::VectorXd zero = h, negative = h, nan = h;
  zero[4] = 0.0;
  negative[7] = -1e-4;
  nan[2] = std::nan("");
  expect_error(n, zero, 2, "surface node 4: expected a thickness > 0 m, found 0 m");
  expect_error(n, negative, 2, "surface node 7: expected a thickness > 0 m, found -0.0001 m");
  expect_error(n, nan, 2, "surface node 2: expected a thickness > 0 m, found nan m");
  common::Points3 bad = n;
  bad.row(5).setZero();
  expect_error(bad, h, 2, "surface node 5: expected a non-zero finite normal");
  expect_error(n, h, 0, "expected at least 1 element layer");
  expect_error(n, Eigen::VectorXd::Constant(8, 1e-3), 2, "expected one normal and one thickness per surface node (9)");
}

TEST(LayerMesh, RefusesALayerThickerThanTheConcaveRadius) {
  // Two ways a layer turns inside out: normals that disagree with the quads'
  // orientation, and a convex layer thicker than its radius of curvature.
  const double R = 5e-3;
  common::QuadMesh s = cylinder_patch(4, 1, R, kPi / 2, 2e-3);
  common::Points3 inward(s.num_nodes(), 3);
  for (int v = 0; v < s.num_nodes(); ++v) inward.row(v) << -s.V(v, 0), -s.V(v, 1), 0.0;
  // Normals pointing to the axis with quads counter-clockwise seen from
  // outside: the element is inside out.
  try {
    extrude_layer(s, inward, Eigen::VectorXd::Constant(s.num_nodes(), 1e-3), 2);
    ADD_FAILURE() << "inverted layer accepted";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("expected a positive volume Jacobian"), std::string::npos)
        << e.what();
  }
  // Outward normals, but thicker than the radius: the bone-side nodes pass
  // through the axis and the elements invert there.
  common::Points3 outward(s.num_nodes(), 3);
  for (int v = 0; v < s.num_nodes(); ++v) outward.row(v) << s.V(v, 0), s.V(v, 1), 0.0;
  EXPECT_THROW(extrude_layer(s, outward, Eigen::VectorXd::Constant(s.num_nodes(), 1.2 * R), 2),
               common::InputError);
  EXPECT_NO_THROW(extrude_layer(s, outward, Eigen::VectorXd::Constant(s.num_nodes(), 0.5 * R), 2));
}

}  // namespace
}  // namespace arthrosim::biphasic
