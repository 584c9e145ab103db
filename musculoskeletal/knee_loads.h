#pragma once
// External loads on the tibia at the knee over a walking trial: a small
// inverse dynamics of the foot and shank, or the loads given by the trial.
//
// What is computed. The shank (tibia frame T) and the foot (frame C) are two
// rigid bodies whose poses follow from the trial's pelvis pose and joint
// angles through an open chain (right leg; OpenSim CustomJoint order):
//   R_WP = Rz(tilt) Rx(list) Ry(rotation),  p_WP = (tx, ty, tz)
//   R_WF = R_WP Rz(hip_flexion) Rx(hip_adduction) Ry(hip_rotation),
//   p_hip = p_WP + R_WP p_PH_P,  p_knee = p_hip + R_WF (0, -L_thigh, 0)
//   R_WT = R_WF Rz(-knee_flexion),  p_ankle = p_knee + R_WT (0, -L_shank, 0)
//   R_WC = R_WT Rz(ankle_flexion)  (the ankle is a hinge about the tibia's Z;
//   no subtalar joint, no knee translations).
// Full 3D Newton-Euler of the shank+foot system, nothing planar: with COM
// accelerations a_i, angular velocities w_i and accelerations alpha_i (i =
// shank, foot; inertia I_i in the world frame), gravity g = (0, -9.80665, 0),
// the ground reaction F_grf at the COP c with free moment T_free, and k the
// knee joint centre (origin of T):
//   F_ext = F_grf + sum_i m_i (g - a_i)
//   M_ext = (c - k) x F_grf + T_free + sum_i (p_i - k) x m_i (g - a_i)
//           - sum_i (I_i alpha_i + w_i x I_i w_i)
// F_ext and M_ext (about k) are the resultant load ON the tibia FROM the ground
// (through the foot) and from gravity and inertia (d'Alembert) of the shank
// and foot; what crosses the knee (contact, ligaments, knee-spanning muscles)
// must balance them: F_knee = -F_ext, M_knee = -M_ext. Muscles that span
// only the ankle are internal to the shank+foot system and do not appear.
// Standing still: F_ext = F_grf - (m_shank + m_foot) g_down; in swing (no
// ground reaction) F_ext = -(weights + m a). Both are returned expressed in the
// tibia frame T (X anterior, Y proximal along the shank, Z to the right =
// lateral for a right leg): F_ext_T = R_WT^T F_ext.
//
// Kinematic derivatives: at each sample the coordinates follow the local
// Taylor path q(s) = q + s qd + s^2/2 qdd; the body poses along it are
// differentiated by central differences in s (step 1e-4 s; truncation and
// rounding errors ~1e-7 relative), giving v, a of the COMs and, from
// [w]x = dR/ds R^T and [alpha]x = d2R/ds2 R^T - [w]x^2, the angular terms.
// qd and qdd come from the trial (filtered, central differences; gait_trial.h).
//
// Left leg: the trial is mirrored through the sagittal plane (z -> -z: pelvis
// list, rotation and tz negated; forces and COP z negated; torques x, y
// negated), solved as a right leg and mirrored back. The left tibia frame is
// then X anterior, Y proximal, Z to the right (= medial for the left leg).
#include <Eigen/Geometry>
#include <optional>
#include <string>
#include <vector>

#include "musculoskeletal/anthropometry.h"
#include "musculoskeletal/gait_trial.h"

namespace arthrosim::musculoskeletal {

struct LegPoses {
  Eigen::Isometry3d X_WP, X_WF, X_WT, X_WC;  ///< pelvis, thigh, tibia, foot in the lab
};

/// Forward kinematics of a right leg for one row of coordinates (SI units,
/// TrialCoordinate order).
LegPoses leg_poses(const LegModel& leg, const Eigen::Matrix<double, kNumTrialCoordinates, 1>& q);

/// The leg model of a trial: anthropometry from its mass and height, then the
/// trial's leg.* overrides.
LegModel leg_model_for_trial(const GaitTrial& trial);

struct KneeLoadOptions {
  /// Gravity in the lab frame [m/s^2].
  Eigen::Vector3d gravity_W = Eigen::Vector3d(0.0, -9.80665, 0.0);
  /// Include the d'Alembert terms m a and I alpha + w x I w (off = quasi-static).
  bool include_inertia = true;
};

enum class KneeLoadSource { kInverseDynamics, kGivenByTrial };

/// Time series of the knee loads and the angles COMAK prescribes.
struct KneeLoads {
  KneeLoadSource source = KneeLoadSource::kInverseDynamics;
  Eigen::VectorXd time;                 ///< n [s]
  Eigen::VectorXd knee_flexion;         ///< n [rad]
  Eigen::VectorXd knee_flexion_velocity;      ///< n [rad/s]
  Eigen::VectorXd knee_flexion_acceleration;  ///< n [rad/s^2]
  Eigen::MatrixXd hip_angles;           ///< n x 3 flexion, adduction, rotation [rad]
  Eigen::VectorXd ankle_flexion;        ///< n [rad]
  /// n x kNumTrialCoordinates coordinates and derivatives (copied from the trial).
  Eigen::MatrixXd q, qd, qdd;
  Eigen::MatrixXd F_ext_T;              ///< n x 3 [N], on the tibia, tibia frame
  Eigen::MatrixXd M_ext_T;              ///< n x 3 [N m], about the knee centre, tibia frame
  /// The load on the FOOT from the ground and from the foot's own weight and
  /// inertia (d'Alembert), about the ankle joint centre, in the tibia frame:
  ///   F_foot = F_grf + m_f (g - a_f),
  ///   M_foot = (c - p_a) x F_grf + T_free + (p_f - p_a) x m_f (g - a_f)
  ///            - (I_f alpha_f + w_f x I_f w_f).
  /// The muscles spanning the ankle balance its component about the ankle
  /// axis (COMAK's optional ankle equilibrium, comak.h). Inverse dynamics
  /// only (has_foot_loads); empty for loads given by the trial.
  bool has_foot_loads = false;
  Eigen::MatrixXd F_foot_T;             ///< n x 3 [N]
  Eigen::MatrixXd M_foot_T;             ///< n x 3 [N m], about the ankle centre
  /// The ankle joint centre of the leg model in the tibia frame [m]:
  /// (0, -shank_length, 0).
  Eigen::Vector3d ankle_centre_T = Eigen::Vector3d::Zero();
  /// Tibia poses in the lab (inverse dynamics only; empty otherwise).
  std::vector<Eigen::Isometry3d> X_WT;
  /// Copied from the trial: set when a non-finite trial value ended it
  /// early (GaitTrialOptions::truncate_at_non_finite); frames from
  /// truncated->frame on have no loads.
  std::optional<TrialTruncation> truncated;
  int num_samples() const { return static_cast<int>(time.size()); }
};

/// Knee loads of a trial: the trial's own knee loads when it gives them,
/// otherwise the inverse dynamics above (needs pelvis columns and GRF; throws
/// common::InputError naming the trial otherwise). Non-finite results throw
/// common::NumericalError naming the sample.
KneeLoads compute_knee_loads(const GaitTrial& trial, const LegModel& leg,
                             const KneeLoadOptions& options = {});

}  // namespace arthrosim::musculoskeletal
