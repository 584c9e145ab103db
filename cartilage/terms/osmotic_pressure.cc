#include "cartilage/terms/osmotic_pressure.h"

#include <algorithm>
#include <functional>

#include "cartilage/surface_model.h"
#include "common/error.h"

namespace arthrosim::cartilage {

SurfaceTermInfo osmotic_pressure_term() {
  return {"osmotic_pressure", "", {}, [](const SurfaceTermContext& c) {
            const double p = c.parameters.osmotic_pressure_Pa, T = c.parameters.osmotic_ramp_s;
            c.model.add_pressure("osmotic_pressure", -1.0, [p, T](double t) {
              if (!(T > 0) || t >= T) return p;
              const double u = std::max(t, 0.0) / T;
              return p * u * u * (3 - 2 * u);
            });
          }};
}

}  // namespace arthrosim::cartilage
