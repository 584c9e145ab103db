#include "biphasic/material.h"

#include <cmath>
#include <sstream>

#include "common/error.h"

namespace arthrosim::biphasic {

void validate(const Material& m, const std::string& where) {
  auto fail = [&](const char* what, const char* expected, double found) {
    std::ostringstream s;
    s << where << ": " << what << ": expected " << expected << ", found " << found;
    throw common::InputError(s.str());
  };
  if (!std::isfinite(m.aggregate_modulus_Pa) || m.aggregate_modulus_Pa <= 0.0)
    fail("aggregate modulus", "a value > 0 Pa", m.aggregate_modulus_Pa);
  if (!std::isfinite(m.poisson_ratio) || m.poisson_ratio < 0.0 || m.poisson_ratio >= 0.5)
    fail("Poisson's ratio", "a value in [0, 0.5)", m.poisson_ratio);
  if (!std::isfinite(m.permeability_m4_per_Ns) || m.permeability_m4_per_Ns <= 0.0)
    fail("permeability", "a value > 0 m^4/(N s)", m.permeability_m4_per_Ns);
}

}  // namespace arthrosim::biphasic
