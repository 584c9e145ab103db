// Tests of Coherent Point Drift (pipelines/cpd.h) against known transforms.
#include "pipelines/cpd.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <algorithm>
#include <numeric>
#include <random>

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

Eigen::MatrixXd rotation(int D, double angle) {
  if (D == 2) return Eigen::Rotation2Dd(angle).toRotationMatrix();
  return Eigen::AngleAxisd(angle, Eigen::Vector3d(0.3, -0.5, 0.8).normalized()).toRotationMatrix();
}

Eigen::MatrixXd apply_similarity(const Eigen::MatrixXd& Y, double s, const Eigen::MatrixXd& R,
                                 const Eigen::VectorXd& t) {
  return ((Y * R.transpose()) * s).rowwise() + t.transpose();
}

double rel(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) { return (a - b).norm() / b.norm(); }

// A smooth warp of the plane (units of the set size ~1): displacement up to ~0.08.
Eigen::MatrixXd smooth_warp(const Eigen::MatrixXd& Y) {
  Eigen::MatrixXd X = Y;
  for (Eigen::Index i = 0; i < Y.rows(); ++i) {
    const double x = Y(i, 0), y = Y(i, 1);
    X(i, 0) = x + 0.06 * std::sin(1.5 * y) + 0.03 * x * y;
    X(i, 1) = y + 0.05 * std::cos(1.2 * x) - 0.04 * x * x;
  }
  return X;
}
Eigen::Matrix2d smooth_warp_jacobian(double x, double y) {
  Eigen::Matrix2d J;
  J << 1 + 0.03 * y, 0.09 * std::cos(1.5 * y) + 0.03 * x, -0.06 * std::sin(1.2 * x) - 0.08 * x, 1.0;
  return J;
}

// Exact data (X = s R Y + t, same points): EM drives sigma2 to the floor, where the posterior is
// a permutation to double precision; Procrustes is then exact up to rounding. 1e-6 relative is
// the requirement and leaves 8+ digits of margin for the floor's residual blur.
TEST(CpdRigid, RecoversSimilarity2dAnd3d) {
  for (int D : {2, 3}) {
    const Eigen::MatrixXd Y = random_points(150, D, 11 + D, -0.05, 0.05);  // metres
    const Eigen::MatrixXd R = rotation(D, 0.5);
    const double s = 1.7;
    const Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(D, 0.2, -0.3);
    const Eigen::MatrixXd X = apply_similarity(Y, s, R, t);
    const CpdResult r = cpd_register(X, Y);
    EXPECT_NE(r.status, CpdStatus::kMaxIterations) << to_string(r.status);
    EXPECT_LT(rel(r.rotation, R), 1e-6) << "D=" << D;
    EXPECT_NEAR(r.scale, s, 1e-6 * s);
    EXPECT_LT(rel(r.translation, t), 1e-6);
    EXPECT_LT(rel(r.transformed, X), 1e-6);
    EXPECT_NEAR(r.rotation.determinant(), 1.0, 1e-12);
    // The Jacobian of a similarity is s R everywhere.
    EXPECT_LT(rel(r.transform.jacobian(Y.row(3).transpose()), s * R), 1e-6);
  }
}

// Same but with scale fixed: the fitted map must be a pure rotation + translation.
TEST(CpdRigid, FixedScaleKeepsScaleOne) {
  const Eigen::MatrixXd Y = random_points(120, 2, 5);
  const Eigen::MatrixXd R = rotation(2, -0.4);
  const Eigen::VectorXd t = Eigen::Vector2d(0.5, 1.0);
  const Eigen::MatrixXd X = apply_similarity(Y, 1.0, R, t);
  CpdOptions o;
  o.estimate_scale = false;
  const CpdResult r = cpd_register(X, Y, o);
  EXPECT_EQ(r.scale, 1.0);
  EXPECT_LT(rel(r.rotation, R), 1e-6);
  EXPECT_LT(rel(r.translation, t), 1e-6);
}

// Reflection is excluded: a mirrored set is fitted by a proper rotation (det +1), never det -1.
TEST(CpdRigid, NeverReflects) {
  const Eigen::MatrixXd Y = random_points(100, 2, 9);
  Eigen::MatrixXd X = Y;
  X.col(0) *= -1.0;
  const CpdResult r = cpd_register(X, Y);
  EXPECT_NEAR(r.rotation.determinant(), 1.0, 1e-12);
  EXPECT_GT(r.sigma2, 1e-3);  // cannot fit a mirror image exactly
}

// Affine: the EM fixed point for exact data is the exact map (sigma2 -> floor); 1e-6 as above.
TEST(CpdAffine, RecoversAffine2dAnd3d) {
  for (int D : {2, 3}) {
    const Eigen::MatrixXd Y = random_points(200, D, 21 + D);
    Eigen::MatrixXd B = rotation(D, 0.3) * 1.2;
    B(0, 1) += 0.25;  // shear
    B(D - 1, 0) -= 0.1;
    const Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(D, -2.0, 3.0);
    const Eigen::MatrixXd X = (Y * B.transpose()).rowwise() + t.transpose();
    CpdOptions o;
    o.method = CpdMethod::kAffine;
    const CpdResult r = cpd_register(X, Y, o);
    EXPECT_NE(r.status, CpdStatus::kMaxIterations) << to_string(r.status);
    EXPECT_LT(rel(r.affine, B), 1e-6) << "D=" << D;
    EXPECT_LT(rel(r.translation, t), 1e-6);
    EXPECT_LT(rel(r.transformed, X), 1e-6);
  }
}

// Non-rigid, known smooth warp (RMS displacement 0.054 of a set of size ~1), X = f(Y) in
// shuffled order. Exact correspondences exist, so as sigma -> 0 the regularisation lambda s^2
// vanishes and the EM fixed point interpolates the data: the residual is set by the sigma2
// floor (s ~ 1e-6). Measured: 3.1e-7 RMS at the points, 2.6e-7 at 200 NEW interior points
// (Gaussian RBF interpolation of a smooth field), Jacobian error <= 3e-6. Tolerances: 1e-5 RMS
// (30x margin), Jacobian 1e-4 (warp gradients are ~0.1, so a wrong term would show).
TEST(CpdNonrigid, RecoversSmoothWarp2d) {
  const Eigen::MatrixXd Y = random_points(400, 2, 31);
  Eigen::MatrixXd X = smooth_warp(Y);
  std::mt19937_64 rng(3);
  std::vector<int> perm(X.rows());
  std::iota(perm.begin(), perm.end(), 0);
  std::shuffle(perm.begin(), perm.end(), rng);
  Eigen::MatrixXd Xs(X.rows(), 2);
  for (int i = 0; i < X.rows(); ++i) Xs.row(i) = X.row(perm[i]);
  CpdOptions o;
  o.method = CpdMethod::kNonrigid;
  o.w = 0.0;
  const CpdResult r = cpd_register(Xs, Y, o);
  EXPECT_NE(r.status, CpdStatus::kMaxIterations) << to_string(r.status);
  const double warp_rms = (X - Y).norm() / std::sqrt(Y.rows());
  const double err_rms = (r.transformed - X).norm() / std::sqrt(Y.rows());
  EXPECT_GT(warp_rms, 0.05);
  EXPECT_LT(err_rms, 1e-5) << "warp rms " << warp_rms << " error rms " << err_rms;
  const Eigen::MatrixXd Z = random_points(200, 2, 77, -0.8, 0.8);
  const double new_err = (r.transform.apply(Z) - smooth_warp(Z)).norm() / std::sqrt(Z.rows());
  EXPECT_LT(new_err, 1e-5) << new_err;
  for (int i = 0; i < 10; ++i) {
    const Eigen::Vector2d z = Z.row(i).transpose();
    const Eigen::MatrixXd J = r.transform.jacobian(z);
    EXPECT_LT((J - smooth_warp_jacobian(z(0), z(1))).norm(), 1e-4);
  }
}

// The Jacobian is the exact derivative of apply(). The kernel weights are large and cancel
// (|w_k| ~ 1e4: G is ill-conditioned, as in every CPD implementation), so the central
// difference's rounding error is ~eps sum|w_k| / h: with h = 1e-3 that is ~1e-8 (measured
// 3e-8..6e-8), and its truncation error h^2 |T'''| / 6 <~ 1e-7 for this smooth warp (beta = 2
// in normalised units). 1e-6 bounds both; a wrong Jacobian term would be O(0.1).
TEST(CpdNonrigid, JacobianMatchesFiniteDifferences) {
  for (int D : {2, 3}) {
    const Eigen::MatrixXd Y = random_points(120, D, 41 + D);
    Eigen::MatrixXd X = Y;
    X.col(0) += 0.1 * Y.col(1).array().sin().matrix();
    X.col(1) += 0.1 * Y.col(0).array().square().matrix();
    for (CpdKernel k : {CpdKernel::kFull, CpdKernel::kLowRank}) {
      CpdOptions o;
      o.method = CpdMethod::kNonrigid;
      o.kernel = k;
      o.prealign = CpdPrealign::kMoments;
      o.max_iterations = 30;
      const CpdResult r = cpd_register(X * 2.0, Y, o);  // also a scale change
      const double h = 1e-3;
      for (int i = 0; i < 5; ++i) {
        const Eigen::VectorXd y = Y.row(i).transpose() * 0.9;
        const Eigen::MatrixXd J = r.transform.jacobian(y);
        Eigen::MatrixXd Jfd(D, D);
        for (int d = 0; d < D; ++d) {
          Eigen::VectorXd e = Eigen::VectorXd::Zero(D);
          e(d) = h;
          Jfd.col(d) = (r.transform.apply((y + e).transpose()) - r.transform.apply((y - e).transpose()))
                           .transpose() / (2 * h);
        }
        EXPECT_LT((J - Jfd).norm(), 1e-6) << "D=" << D;
      }
    }
  }
}

// 30 % outliers (uniform over a box 1.5x the set) with w = 0.3: inlier posteriors dominate as
// sigma shrinks and the outliers' weight vanishes, so the similarity is recovered to 1e-6
// (same reasoning as the exact case; an outlier within ~sigma of an inlier is the only
// perturbation, and its weight decays like exp(-d^2 / 2 sigma^2)).
TEST(CpdOutliers, ThirtyPercentRigidAndNonrigid) {
  const Eigen::MatrixXd Y = random_points(200, 2, 51);
  const Eigen::MatrixXd R = rotation(2, 0.35);
  const Eigen::VectorXd t = Eigen::Vector2d(0.3, -0.2);
  const Eigen::MatrixXd Xin = apply_similarity(Y, 1.3, R, t);
  Eigen::MatrixXd X(260, 2);
  X.topRows(200) = Xin;
  X.bottomRows(60) = random_points(60, 2, 52, -2.0, 2.0);
  CpdOptions o;
  o.w = 0.3;
  const CpdResult r = cpd_register(X, Y, o);
  EXPECT_LT(rel(r.rotation, R), 1e-6);
  EXPECT_NEAR(r.scale, 1.3, 1.3e-6);
  EXPECT_LT(rel(r.translation, t), 1e-6);

  // Non-rigid with the smooth warp and 30 % outliers. Measured: w = 0.1 and 0.3 stall in a local
  // optimum (s^2 ~ 0.04, error ~0.09: the free centroids absorb outliers); w = 0.5 reaches the
  // sigma floor with RMS error 1.6e-6 (set size ~1). Tolerance 1e-4: outliers within a few sigma
  // of an inlier are the only remaining perturbation.
  const Eigen::MatrixXd Xw = smooth_warp(Y);
  Eigen::MatrixXd Xo(260, 2);
  Xo.topRows(200) = Xw;
  Xo.bottomRows(60) = random_points(60, 2, 53, -1.5, 1.5);
  o.method = CpdMethod::kNonrigid;
  o.prealign = CpdPrealign::kRigid;  // the outliers shift X's normalisation: rigid first
  o.w = 0.5;
  const CpdResult rn = cpd_register(Xo, Y, o);
  const double err_rms = (rn.transformed - Xw).norm() / std::sqrt(Y.rows());
  EXPECT_LT(err_rms, 1e-4) << err_rms;
}

// Low-rank kernel (pivoted Cholesky, every entry of G - L L^T <= 1e-10) against the dense
// kernel on the same problem. The kernel perturbation enters the M-step linearly (W changes by ~ |G - G~| |W| / (lambda s^2)) so the
// transformed points agree to ~1e-6 of the set size: tolerance 1e-5 relative.
TEST(CpdNonrigid, LowRankMatchesFullKernel) {
  const Eigen::MatrixXd Y = random_points(300, 2, 61);
  const Eigen::MatrixXd X = smooth_warp(Y);
  CpdOptions o;
  o.method = CpdMethod::kNonrigid;
  o.kernel = CpdKernel::kFull;
  const CpdResult full = cpd_register(X, Y, o);
  o.kernel = CpdKernel::kLowRank;
  o.low_rank_tolerance = 1e-10;
  const CpdResult low = cpd_register(X, Y, o);
  EXPECT_LT(low.kernel_rank, 300);
  EXPECT_LE(low.kernel_error_bound, 1e-10);
  EXPECT_LT(rel(low.transformed, full.transformed), 1e-5)
      << "rank " << low.kernel_rank << " rel " << rel(low.transformed, full.transformed);
  const Eigen::MatrixXd Z = random_points(50, 2, 62, -0.9, 0.9);
  EXPECT_LT(rel(low.transform.apply(Z), full.transform.apply(Z)), 1e-5);
}

// Truncated vs full E-step. With truncation_sigmas = 8 every skipped kernel value is below
// exp(-32) = 1.3e-14, so the runs agree to rounding-level (1e-9 relative allows for the
// amplification through ~100 EM iterations). With the default 5 sigmas (skipped < 3.7e-6)
// they agree to 1e-4 (measured 4.8e-6 rigid, 4.3e-7 non-rigid).
TEST(CpdEStep, TruncatedMatchesFull) {
  const Eigen::MatrixXd Y = random_points(300, 2, 71);
  const Eigen::MatrixXd X = smooth_warp(apply_similarity(Y, 1.1, rotation(2, 0.2), Eigen::Vector2d(0.1, 0.0)));
  for (CpdMethod m : {CpdMethod::kRigid, CpdMethod::kNonrigid}) {
    CpdOptions o;
    o.method = m;
    o.estep = CpdEStep::kFull;
    const CpdResult full = cpd_register(X, Y, o);
    EXPECT_FALSE(full.truncated_estep);
    o.estep = CpdEStep::kTruncated;
    o.truncation_sigmas = 8.0;
    o.bins_per_sigma = 0.0;  // exact truncated sums only
    const CpdResult tr8 = cpd_register(X, Y, o);
    EXPECT_EQ(tr8.binned_estep_iterations, 0);
    EXPECT_TRUE(tr8.truncated_estep);
    EXPECT_LT(rel(tr8.transformed, full.transformed), 1e-9);
    o.truncation_sigmas = 5.0;
    const CpdResult tr5 = cpd_register(X, Y, o);
    EXPECT_LT(rel(tr5.transformed, full.transformed), 1e-4);
    // Binned large-sigma iterations (default 4 cells per sigma): the early E-steps are
    // approximate (~0.5 % kernel error) but the final ones are exact, so the EM ends at the
    // same fixed point to within the convergence tolerance's effect: 1e-4 relative.
    o.bins_per_sigma = 4.0;
    const CpdResult bin = cpd_register(X, Y, o);
    EXPECT_GT(bin.binned_estep_iterations, 0);
    EXPECT_LT(rel(bin.transformed, full.transformed), 1e-4);
  }
}

// Same run twice is bit-identical, and independent of the OpenMP thread count (fixed chunks).
TEST(CpdDeterminism, BitIdenticalRerunsAndThreadCounts) {
  const Eigen::MatrixXd Y = random_points(1500, 2, 81);
  const Eigen::MatrixXd X = smooth_warp(Y);
  CpdOptions o;
  o.method = CpdMethod::kNonrigid;
  o.max_iterations = 20;
  o.estep = CpdEStep::kTruncated;
  const CpdResult a = cpd_register(X, Y, o);
  const CpdResult b = cpd_register(X, Y, o);
  EXPECT_TRUE(a.truncated_estep);
  EXPECT_LT(a.kernel_rank, 1500);  // the low-rank path ran
  EXPECT_EQ(a.transformed, b.transformed);
  EXPECT_EQ(a.sigma2, b.sigma2);
  EXPECT_EQ(a.negative_log_likelihood, b.negative_log_likelihood);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const CpdResult c = cpd_register(X, Y, o);
  omp_set_num_threads(threads);
  EXPECT_EQ(a.transformed, c.transformed);
}

TEST(CpdStatusReport, MaxIterationsIsReported) {
  const Eigen::MatrixXd Y = random_points(100, 2, 91);
  const Eigen::MatrixXd X = smooth_warp(Y);
  CpdOptions o;
  o.method = CpdMethod::kNonrigid;
  o.max_iterations = 2;
  const CpdResult r = cpd_register(X, Y, o);
  EXPECT_EQ(r.status, CpdStatus::kMaxIterations);
  EXPECT_EQ(r.iterations, 2);
  EXPECT_GT(r.relative_change, o.tolerance);
}

TEST(CpdInput, BadInputThrows) {
  const Eigen::MatrixXd Y = random_points(10, 2, 1);
  EXPECT_THROW(cpd_register(Eigen::MatrixXd(0, 2), Y), common::InputError);
  EXPECT_THROW(cpd_register(random_points(10, 3, 2), Y), common::InputError);
  EXPECT_THROW(cpd_register(random_points(10, 4, 2), random_points(10, 4, 3)), common::InputError);
  Eigen::MatrixXd bad = Y;
  bad(4, 1) = std::nan("");
  EXPECT_THROW(cpd_register(bad, Y), common::InputError);
  CpdOptions o;
  o.w = 1.0;
  EXPECT_THROW(cpd_register(Y, Y, o), common::InputError);
  o = {};
  o.beta = 0.0;
  EXPECT_THROW(cpd_register(Y, Y, o), common::InputError);
  EXPECT_THROW(cpd_register(Eigen::MatrixXd::Ones(5, 2), Y), common::InputError);  // zero spread
  EXPECT_THROW(CpdResult{}.transform.apply(Y), common::InputError);
}

}  // namespace
}  // namespace arthrosim::pipelines
