#pragma once
// 4-node bilinear continuum-based ANCF shell element (Yamashita et al. 2015;
// seeds/002_3ffcc11eb7a447d9.txt, "Deformable Cartilage Model") with assumed
// natural strains (ANS) and enhanced assumed strains (EAS). Full derivation,
// sampling points and references: docs/shell_element.md.
//
// Kinematics. Each node k carries its position r_k and its transverse gradient
// d_k = r_z (6 coordinates). With natural coordinates (xi, eta, zeta) in [-1,1]^3
// and nodal thickness h_k,
//     r(xi, eta, zeta) = sum_k N_k(xi, eta) (r_k + zeta h_k/2 d_k),
// i.e. z = zeta h/2 is the physical thickness coordinate and d_k = dr/dz (the
// seed's r = S_m e_p + z S_m e_g). The reference configuration X uses the same
// map with the reference coordinates (X_k, D_k).
//
// Strain. Covariant Green-Lagrange components E_ij = (g_i.g_j - G_i.G_j)/2 with
// g_i = dr/dtheta_i; E_11, E_22, E_12 compatible; E_13, E_23 by ANS (edge
// midpoints), E_33 by ANS (corners). They are transformed to a local orthonormal
// frame (e1, e2 tangent, e3 normal to the reference mid-surface), which equals
// E = (F^T F - I)/2 with F = (dr/dtheta)(dX/dtheta)^-1 for the compatible part.
// EAS adds 5 parameters (4 in-plane, 1 thickness) condensed at element level.
//
// Material: St. Venant-Kirchhoff S = lambda tr(E) I + 2 mu E in the local frame.
// Because S(E) is linear and the enhancement is additive in E, the EAS
// parameters are the closed-form minimiser alpha(q) = -H^-1 L(q) with a constant
// H: no element-level Newton loop and no history to store or roll back.
//
// Element coordinate order (24): [r_0, d_0, r_1, d_1, r_2, d_2, r_3, d_3], each
// 3 components in the world frame; nodes counter-clockwise (common::QuadMesh).
#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

namespace arthrosim::cartilage {

using Vector24 = Eigen::Matrix<double, 24, 1>;
using Matrix24 = Eigen::Matrix<double, 24, 24>;

/// Isotropic St. Venant-Kirchhoff material and section integration.
struct ShellMaterial {
  double youngs_modulus_Pa = 400e6;  ///< E [Pa], > 0; seed 002: 400 MPa
  double poisson_ratio = 0.3;        ///< nu, in (-1, 0.5); seed 002: 0.3
  double density_kg_m3 = 1000.0;     ///< rho [kg/m^3], >= 0; seed 002: 1000
  /// Gauss points through the thickness, 2 or 3. 2 integrates the linear
  /// (small-strain) bending energy exactly (integrand quadratic in zeta);
  /// 3 adds accuracy for large membrane+bending strains (quartic terms).
  int thickness_points = 2;
};

/// Reference data of one element, computed once from the reference
/// configuration (constant; no per-iteration state).
class ShellElement {
 public:
  /// X: 4 nodal reference positions [m]; D: 4 reference transverse gradients
  /// (unit vectors on the side of the quad normal); h: 4 nodal thicknesses [m].
  /// Throws common::InputError (naming `label`) if the element is degenerate,
  /// inverted, or a director points to the other side of the mid-surface.
  ShellElement(const std::array<Eigen::Vector3d, 4>& X, const std::array<Eigen::Vector3d, 4>& D,
               const std::array<double, 4>& h, const ShellMaterial& material,
               const std::string& label = "element");

  /// Internal force f = dPi/dq (24) and, if K != nullptr, the consistent tangent
  /// K = d f / d q including the EAS condensation and the geometric stiffness.
  /// Optional: alpha_out receives the 5 condensed EAS parameters.
  void internal_force(const Vector24& q, Vector24& f, Matrix24* K,
                      Eigen::Matrix<double, 5, 1>* alpha_out = nullptr) const;

  /// Strain energy [J] at q (with condensed EAS).
  double strain_energy(const Vector24& q) const;

  /// Local Green-Lagrange strain (E11, E22, E33, E12, E13, E23; tensor
  /// components, ANS included, EAS included) at natural point (xi, eta, zeta),
  /// in the local frame returned in `frame` (columns e1, e2, e3, world).
  Eigen::Matrix<double, 6, 1> strain(const Vector24& q, double xi, double eta, double zeta,
                                     Eigen::Matrix3d* frame = nullptr) const;
  /// The same at several points of one configuration: the condensed EAS
  /// parameters (one internal-force evaluation) and the ANS samples are
  /// computed once, not per point. Column k of the result and frames[k]
  /// belong to (xi[k], eta[k], zeta); identical to strain() point by point.
  Eigen::Matrix<double, 6, Eigen::Dynamic> strains(const Vector24& q, const std::vector<double>& xi,
                                                   const std::vector<double>& eta, double zeta,
                                                   std::vector<Eigen::Matrix3d>* frames = nullptr) const;

  /// Consistent mass matrix (constant): rho int phi_s phi_t dV (x) I3.
  const Matrix24& mass() const { return mass_; }
  /// Reference coordinates q0.
  const Vector24& reference() const { return q0_; }
  /// Reference mid-surface area [m^2] and the share int N_k dA of each node.
  double area() const { return area_; }
  const std::array<double, 4>& nodal_areas() const { return nodal_area_; }
  /// The 2x2 Gauss points of the reference mid-surface: the bilinear shape
  /// functions N_k there and the area weight dA (sum of dA = area(); sum of
  /// N_k dA = nodal_areas()[k]). A surface integral int f dA of a field
  /// interpolated from the nodes is sum_g dA_g f(sum_k N_k f_k).
  struct SurfacePoint {
    std::array<double, 4> N;
    double dA;
  };
  const std::array<SurfacePoint, 4>& surface_points() const { return surface_points_; }
  const std::array<double, 4>& thickness() const { return h_; }

  /// Slot functions phi_s at (xi, eta, zeta) (s = 2k: N_k multiplies r_k;
  /// s = 2k+1: N_k zeta h_k/2 multiplies d_k) and their derivatives with
  /// respect to (xi, eta, zeta) (columns). r = sum_s phi_s q_s.
  void slot_functions(double xi, double eta, double zeta, Eigen::Matrix<double, 8, 1>& phi,
                      Eigen::Matrix<double, 8, 3>& dphi) const;

  static constexpr int kNumEas = 5;

 private:
  struct QuadraturePoint {
    double xi, eta, zeta;
    double dV;                                ///< det J * weights [m^3]
    Eigen::Matrix<double, 6, 6> T;            ///< natural -> local strain map
    Eigen::Matrix<double, 6, kNumEas> Gamma;  ///< EAS interpolation (local)
    /// Upper-triangular factor of the material matrix in natural strains:
    /// Wt^T Wt = T^T D T dV (Cholesky; SPD for nu < 0.5).
    Eigen::Matrix<double, 6, 6> Wt;
    Eigen::Matrix<double, kNumEas, 6> GDT;    ///< Gamma^T D T dV
    int level;                                ///< index of the zeta level
  };
  /// Natural-to-local map T, local frame and det J at a reference point.
  void local_map(double xi, double eta, double zeta, Eigen::Matrix<double, 6, 6>& T,
                 Eigen::Matrix3d& frame, double& detJ) const;
  /// EAS interpolation (local tensor components) at a point with det J.
  Eigen::Matrix<double, 6, kNumEas> eas_matrix(double xi, double eta, double zeta,
                                               double detJ) const;

  Eigen::Matrix<double, 3, 8> Q0t_;  ///< reference slots (columns)
  std::array<double, 4> h_;
  Eigen::Matrix<double, 6, 6> T0_;  ///< natural -> local map at the centre
  double detJ0_ = 0;                ///< det J at the centre
  std::vector<double> zeta_points_, zeta_weights_;
  std::vector<QuadraturePoint> qp_;
  Eigen::Vector3d e1_center_;  ///< in-plane axis of the local frames
  Eigen::Matrix<double, kNumEas, kNumEas> H_inv_;
  Eigen::Matrix<double, kNumEas, kNumEas> H_inv_t_;  ///< upper factor: H_inv_t_^T H_inv_t_ = H^-1
  Matrix24 mass_;
  Vector24 q0_;
  double area_ = 0;
  std::array<double, 4> nodal_area_{};
  std::array<SurfacePoint, 4> surface_points_{};
  double lambda_ = 0, mu_ = 0;
  Eigen::Matrix<double, 6, 6> D_;  ///< energy matrix: W = eps^T D eps / 2
};

}  // namespace arthrosim::cartilage
