#include "cartilage/terms/director_moments.h"

#include <Eigen/Dense>
#include <cmath>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "cartilage/terms/term_support.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

// Conservative director couple: potential -M theta(d), theta the angle of d
// about the axis e; grad theta = (e x d)/|d_perp|^2 and its Hessian
//   [e]x/|d_perp|^2 - 2 (e x d) d_perp^T/|d_perp|^4   (symmetric).
class DirectorMomentsTerm final : public ShellTerm {
 public:
  DirectorMomentsTerm(const ShellModel& model, std::string name, const Eigen::Vector3d& axis,
                      std::vector<std::pair<int, double>> moments, std::function<double(double)> scale)
      : ShellTerm(std::move(name)), e_(axis.normalized()), moments_(std::move(moments)), scale_(std::move(scale)) {
    if (!(axis.norm() > 0) || !axis.allFinite())
      throw common::InputError(this->name() + ": axis must be a non-zero vector");
    for (const auto& [node, m] : moments_)
      if (node < 0 || node >= model.num_nodes() || !std::isfinite(m))
        throw common::InputError(this->name() + ": invalid node " + std::to_string(node) + " or moment");
    if (!scale_) throw common::InputError(this->name() + ": scale function is empty");
  }
  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    const double s = scale_(ctx.t);
    for (const auto& [node, m] : moments_) {
      const Eigen::Vector3d d = ctx.q.segment<3>(6 * node + 3);
      const Eigen::Vector3d dp = d - d.dot(e_) * e_;
      const double r2 = dp.squaredNorm();
      if (!(r2 > 0))
        throw common::NumericalError(name() + ": director of node " + std::to_string(node) +
                                     " is parallel to the moment axis");
      const Eigen::Vector3d exd = e_.cross(d);
      const double M = s * m;
      F.segment<3>(6 * node + 3) -= M * exd / r2;
      if (K) {
        const Eigen::Matrix3d H = skew(e_) / r2 - 2.0 * exd * dp.transpose() / (r2 * r2);
        K->add_block3(node, 3, node, 3, -ctx.kq * M * H);
      }
    }
  }

 private:
  Eigen::Vector3d e_;
  std::vector<std::pair<int, double>> moments_;
  std::function<double(double)> scale_;
};

}  // namespace

std::unique_ptr<ShellTerm> make_director_moments_term(const ShellModel& model, std::string name,
                                                      const Eigen::Vector3d& axis,
                                                      std::vector<std::pair<int, double>> moments,
                                                      std::function<double(double)> scale) {
  return std::make_unique<DirectorMomentsTerm>(model, std::move(name), axis, std::move(moments), std::move(scale));
}

}  // namespace arthrosim::cartilage
