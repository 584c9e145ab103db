// The sparse direct solves of a saved Newton matrix: why the surface stage
// factorises walking tangents with UMFPACK and not with CHOLMOD
// (docs/contact.md, "Cost of a Newton iteration").
//
// The matrix comes from a real run: ARTHROSIM_SAVE_TANGENT=N:FILE makes any
// program save the N-th matrix it factorises (cartilage/linear_solver.cc),
// and ARTHROSIM_FACTORIZATION_MATRIX=FILE points this benchmark at it:
//
//   build/bin/arthrosim run data/scenes/demo.yaml --out /tmp/fb
//       --set surface.scenarios.gait.end_time_s=0.1 --dry-run   # writes /tmp/fb/scene_set.yaml
//   (run the demo once for /tmp/demo/prepared.h5 and kinematics.h5, or use any earlier output)
//   ARTHROSIM_SAVE_TANGENT=60:/tmp/tangent.mtx build/bin/arthrosim-surface
//       --prepared /tmp/demo/prepared.h5 --kinematics /tmp/demo/kinematics.h5
//       --scene /tmp/fb/scene_set.yaml --scenario gait --out /tmp/fb/short.h5
//   ARTHROSIM_FACTORIZATION_MATRIX=/tmp/tangent.mtx build/bench/factorization_bench
//       --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
//
// Variants:
//   Umfpack                - the stage's solver: UMFPACK LU of the whole
//                            (non-symmetric) matrix, symbolic analysis once;
//                            counter rel_residual of one solve.
//   CholmodSymmetricPart/e - CHOLMOD supernodal LL^T of the symmetric part
//                            (A + A^T)/2 + sigma I with sigma = 10^e N/m
//                            (e = -1: no shift); counter positive_definite
//                            (1: it factorised). It would be the faster
//                            factorisation if the symmetric part were positive
//                            definite (then GMRES on A, preconditioned by it,
//                            would correct the small skew part).
//   SymmetricPartInertia   - Eigen's simplicial LDL^T of the symmetric part
//                            (AMD ordering, no pivoting), once: counters
//                            negative_pivots, skew_relative = |A - A^T|_F / (2 |A|_F),
//                            min_diagonal and max_diagonal [N/m].
#include <benchmark/benchmark.h>

#include <Eigen/SparseCholesky>
#include <unsupported/Eigen/SparseExtra>

#include <cmath>
#include <cstdlib>
#include <memory>
#include <string>

#include "numerics/sparse_direct_solver.h"

namespace {

using SpMat = Eigen::SparseMatrix<double>;

// The matrix of ARTHROSIM_FACTORIZATION_MATRIX (loaded once), or nullptr with
// the reason in *why.
const SpMat* saved_matrix(std::string* why) {
  static std::unique_ptr<SpMat> A;
  static std::string error;
  static bool tried = false;
  if (!tried) {
    tried = true;
    const char* path = std::getenv("ARTHROSIM_FACTORIZATION_MATRIX");
    if (!path) {
      error = "set ARTHROSIM_FACTORIZATION_MATRIX to a Matrix Market file (see the comment at the top of "
              "tests/benchmarks/factorization_bench.cc)";
    } else {
      A = std::make_unique<SpMat>();
      if (!Eigen::loadMarket(*A, path) || A->rows() == 0 || A->rows() != A->cols()) {
        error = std::string("could not read a square matrix from ") + path;
        A.reset();
      } else {
        A->makeCompressed();
      }
    }
  }
  *why = error;
  return A.get();
}

// The saved matrix, or nullptr after marking the benchmark skipped with the reason.
const SpMat* saved_matrix_or_skip(benchmark::State& state) {
  std::string why;
  const SpMat* A = saved_matrix(&why);
  if (!A) state.SkipWithError(why.c_str());
  return A;
}

SpMat symmetric_part(const SpMat& A) { return 0.5 * (A + SpMat(A.transpose())); }

void Umfpack(benchmark::State& state) {
  const SpMat* A = saved_matrix_or_skip(state);
  if (!A) return;
  arthrosim::numerics::SparseDirectSolver lu(arthrosim::numerics::LinearSolverKind::kUmfpack);
  lu.analyze(*A);
  bool ok = true;
  for (auto _ : state) ok = lu.factorize(*A) && ok;
  if (!ok) {
    state.SkipWithError(lu.message().c_str());
    return;
  }
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(A->rows(), -1, 1);
  state.counters["rel_residual"] = (*A * lu.solve(b) - b).norm() / b.norm();
  state.counters["unknowns"] = static_cast<double>(A->rows());
  state.counters["nonzeros"] = static_cast<double>(A->nonZeros());
}
BENCHMARK(Umfpack)->Unit(benchmark::kMillisecond)->UseRealTime();

void CholmodSymmetricPart(benchmark::State& state) {
  const SpMat* A = saved_matrix_or_skip(state);
  if (!A) return;
  SpMat S = symmetric_part(*A);
  const double sigma = state.range(0) < 0 ? 0.0 : std::pow(10.0, static_cast<double>(state.range(0)));
  for (int i = 0; i < S.rows(); ++i) S.coeffRef(i, i) += sigma;
  arthrosim::numerics::SparseDirectSolver llt(arthrosim::numerics::LinearSolverKind::kCholmod);
  llt.analyze(S);
  bool ok = true;
  for (auto _ : state) ok = llt.factorize(S);
  state.counters["positive_definite"] = ok ? 1 : 0;
  state.counters["shift_N_per_m"] = sigma;
}
BENCHMARK(CholmodSymmetricPart)->Arg(-1)->Arg(0)->Arg(2)->Arg(4)->Unit(benchmark::kMillisecond)->UseRealTime();

void SymmetricPartInertia(benchmark::State& state) {
  const SpMat* A = saved_matrix_or_skip(state);
  if (!A) return;
  const SpMat S = symmetric_part(*A);
  int negative = 0;
  bool ok = false;
  for (auto _ : state) {
    Eigen::SimplicialLDLT<SpMat> ldlt(S);
    ok = ldlt.info() == Eigen::Success;
    negative = 0;
    if (ok)
      for (Eigen::Index i = 0; i < ldlt.vectorD().size(); ++i) negative += ldlt.vectorD()(i) < 0;
  }
  if (!ok) {
    state.SkipWithError("simplicial LDL^T of the symmetric part failed (a zero pivot)");
    return;
  }
  state.counters["negative_pivots"] = negative;
  state.counters["skew_relative"] = (*A - SpMat(A->transpose())).norm() / (2 * A->norm());
  state.counters["min_diagonal"] = S.diagonal().minCoeff();
  state.counters["max_diagonal"] = S.diagonal().maxCoeff();
}
BENCHMARK(SymmetricPartInertia)->Iterations(1)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
