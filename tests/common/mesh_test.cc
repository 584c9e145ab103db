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

TEST(Mesh, ConnectedComponentsAndSubmesh) {
  // A tetrahedron (4 triangles) and a square (2 triangles) in one mesh, the
  // square's triangles listed first; plus a triangle touching the square at
  // one vertex only (not edge-connected: its own component).
  const TriangleMesh tet = tetrahedron(), sq = unit_square();
  TriangleMesh m;
  m.V.resize(tet.num_vertices() + sq.num_vertices() + 2, 3);
  m.V << sq.V, tet.V, Eigen::RowVector3d(2, 2, 0), Eigen::RowVector3d(2, 1, 0);
  m.F.resize(sq.num_triangles() + tet.num_triangles() + 1, 3);
  m.F << sq.F, (tet.F.array() + sq.num_vertices()).matrix(), Eigen::RowVector3i(2, 9, 8);
  int count = 0;
  const std::vector<int> c = connected_components(m, &count);
  EXPECT_EQ(count, 3);
  EXPECT_EQ(c, (std::vector<int>{0, 0, 1, 1, 1, 1, 2}));
  const TriangleMesh t = submesh(m, {2, 3, 4, 5});
  EXPECT_EQ(t.num_vertices(), 4);
  EXPECT_EQ(t.num_triangles(), 4);
  EXPECT_NEAR(surface_area(t), surface_area(tet), 1e-15);
  // Vertices renumbered in order of first use, triangles kept in the order given.
  const TriangleMesh one = submesh(m, {6});
  EXPECT_EQ(one.F, (Triangles(1, 3) << 0, 1, 2).finished());
  EXPECT_EQ(one.V.row(0), m.V.row(2));
  EXPECT_THROW(submesh(m, {7}), InputError);
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

TEST(Mesh, QuadNormalsAndAreas) {
  QuadMesh q;
  q.V.resize(8, 3);
  // A planar trapezoid (bases 2 and 1, height 1: area 1.5) and a warped quad
  // (hyperbolic paraboloid z = h x y over the unit square).
  const double h = 0.5;
  q.V << 0, 0, 0, 2, 0, 0, 1.5, 1, 0, 0.5, 1, 0,  //
      0, 0, 0, 1, 0, 0, 1, 1, h, 0, 1, 0;
  q.Q.resize(2, 4);
  q.Q << 0, 1, 2, 3, 4, 5, 6, 7;
  const Points3 N = quad_normals(q);
  const Eigen::VectorXd A = quad_areas(q);
  EXPECT_NEAR((N.row(0) - Eigen::RowVector3d(0, 0, 1)).norm(), 0.0, 1e-15);
  EXPECT_NEAR(A(0), 1.5, 1e-15);
  // Warped: x_u x x_v = (-h y, -h x, 1); at the centre the normal is
  // (-h/2, -h/2, 1)/|.|. Area = integral of sqrt(1 + h^2 (x^2 + y^2)) over the
  // unit square; for h = 0.5 a fine midpoint rule gives 1.0787...; 2x2 Gauss
  // is accurate to ~1e-4 for this smooth integrand.
  const Vec3 n_exact = Vec3(-h / 2, -h / 2, 1).normalized();
  EXPECT_NEAR((N.row(1).transpose() - n_exact).norm(), 0.0, 1e-15);
  double ref = 0.0;
  const int m = 2000;
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j) {
      const double x = (i + 0.5) / m, y = (j + 0.5) / m;
      ref += std::sqrt(1 + h * h * (x * x + y * y)) / (double(m) * m);
    }
  EXPECT_NEAR(A(1), ref, 2e-4);
}

TEST(Mesh, BoundaryNodesOfQuadMesh) {
  // A 2 x 1 strip of quads: every node is on the boundary. The split
  // tetrahedron is closed: no boundary node.
  QuadMesh strip;
  strip.V.resize(6, 3);
  strip.V << 0, 0, 0, 1, 0, 0, 2, 0, 0, 0, 1, 0, 1, 1, 0, 2, 1, 0;
  strip.Q.resize(2, 4);
  strip.Q << 0, 1, 4, 3, 1, 2, 5, 4;
  EXPECT_EQ(boundary_nodes(strip), (std::vector<int>{0, 1, 2, 3, 4, 5}));
  EXPECT_TRUE(boundary_nodes(split_triangles_to_quads(tetrahedron())).empty());
  // The split unit square: boundary = 4 corners + 4 edge midpoints; the
  // diagonal midpoint and the 2 centroids are interior.
  const QuadMesh sq = split_triangles_to_quads(unit_square());
  EXPECT_EQ(boundary_nodes(sq).size(), 8u);
}

TEST(Mesh, BoundaryLoopsFollowOrientation) {
  // Unit square (normal +z): loop counter-clockwise seen from +z, from vertex 0.
  const auto loops = boundary_loops(unit_square());
  ASSERT_EQ(loops.size(), 1u);
  EXPECT_EQ(loops[0], (std::vector<int>{0, 1, 2, 3}));
  EXPECT_TRUE(boundary_loops(tetrahedron()).empty());
  // An annulus-like mesh (square with a square hole) has two loops; the inner
  // one runs clockwise seen from +z (surface on its left).
  TriangleMesh ring;
  ring.V.resize(8, 3);
  ring.V << 0, 0, 0, 3, 0, 0, 3, 3, 0, 0, 3, 0, 1, 1, 0, 2, 1, 0, 2, 2, 0, 1, 2, 0;
  ring.F.resize(8, 3);
  ring.F << 0, 1, 5, 0, 5, 4, 1, 2, 6, 1, 6, 5, 2, 3, 7, 2, 7, 6, 3, 0, 4, 3, 4, 7;
  const auto rl = boundary_loops(ring);
  ASSERT_EQ(rl.size(), 2u);
  EXPECT_EQ(rl[0], (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(rl[1], (std::vector<int>{4, 7, 6, 5}));
  // Two triangles touching at one vertex (a bow tie): not a simple boundary.
  TriangleMesh bow;
  bow.V.resize(5, 3);
  bow.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, -1, 0, 0, -1, -1, 0;
  bow.F.resize(2, 3);
  bow.F << 0, 1, 2, 0, 3, 4;
  EXPECT_THROW(boundary_loops(bow), InputError);
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
