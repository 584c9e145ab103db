#include "pipelines/stages.h"

#include <algorithm>

#include "common/error.h"
#include "pipelines/biphasic_stage.h"
#include "pipelines/comak_stage.h"
#include "pipelines/post_stage.h"
#include "pipelines/prepare.h"
#include "pipelines/shockwave_stage.h"
#include "pipelines/surface_stage.h"

namespace arthrosim::pipelines {

const std::vector<StageDescriptor>& stages() {
  // The stage table, in execution order: one line per stage.
  static const std::vector<StageDescriptor> kStages = {
      prepare_stage_descriptor(),
      comak_stage_descriptor(),
      surface_stage_descriptor(),
      biphasic_stage_descriptor(),
      shockwave_stage_descriptor(),
      post_stage_descriptor(),
  };
  return kStages;
}

const StageDescriptor* find_stage(std::string_view name) {
  for (const StageDescriptor& s : stages())
    if (s.name == name) return &s;
  return nullptr;
}

const StageDescriptor* stage_of_run(std::string_view run) {
  for (const StageDescriptor& s : stages())
    if (run == s.name || (run.size() > s.name.size() && run.substr(0, s.name.size()) == s.name &&
                          run[s.name.size()] == '.'))
      return &s;
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

void add_path_inputs(const common::OptionBlock& block, StageStep& step) {
  for (const auto& [key, v] : block.values()) {
    if (v.spec->type == common::OptionType::kPath) step.inputs.emplace_back(block.name() + "." + key, v.path);
  }
}

void add_referenced_inputs(StageStep& step,
                           const std::vector<std::pair<std::string, std::filesystem::path>>& files) {
  namespace fs = std::filesystem;
  for (const auto& [label, file] : files) {
    if (file.empty()) continue;
    const fs::path f = fs::weakly_canonical(file);
    bool covered = false;
    for (const auto& [l, p] : step.inputs) {
      const fs::path c = fs::weakly_canonical(p);
      const auto [end, rest] = std::mismatch(c.begin(), c.end(), f.begin(), f.end());
      covered = covered || end == c.end();  // c is f or a folder above it
    }
    if (!covered) step.inputs.emplace_back(label, file);
  }
}

std::vector<StageStep> plan_stages(const common::Scene& scene, const std::filesystem::path& out_dir) {
  namespace fs = std::filesystem;
  std::vector<StageStep> runs;
  for (const StageDescriptor& d : stages()) {
    if (!d.runs) continue;
    for (StageStep& r : d.runs(scene, out_dir)) runs.push_back(std::move(r));
  }
  const auto producer = [&](const fs::path& file) -> int {
    for (std::size_t i = 0; i < runs.size(); ++i)
      for (const fs::path& o : runs[i].outputs)
        if (o == file) return static_cast<int>(i);
    return -1;
  };
  std::vector<bool> needed(runs.size(), false);
  const common::OptionValue& outputs = scene.top.value("outputs");
  // Marks run i as needed (and, recursively, the runs writing its inputs).
  // `who`, `line`, `column`: what needs it, for the error when it cannot run.
  std::function<void(std::size_t, const std::string&, const std::string&, int, int)> need =
      [&](std::size_t i, const std::string& why, const std::string& who, int line, int column) {
        if (needed[i]) return;
        StageStep& r = runs[i];
        if (!r.unavailable.empty())
          throw common::InputError(scene.file.string(), line, column, who + ", which needs " + r.unavailable);
        needed[i] = true;
        r.needed_for = why;
        for (const auto& [label, path] : r.inputs) {
          const int p = producer(path);
          if (p < 0) continue;
          auto reason = r.input_reasons.find(label);
          const std::string what =
              (r.origin.empty() ? r.name : r.origin) + " " +
              (reason == r.input_reasons.end() ? "reads " + label : reason->second);
          need(static_cast<std::size_t>(p), label + " for " + r.name, what, r.line ? r.line : line,
               r.line ? r.column : column);
        }
      };
  for (const std::string& word : scene.top.list("outputs")) {
    bool provided = false;
    for (std::size_t i = 0; i < runs.size(); ++i) {
      if (std::find(runs[i].provides.begin(), runs[i].provides.end(), word) == runs[i].provides.end()) continue;
      provided = true;
      need(i, "output " + word, "output '" + word + "' is requested", outputs.value_line, outputs.value_column);
    }
    if (provided) continue;
    std::string lacks = "a stage that provides it";
    for (const StageDescriptor& d : stages())
      if (std::find(d.outputs.begin(), d.outputs.end(), word) != d.outputs.end() && !d.no_runs.empty())
        lacks = d.no_runs;
    throw common::InputError(scene.file.string(), outputs.value_line, outputs.value_column,
                             "output '" + word + "' is requested, which needs " + lacks);
  }
  std::vector<StageStep> plan;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    if (!needed[i]) continue;
    StageStep r = runs[i];
    // Optional inputs are read when a planned run writes them.
    for (const StageStep::OptionalInput& o : r.optional_inputs) {
      const int p = producer(o.path);
      if (p < 0 || !needed[static_cast<std::size_t>(p)]) continue;
      r.inputs.emplace_back(o.label, o.path);
      r.arguments.insert(r.arguments.end(), o.arguments.begin(), o.arguments.end());
    }
    r.optional_inputs.clear();
    plan.push_back(std::move(r));
  }
  return plan;
}

common::Scene parse_scene(const std::string& text, const std::filesystem::path& file) {
  common::Scene scene = common::parse_scene(text, file, scene_schema());
  for (const StageDescriptor& d : stages())
    if (d.check) d.check(scene);
  plan_stages(scene, "OUT");  // what the outputs need must be in the scene
  return scene;
}

common::Scene load_scene(const std::filesystem::path& file) {
  common::Scene scene = common::load_scene(file, scene_schema());
  for (const StageDescriptor& d : stages())
    if (d.check) d.check(scene);
  plan_stages(scene, "OUT");  // what the outputs need must be in the scene
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
