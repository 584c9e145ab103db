#include "pipelines/shockwave_stage.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <map>
#include <optional>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "common/checkpoint.h"
#include "common/effects.h"
#include "common/error.h"
#include "common/output_file.h"
#include "common/hashing.h"
#include "common/hdf5.h"
#include "common/prepared_model_file.h"
#include "common/log.h"
#include "common/mesh_io.h"
#include "common/progress.h"
#include "common/scene.h"
#include "pipelines/json.h"
#include "pipelines/stages.h"
#include "pipelines/shockwave_checkpoint.h"
#include "pipelines/shockwave_output.h"
#include "shockwave/applicator_pulse.h"

namespace arthrosim::pipelines {

namespace fs = std::filesystem;
using shockwave::KneeTissue;

namespace {

constexpr double kPi = 3.14159265358979323846;

std::string number(double v) {
  std::ostringstream s;
  s.precision(6);
  s << v;
  return s.str();
}

bool wants(const ShockwaveStageOptions& o, const std::string& effect) {
  return std::find(o.effects.begin(), o.effects.end(), effect) != o.effects.end();
}

// The tissue table: one row per knee tissue, replacing Table 1.
//   name,density_kg_per_m3,shear_modulus_mpa,bulk_modulus_mpa,solid_bulk_modulus_mpa,porosity,permeability_m2
std::vector<shockwave::Tissue> read_tissue_table(const fs::path& path) {
  std::vector<shockwave::Tissue> tissues = shockwave::default_knee_tissues();
  std::ifstream in(path);
  if (!in) throw common::InputError(path.string(), 0, "cannot open the tissue table");
  std::string line;
  int lineno = 0;
  bool header = false;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    if (!header) {
      if (line.rfind("name,density_kg_per_m3,shear_modulus_mpa,bulk_modulus_mpa,solid_bulk_modulus_mpa,porosity,"
                     "permeability_m2",
                     0) != 0)
        throw common::InputError(path.string(), lineno,
                                 "expected the header 'name,density_kg_per_m3,shear_modulus_mpa,bulk_modulus_mpa,"
                                 "solid_bulk_modulus_mpa,porosity,permeability_m2', found '" + line + "'");
      header = true;
      continue;
    }
    std::stringstream ss(line);
    std::string name;
    std::getline(ss, name, ',');
    double v[6];
    for (double& x : v) {
      std::string cell;
      if (!std::getline(ss, cell, ',')) throw common::InputError(path.string(), lineno, "expected 7 comma-separated values, found '" + line + "'");
      try {
        size_t used = 0;
        x = std::stod(cell, &used);
        if (used != cell.size()) throw std::invalid_argument(cell);
      } catch (const std::exception&) {
        throw common::InputError(path.string(), lineno, "expected a number, found '" + cell + "'");
      }
    }
    int t = -1;
    for (int k = 0; k < shockwave::kKneeTissueCount; ++k)
      if (name == shockwave::knee_tissue_name(k)) t = k;
    if (t < 0)
      throw common::InputError(path.string(), lineno,
                               "expected a tissue name (cortical, cancellous, cartilage, fibrocartilage, fibrous, "
                               "capsule_shell, applicator), found '" + name + "'");
    shockwave::Tissue& ts = tissues[t];
    ts.density = v[0];
    ts.shear_modulus = v[1] * 1e6;
    ts.bulk_modulus = v[2] * 1e6;
    ts.solid_bulk_modulus = v[3] * 1e6;
    ts.porosity = v[4];
    ts.permeability = v[5];
  }
  if (!header) throw common::InputError(path.string(), 0, "expected a header line, found an empty file");
  return tissues;
}

// The options as the run uses them (after the scene and the flags), one
// "key = value" line each with every number exactly, for the checkpoint's
// identity: a scene edited between a kill and the rerun gives another
// identity. checkpoint_interval_s is left out (it changes no result).
class OptionsText final : public common::OptionVisitor {
 public:
  std::string lines;
  OptionVisitor& number(std::string_view key, double& si, common::Unit, common::Range, std::string_view) override {
    if (key != "checkpoint_interval_s") line(key, exact(si));
    return *this;
  }
  OptionVisitor& number(std::string_view key, std::optional<double>& si, common::Unit, common::Range,
                        std::string_view) override {
    line(key, si ? exact(*si) : std::string("(none)"));
    return *this;
  }
  OptionVisitor& integer(std::string_view key, int& value, common::Range, std::string_view) override {
    line(key, std::to_string(value));
    return *this;
  }
  OptionVisitor& flag(std::string_view key, bool& value, std::string_view) override {
    line(key, value ? "true" : "false");
    return *this;
  }
  OptionVisitor& text(std::string_view key, std::string& value, std::string_view, std::string_view) override {
    line(key, value);
    return *this;
  }
  OptionVisitor& path(std::string_view key, fs::path& value, std::string_view) override {
    line(key, value.string());
    return *this;
  }
  OptionVisitor& text_list(std::string_view key, std::vector<std::string>& value, std::string_view,
                           std::string_view) override {
    std::string v;
    for (const std::string& x : value) v += x + ",";
    line(key, v);
    return *this;
  }
  OptionVisitor& number_list(std::string_view key, std::vector<double>& si, common::Unit, common::Range,
                             std::string_view) override {
    std::string v;
    for (double x : si) v += exact(x) + ",";
    line(key, v);
    return *this;
  }
  OptionVisitor& named_numbers(std::string_view key, std::map<std::string, double>& si, common::Unit, common::Range,
                               std::string_view) override {
    std::string v;
    for (const auto& [k, x] : si) v += k + "=" + exact(x) + ",";
    line(key, v);
    return *this;
  }
  OptionVisitor& effect_list(std::string_view key, std::vector<std::string>& value, std::string_view,
                             std::string_view) override {
    std::string v;
    for (const std::string& x : value) v += x + ",";
    line(key, v);
    return *this;
  }

 protected:
  void choice_index(std::string_view key, const std::vector<std::string_view>& words, int& index,
                    std::string_view) override {
    line(key, index >= 0 ? std::string(words[static_cast<size_t>(index)]) : std::string("(none)"));
  }

 private:
  static std::string exact(double v) {
    char b[40];
    std::snprintf(b, sizeof b, "%.17g", v);
    return b;
  }
  void line(std::string_view key, const std::string& value) { lines += std::string(key) + " = " + value + "\n"; }
};

std::string resolved_options_text(ShockwaveStageOptions o) {
  OptionsText v;
  o.declare(v);
  return v.lines;
}

}  // namespace

const std::vector<std::pair<std::string, std::string>>& shockwave_effects() {
  // The stage's part of the effect vocabulary (common/effects.cc).
  static const std::vector<std::pair<std::string, std::string>> k = [] {
    std::vector<std::pair<std::string, std::string>> v;
    for (const common::EffectInfo& e : common::known_effects())
      if (e.stage == common::EffectStage::kShockwave) v.emplace_back(std::string(e.name), std::string(e.description));
    return v;
  }();
  return k;
}

void ShockwaveStageOptions::declare(common::OptionVisitor& v) {
  using common::Unit;
  v.effect_list("effects", effects, "shockwave",
                "physics terms: mca_elastic (required), pore_fluid (Biot, A9-A10), filtration (Darcy, A11-A12; "
                "needs pore_fluid), and the loading: applicator_pulse or platen_compression")
      .required();
  v.text("geometry", geometry, "knee|bar",
         "knee: the prepared knee in its capsule; bar: a laterally periodic bar of one tissue, the pulse on one "
         "end, for checking the p-wave speed against the closed forms");
  v.text("bar_tissue", bar_tissue, "cortical|cancellous|cartilage|fibrocartilage|fibrous|capsule_shell",
         "bar: its tissue");
  v.number("bar_length_mm", bar_length_m, Unit::kMillimetre, {10, 1000}, "bar: its length");
  v.text("lattice", lattice, "fcc|sc", "packing of the automata");
  v.number("automaton_diameter_mm", automaton_diameter_m, Unit::kMillimetre, {0.3, 5.0}, "automaton diameter d (the seed's 1 mm)");
  v.number("femur_cut_mm", femur_cut_m, Unit::kMillimetre, {5, 200}, "femur kept up to this distance above the joint line");
  v.number("tibia_cut_mm", tibia_cut_m, Unit::kMillimetre, {5, 200}, "tibia kept down to this distance below the joint line");
  v.number("capsule_margin_mm", capsule_margin_m, Unit::kMillimetre, {0, 50}, "fibrous tissue around the bones' extent");
  v.number("shell_thickness_mm", shell_thickness_m, Unit::kMillimetre, {0.3, 20}, "capsule shell thickness");
  v.number("cortical_thickness_mm", cortical_thickness_m, Unit::kMillimetre, {0.3, 20}, "cortical shell thickness of the bones");
  v.text("applicator_face", applicator_face, "-x|+x|-z|+z", "capsule box face the applicator lies on (-z: medial, right knee)");
  v.number_list("applicator_centre_mm", applicator_centre_m, Unit::kMillimetre, {3, 3},
                "applicator centre (model frame); default: over the medial meniscus");
  v.number("applicator_size_mm", applicator_size_m, Unit::kMillimetre, {1, 100}, "edge of the square copper plate");
  v.number("applicator_thickness_mm", applicator_thickness_m, Unit::kMillimetre, {0.1, 10}, "copper plate thickness");
  v.number_list("efd_mj_per_mm2", efd_j_per_m2, Unit::kMillijoulePerSquareMillimetre, {1, 20},
                "energy flux densities (seed eq. 2), one run each (the seed's 0.12, 0.33, 0.8)");
  v.text("efd_reference", efd_reference, "water|applicator",
         "reading of seed eq. 2: water (v the wave's particle velocity in efd_impedance, its pressure on the plate) or "
         "applicator (v the plate's velocity, rho c the plate's p-wave impedance, the plate's outer face driven by v)");
  v.number("efd_impedance", efd_impedance, Unit::kNone, {1e5, 1e8},
           "efd_reference water: acoustic impedance rho c [Pa s/m] the EFD is quoted in (water, 1.5e6)");
  v.number("pulse_rise_time_us", pulse_rise_time_s, Unit::kMicrosecond, {0.01, 1000}, "rise of the pressure pulse, 0 to peak");
  v.number("pulse_fall_time_us", pulse_fall_time_s, Unit::kMicrosecond, {0.01, 1000}, "fall at the end of the positive phase");
  v.number("pulse_positive_duration_us", pulse_positive_duration_s, Unit::kMicrosecond, {0.02, 10000}, "positive phase");
  v.number("pulse_tail_duration_us", pulse_tail_duration_s, Unit::kMicrosecond, {0, 10000}, "negative tail (0: none)");
  v.number("pulse_tail_fraction", pulse_tail_fraction, Unit::kNone, {0, 1}, "peak of the tail / peak of the pulse");
  v.number("end_time_us", end_time_s, Unit::kMicrosecond, {1, 1e6}, "simulated time per run");
  v.number("output_interval_us", output_interval_s, Unit::kMicrosecond, {0.01, 1e6}, "time between written frames");
  v.flag("write_frames", write_frames, "write the fields per frame (false: peaks and volumes only)");
  v.number("time_step_safety", time_step_safety, Unit::kNone, {0.01, 1}, "time step / stability limit");
  v.number("fluid_bulk_modulus_mpa", fluid_bulk_modulus_pa, Unit::kMegapascal, {1, 1e5}, "pore fluid bulk modulus (saline 2400)");
  v.number("fluid_density_kg_per_m3", fluid_density, Unit::kKilogramPerCubicMetre, {100, 3000}, "pore fluid density");
  v.number("fluid_viscosity", fluid_viscosity, Unit::kNone, {1e-5, 1}, "pore fluid viscosity [Pa s] (water at 37 C)");
  v.path("tissue_table", tissue_table, "CSV replacing Table 1 (docs/shockwave.md, \"Tissues\")");
  v.number("compression_displacement_mm", compression_displacement_m, Unit::kMillimetre, {0.001, 5},
           "platen_compression: downward displacement of the femur's cut face");
  v.number("compression_time_us", compression_time_s, Unit::kMicrosecond, {10, 1e6}, "platen_compression: time of the ramp");
  v.number("compression_damping", compression_damping, Unit::kNone, {0, 1e7},
           "platen_compression: mass damping [1/s] (0: about critical for the knee's lowest mode)");
  v.number("compressive_stress_min_mpa", compressive_stress_min_pa, Unit::kMegapascal, {0, 100}, "regeneration: P above this");
  v.number("distortional_strain_min", distortional_strain_min, Unit::kNone, {0, 1}, "regeneration: strain from");
  v.number("distortional_strain_max", distortional_strain_max, Unit::kNone, {0, 1}, "regeneration: strain to");
  v.number("pore_pressure_min_mpa", pore_pressure_min_pa, Unit::kMegapascal, {0, 100}, "regeneration: pore pressure from");
  v.number("pore_pressure_max_mpa", pore_pressure_max_pa, Unit::kMegapascal, {0, 100}, "regeneration: pore pressure to");
  v.number("checkpoint_interval_s", checkpoint_interval_s, Unit::kSecond, {0, 86400},
           "wall time between checkpoints <out>.checkpoint (0: after every step); a rerun of the same command "
           "continues from the last one (docs/shockwave.md, \"Checkpoints\")");
}

void check_shockwave_options(const ShockwaveStageOptions& o, const std::string& source) {
  for (const std::string& e : o.effects) {
    bool known = false;
    for (const auto& [name, doc] : shockwave_effects()) known |= name == e;
    if (!known) {
      std::string list;
      for (const auto& [name, doc] : shockwave_effects()) list += (list.empty() ? "" : ", ") + name;
      throw common::InputError(source, 0, "expected shockwave effects from " + list + ", found '" + e + "'");
    }
  }
  if (!wants(o, "mca_elastic")) throw common::InputError(source, 0, "expected the effect mca_elastic (the automata themselves)");
  if (wants(o, "filtration") && !wants(o, "pore_fluid"))
    throw common::InputError(source, 0, "expected pore_fluid with filtration (Darcy flow needs the pore pressure)");
  if (o.geometry == "bar" && !wants(o, "applicator_pulse"))
    throw common::InputError(source, 0, "expected applicator_pulse for the bar (its loading)");
  if (wants(o, "applicator_pulse") == wants(o, "platen_compression"))
    throw common::InputError(source, 0, "expected one loading among the effects: applicator_pulse or platen_compression");
  if (!(o.distortional_strain_min <= o.distortional_strain_max) || !(o.pore_pressure_min_pa <= o.pore_pressure_max_pa))
    throw common::InputError(source, 0, "expected the regeneration ranges' minimum <= maximum");
}

ShockwaveStageOptions shockwave_from_scene(const common::Scene& scene) {
  if (!scene.has_block("shockwave"))
    throw common::InputError(scene.file.string(), 0, "expected a 'shockwave' block with its effects, found none");
  ShockwaveStageOptions o = common::read_options<ShockwaveStageOptions>(scene.block("shockwave"));
  const int line = scene.block_line("shockwave");
  check_shockwave_options(o, scene.file.string() + (line > 0 ? ":" + std::to_string(line) : std::string()) +
                                 ": shockwave block");
  return o;
}

std::vector<std::string> shockwave_run_labels(const ShockwaveStageOptions& o) {
  if (wants(o, "platen_compression")) return {"compression"};
  std::vector<std::string> labels;
  for (double efd : o.efd_j_per_m2) labels.push_back("efd" + number(efd * 1e-3));
  return labels;
}

ShockwaveModel build_shockwave_model(const ShockwaveStageOptions& o, const std::string& source) {
  check_shockwave_options(o, source);
  ShockwaveModel sm;
  if (o.geometry == "bar") {
    // A laterally periodic bar (uniaxial strain) of one tissue, loaded on x = 0.
    sm.bar = true;
    const shockwave::Lattice lat = shockwave::make_lattice(shockwave::parse_lattice_kind(o.lattice, source),
                                                           o.automaton_diameter_m);
    std::vector<shockwave::Tissue> tissues =
        o.tissue_table.empty() ? shockwave::default_knee_tissues() : read_tissue_table(o.tissue_table);
    int t = -1;
    for (int k = 0; k < shockwave::kKneeTissueCount; ++k)
      if (o.bar_tissue == shockwave::knee_tissue_name(k)) t = k;
    if (t < 0 || t == shockwave::kApplicator)
      throw common::InputError(source, 0, "expected a bar tissue of the knee, found '" + o.bar_tissue + "'");
    shockwave::GridSpec g;
    g.count = {static_cast<int>(std::lround(o.bar_length_m / lat.spacing)) + 1, 4, 4};
    g.periodic = {false, true, true};
    shockwave::PoreFluid fluid;
    fluid.bulk_modulus = o.fluid_bulk_modulus_pa;
    fluid.density = o.fluid_density;
    fluid.viscosity = o.fluid_viscosity;
    sm.model = shockwave::build_model(lat, g, {tissues[t]}, fluid,
                                      [](int, int, int, const common::Vec3&) { return 0; }, source);
    for (int a = 0; a < sm.model.size(); ++a)
      if (sm.model.cell[a][0] == 0) {
        sm.model.loaded.automata.push_back(a);
        sm.model.loaded.area.push_back(common::Vec3(lat.area_per_surface_site(), 0, 0));
      }
    sm.model.loaded.normal = common::Vec3(1, 0, 0);
    sm.info.automata = sm.model.tissue_counts();
    return sm;
  }
  if (o.prepared.empty()) throw common::InputError(source, 0, "expected a prepared model (--prepared)");
  shockwave::KneeMeshes meshes;
  const common::PreparedModelReader prepared(o.prepared.string());
  {
    const std::vector<std::string> bones = prepared.bone_names();
    if (std::find(bones.begin(), bones.end(), "femur") == bones.end() ||
        std::find(bones.begin(), bones.end(), "tibia") == bones.end())
      throw common::InputError(o.prepared.string(), 0, "expected the bones femur and tibia, found " +
                                                           std::to_string(bones.size()) + " bones");
  }
  meshes.femur = prepared.bone_mesh("femur");
  meshes.tibia = prepared.bone_mesh("tibia");
  for (const std::string& name : prepared.surface_names()) {
    const std::string b = prepared.bone(name);
    if (b != "femur" && b != "tibia") continue;  // the patella is left out, as in the seed
    shockwave::CartilageSurface c;
    c.name = name;
    c.bone = b == "femur" ? shockwave::BoneId::kFemur : shockwave::BoneId::kTibia;
    common::PreparedModelReader::TriangleSurface t = prepared.triangles(name);
    c.articular.V = std::move(t.mesh.V);
    c.articular.F = std::move(t.mesh.F);
    c.thickness = std::move(t.thickness);
    meshes.cartilage.push_back(std::move(c));
  }
  // Menisci from the model folder, in the unit the prepare stage read it with.
  if (!o.model.empty()) {
    common::MeshReadOptions ro;
    if (!prepared.input_unit().empty()) ro.unit = common::parse_length_unit(prepared.input_unit());
    std::vector<fs::path> files;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(o.model, ec)) files.push_back(e.path());
    if (ec) throw common::InputError(o.model.string(), 0, "cannot read the model folder: " + ec.message());
    std::sort(files.begin(), files.end());
    for (const fs::path& p : files) {
      std::string ext = p.extension().string();
      std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
      const std::string stem = p.stem().string();
      const std::string suffix = "_meniscus";
      if ((ext != ".stl" && ext != ".obj" && ext != ".ply") || stem.size() <= suffix.size() ||
          stem.compare(stem.size() - suffix.size(), suffix.size(), suffix) != 0)
        continue;
      meshes.menisci.emplace_back(stem.substr(0, stem.size() - suffix.size()), common::read_mesh(p.string(), ro));
    }
  }
  shockwave::KneeModelOptions& k = sm.knee_options;
  k.lattice = shockwave::parse_lattice_kind(o.lattice, source);
  k.diameter = o.automaton_diameter_m;
  k.femur_cut = o.femur_cut_m;
  k.tibia_cut = o.tibia_cut_m;
  k.capsule_margin = o.capsule_margin_m;
  k.shell_thickness = o.shell_thickness_m;
  k.cortical_thickness = o.cortical_thickness_m;
  k.applicator.face = shockwave::parse_box_face(o.applicator_face, source);
  if (o.applicator_centre_m.size() == 3)
    k.applicator.centre = common::Vec3(o.applicator_centre_m[0], o.applicator_centre_m[1], o.applicator_centre_m[2]);
  k.applicator.size = o.applicator_size_m;
  k.applicator.thickness = o.applicator_thickness_m;
  k.tissues = o.tissue_table.empty() ? shockwave::default_knee_tissues() : read_tissue_table(o.tissue_table);
  k.fluid.bulk_modulus = o.fluid_bulk_modulus_pa;
  k.fluid.density = o.fluid_density;
  k.fluid.viscosity = o.fluid_viscosity;
  sm.model = shockwave::build_knee_model(meshes, k, &sm.info, source);
  return sm;
}

ShockwaveStageResult run_shockwave_stage(const ShockwaveStageOptions& o, const std::vector<std::string>& argv,
                                         bool progress, bool dry_run) {
  const std::string source = "arthrosim-shockwave options";
  ShockwaveStageResult result;
  const auto t_build = std::chrono::steady_clock::now();
  const ShockwaveModel sm = build_shockwave_model(o, source);
  const shockwave::Model& m = sm.model;
  result.build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_build).count();
  result.automata = m.size();
  result.bonds = m.bonds();
  result.per_tissue = sm.info.automata;
  std::ostringstream log;
 log << (sm.bar ? "bar of " : "knee of ") << m.size() << " automata (" << shockwave::to_string(m.lattice.kind) << ", d = "
      << number(m.lattice.diameter * 1e3) << " mm), " << m.bonds() << " bonds, built in " << number(result.build_s)
      << " s:";
  for (size_t t = 0; t < m.tissues.size(); ++t) log << " " << m.tissues[t].name << " " << sm.info.automata[t];
  common::log_info(log.str());

  shockwave::SimulationOptions so;
  so.pore_fluid = wants(o, "pore_fluid");
  so.filtration = wants(o, "filtration");
  so.time_step_safety = o.time_step_safety;
  shockwave::RegenerationCriteria crit;
  crit.compressive_min = o.compressive_stress_min_pa;
  crit.distortional_min = o.distortional_strain_min;
  crit.distortional_max = o.distortional_strain_max;
  crit.pore_min = o.pore_pressure_min_pa;
  crit.pore_max = o.pore_pressure_max_pa;
  std::ostringstream opts;
  for (const std::string& a : argv) opts << a << " ";
  const std::string options_text = opts.str();
  const bool compression = wants(o, "platen_compression");

  // One run per EFD (or the compression).
  const std::vector<double> runs = compression ? std::vector<double>{0.0} : o.efd_j_per_m2;
  const std::vector<std::string> labels = shockwave_run_labels(o);

  // Checkpoint and resume (pipelines/shockwave_checkpoint.h), tied to this
  // run's identity (program, command line, the options as resolved, the
  // inputs' bytes, the runner's key). Not in a dry run (nothing is simulated).
  const fs::path checkpoint_path = common::checkpoint_name(o.out);
  ShockwaveCheckpoint checkpoint;
  if (!dry_run) {
    checkpoint.identity = common::run_identity(
        argv, resolved_options_text(o),
        {{o.prepared, "--prepared"}, {o.model, "--model"}, {o.tissue_table, "tissue_table"}});
    std::optional<ShockwaveCheckpoint> found;
    const bool resume = common::resume_from_checkpoint(
        checkpoint_path, checkpoint.identity, [&](std::string& identity, std::string& why) {
          found = read_shockwave_checkpoint(checkpoint_path, why);
          if (!found) return false;
          const size_t done = found->finished.size() + (found->current ? 1 : 0);
          bool same = done <= runs.size();
          for (size_t r = 0; same && r < found->finished.size(); ++r) same = found->finished[r].result.label == labels[r];
          if (same && found->current) {
            // Frames of this model: the at-once volumes per tissue, the fields per automaton.
            const size_t n = static_cast<size_t>(m.size()), nt = m.tissues.size();
            for (const ShockwaveFrame& f : found->current->frames) {
              const bool fields = o.write_frames && f.pressure.size() == n && f.distortional_strain.size() == n &&
                                  (f.pore_pressure.empty() || f.pore_pressure.size() == n);
              const bool none = !o.write_frames && f.pressure.empty() && f.distortional_strain.empty() &&
                                f.pore_pressure.empty();
              if (f.all_at_once_m3.size() != nt || !(fields || none)) {
                why = "its frames are not of this model (" + std::to_string(n) + " automata, " + std::to_string(nt) +
                      " tissues)";
                return false;
              }
            }
          }
          if (!same) {
            why = "it holds " + std::to_string(found->finished.size()) + " finished runs and " +
                  (found->current ? "one" : "none") + " in progress for a stage of " + std::to_string(runs.size()) +
                  " runs";
            return false;
          }
          identity = found->identity;
          return true;
        });
    if (resume) checkpoint = std::move(*found);
  }
  common::CheckpointClock checkpoint_clock(o.checkpoint_interval_s);
  for (std::size_t r = 0; r < runs.size(); ++r) {
    const double efd = runs[r];
    ShockwaveRunResult rr;
    rr.efd_j_per_m2 = efd;
    rr.label = labels[r];
    rr.file = fs::path(o.out.string() + "_" + rr.label + ".h5");
    std::unique_ptr<shockwave::PressurePulse> pulse;
    shockwave::Model run_model = m;  // constraints differ per run kind
    std::function<double(double)> load;
    double end_time = o.end_time_s;
    std::vector<int> top;
    shockwave::SimulationOptions ro = so;
    if (!compression) {
      shockwave::PulseShape shape;
      shape.rise_time = o.pulse_rise_time_s;
      shape.fall_time = o.pulse_fall_time_s;
      shape.positive_duration = o.pulse_positive_duration_s;
      shape.tail_duration = o.pulse_tail_duration_s;
      shape.tail_fraction = o.pulse_tail_fraction;
      if (o.efd_reference == "applicator") {
        // The plate's material from the tissue table (the model's plate has
        // its density scaled to the lattice layers, knee_model.cc; the bar
        // has no plate and its face moves as the plate's would).
        const shockwave::Tissue cu = (o.tissue_table.empty() ? shockwave::default_knee_tissues()
                                                             : read_tissue_table(o.tissue_table))[shockwave::kApplicator];
        const double z = shockwave::p_wave_impedance(cu.density, cu.bulk_modulus, cu.shear_modulus);
        pulse = std::make_unique<shockwave::PressurePulse>(shape, efd, z);
        shockwave::drive_loaded_face(run_model, *pulse);
      } else {
        pulse = std::make_unique<shockwave::PressurePulse>(shape, efd, o.efd_impedance);
        load = [p = pulse.get()](double t) { return (*p)(t); };
      }
      rr.peak_pressure_pa = load ? pulse->peak() : 0.0;  // driven: measured over the run
    } else {
      // The femur's cut face (top lattice layer) moves down by the displacement
      // with a smooth velocity ramp, the tibia's (bottom layer) is fixed; then
      // the top holds while the knee settles (damped).
      int kmax = 0, kmin = 1 << 30;
      for (int a = 0; a < m.size(); ++a) {
        if (m.tissue[a] == shockwave::kApplicator) continue;
        kmax = std::max(kmax, m.cell[a][1]);
        kmin = std::min(kmin, m.cell[a][1]);
      }
      for (int a = 0; a < m.size(); ++a) {
        if (m.tissue[a] == shockwave::kApplicator) continue;
        if (m.cell[a][1] == kmax) {
          run_model.constraints.push_back({a, 7, common::Vec3(0, -o.compression_displacement_m, 0)});
          top.push_back(static_cast<int>(run_model.constraints.size()) - 1);
        } else if (m.cell[a][1] == kmin) {
          run_model.constraints.push_back({a, 7, common::Vec3::Zero()});
        }
      }
      const double T = o.compression_time_s;
      run_model.constraint_scale = [T](double t) {
        if (t < 0.0 || t > T) return 0.0;
        const double s = std::sin(kPi * t / T);
        return 2.0 / T * s * s;
      };
      double alpha = o.compression_damping;
      if (alpha <= 0.0) {
        // About critical for the lowest axial mode of the box of fibrous tissue.
        const shockwave::TissueConstants& f = m.constants[shockwave::kFibrous];
        const double c = so.pore_fluid ? f.undrained_p_speed : f.drained_p_speed;
        alpha = kPi * c / (2.0 * (sm.info.box_hi.y() - sm.info.box_lo.y()));
      }
      ro.damping = alpha;
      end_time = 1.5 * T;
    }
    shockwave::Simulation sim(run_model, ro, load);
    sim.track_energy(true);
    result.time_step_s = sim.time_step();
    result.critical_time_step_s = sim.critical_time_step();
    result.critical_tissue = sim.critical_tissue();
    result.fastest_p_wave = sim.fastest_p_wave();
    result.fastest_p_wave_tissue = sim.fastest_p_wave_tissue();
    result.filtration_substeps = sim.filtration() ? sim.filtration()->substeps() : 0;
    const std::int64_t steps = static_cast<std::int64_t>(std::ceil(end_time / sim.time_step())) + 1;
    const std::int64_t every = std::max<std::int64_t>(1, std::llround(o.output_interval_s / sim.time_step()));
    {
      std::ostringstream s;
      s << rr.label << ": time step " << number(sim.time_step() * 1e9) << " ns (stability limit "
        << number(sim.critical_time_step() * 1e9) << " ns, " << sim.critical_tissue() << "; d/c_p of the fastest p-wave ("
        << sim.fastest_p_wave_tissue() << ", " << number(sim.fastest_p_wave()) << " m/s) "
        << number(m.lattice.diameter / sim.fastest_p_wave() * 1e9) << " ns), " << steps << " steps";
      if (sim.filtration()) s << ", filtration stages (fast bonds) " << sim.filtration()->substeps();
      if (pulse && load)
        s << ", pulse peak " << number(pulse->peak() * 1e-6) << " MPa on the plate's outer face (efd_reference water, rho c "
          << number(pulse->impedance()) << " Pa s/m; T_p " << number(pulse->time_to_90_percent() * 1e6) << " us)";
      else if (pulse)
        s << ", plate velocity peak " << number(pulse->velocity_peak()) << " m/s on its outer face (efd_reference "
          << "applicator, rho c " << number(pulse->impedance()) << " Pa s/m; T_p " << number(pulse->time_to_90_percent() * 1e6)
          << " us)";
      common::log_info(s.str());
    }
    if (dry_run) {
      rr.steps = steps;
      result.runs.push_back(std::move(rr));
      continue;
    }
    // A run that finished before the checkpoint: its file is kept (if it is
    // still the one written) and its results are taken, not simulated again.
    if (r < checkpoint.finished.size()) {
      const ShockwaveFinishedRun& done = checkpoint.finished[r];
      std::error_code ec;
      if (fs::is_regular_file(rr.file, ec) && common::sha256_file(rr.file) == done.file_sha256) {
        common::log_info("resuming from the checkpoint " + checkpoint_path.string() + ": " + rr.label +
                         " finished before, " + rr.file.string() + " kept (not simulated again)");
        ShockwaveRunResult taken = done.result;
        taken.file = rr.file;
        result.runs.push_back(std::move(taken));
        ++result.runs_taken;
        continue;
      }
      common::log_warn("not taking " + rr.label + " from the checkpoint " + checkpoint_path.string() + ": " +
                       rr.file.string() + " is missing or changed since; simulating it again");
      checkpoint.finished.resize(r);
      checkpoint.current.reset();
    }
    // The run in progress: restored from the checkpoint, or a fresh one.
    if (checkpoint.current && checkpoint.current->run == static_cast<int>(r)) {
      try {
        if (checkpoint.current->sim.steps >= steps)
          throw std::runtime_error("it holds " + std::to_string(checkpoint.current->sim.steps) + " steps of a run of " +
                                   std::to_string(steps));
        sim.restore(checkpoint.current->sim);  // checks everything before it changes anything
      } catch (const std::exception& e) {
        common::log_warn("not resuming " + rr.label + " from " + checkpoint_path.string() + ": " + e.what() +
                         "; starting it over");
        checkpoint.current.reset();
      }
    } else {
      checkpoint.current.reset();
    }
    if (!checkpoint.current) {
      // Fresh: a Simulation that was not restored is at step 0.
      if (sim.steps_done() != 0) throw std::logic_error("shockwave stage: a half-restored run");
      checkpoint.current.emplace();
      checkpoint.current->run = static_cast<int>(r);
    }
    ShockwaveRunProgress& cur = *checkpoint.current;
    cur.sim = {};  // the state is taken from sim when a checkpoint is written
    ShockwaveWriter writer(rr.file, run_model, rr.label, o.write_frames, sim.pore_fluid(), options_text, argv);
    // The effect ledger: what this run built.
    std::vector<ShockwaveEffect> effects;
    effects.push_back({"mca_elastic", "knee", static_cast<std::int64_t>(m.bonds())});
    if (sim.pore_fluid()) {
      std::int64_t poro = 0;
      for (int a = 0; a < m.size(); ++a) poro += m.constants[m.tissue[a]].poroelastic ? 1 : 0;
      effects.push_back({"pore_fluid", "knee", poro});
    }
    if (sim.filtration()) effects.push_back({"filtration", "knee", sim.filtration()->bonds()});
    if (pulse) effects.push_back({"applicator_pulse", "applicator", static_cast<std::int64_t>(m.loaded.automata.size())});
    if (compression) effects.push_back({"platen_compression", "cut faces", static_cast<std::int64_t>(run_model.constraints.size())});

    common::ProgressOptions po;
    if (!progress) po.mode = common::ProgressOptions::Mode::kOff;
    common::Progress bar("shockwave " + rr.label, steps, po);
    const std::int64_t first_step = sim.steps_done();
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    // The bar: mean pressure of two lattice layers each step (peak arrival
    // times), kept with the checkpoint's run state.
    std::vector<int> st1, st2;
    std::vector<double>& p1 = cur.bar_p1;
    std::vector<double>& p2 = cur.bar_p2;
    if (sm.bar) {
      const int nx = m.grid.count[0];
      st1 = shockwave::layer(m, 0, nx / 4);
      st2 = shockwave::layer(m, 0, 3 * nx / 4);
    }
    auto top_force = [&]() {
      double f = 0.0;
      for (int k : top) f += sim.constraint_forces()[k].y();
      return f;  // the pairs push the platen up: compressive force > 0
    };
    // The velocity-driven plate (efd_reference applicator): the pressure the
    // driven face exerts on the body, -(pairs' force on the face along n) /
    // face area; its peak over every step is the run's pulse peak.
    const bool driven = pulse && !load;
    double face_area = 0.0;
    if (driven)
      for (const common::Vec3& a : m.loaded.area) face_area += a.norm();
    auto face_pressure = [&]() {
      double f = 0.0;
      for (const common::Vec3& c : sim.constraint_forces()) f += c.dot(m.loaded.normal);
      return -f / face_area;
    };
    if (driven) rr.peak_pressure_pa = cur.peak_pressure_pa;  // 0 for a fresh run
    if (first_step > 0) {
      common::log_info("resuming from the checkpoint " + checkpoint_path.string() + ": " + rr.label + ", " +
                       std::to_string(first_step) + " of " + std::to_string(steps) +
                       " steps done, frames written: " + std::to_string(cur.frames.size()) + " (taken from it)");
      result.resumed_steps = first_step;
      bar.update(first_step);
    }
    for (const ShockwaveFrame& f : cur.frames) writer.append_frame(f);
    rr.frames = static_cast<int>(cur.frames.size());
    for (std::int64_t s = first_step; s < steps; ++s) {
      sim.step();
      if (driven) rr.peak_pressure_pa = std::max(rr.peak_pressure_pa, face_pressure());
      if (sm.bar) {
        double a = 0, b = 0;
        for (int i : st1) a += sim.pressure()[i];
        for (int i : st2) b += sim.pressure()[i];
        p1.push_back(a / st1.size());
        p2.push_back(b / st2.size());
      }
      if (s % every == 0 || s + 1 == steps) {
        double disp = 0.0;
        if (compression && !top.empty()) disp = -sim.displacement(run_model.constraints[top[0]].automaton).y();
        ShockwaveFrame frame = shockwave_frame(sim, load ? load(sim.time()) : (driven ? face_pressure() : 0.0), crit,
                                               o.write_frames, sim.pore_fluid(), compression ? top_force() : 0.0, disp);
        writer.append_frame(frame);
        cur.frames.push_back(std::move(frame));
        ++rr.frames;
      }
      if (s + 1 < steps && checkpoint_clock.due()) {
        cur.sim = sim.state();
        cur.peak_pressure_pa = driven ? rr.peak_pressure_pa : 0.0;
        write_shockwave_checkpoint(checkpoint_path, checkpoint, ++result.checkpoints);
        cur.sim = {};
        checkpoint_clock.mark();
      }
      if ((s & 15) == 0) bar.update(s + 1);
    }
    bar.finish();
    rr.steps = steps;
    rr.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    rr.cpu_s = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    const shockwave::EnergyBalance e = sim.energy();
    rr.energy_residual = e.external_work != 0.0 ? std::abs(e.residual()) / std::abs(e.external_work) : 0.0;
    if (sm.bar) {
      // Arrival of the front: the first time a station reaches half its
      // largest pressure (linear interpolation between steps); robust against
      // the dispersive ringing behind a sharp front.
      auto arrival = [&](const std::vector<double>& v) {
        const double half = 0.5 * *std::max_element(v.begin(), v.end());
        for (size_t i = 1; i < v.size(); ++i)
          if (v[i] >= half) return (static_cast<double>(i) - 1.0 + (half - v[i - 1]) / (v[i] - v[i - 1])) * sim.time_step();
        return 0.0;
      };
      rr.bar_speed = (m.x[st2[0]] - m.x[st1[0]]) / (arrival(p2) - arrival(p1));
      rr.bar_drained_speed = m.constants[0].drained_p_speed;
      rr.bar_undrained_speed = m.constants[0].undrained_p_speed;
    }
    if (compression) {
      rr.force_n = top_force();
      rr.displacement_m = -sim.displacement(run_model.constraints[top[0]].automaton).y();
      rr.stiffness_n_per_m = rr.displacement_m > 0 ? rr.force_n / rr.displacement_m : 0.0;
    }
    std::vector<std::pair<std::string, double>> attrs = {
        {"time_step_s", sim.time_step()},
        {"critical_time_step_s", sim.critical_time_step()},
        {"fastest_p_wave_m_per_s", sim.fastest_p_wave()},
        {"steps", static_cast<double>(steps)},
        {"wall_s", rr.wall_s},
        {"automaton_steps_per_s", m.size() * static_cast<double>(steps) / rr.wall_s},
        {"filtration_substeps", static_cast<double>(result.filtration_substeps)},
        {"efd_j_per_m2", efd},
        {"pulse_peak_pa", rr.peak_pressure_pa},
        {"pulse_t_p_s", pulse ? pulse->time_to_90_percent() : 0.0},
        {"efd_positive_integral_j_per_m2", pulse ? pulse->efd_positive_integral() : 0.0},
        {"efd_total_integral_j_per_m2", pulse ? pulse->efd_total_integral() : 0.0},
        {"efd_impedance", pulse ? pulse->impedance() : o.efd_impedance},
        {"pulse_velocity_peak_m_per_s", pulse ? pulse->velocity_peak() : 0.0},
        {"energy_residual", rr.energy_residual},
        {"compression_force_n", rr.force_n},
        {"compression_displacement_m", rr.displacement_m},
        {"stiffness_n_per_m", rr.stiffness_n_per_m},
        {"bar_speed_m_per_s", rr.bar_speed},
        {"bar_drained_speed_m_per_s", rr.bar_drained_speed},
        {"bar_undrained_speed_m_per_s", rr.bar_undrained_speed},
    };
    rr.all_at_once_m3 = writer.finish(sim, crit, effects, attrs);
    for (int t = 0; t < static_cast<int>(m.tissues.size()); ++t) {
      rr.volumes.push_back(shockwave::regeneration_volumes(m, t, sim.peak_pressure(), sim.peak_distortional_strain(),
                                                           sim.peak_pore_pressure(), crit));
      std::array<double, 3> mx{0, 0, 0};
      for (int a = 0; a < m.size(); ++a) {
        if (m.tissue[a] != t) continue;
        mx[0] = std::max(mx[0], sim.peak_pressure()[a]);
        mx[1] = std::max(mx[1], sim.peak_distortional_strain()[a]);
        mx[2] = std::max(mx[2], sim.peak_pore_pressure()[a]);
      }
      rr.max_peaks.push_back(mx);
    }
    std::ostringstream s;
    s << rr.label << ": " << steps << " steps in " << number(rr.wall_s) << " s (" << number(m.size() * double(steps) / rr.wall_s)
      << " automaton-steps/s), wrote " << rr.file.string();
    common::log_info(s.str());
    // The finished run goes into the checkpoint right away (when more runs
    // follow): a rerun after a kill in a later run takes it from there.
    checkpoint.current.reset();
    if (r + 1 < runs.size()) {
      checkpoint.finished.push_back({rr, common::sha256_file(rr.file)});
      write_shockwave_checkpoint(checkpoint_path, checkpoint, ++result.checkpoints);
      checkpoint_clock.mark();
    }
    result.runs.push_back(std::move(rr));
  }
  if (dry_run) return result;
  // Summary: JSON and the volumes-vs-EFD plot.
  result.summary_json = fs::path(o.out.string() + "_summary.json");
  {
    common::AtomicOutput atomic(result.summary_json);  // <name>.partial, renamed when written
    json::Writer w;
    w.begin_object();
    w.integer("automata", static_cast<long long>(result.automata));
    w.integer("bonds", static_cast<long long>(result.bonds));
    w.value("diameter_mm", m.lattice.diameter * 1e3);
    w.value("lattice", shockwave::to_string(m.lattice.kind));
    w.value("time_step_s", result.time_step_s);
    w.begin_array("runs");
    for (const ShockwaveRunResult& rr : result.runs) {
      w.begin_object();
      w.value("label", rr.label);
      w.value("efd_mj_per_mm2", rr.efd_j_per_m2 * 1e-3);
      w.value("pulse_peak_mpa", rr.peak_pressure_pa * 1e-6);
      w.integer("steps", static_cast<long long>(rr.steps));
      w.value("wall_s", rr.wall_s);
      w.value("stiffness_n_per_mm", rr.stiffness_n_per_m * 1e-3);
      w.value("bar_speed_m_per_s", rr.bar_speed);
      w.value("bar_drained_speed_m_per_s", rr.bar_drained_speed);
      w.value("bar_undrained_speed_m_per_s", rr.bar_undrained_speed);
      w.begin_object("tissues");
      for (size_t t = 0; t < rr.volumes.size(); ++t) {
        const shockwave::RegenerationVolumes& v = rr.volumes[t];
        w.begin_object(m.tissues[t].name);
        w.value("volume_mm3", v.tissue * 1e9);
        w.value("compressive_mm3", v.compressive * 1e9);
        w.value("distortional_mm3", v.distortional * 1e9);
        w.value("pore_mm3", v.pore * 1e9);
        w.value("all_mm3", v.all * 1e9);
        w.value("all_at_once_mm3", rr.all_at_once_m3[t] * 1e9);
        w.value("max_peak_pressure_mpa", rr.max_peaks[t][0] * 1e-6);
        w.value("max_peak_distortional_strain", rr.max_peaks[t][1]);
        w.value("max_peak_pore_pressure_mpa", rr.max_peaks[t][2] * 1e-6);
        w.end_object();
      }
      w.end_object();
      w.end_object();
    }
    w.end_array();
    w.end_object();
    std::ofstream js(atomic.temp());
    js << w.str() << "\n";
    js.close();
    if (!js) throw common::InputError(result.summary_json.string(), 0, "write failed");
    atomic.commit();
  }
  if (!compression) {
    // Volumes (all three criteria, and each criterion) of cartilage and
    // menisci against the EFD, as an SVG plot (none for the bar, which has
    // no tissue volumes). Written as <name>.partial and renamed, like the
    // other outputs (common/output_file.h).
    if (sm.bar) {
      fs::remove(checkpoint_path);
      return result;
    }
    result.volumes_svg = fs::path(o.out.string() + "_volumes.svg");
    std::ostringstream svg;
    const double W = 640, H = 420, L = 70, R = 20, T = 30, B = 60;
    double vmax = 1e-12, emax = 0.0;
    for (const ShockwaveRunResult& rr : result.runs) {
      emax = std::max(emax, rr.efd_j_per_m2 * 1e-3);
      for (int t : {shockwave::kCartilage, shockwave::kFibrocartilage})
        for (double v : {rr.volumes[t].compressive, rr.volumes[t].distortional, rr.volumes[t].pore, rr.volumes[t].all})
          vmax = std::max(vmax, v * 1e9);
    }
    emax = std::max(emax * 1.1, 1e-3);
    vmax *= 1.1;
    auto X = [&](double e) { return L + (W - L - R) * e / emax; };
    auto Y = [&](double v) { return H - B - (H - T - B) * v / vmax; };
    svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << H
        << "\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
    svg << "<text x=\"" << W / 2 << "\" y=\"18\" text-anchor=\"middle\">Regeneration volumes (peaks in range) vs energy flux density</text>\n";
    svg << "<line x1=\"" << L << "\" y1=\"" << H - B << "\" x2=\"" << W - R << "\" y2=\"" << H - B << "\" stroke=\"black\"/>\n";
    svg << "<line x1=\"" << L << "\" y1=\"" << T << "\" x2=\"" << L << "\" y2=\"" << H - B << "\" stroke=\"black\"/>\n";
    for (int k = 0; k <= 5; ++k) {
      const double e = emax * k / 5, v = vmax * k / 5;
      svg << "<text x=\"" << X(e) << "\" y=\"" << H - B + 16 << "\" text-anchor=\"middle\">" << number(e) << "</text>\n";
      svg << "<text x=\"" << L - 6 << "\" y=\"" << Y(v) + 4 << "\" text-anchor=\"end\">" << number(v) << "</text>\n";
    }
    svg << "<text x=\"" << W / 2 << "\" y=\"" << H - B + 34 << "\" text-anchor=\"middle\">EFD [mJ/mm^2] (seed eq. 2)</text>\n";
    svg << "<text x=\"16\" y=\"" << H / 2 << "\" transform=\"rotate(-90 16 " << H / 2 << ")\" text-anchor=\"middle\">volume [mm^3]</text>\n";
    // The seed's threshold: large volumes only above 0.3 mJ/mm^2.
    svg << "<line x1=\"" << X(0.3) << "\" y1=\"" << T << "\" x2=\"" << X(0.3) << "\" y2=\"" << H - B
        << "\" stroke=\"gray\" stroke-dasharray=\"4 3\"/>\n";
    const char* colours[] = {"#d62728", "#1f77b4", "#2ca02c", "#000000"};
    const char* names[] = {"compressive > 0.15 MPa", "distortional 0.05-1.1 %", "pore 20 kPa-2 MPa", "all three"};
    int legend = 0;
    for (int t : {shockwave::kCartilage, shockwave::kFibrocartilage}) {
      for (int c = 0; c < 4; ++c) {
        std::ostringstream pts;
        for (const ShockwaveRunResult& rr : result.runs) {
          const shockwave::RegenerationVolumes& v = rr.volumes[t];
          const double val = (c == 0 ? v.compressive : c == 1 ? v.distortional : c == 2 ? v.pore : v.all) * 1e9;
          pts << X(rr.efd_j_per_m2 * 1e-3) << "," << Y(val) << " ";
        }
        svg << "<polyline fill=\"none\" stroke=\"" << colours[c] << "\" stroke-width=\"2\""
            << (t == shockwave::kFibrocartilage ? " stroke-dasharray=\"6 3\"" : "") << " points=\"" << pts.str() << "\"/>\n";
        svg << "<text x=\"" << L + 10 << "\" y=\"" << T + 14 + 14 * legend++ << "\" fill=\"" << colours[c] << "\">"
            << (t == shockwave::kCartilage ? "cartilage: " : "menisci (dashed): ") << names[c] << "</text>\n";
      }
    }
    svg << "</svg>\n";
    common::AtomicOutput atomic(result.volumes_svg);
    std::ofstream file(atomic.temp());
    file << svg.str();
    file.close();
    if (!file) throw common::InputError(atomic.temp().string(), 0, "write failed");
    atomic.commit();
  }
  fs::remove(checkpoint_path);  // every output is complete
  return result;
}

}  // namespace arthrosim::pipelines

namespace arthrosim::pipelines {

namespace {

// Key outputs of one shockwave output folder (its summary JSON), by name.
struct ShockwaveKeyOutput {
  std::string name, unit, description;
  double value = 0.0;
};

std::vector<ShockwaveKeyOutput> shockwave_key_outputs(const fs::path& summary) {
  const json::Value doc = json::read(summary);
  std::vector<ShockwaveKeyOutput> out;
  const json::Value* runs = doc.get("runs");
  if (runs == nullptr || runs->kind != json::Value::Kind::kArray)
    throw common::InputError(summary.string(), 0, "expected an array 'runs', found none");
  auto number_of = [&](const json::Value& v, const std::string& key) {
    const json::Value* x = v.get(key);
    if (x == nullptr || x->kind != json::Value::Kind::kNumber)
      throw common::InputError(summary.string(), 0, "expected a number '" + key + "', found none");
    return x->number;
  };
  for (const json::Value& r : runs->array) {
    const json::Value* label = r.get("label");
    const std::string run = label != nullptr ? label->string : "?";
    const double stiffness = number_of(r, "stiffness_n_per_mm");
    const double bar_speed = number_of(r, "bar_speed_m_per_s");
    if (stiffness > 0)
      out.push_back({"stiffness[" + run + "]", "N/mm", "force / displacement of the platen compression", stiffness});
    if (bar_speed > 0) {
      out.push_back({"bar_speed[" + run + "]", "m/s", "p-wave speed measured along the bar", bar_speed});
      continue;
    }
    const json::Value* tissues = r.get("tissues");
    if (tissues == nullptr) continue;
    for (const char* tissue : {"cartilage", "fibrocartilage"}) {
      const json::Value* t = tissues->get(tissue);
      if (t == nullptr) continue;
      const std::string at = "[" + run + "," + tissue + "]";
      out.push_back({"max_peak_pressure" + at, "MPa", "largest peak hydrostatic pressure of the tissue",
                     number_of(*t, "max_peak_pressure_mpa")});
      out.push_back({"max_peak_distortional_strain" + at, "", "largest peak distortional strain of the tissue",
                     number_of(*t, "max_peak_distortional_strain")});
      out.push_back({"max_peak_pore_pressure" + at, "MPa", "largest peak pore pressure of the tissue",
                     number_of(*t, "max_peak_pore_pressure_mpa")});
      out.push_back({"regeneration_volume" + at, "mm^3", "volume where all three regeneration criteria held",
                     number_of(*t, "all_mm3")});
    }
  }
  return out;
}

}  // namespace

StageDescriptor shockwave_stage_descriptor() {
  StageDescriptor d;
  d.name = "shockwave";
  d.executable = "arthrosim-shockwave";
  d.summary = "poroelastic movable cellular automata: a shockwave pulse through the knee (or a bar), per EFD";
  d.block = block_schema<ShockwaveStageOptions>("shockwave",
                                                "effects and options of the shockwave stage (docs/shockwave.md)");
  d.outputs = {"shockwave"};
  for (const auto& [name, doc] : shockwave_effects()) d.effects.push_back({name, "shockwave", doc});
  d.check = [](const common::Scene& scene) {
    if (scene.has_block("shockwave")) shockwave_from_scene(scene);
  };
  d.no_runs = "a 'shockwave' block with its effects";
  d.runs = [](const common::Scene& scene, const fs::path& out) {
    std::vector<StageStep> runs;
    if (!scene.has_block("shockwave")) return runs;
    const common::OptionBlock& block = scene.block("shockwave");
    const ShockwaveStageOptions o = common::read_options<ShockwaveStageOptions>(block);
    const fs::path stem = out / "shockwave";
    StageStep s;
    s.name = "shockwave";
    s.executable = "arthrosim-shockwave";
    s.provides = {"shockwave"};
    s.origin = "the shockwave block";
    s.line = scene.block_line("shockwave");
    if (o.geometry == "knee") {
      // The knee of automata: the prepared bones and cartilage, the menisci
      // of the model folder.
      const fs::path prepared = out / "prepared.h5";
      const fs::path model = scene_inputs(scene).model;
      s.inputs.emplace_back("prepared.h5", prepared);
      s.inputs.emplace_back("model", model);
      s.arguments = {"--prepared", prepared.string(), "--model", model.string()};
    }
    s.options = block.canonical();
    s.effects = block.list("effects");
    add_path_inputs(block, s);
    // The first output holds the effect ledger the runner checks.
    for (const std::string& label : shockwave_run_labels(o)) s.outputs.push_back(stem.string() + "_" + label + ".h5");
    s.outputs.push_back(stem.string() + "_summary.json");
    s.arguments.insert(s.arguments.end(), {"--scene", scene.file.string(), "--out", stem.string()});
    runs.push_back(std::move(s));
    return runs;
  };
  d.key_outputs = [](const std::string&, const fs::path& dir, const fs::path& ref) {
    const fs::path file = dir / "shockwave_summary.json", ref_file = ref / "shockwave_summary.json";
    const std::vector<ShockwaveKeyOutput> a = shockwave_key_outputs(file), b = shockwave_key_outputs(ref_file);
    std::vector<OutputMetric> metrics;
    for (const ShockwaveKeyOutput& k : b) {
      OutputMetric m;
      m.name = k.name;
      m.description = "|x - x_ref| / |x_ref|, x the " + k.description;
      m.output_unit = k.unit;
      const auto it = std::find_if(a.begin(), a.end(), [&](const ShockwaveKeyOutput& x) { return x.name == k.name; });
      if (it == a.end()) {
        m.note = "not in " + file.string();
      } else {
        m.output = it->value;
        if (k.value != 0.0)
          m.error = std::abs(it->value - k.value) / std::abs(k.value);
        else
          m.note = "the reference value is zero; a relative error is undefined";
      }
      metrics.push_back(m);
    }
    return metrics;
  };
  return d;
}

}  // namespace arthrosim::pipelines
