#pragma once
// Explicit time integration of an ensemble of poroelastic movable cellular
// automata (seed Appendix A). One Simulation holds everything that changes
// (positions, velocities, rotations, pair forces, pore fluid, stresses) for a
// constant Model.
//
// Per time step n -> n + 1 (velocity Verlet in leapfrog form, velocities at
// half steps, h = dt):
//  A. stress predictor: for every automaton i the volumetric strain increment
//     d theta_i = f_i (S/V) sum_j d r_ij w_i / (w_i + w_j), d r_ij =
//     n_ij . (v_j - v_i) h (the A8 split without the many-body term);
//     Biot pore pressure P_i = M_i (zeta_i - a_i theta_i) (A10, pore_fluid);
//     predicted mean stress increment d sigma_mean_i = K_i d theta_i -
//     a_i f_i dP_i (the equation of state); b_i = D_i d sigma_mean_i -
//     c_i a_i f_i dP_i (the many-body and pore terms of A7/A9).
//  B. pair forces: A8 solved for each pair (pair_law.h), tangential force
//     with the relative shear displacement at the contact point including
//     the automata's rotations, F_ij = S (sigma n + tau) (A3), moments
//     M_ij = q n x F^tau (A1, q = r/2, no bending-torsion moment K_ij);
//     each pair is updated once, by its owner (the automaton whose forward
//     direction it is), the other half takes the new pair state in a second
//     pass; averaged stress (A4), pressure (A5), von Mises stress (A6); kick
//     v += F/m h, omega += M/J h (A1, J = 2/5 m R^2 of the equivalent sphere);
//     drift x += v h.
//  C. filtration (A11-A12, filtration.h) over the step with theta fixed.
// f_i corrects the volumetric strain of an automaton with missing
// neighbours (free surface), see free_surface_factor below.
//
// The scheme is conservative: E_kin + E_pot (potential_energy) equals the
// work of the applied pressure minus the filtration dissipation up to the
// O(dt^2) error of the integrator (tests/shockwave/energy_test.cc).
//
// Determinism: every loop writes only its own automaton (and the bonds it
// owns: each pair's state is updated once, in place, by its owner; the other
// half reads the new state in the next pass); global sums use fixed blocks
// (reduce.h). Results are bit-identical for any number of OpenMP threads.
#include <cstdint>
#include <functional>
#include <array>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/mesh.h"
#include "shockwave/filtration.h"
#include "shockwave/model.h"
#include "shockwave/pair_law.h"

namespace arthrosim::shockwave {

/// Correction f of the predicted volumetric strain of automaton i for its
/// missing neighbours. The predictor sums the strains of the existing pairs,
/// theta_e = (S q/V) sum_existing eps_n; for a homogeneous strain
/// (S q/V) sum_all eps_n = theta, so theta_e = theta - (S q/V) eps : T with
/// T = sum_missing n n^T. The missing neighbours are taken as a traction-free
/// face with normal e = sum_missing n / |.| whose strain is
/// eps = alpha (I - e e^T) + beta e e^T, sigma_ee = 0 (beta = -2 lambda alpha /
/// (lambda + 2G)), and f = theta / theta_e. Exact for every traction-free
/// homogeneous state on the planar (001) faces of both packings (there T lies
/// in span{I, e e^T}); approximate at edges and corners. For one missing SC
/// neighbour f = 4G / (4G + lambda), LIGGGHTS-MCA's free-surface correction
/// of its mean stress predictor. `undrained`: use K_u (pore fluid on). 1 for
/// an automaton with all neighbours. A `loaded` automaton (model.loaded: its
/// missing neighbours are replaced by a pressure) takes the strain of a plane
/// wave entering through that face instead, uniaxial along e: f = 1 / (1 -
/// (S q/V) e.T.e) (2 for a face of either packing).
double free_surface_factor(const Model& model, int i, bool undrained, bool loaded = false);

struct SimulationOptions;

/// Stability limit of the explicit scheme for the tissues present in a
/// model: for each tissue, 2 / omega_max with omega_max the largest
/// eigenfrequency of a periodic 4 x 4 x 4 block of that tissue on the
/// model's lattice (power iteration on the linearised pair law, translations
/// and rotations, undrained where the pore fluid is on); the smallest over
/// the tissues [s]. For a p-wave-dominated tissue this is close to d / c_p;
/// tissues with G >~ K (cartilage, G 4.3 MPa > K 4.16 MPa) are limited by
/// the automata's rotations instead (FCC cartilage, drained: 0.5 d / c_p).
/// `limiting_tissue`, if not null, receives the name of the limiting tissue.
double critical_time_step(const Model& model, const SimulationOptions& options, std::string* limiting_tissue = nullptr);

/// Pair geometry (simulation.cc, pair_geometry):
enum class Geometry {
  /// Small strain: pair directions and lever arms of the rest lattice. The
  /// scheme is then exactly energy conserving and a pressure carried by the
  /// pairs has no geometric stiffness. For the knee (strains of a few per
  /// cent at most) the default: with the current directions, the pore
  /// pressure of the nearly incompressible undrained soft tissues (K_u / G up
  /// to 5600) buckles the lattice once it exceeds about G (0.43 MPa in the
  /// fibrous tissue; tests/shockwave/wave_speed_test.cc, StrongPulse...).
  kLinear,
  /// Current pair directions and distances (the MCA form of the seed; exact
  /// for large rotations).
  kNonlinear,
};

struct SimulationOptions {
  /// Many-body coefficient of A7 (pair_law.h). kHooke reproduces the input moduli.
  DForm d_form = DForm::kHooke;
  Geometry geometry = Geometry::kLinear;
  /// Effect pore_fluid: Biot coupling (A9-A10) in poroelastic tissues. Off:
  /// a single-phase (drained) elastic run, no fluid quantity is built.
  bool pore_fluid = true;
  /// Effect filtration: Darcy flow between automata (A11-A12). Needs pore_fluid.
  bool filtration = true;
  /// dt = safety * dt_crit, dt_crit the stability limit 2 / omega_max of the
  /// lattice (critical_time_step). Range (0, 1].
  double time_step_safety = 0.5;
  /// A fixed time step [s] instead (0 = automatic); must not exceed dt_crit.
  double fixed_time_step = 0.0;
  /// Internal (the stability probe itself): do not check fixed_time_step.
  bool skip_stability_check = false;
  /// Mass-proportional damping alpha [1/s] (v += -alpha v dt); 0 for waves,
  /// > 0 only for quasi-static loading (dynamic relaxation). Range [0, 0.5/dt].
  double damping = 0.0;
  /// Stability safety of the explicit filtration (filtration.h). Range (0, 1].
  double filtration_safety = 0.9;
};

/// Energies at the time of the fields [J].
struct EnergyBalance {
  double kinetic = 0.0;        ///< translation + rotation, 1/2 m v^{n-1/2} . v^{n+1/2}
  double potential = 0.0;      ///< stored in pairs, many-body term and pore fluid
  double external_work = 0.0;  ///< work of the applied pressure so far
  double dissipation = 0.0;    ///< by filtration so far
  double damping = 0.0;        ///< removed by the damping so far
  /// external_work - dissipation - damping - kinetic - potential
  double residual() const { return external_work - dissipation - damping - kinetic - potential; }
};

/// Everything a Simulation carries from one step to the next, for
/// checkpoints (pipelines/shockwave_checkpoint.h): restoring it into a
/// Simulation built from the same model, options and load continues the run
/// bit for bit (tests/shockwave/simulation_state_test.cc). Held: the step
/// count and which half of the double buffers is current; positions,
/// velocities and angular velocities of both halves; the pair state (normal
/// stress and tangential force of each bond); volumetric strain, fluid
/// content zeta and pore pressure; the fields of the last step (pressure,
/// distortional strain, constraint forces); the peaks; the energy
/// bookkeeping (per automaton and the accumulated totals). Not held, because
/// every step rewrites them before reading them: the predictor's b_, the
/// loaded automata's peaks before the step, the row sweep's per-thread ring
/// and accumulators, and the filtration term's stage buffers (FiltrationTerm
/// keeps nothing between steps: zeta lives here). A member added to
/// Simulation that carries over between steps belongs in state_arrays().
struct SimulationState {
  std::int64_t steps = 0;
  int buffer = 0;  ///< index of the current half of the double buffers
  /// Energy bookkeeping: the kinetic energy of the last step and the totals
  /// of work, filtration dissipation and damping [J].
  double kinetic = 0.0, work = 0.0, dissipation = 0.0, damping = 0.0;
  /// The state arrays by name, in a fixed order (an array that is empty in
  /// this run, e.g. zeta without pore fluid, is left out).
  std::vector<std::pair<std::string, std::vector<double>>> arrays;
};

class Simulation {
 public:
  /// `load(t)`: pressure on model.loaded at time t [Pa] (empty: no load).
  Simulation(const Model& model, const SimulationOptions& options, std::function<double(double)> load = {});
  ~Simulation();
  Simulation(const Simulation&) = delete;
  Simulation& operator=(const Simulation&) = delete;

  const Model& model() const { return model_; }
  const SimulationOptions& options() const { return options_; }
  double time_step() const { return dt_; }
  /// The stability limit (critical_time_step) [s] and its tissue.
  double critical_time_step() const { return dt_crit_; }
  const std::string& critical_tissue() const { return dt_crit_tissue_; }
  /// The fastest p-wave speed of the tissues present (undrained where the
  /// pore fluid is on) [m/s] and its tissue; d / c_max is the textbook
  /// estimate of the stability limit (reported next to dt_crit).
  double fastest_p_wave() const { return c_max_; }
  const std::string& fastest_p_wave_tissue() const { return c_max_tissue_; }
  bool pore_fluid() const { return fluid_on_; }
  /// The filtration term, or nullptr when it was not built.
  const FiltrationTerm* filtration() const { return filtration_.get(); }

  /// One time step (levels n -> n + 1); fields then belong to level n.
  void step();
  void run(std::int64_t steps);
  std::int64_t steps_done() const { return steps_; }
  /// Time of the current fields (level n = steps_done - 1) [s].
  double time() const { return (static_cast<double>(steps_) - 1.0) * dt_; }

  // Fields at the time of the last step (per automaton).
  /// Hydrostatic pressure P = -sigma_mean (A5), compression > 0 [Pa].
  const std::vector<double>& pressure() const { return pressure_; }
  /// Von Mises stress (A6) of automaton i from its averaged stress (A4) [Pa].
  double von_mises(int i) const;
  /// Distortional strain: the equivalent (von Mises) strain sqrt(2/3 e:e) of
  /// the deviatoric part e of the automaton's averaged strain tensor
  /// eps = (3/N) sum_j s_ij sym(g_j (x) n_j), g_j = e_n n + l/d the pairs'
  /// strain vectors (normal strain (r - d)/d, relative shear displacement l =
  /// tau (w_i + w_j)), s_ij = 2 w_i / (w_i + w_j) the automaton's share of
  /// the pair's deformation (A8's split by compliance; 1 within a tissue);
  /// exact for a homogeneous strain, where it equals
  /// sigma_eq / (3G) of A6. (In a steep pressure gradient of a nearly
  /// incompressible undrained tissue A4's averaged stress carries a spurious
  /// deviatoric part of order d |grad P|, which sigma_eq / (3G) would divide
  /// by G << K_u; tests/shockwave/wave_speed_test.cc) [-].
  const std::vector<double>& distortional_strain() const { return distortional_; }
  /// Pore fluid pressure (gauge) [Pa]; all 0 without pore fluid.
  const std::vector<double>& pore_pressure() const { return pore_; }
  /// Volumetric strain theta [-].
  const std::vector<double>& volumetric_strain() const { return theta_; }
  /// Peaks over the run so far: max P, max distortional strain, max pore pressure.
  const std::vector<double>& peak_pressure() const { return peak_pressure_; }
  const std::vector<double>& peak_distortional_strain() const { return peak_distortional_; }
  const std::vector<double>& peak_pore_pressure() const { return peak_pore_; }
  /// Averaged stress tensor (A4) of automaton i at the fields' time, rows
  /// xx yy zz xy yz xz [Pa] (computed on demand).
  std::array<double, 6> stress(int i) const;

  /// Position of automaton i at the fields' time [m].
  common::Vec3 position(int i) const;
  common::Vec3 displacement(int i) const { return position(i) - model_.position(i); }
  /// Velocity at the fields' time (mean of the two half steps) [m/s].
  common::Vec3 velocity(int i) const;
  /// Velocity and angular velocity of the last half step [m/s], [rad/s].
  common::Vec3 half_step_velocity(int i) const;
  common::Vec3 half_step_angular_velocity(int i) const;
  /// Internal (pair) force on each constrained automaton at the fields'
  /// time, in the order of model.constraints [N]; the reaction of the
  /// support is its negative.
  const std::vector<common::Vec3>& constraint_forces() const { return constraint_force_; }

  /// Turns on the bookkeeping of the energy balance (kinetic energy and the
  /// work of the load each step; costs a few percent).
  void track_energy(bool on) { track_energy_ = on; }
  /// The balance at the fields' time (potential energy computed now).
  EnergyBalance energy() const;
  /// Total linear momentum sum m v at the last half step [kg m/s].
  common::Vec3 linear_momentum() const;
  /// Total angular momentum about the origin, sum (x m v + J omega), with
  /// positions and velocities of the last half step [kg m^2/s].
  common::Vec3 angular_momentum() const;

  /// The state after the steps done (SimulationState).
  SimulationState state() const;
  /// Continues from `state`, taken from a Simulation of the same model,
  /// options and load. std::runtime_error naming the array when one of this
  /// run's arrays is missing, of another length, or one is unknown.
  void restore(const SimulationState& state);

  /// Sets the initial velocity of every automaton (before the first step).
  void set_velocity(int i, const common::Vec3& v);
  void set_angular_velocity(int i, const common::Vec3& w);

 private:
  struct Row {
    int start, len;  ///< automata [start, start + len) share grid j, k
  };
  struct Run {
    int a, b, off;  ///< automata [a, b) of a row have their neighbour at i + off
  };
  void build_rows();
  template <bool kPeriodic, bool kFluid, bool kLinear>
  void step_rows();
  double potential_energy() const;
  /// The members SimulationState holds (name, array), in its order; the
  /// constraint forces separately (Vec3).
  std::vector<std::pair<std::string, std::vector<double>*>> state_arrays();

  const Model& model_;
  SimulationOptions options_;
  std::function<double(double)> load_;
  bool fluid_on_ = false;
  double dt_ = 0.0, c_max_ = 0.0, dt_crit_ = 0.0;
  std::string c_max_tissue_, dt_crit_tissue_;
  std::int64_t steps_ = 0;
  int cur_ = 0;  ///< index of the current buffers
  int n_ = 0, K_ = 0;
  bool periodic_ = false;
  common::Vec3 period_ = common::Vec3::Zero();

  // Per tissue.
  std::vector<double> w_, D_, K_bulk_, a_, M_, pore_coef_, inv3G_, mass_, inv_mass_, inv_inertia_;
  std::vector<std::uint8_t> poro_;
  // Per automaton.
  std::vector<double> f_, wa_;  ///< free-surface factor, compliance R/(2G) per automaton
  std::vector<double> strain_scale_;  ///< 3 / (number of pairs)
  std::vector<std::int32_t> constraint_of_;
  std::vector<double> loaded_peaks_;  ///< peaks of the loaded automata before the step
  std::vector<Row> rows_;
  std::vector<Run> runs_;  ///< [row * K + direction]
  std::vector<std::int32_t> extra_;        ///< automata of the general path, by row and direction
  std::vector<std::int32_t> extra_start_;  ///< [row * K + direction] -> first index into extra_
  int max_row_ = 0;
  /// Largest row distance of a bond (step_rows).
  int lag_ = 0;
  /// Accumulators of step_rows (F (3), M (3), trace of the A4 sum
  /// (1), strain sum (6)) per thread: a ring of ring_cap_ automata (row r at
  /// ring_off_[r]) and the rows that wait for the other threads (scratch, not
  /// state: rewritten every step).
  int ring_cap_ = 0;
  std::vector<std::int32_t> ring_off_;
  std::vector<std::vector<double>> thread_acc_;
  /// Loaded automata (index into model.loaded.automata) and constraints
  /// (index into model.constraints) by row: [start[row], start[row + 1]).
  std::vector<std::int32_t> row_loaded_start_, row_loaded_, row_constraint_start_, row_constraint_;
  std::vector<double> inv3G_a_, inv_mass_a_, inv_inertia_a_;  ///< per automaton
  std::vector<std::uint8_t> drained_;
  std::vector<double> pos_[2][3], vel_[2][3], omg_[2][3];
  std::vector<double> sn_, tx_, ty_, tz_;  ///< pair state [s * n + owner], s < K/2 (in place)
  std::vector<double> theta_, zeta_, pore_, b_;
  std::vector<double> pressure_, distortional_;
  std::vector<double> peak_pressure_, peak_distortional_, peak_pore_;
  std::vector<common::Vec3> constraint_force_;
  std::unique_ptr<FiltrationTerm> filtration_;
  // Energy bookkeeping.
  bool track_energy_ = false;
  std::vector<double> kinetic_, work_, damp_;
  double kinetic_now_ = 0.0, work_total_ = 0.0, dissipation_total_ = 0.0, damping_total_ = 0.0;
};

}  // namespace arthrosim::shockwave
