#pragma once
// point_loads: nodal forces on positions scaled by a time function (ShellModel::add_point_loads).
#include <memory>

#include "cartilage/shell_model.h"
#include "cartilage/surface_terms.h"

namespace arthrosim::cartilage {
std::unique_ptr<ShellTerm> make_point_loads_term(const ShellModel& model, std::string name,
                                                 std::vector<std::pair<int, Eigen::Vector3d>> loads,
                                                 std::function<double(double)> scale);
/// Its registration (cartilage/surface_terms.cc lists it once).
SurfaceTermInfo point_loads_term();
}  // namespace arthrosim::cartilage
