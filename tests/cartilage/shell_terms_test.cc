// ShellModel terms: every tangent handed to Newton is checked against central
// finite differences of the generalised force; terms not asked for are never
// built; assembly is deterministic (bit-identical for 1 and 2 threads).
#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "cartilage/shell_model.h"
#include "common/effects.h"
#include "common/error.h"
#include "shell_test_meshes.h"
#include "tangent_fd.h"

namespace arthrosim::cartilage {
namespace {

struct Fixture {
  common::QuadMesh mesh = testing::spherical_patch(3, 0.02, 0.03);
  common::Points3 directors = quad_mesh_vertex_normals(mesh);
  Eigen::VectorXd thickness = Eigen::VectorXd::Constant(mesh.num_nodes(), 1e-3);
  ShellMaterial material;
};

Eigen::VectorXd deformed(const ShellModel& m, double amp, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd q = m.reference_state();
  for (int i = 0; i < q.size(); ++i) q(i) += amp * u(rng) * (i % 6 < 3 ? 1e-3 : 1.0);
  return q;
}

/// A bone turning at a constant rate omega about the unit axis through the
/// origin while its origin moves at the constant velocity v.
BoneMotion steady_bone(const Eigen::Vector3d& axis, double omega, const Eigen::Vector3d& v) {
  BoneMotion bone;
  bone.pose = [axis, omega, v](double t) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = Eigen::AngleAxisd(omega * t, axis).toRotationMatrix();
    X.translation() = v * t;
    return X;
  };
  bone.spatial_velocity = [axis, omega, v](double) {
    Eigen::Matrix<double, 6, 1> V;
    V << omega * axis, v;
    return V;
  };
  return bone;
}

/// max |K - K_fd| / max |K| with K = dF/dq (wrt = 0) or dF/dv (wrt = 1).
/// Steps: 1e-9 m on positions (0.1% of the 1 mm thickness scale times 1e-3)
/// and 1e-6 on dimensionless gradients; central differences then have
/// truncation and round-off errors < 1e-7 relative.
double fd_error(ShellModel& m, double t, const Eigen::VectorXd& q, const Eigen::VectorXd& v, int wrt) {
  double scale = 0;
  const double e = testing::tangent_fd_error(m, t, q, v, wrt, 1e-9, 1e-6, &scale);
  EXPECT_GT(scale, 0.0);
  return e;
}

// Tolerance for all FD checks below: 1e-6 relative to max|K|. Central
// differences with the steps above are accurate to ~1e-8; a missing or wrong
// term (e.g. a dropped geometric stiffness, the non-symmetric pressure part)
// shows up at 1e-3 .. 1.
constexpr double kFdTol = 1e-6;

TEST(ShellTerms, InternalForcesTangent) {
  Fixture f;
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  m.add_internal_forces();
  const Eigen::VectorXd q = deformed(m, 0.05, 1), v = Eigen::VectorXd::Zero(m.num_dofs());
  EXPECT_LT(fd_error(m, 0, q, v, 0), kFdTol);
  EXPECT_TRUE(m.tangent_symmetric());
}

TEST(ShellTerms, FollowerPressureTangentIsNonSymmetricAndConsistent) {
  for (double face : {-1.0, 0.0, 1.0}) {
    Fixture f;
    ShellModel m(f.mesh, f.directors, f.thickness, f.material);
    m.add_pressure("osmotic_pressure", face, [](double) { return 0.2e6; });
    const Eigen::VectorXd q = deformed(m, 0.1, 2), v = Eigen::VectorXd::Zero(m.num_dofs());
    EXPECT_LT(fd_error(m, 0, q, v, 0), kFdTol) << "face " << face;
    EXPECT_FALSE(m.tangent_symmetric());
    // Total force of a uniform pressure on the undeformed cap equals p times
    // the projected area vector (closed-form: p * integral n dA).
    Eigen::VectorXd F;
    const Eigen::VectorXd q0 = m.reference_state();
    numerics::EvalRequest r;
    r.q = &q0;
    m.evaluate(r, F, nullptr, nullptr);
    Eigen::Vector3d total = Eigen::Vector3d::Zero();
    for (int i = 0; i < m.num_nodes(); ++i) total -= F.segment<3>(6 * i);
    // Sum of p (a1 x a2) over the faces = p times the vector area of the
    // boundary-spanning surface; for this symmetric cap it points along +z.
    EXPECT_NEAR(total.x(), 0.0, 1e-12 * total.norm());
    EXPECT_NEAR(total.y(), 0.0, 1e-12 * total.norm());
    EXPECT_GT(total.z(), 0.0);
  }
}

TEST(ShellTerms, FoundationSpringTangent) {
  for (FoundationIntegration integration : {FoundationIntegration::kNodal, FoundationIntegration::kConsistent}) {
    Fixture f;
    ShellModel m(f.mesh, f.directors, f.thickness, f.material);
    // Moving, rotated bone (the anchors translate and turn); a modulus that
    // varies from node to node (k = K / h of a varying thickness).
    const BoneMotion bone = steady_bone(Eigen::Vector3d::UnitX(), 0.3, Eigen::Vector3d(0, 0, 1e-4));
    Eigen::VectorXd k(m.num_nodes());
    for (int i = 0; i < m.num_nodes(); ++i) k(i) = 7e8 * (1 + 0.5 * std::sin(1.3 * i));
    m.add_foundation_springs(k, bone, /*compressive_only=*/true, integration);
    // Push the nodes towards the bone so most springs are compressed, some not.
    Eigen::VectorXd q = deformed(m, 0.02, 3);
    for (int i = 0; i < m.num_nodes(); ++i) q.segment<3>(6 * i) -= 2e-5 * m.reference_director(i);
    const Eigen::VectorXd v = Eigen::VectorXd::Zero(m.num_dofs());
    EXPECT_LT(fd_error(m, 0.5, q, v, 0), kFdTol) << "consistent " << (integration == FoundationIntegration::kConsistent);
  }
}

// Under a uniform deflection d (every node pushed by d along its director
// towards a bone at rest) the element-consistent foundation gives every node
// exactly the nodal springs' force k d A_i n_i (sum_g N_k dA_g = A_k), so the
// total equals k d times the vector area; they differ only where the
// deflection varies (ShellVerification.StiffFoundationSpreading...).
// Tolerance 1e-12 relative: the two sums differ in round-off only.
TEST(ShellTerms, ConsistentFoundationEqualsNodalSpringsUnderAUniformDeflection) {
  Fixture f;
  const double k = 7e8, d = 1e-5;
  Eigen::VectorXd F[2];
  int which = 0;
  for (FoundationIntegration integration : {FoundationIntegration::kNodal, FoundationIntegration::kConsistent}) {
    ShellModel m(f.mesh, f.directors, f.thickness, f.material);
    m.add_foundation_springs(k, BoneMotion::fixed(), true, integration);
    Eigen::VectorXd q = m.reference_state();
    for (int i = 0; i < m.num_nodes(); ++i) q.segment<3>(6 * i) -= d * m.reference_director(i).normalized();
    numerics::EvalRequest r;
    r.q = &q;
    m.evaluate(r, F[which++], nullptr, nullptr);
  }
  ASSERT_GT(F[0].norm(), 0.0);
  EXPECT_LT((F[0] - F[1]).cwiseAbs().maxCoeff(), 1e-12 * F[0].cwiseAbs().maxCoeff());
}

// periphery_fixed with the normal left to the foundation: the tie's tangent
// against FD on a moving, rotating bone, and its action: a boundary node
// displaced along its (bone-carried) normal feels no tie force, one displaced
// in its tangent plane feels k_t A_i times the displacement (exact: linear).
TEST(ShellTerms, PeripheryTangentialTieTangentAndAction) {
  Fixture f;
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  const BoneMotion bone = steady_bone(Eigen::Vector3d::UnitY(), 0.3, Eigen::Vector3d(2e-4, 0, 1e-4));
  const double k_t = 1e12;
  m.add_periphery_tangential(k_t, bone);
  const Eigen::VectorXd v = Eigen::VectorXd::Zero(m.num_dofs());
  EXPECT_LT(fd_error(m, 0.5, deformed(m, 0.02, 5), v, 0), kFdTol);
  EXPECT_TRUE(std::none_of(m.constrained().begin(), m.constrained().end(), [](char c) { return c != 0; }));
  // Action at t = 0 (bone at its reference pose).
  const std::vector<int> rim = m.boundary_nodes();
  ASSERT_FALSE(rim.empty());
  const int i = rim.front();
  const Eigen::Vector3d n = m.reference_director(i).normalized();
  const Eigen::Vector3d tangent = n.unitOrthogonal();
  const Eigen::VectorXd areas = m.nodal_areas();
  for (int along_normal = 0; along_normal < 2; ++along_normal) {
    Eigen::VectorXd q = m.reference_state();
    q.segment<3>(6 * i) += 1e-6 * (along_normal ? n : tangent);
    Eigen::VectorXd F;
    numerics::EvalRequest r;
    r.q = &q;
    r.v = &v;
    m.evaluate(r, F, nullptr, nullptr);
    const Eigen::Vector3d expected = along_normal ? Eigen::Vector3d::Zero() : Eigen::Vector3d(k_t * areas(i) * 1e-6 * tangent);
    // Round-off of (I - n n^T) d on a 1e-6 m displacement: ~1e-16 relative to k_t A d.
    EXPECT_LT((F.segment<3>(6 * i) - expected).norm(), 1e-12 * k_t * areas(i) * 1e-6) << "normal " << along_normal;
  }
}

// Step predictors with a moving bone. A state made of the bone's rigid
// motion T(t) = X_WB(t) X_WB(0)^-1 applied to a reference shape that deforms
// linearly in time, r(t) = T(t)(r_0 + t u), d(t) = R(t)(d_0 + t w), is
// predicted exactly by the extrapolating predictor from its values at tp and
// t0 (positions and directors, 1e-15 relative: round-off only), while the
// rigid predictor misses the deformation change (its error is (t1 - t0) u).
TEST(ShellTerms, ExtrapolatingPredictorIsExactForLinearDeformationOnAMovingBone) {
  Fixture f;
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  BoneMotion bone;
  bone.pose = [](double t) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = Eigen::AngleAxisd(0.4 * t + 0.3 * t * t, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
    X.translation() = Eigen::Vector3d(1e-3 * t, -2e-3 * t * t, 5e-4);
    return X;
  };
  bone.spatial_velocity = [](double) { return Eigen::Matrix<double, 6, 1>::Zero().eval(); };
  m.set_motion_predictor(bone);
  const Eigen::VectorXd ref = m.reference_state();
  Eigen::VectorXd rate(ref.size());
  for (int i = 0; i < rate.size(); ++i) rate(i) = (i % 6 < 3 ? 1e-3 : 0.1) * std::sin(0.37 * i + 1);
  const Eigen::Isometry3d X0inv = bone.pose(0).inverse();
  auto state = [&](double t) {
    const Eigen::Isometry3d T = bone.pose(t) * X0inv;
    Eigen::VectorXd q(ref.size());
    for (int i = 0; i < m.num_nodes(); ++i) {
      q.segment<3>(6 * i) = T * Eigen::Vector3d(ref.segment<3>(6 * i) + t * rate.segment<3>(6 * i));
      q.segment<3>(6 * i + 3) = T.linear() * (ref.segment<3>(6 * i + 3) + t * rate.segment<3>(6 * i + 3));
    }
    return q;
  };
  const double tp = 0.2, t0 = 0.25, t1 = 0.27;
  Eigen::VectorXd q1, q1_rigid;
  m.predict_extrapolated(tp, state(tp), t0, state(t0), t1, q1);
  m.predict(t0, t1, state(t0), q1_rigid);
  const Eigen::VectorXd exact = state(t1);
  const double err = (q1 - exact).cwiseAbs().maxCoeff() / exact.cwiseAbs().maxCoeff();
  const double err_rigid = (q1_rigid - exact).cwiseAbs().maxCoeff() / exact.cwiseAbs().maxCoeff();
  std::printf("extrapolated predictor error %.2e, rigid %.2e (relative)\n", err, err_rigid);
  EXPECT_LT(err, 1e-14);
  EXPECT_GT(err_rigid, 1e-4);  // (t1 - t0) |w| = 2e-3 on directors of size 1
}

TEST(ShellTerms, FoundationDampingTangents) {
  Fixture f;
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  BoneMotion bone;
  bone.pose = [](double t) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = Eigen::AngleAxisd(0.3 * t, Eigen::Vector3d::UnitY()).toRotationMatrix();
    return X;
  };
  bone.spatial_velocity = [](double) {
    Eigen::Matrix<double, 6, 1> V;
    V << 0, 0.3, 0, 0, 0, 0;
    return V;
  };
  m.add_foundation_damping(7e6, bone, /*compressive_only=*/false);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  const Eigen::VectorXd q = deformed(m, 0.02, 4);
  Eigen::VectorXd v(m.num_dofs());
  for (int i = 0; i < v.size(); ++i) v(i) = 1e-3 * u(rng);
  EXPECT_LT(fd_error(m, 0.2, q, v, 0), kFdTol);  // d/dq (rotating direction)
  EXPECT_LT(fd_error(m, 0.2, q, v, 1), kFdTol);  // d/dv
  EXPECT_FALSE(m.tangent_symmetric());
}

TEST(ShellTerms, DirectorMomentTangent) {
  Fixture f;
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  m.add_director_moments("end_moment", Eigen::Vector3d(0, -1, 0), {{0, 2.0}, {3, 1.5}}, [](double) { return 1.0; });
  const Eigen::VectorXd q = deformed(m, 0.2, 6), v = Eigen::VectorXd::Zero(m.num_dofs());
  EXPECT_LT(fd_error(m, 0, q, v, 0), kFdTol);
}

TEST(ShellTerms, OnlyRequestedTermsAreBuilt) {
  Fixture f;
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  EXPECT_TRUE(m.built_terms().empty());
  m.add_internal_forces();
  m.add_pressure("osmotic_pressure", -1, [](double) { return 0.2e6; });
  m.add_periphery_fixed();
  EXPECT_EQ(m.built_terms(), (std::vector<std::string>{"internal_forces", "osmotic_pressure", "periphery_fixed"}));
  EXPECT_FALSE(m.has_inertia());
  EXPECT_EQ(m.mass_matrix().nonZeros(), 0);  // no mass assembled without inertia
  EXPECT_THROW(m.add_internal_forces(), common::InputError);  // no duplicates
}

TEST(ShellTerms, SceneEffectsAreRecordedInTheLedger) {
  Fixture f;
  f.mesh.name = "femur";
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  common::EffectLedger ledger("surface:test");
  m.attach_ledger(&ledger);
  m.add_internal_forces();
  m.add_foundation_springs(7e8);
  m.add_pressure("osmotic_pressure", -1, [](double) { return 0.2e6; });
  m.add_periphery_fixed();
  EXPECT_TRUE(ledger.built("foundation_springs"));
  EXPECT_EQ(ledger.count("foundation_springs"), m.num_nodes());
  EXPECT_EQ(ledger.count("osmotic_pressure"), m.num_elements());
  EXPECT_EQ(ledger.count("periphery_fixed"), static_cast<long>(m.boundary_nodes().size()));
  EXPECT_FALSE(ledger.built("foundation_damping"));
  EXPECT_FALSE(ledger.built("inertia"));
  EXPECT_NO_THROW(ledger.require_only({"foundation_springs", "osmotic_pressure", "periphery_fixed"}));
}

TEST(ShellTerms, AssemblyIsDeterministicAcrossThreadCounts) {
  Fixture f;
  f.mesh = testing::spherical_patch(12, 0.02, 0.03);  // 144 elements: parallel loops active
  f.directors = quad_mesh_vertex_normals(f.mesh);
  f.thickness = Eigen::VectorXd::Constant(f.mesh.num_nodes(), 1e-3);
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  m.add_internal_forces();
  m.add_pressure("osmotic_pressure", -1, [](double) { return 0.2e6; });
  const Eigen::VectorXd q = deformed(m, 0.05, 9);
  auto run = [&](int threads) {
    omp_set_num_threads(threads);
    Eigen::VectorXd F;
    Eigen::SparseMatrix<double> K;
    numerics::EvalRequest r;
    r.q = &q;
    m.evaluate(r, F, nullptr, &K);
    return std::make_pair(F, Eigen::VectorXd(Eigen::Map<Eigen::VectorXd>(K.valuePtr(), K.nonZeros())));
  };
  const auto a = run(1), b = run(2);
  omp_set_num_threads(2);
  EXPECT_TRUE((a.first.array() == b.first.array()).all());
  EXPECT_TRUE((a.second.array() == b.second.array()).all());
}

TEST(ShellTerms, NonFiniteInputNamesTermAndCoordinate) {
  Fixture f;
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  m.add_internal_forces();
  Eigen::VectorXd q = m.reference_state();
  q(6 * 4 + 2) = std::numeric_limits<double>::quiet_NaN();
  Eigen::VectorXd F;
  numerics::EvalRequest r;
  r.q = &q;
  try {
    m.evaluate(r, F, nullptr, nullptr);
    FAIL() << "expected NumericalError";
  } catch (const common::NumericalError& e) {
    EXPECT_NE(std::string(e.what()).find("internal_forces"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("node"), std::string::npos) << e.what();
  }
}

// Messages name a coordinate by node and component, and say when the node is
// on the surface's rim (where contact and foundation support end: the first
// place to look when Newton stalls, docs/contact.md "Stiff contact").
TEST(ShellTerms, DescribeDofMarksRimNodes) {
  Fixture f;
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  const std::vector<int> rim = m.boundary_nodes();
  ASSERT_FALSE(rim.empty());
  int interior = -1;
  for (int i = 0; i < m.num_nodes() && interior < 0; ++i)
    if (!std::binary_search(rim.begin(), rim.end(), i)) interior = i;
  ASSERT_GE(interior, 0);
  EXPECT_EQ(m.describe_dof(6 * rim[0] + 2), "node " + std::to_string(rim[0]) + " (rim) r_z");
  EXPECT_EQ(m.describe_dof(6 * interior + 4), "node " + std::to_string(interior) + " d_y");
}

TEST(ShellTerms, RejectsBadInput) {
  Fixture f;
  Eigen::VectorXd short_thickness = Eigen::VectorXd::Constant(3, 1e-3);
  EXPECT_THROW(ShellModel(f.mesh, f.directors, short_thickness, f.material), common::InputError);
  ShellModel m(f.mesh, f.directors, f.thickness, f.material);
  EXPECT_THROW(m.add_foundation_springs(-1.0), common::InputError);
  EXPECT_THROW(m.add_pressure("p", 2.0, [](double) { return 1.0; }), common::InputError);
  EXPECT_THROW(m.fix_nodes("bad", {999}, {true, true, true, false, false, false}), common::InputError);
}

}  // namespace
}  // namespace arthrosim::cartilage
