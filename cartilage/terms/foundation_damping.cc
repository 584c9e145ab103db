#include "cartilage/terms/foundation_damping.h"

#include <Eigen/Dense>
#include <cmath>
#include <string>

#include "cartilage/surface_model.h"
#include "cartilage/terms/foundation_geometry.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

class FoundationDampingTerm final : public ShellTerm {
 public:
  FoundationDampingTerm(const ShellModel& model, double c, BoneMotion bone, bool compressive_only, double gate)
      : ShellTerm("foundation_damping"),
        geo_(model, std::move(bone)),
        c_(c),
        compressive_only_(compressive_only),
        gate_(gate) {
    if (!(c >= 0) || !std::isfinite(c))
      throw common::InputError("foundation_damping: coefficient c must be >= 0 N s/m^3, found " + std::to_string(c));
    if (compressive_only && !(gate > 0))
      throw common::InputError("foundation_damping: gate width must be > 0 m, found " + std::to_string(gate));
  }
  // The d n/dt term couples positions and velocities asymmetrically when the
  // bone rotates.
  bool symmetric() const override { return geo_.bone.at_rest; }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    geo_.for_each_node(ctx.t, [&](int i, const Eigen::Vector3d& p, const Eigen::Vector3d& n, const Eigen::Vector3d& pd,
                                  const Eigen::Vector3d& nd) {
      const Eigen::Vector3d r = ctx.q.segment<3>(6 * i);
      // Compressive-only: the damper engages with the compression delta
      // through the smoothstep gate H(delta/gate) (0 at delta <= 0, 1 from
      // delta >= gate). A sharp gate would make the force c A delta_dot
      // jump where delta changes sign -- at every node resting on its
      // foundation -- and Newton would not converge there.
      double H = 1, dH = 0;
      if (compressive_only_) {
        const double s = n.dot(p - r) / gate_;
        if (s <= 0) return;
        if (s < 1) {
          H = s * s * (3 - 2 * s);
          dH = 6 * s * (1 - s) / gate_;
        }
      }
      const Eigen::Vector3d v = ctx.v.segment<3>(6 * i);
      const double delta_dot = nd.dot(p - r) + n.dot(pd - v);
      const double cA = c_ * geo_.area(i);
      F.segment<3>(6 * i) -= cA * delta_dot * H * n;
      if (K) {
        // d/dv: c A H n n^T; d/dr: c A (H n nd^T + delta_dot H' n n^T).
        Eigen::Matrix3d B = (ctx.kv * cA * H + ctx.kq * cA * delta_dot * dH) * n * n.transpose();
        if (!geo_.bone.at_rest) B += ctx.kq * cA * H * n * nd.transpose();
        K->add_block3(i, 0, i, 0, B);
      }
    });
  }

 private:
  FoundationGeometry geo_;
  double c_;
  bool compressive_only_;
  double gate_;
};

}  // namespace

std::unique_ptr<ShellTerm> make_foundation_damping_term(const ShellModel& model, double c_N_s_m3, BoneMotion bone,
                                                        bool compressive_only, double gate_m) {
  return std::make_unique<FoundationDampingTerm>(model, c_N_s_m3, std::move(bone), compressive_only, gate_m);
}

SurfaceTermInfo foundation_damping_term() {
  return {"foundation_damping", "", {}, [](const SurfaceTermContext& c) {
            c.model.add_foundation_damping(c.parameters.foundation_damping_N_s_m3, c.bone, true);
          }};
}

}  // namespace arthrosim::cartilage
