#pragma once
// NaN/Inf guards. A non-finite number must stop a run with a message naming
// where it appeared (engineering standard), e.g.
//   check_finite(residual, "cartilage: shell residual, Newton iteration 3");
// throws NumericalError
//   "cartilage: shell residual, Newton iteration 3: non-finite value nan at (12, 2) of a 40 x 3 matrix".
#include <Eigen/Core>
#include <cmath>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "common/error.h"

namespace arthrosim::common {

/// Throws NumericalError naming `where` and the first offending index (in
/// row-major reading order: row by row) if any entry is NaN or +-Inf.
template <typename Derived>
void check_finite(const Eigen::DenseBase<Derived>& m, const std::string& where) {
  using Scalar = typename Derived::Scalar;
  static_assert(std::is_floating_point_v<Scalar>, "check_finite: floating point matrices only");
  if (m.derived().allFinite()) return;  // fast path, vectorized
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) {
      const Scalar v = m(i, j);
      if (std::isfinite(v)) continue;
      std::ostringstream s;
      s << where << ": non-finite value " << v;
      if (m.cols() == 1) {
        s << " at index " << i << " of a vector of size " << m.rows();
      } else if (m.rows() == 1) {
        s << " at index " << j << " of a vector of size " << m.cols();
      } else {
        s << " at (" << i << ", " << j << ") of a " << m.rows() << " x " << m.cols() << " matrix";
      }
      throw NumericalError(s.str());
    }
  }
}

/// Scalar version: "where: non-finite value inf".
inline void check_finite(double value, const std::string& where) {
  if (std::isfinite(value)) return;
  std::ostringstream s;
  s << where << ": non-finite value " << value;
  throw NumericalError(s.str());
}

/// std::vector version: "where: non-finite value nan at index 7 of 10".
inline void check_finite(const std::vector<double>& values, const std::string& where) {
  for (size_t i = 0; i < values.size(); ++i) {
    if (std::isfinite(values[i])) continue;
    std::ostringstream s;
    s << where << ": non-finite value " << values[i] << " at index " << i << " of " << values.size();
    throw NumericalError(s.str());
  }
}

}  // namespace arthrosim::common
