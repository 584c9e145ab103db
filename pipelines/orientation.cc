#include "pipelines/orientation.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>
#include <string>

#include "common/error.h"

namespace arthrosim::pipelines {
namespace {

void canonical_sign(Eigen::Ref<Eigen::VectorXd> v) {
  Eigen::Index k = 0;
  for (Eigen::Index i = 1; i < v.size(); ++i)
    if (std::abs(v(i)) > std::abs(v(k))) k = i;
  if (v(k) < 0.0) v = -v;
}

std::string shape(const Eigen::MatrixXd& m) {
  return std::to_string(m.rows()) + " x " + std::to_string(m.cols());
}

// Symmetric eigenproblem, eigenvalues decreasing, canonical signs. For 2x2 the closed form
// (see header); for 3x3 Eigen's iterative solver (more accurate than the cubic formula when
// eigenvalues nearly coincide).
void sym_eig_desc(const Eigen::MatrixXd& A, Eigen::VectorXd& values, Eigen::MatrixXd& vectors) {
  const Eigen::Index D = A.rows();
  values.resize(D);
  vectors.resize(D, D);
  if (D == 2) {
    const double a = A(0, 0), b = A(1, 0), c = A(1, 1);
    const double mean = 0.5 * (a + c);
    const double radius = std::hypot(0.5 * (a - c), b);
    values << mean + radius, mean - radius;
    const double theta = 0.5 * std::atan2(2.0 * b, a - c);
    vectors << std::cos(theta), -std::sin(theta), std::sin(theta), std::cos(theta);
  } else {
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(A);  // ascending order
    for (Eigen::Index i = 0; i < D; ++i) {
      values(i) = es.eigenvalues()(D - 1 - i);
      vectors.col(i) = es.eigenvectors().col(D - 1 - i);
    }
  }
  for (Eigen::Index i = 0; i < D; ++i) canonical_sign(vectors.col(i));
}

}  // namespace

PrincipalStrains principal_strains(const Eigen::MatrixXd& E, double degeneracy_tolerance) {
  if (E.rows() != E.cols() || (E.rows() != 2 && E.rows() != 3))
    throw common::InputError("principal_strains: expected a 2x2 or 3x3 strain tensor, found " + shape(E));
  if (!E.allFinite()) throw common::InputError("principal_strains: strain tensor has NaN/Inf entries");
  Eigen::MatrixXd S = E.triangularView<Eigen::Lower>();
  S.triangularView<Eigen::StrictlyUpper>() = S.transpose().triangularView<Eigen::StrictlyUpper>();
  PrincipalStrains out;
  sym_eig_desc(S, out.values, out.directions);
  const double scale = std::max(out.values.cwiseAbs().maxCoeff(), std::numeric_limits<double>::min());
  out.degenerate = (out.values(0) - out.values(1)) <= degeneracy_tolerance * scale;
  return out;
}

AxialAverage average_axial(const Eigen::VectorXd& e1, const Eigen::MatrixXd& d) {
  const Eigen::Index n = e1.size(), D = d.cols();
  if (D != 2 && D != 3)
    throw common::InputError("average_axial: expected directions with 2 or 3 columns, found " + shape(d));
  if (d.rows() != n)
    throw common::InputError("average_axial: expected " + std::to_string(n) + " direction rows (one per e1 value), found " +
                     std::to_string(d.rows()));
  if (!e1.allFinite() || !d.allFinite()) throw common::InputError("average_axial: NaN/Inf in e1 or directions");
  AxialAverage out;
  out.direction = Eigen::VectorXd::Zero(D);
  if (n == 0) return out;
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(D, D);
  double wsum = 0.0, ssum = 0.0;
  for (Eigen::Index t = 0; t < n; ++t) {
    const double len = d.row(t).norm();
    if (!(len > 0.0))
      throw common::InputError("average_axial: direction of frame " + std::to_string(t) + " has zero length");
    const Eigen::VectorXd u = d.row(t).transpose() / len;
    const double w = std::abs(e1(t));
    T.noalias() += w * u * u.transpose();
    wsum += w;
    ssum += e1(t);
  }
  out.mean_magnitude = wsum / static_cast<double>(n);
  out.mean_signed = ssum / static_cast<double>(n);
  if (!(wsum > 0.0)) return out;
  T /= wsum;
  Eigen::VectorXd values;
  Eigen::MatrixXd vectors;
  sym_eig_desc(T, values, vectors);
  out.direction = vectors.col(0);
  out.l1 = values(0);
  out.l2 = values(1);
  const double denom = out.l1 + out.l2;
  // Clamp: the eigenvalues of a PSD tensor can come out as -1e-17.
  out.coherence = denom > 0.0 ? std::clamp((out.l1 - out.l2) / denom, 0.0, 1.0) : 0.0;
  out.defined = true;
  return out;
}

std::vector<AxialAverage> average_axial_field(const Eigen::MatrixXd& e1,
                                              const std::vector<Eigen::MatrixXd>& directions) {
  const Eigen::Index N = e1.rows(), F = e1.cols();
  if (static_cast<Eigen::Index>(directions.size()) != F)
    throw common::InputError("average_axial_field: expected " + std::to_string(F) +
                     " direction frames (columns of e1), found " + std::to_string(directions.size()));
  Eigen::Index D = F > 0 ? directions[0].cols() : 2;
  for (Eigen::Index t = 0; t < F; ++t) {
    if (directions[t].rows() != N || directions[t].cols() != D)
      throw common::InputError("average_axial_field: frame " + std::to_string(t) + ": expected " + std::to_string(N) +
                       " x " + std::to_string(D) + " directions, found " + shape(directions[t]));
  }
  std::vector<AxialAverage> out(static_cast<size_t>(N));
  Eigen::MatrixXd d(F, D);
  for (Eigen::Index i = 0; i < N; ++i) {
    for (Eigen::Index t = 0; t < F; ++t) d.row(t) = directions[t].row(i);
    out[static_cast<size_t>(i)] = average_axial(e1.row(i).transpose(), d);
  }
  return out;
}

double acute_line_angle(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  if (a.size() != b.size() || (a.size() != 2 && a.size() != 3))
    throw common::InputError("acute_line_angle: expected two vectors of size 2 or 3, found sizes " +
                     std::to_string(a.size()) + " and " + std::to_string(b.size()));
  if (!(a.norm() > 0.0) || !(b.norm() > 0.0) || !a.allFinite() || !b.allFinite())
    throw common::InputError("acute_line_angle: expected finite non-zero vectors");
  double cross;
  if (a.size() == 2) {
    cross = std::abs(a(0) * b(1) - a(1) * b(0));
  } else {
    cross = Eigen::Vector3d(a).cross(Eigen::Vector3d(b)).norm();
  }
  return std::atan2(cross, std::abs(a.dot(b)));
}

double acute_line_angle_2d(double theta_a_rad, double theta_b_rad) {
  if (!std::isfinite(theta_a_rad) || !std::isfinite(theta_b_rad))
    throw common::InputError("acute_line_angle_2d: expected finite angles");
  // Lines have period pi: reduce the difference to [0, pi), then fold to [0, pi/2].
  double delta = std::fmod(theta_a_rad - theta_b_rad, std::numbers::pi);
  if (delta < 0.0) delta += std::numbers::pi;
  return std::min(delta, std::numbers::pi - delta);
}

}  // namespace arthrosim::pipelines
