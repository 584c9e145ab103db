// COMAK on the real subject (the bundled lenhart2015 model imported from
// OpenSim-JAM and its walking trial overground_17): the loads of a model with
// its own leg (musculoskeletal/model_loads.h) against closed forms, the
// NLP's derivatives with every row this model can have (knee, ankle, hip;
// coordinate dampers) against finite differences, and the first frames of
// the walk: converged at Ipopt's Solve_Succeeded level and near OpenSim-JAM's
// published secondary kinematics. The whole walk is a benchmark
// (tests/benchmarks/lenhart_comak_bench.cc) and a script
// (scripts/compare_opensim_jam.py), not a test.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/storage.h"
#include "musculoskeletal/comak.h"
#include "musculoskeletal/gait_trial.h"
#include "musculoskeletal/kinematics_file.h"
#include "musculoskeletal/model_io.h"
#include "musculoskeletal/model_loads.h"
#include "musculoskeletal/osim_import.h"

namespace msk = arthrosim::musculoskeletal;
namespace fs = std::filesystem;

namespace {

const fs::path kRoot = ARTHROSIM_SOURCE_DIR;

// The bundled model: the knee, and every muscle of the leg (44).
const msk::Model& knee_model() {
  static const msk::Model m = msk::load_model((kRoot / "data/models/lenhart2015/lenhart2015.urdf").string());
  return m;
}
const msk::Model& leg_model() { return knee_model(); }

msk::GaitTrial trial_for(const msk::Model& m) {
  msk::GaitTrialOptions to;
  to.is_rotational = [&m](const std::string& label) {
    const int c = m.tree.coordinate_index(label);
    for (const msk::Joint& j : m.tree.joints)
      if (c >= 0 && j.coordinate == c) return j.type == msk::JointType::kRevolute;
    return false;
  };
  return msk::load_gait_trial((kRoot / "data/trials/lenhart2015_overground17").string(), to);
}

// Closed forms of the model's own loads. Standing still (all rates zero):
// the weight of each body is m g at its centre of mass, so the generalized
// force equals J^T R_WL m g summed over the bodies. With the pelvis
// accelerating uniformly (qdd of pelvis_tx) and everything else still, every
// body's lab acceleration is that of the pelvis and the d'Alembert force is
// m (g - a). A force of the trial on the foot: J(x)^T R_WG F at R_WG p + o_G.
TEST(ModelDynamics, ClosedForms) {
  const msk::Model& m = knee_model();
  const int ground = m.role_body("ground");
  ASSERT_GE(ground, 0);
  Eigen::VectorXd q = m.default_q;
  q[m.tree.coordinate_index("pelvis_tilt")] = 0.2;
  q[m.tree.coordinate_index("pelvis_ty")] = 0.9;
  q[m.tree.coordinate_index("hip_flex_r")] = 0.3;
  q[m.tree.coordinate_index("knee_flex_r")] = 0.5;
  q[m.tree.coordinate_index("ankle_flex_r")] = 0.1;
  const std::vector<int> bodies = msk::bodies_moved_by(m.tree, m.free_coordinates);
  msk::KinematicsData k;
  msk::forward_kinematics(m.tree, q, k);
  const Eigen::Matrix3d R_WL = k.X_WB[ground].linear();
  for (double ax : {0.0, 2.5}) {
    Eigen::VectorXd qd = Eigen::VectorXd::Zero(q.size()), qdd = qd;
    qdd[m.tree.coordinate_index("pelvis_tx")] = ax;
    Eigen::VectorXd Q = Eigen::VectorXd::Zero(q.size()), Q_ref = Q;
    msk::add_lab_inertial_forces(m.tree, ground, q, qd, qdd, bodies, Q);
    for (int b : bodies) {
      const msk::Body& B = m.tree.bodies[b];
      const Eigen::Vector3d f_L = B.mass * (Eigen::Vector3d(0, -9.80665, 0) - Eigen::Vector3d(ax, 0, 0));
      msk::add_point_force(m.tree, k, b, k.X_WB[b] * B.com, R_WL * f_L, Q_ref);
    }
    // Central differences of a quadratic path are exact up to rounding:
    // ~1e-16 x 1 m / (1e-4 s)^2 = 1e-8 m/s^2 on ~4 kg at <= 1 m: 1e-7.
    EXPECT_LT((Q - Q_ref).cwiseAbs().maxCoeff(), 1e-6) << "pelvis acceleration " << ax;
    EXPECT_GT(Q_ref.cwiseAbs().maxCoeff(), 1.0);
  }
  msk::LabForce f;
  f.body = m.tree.body_index("calcn_r");
  f.force_L = Eigen::Vector3d(-80, 600, 20);
  f.point_L = Eigen::Vector3d(0.4, 0.0, 0.1);
  f.torque_L = Eigen::Vector3d(0, 3, 0);
  Eigen::VectorXd Q = Eigen::VectorXd::Zero(q.size()), Q_ref = Q;
  msk::add_lab_forces(m.tree, k, ground, {f}, Q);
  msk::add_point_force(m.tree, k, f.body, k.X_WB[ground] * f.point_L, R_WL * f.force_L, Q_ref);
  msk::add_body_couple(m.tree, k, f.body, R_WL * f.torque_L, Q_ref);
  EXPECT_LT((Q - Q_ref).cwiseAbs().maxCoeff(), 1e-9);
}

// d residual / d [activations, secondary coordinates] against central
// differences of the residual, with the ankle and hip rows (44 muscles, 16
// rows) and the coordinate dampers of a previous frame, at the first stance
// peak (t = 1.28 s) from the trial's own secondary coordinates. Tolerances
// as Comak.ResidualJacobianMatchesFiniteDifferencesWithContact: the faceted
// contact is piecewise smooth on a micrometre scale, so h = 5e-7 and 1e-2
// relative; the activation columns are exact (linear).
TEST(ComakLenhart, ResidualJacobianMatchesFiniteDifferences) {
  const msk::Model& m = leg_model();
  const msk::GaitTrial t = trial_for(m);
  msk::ComakOptions o;
  o.ankle_equilibrium = true;
  o.hip_equilibrium = true;
  msk::ComakProblem p(m, o);
  ASSERT_TRUE(p.model_dynamics());
  ASSERT_EQ(p.num_rows(), 16);
  const auto [f0, f1] = msk::frames_in_window(t, 1.27, 1.28);
  auto frames = msk::comak_model_frame_inputs(m, t, f0, f1, 1);
  msk::ComakFrameInput in = frames[1];
  in.has_previous = true;
  in.dt_previous = 0.01;
  in.q_previous = p.coordinates(frames[0], p.neutral_pose(frames[0]));
  const Eigen::VectorXd q = p.coordinates(in, p.neutral_pose(in));
  const int nm = static_cast<int>(m.muscles.size());
  Eigen::VectorXd a(nm);
  for (int i = 0; i < nm; ++i) a[i] = 0.05 + 0.005 * i;
  auto d = msk::make_data(m);
  const Eigen::MatrixXd J = p.residual_jacobian(d, in, q, a);
  const auto& sec = p.secondary_coordinates();
  ASSERT_EQ(J.cols(), nm + static_cast<int>(sec.size()));
  const double h = 5e-7;
  double worst = 0.0;
  for (int c = 0; c < J.cols(); ++c) {
    Eigen::VectorXd qp = q, qm = q, ap = a, am = a;
    if (c < nm) {
      ap[c] += h, am[c] -= h;
    } else {
      qp[sec[c - nm]] += h, qm[sec[c - nm]] -= h;
    }
    const Eigen::VectorXd fd = (p.residual(d, in, qp, ap, {}) - p.residual(d, in, qm, am, {})) / (2 * h);
    const double scale = std::max(1.0, fd.cwiseAbs().maxCoeff());
    const double err = (J.col(c) - fd).cwiseAbs().maxCoeff() / scale;
    worst = std::max(worst, err);
    EXPECT_LE(err, 1e-2) << "column " << c << "\nJ  " << J.col(c).transpose() << "\nfd " << fd.transpose();
  }
  std::printf("largest relative error %.3g (h = %g)\n", worst, h);
}

// The first 5 frames of the walk (1.21-1.25 s, heel strike) with the scene's
// settings (data/scenes/lenhart2015_gait.yaml: OpenSim-JAM's primary
// coordinates hip and ankle balanced as well, one start, 15 acceptable
// iterates): every frame converged at Ipopt's Solve_Succeeded level (not
// "acceptable"), and the secondary coordinates near OpenSim-JAM's published
// walking_values.sto (bounds 2 deg and 1.5 mm, inside the targets for
// the walk; measured over the whole walk: docs/comak.md).
// The model's one tibial cartilage (both plateaus) is labelled per triangle
// by prepare's rule (common/compartments.h) from split_lateral="+z" (a right
// knee in OpenSim's frames): two plateaus, the lateral one at larger z.
TEST(ComakLenhart, OneTibialSurfaceIsLabelledByCompartment) {
  const msk::Model& m = knee_model();
  const int i = m.contact_index("tf_contact");
  ASSERT_GE(i, 0);
  const msk::ContactSurface& s = m.contacts[i].casting();
  ASSERT_EQ(static_cast<int>(s.compartment.size()), s.mesh.num_triangles());
  double z[2] = {0, 0};
  int n[2] = {0, 0};
  const auto c = arthrosim::common::triangle_centroids(s.mesh);
  for (int t = 0; t < s.mesh.num_triangles(); ++t) {
    const int side = s.compartment[t] ? 1 : 0;
    z[side] += c(t, 2), ++n[side];
  }
  ASSERT_GT(n[0], 0);
  ASSERT_GT(n[1], 0);
  EXPECT_GT(z[1] / n[1] - z[0] / n[0], 0.02);  // plateau centres ~4 cm apart
  EXPECT_NE(s.compartment_rule.find("2 connected components"), std::string::npos) << s.compartment_rule;
  EXPECT_NE(msk::tibiofemoral_compartment_rule(m).find("tf_contact: per casting triangle"), std::string::npos);
}

TEST(ComakLenhart, FirstFramesConvergeNearOpenSimJam) {
  const msk::Model& m = knee_model();
  const msk::GaitTrial t = trial_for(m);
  msk::ComakOptions o;
  o.second_start = false;
  o.hip_equilibrium = true;
  o.ankle_equilibrium = true;
  o.acceptable_iterations = 15;
  msk::ComakProblem p(m, o);
  const auto [f0, f1] = msk::frames_in_window(t, 1.21, 1.25);
  const auto frames = msk::comak_model_frame_inputs(m, t, f0, f1, 1);
  ASSERT_EQ(frames.size(), 5u);
  const auto ref = arthrosim::common::read_storage(
      (kRoot / "data/trials/lenhart2015_overground17/opensim_jam_comak/walking_values.sto").string());
  int k = 0;
  const auto summary = msk::run_comak(p, frames, [&](const msk::ComakFrameInput& in, const msk::ComakFrameResult& r,
                                                     const msk::ModelData& d) {
    EXPECT_EQ(r.status, msk::ComakFrameStatus::kConverged) << r.message;
    // The one tibial contact surface's force split per compartment
    // (split_lateral="+z"): the parts sum to the total to round-off, both
    // plateaus loaded, the medial one more (medial share 0.55-0.63 measured
    // here; 60-80 % of the load in stance in the literature, docs/comak.md).
    const msk::ContactSummary tf = msk::tibiofemoral_contact(m, d);
    EXPECT_LT((tf.medial_force + tf.lateral_force - tf.force).norm(), 1e-12 * tf.force.norm()) << in.time;
    EXPECT_GT(tf.lateral_force.norm(), 0.2 * tf.force.norm()) << in.time;
    EXPECT_GT(tf.medial_force.norm(), tf.lateral_force.norm()) << in.time;
    EXPECT_EQ(r.ipopt_status, 0) << r.message;
    EXPECT_NEAR(ref.data(k, 0), in.time, 1e-9);
    for (int c : p.secondary_coordinates()) {
      const std::string& n = m.tree.coordinates[c];
      const double theirs = ref.data(k, ref.column_index(n));  // radians / metres after reading
      const bool revolute = [&] {
        for (const msk::Joint& j : m.tree.joints)
          if (j.coordinate == c) return j.type == msk::JointType::kRevolute;
        return false;
      }();
      EXPECT_NEAR(r.q[c], theirs, revolute ? 2.0 * M_PI / 180.0 : 1.5e-3) << n << " at " << in.time << " s";
    }
    ++k;
  });
  EXPECT_EQ(summary.converged, 5);
}

}  // namespace
