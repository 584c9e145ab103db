#include "biphasic/hex_basis.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace arthrosim::biphasic {

void gauss_legendre_1d(int n, std::vector<double>* points, std::vector<double>* weights) {
  switch (n) {
    case 1:
      *points = {0.0};
      *weights = {2.0};
      return;
    case 2: {
      const double a = 1.0 / std::sqrt(3.0);
      *points = {-a, a};
      *weights = {1.0, 1.0};
      return;
    }
    case 3: {
      const double a = std::sqrt(0.6);
      *points = {-a, 0.0, a};
      *weights = {5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};
      return;
    }
    case 4: {
      const double a = std::sqrt(3.0 / 7.0 - 2.0 / 7.0 * std::sqrt(1.2));
      const double b = std::sqrt(3.0 / 7.0 + 2.0 / 7.0 * std::sqrt(1.2));
      const double wa = (18.0 + std::sqrt(30.0)) / 36.0;
      const double wb = (18.0 - std::sqrt(30.0)) / 36.0;
      *points = {-b, -a, a, b};
      *weights = {wb, wa, wa, wb};
      return;
    }
    case 5: {
      const double a = std::sqrt(5.0 - 2.0 * std::sqrt(10.0 / 7.0)) / 3.0;
      const double b = std::sqrt(5.0 + 2.0 * std::sqrt(10.0 / 7.0)) / 3.0;
      const double wa = (322.0 + 13.0 * std::sqrt(70.0)) / 900.0;
      const double wb = (322.0 - 13.0 * std::sqrt(70.0)) / 900.0;
      *points = {-b, -a, 0.0, a, b};
      *weights = {wb, wa, 128.0 / 225.0, wa, wb};
      return;
    }
    default:
      throw std::invalid_argument("gauss_legendre_1d: n must be 1..5, got " + std::to_string(n));
  }
}

QuadratureRule hex_rule(int n) {
  std::vector<double> x, w;
  gauss_legendre_1d(n, &x, &w);
  QuadratureRule rule;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        rule.points.emplace_back(x[i], x[j], x[k]);
        rule.weights.push_back(w[i] * w[j] * w[k]);
      }
  return rule;
}

QuadratureRule quad_rule(int n) {
  std::vector<double> x, w;
  gauss_legendre_1d(n, &x, &w);
  QuadratureRule rule;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      rule.points.emplace_back(x[i], x[j], 0.0);
      rule.weights.push_back(w[i] * w[j]);
    }
  return rule;
}

void lagrange_1d(int order, double x, double* value, double* derivative) {
  if (order == 1) {
    value[0] = 0.5 * (1.0 - x);
    value[1] = 0.5 * (1.0 + x);
    derivative[0] = -0.5;
    derivative[1] = 0.5;
  } else {
    value[0] = 0.5 * x * (x - 1.0);
    value[1] = 1.0 - x * x;
    value[2] = 0.5 * x * (x + 1.0);
    derivative[0] = x - 0.5;
    derivative[1] = -2.0 * x;
    derivative[2] = x + 0.5;
  }
}

void hex_basis(int order, const Eigen::Vector3d& xi, Eigen::VectorXd* values,
               Eigen::MatrixXd* gradients) {
  const int m = order + 1;
  double v[3][3], d[3][3];
  for (int c = 0; c < 3; ++c) lagrange_1d(order, xi[c], v[c], d[c]);
  const int n = m * m * m;
  values->resize(n);
  gradients->resize(n, 3);
  for (int k = 0; k < m; ++k)
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) {
        const int a = (k * m + j) * m + i;
        (*values)[a] = v[0][i] * v[1][j] * v[2][k];
        (*gradients)(a, 0) = d[0][i] * v[1][j] * v[2][k];
        (*gradients)(a, 1) = v[0][i] * d[1][j] * v[2][k];
        (*gradients)(a, 2) = v[0][i] * v[1][j] * d[2][k];
      }
}

void quad_basis(int order, double xi, double eta, Eigen::VectorXd* values,
                Eigen::MatrixXd* gradients) {
  const int m = order + 1;
  double v[2][3], d[2][3];
  lagrange_1d(order, xi, v[0], d[0]);
  lagrange_1d(order, eta, v[1], d[1]);
  values->resize(m * m);
  gradients->resize(m * m, 2);
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < m; ++i) {
      const int a = j * m + i;
      (*values)[a] = v[0][i] * v[1][j];
      (*gradients)(a, 0) = d[0][i] * v[1][j];
      (*gradients)(a, 1) = v[0][i] * d[1][j];
    }
}

}  // namespace arthrosim::biphasic
