#pragma once
// The interface the time integrator (hht_integrator.h) needs from a
// discretised model: generalised forces, inertia, tangents in a sparse
// pattern, constrained (eliminated) coordinates. It assumes nothing about how
// coordinates are grouped (dofs per node, fields): a coordinate is an index
// 0..num_dofs()-1, and describe_dof() names it for messages.
// Implemented by cartilage::ShellModel and cartilage::CoupledShellSystem (6
// coordinates per shell node), and in tests/numerics by a one-coordinate
// oscillator.
//
// Equations. F(q, v, t) collects every non-inertial term (internal forces,
// dampers, minus external loads); M a the inertial one. The integrator asks
// for F, M a, and the combined tangent
//     K = force_scale * (kq dF/dq + kv dF/dv) + ka M
// (HHT: force_scale = 1 + alpha, kv = gamma/(beta h), ka = 1/(beta h^2)).
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <string>
#include <vector>

namespace arthrosim::numerics {

struct EvalRequest {
  double t = 0;                          ///< time [s]
  const Eigen::VectorXd* q = nullptr;    ///< coordinates
  const Eigen::VectorXd* v = nullptr;    ///< velocities (nullptr: zero)
  const Eigen::VectorXd* a = nullptr;    ///< accelerations (nullptr: zero)
  double force_scale = 1.0;              ///< multiplies the F-part of the tangent
  double kq = 1.0, kv = 0.0, ka = 0.0;   ///< tangent factors (see file comment)
};

class TimeIntegrable {
 public:
  virtual ~TimeIntegrable() = default;
  virtual int num_dofs() const = 0;
  /// True when an inertia term exists (dynamic problem).
  virtual bool has_inertia() const = 0;
  /// True when every tangent is symmetric (CHOLMOD may then be used).
  virtual bool tangent_symmetric() const = 0;
  /// F (size n) and, when Ma != nullptr, M a; when K != nullptr, the tangent
  /// values in tangent_pattern()'s layout. Throws NumericalError naming the
  /// term and coordinate if a non-finite value appears.
  virtual void evaluate(const EvalRequest& request, Eigen::VectorXd& F, Eigen::VectorXd* Ma,
                        Eigen::SparseMatrix<double>* K) = 0;
  /// Compressed column pattern (values irrelevant) shared by every tangent.
  virtual const Eigen::SparseMatrix<double>& tangent_pattern() const = 0;
  /// Increases whenever tangent_pattern() changes (e.g. contact couples new
  /// nodes); an evaluation with a tangent may change it. The integrator then
  /// redoes its symbolic analysis. Fixed-pattern systems keep 0.
  virtual long pattern_revision() const { return 0; }
  /// 1 for coordinates fixed/prescribed by a constraint (eliminated), else 0.
  virtual const std::vector<char>& constrained() const = 0;
  /// Writes the prescribed values at time t into the constrained entries of q.
  virtual void apply_constraints(double t, Eigen::VectorXd& q) const = 0;
  /// Solves M a = rhs on the unconstrained coordinates (a = 0 on the others).
  virtual void solve_mass(const Eigen::VectorXd& rhs, Eigen::VectorXd& a) = 0;
  /// Per-coordinate weight turning an increment into the unit of the
  /// increment test (IntegratorOptions::increment_atol_m), e.g. 1 for
  /// positions in m, h/2 for a shell's transverse gradients, a length scale
  /// for a pressure coordinate.
  virtual const Eigen::VectorXd& increment_weights() const = 0;
  /// Predicts q at t1 from the converged q0 at t0 (the Newton start of a
  /// step, IntegratorOptions::predictor = kSystem). Default: q1 = q0.
  virtual void predict(double /*t0*/, double /*t1*/, const Eigen::VectorXd& q0, Eigen::VectorXd& q1) const { q1 = q0; }
  /// As predict, also given the state qp accepted at tp < t0 (the step
  /// before): IntegratorOptions::predictor = kSystemExtrapolated. Default:
  /// predict(t0, t1, q0, q1) (the previous state unused).
  virtual void predict_extrapolated(double tp, const Eigen::VectorXd& qp, double t0, const Eigen::VectorXd& q0,
                                    double t1, Eigen::VectorXd& q1) const {
    (void)tp;
    (void)qp;
    predict(t0, t1, q0, q1);
  }
  /// Human-readable name of coordinate i (for messages), e.g. "node 12 r_z".
  virtual std::string describe_dof(int i) const = 0;
};

}  // namespace arthrosim::numerics
