#pragma once
// Sparse direct solves through SuiteSparse, for any stage (pimpl: no
// SuiteSparse header is visible here, and only arthrosim_numerics links it).
//
//   kCholmod  CHOLMOD supernodal LL^T: symmetric positive definite matrices
//             (only the lower triangle is read);
//   kUmfpack  UMFPACK LU: any non-singular square matrix, including symmetric
//             indefinite ones (saddle-point systems such as a mixed
//             displacement-pressure (u-p) formulation, contact tangents).
//
// Usage: factor once, solve many times.
//
//   numerics::SparseDirectSolver lu(numerics::LinearSolverKind::kUmfpack);
//   if (!lu.factorize(A)) throw common::NumericalError(lu.message());
//   Eigen::VectorXd x = lu.solve(b);            // one right-hand side
//   Eigen::MatrixXd X = lu.solve_columns(B);    // several right-hand sides
//
// factorize() runs the symbolic analysis (fill-reducing ordering,
// elimination tree / supernodes) on its first call; it depends only on the
// sparsity pattern, so later factorisations of matrices with the same pattern
// reuse it (Newton iterations, time steps). For a new pattern construct a new
// solver (or call analyze() again). Matrices are Eigen::SparseMatrix<double>
// in compressed column form (call makeCompressed()); the solver keeps no
// reference to them.
//
// Process-wide settings made on first construction (both for bit-identical,
// fast repeated factorisations): the OpenBLAS under SuiteSparse is pinned to
// one thread, whose threaded kernels round differently from its serial ones,
// so results would depend on the core count; and glibc keeps freed memory in
// the process instead of returning it to the kernel, so a refactorisation
// reuses warm pages rather than zero-filling fresh ones (docs/contact.md,
// "Cost of a Newton iteration"). UMFPACK's iterative refinement is off: its
// callers are Newton iterations, which correct a solve's error in their next
// residual.
//
// Diagnostic: ARTHROSIM_SAVE_TANGENT=N:FILE saves the N-th matrix this process
// factorises (counted over every solver, from 1) to FILE in Matrix Market form
// (tests/benchmarks/factorization_bench.cc reads it).
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>

namespace arthrosim::numerics {

enum class LinearSolverKind {
  kCholmod,  ///< CHOLMOD supernodal Cholesky; requires SPD
  kUmfpack,  ///< UMFPACK LU; any non-singular matrix
};

/// "CHOLMOD supernodal LLT" or "UMFPACK LU".
const char* to_string(LinearSolverKind kind);

class SparseDirectSolver {
 public:
  explicit SparseDirectSolver(LinearSolverKind kind);
  ~SparseDirectSolver();
  SparseDirectSolver(const SparseDirectSolver&) = delete;
  SparseDirectSolver& operator=(const SparseDirectSolver&) = delete;

  LinearSolverKind kind() const { return kind_; }
  /// Symbolic analysis; call again only if the pattern changes.
  void analyze(const Eigen::SparseMatrix<double>& A);
  /// Numeric factorisation reusing the analysis (analyses first if there is
  /// none). Returns false (and sets message()) if it failed: not positive
  /// definite (CHOLMOD) or singular (UMFPACK). Never throws for that.
  bool factorize(const Eigen::SparseMatrix<double>& A);
  /// x = A^-1 b with the last successful factorisation.
  Eigen::VectorXd solve(const Eigen::VectorXd& b) const;
  /// X = A^-1 B, column by column, with the last successful factorisation.
  Eigen::MatrixXd solve_columns(const Eigen::MatrixXd& B) const;
  bool analyzed() const { return analyzed_; }
  int num_analyses() const { return num_analyses_; }
  /// Why the last factorize() failed ("" after a success).
  const std::string& message() const { return message_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  LinearSolverKind kind_;
  bool analyzed_ = false;
  int num_analyses_ = 0;
  std::string message_;
};

}  // namespace arthrosim::numerics
