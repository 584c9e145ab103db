#pragma once
// Cohort studies: many subjects x a grid of settings, run by Snakemake
// (docs/cohorts.md, `arthrosim cohort`).
//
// A cohort file (YAML) names subjects (model folder, trial, scene, overrides)
// and a settings grid (dotted scene keys -> lists of values). plan_cohort()
// turns it into one scene per subject and setting (the subject's scene with
// its model, trial and every override applied, common/scene_edit.h) and plans
// each of them through the stage table (plan_stages, pipelines/stages.h): the
// jobs of the cohort are the planned runs of every subject x setting, each
// with its program, arguments, input files, output files and options. The
// plan goes to OUT/plan.json, which workflow/Snakefile turns into rules (one
// per stage run, wildcards {subject} and {setting}); Snakemake schedules them,
// runs only what is missing and reruns what changed. Nothing here schedules.
//
// The cohort report (write_cohort_report) reads the stages' own output files
// through each stage's key_outputs (the readers the accuracy study uses) plus
// the peak tibiofemoral force of stage 1 (musculoskeletal/kinematics_file.h).
#include <filesystem>
#include <iosfwd>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace arthrosim::pipelines::cohort {

/// (dotted scene key, value as written in a scene) with where it was written.
struct Override {
  std::string key, value;
  int line = 0, column = 0;
};

struct Subject {
  std::string name;
  std::filesystem::path scene;  ///< absolute
  std::filesystem::path model;  ///< absolute; empty: the scene's
  std::filesystem::path trial;  ///< absolute; empty: the scene's
  std::vector<Override> set;    ///< the subject's own overrides
  int line = 0, column = 0;
};

struct Axis {
  std::string key;
  std::vector<std::string> values;
  int line = 0, column = 0;
};

struct Cohort {
  std::filesystem::path file;  ///< absolute
  std::string description;
  std::vector<Override> set;   ///< applied to every subject (before the subject's own)
  std::vector<Axis> settings;  ///< the grid (full product), in file order
  std::vector<Subject> subjects;
};

/// Reads and checks a cohort file. Throws common::InputError
/// ("file:line:column: error: expected ..., found ...") for anything wrong:
/// unknown keys, missing subjects, a subject without a scene, lists where a
/// value is expected, a value given twice, a path that does not exist.
/// Scene keys are checked by plan_cohort (against each subject's scene).
Cohort load_cohort(const std::filesystem::path& file);

/// One point of the settings grid.
struct Setting {
  std::string name;  ///< folder and wildcard value, e.g. "end_time_s-0.05"; "default" without a grid
  std::vector<std::pair<std::string, std::string>> values;  ///< (key, value) per axis
};
/// The full grid, first axis slowest. Names: per axis the key's last dotted
/// part (the whole key when two axes share it) '-' value, joined by '__';
/// characters other than letters, digits and _ . + - become '-' (no '=': stage
/// programs read NAME=FILE arguments).
std::vector<Setting> settings_grid(const Cohort& cohort);

/// One stage run of one subject at one setting.
struct Job {
  std::string subject, setting;
  std::string step;        ///< "prepare", "comak", "surface.osmotic", "post"
  std::string stage;       ///< the descriptor's name, "surface"
  std::string executable;  ///< "arthrosim-surface"
  std::string executable_sha256;
  std::vector<std::string> arguments;
  /// Every file or folder it reads: outputs of other jobs (relative to the
  /// cohort's output folder), input files and folders (absolute; a folder's
  /// files are listed once in Plan::folders).
  std::vector<std::string> inputs;
  std::vector<std::string> outputs;  ///< relative to the output folder: runs/<subject>/<setting>/...
  std::string options;               ///< the options it reads, one "key\tvalue" line each
  std::string options_sha256;        ///< of `options` (plan.json holds this, a rerun trigger)
  /// For a run that builds physics terms: the effects the scene asks for;
  /// the workflow checks its output's effect ledger against them, as the
  /// runner does (check_effects).
  bool check_effects = false;
  std::vector<std::string> effects;
};

struct Plan {
  std::vector<Setting> settings;
  std::vector<Job> jobs;
  /// Per subject x setting: the scene file written and its runs folder
  /// (relative to the output folder).
  struct Run {
    std::string subject, setting;
    std::filesystem::path scene;
    std::string dir;
  };
  std::vector<Run> runs;
  /// Every input folder of a job with its regular files (recursive, sorted):
  /// the workflow's inputs are files, so a file changed inside a model or
  /// trial folder reruns the jobs that read it.
  std::map<std::string, std::vector<std::string>> folders;
};

/// Writes OUT/scenes/<subject>/<setting>.yaml for every subject x setting
/// (only when its text changed, so Snakemake sees no new file), plans every
/// scene and returns the jobs. Throws InputError naming the cohort file and
/// the subject / setting for a bad key or value.
Plan plan_cohort(const Cohort& cohort, const std::filesystem::path& out_dir, const std::filesystem::path& stage_dir);

/// The plan as JSON (workflow/Snakefile reads it): schema, cohort file,
/// stage folder, settings, runs and jobs.
std::string plan_json(const Cohort& cohort, const Plan& plan, const std::filesystem::path& stage_dir);

/// Writes `text` to `file` unless the file already holds exactly it
/// (atomically: a temporary file renamed over it). True when written.
bool write_if_changed(const std::filesystem::path& file, const std::string& text);

/// The runner's check of a physics stage's output (pipelines/runner.h): the
/// effect ledger of `file` lists only terms of `requested`. Returns "" when
/// it does, else why not (an unrequested term, or no readable ledger).
/// `built` receives the ledger's totals ("ligaments 76, muscles 13").
std::string check_effects(const std::filesystem::path& file, const std::vector<std::string>& requested,
                          std::string& built);

/// The cohort report from OUT/plan.json and the stages' output files under
/// OUT: DIR/cohort.csv (one row per subject x setting, one column per key
/// output), DIR/report.html (the table and one plot per key output across
/// subjects and settings). Returns the number of rows. Missing or unreadable
/// outputs are empty cells with the reason in the report.
int write_cohort_report(const std::filesystem::path& plan_file, const std::filesystem::path& report_dir);

/// How `arthrosim cohort` (and `arthrosim study accuracy --workflow`) hands a
/// planned cohort to Snakemake.
struct WorkflowOptions {
  std::filesystem::path workflow_dir;  ///< holds Snakefile; empty: $ARTHROSIM_WORKFLOW_DIR or <repo>/workflow
  std::string snakemake = "snakemake";
  int cores = 1;
  bool cores_given = false;  ///< with a profile, --cores is passed only when given
  std::string profile;       ///< a Snakemake profile folder
  bool slurm = false;        ///< profile workflow/profiles/slurm
  bool dry_run = false;
  std::vector<std::string> extra;  ///< passed to snakemake unchanged
};

/// Plans `cohort` into `out_dir` (scenes, OUT/plan.json; progress to `log`)
/// and returns the snakemake command line that runs it. Throws InputError for
/// a bad cohort or a missing Snakefile.
std::vector<std::string> workflow_command(const Cohort& cohort, const std::filesystem::path& out_dir,
                                          const std::filesystem::path& stage_dir, WorkflowOptions options,
                                          std::ostream& log);

/// Runs `command` (fork + exec, waits) and returns its exit status (127: it
/// could not be started, with the reason on stderr).
int run_command(const std::vector<std::string>& command);

}  // namespace arthrosim::pipelines::cohort
