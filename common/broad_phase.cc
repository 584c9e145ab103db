#include "common/broad_phase.h"

#include <CGAL/Bbox_3.h>
#include <CGAL/box_intersection_d.h>

#include <algorithm>

namespace arthrosim::common {

std::vector<std::pair<int, int>> overlapping_boxes(const std::vector<Box3>& a, const std::vector<Box3>& b) {
  using CgalBox = CGAL::Box_intersection_d::Box_with_info_d<double, 3, int>;
  auto convert = [](const std::vector<Box3>& in) {
    std::vector<CgalBox> out;
    out.reserve(in.size());
    for (size_t i = 0; i < in.size(); ++i) {
      const Box3& x = in[i];
      if ((x.lo.array() > x.hi.array()).any()) continue;  // empty: overlaps nothing
      out.emplace_back(CGAL::Bbox_3(x.lo.x(), x.lo.y(), x.lo.z(), x.hi.x(), x.hi.y(), x.hi.z()),
                       static_cast<int>(i));
    }
    return out;
  };
  std::vector<CgalBox> A = convert(a), B = convert(b);
  std::vector<std::pair<int, int>> pairs;
  if (A.empty() || B.empty()) return pairs;
  CGAL::box_intersection_d(A.begin(), A.end(), B.begin(), B.end(),
                           [&](const CgalBox& x, const CgalBox& y) { pairs.emplace_back(x.info(), y.info()); });
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  return pairs;
}

}  // namespace arthrosim::common
