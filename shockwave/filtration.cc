#include "shockwave/filtration.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <omp.h>

#include "shockwave/reduce.h"

namespace arthrosim::shockwave {

FiltrationTerm::FiltrationTerm(const Model& m, double dt, double safety) : model_(m), dt_(dt) {
  if (!(dt > 0.0) || !(safety > 0.0 && safety <= 1.0))
    throw std::invalid_argument("FiltrationTerm: expected dt > 0 and safety in (0, 1]");
  ntissue_ = static_cast<int>(m.tissues.size());
  a_.resize(ntissue_);
  biot_modulus_.resize(ntissue_);
  for (int t = 0; t < ntissue_; ++t) {
    a_[t] = m.constants[t].a;
    biot_modulus_[t] = m.constants[t].biot_modulus;
  }
  const double S = m.lattice.contact_area, d = m.lattice.diameter, V = m.lattice.cell_volume;
  const double eta = m.fluid.viscosity;
  conductance_.assign(static_cast<size_t>(ntissue_) * ntissue_, 0.0);
  pair_fast_.assign(conductance_.size(), 0);
  const int K = m.lattice.directions;
  for (int t1 = 0; t1 < ntissue_; ++t1)
    for (int t2 = 0; t2 < ntissue_; ++t2) {
      const TissueConstants &c1 = m.constants[t1], &c2 = m.constants[t2];
      if (!c1.poroelastic || !c2.poroelastic) continue;
      const double k1 = c1.permeability, k2 = c2.permeability;
      const double k = (k1 > 0.0 && k2 > 0.0) ? 2.0 * k1 * k2 / (k1 + k2) : 0.0;
      const double C = k * S / (eta * d);
      conductance_[t1 * ntissue_ + t2] = C;
      // Worst case for an automaton of either tissue with all K bonds of this pair.
      const double rate = std::max(c1.biot_modulus, c2.biot_modulus) * K * C / V;
      pair_fast_[t1 * ntissue_ + t2] = rate * dt > safety ? 1 : 0;
    }
  const int n = m.size();
  std::vector<double> fast_rate(n, 0.0);
  std::vector<std::uint8_t> in_fast(n, 0), drained(n, 0);
  for (int a : m.drained) drained[a] = 1;
  for (int i = 0; i < n; ++i) {
    const int ti = m.tissue[i];
    // Drained automata are reservoirs at P = 0: neighbours of the others,
    // never updated themselves.
    if (!m.constants[ti].poroelastic || drained[i]) continue;
    fluid_.push_back(i);
    double rate = 0.0, frate = 0.0;
    for (int s = 0; s < K; ++s) {
      const int j = m.neighbour(s, i);
      if (j < 0) continue;
      const int tj = m.tissue[j];
      const double C = conductance_[ti * ntissue_ + tj];
      if (C <= 0.0) continue;
      if (s < K / 2) ++bonds_;
      rate += C;
      if (pair_fast_[ti * ntissue_ + tj]) {
        frate += C;
        in_fast[i] = 1;
        if (s < K / 2) ++fast_bonds_;
      }
    }
    const double M = m.constants[ti].biot_modulus;
    max_rate_ = std::max(max_rate_, M * rate / V);
    fast_rate[i] = M * frate / V;
  }
  double max_fast = 0.0;
  std::vector<std::int32_t> local(n, -1);
  for (int i = 0; i < n; ++i)
    if (in_fast[i]) {
      local[i] = static_cast<std::int32_t>(fast_list_.size());
      fast_list_.push_back(i);
      max_fast = std::max(max_fast, fast_rate[i]);
    }
  // Compressed rows of the slow and the fast bonds; conductances by index
  // into the (few) distinct values of the tissue pairs.
  auto conductance_index = [this](double C) {
    for (size_t q = 0; q < ctab_.size(); ++q)
      if (ctab_[q] == C) return static_cast<std::uint8_t>(q);
    if (ctab_.size() >= 255) throw std::logic_error("FiltrationTerm: more than 255 conductances");
    ctab_.push_back(C);
    return static_cast<std::uint8_t>(ctab_.size() - 1);
  };
  slow_row_.push_back(0);
  for (int i : fluid_) {
    const int ti = m.tissue[i];
    for (int s = 0; s < K; ++s) {
      const int j = m.neighbour(s, i);
      if (j < 0) continue;
      const int tj = m.tissue[j];
      const double C = conductance_[ti * ntissue_ + tj];
      if (C <= 0.0 || pair_fast_[ti * ntissue_ + tj]) continue;
      slow_col_.push_back(j);
      slow_c_.push_back(conductance_index(C));
    }
    slow_row_.push_back(static_cast<std::int64_t>(slow_col_.size()));
  }
  fast_row_.push_back(0);
  for (int i : fast_list_) {
    const int ti = m.tissue[i];
    for (int s = 0; s < K; ++s) {
      const int j = m.neighbour(s, i);
      if (j < 0) continue;
      const int tj = m.tissue[j];
      const double C = conductance_[ti * ntissue_ + tj];
      if (C <= 0.0 || !pair_fast_[ti * ntissue_ + tj]) continue;
      // A drained neighbour is a reservoir at P = 0: the extra slot at the
      // end of fast_p_, which stays 0.
      if (local[j] < 0 && !drained[j]) throw std::logic_error("FiltrationTerm: a fast bond leaves the fast set");
      fast_col_.push_back(local[j] >= 0 ? local[j] : static_cast<std::int32_t>(fast_list_.size()));
      fast_c_.push_back(conductance_index(C));
    }
    fast_row_.push_back(static_cast<std::int64_t>(fast_col_.size()));
    fast_m_.push_back(m.constants[ti].biot_modulus);
    fast_a_.push_back(m.constants[ti].a);
    fast_tissue_.push_back(static_cast<std::uint8_t>(ti));
  }
  // Stages of the fast bonds (RKL2, filtration.h): stable for dt lambda_max
  // <= (s^2 + s - 2)/2, lambda_max of A = M/V L (L the fast bonds' weighted graph
  // Laplacian; A is self-adjoint in the 1/M-weighted product). lambda_max by
  // power iteration (deterministic start, 5 % margin for its approach from
  // below), never above Gershgorin's bound 2 max_i M_i sum_j C_ij / V (which
  // is 1.5 x lambda_max on an FCC lattice).
  if (!fast_list_.empty()) {
    const size_t nf = fast_list_.size();
    std::vector<double> x(nf + 1, 0.0), y(nf + 1, 0.0);
    for (size_t k = 0; k < nf; ++k) x[k] = 1.0 + 0.5 * std::sin(1.0 + 0.7 * static_cast<double>(k));
    double lambda = 0.0;
    for (int it = 0; it < 80; ++it) {
      double norm = 0.0, dot = 0.0, xx = 0.0;
      for (size_t k = 0; k < nf; ++k) {
        double sum = 0.0;
        for (std::int64_t q = fast_row_[k]; q < fast_row_[k + 1]; ++q) sum += ctab_[fast_c_[q]] * (x[k] - x[fast_col_[q]]);
        y[k] = fast_m_[k] / V * sum;
        dot += y[k] * x[k] / fast_m_[k];  // Rayleigh quotient in the 1/M-weighted product
        xx += x[k] * x[k] / fast_m_[k];
        norm += y[k] * y[k];
      }
      lambda = dot / xx;
      norm = std::sqrt(norm);
      if (!(norm > 0.0)) break;
      for (size_t k = 0; k < nf; ++k) x[k] = y[k] / norm;
    }
    fast_eigenvalue_ = lambda;
    const double bound = std::min(1.05 * lambda, 2.0 * max_fast);
    const double need = dt * bound / safety;
    substeps_ = 2;
    while (0.5 * (static_cast<double>(substeps_) * (substeps_ + 1) - 2.0) < need) ++substeps_;
  }
  p_.assign(n, 0.0);
  fast_ath_.assign(fast_list_.size(), 0.0);
  // One conductance for every fast bond (the knee: cancellous bone only):
  // the stages then read no conductance index.
  fast_uniform_ = !fast_c_.empty() && std::all_of(fast_c_.begin(), fast_c_.end(), [&](std::uint8_t q) { return q == fast_c_[0]; });
  {
    // The padded, slot-major copy of the slow bonds.
    const std::int64_t nfl = static_cast<std::int64_t>(fluid_.size());
    slow_slots_ = 0;
    for (std::int64_t k = 0; k < nfl; ++k)
      slow_slots_ = std::max(slow_slots_, static_cast<int>(slow_row_[k + 1] - slow_row_[k]));
    slow_ell_col_.assign(static_cast<size_t>(slow_slots_) * nfl, 0);
    slow_ell_c_.assign(static_cast<size_t>(slow_slots_) * nfl, 0);
    for (std::int64_t k = 0; k < nfl; ++k)
      for (int q = 0; q < slow_slots_; ++q) {
        const std::int64_t e = slow_row_[k] + q;
        const size_t at = static_cast<size_t>(q) * nfl + k;
        const bool real = e < slow_row_[k + 1];
        slow_ell_col_[at] = real ? slow_col_[e] : fluid_[k];
        slow_ell_c_[at] = real ? slow_c_[e] : 0;
      }
  }
  {
    // The padded, slot-major copy of the fast bonds (the stages' layout).
    const std::int64_t nf = static_cast<std::int64_t>(fast_list_.size());
    fast_slots_ = 0;
    for (std::int64_t k = 0; k < nf; ++k)
      fast_slots_ = std::max(fast_slots_, static_cast<int>(fast_row_[k + 1] - fast_row_[k]));
    fast_ell_col_.assign(static_cast<size_t>(fast_slots_) * nf, 0);
    fast_ell_c_.assign(fast_uniform_ ? 0 : static_cast<size_t>(fast_slots_) * nf, 0);
    for (std::int64_t k = 0; k < nf; ++k)
      for (int q = 0; q < fast_slots_; ++q) {
        const std::int64_t e = fast_row_[k] + q;
        const size_t at = static_cast<size_t>(q) * nf + k;
        const bool real = e < fast_row_[k + 1];
        fast_ell_col_[at] = real ? fast_col_[e] : static_cast<std::int32_t>(k);
        if (!fast_uniform_) fast_ell_c_[at] = real ? fast_c_[e] : 0;
      }
  }
  for (auto& y : fast_y_) y.assign(fast_list_.size(), 0.0);
  fast_y0_.assign(fast_list_.size(), 0.0);
  fast_l0_.assign(fast_list_.size(), 0.0);
  fast_pstart_.assign(fast_list_.size(), 0.0);
  for (auto& p : fast_p_) p.assign(fast_list_.size() + 1, 0.0);  // last: a drained neighbour (P = 0)
  dissip_.assign(n, 0.0);
}

namespace {

// The stage kernels are also compiled for AVX-512 and AVX2 (8 and 4 fast
// automata per vector), chosen at run time; every lane does the scalar
// operations of its automaton in the scalar order (no FMA contraction), so all
// variants give the same bits. GCC only, as in simulation.cc.
#if defined(__GNUC__) && !defined(__clang__)
#define FT_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define FT_CLONES
#endif

// One RKL2 stage (filtration.h) for the fast automata [k0, k1):
//   first:  L = L(Y_0) (kept in ly0), Y_1 = Y_0 + mut L;
//   else:   Y_j = mu Y_{j-1} + nu Y_{j-2} + rest Y_0 + mut L(Y_{j-1}) + gat L(Y_0);
// and the pressure M (Y_j - a theta). The flux sum runs over the padded slots
// in bond order; "no transfer where rho <= rho_0" as a select, not a branch
// (the signs of P change from bond to bond once the pore fluid moves).
struct Stage {
  std::int64_t k0, k1, nf;
  int slots;
  const std::int32_t* col;   // [slot * nf + k]
  const std::uint8_t* cidx;  // [slot * nf + k], null: every bond has cuniform
  const double* ctab;
  double cuniform;
  const double* p;  // pressure of Y_{j-1} (nf + 1 values: the last a drained reservoir at 0)
  const double* mt;
  const std::uint8_t* ft;
  const double* ath;
  bool first;
  double mu, nu, rest, mut, gat;
  const double *y0, *y1, *y2;
  double *ly0, *yn, *pn;
};

template <bool kUniform, bool kFirst>
inline __attribute__((always_inline)) void stage_loop(const Stage& a) {
  const std::int64_t nf = a.nf;
  const int slots = a.slots;
  const std::uint8_t* __restrict cidx = a.cidx;
  const double* __restrict ctab = a.ctab;
  const double cu = a.cuniform;
  const double* __restrict p = a.p;
  const double* __restrict mt = a.mt;
  const std::uint8_t* __restrict ft = a.ft;
  const double* __restrict ath = a.ath;
  const double* __restrict y0 = a.y0;
  const double* __restrict y1 = a.y1;
  const double* __restrict y2 = a.y2;
  double* __restrict ly0 = a.ly0;
  double* __restrict yn = a.yn;
  double* __restrict pn = a.pn;
  const double mu = a.mu, nu = a.nu, rest = a.rest, mut = a.mut, gat = a.gat;
  // Blocks of automata; their flux sums (slot by slot, each sum in slot order
  // from +0 as in the scalar loop) stay in L1.
  constexpr std::int64_t kBlock = 512;
  alignas(64) double fb[kBlock];
  alignas(64) std::int32_t qi[kBlock];
  for (std::int64_t kb = a.k0; kb < a.k1; kb += kBlock) {
    const std::int64_t len = std::min(kBlock, a.k1 - kb);
    for (std::int64_t l = 0; l < len; ++l) fb[l] = 0.0;
    const double* __restrict pb = p + kb;
    for (int s = 0; s < slots; ++s) {
      const std::int32_t* __restrict cs = a.col + s * nf + kb;
      if constexpr (!kUniform) {
        const std::uint8_t* __restrict qs = cidx + s * nf + kb;
        for (std::int64_t l = 0; l < len; ++l) qi[l] = qs[l];  // int indices: GCC gathers with those only
      }
#pragma omp simd
      for (std::int64_t l = 0; l < len; ++l) {
        const double pi = pb[l], pj = p[cs[l]];
        // No transfer where rho <= rho_0: max(P_i, P_j) <= 0.
        const double d = pj - pi;  // computed unconditionally: the select vectorises
        const double dp = std::max(pi, pj) > 0.0 ? d : 0.0;
        const double C = kUniform ? cu : ctab[qi[l]];
        fb[l] += C * dp;
      }
    }
#pragma omp simd
    for (std::int64_t l = 0; l < len; ++l) {
      const std::int64_t k = kb + l;
      const double f = fb[l];
      double v;
      if constexpr (kFirst) {
        ly0[k] = f;
        v = y0[k] + mut * f;
      } else {
        v = mu * y1[k] + nu * y2[k] + rest * y0[k] + mut * f + gat * ly0[k];
      }
      yn[k] = v;
      pn[k] = mt[ft[k]] * (v - ath[k]);
    }
  }
}

// The slow bonds of the fluid automata [k0, k1) (list: their indices): one
// forward Euler step of dt (h), zeta_i += dt/V sum C dP, from the pressures p
// of the old zeta; flux sums in slot order from +0 as the scalar loop did;
// `dis` (null: no bookkeeping) += h/2 sum C dP^2.
struct Slow {
  std::int64_t k0, k1, nf;
  int slots;
  const int* list;
  const std::int32_t* col;
  const std::uint8_t* cidx;
  const double* ctab;
  const double* p;
  double dtV, h;
  double* zeta;
  double* dis;
};

template <bool kTrack>
inline __attribute__((always_inline)) void slow_loop(const Slow& a) {
  const std::int64_t nf = a.nf;
  const int* __restrict list = a.list;
  const double* __restrict ctab = a.ctab;
  const double* __restrict p = a.p;
  double* __restrict zeta = a.zeta;
  double* __restrict dis = a.dis;
  const double dtV = a.dtV, h = a.h;
  constexpr std::int64_t kBlock = 512;
  alignas(64) double fb[kBlock];
  alignas(64) double eb[kBlock];
  alignas(64) std::int32_t qi[kBlock];
  for (std::int64_t kb = a.k0; kb < a.k1; kb += kBlock) {
    const std::int64_t len = std::min(kBlock, a.k1 - kb);
    for (std::int64_t l = 0; l < len; ++l) fb[l] = 0.0;
    if constexpr (kTrack)
      for (std::int64_t l = 0; l < len; ++l) eb[l] = 0.0;
    const int* __restrict lb = list + kb;
    for (int s = 0; s < a.slots; ++s) {
      const std::int32_t* __restrict cs = a.col + s * nf + kb;
      const std::uint8_t* __restrict qs = a.cidx + s * nf + kb;
      for (std::int64_t l = 0; l < len; ++l) qi[l] = qs[l];  // int indices: GCC gathers with those only
#pragma omp simd
      for (std::int64_t l = 0; l < len; ++l) {
        const double pi = p[lb[l]], pj = p[cs[l]];
        const double d = pj - pi;  // computed unconditionally: the select vectorises
        const double dp = std::max(pi, pj) > 0.0 ? d : 0.0;
        const double C = ctab[qi[l]];
        fb[l] += C * dp;
        if constexpr (kTrack) eb[l] += C * dp * dp;
      }
    }
    for (std::int64_t l = 0; l < len; ++l) {
      const int i = lb[l];
      zeta[i] += dtV * fb[l];
      if constexpr (kTrack) dis[i] += 0.5 * h * eb[l];  // each pair is seen from both sides
    }
  }
}

FT_CLONES void slow_pass(const Slow& a) {
  if (a.dis) slow_loop<true>(a);
  else slow_loop<false>(a);
}

FT_CLONES void fast_stage(const Stage& a) {
  if (a.cidx) {
    if (a.first) stage_loop<false, true>(a);
    else stage_loop<false, false>(a);
  } else {
    if (a.first) stage_loop<true, true>(a);
    else stage_loop<true, false>(a);
  }
}

}  // namespace

void FiltrationTerm::pressures(const std::vector<int>& list, const double* theta, const double* zeta) {
  const std::int64_t n = static_cast<std::int64_t>(list.size());
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (std::int64_t k = 0; k < n; ++k) {
    const int i = list[k];
    p_[i] = pressure(i, zeta[i], theta[i]);
  }
}

void FiltrationTerm::advance(const double* theta, double* zeta, double* dissipation, const double* pore) {
  const Model& m = model_;
  const double V = m.lattice.cell_volume;
  const bool track = dissipation != nullptr;
  if (track) std::fill(dissip_.begin(), dissip_.end(), 0.0);
  // Fluxes are Jacobi (all from the same pressures); "no transfer where
  // rho <= rho_0": a pair with both pressures <= 0 exchanges nothing (the
  // kernels slow_pass and fast_stage above).
  const double* ctab = ctab_.data();
  const double cuniform = fast_uniform_ ? ctab_[fast_c_[0]] : 0.0;
  // Slow bonds: one step of dt (the fluxes from the pressures of the old
  // zeta, so zeta can be updated in the same loop).
  if (!pore) pressures(fluid_, theta, zeta);
  const double* p = pore ? pore : p_.data();
  const std::int64_t nf = static_cast<std::int64_t>(fluid_.size());
  if (nf > 0) {
    Slow sl{};
    sl.nf = nf;
    sl.slots = slow_slots_;
    sl.list = fluid_.data();
    sl.col = slow_ell_col_.data();
    sl.cidx = slow_ell_c_.data();
    sl.ctab = ctab;
    sl.p = p;
    sl.dtV = dt_ / V;
    sl.h = dt_;
    sl.zeta = zeta;
    sl.dis = track ? dissip_.data() : nullptr;
#pragma omp parallel if (nf >= kParallelMin) firstprivate(sl)
    {
      const std::int64_t T = omp_get_num_threads(), th = omp_get_thread_num();
      sl.k0 = nf * th / T;
      sl.k1 = nf * (th + 1) / T;
      slow_pass(sl);
    }
  }
  // Fast bonds: one RKL2 step of s stages on a compact copy of the fast set
  // (filtration.h; one parallel region). Y_0 and L(Y_0) are kept; Y_j (j >= 1)
  // in fast_y_[j % 3], its pressure in fast_p_[j % 2] (Y_0's in fast_p_[0]).
  if (!fast_list_.empty()) {
    const int stages = substeps_;
    const double w1 = 4.0 / (static_cast<double>(stages) * (stages + 1) - 2.0);
    auto bcoef = [](int j) { return j <= 2 ? 1.0 / 3.0 : (j * j + j - 2.0) / (2.0 * j * (j + 1.0)); };
    const double tau_V = dt_ / V;
    const std::int64_t nfast = static_cast<std::int64_t>(fast_list_.size());
    double* y0 = fast_y0_.data();
    double* ly0 = fast_l0_.data();
    double* pstart = fast_pstart_.data();
    double* y[3] = {fast_y_[0].data(), fast_y_[1].data(), fast_y_[2].data()};
    double* pp[2] = {fast_p_[0].data(), fast_p_[1].data()};
    // M per tissue, a theta per fast automaton (the same products as
    // fast_m_[k] * (y - fast_a_[k] theta)).
    const double* mt = biot_modulus_.data();
    const std::uint8_t* ft = fast_tissue_.data();
    const double* fa = fast_a_.data();
    double* ath = fast_ath_.data();
    const std::uint8_t* fcond = fast_uniform_ ? nullptr : fast_c_.data();
#pragma omp parallel if (nfast >= kParallelMin)
    {
#pragma omp for schedule(static)
      for (std::int64_t k = 0; k < nfast; ++k) {
        const int i = fast_list_[k];
        y0[k] = zeta[i];
        ath[k] = fa[k] * theta[i];
        pp[0][k] = mt[ft[k]] * (y0[k] - ath[k]);
        pstart[k] = pp[0][k];
      }
      // This thread's share of the fast set (the static schedule of omp for).
      const std::int64_t T = omp_get_num_threads(), th = omp_get_thread_num();
      Stage st{};
      st.k0 = nfast * th / T;
      st.k1 = nfast * (th + 1) / T;
      st.nf = nfast;
      st.slots = fast_slots_;
      st.col = fast_ell_col_.data();
      st.cidx = fcond ? fast_ell_c_.data() : nullptr;
      st.ctab = ctab;
      st.cuniform = cuniform;
      st.mt = mt;
      st.ft = ft;
      st.ath = ath;
      st.y0 = y0;
      st.ly0 = ly0;
      // Stage 1: Y_1 = Y_0 + b_1 w_1 dt L(Y_0).
      st.first = true;
      st.mut = bcoef(1) * w1 * tau_V;
      st.p = pp[0];
      st.yn = y[1];
      st.pn = pp[1];
      fast_stage(st);
#pragma omp barrier
      // Y_j = mu_j Y_{j-1} + nu_j Y_{j-2} + (1 - mu_j - nu_j) Y_0
      //       + mu_j w_1 dt L(Y_{j-1}) - (1 - b_{j-1}) mu_j w_1 dt L(Y_0).
      st.first = false;
      for (int j = 2; j <= stages; ++j) {
        st.mu = (2.0 * j - 1.0) / j * bcoef(j) / bcoef(j - 1);
        st.nu = -(j - 1.0) / j * bcoef(j) / bcoef(j - 2);
        st.rest = 1.0 - st.mu - st.nu;
        st.mut = st.mu * w1 * tau_V;
        st.gat = -(1.0 - bcoef(j - 1)) * st.mu * w1 * tau_V;
        st.y1 = y[(j - 1) % 3];
        st.y2 = j == 2 ? y0 : y[(j - 2) % 3];
        st.yn = y[j % 3];
        st.p = pp[(j - 1) % 2];
        st.pn = pp[j % 2];
        fast_stage(st);
#pragma omp barrier
      }
      const double* ys = y[stages % 3];
      const double* ps = pp[stages % 2];
#pragma omp for schedule(static)
      for (std::int64_t k = 0; k < nfast; ++k) {
        const int i = fast_list_[k];
        // Dissipation (energy bookkeeping): the pore energy V P^2 / (2 M)
        // the step removed, exact for the discrete step.
        if (track) dissip_[i] += V * 0.5 * (pstart[k] + ps[k]) * (zeta[i] - ys[k]);
        zeta[i] = ys[k];
      }
    }
  }
  if (track) *dissipation += deterministic_sum(m.size(), [&](std::int64_t i) { return dissip_[i]; });
}

}  // namespace arthrosim::shockwave
