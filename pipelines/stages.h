#pragma once
// The stage table: the one list of arthrosim's stages (docs/architecture.md,
// "How to add a stage"). The scene schema (`arthrosim schema`, docs/scenes.md),
// the runner's plan, the study and the effect vocabulary are built from it;
// nothing else lists the stages.
//
// A stage contributes one StageDescriptor, made by a function in the stage's
// own source file (e.g. surface_stage_descriptor() in surface_stage.cc), and
// one line in stages.cc's table.
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "common/options.h"
#include "common/scene.h"

namespace arthrosim::pipelines {

/// One run of a stage (a stage with instances, like surface, has one run per
/// scenario): what to execute, every file it reads and writes, and where it
/// comes from in the scene.
struct StageStep {
  std::string name;        ///< "prepare", "comak", "surface.osmotic", "post"
  std::string executable;  ///< file name, e.g. "arthrosim-prepare"
  std::vector<std::string> arguments;  ///< after the program name
  /// (label, path) of every file or folder whose contents the output depends
  /// on; labels ("model", "prepared.h5") are what messages and stamps show.
  std::vector<std::pair<std::string, std::filesystem::path>> inputs;
  /// Why an input is read, by label, for messages ("uses imposed_kinematics").
  std::map<std::string, std::string> input_reasons;
  /// An input read only when a run of the same plan writes it (post reads
  /// kinematics.h5 when COMAK runs), with the arguments that hand it over.
  struct OptionalInput {
    std::string label;
    std::filesystem::path path;
    std::vector<std::string> arguments;
  };
  std::vector<OptionalInput> optional_inputs;
  std::vector<std::filesystem::path> outputs;  ///< files the run must write
  /// ("block.key", canonical value), sorted: the options the run reads.
  std::vector<std::pair<std::string, std::string>> options;
  /// For runs that build physics terms: the effects the scene asks for.
  /// After the run exits 0 the runner reads the effect ledger (/effects,
  /// common/effects.h) from outputs[0] and fails the run if the ledger is
  /// missing or holds a term not in this list.
  std::optional<std::vector<std::string>> effects;
  /// Scene outputs (top-level `outputs` words) this run produces.
  std::vector<std::string> provides;
  /// Where the run is defined in the scene, for messages: e.g. "scenario
  /// 'gait'" with its line and column (0: the scene as a whole).
  std::string origin;
  int line = 0, column = 0;
  /// Non-empty: what the scene lacks for this run, e.g. "the musculoskeletal
  /// stage: add a 'comak' block with its effects"; planning it is an error.
  std::string unavailable;
  std::string needed_for;  ///< set by plan_stages, e.g. "output report", "prepared.h5 for comak"
};

/// One key output of a stage run, compared with a reference run
/// (`arthrosim study accuracy`, pipelines/study.h).
struct OutputMetric {
  std::string name;         ///< e.g. "contact_force", "max_deflection[femur]"
  std::string description;  ///< how the error is defined
  double error = std::numeric_limits<double>::quiet_NaN();   ///< against the reference (NaN: not available)
  double output = std::numeric_limits<double>::quiet_NaN();  ///< the output itself at this setting
  std::string output_unit;  ///< "N", "mm", "deg"
  std::string note;         ///< why it is not available, or how it was compared
};

struct StageDescriptor {
  std::string name;        ///< its scene block and its name in plans, e.g. "prepare"
  std::string executable;  ///< program in build/bin, e.g. "arthrosim-prepare"
  std::string summary;     ///< one line for --help and docs
  /// Its scene block; the keys come from its options struct's declare()
  /// (block_schema<T>()).
  common::BlockSchema block;
  /// The scene outputs it produces (words of the top-level `outputs` key).
  std::vector<std::string> outputs;
  /// The effects a scene may list for it (its `effects` keys take these).
  std::vector<common::EffectName> effects;
  /// Cross-key checks of a whole scene that concern this stage (its
  /// from_scene for every run, e.g. a scenario without imposed_kinematics
  /// needs end_time_s); throws common::InputError with the scene's file and
  /// line. May be empty.
  std::function<void(const common::Scene&)> check;
  /// The runs the scene defines for this stage, writing into `out_dir`
  /// (whether they are needed is decided by plan_stages).
  std::function<std::vector<StageStep>(const common::Scene&, const std::filesystem::path& out_dir)> runs;
  /// What the scene lacks when runs() gives no run, for messages (e.g. "a
  /// 'surface' block with at least one scenario").
  std::string no_runs;
  /// Its program takes --allow-partial (goes on with an incomplete input
  /// from another stage, saying so at the top of its output); `arthrosim run
  /// --allow-partial` passes the flag to the runs of such stages.
  bool takes_allow_partial = false;
  /// The key outputs of run `run` (a name from runs()) for accuracy studies:
  /// its outputs in `dir` against the reference run's in `ref_dir`. Empty for
  /// a stage without a key output of its own (prepare: its resolution shows
  /// in the later stages' errors).
  std::function<std::vector<OutputMetric>(const std::string& run, const std::filesystem::path& dir,
                                          const std::filesystem::path& ref_dir)>
      key_outputs;
};

/// The stages in execution order.
const std::vector<StageDescriptor>& stages();
/// The stage called `name`, or nullptr.
const StageDescriptor* find_stage(std::string_view name);
/// The stage of a run called `run` ("surface.gait" -> surface), or nullptr.
const StageDescriptor* stage_of_run(std::string_view run);

/// The runs `scene` needs, in execution order, writing into `out_dir`: every
/// run that provides a requested output, and every run that writes a file a
/// needed run reads. Throws common::InputError (at the scene line of what
/// needs it) when a needed run is unavailable or no stage can provide a
/// requested output.
std::vector<StageStep> plan_stages(const common::Scene& scene, const std::filesystem::path& out_dir);

/// Every kPath option of a block is an input of the run that reads it
/// (label "<block>.<key>").
void add_path_inputs(const common::OptionBlock& block, StageStep& step);

/// Files a run reads because an input names them (the .mot files of a
/// trial.yaml, a meshes.yaml manifest's meshes): each (label, file) that no
/// input of `step` already covers (the same file, or a folder holding it) is
/// added as an input, so editing it reruns the step. Empty paths are ignored.
void add_referenced_inputs(StageStep& step,
                           const std::vector<std::pair<std::string, std::filesystem::path>>& files);

/// The scene's top-level keys.
struct SceneInputs {
  std::string description;
  std::filesystem::path model;  ///< resolved, absolute
  std::filesystem::path trial;  ///< resolved, absolute; empty = none
  /// The trial's window that the musculoskeletal stage solves (SI seconds);
  /// absent: the trial's first / last time.
  std::optional<double> trial_start_s, trial_end_s;
  std::vector<std::string> outputs;
  void declare(common::OptionVisitor& v);
};
SceneInputs scene_inputs(const common::Scene& scene);

/// The schema of arthrosim's scenes, assembled from the stage table.
const common::SceneSchema& scene_schema();
/// common::load_scene / parse_scene with scene_schema(), then every stage's
/// check.
common::Scene load_scene(const std::filesystem::path& file);
common::Scene parse_scene(const std::string& text, const std::filesystem::path& file);

/// The reference section of docs/scenes.md and `arthrosim schema`: one table
/// per block (keys, types, units, defaults, ranges) and the effects table,
/// all generated from the declarations (a test fails when the doc is stale).
std::string schema_reference();
/// Markers around schema_reference() in docs/scenes.md.
inline constexpr std::string_view kReferenceBegin =
    "<!-- BEGIN generated by `arthrosim schema --write-docs docs/scenes.md`; do not edit -->";
inline constexpr std::string_view kReferenceEnd = "<!-- END generated -->";
/// Replaces the text between the markers in `doc` (InputError naming the
/// file when they are missing).
std::string with_schema_reference(const std::string& doc, const std::string& file);

/// True when the scene's `outputs` lists `output`.
bool wants_output(const common::Scene& scene, std::string_view output);

/// A block whose keys an options struct T declares (T::declare).
template <class T>
common::BlockSchema block_schema(const std::string& name, const std::string& doc) {
  common::BlockSchema b;
  b.name = name;
  b.doc = doc;
  b.keys = common::declared_keys<T>(name);
  return b;
}

/// A block with named instances: the keys every instance shares with the
/// block (Shared::declare) and those only an instance takes
/// (Instance::declare_instance).
template <class T>
common::BlockSchema block_schema_with_instances(const std::string& name, const std::string& doc,
                                                const std::string& instances_key, const std::string& instances_doc,
                                                const std::string& instance_label) {
  common::BlockSchema b;
  b.name = name;
  b.doc = doc;
  T shared{}, own{};
  b.keys = common::collect_keys(name, [&](common::OptionVisitor& v) { shared.declare_shared(v); });
  for (common::OptionSpec& s : b.keys) s.overridable = true;
  b.instances_key = instances_key;
  b.instances_doc = instances_doc;
  b.instance_label = instance_label;
  b.instance_keys = common::collect_keys(instance_label, [&](common::OptionVisitor& v) { own.declare_instance(v); });
  return b;
}

}  // namespace arthrosim::pipelines
