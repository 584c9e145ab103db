#pragma once
// The prepare stage: from a model's bone and cartilage surface files (the
// bundled parametric knee or a user's MR segmentation) to one prepared-model
// HDF5 file (+ XDMF) that the later stages read. Schema: docs/prepared_model.md.
//
// Steps, per model:
//  1. find the files by the naming convention (find_model_files): every
//     <name>_cartilage.{stl,obj,ply} in the folder is a cartilage surface; it
//     lies on the bone <first word of name>_bone.{stl,obj,ply} (e.g.
//     tibia_medial_cartilage.stl -> tibia_bone.stl);
//  2. read (file unit, millimetres by default), repair what is safe
//     (common::repair: merge duplicate vertices, drop degenerate/duplicate
//     triangles and unreferenced vertices, orient consistently) and validate
//     (common::validate); anything still invalid (non-manifold edges, NaN,
//     bad indices, a non-orientable patch) is an InputError naming the file.
//     Cartilage normals are made to point away from the bone (towards the
//     joint space): a patch whose normals mostly point into the bone is
//     flipped, and that is reported as a repair;
//  3. remesh every cartilage surface to the requested edge length (CGAL
//     isotropic remeshing, outline kept);
//  4. cartilage thickness at every vertex: a ray from the vertex along the
//     inward normal (-n) to the bone, first hit within max_cast_distance.
//     A vertex whose ray misses gets the closest-point distance to the bone
//     instead, and is counted and reported (status kClosestPoint); a ray that
//     meets a closed bone from the inside (the vertex is inside the bone) also
//     falls back to the closest-point distance (status kInsideBone). Nothing
//     is filled in silently: the status of every value is stored;
//  5. the all-quad articular surface for the shell stage: every triangle split
//     into three quads (common::split_triangles_to_quads), with per-node
//     normals, thickness (cast the same way) and the periphery node set.
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/mesh.h"
#include "common/mesh_io.h"
#include "common/options.h"

namespace arthrosim::common {
struct RunMetadata;
struct Scene;
}

namespace arthrosim::pipelines {

struct StageDescriptor;
/// The prepare stage's entry in the stage table (pipelines/stages.h).
StageDescriptor prepare_stage_descriptor();

struct PrepareOptions {
  /// Target edge length of the remeshed cartilage surfaces [m].
  double edge_length = 3 * common::units::mm;
  /// Per-surface target edge lengths [m] (cartilage name -> length) in place
  /// of edge_length, e.g. a femoral mesh coarser than the tibial ones.
  std::map<std::string, double> surface_edge_length;
  /// Unit of the coordinates in the input files.
  common::LengthUnit unit = common::LengthUnit::kMillimetre;
  /// Longest thickness ray [m]; a ray that meets no bone within it falls
  /// back to the closest-point distance (articular cartilage is at most
  /// ~6 mm thick).
  double max_cast_distance = 10 * common::units::mm;
  /// Isotropic remeshing iterations.
  int remesh_iterations = 5;
  /// Vertices closer than this are merged by the repair [m]. Range 0 .. 1e-5.
  double merge_tolerance = 1e-9;

  /// The scene's prepare block (common/options.h; ranges there).
  void declare(common::OptionVisitor& v);
};

/// The prepare block of a scene as options (pure: no file is read).
PrepareOptions prepare_from_scene(const common::Scene& scene);

/// Where a thickness value came from (stored per vertex / node).
enum class ThicknessSource : int {
  kRay = 0,           ///< first hit of the inward ray on the bone
  kClosestPoint = 1,  ///< the ray missed the bone within max_cast_distance
  kInsideBone = 2,    ///< the vertex lies inside its (closed) bone
};

/// Model files found by the naming convention.
struct ModelFiles {
  std::string folder;
  std::map<std::string, std::string> bones;      ///< "femur" -> ".../femur_bone.stl"
  std::map<std::string, std::string> cartilage;  ///< "tibia_medial" -> ".../tibia_medial_cartilage.stl"
  std::map<std::string, std::string> cartilage_bone;  ///< "tibia_medial" -> "tibia"
};

/// Scans `folder`; InputError if it has no cartilage file, or a cartilage's
/// bone file is missing, or a name has two files (e.g. .stl and .obj).
ModelFiles find_model_files(const std::string& folder);

/// Per-surface counts (the stage's statistics).
struct PreparedSurfaceStatistics {
  enum class Status { kOk, kWithFallbacks };
  Status status = Status::kOk;
  int input_triangles = 0;
  int triangles = 0;
  int quads = 0;
  int vertices_ray = 0;            ///< triangle vertices with a ray thickness
  int vertices_closest_point = 0;  ///< ... with the closest-point fallback
  int vertices_inside_bone = 0;    ///< ... inside their bone
  int nodes_closest_point = 0;     ///< quad nodes with a fallback (either kind)
  double mean_edge_length = 0.0;   ///< of the remeshed triangles [m]
  double target_edge_length = 0.0; ///< the remeshing target used for this surface [m]
  double thickness_min = 0.0;      ///< over triangle vertices [m]
  double thickness_max = 0.0;
  double thickness_mean = 0.0;
};

struct PreparedSurface {
  std::string name;         ///< "femur", "tibia_medial", ...
  std::string bone;         ///< "femur", "tibia", ...
  std::string source_file;  ///< cartilage file read
  /// Remeshed articular surface [m]; normals point away from the bone.
  common::TriangleMesh triangles;
  common::Points3 vertex_normals;      ///< unit, per vertex
  Eigen::VectorXd thickness;           ///< per vertex [m]
  Eigen::VectorXi thickness_source;    ///< per vertex, ThicknessSource
  /// All-quad surface (3 quads per triangle), same orientation.
  common::QuadMesh quads;
  common::Points3 node_normals;        ///< unit, per node (area-weighted quad normals)
  Eigen::VectorXd node_thickness;      ///< per node [m]
  Eigen::VectorXi node_thickness_source;
  std::vector<int> periphery_nodes;    ///< quad nodes on the outline, sorted
  std::vector<std::string> repairs;    ///< what was repaired, one line each
  PreparedSurfaceStatistics stats;
};

struct PreparedBone {
  std::string name;
  std::string source_file;
  common::TriangleMesh mesh;  ///< repaired, [m]
  bool closed = false;
  std::vector<std::string> repairs;
};

struct PreparedModel {
  std::string folder;
  std::vector<PreparedBone> bones;
  std::vector<PreparedSurface> surfaces;
  /// Warnings for the user (fallback counts with the first vertices, open
  /// bones, ...), also written to the file.
  std::vector<std::string> warnings;
};

/// Reads, repairs, validates, remeshes and measures everything (no output).
PreparedModel prepare_model(const ModelFiles& files, const PrepareOptions& options);

/// Casts the thickness of points p (rows) with unit outward normals n along
/// -n onto `bone`; falls back and sets the source as described above.
/// `bone_closed` enables the inside-bone test (needs an outward-oriented bone).
void cast_thickness(const common::TriangleMesh& bone, bool bone_closed, const common::Points3& points,
                    const common::Points3& normals, double max_distance, Eigen::VectorXd* thickness,
                    Eigen::VectorXi* source);

/// Writes the prepared model to `h5_path` and the XDMF sidecar next to it
/// (same stem, .xdmf), with the run metadata on the root group.
void write_prepared_model(const PreparedModel& model, const PrepareOptions& options,
                          const common::RunMetadata& metadata, const std::string& h5_path);

/// The XDMF path written next to an HDF5 path (".h5" replaced by ".xdmf").
std::string xdmf_path_for(const std::string& h5_path);

}  // namespace arthrosim::pipelines
