// Simulation::state() / restore() (shockwave/simulation.h, SimulationState),
// the part of the shockwave stage's checkpoint (pipelines/shockwave_checkpoint.h)
// that holds the automata: N steps, the state taken, restored into a freshly
// built Simulation, M more steps must give the bytes of N + M uninterrupted
// steps, every state array compared byte for byte (memcmp, so -0.0 vs 0.0 or
// a NaN payload would count), with 1 and 2 OpenMP threads. The set-up has
// every kind of state: a pressure-loaded face, velocity-driven automata
// (constraint forces), pore fluid with slow (forward Euler) and fast (RKL2)
// filtration bonds (cartilage next to cancellous bone at d = 1 mm), energy
// bookkeeping, both pair geometries. The sabotage case shows the comparison
// can fail: a state with one array reset to its fresh value resumes into
// different bytes.
#include <gtest/gtest.h>
#include <omp.h>

#include <array>
#include <cmath>
#include <cstring>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>

#include "shockwave/knee_model.h"
#include "shockwave/lattice.h"
#include "shockwave/model.h"
#include "shockwave/simulation.h"
#include "shockwave/tissue.h"

namespace arthrosim::shockwave {
namespace {

// FCC sites at d = 1 mm: cancellous bone for x < 4, cartilage beyond; a
// pressure pulse on x = 0; the far face driven by a small velocity. `large`:
// 34 x 34 x 30 grid (17,340 FCC sites), above the size from which the step runs in parallel
// (kParallelMin, shockwave/reduce.h), so two threads really share the work;
// else 10 x 5 x 5.
Model make_model(bool large = false) {
  const Lattice lat = make_lattice(LatticeKind::kFcc, 1e-3);
  GridSpec g;
  g.count = large ? std::array<int, 3>{34, 34, 30} : std::array<int, 3>{10, 5, 5};
  const std::vector<Tissue> all = default_knee_tissues();
  Model m = build_model(lat, g, {all[kCancellous], all[kCartilage]}, PoreFluid{},
                        [](int i, int, int, const common::Vec3&) { return i < 4 ? 0 : 1; });
  for (int a = 0; a < m.size(); ++a) {
    if (m.cell[a][0] == 0) {
      m.loaded.automata.push_back(a);
      m.loaded.area.push_back(common::Vec3(lat.area_per_surface_site(), 0, 0));
    }
    if (m.cell[a][0] == g.count[0] - 1) m.constraints.push_back({a, 1, common::Vec3(-0.05, 0, 0)});
    if (m.cell[a][0] == g.count[0] - 2 && m.cell[a][1] == 0) m.drained.push_back(a);
  }
  m.loaded.normal = common::Vec3(1, 0, 0);
  m.constraint_scale = [](double t) { return t < 2e-6 ? 1.0 : 0.0; };
  return m;
}

double load(double t) { return 2e6 * std::exp(-t / 1e-6) * (t > 0 ? 1.0 : 0.0); }

std::unique_ptr<Simulation> fresh(const Model& m, Geometry geometry) {
  SimulationOptions o;
  o.geometry = geometry;
  auto sim = std::make_unique<Simulation>(m, o, load);
  sim->track_energy(true);
  return sim;
}

// Every array and scalar of two states, byte for byte; "" when equal, else
// what differs first.
std::string difference(const SimulationState& a, const SimulationState& b) {
  auto bits = [](double x, double y) { return std::memcmp(&x, &y, sizeof x) == 0; };
  if (a.steps != b.steps || a.buffer != b.buffer) return "steps or buffer";
  if (!bits(a.kinetic, b.kinetic) || !bits(a.work, b.work) || !bits(a.dissipation, b.dissipation) ||
      !bits(a.damping, b.damping))
    return "energy totals";
  if (a.arrays.size() != b.arrays.size()) return "array count";
  for (size_t k = 0; k < a.arrays.size(); ++k) {
    if (a.arrays[k].first != b.arrays[k].first) return "array names";
    const std::vector<double>& x = a.arrays[k].second;
    const std::vector<double>& y = b.arrays[k].second;
    if (x.size() != y.size() || std::memcmp(x.data(), y.data(), x.size() * sizeof(double)) != 0)
      return a.arrays[k].first;
  }
  return "";
}

constexpr int kFirst = 23, kMore = 40;  // N and M of the small model (odd N: buffer 1 is current)

class SimulationStateTest : public ::testing::TestWithParam<std::tuple<int, Geometry>> {};

TEST_P(SimulationStateTest, RestoredRunContinuesBitForBit) {
  const auto [threads, geometry] = GetParam();
  const int before = omp_get_max_threads();
  omp_set_num_threads(threads);
  const Model m = make_model(true);
  ASSERT_GE(m.size(), 16384);
  std::unique_ptr<Simulation> whole = fresh(m, geometry);
  ASSERT_NE(whole->filtration(), nullptr);
  ASSERT_GT(whole->filtration()->fast_bonds(), 0);  // the RKL2 path is exercised
  ASSERT_GT(whole->filtration()->bonds(), whole->filtration()->fast_bonds());  // and the slow one
  // Fewer steps on the large model (seconds on a shared 2-core machine).
  const int first = 7, more = 10;
  whole->run(first);
  const SimulationState saved = whole->state();
  whole->run(more);

  std::unique_ptr<Simulation> resumed = fresh(m, geometry);
  resumed->restore(saved);
  EXPECT_EQ(difference(resumed->state(), saved), "");
  resumed->run(more);
  const SimulationState a = whole->state(), b = resumed->state();
  EXPECT_EQ(difference(a, b), "");
  // The state is not trivial: the pulse moved things, fluid flowed, the
  // driven face pushed back.
  auto array = [&](const char* name) -> const std::vector<double>& {
    for (const auto& [n, v] : a.arrays)
      if (n == name) return v;
    throw std::logic_error(std::string("no array ") + name);
  };
  double maxp = 0, maxz = 0, maxf = 0;
  for (double v : array("peak_pressure")) maxp = std::max(maxp, v);
  for (double v : array("fluid_content")) maxz = std::max(maxz, std::abs(v));
  for (double v : array("constraint_force")) maxf = std::max(maxf, std::abs(v));
  EXPECT_GT(maxp, 1e5);
  EXPECT_GT(maxz, 0.0);
  EXPECT_GT(maxf, 0.0);
  EXPECT_GT(a.work, 0.0);
  EXPECT_GT(a.dissipation, 0.0);
  EXPECT_EQ(a.steps, first + more);
  // The public fields agree too (derived from the arrays).
  for (int i = 0; i < m.size(); i += 97) {
    EXPECT_EQ(whole->position(i), resumed->position(i));
    EXPECT_EQ(whole->velocity(i), resumed->velocity(i));
    EXPECT_EQ(whole->stress(i), resumed->stress(i));
  }
  EXPECT_EQ(whole->energy().potential, resumed->energy().potential);
  omp_set_num_threads(before);
}

INSTANTIATE_TEST_SUITE_P(Threads, SimulationStateTest,
                         ::testing::Combine(::testing::Values(1, 2),
                                            ::testing::Values(Geometry::kLinear, Geometry::kNonlinear)));

// A dry (single-phase) run with mass damping, as the platen compression
// runs: the damping total is state too.
TEST(SimulationState, DampedDryRunContinuesBitForBit) {
  const Model m = make_model();
  SimulationOptions o;
  o.pore_fluid = false;
  o.filtration = false;
  o.damping = 2e4;  // [1/s]; damping * dt ~ 2e-3
  auto make = [&] {
    auto sim = std::make_unique<Simulation>(m, o, load);
    sim->track_energy(true);
    return sim;
  };
  std::unique_ptr<Simulation> whole = make();
  whole->run(kFirst);
  const SimulationState saved = whole->state();
  for (const auto& [name, array] : saved.arrays) EXPECT_NE(name, "fluid_content");  // none without pore fluid
  whole->run(kMore);
  std::unique_ptr<Simulation> resumed = make();
  resumed->restore(saved);
  resumed->run(kMore);
  const SimulationState a = whole->state();
  EXPECT_GT(a.damping, 0.0);
  EXPECT_EQ(difference(a, resumed->state()), "");
}

// The comparison can fail: a state with one array left at its fresh value
// (as if restore() forgot it) continues into different bytes, for each of
// the arrays that carry information from step to step (those of the
// current buffer: kFirst is odd, so buffer 1; the other half is rewritten by
// the next step and is held for the fields at the restored time).
TEST(SimulationState, StateMissingAnArrayIsDetected) {
  const Model m = make_model();
  std::unique_ptr<Simulation> whole = fresh(m, Geometry::kLinear);
  whole->run(kFirst);
  const SimulationState saved = whole->state();
  whole->run(kMore);
  const SimulationState reference = whole->state();
  const SimulationState initial = fresh(m, Geometry::kLinear)->state();
  for (const char* name : {"pair_normal_stress", "pair_tangential_x", "velocity_1_x",
                           "position_1_x", "angular_velocity_1_y", "fluid_content", "peak_pressure",
                           "peak_pore_pressure"}) {
    SCOPED_TRACE(name);
    SimulationState sabotaged = saved;
    bool found = false;
    for (size_t k = 0; k < sabotaged.arrays.size(); ++k)
      if (sabotaged.arrays[k].first == name) {
        sabotaged.arrays[k].second = initial.arrays[k].second;
        found = true;
      }
    ASSERT_TRUE(found);
    std::unique_ptr<Simulation> resumed = fresh(m, Geometry::kLinear);
    resumed->restore(sabotaged);
    resumed->run(kMore);
    EXPECT_NE(difference(reference, resumed->state()), "");
  }
  // The energy totals are state as well.
  SimulationState sabotaged = saved;
  sabotaged.work = 0.0;
  std::unique_ptr<Simulation> resumed = fresh(m, Geometry::kLinear);
  resumed->restore(sabotaged);
  resumed->run(kMore);
  EXPECT_EQ(difference(reference, resumed->state()), "energy totals");
}

// restore() refuses a state that is not of this run, naming the array.
TEST(SimulationState, RestoreRefusesAForeignState) {
  const Model m = make_model();
  std::unique_ptr<Simulation> sim = fresh(m, Geometry::kLinear);
  sim->run(3);
  SimulationState s = sim->state();
  SimulationState missing = s;
  missing.arrays.erase(missing.arrays.begin() + 4);
  std::unique_ptr<Simulation> other = fresh(m, Geometry::kLinear);
  try {
    other->restore(missing);
    FAIL() << "restored a state without " << s.arrays[4].first;
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(s.arrays[4].first + " is missing"), std::string::npos) << e.what();
  }
  SimulationState shorter = s;
  shorter.arrays[0].second.pop_back();
  EXPECT_THROW(other->restore(shorter), std::runtime_error);
  SimulationState extra = s;
  extra.arrays.emplace_back("unknown", std::vector<double>(3, 0.0));
  EXPECT_THROW(other->restore(extra), std::runtime_error);
  // Nothing was changed by the refusals.
  EXPECT_EQ(other->steps_done(), 0);
}

}  // namespace
}  // namespace arthrosim::shockwave
