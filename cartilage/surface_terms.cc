#include "cartilage/surface_terms.h"

#include <algorithm>
#include <array>
#include <map>
#include <stdexcept>

#include "cartilage/surface_model.h"
#include "cartilage/terms/fixed_nodes.h"
#include "cartilage/terms/foundation_damping.h"
#include "cartilage/terms/foundation_springs.h"
#include "cartilage/terms/inertia.h"
#include "cartilage/terms/osmotic_pressure.h"
#include "cartilage/terms/periphery_fixed.h"
#include "cartilage/terms/point_loads.h"
#include "cartilage/terms/prescribed_displacement.h"
#include "cartilage/terms/pressure.h"
#include "common/effects.h"
#include "common/error.h"

namespace arthrosim::cartilage {

namespace {

// The bundled terms, one registration each (the description of a bundled
// term is its entry in common/effects.cc).
std::vector<SurfaceTermInfo> bundled_terms() {
  return {foundation_springs_term(),
          foundation_damping_term(),
          osmotic_pressure_term(),
          periphery_fixed_term(),
          inertia_term(),
          fixed_nodes_term(),
          point_loads_term(),
          pressure_term(),
          prescribed_displacement_term()};
}

std::vector<SurfaceTermInfo>& registry() {
  static std::vector<SurfaceTermInfo> terms = [] {
    std::vector<SurfaceTermInfo> t = bundled_terms();
    for (SurfaceTermInfo& term : t) {
      const common::EffectInfo* e = common::find_effect(term.name);
      if (e == nullptr || e->stage != common::EffectStage::kSurface)
        throw std::logic_error("bundled surface term '" + term.name + "' is not a surface effect of common/effects.cc");
      term.description = std::string(e->description);
    }
    return t;
  }();
  return terms;
}

}  // namespace

bool register_surface_term(SurfaceTermInfo term) {
  if (find_surface_term(term.name) != nullptr)
    throw std::logic_error("surface term '" + term.name + "' registered twice");
  if (!term.build) throw std::logic_error("surface term '" + term.name + "' has no builder");
  common::register_effect(term.name, common::EffectStage::kSurface, term.description);
  registry().push_back(std::move(term));
  return true;
}

const SurfaceTermInfo* find_surface_term(std::string_view name) {
  for (const SurfaceTermInfo& t : registry())
    if (t.name == name) return &t;
  return nullptr;
}

const std::vector<SurfaceTermInfo>& surface_terms() { return registry(); }

}  // namespace arthrosim::cartilage
