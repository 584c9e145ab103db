#pragma once
// The kinematics file: the COMAK stage's HDF5 output and the contract with
// the surface stage. Schema (every dataset, unit and frame): docs/kinematics_file.md.
// Its one writer (KinematicsFileWriter) and one reader (KinematicsFileReader):
// no other file names a dataset of it.
//
// Frames are appended one by one (common::H5File::Appender with the expected
// frame count, flushed per frame), so a killed run keeps every frame written
// before the kill. finish() writes the run summary attributes, the effect
// ledger (/effects), the XDMF sidecar (per-triangle contact pressure for
// ParaView) and the OpenSim .sto exports.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "musculoskeletal/comak.h"

namespace arthrosim::common {
class EffectLedger;
class H5File;
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

/// A kinematics file without a COMAK run (canonical and synthetic cases of
/// the stages downstream): the frames' time, body poses and contact-force
/// series, every frame converged.
struct PrescribedKinematics {
  std::string world_frame;  ///< root attribute world_frame (what "W" is)
  Eigen::VectorXd time_s;
  /// body -> X_WB per frame.
  std::vector<std::pair<std::string, std::vector<Eigen::Isometry3d>>> body_poses;
  /// series (KinematicsFileReader::contact_force) -> frames x 3 [N].
  std::vector<std::pair<std::string, Eigen::MatrixXd>> contact_forces;
};
/// Writes `k` to `path` (truncates) in the kinematics file's schema.
void write_prescribed_kinematics(const std::string& path, const PrescribedKinematics& k);

/// Reads a kinematics file (its consumers: the surface stage's imposed
/// kinematics, the post stage's force curves, the accuracy study).
class KinematicsFileReader {
 public:
  /// Opens `path` (InputError naming it when it cannot be read).
  explicit KinematicsFileReader(const std::string& path);
  ~KinematicsFileReader();
  const std::string& path() const;
  /// /time [s], one entry per frame written.
  Eigen::VectorXd time() const;
  /// X_WB of `body` at every frame (frames x 4 x 4 in the file), each
  /// checked finite with a rotation block; InputError naming the dataset and
  /// frame otherwise, or when the frame count differs from time().
  std::vector<Eigen::Isometry3d> body_poses(const std::string& body) const;
  /// The dataset name of a body's poses (for messages).
  static std::string body_poses_dataset(const std::string& body);
  /// The tibiofemoral contact force (frames x 3, tibia frame [N]), or
  /// nullopt when the run simulated no contact.
  std::optional<Eigen::MatrixXd> tibiofemoral_force() const;
  /// A contact-force series (frames x 3 [N]) by name: "tibiofemoral" (the
  /// total, tibia frame), its compartments "medial" and "lateral", or
  /// "patellofemoral" (patella frame); nullopt when the file has none.
  std::optional<Eigen::MatrixXd> contact_force(const std::string& series) const;
  /// Stage 1's largest elastic-foundation contact pressure of the
  /// tibiofemoral pair per frame [Pa] (/contact/tibiofemoral/max_pressure),
  /// or nullopt when the file has none; InputError naming the dataset when
  /// its length differs from time().
  std::optional<Eigen::VectorXd> tibiofemoral_max_pressure() const;
  /// The dataset of tibiofemoral_max_pressure (for messages).
  static std::string tibiofemoral_max_pressure_dataset();
  /// The dataset of a contact-force series (for messages); std::invalid_argument
  /// for a name not listed at contact_force.
  static std::string contact_force_dataset(const std::string& series);
  /// Per frame: true when COMAK converged there (/solver/status 0); all true
  /// for a file without status.
  std::vector<bool> converged(Eigen::Index frames) const;
  /// The subject's mass (root attribute body_mass_kg) [kg]; 0 when the file
  /// does not record it.
  double body_mass_kg() const;
  /// Muscle names and activations (frames x muscles), or nullopt.
  std::optional<std::pair<std::vector<std::string>, Eigen::MatrixXd>> activations() const;
  /// Completeness (docs/kinematics_file.md, "Completeness"). Frames whose
  /// write completed (/time entries: a killed run's file ends at its last
  /// complete frame).
  std::int64_t frames_complete() const;
  /// Frames the run set out to solve (root attribute frames_expected); -1
  /// when the file does not record it.
  std::int64_t frames_expected() const;
  /// True when the run that wrote the file finished it (its run summary,
  /// root attribute `frames`, is written) and did not stop early (no
  /// attribute `stopped`).
  bool finished() const;
  /// "" when the file is complete (finished() and frames_complete() ==
  /// frames_expected()), else what it holds, e.g. "18 of 21 frames (the run
  /// stopped: ...)" (common::incompleteness).
  std::string incompleteness() const;
  /// What every consumer calls before it uses the frames: kind and version
  /// checked (InputError otherwise); an incomplete file is an InputError
  /// naming the file and what it holds unless `allow_partial`, which returns
  /// the line "PARTIAL INPUT: <file> is an incomplete kinematics file: ..."
  /// for the top of the consumer's report ("" for a complete file).
  std::string require_complete(bool allow_partial) const;
  /// The file (for generic listings: attributes, the force datasets under
  /// kContactGroup).
  const common::H5File& file() const;

  /// Group of the tibiofemoral contact datasets.
  static constexpr const char* kContactGroup = "/contact/tibiofemoral";
  static constexpr const char* kTibiofemoralForce = "/contact/tibiofemoral/force";
  static constexpr const char* kActivations = "/muscles/activation";

 private:
  std::unique_ptr<common::H5File> f_;
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

/// Tibiofemoral (every pair cast from the tibia) and patellofemoral (pairs
/// cast from the patella) contact, expressed in the tibia resp. patella
/// frame. Tibiofemoral compartments: a pair whose name contains
/// "medial"/"lateral" goes whole to that compartment; a pair with another
/// name whose casting surface carries compartment labels (one tibial
/// cartilage holding both plateaus, ContactSurface::compartment) is split per
/// casting triangle (casting_force_by_compartment); other pairs count in the
/// total only.
ContactSummary tibiofemoral_contact(const Model& model, const ModelData& data);
ContactSummary patellofemoral_contact(const Model& model, const ModelData& data);
/// How tibiofemoral_contact splits the compartments, per pair (the
/// attribute `compartments` of /contact/tibiofemoral).
std::string tibiofemoral_compartment_rule(const Model& model);

}  // namespace arthrosim::musculoskeletal
