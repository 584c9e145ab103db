// Tests of axial direction statistics and principal strains (pipelines/orientation.h).
#include "pipelines/orientation.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "common/error.h"

namespace arthrosim::pipelines {
namespace {

constexpr double kPi = std::numbers::pi;

// Principal strains of R diag(e1, e2) R^T recover e1, e2 and the rotated axis. The closed
// form involves a handful of flops on O(1) numbers: 1e-14 is a few ulps times the condition.
TEST(PrincipalStrains, Recovers2dClosedForm) {
  for (double theta : {0.0, 0.3, 1.2, -0.7, 1.5}) {
    Eigen::Matrix2d R;
    R << std::cos(theta), -std::sin(theta), std::sin(theta), std::cos(theta);
    const Eigen::Matrix2d E = R * Eigen::Vector2d(0.03, -0.01).asDiagonal() * R.transpose();
    const PrincipalStrains p = principal_strains(E);
    EXPECT_NEAR(p.values(0), 0.03, 1e-14);
    EXPECT_NEAR(p.values(1), -0.01, 1e-14);
    EXPECT_FALSE(p.degenerate);
    EXPECT_NEAR(acute_line_angle(p.directions.col(0), R.col(0)), 0.0, 1e-12);
    EXPECT_NEAR(acute_line_angle(p.directions.col(1), R.col(1)), 0.0, 1e-12);
  }
}

TEST(PrincipalStrains, Recovers3dAndIsSymmetricInput) {
  Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Matrix3d E = R * Eigen::Vector3d(0.02, 0.005, -0.03).asDiagonal() * R.transpose();
  const PrincipalStrains p = principal_strains(E);
  // Iterative symmetric eigensolver: backward stable, eigenvalue error ~ eps |E|; vectors
  // error ~ eps |E| / gap = 1e-16 * 0.03 / 0.015: 1e-12 is a loose bound.
  EXPECT_NEAR(p.values(0), 0.02, 1e-14);
  EXPECT_NEAR(p.values(1), 0.005, 1e-14);
  EXPECT_NEAR(p.values(2), -0.03, 1e-14);
  EXPECT_NEAR(acute_line_angle(p.directions.col(0), R.col(0)), 0.0, 1e-12);
  EXPECT_NEAR(acute_line_angle(p.directions.col(2), R.col(2)), 0.0, 1e-12);
}

// Equal eigenvalues: the direction is undefined; the result must be flagged and deterministic.
TEST(PrincipalStrains, DegenerateIsFlaggedAndDeterministic) {
  const Eigen::Matrix2d E = 0.01 * Eigen::Matrix2d::Identity();
  const PrincipalStrains a = principal_strains(E), b = principal_strains(E);
  EXPECT_TRUE(a.degenerate);
  EXPECT_EQ(a.directions, b.directions);
  EXPECT_EQ(a.directions.col(0), Eigen::Vector2d(1, 0));  // documented: x axis in 2D
  Eigen::Matrix3d E3 = Eigen::Vector3d(0.01, 0.01, -0.02).asDiagonal();
  EXPECT_TRUE(principal_strains(E3).degenerate);
  EXPECT_EQ(principal_strains(E3).directions, principal_strains(E3).directions);
  // A tiny split is resolved continuously (no jump to an arbitrary axis).
  Eigen::Matrix2d Es;
  Es << 0.01 + 1e-12, 0.0, 0.0, 0.01;
  EXPECT_EQ(principal_strains(Es).directions.col(0), Eigen::Vector2d(1, 0));
}

TEST(PrincipalStrains, BadInputThrows) {
  EXPECT_THROW(principal_strains(Eigen::MatrixXd::Zero(2, 3)), common::InputError);
  Eigen::Matrix2d E = Eigen::Matrix2d::Zero();
  E(0, 0) = std::nan("");
  EXPECT_THROW(principal_strains(E), common::InputError);
}

// A constant field with random sign flips and random magnitudes must average to exactly the
// true line with coherence 1 (T = u u^T exactly, up to rounding: 1e-14).
TEST(AxialAverage, RandomSignFlipsAverageToTrueField) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> mag(0.001, 0.05);
  std::bernoulli_distribution flip(0.5);
  const int N = 50, F = 40;
  Eigen::MatrixXd e1(N, F);
  std::vector<Eigen::MatrixXd> dirs(F, Eigen::MatrixXd(N, 3));
  std::vector<Eigen::Vector3d> truth(N);
  for (int i = 0; i < N; ++i) {
    const double a = 0.1 * i;
    truth[i] = Eigen::Vector3d(std::cos(a), std::sin(a), 0.0);
    for (int t = 0; t < F; ++t) {
      e1(i, t) = (flip(rng) ? -1.0 : 1.0) * mag(rng);
      dirs[t].row(i) = (flip(rng) ? -1.0 : 1.0) * truth[i].transpose();
    }
  }
  const auto avg = average_axial_field(e1, dirs);
  // The naive vector mean of the same data is far from the truth: shows the test can fail.
  int bad_naive = 0;
  for (int i = 0; i < N; ++i) {
    ASSERT_TRUE(avg[i].defined);
    EXPECT_NEAR(acute_line_angle(avg[i].direction, truth[i]), 0.0, 1e-7);  // sqrt(eps): eigvec of rank-1 T
    EXPECT_NEAR(avg[i].coherence, 1.0, 1e-14);
    EXPECT_NEAR(avg[i].mean_magnitude, e1.row(i).cwiseAbs().mean(), 1e-15);
    Eigen::Vector3d naive = Eigen::Vector3d::Zero();
    for (int t = 0; t < F; ++t) naive += dirs[t].row(i).transpose();
    if (naive.norm() < 0.5 * F) ++bad_naive;
  }
  EXPECT_GT(bad_naive, N / 2);
}

// A line rotating uniformly by a total angle phi over the frames (equal magnitudes) has the
// closed-form tensor coherence |sin(phi)/phi| (continuous limit; discrete sum below), so the
// coherence drops monotonically from 1 as the rotation grows (up to phi = pi).
TEST(AxialAverage, CoherenceDropsForRotatingField) {
  const int F = 200;
  double previous = 1.0 + 1e-12;
  for (double phi : {0.0, 0.2, 0.5, 1.0, 2.0, 3.0}) {
    Eigen::VectorXd e1 = Eigen::VectorXd::Constant(F, 0.01);
    Eigen::MatrixXd d(F, 2);
    double c = 0, s = 0;
    for (int t = 0; t < F; ++t) {
      const double a = 0.4 + phi * (t + 0.5) / F - 0.5 * phi;
      d.row(t) << std::cos(a), std::sin(a);
      c += std::cos(2 * a);
      s += std::sin(2 * a);
    }
    const AxialAverage avg = average_axial(e1, d);
    // Exact discrete value: l1 - l2 = |mean of (cos 2a, sin 2a)|, l1 + l2 = 1.
    EXPECT_NEAR(avg.coherence, std::hypot(c, s) / F, 1e-13);
    EXPECT_LT(avg.coherence, previous);
    previous = avg.coherence;
    EXPECT_NEAR(acute_line_angle_2d(std::atan2(avg.direction(1), avg.direction(0)), 0.4), 0.0, 1e-9);
  }
  EXPECT_LT(previous, 0.1);
}

TEST(AxialAverage, ZeroMagnitudeIsUndefinedAndBadInputThrows) {
  const AxialAverage a = average_axial(Eigen::VectorXd::Zero(3), Eigen::MatrixXd::Ones(3, 2));
  EXPECT_FALSE(a.defined);
  EXPECT_EQ(a.coherence, 0.0);
  EXPECT_THROW(average_axial(Eigen::VectorXd::Ones(3), Eigen::MatrixXd::Ones(2, 2)), common::InputError);
  EXPECT_THROW(average_axial(Eigen::VectorXd::Ones(2), Eigen::MatrixXd::Zero(2, 2)), common::InputError);
  EXPECT_THROW(average_axial(Eigen::VectorXd::Ones(2), Eigen::MatrixXd::Ones(2, 4)), common::InputError);
}

TEST(LineAngle, AcuteAngles) {
  EXPECT_NEAR(acute_line_angle(Eigen::Vector2d(1, 0), Eigen::Vector2d(-1, 1)), kPi / 4, 1e-15);
  EXPECT_NEAR(acute_line_angle(Eigen::Vector2d(1, 0), Eigen::Vector2d(-1, 0)), 0.0, 0.0);
  EXPECT_NEAR(acute_line_angle(Eigen::Vector3d(0, 0, 2), Eigen::Vector3d(1, 0, 0)), kPi / 2, 1e-15);
  EXPECT_NEAR(acute_line_angle(Eigen::Vector3d(1, 1, 0), Eigen::Vector3d(-1, 0, 0)), kPi / 4, 1e-15);
  EXPECT_NEAR(acute_line_angle_2d(0.1, 0.1 + kPi), 0.0, 1e-15);
  EXPECT_NEAR(acute_line_angle_2d(0.0, 100 * kPi / 180), 80 * kPi / 180, 1e-13);
  EXPECT_NEAR(acute_line_angle_2d(-0.5, 0.5 + 2 * kPi), 1.0, 1e-13);
  EXPECT_NEAR(acute_line_angle_2d(0.0, kPi / 2), kPi / 2, 1e-15);
  EXPECT_THROW(acute_line_angle(Eigen::Vector2d(0, 0), Eigen::Vector2d(1, 0)), common::InputError);
}

}  // namespace
}  // namespace arthrosim::pipelines
