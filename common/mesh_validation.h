#pragma once
// Checks of triangle meshes read from users' files (MR segmentations, CAD) and
// the repairs that are safe to make without guessing.
//
// Errors (ValidationReport::ok() is false): out-of-range indices, NaN/Inf
// coordinates, degenerate triangles, duplicate triangles, non-manifold edges,
// inconsistent orientation, and open boundary edges when a closed surface is
// required. Warnings: unreferenced vertices, non-manifold vertices, and open
// boundaries when a closed surface is not required (counted, but no error).
#include <array>
#include <string>
#include <vector>

#include "common/mesh.h"
#include "common/mesh_io.h"

namespace arthrosim::common {

struct ValidationOptions {
  /// Open boundary edges are an error (a bone that must be a closed solid).
  bool require_closed = false;
  /// A triangle is degenerate when 2*area <= relative_area_tolerance * L^2,
  /// L = its longest edge (i.e. its height is below tol * L: scale free).
  /// Range [0, 0.1]; an equilateral triangle has 2*area/L^2 = 0.87.
  double degenerate_relative_tolerance = 1e-10;
  /// How many offending indices each category keeps (the counts are complete).
  int max_examples = 5;
};

/// One category of problem on vertices or triangles.
struct IndexIssues {
  int count = 0;
  std::vector<int> first;  ///< the first offending indices (ascending)
};
/// One category of problem on edges (vertex pairs, a < b, lexicographic order).
struct EdgeIssues {
  int count = 0;
  std::vector<std::array<int, 2>> first;
};

struct ValidationReport {
  std::string mesh_name;
  int num_vertices = 0;
  int num_triangles = 0;
  bool require_closed = false;

  IndexIssues invalid_index_triangles;   ///< triangles with an index outside [0, n)
  IndexIssues non_finite_vertices;       ///< NaN or Inf coordinates
  IndexIssues degenerate_triangles;      ///< repeated index or (near-)zero area
  IndexIssues duplicate_triangles;       ///< same vertex set as an earlier triangle (the later ones listed)
  EdgeIssues non_manifold_edges;         ///< edges shared by more than 2 triangles
  EdgeIssues inconsistent_edges;         ///< edges traversed in the same direction by 2 triangles
  EdgeIssues boundary_edges;             ///< edges used by exactly 1 triangle
  IndexIssues unreferenced_vertices;     ///< vertices no triangle uses (warning)
  /// Vertices whose triangles form more than one edge-connected fan (e.g. two
  /// surfaces touching at a point; warning: representable and remeshable, but
  /// usually a segmentation artefact).
  IndexIssues non_manifold_vertices;

  /// No errors (warnings allowed). Boundary edges are errors only if require_closed.
  bool ok() const;
  bool has_warnings() const;
  /// Multi-line human-readable summary: one line per non-empty category with
  /// its count and first indices, "error" or "warning" per line.
  std::string summary() const;
};

/// Runs every check. Never throws on bad meshes (that is what it reports);
/// checks that need valid indices skip triangles with invalid ones.
ValidationReport validate(const TriangleMesh& mesh, const ValidationOptions& options = {});

/// Throws InputError(source, 0, "invalid mesh ...\n<summary>") if !report.ok().
/// `source` names the mesh or file (defaults to report.mesh_name).
void throw_if_invalid(const ValidationReport& report, const std::string& source = "");
/// validate() then throw_if_invalid(); returns the report (for its warnings).
ValidationReport validate_or_throw(const TriangleMesh& mesh, const ValidationOptions& options = {},
                                   const std::string& source = "");

struct RepairOptions {
  /// Vertices closer than this [m] are merged into the lowest-index one (greedy
  /// in index order, no chaining). 0 merges only exact duplicates. Range
  /// [0, a fraction of the shortest real edge]; default 1 nm.
  double merge_tolerance = 1e-9;
  /// Degenerate-triangle criterion, as in ValidationOptions.
  double degenerate_relative_tolerance = 1e-10;
  /// Make the orientation consistent within each edge-connected component
  /// (through manifold edges). Closed components are oriented outward
  /// (positive signed volume); open ones keep the orientation of the larger
  /// area share (ties: that of their lowest-index triangle).
  bool orient = true;
};

/// What repair() changed, so callers can say so.
struct RepairReport {
  int merged_vertices = 0;           ///< vertices merged into another
  int removed_degenerate = 0;        ///< triangles dropped (after merging)
  int removed_duplicate = 0;         ///< triangles dropped as duplicates of an earlier one
  int removed_unreferenced = 0;      ///< vertices dropped
  int flipped_triangles = 0;         ///< triangles whose orientation was reversed
  int components = 0;                ///< edge-connected components (after repair)
  /// Components whose orientation cannot be made consistent (non-orientable
  /// through manifold edges); left as they were.
  int unorientable_components = 0;
  /// Output vertex index for every input vertex (-1: dropped).
  std::vector<int> vertex_map;
  /// Input triangle index for every output triangle.
  std::vector<int> triangle_source;

  bool changed() const;
  /// One line per change made, e.g. "merged 12 duplicate vertices (tolerance 1e-09 m)".
  std::string summary() const;
};

struct RepairResult {
  TriangleMesh mesh;
  RepairReport report;
};

/// Repairs what is safe: merges duplicate vertices, drops degenerate and
/// duplicate triangles and unreferenced vertices, orients components
/// consistently. Non-manifold edges, non-finite coordinates and invalid indices
/// are not touched (validate() the result: they remain errors). Throws
/// InputError if a triangle has an out-of-range index.
RepairResult repair(const TriangleMesh& mesh, const RepairOptions& options = {});

/// Plausible size of one surface of a knee model (a cartilage patch or a
/// bone, possibly a whole femur or tibia): the largest side of its bounding
/// box [m]. Defaults 5 mm .. 1 m.
struct ExtentLimits {
  double min = 5e-3;
  double max = 1.0;
};

/// Unit check of a mesh read with `declared` (coordinates already in metres):
/// throws InputError naming `source` when the largest bounding-box side lies
/// outside `limits`, with the extent found (in the declared unit) and either
///  - the vertices far from all others (a corrupted coordinate such as one
///    flipped exponent bit: a vertex is "far" when its distance from the
///    per-axis median vertex exceeds 10 times the 90th percentile distance;
///    listed when they are at most 1 % of the vertices and without them the
///    extent is plausible), or
///  - the likely unit: each of um, mm, cm, m, inch whose reading of the
///    file's numbers gives a plausible extent (um and inch are named so the
///    user can convert; the readers take mm, cm and m).
/// Factor-10 mistakes (cm read as mm) stay within the limits for most knee
/// surfaces and are not caught here.
void check_plausible_extent(const TriangleMesh& mesh, LengthUnit declared, const std::string& source,
                            const ExtentLimits& limits = {});

}  // namespace arthrosim::common
