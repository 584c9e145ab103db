#pragma once
// The scene runner behind `arthrosim run SCENE` (docs/scenes.md, "Running").
//
// It works out which stages the scene's outputs need (the stage graph below),
// runs only those, in order, each as its own executable build/bin/arthrosim-<stage>
// reading and writing files in the output folder, and reuses a stage's output
// when nothing it depends on has changed.
//
// Stage graph (files in the output folder DIR):
//   prepare          model                                   -> prepared.h5
//   comak            model, trial, prepared.h5               -> kinematics.h5
//   surface.<name>   prepared.h5 [+ kinematics.h5 when the
//                    scenario uses imposed_kinematics]       -> surface_<name>.h5
//   post             every surface_<name>.h5 [+ kinematics.h5
//                    when comak is part of the run]          -> report.html, summary.json
// Outputs -> stages: prepared_model -> prepare; kinematics -> comak;
// surface -> every scenario; biphasic -> biphasic (and therefore comak);
// report -> post (and therefore every scenario).
//
// Effects: a comak, surface or biphasic stage whose output's effect ledger holds a term
// the scene did not ask for fails (and is not stamped), so "only the effects a
// scene calls for" is checked on every run, not only in tests.
//
// Reuse: a stage's key is SHA-256 over (the contents of its input files, its
// canonical options text from the scene, the bytes of its executable, its
// command line with paths replaced by names such as <model> and $OUT/...). After
// a successful run the runner writes DIR/.stamps/<stage>.txt with the key, its
// parts and the hashes of the outputs. The next run skips the stage when the
// key is the same and every output still has the recorded hash; otherwise it
// says what changed and runs it. The stamp is deleted before a stage starts,
// so a stage that fails or is killed never looks up to date. A run holds an
// exclusive lock on DIR/.arthrosim.lock, so two runs never share a folder.
#include <cstdint>
#include <filesystem>
#include <iosfwd>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/scene.h"

namespace arthrosim::pipelines {

/// One stage of a plan: what to execute and what its result depends on.
struct StageStep {
  std::string name;        ///< "prepare", "comak", "surface.osmotic", "post"
  std::string executable;  ///< file name, e.g. "arthrosim-prepare"
  std::vector<std::string> arguments;  ///< after the program name
  /// (label, path) of every file or folder whose contents the output depends
  /// on; labels ("model", "prepared.h5") are what messages and stamps show.
  std::vector<std::pair<std::string, std::filesystem::path>> inputs;
  std::vector<std::filesystem::path> outputs;  ///< files the stage must write
  /// ("block.key", canonical value), sorted: the options the stage reads.
  std::vector<std::pair<std::string, std::string>> options;
  std::string needed_for;  ///< why it is in the plan, e.g. "output prepared_model"
  /// For stages that build physics terms (comak, surface.*): the effects the
  /// scene asks for. After the stage exits 0 the runner reads the effect
  /// ledger (/effects, common/effects.h) from outputs[0] and fails the stage
  /// if the ledger is missing or holds a term not in this list.
  std::optional<std::vector<std::string>> effects;
};

/// The stages `scene` needs, in execution order, writing into `out_dir`.
std::vector<StageStep> plan_stages(const common::Scene& scene,
                                   const std::filesystem::path& out_dir);

struct RunnerOptions {
  std::filesystem::path out_dir = "out";  ///< created when missing
  /// Folder holding the arthrosim-<stage> executables (the `arthrosim`
  /// program passes its own folder, or $ARTHROSIM_STAGE_DIR).
  std::filesystem::path stage_dir;
  bool force = false;    ///< run every planned stage even when up to date
  bool dry_run = false;  ///< print the plan and what would run; run nothing
  /// How many stages may run at once. A stage starts when the stages that
  /// write its inputs are done, so with 2 the surface scenarios run side by
  /// side after COMAK. A stage running alone streams its output and uses every
  /// core; stages running together write DIR/logs/<stage>.log (the runner
  /// prints their progress every 30 s and each log's last lines when it ends)
  /// and share the cores through OMP_NUM_THREADS (unless the caller set it).
  /// Results are bit-identical for any value. 1: one stage after the other.
  int jobs = 1;
};

enum class StageStatus {
  kRan,         ///< executed and exited 0 with all outputs written
  kSkipped,     ///< up to date: inputs, options and code unchanged
  kWouldRun,    ///< dry run: would execute
  kWouldSkip,   ///< dry run: up to date
  kFailed,      ///< exited non-zero, was killed, or did not write its outputs
  kNotReached,  ///< not attempted because an earlier stage failed
};

struct StageOutcome {
  std::string name;
  StageStatus status = StageStatus::kNotReached;
  std::string reason;   ///< why it ran / was skipped / failed
  std::string key;      ///< SHA-256 stage key (empty if not computed)
  int exit_code = 0;    ///< of the executable (128 + signal when killed)
  double wall_time_s = 0.0;
  /// Of a stage that was executed (kRan or kFailed), from wait4's rusage of
  /// the stage process (its waited-for children included): user + system CPU
  /// time, and the peak resident set size of the largest of those processes.
  double cpu_time_s = 0.0;
  std::int64_t max_rss_kb = 0;
};

enum class RunStatus {
  kOk,
  kStageFailed,        ///< a stage failed; outputs of earlier stages stay
  kMissingExecutable,  ///< a planned stage's executable is not in stage_dir
  kFolderBusy,         ///< another run holds the output folder's lock
};

struct RunReport {
  RunStatus status = RunStatus::kOk;
  std::string message;  ///< one line for the user when status != kOk
  std::vector<StageOutcome> stages;
};

/// Plans and runs `scene`, printing progress to `log` (the stages' own output
/// goes straight to this process's stdout/stderr as they run). Never throws
/// for a failing stage (see RunReport); throws common::InputError for files
/// that cannot be read or an output folder that cannot be created.
RunReport run_scene(const common::Scene& scene, const RunnerOptions& options, std::ostream& log);

/// The executables folder of the running program: $ARTHROSIM_STAGE_DIR when
/// set, else the folder of /proc/self/exe.
std::filesystem::path default_stage_dir();

}  // namespace arthrosim::pipelines
