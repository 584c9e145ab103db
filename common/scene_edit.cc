#include "common/scene_edit.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <fstream>
#include <sstream>

#include "common/error.h"

namespace arthrosim::common {
namespace fs = std::filesystem;

namespace {

bool scalar_type(OptionType t) {
  return t == OptionType::kNumber || t == OptionType::kInteger || t == OptionType::kFlag ||
         t == OptionType::kText || t == OptionType::kPath;
}

// Levenshtein distance for the "did you mean" hint.
std::size_t distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] != b[j - 1])});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
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
  auto add_block = [&](std::string_view block, const std::string& prefix, bool overridable_only) {
    for (const OptionSpec& s : option_schema()) {
      if (s.block != block || !scalar_type(s.type)) continue;
      if (overridable_only && !s.overridable) continue;
      keys.push_back({prefix + std::string(s.key), &s});
    }
  };
  add_block("scene", "", false);
  add_block("prepare", "prepare.", false);
  if (scene.comak) add_block("comak", "comak.", false);
  if (scene.surface) {
    add_block("surface", "surface.", false);
    for (const Scenario& sc : scene.scenarios) {
      const std::string prefix = "surface.scenarios." + sc.name + ".";
      add_block("scenario", prefix, false);
      add_block("surface", prefix, true);
    }
  }
  add_block("post", "post.", false);
  return keys;
}

const OptionSpec& find_settable_key(const Scene& scene, const std::string& dotted) {
  const std::vector<SceneKey> keys = settable_scene_keys(scene);
  for (const SceneKey& k : keys) {
    if (k.dotted == dotted) return *k.spec;
  }
  std::string best;
  std::size_t best_d = 5;  // close enough for e.g. a missing unit suffix "_mpa"
  std::string all;
  for (const SceneKey& k : keys) {
    const std::size_t d = distance(dotted, k.dotted);
    if (d < best_d) best_d = d, best = k.dotted;
    all += (all.empty() ? "" : ", ") + k.dotted;
  }
  std::string why;
  const std::vector<std::string> parts = split_dots(dotted);
  if (parts.size() == 4 && parts[0] == "surface" && parts[1] == "scenarios" &&
      scene.scenario(parts[2]) == nullptr) {
    std::string names;
    for (const Scenario& sc : scene.scenarios) names += (names.empty() ? "" : ", ") + sc.name;
    why = " (the scene has no scenario '" + parts[2] + "'; its scenarios: " +
          (names.empty() ? "none" : names) + ")";
  } else if (parts.size() == 2 && parts[0] == "comak" && !scene.comak) {
    why = " (the scene has no comak block)";
  } else {
    for (const OptionSpec& s : option_schema()) {
      if (!parts.empty() && s.key == parts.back() && !scalar_type(s.type)) {
        why = " ('" + parts.back() + "' is a list or block; only single values can be varied)";
      }
    }
  }
  throw InputError(scene.file.string(), 0,
                   "unknown scene key '" + dotted + "'" + why +
                       (best.empty() ? "" : " (did you mean '" + best + "'?)") +
                       "; this scene's keys: " + all);
}

std::string edit_scene_text(const fs::path& file,
                            const std::vector<std::pair<std::string, std::string>>& settings) {
  const Scene scene = load_scene(file);  // the original must be valid
  const fs::path dir = scene.file.parent_path();
  YAML::Node root = YAML::LoadFile(scene.file.string());

  // Paths as the reader resolved them, so the copy names the same files.
  root["model"] = scene.model.string();
  if (scene.trial) root["trial"] = scene.trial->string();
  const YAML::Node& croot = root;
  if (croot["post"] && croot["post"]["splitline_map"]) {
    root["post"]["splitline_map"] = scene.post.path("splitline_map").string();
  }
  for (const Scenario& sc : scene.scenarios) {
    if (sc.options.given("mesh")) {
      root["surface"]["scenarios"][sc.name]["mesh"] = sc.options.path("mesh").string();
    }
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
