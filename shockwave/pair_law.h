#pragma once
// The linear-elastic pair law of movable cellular automata in increments
// (seed Appendix A, eq. A7) with its third-law split (A8) and the Biot term
// (A9). Effect `mca_elastic` (and `pore_fluid` for the A9 term).
//
// Symbols (per pair i-j, R the automaton radius, n the unit vector i -> j):
//   sigma_ij  specific normal force (force per contact area), tension > 0;
//   tau_ij    specific tangential force on i (vector in the contact plane);
//   F_ij      = S (sigma_ij n + tau_ij), force on i from j (A3, S = contact area);
//   w_i       = R / (2 G_i), the compliance of automaton i's half of the pair.
//
// A7 (increments over one time step):
//   d sigma_ij = 2 G_i d eps_ij + D_i d sigma_mean_i,     d tau_ij = 2 G_i d gamma_ij
// A8 (Newton's third law: both halves carry the same force; their strains add
// up to the change of the pair distance / relative shear displacement):
//   d sigma_ij = d sigma_ji,  R d eps_ij + R d eps_ji = d r_ij
//   d tau_ij   = d tau_ji,    R d gamma_ij + R d gamma_ji = d l_ij
// Solved for the strains, with b_i = D_i d sigma_mean_i (+ the A9 pore term):
//   d sigma_ij = (d r_ij + (w_i b_i + w_j b_j)) / (w_i + w_j)
//   d tau_ij   = d l_ij / (w_i + w_j)
// The parenthesised sum is written symmetric in i and j so that both halves
// compute the same bits.
//
// The many-body coefficient D (A7). The seed prints D = 1 - 2G/K; the open
// MCA solver (LIGGGHTS-MCA, src/pair_mca.cpp) uses D = 1 - 2G/(3K). Only the
// second reproduces Hooke's law: summing A7 over the neighbours with the
// averaged stress of A4 gives sigma_mean = (2G/3) theta + D sigma_mean, i.e.
// sigma_mean = K theta exactly when 1 - D = 2G/(3K). The test
// tests/shockwave/mca_elastic_test.cc (EffectiveModuli) measures the
// lattice's E and nu under uniaxial compression with both forms; kHooke is
// the default and kSeedPrinted is kept only for that test.
//
// A9 (Biot): the pore pressure changes the normal law by
//   d sigma_ij = 2 G_i (d eps_ij - c a_i dP_i / K_i) + D_i d sigma_mean_i,
// with c = 1/3 for kHooke (then the averaged stress is Biot's total stress
// sigma = sigma' - a P I exactly) and c = 1 as printed in the seed (which is
// consistent only with the seed's D = 1 - 2G/K, both slips of a factor 3K).
#include <cmath>

namespace arthrosim::shockwave {

enum class DForm {
  kHooke,        ///< D = 1 - 2G/(3K) (LIGGGHTS-MCA; reproduces Hooke's law)
  kSeedPrinted,  ///< D = 1 - 2G/K (as printed in the seed's A7)
};

/// The many-body coefficient D of A7.
inline double many_body_coefficient(double G, double K, DForm form) {
  return form == DForm::kHooke ? 1.0 - 2.0 * G / (3.0 * K) : 1.0 - 2.0 * G / K;
}
/// The coefficient 2G c / K of a dP in A9 (c = 1/3 for kHooke, 1 as printed).
inline double pore_coefficient(double G, double K, DForm form) {
  return form == DForm::kHooke ? 2.0 * G / (3.0 * K) : 2.0 * G / K;
}

/// A8 solved for the normal specific-force increment.
inline double normal_increment(double dr, double wi, double bi, double wj, double bj) {
  return (dr + (wi * bi + wj * bj)) / (wi + wj);
}

}  // namespace arthrosim::shockwave
