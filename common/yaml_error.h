#pragma once
// INTERNAL: file:line:column errors for the sources that read YAML with
// yaml-cpp (common/scene.cc, common/mesh_manifest.cc, pipelines/cohort.cc).
// Not part of common's public API: it includes yaml-cpp, which only the
// targets holding those sources link (PRIVATE); every function is inline, so
// including it adds no link dependency to common.
#include <yaml-cpp/yaml.h>

#include <string>

#include "common/error.h"

namespace arthrosim::common::yaml {

/// A place in a YAML file, 1-based as editors count (yaml-cpp counts from 0).
struct Where {
  std::string file;
  int line = 0;
  int column = 0;
};

inline Where where(const std::string& file, const YAML::Mark& m) { return {file, m.line + 1, m.column + 1}; }

[[noreturn]] inline void fail(const Where& w, const std::string& message) {
  throw InputError(w.file, w.line, w.column, message);
}
[[noreturn]] inline void fail(const std::string& file, const YAML::Mark& m, const std::string& message) {
  fail(where(file, m), message);
}

/// What a node holds, for "expected ..., found <describe>" messages.
inline std::string describe(const YAML::Node& node) {
  switch (node.Type()) {
    case YAML::NodeType::Null:
      return "nothing";
    case YAML::NodeType::Sequence:
      return "a list";
    case YAML::NodeType::Map:
      return "a block of keys";
    case YAML::NodeType::Scalar:
      return "'" + node.Scalar() + "'";
    default:
      return "an undefined value";
  }
}

}  // namespace arthrosim::common::yaml
