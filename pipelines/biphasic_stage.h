#pragma once
// The biphasic stage (issue 31, seed 000): cartilage layers of the prepared
// model as linear biphasic (u-p) volumes on rigid bones, loaded by the
// penetration method from the stage-1 kinematics file (bone poses, the
// tibiofemoral contact force per compartment). Method: docs/biphasic.md;
// library: biphasic/; output: docs/biphasic.md, "Output".
//
// Stage shape: options (this struct), a pure from_options check, build (read
// the files, crop, assemble, factorise) and run (preprocess every frame, step,
// write). When the stage-shape work (issue 29) lands, the options get their
// declare() and the stage its descriptor; the reading of the prepared model
// and the kinematics file moves to their reader modules.
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/options.h"

namespace arthrosim::pipelines {

struct StageDescriptor;

/// The biphasic block of a scene (docs/scenes.md) and the program's options.
struct BiphasicOptions {
  /// Effects to simulate: biphasic_layers and penetration_contact (the
  /// layers without contact conditions would carry nothing, the conditions
  /// need the layers: a scene lists both).
  std::vector<std::string> effects;
  /// Cartilage layers simulated (prepared surface names). The femur with the
  /// two tibial plates by default; "patella" adds the patellofemoral pair.
  std::vector<std::string> layers = {"femur", "tibia_medial", "tibia_lateral"};
  /// Element layers through the thickness [-]; 1..16.
  int element_layers = 2;
  /// Height ratio of successive element layers from the articular surface to
  /// the bone [-]; 1..4 (1: equal heights).
  double grading = 1.0;
  /// Time step [s]; > 0. Default: the bundled trial's frame interval.
  double time_step_s = 10 * common::units::ms;
  /// Generalised trapezoidal parameter [-]; in [0.5, 1] (docs/biphasic.md, "Time integration").
  double omega = 0.5;
  /// Material of every layer (docs/biphasic.md, "Parameters").
  double aggregate_modulus_Pa = 0.9 * common::units::mpa;
  double poisson_ratio = 0.02;
  double permeability_m4_per_Ns = 3e-15;
  /// Each layer is cut to the quads within this distance of a vertex that is
  /// in contact in some frame [m]; 0 keeps the whole surface. >= 0.
  double crop_margin_m = 5 * common::units::mm;
  /// Last frame time simulated [s]; none = the whole trial.
  std::optional<double> end_time_s;
  /// Wall time between checkpoints `<out>.checkpoint` [s] (0: after every
  /// step); a rerun of the same command continues from the last one
  /// (pipelines/biphasic_checkpoint.h).
  double checkpoint_interval_s = 60.0;
  void declare(common::OptionVisitor& v);
};

/// Everything the program needs: the files and the options (without a scene
/// both effects).
struct BiphasicStageOptions : BiphasicOptions {
  BiphasicStageOptions() { effects = {"biphasic_layers", "penetration_contact"}; }
  std::string prepared;    ///< prepared-model HDF5 (arthrosim-prepare)
  std::string kinematics;  ///< kinematics HDF5 (arthrosim-comak)
  std::string out;         ///< output HDF5 (XDMF sidecar next to it)
  bool progress = true;
  /// Go on with an incomplete kinematics file (a killed or stopped COMAK
  /// run; refused otherwise); the output then holds the root attribute
  /// partial_input saying so.
  bool allow_partial = false;
  std::vector<std::string> argv;  ///< for the run metadata
};

/// Checks every option alone and together (InputError naming the option).
void check_options(const BiphasicStageOptions& options);

/// The biphasic stage's entry in the stage table (pipelines/stages.h).
StageDescriptor biphasic_stage_descriptor();

struct BiphasicLayerSummary {
  std::string name;
  int quads_total = 0, quads_kept = 0;
  int unknowns = 0, free_unknowns = 0;
  long long matrix_nonzeros = 0;
  int factorizations = 0, solves = 0;
  double assembly_s = 0.0, factorization_s = 0.0, solve_s = 0.0, step_s = 0.0;
  double max_relative_residual = 0.0;
  double peak_fluid_pressure_Pa = 0.0;          ///< anywhere in the layer
  double peak_surface_fluid_pressure_Pa = 0.0;  ///< prescribed on the contact area
  double peak_tensile_Pa = 0.0, peak_shear_Pa = 0.0;
};

/// One layer at one of the key steps.
struct BiphasicKeyLayer {
  std::string name;
  double contact_area_m2 = 0.0, fluid_load_support = 0.0;
  double max_tensile_Pa = 0.0, max_shear_Pa = 0.0;
  std::string max_tensile_region, max_shear_region;
  double max_surface_fluid_pressure_Pa = 0.0;  ///< the prescribed contact pressure (eq 17)
};

/// The step with the largest summed compartment force in the first and in the
/// second half of the run (the two peaks of stance in a gait cycle).
struct BiphasicKeyStep {
  int step = 0;
  double time_s = 0.0, force_N = 0.0;
  std::vector<BiphasicKeyLayer> layers;
};

struct BiphasicStageResult {
  int frames = 0;            ///< stage-1 frames used
  int frames_failed = 0;     ///< stage-1 frames whose solver failed (left out, reported)
  int steps = 0;
  int skipped_pair_frames = 0;  ///< (pair, frame) with a force but no overlap
  int unloaded_pair_frames = 0;  ///< (pair, frame) with no force but an overlap (no conditions applied)
  std::vector<BiphasicLayerSummary> layers;
  std::vector<BiphasicKeyStep> key_steps;
  /// Mean fluid load support of each layer over the steps with contact.
  std::vector<double> mean_fluid_load_support;
  double preprocessing_s = 0.0, build_s = 0.0, stepping_s = 0.0, wall_s = 0.0;
  int checkpoints = 0;     ///< checkpoints written by this run
  int resumed_steps = 0;   ///< steps taken from a checkpoint (0: a fresh run)
  /// "PARTIAL INPUT: ..." when run on an incomplete kinematics file (allow_partial), else "".
  std::string partial_input;
};

BiphasicStageResult run_biphasic_stage(const BiphasicStageOptions& options);

/// The canonical case for users to check the method: two layers pressed
/// together. Writes `<dir>/two_layers_prepared.h5` (a prepared model with a
/// "femur" layer of 12 x 12 mm, 1.5 mm thick, its articular surface the
/// paraboloid y = (x^2 + z^2) / (2 R), R = 30 mm, facing down, over a flat
/// "tibia_medial" plate of 16 x 16 mm, 2 mm thick, facing up; knee frame
/// convention Y superior) and `<dir>/two_layers_kinematics.h5` (the femur
/// pressed into the plate: overlap at the apex ramped from 0 to 0.15 mm over
/// 0.5 s and held to 1 s, contact radius sqrt(2 R d) = 3 mm, medial contact
/// force ramped to 200 N with it; 10 ms frames) with the datasets the stage
/// reads. Returns the two paths.
std::pair<std::string, std::string> write_two_layer_case(const std::string& dir);

}  // namespace arthrosim::pipelines
