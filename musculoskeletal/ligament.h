#pragma once
// Blankevoort (1991) ligament bundle: the force-strain law used by the
// lenhart2015 knee (seeds/002_3ffcc11eb7a447d9.txt, "Fourteen ligaments were
// represented by bundles of nonlinear elastic springs"; OpenSim's
// Blankevoort1991Ligament follows the same equations).
//
//   strain        e  = l / l0 - 1
//   strain rate   e' = (dl/dt) / l0
//   elastic force f_e = 0                      e <= 0
//                     = k e^2 / (2 e_t)        0 < e < e_t
//                     = k (e - e_t / 2)        e >= e_t
//   (value k e_t / 2 and slope k from both sides at e = e_t: C1)
//   damping       f_d = c e' s(e)   only while stretching (e > 0 and e' > 0), else 0,
//                 s(e) = smoothstep 3x^2 - 2x^3, x = e / e_s clamped to [0, 1]
//                 (smooths the switch-on of damping near e = 0, e_s = 0.01)
//   total         f = f_e + f_d >= 0 (both terms are non-negative by construction)
//
// Units: k [N per unit strain], l0 [m], c [N s] (force per unit strain rate).
#include <string>

namespace arthrosim::musculoskeletal {

struct BlankevoortParameters {
  /// Linear stiffness k [N per unit strain], > 0. lenhart2015: 150..10000 per bundle.
  double stiffness = 0.0;
  /// Slack (zero-force) length l0 [m], > 0.
  double slack_length = 0.0;
  /// Transition strain e_t between the quadratic toe and the linear region [-], > 0.
  /// Blankevoort 1991: 0.06.
  double transition_strain = 0.06;
  /// Damping coefficient c [N s] per unit strain rate, >= 0. OpenSim default 0.003.
  double damping = 0.003;
  /// Strain over which the damping switches on smoothly [-], > 0 (0.01).
  double damping_smoothing_strain = 0.01;
};

/// Throws common::InputError naming `where` and the bad property if a value is
/// outside its range.
void validate(const BlankevoortParameters& p, const std::string& where);

struct BlankevoortForce {
  double strain = 0.0;          ///< e [-]
  double strain_rate = 0.0;     ///< e' [1/s]
  double elastic = 0.0;         ///< f_e [N]
  double damping = 0.0;         ///< f_d [N]
  double total = 0.0;           ///< f_e + f_d [N]
  double dtotal_dlength = 0.0;  ///< d f / d l at fixed dl/dt [N/m]
  double dtotal_dspeed = 0.0;   ///< d f / d (dl/dt) [N s/m]
};

/// Elastic force and its strain derivative only (k e^2/(2 e_t) ... ), for tests.
double blankevoort_elastic(double strain, double stiffness, double transition_strain);

/// Force of one bundle at length l [m] and lengthening speed dl/dt [m/s].
BlankevoortForce blankevoort_force(const BlankevoortParameters& p, double length,
                                   double lengthening_speed);

}  // namespace arthrosim::musculoskeletal
