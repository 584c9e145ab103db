// Stability suite, COMAK (issue 8): hard frames for the per-frame COMAK NLP
// (musculoskeletal/comak.h) on the bundled coarse knee model. Each case
// asserts finite values, an explicit converged status, equilibrium residuals
// within the solver's tolerances (checked again independently of the solver's
// own report) and bounded forces. A trial with spikes and a NaN is run
// through the library and through the arthrosim-comak executable.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "common/error.h"
#include "common/hdf5.h"

#include "musculoskeletal/comak.h"
#include "musculoskeletal/gait_trial.h"
#include "musculoskeletal/knee_loads.h"
#include "musculoskeletal/model_io.h"
#include "tests/musculoskeletal/comak_fixtures.h"

namespace msk = arthrosim::musculoskeletal;

namespace {
using msk::test::coarse_model;
using msk::test::deg;
using msk::test::settled_pose;
using msk::test::trial_loads;

constexpr double kBodyMass = 61.0;  // [kg], the subject of the issue
constexpr double kGravity = 9.81;   // [m/s^2]
constexpr double kBodyWeight = kBodyMass * kGravity;  // [N]


// A frame with the trial's hip/ankle angles and load of `trial_frame`
// (stance), the knee flexion replaced by `flexion`.
msk::ComakFrameInput trial_frame_at(int trial_frame, double flexion) {
  auto in = msk::comak_frame_inputs(trial_loads(), trial_frame, trial_frame, 1).front();
  in.knee_flexion = flexion;
  return in;
}

// Solves the frame from q_start (settle pose if empty) and checks the
// stability contract. Returns the result for case-specific checks.
// With must_converge false the frame may be reported failed, but the report
// must be consistent (converged exactly when Ipopt succeeded and the
// residuals are within tolerance; failed frames say so in their message).
msk::ComakFrameResult solve_and_check(const char* name, const msk::ComakFrameInput& in,
                                      Eigen::VectorXd q_start = {},
                                      double* contact_sum_out = nullptr, bool must_converge = true) {
  const auto& m = coarse_model();
  msk::ComakOptions o;
  msk::ComakProblem p(m, o);
  const int nm = static_cast<int>(m.muscles.size());
  if (q_start.size() == 0) q_start = settled_pose(p, in.knee_flexion, o.activation_min);
  auto d = msk::make_data(m);
  const auto r = msk::solve_comak_frame(p, d, in, q_start,
                                        Eigen::VectorXd::Constant(nm, o.activation_min));
  std::printf("[%s] %s\n", name, r.message.c_str());
  {  // where the solve left the joint (secondary coordinates name the patella's place)
    std::string qs;
    for (int j : p.free_coordinates()) {
      char b[64];
      std::snprintf(b, sizeof b, " %s=%.4g", m.tree.coordinates[j].c_str(), r.q[j]);
      qs += b;
    }
    std::printf("[%s] q:%s\n", name, qs.c_str());
  }

  // Finite values everywhere.
  EXPECT_TRUE(r.q.allFinite()) << name;
  EXPECT_TRUE(r.activations.allFinite()) << name;
  EXPECT_TRUE(std::isfinite(r.objective)) << name;
  EXPECT_TRUE(std::isfinite(r.max_force_residual) && std::isfinite(r.max_moment_residual)) << name;
  const Eigen::VectorXd res = p.residual(d, in, r.q, r.activations, {});
  EXPECT_TRUE(res.allFinite()) << name;
  const bool within = r.max_force_residual <= o.force_tolerance &&
                      r.max_moment_residual <= o.force_tolerance * o.length_scale;
  if (must_converge || r.status == msk::ComakFrameStatus::kConverged) {
    // Explicit status: these frames must converge.
    EXPECT_EQ(r.status, msk::ComakFrameStatus::kConverged) << name << ": " << r.message;
    // Equilibrium within the solver's tolerances (0.1 N; 0.1 N x 0.03 m for
    // moments), as reported and recomputed independently at the solution.
    EXPECT_TRUE(within) << name;
    for (int k = 0; k < res.size(); ++k) {
      const double tol = p.revolute(k) ? o.force_tolerance * o.length_scale : o.force_tolerance;
      EXPECT_LE(std::abs(res[k]), tol) << name << ": free coordinate row " << k;
    }
  } else {
    // Failed, and says so: the message names the status, and the reported
    // largest residual is the one recomputed here (nothing hidden).
    EXPECT_NE(r.message.find("failed"), std::string::npos) << r.message;
    double force_max = 0, moment_max = 0;
    for (int k = 0; k < res.size(); ++k) {
      double& m = p.revolute(k) ? moment_max : force_max;
      m = std::max(m, std::abs(res[k]));
    }
    EXPECT_NEAR(force_max, r.max_force_residual, 1e-9 * (1 + force_max)) << name;
    EXPECT_NEAR(moment_max, r.max_moment_residual, 1e-9 * (1 + moment_max)) << name;
  }
  // Bounded forces: activations in [a_min, 1] (muscle force <= F_max);
  // the net tibiofemoral + patellar contact force below 20 body weights (in
  // vivo peaks are 2.5-3.5 BW in gait; 5 BW of applied axial load must not
  // be amplified by an order of magnitude).
  EXPECT_GE(r.activations.minCoeff(), o.activation_min - 1e-6) << name;
  EXPECT_LE(r.activations.maxCoeff(), 1.0 + 1e-6) << name;
  msk::evaluate_forces(m, d, r.q, Eigen::VectorXd::Zero(m.num_coordinates()), r.activations,
                       o.forces);
  double contact_total = 0.0, contact_sum = 0.0;
  for (const auto& c : d.contacts) {
    EXPECT_TRUE(c.result.force_on_target_W.allFinite()) << name;
    contact_total = std::max(contact_total, c.result.force_on_target_W.norm());
    contact_sum += c.result.force_on_target_W.norm();
  }
  double ligament_max = 0.0;
  for (const auto& lig : d.ligaments)
    for (const auto& b : lig) ligament_max = std::max(ligament_max, std::abs(b.force.total));
  std::printf("[%s] load F_T = (%.1f, %.1f, %.1f) N, M_T = (%.2f, %.2f, %.2f) N m; largest pair "
              "contact force %.1f N (%.2f BW), sum over %zu pairs %.1f N (%.2f BW), largest bundle "
              "force %.1f N, max activation %.3f\n",
              name, in.F_ext_T.x(), in.F_ext_T.y(), in.F_ext_T.z(), in.M_ext_T.x(), in.M_ext_T.y(),
              in.M_ext_T.z(), contact_total, contact_total / kBodyWeight, d.contacts.size(),
              contact_sum, contact_sum / kBodyWeight, ligament_max,
              r.activations.maxCoeff());
  EXPECT_LE(contact_total, 20 * kBodyWeight) << name;
  if (contact_sum_out) *contact_sum_out = contact_sum;
  EXPECT_LE(ligament_max, 20 * kBodyWeight) << name;
  return r;
}
}  // namespace

// Deep flexion 120 deg (inside the model's flexion limits, -20..140 deg),
// loaded as in a deep squat: 1 body weight of axial compression along the
// tibia's long axis (+Y, proximal), no moment. The same flexion with no load
// or with the synthetic trial's stance loads is not in this suite.
// Disabled from the fourth to the eighth session: with OpenBLAS's AVX2
// (Haswell) kernels all three attempts of the time failed (1200 iterations,
// residual 2.62 N), with its Sandybridge kernels attempt 2 "converged" with
// the patella 50 mm lateral on its joint limit. Both were the solver's doing,
// not the model's: from the settle pose Ipopt's first steps carry the
// patella out of its groove. Attempt 4 (step control by moving limits,
// ComakOptions::move_limit_m/_rad; docs/comak.md) and the re-solve of a
// solution on a joint limit find, under the default (AVX2), Haswell and
// Sandybridge kernels, the same pose (measured 2026-12-03: objective
// 6.125e-5 / 6.127e-5 m^3, patella flexed 85 deg, pf_tz within 0.01 mm of
// the groove centre), a lower objective than the dislocated one (9.36e-5).
// So the case also asserts the patella stays in its groove: no secondary
// coordinate on a joint limit and |pf_tz| below 5 mm (the groove's
// cartilage spans |z| < 12 mm, groove_region in pipelines/knee_generator.cc).
TEST(ComakStability, DeepFlexion120Deg) {
  msk::ComakFrameInput in;
  in.knee_flexion = deg(120);
  in.F_ext_T = Eigen::Vector3d(0, kBodyWeight, 0);
  const auto r = solve_and_check("flexion 120 deg, 1 BW axial", in);
  const auto& m = coarse_model();
  msk::ComakProblem p(m, {});
  for (int k : p.secondary_coordinates()) {
    const auto& j = *std::find_if(m.tree.joints.begin(), m.tree.joints.end(),
                                  [&](const msk::Joint& jt) { return jt.coordinate == k; });
    const double margin = 1e-3 * (j.upper - j.lower);
    EXPECT_GT(r.q[k], j.lower + margin) << m.tree.coordinates[k] << " on its lower joint limit";
    EXPECT_LT(r.q[k], j.upper - margin) << m.tree.coordinates[k] << " on its upper joint limit";
  }
  const int pf_tz = m.tree.coordinate_index("pf_tz");
  ASSERT_GE(pf_tz, 0);
  EXPECT_LT(std::abs(r.q[pf_tz]), 5e-3) << "patella left its groove";
}

// The same frame with the part of the contract that does not need it to
// converge, kept from the time the case above was disabled: finite values,
// an explicit status consistent with the residuals, activations in their
// bounds, contact and ligament forces below 20 BW.
TEST(ComakStability, DeepFlexion120DegReportsItsStatus) {
  msk::ComakFrameInput in;
  in.knee_flexion = deg(120);
  in.F_ext_T = Eigen::Vector3d(0, kBodyWeight, 0);
  solve_and_check("flexion 120 deg, 1 BW axial (status)", in, {}, nullptr, false);
}

// Slight hyperextension, -5 deg.
TEST(ComakStability, Hyperextension5Deg) {
  const auto in = trial_frame_at(20, deg(-5));
  solve_and_check("hyperextension -5 deg", in);
}

// Zero external load (no force, no moment): muscles and ligaments alone.
TEST(ComakStability, ZeroExternalLoad) {
  msk::ComakFrameInput in;
  in.index = 0;
  in.knee_flexion = deg(30);
  const auto r = solve_and_check("zero load", in);
  // With nothing to balance, no muscle needs to be strongly active.
  EXPECT_LE(r.activations.maxCoeff(), 0.5);
}

// Five body weights of axial compression along the tibia's long axis (+Y,
// proximal: pushing the tibia into the femur), 61 kg subject.
TEST(ComakStability, FiveBodyWeightsAxial) {
  msk::ComakFrameInput in;
  in.index = 0;
  in.knee_flexion = deg(15);
  in.F_ext_T = Eigen::Vector3d(0, 5 * kBodyWeight, 0);
  double contact_sum = 0.0;
  solve_and_check("5 BW axial", in, {}, &contact_sum);
  // The axial load goes through the joint: ligaments are nearly slack in this
  // pose and activations stay near a_min, so the contact pairs must carry at
  // least the applied 5 BW (muscle tone only adds compression); 5 % margin
  // for the oblique ligament and muscle lines of action.
  EXPECT_GE(contact_sum, 0.95 * 5 * kBodyWeight);
}

// Deliberately bad initial guess: every secondary coordinate offset from the
// settle pose by 4 mm (translations) or 4 deg (rotations).
TEST(ComakStability, BadInitialGuess) {
  const auto& m = coarse_model();
  msk::ComakProblem p(m, {});
  const auto in = trial_frame_at(20, deg(20));
  const Eigen::VectorXd q0 = msk::test::offset_settled_pose(p, in.knee_flexion, 4e-3, deg(4));
  // Only the stability contract is asserted: measured, this start converges
  // to a different local optimum (objective 6.2e-4 m^3) than the start from
  // the settle pose (1.05e-4 m^3); the NLP is non-convex through contact.
  solve_and_check("bad initial guess", in, q0);
}

// ------------------------------------------------ a trial with spikes and a NaN

namespace {
namespace fs = std::filesystem;

// A copy of the bundled SYNTHETIC trial in the build tree, to be edited.
fs::path scratch_trial(const std::string& name) {
  const fs::path dir = fs::path(ARTHROSIM_BINARY_DIR) / "test_scratch" / "comak_stability" / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  for (const char* f : {"trial.yaml", "ik.mot", "grf.mot"})
    fs::copy_file(msk::test::source(std::string("data/trials/synthetic_gait/") + f), dir / f);
  return dir;
}

// Sets the value of `column` in the data row whose time is `time` (s) of a
// .mot file: value = f(old value). Returns the old value. Fails the test if
// the row or column is missing.
template <typename F>
double edit_mot(const fs::path& file, double time, const std::string& column, F f) {
  std::ifstream in(file);
  std::vector<std::string> lines;
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  size_t label = 0;
  while (label < lines.size() && lines[label] != "endheader") ++label;
  ++label;
  auto split = [](const std::string& l) {
    std::vector<std::string> v;
    std::stringstream ss(l);
    for (std::string x; std::getline(ss, x, '\t');) v.push_back(x);
    return v;
  };
  const auto labels = split(lines.at(label));
  const size_t c = std::find(labels.begin(), labels.end(), column) - labels.begin();
  EXPECT_LT(c, labels.size()) << column;
  double old = std::nan("");
  bool found = false;
  for (size_t r = label + 1; r < lines.size(); ++r) {
    auto v = split(lines[r]);
    if (std::abs(std::stod(v.at(0)) - time) > 1e-9) continue;
    old = std::stod(v.at(c));
    std::ostringstream x;
    x.precision(10);
    x << f(old);
    v.at(c) = x.str();
    std::string joined;
    for (size_t k = 0; k < v.size(); ++k) joined += (k ? "\t" : "") + v[k];
    lines[r] = joined;
    found = true;
  }
  EXPECT_TRUE(found) << file << ": no row at t = " << time;
  std::ofstream out(file);
  for (const auto& l : lines) out << l << "\n";
  return old;
}

// The spikes of both tests: one sample of the vertical ground reaction at 4x
// (a force-plate glitch; with the unfiltered GRF (gait_trial.h) it reaches
// the knee load unchanged) and one sample of the knee angle 40 deg too high
// (low-pass filtered with the kinematics).
constexpr double kGrfSpikeTime = 0.12, kAngleSpikeTime = 0.14;  // [s]
void add_spikes(const fs::path& dir) {
  edit_mot(dir / "grf.mot", kGrfSpikeTime, "ground_force_vy", [](double v) { return 4.0 * v; });
  edit_mot(dir / "ik.mot", kAngleSpikeTime, "knee_angle_r", [](double v) { return v + 40.0; });
}

// Checks one frame of a run: finite values and an explicit status; a frame
// reported converged satisfies equilibrium when re-evaluated here.
void check_frame(const msk::ComakProblem& p, const msk::ComakFrameInput& in,
                 const msk::ComakFrameResult& r) {
  const auto& o = p.options();
  SCOPED_TRACE(r.message);
  EXPECT_TRUE(r.q.allFinite());
  EXPECT_TRUE(r.activations.allFinite());
  EXPECT_TRUE(std::isfinite(r.objective));
  EXPECT_TRUE(std::isfinite(r.max_force_residual) && std::isfinite(r.max_moment_residual));
  EXPECT_TRUE(r.status == msk::ComakFrameStatus::kConverged ||
              r.status == msk::ComakFrameStatus::kFailed);
  EXPECT_NE(r.message.find(msk::to_string(r.status)), std::string::npos);
  EXPECT_GE(r.activations.minCoeff(), o.activation_min - 1e-6);
  EXPECT_LE(r.activations.maxCoeff(), 1.0 + 1e-6);
  if (r.status != msk::ComakFrameStatus::kConverged) return;
  auto d = msk::make_data(p.model());
  const Eigen::VectorXd res = p.residual(d, in, r.q, r.activations, r.reserves);
  for (int k = 0; k < res.size(); ++k)
    EXPECT_LE(std::abs(res[k]), p.revolute(k) ? o.force_tolerance * o.length_scale : o.force_tolerance)
        << "row " << k;
}
}  // namespace

// Spikes in a load and an angle channel: every frame ends finite with an
// explicit status, and the run recovers after the spikes.
TEST(ComakStability, SpikyTrialRunsWithExplicitFrameStatus) {
  const fs::path dir = scratch_trial("spikes");
  add_spikes(dir);
  const auto trial = msk::load_gait_trial((dir / "trial.yaml").string());
  const auto loads = msk::compute_knee_loads(trial, msk::leg_model_for_trial(trial));
  const auto& clean = trial_loads();
  // The spikes reach the knee loads (else this test could not fail).
  const int g = static_cast<int>(std::lround(kGrfSpikeTime * 100)), k = static_cast<int>(std::lround(kAngleSpikeTime * 100));
  const double dF = (loads.F_ext_T.row(g) - clean.F_ext_T.row(g)).norm();
  const double dq = std::abs(loads.knee_flexion[k] - clean.knee_flexion[k]);
  std::printf("[spikes] knee load change at frame %d: %.0f N (%.2f BW); knee flexion change at frame %d: %.2f deg\n",
              g, dF, dF / kBodyWeight, k, dq * 180 / std::numbers::pi);
  EXPECT_GT(dF, 1.5 * kBodyWeight);
  EXPECT_GT(dq, deg(2));

  const auto& m = coarse_model();
  msk::ComakProblem p(m, {});
  const auto frames = msk::comak_frame_inputs(loads, 10, 17, 1);
  std::vector<msk::ComakFrameResult> results;
  const auto s = msk::run_comak(p, frames, [&](const auto& f, const auto& r, const auto&) {
    check_frame(p, f, r);
    results.push_back(r);
  });
  for (const auto& r : results) std::printf("[spikes] %s\n", r.message.c_str());
  ASSERT_EQ(results.size(), frames.size());
  EXPECT_EQ(s.frames, static_cast<int>(frames.size()));
  EXPECT_EQ(s.converged + s.failed, s.frames);
  EXPECT_TRUE(s.stopped.empty());
  // Recovery: the last two frames (after both spikes) converge.
  EXPECT_EQ(results.end()[-1].status, msk::ComakFrameStatus::kConverged);
  EXPECT_EQ(results.end()[-2].status, msk::ComakFrameStatus::kConverged);
}

// A NaN in the trial (library): the run solves the frames before it and
// stops at the first frame it cannot compute, naming it and the file, line
// and column of the value.
TEST(ComakStability, NanInTrialStopsAtItsFrame) {
  const fs::path dir = scratch_trial("nan_library");
  add_spikes(dir);
  edit_mot(dir / "ik.mot", 0.15, "knee_angle_r", [](double) { return std::nan(""); });
  // Without truncate_at_non_finite the trial is rejected naming file and line
  // (ik.mot: 9 header/label lines, t = 0.15 s is data row 15 -> line 25).
  try {
    msk::load_gait_trial((dir / "trial.yaml").string());
    ADD_FAILURE() << "expected InputError";
  } catch (const arthrosim::common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("ik.mot:25: error: non-finite value in column 'knee_angle_r'"),
              std::string::npos) << e.what();
  }
  msk::GaitTrialOptions to;
  to.truncate_at_non_finite = true;
  const auto trial = msk::load_gait_trial((dir / "trial.yaml").string(), to);
  ASSERT_TRUE(trial.truncated.has_value());
  EXPECT_EQ(trial.truncated->frame, 15);
  EXPECT_EQ(trial.num_samples(), 15);
  EXPECT_EQ(trial.truncated->full_samples, 115);
  EXPECT_TRUE(trial.q.allFinite() && trial.qd.allFinite() && trial.qdd.allFinite());
  const auto loads = msk::compute_knee_loads(trial, msk::leg_model_for_trial(trial));
  const auto frames = msk::comak_frame_inputs(loads, 12, 20, 1);
  ASSERT_EQ(frames.size(), 4u);  // 12, 13, 14 and the stop frame 15
  EXPECT_FALSE(frames.back().invalid_input.empty());

  const auto& m = coarse_model();
  msk::ComakProblem p(m, {});
  std::vector<int> solved;
  try {
    msk::run_comak(p, frames, [&](const auto& f, const auto& r, const auto&) {
      check_frame(p, f, r);
      solved.push_back(f.index);
    });
    ADD_FAILURE() << "expected ComakRunStopped";
  } catch (const msk::ComakRunStopped& e) {
    const std::string w = e.what();
    std::printf("[nan] %s\n", w.c_str());
    EXPECT_EQ(e.frame, 15);
    EXPECT_NE(w.find("COMAK frame 15 (t = 0.15 s)"), std::string::npos) << w;
    EXPECT_NE(w.find("ik.mot:25"), std::string::npos) << w;
    EXPECT_NE(w.find("'knee_angle_r'"), std::string::npos) << w;
    EXPECT_EQ(e.summary.frames, 3);
    EXPECT_EQ(e.summary.stopped, w);
  }
  EXPECT_EQ(solved, (std::vector<int>{12, 13, 14}));

  // A NaN produced inside the knee loads (not from a file) stops the same
  // way at its frame.
  msk::KneeLoads bad = trial_loads();
  bad.M_ext_T(13, 2) = std::nan("");
  solved.clear();
  try {
    msk::run_comak(p, msk::comak_frame_inputs(bad, 12, 14, 1),
                   [&](const auto& f, const auto&, const auto&) { solved.push_back(f.index); });
    ADD_FAILURE() << "expected ComakRunStopped";
  } catch (const msk::ComakRunStopped& e) {
    EXPECT_NE(std::string(e.what()).find("COMAK frame 13"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("M_ext_T"), std::string::npos) << e.what();
  }
  EXPECT_EQ(solved, (std::vector<int>{12}));
}

// The same trial through the executable: non-zero exit, the message names
// the frame, file and column, and the frames before it are readable in the
// kinematics file <out>.partial (with the `stopped` attribute).
TEST(ComakStability, NanInTrialStopsArthrosimComak) {
  const fs::path dir = scratch_trial("nan_executable");
  add_spikes(dir);
  edit_mot(dir / "grf.mot", 0.16, "ground_force_vx", [](double) { return std::nan(""); });
  const std::string exe = std::string(ARTHROSIM_BINARY_DIR) + "/bin/arthrosim-comak";
  ASSERT_TRUE(fs::exists(exe)) << exe << " not built";
  const fs::path out = dir / "kinematics.h5", log = dir / "stderr.txt";
  fs::remove(out);
  const std::string cmd = exe + " --quiet --model " +
                          msk::test::source("data/models/knee_parametric/knee_coarse.urdf") +
                          " --trial " + dir.string() + " --out " + out.string() +
                          " --first-frame 11 --last-frame 30 2> " + log.string() + " > /dev/null";
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1);
  std::ifstream in(log);
  const std::string err((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::printf("[nan, arthrosim-comak] exit %d, stderr:\n%s", WEXITSTATUS(status), err.c_str());
  EXPECT_NE(err.find("COMAK frame 16 (t = 0.16 s)"), std::string::npos) << err;
  EXPECT_NE(err.find("grf.mot:26"), std::string::npos) << err;
  EXPECT_NE(err.find("'ground_force_vx'"), std::string::npos) << err;

  // A stopped run stays under its partial name (common/output_file.h).
  EXPECT_FALSE(fs::exists(out));
  arthrosim::common::H5File f(out.string() + ".partial", arthrosim::common::H5File::Mode::kRead);
  const Eigen::VectorXi idx = f.read_vector_int("/frame_index");
  ASSERT_EQ(idx.size(), 5);
  for (int i = 0; i < 5; ++i) EXPECT_EQ(idx[i], 11 + i);
  const Eigen::MatrixXd q = f.read_matrix("/coordinates/values");
  EXPECT_EQ(q.rows(), 5);
  EXPECT_TRUE(q.allFinite());
  EXPECT_EQ(f.attribute_int("/", "frames"), 5);
  EXPECT_NE(f.attribute_string("/", "stopped").find("COMAK frame 16"), std::string::npos);
  EXPECT_TRUE(fs::exists(dir / "kinematics_activations.sto"));
}

// arthrosim-comak SIGKILLed in the middle of a run: the frames it had
// written stay readable. The child runs with -v (one log line per solved
// frame, written before that frame is appended) and its stderr is read
// through a pipe; after the line of the 6th frame it gets SIGKILL, so frames
// 0-4 were appended (each append is flushed; common/hdf5.h). The file must
// open, every per-frame dataset must have the same number n >= 5 of complete
// rows (or one more: the kill may land between the datasets of a frame),
// and the rows must be the frames in order with finite values.
TEST(ComakStability, KilledArthrosimComakLeavesWrittenFramesReadable) {
  const std::string exe = std::string(ARTHROSIM_BINARY_DIR) + "/bin/arthrosim-comak";
  ASSERT_TRUE(fs::exists(exe)) << exe << " not built";
  const fs::path dir = fs::path(ARTHROSIM_BINARY_DIR) / "test_scratch" / "comak_stability" / "killed";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path out = dir / "kinematics.h5";
  const std::string model = msk::test::source("data/models/knee_parametric/knee_coarse.urdf");
  const std::string trial = msk::test::source("data/trials/synthetic_gait");
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    dup2(fds[1], 2);
    close(fds[0]);
    close(fds[1]);
    const int null = open("/dev/null", O_WRONLY);
    dup2(null, 1);
    execl(exe.c_str(), exe.c_str(), "-v", "--model", model.c_str(), "--trial", trial.c_str(), "--out",
          out.c_str(), "--first-frame", "20", "--last-frame", "80", static_cast<char*>(nullptr));
    _exit(127);
  }
  close(fds[1]);
  FILE* err = fdopen(fds[0], "r");
  ASSERT_NE(err, nullptr);
  char line[8192];
  int solved = 0;
  while (solved < 6 && std::fgets(line, sizeof line, err)) {
    const std::string l(line);
    if (l.find("COMAK frame ") != std::string::npos &&
        (l.find("): converged") != std::string::npos || l.find("): failed") != std::string::npos))
      ++solved;
  }
  kill(pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  std::fclose(err);
  ASSERT_EQ(solved, 6) << "the child ended before 6 frames";
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << "child was not killed, status " << status;

  // The killed run's frames are in <out>.partial (common/output_file.h).
  EXPECT_FALSE(fs::exists(out));
  arthrosim::common::H5File f(out.string() + ".partial", arthrosim::common::H5File::Mode::kRead);
  const Eigen::VectorXi idx = f.read_vector_int("/frame_index");
  const Eigen::VectorXd t = f.read_vector("/time");
  const Eigen::MatrixXd q = f.read_matrix("/coordinates/values");
  const Eigen::MatrixXd a = f.read_matrix("/muscles/activation");
  const Eigen::MatrixXd tf = f.read_matrix("/contact/tibiofemoral/force");
  const Eigen::VectorXi st = f.read_vector_int("/solver/status");
  const Eigen::Index n = std::min({idx.size(), t.size(), q.rows(), a.rows(), tf.rows(), st.size()});
  const Eigen::Index most = std::max({idx.size(), t.size(), q.rows(), a.rows(), tf.rows(), st.size()});
  std::printf("killed after 6 solved frames: %ld complete frames in the file (longest dataset %ld)\n",
              static_cast<long>(n), static_cast<long>(most));
  EXPECT_GE(n, 5);
  EXPECT_LE(most, n + 1);
  for (Eigen::Index i = 0; i < n; ++i) {
    EXPECT_EQ(idx[i], 20 + i);
    EXPECT_NEAR(t[i], 0.01 * (20 + i), 1e-9);
    EXPECT_TRUE(st[i] == 0 || st[i] == 1);
  }
  EXPECT_TRUE(q.topRows(n).allFinite());
  EXPECT_TRUE(a.topRows(n).allFinite());
  EXPECT_TRUE(tf.topRows(n).allFinite());
}
