#include "musculoskeletal/settle.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

namespace {
bool is_revolute(const Model& m, int coordinate) {
  for (const Joint& j : m.tree.joints)
    if (j.coordinate == coordinate) return j.type == JointType::kRevolute;
  return false;
}
}  // namespace

SettleResult settle(const Model& model, ModelData& data, const Eigen::VectorXd& q0,
                    const SettleOptions& opt) {
  const int n = model.num_coordinates();
  if (q0.size() != n)
    throw common::InputError("settle: expected " + std::to_string(n) + " coordinates, found " +
                             std::to_string(q0.size()));
  std::set<int> fixed(opt.fixed.begin(), opt.fixed.end());
  fixed.insert(model.prescribed_coordinates.begin(), model.prescribed_coordinates.end());
  for (int f : fixed)
    if (f < 0 || f >= n) throw common::InputError("settle: fixed coordinate index out of range");
  std::vector<int> free;
  for (int i = 0; i < n; ++i)
    if (!fixed.count(i)) free.push_back(i);
  const int m = static_cast<int>(free.size());
  Eigen::VectorXd scale_r(m), scale_x(m);  // residual and variable scales
  std::vector<bool> rev(m);
  for (int k = 0; k < m; ++k) {
    rev[k] = is_revolute(model, free[k]);
    scale_r[k] = rev[k] ? 1.0 / opt.length_scale : 1.0;
    scale_x[k] = rev[k] ? 1.0 : 1.0 / opt.length_scale;
  }
  const Eigen::VectorXd act =
      Eigen::VectorXd::Constant(static_cast<int>(model.muscles.size()), opt.muscle_tone);
  const Eigen::VectorXd no_speed;

  SettleResult res;
  res.q = q0;
  auto residual = [&](const Eigen::VectorXd& q, bool jac, Eigen::MatrixXd* J) {
    if (jac) {
      evaluate_jacobian(model, data, q, no_speed, act, opt.forces, free);
    } else {
      evaluate_forces(model, data, q, no_speed, act, opt.forces);
    }
    Eigen::VectorXd r(m);
    for (int k = 0; k < m; ++k) r[k] = scale_r[k] * data.Q[free[k]];
    if (J) {
      J->resize(m, m);
      for (int a = 0; a < m; ++a)
        for (int b = 0; b < m; ++b)
          (*J)(a, b) = scale_r[a] * data.dQ_dq(free[a], free[b]) / scale_x[b];
    }
    return r;
  };
  auto converged = [&]() {  // at the state `data` was last evaluated at
    double fmax = 0, mmax = 0;
    for (int k = 0; k < m; ++k) {
      const double v = std::abs(data.Q[free[k]]);
      (rev[k] ? mmax : fmax) = std::max(rev[k] ? mmax : fmax, v);
    }
    res.max_force_residual = fmax;
    res.max_moment_residual = mmax;
    return fmax <= opt.force_tolerance && mmax <= opt.moment_tolerance;
  };

  if (!(opt.initial_pseudo_time > 0.0))
    throw common::InputError("settle: initial_pseudo_time must be > 0, found " +
                             std::to_string(opt.initial_pseudo_time));
  if (!(opt.max_residual_growth >= 1.0))
    throw common::InputError("settle: max_residual_growth must be >= 1, found " +
                             std::to_string(opt.max_residual_growth));
  // Scales the step dx so that no coordinate moves by more than its limit.
  auto step_factor = [&](const Eigen::VectorXd& dx) {
    double f = 1.0;
    for (int k = 0; k < m; ++k) {
      const double dq = std::abs(dx[k] / scale_x[k]);
      const double lim = rev[k] ? opt.max_step_rad : opt.max_step_m;
      if (dq > lim) f = std::min(f, lim / dq);
    }
    return f;
  };
  auto apply = [&](const Eigen::VectorXd& dx, double f) {
    Eigen::VectorXd q_try = res.q;
    for (int k = 0; k < m; ++k) q_try[free[k]] += f * dx[k] / scale_x[k];
    return q_try;
  };

  Eigen::MatrixXd J;
  Eigen::VectorXd r = residual(res.q, true, &J);
  double lambda = opt.initial_damping;
  double tau = opt.initial_pseudo_time;
  for (res.iterations = 0; res.iterations < opt.max_iterations; ++res.iterations) {
    res.history.push_back(r.norm());
    if (converged()) {
      res.status = SettleStatus::kConverged;
      break;
    }
    bool accepted = false;
    if (opt.method == SettleMethod::kPseudoTransient) {
      // D = diag(|J_kk|), floored so that a coordinate without own stiffness
      // still gets some damping.
      const Eigen::VectorXd D =
          J.diagonal().cwiseAbs().cwiseMax(1e-6 * J.diagonal().cwiseAbs().maxCoeff() + 1e-300);
      for (int attempt = 0; attempt < 12 && !accepted; ++attempt) {
        Eigen::MatrixXd A = -J;
        A.diagonal() += D / tau;
        const Eigen::VectorXd dx = A.partialPivLu().solve(r);
        if (!dx.allFinite()) {
          tau /= 4.0;
          continue;
        }
        const Eigen::VectorXd q_try = apply(dx, step_factor(dx));
        const Eigen::VectorXd r_try = residual(q_try, false, nullptr);
        if (r_try.norm() <= opt.max_residual_growth * r.norm()) {
          const double ratio = r.norm() / std::max(r_try.norm(), 1e-300);
          tau = std::min(tau * std::clamp(ratio, 0.25, 10.0), 1e12);
          res.q = q_try;
          accepted = true;
        } else {
          tau /= 4.0;
        }
      }
    } else {
      for (int attempt = 0; attempt < 12 && !accepted; ++attempt) {
        const Eigen::MatrixXd JtJ = J.transpose() * J;
        Eigen::MatrixXd A = JtJ;
        A.diagonal() += lambda * JtJ.diagonal().cwiseMax(1e-12 * JtJ.diagonal().maxCoeff());
        const Eigen::VectorXd dx = A.ldlt().solve(-J.transpose() * r);
        const Eigen::VectorXd q_try = apply(dx, step_factor(dx));
        const Eigen::VectorXd r_try = residual(q_try, false, nullptr);
        if (r_try.norm() < r.norm()) {
          res.q = q_try;
          lambda = std::max(lambda / 3.0, 1e-9);
          accepted = true;
        } else {
          lambda *= 10.0;
        }
      }
    }
    if (!accepted) {
      residual(res.q, false, nullptr);
      converged();
      res.status = SettleStatus::kStalled;
      break;
    }
    r = residual(res.q, true, &J);
  }
  if (res.status != SettleStatus::kConverged) converged();
  std::ostringstream s;
  s << "settle: "
    << (res.status == SettleStatus::kConverged
            ? "converged"
            : res.status == SettleStatus::kStalled ? "stalled (no acceptable step)"
                                                   : "reached the iteration limit")
    << " after " << res.iterations << " iterations; max |Q| = " << res.max_force_residual
    << " N (tolerance " << opt.force_tolerance << "), " << res.max_moment_residual
    << " N m (tolerance " << opt.moment_tolerance << ")";
  res.message = s.str();
  // Leave the results of the final point in data.
  evaluate_forces(model, data, res.q, no_speed, act, opt.forces);
  return res;
}

}  // namespace arthrosim::musculoskeletal
