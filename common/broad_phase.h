#pragma once
// Broad phase of collision detection: which boxes of one set overlap which
// boxes of another. Backed by CGAL's box_intersection_d (a streamed segment
// tree, Zomorodian & Edelsbrunner 2000); CGAL stays inside broad_phase.cc.
//
// Used by the deformable mesh-to-mesh contact (cartilage/mesh_contact.h):
// boxes are rebuilt from the current (deformed) positions at every
// evaluation, which costs O((n + m) log(n + m) + pairs) and needs no tree
// refitting. CachedOverlaps keeps a superset of the pairs (boxes inflated by
// a margin) while the boxes move less than the margin, so the repeated
// evaluations of one time step (Newton iterations, line-search trials) skip
// the segment tree and only filter the superset.
#include <Eigen/Core>
#include <utility>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::common {

/// Axis-aligned box [lo, hi] (closed).
struct Box3 {
  Eigen::Vector3d lo, hi;
};

/// Every pair (i, j) with boxes a[i] and b[j] overlapping (closed boxes:
/// touching counts), sorted by (i, j) so that the result does not depend on
/// the traversal order. Boxes with lo > hi in any axis overlap nothing.
std::vector<std::pair<int, int>> overlapping_boxes(const std::vector<Box3>& a, const std::vector<Box3>& b);

/// Whether two closed boxes overlap (empty boxes, lo > hi in an axis,
/// overlap nothing): the test overlapping_boxes applies.
bool boxes_overlap(const Box3& a, const Box3& b);

/// overlapping_boxes(a, b) for boxes that move a little between calls,
/// with the same pairs in the same order. The boxes are built by the caller
/// from two point sets, pa for a and pb for b, such that no face of a box
/// moves farther than the largest displacement of its set's points (true
/// for boxes of fixed half-width around points and for the bounding boxes
/// of triangles of points). A call computes the pairs of the boxes inflated
/// by `margin` and keeps them with the points; later calls reuse them while
/// (largest displacement of pa) + (largest displacement of pb) stays within
/// the margin, and filter them by the exact test. Every overlapping pair of
/// the current boxes is in that superset: a box of a moved by at most da and
/// one of b by at most db, so they overlapped within da + db at the kept
/// positions. Not thread-safe (one cache per caller).
class CachedOverlaps {
 public:
  /// margin > 0 [m].
  explicit CachedOverlaps(double margin);
  std::vector<std::pair<int, int>> pairs(const std::vector<Box3>& a, const std::vector<Box3>& b,
                                         const Points3& pa, const Points3& pb);
  long rebuilds() const { return rebuilds_; }
  long reuses() const { return reuses_; }

 private:
  double margin_;
  Points3 pa0_, pb0_;
  std::vector<std::pair<int, int>> superset_;
  size_t na_ = 0, nb_ = 0;
  bool valid_ = false;
  long rebuilds_ = 0, reuses_ = 0;
};

}  // namespace arthrosim::common
