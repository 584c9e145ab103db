#pragma once
// Internal to the surface terms (cartilage/terms/): small pieces several
// terms share.
#include <Eigen/Core>
#include <vector>

#include "cartilage/shell_model.h"

namespace arthrosim::cartilage {

/// [a]x, the cross-product matrix: skew(a) b = a x b.
inline Eigen::Matrix3d skew(const Eigen::Vector3d& a) {
  Eigen::Matrix3d S;
  S << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
  return S;
}

/// Adds per-element forces fe (and kq times the element tangents Ke, when K)
/// to F and K serially in element order, so that a term that evaluates its
/// elements in parallel gives bit-identical sums for any thread count.
inline void scatter_element_results(const ShellModel& model, const std::vector<Vector24>& fe,
                                    const std::vector<Matrix24>& Ke, double kq, Eigen::VectorXd& F,
                                    TangentAssembler* K) {
  double* values = K != nullptr ? K->matrix().valuePtr() : nullptr;
  const int ne = model.num_elements();
  for (int e = 0; e < ne; ++e) {
    for (int l = 0; l < 24; ++l) F(model.global_index(e, l)) += fe[e](l);
    if (values == nullptr) continue;
    const int* idx = model.element_value_indices(e);
    for (int m = 0; m < 24; ++m)
      for (int l = 0; l < 24; ++l) values[idx[24 * l + m]] += kq * Ke[e](l, m);
  }
}

}  // namespace arthrosim::cartilage
