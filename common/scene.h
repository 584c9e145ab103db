#pragma once
// Scenes: what a researcher asks arthrosim to simulate (docs/scenes.md). This
// is the generic reader; it knows no stage.
//
// A scene is a YAML file of top-level keys and blocks. Which keys and blocks
// exist is a SceneSchema that the caller assembles from the options structs
// that declare them (common/options.h); arthrosim's is pipelines::scene_schema(),
// built from the stage table (pipelines/stages.h). The reader checks every key
// against the schema -- type, unit, range, choices, required keys, keys given
// twice, effect names -- converts units to SI, fills in defaults, resolves
// paths, and reports any problem as an InputError
// "scene.yaml:LINE:COLUMN: error: ..." with a "did you mean" hint for near
// misses (a typo must never silently disable physics). yaml-cpp stays inside
// scene.cc.
//
// Units: a key whose value is not in SI carries its unit as a suffix
// (edge_length_mm, osmotic_pressure_mpa). OptionBlock::si(key) returns the
// value converted to SI (m, rad, s, Pa, N/m^3, ...); as_written(key) returns
// it as written in the file (the unit of the suffix).
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "common/options.h"

namespace arthrosim::common {

/// One block of a scene (prepare:, comak:, surface:, post:, ...).
struct BlockSchema {
  std::string name;  ///< as written in a scene, e.g. "prepare"
  std::string doc;   ///< one line, e.g. "options of the prepare stage"
  std::vector<OptionSpec> keys;  ///< the block's own keys (spec.block == name)
  /// Named instances of the block, e.g. surface.scenarios.<name>: the key
  /// that holds them ("" = none; it is then a required key of the block), its
  /// doc, the label of one instance in messages and docs ("scenario") and the
  /// keys only an instance takes (spec.block == instance_label). An instance
  /// also takes every key of the block (marked overridable), and its own value
  /// wins. Instance names are [a-z0-9_]+ (they appear in file names).
  std::string instances_key;
  std::string instances_doc;
  std::string instance_label;
  std::vector<OptionSpec> instance_keys;
};

/// An effect name a kEffectList key may hold.
struct EffectName {
  std::string name;
  std::string stage;  ///< the OptionSpec::effect_stage of the lists that take it
  std::string description;
};

struct SceneSchema {
  std::vector<OptionSpec> top;     ///< top-level keys (spec.block == "scene")
  std::vector<BlockSchema> blocks;  ///< in documentation order
  std::vector<EffectName> effects;  ///< the effect vocabulary

  const BlockSchema* block(std::string_view name) const;
  /// The spec of `key` in `block` ("scene", a block or an instance label), or
  /// nullptr. An instance label also finds its block's keys.
  const OptionSpec* find(std::string_view block, std::string_view key) const;
  /// Every spec, in documentation order (top, then each block followed by its
  /// instance keys).
  std::vector<const OptionSpec*> all() const;
  /// Markdown tables, one per block (docs/scenes.md's reference, `arthrosim schema`).
  std::string markdown() const;
};

/// One named instance of a block (a surface scenario).
struct BlockInstance {
  std::string name;  ///< [a-z0-9_]+
  int line = 0;      ///< where its name is written in the scene
  int column = 0;
  /// Effects listed by its "effects" key (if the schema has one), in order.
  std::vector<std::string> effects;
  /// The block's options with this instance's values applied; its name is
  /// "<block>.<instance>", e.g. "surface.osmotic".
  OptionBlock options;
  bool wants(std::string_view effect) const;
};

struct Scene {
  std::filesystem::path file;  ///< absolute path of the scene file
  const SceneSchema* schema = nullptr;  ///< must outlive the scene
  OptionBlock top;  ///< the top-level keys, defaults filled in

  /// True when the block is written in the scene.
  bool has_block(std::string_view name) const;
  /// Line where the block starts (0 when it is not written).
  int block_line(std::string_view name) const;
  /// The block's options (defaults filled in; a block that is not written
  /// has only its defaults). std::logic_error for a name not in the schema.
  const OptionBlock& block(std::string_view name) const;
  /// Instances of a block in the order written (empty when none).
  const std::vector<BlockInstance>& instances(std::string_view block) const;
  const BlockInstance* instance(std::string_view block, std::string_view name) const;
  /// The instance called `name`; InputError naming the scene file and the
  /// instances it has when there is none.
  const BlockInstance& require_instance(std::string_view block, std::string_view name) const;

  std::map<std::string, OptionBlock, std::less<>> blocks;
  std::map<std::string, int, std::less<>> block_lines;
  std::map<std::string, std::vector<BlockInstance>, std::less<>> block_instances;
};

/// Reads and validates a scene file. Relative paths inside are resolved
/// against the scene file's folder first, then against the repository that
/// contains it (nearest ancestor folder holding a .git entry). Throws
/// InputError with file:line:column on any problem.
Scene load_scene(const std::filesystem::path& file, const SceneSchema& schema);

/// Same from text already in memory; `file` is used for messages and for
/// resolving relative paths (it need not exist).
Scene parse_scene(const std::string& text, const std::filesystem::path& file, const SceneSchema& schema);

/// The folder of the repository holding `dir` (nearest ancestor with a .git
/// entry), or "" when none.
std::filesystem::path repository_of(const std::filesystem::path& dir);

}  // namespace arthrosim::common
