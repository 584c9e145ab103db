// Element quality measures against closed forms: a flat square, a quad on a
// cylinder (admissible shell thickness = the cylinder's diameter), an inverted
// quad, a sliver, and the report's message.
#include "common/mesh_quality.h"

#include <gtest/gtest.h>

#include <cmath>

#include "cartilage/shell_element.h"
#include "common/error.h"
#include "common/mesh.h"

namespace arthrosim::common {
namespace {

constexpr double kPi = 3.14159265358979323846;

QuadMesh one_quad(const std::array<Vec3, 4>& x) {
  QuadMesh q;
  q.V.resize(4, 3);
  for (int k = 0; k < 4; ++k) q.V.row(k) = x[k].transpose();
  q.Q.resize(1, 4);
  q.Q << 0, 1, 2, 3;
  q.name = "one_quad";
  return q;
}

Points3 rows(const std::array<Vec3, 4>& d) {
  Points3 p(4, 3);
  for (int k = 0; k < 4; ++k) p.row(k) = d[k].transpose();
  return p;
}

TEST(MeshQuality, FlatSquareIsPerfect) {
  const std::array<Vec3, 4> x = {Vec3(0, 0, 0), Vec3(1e-3, 0, 0), Vec3(1e-3, 1e-3, 0), Vec3(0, 1e-3, 0)};
  const std::array<Vec3, 4> d = {Vec3::UnitZ(), Vec3::UnitZ(), Vec3::UnitZ(), Vec3::UnitZ()};
  const ElementQualityReport r = check_quads(one_quad(x), rows(d), 1e-3);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_DOUBLE_EQ(r.min_edge, 1e-3);
  EXPECT_NEAR(r.min_angle, kPi / 2, 1e-12);
  EXPECT_NEAR(r.max_angle, kPi / 2, 1e-12);
  EXPECT_NEAR(r.min_jacobian_ratio, 1.0, 1e-12);
  // Parallel directors: the Jacobian does not depend on the thickness.
  EXPECT_TRUE(std::isinf(r.min_shell_thickness));
}

TEST(MeshQuality, QuadOnACylinderAdmitsItsDiameter) {
  // Nodes on a cylinder of radius R (axis z) with radial directors: x = R d
  // exactly, so x_xi + s d_xi = (R + s) d_xi and the Jacobian vanishes at
  // s = -R (the axis): admissible thickness 2R, for directors pointing away
  // from the axis; pointing in (a concave shell seen from the directors), the
  // same: the root is at s = +R.
  const double R = 5e-3, phi = 0.2, hz = 1e-3;
  std::array<Vec3, 4> x, d;
  const double th[4] = {-phi, phi, phi, -phi}, z[4] = {0, 0, hz, hz};
  for (int k = 0; k < 4; ++k) {
    d[k] = Vec3(std::cos(th[k]), std::sin(th[k]), 0);
    x[k] = R * d[k] + Vec3(0, 0, z[k]);
  }
  // Counter-clockwise about +r: theta increases along xi, z along eta: (e_theta x e_z) = e_r.
  // The Jacobian vanishes at zeta h / 2 = -R: with |zeta| <= 1, h = 2R.
  EXPECT_NEAR(admissible_shell_thickness(x, d, 1.0), 2 * R, 1e-15);
  EXPECT_NEAR(admissible_shell_thickness(x, d), 2 * R * std::sqrt(3.0), 1e-14);
  ElementQualityLimits limits;
  limits.shell_zeta = 1.0;
  limits.min_shell_thickness = 2 * R * 1.01;
  EXPECT_FALSE(check_quads(one_quad(x), rows(d), 1e-3, limits).ok());
  limits.min_shell_thickness = 2 * R * 0.99;
  EXPECT_TRUE(check_quads(one_quad(x), rows(d), 1e-3, limits).ok());
}

// The admissible thickness (default zeta_max = 1/sqrt(3)) is the shell
// element's own limit: ShellElement checks its reference Jacobian at
// zeta = +-1/sqrt(3) (2 thickness points) and accepts a shell just thinner
// (every check point of this quad has the same root), refuses one just
// thicker.
TEST(MeshQuality, AdmissibleThicknessIsTheShellElementsLimit) {
  const double R = 5e-3, phi = 0.2, hz = 1e-3;
  std::array<Eigen::Vector3d, 4> x, d;
  const double th[4] = {-phi, phi, phi, -phi}, z[4] = {0, 0, hz, hz};
  for (int k = 0; k < 4; ++k) {
    d[k] = Vec3(std::cos(th[k]), std::sin(th[k]), 0);
    x[k] = R * d[k] + Vec3(0, 0, z[k]);
  }
  const double h_max = admissible_shell_thickness(x, d);
  cartilage::ShellMaterial m;
  auto h = [](double v) { return std::array<double, 4>{v, v, v, v}; };
  EXPECT_NO_THROW(cartilage::ShellElement(x, d, h(0.99 * h_max), m, "cylinder quad"));
  EXPECT_THROW(cartilage::ShellElement(x, d, h(1.01 * h_max), m, "cylinder quad"), InputError);
}

TEST(MeshQuality, InvertedQuadFailsTheJacobianSign) {
  const std::array<Vec3, 4> x = {Vec3(0, 0, 0), Vec3(0, 1e-3, 0), Vec3(1e-3, 1e-3, 0), Vec3(1e-3, 0, 0)};  // clockwise about +z
  const std::array<Vec3, 4> d = {Vec3::UnitZ(), Vec3::UnitZ(), Vec3::UnitZ(), Vec3::UnitZ()};
  const ElementQualityReport r = check_quads(one_quad(x), rows(d), 1e-3);
  EXPECT_FALSE(r.ok());
  EXPECT_NEAR(r.min_jacobian_ratio, -1.0, 1e-12);
  ASSERT_EQ(r.issues.size(), 1u);
  EXPECT_EQ(r.issues[0].check, "jacobian");
  EXPECT_EQ(r.min_shell_thickness, 0.0);
}

TEST(MeshQuality, SliverQuadFailsEdgeAndNamesItsPlace) {
  // The issue-28 sliver: a quad at the outline with a 0.002 mm edge in a
  // 3 mm mesh (a corner pushed almost onto its neighbour).
  const std::array<Vec3, 4> x = {Vec3(0, 0, 0), Vec3(1.5e-3, 0, 0), Vec3(1.5e-3, 1e-3, 0),
                                 Vec3(1.498e-3, 1e-3, 0)};
  const std::array<Vec3, 4> d = {Vec3::UnitZ(), Vec3::UnitZ(), Vec3::UnitZ(), Vec3::UnitZ()};
  const ElementQualityReport r = check_quads(one_quad(x), rows(d), 3e-3);
  EXPECT_FALSE(r.ok());
  ASSERT_EQ(r.issues.size(), 1u);
  EXPECT_EQ(r.issues[0].check, "edge");
  EXPECT_NEAR(r.issues[0].value, 2e-6, 1e-12);
  EXPECT_NEAR(r.issues[0].limit, 3e-5, 1e-15);
  const std::string s = r.summary();
  EXPECT_NE(s.find("quad 0 at ("), std::string::npos) << s;
  EXPECT_NE(s.find("edge 0.002 mm < 0.03 mm"), std::string::npos) << s;
}

TEST(MeshQuality, TriangleAnglesAndNormals) {
  TriangleMesh t;
  t.V.resize(4, 3);
  // Triangle 0 equilateral, triangle 1 a needle with a 1 deg angle at vertex 0.
  const double a = 1e-3;
  t.V << 0, 0, 0, a, 0, 0, 0.5 * a, std::sqrt(3.0) / 2 * a, 0, a * std::cos(kPi / 180), -a * std::sin(kPi / 180), 0;
  t.F.resize(2, 3);
  t.F << 0, 1, 2, 0, 3, 1;
  t.name = "pair";
  Points3 n(4, 3);
  for (int i = 0; i < 4; ++i) n.row(i) << 0, 0, 1;
  const ElementQualityReport r = check_triangles(t, n, a);
  EXPECT_EQ(r.failed, 1);
  ASSERT_EQ(r.issues.size(), 1u);
  EXPECT_EQ(r.issues[0].element, 1);
  EXPECT_EQ(r.issues[0].check, "angle");
  EXPECT_NEAR(r.min_angle, kPi / 180, 1e-9);
  // Normals opposite to the triangles: every triangle is inverted.
  const ElementQualityReport flipped = check_triangles(t, -n, a);
  EXPECT_EQ(flipped.failed, 2);
  EXPECT_EQ(flipped.issues[0].check, "jacobian");
}

}  // namespace
}  // namespace arthrosim::common
