#include "musculoskeletal/anthropometry.h"

#include <sstream>
#include <stdexcept>

namespace arthrosim::musculoskeletal {

Eigen::Matrix3d SegmentInertia::inertia_about_com() const {
  return (mass_kg * radii_of_gyration_m.array().square()).matrix().asDiagonal();
}

void set_segment_inertia(LegModel& leg) {
  // Shank: COM 0.433 L below the knee on the long axis.
  const double Ls = leg.shank_length_m;
  leg.shank.mass_kg = 0.0465 * leg.body_mass_kg;
  leg.shank.p_com = Eigen::Vector3d(0.0, -0.433 * Ls, 0.0);
  leg.shank.radii_of_gyration_m = Eigen::Vector3d(0.302 * Ls, 0.1 * Ls, 0.302 * Ls);

  // Foot: COM halfway between the ankle and the 2nd metatarsal head (on the sole,
  // 0.73 foot lengths in front of the heel).
  const Eigen::Vector3d p_mth(-leg.heel_behind_ankle_m + 0.73 * leg.foot_length_m,
                              -leg.ankle_height_m, 0.0);
  const double Lf = p_mth.norm();
  leg.foot.mass_kg = 0.0145 * leg.body_mass_kg;
  leg.foot.p_com = 0.5 * p_mth;
  // The foot's long axis is close to X: transverse radii about Y and Z, the
  // longitudinal one about X.
  leg.foot.radii_of_gyration_m = Eigen::Vector3d(0.1 * Lf, 0.475 * Lf, 0.475 * Lf);
}

LegModel leg_model_from_anthropometry(double body_mass_kg, double height_m) {
  if (!(body_mass_kg >= 10.0 && body_mass_kg <= 300.0) || !(height_m >= 0.5 && height_m <= 2.5)) {
    std::ostringstream s;
    s << "leg_model_from_anthropometry: expected 10 <= mass <= 300 kg and 0.5 <= height <= 2.5 m,"
      << " found " << body_mass_kg << " kg, " << height_m << " m";
    throw std::invalid_argument(s.str());
  }
  const double H = height_m, M = body_mass_kg;
  LegModel leg;
  leg.body_mass_kg = M;
  leg.height_m = H;
  leg.p_PH_P = Eigen::Vector3d(-0.0707, -0.0661, 0.0835) * (H / 1.80);
  leg.thigh_length_m = 0.245 * H;
  leg.shank_length_m = 0.246 * H;
  leg.ankle_height_m = 0.039 * H;
  leg.foot_length_m = 0.152 * H;
  leg.heel_behind_ankle_m = 0.22 * leg.foot_length_m;

  set_segment_inertia(leg);
  return leg;
}

}  // namespace arthrosim::musculoskeletal
