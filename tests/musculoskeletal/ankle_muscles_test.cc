// The uniarticular ankle stand-ins (musculoskeletal/ankle_muscles.h) and
// COMAK's ankle equilibrium row (ComakOptions::ankle_equilibrium), on the
// bundled coarse knee.
#include "musculoskeletal/ankle_muscles.h"

#include <gtest/gtest.h>

#include <cstdio>

#include "common/error.h"
#include "musculoskeletal/comak.h"
#include "tests/musculoskeletal/comak_fixtures.h"

namespace msk = arthrosim::musculoskeletal;
namespace common = arthrosim::common;

namespace {
using msk::test::coarse_model;
using msk::test::deg;
using msk::test::trial_loads;

// The bundled coarse knee with the two stand-ins (loaded once; Model is not
// copyable).
msk::Model& coarse_with_ankle_muscles() {
  static msk::Model m = [] {
    msk::Model x = msk::load_model(msk::test::source("data/models/knee_parametric/knee_coarse.urdf"));
    msk::add_ankle_muscles(x);
    return x;
  }();
  return m;
}
}  // namespace

// Moment arms about the ankle at the neutral pose against the closed form of
// the straight segment that crosses the ankle level (distance of the line
// from the ankle axis in the sagittal plane; the points' Z offsets do not
// change a moment about Z): soleus plantarflexes (r < 0 about the
// dorsiflexion axis), tibialis anterior dorsiflexes. The path code and the
// closed form use the same points, so they agree to rounding (1e-12 m).
TEST(AnkleMuscles, MomentArmsAtNeutral) {
  const msk::Model& m = coarse_with_ankle_muscles();
  ASSERT_EQ(m.muscles.size(), 15u);
  auto d = msk::make_data(m);
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
  msk::forward_kinematics(m.tree, q, d.kinematics);
  const int ankle = m.tree.coordinate_index("ankle_flexion");
  const int tibia = m.tree.body_index("tibia");
  const auto& X = d.kinematics.X_WB;
  // Ankle centre in the world at q = 0.
  const msk::Vec3 c = d.kinematics.joint_origin_W[m.tree.bodies[m.tree.body_index("calcaneus")].parent_joint];
  auto closed_form = [&](const msk::Muscle& mu, int seg) {
    const auto& a = mu.path.points[seg];
    const auto& b = mu.path.points[seg + 1];
    const msk::Vec3 pa = X[a.body] * a.p_B, pb = X[b.body] * b.p_B;
    const msk::Vec3 u = (pb - pa).normalized();
    // r = -dl/dq for a rotation of the distal point b about Z through c:
    // dl/dq = u . (z x (pb - c)).
    return -u.dot(msk::Vec3::UnitZ().cross(pb - c));
  };
  for (const char* name : {"soleus", "tibant"}) {
    const auto& mu = m.muscles[m.muscle_index(name)];
    const auto path = msk::evaluate_path(mu.path, X);
    const double r = msk::moment_arms(m, d, path)[ankle];
    const double r_cf = closed_form(mu, static_cast<int>(mu.path.points.size()) - 2);
    std::printf("%s: ankle moment arm %.4f m (closed form %.4f m), length %.4f m\n", name, r, r_cf,
                path.length);
    EXPECT_NEAR(r, r_cf, 1e-12);
    EXPECT_EQ(mu.path.points.front().body, tibia);
  }
  EXPECT_LT(msk::moment_arms(m, d, msk::evaluate_path(m.muscles[m.muscle_index("soleus")].path, X))[ankle],
            -0.03);
  EXPECT_GT(msk::moment_arms(m, d, msk::evaluate_path(m.muscles[m.muscle_index("tibant")].path, X))[ankle],
            0.03);
}

// Muscles between the tibia and the calcaneus make no generalized force on
// the knee coordinates (the two bodies move rigidly together when only knee
// coordinates change): |Q_knee| is rounding, 1e-16 x F_max x 1 m ~ 1e-12.
// Checked at a flexed, displaced pose.
TEST(AnkleMuscles, NoGeneralizedForceOnTheKnee) {
  const msk::Model& m = coarse_with_ankle_muscles();
  auto d = msk::make_data(m);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
  q[m.tree.coordinate_index("knee_flexion")] = deg(35);
  q[m.tree.coordinate_index("knee_adduction")] = deg(2);
  q[m.tree.coordinate_index("knee_tx")] = 2e-3;
  q[m.tree.coordinate_index("ankle_flexion")] = deg(-12);
  msk::forward_kinematics(m.tree, q, d.kinematics);
  const int ankle = m.tree.coordinate_index("ankle_flexion");
  for (const char* name : {"soleus", "tibant"}) {
    const auto& mu = m.muscles[m.muscle_index(name)];
    const Eigen::VectorXd r = msk::moment_arms(m, d, msk::evaluate_path(mu.path, d.kinematics.X_WB));
    for (int k : m.free_coordinates) EXPECT_LT(std::abs(r[k] * mu.max_isometric_force), 1e-9) << name << " " << k;
    EXPECT_GT(std::abs(r[ankle]), 0.02) << name;
  }
}

TEST(AnkleMuscles, BadModelsAreErrors) {
  msk::Model& m = coarse_with_ankle_muscles();
  const size_t n = m.muscles.size();
  EXPECT_THROW(msk::add_ankle_muscles(m), common::InputError);  // duplicate names
  EXPECT_EQ(m.muscles.size(), n);
  // The ankle row without uniarticular dorsiflexors cannot balance heel
  // strike: rejected when the problem is built.
  msk::ComakOptions o;
  o.ankle_equilibrium = true;
  EXPECT_THROW(msk::ComakProblem(coarse_model(), o), common::InputError);
  // A frame without the foot's load (knee loads given by the trial).
  msk::ComakProblem p(m, o);
  auto frames = msk::comak_frame_inputs(trial_loads(), 30, 30, 1);
  frames[0].has_foot_load = false;
  auto d = msk::make_data(m);
  EXPECT_THROW(msk::solve_comak_frame(p, d, frames[0], Eigen::VectorXd::Zero(m.num_coordinates()),
                                      Eigen::VectorXd::Constant(m.muscles.size(), 0.01)),
               common::InputError);
}

// The ankle row's external term: the foot's moment about the leg model's
// ankle centre, moved to the model's ankle axis (origin c_A, axis n_A in the
// tibia frame) and projected: n_A . (M + (c_leg - c_A) x F). Closed form for
// the bundled model (n_A = Z, c_A = (0, -0.4059, 0) m at the coarse model's
// shank length): with c_leg 1 cm anterior of c_A and a vertical 600 N
// load, the projection gains (0.01 x 600) = 6 N m about Z.
TEST(AnkleMuscles, ExternalAnkleMomentClosedForm) {
  const msk::Model& m = coarse_with_ankle_muscles();
  msk::ComakOptions o;
  o.ankle_equilibrium = true;
  msk::ComakProblem p(m, o);
  const auto& j = m.tree.joints[m.tree.bodies[m.tree.body_index("calcaneus")].parent_joint];
  msk::ComakFrameInput in;
  in.has_foot_load = true;
  in.F_foot_T = Eigen::Vector3d(0, 600, 0);
  in.M_foot_T = Eigen::Vector3d(1, 2, 30);
  in.ankle_centre_T = j.X_PJ.translation() + Eigen::Vector3d(0.01, 0, 0);
  EXPECT_NEAR(p.external_ankle_moment(in), 30.0 + 6.0, 1e-12);
  EXPECT_EQ(p.num_rows(), 13);
  EXPECT_EQ(p.equilibrium_coordinates().back(), m.tree.coordinate_index("ankle_flexion"));
  // Without the option the term is absent.
  msk::ComakProblem q(m, {});
  EXPECT_EQ(q.external_ankle_moment(in), 0.0);
  EXPECT_EQ(q.num_rows(), 12);
}

namespace {
struct PhaseRun {
  std::vector<msk::ComakFrameResult> results;
  std::vector<double> ankle_external;  // [N m]
};

PhaseRun run_frames(const msk::Model& m, bool ankle, int first, int last) {
  msk::ComakOptions o;
  o.ankle_equilibrium = ankle;
  msk::ComakProblem p(m, o);
  PhaseRun out;
  msk::run_comak(p, msk::comak_frame_inputs(trial_loads(), first, last, 1),
                 [&](const auto& f, const auto& r, const auto&) {
                   out.results.push_back(r);
                   out.ankle_external.push_back(p.external_ankle_moment(f));
                 });
  return out;
}

double mean_activation(const msk::Model& m, const PhaseRun& r, const char* a, const char* b) {
  double s = 0;
  for (const auto& f : r.results) s += 0.5 * (f.activations[m.muscle_index(a)] + f.activations[m.muscle_index(b)]);
  return s / r.results.size();
}
}  // namespace

// Late stance (push-off, frames 50-56 = 0.50-0.56 s of the bundled SYNTHETIC
// trial; external dorsiflexing moment on the foot 70-77 N m): with the ankle
// row, every frame converges, the row is balanced at the returned point
// (recomputed here from the muscle forces and moment arms, independent of
// ComakProblem::residual: sum_i a_i F_max,i r_i,ankle + M_ext = 0 within the
// moment tolerance 0.1 N x 0.03 m), and the gastrocnemii share the
// plantarflexion with the soleus. Without the row nothing asks the
// gastrocnemii for ankle work. Measured (coarse, from the settle at frame
// 50): mean gastrocnemius activation printed below; the bounds (> 0.1 with,
// < 0.05 without) separate the two behaviours that comak_bench measures over
// the whole trial (late-stance means 0.153 and 0.020).
TEST(AnkleMuscles, GastrocnemiiActiveInLateStanceWithAnkleRow) {
  const msk::Model& m = coarse_with_ankle_muscles();
  const PhaseRun with = run_frames(m, true, 50, 56);
  const PhaseRun without = run_frames(coarse_model(), false, 50, 56);
  ASSERT_EQ(with.results.size(), 7u);
  const int ankle = m.tree.coordinate_index("ankle_flexion");
  auto d = msk::make_data(m);
  for (size_t k = 0; k < with.results.size(); ++k) {
    const auto& r = with.results[k];
    EXPECT_EQ(r.status, msk::ComakFrameStatus::kConverged) << r.message;
    msk::forward_kinematics(m.tree, r.q, d.kinematics);
    double moment = with.ankle_external[k];
    for (size_t i = 0; i < m.muscles.size(); ++i) {
      const Eigen::VectorXd arm = msk::moment_arms(m, d, msk::evaluate_path(m.muscles[i].path, d.kinematics.X_WB));
      moment += r.activations[i] * m.muscles[i].max_isometric_force * arm[ankle];
    }
    EXPECT_LE(std::abs(moment), 0.1 * 0.03) << "frame " << 50 + k;
    EXPECT_GT(with.ankle_external[k], 50.0);
  }
  const double g_with = mean_activation(m, with, "gasmed", "gaslat");
  const double g_without = mean_activation(coarse_model(), without, "gasmed", "gaslat");
  const double soleus = mean_activation(m, with, "soleus", "soleus");
  std::printf("frames 50-56: mean gastrocnemius activation %.3f with the ankle row (soleus %.3f), "
              "%.3f without\n", g_with, soleus, g_without);
  EXPECT_GT(g_with, 0.1);
  EXPECT_LT(g_without, 0.05);
}
