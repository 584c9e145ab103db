// The menisci of the parametric knee (pipelines/knee_generator.h): closed
// wedge-shaped C-rings on the tibial plateau with the dimensions of
// docs/knee_geometry.md, clear of the bones, in the bundled models.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "common/mesh_io.h"
#include "common/mesh_validation.h"
#include "common/spatial.h"
#include "pipelines/knee_generator.h"

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

class BundledMenisci : public ::testing::TestWithParam<std::string> {};

// Closed, manifold, outward; size within the literature ranges the shape was
// built from (outer outline length x width 40 x 27 mm medial, 33 x 27 mm
// lateral, peripheral height 6 mm; the contour and remeshing round the
// outline by up to a grid step, tolerance 1.5 mm); volume of a wedge ring of
// that size (about 2-3 cm^3).
TEST_P(BundledMenisci, ClosedRingsOfTheStatedSize) {
  for (KneeMeniscus w : {KneeMeniscus::kMedial, KneeMeniscus::kLateral}) {
    const std::string stem = meniscus_file_stem(w);
    SCOPED_TRACE(stem);
    const TriangleMesh m = common::read_stl(kData + GetParam() + "/" + stem + ".stl");
    common::ValidationOptions vo;
    vo.require_closed = true;
    const auto report = common::validate(m, vo);
    EXPECT_TRUE(report.ok()) << report.summary();
    const double vol = signed_volume(m);
    EXPECT_GT(vol, 0.0) << "inside out";
    const common::BoundingBox box = common::bounding_box(m);
    const Vec3 size = box.size();
    const bool medial = w == KneeMeniscus::kMedial;
    std::printf("%s %s: %d triangles, AP %.1f ML %.1f height %.1f mm, volume %.2f cm^3\n", GetParam().c_str(),
                stem.c_str(), m.num_triangles(), size.x() * 1e3, size.z() * 1e3, size.y() * 1e3, vol * 1e6);
    EXPECT_NEAR(size.x(), medial ? 40e-3 : 33e-3, 1.5e-3);
    EXPECT_NEAR(size.z(), 27e-3, 1.5e-3);
    EXPECT_GT(vol, 1.0e-6);
    EXPECT_LT(vol, 4.0e-6);
    // On its own side of the knee (medial is -Z for this right knee).
    EXPECT_LT(medial ? box.hi.z() : -box.lo.z(), 0.0);
  }
}

// No meniscus vertex lies inside a bone (the lower face follows the tibial
// articular surface, the upper face stays below the femoral one): a ray from
// the vertex meets the closed bone an even number of times.
TEST_P(BundledMenisci, OutsideTheBones) {
  const TriangleMesh femur = common::read_stl(kData + GetParam() + "/femur_bone.stl");
  const TriangleMesh tibia = common::read_stl(kData + GetParam() + "/tibia_bone.stl");
  const common::TriangleTree tf(femur), tt(tibia);
  const Vec3 dir = Vec3(0.31, 0.17, 0.93).normalized();
  auto inside = [&](const common::TriangleTree& tree, const Vec3& p) {
    // Inside iff the first hit along dir is a back face (leaving the body).
    const auto hit = tree.first_hit(p, dir, 1.0);
    if (!hit) return false;
    const common::Points3 n = common::triangle_normals(tree.mesh());
    return n.row(hit->triangle).dot(dir) > 0.0;
  };
  for (KneeMeniscus w : {KneeMeniscus::kMedial, KneeMeniscus::kLateral}) {
    const TriangleMesh m = common::read_stl(kData + GetParam() + "/" + meniscus_file_stem(w) + ".stl");
    int in_bone = 0;
    for (int v = 0; v < m.num_vertices(); ++v) {
      // 0.3 mm inward tolerance: bone and meniscus are separate remeshings of
      // surfaces that touch (the lower face lies on the tibial bone outside
      // the cartilage), facets differ by up to edge^2 / (8 R).
      const common::ClosestPoint cf = tf.closest_point(m.vertex(v)), ct = tt.closest_point(m.vertex(v));
      if ((inside(tf, m.vertex(v)) && cf.distance > 0.3e-3) || (inside(tt, m.vertex(v)) && ct.distance > 0.3e-3)) ++in_bone;
    }
    EXPECT_EQ(in_bone, 0) << meniscus_file_stem(w);
  }
}

INSTANTIATE_TEST_SUITE_P(Resolutions, BundledMenisci, ::testing::Values("coarse", "medium"));

// The implicit function: inside the ring, outside in the opening between the
// horns and above the peripheral height.
TEST(MeniscusImplicit, RingWedgeAndOpening) {
  const ParametricKnee knee;
  // Medial meniscus: centre z = -21 mm; the body at x = 0 on the medial side.
  Vec3 lo, hi;
  knee.meniscus_bounds(KneeMeniscus::kMedial, &lo, &hi);
  auto lowest_inside = [&](double x, double z) {
    for (double y = lo.y(); y < hi.y(); y += 1e-5)
      if (knee.meniscus_implicit(KneeMeniscus::kMedial, Vec3(x, y, z)) < 0) return y;
    return 1.0;
  };
  auto highest_inside = [&](double x, double z) {
    for (double y = hi.y(); y > lo.y(); y -= 1e-5)
      if (knee.meniscus_implicit(KneeMeniscus::kMedial, Vec3(x, y, z)) < 0) return y;
    return -1.0;
  };
  // Periphery (s ~ 0.95): nearly the full 6 mm; near the inner edge: thin.
  const double z_out = -21e-3 - 14.5e-3, z_in = -21e-3 - 6.5e-3;
  const double h_out = highest_inside(0, z_out) - lowest_inside(0, z_out);
  const double h_in = highest_inside(0, z_in) - lowest_inside(0, z_in);
  std::printf("medial body: height %.2f mm near the periphery, %.2f mm near the inner edge\n", h_out * 1e3, h_in * 1e3);
  EXPECT_NEAR(h_out, 5.7e-3, 0.4e-3);
  EXPECT_LT(h_in, 2.5e-3);
  // The opening: between the horns, on the lateral side of the centre.
  EXPECT_GT(knee.meniscus_implicit(KneeMeniscus::kMedial, Vec3(0, lowest_inside(0, z_out) + 1e-3, -21e-3 + 9e-3)), 0.0);
  // A horn: anterior, lateral side of the centre, inside the ring.
  const double zh = -21e-3 + 6e-3, xh = 16e-3;
  EXPECT_LT(knee.meniscus_implicit(KneeMeniscus::kMedial, Vec3(xh, lowest_inside(xh, zh) + 0.5e-3, zh)), 0.0);
}

}  // namespace
}  // namespace arthrosim::pipelines
