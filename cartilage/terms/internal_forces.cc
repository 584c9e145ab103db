#include "cartilage/terms/internal_forces.h"

#include <omp.h>

#include <Eigen/Dense>
#include <chrono>
#include <vector>

#include "cartilage/terms/term_support.h"
#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// internal_forces: f_int = sum_e dPi_e/dq_e. Elements are evaluated in
// parallel into per-element buffers, then summed serially in element order,
// so the result is bit-identical for any number of threads.
class InternalForcesTerm final : public ShellTerm {
 public:
  explicit InternalForcesTerm(ShellModel& model)
      : ShellTerm("internal_forces"), model_(model), fe_(model.num_elements()), Ke_(model.num_elements()) {}

  void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const override {
    const int ne = model_.num_elements();
    const bool want_K = K != nullptr;
    auto t0 = std::chrono::steady_clock::now();
#pragma omp parallel for schedule(static) if (ne > 64)
    for (int e = 0; e < ne; ++e) {
      const Vector24 qe = model_.gather(e, ctx.q);
      model_.element(e).internal_force(qe, fe_[e], want_K ? &Ke_[e] : nullptr);
    }
    auto& stats = model_.mutable_statistics();
    stats.element_time_s += seconds_since(t0);
    t0 = std::chrono::steady_clock::now();
    scatter_element_results(model_, fe_, Ke_, ctx.kq, F, K);
    stats.scatter_time_s += seconds_since(t0);
  }

 private:
  ShellModel& model_;
  mutable std::vector<Vector24> fe_;
  mutable std::vector<Matrix24> Ke_;
};

}  // namespace

std::unique_ptr<ShellTerm> make_internal_forces_term(ShellModel& model) {
  return std::make_unique<InternalForcesTerm>(model);
}

}  // namespace arthrosim::cartilage
