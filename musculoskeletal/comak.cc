#include "musculoskeletal/comak.h"

#include <IpIpoptApplication.hpp>
#include <stdexcept>
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
  const int i = m.role_coordinate(name);
  if (i < 0)
    throw common::InputError(m.source + ": error: COMAK needs the coordinate '" + name +
                             "' (by name or <arthrosim:role>), the model has none");
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
  if (in.model_dynamics) {
    // Every value the model needs (NaN only for coordinates the trial lacks,
    // which comak_model_frame_inputs allows for secondary coordinates only).
    for (const LabForce& f : in.lab_forces) {
      Eigen::VectorXd v(9);
      v << f.force_L, f.point_L, f.torque_L;
      common::check_finite(v, frame_name(in) + ": external force on body " + std::to_string(f.body));
    }
    if (!std::isfinite(in.time) || !std::isfinite(in.knee_flexion))
      throw common::NumericalError(frame_name(in) + ": input (time, knee flexion) not finite");
    return;
  }
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
  // A model with its own leg to the ground (an imported OpenSim model) gets
  // its loads from its own bodies (model_loads.h); the hip angles are then
  // prescribed coordinates like any other, and the ankle is needed only for
  // the ankle row.
  ground_ = model.role_body("ground");
  model_dynamics_ = ground_ >= 0;
  flexion_ = require_coordinate(model, "knee_flexion");
  const char* hips[3] = {"hip_flexion", "hip_adduction", "hip_rotation"};
  for (int k = 0; k < 3; ++k)
    hip_[k] = model_dynamics_ ? model.role_coordinate(hips[k]) : require_coordinate(model, hips[k]);
  ankle_ = model_dynamics_ && !options.ankle_equilibrium ? model.role_coordinate("ankle_flexion")
                                                         : require_coordinate(model, "ankle_flexion");
  tibia_ = model.role_body("tibia");
  if (tibia_ < 0) throw common::InputError(model.source + ": error: COMAK needs a body 'tibia' (or the role)");
  inertial_bodies_ = {tibia_};
  if (const int patella = model.role_body("patella"); patella >= 0) inertial_bodies_.push_back(patella);
  free_ = model.free_coordinates;
  if (model_dynamics_) inertial_bodies_ = bodies_moved_by(model.tree, free_);
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
    if (model_dynamics_) {
      // The foot's balance about the model's own ankle: its external term
      // comes from the trial's forces and the foot's dynamics like the knee's.
      for (int b : bodies_moved_by(model.tree, {ankle_}))
        if (std::find(inertial_bodies_.begin(), inertial_bodies_.end(), b) == inertial_bodies_.end())
          inertial_bodies_.push_back(b);
    } else if (!j || j->type != JointType::kRevolute || j->parent != tibia_)
      throw common::InputError(model.source + ": error: COMAK ankle equilibrium needs 'ankle_flexion' "
                               "to be a revolute joint whose parent is the tibia");
    if (!model_dynamics_) {
      ankle_axis_T_ = j->X_PJ.linear() * j->axis_J;
      ankle_origin_T_ = j->X_PJ.translation();
    }
    rows_.push_back(ankle_);
    revolute_.push_back(true);
  }
  if (options.hip_equilibrium) {
    if (!model_dynamics_)
      throw common::InputError(model.source + ": error: COMAK hip equilibrium needs a model with its own leg "
                               "to the ground (a 'ground' role, e.g. an imported OpenSim model)");
    for (int k = 0; k < 3; ++k) {
      if (hip_[k] < 0)
        throw common::InputError(model.source + ": error: COMAK hip equilibrium needs the coordinates "
                                 "hip_flexion, hip_adduction and hip_rotation (roles)");
      const Joint* j = joint_of(model, hip_[k]);
      if (!j || j->type != JointType::kRevolute)
        throw common::InputError(model.source + ": error: COMAK hip equilibrium: '" +
                                 model.tree.coordinates[hip_[k]] + "' is not a revolute joint");
      hip_rows_.push_back(hip_[k]);
      hip_joints_.push_back(static_cast<int>(j - model.tree.joints.data()));
      rows_.push_back(hip_[k]);
      revolute_.push_back(true);
    }
    // The leg: every body the hip coordinates do not move (the root's side).
    const std::vector<int> pelvis_side = bodies_moved_by(model.tree, hip_rows_);
    for (int b = 0; b < static_cast<int>(model.tree.bodies.size()); ++b)
      if (std::find(pelvis_side.begin(), pelvis_side.end(), b) == pelvis_side.end()) leg_bodies_.push_back(b);
    for (int b : leg_bodies_)
      if (std::find(inertial_bodies_.begin(), inertial_bodies_.end(), b) == inertial_bodies_.end())
        inertial_bodies_.push_back(b);
  }
  const int nr = static_cast<int>(rows_.size());
  row_scale_.resize(nr);
  for (int k = 0; k < nr; ++k) row_scale_[k] = revolute_[k] ? 1.0 / options.length_scale : 1.0;

  // Volume weights V = F_max l_opt / sigma (COMAK's), with the path length at
  // the default pose standing in for l_opt where the model file gives none.
  const int nm = static_cast<int>(model.muscles.size());
  V_.resize(nm);
  w_ = Eigen::VectorXd::Ones(nm);
  KinematicsData kin;
  const Eigen::VectorXd q_ref = model.default_q.size() == model.num_coordinates()
                                    ? model.default_q
                                    : Eigen::VectorXd::Zero(model.num_coordinates());
  forward_kinematics(model.tree, q_ref, kin);
  for (int i = 0; i < nm; ++i) {
    const Muscle& mu = model.muscles[i];
    const double l = mu.optimal_fiber_length > 0 ? mu.optimal_fiber_length
                                                 : evaluate_path(mu.path, kin.X_WB, q_ref).length;
    V_[i] = mu.max_isometric_force * l / options.muscle_stress;
  }
  if (options.ankle_equilibrium) {
    // The ankle row must be balanceable both ways: plantarflexors (moment
    // arm < 0 about the dorsiflexion axis) for push-off and dorsiflexors for
    // the heel-strike moment. Checked at q = 0.
    KinematicsData k0;
    forward_kinematics(model.tree, q_ref, k0);
    ModelData d0 = make_data(model);
    d0.kinematics = k0;
    bool plantar = false, dorsi = false;
    for (int i = 0; i < nm; ++i) {
      const double r = moment_arms(
          model, d0, evaluate_path(model.muscles[i].path, k0.X_WB, q_ref))[ankle_];
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
                          : (model_.default_q.size() == model_.num_coordinates()
                                 ? model_.default_q
                                 : Eigen::VectorXd::Zero(model_.num_coordinates()));
  if (in.model_dynamics) {
    if (in.q_trial.size() != model_.num_coordinates())
      throw common::InputError(frame_name(in) + ": model-dynamics input of the wrong size");
    for (int c : model_.prescribed_coordinates) q[c] = in.q_trial[c];
    q[flexion_] = in.q_trial[flexion_];
    return q;
  }
  q[flexion_] = in.knee_flexion;
  for (int k = 0; k < 3; ++k) q[hip_[k]] = in.hip_angles[k];
  q[ankle_] = in.ankle_flexion;
  return q;
}

Eigen::VectorXd ComakProblem::external_generalized_force(const ModelData& data,
                                                         const ComakFrameInput& in) const {
  Eigen::VectorXd Q = Eigen::VectorXd::Zero(model_.num_coordinates());
  if (in.model_dynamics) {
    // The trial's forces on the model's own bodies (the foot's ground
    // reaction where the trial puts it); weight and inertia: inertial_generalized_force.
    const std::vector<BodyWrench> w = lab_force_wrenches(data.kinematics, ground_, in.lab_forces);
    add_wrenches(model_.tree, data.kinematics, w, Q);
    add_hip_moments(data.kinematics, w, Q);
    return Q;
  }
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
  if (in.model_dynamics) {
    // Lab motion of the model's own chain: the prescribed coordinates (and
    // the knee flexion) move with the trial's rates, the secondary ones are
    // held at zero rate (see docs/comak.md, "Body inertia").
    Eigen::VectorXd qd = Eigen::VectorXd::Zero(q.size()), qdd = qd;
    for (int c : model_.prescribed_coordinates) qd[c] = in.qd_trial[c], qdd[c] = in.qdd_trial[c];
    qd[flexion_] = in.qd_trial[flexion_];
    qdd[flexion_] = in.qdd_trial[flexion_];
    KinematicsData centre;
    const std::vector<BodyWrench> w =
        lab_inertial_wrenches(model_.tree, ground_, q, qd, qdd, inertial_bodies_, Vec3(0.0, -9.80665, 0.0), 1e-4,
                              &centre);
    add_wrenches(model_.tree, centre, w, Q);
    add_hip_moments(centre, w, Q);
    return Q;
  }
  if (!options_.body_inertia) return Q;
  if (!in.has_femur_motion)
    throw common::InputError(frame_name(in) + ": COMAK body inertia needs the femur's lab motion "
                             "(comak_frame_inputs with the leg model of the inverse dynamics)");
  RootMotion m = in.femur_motion;
  m.coordinate = flexion_;
  add_inertial_forces(model_.tree, q, inertial_bodies_, m, Q);
  return Q;
}

void ComakProblem::add_hip_moments(const KinematicsData& k, const std::vector<BodyWrench>& w,
                                   Eigen::VectorXd& Q) const {
  // Hip row c: the leg's balance about the hip axis. The tree measures the
  // muscles' and ligaments' moment on the pelvis side (Q[c] through the
  // reversed hip joint), which is minus their moment on the leg; a force on a
  // leg body adds -a . ((x - o) x f + tau) (a, o: the joint's world axis and
  // origin), so Q[c] = 0 says the leg's moments about the axis sum to zero.
  if (hip_rows_.empty()) return;
  std::vector<BodyWrench> leg;
  for (const BodyWrench& x : w)
    if (std::find(leg_bodies_.begin(), leg_bodies_.end(), x.body) != leg_bodies_.end()) leg.push_back(x);
  for (std::size_t r = 0; r < hip_rows_.size(); ++r) {
    const int ji = hip_joints_[r];
    Q[hip_rows_[r]] -= axis_moment(leg, k.joint_origin_W[ji], k.joint_axis_W[ji]);
  }
}

Eigen::VectorXd ComakProblem::neutral_pose(const ComakFrameInput& in) const {
  Eigen::VectorXd q = coordinates(in, Eigen::VectorXd());  // defaults + the frame's prescribed values
  if (in.model_dynamics) {
    bool all = true;
    for (int c : secondary_) all = all && std::isfinite(in.q_trial[c]);
    if (all) {
      for (int c : secondary_) q[c] = in.q_trial[c];
      return q;
    }
  }
  const int pf = model_.role_coordinate("pf_flexion");
  const double knee = q[flexion_];
  q[pf >= 0 ? pf : flexion_] += 0.7 * knee;
  q[flexion_] = knee;
  return q;
}

Eigen::VectorXd ComakProblem::damping_generalized_force(const Eigen::VectorXd& q,
                                                       const ComakFrameInput& in) const {
  Eigen::VectorXd Q = Eigen::VectorXd::Zero(model_.num_coordinates());
  if (!options_.coordinate_damping || !in.has_previous || !(in.dt_previous > 0)) return Q;
  for (const CoordinateSpring& sp : model_.coordinate_springs) {
    if (sp.viscosity == 0.0) continue;
    const int c = sp.coordinate;
    const bool secondary = std::find(secondary_.begin(), secondary_.end(), c) != secondary_.end();
    double v = 0.0;
    if (secondary)
      v = (q[c] - in.q_previous[c]) / in.dt_previous;
    else if (in.model_dynamics)
      v = in.qd_trial[c];
    else if (c == flexion_ && in.has_femur_motion)
      v = in.femur_motion.velocity;
    Q[c] -= sp.viscosity * v;
  }
  return Q;
}

double ComakProblem::external_ankle_moment(const ComakFrameInput& in) const {
  if (!options_.ankle_equilibrium || in.model_dynamics) return 0.0;
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
  if (options_.body_inertia || in.model_dynamics) Qe += inertial_generalized_force(q, in);
  Qe += damping_generalized_force(q, in);
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
    if (options_.body_inertia || in.model_dynamics) {
      Qp += inertial_generalized_force(qp, in);
      Qm += inertial_generalized_force(qm, in);
    }
    for (int k = 0; k < nf; ++k)
      J(k, nm + c) = data.dQ_dq(rows_[k], secondary_[c]) + (Qp[rows_[k]] - Qm[rows_[k]]) / (2 * h);
  }
  // Coordinate dampers: -c (s - s_prev) / dt on the coordinate's own row (exact).
  if (options_.coordinate_damping && in.has_previous && in.dt_previous > 0) {
    for (const CoordinateSpring& sp : model_.coordinate_springs) {
      const auto sc = std::find(secondary_.begin(), secondary_.end(), sp.coordinate);
      const auto rk = std::find(rows_.begin(), rows_.end(), sp.coordinate);
      if (sc == secondary_.end() || rk == rows_.end()) continue;
      J(rk - rows_.begin(), nm + (sc - secondary_.begin())) -= sp.viscosity / in.dt_previous;
    }
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
  return settle_at_flexion(p, data, p.neutral_pose(in));
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
  if (p.model_dynamics() != in.model_dynamics)
    throw common::InputError(frame_name(in) + ": " +
                             (p.model_dynamics() ? "the model has its own leg to the ground: its frames must come "
                                                   "from comak_model_frame_inputs (the trial's coordinates by name)"
                                                 : "model-dynamics frames need a model with a ground body"));
  if (o.ankle_equilibrium && !in.has_foot_load && !in.model_dynamics)
    throw common::InputError(frame_name(in) + ": COMAK ankle equilibrium needs the load on the foot "
                             "from the inverse dynamics (a trial with pelvis and ground-reaction "
                             "columns); this frame has none (knee loads given by the trial?)");
  if (o.body_inertia && !in.model_dynamics && (!in.has_foot_load || !in.has_femur_motion))
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

std::vector<ComakFrameInput> comak_model_frame_inputs(const Model& model, const GaitTrial& trial, int first,
                                                      int last, int stride, std::vector<std::string>* ignored) {
  const int n = trial.num_samples();
  const int n_trial = trial.truncated ? trial.truncated->full_samples : n;
  if (n == 0) throw common::InputError(trial.source + ": error: the trial has no samples");
  if (last < 0) last = n_trial - 1;
  if (first < 0 || first >= n_trial || last >= n_trial || last < first || stride < 1)
    throw common::InputError("COMAK: frame selection first " + std::to_string(first) + ", last " +
                             std::to_string(last) + ", stride " + std::to_string(stride) +
                             " outside the trial's frames 0.." + std::to_string(n_trial - 1));
  const int nc = model.num_coordinates();
  const int flexion = model.role_coordinate("knee_flexion");
  // Trial column of every model coordinate (by name); the prescribed ones and
  // the flexion must have one.
  std::vector<int> col(nc, -1);
  std::string missing;
  for (int c = 0; c < nc; ++c) {
    col[c] = trial.kinematics_column(model.tree.coordinates[c]);
    const bool needed = c == flexion || std::find(model.prescribed_coordinates.begin(),
                                                  model.prescribed_coordinates.end(), c) !=
                                            model.prescribed_coordinates.end();
    if (col[c] < 0 && needed) missing += (missing.empty() ? "" : ", ") + model.tree.coordinates[c];
  }
  if (!missing.empty())
    throw common::InputError(trial.source + ": error: the model's coordinates " + missing +
                             " have no column in the trial's kinematics file (expected one per prescribed "
                             "coordinate and the knee flexion, by name)");
  std::vector<std::pair<int, const TrialExternalForce*>> forces;
  for (const TrialExternalForce& f : trial.external_forces) {
    const int b = model.tree.body_index(f.body);
    if (b >= 0)
      forces.push_back({b, &f});
    else if (ignored)
      ignored->push_back(f.name + " (acts on " + f.body + ", not a body of the model)");
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<ComakFrameInput> out;
  for (int i = first; i <= last; i += stride) {
    ComakFrameInput in;
    in.index = i;
    in.model_dynamics = true;
    if (i >= n) {
      // The first selected frame after a truncated trial's end (see comak_frame_inputs).
      const double h = n > 1 ? trial.time[1] - trial.time[0] : 0.0;
      in.time = trial.truncated->time + (i - trial.truncated->frame) * h;
      in.knee_flexion = nan;
      in.q_trial = in.qd_trial = in.qdd_trial = Eigen::VectorXd::Constant(nc, nan);
      in.invalid_input = trial.truncated->reason + " (the trial was read up to the row before it)";
      out.push_back(in);
      break;
    }
    in.time = trial.time[i];
    in.q_trial = in.qd_trial = in.qdd_trial = Eigen::VectorXd::Constant(nc, nan);
    for (int c = 0; c < nc; ++c) {
      if (col[c] < 0) continue;
      in.q_trial[c] = trial.kinematics_q(i, col[c]);
      in.qd_trial[c] = trial.kinematics_qd(i, col[c]);
      in.qdd_trial[c] = trial.kinematics_qdd(i, col[c]);
    }
    in.knee_flexion = in.q_trial[flexion];
    const char* hips[3] = {"hip_flexion", "hip_adduction", "hip_rotation"};
    for (int k = 0; k < 3; ++k)
      if (const int c = model.role_coordinate(hips[k]); c >= 0) in.hip_angles[k] = in.q_trial[c];
    if (const int c = model.role_coordinate("ankle_flexion"); c >= 0) in.ankle_flexion = in.q_trial[c];
    for (const auto& [b, f] : forces) {
      LabForce lf;
      lf.body = b;
      lf.force_L = f->force_W.row(i).transpose();
      lf.point_L = f->point_W.row(i).transpose();
      lf.torque_L = f->torque_W.row(i).transpose();
      lf.has_point = f->has_point;
      in.lab_forces.push_back(lf);
    }
    // Every value the model uses must be finite (NaN of a missing secondary
    // column is allowed: it only decides the neutral start).
    for (int c = 0; c < nc; ++c) {
      const bool needed = col[c] >= 0 &&
                          (c == flexion || std::find(model.prescribed_coordinates.begin(),
                                                     model.prescribed_coordinates.end(), c) !=
                                               model.prescribed_coordinates.end());
      if (needed && !(std::isfinite(in.q_trial[c]) && std::isfinite(in.qd_trial[c]) &&
                      std::isfinite(in.qdd_trial[c])))
        in.invalid_input = trial.source + ": coordinate '" + model.tree.coordinates[c] + "' at t = " +
                           std::to_string(in.time) + " s";
    }
    out.push_back(in);
  }
  return out;
}

ComakRunSummary run_comak(
    const ComakProblem& p, const std::vector<ComakFrameInput>& frames,
    const std::function<void(const ComakFrameInput&, const ComakFrameResult&, const ModelData&)>&
        on_frame) {
  return run_comak(p, frames, on_frame, nullptr, {});
}

ComakRunSummary run_comak(
    const ComakProblem& p, const std::vector<ComakFrameInput>& frames,
    const std::function<void(const ComakFrameInput&, const ComakFrameResult&, const ModelData&)>&
        on_frame,
    const ComakRunState* resume, const std::function<void(const ComakRunState&)>& on_state) {
  common::register_dependency_version("ipopt", IPOPT_VERSION);
  if (frames.empty()) return ComakRunSummary{};
  const Model& model = p.model();
  const ComakOptions& o = p.options();
  ModelData data = make_data(model);
  const int nm = static_cast<int>(model.muscles.size());
  ComakRunState st;
  ComakRunSummary& sum = st.summary;
  double wall_before = 0.0;  // of the frames a resumed run did not solve itself
  auto t0 = std::chrono::steady_clock::now();  // restarted after the first settle
  // A non-finite input or evaluation stops the run at its frame; the
  // summary of the frames before goes with the exception.
  auto stop = [&](const ComakFrameInput& f, const common::NumericalError& e) {
    sum.wall_time = wall_before + std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    sum.stopped = e.what();
    common::log_error(std::string(e.what()) + " -- run stopped after " +
                      std::to_string(sum.frames) + " frames");
    return ComakRunStopped(e.what(), f.index, sum);
  };
  if (resume != nullptr) {
    if (resume->frames_done < 0 || resume->frames_done > static_cast<int>(frames.size()))
      throw std::logic_error("run_comak: resume state of " + std::to_string(resume->frames_done) + " frames for " +
                             std::to_string(frames.size()) + " frames");
    st = *resume;
    wall_before = st.summary.wall_time;
  } else {
    try {
      check_frame_input(frames.front());
    } catch (const common::NumericalError& e) {
      throw stop(frames.front(), e);
    }
    // The first frame starts from the passive settle at its flexion.
    sum.first_settle = settle_from_neutral(p, data, frames.front());
    common::log_info("COMAK: first frame from the passive settle: " + sum.first_settle.message);
    st.q = sum.first_settle.q;
    st.a = Eigen::VectorXd::Constant(nm, o.activation_min);
    // The previous pose of the coordinate dampers: the first frame's settle,
    // one frame spacing before it; then the last converged frame.
    st.q_prev = st.q;
    st.t_prev = frames.front().time - (frames.size() > 1 ? frames[1].time - frames[0].time : 0.01);
  }
  t0 = std::chrono::steady_clock::now();
  for (std::size_t i = static_cast<std::size_t>(st.frames_done); i < frames.size(); ++i) {
    ComakFrameInput f = frames[i];
    f.has_previous = true;
    f.q_previous = st.q_prev;
    f.dt_previous = f.time - st.t_prev;
    ComakFrameResult r;
    try {
      r = solve_comak_frame(p, data, f, st.q, st.a,
                            st.have_warm && o.warm_start_multipliers ? &st.warm : nullptr);
      // Evaluate the model at the reported solution for the writer.
      p.residual(data, f, r.q, r.activations, r.reserves);
    } catch (const common::NumericalError& e) {
      throw stop(f, e);
    }
    ++sum.frames;
    sum.total_iterations += r.iterations;
    if (r.status == ComakFrameStatus::kConverged) {
      ++sum.converged;
      st.q = r.q;
      st.q_prev = r.q;
      st.t_prev = f.time;
      st.a = r.activations;
      st.warm = r.multipliers;
      st.have_warm = true;
      common::log_debug(r.message);
    } else {
      ++sum.failed;
      sum.failed_frames.push_back(f.index);
      common::log_warn(r.message + " -- marked failed; the next frame starts from the last "
                                   "converged one");
    }
    on_frame(f, r, data);
    st.frames_done = static_cast<int>(i) + 1;
    sum.wall_time = wall_before + std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (on_state) on_state(st);
  }
  sum.wall_time = wall_before + std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return sum;
}

}  // namespace arthrosim::musculoskeletal
