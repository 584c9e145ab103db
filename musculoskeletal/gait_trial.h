#pragma once
// Walking trials as OpenSim users have them: joint angles from an
// inverse-kinematics .mot/.sto, ground reactions from an ExternalLoads-style
// .mot, subject mass and height, all described by a small trial file.
//
// Trial description (e.g. data/trials/synthetic_gait/trial.yaml). It is valid
// YAML restricted to flat "key: value" lines (comments '#', blank lines), so it
// is read line by line here with file:line errors (yaml-cpp is private to
// arthrosim_common). Keys:
//   subject_mass_kg: 61         subject_height_m: 1.65
//       (optional: without them the mass comes from the model, see
//       Model::subject_mass_kg, and the generic leg chain of knee_loads.h,
//       which needs the height, cannot be used)
//   side: right|left            lab_frame: opensim_x_forward_y_up_z_right (required)
//   kinematics_file: ik.mot     (required; paths relative to the trial file)
//   grf_file: grf.mot           knee_loads_file: loads.sto
//   external_loads_file: ext_loads.xml
//       (at least one of the three; grf_file and external_loads_file exclude
//       each other). external_loads_file is OpenSim's ExternalLoads XML
//       (external_loads.h): every ExternalForce it lists is read with the
//       body it acts on and its columns; no column.grf_* mapping is needed.
//   foot_body: calcn_r          with external_loads_file: the ExternalForce
//       acting on this body is the foot's ground reaction of the generic leg
//       chain (grf_* below; exactly one force must act on it). A model with
//       its own foot bodies takes every force acting on one of its bodies
//       (comak_model_loads.h) and needs no foot_body.
//   synthetic: true|false       description: free text
//   periodic: true|false        the kinematics are exactly one cycle (last row
//                               = first row one period later; pelvis_tx/tz may
//                               drift): filter and differentiate periodically
//   column.<quantity>: <label>  maps a quantity to a column; "-label" negates it.
//   leg.thigh_length_m, leg.shank_length_m, leg.ankle_height_m,
//   leg.foot_length_m, leg.hip_x_m, leg.hip_y_m, leg.hip_z_m: override the
//   stature-based geometry of musculoskeletal/anthropometry.h (hip = hip joint
//   centre in the pelvis frame) so it matches the model that produced the IK.
// Quantities (kinematics file): pelvis_tilt, pelvis_list, pelvis_rotation,
// pelvis_tx, pelvis_ty, pelvis_tz, hip_flexion, hip_adduction, hip_rotation,
// knee_flexion, ankle_flexion. The five joint angles are required unless the
// trial has an external_loads_file (then a model with its own coordinates
// reads the kinematics columns by coordinate name, GaitTrial::kinematics_*);
// the six pelvis columns are needed for the inverse dynamics (all or none). Angles are
// converted to radians when the file says inDegrees=yes. Sign conventions are
// OpenSim's (gait2392/Rajagopal): hip flexion, adduction and internal rotation
// positive, knee flexion positive (map "-knee_angle_r" for gait2392, whose knee
// angle is negative in flexion), ankle dorsiflexion positive.
// Quantities (GRF file, lab frame, on the foot from the ground): grf_force_x/y/z
// [N], grf_cop_x/y/z [m], grf_torque_x/y/z [N m] (torque about the COP, the free
// moment). Quantities (knee loads file, tibia frame, about the knee centre; the
// load on the tibia from the distal segments and the ground, see knee_loads.h):
// knee_force_x/y/z [N], knee_moment_x/y/z [N m].
//
// Lab frame: OpenSim's, X forward, Y up, Z to the right; gravity -Y.
//
// Processing (load_gait_trial): every table is resampled by linear
// interpolation onto one uniform grid at options.rate_hz covering the time
// range common to all files; kinematics are low-pass filtered (zero-lag
// Butterworth, musculoskeletal/signal.h; 6 Hz, 2nd order per pass by default;
// padded by odd reflection, or periodically for a periodic trial) and
// differentiated by central differences to velocities and accelerations;
// ground reactions are not filtered by default (their steps at heel strike and
// toe-off would leak into swing) and are zeroed wherever the vertical force is
// below options.min_vertical_grf_n (COP undefined there). Every column of the
// kinematics file (not only the mapped quantities) is processed the same way
// into GaitTrial::kinematics_labels/q/qd/qdd, and every ExternalForce of an
// external_loads_file into GaitTrial::external_forces.
#include <Eigen/Core>
#include <functional>
#include <iosfwd>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "musculoskeletal/signal.h"

namespace arthrosim::musculoskeletal {

enum class Side { kRight, kLeft };

/// Columns of GaitTrial::q (and qd, qdd).
enum TrialCoordinate : int {
  kPelvisTilt = 0, kPelvisList, kPelvisRotation, kPelvisTx, kPelvisTy, kPelvisTz,
  kHipFlexion, kHipAdduction, kHipRotation, kKneeFlexion, kAnkleFlexion,
  kNumTrialCoordinates
};
/// Quantity names of the TrialCoordinate columns ("pelvis_tilt", ...).
const std::vector<std::string>& trial_coordinate_names();

struct ColumnMapping {
  std::string label;   ///< column label in the file
  double sign = 1.0;   ///< -1 when the mapping starts with '-'
  int line = 0;        ///< line of the mapping in the trial file
};

struct TrialDescription {
  std::string path;                   ///< the trial file as given
  bool synthetic = false;
  bool periodic = false;
  std::string description;
  double subject_mass_kg = 0.0;
  double subject_height_m = 0.0;
  Side side = Side::kRight;
  std::string kinematics_file;        ///< resolved against the trial file's folder
  std::string grf_file;               ///< empty when absent
  std::string knee_loads_file;        ///< empty when absent
  std::string external_loads_file;    ///< OpenSim ExternalLoads XML, empty when absent
  std::string foot_body;              ///< body of the generic chain's ground reaction, or empty
  std::map<std::string, ColumnMapping> columns;  ///< quantity -> column
  std::map<std::string, double> leg_overrides;   ///< "thigh_length_m" -> value, ...
  std::map<std::string, int> key_lines;          ///< key -> line (for messages)
};

/// Reads a trial description (a folder means the trial.yaml inside it); throws common::InputError "file:line: error: ..."
/// on unknown keys, nested YAML, bad numbers, duplicate or missing keys.
TrialDescription read_trial_description(const std::string& path);
/// Same from a stream; relative file names are resolved against `directory`.
TrialDescription parse_trial_description(std::istream& in, const std::string& source_name,
                                         const std::string& directory);

struct GaitTrialOptions {
  /// Output sampling rate [Hz], > 0. COMAK works at 100 Hz.
  double rate_hz = 100.0;
  /// Low-pass of the kinematics (cutoff of each pass 6 Hz, 2nd order per pass).
  LowPassOptions lowpass;
  bool filter_kinematics = true;
  /// Low-pass the ground reactions with the same filter (off: see header).
  bool filter_grf = false;
  /// Below this vertical ground reaction [N] force, torque and COP are set to 0.
  double min_vertical_grf_n = 10.0;
  /// A non-finite value in a mapped column: false (default) throws
  /// InputError "file:line: error: non-finite value in column 'c' (time t s)";
  /// true keeps the trial up to the last row before it (in every file) and
  /// records where it ends in GaitTrial::truncated, so a consumer can run the
  /// frames before it and stop at the first frame it cannot compute, naming
  /// that frame and the file, line and column (arthrosim-comak does). The
  /// shortened trial is filtered non-periodically (it is no longer one cycle).
  /// A non-finite time stays an InputError; so does a bad value leaving fewer
  /// than 4 samples.
  bool truncate_at_non_finite = false;
  /// Which columns of the kinematics file are angles (converted from degrees
  /// when the file says inDegrees=yes) in GaitTrial::kinematics_*: empty =
  /// common::default_is_rotational; a model passes its revolute coordinates.
  std::function<bool(const std::string&)> is_rotational;
};

/// Where a trial read with truncate_at_non_finite ends early.
struct TrialTruncation {
  int frame = 0;           ///< first sample of the full grid that is not in the trial
  double time = 0.0;       ///< its time [s]
  int full_samples = 0;    ///< samples the grid would have without the bad value
  std::string reason;      ///< "ik.mot:48: non-finite value in column 'knee_angle_r' (time 0.35 s)"
};

/// A trial on a uniform time grid, SI units, lab frame.
/// One ExternalForce of an external_loads_file on the trial's grid (lab
/// frame): the force on `body` from the ground [N], its point of application
/// [m] (zero without a point identifier) and the free torque [N m] (zero
/// without a torque identifier). Force, point and torque are zero wherever
/// the force's vertical component is below GaitTrialOptions::min_vertical_grf_n.
struct TrialExternalForce {
  std::string name;   ///< ExternalForce name
  std::string body;   ///< applied_to_body
  bool has_point = false, has_torque = false;
  Eigen::MatrixXd force_W, point_W, torque_W;  ///< n x 3 each
};

struct GaitTrial {
  std::string source;            ///< trial file
  bool synthetic = false;
  bool periodic = false;         ///< filtered/differentiated as one cycle
  double body_mass_kg = 0.0;     ///< 0 when the trial does not give it
  double height_m = 0.0;         ///< 0 when the trial does not give it
  Side side = Side::kRight;
  double rate_hz = 0.0;
  Eigen::VectorXd time;          ///< n [s]
  /// n x kNumTrialCoordinates: angles [rad], pelvis translations [m], and their
  /// first and second time derivatives. Unmapped pelvis columns are zero.
  Eigen::MatrixXd q, qd, qdd;
  bool has_pelvis = false;
  /// The five joint angles of q are mapped (column.hip_flexion ...
  /// ankle_flexion); load_gait_trial sets false for a trial without them.
  bool has_joint_angles = true;
  bool has_grf = false;
  Eigen::MatrixXd grf_force_W;   ///< n x 3 [N] on the foot from the ground
  Eigen::MatrixXd grf_cop_W;     ///< n x 3 [m]
  Eigen::MatrixXd grf_torque_W;  ///< n x 3 [N m] about the COP
  bool has_knee_loads = false;
  Eigen::MatrixXd knee_force_T;  ///< n x 3 [N], given by the trial
  Eigen::MatrixXd knee_moment_T; ///< n x 3 [N m], given by the trial
  /// Every column of the kinematics file (labels without time), resampled,
  /// filtered and differentiated like q: angles [rad] (per
  /// GaitTrialOptions::is_rotational), translations [m]; n x labels.
  std::vector<std::string> kinematics_labels;
  Eigen::MatrixXd kinematics_q, kinematics_qd, kinematics_qdd;
  /// Column of `label` in kinematics_*, -1 if absent.
  int kinematics_column(const std::string& label) const;
  /// Every ExternalForce of the trial's external_loads_file.
  std::vector<TrialExternalForce> external_forces;
  std::string external_loads_file;  ///< as resolved, empty when absent
  std::map<std::string, double> leg_overrides;  ///< from the description
  /// Set when a non-finite value ended the trial early (see
  /// GaitTrialOptions::truncate_at_non_finite); the samples above are those
  /// before it.
  std::optional<TrialTruncation> truncated;
  int num_samples() const { return static_cast<int>(time.size()); }
};

/// The first and last sample of the trial's grid inside the time window
/// [start_s, end_s] (NaN = the trial's first / last time), within 1e-9 s.
/// Throws InputError naming the trial when the window is empty, reversed or
/// outside the trial's time range.
std::pair<int, int> frames_in_window(const GaitTrial& trial, double start_s, double end_s);

/// Loads, resamples, filters and differentiates a described trial.
GaitTrial load_gait_trial(const TrialDescription& description, const GaitTrialOptions& options = {});
GaitTrial load_gait_trial(const std::string& trial_path, const GaitTrialOptions& options = {});

}  // namespace arthrosim::musculoskeletal
