#pragma once
// The constant description of an ensemble of movable cellular automata: the
// lattice, the tissues, every automaton's reference position and tissue, the
// neighbour (bond) table, boundary conditions. Built once; the time
// integration (simulation.h) keeps all changing quantities separately
// (Model/Data split).
//
// Bonds: every pair of neighbouring sites that both carry an automaton is
// bonded (seed Appendix A: "an ensemble of bonded ... discrete elements";
// automata of different tissues are bonded too, the knee is one body). The
// neighbour table is stored direction-major: neighbours[s * n + i] is the
// automaton in direction s of automaton i, or -1.
#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "common/mesh.h"
#include "shockwave/lattice.h"
#include "shockwave/tissue.h"

namespace arthrosim::shockwave {

/// The grid the lattice sites are taken from (see lattice.h).
struct GridSpec {
  common::Vec3 origin = common::Vec3::Zero();  ///< position of grid point (0, 0, 0) [m]
  std::array<int, 3> count{0, 0, 0};           ///< grid points per axis (>= 1)
  /// Periodic axes: the last grid point bonds to the first (period
  /// count * h). For FCC a periodic count must be even.
  std::array<bool, 3> periodic{false, false, false};
};

/// Translational velocity prescribed on some axes of one automaton (a
/// displacement boundary condition). The prescribed velocity is
/// `velocity * scale(t)` with the model's constraint_scale (default 1).
struct VelocityConstraint {
  int automaton = -1;
  std::uint8_t axes = 0;  ///< bit 0: x, bit 1: y, bit 2: z
  common::Vec3 velocity = common::Vec3::Zero();  ///< [m/s]
};

/// A loaded surface: a pressure p(t) acts on every listed automaton with the
/// force p(t) * area (area vector pointing into the body, |area| = the
/// automaton's share of the surface).
struct PressureSurface {
  std::vector<int> automata;
  std::vector<common::Vec3> area;  ///< [m^2], into the body
  /// Unit normal into the body (all automata of one surface share it).
  common::Vec3 normal = common::Vec3::Zero();
};

struct Model {
  Lattice lattice;
  GridSpec grid;
  PoreFluid fluid;
  std::vector<Tissue> tissues;             ///< index = tissue id
  std::vector<TissueConstants> constants;  ///< derived, per tissue
  std::vector<double> x, y, z;             ///< reference positions [m]
  std::vector<std::uint8_t> tissue;        ///< tissue id per automaton
  std::vector<std::array<int, 3>> cell;    ///< grid index per automaton
  std::vector<std::int32_t> neighbours;    ///< [s * n + i], -1 = none
  std::vector<std::uint8_t> neighbour_count;
  std::vector<VelocityConstraint> constraints;
  /// Scale of the prescribed velocities at time t (e.g. a ramp); empty = 1.
  std::function<double(double)> constraint_scale;
  PressureSurface loaded;
  /// Drained automata: their pore pressure is held at 0 (a reservoir at the
  /// reference pressure; the fluid they exchange is not counted).
  std::vector<int> drained;

  int size() const { return static_cast<int>(tissue.size()); }
  int neighbour(int s, int i) const { return neighbours[static_cast<size_t>(s) * tissue.size() + i]; }
  /// Number of bonds (pairs).
  std::int64_t bonds() const;
  /// Automata per tissue.
  std::vector<std::int64_t> tissue_counts() const;
  common::Vec3 position(int i) const { return {x[i], y[i], z[i]}; }
  /// Period per axis [m] (0 for a non-periodic axis).
  common::Vec3 period() const;
};

/// Builds a model. `classify(i, j, k, p)` returns the tissue id of the site at
/// grid index (i, j, k), position p, or -1 for no automaton; it is called for
/// every lattice site, in parallel (must be thread-safe). Tissues are
/// validated (InputError naming `source`); at most 255 tissues.
Model build_model(const Lattice& lattice, const GridSpec& grid, std::vector<Tissue> tissues,
                  const PoreFluid& fluid,
                  const std::function<int(int, int, int, const common::Vec3&)>& classify,
                  const std::string& source = "shockwave model");

/// Automata whose grid index on `axis` equals `index` (a lattice layer).
std::vector<int> layer(const Model& model, int axis, int index);

}  // namespace arthrosim::shockwave
