// arthrosim-shockwave: the shockwave stage (issue 32, seed 001). Prepared
// model + model folder (menisci) -> poroelastic movable cellular automata ->
// one HDF5 + XDMF pair per energy flux density (docs/shockwave.md).
#include <cmath>
#include <cstdio>
#include <exception>
#include <iostream>
#include <sstream>
#include <string>

#include <CLI/CLI.hpp>

#include "common/log.h"
#include "pipelines/shockwave_stage.h"

using namespace arthrosim;

namespace {

std::string flag_name(const char* key) {
  std::string s = "--";
  for (const char* c = key; *c; ++c) s += *c == '_' ? '-' : *c;
  return s;
}

std::string shortest(double v) {
  for (int p = 1; p <= 17; ++p) {
    std::ostringstream s;
    s.precision(p);
    s << v;
    if (std::stod(s.str()) == v) return s.str();
  }
  return std::to_string(v);
}

// Turns the stage's option declaration (ShockwaveStageOptions::declare) into
// command-line options: --key-with-dashes VALUE in the unit of the key's
// suffix, converted to SI after parsing.
class CliVisitor {
 public:
  explicit CliVisitor(CLI::App& app) : app_(app) {}
  void number(const char* key, double& si, pipelines::OptionUnit unit, double min, double max, const char* doc) {
    auto written = std::make_shared<double>(si / unit.to_si);
    app_.add_option(flag_name(key), *written, std::string(doc) + " [default " + shortest(*written) + "]")
        ->check(CLI::Range(min, max));
    finish_.push_back([&si, written, unit] { si = *written * unit.to_si; });
  }
  void number_list(const char* key, std::vector<double>& si, pipelines::OptionUnit unit, double min_len,
                   double max_len, const char* doc) {
    auto written = std::make_shared<std::vector<double>>();
    std::string def;
    for (double v : si) def += (def.empty() ? "" : " ") + shortest(v / unit.to_si);
    app_.add_option(flag_name(key), *written, std::string(doc) + (def.empty() ? "" : " [default " + def + "]"))
        ->expected(static_cast<int>(min_len), static_cast<int>(max_len));
    finish_.push_back([&si, written, unit] {
      if (written->empty()) return;
      si.clear();
      for (double v : *written) si.push_back(v * unit.to_si);
    });
  }
  void flag(const char* key, bool& value, const char* doc) {
    app_.add_option(flag_name(key), value, std::string(doc) + " [default " + (value ? "true" : "false") + "]");
  }
  void text(const char* key, std::string& value, const char* choices, const char* doc) {
    auto* opt = app_.add_option(flag_name(key), value, std::string(doc) + " [default " + value + "]");
    if (*choices) {
      std::vector<std::string> words;
      std::stringstream ss(choices);
      std::string w;
      while (std::getline(ss, w, '|')) words.push_back(w);
      opt->check(CLI::IsMember(words));
    }
  }
  void path(const char* key, std::filesystem::path& value, const char* doc) {
    app_.add_option(flag_name(key), value, doc);
  }
  void effect_list(const char* key, std::vector<std::string>& value, const char* doc) {
    std::string def;
    for (const std::string& e : value) def += (def.empty() ? "" : " ") + e;
    app_.add_option(flag_name(key), value, std::string(doc) + " [default " + def + "]")->expected(1, 8);
  }
  void finish() {
    for (auto& f : finish_) f();
  }

 private:
  CLI::App& app_;
  std::vector<std::function<void()>> finish_;
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
  app.add_option("--prepared", o.prepared, "prepared-model HDF5 (arthrosim-prepare); not needed with --geometry bar");
  app.add_option("--model", o.model, "model folder with <name>_meniscus.{stl,obj,ply} (the menisci)");
  app.add_option("--out", o.out, "output stem: <stem>_efd<EFD>.h5/.xdmf per run, <stem>_summary.json, <stem>_volumes.svg")
      ->required();
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
      "Threads: OMP_NUM_THREADS (same bytes for any count); on a shared machine also\n"
      "OMP_WAIT_POLICY=passive (threads waiting at a barrier sleep instead of spinning).\n");
  CLI11_PARSE(app, argc, argv);
  visitor.finish();
  common::set_log_program("arthrosim-shockwave");
  common::set_log_level(common::log_level_from_flags(verbose, quiet));
  std::vector<std::string> args(argv, argv + argc);
  try {
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
