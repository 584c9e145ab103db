#pragma once
// Coherent Point Drift (Myronenko & Song 2010, "Point Set Registration: Coherent Point
// Drift", IEEE TPAMI 32(12)): rigid (rotation, translation, optional scale), affine and
// non-rigid registration of a moving set Y (M x D, the GMM centroids) onto a fixed set
// X (N x D, the data), D = 2 or 3. Points are rows.
//
// EM iteration (all in normalised coordinates, see CpdOptions::normalize):
//   E-step  P_mn = exp(-|x_n - T(y_m)|^2 / 2 s^2)
//                  / (sum_k exp(-|x_n - T(y_k)|^2 / 2 s^2) + c),
//           c = (2 pi s^2)^(D/2) w/(1 - w) M/N;  only P1 = P 1, Pt1 = P^T 1 and PX = P X are
//           needed, so P itself is never stored (memory O(M + N)).
//   M-step  rigid:  weighted Procrustes, A = (X - 1 mx^T)^T P^T (Y - 1 my^T) = U S V^T,
//                   R = U diag(1, .., det(U V^T)) V^T (no reflections), s = tr(S C) / tr(Yh^T d(P1) Yh),
//                   t = mx - s R my
//           affine: B = A (Yh^T d(P1) Yh)^-1, t = mx - B my
//           non-rigid: (d(P1) G + lambda s^2 I) W = P X - d(P1) Y,  T(Y) = Y + G W,
//                   G_ij = exp(-|y_i - y_j|^2 / 2 beta^2)
//   s^2 update from the weighted residual; stop when the relative change of the negative
//   log-likelihood
//      L = -sum_n log(sum_m exp(-|x_n - T(y_m)|^2 / 2 s^2) + c) + (N D / 2) log s^2
//          (+ lambda/2 tr(W^T G W) for non-rigid)
//   falls below `tolerance` (as the authors' reference code does).
//
// Large sets (see docs/cpd.md for the error bounds):
//  * E-step: truncated Gaussian. Pairs with |x - T(y)| > r_c = truncation_sigmas * s are
//    skipped; a uniform grid over T(Y) with cell size >= r_c finds the others. Each
//    skipped kernel value is < exp(-truncation_sigmas^2 / 2) (3.7e-6 for the default 5)
//    relative to the largest possible value 1.
//  * Non-rigid: G is replaced by the Nystrom approximation G ~ L L^T from a diagonally
//    pivoted (incomplete) Cholesky factorisation, stopped when the largest residual
//    diagonal is below `low_rank_tolerance`; since G - L L^T is positive semidefinite,
//    every entry of it is bounded by that number. The M-step is then solved with the
//    Woodbury identity in O(M r^2). The resulting warp is exactly a Gaussian RBF field
//    centred at the r pivot points, so it can be evaluated at new points.
//  * Deterministic: fixed summation orders; OpenMP work is split into a fixed number of
//    chunks reduced in a fixed order, so results are bit-identical on re-run and
//    independent of the thread count.
#include <Eigen/Core>

#include <string>

namespace arthrosim::pipelines {

enum class CpdMethod { kRigid, kAffine, kNonrigid };

/// How the E-step sums over pairs.
enum class CpdEStep {
  kAuto,       ///< kFull when M * N <= full_estep_max_pairs, else kTruncated
  kFull,       ///< every pair (streamed; still never stores an M x N matrix)
  kTruncated,  ///< only pairs within truncation_sigmas * sigma (uniform grid)
};

/// How the non-rigid kernel G is represented.
enum class CpdKernel {
  kAuto,     ///< kFull when M <= full_kernel_max_points, else kLowRank
  kFull,     ///< dense M x M G, LU solve per iteration (O(M^3): small sets only)
  kLowRank,  ///< pivoted-Cholesky Nystrom G ~ L L^T + Woodbury (O(M r^2) per iteration)
};

/// Initial alignment before the EM iterations.
enum class CpdPrealign {
  kNone,     ///< start from the identity (after normalisation)
  kRigid,    ///< affine/non-rigid only: run rigid CPD (with scale) from the identity first and
             ///< start from its result (the paper's advice for a small capture range)
  kMoments,  ///< principal axes (second moments) of both normalised sets: every proper
             ///< rotation mapping Y's axes onto X's (2D: 4 candidates = PCA angle + k 90 deg,
             ///< 3D: the 4 sign choices with det = +1) is refined by rigid CPD and the
             ///< candidate with the lowest final negative log-likelihood is kept (ties: first).
             ///< For affine/non-rigid the best rigid result is applied first.
};

struct CpdOptions {
  CpdMethod method = CpdMethod::kRigid;
  /// Outlier weight w of the uniform component, in [0, 1). Reference default 0.1.
  double w = 0.1;
  /// Maximum EM iterations (>= 1). Reference default 150.
  int max_iterations = 150;
  /// Stop when |L_k - L_{k-1}| / |L_k| < tolerance (L: negative log-likelihood). Reference 1e-5.
  double tolerance = 1e-5;
  /// Also stop (status kSigmaFloor) when s^2 (normalised units) falls below this: the sets
  /// then coincide to ~1e-6 of their size and further EM steps only divide by ~0.
  double sigma2_floor = 1e-12;
  /// Initial s^2 in normalised units; <= 0 means the paper's sum|x_n - y_m|^2 / (D M N), except
  /// that an affine/non-rigid stage after a pre-alignment starts from the pre-alignment's final s^2.
  double sigma2_initial = 0.0;
  /// Normalise X and Y separately to zero mean and unit RMS radius (as the reference
  /// code does, so beta, lambda and sigma are in units of the set size), then express
  /// the result in X's units. Switching it off makes beta/lambda absolute.
  bool normalize = true;
  /// Rigid only: estimate the isotropic scale (else scale = 1 in normalised units, i.e.
  /// the data scale ratio std(X)/std(Y) when normalize is on — switch normalize off for a
  /// strictly scale-free rigid fit).
  bool estimate_scale = true;
  /// Non-rigid: Gaussian kernel width beta (normalised length units, > 0). Reference 2.
  double beta = 2.0;
  /// Non-rigid: regularisation weight lambda (> 0). Reference 3.
  double lambda = 3.0;

  CpdEStep estep = CpdEStep::kAuto;
  /// Truncation radius in units of sigma (>= 1). Skipped kernel values < exp(-k^2/2).
  double truncation_sigmas = 5.0;
  /// Truncated E-step only: while sigma is large compared with the point spacing, both sets are
  /// binned into grid cells of size sigma / bins_per_sigma and each cell acts as one weighted
  /// point at its centroid (first moments exact; kernel values off by ~var_cell / sigma^2 =
  /// 1 / (12 bins_per_sigma^2) per dimension, 0.5 % for the default 4). Used only in iterations
  /// where it cuts the pair count 4x or more (so the final, small-sigma iterations are exact);
  /// 0 disables it. Count reported in CpdResult::binned_estep_iterations.
  double bins_per_sigma = 4.0;
  /// kAuto E-step uses the full sum up to this many pairs (M * N).
  double full_estep_max_pairs = 2.5e5;

  CpdKernel kernel = CpdKernel::kAuto;
  /// kAuto kernel uses the dense G up to this many moving points.
  int full_kernel_max_points = 800;
  /// Low-rank kernel: stop the pivoted Cholesky when max residual diagonal < this
  /// (bound on every entry of G - L L^T; G_ii = 1).
  double low_rank_tolerance = 1e-8;
  /// Low-rank kernel: maximum rank r. If reached before the tolerance, the achieved bound
  /// is reported in CpdResult::kernel_error_bound (never silent).
  int low_rank_max_rank = 400;

  CpdPrealign prealign = CpdPrealign::kNone;
};

enum class CpdStatus {
  kConverged,      ///< relative change of the negative log-likelihood < tolerance
  kSigmaFloor,     ///< s^2 < sigma2_floor: the sets coincide (exact data)
  kMaxIterations,  ///< max_iterations reached without either criterion (not converged)
};

std::string to_string(CpdStatus status);

/// The registration map T: R^D -> R^D in data coordinates (Y's units in, X's units out):
///   u    = A y + b                                        (normalisation / linear part)
///   T(y) = out_scale * (u + sum_k exp(-|u - c_k|^2 / 2 beta^2) w_k) + out_offset
/// Rigid and affine maps have no kernel terms and out_scale = 1, out_offset = 0, so
/// T(y) = A y + b. Non-rigid maps are Gaussian RBF fields (centres c_k = the moving points
/// for the full kernel, the Nystrom pivots for the low-rank kernel).
struct CpdTransform {
  Eigen::MatrixXd A;         ///< D x D
  Eigen::VectorXd b;         ///< D
  Eigen::MatrixXd centres;   ///< K x D kernel centres (u coordinates); K = 0 for rigid/affine
  Eigen::MatrixXd weights;   ///< K x D kernel weights
  double beta = 1.0;         ///< kernel width (u units)
  double out_scale = 1.0;
  Eigen::VectorXd out_offset;  ///< D

  int dimension() const { return static_cast<int>(A.rows()); }
  /// Applies T to every row of Z (K_new x D). O(K_new * K). Throws InputError on wrong width.
  Eigen::MatrixXd apply(const Eigen::MatrixXd& Z) const;
  /// Jacobian dT/dy at y (D x D): out_scale (I + sum_k w_k grad_u g_k^T) A with
  /// grad_u g_k = -(u - c_k)/beta^2 g_k. Carries tangent vectors: v' = J v.
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& y) const;
};

struct CpdResult {
  CpdMethod method = CpdMethod::kRigid;
  CpdStatus status = CpdStatus::kMaxIterations;
  int iterations = 0;              ///< EM iterations of the main stage
  double sigma2 = 0.0;             ///< final s^2 in normalised units
  double sigma2_data = 0.0;        ///< final s^2 in X's units^2
  double negative_log_likelihood = 0.0;  ///< final L (normalised units)
  double relative_change = 0.0;    ///< last |dL| / |L|
  /// Rigid: T(y) = scale * rotation * y + translation (data units). Affine: T(y) =
  /// affine * y + translation. For non-rigid with prealignment these hold the rigid
  /// pre-alignment, otherwise identity / zero.
  Eigen::MatrixXd rotation;
  double scale = 1.0;
  Eigen::MatrixXd affine;
  Eigen::VectorXd translation;
  CpdTransform transform;          ///< the full map (use this to carry new points)
  Eigen::MatrixXd transformed;     ///< T(Y), M x D, equal to transform.apply(Y)
  Eigen::VectorXd match_weight;    ///< P1 of the last E-step (M): soft match count per y_m
  bool truncated_estep = false;    ///< which E-step ran
  int binned_estep_iterations = 0; ///< E-steps that used the binned approximation
  int kernel_rank = 0;             ///< non-rigid: r (low rank) or M (full)
  double kernel_error_bound = 0.0; ///< non-rigid low rank: max |G - L L^T| entry bound
  int prealign_candidate = -1;     ///< kMoments: index of the kept candidate
  int unmatched_points = 0;        ///< truncated E-step with w = 0: data points with no
                                   ///< centroid within the cutoff in the last E-step
};

/// Registers Y (moving, M x D) onto X (fixed, N x D). Throws InputError on bad input
/// (empty sets, D not 2/3 or different, NaN/Inf, option out of range) and NumericalError
/// if the iteration produces a non-finite value (naming the iteration).
CpdResult cpd_register(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, const CpdOptions& options = {});

}  // namespace arthrosim::pipelines
