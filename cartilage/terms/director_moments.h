#pragma once
// director_moments: a conservative couple on transverse gradients (ShellModel::add_director_moments; verification
// loads, not a scene effect).
#include <memory>

#include "cartilage/shell_model.h"

namespace arthrosim::cartilage {
std::unique_ptr<ShellTerm> make_director_moments_term(const ShellModel& model, std::string name,
                                                      const Eigen::Vector3d& axis,
                                                      std::vector<std::pair<int, double>> moments,
                                                      std::function<double(double)> scale);
}  // namespace arthrosim::cartilage
