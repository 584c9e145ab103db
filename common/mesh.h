#pragma once
// Surface meshes. Coordinates are in metres (SI) everywhere inside arthrosim;
// millimetres appear only at file edges (see mesh_io.h).
//
// Conventions:
//  - TriangleMesh::V is (n_vertices x 3), TriangleMesh::F is (n_triangles x 3)
//    with counter-clockwise vertex order seen from outside (normal = (b-a)x(c-a)).
//  - QuadMesh::Q is (n_quads x 4), nodes counter-clockwise, same normal rule
//    (normal of the bilinear surface at the centre).
//  - Indices are 0-based ints.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <limits>
#include <string>
#include <vector>

namespace arthrosim::common {

using Vec3 = Eigen::Vector3d;
using Points3 = Eigen::Matrix<double, Eigen::Dynamic, 3>;     // rows are points
using Triangles = Eigen::Matrix<int, Eigen::Dynamic, 3>;
using Quads = Eigen::Matrix<int, Eigen::Dynamic, 4>;

struct TriangleMesh {
  Points3 V;       ///< vertex positions [m]
  Triangles F;     ///< triangle vertex indices
  std::string name;  ///< optional label used in messages

  int num_vertices() const { return static_cast<int>(V.rows()); }
  int num_triangles() const { return static_cast<int>(F.rows()); }
  Vec3 vertex(int i) const { return V.row(i).transpose(); }
};

struct QuadMesh {
  Points3 V;       ///< node positions [m]
  Quads Q;         ///< quad node indices
  std::string name;

  int num_nodes() const { return static_cast<int>(V.rows()); }
  int num_quads() const { return static_cast<int>(Q.rows()); }
};

/// Unit normals of every triangle (rows). Degenerate triangles give a zero row.
Points3 triangle_normals(const TriangleMesh& mesh);
/// Areas [m^2] of every triangle.
Eigen::VectorXd triangle_areas(const TriangleMesh& mesh);
/// Centroids of every triangle (rows).
Points3 triangle_centroids(const TriangleMesh& mesh);
/// Area-weighted unit vertex normals (rows).
Points3 vertex_normals(const TriangleMesh& mesh);
/// Unit normals of the nodes, area-weighted over their quads (zero for a
/// node of no quad): the orientation the quads' node order gives.
Points3 quad_vertex_normals(const QuadMesh& mesh);
/// Total area [m^2].
double surface_area(const TriangleMesh& mesh);

/// Each quad split along its 0-2 diagonal into two triangles (2 per quad,
/// triangle 2q = (0,1,2), 2q+1 = (0,2,3)); the vertices are shared.
TriangleMesh triangulate(const QuadMesh& quads);

/// Edge-based adjacency of a triangle mesh.
struct MeshTopology {
  /// Unique undirected edges (n_edges x 2), each row sorted (a < b).
  Eigen::Matrix<int, Eigen::Dynamic, 2> edges;
  /// For each edge, the triangles that share it (usually 1 or 2).
  std::vector<std::vector<int>> edge_triangles;
  /// For each triangle, its up-to-3 edge-neighbour triangles (-1 if none),
  /// neighbour k is across the edge opposite vertex k.
  Triangles triangle_neighbours;
  /// For each vertex, the triangles incident on it.
  std::vector<std::vector<int>> vertex_triangles;
  /// Vertices on an open boundary (edges used by exactly one triangle), sorted.
  std::vector<int> boundary_vertices;
};
MeshTopology build_topology(const TriangleMesh& mesh);

/// Axis-aligned bounding box [m]. An empty point set gives lo = +inf, hi = -inf
/// (empty() is true).
struct BoundingBox {
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 hi = Vec3::Constant(-std::numeric_limits<double>::infinity());
  bool empty() const { return (lo.array() > hi.array()).any(); }
  Vec3 size() const { return hi - lo; }
  Vec3 center() const { return 0.5 * (lo + hi); }
  double diagonal() const { return empty() ? 0.0 : (hi - lo).norm(); }
};
BoundingBox bounding_box(const Points3& points);
inline BoundingBox bounding_box(const TriangleMesh& mesh) { return bounding_box(mesh.V); }
inline BoundingBox bounding_box(const QuadMesh& mesh) { return bounding_box(mesh.V); }

/// Unit normal of every quad at its centre, ((x2 - x0) x (x3 - x1)) normalised:
/// the normal of the bilinear surface at (0, 0) (x_xi x x_eta there is half of
/// that diagonal cross product). Degenerate quads give a zero row.
Points3 quad_normals(const QuadMesh& mesh);
/// Areas [m^2] of the bilinear quads (2x2 Gauss quadrature of |x_xi x x_eta|;
/// exact for planar quads, where it equals |(x2 - x0) x (x3 - x1)| / 2).
Eigen::VectorXd quad_areas(const QuadMesh& mesh);
/// Nodes on the open boundary of a quad mesh (on edges used by one quad), sorted.
std::vector<int> boundary_nodes(const QuadMesh& mesh);

/// Ordered boundary loops of a triangle mesh. Each loop follows the boundary
/// edges in the direction their triangle traverses them (the surface is on
/// the left seen from the normal side), starts at its smallest vertex, and
/// loops are sorted by that vertex. Throws InputError (naming the mesh and
/// vertex) if a boundary vertex has other than one outgoing and one incoming
/// boundary edge (a non-manifold or inconsistently oriented boundary).
std::vector<std::vector<int>> boundary_loops(const TriangleMesh& mesh);

/// Each triangle (a,b,c) becomes 3 quads through its edge midpoints and its
/// centroid g: (a, m_ab, g, m_ca), (b, m_bc, g, m_ab), (c, m_ca, g, m_bc),
/// same orientation as the triangle. Output nodes: the n input vertices first
/// (same indices), then one midpoint per unique undirected edge (in the order of
/// build_topology(mesh).edges, so shared edges give one node and the quad mesh
/// is conforming), then one centroid per triangle (node n + n_edges + t).
/// Quad 3t+k starts at vertex F(t,k).
QuadMesh split_triangles_to_quads(const TriangleMesh& mesh);

/// Edge-connected components: component id of every triangle (0-based, in
/// order of each component's lowest triangle index) and their count.
std::vector<int> connected_components(const TriangleMesh& mesh, int* count = nullptr);

/// The triangles `triangles` of mesh (in that order) with only the vertices
/// they use, renumbered in order of first use; name kept.
TriangleMesh submesh(const TriangleMesh& mesh, const std::vector<int>& triangles);

/// The mesh with every vertex mapped by X (p -> X * p); F and name unchanged.
/// X is a rigid transform, so orientation (and normals' sense) is preserved.
TriangleMesh transformed(const TriangleMesh& mesh, const Eigen::Isometry3d& X);
QuadMesh transformed(const QuadMesh& mesh, const Eigen::Isometry3d& X);

}  // namespace arthrosim::common
