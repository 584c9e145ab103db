#pragma once
// Which lattice sites lie inside a closed triangle mesh, line by line: along
// each grid line every crossing with the surface is found with the existing
// CGAL ray queries (common::TriangleTree::first_hit, repeated from just past
// each hit), and a site is inside when the next crossing beyond it is a back
// face (the ray leaves the body there). Robust to rays through edges and
// vertices (the two triangles sharing the point are met at the same distance;
// one is kept) and to grazing touches (only the next genuine crossing after a
// site decides).
#include <vector>

#include "common/mesh.h"
#include "common/spatial.h"

namespace arthrosim::shockwave {

class LineContainment {
 public:
  /// `mesh` closed and outward oriented [m].
  explicit LineContainment(const common::TriangleMesh& mesh);

  /// For the line origin + t * (1, 0, 0), t in [0, length]: sets inside[k]
  /// for the points at t_k = positions[k] (ascending).
  void classify_line(const common::Vec3& origin, double length, const std::vector<double>& positions,
                     std::vector<char>* inside) const;
  const common::TriangleTree& tree() const { return tree_; }
  const common::BoundingBox& box() const { return box_; }

 private:
  common::TriangleTree tree_;
  common::Points3 normals_;
  common::BoundingBox box_;
};

}  // namespace arthrosim::shockwave
