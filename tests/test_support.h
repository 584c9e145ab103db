// Small helpers shared by the test files: the message of an expected
// exception, a whole text file, an emptied scratch folder under the build
// tree, a shell command's status and output, and the objects two HDF5 files
// differ in.
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <set>
#include <sstream>
#include <string>
#include <utility>

namespace arthrosim::test_support {

/// what() of the exception f throws, or "(no exception)".
inline std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no exception)";
}

/// The whole file as text ("" if it cannot be read).
inline std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// build/test_scratch/<name>, emptied and created.
inline std::filesystem::path fresh_scratch_dir(const std::string& name) {
  const std::filesystem::path dir = std::filesystem::path(ARTHROSIM_BINARY_DIR) / "test_scratch" / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

/// Runs a shell command; returns (its exit status, -1 when it did not exit
/// normally; stdout + stderr).
inline std::pair<int, std::string> run_shell(const std::string& command) {
  std::string out;
  FILE* p = ::popen((command + " 2>&1").c_str(), "r");
  char buf[4096];
  while (p && std::fgets(buf, sizeof buf, p)) out += buf;
  const int status = p ? ::pclose(p) : -1;
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

/// The objects (datasets or attributes) in which `h5diff -r a b` finds
/// differences, as h5diff names them ("dataset: </x>", "attribute: <k of
/// </x>>"). h5diff cannot leave out attributes, so its report is read: each
/// "N differences found" (N > 0) belongs to the last object named before
/// it. A failure of h5diff itself is one entry "h5diff failed: ...".
inline std::set<std::string> h5diff_differences(const std::filesystem::path& a, const std::filesystem::path& b) {
  const auto [status, report] = run_shell("h5diff -r " + a.string() + " " + b.string());
  std::set<std::string> differing;
  std::istringstream in(report);
  std::string line, object;
  while (std::getline(in, line)) {
    if (line.rfind("attribute: <", 0) == 0 || line.rfind("dataset: <", 0) == 0) {
      object = line.substr(0, line.find("> and <") + 1);
    } else if (!line.empty() && line[0] >= '1' && line[0] <= '9' && line.find("difference") != std::string::npos) {
      differing.insert(object);
    }
  }
  if (status != 0 && status != 1) differing.insert("h5diff failed: " + report);
  return differing;
}

}  // namespace arthrosim::test_support
