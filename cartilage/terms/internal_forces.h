#pragma once
// internal_forces: the elastic internal forces of every element (always built; not an effect).
#include <memory>

#include "cartilage/shell_model.h"

namespace arthrosim::cartilage {
std::unique_ptr<ShellTerm> make_internal_forces_term(ShellModel& model);
}  // namespace arthrosim::cartilage
