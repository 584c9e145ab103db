// cartilage/surface_model.h: model building with exactly the listed effects,
// and the nodal strain post-processing against closed forms.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>

#include "numerics/hht_integrator.h"
#include "cartilage/surface_model.h"
#include "common/effects.h"
#include "common/error.h"
#include "shell_test_meshes.h"

namespace arthrosim::cartilage {
namespace {

SurfaceInput plate_input(const Eigen::Matrix3d& R_WP, double distortion) {
  SurfaceInput s;
  s.name = "plate";
  s.mesh = testing::plate_mesh(6, 4, 0.03, 0.02, distortion);
  s.mesh.V = (s.mesh.V * R_WP.transpose()).eval();  // rows: p_W = R_WP p_P
  s.normals = quad_mesh_vertex_normals(s.mesh);
  return s;
}

// Homogeneous deformation r = X_W0 + A (X - X_W0) of a flat plate (any
// orientation, distorted elements): the bilinear element reproduces it
// exactly, so every node's strain is the closed form E = (A^T A - I)/2
// projected on its basis (a1, a2), and e1, e2, e1_dir are the eigen-pairs of
// that 2 x 2 tensor. Tolerance 1e-12: only round-off of O(1) quantities.
TEST(SurfaceStrain, HomogeneousDeformationGivesClosedFormAtEveryNode) {
  for (double distortion : {0.0, 0.25}) {
    const Eigen::Matrix3d R_WP =
        (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())).toRotationMatrix();
    const SurfaceInput s = plate_input(R_WP, distortion);
    auto model = build_surface_model(s, SurfaceParameters{}, {}, BoneMotion::fixed(), nullptr);
    const NodeBasis b = node_strain_basis(*model);
    // In-plate stretch 3% / -1% and shear 2%, expressed in world components.
    Eigen::Matrix3d A_P = Eigen::Matrix3d::Identity();
    A_P(0, 0) = 1.03;
    A_P(1, 1) = 0.99;
    A_P(0, 1) = 0.02;
    const Eigen::Matrix3d A_W = R_WP * A_P * R_WP.transpose();
    Eigen::VectorXd q = model->reference_state();
    for (int i = 0; i < model->num_nodes(); ++i) {
      q.segment<3>(6 * i) = A_W * model->reference_position(i);
      // Director: the deformed normal (unit, so no thickness strain).
      q.segment<3>(6 * i + 3) = (R_WP * (A_P.col(0).cross(A_P.col(1))).normalized()).eval();
    }
    const Eigen::Matrix3d E_W = 0.5 * (A_W.transpose() * A_W - Eigen::Matrix3d::Identity());
    const NodalStrains st = nodal_strains(*model, b, q);
    for (int i = 0; i < model->num_nodes(); ++i) {
      const Eigen::Vector3d a1 = b.a1.row(i).transpose(), a2 = b.a2.row(i).transpose(), n = b.n.row(i).transpose();
      ASSERT_NEAR(a1.norm(), 1, 1e-14);
      ASSERT_NEAR(a1.dot(n), 0, 1e-14);
      ASSERT_NEAR(a2.dot(a1), 0, 1e-14);
      const double exx = a1.dot(E_W * a1), eyy = a2.dot(E_W * a2), exy = a1.dot(E_W * a2);
      ASSERT_NEAR(st.E(i, 0), exx, 1e-12) << "node " << i << " distortion " << distortion;
      ASSERT_NEAR(st.E(i, 1), eyy, 1e-12);
      ASSERT_NEAR(st.E(i, 2), exy, 1e-12);
      Eigen::Matrix2d E2;
      E2 << exx, exy, exy, eyy;
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(E2);
      ASSERT_NEAR(st.e1(i), es.eigenvalues()(1), 1e-12);
      ASSERT_NEAR(st.e2(i), es.eigenvalues()(0), 1e-12);
      const Eigen::Vector3d v = es.eigenvectors()(0, 1) * a1 + es.eigenvectors()(1, 1) * a2;
      const Eigen::Vector3d d = st.e1_dir.row(i).transpose();
      ASSERT_NEAR(d.norm(), 1, 1e-12);
      ASSERT_NEAR(std::abs(d.dot(v)), 1, 1e-9);  // same axis (eigenvalues differ by ~0.04)
      ASSERT_GE(d.dot(a1), 0);
    }
    // Deflection and displacement of the same state: in-plane motion only.
    EXPECT_LT(nodal_deflection(*model, q).cwiseAbs().maxCoeff(), 1e-15);
    EXPECT_NEAR(nodal_displacement(*model, q).row(7).norm(),
                ((A_W - Eigen::Matrix3d::Identity()) * model->reference_position(7)).norm(), 1e-15);
  }
}

// The basis falls back to the world y axis where the normal is along x.
TEST(SurfaceStrain, BasisFallsBackToYWhenNormalIsAlongX) {
  const Eigen::Matrix3d R_WP = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const SurfaceInput s = plate_input(R_WP, 0.0);  // plate normal +z -> +x
  auto model = build_surface_model(s, SurfaceParameters{}, {}, BoneMotion::fixed(), nullptr);
  const NodeBasis b = node_strain_basis(*model);
  EXPECT_NEAR(std::abs(b.n(0, 0)), 1.0, 1e-12);
  EXPECT_NEAR(b.a1(0, 1), 1.0, 1e-12);
}

// Exactly the listed effects are built and recorded, per surface.
TEST(SurfaceModel, BuildsExactlyTheListedEffects) {
  const SurfaceInput s = plate_input(Eigen::Matrix3d::Identity(), 0.0);
  common::EffectLedger ledger("test");
  auto model = build_surface_model(s, SurfaceParameters{}, {"osmotic_pressure", "periphery_fixed"},
                                   BoneMotion::fixed(), &ledger);
  EXPECT_TRUE(ledger.built("osmotic_pressure"));
  EXPECT_EQ(ledger.count("osmotic_pressure"), model->num_elements());
  EXPECT_TRUE(ledger.built("periphery_fixed"));
  EXPECT_EQ(ledger.count("periphery_fixed"), 2 * (6 + 4));  // boundary nodes of a 6 x 4 grid
  for (const char* e : {"foundation_springs", "foundation_damping", "inertia", "mesh_contact", "imposed_kinematics"})
    EXPECT_FALSE(ledger.built(e)) << e;
  EXPECT_FALSE(model->has_inertia());
  const std::vector<std::string> expected = {"internal_forces", "osmotic_pressure", "periphery_fixed"};
  EXPECT_EQ(model->built_terms(), expected);
}

// foundation_integration reaches the term: springs at the nodes (one per
// node) or the Gauss points of every element (four per element), recorded
// as such in the ledger.
TEST(SurfaceModel, FoundationIntegrationChoosesNodesOrGaussPoints) {
  const SurfaceInput s = plate_input(Eigen::Matrix3d::Identity(), 0.0);
  for (FoundationIntegration integration : {FoundationIntegration::kNodal, FoundationIntegration::kConsistent}) {
    SurfaceParameters par;
    par.foundation_integration = integration;
    common::EffectLedger ledger("test");
    auto model = build_surface_model(s, par, {"foundation_springs"}, BoneMotion::fixed(), &ledger);
    EXPECT_EQ(ledger.count("foundation_springs"),
              integration == FoundationIntegration::kNodal ? model->num_nodes() : 4 * model->num_elements());
  }
}

// osmotic_ramp_s: the osmotic pressure's nodal forces (the residual of the
// undeformed plate, where internal forces vanish) are 0 at t = 0, the
// smoothstep's 1/2 at half the ramp, s(1/4) = 0.15625 at a quarter and the
// full pressure from the end of the ramp on; without a
// ramp the full pressure acts from t = 0. Exact up to round-off (1e-12).
TEST(SurfaceModel, OsmoticPressureRampsOverTheGivenTime) {
  const SurfaceInput s = plate_input(Eigen::Matrix3d::Identity(), 0.1);
  SurfaceParameters par;
  par.osmotic_ramp_s = 0.02;
  auto ramped = build_surface_model(s, par, {"osmotic_pressure"}, BoneMotion::fixed(), nullptr);
  auto plain = build_surface_model(s, SurfaceParameters{}, {"osmotic_pressure"}, BoneMotion::fixed(), nullptr);
  const Eigen::VectorXd q = ramped->reference_state();
  auto force = [&](ShellModel& m, double t) {
    numerics::EvalRequest r;
    r.t = t;
    r.q = &q;
    Eigen::VectorXd F;
    m.evaluate(r, F, nullptr, nullptr);
    return F;
  };
  const Eigen::VectorXd full = force(*plain, 0.0);
  ASSERT_GT(full.norm(), 0.0);
  const double s_quarter = 0.25 * 0.25 * (3 - 2 * 0.25);
  EXPECT_LT(force(*ramped, 0.0).norm(), 1e-12 * full.norm());
  EXPECT_LT((force(*ramped, 0.005) - s_quarter * full).norm(), 1e-12 * full.norm());
  EXPECT_LT((force(*ramped, 0.01) - 0.5 * full).norm(), 1e-12 * full.norm());
  EXPECT_LT((force(*ramped, 0.02) - full).norm(), 1e-12 * full.norm());
  EXPECT_LT((force(*ramped, 0.5) - full).norm(), 1e-12 * full.norm());
  EXPECT_LT((force(*plain, 0.5) - full).norm(), 1e-12 * full.norm());
}

TEST(SurfaceModel, EffectsItCannotBuildAreErrorsNotOmissions) {
  const SurfaceInput s = plate_input(Eigen::Matrix3d::Identity(), 0.0);
  common::EffectLedger ledger("test");
  // mesh_contact is accepted (it couples two models: the caller builds it,
  // CoupledShellSystem); imposed_kinematics is rejected here because the
  // bone is at rest.
  for (const char* e : {"imposed_kinematics", "no_such_effect"}) {
    try {
      build_surface_model(s, SurfaceParameters{}, {"foundation_springs", e}, BoneMotion::fixed(), &ledger);
      FAIL() << e;
    } catch (const common::InputError& err) {
      EXPECT_NE(std::string(err.what()).find(e), std::string::npos) << err.what();
    }
  }
  EXPECT_TRUE(ledger.records().empty());  // nothing was built before the error
}

// The osmotic scenario's two paths to its steady state (docs/surface_output.md,
// "How the scenario is solved"): the direct static solve (steady_state: true)
// and the dynamic HHT path from rest (inertia, foundation springs and the
// seed's compressive-only dampers, osmotic pressure applied at t = 0,
// periphery fixed) stepped until the change per step is below a tolerance.
// Model: a 12 x 12 spherical patch (24 mm across, R = 25 mm, seed material and
// effect values, SurfaceParameters defaults; the full pressure from t = 0). The rest state of the dynamic
// problem is the static equilibrium (a = v = 0 in the HHT equation leaves
// F(q) = 0), so both must end in the same state, for the seed's dt = 1e-4 s and
// for a 10x larger step.
// Tolerance: the dynamic run stops when the largest weighted change per step is
// below tol = 1e-6 x the static max deflection; a transient that decays by a
// factor rho per step leaves about tol rho/(1 - rho) behind (HHT with alpha
// -0.2: rho -> (1 + alpha)/(1 - alpha) = 2/3 for omega h -> infinity, 0.88 at
// omega h = pi); both Newton solves are converged to a relative 1e-8. Bound:
// 1e-5 x the max deflection, i.e. rho up to 0.9 (measured: 8.3e-7 and 3.3e-7
// of it for dt = 1e-4 and 1e-3 s).
SurfaceInput osmotic_patch_input(int n) {
  SurfaceInput s;
  s.name = "patch";
  s.mesh = testing::spherical_patch(n, 0.024, 0.025);
  s.mesh.name = s.name;
  s.normals = quad_mesh_vertex_normals(s.mesh);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i)
      if (i == 0 || j == 0 || i == n || j == n) s.periphery.push_back(j * (n + 1) + i);
  return s;
}

TEST(SurfaceModel, DynamicOsmoticPathEndsAtTheStaticSteadyState) {
  const SurfaceInput s = osmotic_patch_input(12);
  const std::vector<std::string> effects = {"foundation_springs", "foundation_damping", "osmotic_pressure",
                                            "periphery_fixed", "inertia"};
  auto max_weighted = [](const Eigen::VectorXd& x, const Eigen::VectorXd& w) {
    return x.cwiseAbs().cwiseProduct(w).maxCoeff();
  };
  // Static equilibrium in one quasi-static load step (the steady_state solve).
  auto stat_model = build_surface_model(s, SurfaceParameters{}, effects, BoneMotion::fixed(), nullptr);
  numerics::IntegratorOptions so;
  so.quasi_static = true;
  so.dt_s = 1.0;
  so.max_newton_iterations = 30;
  numerics::HhtIntegrator stat(*stat_model, so);
  stat.initialize(0, stat_model->reference_state());
  stat.advance_to(1.0);
  const Eigen::VectorXd& w = stat_model->increment_weights();
  const Eigen::VectorXd w_stat = nodal_deflection(*stat_model, stat.q());
  const double w_max = w_stat.maxCoeff();
  ASSERT_GT(w_max, 1e-5);  // the patch swells (tens of micrometres)
  // Precondition of the comparison with the seed's dampers (c/k = 1e7 s): no
  // node ends pressed towards the bone, where a compressive damper would hold
  // it back for ~c/k (the anchor femur has such nodes; docs/shell_element.md,
  // section 4). Round-off bound 1e-12 m.
  ASSERT_GE(w_stat.minCoeff(), -1e-12);
  for (double dt : {1e-4, 1e-3}) {
    auto dyn_model = build_surface_model(s, SurfaceParameters{}, effects, BoneMotion::fixed(), nullptr);
    numerics::IntegratorOptions o;  // alpha -0.2 (seed)
    o.dt_s = dt;
    o.reuse_factorization = true;
    numerics::HhtIntegrator dyn(*dyn_model, o);
    dyn.initialize(0, dyn_model->reference_state());
    double change = 0;
    const bool steady = dyn.advance_to_steady_state(1e-6 * w_max, 2000 * dt, &change);
    ASSERT_TRUE(steady) << "dt " << dt << ": change per step still " << change << " m at t = " << dyn.time();
    const double diff = max_weighted(dyn.q() - stat.q(), w);
    std::printf("dynamic osmotic patch, dt %g: %ld steps, %ld Newton iterations, %ld factorizations, max deflection %.6e (static %.6e), "
                "max weighted difference %.3e m (%.3e of it)\n",
                dt, dyn.statistics().steps, dyn.statistics().newton_iterations, dyn.statistics().factorizations,
                nodal_deflection(*dyn_model, dyn.q()).maxCoeff(), w_max, diff, diff / w_max);
    EXPECT_LT(diff, 1e-5 * w_max) << "dt " << dt;
    EXPECT_EQ(dyn.statistics().rejected_steps, 0);
  }
}

// Interpolated bone motion: samples are reproduced, and the spatial velocity
// is the derivative of the interpolated pose (central differences inside an
// interval; both are exact for the piecewise slerp/linear path, so the
// tolerance only covers the O(h^2) difference error at h = 1e-6 s and
// round-off: 1e-6 relative).
TEST(SurfaceKinematics, InterpolatedMotionReproducesSamplesAndItsVelocityIsItsDerivative) {
  std::vector<double> t = {0.5, 0.6, 0.75};
  std::vector<Eigen::Isometry3d> X(3, Eigen::Isometry3d::Identity());
  X[1].linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(0, 0, 1)).toRotationMatrix();
  X[1].translation() << 0.01, -0.02, 0.005;
  X[2].linear() = Eigen::AngleAxisd(0.5, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  X[2].translation() << 0.0, 0.01, 0.0;
  const BoneMotion m = interpolated_bone_motion(t, X, "test");
  EXPECT_FALSE(m.at_rest);
  for (int k = 0; k < 3; ++k)
    EXPECT_LT((m.pose(t[k] - t[0]).matrix() - X[k].matrix()).norm(), 1e-14) << k;
  for (double s : {0.03, 0.08, 0.12, 0.2}) {
    const double h = 1e-6;
    const Eigen::Isometry3d A = m.pose(s - h), B = m.pose(s + h);
    const Eigen::AngleAxisd rel(B.linear() * A.linear().transpose());
    const Eigen::Vector3d w_fd = rel.angle() / (2 * h) * rel.axis();
    const Eigen::Vector3d v_fd = (B.translation() - A.translation()) / (2 * h);
    const Eigen::Matrix<double, 6, 1> V = m.spatial_velocity(s);
    EXPECT_LT((V.head<3>() - w_fd).norm(), 1e-6 * V.head<3>().norm()) << s;
    EXPECT_LT((V.tail<3>() - v_fd).norm(), 1e-6 * V.tail<3>().norm()) << s;
  }
  // Held before the first and after the last sample, with zero velocity.
  EXPECT_LT((m.pose(1.0).matrix() - X[2].matrix()).norm(), 1e-14);
  EXPECT_EQ(m.spatial_velocity(1.0).norm(), 0.0);
  EXPECT_THROW(interpolated_bone_motion({0, 0}, {X[0], X[1]}, "test"), common::InputError);
  EXPECT_THROW(interpolated_bone_motion({0}, {}, "test"), common::InputError);
}

}  // namespace
}  // namespace arthrosim::cartilage
