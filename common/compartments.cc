#include "common/compartments.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace arthrosim::common {

int CompartmentSplit::medial_triangles() const {
  return static_cast<int>(std::count(is_lateral.begin(), is_lateral.end(), 0));
}
int CompartmentSplit::lateral_triangles() const {
  return static_cast<int>(is_lateral.size()) - medial_triangles();
}

CompartmentSplit split_medial_lateral(const TriangleMesh& mesh, const Vec3& lateral) {
  const Vec3 u = lateral.normalized();
  const Eigen::VectorXd area = triangle_areas(mesh);
  const Points3 centroid = triangle_centroids(mesh);
  const int nt = mesh.num_triangles();
  Eigen::VectorXd proj(nt);
  for (int t = 0; t < nt; ++t) proj[t] = centroid.row(t).dot(u);
  CompartmentSplit r;
  int count = 0;
  const std::vector<int> comp = connected_components(mesh, &count);
  r.components = count;
  r.is_lateral.assign(nt, 0);
  if (count >= 2) {
    std::vector<double> carea(count, 0.0), cproj(count, 0.0);
    for (int t = 0; t < nt; ++t) {
      carea[comp[t]] += area[t];
      cproj[comp[t]] += area[t] * proj[t];
    }
    for (int c = 0; c < count; ++c) cproj[c] /= carea[c];
    std::vector<int> order(count);
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return carea[a] > carea[b]; });
    const int a = order[0], b = order[1];
    const double lat = std::max(cproj[a], cproj[b]), med = std::min(cproj[a], cproj[b]);
    for (int t = 0; t < nt; ++t) r.is_lateral[t] = std::abs(cproj[comp[t]] - lat) < std::abs(cproj[comp[t]] - med);
    r.separation = lat - med;
  } else if (nt > 0) {
    // One piece: 1-D 2-means of the area-weighted centroid projections.
    double lo = proj.minCoeff(), hi = proj.maxCoeff();
    double cut = 0.5 * (lo + hi);
    for (int it = 0; it < 100; ++it) {
      double w0 = 0, s0 = 0, w1 = 0, s1 = 0;
      for (int t = 0; t < nt; ++t)
        (proj[t] > cut ? (w1 += area[t], s1 += area[t] * proj[t]) : (w0 += area[t], s0 += area[t] * proj[t]));
      if (w0 <= 0 || w1 <= 0) break;
      const double next = 0.5 * (s0 / w0 + s1 / w1);
      if (next == cut) break;
      cut = next;
    }
    for (int t = 0; t < nt; ++t) r.is_lateral[t] = proj[t] > cut;
    r.cut = cut;
  }
  return r;
}

}  // namespace arthrosim::common
