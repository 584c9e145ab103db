#pragma once
// The musculoskeletal (COMAK) stage: its scene block (comak:) and descriptor.
// Method: musculoskeletal/comak.h, docs/comak.md; output: the kinematics
// file (docs/kinematics_file.md).
#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "common/options.h"
#include "musculoskeletal/comak.h"
#include "musculoskeletal/gait_trial.h"

namespace arthrosim::common {
struct Scene;
}

namespace arthrosim::pipelines {

struct StageDescriptor;

/// The comak block of a scene.
struct ComakStageOptions {
  /// Effects to simulate: muscles (required: they balance the flexion row),
  /// ligaments, and tibiofemoral_contact with patellofemoral_contact (one
  /// contact term: both or neither).
  std::vector<std::string> effects;
  musculoskeletal::ComakOptions solver;
  /// The trial's processing (its low-pass filter).
  musculoskeletal::GaitTrialOptions trial;
  /// The time window of the trial to solve [s] (the scene's top-level
  /// trial.start_s / trial.end_s; NaN: from the first / to the last frame).
  /// The whole trial is still filtered and differentiated. When either is
  /// set, it replaces the frame range of ComakStageConfig.
  double start_time_s = std::numeric_limits<double>::quiet_NaN();
  double end_time_s = std::numeric_limits<double>::quiet_NaN();
  /// Wall time between checkpoints `<out>.checkpoint` [s] (0: after every
  /// frame). A rerun of the same command (same inputs, options, command line
  /// and build) continues from the last checkpoint with datasets
  /// bit-identical to an uninterrupted run (pipelines/comak_checkpoint.h).
  double checkpoint_interval_s = 60.0;
  void declare(common::OptionVisitor& v);
};

/// The comak stage's entry in the stage table (pipelines/stages.h).
StageDescriptor comak_stage_descriptor();

/// Checks a comak effect list: muscles are required (they balance the
/// flexion row), tibiofemoral_contact and patellofemoral_contact come
/// together (one contact term). InputError naming `where` otherwise.
void check_comak_effects(const std::vector<std::string>& effects, const std::string& where);

/// The comak block of a scene as options, effects checked, with the scene's
/// trial window (pure: no file is read). A scene without a comak block gives
/// the defaults with every effect.
ComakStageOptions comak_from_scene(const common::Scene& scene);

/// Everything one run of the stage needs.
struct ComakStageConfig {
  ComakStageOptions options;
  std::filesystem::path model;     ///< URDF or model folder (comak_model_file)
  std::filesystem::path prepared;  ///< prepared-model HDF5; empty: the model file's meshes
  std::filesystem::path trial;     ///< trial description or its folder
  std::filesystem::path out;       ///< the kinematics file to write
  std::string sto_prefix;          ///< of the .sto exports; empty: `out` without .h5
  int first_frame = 0, last_frame = -1, stride = 1;  ///< trial frames (last -1: the last)
  bool pressure_fields = true;     ///< per-triangle pressure and the XDMF sidecar
  std::filesystem::path scene;     ///< for the run metadata; empty: none
  std::vector<std::string> argv;   ///< the command line, for the run metadata
};

struct ComakStageResult {
  musculoskeletal::ComakRunSummary summary;
  /// Frames taken from a checkpoint of an earlier killed run (0: none).
  int resumed_frames = 0;
  /// Checkpoints written, and the size of the last one [bytes].
  int checkpoints = 0;
  std::uintmax_t checkpoint_bytes = 0;
  /// A non-finite value stopped the run at stopped_frame; the frames before
  /// it are in <out>.partial (attribute `stopped`; a previous <out> is kept).
  bool stopped = false;
  int stopped_frame = -1;
};

/// Builds (model with its prepared surfaces and the ankle muscles when
/// asked, trial and its loads: the generic leg chain, or for a model with
/// its own leg to the ground the model's dynamics; the NLP) and runs the stage: every frame
/// solved and written into the kinematics file as it converges
/// (docs/kinematics_file.md), with progress. Throws common::InputError for bad
/// input.
ComakStageResult run_comak_stage(const ComakStageConfig& config);

/// The URDF the stage loads for a scene's `model`: the file itself, or for a
/// folder the one URDF inside it, else the one URDF next to it that
/// references meshes in it ("<folder>/" in the file, as the bundled knee.urdf
/// references medium/...). Anything else is an InputError naming what was
/// found.
std::filesystem::path comak_model_file(const std::filesystem::path& model);

}  // namespace arthrosim::pipelines
