#include "common/broad_phase.h"

#include <CGAL/Bbox_3.h>
#include <CGAL/box_intersection_d.h>

#include <algorithm>
#include <string>

#include "common/error.h"

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

bool boxes_overlap(const Box3& a, const Box3& b) {
  for (int d = 0; d < 3; ++d)
    if (!(a.lo[d] <= a.hi[d] && b.lo[d] <= b.hi[d] && a.lo[d] <= b.hi[d] && b.lo[d] <= a.hi[d])) return false;
  return true;
}

CachedOverlaps::CachedOverlaps(double margin) : margin_(margin) {
  if (!(margin > 0)) throw InputError("CachedOverlaps: margin must be > 0 m, found " + std::to_string(margin));
}

std::vector<std::pair<int, int>> CachedOverlaps::pairs(const std::vector<Box3>& a, const std::vector<Box3>& b,
                                                       const Points3& pa, const Points3& pb) {
  auto largest_move = [](const Points3& p, const Points3& p0) {
    return p.rows() == 0 ? 0.0 : (p - p0).rowwise().norm().maxCoeff();
  };
  bool reuse = valid_ && a.size() == na_ && b.size() == nb_ && pa.rows() == pa0_.rows() && pb.rows() == pb0_.rows();
  // 0.99: room for the rounding of the boxes' bounds.
  if (reuse) reuse = largest_move(pa, pa0_) + largest_move(pb, pb0_) <= 0.99 * margin_;
  if (!reuse) {
    std::vector<Box3> inflated = a;
    for (Box3& x : inflated) {
      x.lo.array() -= margin_;
      x.hi.array() += margin_;
    }
    superset_ = overlapping_boxes(inflated, b);
    pa0_ = pa;
    pb0_ = pb;
    na_ = a.size();
    nb_ = b.size();
    valid_ = true;
    ++rebuilds_;
  } else {
    ++reuses_;
  }
  std::vector<std::pair<int, int>> out;
  out.reserve(superset_.size());
  for (const auto& [i, j] : superset_)
    if (boxes_overlap(a[i], b[j])) out.emplace_back(i, j);
  return out;
}

}  // namespace arthrosim::common
