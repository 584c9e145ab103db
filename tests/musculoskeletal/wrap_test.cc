// Wrap surfaces against closed forms and an independent reference:
// cylinder helix (unrolling), quadrant-restricted cylinder (keyhole), finite
// cylinder, sphere great circle, torus (symmetric section), ellipsoid = sphere,
// ellipsoid against a continuous geodesic shot with RK4, the convergence order
// of the discrete geodesic, C1 continuity at engagement, coordinate functions.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>

#include "common/error.h"
#include "musculoskeletal/path.h"
#include "musculoskeletal/wrap.h"

namespace msk = arthrosim::musculoskeletal;
using msk::Vec3;
constexpr double kPi = std::numbers::pi;

namespace {

double seg_length(const msk::SegmentWrap& w, const Vec3& a, const Vec3& b) {
  return w.active ? (w.entry - a).norm() + w.arc_length + (b - w.exit).norm() : (b - a).norm();
}

msk::WrapSurface cylinder(double R, msk::WrapQuadrant q = msk::WrapQuadrant::kAll) {
  msk::WrapSurface s;
  s.name = "cyl";
  s.body = 0;
  s.radius = R;
  s.quadrant = q;
  return s;
}

msk::WrapSurface ellipsoid(const Vec3& axes) {
  msk::WrapSurface s;
  s.name = "ell";
  s.body = 0;
  s.shape = msk::WrapShape::kEllipsoid;
  s.semi_axes = axes;
  return s;
}

// Length of a one-segment path over an ellipsoid through evaluate_path (with
// the Richardson combination of N and 2N chords).
double path_length(const msk::WrapSurface& s, const Vec3& a, const Vec3& b) {
  msk::Path p;
  p.points = {{0, a}, {0, b}};
  p.wraps = {msk::PathWrap{s}};
  return msk::evaluate_path(p, {msk::Pose::Identity()}).length;
}

// Planar wrap length around a circle of radius R given the travel angle
// between the points (rho_a, rho_b their distances from the centre).
double planar(double R, double rho_a, double rho_b, double travel) {
  const double theta = travel - std::acos(R / rho_a) - std::acos(R / rho_b);
  return std::sqrt(rho_a * rho_a - R * R) + std::sqrt(rho_b * rho_b - R * R) + R * theta;
}

// ---- independent reference for the ellipsoid: the continuous geodesic ----
// x'' = -(v^T A v / |A x|^2) A x (unit speed on x^T A x = 1), RK4 with M steps.
struct Geo {
  Vec3 A;
  void rhs(const Vec3& x, const Vec3& v, Vec3& dx, Vec3& dv) const {
    const Vec3 g = A.cwiseProduct(x);
    dx = v;
    dv = -(v.dot(A.cwiseProduct(v)) / g.squaredNorm()) * g;
  }
  void shoot(Vec3 x, Vec3 v, double s, int M, Vec3& xe, Vec3& ve) const {
    const double h = s / M;
    for (int i = 0; i < M; ++i) {
      Vec3 k1x, k1v, k2x, k2v, k3x, k3v, k4x, k4v;
      rhs(x, v, k1x, k1v);
      rhs(x + 0.5 * h * k1x, v + 0.5 * h * k1v, k2x, k2v);
      rhs(x + 0.5 * h * k2x, v + 0.5 * h * k2v, k3x, k3v);
      rhs(x + h * k3x, v + h * k3v, k4x, k4v);
      x += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
      v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
    }
    xe = x;
    ve = v;
  }
};

// Solves for the shortest path a -> T1 (tangent) -> geodesic of length s ->
// T2 (tangent) -> b by Newton (finite-difference Jacobian) on 3 unknowns:
// T1 in a chart of the surface (2) and s; the start direction is the
// tangential part of T1 - a. Residuals: (T1 - a).n1, (b - T2).n2 and the
// binormal component of b - T2 at T2.
double reference_ellipsoid_length(const Vec3& D, const Vec3& a, const Vec3& b, const Vec3& T1_guess,
                                  double s_guess, Vec3* T1_out = nullptr) {
  Geo g{D.cwiseProduct(D).cwiseInverse()};
  const Vec3 y0 = T1_guess.cwiseQuotient(D).normalized();
  const Vec3 e1 = y0.unitOrthogonal(), e2 = y0.cross(e1);
  auto point = [&](double u, double w) { return Vec3(D.cwiseProduct((y0 + u * e1 + w * e2).normalized())); };
  const int M = 4000;
  auto residual = [&](const Eigen::Vector3d& z, double* len) {
    const Vec3 T1 = point(z[0], z[1]);
    const Vec3 n1 = g.A.cwiseProduct(T1).normalized();
    Vec3 t = T1 - a;
    t = (t - t.dot(n1) * n1).normalized();
    Vec3 T2, t2;
    g.shoot(T1, t, z[2], M, T2, t2);
    const Vec3 n2 = g.A.cwiseProduct(T2).normalized();
    const Vec3 e = b - T2;
    if (len) *len = (T1 - a).norm() + z[2] + e.norm();
    return Eigen::Vector3d((T1 - a).normalized().dot(n1), e.normalized().dot(n2),
                           e.normalized().dot(n2.cross(t2.normalized())));
  };
  Eigen::Vector3d z(0, 0, s_guess);
  for (int it = 0; it < 30; ++it) {
    const Eigen::Vector3d r = residual(z, nullptr);
    if (r.norm() < 1e-13) break;
    Eigen::Matrix3d J;
    for (int k = 0; k < 3; ++k) {
      Eigen::Vector3d zp = z, zm = z;
      const double h = 1e-7;
      zp[k] += h;
      zm[k] -= h;
      J.col(k) = (residual(zp, nullptr) - residual(zm, nullptr)) / (2 * h);
    }
    z -= J.lu().solve(r);
  }
  double len = 0;
  const Eigen::Vector3d r = residual(z, &len);
  EXPECT_LT(r.norm(), 1e-10) << "reference geodesic did not converge";
  if (T1_out) *T1_out = point(z[0], z[1]);
  return len;
}

}  // namespace

TEST(Wrap, CylinderHelixMatchesUnrolledClosedForm) {
  const double R = 0.01, rho = 0.03, phi = 3.0, dz = 0.015;
  const Vec3 a(rho, 0, -0.004), b(rho * std::cos(phi), rho * std::sin(phi), -0.004 + dz);
  const auto w = msk::wrap_segment(cylinder(R), a, b);
  ASSERT_TRUE(w.active);
  const double Lxy = planar(R, rho, rho, phi);
  // Three square roots and sums of numbers ~0.03 m: rounding ~1e-17 m.
  EXPECT_NEAR(seg_length(w, a, b), std::hypot(Lxy, dz), 1e-15);
  EXPECT_NEAR(w.entry.head<2>().norm(), R, 1e-16);
  // The helix is a straight line when unrolled: the contact points' heights
  // split dz in proportion to the planar lengths.
  EXPECT_NEAR(w.entry.z() - a.z(), dz * std::sqrt(rho * rho - R * R) / Lxy, 1e-16);
}

TEST(Wrap, CylinderQuadrantWrapsOverTheAllowedSide) {
  const double R = 0.01;
  // Both points on the -x side, the straight line x = -0.03 clear of the
  // cylinder but crossing the half-line x < 0, y = 0.
  const Vec3 a(-0.03, 0.02, 0.0), b(-0.03, -0.02, 0.01);
  const double rho = std::hypot(0.03, 0.02), dphi = 2 * std::atan2(0.02, 0.03);  // short way through 180 deg
  EXPECT_FALSE(msk::wrap_segment(cylinder(R), a, b).active);
  EXPECT_FALSE(msk::wrap_segment(cylinder(R, msk::WrapQuadrant::kNegX), a, b).active);
  const auto w = msk::wrap_segment(cylinder(R, msk::WrapQuadrant::kPosX), a, b);
  ASSERT_TRUE(w.active);
  // Long way round over +x: travel 2 pi - dphi.
  EXPECT_NEAR(seg_length(w, a, b), std::hypot(planar(R, rho, rho, 2 * kPi - dphi), 0.01), 1e-15);
  EXPECT_NEAR(w.arc_angle, 2 * kPi - dphi - 2 * std::acos(R / rho), 1e-14);  // atan2/acos rounding
  // The arc runs from the entry (y > 0) clockwise over x > 0 to the exit.
  EXPECT_GT(w.entry.y(), 0.0);
  EXPECT_LT(w.exit.y(), 0.0);
  // +y forbids the half-line y < 0, x = 0: the line does not cross it, no wrap;
  // -y forbids y > 0: not crossed either.
  EXPECT_FALSE(msk::wrap_segment(cylinder(R, msk::WrapQuadrant::kPosY), a, b).active);
  EXPECT_FALSE(msk::wrap_segment(cylinder(R, msk::WrapQuadrant::kNegY), a, b).active);
  // A segment through the cylinder: +y must go over y > 0, -y over y < 0.
  const Vec3 c(0.03, 0.002, 0.0), d(-0.03, 0.001, 0.0);
  const auto wp = msk::wrap_segment(cylinder(R, msk::WrapQuadrant::kPosY), c, d);
  const auto wn = msk::wrap_segment(cylinder(R, msk::WrapQuadrant::kNegY), c, d);
  ASSERT_TRUE(wp.active && wn.active);
  EXPECT_GT(wp.entry.y(), 0.0);
  EXPECT_LT(wn.entry.y(), 0.0);
  // The unrestricted wrap takes the short way (over y > 0, where the line passes).
  EXPECT_NEAR(seg_length(msk::wrap_segment(cylinder(R), c, d), c, d), seg_length(wp, c, d), 1e-16);
  EXPECT_GT(seg_length(wn, c, d), seg_length(wp, c, d));
}

TEST(Wrap, FiniteCylinderDoesNotWrapBeyondItsEnds) {
  const Vec3 a(0.03, 0.0, 0.05), b(-0.03, 0.001, 0.07);
  msk::WrapSurface s = cylinder(0.01);
  ASSERT_TRUE(msk::wrap_segment(s, a, b).active);
  s.length = 0.08;  // |z| <= 0.04: both contact points (z ~ 0.055, 0.065) beyond the end
  EXPECT_FALSE(msk::wrap_segment(s, a, b).active);
  s.length = 0.12;
  EXPECT_TRUE(msk::wrap_segment(s, a, b).active);
}

TEST(Wrap, SphereMatchesGreatCircleClosedForm) {
  msk::WrapSurface s;
  s.name = "sph";
  s.shape = msk::WrapShape::kSphere;
  s.radius = 0.02;
  const Vec3 a(0.05, 0.01, 0.003), b(-0.04, 0.015, -0.01);
  const auto w = msk::wrap_segment(s, a, b);
  ASSERT_TRUE(w.active);
  const double gamma = std::atan2(a.cross(b).norm(), a.dot(b));
  EXPECT_NEAR(seg_length(w, a, b), planar(0.02, a.norm(), b.norm(), gamma), 1e-15);
  EXPECT_NEAR(w.entry.norm(), 0.02, 1e-16);
  EXPECT_NEAR((w.entry - a).dot(w.entry), 0.0, 1e-16);  // tangent
  // In the plane of a, b and the centre.
  EXPECT_NEAR(w.exit.dot(a.cross(b).normalized()), 0.0, 1e-16);
  EXPECT_FALSE(msk::wrap_segment(s, a, Vec3(0.05, 0.05, 0.0)).active);
}

TEST(Wrap, TorusSymmetricSectionMatchesClosedForm) {
  msk::WrapSurface s;
  s.name = "tor";
  s.shape = msk::WrapShape::kTorus;
  s.radius = 0.01;       // tube
  s.ring_radius = 0.04;  // centre circle
  // A segment parallel to the axis, through the hole, 4 mm inside the tube's
  // inner equator (x = 0.03): by symmetry it wraps in the meridian plane
  // y = 0 over the tube's inner side: a circle of radius 0.01 centred at
  // (0.04, 0, 0).
  const Vec3 a(0.033, 0.0, 0.05), b(0.033, 0.0, -0.05);
  const auto w = msk::wrap_segment(s, a, b);
  ASSERT_TRUE(w.active);
  const double rho = std::hypot(0.007, 0.05);
  const double travel = 2 * std::atan2(0.05, 0.007);  // around the inner side
  // phi* from a Newton iteration on central differences (1e-10 rad) changes
  // the length only at second order.
  EXPECT_NEAR(seg_length(w, a, b), planar(0.01, rho, rho, travel), 1e-13);
  EXPECT_LT(w.entry.x(), 0.04);  // on the side facing the axis
  EXPECT_NEAR(w.entry.y(), 0.0, 1e-9);
  // Not through the hole: no wrap.
  EXPECT_FALSE(msk::wrap_segment(s, Vec3(0.06, 0, 0.05), Vec3(0.06, 0, -0.05)).active);
  // Through the hole but clear of the tube: no wrap.
  EXPECT_FALSE(msk::wrap_segment(s, Vec3(0.0, 0.001, 0.05), Vec3(0.001, 0, -0.05)).active);
}

TEST(Wrap, EllipsoidEqualAxesMatchesSphere) {
  const double R = 0.025;
  const Vec3 a(0.04, 0.002, 0.01), b(-0.035, -0.01, -0.02);  // arc angle ~0.96 rad
  const double exact = planar(R, a.norm(), b.norm(), std::atan2(a.cross(b).norm(), a.dot(b)));
  // Richardson of 8 and 16 chords: error measured 4.7e-7 m on this 0.96-rad
  // arc (2.0e-5 relative to the arc); plain 16 chords 3.2e-6 m. The tolerance
  // allows 1.5 x the measured error.
  const double l_default = path_length(ellipsoid(Vec3(R, R, R)), a, b);
  std::printf("ellipsoid = sphere: l = %.12f m, closed form %.12f m, difference %.2e m\n", l_default, exact,
              l_default - exact);
  EXPECT_NEAR(l_default, exact, 7e-7);
  // Convergence: the plain discrete geodesic is second order, the Richardson
  // combination about third order (the end secants' error is O(N^-3)).
  double prev = 0, prev_r = 0;
  for (int N : {8, 16, 32, 64}) {
    msk::WrapSurface s = ellipsoid(Vec3(R, R, R));
    const double lN = seg_length(msk::wrap_segment(s, a, b, N), a, b);
    const double l2N = seg_length(msk::wrap_segment(s, a, b, 2 * N), a, b);
    const double err = exact - l2N, err_r = exact - (4 * l2N - lN) / 3;
    EXPECT_GT(err, 0.0) << "the inscribed polyline is shorter";
    if (prev > 0) {
      EXPECT_NEAR(prev / err, 4.0, 0.3) << N;
      EXPECT_GT(prev_r / err_r, 6.0) << N;
    }
    prev = err;
    prev_r = err_r;
  }
}

TEST(Wrap, EllipsoidMatchesContinuousGeodesicReference) {
  // The lenhart2015 gastrocnemius ellipsoid's semi-axes and a segment that
  // wraps ~0.7 rad around its long axis with an axial slope; a second case on
  // the flat Med_Lig ellipsoid.
  struct Case {
    Vec3 D, a, b;
  };
  for (const Case& c : {Case{Vec3(0.0277566, 0.0231305, 0.138783), Vec3(0.05, 0.01, 0.02), Vec3(-0.04, 0.003, -0.05)},
                        Case{Vec3(0.03, 0.018, 0.012), Vec3(0.045, 0.004, 0.02), Vec3(-0.05, 0.001, -0.016)}}) {
    const msk::WrapSurface s = ellipsoid(c.D);
    std::vector<Vec3> arc;
    const auto w = msk::wrap_segment(s, c.a, c.b, 64, &arc);
    ASSERT_TRUE(w.active);
    Vec3 T1;
    const double ref = reference_ellipsoid_length(c.D, c.a, c.b, w.entry, w.arc_length, &T1);
    const double L = path_length(s, c.a, c.b);
    std::printf("ellipsoid (%g %g %g): l = %.12f m, reference %.12f m, difference %.2e m, arc %.4f rad\n",
                c.D.x(), c.D.y(), c.D.z(), L, ref, L - ref, w.arc_angle);
    // Measured |L - ref| 4.5e-8 .. 3.2e-7 m (Richardson 8/16 chords) against
    // a reference whose RK4 error is ~(s/4000)^4 / rho^3 ~ 1e-16 m; 1e-6 m
    // bounds both cases (relative < 1e-5 of the path).
    EXPECT_NEAR(L, ref, 1e-6);
    EXPECT_LT(L, ref + 1e-9) << "discrete solutions approach the geodesic from below";
    // The first node of 64 chords lies within half a chord of the tangent point.
    EXPECT_LT((arc[0] - T1).norm(), (arc[1] - arc[0]).norm());
  }
}

TEST(Wrap, EllipsoidEngagementIsC1) {
  // Segments at height y over an ellipsoid; the wrap engages at y* where the
  // line touches. With the end points at finite distance the path kinks by an
  // angle ~ depth / distance, so the excess length grows like depth^2 and its
  // derivative like depth (depth = y* - y): l is C1 at engagement (not C2).
  const msk::WrapSurface s = ellipsoid(Vec3(0.02, 0.015, 0.03));
  auto ends = [](double y) { return std::pair(Vec3(0.06, y, 0.01), Vec3(-0.06, y, -0.012)); };
  double lo = 0.0, hi = 0.02;  // active at lo, not at hi
  for (int i = 0; i < 80; ++i) {
    const double mid = 0.5 * (lo + hi);
    auto [a, b] = ends(mid);
    (msk::wrap_segment(s, a, b, 8).active ? lo : hi) = mid;
  }
  const double ystar = hi;
  auto excess = [&](double y) {
    auto [a, b] = ends(y);
    return path_length(s, a, b) - (b - a).norm();
  };
  auto slope = [&](double y, double h) {  // d(excess)/dy, central differences inside the wrapped side
    return (excess(y + h) - excess(y - h)) / (2 * h);
  };
  double prev_e = 0, prev_d = 0;
  for (double depth : {1e-4, 1e-5, 1e-6}) {
    const double e = excess(ystar - depth), d = slope(ystar - depth, 0.01 * depth);
    EXPECT_GT(e, 0.0);
    if (prev_e > 0) {
      // Ratios measured 99.99 and 10.0 (depth 1e-5 -> 1e-6); 5 % allows the
      // next-order terms at 1e-4.
      EXPECT_NEAR(prev_e / e, 100.0, 5.0) << depth;
      EXPECT_NEAR(prev_d / d, 10.0, 0.5) << depth;
    }
    prev_e = e;
    prev_d = d;
  }
  EXPECT_LT(excess(ystar - 1e-7), 1e-12);  // value continuous (1.6e-13 m at 1e-7)
  EXPECT_EQ(excess(ystar + 1e-7), 0.0);    // straight beyond engagement
}

TEST(Wrap, ValidateRejectsBadDimensions) {
  msk::WrapSurface s = cylinder(-0.01);
  EXPECT_THROW(msk::validate(s), arthrosim::common::InputError);
  s = ellipsoid(Vec3(0.01, 0.0, 0.02));
  EXPECT_THROW(msk::validate(s), arthrosim::common::InputError);
  s = ellipsoid(Vec3(0.01, 0.01, 0.02));
  s.quadrant = msk::WrapQuadrant::kPosX;
  EXPECT_THROW(msk::validate(s), arthrosim::common::InputError);
  s = cylinder(0.01, msk::WrapQuadrant::kPosZ);
  EXPECT_THROW(msk::validate(s), arthrosim::common::InputError);
  msk::WrapSurface t;
  t.name = "t";
  t.shape = msk::WrapShape::kTorus;
  t.radius = 0.05;
  t.ring_radius = 0.04;
  EXPECT_THROW(msk::validate(t), arthrosim::common::InputError);
}

TEST(CoordinateFunction, SplineReproducesCubicsAndParabolas) {
  // The end conditions match the third derivative of the cubic through the
  // end points, so data from a cubic are reproduced exactly (to rounding).
  const std::vector<double> x = {-1.0, -0.3, 0.1, 0.8, 1.1, 2.0};
  auto cubic = [](double t) { return 0.5 * t * t * t - 2 * t * t + t + 0.3; };
  std::vector<double> y;
  for (double t : x) y.push_back(cubic(t));
  const auto f = msk::CoordinateFunction::cubic_spline(x, y);
  for (double t = -1.0; t <= 2.0; t += 0.07) {
    EXPECT_NEAR(f.value(t), cubic(t), 1e-13) << t;
    EXPECT_NEAR(f.derivative(t), 1.5 * t * t - 4 * t + 1, 1e-12) << t;
  }
  // Beyond the knots: linear with the end slope.
  EXPECT_NEAR(f.value(2.5), cubic(2.0) + 0.5 * (1.5 * 4 - 8 + 1), 1e-12);
  EXPECT_NEAR(f.derivative(-2.0), 1.5 + 4 + 1, 1e-12);
  // Three points: the parabola; two points: the line.
  const auto p = msk::CoordinateFunction::cubic_spline({0, 1, 3}, {1, 2, 10});  // y = x^2 + 1
  EXPECT_NEAR(p.value(2.0), 5.0, 1e-13);
  EXPECT_NEAR(p.derivative(0.5), 1.0, 1e-13);
  const auto l = msk::CoordinateFunction::cubic_spline({0, 2}, {1, 5});
  EXPECT_NEAR(l.value(1.5), 4.0, 1e-15);
  // Scaling (MultiplierFunction), piecewise linear, constant, linear.
  EXPECT_NEAR(p.scaled(0.5).value(2.0), 2.5, 1e-13);
  const auto pl = msk::CoordinateFunction::piecewise_linear({0, 1, 2}, {0, 2, 1});
  EXPECT_DOUBLE_EQ(pl.value(0.5), 1.0);
  EXPECT_DOUBLE_EQ(pl.derivative(1.5), -1.0);
  EXPECT_DOUBLE_EQ(pl.value(3.0), 0.0);
  EXPECT_DOUBLE_EQ(msk::CoordinateFunction::constant(0.2).value(7.0), 0.2);
  EXPECT_DOUBLE_EQ(msk::CoordinateFunction::linear(2.0, 1.0).derivative(3.0), 2.0);
  EXPECT_THROW(msk::CoordinateFunction::cubic_spline({0, 0}, {1, 2}), arthrosim::common::InputError);
}

TEST(Wrap, EllipsoidRandomSegmentsAreSolved) {
  // Random ellipsoids (semi-axes 5-65 mm) and random segments passing through
  // them, many deep: the solver must find the discrete geodesic (8 and 16
  // chords) in all but a few cases near the centre, where both sides of the
  // body are nearly equally short; a failure is a NumericalError naming the
  // surface, never a silent wrong result. Measured: 2 of 9,221 wrapped cases
  // raise (0.02 %), both with the segment within 47 % of the way from the
  // centre to the surface; the bound allows 0.2 %.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1, 1), V(0, 1);
  int active = 0, failures = 0, deepest_failure_pct = 100;
  double worst_short = 0.0;
  for (int i = 0; i < 10000; ++i) {
    msk::WrapSurface e = ellipsoid(Vec3(0.005 + 0.06 * V(rng), 0.005 + 0.06 * V(rng), 0.005 + 0.06 * V(rng)));
    Vec3 dir(U(rng), U(rng), U(rng));
    dir.normalize();
    const Vec3 a = e.semi_axes.cwiseProduct(Vec3(U(rng), U(rng), U(rng))) * 0.6 - dir * (0.05 + 0.1 * V(rng));
    const Vec3 b = a + dir * (0.15 + 0.2 * V(rng)) + 0.02 * Vec3(U(rng), U(rng), U(rng));
    try {
      const auto w8 = msk::wrap_segment(e, a, b, 8);
      if (!w8.active) continue;
      ++active;
      const auto w16 = msk::wrap_segment(e, a, b, 16);
      ASSERT_TRUE(w16.active);
      // Both inscribed: the finer one is not shorter by more than rounding
      // unless they chose different sides (then the coarse one may be longer).
      worst_short = std::max(worst_short, seg_length(w8, a, b) - seg_length(w16, a, b));
    } catch (const arthrosim::common::NumericalError& err) {
      ++failures;
      EXPECT_NE(std::string(err.what()).find("wrap ellipsoid"), std::string::npos);
      const Vec3 A = e.semi_axes.cwiseProduct(e.semi_axes).cwiseInverse(), d = b - a;
      const double t = std::clamp(-a.dot(A.cwiseProduct(d)) / d.dot(A.cwiseProduct(d)), 0.0, 1.0);
      const Vec3 m = a + t * d;
      deepest_failure_pct = std::min(deepest_failure_pct, int(100 * std::sqrt(m.dot(A.cwiseProduct(m)))));
    }
  }
  std::printf("random ellipsoid wraps: %d wrapped, %d failures (%.2f %%), deepest point of a failing segment "
              "at %d %% of the way from the centre to the surface\n",
              active, failures, 100.0 * failures / std::max(1, active), deepest_failure_pct);
  EXPECT_GT(active, 9000);
  EXPECT_LT(failures, 0.002 * active);
}
