// Effect mca_elastic: the pair law of movable cellular automata (seed eq.
// A1-A8) against closed forms.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <tuple>

#include "shockwave/simulation.h"
#include "tests/shockwave/test_support.h"

namespace arthrosim::shockwave {
namespace {

using testing::box;
using testing::material;
using testing::ramp_velocity;

struct Moduli {
  double E = 0.0, nu = 0.0, E_platen = 0.0;
  double distortional = 0.0, vm_over_3G = 0.0;  ///< per unit axial strain
};

// Uniaxial compression of a prism (n x n x 3n automata): the bottom layer on
// frictionless rollers (v_z = 0; one automaton also fixed in x, y and one in
// y against rigid motion), the top layer moved down with free lateral motion
// (a frictionless platen); quasi-static by dynamic relaxation (mass
// damping). The platen layers are not traction-free, so the measurement uses
// the middle third (Saint-Venant): E = sigma_zz / eps_zz with sigma_zz the
// mean averaged stress (A4) of the gauge's automata that have all their
// neighbours and eps_zz from the mean axial displacement of the gauge's end
// layers; nu = -eps_lateral / eps_zz from the mean lateral displacement of
// the layers next to the side faces in the gauge. (The platen force over the layer area,
// printed too, is lower for FCC: the automata of an FCC (001) face have 3 of
// the 4 pairs that carry axial force, so the face layer transmits 3/4 of the
// interior stress, an O(d/width) size effect absent for SC.)
Moduli compress(LatticeKind kind, int nsites, DForm form, double K, double G) {
  const double d = 1e-3;
  const Lattice lat = make_lattice(kind, d);
  const int n = kind == LatticeKind::kFcc ? static_cast<int>(std::lround(nsites * std::sqrt(2.0))) : nsites;
  const int nz = 3 * n;
  Model m = box(lat, {n, n, nz}, material(K, G));
  const double h = lat.spacing;
  const double L = (nz - 1) * h;
  const double eps = 1e-4;
  const TissueConstants& c = m.constants[0];
  const double t_wave = L / c.drained_p_speed;
  const double T = 6.0 * t_wave;  // ramp
  for (int a = 0; a < m.size(); ++a) {
    const auto& cell = m.cell[a];
    if (cell[2] == 0) m.constraints.push_back({a, 4, common::Vec3::Zero()});
    if (cell[2] == nz - 1) m.constraints.push_back({a, 4, common::Vec3(0, 0, -eps * L)});
  }
  // Rigid-body motion in x, y and about z: fix one bottom automaton in x, y
  // and a second one on the same x row in y.
  m.constraints[0].axes = 7;
  for (auto& con : m.constraints)
    if (m.cell[con.automaton][2] == 0 && m.cell[con.automaton][1] == m.cell[m.constraints[0].automaton][1] &&
        con.automaton != m.constraints[0].automaton) {
      con.axes = 6;
      break;
    }
  m.constraint_scale = [T](double t) { return ramp_velocity(t, T); };
  SimulationOptions o;
  o.pore_fluid = false;
  o.filtration = false;
  o.d_form = form;
  // About critical damping of the lowest axial mode, omega = pi c / (2 L).
  o.damping = 3.14159 * c.drained_p_speed / (2.0 * L);
  Simulation sim(m, o);
  const std::int64_t steps = static_cast<std::int64_t>(std::ceil(2.5 * T / sim.time_step()));
  sim.run(steps);
  double Fz = 0.0;
  int top = 0;
  for (size_t k = 0; k < m.constraints.size(); ++k)
    if (m.cell[m.constraints[k].automaton][2] == nz - 1) {
      Fz += sim.constraint_forces()[k].z();
      ++top;
    }
  const double area = top * lat.area_per_surface_site();
  const double platen_stress = Fz / area;  // compressive (the pairs push the platen up)
  const int k0 = n, k1 = 2 * n;
  double szz = 0.0, eq = 0.0, vm = 0.0;
  int inner = 0;
  for (int a = 0; a < m.size(); ++a)
    if (m.cell[a][2] >= k0 && m.cell[a][2] <= k1 && m.neighbour_count[a] == lat.directions) {
      szz += -sim.stress(a)[2];
      eq += sim.distortional_strain()[a];
      vm += sim.von_mises(a);
      ++inner;
    }
  const double stress = szz / inner;
  auto mean = [&](auto pred, int axis) {
    double sum = 0.0;
    int cnt = 0;
    for (int a = 0; a < m.size(); ++a)
      if (pred(m.cell[a])) {
        sum += sim.displacement(a)[axis];
        ++cnt;
      }
    return sum / cnt;
  };
  const double uz0 = mean([&](const auto& cl) { return cl[2] == k0; }, 2);
  const double uz1 = mean([&](const auto& cl) { return cl[2] == k1; }, 2);
  const double eps_zz = (uz0 - uz1) / ((k1 - k0) * h);  // compressive, > 0
  double lat_strain = 0.0;
  for (int axis : {0, 1}) {
    const double lo = mean([&](const auto& cl) { return cl[axis] == 1 && cl[2] >= k0 && cl[2] <= k1; }, axis);
    const double hi = mean([&](const auto& cl) { return cl[axis] == n - 2 && cl[2] >= k0 && cl[2] <= k1; }, axis);
    lat_strain += 0.5 * (hi - lo) / ((n - 3) * h);
  }
  Moduli out;
  out.E = stress / eps_zz;
  out.nu = lat_strain / eps_zz;
  out.E_platen = platen_stress / eps_zz;
  out.distortional = eq / inner / eps_zz;
  out.vm_over_3G = vm / inner / (3.0 * G) / eps_zz;
  return out;
}

class EffectiveModuli : public ::testing::TestWithParam<std::tuple<LatticeKind, double, double>> {};

// Decides the D question (pair_law.h): with D = 1 - 2G/(3K) the lattice
// reproduces the input E and nu; with the seed's printed D = 1 - 2G/K it
// does not (measured for nu = 0.25: E 40 % low, nu -0.23). Materials:
// nu = 0.25 and the drained skeleton of Table 1's fibrous tissue (K 4.16 MPa,
// G 0.43 MPa, nu = 0.45). Tolerance 1 %: the gauge is not perfectly
// homogeneous (Saint-Venant decay of the platen layers over one width) and
// dynamic relaxation stops at a finite time; measured within 0.5 % (E) and
// 0.5 % (nu).
TEST_P(EffectiveModuli, HookeFormMatchesInputSeedFormDoesNot) {
  const auto [kind, K, G] = GetParam();
  const double E = 9 * K * G / (3 * K + G), nu = (3 * K - 2 * G) / (2 * (3 * K + G));
  const Moduli hooke = compress(kind, 8, DForm::kHooke, K, G);
  const Moduli seed = compress(kind, 8, DForm::kSeedPrinted, K, G);
  std::printf("%s: input E %.4g nu %.4f | D=1-2G/(3K): E %.4g nu %.4f (platen force: E %.4g) | D=1-2G/K: E %.4g nu %.4f\n",
              to_string(kind).c_str(), E, nu, hooke.E, hooke.nu, hooke.E_platen, seed.E, seed.nu);
  EXPECT_NEAR(hooke.E / E, 1.0, 0.01);
  EXPECT_NEAR(hooke.nu / nu, 1.0, 0.01);
  // The printed form makes the bulk modulus K - 4G/3 (summing A7 as above);
  // for a nearly incompressible skeleton (fibrous, K >> G) E and nu hardly
  // notice (measured 2-3 %), so the form is decided on the nu = 0.25 material.
  if (nu < 0.3) { EXPECT_GT(std::abs(seed.E / E - 1.0) + std::abs(seed.nu / nu - 1.0), 0.3); }
  // Uniaxial stress: equivalent strain (2/3)(1 + nu) eps_zz, from the pairs'
  // strains and, in this homogeneous state, equally from A6's sigma_eq / 3G.
  const double eq = 2.0 / 3.0 * (1.0 + nu);
  std::printf("  distortional strain / eps_zz %.4f, sigma_eq/(3G eps_zz) %.4f, closed form %.4f\n", hooke.distortional,
              hooke.vm_over_3G, eq);
  EXPECT_NEAR(hooke.distortional / eq, 1.0, 0.01);
  EXPECT_NEAR(hooke.vm_over_3G / eq, 1.0, 0.01);
}

INSTANTIATE_TEST_SUITE_P(
    Lattices, EffectiveModuli,
    ::testing::Values(std::make_tuple(LatticeKind::kSimpleCubic, 10e6, 6e6), std::make_tuple(LatticeKind::kFcc, 10e6, 6e6),
                      std::make_tuple(LatticeKind::kSimpleCubic, 4.16e6, 0.43e6),
                      std::make_tuple(LatticeKind::kFcc, 4.16e6, 0.43e6)),
    [](const auto& info) {
      return to_string(std::get<0>(info.param)) + (std::get<2>(info.param) < 1e6 ? "_fibrous" : "_nu025");
    });

}  // namespace
}  // namespace arthrosim::shockwave


namespace arthrosim::shockwave {
namespace {

// The averaged strain of automata at an interface: a confined column (periodic
// laterally) of a stiff and a soft tissue (K 1 GPa / 10 MPa, nu 0.25) under
// a quasi-static axial load. Uniaxial strain: equivalent strain 2/3 eps_zz
// with eps_zz = sigma / (K + 4G/3) in each tissue. With A8's split by
// compliance the automata next to the interface carry their own tissue's
// strain: tolerance 5 % (measured < 0.1 %); the pair strain itself (share 1)
// would give the stiff side about half the soft strain, 50 times too much.
TEST(AveragedStrain, InterfaceAutomataCarryTheirOwnTissuesStrain) {
  const Lattice lat = make_lattice(LatticeKind::kFcc, 1e-3);
  const int nz = 20;
  GridSpec g;
  g.count = {4, 4, nz};
  g.periodic = {true, true, false};
  const Tissue stiff = testing::material(1e9, 6e8, 2000, "stiff"), soft = testing::material(10e6, 6e6, 1000, "soft");
  Model m = build_model(lat, g, {stiff, soft}, PoreFluid{},
                        [nz](int, int, int k, const common::Vec3&) { return k < nz / 2 ? 0 : 1; });
  const double sigma = 1e4;
  for (int a = 0; a < m.size(); ++a) {
    if (m.cell[a][2] == 0) m.constraints.push_back({a, 7, common::Vec3::Zero()});
    if (m.cell[a][2] == nz - 1) {
      m.loaded.automata.push_back(a);
      m.loaded.area.push_back(common::Vec3(0, 0, -lat.area_per_surface_site()));
    }
  }
  const double Mc_soft = 10e6 + 4 * 6e6 / 3, Mc_stiff = 1e9 + 4 * 6e8 / 3;
  const double c = std::sqrt(Mc_soft / 1000.0), L = nz * lat.spacing;
  const double T = 8 * L / c;
  SimulationOptions o;
  o.pore_fluid = false;
  o.filtration = false;
  o.damping = 3.14159 * c / (2 * L);
  Simulation sim(m, o, [T, sigma](double t) { return sigma * std::min(1.0, t / T); });
  sim.run(static_cast<std::int64_t>(3 * T / sim.time_step()));
  auto mean_strain = [&](int k) {
    double s = 0;
    int n = 0;
    for (int a : layer(m, 2, k)) {
      s += sim.distortional_strain()[a];
      ++n;
    }
    return s / n;
  };
  const double soft_eq = 2.0 / 3.0 * sigma / Mc_soft, stiff_eq = 2.0 / 3.0 * sigma / Mc_stiff;
  const double at_stiff = mean_strain(nz / 2 - 1), at_soft = mean_strain(nz / 2);
  std::printf("interface: stiff side %.4g (tissue %.4g), soft side %.4g (tissue %.4g)\n", at_stiff, stiff_eq, at_soft,
              soft_eq);
  EXPECT_NEAR(at_stiff / stiff_eq, 1.0, 0.05);
  EXPECT_NEAR(at_soft / soft_eq, 1.0, 0.05);
}

}  // namespace
}  // namespace arthrosim::shockwave
