// The element matrices of the u-p system: patch tests on a distorted layer
// (fields each element represents exactly), rigid-body modes, the surface
// load operator, the stress/flux evaluation and the material checks.
#include "biphasic/layer_system.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <numeric>

#include "biphasic/layer_fields.h"
#include "biphasic/trapezoidal.h"
#include "biphasic_fixtures.h"
#include "common/error.h"

namespace arthrosim::biphasic {
namespace {

const Material kMaterial{0.7e6, 0.2, 2e-15};

// A 3 x 3 surface whose interior nodes are moved (deterministically) and
// whose thickness and normals vary: every element is a general trilinear hex.
LayerMesh distorted_layer(int layers) {
  common::QuadMesh s = testing::grid_surface(3, 3, 3e-3, 3e-3, 0.0);
  const double shift[4][2] = {{0.21, -0.13}, {-0.17, 0.09}, {0.12, 0.19}, {-0.08, -0.22}};
  int k = 0;
  for (int j = 1; j <= 2; ++j)
    for (int i = 1; i <= 2; ++i, ++k) {
      s.V(j * 4 + i, 0) += shift[k][0] * 1e-3;
      s.V(j * 4 + i, 1) += shift[k][1] * 1e-3;
    }
  common::Points3 n(16, 3);
  Eigen::VectorXd h(16);
  for (int v = 0; v < 16; ++v) {
    s.V(v, 2) = 0.1 * s.V(v, 0) - 0.05 * s.V(v, 1);  // a tilted plane
    n.row(v) << 0.1 + 0.03 * std::sin(3.0 * v), -0.05 + 0.02 * std::cos(2.0 * v), 1.0;
    h[v] = 1.5e-3 + 0.4e-3 * std::sin(1.7 * v);
  }
  s.name = "distorted";
  return extrude_layer(s, n, h, layers);
}

std::vector<int> all_dofs(int n) {
  std::vector<int> v(n);
  std::iota(v.begin(), v.end(), 0);
  return v;
}

TEST(LayerSystem, RigidBodyModesHaveNoStiffnessAndNoDilatation) {
  for (ElementPair pair : {ElementPair::kTaylorHood, ElementPair::kEqualOrder}) {
    const LayerSystem sys = assemble_layer(distorted_layer(2), kMaterial, pair);
    const common::Points3& X = sys.u_nodes();
    for (int mode = 0; mode < 6; ++mode) {
      Eigen::VectorXd u(sys.num_u_dofs());
      for (int a = 0; a < sys.num_u_nodes(); ++a) {
        Eigen::Vector3d d = Eigen::Vector3d::Zero();
        if (mode < 3) d[mode] = 1e-3;
        else d = Eigen::Vector3d::Unit(mode - 3).cross(X.row(a).transpose()) * 1.0;
        u.segment<3>(3 * a) = d;
      }
      // K u = 0 and A^T u = 0 to round-off relative to |K| |u| (1e-9: sums of
      // ~100 terms of both signs per row).
      const double scale = sys.K.norm() * u.norm();
      EXPECT_LT((sys.K * u).norm(), 1e-9 * scale) << to_string(pair) << " mode " << mode;
      EXPECT_LT((sys.A.transpose() * u).norm(), 1e-9 * sys.A.norm() * u.norm()) << mode;
    }
    // B annihilates constant pressure.
    const Eigen::VectorXd one = Eigen::VectorXd::Ones(sys.num_p_dofs());
    EXPECT_LT((sys.B * one).norm(), 1e-9 * sys.B.norm());
  }
}

TEST(LayerSystem, DisplacementPatchTestOnADistortedLayer) {
  // Drained (p = 0 everywhere), a linear displacement field prescribed on the
  // whole boundary: the interior solution must reproduce it exactly and the
  // stress must be the constant C : eps. Tolerance 1e-9 relative (round-off
  // of the solve; the field is in both element spaces).
  for (ElementPair pair : {ElementPair::kTaylorHood, ElementPair::kEqualOrder}) {
    const LayerSystem sys = assemble_layer(distorted_layer(3), kMaterial, pair);
    const int order = sys.u_order();
    Eigen::Matrix3d G;  // displacement gradient
    G << 1e-3, 2e-4, -3e-4, 5e-4, -8e-4, 1e-4, -2e-4, 3e-4, 6e-4;
    const common::Points3& X = sys.u_nodes();
    auto exact = [&](int node) { return Eigen::Vector3d(G * X.row(node).transpose()); };
    std::vector<int> boundary = sys.mesh.bone_nodes(order);
    for (int n : sys.mesh.articular_nodes(order)) boundary.push_back(n);
    for (int n : sys.mesh.periphery_nodes(order)) boundary.push_back(n);
    std::sort(boundary.begin(), boundary.end());
    boundary.erase(std::unique(boundary.begin(), boundary.end()), boundary.end());
    const std::vector<int> fixed_u = testing::dofs_of(boundary, {0, 1, 2});
    TrapezoidalIntegrator integ(sys, fixed_u, all_dofs(sys.num_p_dofs()), {1.0, 1.0});
    StepInput in;
    in.u_fixed.resize(fixed_u.size());
    for (size_t i = 0; i < fixed_u.size(); ++i) in.u_fixed[i] = exact(fixed_u[i] / 3)[fixed_u[i] % 3];
    integ.step(in);
    double err = 0.0;
    for (int a = 0; a < sys.num_u_nodes(); ++a)
      err = std::max(err, (integ.u().segment<3>(3 * a) - exact(a)).norm());
    EXPECT_LT(err, 1e-9 * 3e-3 * G.norm()) << to_string(pair);
    const Eigen::Matrix3d eps = 0.5 * (G + G.transpose());
    const Eigen::Matrix3d sigma = kMaterial.lame_lambda() * eps.trace() * Eigen::Matrix3d::Identity() +
                                  2 * kMaterial.shear_modulus() * eps;
    for (int el = 0; el < sys.mesh.num_elements(); el += 5) {
      const PointFields f = evaluate_point(sys, el, Eigen::Vector3d(0.3, -0.7, 0.9), integ.u(), integ.p());
      EXPECT_LT((f.effective_stress - sigma).norm(), 1e-8 * sigma.norm()) << el;
      EXPECT_LT((f.total_stress - sigma).norm(), 1e-8 * sigma.norm()) << el;
    }
    // Nodal fields: the same constant stress at every corner node, its
    // principal values and the displacement of the corner nodes.
    const NodalFields nf = nodal_fields(sys, integ.u(), integ.p());
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sigma);
    const Eigen::Vector3d ev = eig.eigenvalues();
    for (int n = 0; n < sys.mesh.num_q1_nodes(); ++n) {
      EXPECT_LT((from_voigt(nf.effective_stress.row(n)) - sigma).norm(), 1e-8 * sigma.norm()) << n;
      EXPECT_NEAR(nf.max_principal[n], ev[2], 1e-8 * sigma.norm());
      EXPECT_NEAR(nf.max_shear[n], 0.5 * (ev[2] - ev[0]), 1e-8 * sigma.norm());
      EXPECT_LT((nf.displacement.row(n).transpose() - G * sys.mesh.q1_nodes.row(n).transpose()).norm(),
                1e-9 * 3e-3 * G.norm());
    }
  }
}

TEST(LayerSystem, PressurePatchTestOnADistortedLayer) {
  // Solid held (u = 0), a linear pressure prescribed on the boundary corner
  // nodes (articular, bone and side faces): steady Darcy flow reproduces the
  // linear field inside and the flux -k grad p exactly.
  const LayerSystem sys = assemble_layer(distorted_layer(3), kMaterial, ElementPair::kTaylorHood);
  const Eigen::Vector3d g(2e8, -1e8, 5e8);  // pressure gradient [Pa/m]
  auto exact = [&](int node) { return 1e5 + g.dot(sys.mesh.q1_nodes.row(node).transpose()); };
  std::vector<int> boundary = sys.mesh.bone_nodes(1);
  for (int n : sys.mesh.articular_nodes(1)) boundary.push_back(n);
  for (int n : sys.mesh.periphery_nodes(1)) boundary.push_back(n);
  std::sort(boundary.begin(), boundary.end());
  boundary.erase(std::unique(boundary.begin(), boundary.end()), boundary.end());
  TrapezoidalIntegrator integ(sys, all_dofs(sys.num_u_dofs()), boundary, {1.0, 1.0});
  StepInput in;
  in.u_fixed = Eigen::VectorXd::Zero(sys.num_u_dofs());
  in.p_fixed.resize(boundary.size());
  for (size_t i = 0; i < boundary.size(); ++i) in.p_fixed[i] = exact(boundary[i]);
  integ.step(in);
  double err = 0.0;
  for (int n = 0; n < sys.num_p_dofs(); ++n) err = std::max(err, std::abs(integ.p()[n] - exact(n)));
  EXPECT_LT(err, 1e-9 * 1e5);
  const PointFields f = evaluate_point(sys, 7, Eigen::Vector3d(-0.2, 0.4, 0.1), integ.u(), integ.p());
  EXPECT_LT((f.flux + kMaterial.permeability_m4_per_Ns * g).norm(), 1e-8 * kMaterial.permeability_m4_per_Ns * g.norm());
}

TEST(LayerSystem, SurfaceLoadIntegratesTheTraction) {
  // A uniform traction gives a total force traction x area; a traction linear
  // in x gives the exact moment about the y axis (the bilinear interpolation
  // represents it; 3 x 3 Gauss integrates it exactly on a flat layer).
  const common::QuadMesh s = testing::grid_surface(3, 2, 3e-3, 2e-3, 1e-3);
  const LayerSystem sys = assemble_layer(
      extrude_layer(s, testing::constant_normals(12, Eigen::Vector3d::UnitZ()),
                    Eigen::VectorXd::Constant(12, 1e-3), 2),
      kMaterial);
  Eigen::VectorXd t(36);
  for (int v = 0; v < 12; ++v) t.segment<3>(3 * v) << 1e3, -2e3, -5e4 * (1 + s.V(v, 0) / 3e-3);
  const Eigen::VectorXd F = sys.surface_load * t;
  Eigen::Vector3d total = Eigen::Vector3d::Zero();
  double moment = 0.0;  // about the y axis through x = 0 of the z force
  for (int a = 0; a < sys.num_u_nodes(); ++a) {
    total += F.segment<3>(3 * a);
    moment += sys.u_nodes()(a, 0) * F[3 * a + 2];
  }
  const double area = 6e-6;
  EXPECT_NEAR(total.x(), 1e3 * area, 1e-12);
  EXPECT_NEAR(total.y(), -2e3 * area, 1e-12);
  EXPECT_NEAR(total.z(), -5e4 * 1.5 * area, 1e-10);
  // int_0^L x (1 + x/L) dx * width = (L^2/2 + L^2/3) * width
  EXPECT_NEAR(moment, -5e4 * (4.5e-6 + 3e-6) * 2e-3, 1e-13);
}

TEST(LayerSystem, RefusesInvalidMaterial) {
  const common::QuadMesh s = testing::grid_surface(1, 1, 1e-3, 1e-3);
  const LayerMesh m = extrude_layer(s, testing::constant_normals(4, Eigen::Vector3d::UnitZ()),
                                    Eigen::VectorXd::Constant(4, 1e-3), 1);
  auto expect = [&](Material mat, const std::string& needle) {
    try {
      assemble_layer(m, mat);
      ADD_FAILURE() << needle;
    } catch (const common::InputError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect({0.7e6, 0.2, 0.0}, "permeability: expected a value > 0 m^4/(N s), found 0");
  expect({0.7e6, 0.2, -1e-15}, "permeability: expected a value > 0 m^4/(N s), found -1e-15");
  expect({0.0, 0.2, 1e-15}, "aggregate modulus: expected a value > 0 Pa, found 0");
  expect({0.7e6, 0.5, 1e-15}, "Poisson's ratio: expected a value in [0, 0.5), found 0.5");
  expect({0.7e6, 0.2, std::nan("")}, "permeability");
}

TEST(LayerSystem, AssemblyIsDeterministic) {
  // Same input, bit-identical matrices (no unordered summation).
  const LayerSystem a = assemble_layer(distorted_layer(2), kMaterial);
  const LayerSystem b = assemble_layer(distorted_layer(2), kMaterial);
  ASSERT_EQ(a.K.nonZeros(), b.K.nonZeros());
  for (Eigen::Index i = 0; i < a.K.nonZeros(); ++i) EXPECT_EQ(a.K.valuePtr()[i], b.K.valuePtr()[i]);
  for (Eigen::Index i = 0; i < a.A.nonZeros(); ++i) EXPECT_EQ(a.A.valuePtr()[i], b.A.valuePtr()[i]);
}

}  // namespace
}  // namespace arthrosim::biphasic
