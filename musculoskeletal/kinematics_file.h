#pragma once
// The kinematics file: the COMAK stage's HDF5 output and the contract with
// the surface stage. Schema (every dataset, unit and frame): docs/kinematics_file.md.
//
// Frames are appended one by one (common::H5File::Appender with the expected
// frame count, flushed per frame), so a killed run keeps every frame written
// before the kill. finish() writes the run summary attributes, the effect
// ledger (/effects), the XDMF sidecar (per-triangle contact pressure for
// ParaView) and the OpenSim .sto exports.
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "musculoskeletal/comak.h"

namespace arthrosim::common {
class EffectLedger;
struct RunMetadata;
}  // namespace arthrosim::common

namespace arthrosim::musculoskeletal {

struct KinematicsFileInfo {
  std::string model_path;      ///< as given
  std::string trial_path;      ///< as given
  double body_mass_kg = 0.0;   ///< subject mass (root attribute body_mass_kg)
  bool synthetic = false;      ///< the trial is synthetic (root attribute)
  std::int64_t expected_frames = 0;  ///< frames to be appended (preallocation)
  /// Write per-triangle pressure of every contact pair (/contact/pairs/...)
  /// and the XDMF sidecar <file>.xdmf.
  bool pressure_fields = true;
};

class KinematicsFileWriter {
 public:
  /// Creates (truncates) `path` and writes the static part (names, meshes,
  /// metadata). Throws InputError if the file cannot be created.
  KinematicsFileWriter(const std::string& path, const ComakProblem& problem,
                       const KinematicsFileInfo& info, const common::RunMetadata& metadata);
  ~KinematicsFileWriter();
  KinematicsFileWriter(const KinematicsFileWriter&) = delete;
  KinematicsFileWriter& operator=(const KinematicsFileWriter&) = delete;

  /// Appends one frame; `data` holds the model evaluated at the frame's
  /// solution (as run_comak hands it over).
  void append(const ComakFrameInput& input, const ComakFrameResult& result, const ModelData& data);

  /// Closes the appenders, writes the summary attributes (frames,
  /// frames_converged, frames_failed, failed_frames), the effect ledger, the
  /// XDMF sidecar and the .sto files <sto_prefix>_{activations,coordinates,
  /// contact_forces}.sto (no .sto when sto_prefix is empty).
  void finish(const ComakRunSummary& summary, const common::EffectLedger& ledger,
              const std::string& sto_prefix);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Contact quantities of one frame as written to the file (tests use it).
struct ContactSummary {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();          ///< on the casting body, its frame [N]
  Eigen::Vector3d medial_force = Eigen::Vector3d::Zero();   ///< [N] (tibiofemoral only)
  Eigen::Vector3d lateral_force = Eigen::Vector3d::Zero();  ///< [N] (tibiofemoral only)
  Eigen::Vector3d cop = Eigen::Vector3d::Zero();            ///< casting body frame [m]
  double area = 0.0;          ///< [m^2]
  double max_pressure = 0.0;  ///< [Pa]
};

/// Tibiofemoral (every pair cast from the tibia; medial/lateral by the pair
/// name containing "medial"/"lateral") and patellofemoral (pairs cast from
/// the patella) contact, expressed in the tibia resp. patella frame.
ContactSummary tibiofemoral_contact(const Model& model, const ModelData& data);
ContactSummary patellofemoral_contact(const Model& model, const ModelData& data);

}  // namespace arthrosim::musculoskeletal
