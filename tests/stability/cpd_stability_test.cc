// Stability cases for Coherent Point Drift (pipelines/cpd.h): degenerate and adversarial inputs
// must give either a correct registration or a clear status/error, never a crash or NaN.
#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <cmath>
#include <algorithm>
#include <numbers>
#include <random>

#include "pipelines/cpd.h"
#include "common/error.h"

namespace arthrosim::pipelines {
namespace {

Eigen::MatrixXd random_points(int n, int D, uint64_t seed, double lo = -1.0, double hi = 1.0) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  Eigen::MatrixXd P(n, D);
  for (int i = 0; i < n; ++i)
    for (int d = 0; d < D; ++d) P(i, d) = u(rng);
  return P;
}

double rel(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) { return (a - b).norm() / b.norm(); }

// An asymmetric 2D outline (like a cartilage map outline): a lobed closed curve plus an interior
// stripe, so its principal axes are distinct and no rotation maps it onto itself.
Eigen::MatrixXd outline(int n) {
  Eigen::MatrixXd P(n, 2);
  for (int i = 0; i < n; ++i) {
    const double a = 2 * std::numbers::pi * i / n;
    const double r = 1.0 + 0.3 * std::cos(2 * a) + 0.15 * std::sin(3 * a);
    P.row(i) << 1.6 * r * std::cos(a), r * std::sin(a);
  }
  return P;
}

// Every point duplicated (and one point repeated 20 times): the GMM has coincident centroids,
// which splits their posterior mass but leaves the Procrustes problem unchanged -> exact.
TEST(CpdStability, DuplicatePoints) {
  Eigen::MatrixXd Y0 = random_points(80, 2, 1);
  Eigen::MatrixXd Y(180, 2);
  Y << Y0, Y0, Y0.row(5).replicate(20, 1);
  const Eigen::MatrixXd R = Eigen::Rotation2Dd(0.4).toRotationMatrix();
  const Eigen::MatrixXd X = (Y * R.transpose()).rowwise() + Eigen::RowVector2d(0.2, 0.1);
  const CpdResult r = cpd_register(X, Y);
  EXPECT_LT(rel(r.rotation, R), 1e-6);
  EXPECT_TRUE(r.transformed.allFinite());
  CpdOptions o;
  o.method = CpdMethod::kNonrigid;  // the duplicated rows make G singular; lambda s^2 I regularises
  const CpdResult rn = cpd_register(X, Y, o);
  EXPECT_LT((rn.transformed - X).norm() / std::sqrt(X.rows()), 1e-4);
}

// All points on a line (rank-1 covariance), unevenly spaced. Measured: the rotation is exact
// (1e-16) but the EM stops at a fixed point with the scale 4.2 % low (0.479 for 0.5, sigma2
// ~1e-4, also with tolerance 1e-10): on a line, soft assignments at the dense end pull the
// set together and the spacing gives no transverse information to resolve it. The test pins
// that behaviour: exact rotation, scale within 5 %, finite output; affine (singular weighted
// covariance) must give finite output or a common::NumericalError, never NaN.
TEST(CpdStability, CollinearPoints) {
  Eigen::MatrixXd Y(60, 2);
  for (int i = 0; i < 60; ++i) Y.row(i) << 0.05 * i * i / 60.0 + i, 0.0;  // uneven spacing on the x axis
  const Eigen::MatrixXd R = Eigen::Rotation2Dd(0.3).toRotationMatrix();
  const Eigen::MatrixXd X = ((Y * R.transpose()) * 0.5).rowwise() + Eigen::RowVector2d(1.0, -2.0);
  const CpdResult r = cpd_register(X, Y);
  EXPECT_LT(rel(r.rotation, R), 1e-6);
  EXPECT_NEAR(r.scale, 0.5, 0.05 * 0.5);
  EXPECT_TRUE(r.transformed.allFinite());
  CpdOptions o;
  o.method = CpdMethod::kAffine;
  try {
    const CpdResult a = cpd_register(X, Y, o);
    EXPECT_TRUE(a.transformed.allFinite());
    EXPECT_TRUE(a.affine.allFinite());
  } catch (const common::NumericalError& e) {
    SUCCEED() << "reported: " << e.what();
  }
}

// 50 % outliers: X = 200 transformed points + 200 uniform points over (about) the inliers'
// bounding box. Measured: w = 0.5 and 0.6 end at max iterations with the rotation off by 1 %
// and 0.3 %; w >= 0.7 reaches the sigma floor with the exact similarity (outliers lose their
// weight as sigma shrinks). Outliers spread over a box 4x the inliers' area trap every w in
// (0.5, 0.9) at scale ~1.4 (measured): the moderate case is what CPD handles.
TEST(CpdStability, FiftyPercentOutliers) {
  const Eigen::MatrixXd Y = random_points(200, 2, 7);
  const Eigen::MatrixXd R = Eigen::Rotation2Dd(-0.5).toRotationMatrix();
  Eigen::MatrixXd X(400, 2);
  X.topRows(200) = ((Y * R.transpose()) * 1.2).rowwise() + Eigen::RowVector2d(0.3, 0.3);
  X.bottomRows(200) = random_points(200, 2, 8, -1.0, 1.6);
  CpdOptions o;
  o.w = 0.7;
  const CpdResult r = cpd_register(X, Y, o);
  EXPECT_NE(r.status, CpdStatus::kMaxIterations);
  EXPECT_LT(rel(r.rotation, R), 1e-6);
  EXPECT_NEAR(r.scale, 1.2, 1.2e-6);
}

// 90 degree rotation: outside plain CPD's capture range for this shape (checked: the plain
// run ends at a wrong local optimum), recovered with the moment-based pre-alignment (principal
// axes, 4 candidate rotations in 2D, best final likelihood kept).
TEST(CpdStability, NinetyDegreeRotationWithMomentPrealignment) {
  const Eigen::MatrixXd Y = outline(300);
  const Eigen::MatrixXd R = Eigen::Rotation2Dd(std::numbers::pi / 2).toRotationMatrix();
  const Eigen::MatrixXd X = (Y * R.transpose()).rowwise() + Eigen::RowVector2d(5.0, 1.0);
  const CpdResult plain = cpd_register(X, Y);
  EXPECT_GT(rel(plain.rotation, R), 0.1) << "plain CPD already captures 90 deg: the test shows nothing";
  CpdOptions o;
  o.prealign = CpdPrealign::kMoments;
  const CpdResult r = cpd_register(X, Y, o);
  EXPECT_GE(r.prealign_candidate, 0);
  EXPECT_LT(rel(r.rotation, R), 1e-6);
  EXPECT_LT(rel(r.transformed, X), 1e-6);
  // Same for 3D with a 90 degree rotation about an oblique axis, and for non-rigid with the
  // rigid pre-alignment composed into the transform.
  Eigen::MatrixXd Y3 = random_points(300, 3, 9);
  Y3.col(0) *= 3.0;
  Y3.col(1) *= 1.5;
  const Eigen::MatrixXd R3 =
      Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  const Eigen::MatrixXd X3 = Y3 * R3.transpose();
  const CpdResult r3 = cpd_register(X3, Y3, o);
  EXPECT_LT(rel(r3.rotation, R3), 1e-6);
  o.method = CpdMethod::kNonrigid;
  const CpdResult rn = cpd_register(X, Y, o);
  EXPECT_LT((rn.transformed - X).norm() / X.norm(), 1e-5);
  EXPECT_LT((rn.transform.jacobian(Y.row(0).transpose()) - R).norm(), 1e-3);
}

// Very unequal sizes: 50 moving points against 5000 data points sampled from the same outline
// (and the reverse). Rigid: checked against the true map with 1 % of the outline size (~3)
// (a 50-point GMM on a 5000-point curve has a bias of order spacing^2 / curvature radius).
// Non-rigid: tangential sliding along the curve is (nearly) free, so the check is the distance
// of every transformed point to the true transformed curve (dense polyline), same tolerance.
TEST(CpdStability, VeryUnequalSetSizes) {
  const Eigen::MatrixXd Ydense = outline(5000);
  const Eigen::MatrixXd Ysparse = outline(50);
  const Eigen::MatrixXd R = Eigen::Rotation2Dd(0.25).toRotationMatrix();
  const Eigen::RowVector2d t(0.4, -0.1);
  const Eigen::MatrixXd curve = (outline(4000) * R.transpose()).rowwise() + t;
  auto curve_distance = [&](const Eigen::MatrixXd& P) {
    double worst = 0.0;
    for (Eigen::Index i = 0; i < P.rows(); ++i)
      worst = std::max(worst, std::sqrt((curve.rowwise() - P.row(i)).rowwise().squaredNorm().minCoeff()));
    return worst;
  };
  for (int dir = 0; dir < 2; ++dir) {
    const Eigen::MatrixXd& Y = dir == 0 ? Ysparse : Ydense;
    const Eigen::MatrixXd& Xsrc = dir == 0 ? Ydense : Ysparse;
    const Eigen::MatrixXd X = (Xsrc * R.transpose()).rowwise() + t;
    CpdOptions o;
    const CpdResult r = cpd_register(X, Y, o);
    const Eigen::MatrixXd truth = (Y * R.transpose()).rowwise() + t;
    EXPECT_LT((r.transformed - truth).cwiseAbs().maxCoeff(), 0.03) << "rigid dir " << dir;
    EXPECT_NE(r.status, CpdStatus::kMaxIterations);
    o.method = CpdMethod::kNonrigid;
    o.prealign = CpdPrealign::kRigid;
    const CpdResult n = cpd_register(X, Y, o);
    EXPECT_TRUE(n.transformed.allFinite());
    // 50 data points cannot pin 5000 centroids everywhere: the bound applies where the sparse
    // set is the moving one; the reverse must stay finite and near (10 % of the size).
    EXPECT_LT(curve_distance(n.transformed), dir == 0 ? 0.03 : 0.3) << "non-rigid dir " << dir;
  }
}

// Two points only (rotated 0.5 rad, scaled 2) / far-apart sets: no crash, finite output or a clear error.
TEST(CpdStability, TinyAndFarApartSets) {
  Eigen::MatrixXd Y(2, 2), X(2, 2);
  Y << 0, 0, 1, 0;
  X << 0, 0, 2 * std::cos(0.5), 2 * std::sin(0.5);
  const CpdResult r = cpd_register(X, Y);
  EXPECT_TRUE(r.transformed.allFinite());
  EXPECT_NEAR(r.scale, 2.0, 1e-6);
  CpdOptions o;
  o.normalize = false;
  o.estep = CpdEStep::kTruncated;
  o.sigma2_initial = 1e-6;  // far too small for sets 1e3 apart: nothing within the cutoff
  try {
    const CpdResult f = cpd_register(X, Y.array() + 1e3, o);
    EXPECT_TRUE(f.transformed.allFinite());
  } catch (const common::NumericalError& e) {
    EXPECT_NE(std::string(e.what()).find("no correspondences"), std::string::npos);
  }
}

}  // namespace
}  // namespace arthrosim::pipelines
