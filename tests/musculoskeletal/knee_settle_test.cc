// Passive settle of the bundled parametric knee (issue 3, "Passive settle"):
// with the knee flexion held and muscles at the small tone COMAK settles with
// (0.02 F_max), the 11 secondary coordinates (5 tibiofemoral, 6
// patellofemoral) are solved for static equilibrium of ligaments, contact and
// tone (musculoskeletal/settle.h, pseudo-transient continuation).
//
// Tolerances (SettleOptions defaults, not loosened): max |Q| <= 0.1 N on the
// translations and <= 0.005 N m on the rotations. Why these are meaningful:
// the contact forces at equilibrium are 90..400 N per pair, so 0.1 N is
// <= 0.1 % of the loads; the softest direction measured at the solutions
// (knee_tz, dQ/dq ~ -2.8e4 N/m on the coarse model) turns 0.1 N into a 4 um
// position error, far below the 3 mm triangle edges of the coarse mesh;
// 0.005 N m is 0.1 N at a 50 mm lever (the joint size).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "common/error.h"
#include "musculoskeletal/model_io.h"
#include "musculoskeletal/settle.h"

namespace msk = arthrosim::musculoskeletal;

namespace {
std::string model_path(const char* name) {
  return std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/" + name;
}
constexpr double kDeg = std::numbers::pi / 180;

struct Pose6 {
  double flexion_deg, tx_mm, ty_mm, tz_mm, rotation_deg, adduction_deg;  // tibia in femur
  double pf_flexion_deg, pf_tx_mm, pf_ty_mm, pf_tz_mm, pf_rotation_deg, pf_tilt_deg;
};

Pose6 pose_of(const msk::Model& m, const Eigen::VectorXd& q) {
  auto c = [&](const char* n) { return q[m.tree.coordinate_index(n)]; };
  return {c("knee_flexion") / kDeg, c("knee_tx") * 1e3,      c("knee_ty") * 1e3,
          c("knee_tz") * 1e3,       c("knee_rotation") / kDeg, c("knee_adduction") / kDeg,
          c("pf_flexion") / kDeg,   c("pf_tx") * 1e3,        c("pf_ty") * 1e3,
          c("pf_tz") * 1e3,         c("pf_rotation") / kDeg, c("pf_tilt") / kDeg};
}

void print(const Pose6& p, const msk::SettleResult& r, const msk::ModelData& d,
           const msk::Model& m) {
  std::printf("%5.1f deg  %3d it  |Q| %.2e N %.2e N m | tibia anterior %6.2f superior %5.2f "
              "lateral %6.2f mm, int. rot %6.2f add %6.2f deg | patella flex %5.1f deg, "
              "tx %6.2f ty %6.2f tz %5.2f mm, rot %5.2f tilt %5.2f deg | contact",
              p.flexion_deg, r.iterations, r.max_force_residual, r.max_moment_residual, p.tx_mm,
              p.ty_mm, p.tz_mm, p.rotation_deg, p.adduction_deg, p.pf_flexion_deg, p.pf_tx_mm,
              p.pf_ty_mm, p.pf_tz_mm, p.pf_rotation_deg, p.pf_tilt_deg);
  for (size_t i = 0; i < m.contacts.size(); ++i)
    std::printf(" %s %.0f N", m.contacts[i].name().c_str(),
                d.contacts[i].result.force_on_target_W.norm());
  std::printf("\n");
}

// Independent check of a returned point: a fresh ModelData (no search caches),
// the generalized forces of the 11 secondary coordinates.
void expect_equilibrium(const msk::Model& m, const Eigen::VectorXd& q,
                        const msk::SettleOptions& opt, double deg) {
  auto d = msk::make_data(m);
  msk::evaluate_forces(m, d, q, {}, Eigen::VectorXd::Constant(m.muscles.size(), opt.muscle_tone));
  for (const char* c : {"knee_tx", "knee_ty", "knee_tz", "pf_tx", "pf_ty", "pf_tz"})
    EXPECT_LE(std::abs(d.Q[m.tree.coordinate_index(c)]), opt.force_tolerance) << c << " at " << deg;
  for (const char* c : {"knee_adduction", "knee_rotation", "pf_flexion", "pf_rotation", "pf_tilt"})
    EXPECT_LE(std::abs(d.Q[m.tree.coordinate_index(c)]), opt.moment_tolerance) << c << " at " << deg;
  for (size_t i = 0; i < m.contacts.size(); ++i)
    EXPECT_GT(d.contacts[i].result.force_on_target_W.norm(), 10.0)
        << m.contacts[i].name() << " unloaded at " << deg << " deg";
}

// Flexion sweep by continuation in 10 deg steps (each settle starts from the
// previous solution, patella advanced by 0.7 x the flexion step).
std::vector<Pose6> sweep(const msk::Model& m, const msk::SettleOptions& opt, double from_deg,
                         double to_deg) {
  auto d = msk::make_data(m);
  const int flex = m.tree.coordinate_index("knee_flexion");
  const int pf_flex = m.tree.coordinate_index("pf_flexion");
  Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
  q[flex] = from_deg * kDeg;
  q[pf_flex] = 0.7 * q[flex];
  std::vector<Pose6> out;
  const double step = to_deg > from_deg ? 10.0 : -10.0;
  for (double deg = from_deg; step > 0 ? deg <= to_deg + 1e-9 : deg >= to_deg - 1e-9;
       deg += step) {
    const double prev = q[flex];
    q[flex] = deg * kDeg;
    q[pf_flex] += 0.7 * (q[flex] - prev);
    const auto res = msk::settle(m, d, q, opt);
    const Pose6 p = pose_of(m, res.q);
    print(p, res, d, m);
    EXPECT_EQ(res.status, msk::SettleStatus::kConverged) << deg << " deg: " << res.message;
    expect_equilibrium(m, res.q, opt, deg);
    out.push_back(p);
    q = res.q;
  }
  return out;
}
// Cold starts (secondary coordinates at 0, patella at 0.7 x flexion) at the four
// angles of the issue. The first (Levenberg-Marquardt) settle stalled here at
// 0 deg with 8.7 N on knee_tz (coarse) and 6.7 N (medium); pseudo-transient
// continuation converges.
void cold_starts_at_four_angles(const char* file) {
  const auto m = msk::load_model(model_path(file));
  msk::SettleOptions opt;
  opt.fixed = {m.tree.coordinate_index("knee_flexion")};
  for (double deg : {0.0, 30.0, 60.0, 90.0}) {
    auto d = msk::make_data(m);
    Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
    q[m.tree.coordinate_index("knee_flexion")] = deg * kDeg;
    q[m.tree.coordinate_index("pf_flexion")] = 0.7 * deg * kDeg;
    const auto t0 = std::chrono::steady_clock::now();
    const auto res = msk::settle(m, d, q, opt);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    print(pose_of(m, res.q), res, d, m);
    std::printf("        (%s, %.0f ms)\n", file, ms);
    ASSERT_EQ(res.status, msk::SettleStatus::kConverged) << deg << " deg: " << res.message;
    EXPECT_LE(res.max_force_residual, opt.force_tolerance);
    EXPECT_LE(res.max_moment_residual, opt.moment_tolerance);
    expect_equilibrium(m, res.q, opt, deg);
  }
}
}  // namespace

TEST(KneeSettle, CoarseKneeColdStartsAtFourAngles) { cold_starts_at_four_angles("knee_coarse.urdf"); }

// The medium model (knee.urdf) at the same angles (about 1 s). Not covered:
// on this model a continuation in 10 deg steps does not converge at 80 deg
// (4.6 N left): there the patellofemoral contact force jumps by 4.3 N between
// two points 20 urad apart (one patellar triangle's overlap 0 -> 0.36 mm, the
// ray entering the femoral cartilage through its boundary), so no point with
// |Q| < 0.1 N exists nearby; see docs/model_format.md, "Passive settle".
TEST(KneeSettle, MediumKneeColdStartsAtFourAngles) { cold_starts_at_four_angles("knee.urdf"); }

// Continuation from 90 down to 0 deg in 10 deg steps: equilibrium at every
// angle, and smooth variation. Smoothness check: between successive 10 deg
// steps no secondary coordinate changes by more than a bound that is ~1.5 x
// the largest change measured on a smooth stretch (tibial anterior
// translation 3.0 mm / 10 deg, patellar flexion ~10 deg / 10 deg, internal
// rotation 3.1 deg / 10 deg): a branch switch of the equilibrium shows as a
// jump of 5..12 mm / 5 deg and fails it. Known exception (measured, a property
// of the bundled geometry, not of the solver): the mediolateral position has
// two equilibrium branches (tibia ~5 mm medial or ~6.5 mm lateral); between
// 10 and 0 deg the medial branch ends and the tibia moves to the lateral one,
// so the mediolateral translation and the coupled rotation and adduction are
// checked over 10..90 deg only. See docs/model_format.md, "Passive settle".
TEST(KneeSettle, CoarseKneeSweepIsContinuous) {
  const auto m = msk::load_model(model_path("knee_coarse.urdf"));
  msk::SettleOptions opt;
  opt.fixed = {m.tree.coordinate_index("knee_flexion")};
  const auto p = sweep(m, opt, 90.0, 0.0);
  ASSERT_EQ(p.size(), 10u);
  for (size_t i = 1; i < p.size(); ++i) {
    const Pose6 &a = p[i - 1], &b = p[i];
    const double at = b.flexion_deg;
    EXPECT_LE(std::abs(b.tx_mm - a.tx_mm), 4.5) << "tibial anterior translation at " << at;
    EXPECT_LE(std::abs(b.ty_mm - a.ty_mm), 1.0) << "tibial superior translation at " << at;
    EXPECT_LE(std::abs(b.pf_flexion_deg - a.pf_flexion_deg), 15.0) << "patellar flexion at " << at;
    EXPECT_LE(std::abs(b.pf_tx_mm - a.pf_tx_mm), 3.5) << "patellar tx at " << at;
    EXPECT_LE(std::abs(b.pf_ty_mm - a.pf_ty_mm), 3.5) << "patellar ty at " << at;
    if (at < 10.0 - 1e-9) continue;  // mediolateral branch switch, see above
    EXPECT_LE(std::abs(b.tz_mm - a.tz_mm), 2.0) << "tibial mediolateral translation at " << at;
    EXPECT_LE(std::abs(b.rotation_deg - a.rotation_deg), 4.5) << "tibial rotation at " << at;
    EXPECT_LE(std::abs(b.adduction_deg - a.adduction_deg), 2.5) << "tibial adduction at " << at;
    EXPECT_LE(std::abs(b.pf_tz_mm - a.pf_tz_mm), 2.0) << "patellar tz at " << at;
  }
  // Flexion moves the tibia anteriorly (roll-back of the femur) on this model:
  // monotonic from 20 to 90 deg.
  for (size_t i = 1; i + 1 < p.size() && p[i].flexion_deg >= 20.0; ++i)
    EXPECT_GT(p[i - 1].tx_mm, p[i].tx_mm) << p[i].flexion_deg;
}

// Robustness: cold starts every 5 deg from 0 to 90 deg all converge (the
// mediolateral double well near extension is where the first settle failed;
// with max_residual_growth = 2 the 10 deg start did not converge either).
TEST(KneeSettle, CoarseKneeColdStartsEveryFiveDegrees) {
  const auto m = msk::load_model(model_path("knee_coarse.urdf"));
  msk::SettleOptions opt;
  opt.fixed = {m.tree.coordinate_index("knee_flexion")};
  int iterations = 0;
  for (double deg = 0; deg <= 90; deg += 5) {
    auto d = msk::make_data(m);
    Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
    q[m.tree.coordinate_index("knee_flexion")] = deg * kDeg;
    q[m.tree.coordinate_index("pf_flexion")] = 0.7 * deg * kDeg;
    const auto res = msk::settle(m, d, q, opt);
    EXPECT_EQ(res.status, msk::SettleStatus::kConverged) << deg << " deg: " << res.message;
    iterations += res.iterations;
  }
  std::printf("19 cold starts: %d iterations in total\n", iterations);
}

// The Levenberg-Marquardt option (the first settle) started near the
// pseudo-transient solution (tibia moved 1 mm anterior and 1 deg, patella 1 mm
// lateral) returns to the same equilibrium (coarse, 60 deg). (From a cold start
// at 60 deg LM stalls with 190 N left, measured; the default converges.)
// Tolerance: 0.1 N over the softest measured stiffness (~2.8e4 N/m) is 4 um;
// 20 um / 0.05 deg leaves room for both residuals.
TEST(KneeSettle, LevenbergMarquardtReturnsToTheSameEquilibrium) {
  const auto m = msk::load_model(model_path("knee_coarse.urdf"));
  msk::SettleOptions opt;
  opt.fixed = {m.tree.coordinate_index("knee_flexion")};
  auto d = msk::make_data(m);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
  q[m.tree.coordinate_index("knee_flexion")] = 60 * kDeg;
  q[m.tree.coordinate_index("pf_flexion")] = 0.7 * 60 * kDeg;
  const auto ptc = msk::settle(m, d, q, opt);
  ASSERT_EQ(ptc.status, msk::SettleStatus::kConverged) << ptc.message;
  q = ptc.q;
  q[m.tree.coordinate_index("knee_tx")] += 1e-3;
  q[m.tree.coordinate_index("knee_rotation")] += 1 * kDeg;
  q[m.tree.coordinate_index("pf_tz")] += 1e-3;
  opt.method = msk::SettleMethod::kLevenbergMarquardt;
  const auto lm = msk::settle(m, d, q, opt);
  std::printf("%s\n%s\n", ptc.message.c_str(), lm.message.c_str());
  ASSERT_EQ(lm.status, msk::SettleStatus::kConverged) << lm.message;
  const Pose6 a = pose_of(m, ptc.q), b = pose_of(m, lm.q);
  for (auto [x, y] : {std::pair{a.tx_mm, b.tx_mm}, {a.ty_mm, b.ty_mm}, {a.tz_mm, b.tz_mm},
                      {a.pf_tx_mm, b.pf_tx_mm}, {a.pf_ty_mm, b.pf_ty_mm}, {a.pf_tz_mm, b.pf_tz_mm}})
    EXPECT_NEAR(x, y, 0.02);
  for (auto [x, y] : {std::pair{a.rotation_deg, b.rotation_deg}, {a.adduction_deg, b.adduction_deg},
                      {a.pf_flexion_deg, b.pf_flexion_deg}, {a.pf_rotation_deg, b.pf_rotation_deg},
                      {a.pf_tilt_deg, b.pf_tilt_deg}})
    EXPECT_NEAR(x, y, 0.05);
}

TEST(KneeSettle, RejectsBadOptions) {
  const auto m = msk::load_model(model_path("knee_coarse.urdf"));
  auto d = msk::make_data(m);
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
  msk::SettleOptions opt;
  opt.initial_pseudo_time = 0.0;
  EXPECT_THROW(msk::settle(m, d, q, opt), arthrosim::common::InputError);
  opt = {};
  opt.max_residual_growth = 0.5;
  EXPECT_THROW(msk::settle(m, d, q, opt), arthrosim::common::InputError);
}
