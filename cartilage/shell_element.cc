// 4-node ANCF continuum shell with ANS/EAS; see shell_element.h and
// docs/shell_element.md for the equations.
#include "cartilage/shell_element.h"

#include <Eigen/Dense>
#include <cmath>
#include <sstream>

#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

using Vector8 = Eigen::Matrix<double, 8, 1>;
using Matrix8 = Eigen::Matrix<double, 8, 8>;
using Vector6 = Eigen::Matrix<double, 6, 1>;
using Row24 = Eigen::Matrix<double, 1, 24>;
/// Strain gradients, one strain component per row (rows contiguous: the
/// tangent kernels below combine whole rows).
using StrainGradient = Eigen::Matrix<double, 6, 24, Eigen::RowMajor>;

constexpr double kNodeXi[4] = {-1, 1, 1, -1};
constexpr double kNodeEta[4] = {-1, -1, 1, 1};
// Natural strain components d = (i, j): 11, 22, 33, 12, 13, 23.
constexpr int kPairI[6] = {0, 1, 2, 0, 0, 1};
constexpr int kPairJ[6] = {0, 1, 2, 1, 2, 2};

/// Bilinear shape functions and their in-plane derivatives at (xi, eta).
void bilinear(double xi, double eta, double N[4], double Nxi[4], double Neta[4]) {
  for (int k = 0; k < 4; ++k) {
    const double a = kNodeXi[k], b = kNodeEta[k];
    N[k] = 0.25 * (1 + a * xi) * (1 + b * eta);
    Nxi[k] = 0.25 * a * (1 + b * eta);
    Neta[k] = 0.25 * b * (1 + a * xi);
  }
}

/// Derivatives of the 8 slot functions phi_s (s = 2k: N_k for r_k,
/// s = 2k+1: N_k zeta h_k/2 for d_k) w.r.t. xi, eta, zeta (columns).
Eigen::Matrix<double, 8, 3> slot_derivatives(double xi, double eta, double zeta,
                                             const std::array<double, 4>& h, Vector8* phi = nullptr) {
  double N[4], Nxi[4], Neta[4];
  bilinear(xi, eta, N, Nxi, Neta);
  Eigen::Matrix<double, 8, 3> P;
  for (int k = 0; k < 4; ++k) {
    const double c = 0.5 * h[k];
    P.row(2 * k) << Nxi[k], Neta[k], 0.0;
    P.row(2 * k + 1) << Nxi[k] * zeta * c, Neta[k] * zeta * c, N[k] * c;
    if (phi) {
      (*phi)(2 * k) = N[k];
      (*phi)(2 * k + 1) = N[k] * zeta * c;
    }
  }
  return P;
}

/// d E_ij / d q for E_ij = (g_i.g_j - G_i.G_j)/2: slot s block is
/// (phi_{s,i} g_j + phi_{s,j} g_i)/2.
Row24 strain_gradient(const Vector8& pi, const Vector8& pj, const Eigen::Vector3d& gi,
                      const Eigen::Vector3d& gj) {
  Row24 B;
  for (int s = 0; s < 8; ++s) B.segment<3>(3 * s) = 0.5 * (pi(s) * gj + pj(s) * gi).transpose();
  return B;
}

/// Symmetrised outer product (a b^T + b a^T)/2: the second derivative of
/// E_ij w.r.t. slots (times I3).
Matrix8 sym_outer(const Vector8& a, const Vector8& b) {
  return 0.5 * (a * b.transpose() + b * a.transpose());
}

/// K(l, m) = a_l . a_m - b_l . b_m for the 24 rows [a_l b_l] (a: NA
/// values, b: NB) of a row-major array with the given row stride: dot
/// products of contiguous rows with sizes known at compile time.
template <int NA, int NB>
void gram_minus(const double* rows, Eigen::Index stride, Matrix24& K) {
  using RowA = Eigen::Map<const Eigen::Matrix<double, 1, NA>>;
  using RowB = Eigen::Map<const Eigen::Matrix<double, 1, NB>>;
  for (int m = 0; m < 24; ++m) {
    const RowA am(rows + m * stride);
    const RowB bm(rows + m * stride + NA);
    for (int l = m; l < 24; ++l) {
      const double k = RowA(rows + l * stride).dot(am) - RowB(rows + l * stride + NA).dot(bm);
      K(l, m) = k;
      K(m, l) = k;
    }
  }
}

void gauss_rule(int n, std::vector<double>& x, std::vector<double>& w) {
  if (n == 2) {
    const double a = 1.0 / std::sqrt(3.0);
    x = {-a, a};
    w = {1.0, 1.0};
  } else if (n == 3) {
    const double a = std::sqrt(0.6);
    x = {-a, 0.0, a};
    w = {5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};
  } else {
    throw common::InputError("ShellMaterial::thickness_points must be 2 or 3, found " +
                             std::to_string(n));
  }
}

/// ANS sample data on one zeta level (the samples are taken at the same zeta
/// as the quadrature point, so the through-thickness variation is kept).
struct Level {
  // E13 at A = (0,-1) and B = (0,+1); E23 at C = (-1,0) and D = (+1,0).
  double E13[2], E23[2];
  Row24 dE13[2], dE23[2];
  Vector8 p13a[2], p13b[2], p23a[2], p23b[2];  // phi_{,i}, phi_{,j} at the samples
};

/// Transverse normal E33 at the four corners (independent of zeta since
/// g_3 = sum N_k h_k/2 d_k): E33_k = (h_k/2)^2 (d_k.d_k - D_k.D_k)/2.
struct Corners {
  double E33[4];
  Row24 dE33[4];
};

Level sample_level(const Eigen::Matrix<double, 3, 8>& Qt, const Eigen::Matrix<double, 3, 8>& Q0t,
                   const std::array<double, 4>& h, double zeta) {
  Level L;
  const double pts13[2][2] = {{0.0, -1.0}, {0.0, 1.0}};
  const double pts23[2][2] = {{-1.0, 0.0}, {1.0, 0.0}};
  for (int s = 0; s < 2; ++s) {
    {
      const auto P = slot_derivatives(pts13[s][0], pts13[s][1], zeta, h);
      const Vector8 p1 = P.col(0), p3 = P.col(2);
      const Eigen::Vector3d g1 = Qt * p1, g3 = Qt * p3, G1 = Q0t * p1, G3 = Q0t * p3;
      L.E13[s] = 0.5 * (g1.dot(g3) - G1.dot(G3));
      L.dE13[s] = strain_gradient(p1, p3, g1, g3);
      L.p13a[s] = p1;
      L.p13b[s] = p3;
    }
    {
      const auto P = slot_derivatives(pts23[s][0], pts23[s][1], zeta, h);
      const Vector8 p2 = P.col(1), p3 = P.col(2);
      const Eigen::Vector3d g2 = Qt * p2, g3 = Qt * p3, G2 = Q0t * p2, G3 = Q0t * p3;
      L.E23[s] = 0.5 * (g2.dot(g3) - G2.dot(G3));
      L.dE23[s] = strain_gradient(p2, p3, g2, g3);
      L.p23a[s] = p2;
      L.p23b[s] = p3;
    }
  }
  return L;
}

Corners sample_corners(const Eigen::Matrix<double, 3, 8>& Qt, const Eigen::Matrix<double, 3, 8>& Q0t,
                       const std::array<double, 4>& h) {
  Corners C;
  for (int k = 0; k < 4; ++k) {
    const double c2 = 0.25 * h[k] * h[k];
    const Eigen::Vector3d d = Qt.col(2 * k + 1), D = Q0t.col(2 * k + 1);
    C.E33[k] = 0.5 * c2 * (d.squaredNorm() - D.squaredNorm());
    C.dE33[k].setZero();
    C.dE33[k].segment<3>(3 * (2 * k + 1)) = c2 * d.transpose();
  }
  return C;
}

/// Natural strains (compatible 11, 22, 12; ANS 13, 23, 33) and their
/// gradients at (xi, eta) on a level.
void point_strain(const Eigen::Matrix<double, 3, 8>& Qt, const Eigen::Matrix<double, 3, 8>& Q0t,
                  const std::array<double, 4>& h, const Level& L, const Corners& C, double xi,
                  double eta, double zeta, Vector6& eps, StrainGradient& B,
                  Vector8& p1, Vector8& p2) {
  const auto P = slot_derivatives(xi, eta, zeta, h);
  p1 = P.col(0);
  p2 = P.col(1);
  const Eigen::Vector3d g1 = Qt * p1, g2 = Qt * p2, G1 = Q0t * p1, G2 = Q0t * p2;
  eps(0) = 0.5 * (g1.squaredNorm() - G1.squaredNorm());
  eps(1) = 0.5 * (g2.squaredNorm() - G2.squaredNorm());
  eps(3) = 0.5 * (g1.dot(g2) - G1.dot(G2));
  B.row(0) = strain_gradient(p1, p1, g1, g1);
  B.row(1) = strain_gradient(p2, p2, g2, g2);
  B.row(3) = strain_gradient(p1, p2, g1, g2);
  // Transverse shear E13: linear in eta between the edge midpoints (0,-1), (0,1).
  const double a0 = 0.5 * (1 - eta), a1 = 0.5 * (1 + eta);
  eps(4) = a0 * L.E13[0] + a1 * L.E13[1];
  B.row(4) = a0 * L.dE13[0] + a1 * L.dE13[1];
  // Transverse shear E23: linear in xi between (-1,0), (1,0).
  const double b0 = 0.5 * (1 - xi), b1 = 0.5 * (1 + xi);
  eps(5) = b0 * L.E23[0] + b1 * L.E23[1];
  B.row(5) = b0 * L.dE23[0] + b1 * L.dE23[1];
  // Thickness strain E33: bilinear from the corner k = node k (same numbering).
  double N[4], Nxi[4], Neta[4];
  bilinear(xi, eta, N, Nxi, Neta);
  eps(2) = 0;
  B.row(2).setZero();
  for (int k = 0; k < 4; ++k) {
    eps(2) += N[k] * C.E33[k];
    B.row(2) += N[k] * C.dE33[k];
  }
}

}  // namespace

ShellElement::ShellElement(const std::array<Eigen::Vector3d, 4>& X,
                           const std::array<Eigen::Vector3d, 4>& D, const std::array<double, 4>& h,
                           const ShellMaterial& material, const std::string& label)
    : h_(h) {
  const double E = material.youngs_modulus_Pa, nu = material.poisson_ratio;
  if (!(E > 0) || !(nu > -1 && nu < 0.5) || !(material.density_kg_m3 >= 0))
    throw common::InputError(label + ": material must have E > 0, -1 < nu < 0.5, rho >= 0; found E=" +
                             std::to_string(E) + " nu=" + std::to_string(nu) +
                             " rho=" + std::to_string(material.density_kg_m3));
  for (int k = 0; k < 4; ++k) {
    if (!(h[k] > 0) || !std::isfinite(h[k]))
      throw common::InputError(label + ": nodal thickness must be > 0, found " + std::to_string(h[k]));
    if (!X[k].allFinite() || !D[k].allFinite() || D[k].norm() < 1e-12)
      throw common::InputError(label + ": nodal position/director must be finite and the director non-zero");
    Q0t_.col(2 * k) = X[k];
    Q0t_.col(2 * k + 1) = D[k];
  }
  q0_ = Eigen::Map<const Vector24>(Q0t_.data());
  lambda_ = E * nu / ((1 + nu) * (1 - 2 * nu));
  mu_ = E / (2 * (1 + nu));
  D_.setZero();
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) D_(a, b) = lambda_;
    D_(a, a) = lambda_ + 2 * mu_;
    D_(3 + a, 3 + a) = 4 * mu_;
  }
  gauss_rule(material.thickness_points, zeta_points_, zeta_weights_);

  // In-plane axis shared by all local frames of the element: the reference
  // xi-direction at the centre (projected on each point's tangent plane).
  {
    double N[4], Nxi[4], Neta[4];
    bilinear(0, 0, N, Nxi, Neta);
    e1_center_.setZero();
    for (int k = 0; k < 4; ++k) e1_center_ += Nxi[k] * X[k];
    if (e1_center_.norm() <= 0) throw common::InputError(label + ": degenerate element (zero xi-edge)");
  }
  Eigen::Matrix3d frame0;
  local_map(0, 0, 0, T0_, frame0, detJ0_);
  if (!(detJ0_ > 0))
    throw common::InputError(label + ": reference Jacobian at the centre is " + std::to_string(detJ0_) +
                             " (expected > 0: nodes counter-clockwise about the directors)");

  const double g = 1.0 / std::sqrt(3.0);
  const double gx[2] = {-g, g};
  Eigen::Matrix<double, kNumEas, kNumEas> H = Eigen::Matrix<double, kNumEas, kNumEas>::Zero();
  mass_.setZero();
  Matrix8 m8 = Matrix8::Zero();
  for (int l = 0; l < static_cast<int>(zeta_points_.size()); ++l) {
    for (int j = 0; j < 2; ++j) {
      for (int i = 0; i < 2; ++i) {
        QuadraturePoint p;
        p.xi = gx[i];
        p.eta = gx[j];
        p.zeta = zeta_points_[l];
        p.level = l;
        Eigen::Matrix3d frame;
        double detJ;
        local_map(p.xi, p.eta, p.zeta, p.T, frame, detJ);
        if (!(detJ > 0)) {
          std::ostringstream os;
          os << label << ": reference Jacobian " << detJ << " <= 0 at (" << p.xi << ", " << p.eta
             << ", " << p.zeta << "): distorted/inverted element or director on the wrong side";
          throw common::InputError(os.str());
        }
        p.dV = detJ * zeta_weights_[l];  // in-plane weights are 1
        p.Gamma = eas_matrix(p.xi, p.eta, p.zeta, detJ);
        H += p.Gamma.transpose() * D_ * p.Gamma * p.dV;
        p.GDT = p.Gamma.transpose() * D_ * p.T * p.dV;
        const Eigen::Matrix<double, 6, 6> Dnat = p.T.transpose() * D_ * p.T * p.dV;
        Eigen::LLT<Eigen::Matrix<double, 6, 6>> llt(0.5 * (Dnat + Dnat.transpose()));
        if (llt.info() != Eigen::Success)
          throw common::InputError(label + ": material matrix is not positive definite at a quadrature point");
        p.Wt = llt.matrixU();
        Vector8 phi;
        slot_derivatives(p.xi, p.eta, p.zeta, h_, &phi);
        m8 += material.density_kg_m3 * phi * phi.transpose() * p.dV;
        qp_.push_back(p);
      }
    }
  }
  H_inv_ = H.inverse();
  {
    Eigen::LLT<Eigen::Matrix<double, kNumEas, kNumEas>> llt(0.5 * (H_inv_ + H_inv_.transpose()));
    if (llt.info() != Eigen::Success)
      throw common::InputError(label + ": EAS matrix is not positive definite");
    H_inv_t_ = llt.matrixU();
  }
  for (int s = 0; s < 8; ++s)
    for (int t = 0; t < 8; ++t) mass_.block<3, 3>(3 * s, 3 * t) = m8(s, t) * Eigen::Matrix3d::Identity();

  // Mid-surface area and nodal shares int N_k dA (2x2 Gauss is exact for the
  // bilinear |A1 x A2| N_k of a flat element and accurate for a warped one).
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      double N[4], Nxi[4], Neta[4];
      bilinear(gx[i], gx[j], N, Nxi, Neta);
      Eigen::Vector3d A1 = Eigen::Vector3d::Zero(), A2 = Eigen::Vector3d::Zero();
      for (int k = 0; k < 4; ++k) {
        A1 += Nxi[k] * X[k];
        A2 += Neta[k] * X[k];
      }
      const double dA = A1.cross(A2).norm();
      area_ += dA;
      SurfacePoint& sp = surface_points_[2 * j + i];
      sp.dA = dA;
      for (int k = 0; k < 4; ++k) {
        nodal_area_[k] += N[k] * dA;
        sp.N[k] = N[k];
      }
    }
}

void ShellElement::slot_functions(double xi, double eta, double zeta, Eigen::Matrix<double, 8, 1>& phi,
                                  Eigen::Matrix<double, 8, 3>& dphi) const {
  dphi = slot_derivatives(xi, eta, zeta, h_, &phi);
}

void ShellElement::local_map(double xi, double eta, double zeta, Eigen::Matrix<double, 6, 6>& T,
                             Eigen::Matrix3d& frame, double& detJ) const {
  const auto P = slot_derivatives(xi, eta, zeta, h_);
  Eigen::Matrix3d J;  // columns G_1, G_2, G_3
  J = Q0t_ * P;
  detJ = J.determinant();
  // Local frame from the mid-surface tangent plane at (xi, eta).
  const auto P0 = slot_derivatives(xi, eta, 0.0, h_);
  const Eigen::Vector3d A1 = Q0t_ * P0.col(0), A2 = Q0t_ * P0.col(1);
  const Eigen::Vector3d e3 = A1.cross(A2).normalized();
  const Eigen::Vector3d e1 = (e1_center_ - e1_center_.dot(e3) * e3).normalized();
  const Eigen::Vector3d e2 = e3.cross(e1);
  frame.col(0) = e1;
  frame.col(1) = e2;
  frame.col(2) = e3;
  // C_ai = e_a . G^i (contravariant base vectors = rows of J^-1).
  const Eigen::Matrix3d C = frame.transpose() * J.inverse().transpose();
  for (int c = 0; c < 6; ++c) {
    const int a = kPairI[c], b = kPairJ[c];
    for (int d = 0; d < 6; ++d) {
      const int i = kPairI[d], j = kPairJ[d];
      T(c, d) = (i == j) ? C(a, i) * C(b, i) : C(a, i) * C(b, j) + C(a, j) * C(b, i);
    }
  }
}

Eigen::Matrix<double, 6, ShellElement::kNumEas> ShellElement::eas_matrix(double xi, double eta,
                                                                          double zeta,
                                                                          double detJ) const {
  // In-plane modes (Andelfinger & Ramm 1993 / Simo & Rifai EAS-4): natural
  // E11 = xi a1, E22 = eta a2, E12 = xi a3 + eta a4, mapped to the local frame
  // with the centre transformation T0 and scaled by detJ0/detJ so that
  // int Gamma dV = 0 (patch test: a constant stress does no work on them).
  // Thickness mode: local E33 = zeta a5, linear through the thickness, which
  // removes Poisson thickness locking in bending (compatible E33 is constant
  // in zeta). It is not scaled: for a flat element detJ does not depend on
  // zeta, so int zeta dV = 0 still holds.
  Eigen::Matrix<double, 6, kNumEas> G = Eigen::Matrix<double, 6, kNumEas>::Zero();
  const double s = detJ0_ / detJ;
  G.col(0) = s * xi * T0_.col(0);
  G.col(1) = s * eta * T0_.col(1);
  G.col(2) = s * xi * T0_.col(3);
  G.col(3) = s * eta * T0_.col(3);
  G(2, 4) = zeta;
  return G;
}

void ShellElement::internal_force(const Vector24& q, Vector24& f, Matrix24* K,
                                  Eigen::Matrix<double, 5, 1>* alpha_out) const {
  const Eigen::Map<const Eigen::Matrix<double, 3, 8>> Qt(q.data());
  const Corners C = sample_corners(Qt, Q0t_, h_);
  // Fixed-size work arrays (at most 3 zeta levels x 4 points): no heap
  // allocation per call.
  constexpr int kMaxQp = 12;
  std::array<Level, 3> levels;
  for (size_t l = 0; l < zeta_points_.size(); ++l) levels[l] = sample_level(Qt, Q0t_, h_, zeta_points_[l]);

  const int nq = static_cast<int>(qp_.size());
  // Pass 1: compatible/ANS strains in the local frame; EAS right-hand sides.
  // The material tangent sum_g B_g^T T^T D T B_g dV (B_g natural) is the
  // Gram matrix of the rows of W_g = Wt_g B_g (Wt_g^T Wt_g = T^T D T dV),
  // and the EAS correction P^T H^-1 P that of the rows of H_inv_t_ P: the
  // tangent is sum_r w_r w_r^T over 6 nq rows minus the same over 5, with
  // only its lower half computed (see docs/shell_element.md).
  Eigen::Matrix<double, 6, kMaxQp> eps_loc;
  std::array<StrainGradient, kMaxQp> Bnat;
  // Columns: the rows w_r (24 each) of all W_g, then those of H_inv_t_ P.
  Eigen::Matrix<double, 24, 6 * kMaxQp + kNumEas, Eigen::RowMajor> Wcols;
  Eigen::Matrix<double, 24, kNumEas> Pt = Eigen::Matrix<double, 24, kNumEas>::Zero();  // P^T
  std::array<Vector8, kMaxQp> p1, p2;
  Eigen::Matrix<double, kNumEas, 1> Lv = Eigen::Matrix<double, kNumEas, 1>::Zero();
  for (int g = 0; g < nq; ++g) {
    const QuadraturePoint& qp = qp_[g];
    Vector6 eps_nat;
    const StrainGradient& B = Bnat[g];
    point_strain(Qt, Q0t_, h_, levels[qp.level], C, qp.xi, qp.eta, qp.zeta, eps_nat, Bnat[g], p1[g],
                 p2[g]);
    eps_loc.col(g).noalias() = qp.T * eps_nat;
    Lv.noalias() += qp.GDT * eps_nat;
    if (!K) continue;
    for (int i = 0; i < kNumEas; ++i)
      for (int c = 0; c < 6; ++c) Pt.col(i) += qp.GDT(i, c) * B.row(c).transpose();
    for (int r = 0; r < 6; ++r) {
      auto w = Wcols.col(6 * g + r);
      w = qp.Wt(r, r) * B.row(r).transpose();
      for (int c = r + 1; c < 6; ++c) w += qp.Wt(r, c) * B.row(c).transpose();
    }
  }
  // Condensed EAS parameters: dPi/dalpha = L + H alpha = 0.
  const Eigen::Matrix<double, kNumEas, 1> alpha = -H_inv_ * Lv;
  if (alpha_out) *alpha_out = alpha;

  // Pass 2: stresses, forces, geometric stiffness.
  f.setZero();
  Matrix8 kg = Matrix8::Zero();
  // Coefficients of the ANS sample terms, summed per level (the sample
  // vectors belong to the level, not to the point).
  std::array<std::array<double, 2>, 3> c13{}, c23{};
  for (int g = 0; g < nq; ++g) {
    const QuadraturePoint& qp = qp_[g];
    const Vector6 eps = eps_loc.col(g) + qp.Gamma * alpha;
    const Vector6 Deps = D_ * eps;                    // = m o S (m = 1,1,1,2,2,2)
    const Vector6 sig = qp.T.transpose() * Deps;      // work-conjugate to natural strains
    f.noalias() += Bnat[g].transpose() * (sig * qp.dV);
    if (!K) continue;
    // sig0 p1 p1^T + sig1 p2 p2^T + sig3 (p1 p2^T + p2 p1^T)/2, as two outer products.
    const Vector8 u = qp.dV * (sig(0) * p1[g] + 0.5 * sig(3) * p2[g]);
    const Vector8 v = qp.dV * (0.5 * sig(3) * p1[g] + sig(1) * p2[g]);
    kg.noalias() += u * p1[g].transpose();
    kg.noalias() += v * p2[g].transpose();
    c13[qp.level][0] += qp.dV * sig(4) * 0.5 * (1 - qp.eta);
    c13[qp.level][1] += qp.dV * sig(4) * 0.5 * (1 + qp.eta);
    c23[qp.level][0] += qp.dV * sig(5) * 0.5 * (1 - qp.xi);
    c23[qp.level][1] += qp.dV * sig(5) * 0.5 * (1 + qp.xi);
    double N[4], Nxi[4], Neta[4];
    bilinear(qp.xi, qp.eta, N, Nxi, Neta);
    for (int k = 0; k < 4; ++k) kg(2 * k + 1, 2 * k + 1) += qp.dV * sig(2) * N[k] * 0.25 * h_[k] * h_[k];
  }
  if (K) {
    for (size_t l = 0; l < zeta_points_.size(); ++l) {
      const Level& L = levels[l];
      for (int s = 0; s < 2; ++s) {
        kg += c13[l][s] * sym_outer(L.p13a[s], L.p13b[s]);
        kg += c23[l][s] * sym_outer(L.p23a[s], L.p23b[s]);
      }
    }
    // Columns of (H_inv_t_ P)^T = P^T H_inv_t_^T.
    const int nw = 6 * nq;
    for (int i = 0; i < kNumEas; ++i) {
      auto w = Wcols.col(nw + i);
      w = H_inv_t_(i, i) * Pt.col(i);
      for (int j = i + 1; j < kNumEas; ++j) w += H_inv_t_(i, j) * Pt.col(j);
    }
    if (nq == 8)
      gram_minus<48, kNumEas>(Wcols.data(), Wcols.cols(), *K);
    else
      gram_minus<72, kNumEas>(Wcols.data(), Wcols.cols(), *K);
    for (int s = 0; s < 8; ++s)
      for (int t = 0; t < 8; ++t)
        for (int c = 0; c < 3; ++c) (*K)(3 * s + c, 3 * t + c) += kg(s, t);
  }
}

double ShellElement::strain_energy(const Vector24& q) const {
  const Eigen::Map<const Eigen::Matrix<double, 3, 8>> Qt(q.data());
  const Corners C = sample_corners(Qt, Q0t_, h_);
  std::vector<Level> levels;
  for (double z : zeta_points_) levels.push_back(sample_level(Qt, Q0t_, h_, z));
  Eigen::Matrix<double, 6, Eigen::Dynamic> eps_loc(6, qp_.size());
  Eigen::Matrix<double, kNumEas, 1> Lv = Eigen::Matrix<double, kNumEas, 1>::Zero();
  for (size_t g = 0; g < qp_.size(); ++g) {
    const QuadraturePoint& qp = qp_[g];
    Vector6 eps_nat;
    StrainGradient B;
    Vector8 a, b;
    point_strain(Qt, Q0t_, h_, levels[qp.level], C, qp.xi, qp.eta, qp.zeta, eps_nat, B, a, b);
    eps_loc.col(g) = qp.T * eps_nat;
    Lv += qp.Gamma.transpose() * D_ * eps_loc.col(g) * qp.dV;
  }
  const Eigen::Matrix<double, kNumEas, 1> alpha = -H_inv_ * Lv;
  double W = 0;
  for (size_t g = 0; g < qp_.size(); ++g) {
    const Vector6 eps = eps_loc.col(g) + qp_[g].Gamma * alpha;
    W += 0.5 * eps.dot(D_ * eps) * qp_[g].dV;
  }
  return W;
}

Eigen::Matrix<double, 6, 1> ShellElement::strain(const Vector24& q, double xi, double eta,
                                                 double zeta, Eigen::Matrix3d* frame) const {
  std::vector<Eigen::Matrix3d> frames;
  const Eigen::Matrix<double, 6, Eigen::Dynamic> s = strains(q, {xi}, {eta}, zeta, frame ? &frames : nullptr);
  if (frame) *frame = frames.front();
  return s.col(0);
}

Eigen::Matrix<double, 6, Eigen::Dynamic> ShellElement::strains(const Vector24& q, const std::vector<double>& xi,
                                                               const std::vector<double>& eta, double zeta,
                                                               std::vector<Eigen::Matrix3d>* frames) const {
  const Eigen::Map<const Eigen::Matrix<double, 3, 8>> Qt(q.data());
  Eigen::Matrix<double, 5, 1> alpha;
  Vector24 f;
  internal_force(q, f, nullptr, &alpha);
  const Corners C = sample_corners(Qt, Q0t_, h_);
  const Level L = sample_level(Qt, Q0t_, h_, zeta);
  const int n = static_cast<int>(xi.size());
  Eigen::Matrix<double, 6, Eigen::Dynamic> out(6, n);
  if (frames) frames->resize(n);
  for (int k = 0; k < n; ++k) {
    Vector6 eps_nat;
    StrainGradient B;
    Vector8 a, b;
    point_strain(Qt, Q0t_, h_, L, C, xi[k], eta[k], zeta, eps_nat, B, a, b);
    Eigen::Matrix<double, 6, 6> T;
    Eigen::Matrix3d fr;
    double detJ;
    local_map(xi[k], eta[k], zeta, T, fr, detJ);
    if (frames) (*frames)[k] = fr;
    out.col(k) = T * eps_nat + eas_matrix(xi[k], eta[k], zeta, detJ) * alpha;
  }
  return out;
}

}  // namespace arthrosim::cartilage
