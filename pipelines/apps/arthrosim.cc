// arthrosim: the driver. Runs a scene -- only the stages its outputs need, in
// order, each as its own program (arthrosim-prepare, arthrosim-comak,
// arthrosim-surface, arthrosim-post next to this executable), reusing every
// stage output whose inputs, options and code are unchanged.
// Scene format: docs/scenes.md. Runner: pipelines/runner.h.
#include <CLI/CLI.hpp>

#include <iostream>

#include "common/effects.h"
#include "common/error.h"
#include "common/scene.h"
#include "common/version.h"
#include "pipelines/runner.h"

namespace {

constexpr const char* kDescription = R"(arthrosim: knee simulation pipeline driver.

Runs a scene (a YAML file naming the model, trial, outputs, effects and
options; see docs/scenes.md): works out which stages its outputs need, runs
only those, in order, each as its own program writing files into the output
folder, and skips a stage whose inputs, options and code are unchanged since
its last successful run (hashes in OUT/.stamps/).

Sample runs (from the repository root, after scripts/build.sh):
  build/bin/arthrosim run data/scenes/demo.yaml --out out/demo
      prepare the bundled knee (the demo today asks for the prepared model)
  build/bin/arthrosim run data/scenes/demo.yaml --out out/demo --dry-run
      show the plan and what would run or be skipped, and why
  build/bin/arthrosim run data/scenes/demo.yaml --out out/demo --force
      rerun every stage of the plan
  build/bin/arthrosim run data/scenes/osmotic.yaml --out out/osmotic
      the seed's osmotic scenario: prepare, then the surface stage (no COMAK)
  build/bin/arthrosim schema
      every scene key with its type, unit, default and range, and every effect

Stage programs are looked up next to this executable, or in
$ARTHROSIM_STAGE_DIR when set.
Exit status: 0 success; 1 bad scene, missing stage program or failed stage.)";

}  // namespace

int main(int argc, char** argv) {
  namespace pl = arthrosim::pipelines;
  namespace cm = arthrosim::common;
  CLI::App app{kDescription, "arthrosim"};
  app.set_version_flag("--version", std::string(cm::kVersion) + " (" + cm::kGitRevision + ")");
  app.require_subcommand(1);

  std::string scene_file;
  pl::RunnerOptions options;
  std::string out_dir = "out";
  CLI::App* run = app.add_subcommand("run", "run a scene");
  run->add_option("SCENE", scene_file, "scene file (YAML)")->required()->check(CLI::ExistingFile);
  run->add_option("--out", out_dir, "output folder (created when missing)")->capture_default_str();
  run->add_flag("--force", options.force, "run every planned stage even when up to date");
  run->add_flag("--dry-run", options.dry_run, "print the plan and what would run; run nothing");

  CLI::App* schema = app.add_subcommand("schema", "print every scene key and effect");

  CLI11_PARSE(app, argc, argv);

  if (schema->parsed()) {
    std::cout << "# Scene keys (from option_schema() in common/scene.cc)\n"
              << cm::schema_markdown() << "\n# Effects\n\n| effect | stage | meaning |\n"
              << "|---|---|---|\n";
    for (const cm::EffectInfo& e : cm::known_effects()) {
      std::cout << "| `" << e.name << "` | " << cm::to_string(e.stage) << " | " << e.description
                << " |\n";
    }
    return 0;
  }

  try {
    const cm::Scene scene = cm::load_scene(scene_file);
    options.out_dir = out_dir;
    options.stage_dir = pl::default_stage_dir();
    const pl::RunReport report = pl::run_scene(scene, options, std::cout);
    if (report.status != pl::RunStatus::kOk) {
      std::cerr << "arthrosim: " << report.message << "\n";
      return 1;
    }
    return 0;
  } catch (const cm::InputError& e) {
    std::cerr << e.what() << "\n";
    return 1;
  } catch (const std::filesystem::filesystem_error& e) {
    std::cerr << "arthrosim: error: " << e.what() << "\n";
    return 1;
  }
}
