#include "cartilage/terms/pressure.h"

#include <Eigen/Dense>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "cartilage/surface_model.h"
#include "cartilage/terms/term_support.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

// Follower pressure on the face zeta = zf: external virtual work
//   dW = int p n . dr da = int p (a1 x a2) . dr dxi deta,  a_alpha = dr/dxi_alpha
// at zeta = zf; 2x2 Gauss is exact (integrand bi-quadratic). Tangent of
// F = -f_ext: dF_s/dq_t = -p phi_s (phi_t,xi (-[a2]x) + phi_t,eta [a1]x).
class PressureTerm final : public ShellTerm {
 public:
  PressureTerm(const ShellModel& model, std::string name, double zf, std::function<double(double)> p)
      : ShellTerm(std::move(name)),
        model_(model),
        zf_(zf),
        p_(std::move(p)),
        fe_(model.num_elements()),
        Ke_(model.num_elements()) {
    if (!(zf >= -1 && zf <= 1))
      throw common::InputError(this->name() + ": face_zeta must be in [-1, 1], found " + std::to_string(zf));
    if (!p_) throw common::InputError(this->name() + ": pressure function is empty");
  }
  bool symmetric() const override { return false; }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    const double p = p_(ctx.t);
    if (!std::isfinite(p))
      throw common::NumericalError(name() + ": non-finite pressure at t = " + std::to_string(ctx.t));
    if (p == 0) return;
    const int ne = model_.num_elements();
    const bool want_K = K != nullptr;
    const double g = 1.0 / std::sqrt(3.0);
#pragma omp parallel for schedule(static) if (ne > 64)
    for (int e = 0; e < ne; ++e) {
      const Vector24 qe = model_.gather(e, ctx.q);
      const Eigen::Map<const Eigen::Matrix<double, 3, 8>> Qt(qe.data());
      fe_[e].setZero();
      if (want_K) Ke_[e].setZero();
      for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
          Eigen::Matrix<double, 8, 1> phi;
          Eigen::Matrix<double, 8, 3> dphi;
          model_.element(e).slot_functions(i ? g : -g, j ? g : -g, zf_, phi, dphi);
          const Eigen::Vector3d a1 = Qt * dphi.col(0), a2 = Qt * dphi.col(1);
          const Eigen::Vector3d na = a1.cross(a2);
          for (int s = 0; s < 8; ++s) fe_[e].segment<3>(3 * s) -= p * phi(s) * na;
          if (!want_K) continue;
          const Eigen::Matrix3d S1 = -skew(a2), S2 = skew(a1);
          for (int t = 0; t < 8; ++t) {
            const Eigen::Matrix3d dna = dphi(t, 0) * S1 + dphi(t, 1) * S2;
            for (int s = 0; s < 8; ++s) Ke_[e].block<3, 3>(3 * s, 3 * t) -= p * phi(s) * dna;
          }
        }
    }
    scatter_element_results(model_, fe_, Ke_, ctx.kq, F, K);
  }

 private:
  const ShellModel& model_;
  double zf_;
  std::function<double(double)> p_;
  mutable std::vector<Vector24> fe_;
  mutable std::vector<Matrix24> Ke_;
};

}  // namespace

std::unique_ptr<ShellTerm> make_pressure_term(const ShellModel& model, std::string name, double face_zeta,
                                              std::function<double(double)> p_Pa) {
  return std::make_unique<PressureTerm>(model, std::move(name), face_zeta, std::move(p_Pa));
}

SurfaceTermInfo pressure_term() {
  return {"pressure", "", {}, [](const SurfaceTermContext& c) {
            const double p = c.surface.generic.pressure_Pa;
            const std::function<double(double)> ramp = c.ramp;
            c.model.add_pressure("pressure", 0.0, [p, ramp](double t) { return p * ramp(t); });
          }};
}

}  // namespace arthrosim::cartilage
