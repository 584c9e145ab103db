#include "musculoskeletal/wrap.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

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
[[gnu::always_inline]] inline D2 operator+(const D2& a, const D2& b) { return {a.v + b.v, a.d0 + b.d0, a.d1 + b.d1}; }
[[gnu::always_inline]] inline D2 operator-(const D2& a, const D2& b) { return {a.v - b.v, a.d0 - b.d0, a.d1 - b.d1}; }
[[gnu::always_inline]] inline D2 operator-(const D2& a) { return {-a.v, -a.d0, -a.d1}; }
[[gnu::always_inline]] inline D2 operator*(const D2& a, const D2& b) {
  return {a.v * b.v, a.d0 * b.v + a.v * b.d0, a.d1 * b.v + a.v * b.d1};
}
[[gnu::always_inline]] inline D2 operator*(double s, const D2& a) { return {s * a.v, s * a.d0, s * a.d1}; }
[[gnu::always_inline]] inline D2 operator/(const D2& a, const D2& b) {
  const double inv = 1.0 / b.v, q = a.v * inv;
  return {q, (a.d0 - q * b.d0) * inv, (a.d1 - q * b.d1) * inv};
}
[[gnu::always_inline]] inline D2 dsqrt(const D2& a) {
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
[[gnu::always_inline]] inline V3<T> operator+(const V3<T>& a, const V3<T>& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
template <class T>
[[gnu::always_inline]] inline V3<T> operator-(const V3<T>& a, const V3<T>& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
template <class T>
[[gnu::always_inline]] inline V3<T> scale(const T& s, const V3<T>& a) { return {s * a.x, s * a.y, s * a.z}; }
template <class T>
[[gnu::always_inline]] inline T dot(const V3<T>& a, const V3<T>& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
// A v (A = diag(k)).
template <class T>
[[gnu::always_inline]] inline V3<T> amul(const Vec3& k, const V3<T>& v) { return {k.x() * v.x, k.y() * v.y, k.z() * v.z}; }
template <class T>
[[gnu::always_inline]] inline V3<T> lift(const Vec3& v) { return {T(v.x()), T(v.y()), T(v.z())}; }

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
    const V3<T> Au = amul(s.A, u);
    const T t = -T(2.0) * dot(u, g) / dot(u, Au);
    x = x + scale(t, u);
    g = g + scale(t, Au);  // = A x
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

// The section of the ellipsoid by the plane through p spanned by dir and
// side (orthonormal): x(tau) = p + z_s dir + z_t side with
// z(tau) = z_c + V (sqrt(k / l1) cos tau, sqrt(k / l2) sin tau).
struct Section {
  Vec3 p, dir, side;
  Eigen::Vector2d zc;
  Eigen::Matrix2d V;
  double r1 = 0, r2 = 0;
  Vec3 point(double tau) const {
    const Eigen::Vector2d z = zc + V * Eigen::Vector2d(r1 * std::cos(tau), r2 * std::sin(tau));
    return p + z[0] * dir + z[1] * side;
  }
  double angle(const Vec3& x) const {
    const Eigen::Vector2d w = V.transpose() * (Eigen::Vector2d((x - p).dot(dir), (x - p).dot(side)) - zc);
    return std::atan2(w[1] / r2, w[0] / r1);
  }
  double t_coordinate(double tau) const { return (point(tau) - p).dot(side); }
};

Section make_section(const Vec3& A, const Vec3& p, const Vec3& dir, const Vec3& side) {
  auto Am = [&](const Vec3& v) { return Vec3(A.cwiseProduct(v)); };
  Eigen::Matrix2d M;
  M << dir.dot(Am(dir)), dir.dot(Am(side)), dir.dot(Am(side)), side.dot(Am(side));
  const Eigen::Vector2d bv(dir.dot(Am(p)), side.dot(Am(p)));
  const double c = p.dot(Am(p)) - 1.0;
  Section sec;
  sec.p = p;
  sec.dir = dir;
  sec.side = side;
  sec.zc = -M.ldlt().solve(bv);
  const double k = std::max(1e-300, bv.dot(-sec.zc) - c);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(M);
  sec.V = es.eigenvectors();
  sec.r1 = std::sqrt(k / es.eigenvalues()[0]);
  sec.r2 = std::sqrt(k / es.eigenvalues()[1]);
  return sec;
}

// Residuals of all nodes of the discrete geodesic (multiple shooting): node
// k at x_k = D normalize(y_k + E_k u_k); r_k = the tangential components of
// unit(x_k - x_{k-1}) - unit(x_{k+1} - x_k) (x_{-1} = P, x_{N+1} = S) on the
// projections of D E_k.
template <class T>
void all_node_residuals(const Vec3& D, const Vec3& A, const Vec3& P, const Vec3& S, const std::vector<Vec3>& y,
                        const std::vector<Vec3>& e1, const std::vector<Vec3>& e2, const std::vector<T>& u,
                        std::vector<T>& r) {
  const int n = static_cast<int>(y.size());
  std::vector<V3<T>> x(n);
  for (int k = 0; k < n; ++k) {
    V3<T> yy = lift<T>(y[k]) + scale(u[2 * k], lift<T>(e1[k])) + scale(u[2 * k + 1], lift<T>(e2[k]));
    yy = scale(T(1.0) / dsqrt(dot(yy, yy)), yy);
    x[k] = amul(D, yy);
  }
  auto unit = [](const V3<T>& v) { return scale(T(1.0) / dsqrt(dot(v, v)), v); };
  for (int k = 0; k < n; ++k) {
    const V3<T> a = unit(x[k] - (k == 0 ? lift<T>(P) : x[k - 1]));
    const V3<T> b = unit((k + 1 == n ? lift<T>(S) : x[k + 1]) - x[k]);
    const V3<T> g = amul(A, x[k]);
    const V3<T> nn = unit(g);
    const V3<T> diff = a - b;
    for (int j = 0; j < 2; ++j) {
      const V3<T> F = amul(D, lift<T>(j == 0 ? e1[k] : e2[k]));
      const V3<T> Ft = F - scale(dot(F, nn), nn);
      r[2 * k + j] = dot(Ft, diff);
    }
  }
}

// Newton on all nodes (block-tridiagonal 2x2 Jacobian from three coloured
// dual-number passes); y: initial nodes on the unit sphere of y = x / D,
// replaced by the solution. Returns false when it does not converge.
bool solve_all_nodes(const Vec3& D, const Vec3& A, const Vec3& P, const Vec3& S, std::vector<Vec3>& y, int* its) {
  const int n = static_cast<int>(y.size());
  std::vector<Vec3> e1(n), e2(n);
  auto charts = [&]() {
    for (int k = 0; k < n; ++k) {
      e1[k] = y[k].unitOrthogonal();
      e2[k] = y[k].cross(e1[k]);
    }
  };
  charts();
  std::vector<double> u(2 * n, 0.0), r(2 * n);
  auto norm_of = [&](const std::vector<double>& uu) {
    all_node_residuals<double>(D, A, P, S, y, e1, e2, uu, r);
    double m = 0;  // 2-norm: the Newton direction is a descent direction for it
    for (double v : r) m += v * v;
    return std::sqrt(m);
  };
  double rn = norm_of(u);
  std::vector<Eigen::Matrix2d> L(n), Dg(n), U(n);
  std::vector<D2> ud(2 * n), rd(2 * n);
  for (int it = 0; it < 60; ++it) {
    if (its) *its = it;
    if (rn < 1e-11) return true;
    for (int color = 0; color < 3; ++color) {
      for (int k = 0; k < n; ++k) {
        const bool seeded = k % 3 == color;
        ud[2 * k] = D2(0.0, seeded ? 1.0 : 0.0, 0.0);
        ud[2 * k + 1] = D2(0.0, 0.0, seeded ? 1.0 : 0.0);
      }
      all_node_residuals<D2>(D, A, P, S, y, e1, e2, ud, rd);
      for (int j = 0; j < n; ++j)
        for (int k = std::max(0, j - 1); k <= std::min(n - 1, j + 1); ++k) {
          if (k % 3 != color) continue;
          Eigen::Matrix2d B;
          B << rd[2 * j].d0, rd[2 * j].d1, rd[2 * j + 1].d0, rd[2 * j + 1].d1;
          (k == j ? Dg[j] : (k < j ? L[j] : U[j])) = B;
        }
    }
    all_node_residuals<double>(D, A, P, S, y, e1, e2, u, r);  // u = 0
    // Block Thomas algorithm.
    std::vector<Eigen::Matrix2d> Dp(n);
    std::vector<Eigen::Vector2d> rp(n), du(n);
    Dp[0] = Dg[0];
    rp[0] = Eigen::Vector2d(r[0], r[1]);
    for (int j = 1; j < n; ++j) {
      const Eigen::Matrix2d W = L[j] * Dp[j - 1].inverse();
      Dp[j] = Dg[j] - W * U[j - 1];
      rp[j] = Eigen::Vector2d(r[2 * j], r[2 * j + 1]) - W * rp[j - 1];
    }
    du[n - 1] = Dp[n - 1].inverse() * rp[n - 1];
    for (int j = n - 2; j >= 0; --j) du[j] = Dp[j].inverse() * (rp[j] - U[j] * du[j + 1]);
    double lam = 1.0, rn_new = rn;
    std::vector<double> trial(2 * n);
    for (int ls = 0; ls < 30; ++ls, lam *= 0.5) {
      for (int k = 0; k < n; ++k) {
        trial[2 * k] = -lam * du[k][0];
        trial[2 * k + 1] = -lam * du[k][1];
      }
      rn_new = norm_of(trial);
      if (std::isfinite(rn_new) && rn_new < rn) break;
    }
    if (!(rn_new < rn)) return false;
    for (int k = 0; k < n; ++k)
      y[k] = (y[k] + trial[2 * k] * e1[k] + trial[2 * k + 1] * e2[k]).normalized();
    charts();
    rn = rn_new;
  }
  return false;
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
  // Where that guess fails (a segment near the body's centre, where the two
  // sides are nearly equally short), the opposite side is tried as well and
  // the shorter solution is kept (the length stays continuous through the
  // switch of sides; the contact points jump, as for any shortest path).
  const Vec3 mpt = a + t_min * d;
  const Vec3 dir = d / d.norm();
  // Q: in the plane through m normal to the segment, the point of the
  // section ellipse closest to m (the shortest way out across the segment).
  Vec3 side0;
  {
    const Vec3 p1 = any_perpendicular(dir), p2 = dir.cross(p1);
    Eigen::Matrix2d M2;
    M2 << p1.dot(A.cwiseProduct(p1)), p1.dot(A.cwiseProduct(p2)), p1.dot(A.cwiseProduct(p2)),
        p2.dot(A.cwiseProduct(p2));
    const Eigen::Vector2d b2(p1.dot(A.cwiseProduct(mpt)), p2.dot(A.cwiseProduct(mpt)));
    const Eigen::Vector2d zc = -M2.ldlt().solve(b2);
    const double kap = std::max(1e-300, b2.dot(-zc) - (quad(mpt) - 1.0));
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(M2);
    const Eigen::Vector2d w0 = -es.eigenvectors().transpose() * zc;  // m in the section's axes
    const Vec3 q3 = closest_surface_point(
        Vec3(std::sqrt(kap / es.eigenvalues()[0]), std::sqrt(kap / es.eigenvalues()[1]), 1e30), Vec3(w0[0], w0[1], 0.0));
    const Eigen::Vector2d z = es.eigenvectors() * (Eigen::Vector2d(q3.x(), q3.y()) - w0);  // from m
    side0 = z[0] * p1 + z[1] * p2;
    if (!(side0.norm() > 1e-12 * D.maxCoeff())) side0 = p1;
    side0.normalize();
  }
  const double tiny = 1e-12 * D.maxCoeff();

  struct Solution {
    bool found = false;     // converged, valid and within the planar bound
    bool have = false;      // converged and valid with N chords (maybe beyond the bound)
    double total = 0.0;
    EllipsoidShot s;
    double al = 0, be = 0;
    int its = 0;
  };
  // Solves for the discrete geodesic with the planar guess on `side`.
  auto attempt = [&](const Vec3& side, const Vec3* x0_hint) {
    Solution best;
    EllipsoidShot s;
    s.D = D;
    s.A = A;
    s.P = a;
    s.S = b;
    s.N = N;
    const Vec3 T1 = section_tangent_point(A, a, dir, side);
    const Vec3 T2 = section_tangent_point(A, b, -dir, side);
    const Vec3 t1 = (T1 - a).normalized();
    // u_N - w is (nearly) normal to the exit direction: measure it on the
    // surface normal and the binormal at the guessed exit.
    {
      const Vec3 n = A.cwiseProduct(T2).normalized();
      const Vec3 t = (dir - dir.dot(n) * n).normalized();
      s.r1 = n;
      s.r2 = n.cross(t);
    }
    auto set_chart = [&](const Vec3& x0) {
      const Vec3 y0 = x0.cwiseQuotient(D).normalized();
      s.y0 = y0;
      // Chart directions in y: the image of the travel direction and its
      // normal, tangent to the unit sphere at y0.
      Vec3 ta = dir.cwiseQuotient(D);
      ta = (ta - ta.dot(y0) * y0).normalized();
      s.ea = ta;
      s.eb = y0.cross(ta);
    };
    // The discrete x_0 lies past the tangent point T1 by half a chord angle:
    // delta = theta / (n + 1) with theta the planar guess's turning angle,
    // i.e. by an arc length delta / (2 kappa) (kappa the normal curvature).
    auto planar_guess = [&](int n) {
      const double theta = std::acos(std::clamp(t1.dot((b - T2).normalized()), -1.0, 1.0));
      const double kappa = t1.dot(A.cwiseProduct(t1)) / A.cwiseProduct(T1).norm();
      const Vec3 x = T1 + (theta / (n + 1) / (2 * kappa)) * t1;
      return Vec3(x / std::sqrt(quad(x)));
    };
    // Newton on (alpha, beta) (single shooting); each iteration costs one
    // dual-number shot (a halving line search on |r| only when a full step
    // does not reduce it).
    double al = 0.0, be = 0.0, rn = 0.0;
    int it = 0;
    auto single = [&](int max_its) {
      al = be = 0.0;
      D2 rd[2];
      shoot<D2>(s, D2(al, 1, 0), D2(be, 0, 1), rd);
      rn = std::sqrt(rd[0].v * rd[0].v + rd[1].v * rd[1].v);
      for (it = 0; it < max_its && std::isfinite(rn); ++it) {
        if (rn < 1e-11) return true;  // the initial guess is already converged
        const double j00 = rd[0].d0, j01 = rd[0].d1, j10 = rd[1].d0, j11 = rd[1].d1;
        const double det = j00 * j11 - j01 * j10;
        if (!(std::abs(det) > 0) || !std::isfinite(det)) return false;
        const double da = -(j11 * rd[0].v - j01 * rd[1].v) / det;
        const double db = -(-j10 * rd[0].v + j00 * rd[1].v) / det;
        const double step = std::sqrt(da * da + db * db);
        D2 rn_d[2];
        shoot<D2>(s, D2(al + da, 1, 0), D2(be + db, 0, 1), rn_d);
        double rn_new = std::sqrt(rn_d[0].v * rn_d[0].v + rn_d[1].v * rn_d[1].v);
        double lam = 1.0;
        if (!(rn_new < rn)) {
          if (rn < 1e-12) return true;  // no decrease possible at rounding level
          double r[2];
          for (int ls = 0; ls < 40; ++ls) {
            lam *= 0.5;
            shoot<double>(s, al + lam * da, be + lam * db, r);
            rn_new = std::sqrt(r[0] * r[0] + r[1] * r[1]);
            if (rn_new < rn) break;
          }
          if (!(rn_new < rn)) return false;
          shoot<D2>(s, D2(al + lam * da, 1, 0), D2(be + lam * db, 0, 1), rn_d);
          rn_new = std::sqrt(rn_d[0].v * rn_d[0].v + rn_d[1].v * rn_d[1].v);
        }
        rd[0] = rn_d[0];
        rd[1] = rn_d[1];
        al += lam * da;
        be += lam * db;
        rn = rn_new;
        // Converged when the residual (a difference of unit vectors, i.e. an
        // angle) is below 1e-11 rad: the length is then stationary to ~1e-11
        // x its straight parts, far below any moment-arm tolerance.
        if (rn < 1e-11 || (lam == 1.0 && step < 1e-9)) {
          ++it;
          return true;
        }
      }
      return false;
    };
    // A discrete geodesic is not longer than the geodesic, which is not
    // longer than the planar path over the section through a and b on this
    // side (straight to T1, the section's arc, straight from T2). The arc is
    // integrated by 16-point Gauss-Legendre quadrature of the ellipse's
    // speed; a result longer than 1.001 x this bound is another branch (e.g.
    // one spiralling round the body).
    const Section sec = make_section(A, a, dir, side);
    const double tau1 = sec.angle(T1), tau2 = sec.angle(T2);
    double span = mod_two_pi(tau2 - tau1);
    if (sec.t_coordinate(tau1 + 0.5 * span) < 0) span -= 2 * kPi;
    double planar_arc = 0.0;
    {
      static const double gx[8] = {0.0950125098376374, 0.2816035507792589, 0.4580167776572274,
                                   0.6178762444026438, 0.7554044083550030, 0.8656312023878318,
                                   0.9445750230732326, 0.9894009349916499};
      static const double gw[8] = {0.1894506104550685, 0.1826034150449236, 0.1691565193950025,
                                   0.1495959888165767, 0.1246289712555339, 0.0951585116824928,
                                   0.0622535239386479, 0.0271524594117541};
      auto speed = [&](double tau) { return std::hypot(sec.r1 * std::sin(tau), sec.r2 * std::cos(tau)); };
      const double mid = tau1 + 0.5 * span, half = 0.5 * std::abs(span);
      for (int i = 0; i < 8; ++i)
        planar_arc += gw[i] * half * (speed(mid + gx[i] * 0.5 * span) + speed(mid - gx[i] * 0.5 * span));
    }
    const double bound = 1.001 * ((T1 - a).norm() + (b - T2).norm() + planar_arc) + 1e-12;
    std::vector<Vec3> nodes;
    double total = 0.0;
    // Chords positive (the wrapped side; at engagement they shrink to zero,
    // where rounding may leave ~1e-17 m of either sign).
    auto valid = [&]() {
      nodes.clear();
      std::vector<double> steps;
      double r[2], first = 0, last = 0;
      shoot<double>(s, al, be, r, &nodes, &steps, &first, &last);
      total = first + last;
      for (double t : steps) {
        if (!(t > -tiny)) return false;
        total += t;
      }
      return std::isfinite(total);
    };
    auto record = [&](bool converged) {
      if (!(converged && valid())) return false;
      const bool within = total <= bound;
      if (s.N == N && (!best.have || (within && !best.found) || (within == best.found && total < best.total))) {
        best.have = true;
        best.found = within;
        best.total = total;
        best.s = s;
        best.al = al;
        best.be = be;
      }
      return true;
    };
    set_chart(x0_hint ? *x0_hint : planar_guess(N));
    // First attempt: at most 12 iterations (a good guess converges in 2-4).
    bool ok = record(single(12));
    best.its += it;
    if (best.found) return best;
    // Continuation in the number of chords: solve with n_0 <= 4 chords
    // (multiple shooting from nodes on the planar section, or else single
    // shooting from the planar guess), then double n up to N, each solve
    // started from the previous first node moved back by the change of half
    // a chord.
    std::vector<int> seq{N};
    while (seq.back() > 4) seq.push_back((seq.back() + 1) / 2);
    std::reverse(seq.begin(), seq.end());
    s.N = seq[0];
    std::vector<Vec3> y(s.N + 1);
    for (int k = 0; k <= s.N; ++k)
      y[k] = sec.point(tau1 + (k + 0.5) * span / (s.N + 1)).cwiseQuotient(D).normalized();
    int ms_its = 0;
    ok = solve_all_nodes(D, A, a, b, y, &ms_its);
    best.its += ms_its;
    if (ok) {
      set_chart(D.cwiseProduct(y[0]));
      ok = record(single(50));
      best.its += it;
    }
    if (!ok) {
      set_chart(planar_guess(s.N));
      ok = record(single(50));
      best.its += it;
    }
    for (size_t i = 1; i < seq.size() && ok; ++i) {
      const double shift = 0.5 * (1.0 - double(s.N + 1) / (seq[i] + 1));
      const Vec3 guess = nodes[0] - shift * (nodes[1] - nodes[0]);
      s.N = seq[i];
      set_chart(guess);
      ok = record(single(50));
      best.its += it;
    }
    return best;
  };

  Solution sol = attempt(side0, hint);
  if (!sol.found) {
    Solution other = attempt(-side0, nullptr);
    other.its += sol.its;
    if (other.have && (!sol.have || (other.found && !sol.found) ||
                       (other.found == sol.found && other.total < sol.total)))
      sol = other;
    else
      sol.its = other.its;
  }
  if (!sol.have) {
    std::ostringstream msg;
    msg << "the discrete geodesic (" << N << " chords) was not found on either side (" << sol.its
        << " Newton iterations, single and multiple shooting, continuation in the number of chords)";
    ellipsoid_failure(surf, msg.str());
  }
  std::vector<Vec3> nodes;
  std::vector<double> steps;
  nodes.reserve(N + 1);
  steps.reserve(N);
  {
    double r[2];
    shoot<double>(sol.s, sol.al, sol.be, r, &nodes, &steps);
  }
  double arc_len = 0.0;
  for (double t : steps) arc_len += t;
  const int it = sol.its;
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

// ------------------------------------------------------------------- torus --
// Frame of the local cylinder at angle phi of the centre circle: origin on the
// circle, z along its tangent, x towards the torus axis (the allowed side).
Pose torus_section(double ring, double phi) {
  const double c = std::cos(phi), s = std::sin(phi);
  Pose X = Pose::Identity();
  X.linear().col(0) = Vec3(-c, -s, 0.0);
  X.linear().col(1) = Vec3(0.0, 0.0, 1.0);
  X.linear().col(2) = Vec3(-s, c, 0.0);
  X.translation() = Vec3(ring * c, ring * s, 0.0);
  return X;
}

SegmentWrap torus_wrap(const WrapSurface& surf, const Vec3& a, const Vec3& b, std::vector<Vec3>* arc) {
  // Through the hole: the segment crosses z = 0 inside the centre circle.
  if (!((a.z() > 0) != (b.z() > 0))) return SegmentWrap{};
  const double f = a.z() / (a.z() - b.z());
  const Vec3 cross = a + f * (b - a);
  if (!(std::hypot(cross.x(), cross.y()) < surf.ring_radius)) return SegmentWrap{};
  const double R = surf.radius, ring = surf.ring_radius;
  auto length_at = [&](double phi, SegmentWrap* out, std::vector<Vec3>* pts) {
    const Pose X = torus_section(ring, phi);
    const Pose Xi = X.inverse();
    const Vec3 ac = Xi * a, bc = Xi * b;
    const SegmentWrap w = cylinder_wrap(ac, bc, R, std::numeric_limits<double>::infinity(), kPi, pts);
    if (out) *out = w;
    return w.active ? (w.entry - ac).norm() + w.arc_length + (bc - w.exit).norm() : (bc - ac).norm();
  };
  const double phi_c = std::atan2(cross.y(), cross.x());
  SegmentWrap w0;
  length_at(phi_c, &w0, nullptr);
  if (!w0.active) return SegmentWrap{};
  // Maximise l(phi) (Danskin: the most constraining section) by Newton on
  // l'(phi) = 0 with central differences of the closed-form l: l' with
  // h = 1e-6 rad (rounding ~1e-16 l / h), l'' with h2 = 1e-3 rad (l'' h2^2
  // ~1e-10 m stays far above rounding; it only steers the iteration), steps
  // limited to 0.05 rad, within a quarter turn of phi_c.
  const double h = 1e-6, h2 = 1e-3, window = kPi / 4;
  double phi = phi_c;
  int it = 0;
  bool converged = false;
  for (; it < 100; ++it) {
    const double lp = length_at(phi + h, nullptr, nullptr), l0 = length_at(phi, nullptr, nullptr),
                 lm = length_at(phi - h, nullptr, nullptr);
    const double lpp = length_at(phi + h2, nullptr, nullptr), lmm = length_at(phi - h2, nullptr, nullptr);
    const double d1 = (lp - lm) / (2 * h), d2 = (lpp - 2 * l0 + lmm) / (h2 * h2);
    // Converged when l' is at its rounding level (8 ulp(l) / h, ~5e-10 m/rad
    // for l = 0.3 m): phi* is then known to |l'| / |l''|, and the envelope
    // error of the moment arms is of the order of l' itself.
    if (d2 < 0 && std::abs(d1) < 8 * std::numeric_limits<double>::epsilon() * l0 / h) {
      converged = true;
      ++it;
      break;
    }
    double step = d2 < 0 ? -d1 / d2 : (d1 > 0 ? 0.05 : -0.05);
    step = std::clamp(step, -0.05, 0.05);
    phi = std::clamp(phi + step, phi_c - window, phi_c + window);
    if (std::abs(step) < 1e-10 && d2 < 0) {
      converged = true;
      ++it;
      break;
    }
  }
  if (!converged) {
    std::ostringstream m;
    m << "wrap torus '" << surf.name << "': the most constraining section was not found (" << it
      << " iterations, phi = " << phi << " rad)";
    throw common::NumericalError(m.str());
  }
  SegmentWrap w;
  std::vector<Vec3> pts;
  length_at(phi, &w, arc ? &pts : nullptr);
  if (!w.active) return SegmentWrap{};
  const Pose X = torus_section(ring, phi);
  w.entry = X * w.entry;
  w.exit = X * w.exit;
  w.X_SC = X;
  w.iterations = it;
  if (arc)
    for (const Vec3& p : pts) arc->push_back(X * p);
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
      return torus_wrap(s, a, b, arc);
  }
  throw common::InputError("wrap '" + s.name + "': unknown shape");
}

}  // namespace arthrosim::musculoskeletal
