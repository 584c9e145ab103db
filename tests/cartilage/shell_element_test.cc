// Element-level checks of the ANCF shell: consistent tangent against central
// finite differences (with EAS condensation, ANS), energy/force consistency,
// rigid-body invariance, mass matrix totals.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "cartilage/shell_element.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

// A warped, distorted, curved element with directors deliberately not normal
// to the mid-surface and unequal nodal thicknesses (the cases where Chrono's
// 3423 element had indexing slips).
ShellElement make_general_element(const ShellMaterial& m) {
  std::array<Eigen::Vector3d, 4> X = {Eigen::Vector3d(0.0, 0.0, 0.0), Eigen::Vector3d(1.1, 0.1, 0.05),
                                      Eigen::Vector3d(1.3, 0.9, -0.04), Eigen::Vector3d(-0.1, 1.0, 0.02)};
  std::array<Eigen::Vector3d, 4> D = {Eigen::Vector3d(0.1, 0.05, 1.0).normalized(),
                                      Eigen::Vector3d(-0.05, 0.1, 1.0).normalized(),
                                      Eigen::Vector3d(0.0, -0.1, 1.0).normalized(),
                                      Eigen::Vector3d(0.08, 0.0, 1.0).normalized()};
  std::array<double, 4> h = {0.05, 0.06, 0.055, 0.045};
  return ShellElement(X, D, h, m, "test element");
}

Vector24 perturbed_state(const ShellElement& el, double amplitude, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Vector24 q = el.reference();
  for (int i = 0; i < 24; ++i) q(i) += amplitude * u(rng);
  // Large rigid rotation on top so geometric stiffness matters.
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  for (int s = 0; s < 8; ++s) q.segment<3>(3 * s) = R * q.segment<3>(3 * s);
  return q;
}

TEST(ShellElement, TangentMatchesCentralDifferences) {
  for (int nz : {2, 3}) {
    ShellMaterial m;
    m.youngs_modulus_Pa = 1e6;
    m.poisson_ratio = 0.3;
    m.thickness_points = nz;
    const ShellElement el = make_general_element(m);
    const Vector24 q = perturbed_state(el, 0.05, 42);
    Vector24 f;
    Matrix24 K;
    el.internal_force(q, f, &K);
    Matrix24 Kfd;
    const double step = 1e-6;  // coordinates are O(1) m
    for (int j = 0; j < 24; ++j) {
      Vector24 qp = q, qm = q, fp, fm;
      qp(j) += step;
      qm(j) -= step;
      el.internal_force(qp, fp, nullptr);
      el.internal_force(qm, fm, nullptr);
      Kfd.col(j) = (fp - fm) / (2 * step);
    }
    // Central differences: truncation ~ step^2 |f'''| ~ 1e-12 relative and
    // round-off ~ eps |f| / step ~ 1e-10 relative; 1e-6 of the largest entry
    // leaves a wide margin yet would catch any missing term (the geometric
    // or the EAS coupling terms are O(1e-2..1) of max|K| here).
    const double scale = K.cwiseAbs().maxCoeff();
    EXPECT_LT((K - Kfd).cwiseAbs().maxCoeff(), 1e-6 * scale) << "nz=" << nz;
    // Symmetry: the element is hyperelastic with condensed EAS.
    EXPECT_LT((K - K.transpose()).cwiseAbs().maxCoeff(), 1e-10 * scale);
  }
}

TEST(ShellElement, ForceIsGradientOfEnergy) {
  ShellMaterial m;
  m.youngs_modulus_Pa = 1e6;
  const ShellElement el = make_general_element(m);
  const Vector24 q = perturbed_state(el, 0.05, 7);
  Vector24 f;
  el.internal_force(q, f, nullptr);
  const double step = 1e-6;
  double max_err = 0;
  for (int j = 0; j < 24; ++j) {
    Vector24 qp = q, qm = q;
    qp(j) += step;
    qm(j) -= step;
    const double g = (el.strain_energy(qp) - el.strain_energy(qm)) / (2 * step);
    max_err = std::max(max_err, std::abs(g - f(j)));
  }
  // Same finite-difference error budget as above (energy differences lose
  // ~eps*W/step ~ 1e-10 of |f|).
  EXPECT_LT(max_err, 1e-6 * f.cwiseAbs().maxCoeff());
}

TEST(ShellElement, RigidMotionIsStressFree) {
  const ShellElement el = make_general_element(ShellMaterial{});
  const Eigen::Matrix3d R = Eigen::AngleAxisd(2.0, Eigen::Vector3d(0.3, -1, 0.5).normalized()).toRotationMatrix();
  const Eigen::Vector3d t(0.3, -2.0, 5.0);
  Vector24 q = el.reference();
  for (int k = 0; k < 4; ++k) {
    q.segment<3>(6 * k) = R * q.segment<3>(6 * k) + t;
    q.segment<3>(6 * k + 3) = R * q.segment<3>(6 * k + 3);
  }
  Vector24 f;
  el.internal_force(q, f, nullptr);
  // Forces are differences of O(E h) terms; round-off ~1e-16 * E * h * L.
  EXPECT_LT(f.cwiseAbs().maxCoeff(), 1e-12 * 400e6 * 0.06);
}

TEST(ShellElement, MassMatrixTotals) {
  ShellMaterial m;
  m.density_kg_m3 = 1000;
  const ShellElement el = make_general_element(m);
  // Translational mass: sum over r-slot blocks of one component equals
  // rho * volume; volume = int det J over the element.
  double mass_x = 0;
  for (int s = 0; s < 4; ++s)
    for (int t = 0; t < 4; ++t) mass_x += el.mass()(6 * s, 6 * t);
  // Independent volume estimate: mid-surface area times mean thickness is
  // exact to O(curvature * h), which is ~1e-3 relative for this element.
  const double h_mean = (0.05 + 0.06 + 0.055 + 0.045) / 4;
  EXPECT_NEAR(mass_x, 1000 * el.area() * h_mean, 2e-2 * mass_x);
  EXPECT_NEAR(el.nodal_areas()[0] + el.nodal_areas()[1] + el.nodal_areas()[2] + el.nodal_areas()[3],
              el.area(), 1e-14 * el.area());
  // SPD.
  Eigen::SelfAdjointEigenSolver<Matrix24> es(el.mass());
  EXPECT_GT(es.eigenvalues().minCoeff(), 0.0);
}

TEST(ShellElement, RejectsInvertedElement) {
  std::array<Eigen::Vector3d, 4> X = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, 1, 0),
                                      Eigen::Vector3d(1, 1, 0), Eigen::Vector3d(1, 0, 0)};  // clockwise
  std::array<Eigen::Vector3d, 4> D;
  D.fill(Eigen::Vector3d::UnitZ());
  EXPECT_THROW(ShellElement(X, D, {0.1, 0.1, 0.1, 0.1}, ShellMaterial{}, "e7"), common::InputError);
  ShellMaterial bad;
  bad.poisson_ratio = 0.5;
  std::array<Eigen::Vector3d, 4> Xg = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 0, 0),
                                       Eigen::Vector3d(1, 1, 0), Eigen::Vector3d(0, 1, 0)};
  EXPECT_THROW(ShellElement(Xg, D, {0.1, 0.1, 0.1, 0.1}, bad, "e8"), common::InputError);
}

}  // namespace
}  // namespace arthrosim::cartilage
