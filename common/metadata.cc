// Run metadata (see metadata.h). The scene hash uses common/hashing.h.
#include "common/metadata.h"

#include <CGAL/version_macros.h>
#include <Eigen/Core>
#include <hdf5.h>

#include <mutex>
#include <sstream>

#include "common/error.h"
#include "common/hashing.h"
#include "common/hdf5.h"
#include "common/version.h"

namespace arthrosim::common {
namespace {

std::mutex g_deps_mutex;
std::map<std::string, std::string>& registered() {
  static std::map<std::string, std::string> deps;
  return deps;
}

bool shell_safe(const std::string& s) {
  if (s.empty()) return false;
  for (char c : s) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    std::string("_-./=:,+@%").find(c) != std::string::npos;
    if (!ok) return false;
  }
  return true;
}

constexpr const char* kVersionPrefix = "version_";

}  // namespace

void register_dependency_version(const std::string& name, const std::string& version) {
  std::lock_guard<std::mutex> lock(g_deps_mutex);
  registered()[name] = version;
}

std::map<std::string, std::string> dependency_versions() {
  std::map<std::string, std::string> out;
  unsigned maj = 0, min = 0, rel = 0;
  H5get_libversion(&maj, &min, &rel);
  out["hdf5"] = std::to_string(maj) + "." + std::to_string(min) + "." + std::to_string(rel);
  out["eigen"] = std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) + "." +
                 std::to_string(EIGEN_MINOR_VERSION);
  out["cgal"] = CGAL_VERSION_STR;
  std::lock_guard<std::mutex> lock(g_deps_mutex);
  for (const auto& [k, v] : registered()) out[k] = v;
  return out;
}

std::string join_command_line(int argc, const char* const* argv) {
  std::string out;
  for (int i = 0; i < argc; ++i) {
    const std::string a = argv[i] ? argv[i] : "";
    if (i) out += ' ';
    if (shell_safe(a)) {
      out += a;
    } else {
      out += '\'';
      for (char c : a) {
        if (c == '\'') {
          out += "'\\''";
        } else {
          out += c;
        }
      }
      out += '\'';
    }
  }
  return out;
}

RunMetadata collect_run_metadata(const std::string& program, int argc, const char* const* argv,
                                 const std::string& scene_path, const std::string& options) {
  RunMetadata m;
  m.program = program;
  m.version = kVersion;
  m.git_revision = kGitRevision;
  m.scene_path = scene_path;
  if (!scene_path.empty()) m.scene_sha256 = sha256_file(scene_path);
  m.command_line = join_command_line(argc, argv);
  m.options = options;
  m.dependencies = dependency_versions();
  return m;
}

void write_metadata(H5File& file, const RunMetadata& m, const std::string& object) {
  file.set_attribute(object, "arthrosim_version", m.version);
  file.set_attribute(object, "arthrosim_git_revision", m.git_revision);
  file.set_attribute(object, "program", m.program);
  file.set_attribute(object, "scene_path", m.scene_path);
  file.set_attribute(object, "scene_sha256", m.scene_sha256);
  file.set_attribute(object, "command_line", m.command_line);
  file.set_attribute(object, "options", m.options);
  for (const auto& [name, version] : m.dependencies) file.set_attribute(object, kVersionPrefix + name, version);
}

RunMetadata read_metadata(const H5File& file, const std::string& object) {
  RunMetadata m;
  m.version = file.attribute_string(object, "arthrosim_version");
  m.git_revision = file.attribute_string(object, "arthrosim_git_revision");
  m.program = file.attribute_string(object, "program");
  m.scene_path = file.attribute_string(object, "scene_path");
  m.scene_sha256 = file.attribute_string(object, "scene_sha256");
  m.command_line = file.attribute_string(object, "command_line");
  m.options = file.attribute_string(object, "options");
  const std::string prefix = kVersionPrefix;
  for (const std::string& key : file.attribute_names(object)) {
    if (key.compare(0, prefix.size(), prefix) == 0) m.dependencies[key.substr(prefix.size())] = file.attribute_string(object, key);
  }
  return m;
}

}  // namespace arthrosim::common
