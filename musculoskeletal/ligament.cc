#include "musculoskeletal/ligament.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

namespace {
void require(bool ok, const std::string& where, const std::string& what, double found) {
  if (ok && std::isfinite(found)) return;
  std::ostringstream s;
  s << where << ": expected " << what << ", found " << found;
  throw common::InputError(s.str());
}
}  // namespace

void validate(const BlankevoortParameters& p, const std::string& where) {
  require(p.stiffness > 0.0, where, "stiffness > 0 [N per unit strain]", p.stiffness);
  require(p.slack_length > 0.0, where, "slack length > 0 [m]", p.slack_length);
  require(p.transition_strain > 0.0, where, "transition strain > 0", p.transition_strain);
  require(p.damping >= 0.0, where, "damping >= 0 [N s]", p.damping);
  require(p.damping_smoothing_strain > 0.0, where, "damping smoothing strain > 0",
          p.damping_smoothing_strain);
}

double blankevoort_elastic(double e, double k, double et) {
  if (e <= 0.0) return 0.0;
  if (e < et) return k * e * e / (2.0 * et);
  return k * (e - 0.5 * et);
}

BlankevoortForce blankevoort_force(const BlankevoortParameters& p, double length,
                                   double lengthening_speed) {
  BlankevoortForce r;
  const double l0 = p.slack_length, k = p.stiffness, et = p.transition_strain;
  r.strain = length / l0 - 1.0;
  r.strain_rate = lengthening_speed / l0;
  const double e = r.strain, ed = r.strain_rate;
  double dfe_de = 0.0;
  if (e > 0.0 && e < et) {
    r.elastic = k * e * e / (2.0 * et);
    dfe_de = k * e / et;
  } else if (e >= et) {
    r.elastic = k * (e - 0.5 * et);
    dfe_de = k;
  }
  // Damping only while the bundle is taut and lengthening; the smoothstep s(e)
  // makes the damping force continuous in e at e = 0.
  double dfd_de = 0.0, dfd_ded = 0.0;
  if (e > 0.0 && ed > 0.0 && p.damping > 0.0) {
    const double x = std::min(e / p.damping_smoothing_strain, 1.0);
    const double s = x * x * (3.0 - 2.0 * x);
    const double ds_de = x < 1.0 ? 6.0 * x * (1.0 - x) / p.damping_smoothing_strain : 0.0;
    r.damping = p.damping * ed * s;
    dfd_de = p.damping * ed * ds_de;
    dfd_ded = p.damping * s;
  }
  r.total = r.elastic + r.damping;
  r.dtotal_dlength = (dfe_de + dfd_de) / l0;
  r.dtotal_dspeed = dfd_ded / l0;
  return r;
}

}  // namespace arthrosim::musculoskeletal
