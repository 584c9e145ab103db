#pragma once
// osmotic_pressure: the seed's osmotic swelling pressure on the inner face, a pressure term (pressure.h) ramped by a
// smoothstep over osmotic_ramp_s.
#include "cartilage/shell_model.h"
#include "cartilage/surface_terms.h"

namespace arthrosim::cartilage {
/// Its registration (cartilage/surface_terms.cc lists it once).
SurfaceTermInfo osmotic_pressure_term();
}  // namespace arthrosim::cartilage
