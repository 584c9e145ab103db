#include "common/output_file.h"

#include <sys/stat.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "common/error.h"

namespace arthrosim::common {
namespace fs = std::filesystem;

bool same_file(const fs::path& a, const fs::path& b) {
  if (a.empty() || b.empty()) return false;
  struct stat sa {}, sb {};
  if (::stat(a.c_str(), &sa) == 0 && ::stat(b.c_str(), &sb) == 0)
    return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
  // At least one does not exist yet: compare the resolved names (a missing
  // output inside a symlinked folder still resolves through the link).
  std::error_code ea, eb;
  const fs::path ra = fs::weakly_canonical(fs::absolute(a), ea);
  const fs::path rb = fs::weakly_canonical(fs::absolute(b), eb);
  return !ea && !eb && ra == rb;
}

void refuse_output_over_inputs(const std::string& program, const std::string& option, const fs::path& out,
                               const std::vector<NamedInput>& inputs) {
  for (const NamedInput& in : inputs) {
    if (in.path.empty() || !same_file(out, in.path)) continue;
    throw InputError(program + ": error: " + option + " " + out.string() + " is the input " + in.path.string() +
                     " (" + in.given_as + "); an output never replaces an input: choose another " + option);
  }
}

std::vector<NamedInput> files_of(const fs::path& path, const std::string& given_as) {
  std::vector<NamedInput> files;
  std::error_code ec;
  if (path.empty()) return files;
  if (!fs::is_directory(path, ec)) return {{path, given_as}};
  for (fs::directory_iterator it(path, ec), end; !ec && it != end && files.size() < 10000; it.increment(ec))
    if (it->is_regular_file(ec)) files.push_back({it->path(), given_as});
  return files;
}

fs::path partial_name(const fs::path& out) { return fs::path(out.string() + ".partial"); }

std::string complete_name(const std::string& path) {
  const std::string suffix = ".partial";
  if (path.size() > suffix.size() && path.compare(path.size() - suffix.size(), suffix.size(), suffix) == 0)
    return path.substr(0, path.size() - suffix.size());
  return path;
}

AtomicOutput::AtomicOutput(fs::path out) : out_(std::move(out)), temp_(partial_name(out_)) {
  std::error_code ec;
  fs::remove(temp_, ec);
}

void AtomicOutput::commit() {
  if (committed_) return;
  if (std::rename(temp_.c_str(), out_.c_str()) != 0) {
    throw InputError(out_.string(), 0,
                     "cannot move the finished output " + temp_.string() + " into place: " + std::strerror(errno));
  }
  committed_ = true;
}

}  // namespace arthrosim::common
