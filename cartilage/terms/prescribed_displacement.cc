#include "cartilage/terms/prescribed_displacement.h"

#include <array>
#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "cartilage/surface_model.h"
#include "common/error.h"

namespace arthrosim::cartilage {

SurfaceTermInfo prescribed_displacement_term() {
  return {"prescribed_displacement", "",
          [](const SurfaceInput& s) {
            bool any = !s.generic.displaced_nodes.empty();
            for (const auto& c : s.generic.constraints) any = any || c.definition.prescribed();
            if (!any)
              throw common::InputError("surface " + s.name +
                                       ": effect 'prescribed_displacement' is requested "
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
          }};
}

}  // namespace arthrosim::cartilage
