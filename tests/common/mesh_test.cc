// Tests of common/mesh.h against hand-computed closed forms.
#include "common/mesh.h"

#include <gtest/gtest.h>

#include <cmath>

#include "common/error.h"

namespace arthrosim::common {
namespace {

// Regular-ish tetrahedron with outward (counter-clockwise from outside) faces.
TriangleMesh tetrahedron() {
  TriangleMesh m;
  m.V.resize(4, 3);
  m.V << 0, 0, 0,  //
      1, 0, 0,     //
      0, 1, 0,     //
      0, 0, 1;
  m.F.resize(4, 3);
  m.F << 0, 2, 1,  // z = 0, normal -z
      0, 1, 3,     // y = 0, normal -y
      0, 3, 2,     // x = 0, normal -x
      1, 2, 3;     // slanted, normal (1,1,1)/sqrt(3)
  m.name = "tet";
  return m;
}

TriangleMesh unit_square() {
  TriangleMesh m;
  m.V.resize(4, 3);
  m.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  m.F.resize(2, 3);
  m.F << 0, 1, 2, 0, 2, 3;
  return m;
}

TEST(Mesh, NormalsAreasCentroidsOfTetrahedron) {
  const TriangleMesh m = tetrahedron();
  const Points3 N = triangle_normals(m);
  const Eigen::VectorXd A = triangle_areas(m);
  const Points3 C = triangle_centroids(m);
  // Closed forms: three right triangles with legs 1 (area 1/2) and one
  // equilateral triangle with side sqrt(2) (area sqrt(3)/2).
  EXPECT_NEAR((N.row(0) - Eigen::RowVector3d(0, 0, -1)).norm(), 0.0, 1e-15);
  EXPECT_NEAR((N.row(1) - Eigen::RowVector3d(0, -1, 0)).norm(), 0.0, 1e-15);
  EXPECT_NEAR((N.row(2) - Eigen::RowVector3d(-1, 0, 0)).norm(), 0.0, 1e-15);
  EXPECT_NEAR((N.row(3) - Eigen::RowVector3d(1, 1, 1) / std::sqrt(3.0)).norm(), 0.0, 1e-15);
  EXPECT_DOUBLE_EQ(A(0), 0.5);
  EXPECT_DOUBLE_EQ(A(3), std::sqrt(3.0) / 2.0);
  EXPECT_NEAR(surface_area(m), 1.5 + std::sqrt(3.0) / 2.0, 1e-15);
  EXPECT_NEAR((C.row(3) - Eigen::RowVector3d(1, 1, 1) / 3.0).norm(), 0.0, 1e-15);
}

TEST(Mesh, VertexNormalsAreAreaWeighted) {
  const TriangleMesh m = tetrahedron();
  const Points3 Nv = vertex_normals(m);
  // Vertex 0 touches the three axis faces of area 1/2: normal -(1,1,1)/sqrt(3).
  EXPECT_NEAR((Nv.row(0) + Eigen::RowVector3d(1, 1, 1) / std::sqrt(3.0)).norm(), 0.0, 1e-15);
  // Vertex 1 touches faces 0 (-z, area 1/2), 1 (-y, 1/2), 3 ((1,1,1)/sqrt3, sqrt3/2):
  // sum of 2*area*n = (0,0,-1) + (0,-1,0) + (1,1,1) = (1,0,0).
  EXPECT_NEAR((Nv.row(1) - Eigen::RowVector3d(1, 0, 0)).norm(), 0.0, 1e-15);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(Nv.row(i).norm(), 1.0, 1e-15);
}

TEST(Mesh, DegenerateTriangleHasZeroNormal) {
  TriangleMesh m;
  m.V.resize(3, 3);
  m.V << 0, 0, 0, 1, 0, 0, 2, 0, 0;  // collinear
  m.F.resize(1, 3);
  m.F << 0, 1, 2;
  EXPECT_EQ(triangle_normals(m).row(0).norm(), 0.0);
  EXPECT_EQ(triangle_areas(m)(0), 0.0);
  EXPECT_EQ(vertex_normals(m).norm(), 0.0);
}

TEST(Mesh, TopologyOfClosedTetrahedron) {
  const MeshTopology topo = build_topology(tetrahedron());
  ASSERT_EQ(topo.edges.rows(), 6);
  for (int e = 0; e < 6; ++e) {
    EXPECT_LT(topo.edges(e, 0), topo.edges(e, 1));
    EXPECT_EQ(topo.edge_triangles[e].size(), 2u);
  }
  // Lexicographic order of edges.
  EXPECT_EQ(topo.edges(0, 0), 0);
  EXPECT_EQ(topo.edges(0, 1), 1);
  EXPECT_EQ(topo.edges(5, 0), 2);
  EXPECT_EQ(topo.edges(5, 1), 3);
  EXPECT_TRUE(topo.boundary_vertices.empty());
  // Triangle 0 = (0,2,1): neighbour 0 is across edge (2,1) -> triangle 3 (1,2,3);
  // neighbour 1 across (1,0) -> triangle 1; neighbour 2 across (0,2) -> triangle 2.
  EXPECT_EQ(topo.triangle_neighbours(0, 0), 3);
  EXPECT_EQ(topo.triangle_neighbours(0, 1), 1);
  EXPECT_EQ(topo.triangle_neighbours(0, 2), 2);
  for (int v = 0; v < 4; ++v) EXPECT_EQ(topo.vertex_triangles[v].size(), 3u);
}

TEST(Mesh, TopologyOfOpenSquare) {
  const MeshTopology topo = build_topology(unit_square());
  EXPECT_EQ(topo.edges.rows(), 5);
  EXPECT_EQ(topo.boundary_vertices, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(topo.triangle_neighbours(0, 1), 1);  // across (2,0)
  EXPECT_EQ(topo.triangle_neighbours(0, 0), -1);
  EXPECT_EQ(topo.triangle_neighbours(1, 2), 0);  // across (0,2)
}

TEST(Mesh, TopologyRejectsOutOfRangeIndex) {
  TriangleMesh m = unit_square();
  m.F(1, 2) = 7;
  EXPECT_THROW(build_topology(m), InputError);
}

TEST(Mesh, TriangulateQuadsAlongDiagonal02) {
  QuadMesh q;
  q.V.resize(4, 3);
  q.V << 0, 0, 0, 2, 0, 0, 2, 1, 0, 0, 1, 0;
  q.Q.resize(1, 4);
  q.Q << 0, 1, 2, 3;
  const TriangleMesh t = triangulate(q);
  ASSERT_EQ(t.num_triangles(), 2);
  EXPECT_EQ(t.F.row(0), Eigen::RowVector3i(0, 1, 2));
  EXPECT_EQ(t.F.row(1), Eigen::RowVector3i(0, 2, 3));
  EXPECT_DOUBLE_EQ(surface_area(t), 2.0);
  EXPECT_NEAR((triangle_normals(t).row(1) - Eigen::RowVector3d(0, 0, 1)).norm(), 0.0, 1e-15);
}

TEST(Mesh, SplitTrianglesToQuadsIsConformingAndKeepsAreaAndOrientation) {
  const TriangleMesh m = tetrahedron();
  const QuadMesh q = split_triangles_to_quads(m);
  // 4 vertices + 6 edge midpoints + 4 centroids; 3 quads per triangle.
  ASSERT_EQ(q.num_nodes(), 14);
  ASSERT_EQ(q.num_quads(), 12);
  EXPECT_EQ(q.V.topRows(4), m.V);
  const TriangleMesh t = triangulate(q);
  // Each quad lies in its (planar) triangle, so the area is unchanged exactly
  // up to rounding.
  EXPECT_NEAR(surface_area(t), surface_area(m), 1e-14);
  // Conforming and closed: every edge of the triangulated quad mesh has 2 faces.
  const MeshTopology topo = build_topology(t);
  EXPECT_TRUE(topo.boundary_vertices.empty());
  for (const auto& tris : topo.edge_triangles) EXPECT_EQ(tris.size(), 2u);
  // Orientation: each quad's normal equals its parent triangle's.
  const Points3 Nt = triangle_normals(m);
  const Points3 Nq = triangle_normals(t);
  for (int k = 0; k < q.num_quads(); ++k) {
    const int parent = k / 3;
    EXPECT_NEAR((Nq.row(2 * k) - Nt.row(parent)).norm(), 0.0, 1e-14);
    EXPECT_NEAR((Nq.row(2 * k + 1) - Nt.row(parent)).norm(), 0.0, 1e-14);
    EXPECT_EQ(q.Q(k, 0), m.F(parent, k % 3));
  }
  // Midpoint of edge (0,1) is node 4 (first edge in lexicographic order).
  EXPECT_NEAR((q.V.row(4) - Eigen::RowVector3d(0.5, 0, 0)).norm(), 0.0, 1e-15);
  // Centroid of triangle 3 is the last node.
  EXPECT_NEAR((q.V.row(13) - Eigen::RowVector3d(1, 1, 1) / 3.0).norm(), 0.0, 1e-15);
}

TEST(Mesh, TransformedIsRigid) {
  const TriangleMesh m = tetrahedron();
  Eigen::Isometry3d X_WM = Eigen::Isometry3d::Identity();
  X_WM.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  X_WM.translation() = Eigen::Vector3d(0.1, -0.2, 0.3);
  const TriangleMesh w = transformed(m, X_WM);
  EXPECT_NEAR(surface_area(w), surface_area(m), 1e-14);
  const Points3 Nm = triangle_normals(m);
  const Points3 Nw = triangle_normals(w);
  for (int t = 0; t < 4; ++t) {
    EXPECT_NEAR((Nw.row(t).transpose() - X_WM.linear() * Nm.row(t).transpose()).norm(), 0.0, 1e-14);
  }
  EXPECT_NEAR((w.vertex(0) - X_WM.translation()).norm(), 0.0, 1e-15);
  EXPECT_EQ(w.F, m.F);
}

TEST(Mesh, BoundingBox) {
  const BoundingBox b = bounding_box(tetrahedron());
  EXPECT_EQ(b.lo, Vec3(0, 0, 0));
  EXPECT_EQ(b.hi, Vec3(1, 1, 1));
  EXPECT_DOUBLE_EQ(b.diagonal(), std::sqrt(3.0));
  EXPECT_FALSE(b.empty());
  EXPECT_TRUE(bounding_box(Points3(0, 3)).empty());
}

}  // namespace
}  // namespace arthrosim::common
