#pragma once
// Small set-ups shared by the shockwave tests.
#include <array>
#include <cmath>

#include "shockwave/model.h"
#include "shockwave/simulation.h"

namespace arthrosim::shockwave::testing {

/// An arbitrary isotropic test material (K, G in Pa), porosity 0.5.
inline Tissue material(double K, double G, double rho = 1000.0, const char* name = "test") {
  Tissue t;
  t.name = name;
  t.density = rho;
  t.bulk_modulus = K;
  t.shear_modulus = G;
  t.solid_bulk_modulus = 1e3 * K;
  t.porosity = 0.5;
  t.permeability = 0.0;
  return t;
}

/// A box of one tissue filling the grid (every site an automaton).
inline Model box(const Lattice& lattice, std::array<int, 3> count, const Tissue& tissue, const PoreFluid& fluid = {},
                 std::array<bool, 3> periodic = {false, false, false}) {
  GridSpec g;
  g.count = count;
  g.periodic = periodic;
  return build_model(lattice, g, {tissue}, fluid, [](int, int, int, const common::Vec3&) { return 0; });
}

/// Smooth velocity ramp: sin^2-shaped velocity pulse of duration T whose
/// integral is 1 (so scale * v0 moves a constrained automaton by v0 in total).
inline double ramp_velocity(double t, double T) {
  if (t < 0.0 || t > T) return 0.0;
  const double s = std::sin(3.14159265358979323846 * t / T);
  return 2.0 / T * s * s;
}

}  // namespace arthrosim::shockwave::testing
