// Broad phase: overlapping_boxes against a brute-force double loop, and
// CachedOverlaps against overlapping_boxes over a sequence of moves (small
// ones that reuse the kept superset, large ones that rebuild it).
#include "common/broad_phase.h"

#include <gtest/gtest.h>

#include <random>

#include "common/error.h"

namespace arthrosim::common {
namespace {

// Brute force, written independently of boxes_overlap: two closed intervals
// overlap unless one ends before the other begins; empty boxes never do.
std::vector<std::pair<int, int>> brute_pairs(const std::vector<Box3>& a, const std::vector<Box3>& b) {
  auto empty = [](const Box3& x) { return x.lo.x() > x.hi.x() || x.lo.y() > x.hi.y() || x.lo.z() > x.hi.z(); };
  std::vector<std::pair<int, int>> out;
  for (size_t i = 0; i < a.size(); ++i)
    for (size_t j = 0; j < b.size(); ++j) {
      if (empty(a[i]) || empty(b[j])) continue;
      bool separated = false;
      for (int d = 0; d < 3; ++d)
        if (a[i].hi[d] < b[j].lo[d] || b[j].hi[d] < a[i].lo[d]) separated = true;
      if (!separated) out.emplace_back(static_cast<int>(i), static_cast<int>(j));
    }
  return out;  // sorted by (i, j) by construction
}

// Boxes as the mesh contact builds them: half-width r around points of a,
// bounding boxes of "triangles" of three consecutive points of b.
std::vector<Box3> point_boxes(const Points3& p, double r) {
  std::vector<Box3> out(p.rows());
  for (int i = 0; i < p.rows(); ++i) {
    out[i].lo = p.row(i).transpose().array() - r;
    out[i].hi = p.row(i).transpose().array() + r;
  }
  return out;
}
std::vector<Box3> triangle_boxes(const Points3& p) {
  std::vector<Box3> out(p.rows() / 3);
  for (size_t t = 0; t < out.size(); ++t) {
    out[t].lo = p.middleRows(3 * t, 3).colwise().minCoeff().transpose();
    out[t].hi = p.middleRows(3 * t, 3).colwise().maxCoeff().transpose();
  }
  return out;
}

TEST(BroadPhase, OverlappingBoxesMatchesBruteForceIncludingTouchingAndEmpty) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Points3 pa(300, 3), pb(600, 3);
  for (int i = 0; i < pa.rows(); ++i) pa.row(i) << u(rng), u(rng), u(rng);
  for (int i = 0; i < pb.rows(); ++i) pb.row(i) << u(rng), u(rng), u(rng);
  std::vector<Box3> a = point_boxes(pa, 0.05), b = triangle_boxes(pb);
  // A touching pair (closed boxes) and an empty box.
  a[0].lo = Eigen::Vector3d(2, 2, 2);
  a[0].hi = Eigen::Vector3d(3, 3, 3);
  b[0].lo = Eigen::Vector3d(3, 3, 3);
  b[0].hi = Eigen::Vector3d(4, 4, 4);
  a[1].lo = Eigen::Vector3d(0.5, 0.5, 0.5);
  a[1].hi = Eigen::Vector3d(0.4, 0.6, 0.6);
  const auto got = overlapping_boxes(a, b);
  EXPECT_EQ(got, brute_pairs(a, b));
  EXPECT_NE(std::find(got.begin(), got.end(), std::make_pair(0, 0)), got.end());
  EXPECT_GT(got.size(), 50u);  // not a vacuous comparison
  for (const auto& [i, j] : got) EXPECT_TRUE(boxes_overlap(a[i], b[j]));
}

TEST(BroadPhase, CachedOverlapsGivesTheFreshPairsAndRebuildsOnlyBeyondItsMargin) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0), s(-1.0, 1.0);
  Points3 pa(400, 3), pb(900, 3);
  for (int i = 0; i < pa.rows(); ++i) pa.row(i) << u(rng), u(rng), 0.1 * u(rng);
  for (int i = 0; i < pb.rows(); ++i) pb.row(i) << u(rng), u(rng), 0.1 * u(rng) + 0.05;
  const double r = 0.03, margin = 0.2 * r;
  CachedOverlaps cache(margin);
  long expected_rebuilds = 0;
  for (int call = 0; call < 40; ++call) {
    // Every tenth call moves far (a new time step); the others jitter each
    // point by at most 0.1 margin in each coordinate from its current place,
    // so a few calls in a row stay within the margin and then one does not.
    const double amp = call % 10 == 0 ? 5 * margin : 0.1 * margin / std::sqrt(3.0);
    for (int i = 0; i < pa.rows(); ++i) pa.row(i) += amp * Eigen::RowVector3d(s(rng), s(rng), s(rng));
    for (int i = 0; i < pb.rows(); ++i) pb.row(i) += amp * Eigen::RowVector3d(s(rng), s(rng), s(rng));
    const std::vector<Box3> a = point_boxes(pa, r), b = triangle_boxes(pb);
    const auto fresh = overlapping_boxes(a, b);
    ASSERT_EQ(cache.pairs(a, b, pa, pb), fresh) << "call " << call;
    ASSERT_GT(fresh.size(), 20u);
    expected_rebuilds = cache.rebuilds();
  }
  // 4 large moves force at least 4 rebuilds; the small ones are mostly reused.
  EXPECT_GE(expected_rebuilds, 4);
  EXPECT_GT(cache.reuses(), 20);
  EXPECT_EQ(cache.rebuilds() + cache.reuses(), 40);
  EXPECT_THROW(CachedOverlaps(0.0), InputError);
}

}  // namespace
}  // namespace arthrosim::common
