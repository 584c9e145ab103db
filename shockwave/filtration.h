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
// Explicit forward Euler, stable when dt * M_i sum_j C_ij / V_i <= 1 for all
// i (Gershgorin). Bonds whose tissue pair would break that bound at the
// mechanical step (cancellous bone: k = 1e-11 m^2) are sub-cycled with
// n = ceil(dt lambda_max / (2 safety)) steps, lambda_max the largest
// eigenvalue of their operator (power iteration); the others take one step of
// dt (multirate, each part stable on its own). The sum over i of V_i zeta_i is
// conserved to round-off (drained automata, model.drained, are reservoirs at
// P = 0 outside that sum).
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
  /// dissipates, dt * sum over pairs of C (P_i - P_j)^2 [J].
  void advance(const double* theta, double* zeta, double* dissipation);

  /// Pore pressure of automaton i for the given zeta, theta (0 if not poroelastic).
  double pressure(int i, double zeta, double theta) const {
    const int t = model_.tissue[i];
    return biot_modulus_[t] * (zeta - a_[t] * theta);
  }

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
  std::vector<double> fast_m_, fast_a_, fast_zeta_, fast_theta_, fast_p_;  ///< per fast automaton
  std::vector<double> p_;                ///< pore pressure scratch, per automaton
  std::vector<double> delta_;            ///< zeta increments, per fast automaton
  std::vector<double> slow_delta_;       ///< zeta increments, per poroelastic automaton
  std::vector<double> dissip_;           ///< per automaton (energy diagnostics)
};

}  // namespace arthrosim::shockwave
