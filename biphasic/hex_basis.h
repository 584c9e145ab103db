#pragma once
// Lagrange bases on the reference hexahedron [-1, 1]^3 and Gauss-Legendre rules.
//
// Local node order is lexicographic with the first coordinate fastest:
//   trilinear (Q1, 8 nodes):     node (i, j, k), i, j, k in {0, 1} at xi = -1, +1;
//                                index = (k * 2 + j) * 2 + i
//   triquadratic (Q2, 27 nodes): node (i, j, k), i, j, k in {0, 1, 2} at xi = -1, 0, +1;
//                                index = (k * 3 + j) * 3 + i
// (not the VTK order; output converts where needed). The same conventions hold
// for the bilinear / biquadratic bases of a face (4 and 9 nodes).
#include <Eigen/Core>
#include <array>
#include <vector>

namespace arthrosim::biphasic {

/// Points and weights of a tensor Gauss-Legendre rule; exact for polynomials of
/// degree 2n - 1 in each coordinate.
struct QuadratureRule {
  std::vector<Eigen::Vector3d> points;  ///< reference coordinates (third = 0 for faces)
  std::vector<double> weights;
};

/// n-point Gauss-Legendre rule on [-1, 1] (n = 1..5).
void gauss_legendre_1d(int n, std::vector<double>* points, std::vector<double>* weights);
/// n x n x n rule on the reference hexahedron.
QuadratureRule hex_rule(int n);
/// n x n rule on the reference square (third coordinate 0).
QuadratureRule quad_rule(int n);

/// 1D Lagrange values and derivatives of order 1 (nodes -1, 1) or 2 (nodes -1, 0, 1).
void lagrange_1d(int order, double x, double* value, double* derivative);

/// Values (n) and reference gradients (n x 3) of the order-`order` hexahedral
/// basis (order 1: n = 8, order 2: n = 27) at reference point xi.
void hex_basis(int order, const Eigen::Vector3d& xi, Eigen::VectorXd* values,
               Eigen::MatrixXd* gradients);
/// Values (n) and reference gradients (n x 2) of the order-`order`
/// quadrilateral basis (order 1: n = 4, order 2: n = 9) at (xi, eta).
void quad_basis(int order, double xi, double eta, Eigen::VectorXd* values,
                Eigen::MatrixXd* gradients);

/// Number of nodes of the hexahedral basis of an order (8 or 27).
inline int hex_nodes(int order) { return order == 1 ? 8 : 27; }

}  // namespace arthrosim::biphasic
