#pragma once
// Geometric paths of ligament bundles and muscles, as OpenSim's GeometryPath:
// a chain of points on bodies (fixed, conditional or moving) and an ordered
// wrap set of surfaces (cylinder, ellipsoid, sphere, torus; wrap.h) that the
// straight segments wrap over.
//
// Length and its first variation. The evaluated path is a polyline of nodes
// x_0..x_m (the active path points and, for every active wrap, its entry and
// exit contact points), straight between consecutive nodes except between the
// entry and exit of one wrap, where it runs on the surface:
//   l = sum_straight |x_{k+1} - x_k| + sum_wraps arc_length.
// Every wrap solution is a stationary point of l with respect to its contact
// points and its curve (wrap.h), so dl/dq is the partial derivative with the
// contact points held fixed on their surfaces (envelope theorem). A tension T
// therefore acts, for each straight segment between nodes a and b, on the body
// carrying a with T u and on the body carrying b with -T u (u = unit vector
// from a to b); a contact node is carried by its surface's body. Every path
// reports these as "applications" (body, world point, world force per unit
// tension), and Q = T sum J(body, point)^T g = -T dl/dq (moment arm
// r = -dl/dq). A moving point (location a function of coordinates) adds the
// work of its motion relative to its body as a direct generalized force per
// unit tension, (u_out - u_in) . R_WB dp_B/dq_c ("coordinate forces").
//
// Wrap sets (OpenSim's PathWrapSet semantics): wraps are applied in order; each
// considers the segments of the current path (active points plus contact
// points of earlier wraps, but not the arc of another wrap) between the first
// and last active points of its range and wraps the first segment that needs
// it (OpenSim takes the first intersected segment). With two or more active
// wraps the contact points are then refined by Gauss-Seidel sweeps (each wrap
// recomputed between its current neighbours) until no contact point moves by
// more than 1e-12 m, so the whole chain is stationary and the envelope
// argument holds for it too (OpenSim instead stops after 8 passes or a 0.5 mm
// length change); a wrap that disengages during the sweeps is dropped.
//
// Ellipsoid wraps use a discrete geodesic of N and 2N chords (wrap.h); when an
// ellipsoid wrap is active the whole path is evaluated with both and combined
// by Richardson extrapolation, l = (4 l_2N - l_N) / 3, with applications and
// coordinate forces combined with the same weights (4/3 and -1/3), so the
// moment arms stay exact for the reported length. Points and contact points
// reported are those of the 2N evaluation.
//
// Conditional points (OpenSim ConditionalPathPoint) are part of the path only
// while their coordinate lies in [range_min, range_max] (l jumps when one
// switches, as in OpenSim). A straight segment of zero length throws
// common::NumericalError (the direction of the tension is undefined).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "common/mesh.h"
#include "musculoskeletal/wrap.h"

namespace arthrosim::musculoskeletal {

using common::Vec3;
using Pose = Eigen::Isometry3d;

/// A function of one coordinate, as OpenSim's functions of path points:
/// constant, linear (slope, intercept), piecewise linear, and the cubic spline
/// of OpenSim's SimmSpline and NaturalCubicSpline (both use the end conditions
/// of Forsythe, Malcolm & Moler: the third derivative at each end equals that
/// of the cubic through the four end points; 3 points give the parabola, 2 the
/// line). Beyond the first/last knot splines and piecewise-linear functions
/// continue linearly with their end slope (OpenSim's rule). OpenSim's
/// MultiplierFunction is folded in by scaling (make_... (..., scale)).
class CoordinateFunction {
 public:
  enum class Kind { kConstant, kLinear, kPiecewiseLinear, kCubicSpline };
  static CoordinateFunction constant(double value);
  static CoordinateFunction linear(double slope, double intercept);
  /// Knots strictly increasing, >= 2, equal sizes; throws common::InputError.
  static CoordinateFunction piecewise_linear(std::vector<double> x, std::vector<double> y);
  static CoordinateFunction cubic_spline(std::vector<double> x, std::vector<double> y);
  /// The function times s.
  CoordinateFunction scaled(double s) const;

  Kind kind() const { return kind_; }
  double value(double x) const;
  double derivative(double x) const;

 private:
  Kind kind_ = Kind::kConstant;
  std::vector<double> x_, y_, b_, c_, d_;  // knots, values, slope/curvature/cubic coefficients
  double slope_ = 0.0, intercept_ = 0.0;
  int interval(double x) const;
};

/// A point of a path on a body [m]. Plain points use body and p_B; a
/// conditional point is active only while q[condition_coordinate] lies in
/// [range_min, range_max]; a moving point's body-frame coordinate j is
/// moving[j](q[moving_coordinate[j]]) where moving[j] is set (p_B otherwise).
struct PathPoint {
  PathPoint() = default;
  PathPoint(int body_index, const Vec3& point_B) : body(body_index), p_B(point_B) {}
  int body = -1;
  Vec3 p_B = Vec3::Zero();
  int condition_coordinate = -1;  ///< >= 0: conditional point
  double range_min = 0.0, range_max = 0.0;
  std::array<int, 3> moving_coordinate = {-1, -1, -1};
  std::array<std::shared_ptr<const CoordinateFunction>, 3> moving;

  bool is_conditional() const { return condition_coordinate >= 0; }
  bool is_moving() const { return moving[0] || moving[1] || moving[2]; }
};

/// OpenSim's ellipsoid wrapping methods, recorded from the model file; every
/// method computes the same (shortest) path in arthrosim.
enum class WrapMethod { kShortest, kHybrid, kMidpoint, kAxial };

/// One entry of a path's wrap set.
struct PathWrap {
  WrapSurface surface;
  /// Range of path points considered, 0-based indices into Path::points
  /// (conditional points included), inclusive; -1 = first / last point.
  int first_point = -1, last_point = -1;
  WrapMethod method = WrapMethod::kShortest;
};

struct Path {
  std::vector<PathPoint> points;  ///< >= 2 points (>= 2 of them not conditional), origin first
  std::vector<PathWrap> wraps;    ///< ordered wrap set
};

/// A force per unit tension applied to a body at a world point.
struct PathApplication {
  int body = -1;
  Vec3 point_W = Vec3::Zero();
  Vec3 direction_W = Vec3::Zero();
};

/// A generalized force per unit tension on one coordinate (moving points).
struct CoordinateForce {
  int coordinate = -1;
  double force = 0.0;  ///< N per N of tension (revolute: m; prismatic: -)
};

/// One active wrap of an evaluated path.
struct WrapContact {
  int wrap = -1;  ///< index into Path::wraps
  Vec3 entry_W = Vec3::Zero(), exit_W = Vec3::Zero();
  double arc_length = 0.0;  ///< [m]
  double arc_angle = 0.0;   ///< [rad], see SegmentWrap::arc_angle
};

struct PathState {
  double length = 0.0;          ///< [m]
  bool wrapped = false;         ///< at least one wrap active
  double wrap_arc_angle = 0.0;  ///< arc angle of the first active wrap [rad]
  std::vector<WrapContact> contacts;
  std::vector<Vec3> points_W;   ///< the path's polyline (with points along wrapped arcs)
  std::vector<PathApplication> applications;
  std::vector<CoordinateForce> coordinate_forces;
};

/// Evaluates the path given the world poses of all bodies (X_WB[body]) and
/// the coordinates q (used by conditional and moving points; may be empty for
/// a path without them). Throws common::InputError when q is needed and
/// missing, common::NumericalError on a zero-length straight segment or a
/// wrap iteration that does not converge.
PathState evaluate_path(const Path& path, const std::vector<Pose>& X_WB, const Eigen::VectorXd& q);
PathState evaluate_path(const Path& path, const std::vector<Pose>& X_WB);

/// True when the path's length can change with coordinate c: a point or wrap
/// surface lies on a body that c moves (moved[body]), or a conditional or
/// moving point depends on c.
bool path_depends_on(const Path& path, const std::vector<char>& moved, int c);

/// True when some point is conditional or moving (evaluation needs q).
bool path_needs_coordinates(const Path& path);

}  // namespace arthrosim::musculoskeletal
