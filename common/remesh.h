#pragma once
// Isotropic remeshing (CGAL::Polygon_mesh_processing::isotropic_remeshing,
// Botsch & Kobbelt 2004: split long edges, collapse short ones, flip to equalise
// valence, tangential smoothing, projection back onto the input surface).
#include "common/mesh.h"

namespace arthrosim::common {

struct RemeshOptions {
  /// Target edge length [m]. Range: > 0, typically 0.5e-3 .. 3e-3 for cartilage.
  double target_edge_length = 1e-3;
  /// Remeshing iterations (split/collapse/flip/smooth/project). Range 1..20.
  int iterations = 5;
  /// Tangential relaxation steps per iteration. Range 1..10.
  int relaxation_steps = 1;
  /// Open boundaries (e.g. the outline of an articular cartilage surface) keep
  /// their geometry: boundary edges are first split to at most
  /// 4/3 * target_edge_length along the original outline, then protected (not
  /// split, collapsed, flipped, and their vertices not moved). The outline
  /// polyline is therefore preserved exactly. When false, boundary edges may
  /// also be split and collapsed during remeshing (CGAL's default): boundary
  /// vertices stay on the input outline, but collapses can cut its corners.
  bool protect_boundary = true;
  /// Feature edges [rad]: edges whose dihedral angle (between the normals of
  /// their two triangles) exceeds this are treated like the boundary (split
  /// along themselves, then protected when protect_boundary; never flipped,
  /// end points never smoothed), so sharp rims of closed layers stay sharp.
  /// 0 disables. Range 0 or [0.2, 1.5]; ~0.5 (30 deg) for CAD-like shapes.
  /// Keep 0 for smooth but coarse inputs (their facet creases would be kept).
  double feature_angle = 0.0;
};

/// Statistics of a remeshing run.
struct RemeshStatistics {
  int input_triangles = 0;
  int output_triangles = 0;
  double mean_edge_length = 0.0;  ///< [m] of the output
  double min_edge_length = 0.0;   ///< [m]
  double max_edge_length = 0.0;   ///< [m]
};

/// Remeshes `mesh` (must be a valid, manifold, consistently oriented triangle
/// mesh; InputError naming the mesh otherwise). Deterministic: the same input
/// and options give bit-identical output. If `stats` is not null it is filled.
TriangleMesh isotropic_remesh(const TriangleMesh& mesh, const RemeshOptions& options,
                              RemeshStatistics* stats = nullptr);

/// Triangles an isotropic remesh of `mesh` at `target_edge_length` [m] is
/// expected to produce, computed from the input alone (cheap, before any
/// allocation): area / (sqrt(3)/4 L^2) (equilateral triangles of side L)
/// plus the outline length / L (the outline is split to L first). Measured
/// in remesh_test: the real count is 0.8-1.1 x the estimate. A double, as a
/// corrupted input can give counts beyond any integer type.
double estimate_remesh_triangles(const TriangleMesh& mesh, double target_edge_length);

/// Edge length statistics of any mesh (unique undirected edges).
RemeshStatistics edge_length_statistics(const TriangleMesh& mesh);

}  // namespace arthrosim::common
