#pragma once
// The shockwave pulse applied through the applicator (effect
// `applicator_pulse`).
//
// Shape (normalised to a peak of 1; after Cleveland, Chitnis & McClure 2007,
// "Acoustic field of a ballistic shock wave therapy device", Ultrasound Med
// Biol 33:1327, who measured for a ballistic source with a metal applicator a
// rectangular positive phase of about 4 us with rise times around 1 us,
// followed by a predominantly negative tail of about 20 us with a peak
// negative pressure of about 3/4 of the positive peak):
//   rise      0 <= t < t_r:            sin^2(pi t / (2 t_r))
//   plateau   t_r <= t < T+ - t_f:     1
//   fall      T+ - t_f <= t < T+:      cos^2(pi (t - T+ + t_f) / (2 t_f))
//   tail      T+ <= t < T+ + T-:       -f_tail sin(pi (t - T+) / T-)
//   then 0.
// Defaults: t_r = t_f = 1.5 us (10-90 % rise 0.89 us), T+ = 4 us,
// T- = 20 us, f_tail = 0.75. The measured tail oscillates; one half-sine of
// the same duration and peak stands for it.
//
// Calibration (seed eqs. 1-2): PII = I T_p = v^2 rho c T_p / 2 with v the
// particle velocity of a plane wave, v = p / (rho c), so
//   p_peak = sqrt(2 rho c PII / T_p),
// T_p the time from the onset to 90 % of the peak (seed section 3.3), and
// rho c the impedance of the medium the energy flux density is quoted in
// (default water, 1.5 MRayl: device EFDs are measured in water, IEC 61846;
// Cleveland & McAteer 2012). For reference the class also reports the EFD by
// its definition (1/(rho c)) int p^2 dt over the positive phase and over the
// whole pulse (references.md, "Shockwave").
//
// Two readings of eq. 2 drive the plate (option `efd_reference`):
//  - water: v is the particle velocity of the wave in water (impedance
//    `efd_impedance`); its pressure p(t) = rho c v(t) acts on the plate's
//    outer face (PressurePulse as the load of Simulation).
//  - applicator: v is the velocity of the plate ("calculated from the
//    parameters of the plates", seed section 1), rho c the plate's p-wave
//    impedance sqrt(rho (K + 4G/3)) (copper: 3.91e7 Pa s/m); the plate's outer
//    face moves with v(t) = v_peak s(t) along the surface normal
//    (drive_loaded_face), v_peak = sqrt(2 PII / (rho c T_p)).
//
// Units: SI (s, Pa, J/m^2; 1 mJ/mm^2 = 1000 J/m^2).

#include "shockwave/model.h"

namespace arthrosim::shockwave {

/// p-wave impedance rho c_p = sqrt(rho (K + 4G/3)) of an elastic solid
/// [Pa s/m] (density [kg/m^3], moduli [Pa]).
double p_wave_impedance(double density, double bulk_modulus, double shear_modulus);

struct PulseShape {
  double rise_time = 1.5e-6;          ///< t_r [s], > 0
  double fall_time = 1.5e-6;          ///< t_f [s], > 0
  double positive_duration = 4.0e-6;  ///< T+ [s], >= t_r + t_f
  double tail_duration = 20.0e-6;     ///< T- [s], >= 0
  double tail_fraction = 0.75;        ///< f_tail, in [0, 1]
};

class PressurePulse {
 public:
  /// Scaled so that the seed's PII (eq. 2) equals `efd` [J/m^2] in a medium
  /// of impedance `impedance` [Pa s/m]. InputError on a bad shape or a
  /// non-positive efd/impedance.
  PressurePulse(const PulseShape& shape, double efd, double impedance = 1.5e6);

  /// Pressure at time t [s] (0 for t < 0) [Pa].
  double operator()(double t) const { return peak_ * normalized(t); }
  /// Shape with peak 1.
  double normalized(double t) const;

  double peak() const { return peak_; }               ///< p_peak [Pa]
  /// Velocity amplitude v of eq. 2, p_peak / (rho c) [m/s].
  double velocity_peak() const { return peak_ / impedance_; }
  double time_to_90_percent() const { return t_p_; }  ///< T_p [s]
  double duration() const { return shape_.positive_duration + shape_.tail_duration; }
  double efd() const { return efd_; }                 ///< seed's PII [J/m^2]
  double impedance() const { return impedance_; }
  /// (1/(rho c)) int p^2 dt over the positive phase / the whole pulse [J/m^2].
  double efd_positive_integral() const;
  double efd_total_integral() const;
  const PulseShape& shape() const { return shape_; }

 private:
  double integral_p2(double t0, double t1) const;
  PulseShape shape_;
  double efd_;
  double impedance_;
  double t_p_ = 0.0;
  double peak_ = 0.0;
};

/// The applicator reading: prescribe on every automaton of model.loaded the
/// velocity v(t) = pulse.velocity_peak() * pulse.normalized(t) along the
/// surface normal (into the body; the other axes stay free) by appending
/// velocity constraints and setting model.constraint_scale. InputError if the
/// surface is empty, already constrained or its normal is not a lattice axis.
void drive_loaded_face(Model& model, const PressurePulse& pulse);

}  // namespace arthrosim::shockwave
