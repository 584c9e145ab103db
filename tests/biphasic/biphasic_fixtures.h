#pragma once
// Shared fixtures of the biphasic tests: simple articular surfaces (flat
// rectangles, a quarter disk, a cylinder patch), column set-ups and the
// closed-form series the tests compare against (computed here from the
// published formulas, not tabulated).
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <functional>
#include <numbers>
#include <vector>

#include "biphasic/layer_mesh.h"
#include "biphasic/layer_system.h"
#include "common/mesh.h"

namespace arthrosim::biphasic::testing {

constexpr double kPi = std::numbers::pi;

// ---------------------------------------------------------------- surfaces

/// nx x ny quads on [0, lx] x [0, ly] at height z, counter-clockwise seen from
/// +z (normal +z). Node (i, j) has index j * (nx + 1) + i.
inline common::QuadMesh grid_surface(int nx, int ny, double lx, double ly, double z = 0.0) {
  common::QuadMesh m;
  m.name = "grid";
  m.V.resize((nx + 1) * (ny + 1), 3);
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i)
      m.V.row(j * (nx + 1) + i) << lx * i / nx, ly * j / ny, z;
  m.Q.resize(nx * ny, 4);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i;
      m.Q.row(j * nx + i) << a, a + 1, a + nx + 2, a + nx + 1;
    }
  return m;
}

/// Quarter disk of radius a (x, y >= 0) at height z as an O-grid of three
/// n x n blocks (inner square to 0.5 a, two outer blocks to the arc), normal +z.
inline common::QuadMesh quarter_disk_surface(int n, double a, double z = 0.0) {
  // Block corners in the (x, y) plane; outer edges on the arc.
  const double b = 0.5 * a;              // inner square corner on the axes
  const double c = 0.42 * a;             // inner square's diagonal corner (c, c)
  auto arc = [a](double t) {             // t in [0, 1]: angle t pi/4 .. from x axis
    return Eigen::Vector2d(a * std::cos(t * kPi / 4), a * std::sin(t * kPi / 4));
  };
  auto lerp = [](const Eigen::Vector2d& p, const Eigen::Vector2d& q, double t) {
    return Eigen::Vector2d((1 - t) * p + t * q);
  };
  // Transfinite (Coons) patch of four boundary curves.
  auto coons = [&](auto bottom, auto right, auto top, auto left, double s, double t) {
    const Eigen::Vector2d p00 = bottom(0.0), p10 = bottom(1.0), p11 = top(1.0), p01 = top(0.0);
    return Eigen::Vector2d((1 - t) * bottom(s) + t * top(s) + (1 - s) * left(t) + s * right(t) -
                           ((1 - s) * (1 - t) * p00 + s * (1 - t) * p10 + s * t * p11 +
                            (1 - s) * t * p01));
  };
  const Eigen::Vector2d O(0, 0), Bx(b, 0), By(0, b), C(c, c);
  const Eigen::Vector2d Ax = arc(0.0), Ad = arc(1.0);
  const Eigen::Vector2d Ay(0.0, a);
  std::vector<std::function<Eigen::Vector2d(double, double)>> blocks;
  // Block 0: inner square O, Bx, C, By.
  blocks.push_back([=](double s, double t) {
    return coons([&](double u) { return lerp(O, Bx, u); }, [&](double u) { return lerp(Bx, C, u); },
                 [&](double u) { return lerp(By, C, u); }, [&](double u) { return lerp(O, By, u); },
                 s, t);
  });
  // Block 1: Bx, Ax (x axis), arc to Ad, C.
  blocks.push_back([=](double s, double t) {
    return coons([&](double u) { return lerp(Bx, Ax, u); }, [&](double u) { return arc(u); },
                 [&](double u) { return lerp(C, Ad, u); }, [&](double u) { return lerp(Bx, C, u); },
                 s, t);
  });
  // Block 2: By, C, Ad, Ay: s along the y axis outward, t from the y axis to the diagonal.
  blocks.push_back([=](double s, double t) {
    auto arc2 = [a](double u) {  // from the y axis (90 deg) down to 45 deg
      return Eigen::Vector2d(a * std::cos(kPi / 2 - u * kPi / 4), a * std::sin(kPi / 2 - u * kPi / 4));
    };
    return coons([&](double u) { return lerp(By, Ay, u); }, [&](double u) { return arc2(u); },
                 [&](double u) { return lerp(C, Ad, u); }, [&](double u) { return lerp(By, C, u); },
                 s, t);
  });
  // Points of every block on an (n+1)^2 grid, merged by position.
  std::vector<Eigen::Vector2d> pts;
  auto index_of = [&](const Eigen::Vector2d& p) {
    for (size_t i = 0; i < pts.size(); ++i)
      if ((pts[i] - p).norm() < 1e-9 * a) return static_cast<int>(i);
    pts.push_back(p);
    return static_cast<int>(pts.size()) - 1;
  };
  std::vector<Eigen::Vector4i> quads;
  for (int k = 0; k < 3; ++k) {
    std::vector<int> id((n + 1) * (n + 1));
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i)
        id[j * (n + 1) + i] = index_of(blocks[k](static_cast<double>(i) / n, static_cast<double>(j) / n));
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const int a0 = id[j * (n + 1) + i], a1 = id[j * (n + 1) + i + 1];
        const int a2 = id[(j + 1) * (n + 1) + i + 1], a3 = id[(j + 1) * (n + 1) + i];
        // Orientation: make it counter-clockwise seen from +z.
        const Eigen::Vector2d e1 = pts[a1] - pts[a0], e2 = pts[a3] - pts[a0];
        if (e1.x() * e2.y() - e1.y() * e2.x() > 0) quads.emplace_back(a0, a1, a2, a3);
        else quads.emplace_back(a0, a3, a2, a1);
      }
  }
  common::QuadMesh m;
  m.name = "quarter_disk";
  m.V.resize(static_cast<int>(pts.size()), 3);
  for (size_t i = 0; i < pts.size(); ++i) m.V.row(i) << pts[i].x(), pts[i].y(), z;
  m.Q.resize(static_cast<int>(quads.size()), 4);
  for (size_t q = 0; q < quads.size(); ++q) m.Q.row(q) = quads[q].transpose();
  return m;
}

/// Constant normals (one row per node).
inline common::Points3 constant_normals(int n, const Eigen::Vector3d& normal) {
  common::Points3 N(n, 3);
  for (int i = 0; i < n; ++i) N.row(i) = normal.transpose();
  return N;
}

/// u-dofs (3 * node + component) of the given nodes.
inline std::vector<int> dofs_of(const std::vector<int>& nodes, std::initializer_list<int> components) {
  std::vector<int> out;
  for (int n : nodes)
    for (int c : components) out.push_back(3 * n + c);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

/// Indices of the rows of `points` for which pred(row) holds.
template <typename Pred>
std::vector<int> nodes_where(const common::Points3& points, Pred pred) {
  std::vector<int> out;
  for (int i = 0; i < points.rows(); ++i)
    if (pred(Eigen::Vector3d(points.row(i).transpose()))) out.push_back(i);
  return out;
}

// ------------------------------------------------------- closed-form series

/// Confined compression creep (Mow et al. 1980; Terzaghi): surface
/// displacement over its equilibrium value at T = H_A k t / h^2,
/// 1 - (8 / pi^2) sum_{m>=0} exp(-M^2 pi^2 T / 4) / M^2, M = 2m + 1.
inline double creep_fraction(double T) {
  if (T <= 0.0) return 0.0;
  double sum = 0.0;
  for (int m = 0; m < 200000; ++m) {
    const double M = 2.0 * m + 1.0;
    const double term = std::exp(-M * M * kPi * kPi * T / 4.0) / (M * M);
    sum += term;
    if (term < 1e-18) break;
  }
  return 1.0 - 8.0 / (kPi * kPi) * sum;
}

/// Terzaghi consolidation: pore pressure over the applied stress at depth
/// zeta = (distance from the drained surface) / h in [0, 1] and T:
/// sum_{m>=0} 4 / (M pi) sin(M pi zeta / 2) exp(-M^2 pi^2 T / 4).
inline double terzaghi_pressure(double zeta, double T) {
  double sum = 0.0;
  for (int m = 0; m < 200000; ++m) {
    const double M = 2.0 * m + 1.0;
    const double decay = std::exp(-M * M * kPi * kPi * T / 4.0);
    sum += 4.0 / (M * kPi) * std::sin(M * kPi * zeta / 2.0) * decay;
    if (decay < 1e-18) break;
  }
  return sum;
}

/// Ramp-and-hold confined compression stress relaxation (Mow et al. 1980):
/// total axial stress on the surface [Pa] (negative in compression) for a
/// surface displacement ramp at V0 [m/s] to t0, held afterwards.
/// tau = h^2 / (H_A k). Uses sum 1/(n pi)^2 = 1/6 so only the fast-converging
/// exponential sums are summed.
inline double relaxation_stress(double t, double t0, double V0, double h, double H, double k) {
  const double tau = h * h / (H * k);
  auto expsum = [tau](double s) {  // sum_n exp(-n^2 pi^2 s / tau) / (n^2 pi^2)
    if (s <= 0.0) return 1.0 / 6.0;
    double sum = 0.0;
    for (int n = 1; n < 2000000; ++n) {
      const double a = static_cast<double>(n) * n * kPi * kPi;
      const double e = std::exp(-a * s / tau);
      sum += e / a;
      if (e < 1e-18) break;
    }
    return sum;
  };
  if (t <= t0) return -H * V0 * t / h - 2.0 * V0 * h / k * (1.0 / 6.0 - expsum(t));
  return -H * V0 * t0 / h - 2.0 * V0 * h / k * (expsum(t - t0) - expsum(t));
}

/// Unconfined compression between frictionless impermeable platens of a disk
/// of radius a (Armstrong, Lai and Mow 1984), derived in
/// unconfined_compression_test.cc. For a unit step of axial strain the force
/// over its equilibrium value E_s eps0 pi a^2 is
///   F/F_inf = 1 + (1 - 2 nu)/(1 + nu) sum_n (2 - c) exp(-alpha_n^2 tau) / (alpha_n^2 - c (2 - c)),
/// tau = H_A k t / a^2, c = (1 - 2 nu)/(1 - nu), alpha_n the positive roots of
///   c J1(alpha) - alpha J0(alpha) = 0.
struct UnconfinedSeries {
  double nu = 0.0;
  double c = 0.0;
  std::vector<double> alpha;  ///< roots
  std::vector<double> coef;   ///< (2 - c) / (alpha^2 - c (2 - c))

  explicit UnconfinedSeries(double nu_s, int roots = 400) : nu(nu_s), c((1 - 2 * nu_s) / (1 - nu_s)) {
    auto f = [this](double x) { return c * std::cyl_bessel_j(1.0, x) - x * std::cyl_bessel_j(0.0, x); };
    // Roots are at least 2.5 apart (asymptotically pi, checked by the test), so a
    // scan at 0.1 brackets each one alone.
    const double step = 0.1;
    double x0 = step, f0 = f(x0);
    while (static_cast<int>(alpha.size()) < roots) {
      const double x1 = x0 + step, f1 = f(x1);
      if ((f0 < 0) != (f1 < 0)) {
        double lo = x0, hi = x1, flo = f0;
        for (int it = 0; it < 60 && hi - lo > 1e-15 * hi; ++it) {
          const double mid = 0.5 * (lo + hi), fm = f(mid);
          if ((fm < 0) == (flo < 0)) { lo = mid; flo = fm; } else { hi = mid; }
        }
        const double r = 0.5 * (lo + hi);
        alpha.push_back(r);
        coef.push_back((2 - c) / (r * r - c * (2 - c)));
      }
      x0 = x1;
      f0 = f1;
    }
  }
  /// Step response F/F_inf at tau > 0 (tau = 0: the 0+ limit with the tail
  /// of the sum estimated by its asymptotic form).
  double step(double tau) const {
    double s = 0.0;
    for (size_t n = 0; n < alpha.size(); ++n) s += coef[n] * std::exp(-alpha[n] * alpha[n] * tau);
    if (tau == 0.0) s += tail();
    return 1.0 + (1 - 2 * nu) / (1 + nu) * s;
  }
  /// Integral of (F/F_inf - 1) of the step response from 0 to tau, in tau units.
  double step_integral(double tau) const {
    double s = 0.0;
    for (size_t n = 0; n < alpha.size(); ++n) {
      const double a2 = alpha[n] * alpha[n];
      s += coef[n] * (1.0 - std::exp(-a2 * tau)) / a2;
    }
    return (1 - 2 * nu) / (1 + nu) * s;
  }
  /// Ramp of the axial strain to 1 at tau0, held: F/F_inf(eps0 = 1) at tau.
  double ramp(double tau, double tau0) const {
    auto I = [this](double s) { return s <= 0.0 ? 0.0 : s + step_integral(s); };
    return (I(tau) - I(tau - tau0)) / tau0;
  }
  /// Sum of coef over the roots beyond those computed, from the asymptotic
  /// root spacing pi: (2 - c) sum_{n > N} 1/alpha_n^2 ~ (2 - c) / (pi^2 N).
  double tail() const { return (2 - c) / (kPi * kPi * alpha.size()); }
};

}  // namespace arthrosim::biphasic::testing
