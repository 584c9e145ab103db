#include "biphasic/trapezoidal.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

#include "common/error.h"
#include "common/finite.h"
#include "numerics/sparse_direct_solver.h"

namespace arthrosim::biphasic {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void check_indices(const std::vector<int>& idx, int n, const std::string& what,
                   const std::string& layer) {
  std::vector<int> sorted = idx;
  std::sort(sorted.begin(), sorted.end());
  for (size_t i = 0; i < sorted.size(); ++i) {
    if (sorted[i] < 0 || sorted[i] >= n || (i > 0 && sorted[i] == sorted[i - 1])) {
      std::ostringstream s;
      s << "layer '" << layer << "': " << what << ": expected distinct indices in [0, " << n
        << "), found " << sorted[i];
      throw common::InputError(s.str());
    }
  }
}

}  // namespace

TrapezoidalIntegrator::TrapezoidalIntegrator(const LayerSystem& system, std::vector<int> fixed_u,
                                             std::vector<int> fixed_p, TrapezoidalOptions options)
    : system_(system),
      fixed_u_(std::move(fixed_u)),
      fixed_p_(std::move(fixed_p)),
      options_(options) {
  const std::string& name = system.mesh.name;
  if (!std::isfinite(options.time_step_s) || options.time_step_s <= 0.0) {
    std::ostringstream s;
    s << "layer '" << name << "': time step: expected a value > 0 s, found " << options.time_step_s;
    throw common::InputError(s.str());
  }
  if (!std::isfinite(options.omega) || options.omega < 0.5 || options.omega > 1.0) {
    std::ostringstream s;
    s << "layer '" << name << "': omega: expected a value in [0.5, 1], found " << options.omega;
    throw common::InputError(s.str());
  }
  const int nu = system.num_u_dofs();
  const int np = system.num_p_dofs();
  check_indices(fixed_u_, nu, "fixed displacement dofs", name);
  check_indices(fixed_p_, np, "fixed pressure dofs", name);
  const auto t0 = std::chrono::steady_clock::now();
  const double a = options.omega * options.time_step_s;

  // Position of every unknown (v then p) in the free or fixed list.
  const int n = nu + np;
  std::vector<int> fixed_pos(n, -1), free_pos(n, -1);
  for (size_t i = 0; i < fixed_u_.size(); ++i) fixed_pos[fixed_u_[i]] = static_cast<int>(i);
  for (size_t i = 0; i < fixed_p_.size(); ++i)
    fixed_pos[nu + fixed_p_[i]] = static_cast<int>(fixed_u_.size() + i);
  for (int i = 0; i < n; ++i) {
    if (fixed_pos[i] < 0) {
      free_pos[i] = static_cast<int>(free_.size());
      free_.push_back(i);
    }
  }
  fixed_.resize(fixed_u_.size() + fixed_p_.size());
  for (int i = 0; i < n; ++i)
    if (fixed_pos[i] >= 0) fixed_[fixed_pos[i]] = i;
  const int nf = static_cast<int>(free_.size());
  const int nc = static_cast<int>(fixed_.size());
  if (nf == 0) {
    throw common::InputError("layer '" + name + "': every unknown is prescribed; nothing to solve");
  }

  // Scaling D of the free unknowns.
  Eigen::VectorXd kdiag = system.K.diagonal();
  Eigen::VectorXd bdiag = system.B.diagonal();
  scale_.resize(nf);
  // p: diagonal of B + A^T (a diag K)^-1 A, an estimate of the Schur complement's.
  Eigen::VectorXd schur = bdiag;
  for (int j = 0; j < system.A.outerSize(); ++j) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(system.A, j); it; ++it) {
      if (free_pos[it.row()] >= 0 && kdiag[it.row()] > 0.0)
        schur[j] += it.value() * it.value() / (a * kdiag[it.row()]);
    }
  }
  for (int f = 0; f < nf; ++f) {
    const int i = free_[f];
    const double d = i < nu ? a * kdiag[i] : schur[i - nu];
    if (!(d > 0.0) || !std::isfinite(d)) {
      std::ostringstream s;
      s << "layer '" << name << "': " << (i < nu ? "displacement" : "pressure") << " dof "
        << (i < nu ? i : i - nu) << " has no stiffness (" << d
        << "): an unconnected node or a singular system";
      throw common::NumericalError(s.str());
    }
    scale_[f] = 1.0 / std::sqrt(d);
  }

  // Blocks of M = [a K, -A; -A^T, -B] split into free-free (scaled) and free-fixed.
  std::vector<Eigen::Triplet<double>> tff, tfc;
  auto put = [&](int i, int j, double value) {
    const int fi = free_pos[i];
    if (fi < 0) return;  // fixed row: not an equation of the reduced system
    const int fj = free_pos[j];
    if (fj >= 0) {
      tff.emplace_back(fi, fj, scale_[fi] * value * scale_[fj]);
    } else {
      tfc.emplace_back(fi, fixed_pos[j], value);
    }
  };
  for (int j = 0; j < system.K.outerSize(); ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(system.K, j); it; ++it)
      put(it.row(), j, a * it.value());
  for (int j = 0; j < system.A.outerSize(); ++j) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(system.A, j); it; ++it) {
      put(it.row(), nu + j, -it.value());
      put(nu + j, it.row(), -it.value());
    }
  }
  for (int j = 0; j < system.B.outerSize(); ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(system.B, j); it; ++it)
      put(nu + it.row(), nu + j, -it.value());
  M_ff_scaled_.resize(nf, nf);
  M_ff_scaled_.setFromTriplets(tff.begin(), tff.end());
  M_ff_scaled_.makeCompressed();
  M_fc_.resize(nf, nc);
  M_fc_.setFromTriplets(tfc.begin(), tfc.end());
  M_fc_.makeCompressed();

  solver_ = std::make_unique<numerics::SparseDirectSolver>(numerics::LinearSolverKind::kUmfpack);
  if (!solver_->factorize(M_ff_scaled_)) {
    throw common::NumericalError("layer '" + name + "': factorisation of the biphasic matrix failed: " +
                                 solver_->message());
  }
  counters_.factorizations = 1;
  counters_.free_dofs = nf;
  counters_.fixed_dofs = nc;
  counters_.matrix_nonzeros = M_ff_scaled_.nonZeros();
  counters_.factorization_s = seconds_since(t0);

  u_ = Eigen::VectorXd::Zero(nu);
  v_ = Eigen::VectorXd::Zero(nu);
  p_ = Eigen::VectorXd::Zero(np);
  last_F_t_ = Eigen::VectorXd::Zero(nu);
  last_F_Q_ = Eigen::VectorXd::Zero(np);
}

TrapezoidalIntegrator::~TrapezoidalIntegrator() = default;

void TrapezoidalIntegrator::step(const StepInput& in) {
  const auto t0 = std::chrono::steady_clock::now();
  const std::string& name = system_.mesh.name;
  const int nu = system_.num_u_dofs();
  const int np = system_.num_p_dofs();
  const double dt = options_.time_step_s;
  const double w = options_.omega;
  auto check_size = [&](const Eigen::VectorXd& x, Eigen::Index n, const char* what) {
    if (x.size() != 0 && x.size() != n) {
      std::ostringstream s;
      s << "layer '" << name << "': step input " << what << ": expected size " << n << ", found "
        << x.size();
      throw std::invalid_argument(s.str());
    }
  };
  check_size(in.u_fixed, static_cast<Eigen::Index>(fixed_u_.size()), "u_fixed");
  check_size(in.p_fixed, static_cast<Eigen::Index>(fixed_p_.size()), "p_fixed");
  check_size(in.F_t, nu, "F_t");
  check_size(in.F_Q, np, "F_Q");
  const std::string where = "biphasic: layer '" + name + "', step " + std::to_string(steps_ + 1) +
                            " (t = " + std::to_string(time_ + dt) + " s)";

  // Known part of u_{i+1}: u_i + (1 - omega) dt v_i.
  const Eigen::VectorXd u_star = u_ + (1.0 - w) * dt * v_;
  Eigen::VectorXd rhs_u = -(system_.K * u_star);
  if (in.F_t.size()) rhs_u += in.F_t;
  Eigen::VectorXd rhs_p = Eigen::VectorXd::Zero(np);
  if (in.F_Q.size()) rhs_p += in.F_Q;

  // Prescribed unknowns: velocities implied by (15), pressures as given.
  Eigen::VectorXd x_c(fixed_.size());
  for (size_t c = 0; c < fixed_u_.size(); ++c) {
    const int i = fixed_u_[c];
    const double ubar = in.u_fixed.size() ? in.u_fixed[c] : 0.0;
    x_c[c] = (ubar - u_star[i]) / (w * dt);
  }
  for (size_t c = 0; c < fixed_p_.size(); ++c)
    x_c[fixed_u_.size() + c] = in.p_fixed.size() ? in.p_fixed[c] : 0.0;

  const int nf = static_cast<int>(free_.size());
  Eigen::VectorXd b(nf);
  for (int f = 0; f < nf; ++f) {
    const int i = free_[f];
    b[f] = i < nu ? rhs_u[i] : rhs_p[i - nu];
  }
  if (x_c.size()) b -= M_fc_ * x_c;
  const Eigen::VectorXd b_scaled = scale_.cwiseProduct(b);
  const auto ts = std::chrono::steady_clock::now();
  const Eigen::VectorXd y = solver_->solve(b_scaled);
  counters_.solve_s += seconds_since(ts);
  ++counters_.solves;
  common::check_finite(y, where + ": solution");
  const double bnorm = b_scaled.norm();
  if (bnorm > 0.0) {
    const double rel = (M_ff_scaled_ * y - b_scaled).norm() / bnorm;
    counters_.max_relative_residual = std::max(counters_.max_relative_residual, rel);
  }

  Eigen::VectorXd v_next(nu), p_next(np);
  for (int f = 0; f < nf; ++f) {
    const int i = free_[f];
    const double x = scale_[f] * y[f];
    if (i < nu) v_next[i] = x; else p_next[i - nu] = x;
  }
  for (size_t c = 0; c < fixed_.size(); ++c) {
    const int i = fixed_[c];
    if (i < nu) v_next[i] = x_c[c]; else p_next[i - nu] = x_c[c];
  }
  u_ = u_star + w * dt * v_next;
  v_ = std::move(v_next);
  p_ = std::move(p_next);
  // Prescribed displacements exactly as given (no round-off drift from (15)).
  for (size_t c = 0; c < fixed_u_.size(); ++c)
    u_[fixed_u_[c]] = in.u_fixed.size() ? in.u_fixed[c] : 0.0;
  common::check_finite(u_, where + ": displacement");
  common::check_finite(p_, where + ": pressure");
  last_F_t_ = in.F_t.size() ? in.F_t : Eigen::VectorXd::Zero(nu);
  last_F_Q_ = in.F_Q.size() ? in.F_Q : Eigen::VectorXd::Zero(np);
  ++steps_;
  time_ = steps_ * dt;
  counters_.step_s += seconds_since(t0);
}

Eigen::VectorXd TrapezoidalIntegrator::reaction() const {
  return system_.K * u_ - system_.A * p_ - last_F_t_;
}

Eigen::VectorXd TrapezoidalIntegrator::flux_reaction() const {
  return -(system_.A.transpose() * v_) - system_.B * p_ - last_F_Q_;
}

}  // namespace arthrosim::biphasic

namespace arthrosim::biphasic {

TrapezoidalState TrapezoidalIntegrator::state() const {
  TrapezoidalState s;
  s.time = time_;
  s.steps = steps_;
  s.u = u_;
  s.v = v_;
  s.p = p_;
  s.last_F_t = last_F_t_;
  s.last_F_Q = last_F_Q_;
  s.solves = counters_.solves;
  s.solve_s = counters_.solve_s;
  s.step_s = counters_.step_s;
  s.max_relative_residual = counters_.max_relative_residual;
  return s;
}

void TrapezoidalIntegrator::restore(const TrapezoidalState& s) {
  if (s.u.size() != u_.size() || s.v.size() != v_.size() || s.p.size() != p_.size() ||
      s.last_F_t.size() != last_F_t_.size() || s.last_F_Q.size() != last_F_Q_.size()) {
    throw std::invalid_argument("biphasic: layer '" + system_.mesh.name + "': a state of " +
                                std::to_string(s.u.size()) + " u and " + std::to_string(s.p.size()) +
                                " p dofs for a system of " + std::to_string(u_.size()) + " and " +
                                std::to_string(p_.size()));
  }
  time_ = s.time;
  steps_ = s.steps;
  u_ = s.u;
  v_ = s.v;
  p_ = s.p;
  last_F_t_ = s.last_F_t;
  last_F_Q_ = s.last_F_Q;
  counters_.solves = s.solves;
  counters_.solve_s = s.solve_s;
  counters_.step_s = s.step_s;
  counters_.max_relative_residual = s.max_relative_residual;
}

}  // namespace arthrosim::biphasic
