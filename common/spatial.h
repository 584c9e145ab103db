#pragma once
// Spatial queries on a triangle mesh, backed by CGAL's AABB tree. CGAL is an
// implementation detail (pimpl): this header never includes it.
#include <memory>
#include <optional>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::common {

struct RayHit {
  int triangle = -1;        ///< index into the mesh's F
  Vec3 point;               ///< hit point [m]
  Vec3 barycentric;         ///< weights of F(triangle, 0..2)
  double distance = 0.0;    ///< along the ray, in units of |direction| = 1 [m]
};

struct ClosestPoint {
  int triangle = -1;
  Vec3 point;
  Vec3 barycentric;
  double distance = 0.0;    ///< |query - point| [m]
};

/// Which triangle sides a ray may hit. Front: the ray travels against the
/// triangle normal (direction . n < 0, it arrives from the side the normal
/// points to); back: direction . n > 0.
enum class HitSide { kBoth, kFront, kBack };

/// Immutable AABB tree over a triangle mesh (the mesh is copied in).
class TriangleTree {
 public:
  explicit TriangleTree(const TriangleMesh& mesh);
  ~TriangleTree();
  TriangleTree(TriangleTree&&) noexcept;
  TriangleTree& operator=(TriangleTree&&) noexcept;

  const TriangleMesh& mesh() const;

  /// First intersection of the ray origin + t * direction, 0 <= t <= max_distance
  /// (direction need not be unit; distance is reported in metres).
  /// The direction is normalised internally, so max_distance and
  /// RayHit::distance are both metres along the ray. Both faces of a triangle
  /// are hit. Equal distances: the lower triangle index. Thread-safe (const,
  /// no heap allocation). A zero/non-finite direction throws NumericalError.
  std::optional<RayHit> first_hit(const Vec3& origin, const Vec3& direction,
                                  double max_distance = 1e30) const;
  /// As above, but only triangles seen from `side` count (others are passed
  /// through, so the result is the first hit of that side, not the first hit
  /// filtered afterwards).
  std::optional<RayHit> first_hit(const Vec3& origin, const Vec3& direction, double max_distance,
                                  HitSide side) const;
  /// Closest point on the surface to p (ties: the lower triangle index). An
  /// empty mesh gives triangle -1 and an infinite distance.
  ClosestPoint closest_point(const Vec3& p) const;
  /// Triangles whose bounding boxes overlap the axis-aligned box [lo, hi] and
  /// that truly intersect it, sorted ascending.
  std::vector<int> triangles_in_box(const Vec3& lo, const Vec3& hi) const;

  /// Exact ray/triangle test on one triangle (Moller-Trumbore, no tree); used
  /// to test a cached guess before a tree query.
  std::optional<RayHit> hit_triangle(int triangle, const Vec3& origin, const Vec3& direction,
                                     double max_distance = 1e30) const;
  std::optional<RayHit> hit_triangle(int triangle, const Vec3& origin, const Vec3& direction,
                                     double max_distance, HitSide side) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Point-in-solid test of a closed triangle mesh (e.g. a bone): which side of
/// the surface a point lies on. CGAL::Side_of_triangle_mesh (ray parity with
/// exact predicates, so a ray through an edge or vertex is handled). The mesh
/// must be closed and consistently oriented (validate with require_closed);
/// InputError naming the mesh otherwise. Queries are const and thread-safe.
class ClosedSurfaceSide {
 public:
  enum class Side { kInside, kOnBoundary, kOutside };
  explicit ClosedSurfaceSide(const TriangleMesh& closed_mesh);
  ~ClosedSurfaceSide();
  ClosedSurfaceSide(ClosedSurfaceSide&&) noexcept;
  ClosedSurfaceSide& operator=(ClosedSurfaceSide&&) noexcept;
  Side side(const Vec3& p) const;
  bool inside(const Vec3& p) const { return side(p) == Side::kInside; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arthrosim::common
