// SparseDirectSolver: both factorisations solve a system they should, and
// repeated factorisations of one pattern reuse the process's memory instead
// of zero-filling fresh pages from the kernel each time (the walks' cost per
// Newton iteration, docs/contact.md "Cost of a Newton iteration").
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <Eigen/SparseCore>
#include <cstdio>
#include <vector>

#include "numerics/sparse_direct_solver.h"

namespace arthrosim::numerics {
namespace {

// Convection-diffusion on an n x n grid (5-point stencil, first-order upwind
// convection): non-symmetric, non-singular (diagonally dominant), with
// `skew` = 0 the SPD discrete Laplacian.
Eigen::SparseMatrix<double> grid_operator(int n, double skew) {
  std::vector<Eigen::Triplet<double>> t;
  auto id = [n](int i, int j) { return i * n + j; };
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      t.emplace_back(id(i, j), id(i, j), 4.0 + skew);
      if (i > 0) t.emplace_back(id(i, j), id(i - 1, j), -1.0 - skew);
      if (i + 1 < n) t.emplace_back(id(i, j), id(i + 1, j), -1.0);
      if (j > 0) t.emplace_back(id(i, j), id(i, j - 1), -1.0);
      if (j + 1 < n) t.emplace_back(id(i, j), id(i, j + 1), -1.0);
    }
  Eigen::SparseMatrix<double> A(n * n, n * n);
  A.setFromTriplets(t.begin(), t.end());
  A.makeCompressed();
  return A;
}

long minor_faults() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt;
}

double relative_residual(const Eigen::SparseMatrix<double>& A, const Eigen::VectorXd& x,
                         const Eigen::VectorXd& b) {
  return (A * x - b).norm() / b.norm();
}

TEST(SparseDirectSolver, CholmodAndUmfpackSolveTheirSystems) {
  const Eigen::SparseMatrix<double> L = grid_operator(40, 0.0);
  const Eigen::SparseMatrix<double> C = grid_operator(40, 0.5);
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(L.rows(), -1.0, 2.0);
  SparseDirectSolver chol(LinearSolverKind::kCholmod), lu(LinearSolverKind::kUmfpack);
  ASSERT_TRUE(chol.factorize(L)) << chol.message();
  ASSERT_TRUE(lu.factorize(C)) << lu.message();
  // Condition numbers are below 1e3 on this grid, so a backward-stable direct
  // solve leaves a relative residual of order 1e-16 x 1e3; 1e-10 is the margin.
  EXPECT_LT(relative_residual(L, chol.solve(b), b), 1e-10);
  EXPECT_LT(relative_residual(C, lu.solve(b), b), 1e-10);
  // CHOLMOD's LL^T refuses a matrix that is not positive definite, and says so.
  Eigen::SparseMatrix<double> N = L;
  N.coeffRef(0, 0) = -4.0;
  SparseDirectSolver chol_n(LinearSolverKind::kCholmod);
  EXPECT_FALSE(chol_n.factorize(N));
  EXPECT_NE(chol_n.message().find("not positive definite"), std::string::npos);
}

// A saddle-point matrix [K B^T; B 0] (symmetric, indefinite: the shape of a
// mixed displacement-pressure system), K the SPD grid Laplacian and B a
// full-rank constraint block: UMFPACK factorises it once and solves several
// right-hand sides, each to the residual of a backward-stable solve; CHOLMOD's
// LL^T refuses it.
TEST(SparseDirectSolver, UmfpackSolvesASymmetricIndefiniteSaddlePointSystemForManyRightHandSides) {
  const Eigen::SparseMatrix<double> K = grid_operator(20, 0.0);
  const int n = static_cast<int>(K.rows()), m = 30;
  std::vector<Eigen::Triplet<double>> t;
  for (int k = 0; k < K.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(K, k); it; ++it) t.emplace_back(it.row(), it.col(), it.value());
  for (int j = 0; j < m; ++j)
    for (int c = 0; c < 3; ++c) {
      const int col = (13 * j + 7 * c) % n;
      const double b = 1.0 + 0.1 * c;
      t.emplace_back(n + j, col, b);
      t.emplace_back(col, n + j, b);
    }
  Eigen::SparseMatrix<double> S(n + m, n + m);
  S.setFromTriplets(t.begin(), t.end());
  S.makeCompressed();
  SparseDirectSolver lu(LinearSolverKind::kUmfpack);
  ASSERT_TRUE(lu.factorize(S)) << lu.message();
  Eigen::MatrixXd B(n + m, 3);
  for (int j = 0; j < 3; ++j) B.col(j) = Eigen::VectorXd::LinSpaced(n + m, -1.0 - j, 2.0 + j);
  const Eigen::MatrixXd X = lu.solve_columns(B);
  for (int j = 0; j < 3; ++j) {
    // Same bound as above: condition number of order 1e3 here.
    EXPECT_LT(relative_residual(S, X.col(j), B.col(j)), 1e-10) << "column " << j;
    EXPECT_EQ(X.col(j), lu.solve(Eigen::VectorXd(B.col(j))));  // same solve, bit for bit
  }
  EXPECT_EQ(lu.num_analyses(), 1);
  SparseDirectSolver chol(LinearSolverKind::kCholmod);
  EXPECT_FALSE(chol.factorize(S));
}

// A 90,000-unknown non-symmetric operator: UMFPACK's numeric factors are
// tens of MB, the size of the walks' (42k shell unknowns with 6 per node).
// The first factorisation takes its memory from the kernel (page faults for
// every page it touches); the next ones must find it in the process. Without
// keeping freed memory (glibc's default: large blocks from mmap, the top of
// the heap trimmed), every factorisation would fault about as
// many pages as the first one. Bound: a repeat may fault at most 1/10 of the
// first's pages (with the setting removed, repeats fault as many pages as the
// first and the test fails).
TEST(SparseDirectSolver, RepeatedFactorisationsReuseTheirMemory) {
  const Eigen::SparseMatrix<double> A = grid_operator(300, 0.5);
  SparseDirectSolver lu(LinearSolverKind::kUmfpack);
  lu.analyze(A);
  long f0 = minor_faults();
  ASSERT_TRUE(lu.factorize(A)) << lu.message();
  const long first = minor_faults() - f0;
  long repeat_max = 0;
  for (int k = 0; k < 3; ++k) {
    f0 = minor_faults();
    ASSERT_TRUE(lu.factorize(A)) << lu.message();
    repeat_max = std::max(repeat_max, minor_faults() - f0);
  }
  std::printf("minor page faults: first factorisation %ld, largest of three repeats %ld\n", first,
              repeat_max);
  // The first factorisation must have touched enough memory for the check to
  // mean something (a factor well above glibc's 32 MB dynamic mmap ceiling
  // would be 8,000+ pages).
  EXPECT_GT(first, 8000);
  EXPECT_LT(repeat_max, first / 10);
}

}  // namespace
}  // namespace arthrosim::numerics
