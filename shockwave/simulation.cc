#include "shockwave/simulation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <omp.h>

#include "common/error.h"
#include "common/finite.h"
#include "shockwave/reduce.h"

namespace arthrosim::shockwave {

namespace {
inline double wrap(double d, double period, double inv_period) {
  return period > 0.0 ? d - period * std::nearbyint(d * inv_period) : d;
}
}  // namespace

double free_surface_factor(const Model& model, int i, bool undrained, bool loaded) {
  const int K = model.lattice.directions;
  Eigen::Matrix3d T = Eigen::Matrix3d::Zero();
  common::Vec3 sum = common::Vec3::Zero();
  int missing = 0;
  for (int s = 0; s < K; ++s) {
    if (model.neighbour(s, i) >= 0) continue;
    const common::Vec3& n = model.lattice.unit[s];
    T += n * n.transpose();
    sum += n;
    ++missing;
  }
  if (missing == 0) return 1.0;
  const int t = model.tissue[i];
  const Tissue& ts = model.tissues[t];
  const double G = ts.shear_modulus;
  const double Kb = undrained ? model.constants[t].undrained_bulk : ts.bulk_modulus;
  const double lambda = Kb - 2.0 * G / 3.0;
  const double c = 3.0 / K;  // S q / V per pair
  // Fallback (no mean outward direction, or a degenerate result): every
  // missing pair traction-free, as in LIGGGHTS-MCA's mean stress predictor.
  const double D = 3.0 * lambda / (3.0 * lambda + 2.0 * G);
  const double fallback = (D > 0.0 && D < 1.0) ? 1.0 / (1.0 + static_cast<double>(missing) / K * D / (1.0 - D)) : 1.0;
  if (sum.norm() < 1e-9) return fallback;
  const common::Vec3 e = sum.normalized();
  if (loaded) {
    // A face pressed by a load: uniaxial strain along its normal (a plane
    // wave entering), eps = beta e e^T: theta_e = beta (1 - c e.T.e).
    const double x = 1.0 - c * e.dot(T * e);
    return x > 0.1 ? 1.0 / x : fallback;
  }
  const double alpha = 1.0, beta = -2.0 * lambda * alpha / (lambda + 2.0 * G);
  const double theta = 2.0 * alpha + beta;
  const double eTe = e.dot(T * e);
  const double theta_e = theta - c * (alpha * (T.trace() - eTe) + beta * eTe);
  const double f = theta / theta_e;
  if (!(theta > 0.0 && theta_e > 0.0 && f > 0.0 && f < 10.0)) return fallback;
  return f;
}

Simulation::Simulation(const Model& model, const SimulationOptions& options, std::function<double(double)> load)
    : model_(model), options_(options), load_(std::move(load)) {
  const std::string src = "shockwave simulation";
  if (!(options.time_step_safety > 0.0 && options.time_step_safety <= 1.0))
    throw common::InputError(src, 0, "expected a time step safety in (0, 1], found " + std::to_string(options.time_step_safety));
  if (!(options.damping >= 0.0))
    throw common::InputError(src, 0, "expected a damping >= 0 1/s, found " + std::to_string(options.damping));
  if (options.filtration && !options.pore_fluid)
    throw common::InputError(src, 0, "expected pore_fluid with filtration (Darcy flow needs the pore pressure)");
  n_ = model.size();
  K_ = model.lattice.directions;
  if (n_ == 0) throw common::InputError(src, 0, "expected at least one automaton, found none");
  period_ = model.period();
  periodic_ = period_.x() > 0.0 || period_.y() > 0.0 || period_.z() > 0.0;

  // Tissue tables.
  const int nt = static_cast<int>(model.tissues.size());
  const std::vector<std::int64_t> counts = model.tissue_counts();
  bool any_poro = false;
  for (int t = 0; t < nt; ++t) any_poro |= counts[t] > 0 && model.constants[t].poroelastic;
  fluid_on_ = options.pore_fluid && any_poro;
  const double R = model.lattice.radius, V = model.lattice.cell_volume;
  for (int t = 0; t < nt; ++t) {
    const Tissue& ts = model.tissues[t];
    const TissueConstants& c = model.constants[t];
    const bool poro = fluid_on_ && c.poroelastic;
    w_.push_back(R / (2.0 * ts.shear_modulus));
    D_.push_back(many_body_coefficient(ts.shear_modulus, ts.bulk_modulus, options.d_form));
    K_bulk_.push_back(ts.bulk_modulus);
    a_.push_back(poro ? c.a : 0.0);
    M_.push_back(poro ? c.biot_modulus : 0.0);
    pore_coef_.push_back(pore_coefficient(ts.shear_modulus, ts.bulk_modulus, options.d_form));
    inv3G_.push_back(1.0 / (3.0 * ts.shear_modulus));
    const double m = c.total_density * V;
    mass_.push_back(m);
    inv_mass_.push_back(1.0 / m);
    inv_inertia_.push_back(1.0 / (0.4 * m * R * R));
    poro_.push_back(poro ? 1 : 0);
    if (counts[t] > 0) {
      const double cp = poro ? c.undrained_p_speed : c.drained_p_speed;
      if (cp > c_max_) {
        c_max_ = cp;
        c_max_tissue_ = ts.name;
      }
    }
  }
  if (options.fixed_time_step > 0.0) {
    dt_ = options.fixed_time_step;
    if (!options.skip_stability_check) {
      dt_crit_ = shockwave::critical_time_step(model, options, &dt_crit_tissue_);
      if (dt_ > dt_crit_)
        throw common::InputError(src, 0, "expected a time step <= the stability limit " + std::to_string(dt_crit_) +
                                             " s (" + dt_crit_tissue_ + "), found " + std::to_string(dt_));
    }
  } else {
    dt_crit_ = shockwave::critical_time_step(model, options, &dt_crit_tissue_);
    dt_ = options.time_step_safety * dt_crit_;
  }
  if (!(options.damping * dt_ <= 0.5))
    throw common::InputError(src, 0, "expected damping * dt <= 0.5, found " + std::to_string(options.damping * dt_));

  wa_.resize(n_);
  inv3G_a_.resize(n_);
  inv_mass_a_.resize(n_);
  inv_inertia_a_.resize(n_);
  for (int i = 0; i < n_; ++i) {
    const int t = model.tissue[i];
    wa_[i] = w_[t];
    inv3G_a_[i] = inv3G_[t];
    inv_mass_a_[i] = inv_mass_[t];
    inv_inertia_a_[i] = inv_inertia_[t];
  }
  strain_scale_.resize(n_);
  for (int i = 0; i < n_; ++i)
    strain_scale_[i] = model.neighbour_count[i] > 0 ? 3.0 / model.neighbour_count[i] : 0.0;
  // Free-surface factor of the volumetric strain (see simulation.h).
  f_.resize(n_);
  {
    std::vector<char> loaded(n_, 0);
    for (int a : model.loaded.automata)
      if (a >= 0 && a < n_) loaded[a] = 1;
    for (int i = 0; i < n_; ++i) f_[i] = free_surface_factor(model, i, poro_[model.tissue[i]] != 0, loaded[i] != 0);
  }
  constraint_of_.assign(n_, -1);
  for (size_t k = 0; k < model.constraints.size(); ++k) {
    const int a = model.constraints[k].automaton;
    if (a < 0 || a >= n_) throw common::InputError(src, 0, "constraint on a non-existent automaton " + std::to_string(a));
    constraint_of_[a] = static_cast<std::int32_t>(k);
  }
  constraint_force_.assign(model.constraints.size(), common::Vec3::Zero());
  if (load_) {
    std::vector<char> seen(n_, 0);
    for (size_t k = 0; k < model.loaded.automata.size(); ++k) {
      const int a = model.loaded.automata[k];
      if (a < 0 || a >= n_) throw common::InputError(src, 0, "load on a non-existent automaton " + std::to_string(a));
      if (seen[a]++) throw common::InputError(src, 0, "automaton " + std::to_string(a) + " loaded twice");
      if (!(model.loaded.area[k].norm() > 0.0)) throw common::InputError(src, 0, "a loaded automaton with zero area");
    }
    loaded_peaks_.assign(2 * model.loaded.automata.size(), 0.0);
  }
  build_rows();
  {
    // Loaded automata and constraints by row (step_rows).
    std::vector<std::int32_t> row_of(n_);
    for (size_t r = 0; r < rows_.size(); ++r)
      for (int i = rows_[r].start; i < rows_[r].start + rows_[r].len; ++i) row_of[i] = static_cast<std::int32_t>(r);
    auto by_row = [&](const std::vector<int>& automata, std::vector<std::int32_t>& start, std::vector<std::int32_t>& list) {
      start.assign(rows_.size() + 1, 0);
      for (int a : automata) ++start[row_of[a] + 1];
      for (size_t r = 0; r < rows_.size(); ++r) start[r + 1] += start[r];
      list.assign(automata.size(), 0);
      std::vector<std::int32_t> fill(start.begin(), start.end() - 1);
      for (size_t k = 0; k < automata.size(); ++k) list[fill[row_of[automata[k]]]++] = static_cast<std::int32_t>(k);
    };
    by_row(load_ ? model.loaded.automata : std::vector<int>{}, row_loaded_start_, row_loaded_);
    std::vector<int> constrained;
    for (const VelocityConstraint& con : model.constraints) constrained.push_back(con.automaton);
    by_row(constrained, row_constraint_start_, row_constraint_);
  }
  drained_.assign(n_, 0);
  for (int a : model.drained) {
    if (a < 0 || a >= n_) throw common::InputError(src, 0, "drained boundary on a non-existent automaton " + std::to_string(a));
    drained_[a] = 1;
  }
  for (int b = 0; b < 2; ++b)
    for (int a = 0; a < 3; ++a) {
      pos_[b][a].assign(n_, 0.0);
      vel_[b][a].assign(n_, 0.0);
      omg_[b][a].assign(n_, 0.0);
    }
  for (int i = 0; i < n_; ++i) {
    pos_[0][0][i] = model.x[i];
    pos_[0][1][i] = model.y[i];
    pos_[0][2][i] = model.z[i];
  }
  pos_[1][0] = pos_[0][0];
  pos_[1][1] = pos_[0][1];
  pos_[1][2] = pos_[0][2];
  const size_t nb = static_cast<size_t>(K_ / 2) * n_;
  sn_.assign(nb, 0.0);
  tx_.assign(nb, 0.0);
  ty_.assign(nb, 0.0);
  tz_.assign(nb, 0.0);
  theta_.assign(n_, 0.0);
  b_.assign(n_, 0.0);
  pore_.assign(n_, 0.0);
  if (fluid_on_) zeta_.assign(n_, 0.0);
  pressure_.assign(n_, 0.0);
  distortional_.assign(n_, 0.0);
  peak_pressure_.assign(n_, 0.0);
  peak_distortional_.assign(n_, 0.0);
  peak_pore_.assign(n_, 0.0);
  kinetic_.assign(n_, 0.0);
  work_.assign(n_, 0.0);
  damp_.assign(n_, 0.0);
  if (fluid_on_ && options.filtration)
    filtration_ = std::make_unique<FiltrationTerm>(model, dt_, options.filtration_safety);
}

Simulation::~Simulation() = default;

void Simulation::set_velocity(int i, const common::Vec3& v) {
  for (int a = 0; a < 3; ++a) vel_[cur_][a][i] = v[a];
}
void Simulation::set_angular_velocity(int i, const common::Vec3& w) {
  for (int a = 0; a < 3; ++a) omg_[cur_][a][i] = w[a];
}

// ---------------------------------------------------------------------------
// The three passes work on lattice rows (consecutive automata with the same
// grid j, k). Along a row the neighbour in a given direction is, for most
// automata, at a constant index offset (Run): those pair halves are computed
// in `omp simd` loops with contiguous loads; the rest of the row (row ends,
// holes, periodic models) takes the general path through the neighbour table.
// Both paths do the same floating-point operations in the same order (no FMA
// contraction, -ffp-contract=off), so the results do not depend on which path
// or vector width computed them. Every automaton accumulates its pair halves
// in direction order.

#define SW_INLINE inline __attribute__((always_inline))
// The row kernels are also compiled for AVX-512 and AVX2 (8 and 4 doubles per
// vector) and the variant is chosen at run time; without FMA contraction all
// give the same bits. GCC only: clang 14 (the sanitizer build) cannot resolve
// target_clones on member function templates, and there one variant suffices.
#if defined(__GNUC__) && !defined(__clang__)
#define SW_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define SW_CLONES
#endif

namespace {

// Pair geometry in the owner's frame from d = x_other - x_owner: the unit
// vector n, the distance r and the lever arm q of the contact point.
//  - geometrically nonlinear (Geometry::kNonlinear): the current direction,
//    r = |d|, q = r/2 (the MCA form of the seed: large rotations exact);
//  - small strain (Geometry::kLinear): n the pair's rest direction u, r = u . d
//    (the rest distance plus the normal displacement), q = d0/2. The forces
//    then follow from a quadratic energy and carry no geometric stiffness:
//    a large pressure carried by the pairs (the pore fluid of a nearly
//    incompressible tissue) cannot buckle the lattice (simulation.h).
template <bool kLinear>
struct PairGeo {
  double nx, ny, nz, r, inv_r, q;
};
template <bool kLinear>
SW_INLINE PairGeo<kLinear> pair_geometry(double dx, double dy, double dz, double ux, double uy, double uz, double d0) {
  PairGeo<kLinear> g;
  if constexpr (kLinear) {
    g.nx = ux;
    g.ny = uy;
    g.nz = uz;
    g.r = ux * dx + uy * dy + uz * dz;
    g.inv_r = 1.0;  // unused
    g.q = 0.5 * d0;
  } else {
    g.r = std::sqrt(dx * dx + dy * dy + dz * dz);
    g.inv_r = 1.0 / g.r;
    g.nx = dx * g.inv_r;
    g.ny = dy * g.inv_r;
    g.nz = dz * g.inv_r;
    g.q = 0.5 * g.r;
  }
  return g;
}

// d r of a pair (A8's distance increment) times i's share w_i / (w_i + w_j).
template <bool kLinear>
SW_INLINE double predictor_side(double dx, double dy, double dz, double dvx, double dvy, double dvz, double wi,
                                double wj, double dt, double ux, double uy, double uz) {
  double dr;
  if constexpr (kLinear) {
    dr = (ux * dvx + uy * dvy + uz * dvz) * dt;
  } else {
    const double inv_r = 1.0 / std::sqrt(dx * dx + dy * dy + dz * dz);
    dr = (dx * dvx + dy * dvy + dz * dvz) * inv_r * dt;
  }
  return dr * (wi / (wi + wj));
}

struct PairIn {
  double dvx, dvy, dvz;  // v_other - v_owner (half step)
  double osx, osy, osz;  // omega_owner + omega_other
  double wo, wt, bo, bt;
  double sn, tx, ty, tz;  // old pair state
};
struct PairOut {
  double sn, tx, ty, tz;                    // new pair state
  double fx, fy, fz, mx, my, mz;            // force on the owner, moment (both)
  double tr;                                // q n . F, the trace of A4's q n (x) F (both)
  double e11, e22, e33, e12, e23, e13;      // sym(g (x) n), g the pair's strain vector (both)
};

// The pair's strain vector g = e_n n + l / d: normal strain (r - d)/d and the
// accumulated relative shear displacement l = tau (w_o + w_t) over the rest
// length d; for a homogeneous strain eps, g = eps n, and
// (3/K) sum_j sym(g_j (x) n_j) = eps (the averaged strain, simulation.h).
// Each automaton takes its own share 2 w_i / (w_i + w_j) of it (A8's split
// by compliance: 1 between equal tissues, ~0 for bone next to soft tissue).
SW_INLINE void pair_strain(PairOut& out, double r, double nx, double ny, double nz, double tX, double tY, double tZ,
                           double wsum, double inv_d) {
  const double en = (r * inv_d - 1.0);
  const double gx = en * nx + tX * wsum * inv_d, gy = en * ny + tY * wsum * inv_d, gz = en * nz + tZ * wsum * inv_d;
  out.e11 = gx * nx;
  out.e22 = gy * ny;
  out.e33 = gz * nz;
  out.e12 = 0.5 * (gx * ny + gy * nx);
  out.e23 = 0.5 * (gy * nz + gz * ny);
  out.e13 = 0.5 * (gx * nz + gz * nx);
}

// Force, moment, A4 term and strain of a pair from its (new) state.
template <bool kLinear>
SW_INLINE void pair_loads(PairOut& out, const PairGeo<kLinear>& g, double sig, double tX, double tY, double tZ, double S,
                          double wsum, double inv_d) {
  const double nx = g.nx, ny = g.ny, nz = g.nz, q = g.q;
  // A3: force on the owner; A1: moment q n x F^tau, the same on both;
  // A4: q n (x) F, the same for both automata.
  out.fx = S * (sig * nx + tX);
  out.fy = S * (sig * ny + tY);
  out.fz = S * (sig * nz + tZ);
  const double qS = q * S;
  out.mx = qS * (ny * tZ - nz * tY);
  out.my = qS * (nz * tX - nx * tZ);
  out.mz = qS * (nx * tY - ny * tX);
  out.tr = q * (nx * out.fx + ny * out.fy + nz * out.fz);
  pair_strain(out, g.r, nx, ny, nz, tX, tY, tZ, wsum, inv_d);
}

// A7-A8 for one pair in its owner's frame.
template <bool kLinear>
SW_INLINE PairOut pair_update(const PairIn& in, const PairGeo<kLinear>& g, double dx, double dy, double dz, double S,
                              double dt, double inv_d) {
  PairOut out;
  const double nx = g.nx, ny = g.ny, nz = g.nz, q = g.q;
  double dr;
  if constexpr (kLinear) {
    dr = (nx * in.dvx + ny * in.dvy + nz * in.dvz) * dt;
  } else {
    dr = (dx * in.dvx + dy * in.dvy + dz * in.dvz) * g.inv_r * dt;
  }
  const double inv_w = 1.0 / (in.wo + in.wt);
  // A8: normal specific force.
  const double sig = in.sn + (dr + (in.wo * in.bo + in.wt * in.bt)) * inv_w;
  // Relative shear displacement at the contact point, (v_t - v_o) -
  // q (omega_o + omega_t) x n, tangential part, times dt.
  double lx = (in.dvx - q * (in.osy * nz - in.osz * ny)) * dt;
  double ly = (in.dvy - q * (in.osz * nx - in.osx * nz)) * dt;
  double lz = (in.dvz - q * (in.osx * ny - in.osy * nx)) * dt;
  const double ln = lx * nx + ly * ny + lz * nz;
  lx -= ln * nx;
  ly -= ln * ny;
  lz -= ln * nz;
  // Stored tangential force turned into the current contact plane, plus the
  // A8 increment.
  double tX = in.tx, tY = in.ty, tZ = in.tz;
  const double tn = tX * nx + tY * ny + tZ * nz;
  tX += lx * inv_w - tn * nx;
  tY += ly * inv_w - tn * ny;
  tZ += lz * inv_w - tn * nz;
  out.sn = sig;
  out.tx = tX;
  out.ty = tY;
  out.tz = tZ;
  pair_loads(out, g, sig, tX, tY, tZ, S, in.wo + in.wt, inv_d);
  return out;
}

}  // namespace

void Simulation::build_rows() {
  rows_.clear();
  runs_.clear();
  const int n = n_, K = K_;
  int start = 0;
  for (int i = 1; i <= n; ++i) {
    if (i < n && model_.cell[i][1] == model_.cell[start][1] && model_.cell[i][2] == model_.cell[start][2]) continue;
    rows_.push_back({start, i - start});
    start = i;
  }
  max_row_ = 0;
  for (const Row& r : rows_) max_row_ = std::max(max_row_, r.len);
  // The lag of step_rows and its ring of accumulators.
  {
    std::vector<std::int32_t> row_of(n);
    for (size_t r = 0; r < rows_.size(); ++r)
      for (int i = rows_[r].start; i < rows_[r].start + rows_[r].len; ++i) row_of[i] = static_cast<std::int32_t>(r);
    lag_ = 0;
    for (int s = 0; s < K; ++s)
      for (int i = 0; i < n; ++i) {
        const int j = model_.neighbour(s, i);
        if (j >= 0) lag_ = std::max(lag_, std::abs(row_of[i] - row_of[j]));
      }
    const int nrows = static_cast<int>(rows_.size());
    ring_cap_ = 1;
    for (int r = 0; r < nrows; ++r) {
      const int end = r + lag_ + 1 < nrows ? rows_[r + lag_ + 1].start : n;
      ring_cap_ = std::max(ring_cap_, end - rows_[r].start);
    }
    ring_off_.resize(rows_.size());
    for (int r = 0; r < nrows; ++r) ring_off_[r] = rows_[r].start % ring_cap_;
  }
  runs_.assign(rows_.size() * K, Run{0, 0, 0});
  for (size_t r = 0; r < rows_.size(); ++r) {
    if (periodic_) break;  // minimum images: the general path only
    const int a0 = rows_[r].start, a1 = a0 + rows_[r].len;
    for (int s = 0; s < K; ++s) {
      // The longest stretch of the row with a constant, valid offset.
      Run best{a0, a0, 0};
      int i = a0;
      while (i < a1) {
        const int j = model_.neighbour(s, i);
        if (j < 0) { ++i; continue; }
        const int off = j - i;
        int e = i + 1;
        while (e < a1 && model_.neighbour(s, e) == e + off) ++e;
        if (e - i > best.b - best.a) best = Run{i, e, off};
        i = e;
      }
      runs_[r * K + s] = best;
    }
  }
  // The pairs outside the runs (row ends, holes, periodic models), per row
  // and direction in automaton order: the general path.
  extra_.clear();
  extra_start_.assign(rows_.size() * K + 1, 0);
  for (size_t r = 0; r < rows_.size(); ++r) {
    const int a0 = rows_[r].start, a1 = a0 + rows_[r].len;
    for (int s = 0; s < K; ++s) {
      const Run run = runs_[r * K + s];
      for (int i = a0; i < a1; ++i)
        if ((i < run.a || i >= run.b) && model_.neighbour(s, i) >= 0) extra_.push_back(i);
      extra_start_[r * K + s + 1] = static_cast<std::int32_t>(extra_.size());
    }
  }
}

// ---------------------------------------------------------------------------
// One step in one sweep over the rows, so that each automaton's data is
// loaded once per step. Row r:
//  A (predictor_row): the stress predictor, b and the pore pressure;
//  B1 (pair_row): the pairs its automata own (their forward directions): new
//     pair state, in place, and the owner's share of force, moment, the trace
//     of A4 and the strain, into the row's accumulators (A3, A7-A9);
//  B2 (integrate_row): the other half of every pair (from the new pair state
//     of its owner), the load, A5-A6, kick (A1) and drift.
// Every bond joins rows at most lag_ apart: B1 of row r needs b of rows
// r +- lag_, B2 of row r the pair state of owners in rows r +- lag_. A
// thread's sweep therefore runs A of row k, B1 of row k - lag_ and B2 of row
// k - 2 lag_; the accumulators of the rows between B1 and B2 live in a
// per-thread ring of lag_ + 1 rows (it stays in cache). With several threads
// each takes a contiguous block of rows: A of its first and last lag_ rows
// runs before a barrier (the neighbouring blocks' B1 reads their b), B2 of
// those rows after a second one (their owners may lie in a neighbouring
// block), with their accumulators kept meanwhile. Every automaton gets the
// same operations in the same order (B1 in direction order, then B2 in
// direction order), whatever the thread count.
template <bool kPeriodic, bool kFluid, bool kLinear>
SW_CLONES void Simulation::step_rows() {
  const int n = n_, K = K_, H = K_ / 2;
  const double dt = dt_;
  const int c = cur_, o = 1 - cur_;
  const double* __restrict px = pos_[c][0].data();
  const double* __restrict py = pos_[c][1].data();
  const double* __restrict pz = pos_[c][2].data();
  const double* __restrict vx = vel_[c][0].data();
  const double* __restrict vy = vel_[c][1].data();
  const double* __restrict vz = vel_[c][2].data();
  const double* __restrict wx = omg_[c][0].data();
  const double* __restrict wy = omg_[c][1].data();
  const double* __restrict wz = omg_[c][2].data();
  double* __restrict qx = pos_[o][0].data();
  double* __restrict qy = pos_[o][1].data();
  double* __restrict qz = pos_[o][2].data();
  double* __restrict ux = vel_[o][0].data();
  double* __restrict uy = vel_[o][1].data();
  double* __restrict uz = vel_[o][2].data();
  double* __restrict ox = omg_[o][0].data();
  double* __restrict oy = omg_[o][1].data();
  double* __restrict oz = omg_[o][2].data();
  // Pair state, updated in place (each pair read and written once, by its
  // owner, in B1; read again by the other automaton in B2).
  double* __restrict snp = sn_.data();
  double* __restrict txp = tx_.data();
  double* __restrict typ = ty_.data();
  double* __restrict tzp = tz_.data();
  const std::int32_t* __restrict nb = model_.neighbours.data();
  const double* __restrict w = wa_.data();
  const double* b = b_.data();  // written by A (predictor_row), read by B1
  const double S = model_.lattice.contact_area;
  const double R = model_.lattice.radius;
  const double invV = 1.0 / model_.lattice.cell_volume;
  const double Lx = period_.x(), Ly = period_.y(), Lz = period_.z();
  const double iLx = Lx > 0 ? 1.0 / Lx : 0.0, iLy = Ly > 0 ? 1.0 / Ly : 0.0, iLz = Lz > 0 ? 1.0 / Lz : 0.0;
  const double t = static_cast<double>(steps_) * dt;
  const double p_load = load_ ? load_(t) : 0.0;
  const double p_prev = load_ ? load_(t - dt) : 0.0;
  const double cscale = !model_.constraints.empty() && model_.constraint_scale ? model_.constraint_scale(t + 0.5 * dt) : 1.0;
  const double damp = 1.0 - options_.damping * dt;
  const bool track = track_energy_;
  const double* __restrict escale = strain_scale_.data();
  const double inv_d = 1.0 / model_.lattice.diameter;
  const double* __restrict im_a = inv_mass_a_.data();
  const double* __restrict iJ_a = inv_inertia_a_.data();
  double* __restrict Pout = pressure_.data();
  double* __restrict Eout = distortional_.data();
  double* __restrict Ppk = peak_pressure_.data();
  double* __restrict Epk = peak_distortional_.data();
  const double d0 = model_.lattice.diameter;

  // A of one row (sum: scratch of max_row_ doubles).
  const double sv = model_.lattice.contact_area / model_.lattice.cell_volume;
  double* bw = b_.data();
  auto predictor_row = [&](int row, double* __restrict sum) __attribute__((always_inline)) {
    const int a0 = rows_[row].start, len = rows_[row].len, a1 = a0 + len;
    for (int k = 0; k < len; ++k) sum[k] = 0.0;
    for (int s = 0; s < K; ++s) {
      const Run run = runs_[static_cast<size_t>(row) * K + s];
      const int off = run.off;
      const double ex = model_.lattice.unit[s].x(), ey = model_.lattice.unit[s].y(), ez = model_.lattice.unit[s].z();
#pragma omp simd
      for (int i = run.a; i < run.b; ++i) {
        const int j = i + off;
        sum[i - a0] += predictor_side<kLinear>(px[j] - px[i], py[j] - py[i], pz[j] - pz[i], vx[j] - vx[i],
                                               vy[j] - vy[i], vz[j] - vz[i], w[i], w[j], dt, ex, ey, ez);
      }
      const size_t rs = static_cast<size_t>(row) * K + s;
      for (int e = extra_start_[rs]; e < extra_start_[rs + 1]; ++e) {
        const int i = extra_[e];
        const int j = nb[static_cast<size_t>(s) * n + i];
        double dx = px[j] - px[i], dy = py[j] - py[i], dz = pz[j] - pz[i];
        if constexpr (kPeriodic) {
          dx = wrap(dx, Lx, iLx);
          dy = wrap(dy, Ly, iLy);
          dz = wrap(dz, Lz, iLz);
        }
        sum[i - a0] += predictor_side<kLinear>(dx, dy, dz, vx[j] - vx[i], vy[j] - vy[i], vz[j] - vz[i], w[i], w[j],
                                               dt, ex, ey, ez);
      }
    }
    for (int i = a0; i < a1; ++i) {
      const int ti = model_.tissue[i];
      const double dtheta = f_[i] * sv * sum[i - a0];
      theta_[i] += dtheta;
      double dp = 0.0;
      if constexpr (kFluid) {
        if (poro_[ti]) {
          if (drained_[i]) zeta_[i] = a_[ti] * theta_[i];  // reservoir at P = 0
          const double p = M_[ti] * (zeta_[i] - a_[ti] * theta_[i]);  // A10 (Biot)
          dp = p - pore_[i];
          pore_[i] = p;
        }
      }
      // Predicted mean stress increment (equation of state), then A7/A9's b.
      const double fa_dp = f_[i] * a_[ti] * dp;
      const double dsm = K_bulk_[ti] * dtheta - fa_dp;
      bw[i] = D_[ti] * dsm - pore_coef_[ti] * fa_dp;
    }
  };

  // B1 of one row; accumulator a of automaton i at acc[a * stride + i - a0].
  auto pair_row = [&](int row, double* __restrict acc, size_t stride) __attribute__((always_inline)) {
    const int a0 = rows_[row].start, len = rows_[row].len;
    double* __restrict A0 = acc;
    double* __restrict A1 = acc + stride;
    double* __restrict A2 = acc + 2 * stride;
    double* __restrict A3 = acc + 3 * stride;
    double* __restrict A4 = acc + 4 * stride;
    double* __restrict A5 = acc + 5 * stride;
    double* __restrict A6 = acc + 6 * stride;
    double* __restrict E0 = acc + 7 * stride;
    double* __restrict E1 = acc + 8 * stride;
    double* __restrict E2 = acc + 9 * stride;
    double* __restrict E3 = acc + 10 * stride;
    double* __restrict E4 = acc + 11 * stride;
    double* __restrict E5 = acc + 12 * stride;
    auto side = [&](int i, int j, size_t bi, double dx, double dy, double dz, double ux, double uy, double uz)
                    __attribute__((always_inline)) {
      const PairGeo<kLinear> g = pair_geometry<kLinear>(dx, dy, dz, ux, uy, uz, d0);
      PairIn in;
      in.dvx = vx[j] - vx[i];
      in.dvy = vy[j] - vy[i];
      in.dvz = vz[j] - vz[i];
      in.osx = wx[i] + wx[j];
      in.osy = wy[i] + wy[j];
      in.osz = wz[i] + wz[j];
      in.wo = w[i];
      in.wt = w[j];
      in.bo = b[i];
      in.bt = b[j];
      in.sn = snp[bi];
      in.tx = txp[bi];
      in.ty = typ[bi];
      in.tz = tzp[bi];
      const PairOut out = pair_update<kLinear>(in, g, dx, dy, dz, S, dt, inv_d);
      snp[bi] = out.sn;
      txp[bi] = out.tx;
      typ[bi] = out.ty;
      tzp[bi] = out.tz;
      const int l = i - a0;
      A0[l] += out.fx;
      A1[l] += out.fy;
      A2[l] += out.fz;
      A3[l] += out.mx;
      A4[l] += out.my;
      A5[l] += out.mz;
      A6[l] += out.tr;
      // The automaton's own share of the pair's strain (A8's split by compliance).
      const double share = 2.0 * w[i] / (w[i] + w[j]);
      E0[l] += share * out.e11;
      E1[l] += share * out.e22;
      E2[l] += share * out.e33;
      E3[l] += share * out.e12;
      E4[l] += share * out.e23;
      E5[l] += share * out.e13;
    };
    for (int l = 0; l < len; ++l) {
      A0[l] = A1[l] = A2[l] = A3[l] = A4[l] = A5[l] = 0.0;
      A6[l] = 0.0;
      E0[l] = E1[l] = E2[l] = E3[l] = E4[l] = E5[l] = 0.0;
    }
    for (int s = 0; s < H; ++s) {
      const Run run = runs_[static_cast<size_t>(row) * K + s];
      const int off = run.off;
      const size_t base = static_cast<size_t>(s) * n;
      const double ex = model_.lattice.unit[s].x(), ey = model_.lattice.unit[s].y(), ez = model_.lattice.unit[s].z();
#pragma omp simd
      for (int i = run.a; i < run.b; ++i) {
        const int j = i + off;
        side(i, j, base + i, px[j] - px[i], py[j] - py[i], pz[j] - pz[i], ex, ey, ez);
      }
      const size_t rs = static_cast<size_t>(row) * K + s;
      for (int e = extra_start_[rs]; e < extra_start_[rs + 1]; ++e) {
        const int i = extra_[e];
        const int j = nb[base + i];
        double dx = px[j] - px[i], dy = py[j] - py[i], dz = pz[j] - pz[i];
        if constexpr (kPeriodic) {
          dx = wrap(dx, Lx, iLx);
          dy = wrap(dy, Ly, iLy);
          dz = wrap(dz, Lz, iLz);
        }
        side(i, j, base + i, dx, dy, dz, ex, ey, ez);
      }
    }
  };

  // B2 of one row, with the accumulators B1 left.
  auto integrate_row = [&](int row, double* __restrict acc, size_t stride) __attribute__((always_inline)) {
    const int a0 = rows_[row].start, a1 = a0 + rows_[row].len;
    double* __restrict A0 = acc;
    double* __restrict A1 = acc + stride;
    double* __restrict A2 = acc + 2 * stride;
    double* __restrict A3 = acc + 3 * stride;
    double* __restrict A4 = acc + 4 * stride;
    double* __restrict A5 = acc + 5 * stride;
    double* __restrict A6 = acc + 6 * stride;
    double* __restrict E0 = acc + 7 * stride;
    double* __restrict E1 = acc + 8 * stride;
    double* __restrict E2 = acc + 9 * stride;
    double* __restrict E3 = acc + 10 * stride;
    double* __restrict E4 = acc + 11 * stride;
    double* __restrict E5 = acc + 12 * stride;
    auto other = [&](int i, int j, size_t bi, double dx, double dy, double dz, double ex, double ey, double ez)
                     __attribute__((always_inline)) {
      const PairGeo<kLinear> g = pair_geometry<kLinear>(dx, dy, dz, ex, ey, ez, d0);
      PairOut out;
      pair_loads(out, g, snp[bi], txp[bi], typ[bi], tzp[bi], S, w[j] + w[i], inv_d);
      const int l = i - a0;
      A0[l] -= out.fx;
      A1[l] -= out.fy;
      A2[l] -= out.fz;
      A3[l] += out.mx;
      A4[l] += out.my;
      A5[l] += out.mz;
      A6[l] += out.tr;
      // The automaton's own share of the pair's strain (A8's split by compliance).
      const double share = 2.0 * w[i] / (w[i] + w[j]);
      E0[l] += share * out.e11;
      E1[l] += share * out.e22;
      E2[l] += share * out.e33;
      E3[l] += share * out.e12;
      E4[l] += share * out.e23;
      E5[l] += share * out.e13;
    };
    for (int s = H; s < K; ++s) {
      const Run run = runs_[static_cast<size_t>(row) * K + s];
      const int off = run.off;
      const size_t base = static_cast<size_t>(s - H) * n;
      // The owner's forward direction (from the owner j to i).
      const common::Vec3& u = model_.lattice.unit[s - H];
      const double ex = u.x(), ey = u.y(), ez = u.z();
#pragma omp simd
      for (int i = run.a; i < run.b; ++i) {
        const int j = i + off;  // the owner of this pair
        // The owner's frame, as in B1: the same bits.
        other(i, j, base + j, px[i] - px[j], py[i] - py[j], pz[i] - pz[j], ex, ey, ez);
      }
      const size_t rs = static_cast<size_t>(row) * K + s;
      for (int e = extra_start_[rs]; e < extra_start_[rs + 1]; ++e) {
        const int i = extra_[e];
        const int j = nb[static_cast<size_t>(s) * n + i];
        double dx = px[i] - px[j], dy = py[i] - py[j], dz = pz[i] - pz[j];
        if constexpr (kPeriodic) {
          dx = wrap(dx, Lx, iLx);
          dy = wrap(dy, Ly, iLy);
          dz = wrap(dz, Lz, iLz);
        }
        other(i, j, base + j, dx, dy, dz, ex, ey, ez);
      }
    }
#pragma omp simd
    for (int i = a0; i < a1; ++i) {
      const int l = i - a0;
      // A5 from the trace of A4's averaged stress (the full tensor: stress()).
      const double P = -(A6[l] * invV) / 3.0;
      // Averaged strain tensor from the pairs' strains, its deviatoric part
      // and the equivalent (von Mises) strain sqrt(2/3 e:e).
      const double cs = escale[i];
      const double e11 = E0[l] * cs, e22 = E1[l] * cs, e33 = E2[l] * cs;
      const double e12 = E3[l] * cs, e23 = E4[l] * cs, e13 = E5[l] * cs;
      const double em = (e11 + e22 + e33) / 3.0;
      const double d1 = e11 - em, d2 = e22 - em, d3 = e33 - em;
      const double eps = std::sqrt(2.0 / 3.0 * (d1 * d1 + d2 * d2 + d3 * d3 + 2.0 * (e12 * e12 + e23 * e23 + e13 * e13)));
      Pout[i] = P;
      Eout[i] = eps;
      Ppk[i] = P > Ppk[i] ? P : Ppk[i];
      Epk[i] = eps > Epk[i] ? eps : Epk[i];
      // Kick (A1) and drift.
      const double im = im_a[i], iJ = iJ_a[i];
      const double nvx = vx[i] * damp + A0[l] * im * dt;
      const double nvy = vy[i] * damp + A1[l] * im * dt;
      const double nvz = vz[i] * damp + A2[l] * im * dt;
      ux[i] = nvx;
      uy[i] = nvy;
      uz[i] = nvz;
      qx[i] = px[i] + nvx * dt;
      qy[i] = py[i] + nvy * dt;
      qz[i] = pz[i] + nvz * dt;
      ox[i] = wx[i] * damp + A3[l] * iJ * dt;
      oy[i] = wy[i] * damp + A4[l] * iJ * dt;
      oz[i] = wz[i] * damp + A5[l] * iJ * dt;
    }
    if constexpr (kFluid) {
      for (int i = a0; i < a1; ++i)
        if (pore_[i] > peak_pore_[i]) peak_pore_[i] = pore_[i];
    }
    if (track) {
      for (int i = a0; i < a1; ++i) {
        const double m = 1.0 / im_a[i], J = 1.0 / iJ_a[i];
        const double vxi = vx[i], vyi = vy[i], vzi = vz[i], wxi = wx[i], wyi = wy[i], wzi = wz[i];
        const double nvx = ux[i], nvy = uy[i], nvz = uz[i], nwx = ox[i], nwy = oy[i], nwz = oz[i];
        const double sx = 0.5 * (vxi + nvx), sy = 0.5 * (vyi + nvy), sz = 0.5 * (vzi + nvz);
        const double gx = 0.5 * (wxi + nwx), gy = 0.5 * (wyi + nwy), gz = 0.5 * (wzi + nwz);
        // Leapfrog's exact discrete energy uses the product of the half-step
        // velocities: E = 1/2 m v^{n-1/2} . v^{n+1/2} + U(x^n).
        kinetic_[i] = 0.5 * m * (vxi * nvx + vyi * nvy + vzi * nvz) + 0.5 * J * (wxi * nwx + wyi * nwy + wzi * nwz);
        // Work over the last drift, (f^{n-1} + f^n)/2 . (x^n - x^{n-1}): with
        // the kinetic energy above the balance is exact for a linear system.
        work_[i] = 0.0;
        damp_[i] = options_.damping * dt * (m * (sx * sx + sy * sy + sz * sz) + J * (gx * gx + gy * gy + gz * gz));
      }
    }
    // The loaded automata of the row (the applicator's outer face): redo
    // their stress and kick with the pressure on the outer face (q = R, n
    // outward).
    for (int e = row_loaded_start_[row]; e < row_loaded_start_[row + 1]; ++e) {
      const int k = row_loaded_[e];
      const int i = model_.loaded.automata[k];
      const int l = i - a0;
      const common::Vec3& Ar = model_.loaded.area[k];
      const double fex = p_load * Ar.x(), fey = p_load * Ar.y(), fez = p_load * Ar.z();
      const double inv_a = 1.0 / Ar.norm();
      const double nx = -Ar.x() * inv_a, ny = -Ar.y() * inv_a, nz = -Ar.z() * inv_a;
      const double P = -((A6[l] + R * (nx * fex + ny * fey + nz * fez)) * invV) / 3.0;
      Pout[i] = P;
      Ppk[i] = std::max(loaded_peaks_[2 * k], P);
      const double im = im_a[i];
      ux[i] = vx[i] * damp + (A0[l] + fex) * im * dt;
      uy[i] = vy[i] * damp + (A1[l] + fey) * im * dt;
      uz[i] = vz[i] * damp + (A2[l] + fez) * im * dt;
      qx[i] = px[i] + ux[i] * dt;
      qy[i] = py[i] + uy[i] * dt;
      qz[i] = pz[i] + uz[i] * dt;
      if (track) {
        const double m = 1.0 / im;
        kinetic_[i] = 0.5 * m * (vx[i] * ux[i] + vy[i] * uy[i] + vz[i] * uz[i]) +
                      0.5 / iJ_a[i] * (wx[i] * ox[i] + wy[i] * oy[i] + wz[i] * oz[i]);
        // Work over the last drift, (f^{n-1} + f^n)/2 . (x^n - x^{n-1}):
        // with the kinetic energy above the balance is exact for a linear system.
        work_[i] = 0.5 * (p_prev + p_load) * (Ar.x() * vx[i] + Ar.y() * vy[i] + Ar.z() * vz[i]) * dt;
      }
    }
    // Prescribed velocities of the row: override the kick on the fixed axes.
    for (int e = row_constraint_start_[row]; e < row_constraint_start_[row + 1]; ++e) {
      const int k = row_constraint_[e];
      const VelocityConstraint& con = model_.constraints[k];
      const int i = con.automaton;
      const int l = i - a0;
      if (con.axes & 1) ux[i] = con.velocity.x() * cscale;
      if (con.axes & 2) uy[i] = con.velocity.y() * cscale;
      if (con.axes & 4) uz[i] = con.velocity.z() * cscale;
      qx[i] = px[i] + ux[i] * dt;
      qy[i] = py[i] + uy[i] * dt;
      qz[i] = pz[i] + uz[i] * dt;
      constraint_force_[k] = common::Vec3(A0[l], A1[l], A2[l]);
    }
  };

  const int nrows = static_cast<int>(rows_.size());
  const int lag = lag_;
  const size_t rstride = static_cast<size_t>(ring_cap_) + static_cast<size_t>(max_row_);
  const int max_threads = omp_get_max_threads();
  if (static_cast<int>(thread_acc_.size()) < max_threads) thread_acc_.resize(static_cast<size_t>(max_threads));
  auto row_start = [&](int r) { return r < nrows ? rows_[r].start : n; };
#pragma omp parallel if (n >= kParallelMin)
  {
    const int T = omp_get_num_threads(), th = omp_get_thread_num();
    const int R0 = static_cast<int>(static_cast<std::int64_t>(nrows) * th / T);
    const int R1 = static_cast<int>(static_cast<std::int64_t>(nrows) * (th + 1) / T);
    // Rows [R0, lo) and [hi, R1) wait for the other blocks' B1.
    const int lo = R0 > 0 ? std::min(R0 + lag, R1) : R0;
    const int hi = R1 < nrows ? std::max(R1 - lag, lo) : R1;
    const size_t front = static_cast<size_t>(row_start(lo) - row_start(R0));
    const size_t dstride = front + static_cast<size_t>(row_start(R1) - row_start(hi));
    std::vector<double>& buf = thread_acc_[static_cast<size_t>(th)];
    const size_t need = 13 * (rstride + dstride);
    if (buf.size() < need) buf.resize(need);
    double* ring = buf.data();
    double* defer = ring + 13 * rstride;
    auto acc_of = [&](int row, size_t& stride) {
      if (row < lo) {
        stride = dstride;
        return defer + (rows_[row].start - row_start(R0));
      }
      if (row >= hi) {
        stride = dstride;
        return defer + front + (rows_[row].start - row_start(hi));
      }
      stride = rstride;
      return ring + ring_off_[row];
    };
    // A of the rows whose b the neighbouring blocks' B1 reads.
    std::vector<double> sum_buf(static_cast<size_t>(max_row_));
    double* sum = sum_buf.data();
    for (int k = R0; k < lo; ++k) predictor_row(k, sum);
    for (int k = hi; k < R1; ++k) predictor_row(k, sum);
#pragma omp barrier
    for (int k = R0; k < R1 + 2 * lag; ++k) {
      size_t stride = 0;
      if (k >= lo && k < hi) predictor_row(k, sum);
      const int r = k - lag;
      if (r >= R0 && r < R1) {
        double* acc = acc_of(r, stride);
        pair_row(r, acc, stride);
      }
      const int g = k - 2 * lag;
      if (g >= lo && g < hi) {
        double* acc = acc_of(g, stride);
        integrate_row(g, acc, stride);
      }
    }
#pragma omp barrier
    for (int g = R0; g < lo; ++g) {
      size_t stride = 0;
      double* acc = acc_of(g, stride);
      integrate_row(g, acc, stride);
    }
    for (int g = hi; g < R1; ++g) {
      size_t stride = 0;
      double* acc = acc_of(g, stride);
      integrate_row(g, acc, stride);
    }
  }
}
void Simulation::step() {
  const bool fluid = fluid_on_;
  if (load_) {
    const std::vector<int>& la = model_.loaded.automata;
    for (size_t k = 0; k < la.size(); ++k) {
      loaded_peaks_[2 * k] = peak_pressure_[la[k]];
      loaded_peaks_[2 * k + 1] = 0.0;
    }
  }
  const bool linear = options_.geometry == Geometry::kLinear;
#define SW_STEP(P, F, L)        \
  {                             \
    step_rows<P, F, L>();       \
  }
  if (periodic_) {
    if (fluid) { if (linear) SW_STEP(true, true, true) else SW_STEP(true, true, false) }
    else { if (linear) SW_STEP(true, false, true) else SW_STEP(true, false, false) }
  } else {
    if (fluid) { if (linear) SW_STEP(false, true, true) else SW_STEP(false, true, false) }
    else { if (linear) SW_STEP(false, false, true) else SW_STEP(false, false, false) }
  }
#undef SW_STEP
  if (track_energy_) {
    kinetic_now_ = deterministic_sum(n_, [&](std::int64_t i) { return kinetic_[i]; });
    work_total_ += deterministic_sum(n_, [&](std::int64_t i) { return work_[i]; });
    damping_total_ += deterministic_sum(n_, [&](std::int64_t i) { return damp_[i]; });
  }
  // The predictor left each automaton's pore pressure for this zeta and theta.
  if (filtration_)
    filtration_->advance(theta_.data(), zeta_.data(), track_energy_ ? &dissipation_total_ : nullptr, pore_.data());
  cur_ = 1 - cur_;
  ++steps_;
  // NaN/Inf stop the run naming where (checked on the cheap global sums).
  if ((steps_ & 63) == 1) {
    for (int a = 0; a < 3; ++a) {
      const std::vector<double>& v = vel_[cur_][a];
      const double s = deterministic_sum(n_, [&](std::int64_t i) { return v[i]; });
      if (!std::isfinite(s)) {
        for (int i = 0; i < n_; ++i)
          if (!std::isfinite(v[i])) {
            std::ostringstream m;
            m << "shockwave: step " << steps_ << " (t = " << time() << " s): non-finite velocity of automaton " << i
              << " (" << model_.tissues[model_.tissue[i]].name << ") at (" << model_.x[i] << ", " << model_.y[i]
              << ", " << model_.z[i] << ") m";
            throw common::NumericalError(m.str());
          }
      }
    }
  }
}

void Simulation::run(std::int64_t steps) {
  for (std::int64_t k = 0; k < steps; ++k) step();
}

common::Vec3 Simulation::position(int i) const {
  // After a step the other buffer still holds the positions of the fields' level.
  const int o = 1 - cur_;
  return {pos_[o][0][i], pos_[o][1][i], pos_[o][2][i]};
}

common::Vec3 Simulation::half_step_velocity(int i) const {
  return {vel_[cur_][0][i], vel_[cur_][1][i], vel_[cur_][2][i]};
}
common::Vec3 Simulation::half_step_angular_velocity(int i) const {
  return {omg_[cur_][0][i], omg_[cur_][1][i], omg_[cur_][2][i]};
}

double critical_time_step(const Model& model, const SimulationOptions& options, std::string* limiting) {
  const std::vector<std::int64_t> counts = model.tissue_counts();
  double best = std::numeric_limits<double>::infinity();
  for (size_t t = 0; t < model.tissues.size(); ++t) {
    if (counts[t] == 0) continue;
    GridSpec g;
    g.count = {4, 4, 4};
    g.periodic = {true, true, true};
    const Model block = build_model(model.lattice, g, {model.tissues[t]}, model.fluid,
                                    [](int, int, int, const common::Vec3&) { return 0; });
    SimulationOptions po = options;
    po.filtration = false;
    po.damping = 0.0;
    const TissueConstants& c = block.constants[0];
    // Tiny steps: the increments stay linear; the value cancels below.
    po.fixed_time_step = 1e-3 * model.lattice.diameter / c.undrained_p_speed;
    po.skip_stability_check = true;
    const int n = block.size();
    const double R = model.lattice.radius;
    // Deterministic start vector (translations and rotations times R).
    std::vector<common::Vec3> u(n), phi(n);
    std::uint64_t state = 0x9E3779B97F4A7C15ull;
    auto rnd = [&state]() {
      state = state * 6364136223846793005ull + 1442695040888963407ull;
      return static_cast<double>(state >> 11) * (1.0 / 9007199254740992.0) - 0.5;
    };
    for (int i = 0; i < n; ++i) {
      u[i] = common::Vec3(rnd(), rnd(), rnd());
      phi[i] = common::Vec3(rnd(), rnd(), rnd()) / R;
    }
    const double m = c.total_density * model.lattice.cell_volume, J = 0.4 * m * R * R;
    double lambda = 0.0;
    for (int it = 0; it < 60; ++it) {
      Simulation sim(block, po);
      const double h = sim.time_step();
      for (int i = 0; i < n; ++i) {
        sim.set_velocity(i, u[i] / h);
        sim.set_angular_velocity(i, phi[i] / h);
      }
      sim.step();
      // One step from rest with displacement u: v changes by -M^-1 K u h.
      double num = 0.0, den = 0.0, norm = 0.0;
      std::vector<common::Vec3> au(n), aphi(n);
      for (int i = 0; i < n; ++i) {
        au[i] = -(sim.half_step_velocity(i) - u[i] / h) / h;
        aphi[i] = -(sim.half_step_angular_velocity(i) - phi[i] / h) / h;
        num += m * u[i].dot(au[i]) + J * phi[i].dot(aphi[i]);
        den += m * u[i].squaredNorm() + J * phi[i].squaredNorm();
      }
      lambda = num / den;  // Rayleigh quotient u.K u / u.M u
      for (int i = 0; i < n; ++i) norm += m * au[i].squaredNorm() + J * aphi[i].squaredNorm();
      norm = std::sqrt(norm / den);
      for (int i = 0; i < n; ++i) {
        u[i] = au[i] / norm;
        phi[i] = aphi[i] / norm;
      }
    }
    const double dt = 2.0 / std::sqrt(lambda);
    if (dt < best) {
      best = dt;
      if (limiting) *limiting = model.tissues[t].name;
    }
  }
  return best;
}

common::Vec3 Simulation::velocity(int i) const {
  return 0.5 * common::Vec3(vel_[0][0][i] + vel_[1][0][i], vel_[0][1][i] + vel_[1][1][i], vel_[0][2][i] + vel_[1][2][i]);
}

double Simulation::von_mises(int i) const {
  const std::array<double, 6> s = stress(i);
  const double d12 = s[0] - s[1], d23 = s[1] - s[2], d31 = s[2] - s[0];
  return std::sqrt(0.5 * (d12 * d12 + d23 * d23 + d31 * d31) + 3.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]));  // A6
}

std::array<double, 6> Simulation::stress(int i) const {
  // Recomputed from the pair state of the fields' level (the positions of
  // that level are in 1 - cur_ after the step).
  const int o = 1 - cur_;
  const int K = K_, H = K_ / 2, n = n_;
  const bool linear = options_.geometry == Geometry::kLinear;
  std::array<double, 6> s{0, 0, 0, 0, 0, 0};
  for (int d = 0; d < K; ++d) {
    const int j = model_.neighbour(d, i);
    if (j < 0) continue;
    const bool own = d < H;
    const int io = own ? i : j, it = own ? j : i;
    const size_t bi = static_cast<size_t>(own ? d : d - H) * n + io;
    common::Vec3 dv(pos_[o][0][it] - pos_[o][0][io], pos_[o][1][it] - pos_[o][1][io], pos_[o][2][it] - pos_[o][2][io]);
    for (int a = 0; a < 3; ++a)
      if (period_[a] > 0) dv[a] = wrap(dv[a], period_[a], 1.0 / period_[a]);
    const common::Vec3 nv = linear ? model_.lattice.unit[own ? d : d - H] : common::Vec3(dv / dv.norm());
    const double q = linear ? 0.5 * model_.lattice.diameter : 0.5 * dv.norm();
    const common::Vec3 F = model_.lattice.contact_area * (sn_[bi] * nv + common::Vec3(tx_[bi], ty_[bi], tz_[bi]));
    s[0] += q * nv.x() * F.x();
    s[1] += q * nv.y() * F.y();
    s[2] += q * nv.z() * F.z();
    s[3] += 0.5 * q * (nv.x() * F.y() + nv.y() * F.x());
    s[4] += 0.5 * q * (nv.y() * F.z() + nv.z() * F.y());
    s[5] += 0.5 * q * (nv.x() * F.z() + nv.z() * F.x());
  }
  for (double& v : s) v /= model_.lattice.cell_volume;
  return s;
}

double Simulation::potential_energy() const {
  // E = sum_pairs S (w_i + w_j)/2 [(sigma - beta)^2 + |tau|^2]
  //   + sum_i V [D_i K_i theta_i^2 / (2 f_i) + P_i^2 / (2 M_i)],
  // beta = (w_i B_i + w_j B_j)/(w_i + w_j), B_i = D_i (K_i theta_i - a_i f_i P_i) - c_i a_i f_i P_i
  // (the accumulated many-body and pore parts of the pair force).
  const int n = n_, H = K_ / 2;
  const double S = model_.lattice.contact_area, V = model_.lattice.cell_volume;
  auto B = [&](int i) {
    const int t = model_.tissue[i];
    const double fap = f_[i] * a_[t] * pore_[i];
    return D_[t] * (K_bulk_[t] * theta_[i] - fap) - pore_coef_[t] * fap;
  };
  return deterministic_sum(n, [&](std::int64_t ii) {
    const int i = static_cast<int>(ii);
    const int ti = model_.tissue[i];
    double e = 0.0;
    for (int s = 0; s < H; ++s) {
      const int j = model_.neighbour(s, i);
      if (j < 0) continue;
      const size_t bi = static_cast<size_t>(s) * n + i;
      const double wi = w_[ti], wj = w_[model_.tissue[j]];
      const double beta = (wi * B(i) + wj * B(j)) / (wi + wj);
      const double d = sn_[bi] - beta;
      const double t2 = tx_[bi] * tx_[bi] + ty_[bi] * ty_[bi] + tz_[bi] * tz_[bi];
      e += 0.5 * S * (wi + wj) * (d * d + t2);
    }
    e += V * D_[ti] * K_bulk_[ti] * theta_[i] * theta_[i] / (2.0 * f_[i]);
    if (poro_[ti]) e += V * pore_[i] * pore_[i] / (2.0 * M_[ti]);
    return e;
  });
}

EnergyBalance Simulation::energy() const {
  EnergyBalance e;
  e.kinetic = kinetic_now_;
  e.potential = potential_energy();
  e.external_work = work_total_;
  e.dissipation = dissipation_total_;
  e.damping = damping_total_;
  return e;
}

common::Vec3 Simulation::linear_momentum() const {
  common::Vec3 p;
  for (int a = 0; a < 3; ++a) {
    const std::vector<double>& v = vel_[cur_][a];
    p[a] = deterministic_sum(n_, [&](std::int64_t i) { return mass_[model_.tissue[i]] * v[i]; });
  }
  return p;
}

common::Vec3 Simulation::angular_momentum() const {
  // Positions and velocities at the same time: x^{n+1/2} = (x^n + x^{n+1})/2.
  common::Vec3 L;
  for (int a = 0; a < 3; ++a) {
    const int b1 = (a + 1) % 3, b2 = (a + 2) % 3;
    L[a] = deterministic_sum(n_, [&](std::int64_t ii) {
      const int i = static_cast<int>(ii);
      const int t = model_.tissue[i];
      const double m = mass_[t];
      const double x1 = 0.5 * (pos_[0][b1][i] + pos_[1][b1][i]), x2 = 0.5 * (pos_[0][b2][i] + pos_[1][b2][i]);
      return m * (x1 * vel_[cur_][b2][i] - x2 * vel_[cur_][b1][i]) + omg_[cur_][a][i] / inv_inertia_[t];
    });
  }
  return L;
}

// ---------------------------------------------------------------------------
// State for checkpoints (SimulationState).

std::vector<std::pair<std::string, std::vector<double>*>> Simulation::state_arrays() {
  std::vector<std::pair<std::string, std::vector<double>*>> v;
  const char* axis[3] = {"x", "y", "z"};
  for (int b = 0; b < 2; ++b)
    for (int a = 0; a < 3; ++a) {
      const std::string tail = std::to_string(b) + "_" + axis[a];
      v.emplace_back("position_" + tail, &pos_[b][a]);
      v.emplace_back("velocity_" + tail, &vel_[b][a]);
      v.emplace_back("angular_velocity_" + tail, &omg_[b][a]);
    }
  v.emplace_back("pair_normal_stress", &sn_);
  v.emplace_back("pair_tangential_x", &tx_);
  v.emplace_back("pair_tangential_y", &ty_);
  v.emplace_back("pair_tangential_z", &tz_);
  v.emplace_back("volumetric_strain", &theta_);
  v.emplace_back("fluid_content", &zeta_);
  v.emplace_back("pore_pressure", &pore_);
  v.emplace_back("pressure", &pressure_);
  v.emplace_back("distortional_strain", &distortional_);
  v.emplace_back("peak_pressure", &peak_pressure_);
  v.emplace_back("peak_distortional_strain", &peak_distortional_);
  v.emplace_back("peak_pore_pressure", &peak_pore_);
  v.emplace_back("kinetic_energy", &kinetic_);
  v.emplace_back("work", &work_);
  v.emplace_back("damping_energy", &damp_);
  return v;
}

SimulationState Simulation::state() const {
  SimulationState st;
  st.steps = steps_;
  st.buffer = cur_;
  st.kinetic = kinetic_now_;
  st.work = work_total_;
  st.dissipation = dissipation_total_;
  st.damping = damping_total_;
  for (const auto& [name, array] : const_cast<Simulation*>(this)->state_arrays())
    if (!array->empty()) st.arrays.emplace_back(name, *array);
  std::vector<double> cf;
  cf.reserve(3 * constraint_force_.size());
  for (const common::Vec3& f : constraint_force_) cf.insert(cf.end(), {f.x(), f.y(), f.z()});
  if (!cf.empty()) st.arrays.emplace_back("constraint_force", std::move(cf));
  return st;
}

void Simulation::restore(const SimulationState& st) {
  if (st.steps < 0 || (st.buffer != 0 && st.buffer != 1))
    throw std::runtime_error("simulation state: expected steps >= 0 and buffer 0 or 1, found " +
                             std::to_string(st.steps) + " and " + std::to_string(st.buffer));
  auto find = [&](const std::string& name) -> const std::vector<double>* {
    for (const auto& [n, a] : st.arrays)
      if (n == name) return &a;
    return nullptr;
  };
  std::vector<std::pair<std::string, std::vector<double>*>> mine = state_arrays();
  std::vector<double> cf_flat(3 * constraint_force_.size());
  mine.emplace_back("constraint_force", &cf_flat);
  // Check everything before changing anything.
  size_t expected = 0;
  for (const auto& [name, array] : mine) {
    if (array->empty()) continue;
    ++expected;
    const std::vector<double>* a = find(name);
    if (a == nullptr) throw std::runtime_error("simulation state: the array " + name + " is missing");
    if (a->size() != array->size())
      throw std::runtime_error("simulation state: the array " + name + " has " + std::to_string(a->size()) +
                               " values, expected " + std::to_string(array->size()));
  }
  if (st.arrays.size() != expected)
    throw std::runtime_error("simulation state: " + std::to_string(st.arrays.size()) + " arrays, expected " +
                             std::to_string(expected) + " (one of another run)");
  for (const auto& [name, array] : mine)
    if (!array->empty()) *array = *find(name);
  for (size_t k = 0; k < constraint_force_.size(); ++k)
    constraint_force_[k] = common::Vec3(cf_flat[3 * k], cf_flat[3 * k + 1], cf_flat[3 * k + 2]);
  steps_ = st.steps;
  cur_ = st.buffer;
  kinetic_now_ = st.kinetic;
  work_total_ = st.work;
  dissipation_total_ = st.dissipation;
  damping_total_ = st.damping;
}

}  // namespace arthrosim::shockwave
