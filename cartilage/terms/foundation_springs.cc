#include "cartilage/terms/foundation_springs.h"

#include <Eigen/Dense>
#include <cmath>
#include <string>

#include "cartilage/surface_model.h"
#include "cartilage/terms/foundation_geometry.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

class FoundationSpringsTerm final : public ShellTerm {
 public:
  FoundationSpringsTerm(const ShellModel& model, Eigen::VectorXd k, BoneMotion bone, bool compressive_only)
      : ShellTerm("foundation_springs"),
        geo_(model, std::move(bone)),
        k_(std::move(k)),
        compressive_only_(compressive_only) {
    if (k_.size() != model.num_nodes())
      throw common::InputError("foundation_springs: expected " + std::to_string(model.num_nodes()) +
                               " nodal stiffnesses, found " + std::to_string(k_.size()));
    for (int i = 0; i < k_.size(); ++i)
      if (!(k_(i) >= 0) || !std::isfinite(k_(i)))
        throw common::InputError("foundation_springs: stiffness k must be >= 0 N/m^3, found " + std::to_string(k_(i)) +
                                 " at node " + std::to_string(i));
  }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    geo_.for_each_node(ctx.t, [&](int i, const Eigen::Vector3d& p, const Eigen::Vector3d& n,
                                  const Eigen::Vector3d& /*p_dot*/, const Eigen::Vector3d& /*n_dot*/) {
      const double delta = n.dot(p - ctx.q.segment<3>(6 * i));
      // Compressive-only (the seed's elements). At delta = 0 (the reference
      // state) the spring counts as engaged: zero force but its stiffness in
      // the tangent, so the first Newton step from rest sees the foundation.
      if (compressive_only_ && delta < 0) return;
      const double kA = k_(i) * geo_.area(i);
      F.segment<3>(6 * i) -= kA * delta * n;
      if (K) K->add_block3(i, 0, i, 0, ctx.kq * kA * n * n.transpose());
    });
  }

 private:
  FoundationGeometry geo_;
  Eigen::VectorXd k_;
  bool compressive_only_;
};

}  // namespace

std::unique_ptr<ShellTerm> make_foundation_springs_term(const ShellModel& model, Eigen::VectorXd k_per_node_N_m3,
                                                        BoneMotion bone, bool compressive_only) {
  return std::make_unique<FoundationSpringsTerm>(model, std::move(k_per_node_N_m3), std::move(bone), compressive_only);
}

SurfaceTermInfo foundation_springs_term() {
  return {"foundation_springs", "", {}, [](const SurfaceTermContext& c) {
            const Eigen::VectorXd& k = c.parameters.foundation_stiffness_per_node_N_m3;
            if (k.size() > 0) {
              if (k.size() != c.model.num_nodes())
                throw common::InputError("surface " + c.surface.name + ": " + std::to_string(k.size()) +
                                         " nodal foundation stiffnesses for " + std::to_string(c.model.num_nodes()) +
                                         " nodes");
              c.model.add_foundation_springs(k, c.bone);
            } else {
              c.model.add_foundation_springs(c.parameters.foundation_stiffness_N_m3, c.bone);
            }
          }};
}

}  // namespace arthrosim::cartilage
