#include "cartilage/shell_model.h"

#include <omp.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

#include "cartilage/terms/director_moments.h"
#include "cartilage/terms/foundation_damping.h"
#include "cartilage/terms/foundation_springs.h"
#include "cartilage/terms/inertia.h"
#include "cartilage/terms/internal_forces.h"
#include "cartilage/terms/periphery_fixed.h"
#include "cartilage/terms/point_loads.h"
#include "cartilage/terms/pressure.h"
#include "numerics/sparse_direct_solver.h"
#include "common/effects.h"
#include "common/error.h"

namespace arthrosim::cartilage {

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

void TangentAssembler::add_element_block3(int e, int a, int oa, int b, int ob, const Eigen::Matrix3d& B) {
  const int* idx = model_.element_value_indices(e);
  double* v = K_.valuePtr();
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) v[idx[24 * (6 * a + oa + i) + 6 * b + ob + j]] += B(i, j);
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
  return register_term(make_internal_forces_term(*this), num_elements());
}

ShellTerm& ShellModel::add_foundation_springs(double k, BoneMotion bone, bool compressive_only,
                                              FoundationIntegration integration) {
  return add_foundation_springs(Eigen::VectorXd::Constant(num_nodes_, k), std::move(bone), compressive_only,
                               integration);
}

ShellTerm& ShellModel::add_foundation_springs(const Eigen::VectorXd& k_per_node, BoneMotion bone,
                                              bool compressive_only, FoundationIntegration integration) {
  return register_term(
      make_foundation_springs_term(*this, k_per_node, std::move(bone), compressive_only, integration),
      integration == FoundationIntegration::kNodal ? num_nodes_ : 4 * num_elements());
}

ShellTerm& ShellModel::add_foundation_damping(double c, BoneMotion bone, bool compressive_only, double gate_m) {
  return register_term(make_foundation_damping_term(*this, c, std::move(bone), compressive_only, gate_m),
                       num_nodes_);
}

ShellTerm& ShellModel::add_pressure(const std::string& name, double face_zeta, std::function<double(double)> p) {
  return register_term(make_pressure_term(*this, name, face_zeta, std::move(p)), num_elements());
}

ShellTerm& ShellModel::add_point_loads(const std::string& name, std::vector<std::pair<int, Eigen::Vector3d>> loads,
                                       std::function<double(double)> scale) {
  const long n = static_cast<long>(loads.size());
  return register_term(make_point_loads_term(*this, name, std::move(loads), std::move(scale)), n);
}

ShellTerm& ShellModel::add_director_moments(const std::string& name, const Eigen::Vector3d& axis,
                                            std::vector<std::pair<int, double>> moments,
                                            std::function<double(double)> scale) {
  const long n = static_cast<long>(moments.size());
  return register_term(make_director_moments_term(*this, name, axis, std::move(moments), std::move(scale)), n);
}

ShellTerm& ShellModel::add_inertia() {
  // Assemble the constant consistent mass matrix once, in the tangent pattern.
  mass_ = pattern_;
  std::fill(mass_.valuePtr(), mass_.valuePtr() + mass_.nonZeros(), 0.0);
  TangentAssembler A(*this, mass_);
  for (int e = 0; e < num_elements(); ++e) A.add_element(e, elements_[e]->mass());
  has_inertia_ = true;
  return register_term(make_inertia_term(*this), num_elements());
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
  return register_term(make_periphery_tangential_term(*this, std::move(nodes), k_t_N_m3, std::move(bone)),
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

common::Points3 quad_mesh_vertex_normals(const common::QuadMesh& mesh) { return common::quad_vertex_normals(mesh); }

}  // namespace arthrosim::cartilage
