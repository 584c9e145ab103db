#pragma once
// Axial direction statistics and principal strains.
//
// A principal strain direction d is axial: d and -d describe the same line, so
// directions must never be averaged as vectors (a field with random sign flips
// would average to zero). Instead we average the orientation tensor
//
//   T = sum_t |e1_t| d_t d_t^T / sum_t |e1_t|          (D x D, symmetric PSD, trace 1)
//
// whose principal eigenvector is the mean line, and whose eigenvalue spread is a
// confidence: coherence = (l1 - l2) / (l1 + l2), 1 for a constant line, 0 for
// lines spread evenly over all in-plane directions (issue 7; the same tensor is
// the "orientation tensor" of fibre statistics, Advani & Tucker 1987).
//
// In 3D the directions live in the local surface tangent plane, so T has rank
// <= 2 and its smallest eigenvalue l3 is ~0 (exactly 0 for exactly tangent
// inputs). The coherence therefore uses the two largest eigenvalues, which is
// the in-plane 2D coherence; including l3 would only measure how far the inputs
// leave the tangent plane.
//
// Angles are in radians (SI); the acute angle between two lines is in [0, pi/2].
#include <Eigen/Core>

#include <vector>

namespace arthrosim::pipelines {

/// Eigen-decomposition of a symmetric 2x2 or 3x3 strain tensor.
struct PrincipalStrains {
  /// Eigenvalues in decreasing algebraic order (e(0) = e1 = first principal strain,
  /// the maximum; e(1) = e2). Size D.
  Eigen::VectorXd values;
  /// Unit eigenvectors as columns, same order as `values`. Each column has a
  /// canonical sign: its largest-magnitude component is positive (ties -> lowest index).
  Eigen::MatrixXd directions;
  /// True when |e1 - e2| <= degeneracy_tolerance * max(|e_i|, tiny): the first
  /// direction is then not defined by the tensor. The returned direction is still
  /// deterministic (2D: the x axis; 3D: what the deterministic QR-based
  /// eigensolver returns within the eigenspace) but callers should mask it.
  bool degenerate = false;
};

/// Principal strains of a symmetric 2x2 or 3x3 tensor E (only the lower triangle
/// is read). 2D uses the closed form e = (a+c)/2 +- sqrt(((a-c)/2)^2 + b^2) and
/// theta = atan2(2b, a - c) / 2, which is continuous and deterministic even for
/// equal eigenvalues (atan2(0, 0) = 0 -> x axis). 3D uses Eigen's
/// SelfAdjointEigenSolver (Householder tridiagonalisation + implicit QR).
/// Throws InputError for a non-square, wrong-size or non-finite tensor.
PrincipalStrains principal_strains(const Eigen::MatrixXd& E, double degeneracy_tolerance = 1e-9);

/// Time average of the axial directions at ONE point.
struct AxialAverage {
  Eigen::VectorXd direction;  ///< unit principal eigenvector of T (canonical sign); size D
  double coherence = 0.0;     ///< (l1 - l2)/(l1 + l2) in [0, 1]; 0 when undefined
  double mean_magnitude = 0.0;  ///< sum_t |e1_t| / n (same unit as e1)
  double mean_signed = 0.0;     ///< sum_t e1_t / n
  double l1 = 0.0, l2 = 0.0;    ///< the two largest eigenvalues of T
  bool defined = false;  ///< false when sum_t |e1_t| == 0 (no direction information)
};

/// Average over frames at one point: magnitudes e1 (size n), directions d (n x D,
/// rows need not be unit: they are normalised; a zero row throws). D = 2 or 3.
AxialAverage average_axial(const Eigen::VectorXd& e1, const Eigen::MatrixXd& d);

/// Field version: e1 is N x n (point x frame); directions[t] is N x D for frame t.
/// Returns one AxialAverage per point. Throws InputError on size mismatch.
std::vector<AxialAverage> average_axial_field(const Eigen::MatrixXd& e1,
                                              const std::vector<Eigen::MatrixXd>& directions);

/// Acute angle between the lines spanned by a and b (any length > 0, D = 2 or 3), in
/// [0, pi/2] rad, computed as atan2(|a x b|, |a . b|) (accurate near 0 and pi/2).
double acute_line_angle(const Eigen::VectorXd& a, const Eigen::VectorXd& b);

/// 2D version on line angles (radians, any range; axial so theta ~ theta + pi):
/// the acute angle between the lines, in [0, pi/2].
double acute_line_angle_2d(double theta_a_rad, double theta_b_rad);

}  // namespace arthrosim::pipelines
