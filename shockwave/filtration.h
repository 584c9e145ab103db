#pragma once
// Darcy filtration of the pore fluid between neighbouring automata (seed
// Appendix A, eq. A11-A12), effect `filtration`.
//
// A11, phi d(rho)/dt = K_f div(k/eta grad rho), is discretised on the graph of
// bonded automata (the seed's "finite volume method on an ensemble of
// automata"), linearised about the reference fluid density rho_0 (|P| << K_f:
// rho = rho_0 (1 + P/K_f), A10). With zeta_i the fluid volume content of
// automaton i (fluid volume gained per automaton volume) the mass balance is
//   V_i d(zeta_i)/dt = sum_j C_ij (P_j - P_i),   C_ij = k_ij S / (eta d),
// k_ij = 2 k_i k_j / (k_i + k_j) (two half-distances in series), S the contact
// area, d the pair distance at rest. The pore pressure follows from Biot's
// constitutive law (A10 with the pore volume of the deforming skeleton):
//   P_i = M_i (zeta_i - a_i theta_i).
// "No mass transfer between the mesh nodes in which rho <= rho_0" (seed): the
// flux of a pair is zero when max(P_i, P_j) <= 0. Fluid passes only between
// two poroelastic automata (a > 0); every other face is impermeable.
// Permeability: the tissue's k, or k = phi d_ch^2 (A12).
//
// Explicit. Bonds whose tissue pair keeps forward Euler stable at the
// mechanical step (dt M_i sum_j C_ij / V_i <= safety, Gershgorin) take one
// forward Euler step of dt. The others (cancellous bone: k = 1e-11 m^2, ~40 x
// over that bound at d = 1 mm) take one step of the second-order
// Runge-Kutta-Legendre super-time-stepping scheme (RKL2; Meyer, Balsara and
// Aslam 2014, J. Comput. Phys. 257:594) with s stages (s flux evaluations):
//   Y_0 = zeta,  Y_1 = Y_0 + b_1 w_1 dt L(Y_0),
//   Y_j = mu_j Y_{j-1} + nu_j Y_{j-2} + (1 - mu_j - nu_j) Y_0
//         + mu_j w_1 dt L(Y_{j-1}) - (1 - b_{j-1}) mu_j w_1 dt L(Y_0)  (j = 2..s),
//   b_j = (j^2 + j - 2) / (2 j (j + 1)) (b_0 = b_1 = b_2 = 1/3),
//   mu_j = (2j - 1)/j b_j/b_{j-1}, nu_j = -(j - 1)/j b_j/b_{j-2},
//   w_1 = 4 / (s^2 + s - 2), zeta' = Y_s,
// L the fast bonds' flux (the no-transfer rule applied at every stage). Its
// amplification stays within [-1, 1] for dt lambda <= (s^2 + s - 2)/2: s is the
// smallest count >= 2 with (s^2 + s - 2)/2 >= dt lambda_max / safety,
// lambda_max the largest eigenvalue of the fast operator M/V L (power
// iteration, 5 % margin, capped by Gershgorin's bound): 9 stages at d = 1 mm,
// where forward Euler sub-cycling needs 20 sub-steps (29 with Gershgorin's
// bound), at the same accuracy (second order: 0.25 % per step on a mode with
// dt lambda_k = 0.33, Euler with 20 sub-steps 0.27 %;
// tests/shockwave/consolidation_test.cc). Every stage is an affine
// combination of Y's plus fluxes that cancel pairwise, so the sum over i of
// V_i zeta_i is conserved to round-off (drained automata, model.drained, are
// reservoirs at P = 0 outside that sum). The energy the flow dissipates
// (bookkeeping only): dt sum over pairs C (P_i - P_j)^2 for the slow bonds;
// for the fast ones the pore energy sum V P^2 / (2 M) the step removed, sum
// V (P + P')/2 (zeta - zeta') (exact for the discrete step; dt lambda >> 1
// there, so a quadrature of C dP^2 over the step would not do).
#include <cstdint>
#include <vector>

#include "shockwave/model.h"

namespace arthrosim::shockwave {

class FiltrationTerm {
 public:
  /// `dt` the mechanical time step [s]; `safety` in (0, 1].
  FiltrationTerm(const Model& model, double dt, double safety = 0.9);

  /// Advances zeta over one mechanical step with theta held fixed.
  /// `dissipation`, if not null, is increased by the energy the flow
  /// dissipates, dt * sum over pairs of C (P_i - P_j)^2 [J]. `pore`, if not
  /// null, holds every automaton's pore pressure for this zeta and theta
  /// (pressure(); 0 where not poroelastic or drained), which the step then
  /// does not recompute.
  void advance(const double* theta, double* zeta, double* dissipation, const double* pore = nullptr);

  /// Pore pressure of automaton i for the given zeta, theta (0 if not poroelastic).
  double pressure(int i, double zeta, double theta) const {
    const int t = model_.tissue[i];
    return biot_modulus_[t] * (zeta - a_[t] * theta);
  }

  /// Flux evaluations of the fast bonds per step (RKL2 stages s; 1 without
  /// fast bonds).
  int substeps() const { return substeps_; }
  std::int64_t bonds() const { return bonds_; }          ///< permeable pairs
  std::int64_t fast_bonds() const { return fast_bonds_; }
  std::int64_t fast_automata() const { return static_cast<std::int64_t>(fast_list_.size()); }
  /// The largest rate M sum C / V over all automata [1/s] (stability).
  double max_rate() const { return max_rate_; }
  /// lambda_max of the fast bonds' operator M/V L by power iteration, the
  /// estimate the sub-step count is taken from [1/s] (0 without fast bonds).
  double fast_eigenvalue() const { return fast_eigenvalue_; }

 private:
  void pressures(const std::vector<int>& list, const double* theta, const double* zeta);
  const Model& model_;
  double dt_;
  int substeps_ = 1;
  std::int64_t bonds_ = 0, fast_bonds_ = 0;
  double max_rate_ = 0.0, fast_eigenvalue_ = 0.0;
  int ntissue_ = 0;
  std::vector<double> a_, biot_modulus_;
  std::vector<double> conductance_;  ///< [t1 * ntissue + t2], 0 = impermeable
  std::vector<std::uint8_t> pair_fast_;  ///< per tissue pair: sub-cycled
  std::vector<int> fluid_;               ///< poroelastic automata (not drained)
  std::vector<int> fast_list_;           ///< automata with at least one sub-cycled bond
  // Bonds as compressed rows: slow bonds per fluid automaton (neighbour
  // automaton index), fast bonds per fast automaton (neighbour's index in
  // fast_list_); each with its conductance C (an index into ctab_).
  std::vector<std::int64_t> slow_row_, fast_row_;
  std::vector<std::int32_t> slow_col_, fast_col_;
  std::vector<std::uint8_t> slow_c_, fast_c_;  ///< index into ctab_
  std::vector<double> ctab_;
  // The fast bonds again, padded to fast_slots_ per automaton and stored slot
  // by slot ([slot * fast automata + k]) for the stages' vector loops; a
  // padding slot names the automaton itself (a zero pressure difference, a
  // flux of +0 that leaves the sum's bits unchanged).
  // The slow bonds in the same layout ([slot * fluid automata + k], neighbour
  // automaton index, padding: the automaton itself).
  int slow_slots_ = 0;
  std::vector<std::int32_t> slow_ell_col_;
  std::vector<std::uint8_t> slow_ell_c_;
  int fast_slots_ = 0;
  std::vector<std::int32_t> fast_ell_col_;
  std::vector<std::uint8_t> fast_ell_c_;  ///< index into ctab_ (empty when fast_uniform_)
  std::vector<double> fast_m_, fast_a_, fast_ath_;  ///< per fast automaton (fast_ath_: a theta of the step)
  std::vector<std::uint8_t> fast_tissue_;           ///< per fast automaton
  bool fast_uniform_ = false;                       ///< every fast bond has the conductance ctab_[fast_c_[0]]
  std::vector<double> fast_y0_, fast_l0_, fast_pstart_;  ///< RKL2: Y_0, L(Y_0), P(Y_0)
  std::vector<double> fast_y_[3], fast_p_[2];          ///< stages (Y_j in [j % 3]), their pressures
  std::vector<double> p_;                ///< pore pressure scratch, per automaton
  std::vector<double> dissip_;           ///< per automaton (energy diagnostics)
};

}  // namespace arthrosim::shockwave
