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
// Stage shape: build() turns options into the model (reads files, no
// physics), run() simulates one run; the options struct declares its keys,
// units, ranges and the one default of each (declare()). The visitor is a
// template parameter so the declaration works with the local CLI visitor of
// arthrosim-shockwave now and with the generic scene visitor of the stage
// table (common/options.h on the `shape` branch) once the stage is registered
// there: the keys, units (_mm, _us, _mpa, _mj_per_mm2, _kg_per_m3) and ranges
// carry over unchanged.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "shockwave/criteria.h"
#include "shockwave/knee_model.h"
#include "shockwave/simulation.h"

namespace arthrosim::pipelines {

/// Units as written in the options (factor to SI), for declare().
struct OptionUnit {
  const char* suffix;  ///< e.g. "_mm"; "" for SI or dimensionless
  double to_si;
};
namespace units {
inline constexpr OptionUnit none{"", 1.0};
inline constexpr OptionUnit mm{"_mm", 1e-3};
inline constexpr OptionUnit us{"_us", 1e-6};
inline constexpr OptionUnit mpa{"_mpa", 1e6};
inline constexpr OptionUnit kg_per_m3{"_kg_per_m3", 1.0};
inline constexpr OptionUnit mj_per_mm2{"_mj_per_mm2", 1e3};  ///< -> J/m^2
}  // namespace units

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
  double bar_length_m = 100e-3;
  std::string lattice = "fcc";
  double automaton_diameter_m = 1e-3;
  double femur_cut_m = 40e-3;
  double tibia_cut_m = 40e-3;
  double capsule_margin_m = 5e-3;
  double shell_thickness_m = 2e-3;
  double cortical_thickness_m = 2e-3;
  std::string applicator_face = "-z";
  std::vector<double> applicator_centre_m;  ///< empty = over the medial meniscus
  double applicator_size_m = 20e-3;
  double applicator_thickness_m = 1e-3;
  std::vector<double> efd_j_per_m2{330.0};
  double efd_impedance = 1.5e6;  ///< [Pa s/m]
  double pulse_rise_time_s = 1.5e-6;
  double pulse_fall_time_s = 1.5e-6;
  double pulse_positive_duration_s = 4e-6;
  double pulse_tail_duration_s = 20e-6;
  double pulse_tail_fraction = 0.75;
  double end_time_s = 100e-6;
  double output_interval_s = 10e-6;
  bool write_frames = true;
  double time_step_safety = 0.5;
  double fluid_bulk_modulus_pa = 2.4e9;
  double fluid_density = 1000.0;
  double fluid_viscosity = 0.69e-3;  ///< [Pa s]
  std::filesystem::path tissue_table;  ///< CSV overriding Table 1 ("" = none)
  double compression_displacement_m = 0.3e-3;
  double compression_time_s = 0.4e-3;
  double compression_damping = 0.0;  ///< [1/s]; 0 = about critical for the knee's lowest mode
  double compressive_stress_min_pa = 0.15e6;
  double distortional_strain_min = 0.05e-2;
  double distortional_strain_max = 1.1e-2;
  double pore_pressure_min_pa = 20e3;
  double pore_pressure_max_pa = 2e6;

  template <class V>
  void declare(V& v) {
    v.effect_list("effects", effects,
                  "physics terms: mca_elastic (required), pore_fluid (Biot, A9-A10), filtration (Darcy, A11-A12; "
                  "needs pore_fluid), and the loading: applicator_pulse or platen_compression");
    v.text("geometry", geometry, "knee|bar",
           "knee: the prepared knee in its capsule; bar: a laterally periodic bar of one tissue, the pulse on one "
           "end, for checking the p-wave speed against the closed forms");
    v.text("bar_tissue", bar_tissue, "cortical|cancellous|cartilage|fibrocartilage|fibrous|capsule_shell",
           "bar: its tissue");
    v.number("bar_length_mm", bar_length_m, units::mm, 10, 1000, "bar: its length");
    v.text("lattice", lattice, "fcc|sc", "packing of the automata");
    v.number("automaton_diameter_mm", automaton_diameter_m, units::mm, 0.3, 5.0, "automaton diameter d (the seed's 1 mm)");
    v.number("femur_cut_mm", femur_cut_m, units::mm, 5, 200, "femur kept up to this distance above the joint line");
    v.number("tibia_cut_mm", tibia_cut_m, units::mm, 5, 200, "tibia kept down to this distance below the joint line");
    v.number("capsule_margin_mm", capsule_margin_m, units::mm, 0, 50, "fibrous tissue around the bones' extent");
    v.number("shell_thickness_mm", shell_thickness_m, units::mm, 0.3, 20, "capsule shell thickness");
    v.number("cortical_thickness_mm", cortical_thickness_m, units::mm, 0.3, 20, "cortical shell thickness of the bones");
    v.text("applicator_face", applicator_face, "-x|+x|-z|+z", "capsule box face the applicator lies on (-z: medial, right knee)");
    v.number_list("applicator_centre_mm", applicator_centre_m, units::mm, 3, 3,
                  "applicator centre (model frame); default: over the medial meniscus");
    v.number("applicator_size_mm", applicator_size_m, units::mm, 1, 100, "edge of the square copper plate");
    v.number("applicator_thickness_mm", applicator_thickness_m, units::mm, 0.1, 10, "copper plate thickness");
    v.number_list("efd_mj_per_mm2", efd_j_per_m2, units::mj_per_mm2, 1, 20,
                  "energy flux densities (seed eq. 2), one run each (the seed's 0.12, 0.33, 0.8)");
    v.number("efd_impedance", efd_impedance, units::none, 1e5, 1e8,
             "acoustic impedance rho c [Pa s/m] the EFD is quoted in (water, 1.5e6)");
    v.number("pulse_rise_time_us", pulse_rise_time_s, units::us, 0.01, 1000, "rise of the pressure pulse, 0 to peak");
    v.number("pulse_fall_time_us", pulse_fall_time_s, units::us, 0.01, 1000, "fall at the end of the positive phase");
    v.number("pulse_positive_duration_us", pulse_positive_duration_s, units::us, 0.02, 10000, "positive phase");
    v.number("pulse_tail_duration_us", pulse_tail_duration_s, units::us, 0, 10000, "negative tail (0: none)");
    v.number("pulse_tail_fraction", pulse_tail_fraction, units::none, 0, 1, "peak of the tail / peak of the pulse");
    v.number("end_time_us", end_time_s, units::us, 1, 1e6, "simulated time per run");
    v.number("output_interval_us", output_interval_s, units::us, 0.01, 1e6, "time between written frames");
    v.flag("write_frames", write_frames, "write the fields per frame (false: peaks and volumes only)");
    v.number("time_step_safety", time_step_safety, units::none, 0.01, 1, "time step / stability limit");
    v.number("fluid_bulk_modulus_mpa", fluid_bulk_modulus_pa, units::mpa, 1, 1e5, "pore fluid bulk modulus (saline 2400)");
    v.number("fluid_density_kg_per_m3", fluid_density, units::kg_per_m3, 100, 3000, "pore fluid density");
    v.number("fluid_viscosity", fluid_viscosity, units::none, 1e-5, 1, "pore fluid viscosity [Pa s] (water at 37 C)");
    v.path("tissue_table", tissue_table, "CSV replacing Table 1 (docs/shockwave.md, \"Tissues\")");
    v.number("compression_displacement_mm", compression_displacement_m, units::mm, 0.001, 5,
             "platen_compression: downward displacement of the femur's cut face");
    v.number("compression_time_us", compression_time_s, units::us, 10, 1e6, "platen_compression: time of the ramp");
    v.number("compression_damping", compression_damping, units::none, 0, 1e7,
             "platen_compression: mass damping [1/s] (0: about critical for the knee's lowest mode)");
    v.number("compressive_stress_min_mpa", compressive_stress_min_pa, units::mpa, 0, 100, "regeneration: P above this");
    v.number("distortional_strain_min", distortional_strain_min, units::none, 0, 1, "regeneration: strain from");
    v.number("distortional_strain_max", distortional_strain_max, units::none, 0, 1, "regeneration: strain to");
    v.number("pore_pressure_min_mpa", pore_pressure_min_pa, units::mpa, 0, 100, "regeneration: pore pressure from");
    v.number("pore_pressure_max_mpa", pore_pressure_max_pa, units::mpa, 0, 100, "regeneration: pore pressure to");
  }
};

/// The effects the stage knows: (name, one-line description).
const std::vector<std::pair<std::string, std::string>>& shockwave_effects();

/// One run's results.
struct ShockwaveRunResult {
  std::string label;            ///< "efd0.33" or "compression"
  std::filesystem::path file;   ///< its HDF5 file
  double efd_j_per_m2 = 0.0;    ///< 0 for compression
  double peak_pressure_pa = 0.0;  ///< of the applied pulse
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
