#pragma once
// inertia: M a with the model's constant consistent mass matrix (assembled by ShellModel::add_inertia).
#include <memory>

#include "cartilage/shell_model.h"
#include "cartilage/surface_terms.h"

namespace arthrosim::cartilage {
std::unique_ptr<ShellTerm> make_inertia_term(const ShellModel& model);
/// Its registration (cartilage/surface_terms.cc lists it once).
SurfaceTermInfo inertia_term();
}  // namespace arthrosim::cartilage
