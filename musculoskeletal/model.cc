#include "musculoskeletal/model.h"

#include <cmath>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

int Model::num_bundles() const {
  int n = 0;
  for (const auto& l : ligaments) n += static_cast<int>(l.bundles.size());
  return n;
}

int Model::ligament_index(const std::string& n) const {
  for (size_t i = 0; i < ligaments.size(); ++i)
    if (ligaments[i].name == n) return static_cast<int>(i);
  return -1;
}

int Model::muscle_index(const std::string& n) const {
  for (size_t i = 0; i < muscles.size(); ++i)
    if (muscles[i].name == n) return static_cast<int>(i);
  return -1;
}

int Model::role_coordinate(const std::string& role) const {
  if (auto it = coordinate_roles.find(role); it != coordinate_roles.end()) return it->second;
  return tree.coordinate_index(role);
}

int Model::role_body(const std::string& role) const {
  if (auto it = body_roles.find(role); it != body_roles.end()) return it->second;
  return tree.body_index(role);
}

int Model::contact_index(const std::string& n) const {
  for (size_t i = 0; i < contacts.size(); ++i)
    if (contacts[i].name() == n) return static_cast<int>(i);
  return -1;
}

double active_force_length(double x, double gamma) {
  if (!(gamma > 0)) throw common::InputError("active_force_length: width gamma must be > 0");
  return std::exp(-(x - 1.0) * (x - 1.0) / gamma);
}

ModelData make_data(const Model& model) {
  ModelData d;
  d.ligaments.resize(model.ligaments.size());
  for (size_t i = 0; i < model.ligaments.size(); ++i)
    d.ligaments[i].resize(model.ligaments[i].bundles.size());
  d.muscle_paths.resize(model.muscles.size());
  d.muscle_forces = Eigen::VectorXd::Zero(model.muscles.size());
  d.muscle_force_length = Eigen::VectorXd::Ones(model.muscles.size());
  d.contacts.resize(model.contacts.size());
  const int n = model.num_coordinates();
  d.Q_ligaments = d.Q_muscles = d.Q_contact = d.Q_springs = d.Q = Eigen::VectorXd::Zero(n);
  d.dQ_dq = Eigen::MatrixXd::Zero(n, n);
  return d;
}

Eigen::VectorXd moment_arms(const Model& model, const ModelData& data, const PathState& path) {
  Eigen::VectorXd r = Eigen::VectorXd::Zero(model.num_coordinates());
  for (const PathApplication& a : path.applications)
    add_point_force(model.tree, data.kinematics, a.body, a.point_W, a.direction_W, r);
  for (const CoordinateForce& f : path.coordinate_forces) r[f.coordinate] += f.force;
  return r;
}

namespace {
void check_finite(const Eigen::VectorXd& v, const std::string& what) {
  if (!v.allFinite()) throw common::NumericalError("musculoskeletal model: non-finite " + what);
}
}  // namespace

namespace {

// Which force terms to evaluate (flattened bundles, muscles, contact pairs);
// a null mask means all of them.
struct TermMask {
  std::vector<char> bundle, muscle, pair;
};

// Forward kinematics at q, then the generalized forces of the terms in
// `mask` (inputs already checked by the caller).
void evaluate_terms(const Model& model, ModelData& d, const Eigen::VectorXd& q,
                    const Eigen::VectorXd& qdot, const Eigen::VectorXd& activations,
                    const ForceOptions& opt, const TermMask* mask) {
  const int n = model.num_coordinates();
  forward_kinematics(model.tree, q, d.kinematics);
  const auto& X = d.kinematics.X_WB;
  d.Q_ligaments.setZero(n);
  d.Q_muscles.setZero(n);
  d.Q_contact.setZero(n);
  d.Q_springs.setZero(n);

  if (opt.coordinate_springs) {
    // Each acts on its own coordinate only (so every Jacobian column gets
    // its -stiffness from the difference quotient, and masks need not know them).
    for (const CoordinateSpring& s : model.coordinate_springs)
      d.Q_springs[s.coordinate] += -s.stiffness * (q[s.coordinate] - s.rest_length) -
                                   s.viscosity * (qdot.size() ? qdot[s.coordinate] : 0.0);
    check_finite(d.Q_springs, "coordinate spring generalized forces");
  }
  if (opt.ligaments) {
    int flat = 0;
    for (size_t li = 0; li < model.ligaments.size(); ++li) {
      const Ligament& lig = model.ligaments[li];
      for (size_t bi = 0; bi < lig.bundles.size(); ++bi, ++flat) {
        if (mask && !mask->bundle[flat]) continue;
        BundleResult& br = d.ligaments[li][bi];
        br.path = evaluate_path(lig.bundles[bi].path, X, q);
        const Eigen::VectorXd r = moment_arms(model, d, br.path);
        const double ldot = qdot.size() ? -r.dot(qdot) : 0.0;
        br.force = blankevoort_force(lig.bundles[bi].parameters, br.path.length, ldot);
        d.Q_ligaments += br.force.total * r;
      }
    }
    check_finite(d.Q_ligaments, "ligament generalized forces");
  }
  if (opt.muscles) {
    for (size_t mi = 0; mi < model.muscles.size(); ++mi) {
      if (mask && !mask->muscle[mi]) continue;
      const Muscle& m = model.muscles[mi];
      const double a = activations.size() ? activations[mi] : 0.0;
      d.muscle_paths[mi] = evaluate_path(m.path, X, q);
      double fl = 1.0;
      if (opt.force_length) {
        if (!(m.optimal_fiber_length > 0) || !(m.tendon_slack_length > 0))
          throw common::InputError(model.source + ": error: muscle '" + m.name +
                                   "': force-length scaling needs optimal_fiber_length and "
                                   "tendon_slack_length (docs/model_format.md)");
        fl = active_force_length(
            (d.muscle_paths[mi].length - m.tendon_slack_length) / m.optimal_fiber_length,
            opt.force_length_width);
      }
      d.muscle_force_length[mi] = fl;
      d.muscle_forces[mi] = a * m.max_isometric_force * fl;
      if (a != 0.0) d.Q_muscles += d.muscle_forces[mi] * moment_arms(model, d, d.muscle_paths[mi]);
    }
    check_finite(d.Q_muscles, "muscle generalized forces");
  }
  if (opt.contact) {
    for (size_t ci = 0; ci < model.contacts.size(); ++ci) {
      if (mask && !mask->pair[ci]) continue;
      const ContactPair& pair = model.contacts[ci];
      const int A = pair.casting().body, B = pair.target().body;
      evaluate_contact(pair, X[A], X[B], d.contacts[ci]);
      const ContactResult& r = d.contacts[ci].result;
      // Wrench about the world origin on each body: Q += J_O^T F + J_w^T M_O.
      add_point_force(model.tree, d.kinematics, A, Vec3::Zero(), r.force_on_casting_W, d.Q_contact);
      add_body_couple(model.tree, d.kinematics, A, r.moment_on_casting_W, d.Q_contact);
      add_point_force(model.tree, d.kinematics, B, Vec3::Zero(), r.force_on_target_W, d.Q_contact);
      add_body_couple(model.tree, d.kinematics, B, r.moment_on_target_W, d.Q_contact);
    }
    check_finite(d.Q_contact, "contact generalized forces");
  }
  d.Q = d.Q_ligaments + d.Q_muscles + d.Q_contact + d.Q_springs;
}

// moved[b]: body b moves when coordinate c changes (b lies below c's joint).
std::vector<char> bodies_moved_by(const KinematicTree& tree, int c) {
  std::vector<char> moved(tree.bodies.size(), 0);
  for (size_t b = 1; b < tree.bodies.size(); ++b) {
    const Joint& j = tree.joints[tree.bodies[b].parent_joint];
    moved[b] = j.coordinate == c || moved[j.parent];  // parents precede children
  }
  return moved;
}

// The terms whose forces or moment arms change with coordinate c: those
// attached to a body that c moves (or with path points that depend on c). The others give the same generalized
// force at q +- h e_c (their bodies, and the joint axes between those bodies
// and the root, do not move), so their difference quotient is exactly zero.
TermMask terms_moved_by(const Model& model, int c) {
  const std::vector<char> moved = bodies_moved_by(model.tree, c);
  TermMask m;
  for (const Ligament& l : model.ligaments)
    for (const LigamentBundle& b : l.bundles) m.bundle.push_back(path_depends_on(b.path, moved, c));
  for (const Muscle& mu : model.muscles) m.muscle.push_back(path_depends_on(mu.path, moved, c));
  for (const ContactPair& p : model.contacts)
    m.pair.push_back(moved[p.casting().body] || moved[p.target().body]);
  return m;
}

}  // namespace

void evaluate_forces(const Model& model, ModelData& d, const Eigen::VectorXd& q,
                     const Eigen::VectorXd& qdot, const Eigen::VectorXd& activations,
                     const ForceOptions& opt) {
  const int n = model.num_coordinates();
  if (q.size() != n || (qdot.size() != 0 && qdot.size() != n))
    throw common::InputError("evaluate_forces: expected q (and qdot, or empty) of size " +
                             std::to_string(n));
  if (activations.size() != 0 && activations.size() != static_cast<int>(model.muscles.size()))
    throw common::InputError("evaluate_forces: expected " + std::to_string(model.muscles.size()) +
                             " activations (or none), found " +
                             std::to_string(activations.size()));
  check_finite(q, "coordinates q");
  if (d.ligaments.size() != model.ligaments.size() || d.contacts.size() != model.contacts.size())
    d = make_data(model);
  evaluate_terms(model, d, q, qdot, activations, opt, nullptr);
}

void evaluate_jacobian(const Model& model, ModelData& d, const Eigen::VectorXd& q,
                       const Eigen::VectorXd& qdot, const Eigen::VectorXd& activations,
                       const ForceOptions& opt, const std::vector<int>& columns) {
  const int n = model.num_coordinates();
  std::vector<int> cols = columns;
  if (cols.empty())
    for (int i = 0; i < n; ++i) cols.push_back(i);
  // The centre first: checks the inputs and leaves its results in d.
  evaluate_forces(model, d, q, qdot, activations, opt);
  ModelData work = make_data(model);
  work.contacts = d.contacts;  // warm search caches
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(n, n);
  const double h = opt.jacobian_step;
  for (int c : cols) {
    Eigen::VectorXd qp = q, qm = q;
    qp[c] += h;
    qm[c] -= h;
    TermMask mask;
    if (opt.jacobian_skip_unmoved_terms) mask = terms_moved_by(model, c);
    const TermMask* m = opt.jacobian_skip_unmoved_terms ? &mask : nullptr;
    evaluate_terms(model, work, qp, qdot, activations, opt, m);
    const Eigen::VectorXd Qp = work.Q;
    evaluate_terms(model, work, qm, qdot, activations, opt, m);
    J.col(c) = (Qp - work.Q) / (2 * h);
  }
  d.dQ_dq = J;
}

}  // namespace arthrosim::musculoskeletal
