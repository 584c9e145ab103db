#pragma once
// The prepare stage: from a model's bone and cartilage surface files (the
// bundled parametric knee or a user's MR segmentation) to one prepared-model
// HDF5 file (+ XDMF) that the later stages read. Schema and method:
// docs/prepared_model.md.
//
// Steps, per model:
//  1. find the files (find_model_files): the folder's mesh manifest
//     meshes.yaml (common/mesh_manifest.h: files, units and body frames by
//     name) or, without one, the naming convention: every
//     <name>_cartilage.{stl,obj,ply} is a cartilage surface on the bone
//     <first word of name>_bone.{stl,obj,ply} (tibia_medial_cartilage.stl ->
//     tibia_bone.stl);
//  2. read (each file's unit), check the size against the unit
//     (common::check_plausible_extent), repair what is safe (common::repair)
//     and validate (common::validate); anything still invalid is an
//     InputError naming the file. Cartilage normals are made to point away
//     from the bone (a patch whose normals mostly point into it is flipped,
//     reported as a repair); a cartilage must lie on its bone (median distance
//     within max_cast_distance: else another frame or unit);
//  3. a cartilage declared `split` (one mesh holding both tibial plateaus) is
//     split into <name>_medial and <name>_lateral (connected components, or a
//     plane between the two area clusters if it is one piece);
//  4. remesh every cartilage surface to its target edge length (CGAL
//     isotropic remeshing) after estimating its triangle count (refused above
//     max_triangles). The outline is kept exactly unless it is over-resolved
//     (mean outline edge < target / 2) or keeping it leaves an element that
//     fails the quality check; then it is resampled by the remesher (on the
//     input outline);
//  5. the all-quad surface (every triangle split into three quads) with node
//     normals; every triangle and quad written is checked (shortest edge,
//     smallest angle, Jacobian sign against the normals, admissible shell
//     thickness: common/mesh_quality.h); a failing element is an InputError
//     naming it;
//  6. cartilage thickness at every vertex and quad node: a point inside the
//     (closed) bone has thickness 0 (overlapping segmentations; kInsideBone);
//     else the first entry of the ray along the inward normal (-n) into the
//     bone within max_cast_distance (kRay); a ray that enters no bone falls
//     back to the closest-point distance (kClosestPoint). Values below
//     min_thickness are raised to it. Every fallback and raise is counted and
//     stored (thickness_source, thickness_measured).
#include <map>
#include <utility>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/mesh.h"
#include "common/mesh_io.h"
#include "common/mesh_quality.h"
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

  /// Thickness floor [m]: measured values below it (a rim on the bone, a
  /// vertex inside the bone) are raised to it and counted, so the foundation
  /// and contact stiffness K/h stay finite. Default 0.2 mm (about half the
  /// in-plane voxel size of knee MR, 0.3-0.5 mm).
  double min_thickness = 0.2 * common::units::mm;
  /// Largest estimated triangle count of one remeshed surface
  /// (common::estimate_remesh_triangles); above it the surface is refused
  /// before remeshing. Default 1e6 (the lenhart2015 femoral cartilage at the
  /// smallest edge length, 0.2 mm, estimates 4.1e5).
  double max_triangles = 1e6;
  /// Limits of the element check of every triangle and quad written.
  common::ElementQualityLimits quality;

  /// The scene's prepare block (common/options.h; ranges there).
  void declare(common::OptionVisitor& v);
};

/// The prepare block of a scene as options (pure: no file is read).
PrepareOptions prepare_from_scene(const common::Scene& scene);

/// Where a measured thickness value came from (stored per vertex / node).
enum class ThicknessSource : int {
  kRay = 0,           ///< the inward ray's entry into the bone
  kClosestPoint = 1,  ///< the ray entered no bone within max_cast_distance: closest-point distance
  kInsideBone = 2,    ///< the point lies inside its (closed) bone: measured thickness 0
};

/// Model files, from the manifest or the naming convention.
struct ModelFiles {
  std::string folder;
  std::string manifest;  ///< the manifest read ("" = naming convention)
  std::map<std::string, std::string> bones;      ///< "femur" -> ".../femur_bone.stl"
  std::map<std::string, std::string> cartilage;  ///< "tibia_medial" -> ".../tibia_medial_cartilage.stl"
  std::map<std::string, std::string> cartilage_bone;  ///< "tibia_medial" -> "tibia"
  /// Units declared by the manifest (by bone / cartilage name); files
  /// without one are read in PrepareOptions::unit.
  std::map<std::string, common::LengthUnit> bone_unit, cartilage_unit;
  /// Body whose frame a bone's coordinates (and its cartilage's) are in, as
  /// declared by the manifest; absent: the model frame at the reference pose.
  std::map<std::string, std::string> bone_body;
  /// Cartilage declared `split`: unit direction from medial to lateral.
  std::map<std::string, common::Vec3> split_lateral;
};

/// `path` is a model folder or a manifest file. A folder with meshes.yaml
/// (or the manifest itself) is read as a manifest; otherwise the folder is
/// scanned by the naming convention: InputError if it has no cartilage file,
/// or a cartilage's bone file is missing, or a name has two files (e.g. .stl
/// and .obj).
ModelFiles find_model_files(const std::string& path);

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
  /// Area-weighted mean over the surface (each vertex weighted by a third of
  /// its triangles' area) [m]: the resolution-independent mean.
  double thickness_mean = 0.0;
  /// Mean over the outline, each outline vertex weighted by half its two
  /// outline edges [m].
  double thickness_rim_mean = 0.0;
  int vertices_floored = 0;        ///< triangle vertices raised to min_thickness
  int nodes_floored = 0;           ///< quad nodes raised to min_thickness
  double max_overlap = 0.0;        ///< deepest vertex inside the bone (closest-point distance) [m]
  bool outline_resampled = false;  ///< the outline was resampled (else kept exactly)
  std::string outline_reason;      ///< why it was resampled
  double estimated_triangles = 0.0;
  common::ElementQualityReport triangle_quality, quad_quality;
};

struct PreparedSurface {
  std::string name;         ///< "femur", "tibia_medial", ...
  std::string bone;         ///< "femur", "tibia", ...
  std::string source_file;  ///< cartilage file read
  std::string body;         ///< frame of the coordinates (manifest), "" = model frame
  std::string split_from;   ///< manifest cartilage this compartment was split from, or ""
  std::string compartment;  ///< "medial" / "lateral" for a split part, or ""
  /// Remeshed articular surface [m]; normals point away from the bone.
  common::TriangleMesh triangles;
  common::Points3 vertex_normals;      ///< unit, per vertex
  Eigen::VectorXd thickness;           ///< per vertex [m] (after the floor)
  Eigen::VectorXi thickness_source;    ///< per vertex, ThicknessSource
  Eigen::VectorXd thickness_measured;  ///< per vertex [m], before the floor
  /// All-quad surface (3 quads per triangle), same orientation.
  common::QuadMesh quads;
  common::Points3 node_normals;        ///< unit, per node (area-weighted quad normals)
  Eigen::VectorXd node_thickness;      ///< per node [m] (after the floor)
  Eigen::VectorXi node_thickness_source;
  Eigen::VectorXd node_thickness_measured;
  std::vector<int> periphery_nodes;    ///< quad nodes on the outline, sorted
  std::vector<std::string> repairs;    ///< what was repaired, one line each
  PreparedSurfaceStatistics stats;
};

struct PreparedBone {
  std::string name;
  std::string source_file;
  std::string body;  ///< frame of the coordinates (manifest), "" = model frame
  common::LengthUnit unit = common::LengthUnit::kMillimetre;  ///< of the file
  common::TriangleMesh mesh;  ///< repaired, [m]
  bool closed = false;
  std::vector<std::string> repairs;
};

struct PreparedModel {
  std::string folder;
  std::string manifest;
  std::vector<PreparedBone> bones;
  std::vector<PreparedSurface> surfaces;
  /// Warnings for the user (fallback counts with the first vertices, open
  /// bones, ...), also written to the file.
  std::vector<std::string> warnings;
};

/// Reads, repairs, validates, remeshes and measures everything (no output).
PreparedModel prepare_model(const ModelFiles& files, const PrepareOptions& options);

/// Measures the thickness of points p (rows) with unit outward normals n
/// against `bone` as described above (step 6, without the floor).
/// `bone_closed` enables the inside-bone test (needs a closed,
/// outward-oriented bone). If `overlap` is given, it receives for points
/// inside the bone their closest-point distance (the overlap depth), else 0.
void cast_thickness(const common::TriangleMesh& bone, bool bone_closed, const common::Points3& points,
                    const common::Points3& normals, double max_distance, Eigen::VectorXd* thickness,
                    Eigen::VectorXi* source, Eigen::VectorXd* overlap = nullptr);

/// Splits one cartilage mesh holding two compartments into (medial,
/// lateral) along `lateral` (unit, medial -> lateral): by connected
/// components when it has several (the two largest by area seed the sides,
/// smaller pieces go to the side whose seed centroid is nearer along
/// `lateral`), else by the plane normal to `lateral` between the two
/// area-weighted clusters of triangle centroids (1-D 2-means), triangles by
/// their centroid. `how` (optional) receives a one-line description.
/// InputError naming `source` if a side would be empty.
std::pair<common::TriangleMesh, common::TriangleMesh> split_compartments(const common::TriangleMesh& mesh,
                                                                           const common::Vec3& lateral,
                                                                           const std::string& source,
                                                                           std::string* how = nullptr);

/// Writes the prepared model to `h5_path` and the XDMF sidecar next to it
/// (same stem, .xdmf), with the run metadata on the root group.
void write_prepared_model(const PreparedModel& model, const PrepareOptions& options,
                          const common::RunMetadata& metadata, const std::string& h5_path);

/// The XDMF path written next to an HDF5 path (".h5" replaced by ".xdmf").
std::string xdmf_path_for(const std::string& h5_path);

}  // namespace arthrosim::pipelines
