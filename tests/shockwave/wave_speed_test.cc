// Longitudinal waves in a laterally periodic bar of automata (uniaxial
// strain): the drained p-wave speed sqrt((K + 4G/3)/rho) without the pore
// fluid and Gassmann's undrained speed sqrt((K + a^2 M + 4G/3)/rho) with it
// (effects mca_elastic, pore_fluid).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "common/error.h"
#include "shockwave/simulation.h"
#include "tests/shockwave/test_support.h"

namespace arthrosim::shockwave {
namespace {

struct WaveCase {
  LatticeKind lattice;
  const char* tissue;
  bool undrained;
};

Tissue tissue_by_name(const std::string& name) {
  if (name == "cartilage") return cartilage();
  if (name == "fibrocartilage") return fibrocartilage();
  if (name == "cancellous") return cancellous_bone();
  if (name == "fibrous") return fibrous_tissue();
  return cortical_bone();
}

// Time of the maximum of a sampled signal, refined by a parabola through the
// largest sample and its neighbours.
double peak_time(const std::vector<double>& v, double dt) {
  size_t k = 0;
  for (size_t i = 1; i < v.size(); ++i)
    if (v[i] > v[k]) k = i;
  if (k == 0 || k + 1 >= v.size()) return k * dt;
  const double a = v[k - 1], b = v[k], c = v[k + 1];
  return (k + 0.5 * (a - c) / (a - 2 * b + c)) * dt;
}

struct Measured {
  double speed = 0.0, expected = 0.0;
};

// A smooth compressive pulse (sin^2, spatial length about 40 d) enters at
// x = 0; the arrival time of the peak of the mean pressure (A5) of two
// lattice layers 100 d apart gives the speed.
Measured measure(const WaveCase& wc, double amplitude = 1e5, Geometry geometry = Geometry::kLinear) {
  const double d = 1e-3;
  const Lattice lat = make_lattice(wc.lattice, d);
  const int nx = static_cast<int>(std::lround(200 * d / lat.spacing));
  Model m = testing::box(lat, {nx, 4, 4}, tissue_by_name(wc.tissue), {}, {false, true, true});
  const TissueConstants& c = m.constants[0];
  const double speed = wc.undrained ? c.undrained_p_speed : c.drained_p_speed;
  for (int a = 0; a < m.size(); ++a)
    if (m.cell[a][0] == 0) {
      m.loaded.automata.push_back(a);
      m.loaded.area.push_back(common::Vec3(lat.area_per_surface_site(), 0, 0));
    }
  m.loaded.normal = common::Vec3(1, 0, 0);
  const double T = 40 * d / speed;
  auto pulse = [T, amplitude](double t) {
    if (t < 0 || t > T) return 0.0;
    const double s = std::sin(3.14159265358979323846 * t / T);
    return amplitude * s * s;
  };
  SimulationOptions o;
  o.pore_fluid = wc.undrained;
  o.filtration = false;
  o.geometry = geometry;
  Simulation sim(m, o, pulse);
  const int i1 = static_cast<int>(std::lround(50 * d / lat.spacing)), i2 = static_cast<int>(std::lround(150 * d / lat.spacing));
  std::vector<int> l1 = layer(m, 0, i1), l2 = layer(m, 0, i2);
  const double x1 = m.x[l1[0]], x2 = m.x[l2[0]];
  std::vector<double> p1, p2;
  const std::int64_t steps = static_cast<std::int64_t>(std::ceil((x2 + 1.5 * speed * T) / speed / sim.time_step()));
  for (std::int64_t s = 0; s < steps; ++s) {
    sim.step();
    double a = 0, b = 0;
    for (int i : l1) a += sim.pressure()[i];
    for (int i : l2) b += sim.pressure()[i];
    p1.push_back(a / l1.size());
    p2.push_back(b / l2.size());
  }
  Measured out;
  out.speed = (x2 - x1) / (peak_time(p2, sim.time_step()) - peak_time(p1, sim.time_step()));
  out.expected = speed;
  return out;
}

class BarWave : public ::testing::TestWithParam<WaveCase> {};

// Tolerance 2 % (the requirement at the default lattice): the
// lattice's dispersion delays the peak of a pulse about 40 automata long by
// (k d)^2 / 8 ~ 0.3 %; measured 0.1-0.5 %.
TEST_P(BarWave, SpeedMatchesClosedForm) {
  const WaveCase wc = GetParam();
  const Measured r = measure(wc);
  std::printf("%s %s %s: measured %.1f m/s, closed form %.1f m/s (%+.2f %%)\n", to_string(wc.lattice).c_str(), wc.tissue,
              wc.undrained ? "undrained (Gassmann)" : "drained", r.speed, r.expected, 100 * (r.speed / r.expected - 1));
  EXPECT_NEAR(r.speed / r.expected, 1.0, 0.02);
}

INSTANTIATE_TEST_SUITE_P(
    Tissues, BarWave,
    ::testing::Values(WaveCase{LatticeKind::kFcc, "cancellous", false}, WaveCase{LatticeKind::kFcc, "cartilage", false},
                      WaveCase{LatticeKind::kFcc, "cartilage", true}, WaveCase{LatticeKind::kFcc, "fibrocartilage", true},
                      WaveCase{LatticeKind::kFcc, "cancellous", true}, WaveCase{LatticeKind::kFcc, "fibrous", true},
                      WaveCase{LatticeKind::kSimpleCubic, "cartilage", false},
                      WaveCase{LatticeKind::kSimpleCubic, "cartilage", true}),
    [](const auto& info) {
      return to_string(info.param.lattice) + "_" + info.param.tissue + (info.param.undrained ? "_undrained" : "_drained");
    });

// The distortional strain of a plane pressure wave in undrained cartilage
// (uniaxial strain: |eps_xx| = P / K_u, equivalent strain 2/3 |eps_xx|): the
// averaged strain of the pairs gives it; A4's von Mises stress over 3G would
// be dominated by the spurious deviatoric part of the averaged stress in the
// steep front (order d |grad P|, divided by G = K_u / 600).
TEST(BarWave, DistortionalStrainOfAPressureWave) {
  const Lattice lat = make_lattice(LatticeKind::kFcc, 1e-3);
  const int nx = static_cast<int>(std::lround(120e-3 / lat.spacing));
  Model m = testing::box(lat, {nx, 4, 4}, cartilage(), {}, {false, true, true});
  for (int a = 0; a < m.size(); ++a)
    if (m.cell[a][0] == 0) {
      m.loaded.automata.push_back(a);
      m.loaded.area.push_back(common::Vec3(lat.area_per_surface_site(), 0, 0));
    }
  const TissueConstants& c = m.constants[0];
  const double T = 40e-3 / c.undrained_p_speed;
  auto pulse = [T](double t) {
    if (t < 0 || t > T) return 0.0;
    const double s = std::sin(3.14159265358979323846 * t / T);
    return 1e5 * s * s;
  };
  SimulationOptions o;
  o.filtration = false;
  Simulation sim(m, o, pulse);
  const std::vector<int> station = layer(m, 0, static_cast<int>(std::lround(60e-3 / lat.spacing)));
  double best_p = 0.0, eps_at_peak = 0.0, vm_at_peak = 0.0;
  while (sim.time() < (60e-3 + 0.5 * 40e-3) / c.undrained_p_speed + 0.5 * T) {
    sim.step();
    const int a = station[0];
    if (sim.pressure()[a] > best_p) {
      best_p = sim.pressure()[a];
      eps_at_peak = sim.distortional_strain()[a];
      vm_at_peak = sim.von_mises(a) / (3 * cartilage().shear_modulus);
    }
  }
  const double expected = 2.0 / 3.0 * best_p / c.undrained_bulk;
  std::printf("peak P %.4g Pa: distortional strain %.4g (closed form %.4g), sigma_eq/3G %.4g\n", best_p, eps_at_peak,
              expected, vm_at_peak);
  // Tolerance 5 %: the strain and the pressure peak need not be at the same
  // step (the pulse spans 40 automata; its peak moves 0.7 automata per step).
  EXPECT_NEAR(eps_at_peak / expected, 1.0, 0.05);
}

// A strong pulse (20 MPa) into undrained fibrous tissue (K_u 2.4 GPa, G 0.43
// MPa). With the small-strain pair geometry (the default) the response is
// linear: the same speed as for a weak pulse. With the current pair
// directions the pairs' compression (carried mostly by the pore pressure)
// has a geometric stiffness -P/r across the pairs that exceeds the shear
// stiffness ~G once P >~ G: the lattice buckles and the pulse is destroyed
// (measured: speed off by > 100 % or a non-finite state).
TEST(BarWave, StrongPulseInSoftUndrainedTissue) {
  const WaveCase wc{LatticeKind::kFcc, "fibrous", true};
  const Measured weak = measure(wc, 1e3), strong = measure(wc, 2e7);
  std::printf("fibrous, small strain: weak pulse %.2f m/s, 20 MPa pulse %.2f m/s\n", weak.speed, strong.speed);
  EXPECT_NEAR(strong.speed / weak.speed, 1.0, 1e-9);  // linear
  bool broken = false;
  try {
    const Measured nl = measure(wc, 2e7, Geometry::kNonlinear);
    std::printf("fibrous, current directions: 20 MPa pulse %.2f m/s\n", nl.speed);
    broken = !(std::abs(nl.speed / nl.expected - 1.0) < 0.1);
  } catch (const common::NumericalError& e) {
    std::printf("fibrous, current directions: %s\n", e.what());
    broken = true;
  }
  EXPECT_TRUE(broken);
}

// The undrained speed really is the fluid's doing: for cartilage it is 16
// times the drained one (K_u = K + a^2 M = 2.55 GPa against K = 4.2 MPa).
TEST(BarWave, CartilageGassmannFarAboveDrained) {
  const TissueConstants c = derive(cartilage(), PoreFluid{}, "test");
  EXPECT_GT(c.undrained_p_speed, 10 * c.drained_p_speed);
  // Independent evaluation of Gassmann's relation for cartilage (Table 1).
  const double K = 4.16e6, Ks = 3.4e9, phi = 0.8, Kf = 2.4e9;
  const double a = 1 - K / Ks;
  const double M = 1.0 / (phi / Kf + (a - phi) / Ks);
  EXPECT_NEAR(c.undrained_bulk, K + a * a * M, 1e-9 * c.undrained_bulk);
}

}  // namespace
}  // namespace arthrosim::shockwave
