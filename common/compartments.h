#pragma once
// Medial/lateral compartments of one tibial cartilage mesh holding both
// plateaus: THE rule shared by the prepare stage (which splits such a mesh
// into <name>_medial and <name>_lateral surfaces) and stage 1 (which splits
// one tibial contact surface's force per compartment), so both agree.
//
// Given the medial-to-lateral direction u (in the mesh's frame; from the
// model: the meshes.yaml manifest's `split: {lateral: ...}` or the model
// file's `split_lateral` on the surface), a triangle is lateral when
//  - the mesh has two or more connected components: the triangle's component
//    lies nearer (area-weighted centroid projected on u) to the more lateral
//    of the two largest components than to the other;
//  - the mesh is one connected piece: its centroid's projection on u exceeds
//    the cut c of the 1-D 2-means of the area-weighted centroid projections
//    (the plane normal to u at c: a sagittal plane through the gap between
//    the plateaus, the intercondylar region).
#include <vector>

#include "common/mesh.h"

namespace arthrosim::common {

struct CompartmentSplit {
  std::vector<char> is_lateral;  ///< per triangle: 1 lateral, 0 medial
  int components = 0;            ///< connected components of the mesh
  /// >= 2 components: distance along u between the two largest ones'
  /// area-weighted centroids [mesh unit]; one piece: the cut c along u.
  double separation = 0.0;
  double cut = 0.0;
  int medial_triangles() const;
  int lateral_triangles() const;
};

/// Classifies every triangle of `mesh` (u need not be unit; non-zero).
CompartmentSplit split_medial_lateral(const TriangleMesh& mesh, const Vec3& lateral);

}  // namespace arthrosim::common
