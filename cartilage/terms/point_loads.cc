#include "cartilage/terms/point_loads.h"

#include <Eigen/Dense>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "cartilage/surface_model.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

class PointLoadsTerm final : public ShellTerm {
 public:
  PointLoadsTerm(const ShellModel& model, std::string name, std::vector<std::pair<int, Eigen::Vector3d>> loads,
                 std::function<double(double)> scale)
      : ShellTerm(std::move(name)), loads_(std::move(loads)), scale_(std::move(scale)) {
    for (const auto& [node, f] : loads_)
      if (node < 0 || node >= model.num_nodes() || !f.allFinite())
        throw common::InputError(this->name() + ": node index must be in [0, " + std::to_string(model.num_nodes()) +
                                 ") with a finite force, found node " + std::to_string(node));
    if (!scale_) throw common::InputError(this->name() + ": scale function is empty");
  }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler*) const override {
    const double s = scale_(ctx.t);
    for (const auto& [node, f] : loads_) F.segment<3>(6 * node) -= s * f;
  }

 private:
  std::vector<std::pair<int, Eigen::Vector3d>> loads_;
  std::function<double(double)> scale_;
};

}  // namespace

std::unique_ptr<ShellTerm> make_point_loads_term(const ShellModel& model, std::string name,
                                                 std::vector<std::pair<int, Eigen::Vector3d>> loads,
                                                 std::function<double(double)> scale) {
  return std::make_unique<PointLoadsTerm>(model, std::move(name), std::move(loads), std::move(scale));
}

SurfaceTermInfo point_loads_term() {
  return {"point_loads", "",
          [](const SurfaceInput& s) {
            if (s.generic.load_nodes.empty() && s.generic.set_loads_N.empty() && s.generic.history_loads_N.empty())
              throw common::InputError("surface " + s.name +
                                       ": effect 'point_loads' is requested but neither "
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
              c.model.add_point_loads("point_loads (history " + name + ")", l, [h](double t) { return h.at(t); });
            }
          }};
}

}  // namespace arthrosim::cartilage
