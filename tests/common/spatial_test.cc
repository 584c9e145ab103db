// TriangleTree (CGAL AABB tree) against brute force on seeded random meshes.
// The brute-force routines here are written independently of spatial.cc
// (plane intersection + signed sub-areas for rays, plane projection + segment
// distances for closest points, separating axes for boxes), so agreement is a
// real check of both the tree traversal and the per-triangle predicates.
#include "common/spatial.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "common/error.h"
#include "tests/common/test_meshes.h"

namespace arthrosim::common {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

struct BruteHit {
  int triangle = -1;
  double t = kInf;
  double min_bary = 0.0;  // how far inside the triangle (0 = on an edge)
};

// Ray/plane intersection, then the barycentrics as signed sub-area ratios.
bool brute_ray_triangle(const TriangleMesh& m, int tri, const Vec3& o, const Vec3& d_unit,
                        double t_max, double* t_out, Vec3* w_out) {
  const Vec3 a = m.vertex(m.F(tri, 0)), b = m.vertex(m.F(tri, 1)), c = m.vertex(m.F(tri, 2));
  const Vec3 n = (b - a).cross(c - a);
  const double nn = n.squaredNorm();
  const double denom = n.dot(d_unit);
  if (nn == 0.0 || std::abs(denom) <= 1e-12 * std::sqrt(nn)) return false;
  const double t = n.dot(a - o) / denom;
  if (t < 0.0 || t > t_max) return false;
  const Vec3 p = o + t * d_unit;
  const Vec3 w((c - b).cross(p - b).dot(n) / nn, (a - c).cross(p - c).dot(n) / nn,
               (b - a).cross(p - a).dot(n) / nn);
  if (w.minCoeff() < -1e-12) return false;
  *t_out = t;
  *w_out = w;
  return true;
}

BruteHit brute_first_hit(const TriangleMesh& m, const Vec3& o, const Vec3& d, double t_max) {
  BruteHit best;
  const Vec3 du = d.normalized();
  for (int tri = 0; tri < m.num_triangles(); ++tri) {
    double t;
    Vec3 w;
    if (brute_ray_triangle(m, tri, o, du, t_max, &t, &w) && t < best.t) {
      best = {tri, t, w.minCoeff()};
    }
  }
  return best;
}

Vec3 closest_on_segment(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 e = b - a;
  const double s = std::clamp((p - a).dot(e) / e.squaredNorm(), 0.0, 1.0);
  return a + s * e;
}

// Distance from p to triangle tri: projection if inside, else nearest edge.
double brute_distance(const TriangleMesh& m, int tri, const Vec3& p) {
  const Vec3 a = m.vertex(m.F(tri, 0)), b = m.vertex(m.F(tri, 1)), c = m.vertex(m.F(tri, 2));
  const Vec3 n = (b - a).cross(c - a);
  const double nn = n.squaredNorm();
  const Vec3 q = p - n * (n.dot(p - a) / nn);
  const Vec3 w((c - b).cross(q - b).dot(n) / nn, (a - c).cross(q - c).dot(n) / nn,
               (b - a).cross(q - a).dot(n) / nn);
  if (w.minCoeff() >= 0.0) return (p - q).norm();
  return std::min({(p - closest_on_segment(p, a, b)).norm(), (p - closest_on_segment(p, b, c)).norm(),
                   (p - closest_on_segment(p, c, a)).norm()});
}

// Separating axis test of a triangle against an axis-aligned box (Akenine-Moller
// 2001): the 3 box axes, the triangle normal and the 9 edge cross products.
bool brute_triangle_box(const TriangleMesh& m, int tri, const Vec3& lo, const Vec3& hi) {
  const Vec3 c = 0.5 * (lo + hi), h = 0.5 * (hi - lo);
  const Vec3 v[3] = {m.vertex(m.F(tri, 0)) - c, m.vertex(m.F(tri, 1)) - c, m.vertex(m.F(tri, 2)) - c};
  const Vec3 e[3] = {v[1] - v[0], v[2] - v[1], v[0] - v[2]};
  auto separated = [&](const Vec3& axis) {
    if (axis.squaredNorm() == 0.0) return false;
    const double p0 = axis.dot(v[0]), p1 = axis.dot(v[1]), p2 = axis.dot(v[2]);
    const double r = h.x() * std::abs(axis.x()) + h.y() * std::abs(axis.y()) + h.z() * std::abs(axis.z());
    return std::min({p0, p1, p2}) > r || std::max({p0, p1, p2}) < -r;
  };
  for (int i = 0; i < 3; ++i) {
    if (separated(Vec3::Unit(i))) return false;
    for (int j = 0; j < 3; ++j)
      if (separated(Vec3::Unit(i).cross(e[j]))) return false;
  }
  return !separated(e[0].cross(e[1]));
}

double signed_volume(const TriangleMesh& m) {
  double vol = 0.0;
  for (int t = 0; t < m.num_triangles(); ++t)
    vol += m.vertex(m.F(t, 0)).dot(m.vertex(m.F(t, 1)).cross(m.vertex(m.F(t, 2)))) / 6.0;
  return vol;
}

Vec3 random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  return Vec3(g(rng), g(rng), g(rng)).normalized();
}

// A closed, bumpy sphere of 5120 triangles (radius 30 mm, +-5 % radial noise).
TriangleMesh test_sphere() { return testing::perturbed_sphere(4, 0.03, 0.05, 12345); }

// 1500 random, overlapping triangles in a 0.1 m cube (a "soup": no topology).
TriangleMesh triangle_soup() {
  std::mt19937_64 rng(777);
  std::uniform_real_distribution<double> u(0.0, 0.1), s(-0.01, 0.01);
  TriangleMesh m;
  const int nt = 1500;
  m.V.resize(3 * nt, 3);
  m.F.resize(nt, 3);
  for (int t = 0; t < nt; ++t) {
    const Vec3 c(u(rng), u(rng), u(rng));
    for (int k = 0; k < 3; ++k) m.V.row(3 * t + k) = (c + Vec3(s(rng), s(rng), s(rng))).transpose();
    m.F.row(t) << 3 * t, 3 * t + 1, 3 * t + 2;
  }
  m.name = "soup";
  return m;
}

void check_rays_against_brute_force(const TriangleMesh& mesh, double scale, unsigned seed) {
  const TriangleTree tree(mesh);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0), len(0.2, 3.0);
  int hits = 0, misses = 0, same_id = 0, ties = 0;
  for (int r = 0; r < 2000; ++r) {
    const Vec3 o = scale * 1.5 * Vec3(u(rng), u(rng), u(rng));
    // Non-unit directions on purpose: distances must still be in metres.
    const Vec3 d = len(rng) * random_unit(rng);
    const double t_max = (r % 3 == 0) ? scale * 0.5 * (1.0 + u(rng)) : 1e30;
    const auto hit = tree.first_hit(o, d, t_max);
    const BruteHit bf = brute_first_hit(mesh, o, d, t_max);
    if (bf.triangle < 0) {
      // The brute force accepts barycentrics down to -1e-12 as does the tree, so a
      // miss must be a miss for both (no grazing cases in random data).
      EXPECT_FALSE(hit.has_value()) << "ray " << r;
      ++misses;
      continue;
    }
    ASSERT_TRUE(hit.has_value()) << "ray " << r << " brute force hit triangle " << bf.triangle;
    ++hits;
    // Distances: two different formulas for the same t; rounding differs at the
    // 1e-15 relative level, so 1e-12 relative is a safe bound.
    EXPECT_NEAR(hit->distance, bf.t, 1e-12 * bf.t) << "ray " << r;
    if (hit->triangle == bf.triangle) {
      ++same_id;
    } else {
      // Only a tie may differ: the ray passes through a shared edge or vertex
      // (brute-force barycentric ~0) at the same distance.
      ++ties;
      EXPECT_LT(std::abs(bf.min_bary), 1e-9) << "ray " << r;
    }
    // The point is on the ray and equals the barycentric combination.
    const Vec3 on_ray = o + hit->distance * d.normalized();
    EXPECT_LT((hit->point - on_ray).norm(), 1e-12 * scale);
    Vec3 interp = Vec3::Zero();
    for (int k = 0; k < 3; ++k) interp += hit->barycentric[k] * mesh.vertex(mesh.F(hit->triangle, k));
    EXPECT_LT((interp - hit->point).norm(), 1e-12 * scale) << "ray " << r;
    EXPECT_NEAR(hit->barycentric.sum(), 1.0, 1e-14);
    EXPECT_GE(hit->barycentric.minCoeff(), 0.0);
    // hit_triangle on the returned triangle gives the identical answer.
    const auto again = tree.hit_triangle(hit->triangle, o, d, t_max);
    ASSERT_TRUE(again.has_value());
    EXPECT_EQ(again->distance, hit->distance);
    EXPECT_EQ(again->barycentric, hit->barycentric);
  }
  // The sample must exercise both outcomes and mostly give exact id agreement.
  EXPECT_GT(hits, 300);
  EXPECT_GT(misses, 50);
  EXPECT_LE(ties, hits / 100);
  std::printf("[rays] %s: %d hits (%d same triangle id, %d ties), %d misses\n", mesh.name.c_str(), hits,
              same_id, ties, misses);
}

TEST(Spatial, TestSphereIsClosedAndOutward) {
  const TriangleMesh m = test_sphere();
  EXPECT_EQ(m.num_triangles(), 5120);
  EXPECT_GT(signed_volume(m), 0.0);
  EXPECT_TRUE(build_topology(m).boundary_vertices.empty());
}

TEST(Spatial, FirstHitMatchesBruteForceOnPerturbedSphere) {
  check_rays_against_brute_force(test_sphere(), 0.03, 1);
}

TEST(Spatial, FirstHitMatchesBruteForceOnTriangleSoup) {
  TriangleMesh soup = triangle_soup();
  // Centre the soup on the origin so the random rays pass through it.
  soup.V.rowwise() -= Eigen::RowVector3d(0.05, 0.05, 0.05);
  check_rays_against_brute_force(soup, 0.05, 2);
}

TEST(Spatial, RaysFromInsideSphereAlwaysHitOnce) {
  // From the centre of a closed, star-shaped surface every ray hits, at a
  // distance between the min and max vertex radius.
  const TriangleMesh m = test_sphere();
  const TriangleTree tree(m);
  const double rmin = m.V.rowwise().norm().minCoeff(), rmax = m.V.rowwise().norm().maxCoeff();
  std::mt19937_64 rng(3);
  for (int r = 0; r < 500; ++r) {
    const auto hit = tree.first_hit(Vec3::Zero(), random_unit(rng));
    ASSERT_TRUE(hit.has_value());
    EXPECT_GE(hit->distance, rmin * (1 - 1e-12));
    EXPECT_LE(hit->distance, rmax * (1 + 1e-12));
  }
}

TEST(Spatial, ClosestPointMatchesBruteForce) {
  for (const TriangleMesh& mesh : {test_sphere(), triangle_soup()}) {
    const TriangleTree tree(mesh);
    const double scale = bounding_box(mesh).diagonal();
    const Vec3 centre = bounding_box(mesh).center();
    std::mt19937_64 rng(4);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    int same_id = 0;
    const int n = 1000;
    for (int i = 0; i < n; ++i) {
      const Vec3 p = centre + scale * Vec3(u(rng), u(rng), u(rng));
      const ClosestPoint cp = tree.closest_point(p);
      double best = kInf;
      int best_tri = -1;
      for (int t = 0; t < mesh.num_triangles(); ++t) {
        const double dist = brute_distance(mesh, t, p);
        if (dist < best) best = dist, best_tri = t;
      }
      ASSERT_GE(cp.triangle, 0);
      // Distances from two different formulas: 1e-12 relative (rounding ~1e-15),
      // plus an absolute 1e-15 * mesh size for points very near the surface,
      // where both formulas lose digits to cancellation in p - q.
      const double tol = 1e-12 * best + 1e-15 * scale;
      EXPECT_NEAR(cp.distance, best, tol) << mesh.name << " point " << i;
      // The reported triangle is a minimiser (equal to brute force, or a tie at
      // a shared edge/vertex where several triangles are equally close).
      if (cp.triangle == best_tri) {
        ++same_id;
      } else {
        EXPECT_NEAR(brute_distance(mesh, cp.triangle, p), best, tol) << mesh.name << " " << i;
      }
      Vec3 interp = Vec3::Zero();
      for (int k = 0; k < 3; ++k) interp += cp.barycentric[k] * mesh.vertex(mesh.F(cp.triangle, k));
      EXPECT_LT((interp - cp.point).norm(), 1e-12 * scale);
      EXPECT_NEAR((p - cp.point).norm(), cp.distance, 1e-12 * scale);
      EXPECT_GE(cp.barycentric.minCoeff(), 0.0);
    }
    std::printf("[closest] %s: %d / %d same triangle id (rest: ties on shared edges/vertices)\n",
                mesh.name.c_str(), same_id, n);
    EXPECT_GT(same_id, n / 2);
  }
}

TEST(Spatial, TrianglesInBoxMatchesSeparatingAxisBruteForce) {
  for (const TriangleMesh& mesh : {test_sphere(), triangle_soup()}) {
    const TriangleTree tree(mesh);
    const BoundingBox bb = bounding_box(mesh);
    const double scale = bb.diagonal();
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    size_t total = 0;
    for (int i = 0; i < 200; ++i) {
      const Vec3 c = bb.lo + Vec3(u(rng), u(rng), u(rng)).cwiseProduct(bb.size());
      const Vec3 h = 0.15 * scale * Vec3(u(rng), u(rng), u(rng));
      const std::vector<int> got = tree.triangles_in_box(c - h, c + h);
      std::vector<int> expected;
      for (int t = 0; t < mesh.num_triangles(); ++t)
        if (brute_triangle_box(mesh, t, c - h, c + h)) expected.push_back(t);
      EXPECT_EQ(got, expected) << mesh.name << " box " << i;
      EXPECT_TRUE(std::is_sorted(got.begin(), got.end()));
      total += got.size();
    }
    EXPECT_GT(total, 1000u);  // the boxes are not all empty
  }
}

TEST(Spatial, HitTriangleClosedForm) {
  // Triangle (0,0,0), (2,0,0), (0,2,0); a ray from (0.5, 0.25, 3) straight down
  // with |direction| = 4 hits (0.5, 0.25, 0) at distance 3 m with barycentrics
  // (1 - 0.25 - 0.125, 0.25, 0.125).
  TriangleMesh m;
  m.V.resize(3, 3);
  m.V << 0, 0, 0, 2, 0, 0, 0, 2, 0;
  m.F.resize(1, 3);
  m.F << 0, 1, 2;
  const TriangleTree tree(m);
  const Vec3 o(0.5, 0.25, 3.0), d(0, 0, -4.0);
  for (const auto& hit : {tree.hit_triangle(0, o, d), tree.first_hit(o, d)}) {
    ASSERT_TRUE(hit.has_value());
    EXPECT_EQ(hit->triangle, 0);
    EXPECT_NEAR(hit->distance, 3.0, 1e-15);
    EXPECT_NEAR((hit->barycentric - Vec3(0.625, 0.25, 0.125)).norm(), 0.0, 1e-15);
    EXPECT_NEAR((hit->point - Vec3(0.5, 0.25, 0.0)).norm(), 0.0, 1e-15);
  }
  // Beyond max_distance (metres along the ray): no hit; exactly at it: hit.
  EXPECT_FALSE(tree.first_hit(o, d, 2.999).has_value());
  EXPECT_TRUE(tree.first_hit(o, d, 3.0).has_value());
  // Pointing away, parallel to the plane, or outside the triangle: no hit.
  EXPECT_FALSE(tree.first_hit(o, -d).has_value());
  EXPECT_FALSE(tree.first_hit(Vec3(0.5, 0.25, 0.0), Vec3(1, 0, 0)).has_value());
  EXPECT_FALSE(tree.first_hit(Vec3(1.5, 1.5, 1.0), d).has_value());
  // Back faces are hit too (contact rays may come from either side).
  EXPECT_TRUE(tree.first_hit(Vec3(0.5, 0.25, -1.0), -d).has_value());
  // Bad input is reported, not a crash.
  EXPECT_THROW(tree.first_hit(o, Vec3::Zero()), NumericalError);
  EXPECT_THROW(tree.hit_triangle(1, o, d), std::out_of_range);
  const ClosestPoint cp = tree.closest_point(Vec3(3, 3, 1));
  // Closest to the hypotenuse x + y = 2 at (1, 1, 0): distance |(2, 2, 1)| = 3.
  EXPECT_NEAR(cp.distance, 3.0, 1e-15);
  EXPECT_NEAR((cp.barycentric - Vec3(0, 0.5, 0.5)).norm(), 0.0, 1e-15);
}

TEST(Spatial, FirstHitReturnsNearestOfStackedTriangles) {
  // Ten parallel triangles at z = 0..9; rays from above/below must report the
  // nearest one, whatever the tree order.
  TriangleMesh m;
  m.V.resize(30, 3);
  m.F.resize(10, 3);
  for (int i = 0; i < 10; ++i) {
    const int z = (i * 7) % 10;  // shuffled heights
    m.V.row(3 * i) << 0, 0, z;
    m.V.row(3 * i + 1) << 1, 0, z;
    m.V.row(3 * i + 2) << 0, 1, z;
    m.F.row(i) << 3 * i, 3 * i + 1, 3 * i + 2;
  }
  const TriangleTree tree(m);
  const auto down = tree.first_hit(Vec3(0.2, 0.2, 20), Vec3(0, 0, -1));
  ASSERT_TRUE(down.has_value());
  EXPECT_EQ((down->triangle * 7) % 10, 9);
  EXPECT_DOUBLE_EQ(down->distance, 11.0);
  const auto up = tree.first_hit(Vec3(0.2, 0.2, 4.5), Vec3(0, 0, 1));
  ASSERT_TRUE(up.has_value());
  EXPECT_EQ((up->triangle * 7) % 10, 5);
  EXPECT_DOUBLE_EQ(up->distance, 0.5);
}

TEST(Spatial, RejectsInvalidMeshes) {
  TriangleMesh m = testing::icosphere(0, 1.0);
  m.V(3, 1) = std::nan("");
  EXPECT_THROW(TriangleTree{m}, InputError);
  m = testing::icosphere(0, 1.0);
  m.F(2, 0) = 99;
  EXPECT_THROW(TriangleTree{m}, InputError);
}

TEST(Spatial, ConcurrentQueriesMatchSerialOnes) {
  // Queries are const and allocation-free; the tree is built in the
  // constructor, so OpenMP threads may share one tree.
  const TriangleMesh m = test_sphere();
  const TriangleTree tree(m);
  std::mt19937_64 rng(6);
  const int n = 4000;
  std::vector<Vec3> dirs(n);
  for (auto& d : dirs) d = random_unit(rng);
  std::vector<int> serial(n), parallel(n);
  std::vector<double> serial_d(n), parallel_d(n);
  for (int i = 0; i < n; ++i) {
    const auto h = tree.first_hit(Vec3(0.001, -0.002, 0.003), dirs[i]);
    serial[i] = h ? h->triangle : -1;
    serial_d[i] = tree.closest_point(0.05 * dirs[i]).distance;
  }
#pragma omp parallel for num_threads(2) schedule(dynamic, 64)
  for (int i = 0; i < n; ++i) {
    const auto h = tree.first_hit(Vec3(0.001, -0.002, 0.003), dirs[i]);
    parallel[i] = h ? h->triangle : -1;
    parallel_d[i] = tree.closest_point(0.05 * dirs[i]).distance;
  }
  EXPECT_EQ(serial, parallel);
  EXPECT_EQ(serial_d, parallel_d);
}

TEST(Spatial, HitSideSelectsFrontOrBackFaces) {
  // Closed outward sphere: a ray from outside through the centre meets the
  // near wall from the front and the far wall from the back.
  const TriangleMesh m = test_sphere();
  const TriangleTree tree(m);
  const Points3 N = triangle_normals(m);
  std::mt19937_64 rng(8);
  for (int r = 0; r < 300; ++r) {
    const Vec3 u = random_unit(rng);
    const Vec3 o = 0.1 * u, d = -u;
    const auto any = tree.first_hit(o, d);
    const auto front = tree.first_hit(o, d, 1e30, HitSide::kFront);
    const auto back = tree.first_hit(o, d, 1e30, HitSide::kBack);
    ASSERT_TRUE(any && front && back);
    EXPECT_EQ(front->triangle, any->triangle);
    EXPECT_LT(N.row(front->triangle).dot(d.transpose()), 0.0);
    EXPECT_GT(N.row(back->triangle).dot(d.transpose()), 0.0);
    EXPECT_GT(back->distance, front->distance);
    // Brute force over the filtered triangles: the same far-wall triangle.
    double best = kInf;
    int best_tri = -1;
    for (int t = 0; t < m.num_triangles(); ++t) {
      if (N.row(t).dot(d.transpose()) <= 0.0) continue;
      double tt;
      Vec3 w;
      if (brute_ray_triangle(m, t, o, d, 1e30, &tt, &w) && tt < best) best = tt, best_tri = t;
    }
    EXPECT_EQ(back->triangle, best_tri);
    EXPECT_NEAR(back->distance, best, 1e-12 * best);
    // The single-triangle test applies the same rule.
    EXPECT_FALSE(tree.hit_triangle(front->triangle, o, d, 1e30, HitSide::kBack).has_value());
    EXPECT_TRUE(tree.hit_triangle(back->triangle, o, d, 1e30, HitSide::kBack).has_value());
  }
}

TEST(Spatial, EmptyAndSingleTriangleMeshes) {
  const TriangleTree empty{TriangleMesh{}};
  EXPECT_FALSE(empty.first_hit(Vec3::Zero(), Vec3(1, 0, 0)).has_value());
  EXPECT_EQ(empty.closest_point(Vec3::Zero()).triangle, -1);
  EXPECT_TRUE(std::isinf(empty.closest_point(Vec3::Zero()).distance));
  EXPECT_TRUE(empty.triangles_in_box(Vec3::Constant(-1), Vec3::Constant(1)).empty());
  TriangleMesh one;
  one.V.resize(3, 3);
  one.V << 0, 0, 0, 1, 0, 0, 0, 1, 0;
  one.F.resize(1, 3);
  one.F << 0, 1, 2;
  const TriangleTree tree(one);
  EXPECT_EQ(tree.first_hit(Vec3(0.2, 0.2, 1), Vec3(0, 0, -1))->triangle, 0);
  EXPECT_NEAR(tree.closest_point(Vec3(0.2, 0.2, 1)).distance, 1.0, 1e-15);
  EXPECT_EQ(tree.triangles_in_box(Vec3(0.1, 0.1, -0.1), Vec3(0.2, 0.2, 0.1)), std::vector<int>{0});
  EXPECT_TRUE(tree.triangles_in_box(Vec3(0.6, 0.6, -0.1), Vec3(0.9, 0.9, 0.1)).empty());  // box beyond the hypotenuse
}

// Inside/outside of a closed mesh: points on a line through a perturbed
// sphere against the radial distance, including points whose test ray would
// pass exactly through vertices (the sphere's own vertices scaled in/out);
// an open mesh is refused.
TEST(Spatial, ClosedSurfaceSideMatchesTheSphere) {
  const TriangleMesh sphere = testing::icosphere(3, 0.02);  // inscribed: facets within 0.5 mm of r
  const ClosedSurfaceSide side(sphere);
  for (double r = 0.0; r < 0.03; r += 0.0007) {
    const Vec3 p(r * 0.6, r * -0.48, r * 0.64);
    const ClosedSurfaceSide::Side s = side.side(p);
    if (r < 0.019) { EXPECT_EQ(s, ClosedSurfaceSide::Side::kInside) << r; }
    if (r > 0.0201) { EXPECT_EQ(s, ClosedSurfaceSide::Side::kOutside) << r; }
  }
  for (int v = 0; v < sphere.num_vertices(); v += 17) {
    EXPECT_TRUE(side.inside(0.9 * sphere.vertex(v)));
    EXPECT_FALSE(side.inside(1.1 * sphere.vertex(v)));
    EXPECT_EQ(side.side(sphere.vertex(v)), ClosedSurfaceSide::Side::kOnBoundary);
  }
  TriangleMesh open = sphere;
  open.F.conservativeResize(open.num_triangles() - 1, 3);
  open.name = "open.stl";
  try {
    ClosedSurfaceSide bad(open);
    ADD_FAILURE();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("open.stl"), std::string::npos);
  }
}

TEST(Spatial, TreeIsMovable) {
  TriangleTree a(test_sphere());
  TriangleTree b = std::move(a);
  EXPECT_TRUE(b.first_hit(Vec3::Zero(), Vec3(1, 0, 0)).has_value());
  EXPECT_EQ(b.mesh().num_triangles(), 5120);
}

}  // namespace
}  // namespace arthrosim::common
