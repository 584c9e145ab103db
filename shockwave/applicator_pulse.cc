#include "shockwave/applicator_pulse.h"

#include <cmath>
#include <string>

#include "common/error.h"

namespace arthrosim::shockwave {

namespace {
constexpr double kPi = 3.14159265358979323846;
std::string us(double t) { return std::to_string(t * 1e6) + " us"; }
}  // namespace

double p_wave_impedance(double density, double bulk_modulus, double shear_modulus) {
  const double m = bulk_modulus + 4.0 * shear_modulus / 3.0;
  if (!(density > 0.0 && m > 0.0))
    throw common::InputError("applicator pulse", 0, "expected a density and p-wave modulus > 0, found " +
                                                        std::to_string(density) + " kg/m^3, " + std::to_string(m) + " Pa");
  return std::sqrt(density * m);
}

PressurePulse::PressurePulse(const PulseShape& s, double efd, double impedance)
    : shape_(s), efd_(efd), impedance_(impedance) {
  const std::string src = "applicator pulse";
  if (!(s.rise_time > 0.0)) throw common::InputError(src, 0, "expected a rise time > 0, found " + us(s.rise_time));
  if (!(s.fall_time > 0.0)) throw common::InputError(src, 0, "expected a fall time > 0, found " + us(s.fall_time));
  if (!(s.positive_duration >= s.rise_time + s.fall_time))
    throw common::InputError(src, 0, "expected a positive phase >= rise + fall time (" + us(s.rise_time + s.fall_time) +
                                         "), found " + us(s.positive_duration));
  if (!(s.tail_duration >= 0.0)) throw common::InputError(src, 0, "expected a tail duration >= 0, found " + us(s.tail_duration));
  if (!(s.tail_fraction >= 0.0 && s.tail_fraction <= 1.0))
    throw common::InputError(src, 0, "expected a tail fraction in [0, 1], found " + std::to_string(s.tail_fraction));
  if (!(efd > 0.0 && std::isfinite(efd)))
    throw common::InputError(src, 0, "expected an energy flux density > 0 J/m^2, found " + std::to_string(efd));
  if (!(impedance > 0.0 && std::isfinite(impedance)))
    throw common::InputError(src, 0, "expected an impedance > 0 Pa s/m, found " + std::to_string(impedance));
  // sin^2(pi t / (2 t_r)) = 0.9.
  t_p_ = 2.0 * s.rise_time / kPi * std::asin(std::sqrt(0.9));
  // Eq. 2 with v = p / (rho c): PII = p^2 T_p / (2 rho c).
  peak_ = std::sqrt(2.0 * impedance * efd / t_p_);
}

double PressurePulse::normalized(double t) const {
  const PulseShape& s = shape_;
  if (t < 0.0) return 0.0;
  if (t < s.rise_time) {
    const double v = std::sin(kPi * t / (2.0 * s.rise_time));
    return v * v;
  }
  const double fall_start = s.positive_duration - s.fall_time;
  if (t < fall_start) return 1.0;
  if (t < s.positive_duration) {
    const double v = std::cos(kPi * (t - fall_start) / (2.0 * s.fall_time));
    return v * v;
  }
  if (t < s.positive_duration + s.tail_duration)
    return -s.tail_fraction * std::sin(kPi * (t - s.positive_duration) / s.tail_duration);
  return 0.0;
}

double PressurePulse::integral_p2(double t0, double t1) const {
  // Composite Simpson on a fine grid (the shape is smooth between its pieces,
  // whose joints lie on grid points for the default shape).
  const int n = 20000;
  const double h = (t1 - t0) / n;
  double sum = 0.0;
  for (int i = 0; i <= n; ++i) {
    const double p = (*this)(t0 + i * h);
    const double w = (i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0);
    sum += w * p * p;
  }
  return sum * h / 3.0;
}

double PressurePulse::efd_positive_integral() const {
  return integral_p2(0.0, shape_.positive_duration) / impedance_;
}
double PressurePulse::efd_total_integral() const { return integral_p2(0.0, duration()) / impedance_; }

void drive_loaded_face(Model& model, const PressurePulse& pulse) {
  const std::string src = "applicator pulse";
  const PressureSurface& face = model.loaded;
  if (face.automata.empty()) throw common::InputError(src, 0, "expected a loaded surface to drive, found none");
  int axis = -1;
  for (int k = 0; k < 3; ++k)
    if (std::abs(std::abs(face.normal[k]) - 1.0) < 1e-12) axis = k;
  if (axis < 0)
    throw common::InputError(src, 0, "expected the loaded surface's normal along a lattice axis, found (" +
                                         std::to_string(face.normal.x()) + ", " + std::to_string(face.normal.y()) + ", " +
                                         std::to_string(face.normal.z()) + ")");
  if (model.constraint_scale)
    throw common::InputError(src, 0, "expected no other prescribed velocities, found a velocity scale already set");
  common::Vec3 v = common::Vec3::Zero();
  v[axis] = pulse.velocity_peak() * face.normal[axis];
  for (int a : face.automata) model.constraints.push_back({a, static_cast<std::uint8_t>(1u << axis), v});
  model.constraint_scale = [pulse](double t) { return pulse.normalized(t); };
}

}  // namespace arthrosim::shockwave
