#pragma once
// The shockwave stage (arthrosim-shockwave, issue 32): the poroelastic movable
// cellular automata model of seed 001 (shockwave/, docs/shockwave.md) on the
// prepared knee. Reads the prepared model (bones, cartilage surfaces and
// thickness, docs/prepared_model.md) and the meniscus meshes of the model
// folder (`<name>_meniscus.{stl,obj,ply}`), builds the knee of automata
// (shockwave/knee_model.h) and runs, per energy flux density of the options,
// one pulse through the applicator; or, with the effect platen_compression, a
// slow compression of the knee between its cut faces (the seed's convergence
// and validation loading). Writes one HDF5 + XDMF pair per run
// (pipelines/shockwave_output.h, schema in docs/shockwave.md) and a summary
// (JSON, and an SVG plot of the regeneration volumes against the EFD).
//
// Stage shape: the options struct declares its scene keys, units, ranges and
// the one default of each (declare(), the `shockwave` block of a scene);
// shockwave_from_scene() reads and checks the block (pure); build() turns
// options into the model (reads files, no physics); run() simulates one run;
// shockwave_stage_descriptor() is its entry in the stage table.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/options.h"
#include "shockwave/criteria.h"
#include "shockwave/knee_model.h"
#include "shockwave/simulation.h"

namespace arthrosim::common {
struct Scene;
}

namespace arthrosim::pipelines {

struct ShockwaveStageOptions {
  // --- files (given by the runner / on the command line) -------------------
  std::filesystem::path prepared;  ///< prepared-model HDF5
  std::filesystem::path model;     ///< model folder (for the meniscus meshes; "" = none)
  /// Output stem: writes <stem>_efd<value>.h5 (+ .xdmf) per EFD, or
  /// <stem>_compression.h5, and <stem>_summary.json / _volumes.svg.
  std::filesystem::path out = "shockwave";

  // --- declared options (SI values; their one default here) ---------------
  std::vector<std::string> effects{"mca_elastic", "pore_fluid", "filtration", "applicator_pulse"};
  std::string geometry = "knee";
  std::string bar_tissue = "cartilage";
  double bar_length_m = 100 * common::units::mm;
  std::string lattice = "fcc";
  double automaton_diameter_m = 1 * common::units::mm;
  double femur_cut_m = 40 * common::units::mm;
  double tibia_cut_m = 40 * common::units::mm;
  double capsule_margin_m = 5 * common::units::mm;
  double shell_thickness_m = 2 * common::units::mm;
  double cortical_thickness_m = 2 * common::units::mm;
  std::string applicator_face = "-z";
  std::vector<double> applicator_centre_m;  ///< empty = over the medial meniscus
  double applicator_size_m = 20 * common::units::mm;
  double applicator_thickness_m = 1 * common::units::mm;
  std::vector<double> efd_j_per_m2{0.33 * common::units::mj_per_mm2};
  std::string efd_reference = "applicator";  ///< water|applicator (docs/shockwave.md, "The pulse")
  double efd_impedance = 1.5e6;  ///< [Pa s/m]
  double pulse_rise_time_s = 1.5 * common::units::us;
  double pulse_fall_time_s = 1.5 * common::units::us;
  double pulse_positive_duration_s = 4 * common::units::us;
  double pulse_tail_duration_s = 20 * common::units::us;
  double pulse_tail_fraction = 0.75;
  double end_time_s = 100 * common::units::us;
  double output_interval_s = 10 * common::units::us;
  bool write_frames = true;
  double time_step_safety = 0.5;
  double fluid_bulk_modulus_pa = 2400 * common::units::mpa;
  double fluid_density = 1000.0;
  double fluid_viscosity = 0.69e-3;  ///< [Pa s]
  std::filesystem::path tissue_table;  ///< CSV overriding Table 1 ("" = none)
  double compression_displacement_m = 0.3 * common::units::mm;
  double compression_time_s = 400 * common::units::us;
  double compression_damping = 0.0;  ///< [1/s]; 0 = about critical for the knee's lowest mode
  double compressive_stress_min_pa = 0.15 * common::units::mpa;
  double distortional_strain_min = 0.05e-2;
  double distortional_strain_max = 1.1e-2;
  double pore_pressure_min_pa = 0.02 * common::units::mpa;
  double pore_pressure_max_pa = 2 * common::units::mpa;
  /// Wall time between checkpoints <out>.checkpoint [s] (0: after every step).
  double checkpoint_interval_s = 60.0;

  // Defaults with a unit are written as number times unit (common/options.h),
  // so that each is exactly what the scene reader makes of its text.
  void declare(common::OptionVisitor& v);
};

/// The effects the stage knows: (name, one-line description).
const std::vector<std::pair<std::string, std::string>>& shockwave_effects();

/// Checks the options alone and together (effects, loading, regeneration
/// ranges): InputError naming `source`. build_shockwave_model calls it.
void check_shockwave_options(const ShockwaveStageOptions& options, const std::string& source);

/// The shockwave block of a scene as options, checked (pure: no file is read);
/// the files (prepared, model, out) are left for the caller.
ShockwaveStageOptions shockwave_from_scene(const common::Scene& scene);

/// The runs of the options, by label ("efd0.33" per EFD, or "compression"):
/// each writes <out>_<label>.h5 (+ .xdmf).
std::vector<std::string> shockwave_run_labels(const ShockwaveStageOptions& options);

struct StageDescriptor;
/// The shockwave stage's entry in the stage table (pipelines/stages.h).
StageDescriptor shockwave_stage_descriptor();

/// One run's results.
struct ShockwaveRunResult {
  std::string label;            ///< "efd0.33" or "compression"
  std::filesystem::path file;   ///< its HDF5 file
  double efd_j_per_m2 = 0.0;    ///< 0 for compression
  double peak_pressure_pa = 0.0;  ///< of the applied pulse (applicator reading: of the driven face on the body)
  std::int64_t steps = 0;
  int frames = 0;
  double wall_s = 0.0;
  double cpu_s = 0.0;
  /// Regeneration volumes on the peaks, per knee tissue (KneeTissue order).
  std::vector<shockwave::RegenerationVolumes> volumes;
  /// Largest (over frames) volume where all three criteria held at once.
  std::vector<double> all_at_once_m3;
  /// Largest peak of each field per tissue: P, distortional strain, pore pressure.
  std::vector<std::array<double, 3>> max_peaks;
  double energy_residual = 0.0;  ///< |balance residual| / work at the end (pulse runs)
  // platen_compression:
  double force_n = 0.0, displacement_m = 0.0, stiffness_n_per_m = 0.0;
  // bar: measured p-wave speed (arrival of the front, half its peak, at 1/4
  // and 3/4 of the length)
  // and the closed forms sqrt((K + 4G/3)/rho), sqrt((K_u + 4G/3)/rho).
  double bar_speed = 0.0, bar_drained_speed = 0.0, bar_undrained_speed = 0.0;
};

struct ShockwaveStageResult {
  int automata = 0;
  std::int64_t bonds = 0;
  std::vector<std::int64_t> per_tissue;
  double time_step_s = 0.0, critical_time_step_s = 0.0, fastest_p_wave = 0.0;
  std::string critical_tissue, fastest_p_wave_tissue;
  int filtration_substeps = 0;
  double build_s = 0.0;
  std::vector<ShockwaveRunResult> runs;
  int checkpoints = 0;        ///< written by this process (pipelines/shockwave_checkpoint.h)
  int runs_taken = 0;         ///< finished runs taken from a checkpoint, not simulated again
  std::int64_t resumed_steps = 0;  ///< steps of the run in progress taken from a checkpoint
  std::filesystem::path summary_json, volumes_svg;
};

/// The knee (or the bar) of automata from the options' files (no simulation).
struct ShockwaveModel {
  bool bar = false;
  shockwave::Model model;
  shockwave::KneeModelInfo info;
  shockwave::KneeModelOptions knee_options;
};
/// Checks the options (InputError naming `source`) and builds the model.
ShockwaveModel build_shockwave_model(const ShockwaveStageOptions& options, const std::string& source);

/// Runs every run of the options (one per EFD, or the compression) on a built
/// model, writing the files; `argv` goes into the run metadata.
/// `dry_run`: build the model and choose the time step, report the steps of
/// every run (ShockwaveRunResult::steps), simulate and write nothing.
ShockwaveStageResult run_shockwave_stage(const ShockwaveStageOptions& options, const std::vector<std::string>& argv,
                                         bool progress = true, bool dry_run = false);

}  // namespace arthrosim::pipelines
