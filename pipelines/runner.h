#pragma once
// The scene runner behind `arthrosim run SCENE` (docs/scenes.md, "Running").
//
// It works out which stages the scene's outputs need (the stage graph below),
// runs only those, in order, each as its own executable build/bin/arthrosim-<stage>
// reading and writing files in the output folder, and reuses a stage's output
// when nothing it depends on has changed.
//
// The plan comes from the stage table (pipelines/stages.h, plan_stages): each
// stage's descriptor says which runs a scene has, what each reads and writes
// and which scene outputs it provides; a run is planned when the scene asks
// for one of its outputs or a planned run reads one of its files.
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
#include "pipelines/stages.h"

namespace arthrosim::pipelines {

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
  /// Pass --allow-partial to the runs of stages that take it
  /// (StageDescriptor::takes_allow_partial: surface, biphasic, post): they go on with an
  /// incomplete input and say so at the top of their output. The flag is part
  /// of those runs' command lines, hence of their stage keys.
  bool allow_partial = false;
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

/// The runs run_scene executes: plan_stages in the absolute output folder,
/// with the runner's own arguments added (--allow-partial).
std::vector<StageStep> runner_plan(const common::Scene& scene, const RunnerOptions& options);

/// The stamp of a run in an output folder: DIR/.stamps/<run>.txt (its format
/// is the runner's own; read it through these functions).
std::filesystem::path stamp_path(const std::filesystem::path& out_dir, const std::string& run);
/// The hash of the executable that wrote a run's stamp ("" without a stamp).
std::string stamp_executable_hash(const std::filesystem::path& out_dir, const std::string& run);

/// The executables folder of the running program: $ARTHROSIM_STAGE_DIR when
/// set, else the folder of /proc/self/exe.
std::filesystem::path default_stage_dir();

}  // namespace arthrosim::pipelines
