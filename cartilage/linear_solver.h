#pragma once
// Sparse direct solves through SuiteSparse (pimpl: no SuiteSparse header is
// visible here). CHOLMOD (supernodal LL^T) for symmetric positive definite
// matrices, UMFPACK (LU) for general ones. The symbolic analysis (fill-reducing
// ordering, elimination tree / supernodes) depends only on the pattern, which
// is fixed for a model, so it is computed once and reused by every
// factorisation (Newton iterations and time steps).
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>

namespace arthrosim::cartilage {

enum class LinearSolverKind {
  kCholmod,  ///< CHOLMOD supernodal Cholesky; requires SPD
  kUmfpack,  ///< UMFPACK LU; any non-singular matrix
};

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
  /// Numeric factorisation reusing the analysis. Returns false (and sets
  /// message()) if it failed: not positive definite (CHOLMOD) or singular.
  bool factorize(const Eigen::SparseMatrix<double>& A);
  /// x = A^-1 b with the last successful factorisation.
  Eigen::VectorXd solve(const Eigen::VectorXd& b) const;
  bool analyzed() const { return analyzed_; }
  int num_analyses() const { return num_analyses_; }
  const std::string& message() const { return message_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  LinearSolverKind kind_;
  bool analyzed_ = false;
  int num_analyses_ = 0;
  std::string message_;
};

}  // namespace arthrosim::cartilage
