// arthrosim: the driver. Runs a scene -- only the stages its outputs need, in
// order, each as its own program (arthrosim-prepare, arthrosim-comak,
// arthrosim-surface, arthrosim-post next to this executable), reusing every
// stage output whose inputs, options and code are unchanged.
// Scene format: docs/scenes.md. Runner: pipelines/runner.h.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <thread>

#include <unistd.h>

#include "common/effects.h"
#include "common/error.h"
#include "common/scene.h"
#include "common/scene_edit.h"
#include "common/version.h"
#include "pipelines/apps/import_osim_command.h"
#include "pipelines/cohort.h"
#include "pipelines/apps/name_value.h"
#include "pipelines/runner.h"
#include "pipelines/stages.h"
#include "pipelines/study.h"

namespace {

constexpr const char* kDescription = R"(arthrosim: knee simulation pipeline driver.

Runs a scene (a YAML file naming the model, trial, outputs, effects and
options; see docs/scenes.md): works out which stages its outputs need, runs
only those, each as its own program writing files into the output folder, and
skips a stage whose inputs, options and code are unchanged since its last
successful run (hashes in OUT/.stamps/). A stage starts once the stages that
write its inputs are done; with --jobs 2 (the default on a 2-core machine)
the surface scenarios run side by side after COMAK, each with its share of
the cores and its output in OUT/logs/<stage>.log. Results do not depend on
--jobs.

Sample runs (from the repository root, after scripts/build.sh):
  build/bin/arthrosim run data/scenes/demo.yaml --out out/demo
      the whole pipeline on the bundled knee (README command 1)
  build/bin/arthrosim run data/scenes/demo.yaml --out out/demo --jobs 1
      the same, one stage after the other, every stage's output on the terminal
  build/bin/arthrosim run data/scenes/demo.yaml --out out/demo --dry-run
      show the plan and what would run or be skipped, and why
  build/bin/arthrosim run data/scenes/demo.yaml --out out/demo --force
      rerun every stage of the plan
  build/bin/arthrosim run data/scenes/osmotic.yaml --out out/osmotic
      the seed's osmotic scenario: prepare, then the surface stage (no COMAK)
  build/bin/arthrosim run data/scenes/gait.yaml --out out/gait_stance \
      --set surface.scenarios.gait.end_time_s=0.63
      the scene with one option changed (dotted keys as in `arthrosim study`;
      the changed scene is written to OUT/scene_set.yaml and run from there)
  build/bin/arthrosim cohort data/cohorts/tiny.yaml --out out/cohort_tiny --cores 2
      a cohort (subjects x a settings grid) run by Snakemake (docs/cohorts.md)
  build/bin/arthrosim schema
      every scene key with its type, unit, default and range, and every effect
  build/bin/arthrosim import-osim data/models/lenhart2015/source/lenhart2015.osim \
      --geometry data/models/lenhart2015/Geometry --out out/lenhart2015
      an OpenSim-JAM model into arthrosim's model format (docs/import.md)
  build/bin/arthrosim study accuracy data/studies/surface_edge_length.yaml \
      --vary prepare.edge_length_mm=3,2.5,2,1.5 --out out/study_surface
      what accuracy costs in time (see `arthrosim study accuracy --help`)

Stage programs are looked up next to this executable, or in
$ARTHROSIM_STAGE_DIR when set.
Exit status: 0 success; 1 bad scene, missing stage program or failed stage.)";

constexpr const char* kStudyDescription = R"(arthrosim study accuracy: what accuracy costs in time.

Runs SCENE at every setting of the --vary keys (the full grid when several
are given), each through the scene runner in its own folder OUT/runs/<setting>
(a stage whose options and inputs equal those of an earlier setting is copied
from it and reused by the runner's stamps, not rerun), and measures per stage
the wall time, the CPU time and the peak memory (max RSS) of the stage
process, and the error of the stage's key outputs against the reference
setting (the last value of every --vary, or --reference):
  comak            tibiofemoral contact force (RMS of |F - F_ref| over the
                   cycle / mean |F_ref|), muscle activations (RMS)
  surface.<S>      max deflection (relative), tibiofemoral contact force
                   (relative RMS) when the surface output has it
  post             mean model-map angle per scenario (relative)
List the values from coarsest to finest. The recommended setting of each stage
is the coarsest one from which refining further changes its key outputs by no
more than 5 % (seed 001's convergence rule).

KEY is a dotted scene key: model, prepare.edge_length_mm, comak.ipopt_tolerance,
surface.time_step_s (every scenario that does not set it),
surface.scenarios.osmotic.time_step_s, post.outline_points, ... (`arthrosim
schema` lists the keys; an unknown key is refused with the list of this
scene's keys). A relative path value is relative to the scene file.

Writes OUT/study.json (everything), OUT/study.csv (one row per setting and
stage), OUT/report.html (error-versus-time plot with Pareto fronts, tables,
recommended settings), OUT/scenes/ (each setting's scene).

With --workflow the grid runs through Snakemake instead (grids too large for
one machine): OUT/cohort.yaml, a cohort of one subject with the --vary values
as its settings, run like `arthrosim cohort` into OUT/cohort/ (--cores N
locally, --slurm or --profile P on a cluster; docs/cohorts.md), then evaluated
by the same code into the same outputs. Time, CPU and memory per stage are
not measured then.

Sample runs (from the repository root, after scripts/build.sh):
  build/bin/arthrosim study accuracy data/studies/post_outline_points.yaml \
      --vary post.outline_points=50,100,200,400,800 --out out/study_post
      post stage: CPD outline resolution (prepare and surface run once)
  build/bin/arthrosim study accuracy data/studies/surface_edge_length.yaml \
      --vary prepare.edge_length_mm=3,2.5,2,1.5 --out out/study_surface
      stage 2: the osmotic scenario at four shell resolutions (coarse knee)
  build/bin/arthrosim study accuracy data/studies/comak_tolerance.yaml \
      --vary comak.ipopt_tolerance=1e-2,1e-3,1e-4,1e-6,1e-8 --out out/study_comak
      stage 1: Ipopt tolerance on the coarse knee
  build/bin/arthrosim study accuracy data/scenes/cantilever_plate.yaml \
      --vary surface.scenarios.cantilever.youngs_modulus_mpa=100,400 \
      --vary surface.scenarios.cantilever.shell_thickness_mm=1,2 --reference \
      surface.scenarios.cantilever.youngs_modulus_mpa=400 --out out/study_grid
      a 2 x 2 grid
  build/bin/arthrosim study accuracy data/scenes/osmotic.yaml \
      --vary prepare.edge_length_mm=3,2.5 --out out/study_wf --workflow --cores 2
      a grid run by Snakemake (--slurm: on a cluster)

Exit status: 0 every setting ran; 1 bad input (nothing runs) or a setting
failed (the outputs are still written and name it).)";

constexpr const char* kCohortDescription = R"(arthrosim cohort: many subjects x a grid of settings, run by Snakemake.

Reads COHORT (YAML: subjects with model, trial, scene and overrides; a
settings grid of dotted scene keys -> lists of values; docs/cohorts.md),
writes one scene per subject x setting into OUT/scenes/, plans each through
the stage table and writes the jobs to OUT/plan.json, then runs Snakemake
(Debian's `snakemake`) with workflow/Snakefile in OUT: every stage run is a
job whose outputs are OUT/runs/<subject>/<setting>/..., so a second call
runs only what is missing or changed (inputs newer than outputs, other
options, another stage program). Last job: the cohort report
OUT/report/cohort.csv and OUT/report/report.html.

Local by default (--cores N); --slurm submits every job to Slurm with the
profile workflow/profiles/slurm (or --profile DIR for your own). Arguments
after `--` go to snakemake unchanged (e.g. -- --summary, -- --forcerun comak).

Sample runs (from the repository root, after scripts/build.sh):
  build/bin/arthrosim cohort data/cohorts/tiny.yaml --out out/cohort_tiny --cores 2
      2 subjects x 2 settings on the bundled knee, short windows (about a minute)
  build/bin/arthrosim cohort data/cohorts/tiny.yaml --out out/cohort_tiny --dry-run
      what would run, and why (snakemake -n)
  build/bin/arthrosim cohort data/cohorts/tiny.yaml --out out/cohort_tiny --plan-only
      write the scenes and plan.json, print the snakemake command, run nothing
  build/bin/arthrosim cohort data/cohorts/tiny.yaml --out /shared/cohort_tiny --slurm
      every stage run as a Slurm job (from a login node of the cluster)

Exit status: snakemake's (0: every job done); 1 bad cohort file (nothing runs).)";

}  // namespace

int main(int argc, char** argv) {
  namespace pl = arthrosim::pipelines;
  namespace cm = arthrosim::common;
  namespace fs = std::filesystem;
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
  run->add_flag("--allow-partial", options.allow_partial,
                "let the surface and post stages go on with an incomplete input (a killed or stopped COMAK or "
                "surface run); their outputs say so at the top");
  options.jobs = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  run->add_option("--jobs", options.jobs,
                  "how many stages may run at once (stages whose inputs are ready); "
                  "default: the number of cores")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  std::vector<std::string> set_items;
  run->add_option("--set", set_items,
                  "KEY=VALUE: change one scalar option of the scene (dotted key, e.g. "
                  "surface.scenarios.gait.end_time_s=0.3 or prepare.edge_length_mm=2.5); repeatable")
      ->allow_extra_args(false);

  CLI::App* schema = app.add_subcommand("schema", "print every scene key and effect (docs/scenes.md's reference)");
  std::string write_docs;
  schema->add_option("--write-docs", write_docs,
                     "replace the generated reference between the markers in this file (docs/scenes.md) instead of "
                     "printing it");

  CLI::App* study = app.add_subcommand("study", "studies of a scene (accuracy versus time)");
  study->require_subcommand(1);
  CLI::App* accuracy = study->add_subcommand("accuracy", kStudyDescription);
  std::string study_scene;
  std::vector<std::string> vary;
  pl::study::StudyOptions study_options;
  std::string study_out;
  accuracy->add_option("SCENE", study_scene, "scene file (YAML)")->required()->check(CLI::ExistingFile);
  accuracy->add_option("--vary", vary, "KEY=V1,V2,... (coarsest first); repeat for a grid")
      ->required()
      ->allow_extra_args(false);
  accuracy->add_option("--out", study_out, "output folder (created when missing)")->required();
  accuracy->add_option("--reference", study_options.reference,
                       "reference value: V (one --vary) or KEY=V; default the last value of each")
      ->allow_extra_args(false);
  accuracy->add_flag("--force", study_options.force, "rerun every stage of every setting");
  accuracy->add_flag("--workflow", study_options.use_workflow,
                     "run the grid as a one-subject cohort through Snakemake (OUT/cohort.yaml; docs/cohorts.md, "
                     "\"Accuracy grids\"); time, CPU and memory per stage are then not measured");
  study_options.workflow.cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  accuracy->add_option("--cores", study_options.workflow.cores, "with --workflow: cores Snakemake may use (snakemake -c)")
      ->check(CLI::PositiveNumber);
  accuracy->add_flag("--slurm", study_options.workflow.slurm, "with --workflow: every job on Slurm (workflow/profiles/slurm)");
  accuracy->add_option("--profile", study_options.workflow.profile, "with --workflow: a Snakemake profile folder");
  accuracy->add_option("--snakemake", study_options.workflow.snakemake, "with --workflow: the snakemake program")
      ->capture_default_str();

  CLI::App* cohort = app.add_subcommand("cohort", kCohortDescription);
  std::string cohort_file, cohort_out, cohort_profile, snakemake_program = "snakemake", workflow_dir;
  int cohort_cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  bool cohort_dry_run = false, cohort_slurm = false, cohort_plan_only = false;
  cohort->add_option("COHORT", cohort_file, "cohort file (YAML)")->required()->check(CLI::ExistingFile);
  cohort->add_option("--out", cohort_out, "output folder (created when missing)")->required();
  cohort->add_option("--cores", cohort_cores, "cores Snakemake may use on this machine (snakemake -c)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cohort->add_flag("--dry-run", cohort_dry_run, "show what would run (snakemake -n); run nothing");
  cohort->add_flag("--plan-only", cohort_plan_only, "write the scenes and plan.json, print the snakemake command");
  cohort->add_flag("--slurm", cohort_slurm, "run every job on Slurm (profile workflow/profiles/slurm)");
  cohort->add_option("--profile", cohort_profile, "a Snakemake profile folder (cluster settings)");
  cohort->add_option("--snakemake", snakemake_program, "the snakemake program")->capture_default_str();
  cohort->add_option("--workflow", workflow_dir,
                     "folder of the Snakefile (default: $ARTHROSIM_WORKFLOW_DIR, else workflow/ of the repository "
                     "holding this program)");
  std::vector<std::string> snakemake_args;
  cohort->add_option("SNAKEMAKE_ARGS", snakemake_args, "after `--`: arguments passed to snakemake unchanged");

  CLI::App* cohort_report = app.add_subcommand(
      "cohort-report", "the cohort report from OUT/plan.json and the runs' output files (the workflow's last job)");
  std::string report_plan, report_out;
  cohort_report->add_option("PLAN", report_plan, "OUT/plan.json written by `arthrosim cohort`")
      ->required()
      ->check(CLI::ExistingFile);
  cohort_report->add_option("--out", report_out, "report folder (cohort.csv, report.html)")->required();

  CLI::App* check_effects = app.add_subcommand(
      "cohort-check-effects", "the runner's effect-ledger check of one stage output (run by workflow/Snakefile)");
  std::string effects_file;
  std::vector<std::string> effects_requested;
  check_effects->add_option("FILE", effects_file, "a stage's HDF5 output")->required()->check(CLI::ExistingFile);
  check_effects->add_option("--effects", effects_requested, "the effects the scene asks for")->delimiter(',');

  pl::ImportOsimCommand import_osim;
  pl::add_import_osim_command(app, import_osim);

  CLI11_PARSE(app, argc, argv);

  if (import_osim.app->parsed()) return pl::run_import_osim_command(import_osim);
  if (check_effects->parsed()) {
    std::string built;
    const std::string problem = pl::cohort::check_effects(effects_file, effects_requested, built);
    std::cout << effects_file << ": effects built: " << (built.empty() ? "none" : built) << "\n";
    if (problem.empty()) return 0;
    std::cerr << "arthrosim cohort-check-effects: " << effects_file << ": error: " << problem << "\n";
    return 1;
  }
  if (cohort_report->parsed()) {
    try {
      const int rows = pl::cohort::write_cohort_report(report_plan, report_out);
      std::cout << "cohort-report: " << rows << " runs; wrote " << (fs::path(report_out) / "cohort.csv").string()
                << ", " << (fs::path(report_out) / "report.html").string() << "\n";
      return 0;
    } catch (const cm::InputError& e) {
      std::cerr << "arthrosim cohort-report: " << e.what() << "\n";
      return 1;
    }
  }
  if (cohort->parsed()) {
    std::vector<std::string> command;
    try {
      const fs::path stage_dir = pl::default_stage_dir();
      const pl::cohort::Cohort c = pl::cohort::load_cohort(cohort_file);
      pl::cohort::WorkflowOptions wo;
      wo.workflow_dir = workflow_dir;
      wo.snakemake = snakemake_program;
      wo.cores = cohort_cores;
      wo.cores_given = cohort->count("--cores") > 0;
      wo.profile = cohort_profile;
      wo.slurm = cohort_slurm;
      wo.dry_run = cohort_dry_run;
      wo.extra = snakemake_args;
      command = pl::cohort::workflow_command(c, cohort_out, stage_dir, wo, std::cout);
    } catch (const cm::InputError& e) {
      std::cerr << "arthrosim cohort: " << e.what() << "\n";
      return 1;
    } catch (const fs::filesystem_error& e) {
      std::cerr << "arthrosim cohort: error: " << e.what() << "\n";
      return 1;
    }
    std::string shown;
    for (const std::string& w : command) shown += (shown.empty() ? "" : " ") + w;
    std::cout << "arthrosim cohort: " << (cohort_plan_only ? "to run it: " : "$ ") << shown << std::endl;
    if (cohort_plan_only) return 0;
    std::vector<char*> argv_exec;
    for (std::string& w : command) argv_exec.push_back(w.data());
    argv_exec.push_back(nullptr);
    execvp(argv_exec[0], argv_exec.data());
    std::cerr << "arthrosim cohort: error: cannot run " << snakemake_program << " (" << std::strerror(errno)
              << "): install it (scripts/install-deps.sh installs Debian's snakemake) or name it with --snakemake\n";
    return 1;
  }
  if (accuracy->parsed()) {
    try {
      study_options.scene_file = study_scene;
      study_options.out_dir = study_out;
      study_options.stage_dir = pl::default_stage_dir();
      for (int i = 0; i < argc; ++i) {
        study_options.command_line += (i ? " " : "") + std::string(i ? argv[i] : "arthrosim");
      }
      for (const std::string& v : vary) study_options.axes.push_back(pl::study::parse_vary(v));
      study_options.workflow.cores_given = accuracy->count("--cores") > 0;
      if (!study_options.use_workflow &&
          (study_options.workflow.cores_given || study_options.workflow.slurm || !study_options.workflow.profile.empty())) {
        throw cm::InputError("--cores/--slurm/--profile", 0, "expected --workflow with them (they configure Snakemake)");
      }
      const pl::study::StudyResult result = pl::study::run_accuracy_study(study_options, std::cout);
      pl::study::write_study_outputs(study_options, result);
      const fs::path out = fs::absolute(study_out).lexically_normal();
      std::cout << "study: wrote " << (out / "study.json").string() << ", "
                << (out / "study.csv").string() << ", " << (out / "report.html").string() << "\n";
      bool all_ok = true;
      for (const pl::study::SettingResult& r : result.settings) all_ok = all_ok && r.ok;
      if (!all_ok) {
        std::cerr << "arthrosim study: error: at least one setting failed (see the report)\n";
        return 1;
      }
      return 0;
    } catch (const cm::InputError& e) {
      std::cerr << "arthrosim study: " << e.what() << "\n";
      return 1;
    } catch (const std::filesystem::filesystem_error& e) {
      std::cerr << "arthrosim study: error: " << e.what() << "\n";
      return 1;
    }
  }

  if (schema->parsed()) {
    if (write_docs.empty()) {
      std::cout << pl::schema_reference();
      return 0;
    }
    try {
      std::ifstream in(write_docs, std::ios::binary);
      if (!in) throw cm::InputError(write_docs, 0, "cannot read the file");
      const std::string doc((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      const std::string updated = pl::with_schema_reference(doc, write_docs);
      std::ofstream(write_docs, std::ios::binary) << updated;
      std::cout << "arthrosim: " << (updated == doc ? "already up to date: " : "updated the reference in ")
                << write_docs << "\n";
      return 0;
    } catch (const cm::InputError& e) {
      std::cerr << "arthrosim schema: " << e.what() << "\n";
      return 1;
    }
  }

  try {
    std::string file = scene_file;
    if (!set_items.empty()) {
      // The scene with the settings applied (paths made absolute) goes into
      // the output folder: the stage programs read it from there.
      std::vector<std::pair<std::string, std::string>> settings;
      for (const std::string& item : set_items) settings.push_back(pl::split_name_value(item, "--set", "KEY=VALUE"));
      // Checks the original scene and every key (the values: when the copy is loaded below).
      const std::string text = cm::edit_scene_text(scene_file, pl::scene_schema(), settings);
      std::filesystem::create_directories(out_dir);
      file = (std::filesystem::path(out_dir) / "scene_set.yaml").string();
      std::ofstream(file, std::ios::binary) << text;
      std::cout << "arthrosim: scene " << scene_file << " with " << set_items.size()
                << " setting(s) written to " << file << "\n";
    }
    const cm::Scene scene = pl::load_scene(file);
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
