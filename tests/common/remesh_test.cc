// Isotropic remeshing: edge lengths near the target, boundary outline kept,
// area kept, valid output, determinism.
#include "common/remesh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "common/error.h"
#include "common/mesh_validation.h"
#include "tests/common/test_meshes.h"

namespace arthrosim::common {
namespace {

struct Boundary {
  std::vector<std::array<int, 2>> edges;
  std::vector<int> vertices;
  double length = 0.0;
};

Boundary boundary_of(const TriangleMesh& m) {
  const MeshTopology topo = build_topology(m);
  Boundary b;
  for (Eigen::Index e = 0; e < topo.edges.rows(); ++e) {
    if (topo.edge_triangles[e].size() != 1) continue;
    b.edges.push_back({topo.edges(e, 0), topo.edges(e, 1)});
    b.length += (m.V.row(topo.edges(e, 0)) - m.V.row(topo.edges(e, 1))).norm();
  }
  b.vertices = topo.boundary_vertices;
  return b;
}

double distance_to_polyline(const Vec3& p, const TriangleMesh& m, const Boundary& b) {
  double best = INFINITY;
  for (const auto& e : b.edges) {
    const Vec3 a = m.vertex(e[0]), c = m.vertex(e[1]);
    const double s = std::clamp((p - a).dot(c - a) / (c - a).squaredNorm(), 0.0, 1.0);
    best = std::min(best, (p - (a + s * (c - a))).norm());
  }
  return best;
}

// A coarse, open, curved patch 20 x 15 mm with a 2 mm bump: 4 x 3 quads, edges 5 mm.
TriangleMesh coarse_patch() { return testing::curved_patch(4, 3, 0.02, 0.015, 0.002); }

TEST(Remesh, OpenPatchReachesTargetAndKeepsItsOutline) {
  const TriangleMesh in = coarse_patch();
  RemeshOptions opt;
  opt.target_edge_length = 1e-3;
  RemeshStatistics st;
  const TriangleMesh out = isotropic_remesh(in, opt, &st);
  std::printf("[patch] %d -> %d triangles, edges mean %.4g mm (min %.4g, max %.4g), target 1 mm\n",
              st.input_triangles, st.output_triangles, st.mean_edge_length * 1e3, st.min_edge_length * 1e3,
              st.max_edge_length * 1e3);
  // CGAL aims at [0.8, 1.33] x target; the mean lies within 20 % of it.
  EXPECT_NEAR(st.mean_edge_length, opt.target_edge_length, 0.2 * opt.target_edge_length);
  EXPECT_LE(st.max_edge_length, 4.0 / 3.0 * opt.target_edge_length * 1.05);
  EXPECT_GT(st.output_triangles, 20 * st.input_triangles);

  // Output is a valid open mesh with one boundary loop, same orientation (+z).
  const ValidationReport r = validate(out);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_GT(triangle_normals(out).col(2).minCoeff(), 0.0);

  // Outline preserved exactly: every input boundary vertex is still there
  // (bit-identical), every output boundary vertex lies on the input outline,
  // and the outline length is unchanged (splitting a straight segment at
  // midpoints keeps its length up to rounding, 1e-12 relative).
  const Boundary bin = boundary_of(in), bout = boundary_of(out);
  for (int v : bin.vertices) {
    bool found = false;
    for (int w : bout.vertices) found = found || (out.V.row(w) == in.V.row(v));
    EXPECT_TRUE(found) << "input boundary vertex " << v << " lost";
  }
  double worst = 0.0;
  for (int w : bout.vertices) worst = std::max(worst, distance_to_polyline(out.vertex(w), in, bin));
  EXPECT_LT(worst, 1e-15);
  EXPECT_NEAR(bout.length, bin.length, 1e-12 * bin.length);

  // Area: new vertices are projected onto the faceted input, so the output is
  // inscribed in it and cuts the creases between input facets (crease angles
  // here are <= ~20 degrees, 5 mm facets): measured loss well below 1 %.
  const double a_in = surface_area(in), a_out = surface_area(out);
  std::printf("[patch] area %.6g -> %.6g mm^2 (relative change %.3g)\n", a_in * 1e6, a_out * 1e6,
              (a_out - a_in) / a_in);
  EXPECT_NEAR(a_out, a_in, 0.01 * a_in);
}

TEST(Remesh, ClosedSphereStaysClosedAndOnTheInputSurface) {
  const double radius = 0.03;
  const TriangleMesh in = testing::icosphere(2, radius);  // 320 triangles, edges ~8 mm
  RemeshOptions opt;
  opt.target_edge_length = 2e-3;
  RemeshStatistics st;
  const TriangleMesh out = isotropic_remesh(in, opt, &st);
  std::printf("[sphere] %d -> %d triangles, edges mean %.4g mm (min %.4g, max %.4g), target 2 mm\n",
              st.input_triangles, st.output_triangles, st.mean_edge_length * 1e3, st.min_edge_length * 1e3,
              st.max_edge_length * 1e3);
  EXPECT_NEAR(st.mean_edge_length, opt.target_edge_length, 0.2 * opt.target_edge_length);
  ValidationOptions closed;
  closed.require_closed = true;
  const ValidationReport r = validate(out, closed);
  EXPECT_TRUE(r.ok()) << r.summary();
  // Vertices lie on the input facets: inside the circumscribed sphere, outside
  // the sphere through the facets' closest points (r * cos of the facet
  // circumradius angle; level-2 facets: >= 0.98 r).
  const Eigen::VectorXd rad = out.V.rowwise().norm();
  EXPECT_LE(rad.maxCoeff(), radius * (1 + 1e-12));
  EXPECT_GE(rad.minCoeff(), 0.98 * radius);
  const double a_in = surface_area(in), a_out = surface_area(out);
  std::printf("[sphere] area %.6g -> %.6g mm^2 (relative change %.3g)\n", a_in * 1e6, a_out * 1e6,
              (a_out - a_in) / a_in);
  EXPECT_NEAR(a_out, a_in, 0.01 * a_in);
  // Outward orientation kept: positive enclosed volume.
  double vol6 = 0.0;
  for (int t = 0; t < out.num_triangles(); ++t)
    vol6 += out.vertex(out.F(t, 0)).dot(out.vertex(out.F(t, 1)).cross(out.vertex(out.F(t, 2))));
  EXPECT_GT(vol6, 0.0);
}

// A closed 10 mm cube (12 triangles) remeshed at 2 mm.
TriangleMesh cube() {
  TriangleMesh m;
  m.V.resize(8, 3);
  const double a = 0.005;
  m.V << -a, -a, -a, a, -a, -a, a, a, -a, -a, a, -a, -a, -a, a, a, -a, a, a, a, a, -a, a, a;
  m.F.resize(12, 3);
  m.F << 0, 2, 1, 0, 3, 2,  // bottom (-z)
      4, 5, 6, 4, 6, 7,     // top (+z)
      0, 1, 5, 0, 5, 4,     // -y
      1, 2, 6, 1, 6, 5,     // +x
      2, 3, 7, 2, 7, 6,     // +y
      3, 0, 4, 3, 4, 7;     // -x
  m.name = "cube";
  return m;
}

double volume(const TriangleMesh& m) {
  double v6 = 0.0;
  for (int t = 0; t < m.num_triangles(); ++t)
    v6 += m.vertex(m.F(t, 0)).dot(m.vertex(m.F(t, 1)).cross(m.vertex(m.F(t, 2))));
  return v6 / 6.0;
}

TEST(Remesh, FeatureAngleKeepsSharpEdges) {
  const TriangleMesh in = cube();
  ASSERT_NEAR(volume(in), 1e-6, 1e-20);
  RemeshOptions opt;
  opt.target_edge_length = 2e-3;
  opt.feature_angle = 30.0 * M_PI / 180.0;
  const TriangleMesh out = isotropic_remesh(in, opt);
  ValidationOptions closed;
  closed.require_closed = true;
  EXPECT_TRUE(validate(out, closed).ok()) << validate(out, closed).summary();
  // All 8 corners survive bit-identically, every vertex stays on the cube
  // surface (max-norm = a), and the volume is that of the cube up to rounding
  // (all faces planar, edges kept).
  for (int c = 0; c < 8; ++c) {
    bool found = false;
    for (int v = 0; v < out.num_vertices(); ++v) found = found || out.V.row(v) == in.V.row(c);
    EXPECT_TRUE(found) << "corner " << c;
  }
  EXPECT_LT((out.V.cwiseAbs().rowwise().maxCoeff().array() - 0.005).abs().maxCoeff(), 1e-15);
  EXPECT_NEAR(volume(out), 1e-6, 1e-18);
  const RemeshStatistics st = edge_length_statistics(out);
  std::printf("[cube] %d triangles, edges mean %.4g mm, volume %.9g mm^3\n", out.num_triangles(),
              st.mean_edge_length * 1e3, volume(out) * 1e9);
  EXPECT_NEAR(st.mean_edge_length, opt.target_edge_length, 0.2 * opt.target_edge_length);
  // Without feature edges the remesher cuts the cube's edges: volume is lost.
  opt.feature_angle = 0.0;
  const TriangleMesh rounded = isotropic_remesh(in, opt);
  std::printf("[cube] without features: volume %.9g mm^3\n", volume(rounded) * 1e9);
  EXPECT_LT(volume(rounded), 0.999e-6);
  opt.feature_angle = -1.0;
  EXPECT_THROW(isotropic_remesh(in, opt), InputError);
}

TEST(Remesh, IsDeterministic) {
  RemeshOptions opt;
  opt.target_edge_length = 1.5e-3;
  const TriangleMesh a = isotropic_remesh(coarse_patch(), opt);
  const TriangleMesh b = isotropic_remesh(coarse_patch(), opt);
  EXPECT_EQ(a.V, b.V);  // bit-identical
  EXPECT_EQ(a.F, b.F);
}

TEST(Remesh, UnprotectedBoundaryStaysOnTheOutline) {
  RemeshOptions opt;
  opt.target_edge_length = 1e-3;
  opt.protect_boundary = false;
  const TriangleMesh in = coarse_patch();
  const TriangleMesh out = isotropic_remesh(in, opt);
  EXPECT_TRUE(validate(out).ok());
  const Boundary bin = boundary_of(in), bout = boundary_of(out);
  double worst = 0.0;
  for (int w : bout.vertices) worst = std::max(worst, distance_to_polyline(out.vertex(w), in, bin));
  EXPECT_LT(worst, 1e-15);
}

// The triangle-count estimate made before remeshing (prepare refuses beyond
// a limit): within 0.7-1.6 x the real count on the patch and the sphere at
// two targets; it grows as 1/L^2.
TEST(Remesh, TriangleEstimateIsCloseToTheRealCount) {
  for (const TriangleMesh& in : {coarse_patch(), testing::icosphere(2, 0.03)})
    for (const double L : {2e-3, 1e-3}) {
      RemeshOptions opt;
      opt.target_edge_length = L;
      const double estimate = estimate_remesh_triangles(in, L);
      const int real = isotropic_remesh(in, opt).num_triangles();
      std::printf("[estimate] %d input triangles at %.0f mm: estimate %.0f, real %d (ratio %.2f)\n",
                  in.num_triangles(), L * 1e3, estimate, real, real / estimate);
      EXPECT_GT(real, 0.7 * estimate);
      EXPECT_LT(real, 1.6 * estimate);
    }
  // A mesh with one far vertex (2e3 m away): the estimate is beyond the
  // default limit of prepare (1e6), computed without remeshing.
  TriangleMesh far = coarse_patch();
  far.V(0, 0) = 2e3;
  EXPECT_GT(estimate_remesh_triangles(far, 1e-3), 1e6);
}

TEST(Remesh, RejectsBadInputWithReasons) {
  RemeshOptions opt;
  opt.target_edge_length = 0.0;
  EXPECT_THROW(isotropic_remesh(coarse_patch(), opt), InputError);
  // Non-manifold edge: refused with the validation summary.
  TriangleMesh m;
  m.V.resize(5, 3);
  m.V << 0, 0, 0, 0, 0, 1, 1, 0, 0, 0, 1, 0, -1, -1, 0;
  m.F.resize(3, 3);
  m.F << 0, 1, 2, 0, 1, 3, 1, 0, 4;
  m.name = "book.stl";
  opt.target_edge_length = 0.3;
  try {
    isotropic_remesh(m, opt);
    ADD_FAILURE();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("book.stl: error:"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("non-manifold edges"), std::string::npos) << e.what();
  }
  // Two triangles touching at one vertex (a bow tie: manifold edges, one
  // non-manifold vertex) are accepted by CGAL's Surface_mesh; remeshing keeps
  // each flat fan with its outline, so the area is unchanged up to rounding.
  TriangleMesh bow;
  bow.V.resize(5, 3);
  bow.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, -1, 0, 0, -1, -1, 0;
  bow.F.resize(2, 3);
  bow.F << 0, 1, 2, 0, 3, 4;
  const TriangleMesh out = isotropic_remesh(bow, opt);
  EXPECT_GT(out.num_triangles(), 2);
  EXPECT_TRUE(validate(out).ok()) << validate(out).summary();
  EXPECT_NEAR(surface_area(out), surface_area(bow), 1e-12);
}

}  // namespace
}  // namespace arthrosim::common
