#pragma once
// periphery_fixed: the rim nodes carried by the bone -- all six coordinates eliminated
// (ShellModel::add_periphery_fixed), or tied in the tangent plane only (the penalty term here,
// ShellModel::add_periphery_tangential).
#include <memory>

#include "cartilage/shell_model.h"
#include "cartilage/surface_terms.h"

namespace arthrosim::cartilage {
std::unique_ptr<ShellTerm> make_periphery_tangential_term(const ShellModel& model, std::vector<int> nodes,
                                                          double k_t_N_m3, BoneMotion bone);
/// Its registration (cartilage/surface_terms.cc lists it once).
SurfaceTermInfo periphery_fixed_term();
}  // namespace arthrosim::cartilage
