#include "cartilage/terms/fixed_nodes.h"

#include <array>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>

#include "cartilage/surface_model.h"
#include "common/error.h"

namespace arthrosim::cartilage {

SurfaceTermInfo fixed_nodes_term() {
  return {"fixed_nodes", "",
          [](const SurfaceInput& s) {
            bool any = !s.generic.fixed_nodes.empty();
            for (const auto& c : s.generic.constraints) any = any || !c.definition.prescribed();
            if (!any)
              throw common::InputError("surface " + s.name +
                                       ": effect 'fixed_nodes' is requested but neither "
                                       "its box nor a constraint without values holds a node of the mesh");
          },
          [](const SurfaceTermContext& c) {
            // One constraint: the box (all six coordinates) and every
            // constraint without values, masks united per node.
            std::map<int, std::array<bool, 6>> masks;
            for (int n : c.surface.generic.fixed_nodes) masks[n].fill(true);
            using Frame = ConstraintDefinition::Frame;
            for (const auto& sc : c.surface.generic.constraints)
              if (!sc.definition.prescribed() && sc.definition.frame == Frame::kGlobal)
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
            const auto hold = n.value;
            c.model.add_constraint(std::move(n));
            // Each local-frame constraint on its own (a node may lie in
            // several, e.g. two oblique symmetry planes): frames per node.
            int item = 0;
            for (const auto& sc : c.surface.generic.constraints) {
              ++item;
              if (sc.definition.frame == Frame::kGlobal) continue;
              NodeConstraint l;
              l.name = "fixed_nodes (local frame, item " + std::to_string(item) + ", set " + sc.definition.set + ")";
              l.nodes = sc.nodes;
              l.mask = sc.definition.mask;
              for (int node : sc.nodes) {
                try {
                  l.frames.push_back(sc.definition.local_frame(c.model.reference_position(node)));
                } catch (const std::invalid_argument& e) {
                  throw common::InputError("surface " + c.surface.name + ": constraint on set '" + sc.definition.set +
                                           "', node " + std::to_string(node) + ": " + e.what());
                }
              }
              l.value = hold;
              c.model.add_constraint(std::move(l));
            }
          }};
}

}  // namespace arthrosim::cartilage
