// The mesh manifest of a model folder (see mesh_manifest.h).
#include "common/mesh_manifest.h"

#include <yaml-cpp/yaml.h>

#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <vector>

#include "common/error.h"
#include "common/yaml_error.h"

namespace arthrosim::common {

namespace {

namespace fs = std::filesystem;

class Reader {
 public:
  explicit Reader(std::string path) : path_(std::move(path)) {}

  [[noreturn]] void fail(const YAML::Node& at, const std::string& message) const {
    yaml::fail(path_, at.Mark(), message);
  }

  static std::string describe(const YAML::Node& n) { return yaml::describe(n); }

  // Keys of a map, each checked against `allowed` and for repetition.
  std::vector<std::pair<YAML::Node, YAML::Node>> entries(const YAML::Node& node, const std::string& what,
                                                         const std::set<std::string>& allowed) const {
    if (!node.IsMap()) fail(node, "expected a block of keys for " + what + ", found " + describe(node));
    std::vector<std::pair<YAML::Node, YAML::Node>> out;
    std::set<std::string> seen;
    for (auto it = node.begin(); it != node.end(); ++it) {
      const YAML::Node key = it->first;
      if (!key.IsScalar()) fail(key, "expected a key name in " + what + ", found " + describe(key));
      const std::string& k = key.Scalar();
      if (!allowed.empty() && !allowed.count(k)) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        fail(key, "unknown key '" + k + "' in " + what + "; allowed keys: " + list);
      }
      if (!seen.insert(k).second) fail(key, "key '" + k + "' given twice in " + what);
      out.emplace_back(key, it->second);
    }
    return out;
  }

  std::string scalar(const YAML::Node& n, const std::string& what) const {
    if (!n.IsScalar() || n.Scalar().empty()) fail(n, "expected " + what + ", found " + describe(n));
    return n.Scalar();
  }

  LengthUnit unit(const YAML::Node& n) const {
    const std::string s = scalar(n, "a length unit (mm, cm, m)");
    try {
      return parse_length_unit(s);
    } catch (const InputError&) {
      fail(n, "expected a length unit (mm, cm, m), found '" + s + "'");
    }
  }

  void check_name(const YAML::Node& key, const std::string& what) const {
    const std::string& k = key.Scalar();
    for (char c : k)
      if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_'))
        fail(key, "expected a " + what + " name of letters, digits and '_', found '" + k + "'");
  }

  std::string file(const YAML::Node& n, const std::string& folder) const {
    const std::string written = scalar(n, "a mesh file name");
    fs::path p(written);
    if (p.is_relative()) p = fs::path(folder) / p;
    std::error_code ec;
    if (!fs::is_regular_file(p, ec)) fail(n, "expected an existing mesh file, found no file " + p.string());
    return p.lexically_normal().string();
  }

  Vec3 direction(const YAML::Node& n) const {
    if (n.IsScalar()) {
      const std::string s = n.Scalar();
      const std::map<std::string, Vec3> axes = {{"+x", Vec3::UnitX()}, {"-x", -Vec3::UnitX()}, {"+y", Vec3::UnitY()},
                                                {"-y", -Vec3::UnitY()}, {"+z", Vec3::UnitZ()}, {"-z", -Vec3::UnitZ()},
                                                {"x", Vec3::UnitX()},   {"y", Vec3::UnitY()},  {"z", Vec3::UnitZ()}};
      const auto it = axes.find(s);
      if (it == axes.end()) fail(n, "expected a direction (+x, -x, +y, -y, +z, -z or [x, y, z]), found '" + s + "'");
      return it->second;
    }
    if (n.IsSequence() && n.size() == 3) {
      Vec3 d;
      for (int k = 0; k < 3; ++k) {
        const std::string s = scalar(n[k], "a number");
        std::istringstream in(s);
        double v = 0;
        if (!(in >> v) || !(in >> std::ws).eof() || !std::isfinite(v)) fail(n[k], "expected a number, found '" + s + "'");
        d[k] = v;
      }
      if (!(d.norm() > 0)) fail(n, "expected a non-zero direction, found [0, 0, 0]");
      return d.normalized();
    }
    fail(n, "expected a direction (+x, -x, +y, -y, +z, -z or [x, y, z]), found " + describe(n));
  }

 private:
  std::string path_;
};

}  // namespace

MeshManifest parse_mesh_manifest(const std::string& text, const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    yaml::fail(path, e.mark, "not valid YAML: " + e.msg);
  }
  MeshManifest m;
  m.path = path;
  m.folder = fs::path(path).parent_path().string();
  if (m.folder.empty()) m.folder = ".";
  Reader r(path);
  if (!root.IsMap())
    throw InputError(path, 1, "expected a mesh manifest (keys unit, bones, cartilage), found " + Reader::describe(root));
  std::optional<LengthUnit> unit;
  YAML::Node bones, cartilage;
  for (const auto& [key, val] : r.entries(root, "the manifest", {"unit", "bones", "cartilage"})) {
    if (key.Scalar() == "unit") unit = r.unit(val);
    if (key.Scalar() == "bones") bones = val;
    if (key.Scalar() == "cartilage") cartilage = val;
  }
  if (!bones) r.fail(root, "missing key 'bones' (bone name -> {file, unit, body})");
  if (!cartilage) r.fail(root, "missing key 'cartilage' (surface name -> {file, bone, unit, split})");
  for (const auto& [key, val] : r.entries(bones, "'bones'", {})) {
    r.check_name(key, "bone");
    ManifestBone b;
    b.unit = unit;
    b.line = key.Mark().line + 1;
    bool has_file = false;
    for (const auto& [k, v] : r.entries(val, "bone '" + key.Scalar() + "'", {"file", "unit", "body"})) {
      if (k.Scalar() == "file") b.file = r.file(v, m.folder), has_file = true;
      if (k.Scalar() == "unit") b.unit = r.unit(v);
      if (k.Scalar() == "body") b.body = r.scalar(v, "a body name");
    }
    if (!has_file) r.fail(val, "missing key 'file' in bone '" + key.Scalar() + "'");
    m.bones[key.Scalar()] = b;
  }
  for (const auto& [key, val] : r.entries(cartilage, "'cartilage'", {})) {
    r.check_name(key, "cartilage");
    ManifestCartilage c;
    c.unit = unit;
    c.line = key.Mark().line + 1;
    bool has_file = false;
    YAML::Node bone_node;
    for (const auto& [k, v] : r.entries(val, "cartilage '" + key.Scalar() + "'", {"file", "unit", "bone", "split"})) {
      if (k.Scalar() == "file") c.file = r.file(v, m.folder), has_file = true;
      if (k.Scalar() == "unit") c.unit = r.unit(v);
      if (k.Scalar() == "bone") c.bone = r.scalar(v, "a bone name"), bone_node = v;
      if (k.Scalar() == "split") {
        for (const auto& [sk, sv] : r.entries(v, "split of '" + key.Scalar() + "'", {"lateral", "medial"})) {
          const Vec3 d = r.direction(sv);
          if (c.split_lateral) r.fail(sk, "give one of 'lateral' and 'medial' in split, found both");
          c.split_lateral = sk.Scalar() == "lateral" ? d : Vec3(-d);
        }
        if (!c.split_lateral) r.fail(v, "expected 'lateral: <direction>' (or 'medial:') in split, found none");
      }
    }
    if (!has_file) r.fail(val, "missing key 'file' in cartilage '" + key.Scalar() + "'");
    if (!bone_node) r.fail(val, "missing key 'bone' in cartilage '" + key.Scalar() + "' (one of 'bones')");
    if (!m.bones.count(c.bone)) {
      std::string list;
      for (const auto& [b, e] : m.bones) list += (list.empty() ? "" : ", ") + b;
      r.fail(bone_node, "expected one of the bones (" + list + "), found '" + c.bone + "'");
    }
    m.cartilage[key.Scalar()] = c;
  }
  if (m.cartilage.empty()) r.fail(cartilage, "expected at least one cartilage surface, found none");
  // Split parts must not clash with other names.
  for (const auto& [name, c] : m.cartilage)
    if (c.split_lateral)
      for (const char* part : {"_medial", "_lateral"})
        if (m.cartilage.count(name + part))
          throw InputError(path, c.line,
                           "cartilage '" + name + "' is split into " + name + "_medial and " + name +
                               "_lateral, but '" + name + part + "' is also declared");
  return m;
}

MeshManifest read_mesh_manifest(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path, 0, "expected a readable mesh manifest, found no such file");
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_mesh_manifest(ss.str(), path);
}

}  // namespace arthrosim::common
