// arthrosim-shockwave: the shockwave stage (issue 32, seed 001). Prepared
// model + model folder (menisci) -> poroelastic movable cellular automata ->
// one HDF5 + XDMF pair per energy flux density (docs/shockwave.md).
#include <cmath>
#include <cstdio>
#include <exception>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <iostream>
#include <sstream>
#include <string>

#include <CLI/CLI.hpp>

#include "common/log.h"
#include "common/options.h"
#include "pipelines/shockwave_stage.h"
#include "pipelines/stages.h"

using namespace arthrosim;

namespace {

std::string flag_name(std::string_view key) {
  std::string s = "--";
  for (char c : key) s += c == '_' ? '-' : c;
  return s;
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const std::string& x : v) s += (s.empty() ? "" : " ") + x;
  return s;
}

// Turns the stage's option declaration (ShockwaveStageOptions::declare) into
// command-line options: --key-with-dashes VALUE in the unit of the key's
// suffix. apply() copies the options given on the command line into the
// struct (converted to SI), over the defaults or the scene's block.
class CliVisitor : public common::OptionVisitor {
 public:
  explicit CliVisitor(CLI::App& app) : app_(app) {}
  OptionVisitor& number(std::string_view key, double& si, common::Unit unit, common::Range range,
                        std::string_view doc) override {
    auto written = std::make_shared<double>(si / common::unit_to_si(unit));
    CLI::Option* opt = app_.add_option(flag_name(key), *written,
                                       std::string(doc) + " [default " + common::written_value(si, unit) + "]");
    opt->check(CLI::Range(range.min, range.max));
    apply_.push_back([&si, written, unit, opt] {
      if (opt->count()) si = *written * common::unit_to_si(unit);
    });
    return *this;
  }
  OptionVisitor& number(std::string_view key, std::optional<double>& si, common::Unit unit, common::Range range,
                        std::string_view doc) override {
    auto written = std::make_shared<double>(0.0);
    CLI::Option* opt = app_.add_option(flag_name(key), *written, std::string(doc));
    opt->check(CLI::Range(range.min, range.max));
    apply_.push_back([&si, written, unit, opt] {
      if (opt->count()) si = *written * common::unit_to_si(unit);
    });
    return *this;
  }
  OptionVisitor& integer(std::string_view key, int& value, common::Range range, std::string_view doc) override {
    auto given = std::make_shared<int>(value);
    CLI::Option* opt =
        app_.add_option(flag_name(key), *given, std::string(doc) + " [default " + std::to_string(value) + "]");
    opt->check(CLI::Range(range.min, range.max));
    apply_.push_back([&value, given, opt] {
      if (opt->count()) value = *given;
    });
    return *this;
  }
  OptionVisitor& flag(std::string_view key, bool& value, std::string_view doc) override {
    auto given = std::make_shared<bool>(value);
    CLI::Option* opt = app_.add_option(flag_name(key), *given,
                                       std::string(doc) + " [default " + (value ? "true" : "false") + "]");
    apply_.push_back([&value, given, opt] {
      if (opt->count()) value = *given;
    });
    return *this;
  }
  OptionVisitor& text(std::string_view key, std::string& value, std::string_view choices,
                      std::string_view doc) override {
    auto given = std::make_shared<std::string>(value);
    CLI::Option* opt = app_.add_option(flag_name(key), *given, std::string(doc) + " [default " + value + "]");
    if (!choices.empty()) opt->check(CLI::IsMember(words(choices)));
    apply_.push_back([&value, given, opt] {
      if (opt->count()) value = *given;
    });
    return *this;
  }
  OptionVisitor& path(std::string_view key, std::filesystem::path& value, std::string_view doc) override {
    auto given = std::make_shared<std::filesystem::path>(value);
    CLI::Option* opt = app_.add_option(flag_name(key), *given, std::string(doc));
    apply_.push_back([&value, given, opt] {
      if (opt->count()) value = *given;
    });
    return *this;
  }
  OptionVisitor& text_list(std::string_view key, std::vector<std::string>& value, std::string_view choices,
                           std::string_view doc) override {
    auto given = std::make_shared<std::vector<std::string>>();
    CLI::Option* opt = app_.add_option(flag_name(key), *given, std::string(doc) + " [default " + join(value) + "]");
    if (!choices.empty()) opt->check(CLI::IsMember(words(choices)));
    apply_.push_back([&value, given, opt] {
      if (opt->count()) value = *given;
    });
    return *this;
  }
  OptionVisitor& number_list(std::string_view key, std::vector<double>& si, common::Unit unit, common::Range length,
                             std::string_view doc) override {
    auto written = std::make_shared<std::vector<double>>();
    std::vector<std::string> def;
    for (double v : si) def.push_back(common::written_value(v, unit));
    CLI::Option* opt = app_.add_option(flag_name(key), *written,
                                       std::string(doc) + (def.empty() ? "" : " [default " + join(def) + "]"));
    opt->expected(static_cast<int>(length.min), static_cast<int>(length.max));
    apply_.push_back([&si, written, unit, opt] {
      if (!opt->count()) return;
      si.clear();
      for (double v : *written) si.push_back(v * common::unit_to_si(unit));
    });
    return *this;
  }
  OptionVisitor& named_numbers(std::string_view key, std::map<std::string, double>&, common::Unit, common::Range,
                               std::string_view) override {
    throw std::logic_error("arthrosim-shockwave: no command-line form for the named numbers '" + std::string(key) +
                           "'");
  }
  OptionVisitor& effect_list(std::string_view key, std::vector<std::string>& value, std::string_view,
                             std::string_view doc) override {
    auto given = std::make_shared<std::vector<std::string>>();
    CLI::Option* opt = app_.add_option(flag_name(key), *given, std::string(doc) + " [default " + join(value) + "]");
    opt->expected(1, 8);
    apply_.push_back([&value, given, opt] {
      if (opt->count()) value = *given;
    });
    return *this;
  }
  void apply() {
    for (auto& f : apply_) f();
  }

 protected:
  void choice_index(std::string_view key, const std::vector<std::string_view>&, int&, std::string_view) override {
    throw std::logic_error("arthrosim-shockwave: no command-line form for the choice '" + std::string(key) + "'");
  }

 private:
  static std::vector<std::string> words(std::string_view choices) {
    std::vector<std::string> w;
    std::stringstream ss{std::string(choices)};
    std::string x;
    while (std::getline(ss, x, '|')) w.push_back(x);
    return w;
  }
  CLI::App& app_;
  std::vector<std::function<void()>> apply_;
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "arthrosim-shockwave: shockwave treatment of the knee by poroelastic movable cellular automata (seed 001,\n"
      "Eremina & Smolin 2021). Builds the knee of automata from the prepared model (femur and tibia cut at a distance\n"
      "from the joint line, cortical shell and cancellous interior, cartilage) and the menisci of the model folder, in\n"
      "a capsule box (fibrous tissue, shell) with a copper applicator on one face, and runs one pulse per energy flux\n"
      "density: automata (A1-A8), Biot pore fluid (A9-A10), Darcy filtration (A11-A12). Writes per run the hydrostatic\n"
      "pressure, distortional strain and pore pressure of every automaton over time and their peaks (HDF5 + XDMF\n"
      "points for ParaView) and the regeneration-criteria volumes of cartilage and menisci; a summary JSON and a\n"
      "volumes-vs-EFD plot (SVG). Method, options, units, limits: docs/shockwave.md."};
  pipelines::ShockwaveStageOptions o;
  bool verbose = false, quiet = false, dry_run = false;
  std::string scene_path;
  app.add_option("--prepared", o.prepared, "prepared-model HDF5 (arthrosim-prepare); not needed with --geometry bar");
  app.add_option("--model", o.model, "model folder with <name>_meniscus.{stl,obj,ply} (the menisci)");
  app.add_option("--out", o.out, "output stem: <stem>_efd<EFD>.h5/.xdmf per run, <stem>_summary.json, <stem>_volumes.svg")
      ->required();
  app.add_option("--scene", scene_path,
                 "scene YAML: its shockwave block gives effects and options (docs/scenes.md); a flag below wins "
                 "over it");
  CliVisitor visitor(app);
  o.declare(visitor);
  app.add_flag("--dry-run", dry_run, "build the model and print what each run would take; simulate nothing");
  app.add_flag("--verbose", verbose, "more messages");
  app.add_flag("--quiet", quiet, "warnings and errors only (no progress)");
  app.footer(
      "Sample runs:\n"
      "  arthrosim-prepare --model data/models/knee_parametric/coarse --out prepared_coarse.h5\n"
      "  arthrosim-shockwave --prepared prepared_coarse.h5 --model data/models/knee_parametric/coarse \\\n"
      "      --automaton-diameter-mm 2 --end-time-us 10 --out sw_quick\n"
      "      # a quick look (seconds): the first 10 us of a 0.33 mJ/mm^2 pulse on the 2 mm knee\n"
      "  arthrosim-shockwave --prepared prepared_coarse.h5 --model data/models/knee_parametric/coarse \\\n"
      "      --efd-mj-per-mm2 0.12 0.33 0.8 --out sw [--dry-run]\n"
      "      # the seed's three runs at d = 1 mm (stepping about 3.5 CPU min each, 12 min wall with 2 threads on a\n"
      "      # loaded 2-core machine; --dry-run: the plan)\n"
      "  paraview sw_efd0.33.xdmf                        # pressure, distortional strain, pore pressure per automaton\n"
      "  arthrosim-shockwave --prepared prepared_coarse.h5 --model data/models/knee_parametric/coarse \\\n"
      "      --automaton-diameter-mm 2 --effects mca_elastic pore_fluid filtration platen_compression \\\n"
      "      --out sw_stiff [--dry-run]   # slow compression between the cut faces: stiffness (minutes)\n"
      "  arthrosim-shockwave --geometry bar --bar-tissue cartilage --end-time-us 60 --pulse-rise-time-us 10 \\\n"
      "      --pulse-fall-time-us 10 --pulse-positive-duration-us 20 --pulse-tail-duration-us 0 --out sw_bar\n"
      "      # under a second: the p-wave speed of a cartilage bar against Gassmann's undrained value\n"
      "  arthrosim run data/scenes/shockwave_bar.yaml --out out/shockwave_bar [--dry-run]\n"
      "      # the same bar from its scene (the runner calls this program with --scene)\n"
      "  arthrosim run data/scenes/shockwave.yaml --out out/shockwave --dry-run\n"
      "      # the plan of the seed's three runs: prepare, then this stage with the scene's shockwave block\n"
      "Threads: OMP_NUM_THREADS (same bytes for any count); on a shared machine also\n"
      "OMP_WAIT_POLICY=passive (threads waiting at a barrier sleep instead of spinning).\n");
  CLI11_PARSE(app, argc, argv);
  common::set_log_program("arthrosim-shockwave");
  common::set_log_level(common::log_level_from_flags(verbose, quiet));
  std::vector<std::string> args(argv, argv + argc);
  try {
    // Options: the defaults, then the scene's shockwave block, then the flags given.
    if (!scene_path.empty()) {
      pipelines::ShockwaveStageOptions from_scene = pipelines::shockwave_from_scene(pipelines::load_scene(scene_path));
      from_scene.prepared = o.prepared;
      from_scene.model = o.model;
      from_scene.out = o.out;
      o = from_scene;
    }
    visitor.apply();
    const pipelines::ShockwaveStageResult r = pipelines::run_shockwave_stage(o, args, !quiet, dry_run);
    if (dry_run) {
      std::printf("%d automata, %lld bonds; time step %.4g ns (stability limit %.4g ns, %s)\n", r.automata,
                  static_cast<long long>(r.bonds), r.time_step_s * 1e9, r.critical_time_step_s * 1e9,
                  r.critical_tissue.c_str());
      for (const auto& rr : r.runs)
        std::printf("would run %s: %lld steps, %.3g automaton-steps\n", rr.label.c_str(),
                    static_cast<long long>(rr.steps), r.automata * static_cast<double>(rr.steps));
      return 0;
    }
    std::printf("%d automata, %lld bonds; time step %.4g ns (stability limit %.4g ns, %s; d/c_p %.4g ns, %s %.0f m/s)\n",
                r.automata, static_cast<long long>(r.bonds), r.time_step_s * 1e9, r.critical_time_step_s * 1e9,
                r.critical_tissue.c_str(), o.automaton_diameter_m / r.fastest_p_wave * 1e9,
                r.fastest_p_wave_tissue.c_str(), r.fastest_p_wave);
    for (const auto& rr : r.runs) {
      std::printf("%s: %lld steps, %.1f s (%.3g automaton-steps/s)", rr.label.c_str(), static_cast<long long>(rr.steps),
                  rr.wall_s, r.automata * static_cast<double>(rr.steps) / rr.wall_s);
      if (rr.peak_pressure_pa > 0) std::printf(", pulse peak %.3g MPa", rr.peak_pressure_pa * 1e-6);
      if (rr.stiffness_n_per_m > 0)
        std::printf(", force %.4g N at %.4g mm: stiffness %.4g N/mm", rr.force_n, rr.displacement_m * 1e3,
                    rr.stiffness_n_per_m * 1e-3);
      std::printf("\n");
      if (rr.bar_speed > 0) {
        std::printf("  bar: p-wave speed %.1f m/s; closed forms: drained %.1f m/s, undrained (Gassmann) %.1f m/s\n",
                    rr.bar_speed, rr.bar_drained_speed, rr.bar_undrained_speed);
        continue;
      }
      for (int t : {shockwave::kCartilage, shockwave::kFibrocartilage}) {
        const auto& v = rr.volumes[t];
        std::printf("  %-15s volume %8.1f mm^3: compressive %8.1f, distortional %8.1f, pore %8.1f, all three %8.1f "
                    "(at once %.1f) mm^3; max peaks P %.3g MPa, strain %.3g, pore %.3g MPa\n",
                    shockwave::knee_tissue_name(t), v.tissue * 1e9, v.compressive * 1e9, v.distortional * 1e9,
                    v.pore * 1e9, v.all * 1e9, rr.all_at_once_m3[t] * 1e9, rr.max_peaks[t][0] * 1e-6,
                    rr.max_peaks[t][1], rr.max_peaks[t][2] * 1e-6);
      }
    }
    std::printf("wrote %s%s%s\n", r.summary_json.string().c_str(), r.volumes_svg.empty() ? "" : ", ",
                r.volumes_svg.string().c_str());
  } catch (const std::exception& e) {
    std::cerr << "arthrosim-shockwave: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
