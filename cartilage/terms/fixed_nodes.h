#pragma once
// fixed_nodes: the generic box and the constraints without values, eliminated at their reference values (one
// NodeConstraint).
#include "cartilage/shell_model.h"
#include "cartilage/surface_terms.h"

namespace arthrosim::cartilage {
/// Its registration (cartilage/surface_terms.cc lists it once).
SurfaceTermInfo fixed_nodes_term();
}  // namespace arthrosim::cartilage
