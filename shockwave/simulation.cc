#include "shockwave/simulation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "common/error.h"
#include "common/finite.h"
#include "shockwave/reduce.h"

namespace arthrosim::shockwave {

namespace {
inline double wrap(double d, double period, double inv_period) {
  return period > 0.0 ? d - period * std::nearbyint(d * inv_period) : d;
}
}  // namespace

double free_surface_factor(const Model& model, int i, bool undrained) {
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
  for (int i = 0; i < n_; ++i) wa_[i] = w_[model.tissue[i]];
  for (auto& a : acc_) a.assign(n_, 0.0);
  // Free-surface factor of the volumetric strain (see simulation.h).
  f_.resize(n_);
  for (int i = 0; i < n_; ++i) f_[i] = free_surface_factor(model, i, poro_[model.tissue[i]] != 0);
  constraint_of_.assign(n_, -1);
  for (size_t k = 0; k < model.constraints.size(); ++k) {
    const int a = model.constraints[k].automaton;
    if (a < 0 || a >= n_) throw common::InputError(src, 0, "constraint on a non-existent automaton " + std::to_string(a));
    constraint_of_[a] = static_cast<std::int32_t>(k);
  }
  constraint_force_.assign(model.constraints.size(), common::Vec3::Zero());
  load_of_.assign(n_, -1);
  if (load_) {
    for (size_t k = 0; k < model.loaded.automata.size(); ++k) {
      const int a = model.loaded.automata[k];
      if (a < 0 || a >= n_) throw common::InputError(src, 0, "load on a non-existent automaton " + std::to_string(a));
      load_of_[a] = static_cast<std::int32_t>(k);
    }
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
  for (int b = 0; b < 2; ++b) {
    sn_[b].assign(nb, 0.0);
    tx_[b].assign(nb, 0.0);
    ty_[b].assign(nb, 0.0);
    tz_[b].assign(nb, 0.0);
  }
  theta_.assign(n_, 0.0);
  b_.assign(n_, 0.0);
  pore_.assign(n_, 0.0);
  if (fluid_on_) zeta_.assign(n_, 0.0);
  pressure_.assign(n_, 0.0);
  von_mises_.assign(n_, 0.0);
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
// A. Stress predictor.
template <bool kPeriodic, bool kFluid>
void Simulation::predictor() {
  const int n = n_, K = K_;
  const double dt = dt_;
  const double* px = pos_[cur_][0].data();
  const double* py = pos_[cur_][1].data();
  const double* pz = pos_[cur_][2].data();
  const double* vx = vel_[cur_][0].data();
  const double* vy = vel_[cur_][1].data();
  const double* vz = vel_[cur_][2].data();
  const std::int32_t* nb = model_.neighbours.data();
  const std::uint8_t* tis = model_.tissue.data();
  const double* w = wa_.data();
  const double sv = model_.lattice.contact_area / model_.lattice.cell_volume;
  const double Lx = period_.x(), Ly = period_.y(), Lz = period_.z();
  const double iLx = Lx > 0 ? 1.0 / Lx : 0.0, iLy = Ly > 0 ? 1.0 / Ly : 0.0, iLz = Lz > 0 ? 1.0 / Lz : 0.0;
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (int i = 0; i < n; ++i) {
    const int ti = tis[i];
    const double xi = px[i], yi = py[i], zi = pz[i];
    const double vxi = vx[i], vyi = vy[i], vzi = vz[i];
    const double wi = w[i];
    double sum = 0.0;
    for (int s = 0; s < K; ++s) {
      const int j = nb[static_cast<size_t>(s) * n + i];
      if (j < 0) continue;
      double dx = px[j] - xi, dy = py[j] - yi, dz = pz[j] - zi;
      if constexpr (kPeriodic) {
        dx = wrap(dx, Lx, iLx);
        dy = wrap(dy, Ly, iLy);
        dz = wrap(dz, Lz, iLz);
      }
      const double inv_r = 1.0 / std::sqrt(dx * dx + dy * dy + dz * dz);
      const double dr = (dx * (vx[j] - vxi) + dy * (vy[j] - vyi) + dz * (vz[j] - vzi)) * inv_r * dt;
      const double wj = w[j];
      sum += dr * (wi / (wi + wj));
    }
    const double dtheta = f_[i] * sv * sum;
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
    b_[i] = D_[ti] * dsm - pore_coef_[ti] * fa_dp;
  }
}

// ---------------------------------------------------------------------------
// B1. Pair forces (A3, A7-A9) of the bonds each automaton owns (its forward
// directions): new pair state, and the owner's share of force, moment and
// averaged stress.
template <bool kPeriodic>
void Simulation::pair_forces() {
  const int n = n_, H = K_ / 2;
  const double dt = dt_;
  const int c = cur_, o = 1 - cur_;
  const double* px = pos_[c][0].data();
  const double* py = pos_[c][1].data();
  const double* pz = pos_[c][2].data();
  const double* vx = vel_[c][0].data();
  const double* vy = vel_[c][1].data();
  const double* vz = vel_[c][2].data();
  const double* wx = omg_[c][0].data();
  const double* wy = omg_[c][1].data();
  const double* wz = omg_[c][2].data();
  const double* sn0 = sn_[c].data();
  const double* tx0 = tx_[c].data();
  const double* ty0 = ty_[c].data();
  const double* tz0 = tz_[c].data();
  double* sn1 = sn_[o].data();
  double* tx1 = tx_[o].data();
  double* ty1 = ty_[o].data();
  double* tz1 = tz_[o].data();
  const std::int32_t* nb = model_.neighbours.data();
  const double* w = wa_.data();
  const double* b = b_.data();
  const double S = model_.lattice.contact_area;
  const double Lx = period_.x(), Ly = period_.y(), Lz = period_.z();
  const double iLx = Lx > 0 ? 1.0 / Lx : 0.0, iLy = Ly > 0 ? 1.0 / Ly : 0.0, iLz = Lz > 0 ? 1.0 / Lz : 0.0;
  double* Fx = acc_[0].data();
  double* Fy = acc_[1].data();
  double* Fz = acc_[2].data();
  double* Mx = acc_[3].data();
  double* My = acc_[4].data();
  double* Mz = acc_[5].data();
  double* S11 = acc_[6].data();
  double* S22 = acc_[7].data();
  double* S33 = acc_[8].data();
  double* S12 = acc_[9].data();
  double* S23 = acc_[10].data();
  double* S13 = acc_[11].data();
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (int i = 0; i < n; ++i) {
    double fx = 0, fy = 0, fz = 0, mx = 0, my = 0, mz = 0;
    double s11 = 0, s22 = 0, s33 = 0, s12 = 0, s23 = 0, s13 = 0;
    const double xi = px[i], yi = py[i], zi = pz[i];
    const double vxi = vx[i], vyi = vy[i], vzi = vz[i];
    const double wxi = wx[i], wyi = wy[i], wzi = wz[i];
    const double wi = w[i], wbi = w[i] * b[i];
    for (int s = 0; s < H; ++s) {
      const size_t bi = static_cast<size_t>(s) * n + i;
      const int j = nb[bi];
      if (j < 0) continue;
      double dx = px[j] - xi, dy = py[j] - yi, dz = pz[j] - zi;
      if constexpr (kPeriodic) {
        dx = wrap(dx, Lx, iLx);
        dy = wrap(dy, Ly, iLy);
        dz = wrap(dz, Lz, iLz);
      }
      const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
      const double inv_r = 1.0 / r;
      const double nx = dx * inv_r, ny = dy * inv_r, nz = dz * inv_r;
      const double dvx = vx[j] - vxi, dvy = vy[j] - vyi, dvz = vz[j] - vzi;
      const double dr = (dx * dvx + dy * dvy + dz * dvz) * inv_r * dt;
      const double wj = w[j];
      const double inv_w = 1.0 / (wi + wj);
      // A8: normal specific force.
      const double sig = sn0[bi] + (dr + (wbi + wj * b[j])) * inv_w;
      // Relative shear displacement at the contact point, (v_j - v_i) -
      // q (omega_i + omega_j) x n, tangential part, times dt.
      const double q = 0.5 * r;
      const double osx = wxi + wx[j], osy = wyi + wy[j], osz = wzi + wz[j];
      double lx = (dvx - q * (osy * nz - osz * ny)) * dt;
      double ly = (dvy - q * (osz * nx - osx * nz)) * dt;
      double lz = (dvz - q * (osx * ny - osy * nx)) * dt;
      const double ln = lx * nx + ly * ny + lz * nz;
      lx -= ln * nx;
      ly -= ln * ny;
      lz -= ln * nz;
      // Stored tangential force, turned into the current contact plane, plus
      // the A8 increment.
      double tX = tx0[bi], tY = ty0[bi], tZ = tz0[bi];
      const double tn = tX * nx + tY * ny + tZ * nz;
      tX += lx * inv_w - tn * nx;
      tY += ly * inv_w - tn * ny;
      tZ += lz * inv_w - tn * nz;
      sn1[bi] = sig;
      tx1[bi] = tX;
      ty1[bi] = tY;
      tz1[bi] = tZ;
      // A3: force on the owner; A1: moment q n x F^tau (the same on both);
      // A4: q n (x) F (the same for both automata).
      const double Fx_ = S * (sig * nx + tX), Fy_ = S * (sig * ny + tY), Fz_ = S * (sig * nz + tZ);
      fx += Fx_;
      fy += Fy_;
      fz += Fz_;
      const double qS = q * S;
      mx += qS * (ny * tZ - nz * tY);
      my += qS * (nz * tX - nx * tZ);
      mz += qS * (nx * tY - ny * tX);
      s11 += q * nx * Fx_;
      s22 += q * ny * Fy_;
      s33 += q * nz * Fz_;
      s12 += 0.5 * q * (nx * Fy_ + ny * Fx_);
      s23 += 0.5 * q * (ny * Fz_ + nz * Fy_);
      s13 += 0.5 * q * (nx * Fz_ + nz * Fx_);
    }
    Fx[i] = fx;
    Fy[i] = fy;
    Fz[i] = fz;
    Mx[i] = mx;
    My[i] = my;
    Mz[i] = mz;
    S11[i] = s11;
    S22[i] = s22;
    S33[i] = s33;
    S12[i] = s12;
    S23[i] = s23;
    S13[i] = s13;
  }
}

// ---------------------------------------------------------------------------
// B2. The other half of every pair (from the new pair state of its owner),
// the load, averaged stress (A4-A6), kick (A1) and drift.
template <bool kPeriodic, bool kFluid>
void Simulation::integrate() {
  const int n = n_, K = K_, H = K_ / 2;
  const double dt = dt_;
  const int c = cur_, o = 1 - cur_;
  const double* px = pos_[c][0].data();
  const double* py = pos_[c][1].data();
  const double* pz = pos_[c][2].data();
  const double* vx = vel_[c][0].data();
  const double* vy = vel_[c][1].data();
  const double* vz = vel_[c][2].data();
  const double* wx = omg_[c][0].data();
  const double* wy = omg_[c][1].data();
  const double* wz = omg_[c][2].data();
  double* qx = pos_[o][0].data();
  double* qy = pos_[o][1].data();
  double* qz = pos_[o][2].data();
  double* ux = vel_[o][0].data();
  double* uy = vel_[o][1].data();
  double* uz = vel_[o][2].data();
  double* ox = omg_[o][0].data();
  double* oy = omg_[o][1].data();
  double* oz = omg_[o][2].data();
  const double* sn1 = sn_[o].data();
  const double* tx1 = tx_[o].data();
  const double* ty1 = ty_[o].data();
  const double* tz1 = tz_[o].data();
  const std::int32_t* nb = model_.neighbours.data();
  const std::uint8_t* tis = model_.tissue.data();
  const double S = model_.lattice.contact_area;
  const double R = model_.lattice.radius;
  const double invV = 1.0 / model_.lattice.cell_volume;
  const double Lx = period_.x(), Ly = period_.y(), Lz = period_.z();
  const double iLx = Lx > 0 ? 1.0 / Lx : 0.0, iLy = Ly > 0 ? 1.0 / Ly : 0.0, iLz = Lz > 0 ? 1.0 / Lz : 0.0;
  const double t = static_cast<double>(steps_) * dt;
  const double p_load = load_ ? load_(t) : 0.0;
  const double p_prev = load_ ? load_(t - dt) : 0.0;
  const double cscale = model_.constraint_scale ? model_.constraint_scale(t + 0.5 * dt) : 1.0;
  const double damp = 1.0 - options_.damping * dt;
  const bool track = track_energy_;
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (int i = 0; i < n; ++i) {
    const int ti = tis[i];
    double fx = acc_[0][i], fy = acc_[1][i], fz = acc_[2][i];
    double mx = acc_[3][i], my = acc_[4][i], mz = acc_[5][i];
    double s11 = acc_[6][i], s22 = acc_[7][i], s33 = acc_[8][i];
    double s12 = acc_[9][i], s23 = acc_[10][i], s13 = acc_[11][i];
    const double xi = px[i], yi = py[i], zi = pz[i];
    for (int s = H; s < K; ++s) {
      const int j = nb[static_cast<size_t>(s) * n + i];  // the owner of this pair
      if (j < 0) continue;
      const size_t bi = static_cast<size_t>(s - H) * n + j;
      // The owner's frame, as in pair_forces: the same bits.
      double dx = xi - px[j], dy = yi - py[j], dz = zi - pz[j];
      if constexpr (kPeriodic) {
        dx = wrap(dx, Lx, iLx);
        dy = wrap(dy, Ly, iLy);
        dz = wrap(dz, Lz, iLz);
      }
      const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
      const double inv_r = 1.0 / r;
      const double nx = dx * inv_r, ny = dy * inv_r, nz = dz * inv_r;
      const double sig = sn1[bi], tX = tx1[bi], tY = ty1[bi], tZ = tz1[bi];
      const double Fx_ = S * (sig * nx + tX), Fy_ = S * (sig * ny + tY), Fz_ = S * (sig * nz + tZ);
      fx -= Fx_;
      fy -= Fy_;
      fz -= Fz_;
      const double q = 0.5 * r;
      const double qS = q * S;
      mx += qS * (ny * tZ - nz * tY);
      my += qS * (nz * tX - nx * tZ);
      mz += qS * (nx * tY - ny * tX);
      s11 += q * nx * Fx_;
      s22 += q * ny * Fy_;
      s33 += q * nz * Fz_;
      s12 += 0.5 * q * (nx * Fy_ + ny * Fx_);
      s23 += 0.5 * q * (ny * Fz_ + nz * Fy_);
      s13 += 0.5 * q * (nx * Fz_ + nz * Fx_);
    }
    const int li = load_of_[i];
    double fex = 0, fey = 0, fez = 0;
    if (li >= 0) {
      const common::Vec3& A = model_.loaded.area[li];
      fex = p_load * A.x();
      fey = p_load * A.y();
      fez = p_load * A.z();
      // The load acts on the outer face: q = R, n = -A/|A| (outward).
      const double inv_a = 1.0 / A.norm();
      const double nx = -A.x() * inv_a, ny = -A.y() * inv_a, nz = -A.z() * inv_a;
      s11 += R * nx * fex;
      s22 += R * ny * fey;
      s33 += R * nz * fez;
      s12 += 0.5 * R * (nx * fey + ny * fex);
      s23 += 0.5 * R * (ny * fez + nz * fey);
      s13 += 0.5 * R * (nx * fez + nz * fex);
    }
    s11 *= invV;
    s22 *= invV;
    s33 *= invV;
    s12 *= invV;
    s23 *= invV;
    s13 *= invV;
    const double P = -(s11 + s22 + s33) / 3.0;  // A5
    const double d12 = s11 - s22, d23 = s22 - s33, d31 = s33 - s11;
    const double seq = std::sqrt(0.5 * (d12 * d12 + d23 * d23 + d31 * d31) +
                                 3.0 * (s12 * s12 + s23 * s23 + s13 * s13));  // A6
    const double eps = seq * inv3G_[ti];
    pressure_[i] = P;
    von_mises_[i] = seq;
    distortional_[i] = eps;
    if (P > peak_pressure_[i]) peak_pressure_[i] = P;
    if (eps > peak_distortional_[i]) peak_distortional_[i] = eps;
    if constexpr (kFluid) {
      if (pore_[i] > peak_pore_[i]) peak_pore_[i] = pore_[i];
    }
    // Kick (A1) and drift.
    const double im = inv_mass_[ti], iJ = inv_inertia_[ti];
    const double vxi = vx[i], vyi = vy[i], vzi = vz[i];
    double nvx = vxi * damp + (fx + fex) * im * dt;
    double nvy = vyi * damp + (fy + fey) * im * dt;
    double nvz = vzi * damp + (fz + fez) * im * dt;
    const int ci = constraint_of_[i];
    if (ci >= 0) {
      const VelocityConstraint& con = model_.constraints[ci];
      if (con.axes & 1) nvx = con.velocity.x() * cscale;
      if (con.axes & 2) nvy = con.velocity.y() * cscale;
      if (con.axes & 4) nvz = con.velocity.z() * cscale;
      constraint_force_[ci] = common::Vec3(fx, fy, fz);
    }
    ux[i] = nvx;
    uy[i] = nvy;
    uz[i] = nvz;
    qx[i] = xi + nvx * dt;
    qy[i] = yi + nvy * dt;
    qz[i] = zi + nvz * dt;
    const double wxi = wx[i], wyi = wy[i], wzi = wz[i];
    const double nwx = wxi * damp + mx * iJ * dt;
    const double nwy = wyi * damp + my * iJ * dt;
    const double nwz = wzi * damp + mz * iJ * dt;
    ox[i] = nwx;
    oy[i] = nwy;
    oz[i] = nwz;
    if (track) {
      const double m = mass_[ti], J = 1.0 / iJ;
      const double sx = 0.5 * (vxi + nvx), sy = 0.5 * (vyi + nvy), sz = 0.5 * (vzi + nvz);
      const double gx = 0.5 * (wxi + nwx), gy = 0.5 * (wyi + nwy), gz = 0.5 * (wzi + nwz);
      // Leapfrog's exact discrete energy uses the product of the half-step
      // velocities: E = 1/2 m v^{n-1/2} . v^{n+1/2} + U(x^n).
      kinetic_[i] = 0.5 * m * (vxi * nvx + vyi * nvy + vzi * nvz) + 0.5 * J * (wxi * nwx + wyi * nwy + wzi * nwz);
      // Work over the last drift, (f^{n-1} + f^n)/2 . (x^n - x^{n-1}): with the
      // kinetic energy above the balance is exact for a linear system.
      if (li >= 0) {
        const common::Vec3& A = model_.loaded.area[li];
        work_[i] = 0.5 * (p_prev + p_load) * (A.x() * vxi + A.y() * vyi + A.z() * vzi) * dt;
      } else {
        work_[i] = 0.0;
      }
      damp_[i] = options_.damping * dt * (m * (sx * sx + sy * sy + sz * sz) + J * (gx * gx + gy * gy + gz * gz));
    }
  }
}

void Simulation::step() {
  const bool fluid = fluid_on_;
  if (periodic_) {
    if (fluid) { predictor<true, true>(); pair_forces<true>(); integrate<true, true>(); }
    else { predictor<true, false>(); pair_forces<true>(); integrate<true, false>(); }
  } else {
    if (fluid) { predictor<false, true>(); pair_forces<false>(); integrate<false, true>(); }
    else { predictor<false, false>(); pair_forces<false>(); integrate<false, false>(); }
  }
  if (track_energy_) {
    kinetic_now_ = deterministic_sum(n_, [&](std::int64_t i) { return kinetic_[i]; });
    work_total_ += deterministic_sum(n_, [&](std::int64_t i) { return work_[i]; });
    damping_total_ += deterministic_sum(n_, [&](std::int64_t i) { return damp_[i]; });
  }
  if (filtration_) filtration_->advance(theta_.data(), zeta_.data(), track_energy_ ? &dissipation_total_ : nullptr);
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

std::array<double, 6> Simulation::stress(int i) const {
  // Recomputed from the pair state of the fields' level (buffer 1 - cur_ after
  // the swap is the old one; the new pair state is in cur_).
  const int c = cur_, o = 1 - cur_;
  const int K = K_, H = K_ / 2, n = n_;
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
    const double r = dv.norm();
    const common::Vec3 nv = dv / r;
    const common::Vec3 F = model_.lattice.contact_area * (sn_[c][bi] * nv + common::Vec3(tx_[c][bi], ty_[c][bi], tz_[c][bi]));
    const double q = 0.5 * r;
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
  const int c = cur_, n = n_, H = K_ / 2;
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
      const double d = sn_[c][bi] - beta;
      const double t2 = tx_[c][bi] * tx_[c][bi] + ty_[c][bi] * ty_[c][bi] + tz_[c][bi] * tz_[c][bi];
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

}  // namespace arthrosim::shockwave
