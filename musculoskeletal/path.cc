#include "musculoskeletal/path.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <sstream>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

// ------------------------------------------------------ CoordinateFunction --

namespace {

void check_knots(const std::vector<double>& x, const std::vector<double>& y, const char* what) {
  if (x.size() != y.size() || x.size() < 2)
    throw common::InputError(std::string(what) + ": expected x and y of equal size >= 2, found " +
                             std::to_string(x.size()) + " and " + std::to_string(y.size()));
  for (size_t i = 0; i < x.size(); ++i) {
    if (!std::isfinite(x[i]) || !std::isfinite(y[i]))
      throw common::InputError(std::string(what) + ": expected finite knots and values");
    if (i > 0 && !(x[i] > x[i - 1]))
      throw common::InputError(std::string(what) + ": expected strictly increasing x, found " +
                               std::to_string(x[i - 1]) + " then " + std::to_string(x[i]));
  }
}

}  // namespace

CoordinateFunction CoordinateFunction::constant(double value) {
  CoordinateFunction f;
  f.kind_ = Kind::kConstant;
  f.intercept_ = value;
  return f;
}

CoordinateFunction CoordinateFunction::linear(double slope, double intercept) {
  CoordinateFunction f;
  f.kind_ = Kind::kLinear;
  f.slope_ = slope;
  f.intercept_ = intercept;
  return f;
}

CoordinateFunction CoordinateFunction::piecewise_linear(std::vector<double> x, std::vector<double> y) {
  check_knots(x, y, "piecewise linear function");
  CoordinateFunction f;
  f.kind_ = Kind::kPiecewiseLinear;
  const size_t n = x.size();
  f.b_.resize(n);
  for (size_t i = 0; i + 1 < n; ++i) f.b_[i] = (y[i + 1] - y[i]) / (x[i + 1] - x[i]);
  f.b_[n - 1] = f.b_[n - 2];
  f.c_.assign(n, 0.0);
  f.d_.assign(n, 0.0);
  f.x_ = std::move(x);
  f.y_ = std::move(y);
  return f;
}

CoordinateFunction CoordinateFunction::cubic_spline(std::vector<double> x, std::vector<double> y) {
  check_knots(x, y, "cubic spline");
  CoordinateFunction f;
  f.kind_ = Kind::kCubicSpline;
  const int n = static_cast<int>(x.size());
  f.b_.assign(n, 0.0);
  f.c_.assign(n, 0.0);
  f.d_.assign(n, 0.0);
  if (n == 2) {
    f.b_[0] = f.b_[1] = (y[1] - y[0]) / (x[1] - x[0]);
  } else {
    // Second derivatives M_i: interior rows
    //   h_{i-1} M_{i-1} + 2 (h_{i-1} + h_i) M_i + h_i M_{i+1} = 6 (s_i - s_{i-1}),
    // s_i = (y_{i+1} - y_i) / h_i; end rows: the spline's third derivative on the
    // end interval, (M_1 - M_0)/h_0, equals 6 f[x_0..x_3] (third divided
    // difference; 0 for 3 points), likewise at the other end.
    std::vector<double> h(n - 1), s(n - 1);
    for (int i = 0; i + 1 < n; ++i) {
      h[i] = x[i + 1] - x[i];
      s[i] = (y[i + 1] - y[i]) / h[i];
    }
    auto dd3 = [&](int k) {  // f[x_k .. x_{k+3}]
      const double f01 = s[k], f12 = s[k + 1], f23 = s[k + 2];
      const double f012 = (f12 - f01) / (x[k + 2] - x[k]), f123 = (f23 - f12) / (x[k + 3] - x[k + 1]);
      return (f123 - f012) / (x[k + 3] - x[k]);
    };
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, n);
    Eigen::VectorXd r = Eigen::VectorXd::Zero(n);
    A(0, 0) = -1.0;
    A(0, 1) = 1.0;
    A(n - 1, n - 2) = -1.0;
    A(n - 1, n - 1) = 1.0;
    if (n >= 4) {
      r[0] = 6.0 * h[0] * dd3(0);
      r[n - 1] = 6.0 * h[n - 2] * dd3(n - 4);
    }
    for (int i = 1; i + 1 < n; ++i) {
      A(i, i - 1) = h[i - 1];
      A(i, i) = 2.0 * (h[i - 1] + h[i]);
      A(i, i + 1) = h[i];
      r[i] = 6.0 * (s[i] - s[i - 1]);
    }
    const Eigen::VectorXd M = A.partialPivLu().solve(r);
    for (int i = 0; i + 1 < n; ++i) {
      f.b_[i] = s[i] - h[i] * (2.0 * M[i] + M[i + 1]) / 6.0;
      f.c_[i] = 0.5 * M[i];
      f.d_[i] = (M[i + 1] - M[i]) / (6.0 * h[i]);
    }
    f.b_[n - 1] = s[n - 2] + h[n - 2] * (M[n - 2] + 2.0 * M[n - 1]) / 6.0;  // slope at the last knot
  }
  f.x_ = std::move(x);
  f.y_ = std::move(y);
  return f;
}

CoordinateFunction CoordinateFunction::scaled(double sc) const {
  CoordinateFunction f = *this;
  f.slope_ *= sc;
  f.intercept_ *= sc;
  for (auto* v : {&f.y_, &f.b_, &f.c_, &f.d_})
    for (double& e : *v) e *= sc;
  return f;
}

int CoordinateFunction::interval(double x) const {
  const auto it = std::upper_bound(x_.begin(), x_.end(), x);
  return std::clamp(static_cast<int>(it - x_.begin()) - 1, 0, static_cast<int>(x_.size()) - 2);
}

double CoordinateFunction::value(double x) const {
  switch (kind_) {
    case Kind::kConstant: return intercept_;
    case Kind::kLinear: return slope_ * x + intercept_;
    default: break;
  }
  const int n = static_cast<int>(x_.size());
  if (x < x_[0]) return y_[0] + (x - x_[0]) * b_[0];
  if (x > x_[n - 1]) return y_[n - 1] + (x - x_[n - 1]) * b_[n - 1];
  const int k = interval(x);
  const double dx = x - x_[k];
  return y_[k] + dx * (b_[k] + dx * (c_[k] + dx * d_[k]));
}

double CoordinateFunction::derivative(double x) const {
  switch (kind_) {
    case Kind::kConstant: return 0.0;
    case Kind::kLinear: return slope_;
    default: break;
  }
  const int n = static_cast<int>(x_.size());
  if (x < x_[0]) return b_[0];
  if (x > x_[n - 1]) return b_[n - 1];
  const int k = interval(x);
  const double dx = x - x_[k];
  return b_[k] + dx * (2.0 * c_[k] + 3.0 * dx * d_[k]);
}

// ------------------------------------------------------------------- paths --

namespace {

Vec3 unit_or_throw(const Vec3& v, const char* what) {
  const double n = v.norm();
  if (!(n > 1e-12)) {
    std::ostringstream s;
    s << "path: " << what << " has zero length (|d| = " << n
      << " m); the tension direction is undefined";
    throw common::NumericalError(s.str());
  }
  return v / n;
}

void add_straight(const Vec3& a, int body_a, const Vec3& b, int body_b, PathState& st) {
  const Vec3 u = unit_or_throw(b - a, "a straight segment");
  st.length += (b - a).norm();
  st.applications.push_back({body_a, a, u});
  st.applications.push_back({body_b, b, -u});
}

// A node of the evaluated polyline: an active path point or a contact point.
struct Node {
  Vec3 x_W;
  int body = -1;
  int point = -1;    ///< index into Path::points, -1 for a contact point
  int contact = -1;  ///< index into Pass::wraps for contact points
  bool entry = false;
};

struct ActiveWrap {
  int wrap = -1;  ///< index into Path::wraps
  Pose X_WS;
  SegmentWrap sw;
  std::vector<Vec3> arc_S;
  bool alive = true;
};

struct Pass {
  std::vector<Node> nodes;
  std::vector<ActiveWrap> wraps;
  bool any_ellipsoid = false;
};

Vec3 point_in_body(const PathPoint& p, const Eigen::VectorXd& q) {
  if (!p.is_moving()) return p.p_B;
  Vec3 r = p.p_B;
  for (int j = 0; j < 3; ++j)
    if (p.moving[j]) r[j] = p.moving[j]->value(q[p.moving_coordinate[j]]);
  return r;
}

int node_of_contact(const Pass& pass, int contact) {
  for (size_t k = 0; k < pass.nodes.size(); ++k)
    if (pass.nodes[k].contact == contact && pass.nodes[k].entry) return static_cast<int>(k);
  return -1;
}

// Wraps the segment between nodes k and k+1 over wrap `wi`; inserts the
// contact nodes and returns true when active.
bool try_wrap(const Path& path, const std::vector<Pose>& X_WB, int wi, int k, int chords,
              const std::optional<Vec3>& hint, Pass& pass) {
  const WrapSurface& surf = path.wraps[wi].surface;
  ActiveWrap aw;
  aw.wrap = wi;
  aw.X_WS = X_WB.at(surf.body) * surf.X_BS;
  const Pose X_SW = aw.X_WS.inverse();
  const Vec3 a = X_SW * pass.nodes[k].x_W, b = X_SW * pass.nodes[k + 1].x_W;
  aw.sw = wrap_segment(surf, a, b, chords, &aw.arc_S, hint ? &*hint : nullptr);
  if (!aw.sw.active) return false;
  const int c = static_cast<int>(pass.wraps.size());
  Node en{aw.X_WS * aw.sw.entry, surf.body, -1, c, true};
  Node ex{aw.X_WS * aw.sw.exit, surf.body, -1, c, false};
  pass.nodes.insert(pass.nodes.begin() + k + 1, {en, ex});
  if (surf.shape == WrapShape::kEllipsoid) pass.any_ellipsoid = true;
  pass.wraps.push_back(std::move(aw));
  return true;
}

// One evaluation of the wrapped path with `factor` x the ellipsoids' chords.
// hints[w]: initial guess of the first ellipsoid node of wrap w (surface frame).
Pass evaluate_pass(const Path& path, const std::vector<Pose>& X_WB, const Eigen::VectorXd& q, int factor,
                   const std::vector<std::optional<Vec3>>& hints) {
  Pass pass;
  const int n = static_cast<int>(path.points.size());
  for (int i = 0; i < n; ++i) {
    const PathPoint& p = path.points[i];
    if (p.is_conditional()) {
      const double v = q[p.condition_coordinate];
      if (!(v >= p.range_min && v <= p.range_max)) continue;
    }
    pass.nodes.push_back({X_WB.at(p.body) * point_in_body(p, q), p.body, i, -1, false});
  }
  if (pass.nodes.size() < 2)
    throw common::InputError("path: fewer than 2 active points (check the conditional points' ranges)");
  auto chords_of = [&](int wi) { return factor * std::max(2, path.wraps[wi].surface.ellipsoid_chords); };
  // First pass: each wrap in order wraps the first segment of its range that needs it.
  for (int wi = 0; wi < static_cast<int>(path.wraps.size()); ++wi) {
    const PathWrap& pw = path.wraps[wi];
    const int first = pw.first_point < 0 ? 0 : pw.first_point;
    const int last = pw.last_point < 0 ? n - 1 : pw.last_point;
    int start = -1, end = -1;
    for (int k = 0; k < static_cast<int>(pass.nodes.size()); ++k) {
      const int pi = pass.nodes[k].point;
      if (pi >= first && pi <= last) {
        if (start < 0) start = k;
        end = k;
      }
    }
    if (start < 0 || end <= start) continue;
    for (int k = start; k < end; ++k) {
      const Node &A = pass.nodes[k], &B = pass.nodes[k + 1];
      if (A.contact >= 0 && A.contact == B.contact) continue;  // another wrap's arc
      if (try_wrap(path, X_WB, wi, k, chords_of(wi), hints.empty() ? std::nullopt : hints[wi], pass)) break;
    }
  }
  // Gauss-Seidel refinement of chains of wraps.
  int alive = static_cast<int>(pass.wraps.size());
  if (alive >= 2) {
    double move = 0.0;
    int sweep = 0;
    for (; sweep < 200; ++sweep) {
      move = 0.0;
      for (size_t c = 0; c < pass.wraps.size(); ++c) {
        ActiveWrap& aw = pass.wraps[c];
        if (!aw.alive) continue;
        const int e = node_of_contact(pass, static_cast<int>(c));
        const WrapSurface& surf = path.wraps[aw.wrap].surface;
        const Pose X_SW = aw.X_WS.inverse();
        const Vec3 a = X_SW * pass.nodes[e - 1].x_W, b = X_SW * pass.nodes[e + 2].x_W;
        const Vec3 hint = aw.sw.entry;
        std::vector<Vec3> arc;
        const SegmentWrap sw = wrap_segment(surf, a, b, chords_of(aw.wrap), &arc,
                                            surf.shape == WrapShape::kEllipsoid ? &hint : nullptr);
        if (!sw.active) {
          aw.alive = false;
          pass.nodes.erase(pass.nodes.begin() + e, pass.nodes.begin() + e + 2);
          move = std::numeric_limits<double>::infinity();
          continue;
        }
        move = std::max({move, (sw.entry - aw.sw.entry).norm(), (sw.exit - aw.sw.exit).norm()});
        aw.sw = sw;
        aw.arc_S = std::move(arc);
        pass.nodes[e].x_W = aw.X_WS * sw.entry;
        pass.nodes[e + 1].x_W = aw.X_WS * sw.exit;
      }
      if (move < 1e-11) break;
    }
    if (!(move < 1e-11)) {
      std::ostringstream m;
      m << "path: the contact points of " << alive << " wraps on one path did not converge in " << sweep
        << " Gauss-Seidel sweeps (last change " << move << " m)";
      throw common::NumericalError(m.str());
    }
  }
  return pass;
}

// Length, polyline, applications and coordinate forces of a pass.
PathState assemble(const Path& path, const std::vector<Pose>& X_WB, const Eigen::VectorXd& q, const Pass& pass) {
  PathState st;
  const auto& N = pass.nodes;
  const int m = static_cast<int>(N.size());
  for (int k = 0; k + 1 < m; ++k) {
    if (N[k].contact >= 0 && N[k].entry && N[k + 1].contact == N[k].contact) {
      const ActiveWrap& aw = pass.wraps[N[k].contact];
      st.length += aw.sw.arc_length;
      st.points_W.push_back(N[k].x_W);
      for (size_t i = 1; i + 1 < aw.arc_S.size(); ++i) st.points_W.push_back(aw.X_WS * aw.arc_S[i]);
      if (!st.wrapped) st.wrap_arc_angle = aw.sw.arc_angle;
      st.wrapped = true;
      st.contacts.push_back({aw.wrap, N[k].x_W, N[k + 1].x_W, aw.sw.arc_length, aw.sw.arc_angle});
    } else {
      st.points_W.push_back(N[k].x_W);
      add_straight(N[k].x_W, N[k].body, N[k + 1].x_W, N[k + 1].body, st);
    }
  }
  st.points_W.push_back(N[m - 1].x_W);
  // Moving points: (u_out - u_in) . R_WB dp_B/dq_c per unit tension.
  for (int k = 0; k < m; ++k) {
    if (N[k].point < 0) continue;
    const PathPoint& p = path.points[N[k].point];
    if (!p.is_moving()) continue;
    Vec3 g = Vec3::Zero();
    if (k > 0) g -= (N[k].x_W - N[k - 1].x_W).normalized();
    if (k + 1 < m) g += (N[k + 1].x_W - N[k].x_W).normalized();
    const Eigen::Matrix3d R = X_WB.at(p.body).linear();
    for (int j = 0; j < 3; ++j) {
      if (!p.moving[j]) continue;
      const int c = p.moving_coordinate[j];
      const double f = g.dot(R.col(j)) * p.moving[j]->derivative(q[c]);
      auto it = std::find_if(st.coordinate_forces.begin(), st.coordinate_forces.end(),
                             [&](const CoordinateForce& cf) { return cf.coordinate == c; });
      if (it == st.coordinate_forces.end())
        st.coordinate_forces.push_back({c, f});
      else
        it->force += f;
    }
  }
  return st;
}

}  // namespace

bool path_needs_coordinates(const Path& path) {
  for (const PathPoint& p : path.points)
    if (p.is_conditional() || p.is_moving()) return true;
  return false;
}

bool path_depends_on(const Path& path, const std::vector<char>& moved, int c) {
  for (const PathPoint& p : path.points) {
    if (moved[p.body] || p.condition_coordinate == c) return true;
    for (int j = 0; j < 3; ++j)
      if (p.moving[j] && p.moving_coordinate[j] == c) return true;
  }
  for (const PathWrap& w : path.wraps)
    if (moved[w.surface.body]) return true;
  return false;
}

PathState evaluate_path(const Path& path, const std::vector<Pose>& X_WB) {
  return evaluate_path(path, X_WB, Eigen::VectorXd());
}

PathState evaluate_path(const Path& path, const std::vector<Pose>& X_WB, const Eigen::VectorXd& q) {
  if (path.points.size() < 2) throw common::InputError("path: expected >= 2 points");
  const bool needs_q = path_needs_coordinates(path);
  if (needs_q) {
    int max_c = -1;
    for (const PathPoint& p : path.points)
      max_c = std::max({max_c, p.condition_coordinate, p.moving_coordinate[0], p.moving_coordinate[1],
                        p.moving_coordinate[2]});
    if (q.size() <= max_c)
      throw common::InputError("path: conditional or moving points need the coordinates q (" +
                               std::to_string(max_c + 1) + " or more), found " + std::to_string(q.size()));
  }
  if (path.wraps.empty() && !needs_q) {
    // Straight chain of fixed points.
    PathState st;
    for (const PathPoint& pp : path.points) st.points_W.push_back(X_WB.at(pp.body) * pp.p_B);
    for (size_t i = 0; i + 1 < path.points.size(); ++i)
      add_straight(st.points_W[i], path.points[i].body, st.points_W[i + 1], path.points[i + 1].body, st);
    return st;
  }
  const Pass coarse = evaluate_pass(path, X_WB, q, 1, {});
  if (!coarse.any_ellipsoid) return assemble(path, X_WB, q, coarse);
  // Richardson over the ellipsoids' discretisation: (4 l_2N - l_N) / 3. The
  // fine pass starts every ellipsoid at the coarse first node moved back by a
  // quarter of the coarse first chord (the node offset scales with the chord).
  std::vector<std::optional<Vec3>> hints(path.wraps.size());
  for (const ActiveWrap& aw : coarse.wraps)
    if (aw.alive && path.wraps[aw.wrap].surface.shape == WrapShape::kEllipsoid && aw.arc_S.size() >= 2)
      hints[aw.wrap] = aw.arc_S[0] - 0.25 * (aw.arc_S[1] - aw.arc_S[0]);
  const Pass fine = evaluate_pass(path, X_WB, q, 2, hints);
  const PathState lc = assemble(path, X_WB, q, coarse);
  PathState st = assemble(path, X_WB, q, fine);
  st.length = (4.0 * st.length - lc.length) / 3.0;
  for (PathApplication& a : st.applications) a.direction_W *= 4.0 / 3.0;
  for (const PathApplication& a : lc.applications)
    st.applications.push_back({a.body, a.point_W, -a.direction_W / 3.0});
  for (CoordinateForce& f : st.coordinate_forces) f.force *= 4.0 / 3.0;
  for (const CoordinateForce& f : lc.coordinate_forces) {
    auto it = std::find_if(st.coordinate_forces.begin(), st.coordinate_forces.end(),
                           [&](const CoordinateForce& g) { return g.coordinate == f.coordinate; });
    if (it == st.coordinate_forces.end())
      st.coordinate_forces.push_back({f.coordinate, -f.force / 3.0});
    else
      it->force -= f.force / 3.0;
  }
  return st;
}

}  // namespace arthrosim::musculoskeletal
