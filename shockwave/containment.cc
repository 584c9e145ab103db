#include "shockwave/containment.h"

namespace arthrosim::shockwave {

LineContainment::LineContainment(const common::TriangleMesh& mesh)
    : tree_(mesh), normals_(common::triangle_normals(mesh)), box_(common::bounding_box(mesh)) {}

void LineContainment::classify_line(const common::Vec3& origin, double length, const std::vector<double>& positions,
                                    std::vector<char>* inside) const {
  inside->assign(positions.size(), 0);
  if (positions.empty()) return;
  // Lines that miss the bounding box cannot be inside.
  if (origin.y() < box_.lo.y() || origin.y() > box_.hi.y() || origin.z() < box_.lo.z() || origin.z() > box_.hi.z())
    return;
  const common::Vec3 dir(1.0, 0.0, 0.0);
  struct Crossing {
    double t;
    bool leaving;
  };
  std::vector<Crossing> crossings;
  const double eps = 1e-9;  // [m] past a hit before the next query
  double t = 0.0;
  while (t <= length) {
    const auto hit = tree_.first_hit(origin + t * dir, dir, length - t);
    if (!hit) break;
    const double th = t + hit->distance;
    crossings.push_back({th, normals_.row(hit->triangle).x() > 0.0});
    t = th + eps;
  }
  size_t c = 0;
  for (size_t k = 0; k < positions.size(); ++k) {
    while (c < crossings.size() && crossings[c].t <= positions[k]) ++c;
    (*inside)[k] = (c < crossings.size() && crossings[c].leaving) ? 1 : 0;
  }
}

}  // namespace arthrosim::shockwave
