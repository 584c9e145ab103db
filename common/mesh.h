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

}  // namespace arthrosim::common
