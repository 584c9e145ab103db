#include "cartilage/linear_solver.h"

#include <Eigen/CholmodSupport>
#include <Eigen/UmfPackSupport>

#include "common/error.h"

namespace arthrosim::cartilage {

const char* to_string(LinearSolverKind kind) {
  return kind == LinearSolverKind::kCholmod ? "CHOLMOD supernodal LLT" : "UMFPACK LU";
}

struct SparseDirectSolver::Impl {
  // Only the lower triangle is read by CHOLMOD (the matrix is symmetric).
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> cholmod;
  Eigen::UmfPackLU<Eigen::SparseMatrix<double>> umfpack;
};

SparseDirectSolver::SparseDirectSolver(LinearSolverKind kind) : impl_(std::make_unique<Impl>()), kind_(kind) {
  // A non-SPD matrix is reported through factorize()'s return value and the
  // caller's statistics; keep CHOLMOD from printing its own warning.
  impl_->cholmod.cholmod().print = 0;
}
SparseDirectSolver::~SparseDirectSolver() = default;

void SparseDirectSolver::analyze(const Eigen::SparseMatrix<double>& A) {
  if (kind_ == LinearSolverKind::kCholmod) {
    impl_->cholmod.analyzePattern(A);
  } else {
    impl_->umfpack.analyzePattern(A);
  }
  analyzed_ = true;
  ++num_analyses_;
}

bool SparseDirectSolver::factorize(const Eigen::SparseMatrix<double>& A) {
  if (!analyzed_) analyze(A);
  if (kind_ == LinearSolverKind::kCholmod) {
    impl_->cholmod.factorize(A);
    if (impl_->cholmod.info() != Eigen::Success) {
      message_ = "CHOLMOD: matrix is not positive definite (or factorisation failed)";
      return false;
    }
  } else {
    impl_->umfpack.factorize(A);
    if (impl_->umfpack.info() != Eigen::Success) {
      message_ = "UMFPACK: matrix is singular (or factorisation failed)";
      return false;
    }
  }
  message_.clear();
  return true;
}

Eigen::VectorXd SparseDirectSolver::solve(const Eigen::VectorXd& b) const {
  if (kind_ == LinearSolverKind::kCholmod) return impl_->cholmod.solve(b);
  return impl_->umfpack.solve(b);
}

}  // namespace arthrosim::cartilage
