#include "musculoskeletal/path.h"

#include <cmath>
#include <numbers>
#include <sstream>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

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

// Wrapped two-point path; returns false when the wrap is inactive.
bool wrap_cylinder(const Path& path, const std::vector<Pose>& X_WB, PathState& st) {
  const WrapCylinder& cyl = *path.cylinder;
  const Pose X_WC = X_WB.at(cyl.body) * cyl.X_BC;
  const Vec3 P_W = X_WB.at(path.points[0].body) * path.points[0].p_B;
  const Vec3 S_W = X_WB.at(path.points[1].body) * path.points[1].p_B;
  const Vec3 P = X_WC.inverse() * P_W;
  const Vec3 S = X_WC.inverse() * S_W;
  const double R = cyl.radius;
  const double rho_P = std::hypot(P.x(), P.y()), rho_S = std::hypot(S.x(), S.y());
  if (rho_P <= R || rho_S <= R) return false;
  const double phi_P = std::atan2(P.y(), P.x()), phi_S = std::atan2(S.y(), S.x());
  double delta = phi_S - phi_P;
  const double pi = std::numbers::pi;
  while (delta > pi) delta -= 2 * pi;
  while (delta <= -pi) delta += 2 * pi;
  const double sgn = delta >= 0.0 ? 1.0 : -1.0;  // sense of travel around the axis
  const double a_P = std::acos(R / rho_P), a_S = std::acos(R / rho_S);
  const double theta = std::abs(delta) - a_P - a_S;
  if (theta <= 0.0) return false;
  // Tangent points (angles measured in the sense of travel).
  const double t1 = phi_P + sgn * a_P, t2 = phi_S - sgn * a_S;
  const double seg_P = rho_P * std::sin(a_P), seg_S = rho_S * std::sin(a_S);
  const double L = seg_P + R * theta + seg_S;
  const double dz = S.z() - P.z();
  st.length = std::sqrt(L * L + dz * dz);
  st.wrapped = true;
  st.wrap_arc_angle = theta;
  const Vec3 T1(R * std::cos(t1), R * std::sin(t1), P.z() + dz * seg_P / L);
  const Vec3 T2(R * std::cos(t2), R * std::sin(t2), P.z() + dz * (L - seg_S) / L);
  const Vec3 T1_W = X_WC * T1, T2_W = X_WC * T2;
  // Polyline for output: P, T1, points along the helix, T2, S.
  st.points_W.push_back(P_W);
  const int n_arc = 8;
  for (int i = 0; i <= n_arc; ++i) {
    const double f = double(i) / n_arc;
    const double ang = t1 + sgn * theta * f;
    const double z = T1.z() + (T2.z() - T1.z()) * f;
    st.points_W.push_back(X_WC * Vec3(R * std::cos(ang), R * std::sin(ang), z));
  }
  st.points_W.push_back(S_W);
  // dl/dP (in 3D) is the unit vector from T1 to P; the tension pulls P towards T1.
  const Vec3 d_P = unit_or_throw(T1_W - P_W, "the origin-to-wrap segment");
  const Vec3 d_S = unit_or_throw(T2_W - S_W, "the wrap-to-insertion segment");
  st.applications.push_back({path.points[0].body, P_W, d_P});
  st.applications.push_back({cyl.body, P_W, -d_P});
  st.applications.push_back({path.points[1].body, S_W, d_S});
  st.applications.push_back({cyl.body, S_W, -d_S});
  return true;
}

}  // namespace

PathState evaluate_path(const Path& path, const std::vector<Pose>& X_WB) {
  PathState st;
  if (path.points.size() < 2) throw common::InputError("path: expected >= 2 points");
  if (path.cylinder) {
    if (path.points.size() != 2)
      throw common::InputError("path: cylinder wrapping needs exactly 2 points");
    if (wrap_cylinder(path, X_WB, st)) return st;
  }
  for (const PathPoint& pp : path.points) st.points_W.push_back(X_WB.at(pp.body) * pp.p_B);
  for (size_t i = 0; i + 1 < path.points.size(); ++i)
    add_straight(st.points_W[i], path.points[i].body, st.points_W[i + 1], path.points[i + 1].body,
                 st);
  return st;
}

}  // namespace arthrosim::musculoskeletal
