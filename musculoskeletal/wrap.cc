#include "musculoskeletal/wrap.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <sstream>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

namespace {

constexpr double kPi = std::numbers::pi;

const char* shape_name(WrapShape s) {
  switch (s) {
    case WrapShape::kCylinder: return "cylinder";
    case WrapShape::kEllipsoid: return "ellipsoid";
    case WrapShape::kSphere: return "sphere";
    case WrapShape::kTorus: return "torus";
  }
  return "?";
}

double mod_two_pi(double x) {
  double r = std::fmod(x, 2 * kPi);
  if (r < 0) r += 2 * kPi;
  return r;
}

// A unit vector perpendicular to v (deterministic choice).
Vec3 any_perpendicular(const Vec3& v) {
  const Vec3 t = std::abs(v.x()) < 0.9 * v.norm() ? Vec3::UnitX() : Vec3::UnitY();
  return v.cross(t).normalized();
}

// ---------------------------------------------------------------- cylinder --
// Wrap of a-b over the cylinder of radius R about the local z axis.
// `forbidden`: angle of the half-line (in the xy plane) the path may not
// cross, NaN when unrestricted. `half_length`: infinity for an infinite
// cylinder.
SegmentWrap cylinder_wrap(const Vec3& a, const Vec3& b, double R, double half_length, double forbidden,
                          std::vector<Vec3>* arc) {
  SegmentWrap w;
  const double rho_a = std::hypot(a.x(), a.y()), rho_b = std::hypot(b.x(), b.y());
  if (rho_a <= R || rho_b <= R) return w;
  const double phi_a = std::atan2(a.y(), a.x()), phi_b = std::atan2(b.y(), b.x());
  double sgn = 1.0, travel = 0.0;
  if (std::isnan(forbidden)) {
    double delta = phi_b - phi_a;
    while (delta > kPi) delta -= 2 * kPi;
    while (delta <= -kPi) delta += 2 * kPi;
    sgn = delta >= 0.0 ? 1.0 : -1.0;  // the short way round
    travel = std::abs(delta);
  } else {
    const double ccw = mod_two_pi(phi_b - phi_a);
    if (mod_two_pi(forbidden - phi_a) < ccw) {  // counter-clockwise would cross it
      sgn = -1.0;
      travel = 2 * kPi - ccw;
    } else {
      travel = ccw;
    }
  }
  const double al_a = std::acos(R / rho_a), al_b = std::acos(R / rho_b);
  const double theta = travel - al_a - al_b;
  if (theta <= 0.0) return w;
  const double t1 = phi_a + sgn * al_a, t2 = phi_b - sgn * al_b;
  const double seg_a = rho_a * std::sin(al_a), seg_b = rho_b * std::sin(al_b);
  const double L = seg_a + R * theta + seg_b;
  const double dz = b.z() - a.z();
  w.entry = Vec3(R * std::cos(t1), R * std::sin(t1), a.z() + dz * seg_a / L);
  w.exit = Vec3(R * std::cos(t2), R * std::sin(t2), a.z() + dz * (L - seg_b) / L);
  if (std::abs(w.entry.z()) > half_length && std::abs(w.exit.z()) > half_length) return SegmentWrap{};
  w.active = true;
  w.arc_angle = theta;
  w.arc_length = std::hypot(R * theta, dz * R * theta / L);
  if (arc) {
    const int n = std::max(2, static_cast<int>(std::ceil(theta / 0.2)));
    for (int i = 0; i <= n; ++i) {
      const double f = double(i) / n;
      const double ang = t1 + sgn * theta * f;
      arc->push_back(Vec3(R * std::cos(ang), R * std::sin(ang), w.entry.z() + (w.exit.z() - w.entry.z()) * f));
    }
  }
  return w;
}

double forbidden_angle(WrapQuadrant q) {
  switch (q) {
    case WrapQuadrant::kPosX: return kPi;         // may not pass x < 0
    case WrapQuadrant::kNegX: return 0.0;         // may not pass x > 0
    case WrapQuadrant::kPosY: return -kPi / 2;    // may not pass y < 0
    case WrapQuadrant::kNegY: return kPi / 2;     // may not pass y > 0
    default: return std::nan("");
  }
}

// ------------------------------------------------------------------ sphere --
SegmentWrap sphere_wrap(const Vec3& a, const Vec3& b, double R, std::vector<Vec3>* arc) {
  SegmentWrap w;
  const double ra = a.norm(), rb = b.norm();
  if (ra <= R || rb <= R) return w;
  const Vec3 cr = a.cross(b);
  const double sn = cr.norm();
  const double gamma = std::atan2(sn, a.dot(b));
  const double al_a = std::acos(R / ra), al_b = std::acos(R / rb);
  const double theta = gamma - al_a - al_b;
  if (theta <= 0.0) return w;
  const Vec3 e1 = a / ra;
  // a, b and the centre collinear (b behind the sphere): every plane through
  // them is a great circle; a fixed one is taken (l is continuous, the
  // contact points jump).
  const Vec3 m = sn > 1e-300 ? Vec3(cr / sn) : any_perpendicular(e1);
  const Vec3 e2 = m.cross(e1);
  w.active = true;
  w.entry = R * (std::cos(al_a) * e1 + std::sin(al_a) * e2);
  w.exit = R * (std::cos(gamma - al_b) * e1 + std::sin(gamma - al_b) * e2);
  w.arc_angle = theta;
  w.arc_length = R * theta;
  if (arc) {
    const int n = std::max(2, static_cast<int>(std::ceil(theta / 0.2)));
    for (int i = 0; i <= n; ++i) {
      const double ang = al_a + theta * double(i) / n;
      arc->push_back(R * (std::cos(ang) * e1 + std::sin(ang) * e2));
    }
  }
  return w;
}

// --------------------------------------------------------------- ellipsoid --
// Forward-mode dual number with two derivative directions.
struct D2 {
  double v = 0, d0 = 0, d1 = 0;
  D2() = default;
  D2(double x) : v(x) {}  // NOLINT: constants promote implicitly
  D2(double x, double a, double b) : v(x), d0(a), d1(b) {}
};
inline D2 operator+(const D2& a, const D2& b) { return {a.v + b.v, a.d0 + b.d0, a.d1 + b.d1}; }
inline D2 operator-(const D2& a, const D2& b) { return {a.v - b.v, a.d0 - b.d0, a.d1 - b.d1}; }
inline D2 operator-(const D2& a) { return {-a.v, -a.d0, -a.d1}; }
inline D2 operator*(const D2& a, const D2& b) {
  return {a.v * b.v, a.d0 * b.v + a.v * b.d0, a.d1 * b.v + a.v * b.d1};
}
inline D2 operator*(double s, const D2& a) { return {s * a.v, s * a.d0, s * a.d1}; }
inline D2 operator/(const D2& a, const D2& b) {
  const double inv = 1.0 / b.v, q = a.v * inv;
  return {q, (a.d0 - q * b.d0) * inv, (a.d1 - q * b.d1) * inv};
}
inline D2 dsqrt(const D2& a) {
  const double s = std::sqrt(a.v), h = 0.5 / s;
  return {s, a.d0 * h, a.d1 * h};
}
inline double dsqrt(double x) { return std::sqrt(x); }
inline double value(double x) { return x; }
inline double value(const D2& x) { return x.v; }

template <class T>
struct V3 {
  T x, y, z;
};
template <class T>
V3<T> operator+(const V3<T>& a, const V3<T>& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
template <class T>
V3<T> operator-(const V3<T>& a, const V3<T>& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
template <class T>
V3<T> scale(const T& s, const V3<T>& a) { return {s * a.x, s * a.y, s * a.z}; }
template <class T>
T dot(const V3<T>& a, const V3<T>& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
// A v (A = diag(k)).
template <class T>
V3<T> amul(const Vec3& k, const V3<T>& v) { return {k.x() * v.x, k.y() * v.y, k.z() * v.z}; }
template <class T>
V3<T> lift(const Vec3& v) { return {T(v.x()), T(v.y()), T(v.z())}; }

struct EllipsoidShot {
  Vec3 D, A;       // semi-axes, diag(1/a^2, 1/b^2, 1/c^2)
  Vec3 P, S;       // segment ends (ellipsoid frame)
  Vec3 y0, ea, eb; // chart of x_0: y = normalize(y0 + alpha ea + beta eb), x_0 = D y
  Vec3 r1, r2;     // directions measuring the end residual
  int N = 16;
};

// Shoots the discrete geodesic from x_0(alpha, beta): returns the end residual
// (reflected last direction minus the direction to S, on r1 and r2). When
// `nodes`/`steps` are given (double only) they receive x_0..x_N and the signed
// chord lengths.
template <class T>
void shoot(const EllipsoidShot& s, const T& alpha, const T& beta, T r[2], std::vector<Vec3>* nodes = nullptr,
           std::vector<double>* steps = nullptr, double* first = nullptr, double* last = nullptr) {
  V3<T> y = lift<T>(s.y0) + scale(alpha, lift<T>(s.ea)) + scale(beta, lift<T>(s.eb));
  y = scale(T(1.0) / dsqrt(dot(y, y)), y);
  V3<T> x = amul(s.D, y);
  V3<T> d = x - lift<T>(s.P);
  const T dn = dsqrt(dot(d, d));
  V3<T> u = scale(T(1.0) / dn, d);
  V3<T> g = amul(s.A, x);
  u = u - scale(T(2.0) * dot(u, g) / dot(g, g), g);
  if (nodes) nodes->push_back(Vec3(value(x.x), value(x.y), value(x.z)));
  if (first) *first = value(dn);
  for (int k = 0; k < s.N; ++k) {
    const T t = -T(2.0) * dot(u, g) / dot(u, amul(s.A, u));
    x = x + scale(t, u);
    g = amul(s.A, x);
    u = u - scale(T(2.0) * dot(u, g) / dot(g, g), g);
    if (nodes) nodes->push_back(Vec3(value(x.x), value(x.y), value(x.z)));
    if (steps) steps->push_back(value(t));
  }
  V3<T> e = lift<T>(s.S) - x;
  const T en = dsqrt(dot(e, e));
  if (last) *last = value(en);
  const V3<T> diff = u - scale(T(1.0) / en, e);
  r[0] = dot(diff, lift<T>(s.r1));
  r[1] = dot(diff, lift<T>(s.r2));
}

[[noreturn]] void ellipsoid_failure(const WrapSurface& surf, const std::string& what) {
  std::ostringstream m;
  m << "wrap ellipsoid '" << surf.name << "': " << what;
  throw common::NumericalError(m.str());
}

// Point of the ellipsoid x^T A x = 1 (A = diag(D)^-2) closest to the point m
// inside it: x_i = D_i^2 m_i / (D_i^2 - nu) with the root nu in
// [0, min D_i^2) of sum_i D_i^2 m_i^2 / (D_i^2 - nu)^2 = 1 (bisection).
Vec3 closest_surface_point(const Vec3& D, const Vec3& m) {
  const Vec3 D2 = D.cwiseProduct(D);
  auto F = [&](double nu) {
    double f = 0;
    for (int i = 0; i < 3; ++i) f += D2[i] * m[i] * m[i] / ((D2[i] - nu) * (D2[i] - nu));
    return f - 1.0;
  };
  int k = 0;
  D2.minCoeff(&k);
  double lo = 0.0, hi = D2[k];
  if (F(hi * (1 - 1e-12)) < 0) {
    // m lies on the plane of the shortest axis: the closest point is along it.
    Vec3 x = m;
    double rest = 0;
    for (int i = 0; i < 3; ++i)
      if (i != k) {
        x[i] = D2[i] * m[i] / (D2[i] - D2[k]);
        rest += x[i] * x[i] / D2[i];
      }
    x[k] = D[k] * std::sqrt(std::max(0.0, 1 - rest));
    return x;
  }
  // F is convex and increasing on [lo, hi): Newton from the left overshoots
  // at most once; steps outside the bracket fall back to bisection.
  double nu = 0.0;
  for (int it = 0; it < 100; ++it) {
    double f = -1.0, fp = 0.0;
    for (int i = 0; i < 3; ++i) {
      const double q = 1.0 / (D2[i] - nu);
      f += D2[i] * m[i] * m[i] * q * q;
      fp += 2 * D2[i] * m[i] * m[i] * q * q * q;
    }
    (f < 0 ? lo : hi) = nu;
    double next = nu - f / fp;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (std::abs(next - nu) < 1e-14 * D2[k]) {
      nu = next;
      break;
    }
    nu = next;
  }
  return Vec3(D2[0] * m[0] / (D2[0] - nu), D2[1] * m[1] / (D2[1] - nu), D2[2] * m[2] / (D2[2] - nu));
}

// In the plane through p spanned by `dir` and `side`, the point where the
// tangent from p touches the ellipsoid's section on the `side` half.
Vec3 section_tangent_point(const Vec3& A, const Vec3& p, const Vec3& dir, const Vec3& side) {
  // Section: z = (s, t) -> x = p + s dir + t side; z^T M z + 2 b^T z + c = 0.
  auto Am = [&](const Vec3& v) { return Vec3(A.cwiseProduct(v)); };
  const double M00 = dir.dot(Am(dir)), M01 = dir.dot(Am(side)), M11 = side.dot(Am(side));
  const double b0 = dir.dot(Am(p)), b1 = side.dot(Am(p));
  const double c = p.dot(Am(p)) - 1.0;  // > 0: p outside
  // Polar line of the origin: b^T z + c = 0; z = z0 + lam v.
  const double bb = b0 * b0 + b1 * b1;
  const double z0s = -c * b0 / bb, z0t = -c * b1 / bb;
  const double inv = 1.0 / std::sqrt(bb);
  const double vs = -b1 * inv, vt = b0 * inv;
  const double qa = M00 * vs * vs + 2 * M01 * vs * vt + M11 * vt * vt;
  const double qb = M00 * vs * z0s + M01 * (vs * z0t + vt * z0s) + M11 * vt * z0t;
  const double qc = M00 * z0s * z0s + 2 * M01 * z0s * z0t + M11 * z0t * z0t - c;
  const double disc = std::sqrt(std::max(0.0, qb * qb - qa * qc));
  const double l1 = (-qb + disc) / qa, l2 = (-qb - disc) / qa;
  const double t1 = z0t + l1 * vt, t2 = z0t + l2 * vt;
  const double lam = t1 > t2 ? l1 : l2;  // on the +side half
  return p + (z0s + lam * vs) * dir + (z0t + lam * vt) * side;
}

SegmentWrap ellipsoid_wrap(const WrapSurface& surf, const Vec3& a, const Vec3& b, int N, std::vector<Vec3>* arc,
                           const Vec3* hint) {
  SegmentWrap w;
  const Vec3 D = surf.semi_axes;
  const Vec3 A = D.cwiseProduct(D).cwiseInverse();
  auto quad = [&](const Vec3& x) { return x.dot(A.cwiseProduct(x)); };
  if (quad(a) <= 1.0 || quad(b) <= 1.0) return w;
  // Does the straight segment enter the ellipsoid? min over t in [0,1] of
  // (a + t d)^T A (a + t d) < 1.
  const Vec3 d = b - a;
  const double dAd = quad(d);
  const double t_min = std::clamp(-a.dot(A.cwiseProduct(d)) / dAd, 0.0, 1.0);
  if (quad(a + t_min * d) >= 1.0) return w;

  // Initial guess: the planar wrap in the plane through a, b and the surface
  // point Q closest to the deepest point m of the segment (the wrap passes
  // over the side where the segment is closest to leaving the body); on a
  // sphere that plane is the great circle's. The contact points from a and b
  // to the section ellipse of that plane give x_0 and the end direction.
  EllipsoidShot s;
  s.D = D;
  s.A = A;
  s.P = a;
  s.S = b;
  s.N = N;
  const Vec3 mpt = a + t_min * d;
  const Vec3 Q = closest_surface_point(D, mpt);
  const Vec3 dir = d / d.norm();
  Vec3 side = (Q - mpt) - (Q - mpt).dot(dir) * dir;  // in the plane, normal to the segment
  if (!(side.norm() > 1e-12 * D.maxCoeff())) side = any_perpendicular(dir);
  side.normalize();
  const Vec3 pn = dir.cross(side);  // plane normal
  const Vec3 T2 = section_tangent_point(A, b, -dir, side);
  Vec3 x0_guess;
  if (hint) {
    x0_guess = *hint;
  } else {
    // The discrete x_0 lies past the tangent point T1 by half a chord angle:
    // delta = theta / (N + 1) with theta the planar guess's turning angle,
    // i.e. by an arc length delta / (2 kappa) (kappa the normal curvature).
    const Vec3 T1 = section_tangent_point(A, a, dir, side);
    const Vec3 t1 = (T1 - a).normalized();
    const double theta = std::acos(std::clamp(t1.dot((b - T2).normalized()), -1.0, 1.0));
    const double kappa = t1.dot(A.cwiseProduct(t1)) / A.cwiseProduct(T1).norm();
    const Vec3 x = T1 + (theta / (N + 1) / (2 * kappa)) * t1;
    x0_guess = x / std::sqrt(quad(x));
  }
  {
    const Vec3 y0 = x0_guess.cwiseQuotient(D).normalized();
    s.y0 = y0;
    // Chart directions in y: images of the travel direction and the plane
    // normal, made tangent to the unit sphere at y0.
    Vec3 ta = dir.cwiseQuotient(D);
    ta = (ta - ta.dot(y0) * y0).normalized();
    s.ea = ta;
    s.eb = y0.cross(ta);
    // u_N - w is (nearly) normal to the exit direction ~ t: measure it on
    // the surface normal and the binormal at the guessed exit.
    const Vec3 n = A.cwiseProduct(T2).normalized();
    const Vec3 t = (dir - dir.dot(n) * n).normalized();
    s.r1 = n;
    s.r2 = n.cross(t);
    (void)pn;
  }

  // Newton on (alpha, beta); each iteration costs one dual-number shot (a
  // halving line search on |r| only when a full step does not reduce it).
  double al = 0.0, be = 0.0;
  D2 rd[2];
  shoot<D2>(s, D2(al, 1, 0), D2(be, 0, 1), rd);
  double rn = std::hypot(rd[0].v, rd[1].v);
  int it = 0;
  bool converged = false;
  for (; it < 50 && std::isfinite(rn); ++it) {
    if (rn < 1e-11) {  // the initial guess is already converged
      converged = true;
      break;
    }
    const double j00 = rd[0].d0, j01 = rd[0].d1, j10 = rd[1].d0, j11 = rd[1].d1;
    const double det = j00 * j11 - j01 * j10;
    if (!(std::abs(det) > 0) || !std::isfinite(det)) break;
    const double da = -(j11 * rd[0].v - j01 * rd[1].v) / det;
    const double db = -(-j10 * rd[0].v + j00 * rd[1].v) / det;
    const double step = std::hypot(da, db);
    D2 rn_d[2];
    shoot<D2>(s, D2(al + da, 1, 0), D2(be + db, 0, 1), rn_d);
    double rn_new = std::hypot(rn_d[0].v, rn_d[1].v);
    double lam = 1.0;
    if (!(rn_new < rn)) {
      if (rn < 1e-12) {  // no decrease possible at rounding level
        converged = true;
        break;
      }
      double r[2];
      for (int ls = 0; ls < 40; ++ls) {
        lam *= 0.5;
        shoot<double>(s, al + lam * da, be + lam * db, r);
        rn_new = std::hypot(r[0], r[1]);
        if (rn_new < rn) break;
      }
      if (!(rn_new < rn)) break;
      shoot<D2>(s, D2(al + lam * da, 1, 0), D2(be + lam * db, 0, 1), rn_d);
      rn_new = std::hypot(rn_d[0].v, rn_d[1].v);
    }
    rd[0] = rn_d[0];
    rd[1] = rn_d[1];
    al += lam * da;
    be += lam * db;
    rn = rn_new;
    // Converged when the residual (a difference of unit vectors, i.e. an
    // angle) is below 1e-11 rad: the length is then stationary to ~1e-11 x
    // its straight parts, far below the tolerance of any moment-arm use.
    if (rn < 1e-11 || (lam == 1.0 && step < 1e-9)) {
      converged = true;
      ++it;
      break;
    }
  }
  if (!converged || !std::isfinite(rn) || rn > 1e-9) {
    std::ostringstream msg;
    msg << "Newton iteration of the discrete geodesic (" << N << " chords) did not converge (" << it
        << " iterations, residual " << rn << ")";
    ellipsoid_failure(surf, msg.str());
  }
  double r[2];
  std::vector<Vec3> nodes;
  std::vector<double> steps;
  nodes.reserve(N + 1);
  steps.reserve(N);
  double first = 0, last = 0;
  shoot<double>(s, al, be, r, &nodes, &steps, &first, &last);
  double arc_len = 0.0;
  for (double t : steps) {
    if (!(t > 0)) {
      std::ostringstream msg;
      msg << "the discrete geodesic has a chord of length " << t
          << " m although the segment enters the ellipsoid (wrong branch)";
      ellipsoid_failure(surf, msg.str());
    }
    arc_len += t;
  }
  // Turning angle: at every node the direction turns by 2 asin(|u . n|).
  double turn = 0.0;
  for (int k = 0; k <= N; ++k) {
    const Vec3 in = k == 0 ? Vec3((nodes[0] - a).normalized()) : Vec3((nodes[k] - nodes[k - 1]).normalized());
    const Vec3 n = A.cwiseProduct(nodes[k]).normalized();
    turn += 2 * std::asin(std::min(1.0, std::abs(in.dot(n))));
  }
  w.active = true;
  w.entry = nodes.front();
  w.exit = nodes.back();
  w.arc_length = arc_len;
  w.arc_angle = turn;
  w.iterations = it;
  if (arc) arc->insert(arc->end(), nodes.begin(), nodes.end());
  return w;
}

}  // namespace

void validate(const WrapSurface& s) {
  const std::string what = std::string("wrap ") + shape_name(s.shape) + " '" + s.name + "'";
  auto pos = [&](double v, const char* name) {
    if (!(v > 0) || !std::isfinite(v))
      throw common::InputError(what + ": expected " + name + " > 0 m (finite), found " + std::to_string(v));
  };
  const bool z_quadrant = s.quadrant == WrapQuadrant::kPosZ || s.quadrant == WrapQuadrant::kNegZ;
  switch (s.shape) {
    case WrapShape::kCylinder:
      pos(s.radius, "radius");
      if (!(s.length > 0)) throw common::InputError(what + ": expected length > 0 m (or infinite)");
      if (z_quadrant)
        throw common::InputError(what + ": quadrant +z/-z runs along the cylinder axis; expected all, +x, -x, +y or -y");
      break;
    case WrapShape::kSphere:
      pos(s.radius, "radius");
      break;
    case WrapShape::kEllipsoid:
      pos(s.semi_axes.x(), "semi-axis a");
      pos(s.semi_axes.y(), "semi-axis b");
      pos(s.semi_axes.z(), "semi-axis c");
      break;
    case WrapShape::kTorus:
      pos(s.radius, "inner_radius (tube radius)");
      pos(s.ring_radius, "outer_radius (centre-circle radius)");
      if (!(s.radius < s.ring_radius))
        throw common::InputError(what + ": expected inner_radius < outer_radius, found " +
                                 std::to_string(s.radius) + " >= " + std::to_string(s.ring_radius));
      break;
  }
  if (s.shape == WrapShape::kEllipsoid && s.ellipsoid_chords < 2)
    throw common::InputError(what + ": expected chords >= 2, found " + std::to_string(s.ellipsoid_chords));
  if (s.quadrant != WrapQuadrant::kAll && s.shape != WrapShape::kCylinder)
    throw common::InputError(what + ": a quadrant restriction is implemented for cylinders only; expected "
                                    "quadrant all");
}

SegmentWrap wrap_segment(const WrapSurface& s, const Vec3& a, const Vec3& b, int ellipsoid_chords,
                         std::vector<Vec3>* arc, const Vec3* first_node_guess) {
  switch (s.shape) {
    case WrapShape::kCylinder:
      return cylinder_wrap(a, b, s.radius, 0.5 * s.length, forbidden_angle(s.quadrant), arc);
    case WrapShape::kSphere:
      return sphere_wrap(a, b, s.radius, arc);
    case WrapShape::kEllipsoid:
      return ellipsoid_wrap(s, a, b, std::max(2, ellipsoid_chords), arc, first_node_guess);
    case WrapShape::kTorus:
      break;
  }
  throw common::InputError("wrap torus '" + s.name + "': not implemented yet");
}

}  // namespace arthrosim::musculoskeletal
