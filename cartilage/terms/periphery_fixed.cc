#include "cartilage/terms/periphery_fixed.h"

#include <Eigen/Dense>
#include <cmath>
#include <string>
#include <vector>

#include "cartilage/surface_model.h"
#include "cartilage/terms/foundation_geometry.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

// "periphery_fixed" with the normal left to the foundation: each boundary
// node is tied to its bone-carried anchor p_i(t) in the tangent plane of its
// reference transverse direction n_i(t) only,
//   F_i += k_t A_i (I - n_i n_i^T)(r_i - p_i),  dF_i/dr_i = k_t A_i (I - n_i n_i^T)
// (a penalty tie, symmetric: P depends on t only); its director is free.
class PeripheryTangentialTerm final : public ShellTerm {
 public:
  PeripheryTangentialTerm(const ShellModel& model, std::vector<int> nodes, double k_t, BoneMotion bone)
      : ShellTerm("periphery_fixed"), geo_(model, std::move(bone)), nodes_(std::move(nodes)), k_t_(k_t) {
    if (!(k_t > 0) || !std::isfinite(k_t))
      throw common::InputError("periphery_fixed: tangential tie stiffness must be > 0 N/m^3, found " +
                               std::to_string(k_t));
  }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    const Eigen::Isometry3d X = geo_.bone.pose(ctx.t);
    const Eigen::Matrix<double, 6, 1> V = geo_.bone.spatial_velocity(ctx.t);
    for (int i : nodes_) {
      Eigen::Vector3d p, n, pd, nd;
      geo_.at(X, V, i, p, n, pd, nd);
      const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - n * n.transpose();
      const double kA = k_t_ * geo_.area(i);
      F.segment<3>(6 * i) += kA * P * (ctx.q.segment<3>(6 * i) - p);
      if (K) K->add_block3(i, 0, i, 0, ctx.kq * kA * P);
    }
  }

 private:
  FoundationGeometry geo_;
  std::vector<int> nodes_;
  double k_t_;
};

}  // namespace

std::unique_ptr<ShellTerm> make_periphery_tangential_term(const ShellModel& model, std::vector<int> nodes,
                                                          double k_t_N_m3, BoneMotion bone) {
  return std::make_unique<PeripheryTangentialTerm>(model, std::move(nodes), k_t_N_m3, std::move(bone));
}

SurfaceTermInfo periphery_fixed_term() {
  return {"periphery_fixed", "", {}, [](const SurfaceTermContext& c) {
            if (c.parameters.periphery_tie_N_m3 > 0)
              c.model.add_periphery_tangential(c.parameters.periphery_tie_N_m3, c.bone);
            else
              c.model.add_periphery_fixed(c.bone);
          }};
}

}  // namespace arthrosim::cartilage
