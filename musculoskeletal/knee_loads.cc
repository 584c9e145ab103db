#include "musculoskeletal/knee_loads.h"

#include <array>
#include <cmath>
#include <utility>
#include <sstream>

#include "common/error.h"
#include "common/finite.h"
#include "musculoskeletal/kinematics.h"

namespace arthrosim::musculoskeletal {

namespace {

using Coords = Eigen::Matrix<double, kNumTrialCoordinates, 1>;

Eigen::Matrix3d rx(double a) { return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitX()).toRotationMatrix(); }
Eigen::Matrix3d ry(double a) { return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY()).toRotationMatrix(); }
Eigen::Matrix3d rz(double a) { return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()).toRotationMatrix(); }

// Reflection through the sagittal plane (z -> -z) of coordinates: list,
// rotation and tz change sign (see header).
Coords mirror_coordinates(const Coords& q) {
  Coords m = q;
  m(kPelvisList) = -q(kPelvisList);
  m(kPelvisRotation) = -q(kPelvisRotation);
  m(kPelvisTz) = -q(kPelvisTz);
  return m;
}

const Eigen::Vector3d kMirrorPolar(1.0, 1.0, -1.0);   // forces, positions
const Eigen::Vector3d kMirrorAxial(-1.0, -1.0, 1.0);  // moments

struct BodyMotion {
  Eigen::Vector3d p_com, a_com, w, alpha;
  Eigen::Matrix3d R;
};

}  // namespace

LegPoses leg_poses(const LegModel& leg, const Coords& q) {
  LegPoses x;
  x.X_WP.setIdentity();
  x.X_WP.linear() = rz(q(kPelvisTilt)) * rx(q(kPelvisList)) * ry(q(kPelvisRotation));
  x.X_WP.translation() = Eigen::Vector3d(q(kPelvisTx), q(kPelvisTy), q(kPelvisTz));
  x.X_WF.setIdentity();
  x.X_WF.linear() = x.X_WP.linear() * rz(q(kHipFlexion)) * rx(q(kHipAdduction)) * ry(q(kHipRotation));
  x.X_WF.translation() = x.X_WP * leg.p_PH_P;
  x.X_WT.setIdentity();
  x.X_WT.linear() = x.X_WF.linear() * rz(-q(kKneeFlexion));
  x.X_WT.translation() = x.X_WF * Eigen::Vector3d(0.0, -leg.thigh_length_m, 0.0);
  x.X_WC.setIdentity();
  x.X_WC.linear() = x.X_WT.linear() * rz(q(kAnkleFlexion));
  x.X_WC.translation() = x.X_WT * Eigen::Vector3d(0.0, -leg.shank_length_m, 0.0);
  return x;
}

LegModel leg_model_for_trial(const GaitTrial& trial) {
  if (!(trial.body_mass_kg > 0) || !(trial.height_m > 0))
    throw common::InputError(trial.source, 0,
                             "the generic leg chain (knee_loads.h) needs subject_mass_kg and "
                             "subject_height_m, found " +
                                 std::string(trial.body_mass_kg > 0 ? "no height" : "no mass") +
                                 " (a model with its own leg bodies needs neither)");
  LegModel leg = leg_model_from_anthropometry(trial.body_mass_kg, trial.height_m);
  for (const auto& [key, v] : trial.leg_overrides) {
    if (key == "thigh_length_m") leg.thigh_length_m = v;
    else if (key == "shank_length_m") leg.shank_length_m = v;
    else if (key == "ankle_height_m") leg.ankle_height_m = v;
    else if (key == "foot_length_m") leg.foot_length_m = v;
    else if (key == "hip_x_m") leg.p_PH_P.x() = v;
    else if (key == "hip_y_m") leg.p_PH_P.y() = v;
    else if (key == "hip_z_m") leg.p_PH_P.z() = v;
    else throw common::InputError(trial.source, 0, "unknown leg override '" + key + "'");
  }
  leg.heel_behind_ankle_m = 0.22 * leg.foot_length_m;
  set_segment_inertia(leg);
  return leg;
}

KneeLoads compute_knee_loads(const GaitTrial& trial, const LegModel& leg,
                             const KneeLoadOptions& options) {
  const int n = trial.num_samples();
  if (!trial.has_joint_angles)
    throw common::InputError(trial.source, 0,
                             "the knee loads of the generic leg chain need the joint angles mapped "
                             "(column.hip_flexion, column.hip_adduction, column.hip_rotation, "
                             "column.knee_flexion, column.ankle_flexion), found none");
  KneeLoads out;
  out.time = trial.time;
  out.truncated = trial.truncated;
  out.q = trial.q;
  out.qd = trial.qd;
  out.qdd = trial.qdd;
  out.knee_flexion = trial.q.col(kKneeFlexion);
  out.knee_flexion_velocity = trial.qd.col(kKneeFlexion);
  out.knee_flexion_acceleration = trial.qdd.col(kKneeFlexion);
  out.hip_angles = trial.q.middleCols(kHipFlexion, 3);
  out.ankle_flexion = trial.q.col(kAnkleFlexion);
  out.F_ext_T.resize(n, 3);
  out.M_ext_T.resize(n, 3);

  if (trial.has_knee_loads) {
    out.source = KneeLoadSource::kGivenByTrial;
    out.F_ext_T = trial.knee_force_T;
    out.M_ext_T = trial.knee_moment_T;
    return out;
  }
  out.source = KneeLoadSource::kInverseDynamics;
  out.has_foot_loads = true;
  out.F_foot_T.resize(n, 3);
  out.M_foot_T.resize(n, 3);
  out.ankle_centre_T = Eigen::Vector3d(0.0, -leg.shank_length_m, 0.0);
  if (!trial.has_pelvis || !trial.has_grf) {
    throw common::InputError(
        trial.source, 0,
        std::string("the knee inverse dynamics needs ") +
            (trial.has_pelvis ? "" : "the six pelvis columns (column.pelvis_tilt ... pelvis_tz)") +
            (!trial.has_pelvis && !trial.has_grf ? " and " : "") +
            (trial.has_grf ? "" : "a grf_file") + "; or give knee_loads_file");
  }
  const bool left = trial.side == Side::kLeft;
  const double eps = 1e-4;  // [s] step along the local Taylor path (see header)
  const SegmentInertia* segs[2] = {&leg.shank, &leg.foot};
  out.X_WT.resize(n);

  for (int i = 0; i < n; ++i) {
    Coords q = trial.q.row(i).transpose(), qd = trial.qd.row(i).transpose(),
           qdd = trial.qdd.row(i).transpose();
    Eigen::Vector3d F_grf = trial.grf_force_W.row(i).transpose();
    Eigen::Vector3d c = trial.grf_cop_W.row(i).transpose();
    Eigen::Vector3d T_free = trial.grf_torque_W.row(i).transpose();
    if (left) {
      q = mirror_coordinates(q);
      qd = mirror_coordinates(qd);
      qdd = mirror_coordinates(qdd);
      F_grf = F_grf.cwiseProduct(kMirrorPolar);
      c = c.cwiseProduct(kMirrorPolar);
      T_free = T_free.cwiseProduct(kMirrorAxial);
    }
    LegPoses P[3];
    for (int k = 0; k < 3; ++k) {
      const double s = (k - 1) * eps;
      P[k] = leg_poses(leg, q + s * qd + 0.5 * s * s * qdd);
    }
    const Eigen::Isometry3d& X_WT = P[1].X_WT;
    const Eigen::Vector3d p_knee = X_WT.translation();
    const Eigen::Vector3d p_ankle = P[1].X_WC.translation();
    Eigen::Vector3d F = F_grf;
    Eigen::Vector3d M = (c - p_knee).cross(F_grf) + T_free;
    // The foot alone, about the ankle centre (the b == 1 terms below).
    Eigen::Vector3d F_foot = F_grf;
    Eigen::Vector3d M_foot = (c - p_ankle).cross(F_grf) + T_free;
    for (int b = 0; b < 2; ++b) {
      const SegmentInertia& seg = *segs[b];
      Eigen::Vector3d p[3];
      std::array<Eigen::Matrix3d, 3> R;
      for (int k = 0; k < 3; ++k) {
        const Eigen::Isometry3d& X = b == 0 ? P[k].X_WT : P[k].X_WC;
        p[k] = X * seg.p_com;
        R[k] = X.linear();
      }
      Eigen::Vector3d a = (p[2] - 2.0 * p[1] + p[0]) / (eps * eps);
      Eigen::Vector3d w, alpha;
      central_difference_rotation_rates(R, eps, w, alpha);
      const Eigen::Matrix3d I_W = R[1] * seg.inertia_about_com() * R[1].transpose();
      if (!options.include_inertia) a.setZero();
      const Eigen::Vector3d f = seg.mass_kg * (options.gravity_W - a);
      F += f;
      M += (p[1] - p_knee).cross(f);
      if (options.include_inertia) M -= I_W * alpha + w.cross(I_W * w);
      if (b == 1) {
        F_foot += f;
        M_foot += (p[1] - p_ankle).cross(f);
        if (options.include_inertia) M_foot -= I_W * alpha + w.cross(I_W * w);
      }
    }
    Eigen::Vector3d F_T = X_WT.linear().transpose() * F;
    Eigen::Vector3d M_T = X_WT.linear().transpose() * M;
    Eigen::Vector3d F_foot_T = X_WT.linear().transpose() * F_foot;
    Eigen::Vector3d M_foot_T = X_WT.linear().transpose() * M_foot;
    Eigen::Isometry3d X = X_WT;
    if (left) {
      F_T = F_T.cwiseProduct(kMirrorPolar);
      M_T = M_T.cwiseProduct(kMirrorAxial);
      F_foot_T = F_foot_T.cwiseProduct(kMirrorPolar);
      M_foot_T = M_foot_T.cwiseProduct(kMirrorAxial);
      // Mirror the pose back: R -> S R S, p -> S p with S = diag(1, 1, -1).
      const Eigen::Matrix3d S = kMirrorPolar.asDiagonal();
      X.linear() = S * X_WT.linear() * S;
      X.translation() = S * X_WT.translation();
    }
    std::ostringstream where;
    where << "knee inverse dynamics of " << trial.source << ", sample " << i << " (time "
          << trial.time(i) << " s)";
    common::check_finite(F_T, where.str());
    common::check_finite(M_T, where.str());
    common::check_finite(F_foot_T, where.str() + " (foot)");
    common::check_finite(M_foot_T, where.str() + " (foot)");
    out.F_ext_T.row(i) = F_T.transpose();
    out.F_foot_T.row(i) = F_foot_T.transpose();
    out.M_foot_T.row(i) = M_foot_T.transpose();
    out.M_ext_T.row(i) = M_T.transpose();
    out.X_WT[i] = X;
  }
  return out;
}

}  // namespace arthrosim::musculoskeletal
