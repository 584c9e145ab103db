#include "cartilage/surface_terms.h"

#include <algorithm>
#include <array>
#include <map>
#include <stdexcept>

#include "cartilage/surface_model.h"
#include "common/effects.h"
#include "common/error.h"

namespace arthrosim::cartilage {

namespace {

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
  t.push_back({"fixed_nodes", "",
               [](const SurfaceInput& s) {
                 bool any = !s.generic.fixed_nodes.empty();
                 for (const auto& c : s.generic.constraints) any = any || !c.definition.prescribed();
                 if (!any)
                   throw common::InputError("surface " + s.name + ": effect 'fixed_nodes' is requested but neither "
                                            "its box nor a constraint without values holds a node of the mesh");
               },
               [](const SurfaceTermContext& c) {
                 // One constraint: the box (all six coordinates) and every
                 // constraint without values, masks united per node.
                 std::map<int, std::array<bool, 6>> masks;
                 for (int n : c.surface.generic.fixed_nodes) masks[n].fill(true);
                 for (const auto& sc : c.surface.generic.constraints)
                   if (!sc.definition.prescribed())
                     for (int n : sc.nodes)
                       for (int j = 0; j < 6; ++j) masks[n][j] = masks[n][j] || sc.definition.mask[j];
                 NodeConstraint n;
                 n.name = "fixed_nodes";
                 for (const auto& [node, mask] : masks) {
                   n.nodes.push_back(node);
                   n.node_masks.push_back(mask);
                 }
                 const Eigen::VectorXd q0 = c.model.reference_state();
                 n.value = [q0](double, int node, Eigen::Matrix<double, 6, 1>& q6) { q6 = q0.segment<6>(6 * node); };
                 c.model.add_constraint(std::move(n));
               }});
  t.push_back({"point_loads", "",
               [](const SurfaceInput& s) {
                 if (s.generic.load_nodes.empty() && s.generic.set_loads_N.empty() && s.generic.history_loads_N.empty())
                   throw common::InputError("surface " + s.name + ": effect 'point_loads' is requested but neither "
                                            "its box nor `loads` puts a load on a node of the mesh");
               },
               [](const SurfaceTermContext& c) {
                 const GenericLoads& g = c.surface.generic;
                 std::vector<std::pair<int, Eigen::Vector3d>> loads;
                 for (int n : g.load_nodes)
                   loads.emplace_back(n, g.total_force_N / static_cast<double>(g.load_nodes.size()));
                 for (const auto& l : g.set_loads_N) loads.push_back(l);
                 c.model.add_point_loads("point_loads", std::move(loads), c.ramp);
                 // Loads with a history: one term each (named after it).
                 for (const auto& [name, l] : g.history_loads_N) {
                   const HistoryDefinition h = g.histories.at(name);
                   c.model.add_point_loads("point_loads (history " + name + ")", l,
                                           [h](double t) { return h.at(t); });
                 }
               }});
  t.push_back({"pressure", "", {}, [](const SurfaceTermContext& c) {
                 const double p = c.surface.generic.pressure_Pa;
                 const std::function<double(double)> ramp = c.ramp;
                 c.model.add_pressure("pressure", 0.0, [p, ramp](double t) { return p * ramp(t); });
               }});
  t.push_back({"prescribed_displacement", "",
               [](const SurfaceInput& s) {
                 bool any = !s.generic.displaced_nodes.empty();
                 for (const auto& c : s.generic.constraints) any = any || c.definition.prescribed();
                 if (!any)
                   throw common::InputError("surface " + s.name + ": effect 'prescribed_displacement' is requested "
                                            "but neither its box nor a constraint with values holds a node of the "
                                            "mesh");
               },
               [](const SurfaceTermContext& c) {
                 // One constraint: the box (positions moved by
                 // displacement_m) and every constraint with values, per node
                 // its united mask and its values (a component prescribed
                 // twice must have one value).
                 const GenericLoads& g = c.surface.generic;
                 std::map<int, std::pair<std::array<bool, 6>, Eigen::Matrix<double, 6, 1>>> per_node;
                 // Per node and component: the history's index in `hist`, -1 = the ramp.
                 std::map<int, std::array<int, 6>> node_history;
                 std::vector<HistoryDefinition> hist;
                 auto add = [&](int node, const std::array<bool, 6>& mask, const Eigen::Matrix<double, 6, 1>& v,
                                int h = -1) {
                   if (h >= 0 && !node_history.count(node)) node_history[node].fill(-1);
                   auto [it, fresh] = per_node.try_emplace(node);
                   if (fresh) {
                     it->second.first.fill(false);
                     it->second.second.setZero();
                   }
                   for (int j = 0; j < 6; ++j) {
                     if (!mask[j]) continue;
                     if (it->second.first[j] && it->second.second(j) != v(j))
                       throw common::InputError("surface " + c.surface.name + ": node " + std::to_string(node) +
                                                " has two different prescribed values of one component");
                     if (it->second.first[j] && (node_history.count(node) ? node_history[node][j] : -1) != h)
                       throw common::InputError("surface " + c.surface.name + ": node " + std::to_string(node) +
                                                " has two different histories of one prescribed component");
                     it->second.first[j] = true;
                     it->second.second(j) = v(j);
                     if (h >= 0) node_history[node][j] = h;
                   }
                 };
                 Eigen::Matrix<double, 6, 1> u = Eigen::Matrix<double, 6, 1>::Zero();
                 u.head<3>() = g.displacement_m;
                 for (int n : g.displaced_nodes) add(n, {true, true, true, false, false, false}, u);
                 for (const auto& sc : g.constraints)
                   if (sc.definition.prescribed()) {
                     int h = -1;
                     if (!sc.definition.history.empty()) {
                       h = static_cast<int>(hist.size());
                       hist.push_back(g.histories.at(sc.definition.history));
                     }
                     for (int n : sc.nodes) add(n, sc.definition.mask, sc.definition.value, h);
                   }
                 NodeConstraint n;
                 n.name = "prescribed_displacement";
                 std::vector<Eigen::Matrix<double, 6, 1>> values(static_cast<size_t>(c.model.num_nodes()),
                                                                 Eigen::Matrix<double, 6, 1>::Zero());
                 for (const auto& [node, mv] : per_node) {
                   n.nodes.push_back(node);
                   n.node_masks.push_back(mv.first);
                   values[static_cast<size_t>(node)] = mv.second;
                 }
                 const Eigen::VectorXd q0 = c.model.reference_state();
                 const std::function<double(double)> ramp = c.ramp;
                 if (node_history.empty()) {
                   n.value = [q0, values, ramp](double t, int node, Eigen::Matrix<double, 6, 1>& q6) {
                     q6 = q0.segment<6>(6 * node) + ramp(t) * values[static_cast<size_t>(node)];
                   };
                 } else {
                   std::vector<std::array<int, 6>> which(static_cast<size_t>(c.model.num_nodes()));
                   for (auto& w : which) w.fill(-1);
                   for (const auto& [node, w] : node_history) which[static_cast<size_t>(node)] = w;
                   n.value = [q0, values, ramp, which, hist](double t, int node, Eigen::Matrix<double, 6, 1>& q6) {
                     const size_t i = static_cast<size_t>(node);
                     q6 = q0.segment<6>(6 * node);
                     for (int j = 0; j < 6; ++j) {
                       const int h = which[i][static_cast<size_t>(j)];
                       q6(j) += (h < 0 ? ramp(t) : hist[static_cast<size_t>(h)].at(t)) * values[i](j);
                     }
                   };
                 }
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
