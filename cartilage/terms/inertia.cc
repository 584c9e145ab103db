#include "cartilage/terms/inertia.h"

#include <Eigen/Dense>

#include "cartilage/surface_model.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

class InertiaTerm final : public ShellTerm {
 public:
  explicit InertiaTerm(const ShellModel& model) : ShellTerm("inertia"), model_(model) {}
  bool inertial() const override { return true; }
  void add(const TermContext& ctx, Eigen::VectorXd& Ma, TangentAssembler* K) const override {
    Ma.noalias() += model_.mass_matrix() * ctx.a;
    if (K && ctx.ka != 0) {
      const double* m = model_.mass_matrix().valuePtr();
      double* k = K->matrix().valuePtr();
      const Eigen::Index nnz = model_.mass_matrix().nonZeros();
      for (Eigen::Index i = 0; i < nnz; ++i) k[i] += ctx.ka * m[i];
    }
  }

 private:
  const ShellModel& model_;
};

}  // namespace

std::unique_ptr<ShellTerm> make_inertia_term(const ShellModel& model) { return std::make_unique<InertiaTerm>(model); }

SurfaceTermInfo inertia_term() {
  return {"inertia", "", {}, [](const SurfaceTermContext& c) { c.model.add_inertia(); }};
}

}  // namespace arthrosim::cartilage
