#pragma once
// Geometric paths of ligament bundles and muscles: chains of points fixed on
// bodies, optionally wrapping over one cylinder (two-point paths only).
//
// Length and its first variation. For a straight chain of points x_0..x_n,
//   l = sum_i |x_{i+1} - x_i|,
// and a tension T along the path acts on the body carrying x_i with
//   T (u_{i,i+1} + u_{i,i-1}),  u_{a,b} = (x_b - x_a)/|x_b - x_a|,
// so that the generalized force is Q = -T dl/dq (moment arm r = -dl/dq).
// Every path therefore reports a list of "applications" (body, world point,
// world force per unit tension); Q = T sum J(body, point)^T g.
//
// Cylinder wrapping (Garner & Pandy 2000 style, infinite cylinder, fixed on a
// body): in the cylinder frame C (axis z through the origin, radius R) the
// points P (origin) and S (insertion) are projected on the xy plane. Going
// around the axis the short way from P to S (sense given by the sign of the
// angle between them, so the path always wraps on the side where the straight
// line passes the axis), the path leaves P along the tangent to the circle,
// follows the arc and reaches S along the other tangent. With
//   alpha_X = acos(R / rho_X), rho_X = |X_xy|,
//   theta   = |angle(P_xy, S_xy)| - alpha_P - alpha_S   (arc angle),
// the wrap is active only when theta > 0 (otherwise the straight segment does
// not touch the circle, and the length is the straight one; the switch is C1
// because the arc starts at zero length tangent to the straight line). Unrolling
// the cylinder turns the wrapped path into a straight line in (planar length,
// z), so l = sqrt(L_xy^2 + (z_S - z_P)^2), L_xy = |P T1| + R theta + |T2 S|.
// If P or S lies inside the cylinder (rho <= R) the path is taken straight:
// a stated modelling rule (the wrap surface cannot act on a point inside it).
// Forces: P receives T * dl/dP (negated) along the unrolled tangent direction,
// the cylinder body receives the opposite forces at the same world points
// (the reaction of the wrap surface), which is what the chain rule of l in the
// cylinder frame gives.
#include <Eigen/Geometry>
#include <optional>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::musculoskeletal {

using common::Vec3;
using Pose = Eigen::Isometry3d;

/// A point fixed on a body, given in that body's frame [m].
struct PathPoint {
  int body = -1;
  Vec3 p_B = Vec3::Zero();
};

/// Infinite wrapping cylinder fixed on a body.
struct WrapCylinder {
  int body = -1;
  Pose X_BC = Pose::Identity();  ///< cylinder frame in the body; axis = local z
  double radius = 0.0;           ///< R [m], > 0
};

struct Path {
  std::vector<PathPoint> points;        ///< >= 2 points, origin first
  std::optional<WrapCylinder> cylinder;  ///< only for paths of exactly 2 points
};

/// A force per unit tension applied to a body at a world point.
struct PathApplication {
  int body = -1;
  Vec3 point_W = Vec3::Zero();
  Vec3 direction_W = Vec3::Zero();
};

struct PathState {
  double length = 0.0;          ///< [m]
  bool wrapped = false;         ///< cylinder active
  double wrap_arc_angle = 0.0;  ///< theta [rad] when wrapped
  std::vector<Vec3> points_W;   ///< the path's polyline (with tangent points when wrapped)
  std::vector<PathApplication> applications;
};

/// Evaluates the path given the world poses of all bodies (X_WB[body]).
/// Throws common::NumericalError if two consecutive points coincide
/// (the direction of the tension is undefined).
PathState evaluate_path(const Path& path, const std::vector<Pose>& X_WB);

}  // namespace arthrosim::musculoskeletal
