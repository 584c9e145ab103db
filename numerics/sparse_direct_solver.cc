#include "numerics/sparse_direct_solver.h"

#include <Eigen/CholmodSupport>
#include <Eigen/UmfPackSupport>

#include <dlfcn.h>
#include <malloc.h>
#include <unsupported/Eigen/SparseExtra>

#include <atomic>
#include <cstdlib>
#include <mutex>
#include <string>

#include "common/error.h"
#include "common/log.h"

namespace arthrosim::numerics {

namespace {
// OpenBLAS's threaded kernels round differently from its serial ones (the
// same UMFPACK solve differs in its last bits between 1 and 2 threads), and
// the factorisation gains nothing measurable from a second thread, so the
// BLAS is pinned to one thread when the symbol exists; any other BLAS is left
// as it is.
void pin_blas_to_one_thread() {
  static std::once_flag once;
  std::call_once(once, [] {
    using SetThreads = void (*)(int);
    if (auto* set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))) set(1);
  });
}

// Every UMFPACK factorisation frees the previous numeric factors and
// allocates new ones (tens of MB for a walking tangent). glibc serves blocks
// that large with mmap and returns freed memory at the top of the heap to the
// kernel, so each factorisation would touch its factors in fresh zero-filled
// pages (millions of minor page faults per walk). Keeping freed memory in the
// process (blocks up to 1 GiB from the heap, no trimming) makes repeated
// factorisations faster with bit-identical results, at the price of a higher
// peak resident size (docs/contact.md, "Cost of a Newton iteration").
// Process-wide, set once, like the BLAS threads above; only glibc has mallopt.
void retain_freed_memory() {
#ifdef __GLIBC__
  static std::once_flag once;
  std::call_once(once, [] {
    mallopt(M_MMAP_THRESHOLD, 1 << 30);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
  });
#endif
}
// Diagnostic: ARTHROSIM_SAVE_TANGENT=N:FILE (see the header).
void save_matrix_if_asked(const Eigen::SparseMatrix<double>& A) {
  static const char* spec = std::getenv("ARTHROSIM_SAVE_TANGENT");
  if (!spec) return;
  static long wanted = -1;
  static std::string path;
  static std::once_flag once;
  std::call_once(once, [] {
    const std::string s(spec);
    const size_t colon = s.find(':');
    char* end = nullptr;
    const long n = colon == std::string::npos ? 0 : std::strtol(s.c_str(), &end, 10);
    if (colon == std::string::npos || end != s.c_str() + colon || n < 1 || colon + 1 >= s.size())
      throw common::InputError("ARTHROSIM_SAVE_TANGENT: expected N:FILE with N >= 1 (e.g. 60:/tmp/tangent.mtx), found '" +
                               s + "'");
    wanted = n;
    path = s.substr(colon + 1);
  });
  static std::atomic<long> count{0};
  if (++count != wanted) return;
  if (!Eigen::saveMarket(A, path))
    throw common::InputError("ARTHROSIM_SAVE_TANGENT: could not write " + path);
  common::log_info("saved factorisation " + std::to_string(wanted) + " (" + std::to_string(A.rows()) + " unknowns, " +
                   std::to_string(A.nonZeros()) + " non-zeros) to " + path);
}
}  // namespace

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
  pin_blas_to_one_thread();
  retain_freed_memory();
  // No iterative refinement in UMFPACK's solve: every caller is a Newton
  // iteration, which corrects the solve's error in its next residual, and
  // the default two refinement steps cost several solves each.
  impl_->umfpack.umfpackControl()(UMFPACK_IRSTEP) = 0;
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
  save_matrix_if_asked(A);
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

Eigen::MatrixXd SparseDirectSolver::solve_columns(const Eigen::MatrixXd& B) const {
  Eigen::MatrixXd X(B.rows(), B.cols());
  for (Eigen::Index j = 0; j < B.cols(); ++j) X.col(j) = solve(Eigen::VectorXd(B.col(j)));
  return X;
}

}  // namespace arthrosim::numerics
