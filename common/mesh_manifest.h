#pragma once
// The mesh manifest of a model folder (`meshes.yaml`): which file holds which
// bone and cartilage surface, in which length unit and in which body frame,
// for meshes as users have them (e.g. OpenSim's Geometry/*.stl in metres,
// each in its own body frame) instead of the <bone>_bone / <name>_cartilage
// file-name convention. Format and semantics: docs/prepared_model.md
// ("Input: the model folder").
//
//   unit: m                     # default unit of every file (mm, cm, m); default: the stage's mesh unit
//   bones:
//     femur: {file: Geometry/femur-bone.stl, body: femur_distal_r}
//     tibia: {file: Geometry/tibia-bone.stl, body: tibia_proximal_r}
//   cartilage:
//     femur: {file: Geometry/femur-cartilage.stl, bone: femur}
//     tibia: {file: Geometry/tibia-cartilage.stl, bone: tibia, split: {lateral: +z}}
//
// Errors are InputErrors "meshes.yaml:line:column: error: expected ..., found ...".
#include <map>
#include <optional>
#include <string>

#include "common/mesh.h"
#include "common/mesh_io.h"

namespace arthrosim::common {

struct ManifestBone {
  std::string file;                 ///< absolute or relative to the manifest's folder, as resolved
  std::optional<LengthUnit> unit;   ///< this entry's or the manifest's unit; none: the stage's
  std::string body;                 ///< body whose frame the coordinates are in ("" = not stated)
  int line = 0;
};

struct ManifestCartilage {
  std::string file;
  std::optional<LengthUnit> unit;
  std::string bone;  ///< a key of `bones`
  /// One mesh holding the medial and lateral compartments (a tibial
  /// cartilage): unit direction from medial to lateral in the mesh's frame;
  /// the prepare stage splits it into <name>_medial and <name>_lateral.
  std::optional<Vec3> split_lateral;
  int line = 0;
};

struct MeshManifest {
  std::string path;    ///< the manifest file
  std::string folder;  ///< its folder (relative file names are resolved against it)
  std::map<std::string, ManifestBone> bones;
  std::map<std::string, ManifestCartilage> cartilage;
};

/// The manifest's file name in a model folder.
inline constexpr const char* kMeshManifestName = "meshes.yaml";

/// Reads and checks a manifest: every key known, every file present, every
/// cartilage's bone declared, names usable as HDF5 group names (letters,
/// digits, '_'), split directions non-zero. InputError with file:line:column.
MeshManifest read_mesh_manifest(const std::string& path);
MeshManifest parse_mesh_manifest(const std::string& text, const std::string& path);

}  // namespace arthrosim::common
