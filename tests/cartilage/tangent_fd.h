#pragma once
// Finite-difference check of a numerics::TimeIntegrable's Newton tangent, shared by the
// shell-term and mesh-contact tests.
#include <Eigen/Dense>
#include <Eigen/SparseCore>
#include <algorithm>

#include "numerics/time_integrable.h"

namespace arthrosim::cartilage::testing {

/// max |K - K_fd| / max |K| with K = dF/dq (wrt = 0) or dF/dv (wrt = 1) at
/// time t, K_fd by central differences with step h_position on position
/// coordinates (i % 6 < 3) and h_gradient on transverse gradients. If kmax
/// is given it receives max |K|.
inline double tangent_fd_error(numerics::TimeIntegrable& sys, double t, const Eigen::VectorXd& q, const Eigen::VectorXd& v,
                               int wrt, double h_position, double h_gradient, double* kmax = nullptr) {
  const int n = sys.num_dofs();
  Eigen::SparseMatrix<double> K;
  Eigen::VectorXd F;
  numerics::EvalRequest r;
  r.t = t;
  r.q = &q;
  r.v = &v;
  r.kq = wrt == 0 ? 1.0 : 0.0;
  r.kv = wrt == 1 ? 1.0 : 0.0;
  sys.evaluate(r, F, nullptr, &K);
  const Eigen::MatrixXd Kd(K);
  double err = 0;
  for (int j = 0; j < n; ++j) {
    const double h = (j % 6 < 3) ? h_position : h_gradient;
    Eigen::VectorXd qp = q, qm = q, vp = v, vm = v, Fp, Fm;
    (wrt == 0 ? qp : vp)(j) += h;
    (wrt == 0 ? qm : vm)(j) -= h;
    numerics::EvalRequest a = r, b = r;
    a.q = &qp;
    a.v = &vp;
    b.q = &qm;
    b.v = &vm;
    sys.evaluate(a, Fp, nullptr, nullptr);
    sys.evaluate(b, Fm, nullptr, nullptr);
    err = std::max(err, ((Fp - Fm) / (2 * h) - Kd.col(j)).cwiseAbs().maxCoeff());
  }
  const double scale = Kd.cwiseAbs().maxCoeff();
  if (kmax) *kmax = scale;
  return err / scale;
}

}  // namespace arthrosim::cartilage::testing
