#include "cartilage/shell_model.h"

#include <omp.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

#include "numerics/sparse_direct_solver.h"
#include "common/effects.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

Eigen::Matrix3d skew(const Eigen::Vector3d& a) {
  Eigen::Matrix3d S;
  S << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
  return S;
}

// ---------------------------------------------------------------------------
// internal_forces: f_int = sum_e dPi_e/dq_e. Elements are evaluated in
// parallel into per-element buffers, then summed serially in element order,
// so the result is bit-identical for any number of threads.
class InternalForcesTerm final : public ShellTerm {
 public:
  explicit InternalForcesTerm(ShellModel& model)
      : ShellTerm("internal_forces"), model_(model), fe_(model.num_elements()), Ke_(model.num_elements()) {}

  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    const int ne = model_.num_elements();
    const bool want_K = K != nullptr;
    auto t0 = std::chrono::steady_clock::now();
#pragma omp parallel for schedule(static) if (ne > 64)
    for (int e = 0; e < ne; ++e) {
      const Vector24 qe = model_.gather(e, ctx.q);
      model_.element(e).internal_force(qe, fe_[e], want_K ? &Ke_[e] : nullptr);
    }
    auto& stats = model_.mutable_statistics();
    stats.element_time_s += seconds_since(t0);
    t0 = std::chrono::steady_clock::now();
    double* values = want_K ? K->matrix().valuePtr() : nullptr;
    for (int e = 0; e < ne; ++e) {
      for (int l = 0; l < 24; ++l) F(model_.global_index(e, l)) += fe_[e](l);
      if (!want_K) continue;
      const int* idx = model_.element_value_indices(e);
      for (int m = 0; m < 24; ++m)
        for (int l = 0; l < 24; ++l) values[idx[24 * l + m]] += ctx.kq * Ke_[e](l, m);
    }
    stats.scatter_time_s += seconds_since(t0);
  }

 private:
  ShellModel& model_;
  mutable std::vector<Vector24> fe_;
  mutable std::vector<Matrix24> Ke_;
};

// ---------------------------------------------------------------------------
// Shared geometry of the foundation terms: per node the reference position,
// unit reference transverse direction and nodal area; the anchor moves with
// the bone: T(t) = X_WB(t) X_WB(0)^-1.
struct FoundationGeometry {
  explicit FoundationGeometry(const ShellModel& model, BoneMotion b) : bone(std::move(b)) {
    if (!bone.pose || !bone.spatial_velocity)
      throw common::InputError("foundation: BoneMotion needs both pose and spatial_velocity callbacks");
    X_WB0_inv = bone.pose(0.0).inverse();
    const int n = model.num_nodes();
    r0.resize(n);
    n0.resize(n);
    area = model.nodal_areas();
    for (int i = 0; i < n; ++i) {
      r0[i] = model.reference_position(i);
      n0[i] = model.reference_director(i).normalized();
    }
  }
  /// Anchor point, direction, their time derivatives at time t for node i.
  void at(double t, const Eigen::Isometry3d& X_WB, const Eigen::Matrix<double, 6, 1>& V, int i,
          Eigen::Vector3d& p, Eigen::Vector3d& n, Eigen::Vector3d& p_dot, Eigen::Vector3d& n_dot) const {
    const Eigen::Isometry3d T = X_WB * X_WB0_inv;
    p = T * r0[i];
    n = T.linear() * n0[i];
    const Eigen::Vector3d w = V.head<3>();
    p_dot = V.tail<3>() + w.cross(p - X_WB.translation());
    n_dot = w.cross(n);
  }
  BoneMotion bone;
  Eigen::Isometry3d X_WB0_inv;
  std::vector<Eigen::Vector3d> r0, n0;
  Eigen::VectorXd area;
};

class FoundationSpringsTerm final : public ShellTerm {
 public:
  FoundationSpringsTerm(const ShellModel& model, Eigen::VectorXd k, BoneMotion bone, bool compressive_only)
      : ShellTerm("foundation_springs"), geo_(model, std::move(bone)), k_(std::move(k)),
        compressive_only_(compressive_only) {
    if (k_.size() != model.num_nodes())
      throw common::InputError("foundation_springs: expected " + std::to_string(model.num_nodes()) +
                               " nodal stiffnesses, found " + std::to_string(k_.size()));
    for (int i = 0; i < k_.size(); ++i)
      if (!(k_(i) >= 0) || !std::isfinite(k_(i)))
        throw common::InputError("foundation_springs: stiffness k must be >= 0 N/m^3, found " +
                                 std::to_string(k_(i)) + " at node " + std::to_string(i));
  }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    const Eigen::Isometry3d X = geo_.bone.pose(ctx.t);
    const Eigen::Matrix<double, 6, 1> V = geo_.bone.spatial_velocity(ctx.t);
    for (size_t i = 0; i < geo_.r0.size(); ++i) {
      Eigen::Vector3d p, n, pd, nd;
      geo_.at(ctx.t, X, V, static_cast<int>(i), p, n, pd, nd);
      const double delta = n.dot(p - ctx.q.segment<3>(6 * i));
      // Compressive-only (the seed's elements). At delta = 0 (the reference
      // state) the spring counts as engaged: zero force but its stiffness in
      // the tangent, so the first Newton step from rest sees the foundation.
      if (compressive_only_ && delta < 0) continue;
      const double kA = k_(static_cast<Eigen::Index>(i)) * geo_.area(i);
      F.segment<3>(6 * i) -= kA * delta * n;
      if (K) K->add_block3(i, 0, i, 0, ctx.kq * kA * n * n.transpose());
    }
  }

 private:
  FoundationGeometry geo_;
  Eigen::VectorXd k_;
  bool compressive_only_;
};

// "periphery_fixed" with the normal left to the foundation: each boundary
// node is tied to its bone-carried anchor p_i(t) in the tangent plane of its
// reference transverse direction n_i(t) only,
//   F_i += k_t A_i (I - n_i n_i^T)(r_i - p_i),  dF_i/dr_i = k_t A_i (I - n_i n_i^T)
// (a penalty tie, symmetric: P depends on t only); its director is free.
class PeripheryTangentialTerm final : public ShellTerm {
 public:
  PeripheryTangentialTerm(const ShellModel& model, std::vector<int> nodes, double k_t, BoneMotion bone)
      : ShellTerm("periphery_fixed"), geo_(model, std::move(bone)), nodes_(std::move(nodes)), k_t_(k_t) {
    if (!(k_t > 0) || !std::isfinite(k_t))
      throw common::InputError("periphery_fixed: tangential tie stiffness must be > 0 N/m^3, found " +
                               std::to_string(k_t));
  }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    const Eigen::Isometry3d X = geo_.bone.pose(ctx.t);
    const Eigen::Matrix<double, 6, 1> V = geo_.bone.spatial_velocity(ctx.t);
    for (int i : nodes_) {
      Eigen::Vector3d p, n, pd, nd;
      geo_.at(ctx.t, X, V, i, p, n, pd, nd);
      const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - n * n.transpose();
      const double kA = k_t_ * geo_.area(i);
      F.segment<3>(6 * i) += kA * P * (ctx.q.segment<3>(6 * i) - p);
      if (K) K->add_block3(i, 0, i, 0, ctx.kq * kA * P);
    }
  }

 private:
  FoundationGeometry geo_;
  std::vector<int> nodes_;
  double k_t_;
};

class FoundationDampingTerm final : public ShellTerm {
 public:
  FoundationDampingTerm(const ShellModel& model, double c, BoneMotion bone, bool compressive_only, double gate)
      : ShellTerm("foundation_damping"), geo_(model, std::move(bone)), c_(c), compressive_only_(compressive_only),
        gate_(gate) {
    if (!(c >= 0) || !std::isfinite(c))
      throw common::InputError("foundation_damping: coefficient c must be >= 0 N s/m^3, found " + std::to_string(c));
    if (compressive_only && !(gate > 0))
      throw common::InputError("foundation_damping: gate width must be > 0 m, found " + std::to_string(gate));
  }
  // The d n/dt term couples positions and velocities asymmetrically when the
  // bone rotates.
  bool symmetric() const override { return geo_.bone.at_rest; }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    const Eigen::Isometry3d X = geo_.bone.pose(ctx.t);
    const Eigen::Matrix<double, 6, 1> V = geo_.bone.spatial_velocity(ctx.t);
    for (size_t i = 0; i < geo_.r0.size(); ++i) {
      Eigen::Vector3d p, n, pd, nd;
      geo_.at(ctx.t, X, V, static_cast<int>(i), p, n, pd, nd);
      const Eigen::Vector3d r = ctx.q.segment<3>(6 * i);
      // Compressive-only: the damper engages with the compression delta
      // through the smoothstep gate H(delta/gate) (0 at delta <= 0, 1 from
      // delta >= gate). A sharp gate would make the force c A delta_dot
      // jump where delta changes sign -- at every node resting on its
      // foundation -- and Newton would not converge there.
      double H = 1, dH = 0;
      if (compressive_only_) {
        const double s = n.dot(p - r) / gate_;
        if (s <= 0) continue;
        if (s < 1) {
          H = s * s * (3 - 2 * s);
          dH = 6 * s * (1 - s) / gate_;
        }
      }
      const Eigen::Vector3d v = ctx.v.segment<3>(6 * i);
      const double delta_dot = nd.dot(p - r) + n.dot(pd - v);
      const double cA = c_ * geo_.area(i);
      F.segment<3>(6 * i) -= cA * delta_dot * H * n;
      if (K) {
        // d/dv: c A H n n^T; d/dr: c A (H n nd^T + delta_dot H' n n^T).
        Eigen::Matrix3d B = (ctx.kv * cA * H + ctx.kq * cA * delta_dot * dH) * n * n.transpose();
        if (!geo_.bone.at_rest) B += ctx.kq * cA * H * n * nd.transpose();
        K->add_block3(i, 0, i, 0, B);
      }
    }
  }

 private:
  FoundationGeometry geo_;
  double c_;
  bool compressive_only_;
  double gate_;
};

// ---------------------------------------------------------------------------
// Follower pressure on the face zeta = zf: external virtual work
//   dW = int p n . dr da = int p (a1 x a2) . dr dxi deta,  a_alpha = dr/dxi_alpha
// at zeta = zf; 2x2 Gauss is exact (integrand bi-quadratic). Tangent of
// F = -f_ext: dF_s/dq_t = -p phi_s (phi_t,xi (-[a2]x) + phi_t,eta [a1]x).
class PressureTerm final : public ShellTerm {
 public:
  PressureTerm(const ShellModel& model, std::string name, double zf, std::function<double(double)> p)
      : ShellTerm(std::move(name)), model_(model), zf_(zf), p_(std::move(p)),
        fe_(model.num_elements()), Ke_(model.num_elements()) {
    if (!(zf >= -1 && zf <= 1))
      throw common::InputError(this->name() + ": face_zeta must be in [-1, 1], found " + std::to_string(zf));
    if (!p_) throw common::InputError(this->name() + ": pressure function is empty");
  }
  bool symmetric() const override { return false; }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    const double p = p_(ctx.t);
    if (!std::isfinite(p)) throw common::NumericalError(name() + ": non-finite pressure at t = " + std::to_string(ctx.t));
    if (p == 0) return;
    const int ne = model_.num_elements();
    const bool want_K = K != nullptr;
    const double g = 1.0 / std::sqrt(3.0);
#pragma omp parallel for schedule(static) if (ne > 64)
    for (int e = 0; e < ne; ++e) {
      const Vector24 qe = model_.gather(e, ctx.q);
      const Eigen::Map<const Eigen::Matrix<double, 3, 8>> Qt(qe.data());
      fe_[e].setZero();
      if (want_K) Ke_[e].setZero();
      for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
          Eigen::Matrix<double, 8, 1> phi;
          Eigen::Matrix<double, 8, 3> dphi;
          model_.element(e).slot_functions(i ? g : -g, j ? g : -g, zf_, phi, dphi);
          const Eigen::Vector3d a1 = Qt * dphi.col(0), a2 = Qt * dphi.col(1);
          const Eigen::Vector3d na = a1.cross(a2);
          for (int s = 0; s < 8; ++s) fe_[e].segment<3>(3 * s) -= p * phi(s) * na;
          if (!want_K) continue;
          const Eigen::Matrix3d S1 = -skew(a2), S2 = skew(a1);
          for (int t = 0; t < 8; ++t) {
            const Eigen::Matrix3d dna = dphi(t, 0) * S1 + dphi(t, 1) * S2;
            for (int s = 0; s < 8; ++s) Ke_[e].block<3, 3>(3 * s, 3 * t) -= p * phi(s) * dna;
          }
        }
    }
    double* values = want_K ? K->matrix().valuePtr() : nullptr;
    for (int e = 0; e < ne; ++e) {
      for (int l = 0; l < 24; ++l) F(model_.global_index(e, l)) += fe_[e](l);
      if (!want_K) continue;
      const int* idx = model_.element_value_indices(e);
      for (int m = 0; m < 24; ++m)
        for (int l = 0; l < 24; ++l) values[idx[24 * l + m]] += ctx.kq * Ke_[e](l, m);
    }
  }

 private:
  const ShellModel& model_;
  double zf_;
  std::function<double(double)> p_;
  mutable std::vector<Vector24> fe_;
  mutable std::vector<Matrix24> Ke_;
};

class PointLoadsTerm final : public ShellTerm {
 public:
  PointLoadsTerm(const ShellModel& model, std::string name, std::vector<std::pair<int, Eigen::Vector3d>> loads,
                 std::function<double(double)> scale)
      : ShellTerm(std::move(name)), loads_(std::move(loads)), scale_(std::move(scale)) {
    for (const auto& [node, f] : loads_)
      if (node < 0 || node >= model.num_nodes() || !f.allFinite())
        throw common::InputError(this->name() + ": node index must be in [0, " + std::to_string(model.num_nodes()) +
                                 ") with a finite force, found node " + std::to_string(node));
    if (!scale_) throw common::InputError(this->name() + ": scale function is empty");
  }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler*) const override {
    const double s = scale_(ctx.t);
    for (const auto& [node, f] : loads_) F.segment<3>(6 * node) -= s * f;
  }

 private:
  std::vector<std::pair<int, Eigen::Vector3d>> loads_;
  std::function<double(double)> scale_;
};

// Conservative director couple: potential -M theta(d), theta the angle of d
// about the axis e; grad theta = (e x d)/|d_perp|^2 and its Hessian
//   [e]x/|d_perp|^2 - 2 (e x d) d_perp^T/|d_perp|^4   (symmetric).
class DirectorMomentsTerm final : public ShellTerm {
 public:
  DirectorMomentsTerm(const ShellModel& model, std::string name, const Eigen::Vector3d& axis,
                      std::vector<std::pair<int, double>> moments, std::function<double(double)> scale)
      : ShellTerm(std::move(name)), e_(axis.normalized()), moments_(std::move(moments)), scale_(std::move(scale)) {
    if (!(axis.norm() > 0) || !axis.allFinite()) throw common::InputError(this->name() + ": axis must be a non-zero vector");
    for (const auto& [node, m] : moments_)
      if (node < 0 || node >= model.num_nodes() || !std::isfinite(m))
        throw common::InputError(this->name() + ": invalid node " + std::to_string(node) + " or moment");
    if (!scale_) throw common::InputError(this->name() + ": scale function is empty");
  }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    const double s = scale_(ctx.t);
    for (const auto& [node, m] : moments_) {
      const Eigen::Vector3d d = ctx.q.segment<3>(6 * node + 3);
      const Eigen::Vector3d dp = d - d.dot(e_) * e_;
      const double r2 = dp.squaredNorm();
      if (!(r2 > 0)) throw common::NumericalError(name() + ": director of node " + std::to_string(node) + " is parallel to the moment axis");
      const Eigen::Vector3d exd = e_.cross(d);
      const double M = s * m;
      F.segment<3>(6 * node + 3) -= M * exd / r2;
      if (K) {
        const Eigen::Matrix3d H = skew(e_) / r2 - 2.0 * exd * dp.transpose() / (r2 * r2);
        K->add_block3(node, 3, node, 3, -ctx.kq * M * H);
      }
    }
  }

 private:
  Eigen::Vector3d e_;
  std::vector<std::pair<int, double>> moments_;
  std::function<double(double)> scale_;
};

class InertiaTerm final : public ShellTerm {
 public:
  explicit InertiaTerm(const ShellModel& model) : ShellTerm("inertia"), model_(model) {}
  bool inertial() const override { return true; }
  void add(const TermContext& ctx, Eigen::VectorXd& Ma, TangentAssembler* K) const override {
    Ma.noalias() += model_.mass_matrix() * ctx.a;
    if (K && ctx.ka != 0) {
      const double* m = model_.mass_matrix().valuePtr();
      double* k = K->matrix().valuePtr();
      const Eigen::Index nnz = model_.mass_matrix().nonZeros();
      for (Eigen::Index i = 0; i < nnz; ++i) k[i] += ctx.ka * m[i];
    }
  }

 private:
  const ShellModel& model_;
};

}  // namespace

BoneMotion BoneMotion::fixed() {
  BoneMotion b;
  b.pose = [](double) { return Eigen::Isometry3d::Identity(); };
  b.spatial_velocity = [](double) { return Eigen::Matrix<double, 6, 1>::Zero().eval(); };
  b.at_rest = true;
  return b;
}

void TangentAssembler::add_element(int e, const Matrix24& Ke) {
  const int* idx = model_.element_value_indices(e);
  double* v = K_.valuePtr();
  for (int m = 0; m < 24; ++m)
    for (int l = 0; l < 24; ++l) v[idx[24 * l + m]] += Ke(l, m);
}

void TangentAssembler::add_block3(int a, int oa, int b, int ob, const Eigen::Matrix3d& B) {
  double* v = K_.valuePtr();
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) {
      const int k = model_.value_index(6 * a + oa + i, 6 * b + ob + j);
      if (k < 0) throw common::NumericalError("TangentAssembler: entry outside the pattern");
      v[k] += B(i, j);
    }
}

ShellModel::ShellModel(const common::QuadMesh& mesh, const common::Points3& directors,
                       const Eigen::VectorXd& thickness_m, const ShellMaterial& material)
    : num_nodes_(mesh.num_nodes()), quads_(mesh.Q), part_(mesh.name) {
  const std::string where = mesh.name.empty() ? std::string("shell mesh") : mesh.name;
  if (num_nodes_ == 0 || mesh.num_quads() == 0) throw common::InputError(where + ": expected a non-empty quad mesh");
  if (directors.rows() != num_nodes_ || thickness_m.size() != num_nodes_)
    throw common::InputError(where + ": expected " + std::to_string(num_nodes_) + " directors and thicknesses, found " +
                             std::to_string(directors.rows()) + " and " + std::to_string(thickness_m.size()));
  for (int e = 0; e < mesh.num_quads(); ++e)
    for (int k = 0; k < 4; ++k)
      if (quads_(e, k) < 0 || quads_(e, k) >= num_nodes_)
        throw common::InputError(where + ": quad " + std::to_string(e) + " has node index " +
                                 std::to_string(quads_(e, k)) + ", expected [0, " + std::to_string(num_nodes_) + ")");
  q0_.resize(6 * num_nodes_);
  weights_.resize(6 * num_nodes_);
  for (int i = 0; i < num_nodes_; ++i) {
    const Eigen::Vector3d D = directors.row(i).transpose();
    if (!(D.norm() > 0) || !D.allFinite())
      throw common::InputError(where + ": node " + std::to_string(i) + " has a zero or non-finite director");
    q0_.segment<3>(6 * i) = mesh.V.row(i).transpose();
    q0_.segment<3>(6 * i + 3) = D.normalized();
    weights_.segment<3>(6 * i).setOnes();
    weights_.segment<3>(6 * i + 3).setConstant(0.5 * thickness_m(i));
  }
  nodal_area_ = Eigen::VectorXd::Zero(num_nodes_);
  elements_.reserve(mesh.num_quads());
  for (int e = 0; e < mesh.num_quads(); ++e) {
    std::array<Eigen::Vector3d, 4> X, D;
    std::array<double, 4> h;
    for (int k = 0; k < 4; ++k) {
      const int n = quads_(e, k);
      X[k] = q0_.segment<3>(6 * n);
      D[k] = q0_.segment<3>(6 * n + 3);
      h[k] = thickness_m(n);
    }
    elements_.push_back(std::make_unique<ShellElement>(X, D, h, material, where + ": quad " + std::to_string(e)));
    for (int k = 0; k < 4; ++k) nodal_area_(quads_(e, k)) += elements_.back()->nodal_areas()[k];
  }
  constrained_.assign(6 * num_nodes_, 0);
  build_pattern();
}

ShellModel::~ShellModel() = default;

void ShellModel::build_pattern() {
  // Node-block pattern: nodes a, b couple iff they share a quad.
  std::vector<std::vector<int>> nb(num_nodes_);
  for (int e = 0; e < quads_.rows(); ++e)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) nb[quads_(e, b)].push_back(quads_(e, a));
  for (auto& v : nb) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
  }
  for (int i = 0; i < num_nodes_; ++i)
    if (nb[i].empty()) throw common::InputError("shell mesh: node " + std::to_string(i) + " belongs to no quad");
  const int n = 6 * num_nodes_;
  std::vector<int> outer(n + 1), inner;
  outer[0] = 0;
  for (int b = 0; b < num_nodes_; ++b)
    for (int j = 0; j < 6; ++j) {
      for (int a : nb[b])
        for (int i = 0; i < 6; ++i) inner.push_back(6 * a + i);
      outer[6 * b + j + 1] = static_cast<int>(inner.size());
    }
  std::vector<double> vals(inner.size(), 0.0);
  pattern_ = Eigen::Map<const Eigen::SparseMatrix<double>>(n, n, static_cast<Eigen::Index>(inner.size()), outer.data(),
                                                           inner.data(), vals.data());
  pattern_.makeCompressed();
  element_index_.resize(576 * quads_.rows());
  for (int e = 0; e < quads_.rows(); ++e)
    for (int l = 0; l < 24; ++l)
      for (int m = 0; m < 24; ++m) element_index_[576 * e + 24 * l + m] = value_index(global_index(e, l), global_index(e, m));
}

int ShellModel::value_index(int row, int col) const {
  const int* inner = pattern_.innerIndexPtr();
  const int begin = pattern_.outerIndexPtr()[col], end = pattern_.outerIndexPtr()[col + 1];
  const int* it = std::lower_bound(inner + begin, inner + end, row);
  if (it == inner + end || *it != row) return -1;
  return static_cast<int>(it - inner);
}

Vector24 ShellModel::gather(int e, const Eigen::VectorXd& x) const {
  Vector24 out;
  for (int k = 0; k < 4; ++k) out.segment<6>(6 * k) = x.segment<6>(6 * quads_(e, k));
  return out;
}

std::vector<int> ShellModel::boundary_nodes() const {
  std::map<std::pair<int, int>, int> count;
  for (int e = 0; e < quads_.rows(); ++e)
    for (int k = 0; k < 4; ++k) {
      int a = quads_(e, k), b = quads_(e, (k + 1) % 4);
      if (a > b) std::swap(a, b);
      ++count[{a, b}];
    }
  std::set<int> out;
  for (const auto& [edge, c] : count)
    if (c == 1) {
      out.insert(edge.first);
      out.insert(edge.second);
    }
  return {out.begin(), out.end()};
}

void ShellModel::record(const std::string& name, long count) {
  built_.push_back(name);
  if (ledger_ && common::find_effect(name)) ledger_->record(name, count, part_);
}

ShellTerm& ShellModel::register_term(std::unique_ptr<ShellTerm> term, long count) {
  for (const auto& t : terms_)
    if (t->name() == term->name()) throw common::InputError("shell model: term '" + term->name() + "' added twice");
  record(term->name(), count);
  terms_.push_back(std::move(term));
  return *terms_.back();
}

ShellTerm& ShellModel::add_internal_forces() {
  return register_term(std::make_unique<InternalForcesTerm>(*this), num_elements());
}

ShellTerm& ShellModel::add_foundation_springs(double k, BoneMotion bone, bool compressive_only) {
  return add_foundation_springs(Eigen::VectorXd::Constant(num_nodes_, k), std::move(bone), compressive_only);
}

ShellTerm& ShellModel::add_foundation_springs(const Eigen::VectorXd& k_per_node, BoneMotion bone,
                                              bool compressive_only) {
  return register_term(std::make_unique<FoundationSpringsTerm>(*this, k_per_node, std::move(bone), compressive_only),
                       num_nodes_);
}

ShellTerm& ShellModel::add_foundation_damping(double c, BoneMotion bone, bool compressive_only, double gate_m) {
  return register_term(std::make_unique<FoundationDampingTerm>(*this, c, std::move(bone), compressive_only, gate_m),
                       num_nodes_);
}

ShellTerm& ShellModel::add_pressure(const std::string& name, double face_zeta, std::function<double(double)> p) {
  return register_term(std::make_unique<PressureTerm>(*this, name, face_zeta, std::move(p)), num_elements());
}

ShellTerm& ShellModel::add_point_loads(const std::string& name, std::vector<std::pair<int, Eigen::Vector3d>> loads,
                                       std::function<double(double)> scale) {
  const long n = static_cast<long>(loads.size());
  return register_term(std::make_unique<PointLoadsTerm>(*this, name, std::move(loads), std::move(scale)), n);
}

ShellTerm& ShellModel::add_director_moments(const std::string& name, const Eigen::Vector3d& axis,
                                            std::vector<std::pair<int, double>> moments,
                                            std::function<double(double)> scale) {
  const long n = static_cast<long>(moments.size());
  return register_term(std::make_unique<DirectorMomentsTerm>(*this, name, axis, std::move(moments), std::move(scale)), n);
}

ShellTerm& ShellModel::add_inertia() {
  // Assemble the constant consistent mass matrix once, in the tangent pattern.
  mass_ = pattern_;
  std::fill(mass_.valuePtr(), mass_.valuePtr() + mass_.nonZeros(), 0.0);
  TangentAssembler A(*this, mass_);
  for (int e = 0; e < num_elements(); ++e) A.add_element(e, elements_[e]->mass());
  has_inertia_ = true;
  return register_term(std::make_unique<InertiaTerm>(*this), num_elements());
}

void ShellModel::fix_nodes(const std::string& name, const std::vector<int>& nodes, std::array<bool, 6> mask) {
  NodeConstraint c;
  c.name = name;
  c.nodes = nodes;
  c.mask = mask;
  const Eigen::VectorXd q0 = q0_;
  c.value = [q0](double, int node, Eigen::Matrix<double, 6, 1>& q6) { q6 = q0.segment<6>(6 * node); };
  add_constraint(std::move(c));
}

ShellTerm& ShellModel::add_periphery_tangential(double k_t_N_m3, BoneMotion bone) {
  std::vector<int> nodes = boundary_nodes();
  const long n = static_cast<long>(nodes.size());
  return register_term(std::make_unique<PeripheryTangentialTerm>(*this, std::move(nodes), k_t_N_m3, std::move(bone)),
                       n);
}

void ShellModel::add_periphery_fixed(BoneMotion bone) {
  if (!bone.pose) throw common::InputError("periphery_fixed: BoneMotion needs a pose callback");
  NodeConstraint c;
  c.name = "periphery_fixed";
  c.nodes = boundary_nodes();
  c.mask.fill(true);
  const Eigen::Isometry3d X0_inv = bone.pose(0.0).inverse();
  const Eigen::VectorXd q0 = q0_;
  auto pose = bone.pose;
  c.value = [q0, X0_inv, pose](double t, int node, Eigen::Matrix<double, 6, 1>& q6) {
    const Eigen::Isometry3d T = pose(t) * X0_inv;
    q6.head<3>() = T * Eigen::Vector3d(q0.segment<3>(6 * node));
    q6.tail<3>() = T.linear() * q0.segment<3>(6 * node + 3);
  };
  add_constraint(std::move(c));
}

void ShellModel::add_constraint(NodeConstraint c) {
  if (!c.value) throw common::InputError("constraint '" + c.name + "': value function is empty");
  for (const auto& existing : constraints_)
    if (existing.name == c.name) throw common::InputError("constraint '" + c.name + "' added twice");
  if (!c.node_masks.empty() && c.node_masks.size() != c.nodes.size())
    throw common::InputError("constraint '" + c.name + "': " + std::to_string(c.node_masks.size()) + " masks for " +
                             std::to_string(c.nodes.size()) + " nodes");
  if (c.frames.size() > 1 && c.frames.size() != c.nodes.size())
    throw common::InputError("constraint '" + c.name + "': " + std::to_string(c.frames.size()) + " frames for " +
                             std::to_string(c.nodes.size()) + " nodes");
  for (const Eigen::Matrix3d& R : c.frames)
    if (!R.allFinite() || !(R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-9))
      throw common::InputError("constraint '" + c.name + "': a local frame is not a rotation (orthonormal columns)");
  for (size_t i = 0; i < c.nodes.size(); ++i) {
    const int node = c.nodes[i];
    if (node < 0 || node >= num_nodes_)
      throw common::InputError("constraint '" + c.name + "': node " + std::to_string(node) + " out of range [0, " +
                               std::to_string(num_nodes_) + ")");
  }
  record(c.name, static_cast<long>(c.nodes.size()));
  constraints_.push_back(std::move(c));
  index_constraints();
}

void ShellModel::index_constraints() {
  // Groups (3 coordinates: a node's position or director) touched by a
  // local-frame constraint become skew groups; every other masked
  // coordinate is eliminated as a world coordinate.
  const int n_groups = 2 * num_nodes_;
  std::vector<int> skew_of(static_cast<size_t>(n_groups), -1);
  skew_groups_.clear();
  for (const auto& c : constraints_) {
    if (c.frames.empty()) continue;
    for (size_t i = 0; i < c.nodes.size(); ++i) {
      const std::array<bool, 6>& mask = c.node_masks.empty() ? c.mask : c.node_masks[i];
      for (int g = 0; g < 2; ++g) {
        const int group = 2 * c.nodes[i] + g;
        if ((mask[3 * g] || mask[3 * g + 1] || mask[3 * g + 2]) && skew_of[static_cast<size_t>(group)] < 0) {
          skew_of[static_cast<size_t>(group)] = static_cast<int>(skew_groups_.size());
          skew_groups_.push_back({group, Eigen::Matrix3d::Zero(), {}});
        }
      }
    }
  }
  constrained_.assign(static_cast<size_t>(6 * num_nodes_), 0);
  for (size_t ci = 0; ci < constraints_.size(); ++ci) {
    const NodeConstraint& c = constraints_[ci];
    for (size_t i = 0; i < c.nodes.size(); ++i) {
      const int node = c.nodes[i];
      const std::array<bool, 6>& mask = c.node_masks.empty() ? c.mask : c.node_masks[i];
      for (int j = 0; j < 6; ++j) {
        if (!mask[j]) continue;
        const int sg = skew_of[static_cast<size_t>(2 * node + j / 3)];
        if (sg < 0) {
          constrained_[6 * node + j] = 1;
          continue;
        }
        const Eigen::Vector3d a = c.frames.empty()       ? Eigen::Vector3d::Unit(j % 3)
                                  : c.frames.size() == 1 ? Eigen::Vector3d(c.frames[0].col(j % 3))
                                                         : Eigen::Vector3d(c.frames[i].col(j % 3));
        skew_groups_[static_cast<size_t>(sg)].held.push_back({static_cast<int>(ci), static_cast<int>(i), j, a});
      }
    }
  }
  for (SkewGroup& s : skew_groups_) {
    // Orthonormal basis of the held directions (SVD; rank by a relative
    // threshold far above round-off of unit vectors).
    Eigen::Matrix<double, 3, Eigen::Dynamic> A(3, static_cast<Eigen::Index>(s.held.size()));
    for (size_t k = 0; k < s.held.size(); ++k) A.col(static_cast<Eigen::Index>(k)) = s.held[k].a;
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullU);
    s.P.setZero();
    for (Eigen::Index k = 0; k < svd.singularValues().size(); ++k)
      if (svd.singularValues()(k) > 1e-8) s.P += svd.matrixU().col(k) * svd.matrixU().col(k).transpose();
  }
}

void ShellModel::apply_constraints(double t, Eigen::VectorXd& q) const {
  for (const auto& c : constraints_)
    for (size_t i = 0; i < c.nodes.size(); ++i) {
      const int node = c.nodes[i];
      Eigen::Matrix<double, 6, 1> q6 = q.segment<6>(6 * node);
      c.value(t, node, q6);
      const std::array<bool, 6>& mask = c.node_masks.empty() ? c.mask : c.node_masks[i];
      for (int j = 0; j < 6; ++j)
        if (mask[j] && constrained_[6 * node + j]) q(6 * node + j) = q6(j);
    }
  // Local-frame groups: the smallest change of x with a_k . x = b_k.
  for (const SkewGroup& s : skew_groups_) {
    const Eigen::Index k = static_cast<Eigen::Index>(s.held.size());
    Eigen::MatrixXd A(k, 3);
    Eigen::VectorXd b(k);
    const int node = s.group / 2;
    for (Eigen::Index r = 0; r < k; ++r) {
      const HeldDirection& h = s.held[static_cast<size_t>(r)];
      Eigen::Matrix<double, 6, 1> q6 = q.segment<6>(6 * node);
      constraints_[static_cast<size_t>(h.constraint)].value(t, node, q6);
      A.row(r) = h.a.transpose();
      b(r) = h.a.dot(q6.segment<3>(3 * (h.coordinate / 3)));
    }
    Eigen::Vector3d x = q.segment<3>(3 * s.group);
    x += A.completeOrthogonalDecomposition().solve(b - A * x);
    q.segment<3>(3 * s.group) = x;
  }
}

void ShellModel::project_vector(Eigen::VectorXd& x) const {
  for (const SkewGroup& s : skew_groups_) {
    const Eigen::Vector3d y = x.segment<3>(3 * s.group);
    x.segment<3>(3 * s.group) = y - s.P * y;
  }
}

void ShellModel::project_matrix(Eigen::SparseMatrix<double>& A) const {
  // T = block diagonal, Q on the local-frame groups, 1 elsewhere; A <- T A T + P.
  const Eigen::Index n = A.rows();
  std::vector<Eigen::Triplet<double>> t, p;
  std::vector<char> skew(static_cast<size_t>(n), 0);
  for (const SkewGroup& s : skew_groups_) {
    const Eigen::Matrix3d Q = Eigen::Matrix3d::Identity() - s.P;
    // P scaled like the group's diagonal: T A T carries round-off of order
    // eps |A| into the held directions, so a unit P would let the solve move
    // the held components by eps |A| / 1 of the increment (1e-7 of it for a
    // thin shell in SI); scaled, by eps of it.
    double scale = 0;
    for (int r = 0; r < 3; ++r) scale = std::max(scale, std::abs(A.coeff(3 * s.group + r, 3 * s.group + r)));
    if (!(scale > 0)) scale = 1;
    for (int r = 0; r < 3; ++r) {
      skew[static_cast<size_t>(3 * s.group + r)] = 1;
      for (int c = 0; c < 3; ++c) {
        t.emplace_back(3 * s.group + r, 3 * s.group + c, Q(r, c));
        p.emplace_back(3 * s.group + r, 3 * s.group + c, scale * s.P(r, c));
      }
    }
  }
  for (Eigen::Index i = 0; i < n; ++i)
    if (!skew[static_cast<size_t>(i)]) t.emplace_back(i, i, 1.0);
  Eigen::SparseMatrix<double> T(n, n), P(n, n);
  T.setFromTriplets(t.begin(), t.end());
  P.setFromTriplets(p.begin(), p.end());
  const Eigen::SparseMatrix<double> B = Eigen::SparseMatrix<double>(T * A * T) + P;
  // Back into A's pattern (node blocks are dense in it, so B's entries are a subset).
  long placed = 0;
  for (int j = 0; j < A.outerSize(); ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(A, j); it; ++it) it.valueRef() = 0;
  for (int j = 0; j < B.outerSize(); ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(B, j); it; ++it) {
      if (it.value() == 0) continue;
      A.coeffRef(it.row(), j) = it.value();  // existing entry: no insertion
      ++placed;
    }
  if (A.nonZeros() != pattern_.nonZeros() && A.rows() == pattern_.rows())
    throw common::NumericalError("shell model: local-frame projection left the tangent pattern");
  (void)placed;
}

bool ShellModel::tangent_symmetric() const {
  for (const auto& t : terms_)
    if (!t->symmetric()) return false;
  return true;
}

std::string ShellModel::describe_dof(int i) const {
  static const char* names[6] = {"r_x", "r_y", "r_z", "d_x", "d_y", "d_z"};
  const std::vector<int> rim = boundary_nodes();  // messages only: not on a hot path
  const bool on_rim = std::binary_search(rim.begin(), rim.end(), i / 6);
  return "node " + std::to_string(i / 6) + (on_rim ? " (rim) " : " ") + names[i % 6];
}

void ShellModel::evaluate(const numerics::EvalRequest& req, Eigen::VectorXd& F, Eigen::VectorXd* Ma,
                          Eigen::SparseMatrix<double>* K) {
  assemble(req, F, Ma, K);
  if (skew_groups_.empty()) return;
  project_vector(F);
  if (Ma) project_vector(*Ma);
  if (K) project_matrix(*K);
}

void ShellModel::evaluate_unprojected(const numerics::EvalRequest& req, Eigen::VectorXd& F,
                                      Eigen::SparseMatrix<double>* K) {
  assemble(req, F, nullptr, K);
}

void ShellModel::assemble(const numerics::EvalRequest& req, Eigen::VectorXd& F, Eigen::VectorXd* Ma,
                          Eigen::SparseMatrix<double>* K) {
  const int n = num_dofs();
  if (!req.q || req.q->size() != n) throw common::NumericalError("ShellModel::evaluate: q has the wrong size");
  static thread_local Eigen::VectorXd zero;
  if (zero.size() != n) zero = Eigen::VectorXd::Zero(n);
  const Eigen::VectorXd& v = req.v ? *req.v : zero;
  const Eigen::VectorXd& a = req.a ? *req.a : zero;
  F.setZero(n);
  if (Ma) Ma->setZero(n);
  ++stats_.evaluations;
  std::unique_ptr<TangentAssembler> assembler;
  if (K) {
    ++stats_.tangent_evaluations;
    if (K->nonZeros() != pattern_.nonZeros() || K->rows() != n) *K = pattern_;
    std::fill(K->valuePtr(), K->valuePtr() + K->nonZeros(), 0.0);
    assembler = std::make_unique<TangentAssembler>(*this, *K);
  }
  TermContext ctx{req.t, *req.q, v, a, req.force_scale * req.kq, req.force_scale * req.kv, req.ka};
  Eigen::VectorXd scratch;
  for (const auto& term : terms_) {
    if (term->inertial()) {
      if (!Ma) continue;
      term->add(ctx, *Ma, assembler.get());
    } else {
      term->add(ctx, F, assembler.get());
    }
    const Eigen::VectorXd& out = term->inertial() ? *Ma : F;
    if (!out.allFinite()) {
      for (int i = 0; i < n; ++i)
        if (!std::isfinite(out(i))) {
          std::ostringstream s;
          s << "shell model: term '" << term->name() << "' produced a non-finite force (" << out(i) << ") at "
            << describe_dof(i) << ", t = " << req.t << " s";
          throw common::NumericalError(s.str());
        }
    }
  }
  if (K && !Eigen::Map<const Eigen::VectorXd>(K->valuePtr(), K->nonZeros()).allFinite())
    throw common::NumericalError("shell model: non-finite tangent entry at t = " + std::to_string(req.t) + " s");
}

void ShellModel::predict(double t0, double t1, const Eigen::VectorXd& q0, Eigen::VectorXd& q1) const {
  q1 = q0;
  if (!has_predictor_) return;
  const Eigen::Isometry3d T = predictor_.pose(t1) * predictor_.pose(t0).inverse();
  for (int i = 0; i < num_nodes_; ++i) {
    q1.segment<3>(6 * i) = T * q0.segment<3>(6 * i);
    q1.segment<3>(6 * i + 3) = T.linear() * q0.segment<3>(6 * i + 3);
  }
}

void ShellModel::predict_extrapolated(double tp, const Eigen::VectorXd& qp, double t0, const Eigen::VectorXd& q0,
                                      double t1, Eigen::VectorXd& q1) const {
  if (!(t0 > tp)) {
    predict(t0, t1, q0, q1);
    return;
  }
  const double s = (t1 - t0) / (t0 - tp);
  if (!has_predictor_) {
    q1 = q0 + s * (q0 - qp);
    return;
  }
  const Eigen::Isometry3d X0 = predictor_.pose(t0);
  const Eigen::Isometry3d Tp0 = X0 * predictor_.pose(tp).inverse();
  const Eigen::Isometry3d T01 = predictor_.pose(t1) * X0.inverse();
  q1.resize(q0.size());
  for (int i = 0; i < num_nodes_; ++i) {
    const Eigen::Vector3d r0 = q0.segment<3>(6 * i), d0 = q0.segment<3>(6 * i + 3);
    const Eigen::Vector3d dr = r0 - Tp0 * Eigen::Vector3d(qp.segment<3>(6 * i));
    const Eigen::Vector3d dd = d0 - Tp0.linear() * qp.segment<3>(6 * i + 3);
    q1.segment<3>(6 * i) = T01 * Eigen::Vector3d(r0 + s * dr);
    q1.segment<3>(6 * i + 3) = T01.linear() * (d0 + s * dd);
  }
}

void ShellModel::solve_mass(const Eigen::VectorXd& rhs, Eigen::VectorXd& a) {
  if (!has_inertia_) throw common::NumericalError("ShellModel::solve_mass: the model has no inertia term");
  if (!mass_solver_) {
    // Constrained rows/columns -> identity (elimination); factor once, reuse.
    Eigen::SparseMatrix<double> M = mass_;
    for (int j = 0; j < M.outerSize(); ++j)
      for (Eigen::SparseMatrix<double>::InnerIterator it(M, j); it; ++it)
        if (constrained_[it.row()] || constrained_[j]) it.valueRef() = (it.row() == j) ? 1.0 : 0.0;
    if (!skew_groups_.empty()) project_matrix(M);
    mass_solver_ = std::make_unique<numerics::SparseDirectSolver>(numerics::LinearSolverKind::kCholmod);
    mass_solver_->analyze(M);
    if (!mass_solver_->factorize(M))
      throw common::NumericalError("shell model: mass matrix factorisation failed: " + mass_solver_->message());
  }
  Eigen::VectorXd b = rhs;
  for (int i = 0; i < b.size(); ++i)
    if (constrained_[i]) b(i) = 0;
  project_vector(b);
  a = mass_solver_->solve(b);
}

common::Points3 quad_mesh_vertex_normals(const common::QuadMesh& mesh) {
  common::Points3 N = common::Points3::Zero(mesh.num_nodes(), 3);
  for (int e = 0; e < mesh.num_quads(); ++e) {
    const Eigen::Vector3d d1 = mesh.V.row(mesh.Q(e, 2)) - mesh.V.row(mesh.Q(e, 0));
    const Eigen::Vector3d d2 = mesh.V.row(mesh.Q(e, 3)) - mesh.V.row(mesh.Q(e, 1));
    const Eigen::Vector3d a = 0.5 * d1.cross(d2);
    for (int k = 0; k < 4; ++k) N.row(mesh.Q(e, k)) += a.transpose();
  }
  for (int i = 0; i < N.rows(); ++i) {
    const double l = N.row(i).norm();
    if (l > 0) N.row(i) /= l;
  }
  return N;
}

}  // namespace arthrosim::cartilage
