#include "common/scene.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "common/edit_distance.h"
#include "common/error.h"
#include "common/yaml_error.h"

namespace arthrosim::common {
namespace {

using T = OptionType;

// ---------------------------------------------------------------------------
// Small helpers
// ---------------------------------------------------------------------------
using yaml::describe;
using yaml::fail;
using yaml::where;
using yaml::Where;

std::string join(const std::vector<std::string_view>& words) {
  std::string s;
  for (std::string_view w : words) s += (s.empty() ? "" : ", ") + std::string(w);
  return s;
}

std::string join(const std::vector<std::string>& words) {
  std::string s;
  for (const std::string& w : words) s += (s.empty() ? "" : ", ") + w;
  return s;
}

std::vector<std::string_view> split_choices(std::string_view choices) {
  std::vector<std::string_view> out;
  std::string_view rest = choices;
  while (!rest.empty()) {
    const auto bar = rest.find('|');
    out.push_back(rest.substr(0, bar));
    rest = bar == std::string_view::npos ? std::string_view() : rest.substr(bar + 1);
  }
  return out;
}

bool valid_instance_name(const std::string& name) {
  if (name.empty()) return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_';
  });
}

// ---------------------------------------------------------------------------
// The parser
// ---------------------------------------------------------------------------
class Parser {
 public:
  Parser(std::string file_label, std::filesystem::path scene_dir, const SceneSchema& schema)
      : file_(std::move(file_label)), dir_(std::move(scene_dir)), schema_(schema) {}

  Where at(const YAML::Node& n) const { return where(file_, n.Mark()); }

  // Checks that `node` is a map whose keys are all in `allowed`, that no key
  // repeats and that required keys are present. Returns (key node, value
  // node) pairs in file order.
  std::vector<std::pair<YAML::Node, YAML::Node>> entries(const YAML::Node& node,
                                                         const std::vector<const OptionSpec*>& allowed,
                                                         const std::string& block_label, const std::string& note) {
    if (!node.IsMap()) {
      fail(at(node), "expected a block of keys for '" + block_label + "', found " + describe(node));
    }
    std::vector<std::pair<YAML::Node, YAML::Node>> out;
    std::map<std::string, int> seen;
    std::vector<std::string_view> names;
    for (const OptionSpec* s : allowed) names.push_back(s->key);
    const YAML::const_iterator last = node.end();
    for (YAML::const_iterator it = node.begin(); it != last; ++it) {
      const YAML::Node key = it->first;
      const YAML::Node val = it->second;
      if (!key.IsScalar()) fail(at(key), "expected a key name, found " + describe(key));
      const std::string& k = key.Scalar();
      if (find_in(allowed, k) == nullptr) {
        fail(at(key), "unknown key '" + k + "' in '" + block_label + "'" + did_you_mean(k, names) +
                          "; allowed keys: " + join(names) + note);
      }
      if (auto s = seen.find(k); s != seen.end()) {
        fail(at(key), "key '" + k + "' given twice in '" + block_label + "' (first on line " +
                          std::to_string(s->second) + ")");
      }
      seen[k] = at(key).line;
      out.emplace_back(key, val);
    }
    for (const OptionSpec* s : allowed) {
      if (s->required && !s->overridable && !seen.count(s->key)) {
        fail(at(node), "missing required key '" + s->key + "' in '" + block_label + "' (" + s->doc + ")");
      }
    }
    return out;
  }

  static const OptionSpec* find_in(const std::vector<const OptionSpec*>& specs, std::string_view key) {
    for (const OptionSpec* s : specs)
      if (s->key == key) return s;
    return nullptr;
  }

  std::string scalar(const YAML::Node& value, const OptionSpec& spec) {
    if (!value.IsScalar()) {
      fail(at(value), "'" + spec.key + "': expected " + std::string(type_word(spec.type)) + ", found " +
                          describe(value));
    }
    return value.Scalar();
  }

  double parse_number(const std::string& text, const YAML::Node& value, const OptionSpec& spec) {
    const char* begin = text.c_str();
    char* end = nullptr;
    const double v = std::strtod(begin, &end);
    if (text.empty() || end != begin + text.size() || text.find_first_of("xXpP") != std::string::npos) {
      fail(at(value), "'" + spec.key + "': expected a number, found '" + text + "'");
    }
    if (!std::isfinite(v)) {
      fail(at(value), "'" + spec.key + "': expected a finite number, found '" + text + "'");
    }
    return v;
  }

  void check_range(double v, const std::string& text, const YAML::Node& value, const OptionSpec& spec) {
    if (v < spec.min || v > spec.max) {
      const std::string_view suffix = unit_suffix(spec.unit);
      fail(at(value), "'" + spec.key + "': expected a value in [" + shortest_text(spec.min) + ", " +
                          shortest_text(spec.max) + "]" + (suffix.empty() ? "" : " " + std::string(suffix.substr(1))) +
                          ", found " + text);
    }
  }

  std::vector<std::string> word_list(const YAML::Node& value, const OptionSpec& spec) {
    if (!value.IsSequence()) {
      fail(at(value), "'" + spec.key + "': expected a list like [a, b], found " + describe(value));
    }
    std::vector<std::string> out;
    for (const YAML::Node& item : value) {
      if (!item.IsScalar()) {
        fail(at(item), "'" + spec.key + "': expected a word in the list, found " + describe(item));
      }
      if (std::find(out.begin(), out.end(), item.Scalar()) != out.end()) {
        fail(at(item), "'" + spec.key + "': '" + item.Scalar() + "' listed twice");
      }
      out.push_back(item.Scalar());
    }
    return out;
  }

  std::filesystem::path resolve(const std::string& written, const YAML::Node& value, const OptionSpec& spec) {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::path p(written);
    std::vector<fs::path> tried;
    if (p.is_absolute()) {
      tried.push_back(p);
    } else {
      tried.push_back(dir_ / p);
      const fs::path repo = repository_of(dir_);
      if (!repo.empty()) tried.push_back(repo / p);
    }
    for (const fs::path& c : tried) {
      if (fs::exists(c, ec)) return fs::weakly_canonical(c, ec).lexically_normal();
    }
    std::string where_list;
    for (const fs::path& c : tried) where_list += (where_list.empty() ? "" : ", ") + c.lexically_normal().string();
    fail(at(value), "'" + spec.key + "': expected an existing file or folder, found '" + written + "' (looked for " +
                        where_list + ")");
  }

  // Parses one value against its spec (not for kBlock / kInstances).
  OptionValue value(const YAML::Node& key, const YAML::Node& value, const OptionSpec& spec) {
    OptionValue v;
    v.spec = &spec;
    v.given = true;
    const Where w = at(key);
    v.line = w.line;
    v.column = w.column;
    const Where wv = at(value);
    v.value_line = wv.line;
    v.value_column = wv.column;
    fill(v, value, spec);
    return v;
  }

  void fill(OptionValue& v, const YAML::Node& value, const OptionSpec& spec) {
    const std::string& key = spec.key;
    switch (spec.type) {
      case T::kNumber: {
        const std::string text = scalar(value, spec);
        const double x = parse_number(text, value, spec);
        check_range(x, text, value, spec);
        v.number_as_written = x;
        v.number_si = x * unit_to_si(spec.unit);
        v.canonical = shortest_text(x);
        break;
      }
      case T::kInteger: {
        const std::string text = scalar(value, spec);
        const char* begin = text.c_str();
        char* end = nullptr;
        errno = 0;
        const long long x = std::strtoll(begin, &end, 10);
        if (text.empty() || end != begin + text.size() || errno == ERANGE) {
          fail(at(value), "'" + key + "': expected a whole number, found '" + text + "'");
        }
        check_range(double(x), text, value, spec);
        v.integer = x;
        v.canonical = std::to_string(x);
        break;
      }
      case T::kFlag: {
        const std::string text = scalar(value, spec);
        if (text == "true" || text == "yes" || text == "on") {
          v.flag = true;
        } else if (text == "false" || text == "no" || text == "off") {
          v.flag = false;
        } else {
          fail(at(value), "'" + key + "': expected true or false, found '" + text + "'");
        }
        v.canonical = v.flag ? "true" : "false";
        break;
      }
      case T::kText: {
        const std::string text = scalar(value, spec);
        if (!spec.choices.empty()) {
          const std::vector<std::string_view> choices = split_choices(spec.choices);
          if (std::find(choices.begin(), choices.end(), text) == choices.end()) {
            fail(at(value), "'" + key + "': expected one of " + join(choices) + ", found '" + text + "'" +
                                did_you_mean(text, choices));
          }
        }
        v.text = text;
        v.canonical = text;
        break;
      }
      case T::kPath: {
        const std::string text = scalar(value, spec);
        if (text.empty()) fail(at(value), "'" + key + "': expected a path, found nothing");
        v.text = text;
        v.path = resolve(text, value, spec);
        v.canonical = text;
        break;
      }
      case T::kTextList: {
        v.list = word_list(value, spec);
        if (!spec.choices.empty()) {
          const std::vector<std::string_view> choices = split_choices(spec.choices);
          for (const YAML::Node& item : value) {
            if (std::find(choices.begin(), choices.end(), item.Scalar()) == choices.end()) {
              fail(at(item), "'" + key + "': unknown item '" + item.Scalar() + "'" +
                                 did_you_mean(item.Scalar(), choices) + "; expected any of " + join(choices));
            }
          }
          if (v.list.empty() && spec.required) fail(at(value), "'" + key + "': expected at least one item, found []");
        }
        v.canonical = "[" + join(v.list) + "]";
        break;
      }
      case T::kNumberList: {
        if (!value.IsSequence()) {
          fail(at(value), "'" + key + "': expected a list of numbers like [1, 2.5], found " + describe(value));
        }
        std::vector<std::string> words;
        for (const YAML::Node& item : value) {
          if (!item.IsScalar()) fail(at(item), "'" + key + "': expected a number in the list, found " + describe(item));
          const double x = parse_number(item.Scalar(), item, spec);
          v.numbers_as_written.push_back(x);
          v.numbers_si.push_back(x * unit_to_si(spec.unit));
          words.push_back(shortest_text(x));
        }
        const auto n = static_cast<double>(v.numbers_si.size());
        if (n < spec.min || n > spec.max) {
          fail(at(value), "'" + key + "': expected " +
                              (spec.min == spec.max ? shortest_text(spec.min)
                                                    : shortest_text(spec.min) + " to " + shortest_text(spec.max)) +
                              " numbers, found " + shortest_text(n));
        }
        v.canonical = "[" + join(words) + "]";
        break;
      }
      case T::kNamedNumberList: {
        const std::vector<std::string> items = word_list(value, spec);
        std::vector<std::string> words;
        std::size_t i = 0;
        for (const YAML::Node& item : value) {
          const std::string& text = items[i++];
          const auto eq = text.find('=');
          const std::string name = eq == std::string::npos ? "" : text.substr(0, eq);
          if (eq == std::string::npos || name.empty() || eq + 1 >= text.size())
            fail(at(item), "'" + key + "': expected items 'name=value', found '" + text + "'");
          if (std::find(v.list.begin(), v.list.end(), name) != v.list.end())
            fail(at(item), "'" + key + "': '" + name + "' given twice");
          const std::string number = text.substr(eq + 1);
          const double x = parse_number(number, item, spec);
          check_range(x, number, item, spec);
          v.list.push_back(name);
          v.numbers_as_written.push_back(x);
          v.numbers_si.push_back(x * unit_to_si(spec.unit));
          words.push_back(name + "=" + shortest_text(x));
        }
        v.canonical = "[" + join(words) + "]";
        break;
      }
      case T::kEffectList: {
        const std::string& stage = spec.effect_stage;
        v.list = word_list(value, spec);
        std::vector<std::string_view> names;
        for (const EffectName& e : schema_.effects)
          if (e.stage == stage) names.push_back(e.name);
        for (const YAML::Node& item : value) {
          const EffectName* e = nullptr;
          for (const EffectName& c : schema_.effects)
            if (c.name == item.Scalar()) e = &c;
          if (e == nullptr) {
            fail(at(item), "unknown effect '" + item.Scalar() + "'" + did_you_mean(item.Scalar(), names) + "; the " +
                               stage + " stage knows: " + join(names));
          }
          if (e->stage != stage) {
            fail(at(item), "effect '" + item.Scalar() + "' belongs to the " + e->stage + " stage, not the " + stage +
                               " stage; this list takes: " + join(names));
          }
        }
        v.canonical = "[" + join(v.list) + "]";
        break;
      }
      case T::kBlock:
      case T::kInstances:
        throw std::logic_error("Parser::fill called for a block");
    }
  }

  // Parses a flat option block (instances handled by the caller) into `out`.
  void options(const YAML::Node& node, const std::vector<const OptionSpec*>& allowed, const std::string& label,
               const std::string& note, OptionBlock& out, YAML::Node* instances = nullptr) {
    for (auto& [key, val] : entries(node, allowed, label, note)) {
      const OptionSpec& spec = *find_in(allowed, key.Scalar());
      if (spec.type == T::kInstances) {
        if (instances) *instances = val;
        continue;
      }
      out.set(key.Scalar(), value(key, val, spec));
    }
  }

  void defaults(const std::vector<OptionSpec>& specs, OptionBlock& out) {
    for (const OptionSpec& s : specs) {
      if (s.type == T::kBlock || s.type == T::kInstances) continue;
      if (out.has(s.key) || s.default_value.empty()) continue;
      OptionValue v;
      v.spec = &s;
      v.given = false;
      // Defaults are parsed by the same code as user text, so they obey the
      // same types and ranges (a bad default fails every scene, loudly).
      YAML::Node node;
      try {
        node = YAML::Load(s.default_value);
      } catch (const YAML::Exception& e) {
        throw std::logic_error("schema default of " + s.block + "." + s.key + " is not valid YAML");
      }
      fill(v, node, s);
      out.set(s.key, v);
    }
  }

 private:
  std::string file_;
  std::filesystem::path dir_;
  const SceneSchema& schema_;
};

std::vector<const OptionSpec*> pointers(const std::vector<OptionSpec>& specs) {
  std::vector<const OptionSpec*> out;
  for (const OptionSpec& s : specs) out.push_back(&s);
  return out;
}

}  // namespace

std::filesystem::path repository_of(const std::filesystem::path& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  for (fs::path p = dir; !p.empty(); p = p.parent_path()) {
    if (fs::exists(p / ".git", ec)) return p;
    if (p == p.parent_path()) break;
  }
  return {};
}

// ---------------------------------------------------------------------------
// SceneSchema
// ---------------------------------------------------------------------------
const BlockSchema* SceneSchema::block(std::string_view name) const {
  for (const BlockSchema& b : blocks)
    if (b.name == name) return &b;
  return nullptr;
}

const OptionSpec* SceneSchema::find(std::string_view block_name, std::string_view key) const {
  for (const OptionSpec* s : all()) {
    if (s->key != key) continue;
    if (s->block == block_name) return s;
  }
  for (const BlockSchema& b : blocks) {
    if (b.instance_label.empty() || b.instance_label != block_name) continue;
    for (const OptionSpec& s : b.keys)
      if (s.key == key && s.overridable) return &s;
  }
  return nullptr;
}

std::vector<const OptionSpec*> SceneSchema::all() const {
  std::vector<const OptionSpec*> out;
  for (const OptionSpec& s : top) out.push_back(&s);
  for (const BlockSchema& b : blocks) {
    for (const OptionSpec& s : b.keys) out.push_back(&s);
    for (const OptionSpec& s : b.instance_keys) out.push_back(&s);
  }
  return out;
}

std::string SceneSchema::markdown() const {
  std::ostringstream s;
  std::string current;
  // Every key in documentation order, with a row per block (top level) and
  // per instances key (its block).
  std::vector<OptionSpec> rows(top.begin(), top.end());
  for (const BlockSchema& b : blocks) {
    OptionSpec r;
    r.block = "scene";
    r.key = b.name;
    r.type = T::kBlock;
    r.doc = b.doc;
    rows.push_back(r);
  }
  for (const BlockSchema& b : blocks) {
    if (!b.instances_key.empty()) {
      OptionSpec r;
      r.block = b.name;
      r.key = b.instances_key;
      r.type = T::kInstances;
      r.required = true;
      r.doc = b.instances_doc;
      rows.push_back(r);
    }
    rows.insert(rows.end(), b.keys.begin(), b.keys.end());
    rows.insert(rows.end(), b.instance_keys.begin(), b.instance_keys.end());
  }
  for (const OptionSpec& row : rows) {
    const OptionSpec* o = &row;
    if (o->block != current) {
      current = o->block;
      s << "\n### " << (current == "scene" ? "top level" : current) << "\n\n";
      for (const BlockSchema& b : blocks) {
        if (b.instance_label == current) {
          s << "A " << current << " also accepts every `" << b.name << "` key marked *per " << current << "*.\n\n";
        }
      }
      s << "| key | type | default | range / choices | meaning |\n|---|---|---|---|---|\n";
    }
    std::string range;
    if (o->type == T::kNumber || o->type == T::kInteger) {
      range = "[" + shortest_text(o->min) + ", " + shortest_text(o->max) + "]";
    } else if (o->type == T::kNamedNumberList) {
      range = "each in [" + shortest_text(o->min) + ", " + shortest_text(o->max) + "]";
    } else if (o->type == T::kNumberList) {
      range = o->min == o->max ? shortest_text(o->min) + " numbers"
                               : shortest_text(o->min) + " to " + shortest_text(o->max) + " numbers";
    } else if (!o->choices.empty()) {
      range = o->choices;
    }
    std::string type(type_word(o->type));
    if (!unit_suffix(o->unit).empty()) {
      type += " (" + std::string(unit_suffix(o->unit).substr(1)) + " -> " + std::string(si_unit_name(o->unit)) + ")";
    }
    std::string def = o->default_value.empty() ? (o->required ? "required" : "none") : "`" + o->default_value + "`";
    std::string doc = o->doc;
    if (o->overridable) {
      for (const BlockSchema& b : blocks)
        if (b.name == o->block && !b.instance_label.empty()) doc += " *(per " + b.instance_label + ")*";
    }
    for (char& c : range) {
      if (c == '|') c = '/';
    }
    s << "| `" << o->key << "` | " << type << " | " << def << " | " << range << " | " << doc << " |\n";
  }
  return s.str();
}

// ---------------------------------------------------------------------------
// Scene
// ---------------------------------------------------------------------------
bool BlockInstance::wants(std::string_view effect) const {
  return std::find(effects.begin(), effects.end(), effect) != effects.end();
}

bool Scene::has_block(std::string_view name) const {
  auto it = block_lines.find(name);
  return it != block_lines.end() && it->second > 0;
}

int Scene::block_line(std::string_view name) const {
  auto it = block_lines.find(name);
  return it == block_lines.end() ? 0 : it->second;
}

const OptionBlock& Scene::block(std::string_view name) const {
  auto it = blocks.find(name);
  if (it == blocks.end()) throw std::logic_error("the scene schema has no block '" + std::string(name) + "'");
  return it->second;
}

const std::vector<BlockInstance>& Scene::instances(std::string_view block_name) const {
  static const std::vector<BlockInstance> kNone;
  auto it = block_instances.find(block_name);
  return it == block_instances.end() ? kNone : it->second;
}

const BlockInstance* Scene::instance(std::string_view block_name, std::string_view name) const {
  for (const BlockInstance& i : instances(block_name))
    if (i.name == name) return &i;
  return nullptr;
}

const BlockInstance& Scene::require_instance(std::string_view block_name, std::string_view name) const {
  if (const BlockInstance* i = instance(block_name, name)) return *i;
  const BlockSchema* b = schema ? schema->block(block_name) : nullptr;
  const std::string label = b && !b->instance_label.empty() ? b->instance_label : "instance";
  const std::string key = b ? b->name + "." + b->instances_key : std::string(block_name);
  std::string have;
  for (const BlockInstance& i : instances(block_name)) have += (have.empty() ? "" : ", ") + i.name;
  throw InputError(file.string(), 0,
                   "expected a " + label + " named '" + std::string(name) + "' under " + key + ", found " +
                       (have.empty() ? std::string("none") : have));
}

Scene parse_scene(const std::string& text, const std::filesystem::path& file, const SceneSchema& schema) {
  namespace fs = std::filesystem;
  const std::string label = file.string();
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    fail(label, e.mark, "not valid YAML: " + e.msg);
  }
  Parser p(label, fs::absolute(file).parent_path(), schema);
  std::vector<std::string> block_names;
  for (const BlockSchema& b : schema.blocks) block_names.push_back(b.name);
  if (!root.IsMap()) {
    std::vector<std::string> words;
    for (const OptionSpec& s : schema.top)
      if (s.required) words.push_back(s.key);
    throw InputError(label, root.IsNull() ? 1 : root.Mark().line + 1, root.IsNull() ? 0 : root.Mark().column + 1,
                     "expected a scene (a block of keys: " + join(words) + ", ...), found " + describe(root));
  }

  Scene scene;
  scene.file = fs::absolute(file).lexically_normal();
  scene.schema = &schema;
  scene.top = OptionBlock("scene");

  // The top level: its keys and one entry per block.
  std::vector<OptionSpec> block_entries;
  for (const BlockSchema& b : schema.blocks) {
    OptionSpec s;
    s.block = "scene";
    s.key = b.name;
    s.type = T::kBlock;
    s.doc = b.doc;
    block_entries.push_back(s);
  }
  std::vector<const OptionSpec*> top_allowed = pointers(schema.top);
  for (const OptionSpec& s : block_entries) top_allowed.push_back(&s);
  std::map<std::string, YAML::Node> block_nodes;
  for (auto& [key, val] : p.entries(root, top_allowed, "the scene", "")) {
    const std::string& k = key.Scalar();
    const OptionSpec& spec = *Parser::find_in(top_allowed, k);
    if (spec.type == T::kBlock) {
      block_nodes[k] = val;
      scene.block_lines[k] = p.at(key).line;
      continue;
    }
    scene.top.set(k, p.value(key, val, spec));
  }
  p.defaults(schema.top, scene.top);

  for (const BlockSchema& b : schema.blocks) {
    OptionBlock& out = scene.blocks[b.name];
    out = OptionBlock(b.name);
    auto found = block_nodes.find(b.name);
    if (found == block_nodes.end()) {
      p.defaults(b.keys, out);
      continue;
    }
    std::vector<const OptionSpec*> allowed = pointers(b.keys);
    YAML::Node instances_node;
    OptionSpec instances_spec;
    if (!b.instances_key.empty()) {
      instances_spec.block = b.name;
      instances_spec.key = b.instances_key;
      instances_spec.type = T::kInstances;
      instances_spec.required = true;
      instances_spec.doc = b.instances_doc;
      allowed.push_back(&instances_spec);
    }
    p.options(found->second, allowed, b.name, "", out, &instances_node);
    p.defaults(b.keys, out);
    if (b.instances_key.empty()) continue;
    if (!instances_node.IsMap() || instances_node.size() == 0) {
      fail(p.at(instances_node), "'" + b.instances_key + "': expected a block of named " + b.instance_label +
                                     "s (e.g. name:), found " + describe(instances_node));
    }
    // An instance takes its own keys and every key of the block.
    std::vector<const OptionSpec*> instance_allowed = pointers(b.instance_keys);
    for (const OptionSpec& s : b.keys)
      if (s.overridable) instance_allowed.push_back(&s);
    const std::string note = " (" + b.name + "-wide keys go in the '" + b.name + "' block; these may be overridden per " +
                             b.instance_label + ")";
    std::vector<BlockInstance>& list = scene.block_instances[b.name];
    const YAML::const_iterator last = instances_node.end();
    for (YAML::const_iterator it = instances_node.begin(); it != last; ++it) {
      const std::string name = it->first.Scalar();
      if (!valid_instance_name(name)) {
        fail(p.at(it->first), "expected a " + b.instance_label + " name of lowercase letters, digits and '_', found '" +
                                  name + "'");
      }
      for (const BlockInstance& other : list)
        if (other.name == name) fail(p.at(it->first), b.instance_label + " '" + name + "' given twice");
      BlockInstance inst;
      inst.name = name;
      inst.line = p.at(it->first).line;
      inst.column = p.at(it->first).column;
      inst.options = OptionBlock(b.name + "." + name);
      p.options(it->second, instance_allowed, b.name + "." + b.instances_key + "." + name, note, inst.options);
      p.defaults(b.instance_keys, inst.options);
      // Inherit every block option the instance does not set itself.
      for (const auto& [k, v] : out.values()) {
        if (!inst.options.has(k)) inst.options.set(k, v);
      }
      if (inst.options.has("effects")) inst.effects = inst.options.list("effects");
      list.push_back(std::move(inst));
    }
  }
  return scene;
}

Scene load_scene(const std::filesystem::path& file, const SceneSchema& schema) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError(file.string(), 0, "cannot open the scene file");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_scene(ss.str(), file, schema);
}

}  // namespace arthrosim::common
