#pragma once
// Anthropometry of the leg for the inverse dynamics of the foot and shank
// (musculoskeletal/knee_loads.h), from body mass M and stature H.
//
// Segment lengths (fractions of H, Winter 2009 "Biomechanics and Motor Control
// of Human Movement", 4th ed., Fig. 4.1 after Drillis & Contini 1966):
//   thigh (hip to knee) 0.245 H; shank (knee to ankle) 0.246 H;
//   ankle height 0.039 H; foot length 0.152 H.
// The heel lies 0.22 foot lengths behind the ankle and the second metatarsal
// head 0.73 foot lengths in front of the heel, both on the sole (assumption of
// this code: Winter gives no such fractions; the bundled synthetic trial uses
// the same foot).
//
// Mass, centre of mass and radius of gyration (Winter 2009 Table 4.1, Dempster
// via Winter):
//   foot:  0.0145 M, COM at 0.50 of the ankle -> 2nd metatarsal head line,
//          radius of gyration about the COM 0.475 x that length;
//   shank: 0.0465 M, COM 0.433 of its length from the knee, 0.302 x length.
// Winter tabulates one radius of gyration (about a transverse axis); it is
// used for both transverse axes. The longitudinal radius is not in Winter's
// table: 0.1 x segment length is used for both (the order of de Leva 1996's
// longitudinal values, 0.09-0.14); it only enters through axial angular
// accelerations, which are small in walking.
//
// Frames (OpenSim style; for the right leg): the pelvis P, thigh F (femur), shank
// T (tibia) and foot C (calcaneus) frames all have X anterior, Y proximal/up,
// Z to the right in the neutral pose. The tibia frame has its origin at the knee
// joint centre, the foot frame at the ankle joint centre.
#include <Eigen/Core>

namespace arthrosim::musculoskeletal {

struct SegmentInertia {
  double mass_kg = 0.0;
  /// Centre of mass in the segment frame [m].
  Eigen::Vector3d p_com = Eigen::Vector3d::Zero();
  /// Radii of gyration about the COM along the segment frame axes X, Y, Z [m];
  /// the inertia tensor about the COM is diag(m r_x^2, m r_y^2, m r_z^2).
  Eigen::Vector3d radii_of_gyration_m = Eigen::Vector3d::Zero();
  Eigen::Matrix3d inertia_about_com() const;
};

/// Geometry and inertia of one leg (right-leg convention; a left leg is
/// handled by mirroring in knee_loads).
struct LegModel {
  double body_mass_kg = 0.0;
  double height_m = 0.0;
  /// Hip joint centre in the pelvis frame [m]. Default from OpenSim gait2392
  /// (-0.0707, -0.0661, 0.0835) m for a 1.80 m model, scaled by H / 1.80 m.
  Eigen::Vector3d p_PH_P = Eigen::Vector3d::Zero();
  double thigh_length_m = 0.0;  ///< hip to knee along -Y of the thigh frame
  double shank_length_m = 0.0;  ///< knee to ankle along -Y of the tibia frame
  double ankle_height_m = 0.0;  ///< ankle above the sole, along -Y of the foot frame
  double foot_length_m = 0.0;   ///< heel to toe tip along X of the foot frame
  double heel_behind_ankle_m = 0.0;
  SegmentInertia shank;  ///< in the tibia frame T
  SegmentInertia foot;   ///< in the foot frame C
};

/// Sets the shank and foot masses, centres of mass and radii of gyration from
/// body_mass_kg and the segment lengths of `leg` (the table fractions above).
void set_segment_inertia(LegModel& leg);

/// Leg model of a subject of mass [kg] and stature [m] from the tables above.
/// Throws std::invalid_argument unless 10 <= mass <= 300 and 0.5 <= height <= 2.5.
LegModel leg_model_from_anthropometry(double body_mass_kg, double height_m);

}  // namespace arthrosim::musculoskeletal
