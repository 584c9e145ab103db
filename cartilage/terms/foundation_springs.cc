#include "cartilage/terms/foundation_springs.h"

#include <Eigen/Dense>
#include <cmath>
#include <string>
#include <vector>

#include "cartilage/surface_model.h"
#include "cartilage/terms/foundation_geometry.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

class FoundationSpringsTerm final : public ShellTerm {
 public:
  FoundationSpringsTerm(const ShellModel& model, Eigen::VectorXd k, BoneMotion bone, bool compressive_only,
                        FoundationIntegration integration)
      : ShellTerm("foundation_springs"),
        model_(model),
        geo_(model, std::move(bone)),
        k_(std::move(k)),
        compressive_only_(compressive_only),
        integration_(integration) {
    if (k_.size() != model.num_nodes())
      throw common::InputError("foundation_springs: expected " + std::to_string(model.num_nodes()) +
                               " nodal stiffnesses, found " + std::to_string(k_.size()));
    for (int i = 0; i < k_.size(); ++i)
      if (!(k_(i) >= 0) || !std::isfinite(k_(i)))
        throw common::InputError("foundation_springs: stiffness k must be >= 0 N/m^3, found " + std::to_string(k_(i)) +
                                 " at node " + std::to_string(i));
  }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    if (integration_ == FoundationIntegration::kConsistent) return add_consistent(ctx, F, K);
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
  // The Galerkin integral: nodal deflections delta_k = n_k . (p_k - r_k),
  // interpolated to the Gauss points; dE/dr_k = -sum_g k_g dA_g delta_g N_k n_k.
  void add_consistent(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const {
    const int num_nodes = model_.num_nodes();
    std::vector<Eigen::Vector3d> normal(num_nodes);
    Eigen::VectorXd delta(num_nodes);
    geo_.for_each_node(ctx.t, [&](int i, const Eigen::Vector3d& p, const Eigen::Vector3d& n,
                                  const Eigen::Vector3d& /*p_dot*/, const Eigen::Vector3d& /*n_dot*/) {
      normal[i] = n;
      delta(i) = n.dot(p - ctx.q.segment<3>(6 * i));
    });
    const common::Quads& quads = model_.quads();
    for (int e = 0; e < model_.num_elements(); ++e) {
      const auto& points = model_.element(e).surface_points();
      int node[4];
      for (int a = 0; a < 4; ++a) node[a] = quads(e, a);
      for (const auto& g : points) {
        double delta_g = 0, k_g = 0;
        for (int a = 0; a < 4; ++a) {
          delta_g += g.N[a] * delta(node[a]);
          k_g += g.N[a] * k_(node[a]);
        }
        // Engaged at delta_g = 0, as the nodal springs.
        if (compressive_only_ && delta_g < 0) continue;
        const double kdA = k_g * g.dA;
        for (int a = 0; a < 4; ++a) F.segment<3>(6 * node[a]) -= kdA * delta_g * g.N[a] * normal[node[a]];
        if (!K) continue;
        for (int a = 0; a < 4; ++a)
          for (int b = 0; b < 4; ++b)
            K->add_element_block3(e, a, 0, b, 0,
                                  (ctx.kq * kdA * g.N[a] * g.N[b]) * normal[node[a]] * normal[node[b]].transpose());
      }
    }
  }

  const ShellModel& model_;
  FoundationGeometry geo_;
  Eigen::VectorXd k_;
  bool compressive_only_;
  FoundationIntegration integration_;
};

}  // namespace

std::unique_ptr<ShellTerm> make_foundation_springs_term(const ShellModel& model, Eigen::VectorXd k_per_node_N_m3,
                                                        BoneMotion bone, bool compressive_only,
                                                        FoundationIntegration integration) {
  return std::make_unique<FoundationSpringsTerm>(model, std::move(k_per_node_N_m3), std::move(bone), compressive_only,
                                                 integration);
}

SurfaceTermInfo foundation_springs_term() {
  return {"foundation_springs", "", {}, [](const SurfaceTermContext& c) {
            const Eigen::VectorXd& k = c.parameters.foundation_stiffness_per_node_N_m3;
            if (k.size() > 0) {
              if (k.size() != c.model.num_nodes())
                throw common::InputError("surface " + c.surface.name + ": " + std::to_string(k.size()) +
                                         " nodal foundation stiffnesses for " + std::to_string(c.model.num_nodes()) +
                                         " nodes");
              c.model.add_foundation_springs(k, c.bone, true, c.parameters.foundation_integration);
            } else {
              c.model.add_foundation_springs(c.parameters.foundation_stiffness_N_m3, c.bone, true,
                                             c.parameters.foundation_integration);
            }
          }};
}

}  // namespace arthrosim::cartilage
