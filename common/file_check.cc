#include "common/file_check.h"

#include "common/error.h"
#include "common/hdf5.h"
#include "common/log.h"

namespace arthrosim::common {

namespace {

struct Format {
  const char* attribute;  // root attribute naming the kind
  const char* value;      // its value in the version this build reads
  const char* version;    // separate integer version attribute, or nullptr
  int version_value;
};

Format format_of(StageFile kind) {
  switch (kind) {
    case StageFile::kKinematics: return {"format", "arthrosim kinematics file", "format_version", 1};
    case StageFile::kPreparedModel: return {"schema", "arthrosim prepared model 1", nullptr, 0};
    case StageFile::kSurfaceOutput: return {"schema", "arthrosim surface output 2", nullptr, 0};
  }
  return {"", "", nullptr, 0};
}

std::string frames_of(const H5File& f) {
  if (!f.is_dataset("/time")) return "no frame";
  const auto d = f.dims("/time");
  const std::int64_t n = d.empty() ? 1 : d[0];
  return std::to_string(n) + (n == 1 ? " frame" : " frames");
}

// "0.1.0 (a3d9dcd)" of the program that wrote the file, when recorded.
std::string writer_of(const H5File& f) {
  std::string w;
  if (f.has_attribute("/", "program")) w = f.attribute_string("/", "program");
  if (f.has_attribute("/", "arthrosim_version")) w += (w.empty() ? "" : " ") + f.attribute_string("/", "arthrosim_version");
  if (f.has_attribute("/", "arthrosim_git_revision"))
    w += " (" + f.attribute_string("/", "arthrosim_git_revision") + ")";
  return w.empty() ? "" : "; written by " + w;
}

}  // namespace

std::string stage_file_name(StageFile kind) {
  switch (kind) {
    case StageFile::kKinematics: return "kinematics file";
    case StageFile::kPreparedModel: return "prepared model";
    case StageFile::kSurfaceOutput: return "surface output";
  }
  return "file";
}

void require_file_format(const H5File& f, const std::string& path, StageFile kind) {
  const Format fmt = format_of(kind);
  const std::string what = stage_file_name(kind);
  if (!f.has_attribute("/", fmt.attribute)) {
    throw InputError(path, 0,
                     "expected a " + what + " (root attribute " + fmt.attribute + " = '" + fmt.value +
                         "'), found no attribute '" + fmt.attribute + "'" + writer_of(f));
  }
  const std::string found = f.attribute_string("/", fmt.attribute);
  if (found != fmt.value) {
    // Same kind, another version: "arthrosim prepared model 2" vs "... 1".
    const std::string stem = std::string(fmt.value).substr(0, std::string(fmt.value).find_last_of(' '));
    const bool same_kind = fmt.version == nullptr && found.rfind(stem + " ", 0) == 0;
    throw InputError(path, 0,
                     (same_kind ? "a " + what + " of another version: found " + fmt.attribute + " '" + found +
                                      "', this build reads '" + fmt.value + "'; rerun the stage that wrote it with this build"
                                : "expected a " + what + " (" + fmt.attribute + " '" + fmt.value + "'), found " +
                                      fmt.attribute + " '" + found + "'") +
                         writer_of(f));
  }
  if (fmt.version != nullptr) {
    if (!f.has_attribute("/", fmt.version))
      throw InputError(path, 0, "expected root attribute " + std::string(fmt.version) + " of a " + what + ", found none");
    const std::int64_t v = f.attribute_int("/", fmt.version);
    if (v != fmt.version_value)
      throw InputError(path, 0,
                       "a " + what + " of " + fmt.version + " " + std::to_string(v) + "; this build reads version " +
                           std::to_string(fmt.version_value) + ": rerun the stage that wrote it with this build" +
                           writer_of(f));
  }
}

std::string incompleteness(const H5File& f, StageFile kind) {
  switch (kind) {
    case StageFile::kKinematics: {
      if (!f.has_attribute("/", "frames"))
        return frames_of(f) + " and no run summary (the run that wrote it did not finish: killed or crashed)";
      const std::int64_t frames = f.attribute_int("/", "frames");
      std::string stopped = f.has_attribute("/", "stopped") ? f.attribute_string("/", "stopped") : "";
      if (f.has_attribute("/", "frames_expected")) {
        const std::int64_t expected = f.attribute_int("/", "frames_expected");
        if (frames < expected)
          return std::to_string(frames) + " of " + std::to_string(expected) + " frames" +
                 (stopped.empty() ? "" : " (the run stopped: " + stopped + ")");
      }
      if (!stopped.empty()) return std::to_string(frames) + " frames (the run stopped: " + stopped + ")";
      return "";
    }
    case StageFile::kPreparedModel:
      return "";
    case StageFile::kSurfaceOutput: {
      const std::string status = f.has_attribute("/", "status") ? f.attribute_string("/", "status") : "(none)";
      if (status == "running")
        return "status 'running' with " + frames_of(f) + " (the run that wrote it did not finish: killed or crashed)";
      if (status != "completed") return "status '" + status + "' with " + frames_of(f);
      if (f.has_attribute("/", "partial_input"))
        return "a run on a partial input (" + f.attribute_string("/", "partial_input") + ")";
      return "";
    }
  }
  return "";
}

std::string require_usable_file(const H5File& f, const std::string& path, StageFile kind, bool allow_partial) {
  require_file_format(f, path, kind);
  const std::string holds = incompleteness(f, kind);
  if (holds.empty()) return "";
  const std::string what = stage_file_name(kind);
  if (!allow_partial)
    throw InputError(path, 0,
                     "incomplete " + what + ": it holds " + holds +
                         "; rerun the stage that writes it, or pass --allow-partial to go on with what it holds");
  const std::string line = "PARTIAL INPUT: " + path + " is an incomplete " + what + ": it holds " + holds;
  log_warn(line);
  return line;
}

}  // namespace arthrosim::common
