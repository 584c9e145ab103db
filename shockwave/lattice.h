#pragma once
// Packings of equal automata (seed Appendix A: "ensemble of bonded equiaxial
// discrete elements of the same size ... the initial value of the contact
// area is determined by the size of the automata and their packing").
//
// Sites live on an integer grid (i, j, k) with step h; position
// origin + h (i, j, k).
//  - simple cubic (SC): h = d, every grid point is a site, 6 neighbours;
//  - face-centred cubic (FCC): h = d / sqrt(2), sites where i + j + k is even,
//    12 neighbours at the offsets (+-1, +-1, 0) and permutations.
// d is the automaton diameter = nearest-neighbour distance (R = d/2 the
// radius of the equivalent sphere). Each automaton stands for its Voronoi
// cell: a cube of volume d^3 (SC) or a rhombic dodecahedron of volume
// d^3/sqrt(2) = 4 sqrt(2) R^3 (FCC). The contact area of a pair is the shared
// cell face: S = 4 R^2 = d^2 (SC), S = sqrt(2) R^2 (FCC). With q = R the
// distance from a centre to the contact point, sum over all neighbours of
// S q = 3 V for both packings (used by the mean stress, eq. A4-A5).
#include <array>
#include <string>

#include "common/mesh.h"

namespace arthrosim::shockwave {

enum class LatticeKind { kSimpleCubic, kFcc };

/// "sc" / "fcc".
std::string to_string(LatticeKind kind);
/// Parses "sc", "simple_cubic", "fcc" (InputError naming `source` otherwise).
LatticeKind parse_lattice_kind(const std::string& text, const std::string& source);

struct Lattice {
  LatticeKind kind = LatticeKind::kFcc;
  double diameter = 0.0;      ///< d [m]
  double radius = 0.0;        ///< R = d/2 [m]
  double spacing = 0.0;       ///< grid step h [m]
  double contact_area = 0.0;  ///< S [m^2]
  double cell_volume = 0.0;   ///< V [m^3]
  /// Number of neighbour directions K (6 or 12). Direction s + K/2 is the
  /// opposite of direction s; s < K/2 are the "forward" directions whose
  /// bonds an automaton owns.
  int directions = 0;
  std::array<std::array<int, 3>, 12> offsets{};  ///< grid offsets per direction
  std::array<common::Vec3, 12> unit{};           ///< unit vectors per direction

  /// True if the grid point (i, j, k) is a site of the lattice.
  bool is_site(int i, int j, int k) const {
    return kind == LatticeKind::kSimpleCubic || ((i + j + k) & 1) == 0;
  }
  /// Spacing of lattice planes normal to a grid axis [m]: d (SC), h (FCC).
  double layer_spacing() const { return spacing; }
  /// Area per site of a lattice plane normal to a grid axis [m^2]: d^2 for
  /// both packings (FCC: half of the (h x h) grid points of a plane).
  double area_per_surface_site() const { return diameter * diameter; }
};

/// d > 0 [m].
Lattice make_lattice(LatticeKind kind, double diameter);

}  // namespace arthrosim::shockwave
