#include "shockwave/lattice.h"

#include <cmath>

#include "common/error.h"

namespace arthrosim::shockwave {

std::string to_string(LatticeKind kind) { return kind == LatticeKind::kSimpleCubic ? "sc" : "fcc"; }

LatticeKind parse_lattice_kind(const std::string& text, const std::string& source) {
  if (text == "sc" || text == "simple_cubic") return LatticeKind::kSimpleCubic;
  if (text == "fcc") return LatticeKind::kFcc;
  throw common::InputError(source, 0, "expected lattice 'fcc' or 'sc', found '" + text + "'");
}

Lattice make_lattice(LatticeKind kind, double d) {
  if (!(d > 0.0 && std::isfinite(d)))
    throw common::InputError("lattice", 0, "expected an automaton diameter > 0, found " + std::to_string(d));
  Lattice l;
  l.kind = kind;
  l.diameter = d;
  l.radius = 0.5 * d;
  const double R = l.radius;
  if (kind == LatticeKind::kSimpleCubic) {
    l.spacing = d;
    l.contact_area = 4.0 * R * R;
    l.cell_volume = d * d * d;
    l.directions = 6;
    const std::array<std::array<int, 3>, 3> fwd{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
    for (int s = 0; s < 3; ++s) {
      l.offsets[s] = fwd[s];
      l.offsets[s + 3] = {-fwd[s][0], -fwd[s][1], -fwd[s][2]};
    }
  } else {
    l.spacing = d / std::sqrt(2.0);
    l.contact_area = std::sqrt(2.0) * R * R;
    l.cell_volume = d * d * d / std::sqrt(2.0);
    l.directions = 12;
    const std::array<std::array<int, 3>, 6> fwd{
        {{1, 1, 0}, {1, -1, 0}, {1, 0, 1}, {1, 0, -1}, {0, 1, 1}, {0, 1, -1}}};
    for (int s = 0; s < 6; ++s) {
      l.offsets[s] = fwd[s];
      l.offsets[s + 6] = {-fwd[s][0], -fwd[s][1], -fwd[s][2]};
    }
  }
  for (int s = 0; s < l.directions; ++s) {
    const common::Vec3 v(l.offsets[s][0], l.offsets[s][1], l.offsets[s][2]);
    l.unit[s] = v.normalized();
  }
  return l;
}

}  // namespace arthrosim::shockwave
