#pragma once
// Changing single options of a scene by dotted key, for studies that run one
// scene at several settings (`arthrosim study accuracy`, docs/studies.md).
//
// A dotted key names one scalar option of a scene (keys as in the scene's
// schema, common/scene.h):
//   model, trial, description                  top level
//   prepare.edge_length_mm, comak.ipopt_tolerance, post.outline_points
//   surface.time_step_s                         a block (for surface: every
//                                               scenario that does not set it itself)
//   surface.scenarios.osmotic.time_step_s       one instance of a block
// Only scalar options (number, whole number, flag, text, path) can be set this
// way; lists and blocks cannot. yaml-cpp stays inside scene_edit.cc.
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "common/scene.h"

namespace arthrosim::common {

/// One settable option of a particular scene.
struct SceneKey {
  std::string dotted;        ///< "surface.scenarios.osmotic.time_step_s"
  const OptionSpec* spec = nullptr;
};

/// Every dotted key of `scene` that edit_scene_text() accepts, in schema order:
/// the top-level scalars, then per block its scalars (a block that is not
/// written only when it has no required key and no instances) and every
/// instance's scalars.
std::vector<SceneKey> settable_scene_keys(const Scene& scene);

/// The spec of `dotted` in `scene`. An unknown key throws InputError naming
/// the scene file, the key (with a "did you mean" hint) and every known key.
const OptionSpec& find_settable_key(const Scene& scene, const std::string& dotted);

/// The text of a copy of the scene file `file` with each (dotted key, value as
/// written in a scene) of `settings` set, and every path option written in it
/// (model, trial, post.splitline_map, a scenario's mesh) made absolute, so the copy can live
/// in any folder and still name the same files. A relative path given as a
/// setting is resolved like one written in the scene (against the scene's
/// folder, then its repository). Comments of the original are not kept; the
/// text starts with a comment naming the original and the settings. Throws
/// InputError for an unreadable or invalid original scene, an unknown key or
/// a value that is not a single scalar on one line (a line break or control
/// character, an empty value, a YAML list or map); the value's type and range
/// are checked when the returned text is parsed (parse_scene).
std::string edit_scene_text(const std::filesystem::path& file, const SceneSchema& schema,
                            const std::vector<std::pair<std::string, std::string>>& settings);

}  // namespace arthrosim::common
