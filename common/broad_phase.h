#pragma once
// Broad phase of collision detection: which boxes of one set overlap which
// boxes of another. Backed by CGAL's box_intersection_d (a streamed segment
// tree, Zomorodian & Edelsbrunner 2000); CGAL stays inside broad_phase.cc.
//
// Used by the deformable mesh-to-mesh contact (cartilage/mesh_contact.h):
// boxes are rebuilt from the current (deformed) positions at every
// evaluation, which costs O((n + m) log(n + m) + pairs) and needs no tree
// refitting.
#include <Eigen/Core>
#include <utility>
#include <vector>

namespace arthrosim::common {

/// Axis-aligned box [lo, hi] (closed).
struct Box3 {
  Eigen::Vector3d lo, hi;
};

/// Every pair (i, j) with boxes a[i] and b[j] overlapping (closed boxes:
/// touching counts), sorted by (i, j) so that the result does not depend on
/// the traversal order. Boxes with lo > hi in any axis overlap nothing.
std::vector<std::pair<int, int>> overlapping_boxes(const std::vector<Box3>& a, const std::vector<Box3>& b);

}  // namespace arthrosim::common
