#include "musculoskeletal/comak.h"

#include <IpIpoptApplication.hpp>
#include <IpTNLP.hpp>
#include <IpoptConfig.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <functional>
#include <limits>
#include <sstream>

#include "common/error.h"
#include "common/finite.h"
#include "common/log.h"
#include "common/metadata.h"

namespace arthrosim::musculoskeletal {

namespace {

int require_coordinate(const Model& m, const std::string& name) {
  const int i = m.tree.coordinate_index(name);
  if (i < 0)
    throw common::InputError(m.source + ": error: COMAK needs the coordinate '" + name +
                             "', the model has none");
  return i;
}

const Joint* joint_of(const Model& m, int coordinate) {
  for (const Joint& j : m.tree.joints)
    if (j.coordinate == coordinate) return &j;
  return nullptr;
}

const char* ipopt_status_name(int s) {
  switch (s) {
    case Ipopt::Solve_Succeeded: return "Solve_Succeeded";
    case Ipopt::Solved_To_Acceptable_Level: return "Solved_To_Acceptable_Level";
    case Ipopt::Infeasible_Problem_Detected: return "Infeasible_Problem_Detected";
    case Ipopt::Search_Direction_Becomes_Too_Small: return "Search_Direction_Becomes_Too_Small";
    case Ipopt::Diverging_Iterates: return "Diverging_Iterates";
    case Ipopt::User_Requested_Stop: return "User_Requested_Stop";
    case Ipopt::Feasible_Point_Found: return "Feasible_Point_Found";
    case Ipopt::Maximum_Iterations_Exceeded: return "Maximum_Iterations_Exceeded";
    case Ipopt::Restoration_Failed: return "Restoration_Failed";
    case Ipopt::Error_In_Step_Computation: return "Error_In_Step_Computation";
    case Ipopt::Maximum_CpuTime_Exceeded: return "Maximum_CpuTime_Exceeded";
    case Ipopt::Not_Enough_Degrees_Of_Freedom: return "Not_Enough_Degrees_Of_Freedom";
    case Ipopt::Invalid_Problem_Definition: return "Invalid_Problem_Definition";
    case Ipopt::Invalid_Option: return "Invalid_Option";
    case Ipopt::Invalid_Number_Detected: return "Invalid_Number_Detected";
    case Ipopt::Unrecoverable_Exception: return "Unrecoverable_Exception";
    case Ipopt::NonIpopt_Exception_Thrown: return "NonIpopt_Exception_Thrown";
    case Ipopt::Insufficient_Memory: return "Insufficient_Memory";
    default: return "Internal_Error";
  }
}

std::string frame_name(const ComakFrameInput& in) {
  std::ostringstream s;
  s << "COMAK frame " << in.index << " (t = " << in.time << " s)";
  return s.str();
}

// Throws NumericalError naming the frame (and where its input came from)
// if any input of the frame is not finite.
void check_frame_input(const ComakFrameInput& in) {
  if (!in.invalid_input.empty())
    throw common::NumericalError(frame_name(in) + ": trial input not finite: " + in.invalid_input);
  Eigen::VectorXd v(12);
  v << in.time, in.knee_flexion, in.hip_angles, in.ankle_flexion, in.F_ext_T, in.M_ext_T;
  common::check_finite(v, frame_name(in) +
                              ": input (time, knee flexion, hip flexion/adduction/rotation, ankle "
                              "flexion, F_ext_T xyz, M_ext_T xyz)");
  if (in.has_foot_load) {
    Eigen::VectorXd u(9);
    u << in.F_foot_T, in.M_foot_T, in.ankle_centre_T;
    common::check_finite(u, frame_name(in) + ": foot load (F_foot_T xyz, M_foot_T xyz, ankle centre xyz)");
  }
}

}  // namespace

const char* to_string(ComakFrameStatus s) {
  return s == ComakFrameStatus::kConverged ? "converged" : "failed";
}

// ---------------------------------------------------------------- problem --

ComakProblem::ComakProblem(const Model& model, const ComakOptions& options)
    : model_(model), options_(options) {
  if (!(options.activation_min >= 0.0 && options.activation_min < 1.0))
    throw common::InputError("COMAK: activation_min must be in [0, 1), found " +
                             std::to_string(options.activation_min));
  if (!(options.length_scale > 0) || !(options.force_tolerance > 0) || !(options.muscle_stress > 0))
    throw common::InputError("COMAK: length_scale, force_tolerance and muscle_stress must be > 0");
  if (options.retries < 0 || options.retries > 3)
    throw common::InputError("COMAK: retries must be 0, 1, 2 or 3, found " +
                             std::to_string(options.retries));
  if (!(options.move_limit_m > 0) || !(options.move_limit_rad > 0) || options.move_limit_rounds < 1 ||
      !(options.second_start_move_limit_scale > 0) ||
      options.move_limit_iterations < 1)
    throw common::InputError("COMAK: move limits must be positive and rounds and iterations >= 1");
  flexion_ = require_coordinate(model, "knee_flexion");
  hip_[0] = require_coordinate(model, "hip_flexion");
  hip_[1] = require_coordinate(model, "hip_adduction");
  hip_[2] = require_coordinate(model, "hip_rotation");
  ankle_ = require_coordinate(model, "ankle_flexion");
  tibia_ = model.tree.body_index("tibia");
  if (tibia_ < 0) throw common::InputError(model.source + ": error: COMAK needs a body 'tibia'");
  inertial_bodies_ = {tibia_};
  if (const int patella = model.tree.body_index("patella"); patella >= 0)
    inertial_bodies_.push_back(patella);
  free_ = model.free_coordinates;
  if (std::find(free_.begin(), free_.end(), flexion_) == free_.end())
    throw common::InputError(model.source + ": error: knee_flexion must be a free coordinate");
  for (int c : free_) {
    if (c != flexion_) secondary_.push_back(c);
    const Joint* j = joint_of(model, c);
    revolute_.push_back(j && j->type == JointType::kRevolute);
  }
  rows_ = free_;
  if (options.ankle_equilibrium) {
    const Joint* j = joint_of(model, ankle_);
    if (!j || j->type != JointType::kRevolute || j->parent != tibia_)
      throw common::InputError(model.source + ": error: COMAK ankle equilibrium needs 'ankle_flexion' "
                               "to be a revolute joint whose parent is the tibia");
    ankle_axis_T_ = j->X_PJ.linear() * j->axis_J;
    ankle_origin_T_ = j->X_PJ.translation();
    rows_.push_back(ankle_);
    revolute_.push_back(true);
  }
  const int nr = static_cast<int>(rows_.size());
  row_scale_.resize(nr);
  for (int k = 0; k < nr; ++k) row_scale_[k] = revolute_[k] ? 1.0 / options.length_scale : 1.0;

  // Volume weights from the path length at q = 0 (stand-in for l_opt).
  const int nm = static_cast<int>(model.muscles.size());
  V_.resize(nm);
  w_ = Eigen::VectorXd::Ones(nm);
  KinematicsData kin;
  forward_kinematics(model.tree, Eigen::VectorXd::Zero(model.num_coordinates()), kin);
  for (int i = 0; i < nm; ++i) {
    const PathState p = evaluate_path(model.muscles[i].path, kin.X_WB, Eigen::VectorXd::Zero(model.num_coordinates()));
    V_[i] = model.muscles[i].max_isometric_force * p.length / options.muscle_stress;
  }
  if (options.ankle_equilibrium) {
    // The ankle row must be balanceable both ways: plantarflexors (moment
    // arm < 0 about the dorsiflexion axis) for push-off and dorsiflexors for
    // the heel-strike moment. Checked at q = 0.
    KinematicsData k0;
    forward_kinematics(model.tree, Eigen::VectorXd::Zero(model.num_coordinates()), k0);
    ModelData d0 = make_data(model);
    d0.kinematics = k0;
    bool plantar = false, dorsi = false;
    for (int i = 0; i < nm; ++i) {
      const double r = moment_arms(
          model, d0, evaluate_path(model.muscles[i].path, k0.X_WB, Eigen::VectorXd::Zero(model.num_coordinates())))[ankle_];
      plantar = plantar || r < -1e-3;
      dorsi = dorsi || r > 1e-3;
    }
    if (!plantar || !dorsi)
      throw common::InputError(model.source + ": error: COMAK ankle equilibrium: the model has no " +
                               std::string(!plantar ? "plantarflexor" : "dorsiflexor") +
                               " (a muscle with an ankle moment arm beyond 1 mm of that sign at q "
                               "= 0); add the uniarticular ankle muscles (add_ankle_muscles, "
                               "arthrosim-comak --ankle-equilibrium does)");
  }
  for (const auto& [name, w] : options.muscle_weights) {
    const int i = model.muscle_index(name);
    if (i < 0) throw common::InputError("COMAK: weight given for unknown muscle '" + name + "'");
    if (!(w > 0)) throw common::InputError("COMAK: weight of muscle '" + name + "' must be > 0");
    w_[i] = w;
  }
}

Eigen::VectorXd ComakProblem::coordinates(const ComakFrameInput& in,
                                          const Eigen::VectorXd& q_source) const {
  Eigen::VectorXd q = q_source.size() == model_.num_coordinates()
                          ? q_source
                          : Eigen::VectorXd::Zero(model_.num_coordinates());
  q[flexion_] = in.knee_flexion;
  for (int k = 0; k < 3; ++k) q[hip_[k]] = in.hip_angles[k];
  q[ankle_] = in.ankle_flexion;
  return q;
}

Eigen::VectorXd ComakProblem::external_generalized_force(const ModelData& data,
                                                         const ComakFrameInput& in) const {
  Eigen::VectorXd Q = Eigen::VectorXd::Zero(model_.num_coordinates());
  const Pose& X_WT = data.kinematics.X_WB[tibia_];
  const Eigen::Matrix3d R_WT = X_WT.linear();
  // With body_inertia the shank's weight and d'Alembert terms of the inverse
  // dynamics are left out: the load is the foot's, moved from the ankle
  // centre to the knee centre (the tibia origin); the tibia body's own terms
  // come from inertial_generalized_force.
  const Vec3 F_T = options_.body_inertia ? Vec3(in.F_foot_T) : Vec3(in.F_ext_T);
  const Vec3 M_T = options_.body_inertia ? Vec3(in.M_foot_T + in.ankle_centre_T.cross(in.F_foot_T))
                                         : Vec3(in.M_ext_T);
  add_point_force(model_.tree, data.kinematics, tibia_, X_WT.translation(), R_WT * F_T, Q);
  add_body_couple(model_.tree, data.kinematics, tibia_, R_WT * M_T, Q);
  if (options_.ankle_equilibrium) Q[ankle_] += external_ankle_moment(in);
  return Q;
}

Eigen::VectorXd ComakProblem::inertial_generalized_force(const Eigen::VectorXd& q,
                                                         const ComakFrameInput& in) const {
  Eigen::VectorXd Q = Eigen::VectorXd::Zero(model_.num_coordinates());
  if (!options_.body_inertia) return Q;
  if (!in.has_femur_motion)
    throw common::InputError(frame_name(in) + ": COMAK body inertia needs the femur's lab motion "
                             "(comak_frame_inputs with the leg model of the inverse dynamics)");
  RootMotion m = in.femur_motion;
  m.coordinate = flexion_;
  add_inertial_forces(model_.tree, q, inertial_bodies_, m, Q);
  return Q;
}

double ComakProblem::external_ankle_moment(const ComakFrameInput& in) const {
  if (!options_.ankle_equilibrium) return 0.0;
  // The foot's load is given about the leg model's ankle centre; moved to a
  // point on the model's ankle axis, projected on that axis.
  const Vec3 M = in.M_foot_T + (in.ankle_centre_T - ankle_origin_T_).cross(in.F_foot_T);
  return ankle_axis_T_.dot(M);
}

Eigen::VectorXd ComakProblem::residual(ModelData& data, const ComakFrameInput& in,
                                       const Eigen::VectorXd& q, const Eigen::VectorXd& a,
                                       const Eigen::VectorXd& e) const {
  evaluate_forces(model_, data, q, Eigen::VectorXd(), a, options_.forces);
  Eigen::VectorXd Qe = external_generalized_force(data, in);
  if (options_.body_inertia) Qe += inertial_generalized_force(q, in);
  const int nr = num_rows();
  Eigen::VectorXd r(nr);
  for (int k = 0; k < nr; ++k)
    r[k] = data.Q[rows_[k]] + Qe[rows_[k]] + (k < e.size() ? e[k] : 0.0);
  return r;
}

Eigen::MatrixXd ComakProblem::residual_jacobian(ModelData& data, const ComakFrameInput& in,
                                                const Eigen::VectorXd& q,
                                                const Eigen::VectorXd& a) const {
  const int nf = num_rows();
  const int nm = static_cast<int>(model_.muscles.size());
  const int ns = static_cast<int>(secondary_.size());
  // dQ/ds of the internal forces (central differences in model.cc).
  evaluate_jacobian(model_, data, q, Eigen::VectorXd(), a, options_.forces, secondary_);
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(nf, nm + ns);
  // Activation part: exact, Q_muscles = sum a_i F_max,i r_i(q).
  if (options_.forces.muscles) {
    for (int i = 0; i < nm; ++i) {
      const Eigen::VectorXd r = moment_arms(model_, data, data.muscle_paths[i]);
      // With force-length scaling F = a F_max f_L(l(q)): still linear in a.
      const double F = model_.muscles[i].max_isometric_force * data.muscle_force_length[i];
      for (int k = 0; k < nf; ++k) J(k, i) = F * r[rows_[k]];
    }
  }
  // dQ_ext/ds by central differences of the kinematics (same step).
  const double h = options_.forces.jacobian_step;
  ModelData work;
  for (int c = 0; c < ns; ++c) {
    Eigen::VectorXd qp = q, qm = q;
    qp[secondary_[c]] += h;
    qm[secondary_[c]] -= h;
    forward_kinematics(model_.tree, qp, work.kinematics);
    Eigen::VectorXd Qp = external_generalized_force(work, in);
    forward_kinematics(model_.tree, qm, work.kinematics);
    Eigen::VectorXd Qm = external_generalized_force(work, in);
    if (options_.body_inertia) {
      Qp += inertial_generalized_force(qp, in);
      Qm += inertial_generalized_force(qm, in);
    }
    for (int k = 0; k < nf; ++k)
      J(k, nm + c) = data.dQ_dq(rows_[k], secondary_[c]) + (Qp[rows_[k]] - Qm[rows_[k]]) / (2 * h);
  }
  return J;
}

double ComakProblem::objective(const Eigen::VectorXd& a, const Eigen::VectorXd& e) const {
  double f = 0.0;
  for (int i = 0; i < a.size(); ++i) f += w_[i] * V_[i] * a[i] * a[i];
  if (e.size()) {
    const double Vbar = (w_.array() * V_.array()).mean();
    const double r = options_.reserve_reference;
    for (int k = 0; k < e.size(); ++k) f += options_.reserve_weight * Vbar * (e[k] / r) * (e[k] / r);
  }
  return f;
}

// -------------------------------------------------------------- Ipopt NLP --

namespace {

// x = [a (nm), s (ns), e (ns reserves, only with reserve_actuators)].
// g = S_k (Q + Q_ext + e)_k over the free coordinates.
class FrameNlp : public Ipopt::TNLP {
 public:
  FrameNlp(const ComakProblem& p, ModelData& data, const ComakFrameInput& in,
           const Eigen::VectorXd& x0)
      : p_(p), data_(data), in_(in), x0_(x0) {
    nm_ = static_cast<int>(p.model().muscles.size());
    ns_ = static_cast<int>(p.secondary_coordinates().size());
    nf_ = p.num_rows();
    ne_ = p.options().reserve_actuators ? ns_ : 0;
    q_base_ = p.coordinates(in, Eigen::VectorXd());
    x_best_ = x0;
  }

  int n() const { return nm_ + ns_ + ne_; }

  bool get_nlp_info(Ipopt::Index& n, Ipopt::Index& m, Ipopt::Index& nnz_jac,
                    Ipopt::Index& nnz_h, IndexStyleEnum& style) override {
    n = this->n();
    m = nf_;
    nnz_jac = nf_ * (nm_ + ns_) + ne_;
    nnz_h = 0;
    style = C_STYLE;
    return true;
  }

  bool get_bounds_info(Ipopt::Index n, Ipopt::Number* xl, Ipopt::Number* xu, Ipopt::Index m,
                       Ipopt::Number* gl, Ipopt::Number* gu) override {
    for (int i = 0; i < nm_; ++i) xl[i] = p_.options().activation_min, xu[i] = 1.0;
    for (int c = 0; c < ns_; ++c) {
      const Joint* j = joint_of(p_.model(), p_.secondary_coordinates()[c]);
      xl[nm_ + c] = std::max(j->lower, -1e19);
      xu[nm_ + c] = std::min(j->upper, 1e19);
      if (box_half_.size() == ns_) {  // a move limit around the start (step control)
        xl[nm_ + c] = std::max(xl[nm_ + c], x0_[nm_ + c] - box_half_[c]);
        xu[nm_ + c] = std::min(xu[nm_ + c], x0_[nm_ + c] + box_half_[c]);
      }
    }
    for (int k = 0; k < ne_; ++k) xl[nm_ + ns_ + k] = -1e19, xu[nm_ + ns_ + k] = 1e19;
    for (int k = 0; k < m; ++k) gl[k] = gu[k] = 0.0;
    (void)n;
    return true;
  }

  bool get_starting_point(Ipopt::Index n, bool init_x, Ipopt::Number* x, bool init_z,
                          Ipopt::Number* zl, Ipopt::Number* zu, Ipopt::Index m, bool init_lambda,
                          Ipopt::Number* lambda) override {
    if (!init_x) return false;
    for (int i = 0; i < n; ++i) x[i] = x0_[i];
    if (init_z || init_lambda) {
      // Only asked for with warm_start_init_point (set when warm_ is given).
      if (!warm_ || warm_->lambda.size() != m || warm_->z_lower.size() != n) return false;
      for (int i = 0; i < n; ++i) zl[i] = warm_->z_lower[i], zu[i] = warm_->z_upper[i];
      for (int k = 0; k < m; ++k) lambda[k] = warm_->lambda[k];
    }
    return true;
  }

  bool get_scaling_parameters(Ipopt::Number& obj_scaling, bool& use_x, Ipopt::Index n,
                              Ipopt::Number* xs, bool& use_g, Ipopt::Index m,
                              Ipopt::Number* gs) override {
    obj_scaling = 1.0 / (p_.muscle_weights().array() * p_.volume_weights().array()).sum();
    use_x = true;
    for (int i = 0; i < n; ++i) xs[i] = 1.0;
    const double L = p_.options().length_scale;
    for (int c = 0; c < ns_; ++c) {
      const int k = secondary_row(c);
      xs[nm_ + c] = p_.revolute(k) ? 1.0 : 1.0 / L;
    }
    for (int k = 0; k < ne_; ++k) xs[nm_ + ns_ + k] = 1.0 / p_.options().reserve_reference;
    // Constraints are force-equivalents [N]; 1 scaled unit = kForceUnit N.
    use_g = true;
    for (int k = 0; k < m; ++k) gs[k] = 1.0 / kForceUnit;
    return true;
  }

  bool eval_f(Ipopt::Index, const Ipopt::Number* x, bool, Ipopt::Number& f) override {
    Eigen::Map<const Eigen::VectorXd> X(x, n());
    f = p_.objective(X.head(nm_), X.tail(ne_));
    return std::isfinite(f);
  }

  bool eval_grad_f(Ipopt::Index, const Ipopt::Number* x, bool, Ipopt::Number* g) override {
    for (int i = 0; i < nm_; ++i)
      g[i] = 2.0 * p_.muscle_weights()[i] * p_.volume_weights()[i] * x[i];
    for (int c = 0; c < ns_; ++c) g[nm_ + c] = 0.0;
    if (ne_) {
      const double Vbar = (p_.muscle_weights().array() * p_.volume_weights().array()).mean();
      const double r = p_.options().reserve_reference;
      for (int k = 0; k < ne_; ++k)
        g[nm_ + ns_ + k] = 2.0 * p_.options().reserve_weight * Vbar * x[nm_ + ns_ + k] / (r * r);
    }
    return true;
  }

  bool eval_g(Ipopt::Index, const Ipopt::Number* x, bool, Ipopt::Index, Ipopt::Number* g) override {
    try {
      const Eigen::VectorXd r = residual_at(x);
      for (int k = 0; k < nf_; ++k) g[k] = p_.row_scale()[k] * r[k];
      return r.allFinite();
    } catch (...) {
      error_ = std::current_exception();
      return false;
    }
  }

  bool eval_jac_g(Ipopt::Index, const Ipopt::Number* x, bool, Ipopt::Index, Ipopt::Index,
                  Ipopt::Index* rows, Ipopt::Index* cols, Ipopt::Number* v) override {
    if (!v) {
      int e = 0;
      for (int k = 0; k < nf_; ++k)
        for (int j = 0; j < nm_ + ns_; ++j) rows[e] = k, cols[e] = j, ++e;
      for (int c = 0; c < ne_; ++c) rows[e] = secondary_row(c), cols[e] = nm_ + ns_ + c, ++e;
      return true;
    }
    try {
      Eigen::Map<const Eigen::VectorXd> X(x, n());
      const Eigen::MatrixXd J = p_.residual_jacobian(data_, in_, q_of(x), X.head(nm_));
      if (!J.allFinite()) return false;
      int e = 0;
      for (int k = 0; k < nf_; ++k)
        for (int j = 0; j < nm_ + ns_; ++j) v[e++] = p_.row_scale()[k] * J(k, j);
      for (int c = 0; c < ne_; ++c) v[e++] = p_.row_scale()[secondary_row(c)];
      return true;
    } catch (...) {
      error_ = std::current_exception();
      return false;
    }
  }

  bool intermediate_callback(Ipopt::AlgorithmMode, Ipopt::Index iter, Ipopt::Number,
                             Ipopt::Number, Ipopt::Number, Ipopt::Number, Ipopt::Number,
                             Ipopt::Number, Ipopt::Number, Ipopt::Number, Ipopt::Index,
                             const Ipopt::IpoptData*, Ipopt::IpoptCalculatedQuantities*) override {
    iterations_ = iter;
    return !error_;  // a non-finite evaluation stops the solve at once
  }

  void finalize_solution(Ipopt::SolverReturn, Ipopt::Index n, const Ipopt::Number* x,
                         const Ipopt::Number* zl, const Ipopt::Number* zu, Ipopt::Index m,
                         const Ipopt::Number*, const Ipopt::Number* lambda, Ipopt::Number,
                         const Ipopt::IpoptData*, Ipopt::IpoptCalculatedQuantities*) override {
    x_best_ = Eigen::Map<const Eigen::VectorXd>(x, n);
    final_.z_lower = Eigen::Map<const Eigen::VectorXd>(zl, n);
    final_.z_upper = Eigen::Map<const Eigen::VectorXd>(zu, n);
    final_.lambda = Eigen::Map<const Eigen::VectorXd>(lambda, m);
  }

  Eigen::VectorXd q_of(const Ipopt::Number* x) const {
    Eigen::VectorXd q = q_base_;
    for (int c = 0; c < ns_; ++c) q[p_.secondary_coordinates()[c]] = x[nm_ + c];
    return q;
  }

  Eigen::VectorXd residual_at(const Ipopt::Number* x) {
    Eigen::Map<const Eigen::VectorXd> X(x, n());
    Eigen::VectorXd e = Eigen::VectorXd::Zero(ne_ ? p_.free_coordinates().size() : 0);
    for (int c = 0; c < ne_; ++c) e[secondary_row(c)] = X[nm_ + ns_ + c];
    return p_.residual(data_, in_, q_of(x), X.head(nm_), e);
  }

  int secondary_row(int c) const {
    const auto& f = p_.free_coordinates();
    return static_cast<int>(std::find(f.begin(), f.end(), p_.secondary_coordinates()[c]) - f.begin());
  }

  static constexpr double kForceUnit = 100.0;  ///< [N] per scaled constraint unit

  const Eigen::VectorXd& solution() const { return x_best_; }
  const ComakMultipliers& multipliers() const { return final_; }
  void set_warm(const ComakMultipliers* w) { warm_ = w; }
  /// Limits each secondary coordinate to x0 +- half[c] (besides its joint
  /// limits); empty: joint limits only.
  void set_move_limit(const Eigen::VectorXd& half) { box_half_ = half; }
  int iterations() const { return iterations_; }
  std::exception_ptr error() const { return error_; }
  int nm() const { return nm_; }
  int ns() const { return ns_; }
  int ne() const { return ne_; }

 private:
  const ComakProblem& p_;
  ModelData& data_;
  const ComakFrameInput& in_;
  Eigen::VectorXd x0_, x_best_, q_base_, box_half_;
  const ComakMultipliers* warm_ = nullptr;
  ComakMultipliers final_;
  int nm_ = 0, ns_ = 0, nf_ = 0, ne_ = 0;
  int iterations_ = 0;
  std::exception_ptr error_;
};

struct Attempt {
  int status = 0;
  int iterations = 0;
  Eigen::VectorXd x;
  ComakMultipliers multipliers;
};

Attempt run_ipopt(const ComakProblem& p, ModelData& data, const ComakFrameInput& in,
                  const Eigen::VectorXd& x0, bool robust, const ComakMultipliers* warm,
                  const Eigen::VectorXd& move_limit = {}) {
  Ipopt::SmartPtr<FrameNlp> nlp = new FrameNlp(p, data, in, x0);
  nlp->set_move_limit(move_limit);
  const bool use_warm = warm && warm->lambda.size() == p.num_rows() &&
                        warm->z_lower.size() == x0.size();
  nlp->set_warm(use_warm ? warm : nullptr);
  Ipopt::SmartPtr<Ipopt::IpoptApplication> app = IpoptApplicationFactory();
  const ComakOptions& o = p.options();
  auto& opt = *app->Options();
  opt.SetIntegerValue("print_level", o.print_level);
  opt.SetStringValue("sb", "yes");
  opt.SetStringValue("hessian_approximation", "limited-memory");
  opt.SetStringValue("nlp_scaling_method", "user-scaling");
  opt.SetNumericValue("tol", o.ipopt_tolerance);
  opt.SetNumericValue("acceptable_tol", o.ipopt_acceptable_tolerance);
  opt.SetNumericValue("constr_viol_tol", o.force_tolerance);
  opt.SetNumericValue("acceptable_constr_viol_tol", o.force_tolerance);
  opt.SetIntegerValue("max_iter", robust                ? 2 * o.max_iterations
                                  : move_limit.size() ? std::min(o.move_limit_iterations, o.max_iterations)
                                                      : o.max_iterations);
  // A warm start is close to the solution: a small initial barrier keeps it
  // there instead of pushing activations to the middle of their bounds.
  opt.SetNumericValue("mu_init", 1e-3);
  opt.SetIntegerValue("acceptable_iter", o.acceptable_iterations);
  if (robust) opt.SetStringValue("mu_strategy", "adaptive");
  if (use_warm) {
    // Primal-dual warm start from the previous frame (multipliers of the
    // equilibrium rows and of the bounds), barrier started near its final value.
    opt.SetStringValue("warm_start_init_point", "yes");
    opt.SetNumericValue("warm_start_bound_push", 1e-9);
    opt.SetNumericValue("warm_start_mult_bound_push", 1e-9);
    opt.SetNumericValue("mu_init", 1e-7);
  }
  if (app->Initialize() != Ipopt::Solve_Succeeded)
    throw std::logic_error("COMAK: Ipopt failed to initialise");
  Attempt a;
  a.status = app->OptimizeTNLP(nlp);
  if (nlp->error()) {
    try {
      std::rethrow_exception(nlp->error());
    } catch (const std::exception& e) {
      throw common::NumericalError(frame_name(in) + ": " + e.what());
    }
  }
  a.iterations = nlp->iterations();
  a.x = nlp->solution();
  a.multipliers = nlp->multipliers();
  if (!a.x.allFinite())
    throw common::NumericalError(frame_name(in) + ": Ipopt returned a non-finite point");
  return a;
}

// Whether a secondary coordinate of q lies on one of its joint limits (within
// 1e-6 of the range).
bool on_joint_limit(const ComakProblem& p, const Eigen::VectorXd& q) {
  for (int k : p.secondary_coordinates()) {
    const Joint* j = joint_of(p.model(), k);
    const double tol = 1e-6 * (j->upper - j->lower);
    if (q[k] <= j->lower + tol || q[k] >= j->upper - tol) return true;
  }
  return false;
}

// The passive settle from q with the frame's flexion held.
SettleResult settle_at_flexion(const ComakProblem& p, ModelData& data, const Eigen::VectorXd& q) {
  SettleOptions so = p.options().settle;
  so.fixed = {p.flexion_coordinate()};
  so.forces = p.options().forces;
  return settle(p.model(), data, q, so);
}

// The passive settle at the frame's flexion from the neutral pose (secondary
// coordinates at zero, the patella flexed by 0.7 x the knee flexion, roughly
// where it follows the trochlea): a start that does not depend on the frames
// before. The first frame of a run starts here, and every frame's second start.
SettleResult settle_from_neutral(const ComakProblem& p, ModelData& data, const ComakFrameInput& in) {
  Eigen::VectorXd q = p.coordinates(in, Eigen::VectorXd());
  const int pf = p.model().tree.coordinate_index("pf_flexion");
  q[pf >= 0 ? pf : p.flexion_coordinate()] = 0.7 * in.knee_flexion;
  q[p.flexion_coordinate()] = in.knee_flexion;
  return settle_at_flexion(p, data, q);
}

}  // namespace

ComakFrameResult solve_comak_frame(const ComakProblem& p, ModelData& data,
                                   const ComakFrameInput& in, const Eigen::VectorXd& q_start,
                                   const Eigen::VectorXd& a_start, const ComakMultipliers* warm) {
  const auto t0 = std::chrono::steady_clock::now();
  const Model& model = p.model();
  const ComakOptions& o = p.options();
  const int nm = static_cast<int>(model.muscles.size());
  const int ns = static_cast<int>(p.secondary_coordinates().size());
  const int nf = static_cast<int>(p.free_coordinates().size());
  const int ne = o.reserve_actuators ? ns : 0;
  check_frame_input(in);
  if (o.ankle_equilibrium && !in.has_foot_load)
    throw common::InputError(frame_name(in) + ": COMAK ankle equilibrium needs the load on the foot "
                             "from the inverse dynamics (a trial with pelvis and ground-reaction "
                             "columns); this frame has none (knee loads given by the trial?)");
  if (o.body_inertia && (!in.has_foot_load || !in.has_femur_motion))
    throw common::InputError(frame_name(in) + ": COMAK body inertia needs the load on the foot and "
                             "the femur's lab motion from the inverse dynamics (a trial with "
                             "pelvis and ground-reaction columns, frames from comak_frame_inputs "
                             "with its leg model); this frame has " +
                             std::string(in.has_foot_load ? "no femur motion" : "no foot load") +
                             " (knee loads given by the trial?)");
  if (a_start.size() != nm)
    throw common::InputError("COMAK: expected " + std::to_string(nm) + " start activations");

  auto make_x0 = [&](const Eigen::VectorXd& q, const Eigen::VectorXd& a) {
    Eigen::VectorXd x = Eigen::VectorXd::Zero(nm + ns + ne);
    for (int i = 0; i < nm; ++i) x[i] = std::clamp(a[i], o.activation_min, 1.0);
    for (int c = 0; c < ns; ++c) {
      const int k = p.secondary_coordinates()[c];
      const Joint* j = joint_of(model, k);
      x[nm + c] = std::clamp(q[k], j->lower, j->upper);
    }
    return x;
  };

  ComakFrameResult res;
  auto evaluate = [&](const Attempt& at) {
    Eigen::VectorXd q = p.coordinates(in, q_start);
    for (int c = 0; c < ns; ++c) q[p.secondary_coordinates()[c]] = at.x[nm + c];
    const Eigen::VectorXd a = at.x.head(nm);
    Eigen::VectorXd e = Eigen::VectorXd::Zero(nf);
    for (int c = 0; c < ne; ++c) {
      const auto& f = p.free_coordinates();
      e[std::find(f.begin(), f.end(), p.secondary_coordinates()[c]) - f.begin()] = at.x[nm + ns + c];
    }
    const Eigen::VectorXd r = p.residual(data, in, q, a, e);
    common::check_finite(r, frame_name(in) + ": equilibrium residual");
    res.q = q;
    res.activations = a;
    res.reserves = e;
    res.objective = p.objective(a, ne ? e : Eigen::VectorXd());
    res.max_force_residual = res.max_moment_residual = 0.0;
    for (int k = 0; k < p.num_rows(); ++k) {
      double& m = p.revolute(k) ? res.max_moment_residual : res.max_force_residual;
      m = std::max(m, std::abs(r[k]));
    }
    res.ipopt_status = at.status;
    res.multipliers = at.multipliers;
    res.ipopt_status_name = ipopt_status_name(at.status);
    const bool ipopt_ok = at.status == Ipopt::Solve_Succeeded ||
                          at.status == Ipopt::Solved_To_Acceptable_Level;
    const bool equilibrium = res.max_force_residual <= o.force_tolerance &&
                             res.max_moment_residual <= o.force_tolerance * o.length_scale;
    res.status = ipopt_ok && equilibrium ? ComakFrameStatus::kConverged : ComakFrameStatus::kFailed;
  };

  const Eigen::VectorXd a_min = Eigen::VectorXd::Constant(nm, o.activation_min);
  Attempt at;
  // Step control by moving limits (attempt 1 and the second start with
  // options move_limits_first; attempt 4; the re-solve of a solution on a
  // joint limit), from the start x. Each round solves the NLP with every secondary coordinate
  // held within +-move_limit of the round's start (besides its joint limits);
  // a round that ends on such a limit, or fails, hands its last iterate to the
  // next round as the new centre. Without the limits Ipopt's first steps from
  // a far start can carry the patella out of its groove (measured: 120 deg
  // under 1 BW, docs/comak.md); within them every step stays where the
  // linearised contact is meaningful. A round that converges with no moving
  // limit active is a solution of the unlimited problem (the same KKT
  // conditions). Leaves its outcome in res.
  auto moving_limits = [&](Eigen::VectorXd x, const ComakMultipliers* warm_first, double box_scale = 1.0) {
    Eigen::VectorXd half(ns);
    for (int c = 0; c < ns; ++c)
      half[c] = joint_of(model, p.secondary_coordinates()[c])->type == JointType::kRevolute
                    ? box_scale * o.move_limit_rad
                    : box_scale * o.move_limit_m;
    for (int round = 0; round < o.move_limit_rounds; ++round) {
      at = run_ipopt(p, data, in, x, false, round == 0 ? warm_first : nullptr, half);
      res.iterations += at.iterations;
      evaluate(at);
      bool on_limit = false;
      for (int c = 0; c < ns; ++c) {
        const Joint* j = joint_of(model, p.secondary_coordinates()[c]);
        const double lo = x[nm + c] - half[c], hi = x[nm + c] + half[c], v = at.x[nm + c];
        const double tol = 1e-3 * half[c];
        if ((lo > j->lower && v < lo + tol) || (hi < j->upper && v > hi - tol)) on_limit = true;
      }
      if (!on_limit && res.status == ComakFrameStatus::kConverged) return;
      res.status = ComakFrameStatus::kFailed;  // a solution on a moving limit is not one
      if (at.x == x) return;                    // no progress: the last round's result stands
      x = at.x;
    }
  };
  // Attempt 1: warm start, within moving limits (ComakOptions::move_limits_first).
  const Eigen::VectorXd q0 = p.coordinates(in, q_start);
  res.attempts = 1;
  if (o.move_limits_first) {
    moving_limits(make_x0(q0, a_start), warm);
  } else {
    at = run_ipopt(p, data, in, make_x0(q0, a_start), false, warm);
    res.iterations += at.iterations;
    evaluate(at);
  }
  // The start from the passive settle of the neutral pose, independent of
  // the frames before and of the given start (settled once per frame).
  Eigen::VectorXd neutral_x;
  auto neutral_start = [&]() -> const Eigen::VectorXd& {
    if (neutral_x.size() == 0) neutral_x = make_x0(settle_from_neutral(p, data, in).q, a_min);
    return neutral_x;
  };
  // Solves the converged frame in res again from the neutral start (`solve`)
  // and keeps the lower converged objective; the note says what it found.
  std::string second_note;
  auto keep_lower = [&](const char* label, int attempts, const std::function<void()>& solve) {
    const ComakFrameResult before = res;
    solve();
    const bool wins = res.status == ComakFrameStatus::kConverged && res.objective < before.objective;
    std::ostringstream s;
    s << "; " << label << " " << to_string(res.status) << ", objective " << res.objective << " m^3 (first "
      << before.objective << "), " << (wins ? "kept" : "not kept");
    const int iterations = res.iterations;
    if (!wins) res = before;
    res.iterations = iterations;
    res.attempts = attempts;
    second_note += s.str();
  };
  if (res.status == ComakFrameStatus::kConverged && o.second_start) {
    keep_lower("second start", 2, [&] {
      if (o.move_limits_first) {
        moving_limits(neutral_start(), nullptr, o.second_start_move_limit_scale);
      } else {
        at = run_ipopt(p, data, in, neutral_start(), false, nullptr);
        res.iterations += at.iterations;
        evaluate(at);
      }
    });
  }
  // Attempt 2: from the passive settle at this flexion, activations at a_min.
  if (res.status != ComakFrameStatus::kConverged && o.retries >= 1) {
    at = run_ipopt(p, data, in, make_x0(settle_at_flexion(p, data, q0).q, a_min), false, nullptr);
    res.iterations += at.iterations;
    res.attempts = 2;
    evaluate(at);
  }
  // Attempt 3: warm start, adaptive barrier, doubled iteration limit.
  if (res.status != ComakFrameStatus::kConverged && o.retries >= 2) {
    at = run_ipopt(p, data, in, make_x0(q0, a_start), true, nullptr);
    res.iterations += at.iterations;
    res.attempts = 3;
    evaluate(at);
  }
  // Attempt 4: moving limits from the passive settle of the neutral pose (a
  // start that owes nothing to the frames before or to the given start).
  if (res.status != ComakFrameStatus::kConverged && o.retries >= 3) {
    res.attempts = 4;
    moving_limits(neutral_start(), nullptr);
  }
  // A converged solution with a secondary coordinate on its joint limit (the
  // limits carry no force: a patella 50 mm lateral held only by its
  // ligaments) is solved again with moving limits and the lower converged
  // objective kept, as for the second start.
  if (res.status == ComakFrameStatus::kConverged && o.retries >= 3 && on_joint_limit(p, res.q))
    keep_lower("a coordinate on its joint limit, moving limits", res.attempts + 1,
               [&] { moving_limits(neutral_start(), nullptr); });
  res.wall_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::ostringstream s;
  s << frame_name(in) << ": " << to_string(res.status) << " (Ipopt " << res.ipopt_status_name
    << ", " << res.iterations << " iterations, " << res.attempts << " attempt"
    << (res.attempts > 1 ? "s" : "") << "), objective " << res.objective << " m^3, max residual "
    << res.max_force_residual << " N, " << res.max_moment_residual << " N m, "
    << res.wall_time << " s" << second_note;
  res.message = s.str();
  return res;
}

std::vector<ComakFrameInput> comak_frame_inputs(const KneeLoads& loads, int first, int last,
                                                int stride, const LegModel* leg) {
  const int n = loads.num_samples();
  // A truncated trial: the selection refers to the whole trial's frames.
  const int n_trial = loads.truncated ? loads.truncated->full_samples : n;
  if (n == 0) throw common::InputError("COMAK: the trial has no samples");
  if (last < 0) last = n_trial - 1;
  if (first < 0 || first >= n_trial || last >= n_trial || last < first || stride < 1)
    throw common::InputError("COMAK: frame selection first " + std::to_string(first) + ", last " +
                             std::to_string(last) + ", stride " + std::to_string(stride) +
                             " outside the trial's frames 0.." + std::to_string(n_trial - 1));
  std::vector<ComakFrameInput> out;
  for (int i = first; i <= last; i += stride) {
    ComakFrameInput f;
    f.index = i;
    if (i >= n) {
      // The first selected frame after the cut: no loads exist for it; the
      // run stops here naming it and the bad value.
      const TrialTruncation& cut = *loads.truncated;
      const double h = n > 1 ? loads.time[1] - loads.time[0] : 0.0;
      const double nan = std::numeric_limits<double>::quiet_NaN();
      f.time = cut.time + (i - cut.frame) * h;
      f.knee_flexion = f.ankle_flexion = nan;
      f.hip_angles.setConstant(nan);
      f.F_ext_T.setConstant(nan);
      f.M_ext_T.setConstant(nan);
      f.invalid_input = cut.reason + " (the trial was read up to the row before it)";
      out.push_back(f);
      break;
    }
    f.time = loads.time[i];
    f.knee_flexion = loads.knee_flexion[i];
    f.hip_angles = loads.hip_angles.row(i).transpose();
    f.ankle_flexion = loads.ankle_flexion[i];
    f.F_ext_T = loads.F_ext_T.row(i).transpose();
    f.M_ext_T = loads.M_ext_T.row(i).transpose();
    if (loads.has_foot_loads) {
      f.has_foot_load = true;
      f.F_foot_T = loads.F_foot_T.row(i).transpose();
      f.M_foot_T = loads.M_foot_T.row(i).transpose();
      f.ankle_centre_T = loads.ankle_centre_T;
    }
    if (leg && loads.source == KneeLoadSource::kInverseDynamics) {
      // The femur frame of the knee model in the lab: the thigh frame's axes
      // and the leg chain's knee centre, along the local Taylor path of the
      // coordinates (the same path and step as the inverse dynamics).
      using Coords = Eigen::Matrix<double, kNumTrialCoordinates, 1>;
      const Coords q = loads.q.row(i).transpose(), qd = loads.qd.row(i).transpose(),
                   qdd = loads.qdd.row(i).transpose();
      RootMotion& m = f.femur_motion;
      m.step = 1e-4;
      for (int k = 0; k < 3; ++k) {
        const double s = (k - 1) * m.step;
        const LegPoses P = leg_poses(*leg, q + s * qd + 0.5 * s * s * qdd);
        m.X_LR[k].setIdentity();
        m.X_LR[k].linear() = P.X_WF.linear();
        m.X_LR[k].translation() = P.X_WT.translation();
        if (k == 1 && !loads.X_WT.empty() &&
            !P.X_WT.matrix().isApprox(loads.X_WT[i].matrix(), 1e-9))
          throw common::InputError(
              "COMAK: frame " + std::to_string(i) + ": the leg chain's tibia pose differs from "
              "the knee loads' (another leg model, or a left leg, which COMAK does not take)");
      }
      m.velocity = loads.qd(i, kKneeFlexion);
      m.acceleration = loads.qdd(i, kKneeFlexion);
      f.has_femur_motion = true;
    }
    out.push_back(f);
  }
  return out;
}

ComakRunSummary run_comak(
    const ComakProblem& p, const std::vector<ComakFrameInput>& frames,
    const std::function<void(const ComakFrameInput&, const ComakFrameResult&, const ModelData&)>&
        on_frame) {
  common::register_dependency_version("ipopt", IPOPT_VERSION);
  ComakRunSummary sum;
  if (frames.empty()) return sum;
  const Model& model = p.model();
  const ComakOptions& o = p.options();
  ModelData data = make_data(model);
  const int nm = static_cast<int>(model.muscles.size());
  auto t0 = std::chrono::steady_clock::now();  // restarted after the first settle
  // A non-finite input or evaluation stops the run at its frame; the
  // summary of the frames before goes with the exception.
  auto stop = [&](const ComakFrameInput& f, const common::NumericalError& e) {
    sum.wall_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    sum.stopped = e.what();
    common::log_error(std::string(e.what()) + " -- run stopped after " +
                      std::to_string(sum.frames) + " frames");
    return ComakRunStopped(e.what(), f.index, sum);
  };
  try {
    check_frame_input(frames.front());
  } catch (const common::NumericalError& e) {
    throw stop(frames.front(), e);
  }
  // The first frame starts from the passive settle at its flexion.
  sum.first_settle = settle_from_neutral(p, data, frames.front());
  common::log_info("COMAK: first frame from the passive settle: " + sum.first_settle.message);
  Eigen::VectorXd q = sum.first_settle.q;
  Eigen::VectorXd a = Eigen::VectorXd::Constant(nm, o.activation_min);
  ComakMultipliers warm;
  bool have_warm = false;
  t0 = std::chrono::steady_clock::now();
  for (const ComakFrameInput& f : frames) {
    ComakFrameResult r;
    try {
      r = solve_comak_frame(p, data, f, q, a,
                            have_warm && o.warm_start_multipliers ? &warm : nullptr);
      // Evaluate the model at the reported solution for the writer.
      p.residual(data, f, r.q, r.activations, r.reserves);
    } catch (const common::NumericalError& e) {
      throw stop(f, e);
    }
    ++sum.frames;
    sum.total_iterations += r.iterations;
    if (r.status == ComakFrameStatus::kConverged) {
      ++sum.converged;
      q = r.q;
      a = r.activations;
      warm = r.multipliers;
      have_warm = true;
      common::log_debug(r.message);
    } else {
      ++sum.failed;
      sum.failed_frames.push_back(f.index);
      common::log_warn(r.message + " -- marked failed; the next frame starts from the last "
                                   "converged one");
    }
    on_frame(f, r, data);
  }
  sum.wall_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return sum;
}

}  // namespace arthrosim::musculoskeletal
