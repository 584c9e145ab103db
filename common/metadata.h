#pragma once
// Run metadata, collected once per run and written as attributes of the root
// group of every output HDF5 file (see docs/file_formats.md):
//   arthrosim_version, arthrosim_git_revision, program, scene_path,
//   scene_sha256, command_line, options, and one "version_<dependency>" per
//   dependency (hdf5, eigen, cgal, plus every registered one).
// Deliberately absent: host name, user, wall-clock time -- they would make
// two runs of the same inputs differ (determinism checks compare files).
#include <map>
#include <string>

namespace arthrosim::common {

class H5File;

struct RunMetadata {
  std::string program;        ///< executable name, e.g. "arthrosim-prepare"
  std::string version;        ///< arthrosim version (common/version.h kVersion)
  std::string git_revision;   ///< git revision at configure time (kGitRevision)
  std::string scene_path;     ///< scene file as given on the command line ("" if none)
  std::string scene_sha256;   ///< SHA-256 (hex, common/hashing.h) of the scene file's bytes ("" if none)
  std::string command_line;   ///< argv joined with spaces, shell-quoted where needed
  std::string options;        ///< resolved options of the stage, free text (e.g. YAML)
  std::map<std::string, std::string> dependencies;  ///< name -> version
};

/// Records the version of a third-party library for the run metadata. Called
/// by the library that links it (e.g. musculoskeletal registers Ipopt and
/// urdfdom before a run). Re-registering a name replaces its version.
void register_dependency_version(const std::string& name, const std::string& version);
/// HDF5 (runtime, H5get_libversion), Eigen and CGAL (compile time), plus
/// every registered dependency.
std::map<std::string, std::string> dependency_versions();

/// Fills version, git revision, dependencies, the command line from argv,
/// the scene path and its hash (throws InputError if the scene cannot be
/// read), and `options`.
RunMetadata collect_run_metadata(const std::string& program, int argc, const char* const* argv,
                                 const std::string& scene_path, const std::string& options);

/// Writes the metadata as attributes of `object` (default the root group).
void write_metadata(H5File& file, const RunMetadata& metadata, const std::string& object = "/");
/// Reads what write_metadata wrote (throws InputError if an attribute is missing).
RunMetadata read_metadata(const H5File& file, const std::string& object = "/");

/// Joins argv with spaces; arguments with spaces or shell metacharacters
/// are single-quoted.
std::string join_command_line(int argc, const char* const* argv);

}  // namespace arthrosim::common
