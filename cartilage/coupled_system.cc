#include "cartilage/coupled_system.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

#include "common/effects.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

CoupledShellSystem::CoupledShellSystem(std::vector<ShellModel*> models, std::vector<std::string> names)
    : models_(std::move(models)), names_(std::move(names)) {
  if (models_.empty()) throw common::InputError("coupled shell system: no model given");
  if (names_.size() != models_.size())
    throw common::InputError("coupled shell system: " + std::to_string(names_.size()) + " names for " +
                             std::to_string(models_.size()) + " models");
  for (size_t m = 0; m < models_.size(); ++m) {
    if (!models_[m]) throw common::InputError("coupled shell system: model " + names_[m] + " is null");
    offsets_.push_back(n_);
    n_ += models_[m]->num_dofs();
  }
  constrained_.reserve(n_);
  weights_.resize(n_);
  for (size_t m = 0; m < models_.size(); ++m) {
    const auto& c = models_[m]->constrained();
    constrained_.insert(constrained_.end(), c.begin(), c.end());
    weights_.segment(offsets_[m], models_[m]->num_dofs()) = models_[m]->increment_weights();
  }
  model_K_.resize(models_.size());
  Eigen::VectorXd q(n_);
  for (size_t m = 0; m < models_.size(); ++m)
    q.segment(offsets_[m], models_[m]->num_dofs()) = models_[m]->reference_state();
  rebuild_pattern(q);
  revision_ = 0;
  stats_.pattern_rebuilds = 0;
}

CoupledShellSystem::~CoupledShellSystem() = default;

Eigen::VectorXd CoupledShellSystem::segment(int m, const Eigen::VectorXd& x) const {
  return x.segment(offsets_[m], models_[m]->num_dofs());
}

common::Points3 CoupledShellSystem::positions(int m, const Eigen::VectorXd& q) const {
  const int N = models_[m]->num_nodes();
  common::Points3 X(N, 3);
  for (int i = 0; i < N; ++i) X.row(i) = q.segment<3>(offsets_[m] + 6 * i).transpose();
  return X;
}

int CoupledShellSystem::model_of(int dof) const {
  const auto it = std::upper_bound(offsets_.begin(), offsets_.end(), dof);
  return static_cast<int>(it - offsets_.begin()) - 1;
}

void CoupledShellSystem::add_contact(const std::string& name, int a, int b, const ContactOptions& options,
                                     double pattern_margin_m) {
  if (a < 0 || b < 0 || a >= num_models() || b >= num_models() || a == b)
    throw common::InputError("mesh contact " + name + ": expected two different surfaces of the system, found " +
                             std::to_string(a) + " and " + std::to_string(b));
  if (!(pattern_margin_m >= 0)) throw common::InputError("mesh contact " + name + ": pattern margin must be >= 0");
  Pair p;
  p.contact = std::make_unique<MeshContact>(name, ContactSurface(*models_[a]), ContactSurface(*models_[b]), options);
  p.a = a;
  p.b = b;
  p.margin = pattern_margin_m;
  contacts_.push_back(std::move(p));
  if (ledger_) ledger_->record("mesh_contact", 1, name);
  Eigen::VectorXd q(n_);
  for (size_t m = 0; m < models_.size(); ++m)
    q.segment(offsets_[m], models_[m]->num_dofs()) = models_[m]->reference_state();
  rebuild_pattern(q);
}

void CoupledShellSystem::restore(const Eigen::VectorXd& pattern_coordinates, const CoupledSystemStatistics& statistics) {
  if (pattern_coordinates.size() != n_)
    throw common::InputError("coupled system: restored pattern coordinates of size " +
                             std::to_string(pattern_coordinates.size()) + ", expected " + std::to_string(n_));
  rebuild_pattern(pattern_coordinates);
  stats_ = statistics;
}

void CoupledShellSystem::rebuild_pattern(const Eigen::VectorXd& q) {
  pattern_q_ = q;
  const int nodes = n_ / 6;
  std::vector<std::vector<int>> adj(nodes);
  for (const Pair& p : contacts_) {
    const auto cand = p.contact->coupling_candidates(positions(p.a, q), positions(p.b, q), p.margin);
    const int oa = offsets_[p.a] / 6, ob = offsets_[p.b] / 6;
    for (const auto& [i, j] : cand) {
      adj[oa + i].push_back(ob + j);
      adj[ob + j].push_back(oa + i);
    }
  }
  for (auto& v : adj) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
  }
  std::vector<int> outer(n_ + 1, 0), inner;
  size_t reserve = 0;
  for (const ShellModel* m : models_) reserve += static_cast<size_t>(m->tangent_pattern().nonZeros());
  inner.reserve(reserve);
  model_value_map_.assign(models_.size(), {});
  for (size_t m = 0; m < models_.size(); ++m) model_value_map_[m].resize(models_[m]->tangent_pattern().nonZeros());
  for (int c = 0; c < n_; ++c) {
    const int m = model_of(c);
    const int lo = offsets_[m], hi = offsets_[m] + models_[m]->num_dofs();
    const Eigen::SparseMatrix<double>& P = models_[m]->tangent_pattern();
    const int lc = c - lo;
    const bool position = (c % 6) < 3;
    const std::vector<int>& extra = adj[c / 6];
    if (position)
      for (int cn : extra)
        if (6 * cn < lo)
          for (int d = 0; d < 3; ++d) inner.push_back(6 * cn + d);
    for (int k = P.outerIndexPtr()[lc]; k < P.outerIndexPtr()[lc + 1]; ++k) {
      model_value_map_[m][k] = static_cast<int>(inner.size());
      inner.push_back(P.innerIndexPtr()[k] + lo);
    }
    if (position)
      for (int cn : extra)
        if (6 * cn >= hi)
          for (int d = 0; d < 3; ++d) inner.push_back(6 * cn + d);
    outer[c + 1] = static_cast<int>(inner.size());
  }
  pattern_.resize(n_, n_);
  pattern_.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
  std::copy(outer.begin(), outer.end(), pattern_.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), pattern_.innerIndexPtr());
  std::fill(pattern_.valuePtr(), pattern_.valuePtr() + inner.size(), 0.0);
  ++revision_;
  ++stats_.pattern_rebuilds;
}

int CoupledShellSystem::value_index(int row, int col) const {
  const int* begin = pattern_.innerIndexPtr() + pattern_.outerIndexPtr()[col];
  const int* end = pattern_.innerIndexPtr() + pattern_.outerIndexPtr()[col + 1];
  const int* it = std::lower_bound(begin, end, row);
  return (it != end && *it == row) ? static_cast<int>(it - pattern_.innerIndexPtr()) : -1;
}

bool CoupledShellSystem::has_inertia() const {
  for (const ShellModel* m : models_)
    if (m->has_inertia()) return true;
  return false;
}

bool CoupledShellSystem::tangent_symmetric() const {
  for (const ShellModel* m : models_)
    if (!m->tangent_symmetric()) return false;
  // Contact near an open boundary (the fade, mesh_contact.h) or with damping
  // has a non-symmetric tangent.
  return contacts_.empty();
}

void CoupledShellSystem::evaluate(const numerics::EvalRequest& req, Eigen::VectorXd& F, Eigen::VectorXd* Ma,
                                  Eigen::SparseMatrix<double>* K) {
  ++stats_.evaluations;
  if (K) ++stats_.tangent_evaluations;
  const Eigen::VectorXd& q = *req.q;
  if (q.size() != n_) throw common::InputError("coupled shell system: q has the wrong size");
  // ---- contacts first: they may change the pattern ---------------------------
  auto tc = Clock::now();
  const bool want_K = K != nullptr;
  std::vector<std::vector<ContactPoint>> active(contacts_.size());
  long n_active = 0;
  for (size_t k = 0; k < contacts_.size(); ++k) {
    const Pair& p = contacts_[k];
    common::Points3 va, vb;
    if (req.v) {
      va = positions(p.a, *req.v);
      vb = positions(p.b, *req.v);
    }
    active[k] = p.contact->detect(positions(p.a, q), positions(p.b, q), req.v ? &va : nullptr,
                                  req.v ? &vb : nullptr, want_K);
    n_active += static_cast<long>(active[k].size());
  }
  stats_.max_active_contacts = std::max(stats_.max_active_contacts, n_active);
  if (want_K) {
    bool missing = false;
    for (size_t k = 0; k < contacts_.size() && !missing; ++k) {
      const Pair& p = contacts_[k];
      const int om[2] = {offsets_[p.a], offsets_[p.b]};
      for (const ContactPoint& c : active[k]) {
        for (int i = 0; i < 4 && !missing; ++i)
          for (int j = 0; j < 4 && !missing; ++j)
            if (c.side[i] != c.side[j] &&
                value_index(om[c.side[i]] + 6 * c.node[i], om[c.side[j]] + 6 * c.node[j]) < 0)
              missing = true;
        if (missing) break;
      }
    }
    if (missing) rebuild_pattern(q);
  }
  stats_.contact_time_s += since(tc);
  // ---- the models ---------------------------------------------------------------
  F.setZero(n_);
  if (Ma) Ma->setZero(n_);
  if (want_K) {
    if (K->nonZeros() != pattern_.nonZeros() || K->rows() != n_ ||
        !std::equal(K->outerIndexPtr(), K->outerIndexPtr() + n_ + 1, pattern_.outerIndexPtr()))
      *K = pattern_;
    std::fill(K->valuePtr(), K->valuePtr() + K->nonZeros(), 0.0);
  }
  for (int m = 0; m < num_models(); ++m) {
    auto t0 = Clock::now();
    const Eigen::VectorXd qm = segment(m, q);
    Eigen::VectorXd vm, am, Fm, Mam;
    if (req.v) vm = segment(m, *req.v);
    if (req.a) am = segment(m, *req.a);
    numerics::EvalRequest r = req;
    r.q = &qm;
    r.v = req.v ? &vm : nullptr;
    r.a = req.a ? &am : nullptr;
    stats_.copy_time_s += since(t0);
    t0 = Clock::now();
    try {
      models_[m]->evaluate(r, Fm, Ma ? &Mam : nullptr, want_K ? &model_K_[m] : nullptr);
    } catch (const common::NumericalError& e) {
      throw common::NumericalError("surface " + names_[m] + ": " + e.what());
    }
    stats_.models_time_s += since(t0);
    t0 = Clock::now();
    F.segment(offsets_[m], Fm.size()) = Fm;
    if (Ma) Ma->segment(offsets_[m], Mam.size()) = Mam;
    if (want_K) {
      const double* src = model_K_[m].valuePtr();
      double* dst = K->valuePtr();
      const std::vector<int>& map = model_value_map_[m];
      for (size_t k = 0; k < map.size(); ++k) dst[map[k]] = src[k];
    }
    stats_.copy_time_s += since(t0);
  }
  // ---- contact forces and tangents ---------------------------------------------
  tc = Clock::now();
  const double kq = req.force_scale * req.kq, kv = req.force_scale * req.kv;
  for (size_t k = 0; k < contacts_.size(); ++k) {
    const Pair& p = contacts_[k];
    const int om[2] = {offsets_[p.a], offsets_[p.b]};
    const double cc = p.contact->options().damping_N_s_m3;
    for (const ContactPoint& c : active[k]) {
      int dof[12];
      Eigen::Matrix<double, 12, 1> v12 = Eigen::Matrix<double, 12, 1>::Zero();
      for (int i = 0; i < 4; ++i)
        for (int d = 0; d < 3; ++d) {
          dof[3 * i + d] = om[c.side[i]] + 6 * c.node[i] + d;
          if (req.v) v12(3 * i + d) = (*req.v)(dof[3 * i + d]);
        }
      const double A = c.area * c.fade;
      for (int i = 0; i < 12; ++i) F(dof[i]) -= A * c.pressure * c.G(i);
      if (!want_K) continue;
      Eigen::Matrix<double, 12, 12> T = kq * A * (c.stiffness * c.G * c.G.transpose() - c.pressure * c.H);
      if (cc != 0) {
        T += kq * A * cc * c.G * (c.H * v12).transpose();
        T += kv * A * cc * c.G * c.G.transpose();
      }
      if (c.fade_edge >= 0 || c.blend) T -= kq * c.area * c.pressure * c.G * c.fade_grad.transpose();
      double* vals = K->valuePtr();
      for (int j = 0; j < 12; ++j)
        for (int i = 0; i < 12; ++i) {
          const int idx = value_index(dof[i], dof[j]);
          if (idx < 0) throw common::NumericalError("mesh contact " + p.contact->name() + ": entry outside the pattern");
          vals[idx] += T(i, j);
        }
    }
  }
  stats_.contact_time_s += since(tc);
  if (!F.allFinite())
    for (int i = 0; i < n_; ++i)
      if (!std::isfinite(F(i)))
        throw common::NumericalError("coupled shell system: non-finite force at " + describe_dof(i) +
                                     ", t = " + std::to_string(req.t) + " s");
}

std::array<Eigen::VectorXd, 2> CoupledShellSystem::updated_contact_multipliers(int k, const Eigen::VectorXd& q) const {
  const Pair& p = contacts_.at(k);
  return p.contact->updated_multipliers(positions(p.a, q), positions(p.b, q));
}

ContactPairReport CoupledShellSystem::contact_report(int k, const Eigen::VectorXd& q, const Eigen::VectorXd* v) const {
  const Pair& p = contacts_.at(k);
  ContactPairReport r;
  r.name = p.contact->name();
  common::Points3 va, vb;
  if (v) {
    va = positions(p.a, *v);
    vb = positions(p.b, *v);
  }
  const auto active = p.contact->detect(positions(p.a, q), positions(p.b, q), v ? &va : nullptr,
                                        v ? &vb : nullptr, false, &r.counts);
  common::Points3* out[2] = {&r.force_a, &r.force_b};
  r.force_a = common::Points3::Zero(models_[p.a]->num_nodes(), 3);
  r.force_b = common::Points3::Zero(models_[p.b]->num_nodes(), 3);
  for (const ContactPoint& c : active) {
    for (int i = 0; i < 4; ++i)
      out[c.side[i]]->row(c.node[i]) += (c.area * c.fade * c.pressure * c.G.segment<3>(3 * i)).transpose();
    r.contact_area_m2 += c.area * c.fade;
  }
  r.total_force_a = r.force_a.colwise().sum().transpose();
  r.total_force_b = r.force_b.colwise().sum().transpose();
  const ContactSurface& sa = p.contact->surface(0);
  const ContactSurface& sb = p.contact->surface(1);
  r.pressure_a = r.force_a.rowwise().norm().cwiseQuotient(sa.vertex_area);
  r.pressure_b = r.force_b.rowwise().norm().cwiseQuotient(sb.vertex_area);
  return r;
}

void CoupledShellSystem::apply_constraints(double t, Eigen::VectorXd& q) const {
  for (int m = 0; m < num_models(); ++m) {
    Eigen::VectorXd qm = segment(m, q);
    models_[m]->apply_constraints(t, qm);
    q.segment(offsets_[m], qm.size()) = qm;
  }
}

void CoupledShellSystem::solve_mass(const Eigen::VectorXd& rhs, Eigen::VectorXd& a) {
  a = Eigen::VectorXd::Zero(n_);
  for (int m = 0; m < num_models(); ++m) {
    ShellModel& model = *models_[m];
    if (!model.has_inertia()) {
      for (char c : model.constrained())
        if (!c)
          throw common::NumericalError("coupled shell system: surface " + names_[m] +
                                       " has free coordinates but no inertia term (dynamic run)");
      continue;
    }
    Eigen::VectorXd am;
    model.solve_mass(segment(m, rhs), am);
    a.segment(offsets_[m], am.size()) = am;
  }
}

void CoupledShellSystem::predict(double t0, double t1, const Eigen::VectorXd& q0, Eigen::VectorXd& q1) const {
  // Without a step before (tp = t0) each model falls back to its predict().
  predict_extrapolated(t0, q0, t0, q0, t1, q1);
}

void CoupledShellSystem::predict_extrapolated(double tp, const Eigen::VectorXd& qp, double t0,
                                              const Eigen::VectorXd& q0, double t1, Eigen::VectorXd& q1) const {
  q1.resize(n_);
  for (int m = 0; m < num_models(); ++m) {
    Eigen::VectorXd qm;
    models_[m]->predict_extrapolated(tp, segment(m, qp), t0, segment(m, q0), t1, qm);
    q1.segment(offsets_[m], qm.size()) = qm;
  }
}

std::string CoupledShellSystem::describe_dof(int i) const {
  const int m = model_of(i);
  return "surface " + names_[m] + ", " + models_[m]->describe_dof(i - offsets_[m]);
}

}  // namespace arthrosim::cartilage
