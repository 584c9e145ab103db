// TriangleTree: CGAL's AABB tree (CGAL::AABB_tree over the mesh triangles,
// Epick kernel) with our own traversal predicates for rays and closest points.
//
// Why own predicates on CGAL's tree rather than first_intersection() and
// closest_point(): the contact code casts thousands of rays per model
// evaluation. CGAL's first_intersection() builds a std::priority_queue (heap
// allocation per query) and constructs the intersection as a variant; its
// closest_point() needs a lazily built kd-tree (a mutation inside a const call).
// Here the tree is CGAL's, built once in the constructor; queries use
// AABB_tree::traversal_with_priority (nearest box first, recursive, no heap
// allocation) with a slab test for the boxes and Moller-Trumbore (Moller &
// Trumbore 1997) for the triangles. hit_triangle() runs the very same
// Moller-Trumbore code, so a cached-triangle test and a tree query agree bit for
// bit. Triangles overlapping a box use CGAL's exact (filtered) Epick predicate.
//
// Units: direction need not be unit length; it is normalised, so t, the
// reported distance and max_distance are all in metres along the ray.
#include "common/spatial.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Side_of_triangle_mesh.h>
#include <CGAL/Surface_mesh.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "common/error.h"
#include "common/mesh_validation.h"

namespace arthrosim::common {

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Triangle3 = K::Triangle_3;
using TriangleIterator = std::vector<Triangle3>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<K, TriangleIterator>;
using Traits = CGAL::AABB_traits<K, Primitive>;
using Tree = CGAL::AABB_tree<Traits>;

constexpr double kInf = std::numeric_limits<double>::infinity();

// Triangle in the form Moller-Trumbore wants: a corner and two edge vectors.
struct PackedTriangle {
  Vec3 a, e1, e2;
  double twice_area;  // |e1 x e2|
};

// A ray with unit direction, its componentwise inverse (for the slab test) and
// the search interval [0, t_max].
struct Ray {
  Vec3 o, d, inv_d;
  double t_max;
  HitSide side = HitSide::kBoth;
};

// Moller-Trumbore ray/triangle intersection. Accepts t in [0, t_max] and
// barycentrics within kBaryTolerance of the triangle (so a ray through a shared
// edge hits at least one of its triangles despite rounding). A ray within
// ~1e-12 rad of the triangle's plane is treated as a miss: its intersection is
// ill-conditioned and would be a grazing contact anyway.
constexpr double kBaryTolerance = 1e-12;
constexpr double kParallelTolerance = 1e-12;

inline bool moller_trumbore(const PackedTriangle& tri, const Ray& ray, double* t_out, double* u_out,
                            double* v_out) {
  const Vec3 p = ray.d.cross(tri.e2);
  const double det = tri.e1.dot(p);
  // |det| = |d . (e1 x e2)| = sin(angle to plane) * |e1 x e2| for unit d.
  if (!(std::abs(det) > kParallelTolerance * tri.twice_area)) return false;  // also catches zero-area triangles
  // det = e1 . (d x e2) = -d . (e1 x e2): positive when the ray meets the front side.
  if (ray.side == HitSide::kFront && det < 0.0) return false;
  if (ray.side == HitSide::kBack && det > 0.0) return false;
  const double inv_det = 1.0 / det;
  const Vec3 s = ray.o - tri.a;
  const double u = s.dot(p) * inv_det;
  if (u < -kBaryTolerance || u > 1.0 + kBaryTolerance) return false;
  const Vec3 q = s.cross(tri.e1);
  const double v = ray.d.dot(q) * inv_det;
  if (v < -kBaryTolerance || u + v > 1.0 + kBaryTolerance) return false;
  const double t = tri.e2.dot(q) * inv_det;
  if (t < 0.0 || t > ray.t_max) return false;
  *t_out = t;
  *u_out = u;
  *v_out = v;
  return true;
}

// Barycentrics (w0, w1, w2) = (1-u-v, u, v), clamped into the triangle (the
// tolerance above can leave them outside by <= 1e-12) and renormalised.
inline Vec3 clamped_barycentric(double u, double v) {
  Vec3 w(1.0 - u - v, u, v);
  w = w.cwiseMax(0.0);
  return w / w.sum();
}

// Slab test of the ray against an axis-aligned box for t in [0, t_max]; returns
// the entry parameter. The exit bound is widened by a relative 1e-12 so rounding
// never prunes a box whose triangle Moller-Trumbore would accept.
inline bool ray_box(const Ray& ray, const CGAL::Bbox_3& box, double* t_entry) {
  double t0 = 0.0;
  double t1 = ray.t_max;
  const double lo[3] = {box.xmin(), box.ymin(), box.zmin()};
  const double hi[3] = {box.xmax(), box.ymax(), box.zmax()};
  for (int i = 0; i < 3; ++i) {
    if (ray.d[i] == 0.0) {
      if (ray.o[i] < lo[i] || ray.o[i] > hi[i]) return false;
      continue;
    }
    double ta = (lo[i] - ray.o[i]) * ray.inv_d[i];
    double tb = (hi[i] - ray.o[i]) * ray.inv_d[i];
    if (ta > tb) std::swap(ta, tb);
    const double slack = 1e-12 * (std::abs(tb) + std::abs(ta)) + 1e-300;
    t0 = std::max(t0, ta - slack);
    t1 = std::min(t1, tb + slack);
    if (t0 > t1) return false;
  }
  *t_entry = t0;
  return true;
}

// Closest point on triangle (a, b, c) to p, by Voronoi regions (Ericson 2005,
// Real-Time Collision Detection, 5.1.5). Returns the point and barycentrics.
inline Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                                Vec3* bary) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) {
    *bary = Vec3(1, 0, 0);
    return a;
  }
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) {
    *bary = Vec3(0, 1, 0);
    return b;
  }
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double v = d1 / (d1 - d3);
    *bary = Vec3(1 - v, v, 0);
    return a + v * ab;
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) {
    *bary = Vec3(0, 0, 1);
    return c;
  }
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double w = d2 / (d2 - d6);
    *bary = Vec3(1 - w, 0, w);
    return a + w * ac;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    *bary = Vec3(0, 1 - w, w);
    return b + w * (c - b);
  }
  const double sum = va + vb + vc;
  if (!(sum > 0.0)) {
    // Degenerate (zero-area) triangle not caught above: fall back to the
    // closest of its three edges, which is exact for a segment-like triangle.
    Vec3 best = a;
    *bary = Vec3(1, 0, 0);
    double best_d2 = (p - a).squaredNorm();
    const Vec3 P[3] = {a, b, c};
    for (int k = 0; k < 3; ++k) {
      const Vec3& s0 = P[k];
      const Vec3& s1 = P[(k + 1) % 3];
      const Vec3 e = s1 - s0;
      const double ee = e.squaredNorm();
      const double s = ee > 0.0 ? std::clamp((p - s0).dot(e) / ee, 0.0, 1.0) : 0.0;
      const Vec3 q = s0 + s * e;
      const double d2q = (p - q).squaredNorm();
      if (d2q < best_d2) {
        best_d2 = d2q;
        best = q;
        Vec3 w = Vec3::Zero();
        w[k] = 1.0 - s;
        w[(k + 1) % 3] = s;
        *bary = w;
      }
    }
    return best;
  }
  const double denom = 1.0 / sum;
  const double v = vb * denom, w = vc * denom;
  *bary = Vec3(1.0 - v - w, v, w);
  return a + ab * v + ac * w;
}

inline double box_distance2(const Vec3& p, const CGAL::Bbox_3& box) {
  const double lo[3] = {box.xmin(), box.ymin(), box.zmin()};
  const double hi[3] = {box.xmax(), box.ymax(), box.zmax()};
  double d2 = 0.0;
  for (int i = 0; i < 3; ++i) {
    const double e = p[i] < lo[i] ? lo[i] - p[i] : (p[i] > hi[i] ? p[i] - hi[i] : 0.0);
    d2 += e * e;
  }
  return d2;
}


// The tree and the per-triangle data its traversals read. Never copied or
// moved after construction (the primitives hold iterators into cgal_triangles).
struct TreeData {
  std::vector<Triangle3> cgal_triangles;  // datum of the primitives (index = triangle id)
  std::vector<PackedTriangle> packed;
  Tree tree;

  int index_of(const Primitive& p) const { return static_cast<int>(p.id() - cgal_triangles.begin()); }
};

// Traversal traits for the nearest ray hit. Pruning: a box is visited only if
// the ray enters it before the best hit so far; boxes are visited nearest first.
struct RayTraversal {
  using Priority = double;
  const TreeData* impl;
  double best_t = kInf;
  int best = -1;
  double best_u = 0.0, best_v = 0.0;

  bool go_further() const { return true; }

  void intersection(const Ray& ray, const Primitive& primitive) {
    const int id = impl->index_of(primitive);
    double t, u, v;
    Ray r = ray;
    r.t_max = std::min(ray.t_max, best_t);
    if (moller_trumbore(impl->packed[id], r, &t, &u, &v)) {
      // Strictly nearer wins; equal t: the lower triangle index, so the answer
      // does not depend on the traversal order.
      if (t < best_t || (t == best_t && id < best)) {
        best_t = t;
        best = id;
        best_u = u;
        best_v = v;
      }
    }
  }

  template <class Node>
  bool do_intersect(const Ray& ray, const Node& node) const {
    double t0;
    Ray r = ray;
    r.t_max = std::min(ray.t_max, best_t);
    return ray_box(r, node.bbox(), &t0);
  }

  template <class Node>
  std::pair<bool, Priority> do_intersect_with_priority(const Ray& ray, const Node& node) const {
    double t0 = 0.0;
    Ray r = ray;
    r.t_max = std::min(ray.t_max, best_t);
    const bool hit = ray_box(r, node.bbox(), &t0);
    return {hit, -t0};
  }
};

struct ClosestTraversal {
  using Priority = double;
  const TreeData* impl;
  double best_d2 = kInf;
  int best = -1;
  Vec3 best_point = Vec3::Zero();
  Vec3 best_bary = Vec3::Zero();

  bool go_further() const { return true; }

  void intersection(const Vec3& p, const Primitive& primitive) {
    const int id = impl->index_of(primitive);
    const PackedTriangle& tri = impl->packed[id];
    Vec3 bary;
    const Vec3 q = closest_on_triangle(p, tri.a, tri.a + tri.e1, tri.a + tri.e2, &bary);
    const double d2 = (p - q).squaredNorm();
    if (d2 < best_d2 || (d2 == best_d2 && id < best)) {
      best_d2 = d2;
      best = id;
      best_point = q;
      best_bary = bary;
    }
  }

  template <class Node>
  bool do_intersect(const Vec3& p, const Node& node) const {
    return box_distance2(p, node.bbox()) <= best_d2;
  }

  template <class Node>
  std::pair<bool, Priority> do_intersect_with_priority(const Vec3& p, const Node& node) const {
    const double d2 = box_distance2(p, node.bbox());
    return {d2 <= best_d2, -d2};
  }
};

std::string mesh_label(const TriangleMesh& mesh) {
  return mesh.name.empty() ? std::string("<mesh>") : mesh.name;
}

}  // namespace

struct TriangleTree::Impl {
  TriangleMesh mesh;
  TreeData data;
};

TriangleTree::TriangleTree(const TriangleMesh& mesh) : impl_(std::make_unique<Impl>()) {
  const int n = mesh.num_vertices();
  for (int i = 0; i < n; ++i) {
    if (!mesh.V.row(i).allFinite()) {
      throw InputError(mesh_label(mesh), 0,
                       "TriangleTree: expected finite vertex coordinates, found non-finite "
                       "vertex " + std::to_string(i));
    }
  }
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    for (int k = 0; k < 3; ++k) {
      if (mesh.F(t, k) < 0 || mesh.F(t, k) >= n) {
        throw InputError(mesh_label(mesh), 0,
                         "TriangleTree: expected vertex indices in [0, " + std::to_string(n) +
                             "), found " + std::to_string(mesh.F(t, k)) + " in triangle " +
                             std::to_string(t));
      }
    }
  }
  impl_->mesh = mesh;
  const int nt = mesh.num_triangles();
  impl_->data.cgal_triangles.reserve(nt);
  impl_->data.packed.reserve(nt);
  for (int t = 0; t < nt; ++t) {
    const Vec3 a = mesh.vertex(mesh.F(t, 0));
    const Vec3 b = mesh.vertex(mesh.F(t, 1));
    const Vec3 c = mesh.vertex(mesh.F(t, 2));
    impl_->data.cgal_triangles.emplace_back(K::Point_3(a.x(), a.y(), a.z()), K::Point_3(b.x(), b.y(), b.z()),
                                       K::Point_3(c.x(), c.y(), c.z()));
    impl_->data.packed.push_back({a, b - a, c - a, (b - a).cross(c - a).norm()});
  }
  impl_->data.tree.insert(impl_->data.cgal_triangles.cbegin(), impl_->data.cgal_triangles.cend());
  // Build now, so that const queries never mutate the tree (thread safety), and
  // skip CGAL's kd-tree for distance queries (our closest-point traversal does
  // not use it).
  impl_->data.tree.do_not_accelerate_distance_queries();
  impl_->data.tree.build();
}

TriangleTree::~TriangleTree() = default;
TriangleTree::TriangleTree(TriangleTree&&) noexcept = default;
TriangleTree& TriangleTree::operator=(TriangleTree&&) noexcept = default;

const TriangleMesh& TriangleTree::mesh() const { return impl_->mesh; }

namespace {

Ray make_ray(const Vec3& origin, const Vec3& direction, double max_distance, const char* where) {
  const double len = direction.norm();
  if (!(len > 0.0) || !std::isfinite(len) || !origin.allFinite() || std::isnan(max_distance)) {
    throw NumericalError(std::string("TriangleTree::") + where +
                         ": expected a finite origin and a finite non-zero direction, found origin (" +
                         std::to_string(origin.x()) + ", " + std::to_string(origin.y()) + ", " +
                         std::to_string(origin.z()) + "), |direction| = " + std::to_string(len));
  }
  Ray ray;
  ray.o = origin;
  ray.d = direction / len;
  ray.inv_d = ray.d.cwiseInverse();
  ray.t_max = max_distance;
  return ray;
}

RayHit make_hit(int triangle, const Ray& ray, double t, double u,
                double v) {
  RayHit hit;
  hit.triangle = triangle;
  hit.distance = t;
  hit.point = ray.o + t * ray.d;
  hit.barycentric = clamped_barycentric(u, v);
  return hit;
}

}  // namespace

std::optional<RayHit> TriangleTree::first_hit(const Vec3& origin, const Vec3& direction,
                                              double max_distance) const {
  return first_hit(origin, direction, max_distance, HitSide::kBoth);
}

std::optional<RayHit> TriangleTree::first_hit(const Vec3& origin, const Vec3& direction, double max_distance,
                                              HitSide side) const {
  Ray ray = make_ray(origin, direction, max_distance, "first_hit");
  ray.side = side;
  if (max_distance < 0.0) return std::nullopt;
  RayTraversal traversal{&impl_->data};
  impl_->data.tree.traversal_with_priority(ray, traversal);
  if (traversal.best < 0) return std::nullopt;
  return make_hit(traversal.best, ray, traversal.best_t, traversal.best_u, traversal.best_v);
}

std::optional<RayHit> TriangleTree::hit_triangle(int triangle, const Vec3& origin, const Vec3& direction,
                                                 double max_distance) const {
  return hit_triangle(triangle, origin, direction, max_distance, HitSide::kBoth);
}

std::optional<RayHit> TriangleTree::hit_triangle(int triangle, const Vec3& origin, const Vec3& direction,
                                                 double max_distance, HitSide side) const {
  if (triangle < 0 || triangle >= static_cast<int>(impl_->data.packed.size())) {
    throw std::out_of_range("TriangleTree::hit_triangle: triangle " + std::to_string(triangle) +
                            " outside [0, " + std::to_string(impl_->data.packed.size()) + ")");
  }
  Ray ray = make_ray(origin, direction, max_distance, "hit_triangle");
  ray.side = side;
  double t, u, v;
  if (!moller_trumbore(impl_->data.packed[triangle], ray, &t, &u, &v)) return std::nullopt;
  return make_hit(triangle, ray, t, u, v);
}

ClosestPoint TriangleTree::closest_point(const Vec3& p) const {
  if (!p.allFinite()) {
    throw NumericalError("TriangleTree::closest_point: expected a finite query point, found (" +
                         std::to_string(p.x()) + ", " + std::to_string(p.y()) + ", " +
                         std::to_string(p.z()) + ")");
  }
  ClosestTraversal traversal{&impl_->data};
  impl_->data.tree.traversal_with_priority(p, traversal);
  ClosestPoint result;
  result.triangle = traversal.best;
  if (traversal.best < 0) {  // empty mesh
    result.point = Vec3::Constant(kInf);
    result.barycentric = Vec3::Zero();
    result.distance = kInf;
    return result;
  }
  result.point = traversal.best_point;
  result.barycentric = traversal.best_bary;
  result.distance = std::sqrt(traversal.best_d2);
  return result;
}

std::vector<int> TriangleTree::triangles_in_box(const Vec3& lo, const Vec3& hi) const {
  std::vector<int> out;
  if (!(lo.array() <= hi.array()).all()) return out;  // empty (or NaN) box
  const K::Iso_cuboid_3 box(K::Point_3(lo.x(), lo.y(), lo.z()), K::Point_3(hi.x(), hi.y(), hi.z()));
  std::vector<TriangleIterator> ids;
  impl_->data.tree.all_intersected_primitives(box, std::back_inserter(ids));
  out.reserve(ids.size());
  for (const auto& it : ids) out.push_back(static_cast<int>(it - impl_->data.cgal_triangles.cbegin()));
  std::sort(out.begin(), out.end());
  return out;
}

// ------------------------------------------------------ ClosedSurfaceSide --

struct ClosedSurfaceSide::Impl {
  using SurfaceMesh = CGAL::Surface_mesh<K::Point_3>;
  SurfaceMesh mesh;
  std::unique_ptr<CGAL::Side_of_triangle_mesh<SurfaceMesh, K>> side;
};

ClosedSurfaceSide::ClosedSurfaceSide(const TriangleMesh& closed_mesh) : impl_(std::make_unique<Impl>()) {
  ValidationOptions closed;
  closed.require_closed = true;
  const ValidationReport report = validate(closed_mesh, closed);
  if (!report.ok())
    throw InputError(closed_mesh.name.empty() ? "<mesh>" : closed_mesh.name, 0,
                     "inside/outside test: expected a closed, consistently oriented surface, found:\n" +
                         report.summary());
  std::vector<Impl::SurfaceMesh::Vertex_index> v(closed_mesh.num_vertices());
  for (int i = 0; i < closed_mesh.num_vertices(); ++i)
    v[i] = impl_->mesh.add_vertex(K::Point_3(closed_mesh.V(i, 0), closed_mesh.V(i, 1), closed_mesh.V(i, 2)));
  for (int t = 0; t < closed_mesh.num_triangles(); ++t)
    if (impl_->mesh.add_face(v[closed_mesh.F(t, 0)], v[closed_mesh.F(t, 1)], v[closed_mesh.F(t, 2)]) ==
        Impl::SurfaceMesh::null_face())
      throw InputError(closed_mesh.name.empty() ? "<mesh>" : closed_mesh.name, 0,
                       "inside/outside test: expected a manifold surface, found triangle " + std::to_string(t) +
                           " cannot be added (a non-manifold vertex)");
  impl_->side = std::make_unique<CGAL::Side_of_triangle_mesh<Impl::SurfaceMesh, K>>(impl_->mesh);
}

ClosedSurfaceSide::~ClosedSurfaceSide() = default;
ClosedSurfaceSide::ClosedSurfaceSide(ClosedSurfaceSide&&) noexcept = default;
ClosedSurfaceSide& ClosedSurfaceSide::operator=(ClosedSurfaceSide&&) noexcept = default;

ClosedSurfaceSide::Side ClosedSurfaceSide::side(const Vec3& p) const {
  switch ((*impl_->side)(K::Point_3(p.x(), p.y(), p.z()))) {
    case CGAL::ON_BOUNDED_SIDE: return Side::kInside;
    case CGAL::ON_BOUNDARY: return Side::kOnBoundary;
    default: return Side::kOutside;
  }
}

}  // namespace arthrosim::common
