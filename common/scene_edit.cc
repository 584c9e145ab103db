#include "common/scene_edit.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <fstream>
#include <sstream>

#include "common/edit_distance.h"
#include "common/error.h"

namespace arthrosim::common {
namespace fs = std::filesystem;

namespace {

bool scalar_type(OptionType t) {
  return t == OptionType::kNumber || t == OptionType::kInteger || t == OptionType::kFlag ||
         t == OptionType::kText || t == OptionType::kPath;
}

std::vector<std::string> split_dots(const std::string& s) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  while (true) {
    const std::size_t dot = s.find('.', start);
    parts.push_back(s.substr(start, dot == std::string::npos ? std::string::npos : dot - start));
    if (dot == std::string::npos) break;
    start = dot + 1;
  }
  return parts;
}

fs::path repository_of(const fs::path& dir) {
  std::error_code ec;
  for (fs::path p = dir; !p.empty(); p = p.parent_path()) {
    if (fs::exists(p / ".git", ec)) return p;
    if (p == p.parent_path()) break;
  }
  return {};
}

// Same order as the scene reader: the scene's folder, then its repository.
// A path found nowhere is returned against the scene's folder, so the reader
// of the edited copy reports it as missing.
std::string absolute_path(const std::string& written, const fs::path& scene_dir) {
  const fs::path p(written);
  if (p.is_absolute()) return p.lexically_normal().string();
  std::error_code ec;
  if (fs::exists(scene_dir / p, ec)) return fs::weakly_canonical(scene_dir / p, ec).string();
  const fs::path repo = repository_of(scene_dir);
  if (!repo.empty() && fs::exists(repo / p, ec)) return fs::weakly_canonical(repo / p, ec).string();
  return (scene_dir / p).lexically_normal().string();
}

// The child map `key` of `parent`, created when missing.
YAML::Node child_map(YAML::Node parent, const std::string& key) {
  const YAML::Node& cparent = parent;
  if (!cparent[key]) parent[key] = YAML::Node(YAML::NodeType::Map);
  return parent[key];
}

}  // namespace

std::vector<SceneKey> settable_scene_keys(const Scene& scene) {
  std::vector<SceneKey> keys;
  const SceneSchema& schema = *scene.schema;
  auto add = [&](const std::vector<OptionSpec>& specs, const std::string& prefix, bool overridable_only) {
    for (const OptionSpec& s : specs) {
      if (!scalar_type(s.type)) continue;
      if (overridable_only && !s.overridable) continue;
      keys.push_back({prefix + s.key, &s});
    }
  };
  add(schema.top, "", false);
  for (const BlockSchema& b : schema.blocks) {
    // A block that is not written can take a setting only when it needs
    // nothing else (no required key, no instances).
    bool self_sufficient = b.instances_key.empty();
    for (const OptionSpec& s : b.keys) self_sufficient = self_sufficient && !s.required;
    if (!scene.has_block(b.name) && !self_sufficient) continue;
    add(b.keys, b.name + ".", false);
    for (const BlockInstance& inst : scene.instances(b.name)) {
      const std::string prefix = b.name + "." + b.instances_key + "." + inst.name + ".";
      add(b.instance_keys, prefix, false);
      add(b.keys, prefix, true);
    }
  }
  return keys;
}

const OptionSpec& find_settable_key(const Scene& scene, const std::string& dotted) {
  const std::vector<SceneKey> keys = settable_scene_keys(scene);
  for (const SceneKey& k : keys) {
    if (k.dotted == dotted) return *k.spec;
  }
  std::vector<std::string> names;
  std::string all;
  for (const SceneKey& k : keys) {
    names.push_back(k.dotted);
    all += (all.empty() ? "" : ", ") + k.dotted;
  }
  // Close enough for e.g. a missing unit suffix "_mpa".
  const std::string best = closest_match(dotted, names, 5);
  std::string why;
  const std::vector<std::string> parts = split_dots(dotted);
  const BlockSchema* block = parts.empty() ? nullptr : scene.schema->block(parts[0]);
  if (block && !block->instances_key.empty() && parts.size() == 4 && parts[1] == block->instances_key &&
      scene.instance(block->name, parts[2]) == nullptr) {
    std::string have;
    for (const BlockInstance& i : scene.instances(block->name)) have += (have.empty() ? "" : ", ") + i.name;
    why = " (the scene has no " + block->instance_label + " '" + parts[2] + "'; its " + block->instance_label +
          "s: " + (have.empty() ? "none" : have) + ")";
  } else if (block && parts.size() == 2 && !scene.has_block(block->name) &&
             std::none_of(keys.begin(), keys.end(),
                          [&](const SceneKey& k) { return k.dotted.rfind(block->name + ".", 0) == 0; })) {
    why = " (the scene has no " + block->name + " block)";
  } else {
    for (const OptionSpec* s : scene.schema->all()) {
      if (!parts.empty() && s->key == parts.back() && !scalar_type(s->type)) {
        why = " ('" + parts.back() + "' is a list or block; only single values can be varied)";
      }
    }
  }
  throw InputError(scene.file.string(), 0,
                   "unknown scene key '" + dotted + "'" + why + (best.empty() ? "" : " (did you mean '" + best + "'?)") +
                       "; this scene's keys: " + all);
}

std::string edit_scene_text(const fs::path& file, const SceneSchema& schema,
                            const std::vector<std::pair<std::string, std::string>>& settings) {
  const Scene scene = load_scene(file, schema);  // the original must be valid
  const fs::path dir = scene.file.parent_path();
  YAML::Node root = YAML::LoadFile(scene.file.string());

  // Paths as the reader resolved them, so the copy names the same files.
  for (const auto& [k, v] : scene.top.values())
    if (v.given && v.spec->type == OptionType::kPath) root[k] = v.path.string();
  for (const BlockSchema& b : schema.blocks) {
    if (!scene.has_block(b.name)) continue;
    for (const auto& [k, v] : scene.block(b.name).values())
      if (v.given && v.spec->type == OptionType::kPath) root[b.name][k] = v.path.string();
    const YAML::Node& croot = root;
    for (const BlockInstance& inst : scene.instances(b.name))
      for (const auto& [k, v] : inst.options.values())
        if (v.given && v.spec->type == OptionType::kPath && croot[b.name][b.instances_key][inst.name][k])
          root[b.name][b.instances_key][inst.name][k] = v.path.string();
  }

  std::string header = "# written by arthrosim from " + scene.file.string() + "\n";
  for (const auto& [key, value] : settings) {
    const OptionSpec& spec = find_settable_key(scene, key);
    const std::string v = spec.type == OptionType::kPath ? absolute_path(value, dir) : value;
    header += "#   " + key + " = " + value + "\n";
    if (spec.block == "scene") {  // a top-level key, whose name may hold a dot (trial.start_s)
      root[key] = v;
      continue;
    }
    const std::vector<std::string> parts = split_dots(key);
    // Node::operator= assigns contents; reset() rebinds the handle.
    YAML::Node node;
    node.reset(root);
    for (std::size_t i = 0; i + 1 < parts.size(); ++i) node.reset(child_map(node, parts[i]));
    node[parts.back()] = v;
  }
  YAML::Emitter out;
  out << root;
  if (!out.good()) {
    throw InputError(scene.file.string(), 0,
                     "cannot write the edited scene: " + out.GetLastError());
  }
  return header + out.c_str() + "\n";
}

}  // namespace arthrosim::common
