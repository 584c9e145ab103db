// NaN/Inf guards: the message names where and the first offending index.
#include "common/finite.h"

#include <gtest/gtest.h>

#include <limits>

namespace arthrosim::common {
namespace {

std::string message_of(auto&& fn) {
  try {
    fn();
  } catch (const NumericalError& e) {
    return e.what();
  }
  return "(no exception)";
}

TEST(Finite, FiniteValuesPass) {
  EXPECT_NO_THROW(check_finite(Eigen::MatrixXd::Ones(3, 4), "m"));
  EXPECT_NO_THROW(check_finite(1e308, "s"));
  EXPECT_NO_THROW(check_finite(std::vector<double>{0.0, -1.0}, "v"));
}

TEST(Finite, FirstOffendingIndexRowMajor) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  Eigen::MatrixXd m = Eigen::MatrixXd::Zero(4, 3);
  m(2, 0) = inf;  // row-major order: (1, 2) comes first
  m(1, 2) = nan;
  EXPECT_EQ(message_of([&] { check_finite(m, "shell residual, step 7"); }),
            "shell residual, step 7: non-finite value nan at (1, 2) of a 4 x 3 matrix");
  Eigen::VectorXd v = Eigen::VectorXd::Zero(5);
  v(3) = -inf;
  EXPECT_EQ(message_of([&] { check_finite(v, "q"); }), "q: non-finite value -inf at index 3 of a vector of size 5");
  EXPECT_EQ(message_of([&] { check_finite(m.row(2), "row"); }), "row: non-finite value inf at index 0 of a vector of size 3");
  EXPECT_EQ(message_of([&] { check_finite(nan, "stiffness"); }), "stiffness: non-finite value nan");
  EXPECT_EQ(message_of([&] { check_finite(std::vector<double>{1, 2, inf}, "forces"); }),
            "forces: non-finite value inf at index 2 of 3");
  Eigen::Array3d a(1, nan, 2);
  EXPECT_EQ(message_of([&] { check_finite(a, "array"); }), "array: non-finite value nan at index 1 of a vector of size 3");
}

}  // namespace
}  // namespace arthrosim::common
