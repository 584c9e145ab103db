#include "pipelines/stages.h"

#include <algorithm>

#include "common/error.h"
#include "pipelines/biphasic_stage.h"
#include "pipelines/comak_stage.h"
#include "pipelines/post_stage.h"
#include "pipelines/prepare.h"
#include "pipelines/surface_stage.h"

namespace arthrosim::pipelines {

const std::vector<StageDescriptor>& stages() {
  // The stage table, in execution order: one line per stage.
  static const std::vector<StageDescriptor> kStages = {
      prepare_stage_descriptor(),
      comak_stage_descriptor(),
      surface_stage_descriptor(),
      biphasic_stage_descriptor(),
      post_stage_descriptor(),
  };
  return kStages;
}

const StageDescriptor* find_stage(std::string_view name) {
  for (const StageDescriptor& s : stages())
    if (s.name == name) return &s;
  return nullptr;
}

namespace {

std::string output_choices() {
  std::string s;
  for (const StageDescriptor& d : stages())
    for (const std::string& o : d.outputs) s += (s.empty() ? "" : "|") + o;
  return s;
}

std::string output_list() {
  std::string s;
  for (const StageDescriptor& d : stages())
    for (const std::string& o : d.outputs) s += (s.empty() ? "" : ", ") + o;
  return s;
}

// What the outputs need must be in the scene: the blocks and inputs of the
// stages that produce them.
void check_needs(const common::Scene& scene) {
  const common::OptionValue& outputs = scene.top.value("outputs");
  const bool wants_surface = wants_output(scene, "surface") || wants_output(scene, "report");
  const std::vector<common::BlockInstance>& scenarios = scene.instances("surface");
  if (wants_surface && scenarios.empty()) {
    throw common::InputError(scene.file.string(), outputs.value_line, outputs.value_column,
                             "output '" + std::string(wants_output(scene, "surface") ? "surface" : "report") +
                                 "' needs a 'surface' block with at least one scenario");
  }
  const common::BlockInstance* moving = nullptr;
  if (wants_surface) {
    for (const common::BlockInstance& s : scenarios)
      if (s.wants("imposed_kinematics") && moving == nullptr) moving = &s;
  }
  if (!wants_output(scene, "kinematics") && moving == nullptr) return;
  const std::string why =
      moving ? "scenario '" + moving->name + "' uses imposed_kinematics" : "output 'kinematics' is requested";
  const int line = moving ? moving->line : outputs.value_line, column = moving ? 1 : outputs.value_column;
  if (!scene.has_block("comak")) {
    throw common::InputError(scene.file.string(), line, column,
                             why + ", which needs the musculoskeletal stage: add a 'comak' block with its effects");
  }
  if (!scene.top.has("trial")) {
    throw common::InputError(scene.file.string(), line, column,
                             why + ", which needs a walking trial: add 'trial: PATH'");
  }
}

}  // namespace

void SceneInputs::declare(common::OptionVisitor& v) {
  v.text("description", description, "", "free text shown when the scene runs");
  v.path("model", model, "the knee model: a folder of bone and cartilage surface meshes, or a URDF file").required();
  v.path("trial", trial, "walking trial (folder or file) for the musculoskeletal stage; needed when that stage runs");
  v.number("trial.start_s", trial_start_s, common::Unit::kSecond, {-1e6, 1e6},
           "first time of the trial that the musculoskeletal stage solves (the whole trial is still filtered and "
           "differentiated); absent: the trial's first time");
  v.number("trial.end_s", trial_end_s, common::Unit::kSecond, {-1e6, 1e6},
           "last time of the trial that the musculoskeletal stage solves; absent: the trial's last time");
  static const std::string choices = output_choices();
  static const std::string doc = "what to produce: " + output_list() +
                                 " (surface: every scenario); the stages these need run, nothing else";
  v.text_list("outputs", outputs, choices, doc).required();
}

SceneInputs scene_inputs(const common::Scene& scene) { return common::read_options<SceneInputs>(scene.top); }

const common::SceneSchema& scene_schema() {
  static const common::SceneSchema kSchema = [] {
    common::SceneSchema s;
    s.top = common::declared_keys<SceneInputs>("scene");
    for (const StageDescriptor& d : stages()) {
      s.blocks.push_back(d.block);
      s.effects.insert(s.effects.end(), d.effects.begin(), d.effects.end());
    }
    return s;
  }();
  return kSchema;
}

common::Scene parse_scene(const std::string& text, const std::filesystem::path& file) {
  common::Scene scene = common::parse_scene(text, file, scene_schema());
  for (const StageDescriptor& d : stages())
    if (d.check) d.check(scene);
  check_needs(scene);
  return scene;
}

common::Scene load_scene(const std::filesystem::path& file) {
  common::Scene scene = common::load_scene(file, scene_schema());
  for (const StageDescriptor& d : stages())
    if (d.check) d.check(scene);
  check_needs(scene);
  return scene;
}

std::string schema_reference() {
  const common::SceneSchema& schema = scene_schema();
  std::string s = schema.markdown();
  s += "\n### effects\n\n| effect | stage | meaning |\n|---|---|---|\n";
  for (const common::EffectName& e : schema.effects)
    s += "| `" + e.name + "` | " + e.stage + " | " + e.description + " |\n";
  return s;
}

std::string with_schema_reference(const std::string& doc, const std::string& file) {
  const std::size_t begin = doc.find(kReferenceBegin);
  const std::size_t end = doc.find(kReferenceEnd);
  if (begin == std::string::npos || end == std::string::npos || end < begin)
    throw common::InputError(file, 0,
                             "expected the generated-reference markers '" + std::string(kReferenceBegin) + "' and '" +
                                 std::string(kReferenceEnd) + "'");
  const std::size_t from = begin + kReferenceBegin.size();
  return doc.substr(0, from) + "\n" + schema_reference() + "\n" + doc.substr(end);
}

bool wants_output(const common::Scene& scene, std::string_view output) {
  if (!scene.top.has("outputs")) return false;
  const std::vector<std::string>& o = scene.top.list("outputs");
  return std::find(o.begin(), o.end(), output) != o.end();
}

}  // namespace arthrosim::pipelines
