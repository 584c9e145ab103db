#pragma once
// prescribed_displacement: the generic box moved by displacement_m and the constraints with values, ramped (one
// NodeConstraint).
#include "cartilage/shell_model.h"
#include "cartilage/surface_terms.h"

namespace arthrosim::cartilage {
/// Its registration (cartilage/surface_terms.cc lists it once).
SurfaceTermInfo prescribed_displacement_term();
}  // namespace arthrosim::cartilage
