// NewtonSolver on small systems with known solutions: a coupled cubic system
// with a manufactured solution (quadratic convergence measured), a constrained
// coordinate that must keep its value, arctan (full Newton diverges from
// x0 = 2, the line search converges to the root 0), and failures that are
// reported with the coordinate, never thrown.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "common/error.h"
#include "numerics/newton.h"

namespace arthrosim::numerics {
namespace {

/// G(x) = A x + c x^3 - b (componentwise cube), A the tridiagonal SPD matrix
/// tridiag(-1, 3, -1); b from a chosen solution x*, so x* is the root.
class CubicChain final : public NewtonSystem {
 public:
  CubicChain(int n, double c) : constrained_(n, 0), n_(n), c_(c), w_(Eigen::VectorXd::Ones(n)) {
    std::vector<Eigen::Triplet<double>> t;
    for (int i = 0; i < n; ++i) {
      t.emplace_back(i, i, 3.0);
      if (i > 0) t.emplace_back(i, i - 1, -1.0);
      if (i + 1 < n) t.emplace_back(i, i + 1, -1.0);
    }
    A_.resize(n, n);
    A_.setFromTriplets(t.begin(), t.end());
    A_.makeCompressed();
    x_star_.resize(n);
    for (int i = 0; i < n; ++i) x_star_(i) = std::sin(0.7 * i + 0.3);
    b_ = A_ * x_star_ + c_ * x_star_.array().cube().matrix();
  }
  int size() const override { return n_; }
  void evaluate(const Eigen::VectorXd& x, Eigen::VectorXd& G, Eigen::SparseMatrix<double>* K) override {
    ++evaluations;
    G = A_ * x + c_ * x.array().cube().matrix() - b_;
    if (K) {
      ++tangents;
      *K = A_;
      for (int i = 0; i < n_; ++i) K->coeffRef(i, i) += 3 * c_ * x(i) * x(i);
    }
  }
  const Eigen::SparseMatrix<double>& tangent_pattern() const override { return A_; }
  bool tangent_symmetric() const override { return true; }
  const std::vector<char>& constrained() const override { return constrained_; }
  const Eigen::VectorXd& increment_weights() const override { return w_; }
  std::string describe_dof(int i) const override { return "x" + std::to_string(i); }

  const Eigen::VectorXd& solution() const { return x_star_; }
  std::vector<char> constrained_;
  int evaluations = 0, tangents = 0;

 private:
  int n_;
  double c_;
  Eigen::SparseMatrix<double> A_;
  Eigen::VectorXd x_star_, b_;
  Eigen::VectorXd w_;
};

/// G(x) = atan(x): root 0; Newton's map x - (1 + x^2) atan(x) diverges for
/// |x0| > 1.3917.
class Arctan final : public NewtonSystem {
 public:
  Arctan() : constrained_(1, 0), w_(Eigen::VectorXd::Ones(1)) {
    std::vector<Eigen::Triplet<double>> t{{0, 0, 0.0}};
    P_.resize(1, 1);
    P_.setFromTriplets(t.begin(), t.end());
    P_.makeCompressed();
  }
  int size() const override { return 1; }
  void evaluate(const Eigen::VectorXd& x, Eigen::VectorXd& G, Eigen::SparseMatrix<double>* K) override {
    G.resize(1);
    G(0) = std::atan(x(0));
    if (K) {
      *K = P_;
      K->valuePtr()[0] = 1.0 / (1.0 + x(0) * x(0));
    }
  }
  const Eigen::SparseMatrix<double>& tangent_pattern() const override { return P_; }
  bool tangent_symmetric() const override { return true; }
  const std::vector<char>& constrained() const override { return constrained_; }
  const Eigen::VectorXd& increment_weights() const override { return w_; }
  std::string describe_dof(int) const override { return "x"; }

 private:
  Eigen::SparseMatrix<double> P_;
  std::vector<char> constrained_;
  Eigen::VectorXd w_;
};

TEST(Newton, CubicChainConvergesQuadraticallyToTheManufacturedRoot) {
  CubicChain sys(40, 2.0);
  NewtonOptions o;
  o.residual_rtol = 1e-14;
  o.residual_atol = 1e-13;
  o.increment_rtol = 1e-14;
  o.increment_atol = 1e-15;
  NewtonSolver newton(sys, o);
  const Eigen::VectorXd x0 = Eigen::VectorXd::Zero(40);
  Eigen::VectorXd x = x0;
  const NewtonResult r = newton.solve(x, x0);
  ASSERT_TRUE(r.converged) << r.reason;
  // Root to round-off: |x - x*| ~ eps ||A^-1|| ||b|| (A's smallest eigenvalue
  // is 1, b is O(10)); 1e-12 leaves a factor ~50 for the cube's rounding.
  EXPECT_LT((x - sys.solution()).cwiseAbs().maxCoeff(), 1e-12);
  // Quadratic convergence: once in the basin (r_k < 1), r_{k+1} <= C r_k^2
  // with C of order |G''| |K^-1|^2 ~ 6 c |x| = 12; 100 leaves margin, and a
  // linearly converging method would break it within two steps.
  const auto& rn = r.residual_norms;
  int checked = 0;
  for (size_t k = 0; k + 1 < rn.size(); ++k)
    if (rn[k] < 1.0 && rn[k + 1] > 1e-12) {
      EXPECT_LT(rn[k + 1], 100 * rn[k] * rn[k]) << "iteration " << k;
      ++checked;
    }
  EXPECT_GE(checked, 2);
  EXPECT_EQ(newton.statistics().iterations, static_cast<long>(r.increment_norms.size()));
  EXPECT_EQ(newton.statistics().linear_solver, std::string("CHOLMOD supernodal LLT"));
}

TEST(Newton, ConstrainedCoordinateKeepsItsValueAndItsResidualIsIgnored) {
  CubicChain sys(10, 1.0);
  sys.constrained_[4] = 1;
  NewtonOptions o;
  o.residual_rtol = 1e-13;
  o.residual_atol = 1e-12;
  NewtonSolver newton(sys, o);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(10);
  x(4) = 0.25;  // prescribed, not the free root's value
  const NewtonResult r = newton.solve(x, Eigen::VectorXd::Zero(10));
  ASSERT_TRUE(r.converged) << r.reason;
  EXPECT_EQ(x(4), 0.25);
  // The other rows are satisfied with x(4) held.
  Eigen::VectorXd G;
  sys.evaluate(x, G, nullptr);
  G(4) = 0;
  EXPECT_LT(G.norm(), 1e-11);
}

TEST(Newton, LineSearchConvergesWhereFullStepsDiverge) {
  Arctan sys;
  NewtonOptions full;
  full.max_iterations = 20;
  NewtonSolver plain(sys, full);
  Eigen::VectorXd x = Eigen::VectorXd::Constant(1, 2.0);
  const NewtonResult diverged = plain.solve(x, Eigen::VectorXd::Zero(1));
  EXPECT_FALSE(diverged.converged);

  NewtonOptions ls = full;
  ls.line_search_halvings = 8;
  NewtonSolver searched(sys, ls);
  x = Eigen::VectorXd::Constant(1, 2.0);
  const NewtonResult r = searched.solve(x, Eigen::VectorXd::Zero(1));
  ASSERT_TRUE(r.converged) << r.reason;
  EXPECT_LT(std::abs(x(0)), 1e-9);
  EXPECT_GT(searched.statistics().line_search_reductions, 0);
  // Every accepted step decreased the residual (sufficient decrease).
  for (size_t k = 0; k + 1 < r.residual_norms.size(); ++k) EXPECT_LT(r.residual_norms[k + 1], r.residual_norms[k]);
}

TEST(Newton, FailureIsReportedWithTheWorstCoordinateNotThrown) {
  CubicChain sys(6, 1.0);
  NewtonOptions o;
  o.max_iterations = 1;
  o.residual_rtol = 1e-15;
  o.residual_atol = 0;
  o.increment_rtol = 0;
  o.increment_atol = 0;
  NewtonSolver newton(sys, o);
  Eigen::VectorXd x = Eigen::VectorXd::Constant(6, 5.0);
  const NewtonResult r = newton.solve(x, x);
  EXPECT_FALSE(r.converged);
  EXPECT_NE(r.reason.find("Newton did not converge in 1 iterations"), std::string::npos) << r.reason;
  EXPECT_NE(r.reason.find(" at x"), std::string::npos) << r.reason;
  EXPECT_EQ(r.residual_norms.size(), 2u);
  EXPECT_THROW(NewtonSolver(sys, NewtonOptions{.max_iterations = 0}), common::InputError);
}

TEST(Newton, ANumericalErrorOfTheSystemEndsTheSolveWithItsMessage) {
  class Throwing final : public NewtonSystem {
   public:
    Throwing() : c_(1, 0), w_(Eigen::VectorXd::Ones(1)) {
      std::vector<Eigen::Triplet<double>> t{{0, 0, 0.0}};
      P_.resize(1, 1);
      P_.setFromTriplets(t.begin(), t.end());
    }
    int size() const override { return 1; }
    void evaluate(const Eigen::VectorXd&, Eigen::VectorXd&, Eigen::SparseMatrix<double>*) override {
      throw common::NumericalError("term X: NaN at node 3");
    }
    const Eigen::SparseMatrix<double>& tangent_pattern() const override { return P_; }
    bool tangent_symmetric() const override { return true; }
    const std::vector<char>& constrained() const override { return c_; }
    const Eigen::VectorXd& increment_weights() const override { return w_; }
    std::string describe_dof(int) const override { return "x"; }

   private:
    Eigen::SparseMatrix<double> P_;
    std::vector<char> c_;
    Eigen::VectorXd w_;
  } sys;
  NewtonSolver newton(sys, NewtonOptions{});
  Eigen::VectorXd x = Eigen::VectorXd::Zero(1);
  const NewtonResult r = newton.solve(x, x);
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.reason, "term X: NaN at node 3");
}

}  // namespace
}  // namespace arthrosim::numerics
