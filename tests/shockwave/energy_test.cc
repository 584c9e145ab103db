// Energy balance over a pulse without damping, and the conservation laws of
// the pair law's third-law split (A8).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "shockwave/applicator_pulse.h"
#include "shockwave/simulation.h"
#include "tests/shockwave/test_support.h"

namespace arthrosim::shockwave {
namespace {

// A block of three layers (copper plate, cartilage, cancellous bone; free
// surfaces all round) loaded through the copper face by the applicator pulse.
Model layered_block(LatticeKind kind) {
  const Lattice lat = make_lattice(kind, 1e-3);
  const int nx = static_cast<int>(std::lround(14e-3 / lat.spacing));
  const int ny = static_cast<int>(std::lround(6e-3 / lat.spacing));
  GridSpec g;
  g.count = {nx, ny, ny};
  Model m = build_model(lat, g, {copper(), cartilage(), cancellous_bone()}, PoreFluid{},
                        [nx](int i, int, int, const common::Vec3&) { return i < 2 ? 0 : (i < nx / 2 ? 1 : 2); });
  for (int a = 0; a < m.size(); ++a)
    if (m.cell[a][0] == 0) {
      m.loaded.automata.push_back(a);
      m.loaded.area.push_back(common::Vec3(lat.area_per_surface_site(), 0, 0));
    }
  m.loaded.normal = common::Vec3(1, 0, 0);
  return m;
}

struct EnergyCase {
  LatticeKind lattice;
  bool fluid;
  bool filtration;
};

class EnergyBalanceTest : public ::testing::TestWithParam<EnergyCase> {};

// E_kin + E_pot + (filtration dissipation) = work of the pulse, during and
// after the pulse. With the kinetic energy 1/2 m v^{n-1/2} . v^{n+1/2} and the
// work (f^{n-1} + f^n)/2 . (x^n - x^{n-1}) leapfrog's balance is exact for a
// linear system; what remains comes from the geometric nonlinearity (pair
// directions turn as the free block moves) and the first-order bookkeeping
// of the filtration dissipation. Tolerance 0.05 % of the work; measured
// at most 0.007 %.
TEST_P(EnergyBalanceTest, WorkEqualsEnergyPlusDissipation) {
  const EnergyCase ec = GetParam();
  const Model m = layered_block(ec.lattice);
  PulseShape shape;
  const PressurePulse pulse(shape, 330.0);  // 0.33 mJ/mm^2
  SimulationOptions o;
  o.pore_fluid = ec.fluid;
  o.filtration = ec.filtration;
  Simulation sim(m, o, pulse);
  sim.track_energy(true);
  double worst = 0.0, work = 0.0;
  for (double t_end : {2e-6, 4e-6, 10e-6, 24e-6, 40e-6}) {
    while (sim.time() < t_end) sim.step();
    const EnergyBalance e = sim.energy();
    work = std::max(work, std::abs(e.external_work));
    const double rel = std::abs(e.residual()) / work;
    std::printf("t %5.1f us: work %.4e J, kinetic %.4e, potential %.4e, dissipation %.3e, residual %.2e (%.3f %%)\n",
                sim.time() * 1e6, e.external_work, e.kinetic, e.potential, e.dissipation, e.residual(), 100 * rel);
    worst = std::max(worst, rel);
  }
  EXPECT_GT(work, 0.0);
  EXPECT_LT(worst, 5e-4);
}

INSTANTIATE_TEST_SUITE_P(Cases, EnergyBalanceTest,
                         ::testing::Values(EnergyCase{LatticeKind::kFcc, false, false},
                                           EnergyCase{LatticeKind::kFcc, true, false},
                                           EnergyCase{LatticeKind::kFcc, true, true},
                                           EnergyCase{LatticeKind::kSimpleCubic, true, true}),
                         [](const auto& info) {
                           return to_string(info.param.lattice) + (info.param.fluid ? "_poro" : "_dry") +
                                  (info.param.filtration ? "_filtration" : "");
                         });

// A8 gives every pair equal and opposite forces in the same bits, so the total
// linear momentum of a free block set in motion stays constant to round-off;
// the moments q n x F^tau with q = r/2 balance the couple of the tangential
// forces, so the angular momentum (orbital + spin) is conserved up to the
// integrator's O(dt^2).
TEST(Momentum, ConservedByThirdLawSplit) {
  const Model m = layered_block(LatticeKind::kFcc);
  Simulation sim(m, SimulationOptions{});
  std::uint64_t state = 12345;
  auto rnd = [&state]() {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) * (1.0 / 9007199254740992.0) - 0.5;
  };
  double scale = 0.0;
  for (int i = 0; i < m.size(); ++i) {
    const common::Vec3 v(rnd(), rnd(), rnd());
    sim.set_velocity(i, v);
    sim.set_angular_velocity(i, common::Vec3(rnd(), rnd(), rnd()) * 100.0);
    scale += m.constants[m.tissue[i]].total_density * m.lattice.cell_volume * v.norm();
  }
  const common::Vec3 p0 = sim.linear_momentum();
  sim.step();
  const common::Vec3 L0 = sim.angular_momentum();
  sim.run(300);
  const common::Vec3 p1 = sim.linear_momentum(), L1 = sim.angular_momentum();
  std::printf("|dp| %.3e of sum m|v| %.3e; |dL| / |L| %.3e\n", (p1 - p0).norm(), scale, (L1 - L0).norm() / L0.norm());
  // Round-off: 300 steps x ~1e-16 relative per force sum.
  EXPECT_LT((p1 - p0).norm(), 1e-12 * scale);
  EXPECT_LT((L1 - L0).norm(), 1e-3 * L0.norm());
}

}  // namespace
}  // namespace arthrosim::shockwave
