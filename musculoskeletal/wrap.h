#pragma once
// Wrap surfaces (OpenSim's WrapCylinder, WrapEllipsoid, WrapSphere, WrapTorus)
// and the wrapping of one straight path segment over one of them. Everything
// here works in the surface frame S (fixed on a body); path.h chains segments,
// applies wrap sets and turns the result into forces. Method and limits:
// docs/model_format.md, section "Wrapping".
//
// A segment a-b is wrapped when its straight line would pass through the
// surface (or, for a quadrant-restricted cylinder or a torus, on the
// forbidden side). The wrapped path is  a -> entry -> (curve on the surface)
// -> exit -> b  with straight parts tangent to the surface, and
//   l = |entry - a| + arc_length + |b - exit|.
// Every shape computes a path that is a stationary point of its length with
// respect to the contact points and the curve (a geodesic between tangent
// points), so the derivative of l with respect to a, b and the pose of the
// surface is the partial derivative with the contact points held fixed on the
// surface (envelope theorem): the tension acts along the two straight parts
// and the reaction on the surface's body at the contact points. path.cc uses
// exactly that, so moment arms are exact for the computed path.
//
// Cylinder (axis = local z, radius R, optional finite length): in the plane
// normal to the axis the path leaves a along a tangent, follows the circle and
// reaches b along the other tangent; unrolling the cylinder makes the wrapped
// path a straight line in (planar length, z), so the curve is a helix (the
// cylinder's geodesic) and l = sqrt(L_xy^2 + dz^2). Sense of travel: the short
// way round (quadrant all); with a quadrant (+x, -x, +y, -y) the path may not
// cross the half-plane of the axis on the opposite side (for +x: the points
// with x < 0, y = 0 of the cylinder frame), i.e. it is the shortest path
// around a "keyhole" obstacle (disc plus that half-line), which wraps over
// the allowed side whenever the straight line crosses the half-line, even far
// from the cylinder. Active iff the arc angle theta = travel - acos(R/rho_a) -
// acos(R/rho_b) > 0 (unrestricted: iff the straight segment cuts the circle),
// so l is C1 at engagement (the arc starts at zero length). A finite cylinder
// (OpenSim's length) is not wrapped when both contact points lie beyond its
// ends (|z| > length/2), as in OpenSim (a jump in l at that switch). An end
// point inside the radius (rho <= R) gives no wrap (OpenSim's rule).
//
// Sphere: the shortest path lies in the plane of a, b and the centre (great
// circle); closed form as the cylinder's planar case.
//
// Ellipsoid (semi-axes a, b, c): no closed form. The curve on the surface is
// the discrete geodesic of N chords: nodes x_0..x_N on the surface where
// every node reflects the incoming chord direction in the tangent plane (so
// every node is a stationary point of the polyline length along the surface,
// the discrete analogue of a geodesic); the straight parts a -> x_0 and
// x_N -> b obey the same reflection law at x_0 and x_N. Given x_0 (2 unknowns
// in a chart of the surface) the whole polyline follows in closed form (the
// next node is the second intersection of the reflected ray with the
// ellipsoid), and Newton's method (exact Jacobian by forward-mode dual
// numbers) makes the last reflected direction point at b (2 equations). The
// computed length is the exact length of this polyline, a stationary point of
// the polyline length, so the envelope argument holds exactly. The polyline
// is inscribed: on a sphere it is a regular polygon and the arc is short by
// about (theta/N)^2/24 relatively (theta the turning angle); path.cc removes
// that leading error by Richardson extrapolation over the whole path (see
// path.h). Initial guess: the exact discrete solution on the unit sphere the
// ellipsoid maps to under x = diag(a,b,c) y. Continuity: the polyline is a
// smooth function of a and b while the segment cuts the ellipsoid and shrinks
// to the touching point at engagement (l is C1).
//
// Torus (OpenSim: the path threads the ring; inner_radius r = tube radius,
// outer_radius R = radius of the tube's centre circle, axis = local z): at an
// angle phi of the centre circle the tube is locally the cylinder of radius r
// whose axis is the circle's tangent there, restricted to wrap on the side
// facing the torus axis. The wrapped length is max over phi (within a
// quarter turn of the point where the segment crosses the z = 0 plane) of the
// wrapped length over that cylinder: the most constraining section. At the
// maximiser the derivative with respect to a, b and the pose is again the
// partial one (Danskin's theorem), so forces act as for a cylinder fixed at
// phi*. Active only when the segment crosses the plane z = 0 inside the
// centre circle (through the hole) and the cylinder at phi* wraps.
#include <Eigen/Geometry>
#include <limits>
#include <string>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::musculoskeletal {

using common::Vec3;
using Pose = Eigen::Isometry3d;

enum class WrapShape { kCylinder, kEllipsoid, kSphere, kTorus };

/// Side restriction (OpenSim's quadrant): the path wraps only over the half
/// of the surface where the given local coordinate has the given sign.
enum class WrapQuadrant { kAll, kPosX, kNegX, kPosY, kNegY, kPosZ, kNegZ };

/// One wrap object fixed on a body.
struct WrapSurface {
  std::string name;
  WrapShape shape = WrapShape::kCylinder;
  int body = -1;
  Pose X_BS = Pose::Identity();  ///< surface frame in the body (axis = local z: cylinder, torus)
  /// Cylinder and sphere radius; torus: tube radius (OpenSim inner_radius) [m].
  double radius = 0.0;
  /// Cylinder length along its axis, centred on the origin [m]; infinity = infinite.
  double length = std::numeric_limits<double>::infinity();
  Vec3 semi_axes = Vec3::Zero();  ///< ellipsoid semi-axes along local x, y, z [m]
  double ring_radius = 0.0;       ///< torus: radius of the tube's centre circle (OpenSim outer_radius) [m]
  WrapQuadrant quadrant = WrapQuadrant::kAll;
  /// Ellipsoid: chords N of the coarse discrete geodesic (the fine one has
  /// 2N; path.h combines both), >= 2.
  int ellipsoid_chords = 8;
};

/// Throws common::InputError naming the surface when a dimension is not
/// positive and finite, a quadrant does not apply to the shape, or the torus
/// has inner >= outer radius.
void validate(const WrapSurface& s);

/// Wrapping of one straight segment (surface frame).
struct SegmentWrap {
  bool active = false;
  Vec3 entry = Vec3::Zero(), exit = Vec3::Zero();  ///< contact points (surface frame)
  double arc_length = 0.0;                         ///< length on the surface [m]
  /// Cylinder/torus: angle travelled around the axis; sphere: great-circle
  /// angle; ellipsoid: total turning angle of the polyline [rad].
  double arc_angle = 0.0;
  int iterations = 0;  ///< Newton iterations (ellipsoid) or phi-search steps (torus)
  /// Torus: the local cylinder at phi* (its frame in the torus frame).
  Pose X_SC = Pose::Identity();
};

/// Wraps the segment from a to b (both in the surface frame) over the surface.
/// `ellipsoid_chords` = N of the discrete geodesic (ellipsoid only, >= 2).
/// `arc` (if given) receives points of the curve on the surface from entry to
/// exit (surface frame), for display. `first_node_guess` (ellipsoid only,
/// surface frame) replaces the built-in initial guess of the first contact
/// point (e.g. the solution with fewer chords); the result does not depend on
/// it beyond the Newton tolerance. Throws common::NumericalError naming the
/// surface when the ellipsoid or torus iteration does not converge.
SegmentWrap wrap_segment(const WrapSurface& s, const Vec3& a, const Vec3& b, int ellipsoid_chords = 16,
                         std::vector<Vec3>* arc = nullptr, const Vec3* first_node_guess = nullptr);

}  // namespace arthrosim::musculoskeletal
