// The prepare stage: thickness cast on the bundled knee against the
// generator's analytic thickness at two resolutions; the quad surface; the
// HDF5 + XDMF output; repair and rejection of defective user meshes.
#include "pipelines/prepare.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "common/error.h"
#include "common/hdf5.h"
#include "common/mesh_io.h"
#include "common/mesh_validation.h"
#include "common/metadata.h"
#include "common/spatial.h"
#include "pipelines/knee_generator.h"

namespace arthrosim::pipelines {
namespace {

namespace fs = std::filesystem;
using common::TriangleMesh;
using common::Vec3;

const std::string kData = std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/";
const std::string kTmp = std::string(ARTHROSIM_BINARY_DIR) + "/tests/prepare_test_scratch/";

// The generator's analytic thickness at any point of a cartilage surface:
// barycentric interpolation of its per-vertex values on the closest triangle
// of the generator's mesh.
struct AnalyticThickness {
  TriangleMesh mesh;
  Eigen::VectorXd t;
  std::unique_ptr<common::TriangleTree> tree;
  AnalyticThickness(const std::string& dir, const std::string& stem) {
    mesh = common::read_stl(dir + stem + ".stl");
    t = read_thickness_csv(dir + stem + "_thickness.csv", mesh);
    tree = std::make_unique<common::TriangleTree>(mesh);
  }
  double at(const Vec3& p, double* distance = nullptr) const {
    const auto cp = tree->closest_point(p);
    if (distance) *distance = cp.distance;
    double v = 0;
    for (int k = 0; k < 3; ++k) v += cp.barycentric[k] * t[mesh.F(cp.triangle, k)];
    return v;
  }
};

struct Errors {
  double max_all = 0, max_interior = 0, rms = 0;
  int n = 0;
};

class PrepareBundled : public ::testing::TestWithParam<std::pair<std::string, double>> {};

TEST_P(PrepareBundled, CastThicknessMatchesAnalyticThickness) {
  const auto [resolution, edge] = GetParam();
  const std::string dir = kData + resolution + "/";
  PrepareOptions o;
  o.edge_length = edge;
  const PreparedModel model = prepare_model(find_model_files(dir), o);
  ASSERT_EQ(model.surfaces.size(), 4u);
  for (const PreparedSurface& s : model.surfaces) {
    SCOPED_TRACE(resolution + " " + s.name);
    // Every ray reaches the bone: no fallback on the bundled model.
    EXPECT_EQ(s.stats.status, PreparedSurfaceStatistics::Status::kOk);
    EXPECT_EQ(s.stats.vertices_closest_point, 0);
    EXPECT_EQ(s.stats.vertices_inside_bone, 0);
    EXPECT_EQ(s.stats.nodes_closest_point, 0);
    const AnalyticThickness exact(dir, s.name + "_cartilage");
    const auto topo = common::build_topology(s.triangles);
    std::vector<char> rim(s.triangles.num_vertices(), 0);
    for (int v : topo.boundary_vertices) rim[v] = 1;
    Errors e;
    double worst_surface_gap = 0;
    for (int v = 0; v < s.triangles.num_vertices(); ++v) {
      double gap = 0;
      const double ref = exact.at(s.triangles.vertex(v), &gap);
      worst_surface_gap = std::max(worst_surface_gap, gap);
      const double err = std::abs(s.thickness[v] - ref);
      e.max_all = std::max(e.max_all, err);
      if (!rim[v]) e.max_interior = std::max(e.max_interior, err);
      e.rms += err * err;
      ++e.n;
    }
    e.rms = std::sqrt(e.rms / e.n);
    std::printf("%s %-13s |cast - analytic| rms %.3f mm, max interior %.3f mm, max incl. rim %.3f mm\n",
                resolution.c_str(), s.name.c_str(), e.rms * 1e3, e.max_interior * 1e3, e.max_all * 1e3);
    // The remeshed vertices stay on the generator's surface (remesh projects).
    EXPECT_LT(worst_surface_gap, 1e-6);
    // Tolerances. Two effects separate the cast from the analytic value:
    //  - direction: the cast runs along the cartilage surface normal, the
    //    analytic thickness along the bone normal. Where the thickness ramps
    //    (smoothstep, slope up to 1.5 * 2 mm / 10 mm = 0.3 on the patella,
    //    1.5 * 1.5 / 8 = 0.28 on the tibia) the ray is tilted by up to ~17 deg
    //    and is longer by t (1 / cos - 1) ~ 0.15 mm at t = 3 mm, more where the
    //    bone under it is curved (patellar ridge, condyle fillets, R ~ 5 mm).
    //    Measured on the generator's own vertices (no remesh, no
    //    interpolation): max 0.29 mm (patella), rms <= 0.1 mm;
    //  - interpolation: the reference is the analytic field interpolated
    //    linearly on the generator's triangles, error h^2 |t''| / 8 with
    //    |t''| <= 6 * 2 mm / (10 mm)^2 = 0.12 / mm on the ramps: 0.14 mm at
    //    h = 3 mm, 0.06 mm at 2 mm.
    // Bounds: rms 0.12 mm; max 0.45 mm (coarse) / 0.25 mm (medium).
    EXPECT_LT(e.rms, 0.12e-3);
    EXPECT_LT(e.max_all, edge <= 2e-3 ? 0.25e-3 : 0.45e-3);
    // Quads: three per triangle, conforming, periphery = outline nodes.
    EXPECT_EQ(s.quads.num_quads(), 3 * s.triangles.num_triangles());
    EXPECT_EQ(s.node_thickness.size(), s.quads.num_nodes());
    EXPECT_GT(s.periphery_nodes.size(), 0u);
    // Outline: every periphery node lies on a boundary edge of the triangles.
    EXPECT_EQ(static_cast<int>(s.periphery_nodes.size()), 2 * static_cast<int>(topo.boundary_vertices.size()));
    // Node thickness agrees with the vertex thickness at the shared vertices
    // (the first num_vertices nodes are the triangle vertices, same normals up
    // to the area weighting: within 0.1 mm).
    double worst_node = 0;
    for (int v = 0; v < s.triangles.num_vertices(); ++v)
      worst_node = std::max(worst_node, std::abs(s.node_thickness[v] - s.thickness[v]));
    EXPECT_LT(worst_node, 0.1e-3);
    // Normals point away from the bone (towards the joint space).
    const auto n = common::vertex_normals(s.triangles);
    EXPECT_GT((n.array() * s.vertex_normals.array()).rowwise().sum().minCoeff(), 0.999);
  }
}

INSTANTIATE_TEST_SUITE_P(Resolutions, PrepareBundled,
                         ::testing::Values(std::make_pair(std::string("coarse"), 3e-3),
                                           std::make_pair(std::string("medium"), 2e-3)));

TEST(Prepare, CastThicknessOnAFlatBoneIsTheHeight) {
  // Closed form: a bone slab top at y = 0 and points at height h above it
  // with normal +y: thickness = h exactly; a point beyond the slab's edge has
  // no hit and falls back to the closest distance sqrt(dx^2 + h^2).
  TriangleMesh bone;
  bone.V.resize(8, 3);
  bone.V << -1, -1, -1, 1, -1, -1, 1, 0, -1, -1, 0, -1, -1, -1, 1, 1, -1, 1, 1, 0, 1, -1, 0, 1;
  bone.V *= 0.01;
  bone.F.resize(12, 3);
  bone.F << 0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4, 3, 7, 6, 3, 6, 2, 0, 4, 7, 0, 7, 3, 1, 2, 6, 1, 6, 5;
  common::ValidationOptions vo;
  vo.require_closed = true;
  ASSERT_TRUE(common::validate(bone, vo).ok());
  common::Points3 p(3, 3), n(3, 3);
  p << 0.002, 0.0025, 0.001, -0.005, 0.0015, 0.0, 0.013, 0.002, 0.0;
  n << 0, 1, 0, 0, 1, 0, 0, 1, 0;
  Eigen::VectorXd t;
  Eigen::VectorXi src;
  cast_thickness(bone, true, p, n, 10e-3, &t, &src);
  EXPECT_NEAR(t[0], 0.0025, 1e-12);
  EXPECT_NEAR(t[1], 0.0015, 1e-12);
  EXPECT_EQ(src[0], static_cast<int>(ThicknessSource::kRay));
  EXPECT_EQ(src[2], static_cast<int>(ThicknessSource::kClosestPoint));
  EXPECT_NEAR(t[2], std::hypot(0.003, 0.002), 1e-12);
  // A point inside the bone: its ray meets the top from the inside.
  common::Points3 q(1, 3), m(1, 3);
  q << 0, -0.004, 0;
  m << 0, 1, 0;
  cast_thickness(bone, true, q, m, 10e-3, &t, &src);
  EXPECT_EQ(src[0], static_cast<int>(ThicknessSource::kInsideBone));
  EXPECT_NEAR(t[0], 0.004, 1e-12);  // closest face is the top (4 mm) vs bottom (6 mm)
}

// Copies the coarse bundled model into a scratch folder (bones + the two
// tibial cartilages) so tests can damage one file.
std::string scratch_model(const std::string& name) {
  const std::string dir = kTmp + name + "/";
  fs::remove_all(kTmp + name);
  fs::create_directories(kTmp + name);
  for (const char* f : {"tibia_bone.stl", "tibia_medial_cartilage.stl", "tibia_lateral_cartilage.stl"})
    fs::copy_file(kData + "coarse/" + f, dir + f);
  return dir;
}

TEST(Prepare, DuplicateVerticesAreRepairedAndReported) {
  // An OBJ with every triangle's corners written separately (a "triangle
  // soup", as some exporters do): the repair merges them back.
  const std::string dir = scratch_model("duplicates");
  const TriangleMesh m = common::read_stl(dir + "tibia_medial_cartilage.stl");
  fs::remove(dir + "tibia_medial_cartilage.stl");
  {
    std::ofstream obj(dir + "tibia_medial_cartilage.obj");
    obj.precision(17);
    for (int t = 0; t < m.num_triangles(); ++t)
      for (int k = 0; k < 3; ++k)
        obj << "v " << m.V(m.F(t, k), 0) * 1e3 << " " << m.V(m.F(t, k), 1) * 1e3 << " " << m.V(m.F(t, k), 2) * 1e3
            << "\n";
    for (int t = 0; t < m.num_triangles(); ++t) obj << "f " << 3 * t + 1 << " " << 3 * t + 2 << " " << 3 * t + 3 << "\n";
  }
  PrepareOptions o;
  const PreparedModel model = prepare_model(find_model_files(dir), o);
  ASSERT_EQ(model.surfaces.size(), 2u);
  const PreparedSurface& s = model.surfaces[0].name == "tibia_medial" ? model.surfaces[0] : model.surfaces[1];
  ASSERT_EQ(s.name, "tibia_medial");
  ASSERT_FALSE(s.repairs.empty());
  const int merged = 3 * m.num_triangles() - m.num_vertices();
  EXPECT_NE(s.repairs[0].find("merged " + std::to_string(merged)), std::string::npos) << s.repairs[0];
  EXPECT_EQ(s.stats.vertices_closest_point, 0);
  // The result equals preparing the clean file (same remesh input after the merge up to vertex order).
  EXPECT_NEAR(s.stats.thickness_max, 3.0e-3, 0.05e-3);
}

TEST(Prepare, InvertedCartilageIsFlippedAndReported) {
  const std::string dir = scratch_model("inverted");
  TriangleMesh m = common::read_stl(dir + "tibia_lateral_cartilage.stl");
  m.F.col(1).swap(m.F.col(2));
  common::write_stl(m, dir + "tibia_lateral_cartilage.stl");
  const PreparedModel model = prepare_model(find_model_files(dir), PrepareOptions{});
  const PreparedSurface& s = model.surfaces[0].name == "tibia_lateral" ? model.surfaces[0] : model.surfaces[1];
  ASSERT_EQ(s.repairs.size(), 1u);
  EXPECT_NE(s.repairs[0].find("flipped"), std::string::npos);
  // Normals now point up, away from the tibia.
  EXPECT_GT(s.vertex_normals.col(1).mean(), 0.9);
}

TEST(Prepare, NonManifoldCartilageIsAClearError) {
  // A fin: one extra triangle on an interior edge of the patch makes that edge
  // shared by three triangles.
  const std::string dir = scratch_model("nonmanifold");
  TriangleMesh m = common::read_stl(dir + "tibia_medial_cartilage.stl");
  const auto topo = common::build_topology(m);
  int e = 0;
  while (topo.edge_triangles[e].size() != 2) ++e;
  const int a = topo.edges(e, 0), b = topo.edges(e, 1);
  m.V.conservativeResize(m.num_vertices() + 1, 3);
  m.V.row(m.num_vertices() - 1) = 0.5 * (m.V.row(a) + m.V.row(b)) + Eigen::RowVector3d(0, 0.004, 0);
  m.F.conservativeResize(m.num_triangles() + 1, 3);
  m.F.row(m.num_triangles() - 1) << a, b, m.num_vertices() - 1;
  common::write_stl(m, dir + "tibia_medial_cartilage.stl");
  try {
    prepare_model(find_model_files(dir), PrepareOptions{});
    FAIL() << "expected an InputError";
  } catch (const common::InputError& err) {
    const std::string what = err.what();
    EXPECT_NE(what.find("tibia_medial_cartilage.stl"), std::string::npos) << what;
    EXPECT_NE(what.find("non-manifold"), std::string::npos) << what;
  }
  // The executable exits non-zero with that message.
  const std::string cmd = std::string(ARTHROSIM_BINARY_DIR) + "/bin/arthrosim-prepare --quiet --model " + dir +
                          " --out " + kTmp + "nonmanifold.h5 2> " + kTmp + "nonmanifold.err";
  const int rc = std::system(cmd.c_str());
  EXPECT_NE(rc, 0);
  std::ifstream err(kTmp + "nonmanifold.err");
  const std::string text((std::istreambuf_iterator<char>(err)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("non-manifold"), std::string::npos) << text;
}

TEST(Prepare, NonManifoldVertexIsReportedAsAWarning) {
  // A small extra triangle touching the patch at one outline vertex only (two
  // surfaces meeting at a point): representable and remeshable, so it is a
  // warning naming the file, not an error.
  const std::string dir = scratch_model("bowtie");
  TriangleMesh m = common::read_stl(dir + "tibia_medial_cartilage.stl");
  const auto topo = common::build_topology(m);
  const int a = topo.boundary_vertices.front();
  const Vec3 out = (m.vertex(a) - common::bounding_box(m).center()).normalized();
  const int n = m.num_vertices();
  m.V.conservativeResize(n + 2, 3);
  m.V.row(n) = (m.vertex(a) + 1.5e-3 * out + Vec3(0, 0, 0.8e-3)).transpose();
  m.V.row(n + 1) = (m.vertex(a) + 1.5e-3 * out - Vec3(0, 0, 0.8e-3)).transpose();
  m.F.conservativeResize(m.num_triangles() + 1, 3);
  m.F.row(m.num_triangles() - 1) << a, n, n + 1;
  // Orient the fin like its neighbourhood (normal up).
  const Vec3 fn = (m.vertex(n) - m.vertex(a)).cross(m.vertex(n + 1) - m.vertex(a));
  if (fn.y() < 0) m.F.row(m.num_triangles() - 1) << a, n + 1, n;
  common::write_stl(m, dir + "tibia_medial_cartilage.stl");
  const PreparedModel model = prepare_model(find_model_files(dir), PrepareOptions{});
  bool found = false;
  for (const auto& w : model.warnings)
    found = found || (w.find("tibia_medial_cartilage.stl") != std::string::npos && w.find("non-manifold") != std::string::npos);
  EXPECT_TRUE(found) << "no non-manifold vertex warning";
}

TEST(Prepare, MissingBoneIsAClearError) {
  const std::string dir = scratch_model("missing_bone");
  fs::remove(dir + "tibia_bone.stl");
  try {
    find_model_files(dir);
    FAIL() << "expected an InputError";
  } catch (const common::InputError& err) {
    EXPECT_NE(std::string(err.what()).find("tibia_bone.stl"), std::string::npos) << err.what();
  }
}

// surface_edge_length: one surface remeshed coarser than the rest (the
// bundled gait scenes' femur at 4.2 mm, tibiae at 3 mm): its target and mesh
// change, every other surface is exactly as with the common edge length; a
// name that is not a cartilage surface is an error listing the surfaces.
TEST(Prepare, PerSurfaceEdgeLengthChangesThatSurfaceOnly) {
  const ModelFiles files = find_model_files(kData + "coarse");
  PrepareOptions common_edge;
  PrepareOptions own = common_edge;
  own.surface_edge_length["femur"] = 4.2e-3;
  const PreparedModel a = prepare_model(files, common_edge), b = prepare_model(files, own);
  ASSERT_EQ(a.surfaces.size(), b.surfaces.size());
  for (size_t i = 0; i < a.surfaces.size(); ++i) {
    const auto& sa = a.surfaces[i];
    const auto& sb = b.surfaces[i];
    std::printf("%s: %d -> %d quads, target %.1f -> %.1f mm\n", sa.name.c_str(), sa.stats.quads, sb.stats.quads,
                sa.stats.target_edge_length * 1e3, sb.stats.target_edge_length * 1e3);
    if (sa.name == "femur") {
      EXPECT_EQ(sb.stats.target_edge_length, 4.2e-3);
      // Quads scale about as 1/edge^2: (3 / 4.2)^2 = 0.51; the remesher's
      // result lies within 0.5-0.8 of the 3 mm count.
      EXPECT_LT(sb.stats.quads, 0.8 * sa.stats.quads);
      EXPECT_GT(sb.stats.quads, 0.5 * sa.stats.quads);
    } else {
      EXPECT_EQ(sb.stats.target_edge_length, 3e-3);
      EXPECT_EQ(sb.quads.V, sa.quads.V);
      EXPECT_EQ(sb.quads.Q, sa.quads.Q);
    }
  }
  PrepareOptions bad;
  bad.surface_edge_length["femoral"] = 4e-3;
  try {
    prepare_model(files, bad);
    FAIL() << "expected an InputError";
  } catch (const common::InputError& err) {
    const std::string m = err.what();
    EXPECT_NE(m.find("'femoral'"), std::string::npos) << m;
    EXPECT_NE(m.find("tibia_medial"), std::string::npos) << m;
  }
}

TEST(Prepare, WritesTheDocumentedSchema) {
  PrepareOptions o;
  o.edge_length = 3e-3;
  const PreparedModel model = prepare_model(find_model_files(kData + "coarse"), o);
  fs::create_directories(kTmp);
  const std::string path = kTmp + "schema.h5";
  const char* argv[] = {"prepare_test"};
  write_prepared_model(model, o, common::collect_run_metadata("prepare_test", 1, argv, "", "edge_length_mm: 3"), path);
  common::H5File h5(path, common::H5File::Mode::kRead);
  EXPECT_EQ(h5.attribute_string("/", "program"), "prepare_test");
  EXPECT_EQ(h5.attribute_string("/", "schema"), "arthrosim prepared model 1");
  const auto names = h5.read_strings("/surfaces/names");
  EXPECT_EQ(names, (std::vector<std::string>{"femur", "patella", "tibia_lateral", "tibia_medial"}));
  for (const auto& s : model.surfaces) {
    const std::string g = "/surfaces/" + s.name;
    EXPECT_EQ(h5.attribute_string(g, "bone"), s.bone);
    EXPECT_EQ(h5.read_matrix(g + "/triangles/vertices", 3).rows(), s.triangles.num_vertices());
    EXPECT_EQ(h5.read_matrix_int(g + "/triangles/faces", 3).rows(), s.triangles.num_triangles());
    EXPECT_EQ(h5.read_vector(g + "/triangles/thickness").size(), s.triangles.num_vertices());
    EXPECT_EQ(h5.read_matrix(g + "/quads/nodes", 3).rows(), s.quads.num_nodes());
    EXPECT_EQ(h5.read_matrix_int(g + "/quads/quads", 4).rows(), s.quads.num_quads());
    EXPECT_EQ(h5.read_vector(g + "/quads/thickness").size(), s.quads.num_nodes());
    EXPECT_EQ(h5.read_matrix(g + "/quads/normals", 3).rows(), s.quads.num_nodes());
    EXPECT_EQ(h5.read_vector_int(g + "/quads/periphery").size(), static_cast<int>(s.periphery_nodes.size()));
    EXPECT_EQ(h5.read_vector_int(g + "/quads/thickness_source").size(), s.quads.num_nodes());
  }
  for (const char* b : {"femur", "tibia", "patella"}) EXPECT_TRUE(h5.is_dataset(std::string("/bones/") + b + "/faces"));
  // XDMF sidecar references the HDF5 datasets.
  std::ifstream x(xdmf_path_for(path));
  const std::string xml((std::istreambuf_iterator<char>(x)), std::istreambuf_iterator<char>());
  EXPECT_NE(xml.find("schema.h5:/surfaces/femur/quads/nodes"), std::string::npos);
  EXPECT_NE(xml.find("Quadrilateral"), std::string::npos);
}

TEST(Prepare, SameInputGivesIdenticalDatasets) {
  PrepareOptions o;
  o.edge_length = 3e-3;
  const PreparedModel a = prepare_model(find_model_files(kData + "coarse"), o);
  const PreparedModel b = prepare_model(find_model_files(kData + "coarse"), o);
  ASSERT_EQ(a.surfaces.size(), b.surfaces.size());
  for (size_t i = 0; i < a.surfaces.size(); ++i) {
    EXPECT_TRUE(a.surfaces[i].triangles.V == b.surfaces[i].triangles.V);
    EXPECT_TRUE(a.surfaces[i].quads.Q == b.surfaces[i].quads.Q);
    EXPECT_TRUE(a.surfaces[i].node_thickness == b.surfaces[i].node_thickness);
  }
}

}  // namespace
}  // namespace arthrosim::pipelines
