#include "cartilage/surface_terms.h"

#include <algorithm>
#include <array>
#include <stdexcept>

#include "cartilage/surface_model.h"
#include "common/effects.h"
#include "common/error.h"

namespace arthrosim::cartilage {

namespace {

// A generic mesh's node set of an effect must hold a node.
std::function<void(const SurfaceInput&)> needs_nodes(const char* effect, std::vector<int> GenericLoads::*set) {
  return [effect, set](const SurfaceInput& s) {
    if ((s.generic.*set).empty())
      throw common::InputError("surface " + s.name + ": effect '" + effect +
                               "' is requested but its node set (box) holds no node of the mesh");
  };
}

// The bundled terms, one registration each (the description of a bundled
// term is its entry in common/effects.cc).
std::vector<SurfaceTermInfo> bundled_terms() {
  std::vector<SurfaceTermInfo> t;
  t.push_back({"foundation_springs", "", {}, [](const SurfaceTermContext& c) {
                 const Eigen::VectorXd& k = c.parameters.foundation_stiffness_per_node_N_m3;
                 if (k.size() > 0) {
                   if (k.size() != c.model.num_nodes())
                     throw common::InputError("surface " + c.surface.name + ": " + std::to_string(k.size()) +
                                              " nodal foundation stiffnesses for " +
                                              std::to_string(c.model.num_nodes()) + " nodes");
                   c.model.add_foundation_springs(k, c.bone);
                 } else {
                   c.model.add_foundation_springs(c.parameters.foundation_stiffness_N_m3, c.bone);
                 }
               }});
  t.push_back({"foundation_damping", "", {}, [](const SurfaceTermContext& c) {
                 c.model.add_foundation_damping(c.parameters.foundation_damping_N_s_m3, c.bone, true);
               }});
  t.push_back({"osmotic_pressure", "", {}, [](const SurfaceTermContext& c) {
                 const double p = c.parameters.osmotic_pressure_Pa, T = c.parameters.osmotic_ramp_s;
                 c.model.add_pressure("osmotic_pressure", -1.0, [p, T](double t) {
                   if (!(T > 0) || t >= T) return p;
                   const double u = std::max(t, 0.0) / T;
                   return p * u * u * (3 - 2 * u);
                 });
               }});
  t.push_back({"periphery_fixed", "", {}, [](const SurfaceTermContext& c) {
                 if (c.parameters.periphery_tie_N_m3 > 0)
                   c.model.add_periphery_tangential(c.parameters.periphery_tie_N_m3, c.bone);
                 else
                   c.model.add_periphery_fixed(c.bone);
               }});
  t.push_back({"inertia", "", {}, [](const SurfaceTermContext& c) { c.model.add_inertia(); }});
  t.push_back({"fixed_nodes", "", needs_nodes("fixed_nodes", &GenericLoads::fixed_nodes),
               [](const SurfaceTermContext& c) {
                 std::array<bool, 6> all;
                 all.fill(true);
                 c.model.fix_nodes("fixed_nodes", c.surface.generic.fixed_nodes, all);
               }});
  t.push_back({"point_loads", "", needs_nodes("point_loads", &GenericLoads::load_nodes),
               [](const SurfaceTermContext& c) {
                 const GenericLoads& g = c.surface.generic;
                 std::vector<std::pair<int, Eigen::Vector3d>> loads;
                 for (int n : g.load_nodes)
                   loads.emplace_back(n, g.total_force_N / static_cast<double>(g.load_nodes.size()));
                 c.model.add_point_loads("point_loads", std::move(loads), c.ramp);
               }});
  t.push_back({"pressure", "", {}, [](const SurfaceTermContext& c) {
                 const double p = c.surface.generic.pressure_Pa;
                 const std::function<double(double)> ramp = c.ramp;
                 c.model.add_pressure("pressure", 0.0, [p, ramp](double t) { return p * ramp(t); });
               }});
  t.push_back({"prescribed_displacement", "",
               needs_nodes("prescribed_displacement", &GenericLoads::displaced_nodes),
               [](const SurfaceTermContext& c) {
                 NodeConstraint n;
                 n.name = "prescribed_displacement";
                 n.nodes = c.surface.generic.displaced_nodes;
                 n.mask = {true, true, true, false, false, false};
                 const Eigen::VectorXd q0 = c.model.reference_state();
                 const Eigen::Vector3d u = c.surface.generic.displacement_m;
                 const std::function<double(double)> ramp = c.ramp;
                 n.value = [q0, u, ramp](double t, int node, Eigen::Matrix<double, 6, 1>& q6) {
                   q6.head<3>() = q0.segment<3>(6 * node) + ramp(t) * u;
                 };
                 c.model.add_constraint(std::move(n));
               }});
  return t;
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
