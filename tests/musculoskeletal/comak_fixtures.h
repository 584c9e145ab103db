#pragma once
// Shared set-up of the COMAK tests (tests/musculoskeletal/comak_test.cc and
// tests/stability/comak_stability_test.cc): the bundled coarse knee, the knee
// loads of the bundled SYNTHETIC trial, and a settled start pose.
#include <Eigen/Core>
#include <algorithm>
#include <numbers>
#include <string>

#include "musculoskeletal/comak.h"
#include "musculoskeletal/gait_trial.h"
#include "musculoskeletal/knee_loads.h"
#include "musculoskeletal/model_io.h"
#include "musculoskeletal/settle.h"

namespace arthrosim::musculoskeletal::test {

inline std::string source(const std::string& rel) { return std::string(ARTHROSIM_SOURCE_DIR) + "/" + rel; }

inline const Model& coarse_model() {
  static const Model m = load_model(source("data/models/knee_parametric/knee_coarse.urdf"));
  return m;
}

inline const KneeLoads& trial_loads() {
  static const KneeLoads l = [] {
    const auto trial = load_gait_trial(source("data/trials/synthetic_gait"));
    return compute_knee_loads(trial, leg_model_for_trial(trial));
  }();
  return l;
}

inline double deg(double d) { return d * std::numbers::pi / 180.0; }

/// Passive settle at `flexion` with muscle tone `tone`: a start/test pose, so
/// convergence is not required here.
inline Eigen::VectorXd settled_pose(const ComakProblem& p, double flexion, double tone) {
  const auto& m = p.model();
  auto d = make_data(m);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
  q[p.flexion_coordinate()] = flexion;
  q[m.tree.coordinate_index("pf_flexion")] = 0.7 * flexion;
  SettleOptions so;
  so.fixed = {p.flexion_coordinate()};
  so.muscle_tone = tone;
  return settle(m, d, q, so).q;
}

/// settled_pose (tone 0.01) with every secondary coordinate moved by
/// `offset_m` [m] (translations) or `offset_rad` [rad] (rotations): a
/// deliberately poor start.
inline Eigen::VectorXd offset_settled_pose(const ComakProblem& p, double flexion, double offset_m,
                                           double offset_rad) {
  Eigen::VectorXd q = settled_pose(p, flexion, 0.01);
  const auto& free = p.free_coordinates();
  for (int j : p.secondary_coordinates()) {
    const int k = static_cast<int>(std::find(free.begin(), free.end(), j) - free.begin());
    q[j] += p.revolute(k) ? offset_rad : offset_m;
  }
  return q;
}

}  // namespace arthrosim::musculoskeletal::test
