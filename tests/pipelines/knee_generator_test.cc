// Parametric knee generator: contouring against a closed form, determinism,
// and the bundled models (data/models/knee_parametric/{coarse,medium}):
// closed manifold bones, cartilage thickness range and its offset from the
// bone, contact overlap at extension, dimensions and landmarks.
#include "pipelines/knee_generator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "common/error.h"
#include "common/mesh_io.h"
#include "common/mesh_validation.h"
#include "common/spatial.h"

namespace arthrosim::pipelines {
namespace {

using common::TriangleMesh;
using common::Vec3;

const std::string kData = std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/";

double signed_volume(const TriangleMesh& m) {
  double v = 0;
  for (int t = 0; t < m.num_triangles(); ++t)
    v += m.vertex(m.F(t, 0)).dot(m.vertex(m.F(t, 1)).cross(m.vertex(m.F(t, 2)))) / 6.0;
  return v;
}

int components(const TriangleMesh& m) {
  const auto topo = common::build_topology(m);
  std::vector<int> comp(m.num_triangles(), -1);
  int n = 0;
  for (int s = 0; s < m.num_triangles(); ++s) {
    if (comp[s] >= 0) continue;
    std::vector<int> stack{s};
    comp[s] = n;
    while (!stack.empty()) {
      const int t = stack.back();
      stack.pop_back();
      for (int k = 0; k < 3; ++k) {
        const int nb = topo.triangle_neighbours(t, k);
        if (nb >= 0 && comp[nb] < 0) { comp[nb] = n; stack.push_back(nb); }
      }
    }
    ++n;
  }
  return n;
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(KneeGenerator, ContourOfSphereIsClosedAndAccurate) {
  // Sphere of radius R = 10 mm sampled at h = 1 mm. Marching tetrahedra with
  // linear interpolation of an exact distance puts every vertex within
  // O(h^2 / R) of the sphere (0.1 mm here); the inscribed polyhedron's volume
  // is below the sphere's by about 3 * (mean sagitta) / R, i.e. a few per cent.
  const double R = 10e-3, h = 1e-3;
  const TriangleMesh m = contour_implicit([&](const Vec3& p) { return p.norm() - R; }, Vec3::Constant(-12e-3),
                                          Vec3::Constant(12e-3), h, "sphere");
  common::ValidationOptions vo;
  vo.require_closed = true;
  const auto report = common::validate(m, vo);
  EXPECT_TRUE(report.ok()) << report.summary();
  EXPECT_EQ(components(m), 1);
  double worst = 0;
  for (int v = 0; v < m.num_vertices(); ++v) worst = std::max(worst, std::abs(m.vertex(v).norm() - R));
  EXPECT_LT(worst, 0.1e-3);
  const double exact = 4.0 / 3.0 * M_PI * R * R * R;
  EXPECT_GT(signed_volume(m), 0.95 * exact);  // outward orientation, small chordal loss
  EXPECT_LT(signed_volume(m), 1.001 * exact);
}

TEST(KneeGenerator, ClipKeepsPositiveSideWithCleanOutline) {
  // Clip a sphere contour by the plane field r = z: the result is a
  // hemisphere whose outline lies on z = 0 and whose area is 2 pi R^2 up to
  // the chordal error of the input mesh (under 1 %).
  const double R = 10e-3;
  const TriangleMesh s = contour_implicit([&](const Vec3& p) { return p.norm() - R; }, Vec3::Constant(-12e-3),
                                          Vec3::Constant(12e-3), 0.7e-3, "sphere");
  Eigen::VectorXd r(s.num_vertices());
  for (int v = 0; v < s.num_vertices(); ++v) r[v] = s.V(v, 2) + 0.123e-3;  // cut not through grid planes
  const TriangleMesh h = clip_by_vertex_field(s, r, 0.3, "hemisphere");
  const auto report = common::validate(h);
  EXPECT_TRUE(report.ok()) << report.summary();
  EXPECT_EQ(components(h), 1);
  const auto topo = common::build_topology(h);
  ASSERT_FALSE(topo.boundary_vertices.empty());
  for (int v : topo.boundary_vertices) EXPECT_NEAR(h.V(v, 2), -0.123e-3, 1e-9);
  for (int v = 0; v < h.num_vertices(); ++v) EXPECT_GE(h.V(v, 2), -0.123e-3 - 1e-12);
  const double area = common::surface_area(h);
  const double z0 = -0.123e-3;
  const double exact = 2 * M_PI * R * (R - z0);  // spherical cap above z0
  EXPECT_NEAR(area, exact, 0.01 * exact);
  // Normals still outward (orientation kept): mean normal points to +z.
  const auto n = common::triangle_normals(h);
  EXPECT_GT(n.col(2).mean(), 0.3);
}

TEST(KneeGenerator, SameOptionsGiveIdenticalFiles) {
  KneeGeneratorOptions o;
  o.edge_length = 6e-3;  // coarse and quick: the code path is the same at every resolution
  o.grid_spacing = 2e-3;
  o.remesh_iterations = 2;
  const std::string base = std::string(ARTHROSIM_BINARY_DIR) + "/tests/knee_generator_determinism";
  for (int run = 0; run < 2; ++run) {
    const ParametricKnee knee;
    write_knee_geometry(knee.generate(o), o, base + std::to_string(run));
  }
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(base + "0")) {
    const std::string other = base + "1/" + e.path().filename().string();
    ASSERT_TRUE(std::filesystem::exists(other)) << other;
    EXPECT_EQ(slurp(e.path().string()), slurp(other)) << e.path().filename();
    ++files;
  }
  EXPECT_EQ(files, 14);  // 9 STL (with the 2 menisci) + 4 thickness CSV + landmarks.yaml
}

// Per-cartilage edge length (used by msk_bench for the fine knee with finer
// tibial than femoral triangles): only the chosen patches change; their
// triangle count grows about as (e / e_own)^2 (halving the edge: x4, with
// boundary effects +-30 %), and the finer patch stays valid and within the
// bone's thickness of its surface. 6 mm / 3 mm: quick.
TEST(KneeGenerator, PerCartilageEdgeLength) {
  KneeGeneratorOptions o;
  o.edge_length = 6e-3;
  o.grid_spacing = 2e-3;
  o.remesh_iterations = 2;
  const ParametricKnee knee;
  const KneeGeometry a = knee.generate(o);
  o.cartilage_edge_length[KneeCartilage::kTibiaMedial] = 3e-3;
  const KneeGeometry b = knee.generate(o);
  EXPECT_EQ(a.patch(KneeCartilage::kFemur).mesh.V, b.patch(KneeCartilage::kFemur).mesh.V);
  EXPECT_EQ(a.patch(KneeCartilage::kTibiaLateral).mesh.F, b.patch(KneeCartilage::kTibiaLateral).mesh.F);
  const double ratio = double(b.patch(KneeCartilage::kTibiaMedial).mesh.num_triangles()) /
                       a.patch(KneeCartilage::kTibiaMedial).mesh.num_triangles();
  std::printf("medial tibial cartilage: %d -> %d triangles (x%.2f)\n",
              a.patch(KneeCartilage::kTibiaMedial).mesh.num_triangles(),
              b.patch(KneeCartilage::kTibiaMedial).mesh.num_triangles(), ratio);
  EXPECT_GT(ratio, 4.0 * 0.7);
  EXPECT_LT(ratio, 4.0 * 1.3);
  EXPECT_TRUE(common::validate(b.patch(KneeCartilage::kTibiaMedial).mesh, {}).ok());
  o.cartilage_edge_length[KneeCartilage::kPatella] = 0.1e-3;
  EXPECT_THROW(knee.generate(o), common::InputError);
}

TEST(KneeGenerator, BundledCoarseIsWhatTheGeneratorMakes) {
  // The committed coarse model must be reproducible from the code (no stale data).
  KneeGeneratorOptions o;
  o.edge_length = 3e-3;
  const std::string dir = std::string(ARTHROSIM_BINARY_DIR) + "/tests/knee_generator_coarse";
  write_knee_geometry(ParametricKnee().generate(o), o, dir);
  for (const auto& e : std::filesystem::directory_iterator(kData + "coarse")) {
    const std::string mine = dir + "/" + e.path().filename().string();
    ASSERT_TRUE(std::filesystem::exists(mine)) << mine;
    EXPECT_TRUE(slurp(e.path().string()) == slurp(mine)) << e.path().filename()
                                                         << " differs from a fresh run: regenerate with build/bin/arthrosim-make-knee "
                                                            "--edge-length-mm 3 --out data/models/knee_parametric/coarse";
  }
}

class BundledKnee : public ::testing::TestWithParam<std::string> {
 protected:
  std::string dir() const { return kData + GetParam() + "/"; }
  TriangleMesh read(const std::string& stem) const { return common::read_stl(dir() + stem + ".stl"); }
};

TEST_P(BundledKnee, BonesAreClosedManifoldOutward) {
  common::ValidationOptions vo;
  vo.require_closed = true;
  for (KneeBone b : {KneeBone::kFemur, KneeBone::kTibia, KneeBone::kPatella}) {
    const TriangleMesh m = read(bone_file_stem(b));
    const auto report = common::validate(m, vo);
    EXPECT_TRUE(report.ok()) << report.summary();
    EXPECT_FALSE(report.has_warnings()) << report.summary();
    EXPECT_EQ(components(m), 1) << bone_file_stem(b);
    EXPECT_GT(signed_volume(m), 0.0) << bone_file_stem(b) << " is inside out";
  }
}

TEST_P(BundledKnee, CartilageThicknessRangeAndOffsetFromBone) {
  for (KneeCartilage c : {KneeCartilage::kFemur, KneeCartilage::kTibiaMedial, KneeCartilage::kTibiaLateral,
                          KneeCartilage::kPatella}) {
    const std::string stem = cartilage_file_stem(c);
    const TriangleMesh m = read(stem);
    const auto report = common::validate(m);
    EXPECT_TRUE(report.ok()) << report.summary();
    EXPECT_EQ(components(m), 1) << stem;
    const Eigen::VectorXd t = read_thickness_csv(dir() + stem + "_thickness.csv", m);
    EXPECT_GE(t.minCoeff(), 1.5e-3 - 1e-9) << stem;
    EXPECT_LE(t.maxCoeff(), 3.5e-3 + 1e-9) << stem;
    // Load-bearing centres are thick, rims thin (1.5 mm on the outline).
    const double expected_peak = c == KneeCartilage::kFemur ? 2.8e-3 : c == KneeCartilage::kPatella ? 3.5e-3 : 3.0e-3;
    EXPECT_NEAR(t.maxCoeff(), expected_peak, 0.05e-3) << stem;
    const auto topo = common::build_topology(m);
    double rim_max = 0;
    for (int v : topo.boundary_vertices) rim_max = std::max(rim_max, t[v]);
    // The outline is the region's zero set up to the clip's vertex snapping
    // (30 % of an edge); the thickness ramp's slope there is zero (smoothstep),
    // so the rim stays within 0.1 mm of 1.5 mm.
    EXPECT_LT(rim_max, 1.6e-3) << stem;
    // Every vertex is its thickness away from its bone along the bone normal:
    // the closest bone point is at most that far, and (bone locally convex or
    // gently concave, radii >= 15 mm >> 3.5 mm) not much closer.
    const common::TriangleTree bone(read(bone_file_stem(cartilage_bone(c))));
    double worst = 0;
    for (int v = 0; v < m.num_vertices(); ++v)
      worst = std::max(worst, std::abs(bone.closest_point(m.vertex(v)).distance - t[v]));
    // Tolerance: chordal error of the bone mesh, e^2 / (8 R) with the
    // tightest radius near cartilage R ~ 3.5 mm (the fillet where the
    // patella's articular surface meets its ellipsoid, next to the patellar
    // cartilage rim; condyle/groove fillets ~5 mm): 0.32 mm at 3 mm edges,
    // 0.14 mm at 2 mm; plus the STL float rounding (< 1e-5 mm).
    const double edge = GetParam() == "coarse" ? 3e-3 : 2e-3;
    EXPECT_LT(worst, edge * edge / (8 * 3.5e-3)) << stem;
    // Outward = towards the joint: the normals point away from the bone.
    const auto n = common::vertex_normals(m);
    int away = 0;
    for (int v = 0; v < m.num_vertices(); ++v) {
      const auto cp = bone.closest_point(m.vertex(v));
      away += n.row(v).dot((m.vertex(v) - cp.point).normalized()) > 0.5;
    }
    EXPECT_GT(away, 0.98 * m.num_vertices()) << stem;
  }
}

TEST_P(BundledKnee, CartilageInLightContactAtExtension) {
  const TriangleMesh fem = read("femur_cartilage");
  for (const char* other : {"tibia_medial_cartilage", "tibia_lateral_cartilage", "patella_cartilage"}) {
    const TriangleMesh m = read(other);
    // Designed overlap 0.25 mm at the first contact point; the discretisation
    // (chordal error <= 0.08 mm per surface) moves it by less than 0.2 mm.
    for (int dir = 0; dir < 2; ++dir) {
      const SurfaceOverlap o = dir == 0 ? surface_overlap(m, fem) : surface_overlap(fem, m);
      EXPECT_GT(o.max_depth, 0.05e-3) << other << " not in contact (direction " << dir << ")";
      EXPECT_LE(o.max_depth, 0.5e-3) << other << " overlaps too much (direction " << dir << ")";
      EXPECT_GT(o.penetrating_vertices, 0);
    }
  }
  // No bone reaches into another bone's cartilage or bone (the overlap is
  // cartilage-on-cartilage only).
  for (const auto& [a, b] : std::vector<std::pair<std::string, std::string>>{
           {"tibia_bone", "femur_bone"}, {"patella_bone", "femur_bone"}, {"femur_cartilage", "tibia_bone"},
           {"femur_cartilage", "patella_bone"}, {"tibia_medial_cartilage", "femur_bone"},
           {"patella_cartilage", "femur_bone"}}) {
    EXPECT_EQ(surface_overlap(read(a), read(b)).penetrating_vertices, 0) << a << " into " << b;
  }
}

TEST_P(BundledKnee, AdultFemaleDimensions) {
  // Literature values (docs/knee_geometry.md): epicondylar width ~75 mm,
  // tibial plateau ~70 x 45 mm, patella ~40 (ML) x 35 (SI) mm. Tolerance 1 mm
  // (mesh vs analytic extremes).
  const auto fb = common::bounding_box(read("femur_bone"));
  EXPECT_NEAR(fb.size().z(), 75e-3, 1e-3);
  const TriangleMesh tib = read("tibia_bone");
  common::BoundingBox top;
  for (int v = 0; v < tib.num_vertices(); ++v)
    if (tib.V(v, 1) > -0.035) {  // the plateau region
      top.lo = top.lo.cwiseMin(tib.vertex(v));
      top.hi = top.hi.cwiseMax(tib.vertex(v));
    }
  EXPECT_NEAR(top.size().z(), 70e-3, 1e-3);
  EXPECT_NEAR(top.size().x(), 45e-3, 1e-3);
  const auto pb = common::bounding_box(read("patella_bone"));
  EXPECT_NEAR(pb.size().z(), 40e-3, 1e-3);
  EXPECT_NEAR(pb.size().y(), 35e-3, 1e-3);
  // Medial plateau concave, lateral flat-to-convex (bone): mean height of
  // the plateau 7-9 mm from its centre vs. within 3 mm of it. Designed: bowl
  // radius 45 mm (rise 64 / 90 = 0.7 mm at 8 mm), dome radius 150 mm (drop 0.2 mm).
  for (const std::string side : {"medial", "lateral"}) {
    const double zc = side == "medial" ? -21e-3 : 21e-3;
    double centre = 0, ring = 0;
    int nc = 0, nr = 0;
    for (int v = 0; v < tib.num_vertices(); ++v) {
      if (tib.V(v, 1) < -0.032) continue;  // top surface only
      const double rad = std::hypot(tib.V(v, 0), tib.V(v, 2) - zc);
      if (rad < 3e-3) { centre += tib.V(v, 1); ++nc; }
      if (rad > 7e-3 && rad < 9e-3) { ring += tib.V(v, 1); ++nr; }
    }
    ASSERT_GT(nc, 0);
    ASSERT_GT(nr, 0);
    const double rise = ring / nr - centre / nc;
    if (side == "medial") { EXPECT_GT(rise, 0.4e-3) << "medial plateau not concave"; }
    else { EXPECT_LT(rise, 0.0) << "lateral plateau not flat-to-convex"; }
    if (side == "lateral") { EXPECT_GT(rise, -0.5e-3) << "lateral plateau more than slightly convex"; }
  }
}

TEST_P(BundledKnee, LandmarksFileListsBonePointsOnTheirBones) {
  std::ifstream in(dir() + "landmarks.yaml");
  ASSERT_TRUE(in.good());
  std::map<std::string, Vec3> lm;
  std::string line, body;
  while (std::getline(in, line)) {
    if (line.rfind("  ", 0) == 0 && line.rfind("    ", 0) != 0 && line.back() == ':') body = line.substr(2, line.size() - 3);
    if (line.rfind("    ", 0) != 0) continue;
    const auto colon = line.find(':');
    const auto open = line.find('['), close = line.find(']');
    ASSERT_NE(open, std::string::npos) << line;
    std::string nums = line.substr(open + 1, close - open - 1);
    for (char& ch : nums) if (ch == ',') ch = ' ';
    std::istringstream ss(nums);
    Vec3 p;
    ss >> p.x() >> p.y() >> p.z();
    lm[body + "." + line.substr(4, colon - 4)] = p;
  }
  for (const char* key : {"femur.medial_condyle_centre", "femur.lateral_condyle_centre", "femur.medial_epicondyle",
                          "femur.lateral_epicondyle", "tibia.medial_plateau_centre", "tibia.lateral_plateau_centre",
                          "tibia.tuberosity", "patella.centre", "patella.apex", "limb.hip_centre",
                          "limb.ankle_centre"})
    EXPECT_TRUE(lm.count(key)) << key;
  // Origin midway between the condyle centres, on the flexion (Z) axis.
  EXPECT_NEAR((lm["femur.medial_condyle_centre"] + lm["femur.lateral_condyle_centre"]).norm(), 0.0, 1e-9);
  // Hip and ankle on the mechanical (Y) axis, at Winter's proportions of 1.65 m.
  EXPECT_NEAR(lm["limb.hip_centre"].y(), 0.245 * 1.65, 1e-6);
  EXPECT_NEAR(lm["limb.ankle_centre"].y(), -0.246 * 1.65, 1e-6);
  // Surface landmarks lie on their bone meshes (chordal error < 0.3 mm).
  const std::map<std::string, std::string> on_bone = {
      {"femur.medial_condyle_distal", "femur_bone"}, {"femur.lateral_condyle_posterior", "femur_bone"},
      {"femur.medial_epicondyle", "femur_bone"},     {"femur.lateral_epicondyle", "femur_bone"},
      {"tibia.medial_plateau_centre", "tibia_bone"}, {"tibia.tuberosity", "tibia_bone"},
      {"patella.apex", "patella_bone"},              {"patella.articular_ridge", "patella_bone"}};
  for (const auto& [key, bone] : on_bone) {
    ASSERT_TRUE(lm.count(key)) << key;
    EXPECT_LT(common::TriangleTree(read(bone)).closest_point(lm[key]).distance, 0.3e-3) << key;
  }
}

INSTANTIATE_TEST_SUITE_P(Resolutions, BundledKnee, ::testing::Values("coarse", "medium"));

}  // namespace
}  // namespace arthrosim::pipelines
