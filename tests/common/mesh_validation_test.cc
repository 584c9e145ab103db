// Validation on crafted bad meshes (exact counts and first indices) and the
// safe repairs.
#include "common/mesh_validation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "common/error.h"
#include "common/mesh_io.h"
#include "tests/common/test_meshes.h"

namespace arthrosim::common {
namespace {

TriangleMesh sphere() { return testing::perturbed_sphere(2, 0.03, 0.05, 7); }  // 320 triangles, closed

double signed_volume(const TriangleMesh& m) {
  double v = 0.0;
  for (int t = 0; t < m.num_triangles(); ++t)
    v += m.vertex(m.F(t, 0)).dot(m.vertex(m.F(t, 1)).cross(m.vertex(m.F(t, 2)))) / 6.0;
  return v;
}

TEST(MeshValidation, CleanClosedMeshHasNoProblems) {
  ValidationOptions closed;
  closed.require_closed = true;
  const ValidationReport r = validate(sphere(), closed);
  EXPECT_TRUE(r.ok());
  EXPECT_FALSE(r.has_warnings());
  EXPECT_NE(r.summary().find("no problems found"), std::string::npos);
  EXPECT_NO_THROW(validate_or_throw(sphere(), closed));
}

TEST(MeshValidation, OpenBoundaryIsAnErrorOnlyWhenClosedIsRequired) {
  const TriangleMesh patch = testing::curved_patch(4, 3, 0.02, 0.015, 0.002);
  // 4 x 3 grid: boundary = 2 * (4 + 3) = 14 edges.
  const ValidationReport open = validate(patch);
  EXPECT_TRUE(open.ok());
  EXPECT_TRUE(open.has_warnings());
  EXPECT_EQ(open.boundary_edges.count, 14);
  ValidationOptions closed;
  closed.require_closed = true;
  const ValidationReport r = validate(patch, closed);
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(r.boundary_edges.count, 14);
  ASSERT_EQ(r.boundary_edges.first.size(), 5u);
  EXPECT_EQ(r.boundary_edges.first[0], (std::array<int, 2>{0, 1}));
  EXPECT_EQ(r.boundary_edges.first[1], (std::array<int, 2>{0, 5}));
  EXPECT_NE(r.summary().find("error: 14 open boundary edges (a closed surface is required), first: edges (0,1), (0,5)"),
            std::string::npos)
      << r.summary();
}

TEST(MeshValidation, EachDefectIsCountedWithFirstIndices) {
  TriangleMesh m = sphere();
  const int nv = m.num_vertices(), nt = m.num_triangles();
  // NaN at vertex 11, Inf at vertex 3.
  m.V(11, 2) = std::nan("");
  m.V(3, 0) = INFINITY;
  // Append: a repeated-index triangle, a zero-area (collinear) triangle on new
  // vertices, a duplicate of triangle 5 (reversed), an out-of-range triangle,
  // an unreferenced vertex, and a flipped copy of nothing (handled below).
  m.V.conservativeResize(nv + 4, 3);
  m.V.row(nv) << 1, 0, 0;
  m.V.row(nv + 1) << 2, 0, 0;
  m.V.row(nv + 2) << 3, 0, 0;       // collinear with the two above
  m.V.row(nv + 3) << 9, 9, 9;       // unreferenced
  m.F.conservativeResize(nt + 4, 3);
  m.F.row(nt) << 0, 1, 1;                      // repeated index
  m.F.row(nt + 1) << nv, nv + 1, nv + 2;       // zero area
  m.F.row(nt + 2) << m.F(5, 0), m.F(5, 2), m.F(5, 1);  // duplicate of 5 (same set)
  m.F.row(nt + 3) << 0, 1, nv + 100;           // out of range
  m.name = "crafted.stl";
  const ValidationReport r = validate(m);
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(r.non_finite_vertices.count, 2);
  EXPECT_EQ(r.non_finite_vertices.first, (std::vector<int>{3, 11}));
  EXPECT_EQ(r.degenerate_triangles.count, 2);
  EXPECT_EQ(r.degenerate_triangles.first, (std::vector<int>{nt, nt + 1}));
  EXPECT_EQ(r.duplicate_triangles.count, 1);
  EXPECT_EQ(r.duplicate_triangles.first, (std::vector<int>{nt + 2}));
  EXPECT_EQ(r.invalid_index_triangles.count, 1);
  EXPECT_EQ(r.invalid_index_triangles.first, (std::vector<int>{nt + 3}));
  EXPECT_EQ(r.unreferenced_vertices.count, 1);
  EXPECT_EQ(r.unreferenced_vertices.first, (std::vector<int>{nv + 3}));
  // The reversed duplicate shares its 3 edges with triangle 5 and 5's
  // neighbours: each of those edges now has 3 triangles.
  EXPECT_EQ(r.non_manifold_edges.count, 3);
  // The zero-area triangle is open on its own (3 boundary edges), not closed.
  EXPECT_EQ(r.boundary_edges.count, 3);
  // The message names the file and every category.
  try {
    throw_if_invalid(r);
    ADD_FAILURE();
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_EQ(what.rfind("crafted.stl: error: expected a valid triangle mesh", 0), 0u) << what;
    for (const char* frag : {"2 vertices with NaN/Inf coordinates, first: vertices 3, 11",
                             "2 degenerate triangles", "1 duplicate triangles", "3 non-manifold edges",
                             "1 triangles with a vertex index outside", "warning: 1 unreferenced vertices"})
      EXPECT_NE(what.find(frag), std::string::npos) << frag << "\n" << what;
  }
}

TEST(MeshValidation, InconsistentOrientationIsReportedPerEdge) {
  TriangleMesh m = sphere();
  const MeshTopology topo = build_topology(m);
  // Flip triangle 7: its 3 edges are now traversed in the same direction by
  // it and by each neighbour.
  std::swap(m.F(7, 1), m.F(7, 2));
  ValidationReport r = validate(m);
  EXPECT_EQ(r.inconsistent_edges.count, 3);
  EXPECT_FALSE(r.ok());
  // Flip two neighbouring triangles: their shared edge is consistent again, 4 remain.
  std::swap(m.F(topo.triangle_neighbours(7, 0), 1), m.F(topo.triangle_neighbours(7, 0), 2));
  r = validate(m);
  EXPECT_EQ(r.inconsistent_edges.count, 4);
}

TEST(MeshValidation, NearZeroAreaUsesRelativeTolerance) {
  TriangleMesh m;
  m.V.resize(3, 3);
  // Height 1e-12 over a base of 1e-3 (relative 1e-9): above the default 1e-10.
  m.V << 0, 0, 0, 1e-3, 0, 0, 0.5e-3, 1e-12, 0;
  m.F.resize(1, 3);
  m.F << 0, 1, 2;
  EXPECT_EQ(validate(m).degenerate_triangles.count, 0);
  ValidationOptions strict;
  strict.degenerate_relative_tolerance = 1e-8;
  EXPECT_EQ(validate(m, strict).degenerate_triangles.count, 1);
  // The same shape scaled by 1e3 is judged the same (scale free).
  m.V *= 1e3;
  EXPECT_EQ(validate(m, strict).degenerate_triangles.count, 1);
}

TEST(MeshValidation, RepairWeldsTriangleSoupBackIntoTheClosedMesh) {
  // An unwelded STL-like soup: 3 vertices per triangle, plus tiny noise (1e-12 m)
  // below the merge tolerance.
  const TriangleMesh ref = sphere();
  TriangleMesh soup;
  soup.V.resize(3 * ref.num_triangles(), 3);
  soup.F.resize(ref.num_triangles(), 3);
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-1e-12, 1e-12);
  for (int t = 0; t < ref.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      soup.V.row(3 * t + k) = ref.V.row(ref.F(t, k)) + Eigen::RowVector3d(u(rng), u(rng), u(rng));
      soup.F(t, k) = 3 * t + k;
    }
  ValidationOptions closed;
  closed.require_closed = true;
  EXPECT_FALSE(validate(soup, closed).ok());
  const RepairResult fixed = repair(soup);
  EXPECT_EQ(fixed.report.merged_vertices, 3 * ref.num_triangles() - ref.num_vertices());
  EXPECT_EQ(fixed.mesh.num_vertices(), ref.num_vertices());
  EXPECT_EQ(fixed.mesh.num_triangles(), ref.num_triangles());
  EXPECT_EQ(fixed.report.flipped_triangles, 0);
  EXPECT_EQ(fixed.report.components, 1);
  EXPECT_TRUE(validate(fixed.mesh, closed).ok()) << validate(fixed.mesh, closed).summary();
  // 320 triangles * 3 corners - 162 sphere vertices = 798 merged.
  EXPECT_NE(fixed.report.summary().find("merged 798 duplicate vertices"), std::string::npos) << fixed.report.summary();
  // Exact merging only (tolerance 0) leaves the noisy soup unwelded.
  RepairOptions exact;
  exact.merge_tolerance = 0.0;
  EXPECT_EQ(repair(soup, exact).report.merged_vertices, 0);
}

// Vertex merging far from the origin (issue 30: coordinates beyond ~1e5 mm
// overflowed the signed grid-cell arithmetic of the merge, undefined
// behaviour that UBSan reports). The same soup shifted to 2e3 m (one
// flipped exponent bit in a millimetre file), to 1e13 m (beyond the int64
// range of cells of 1 nm), and with one vertex alone at 2e6 m, must weld
// exactly as at the origin: merging compares true distances, so the cell
// arithmetic decides only which candidates are compared.
TEST(MeshValidation, RepairMergesVerticesFarFromTheOrigin) {
  const TriangleMesh ref = sphere();
  TriangleMesh soup;
  soup.V.resize(3 * ref.num_triangles(), 3);
  soup.F.resize(ref.num_triangles(), 3);
  for (int t = 0; t < ref.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      soup.V.row(3 * t + k) = ref.V.row(ref.F(t, k));
      soup.F(t, k) = 3 * t + k;
    }
  const int merged = 3 * ref.num_triangles() - ref.num_vertices();
  for (const double shift : {0.0, 2e3, -2e3, 1e13}) {
    SCOPED_TRACE("shift " + std::to_string(shift) + " m");
    TriangleMesh m = soup;
    m.V.col(0).array() += shift;
    // Merge tolerance 1 nm is below the double spacing at 1e13 m (2 mm):
    // only exact duplicates can merge there, which is all a soup has.
    const RepairResult r = repair(m);
    EXPECT_EQ(r.report.merged_vertices, merged);
    EXPECT_EQ(r.mesh.num_vertices(), ref.num_vertices());
  }
  // One corrupted vertex far away (a separate triangle): the rest still welds.
  TriangleMesh far = soup;
  const int n = far.num_vertices();
  far.V.conservativeResize(n + 3, 3);
  far.V.row(n) << 2e6, 0, 0;
  far.V.row(n + 1) << 2e6, 1e-3, 0;
  far.V.row(n + 2) << 2e6, 0, 1e-3;
  far.F.conservativeResize(far.num_triangles() + 1, 3);
  far.F.row(far.num_triangles() - 1) << n, n + 1, n + 2;
  const RepairResult r = repair(far);
  EXPECT_EQ(r.report.merged_vertices, merged);
  EXPECT_EQ(r.mesh.num_vertices(), ref.num_vertices() + 3);
  // Coordinates near the largest double: no overflow, nothing merged wrongly.
  TriangleMesh huge = soup;
  huge.V.row(0) << 1.7e308, -1.7e308, 1e300;
  const RepairResult h = repair(huge);
  EXPECT_EQ(h.report.merged_vertices, merged - 1);  // soup vertex 0 no longer duplicates its twins
}

TEST(MeshValidation, RepairOrientsClosedComponentsOutward) {
  const TriangleMesh ref = sphere();
  std::mt19937_64 rng(2);
  for (double fraction : {0.3, 0.7, 1.0}) {
    TriangleMesh m = ref;
    int flipped = 0;
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int t = 0; t < m.num_triangles(); ++t) {
      if (u(rng) < fraction) {
        std::swap(m.F(t, 1), m.F(t, 2));
        ++flipped;
      }
    }
    const RepairResult r = repair(m);
    // Closed: the outward orientation is restored whatever the majority was.
    EXPECT_EQ(r.report.flipped_triangles, flipped) << fraction;
    EXPECT_EQ(r.mesh.F, ref.F);
    EXPECT_GT(signed_volume(r.mesh), 0.0);
    EXPECT_EQ(validate(r.mesh).inconsistent_edges.count, 0);
  }
}

TEST(MeshValidation, RepairKeepsMajorityOrientationOfOpenPatches) {
  const TriangleMesh ref = testing::curved_patch(6, 6, 0.02, 0.02, 0.003);  // 72 triangles
  TriangleMesh m = ref;
  for (int t : {0, 5, 17, 40}) std::swap(m.F(t, 1), m.F(t, 2));
  const RepairResult r = repair(m);
  EXPECT_EQ(r.report.flipped_triangles, 4);
  EXPECT_EQ(r.mesh.F, ref.F);
  // Flip all: the majority is now "down", so that is what is kept (an open
  // patch has no inside; the caller decides its side).
  TriangleMesh all = ref;
  for (int t = 0; t < all.num_triangles(); ++t) std::swap(all.F(t, 1), all.F(t, 2));
  EXPECT_EQ(repair(all).report.flipped_triangles, 0);
}

TEST(MeshValidation, RepairDropsDegenerateDuplicateAndUnreferenced) {
  TriangleMesh m = sphere();
  const int nv = m.num_vertices(), nt = m.num_triangles();
  m.V.conservativeResize(nv + 2, 3);
  m.V.row(nv) = m.V.row(4);  // exact duplicate of vertex 4 (merged)
  m.V.row(nv + 1) << 1, 1, 1;  // unreferenced
  m.F.conservativeResize(nt + 3, 3);
  m.F.row(nt) << 4, nv, 9;               // degenerate after merging nv -> 4
  m.F.row(nt + 1) = m.F.row(10);         // duplicate
  m.F.row(nt + 2) << m.F(20, 2), m.F(20, 0), m.F(20, 1);  // duplicate (rotated)
  const RepairResult r = repair(m);
  EXPECT_EQ(r.report.merged_vertices, 1);
  EXPECT_EQ(r.report.removed_degenerate, 1);
  EXPECT_EQ(r.report.removed_duplicate, 2);
  EXPECT_EQ(r.report.removed_unreferenced, 1);
  EXPECT_EQ(r.report.flipped_triangles, 0);
  EXPECT_TRUE(r.report.changed());
  EXPECT_EQ(r.mesh.V, sphere().V);
  EXPECT_EQ(r.mesh.F, sphere().F);
  EXPECT_EQ(r.report.vertex_map[nv], 4);
  EXPECT_EQ(r.report.vertex_map[nv + 1], -1);
  EXPECT_EQ(static_cast<int>(r.report.triangle_source.size()), nt);
  // A clean mesh is left alone and says so.
  const RepairResult clean = repair(sphere());
  EXPECT_FALSE(clean.report.changed());
  EXPECT_EQ(clean.report.summary(), "no repair needed");
}

TEST(MeshValidation, NonManifoldIsReportedNotRepaired) {
  // Three triangles sharing edge (0,1): a "book" with three pages.
  TriangleMesh m;
  m.V.resize(5, 3);
  m.V << 0, 0, 0, 0, 0, 1, 1, 0, 0, 0, 1, 0, -1, -1, 0;
  m.F.resize(3, 3);
  m.F << 0, 1, 2, 0, 1, 3, 1, 0, 4;
  m.name = "book";
  const ValidationReport before = validate(m);
  EXPECT_EQ(before.non_manifold_edges.count, 1);
  EXPECT_EQ(before.non_manifold_edges.first[0], (std::array<int, 2>{0, 1}));
  const RepairResult r = repair(m);
  EXPECT_EQ(r.mesh.F, m.F);  // untouched: no manifold edge to orient across
  EXPECT_EQ(validate(r.mesh).non_manifold_edges.count, 1);
  EXPECT_THROW(validate_or_throw(r.mesh), InputError);
}

TEST(MeshValidation, NonManifoldVertexIsAWarning) {
  // Two triangles touching at vertex 0 (a bow tie), and two tetrahedra sharing
  // one vertex: both have manifold edges but a vertex with two fans.
  TriangleMesh bow;
  bow.V.resize(5, 3);
  bow.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, -1, 0, 0, -1, -1, 0;
  bow.F.resize(2, 3);
  bow.F << 0, 1, 2, 0, 3, 4;
  ValidationReport r = validate(bow);
  EXPECT_TRUE(r.ok());
  EXPECT_TRUE(r.has_warnings());
  EXPECT_EQ(r.non_manifold_vertices.count, 1);
  EXPECT_EQ(r.non_manifold_vertices.first, std::vector<int>{0});
  EXPECT_NE(r.summary().find("warning: 1 non-manifold vertices"), std::string::npos) << r.summary();
  TriangleMesh two;
  two.V.resize(7, 3);
  two.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, -1, 0, 0, 0, -1, 0, 0, 0, -1;
  two.F.resize(8, 3);
  two.F << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3,  // tetrahedron (0,1,2,3)
      0, 5, 4, 0, 4, 6, 0, 6, 5, 4, 5, 6;       // tetrahedron (0,4,5,6)
  ValidationOptions closed;
  closed.require_closed = true;
  r = validate(two, closed);
  EXPECT_EQ(r.non_manifold_vertices.count, 1);
  EXPECT_EQ(r.non_manifold_edges.count, 0);
  EXPECT_EQ(r.boundary_edges.count, 0);
  EXPECT_EQ(r.inconsistent_edges.count, 0);
  // A clean closed mesh has none.
  EXPECT_EQ(validate(sphere()).non_manifold_vertices.count, 0);
}

TEST(MeshValidation, MobiusStripIsLeftUnchangedAsUnorientable) {
  // A Mobius strip: 10 quads around a loop with a half twist (20 triangles).
  const int n = 10;
  TriangleMesh m;
  m.V.resize(2 * n, 3);
  for (int i = 0; i < n; ++i) {
    const double phi = 2 * M_PI * i / n, tw = phi / 2;
    for (int s = 0; s < 2; ++s) {
      const double w = s ? 0.2 : -0.2;
      m.V.row(2 * i + s) << (1 + w * std::cos(tw)) * std::cos(phi), (1 + w * std::cos(tw)) * std::sin(phi),
          w * std::sin(tw);
    }
  }
  m.F.resize(2 * n, 3);
  for (int i = 0; i < n; ++i) {
    const int a = 2 * i, b = 2 * i + 1;
    // The last quad connects to the first with the strip's sides swapped.
    const int c = i + 1 < n ? 2 * (i + 1) + 1 : 0, d = i + 1 < n ? 2 * (i + 1) : 1;
    m.F.row(2 * i) << a, d, c;
    m.F.row(2 * i + 1) << a, c, b;
  }
  EXPECT_GT(validate(m).inconsistent_edges.count, 0);
  const RepairResult r = repair(m);
  EXPECT_EQ(r.report.unorientable_components, 1);
  EXPECT_EQ(r.report.flipped_triangles, 0);
  EXPECT_EQ(r.mesh.F, m.F);
  EXPECT_NE(r.report.summary().find("non-orientable"), std::string::npos);
}

TEST(MeshValidation, RepairRejectsOutOfRangeIndices) {
  TriangleMesh m = sphere();
  m.F(3, 1) = -2;
  EXPECT_THROW(repair(m), InputError);
}

TEST(MeshValidation, ReadRepairValidateUnweldedStl) {
  // The usual user path: read an STL without welding, repair, validate.
  const std::string path = std::string(ARTHROSIM_BINARY_DIR) + "/tests/validation_unwelded.stl";
  write_stl(sphere(), path, StlEncoding::kAscii);
  MeshReadOptions no_weld;
  no_weld.weld_stl_vertices = false;
  const TriangleMesh raw = read_stl(path, no_weld);
  const RepairResult r = repair(raw);
  ValidationOptions closed;
  closed.require_closed = true;
  EXPECT_TRUE(validate(r.mesh, closed).ok());
  EXPECT_EQ(r.mesh.num_vertices(), sphere().num_vertices());
}

}  // namespace
}  // namespace arthrosim::common
