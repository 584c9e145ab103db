// Element quality measures (see mesh_quality.h).
#include "common/mesh_quality.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>

namespace arthrosim::common {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

double corner_angle(const Vec3& at, const Vec3& a, const Vec3& b) {
  const Vec3 u = a - at, v = b - at;
  const double nu = u.norm(), nv = v.norm();
  if (!(nu > 0) || !(nv > 0)) return 0.0;
  return std::atan2(u.cross(v).norm(), u.dot(v));
}

// Smallest |s| > 0 with p0 + p1 s + p2 s^2 = 0 (p0 > 0), +inf if none.
double smallest_root_magnitude(double p0, double p1, double p2) {
  const double scale = std::max({std::abs(p0), std::abs(p1), std::abs(p2)});
  if (!(scale > 0)) return kInf;
  if (std::abs(p2) <= 1e-14 * scale) {
    if (std::abs(p1) <= 1e-14 * scale) return kInf;
    return std::abs(p0 / p1);
  }
  const double disc = p1 * p1 - 4 * p2 * p0;
  if (disc < 0) return kInf;
  // Stable roots: q = -(p1 + sign(p1) sqrt(disc)) / 2, roots q / p2 and p0 / q.
  const double q = -0.5 * (p1 + std::copysign(std::sqrt(disc), p1));
  double r = kInf;
  if (q != 0) r = std::min({r, std::abs(q / p2), std::abs(p0 / q)});
  return r;
}

void bilinear(double xi, double eta, double N[4], double Nxi[4], double Neta[4]) {
  static const double kXi[4] = {-1, 1, 1, -1}, kEta[4] = {-1, -1, 1, 1};
  for (int k = 0; k < 4; ++k) {
    N[k] = 0.25 * (1 + kXi[k] * xi) * (1 + kEta[k] * eta);
    Nxi[k] = 0.25 * kXi[k] * (1 + kEta[k] * eta);
    Neta[k] = 0.25 * kEta[k] * (1 + kXi[k] * xi);
  }
}

// Check points of a quad: corners, 2x2 Gauss points, centre.
const std::array<std::array<double, 2>, 9>& quad_points() {
  static const double g = 1.0 / std::sqrt(3.0);
  static const std::array<std::array<double, 2>, 9> p = {
      {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}, {-g, -g}, {g, -g}, {g, g}, {-g, g}, {0, 0}}};
  return p;
}

struct QuadJacobian {
  double min_ratio = kInf;  // p0 / (|x_xi| |x_eta| |d|)
  double shell = kInf;      // admissible shell thickness
};

QuadJacobian quad_jacobian(const std::array<Vec3, 4>& x, const std::array<Vec3, 4>& d, double zeta_max) {
  QuadJacobian r;
  for (const auto& pt : quad_points()) {
    double N[4], Nxi[4], Neta[4];
    bilinear(pt[0], pt[1], N, Nxi, Neta);
    Vec3 a = Vec3::Zero(), c = Vec3::Zero(), b = Vec3::Zero(), e = Vec3::Zero(), dm = Vec3::Zero();
    for (int k = 0; k < 4; ++k) {
      a += Nxi[k] * x[k];
      c += Neta[k] * x[k];
      b += Nxi[k] * d[k];
      e += Neta[k] * d[k];
      dm += N[k] * d[k];
    }
    const double p0 = a.cross(c).dot(dm);
    const double p1 = (a.cross(e) + b.cross(c)).dot(dm);
    const double p2 = b.cross(e).dot(dm);
    const double norm = a.norm() * c.norm() * dm.norm();
    r.min_ratio = std::min(r.min_ratio, norm > 0 ? p0 / norm : 0.0);
    r.shell = std::min(r.shell, p0 > 0 ? 2.0 * smallest_root_magnitude(p0, p1, p2) / zeta_max : 0.0);
  }
  return r;
}

void add_issue(ElementQualityReport* r, int max_issues, int element, const char* check, double value, double limit,
               const Vec3& centre) {
  if (static_cast<int>(r->issues.size()) < max_issues) r->issues.push_back({element, check, value, limit, centre});
}

}  // namespace

double admissible_shell_thickness(const std::array<Vec3, 4>& x, const std::array<Vec3, 4>& d, double zeta_max) {
  return quad_jacobian(x, d, zeta_max).shell;
}

std::string ElementQualityReport::summary() const {
  std::ostringstream s;
  s.precision(3);
  s << mesh_name << ": " << elements << " " << element_kind << "s, shortest edge " << min_edge * 1e3 << " mm ("
    << (reference_length > 0 ? min_edge / reference_length : 0.0) << " of " << reference_length * 1e3
    << " mm), angles " << min_angle * kRadToDeg << ".." << max_angle * kRadToDeg << " deg, Jacobian ratio >= "
    << min_jacobian_ratio;
  if (element_kind == "quad") s << ", admissible shell thickness >= " << min_shell_thickness * 1e3 << " mm";
  if (failed > 0) s << "; " << failed << " " << element_kind << "s fail the limits";
  for (const ElementQualityIssue& i : issues) {
    s << "\n  " << element_kind << " " << i.element << " at (" << i.centre.x() * 1e3 << ", " << i.centre.y() * 1e3
      << ", " << i.centre.z() * 1e3 << ") mm: ";
    if (i.check == "edge")
      s << "edge " << i.value * 1e3 << " mm < " << i.limit * 1e3 << " mm";
    else if (i.check == "angle")
      s << "angle " << i.value * kRadToDeg << " deg < " << i.limit * kRadToDeg << " deg";
    else if (i.check == "jacobian")
      s << "Jacobian ratio " << i.value << " <= 0 (inverted against its normals)";
    else
      s << "admissible shell thickness " << i.value * 1e3 << " mm < " << i.limit * 1e3 << " mm";
  }
  if (failed > static_cast<int>(issues.size())) s << "\n  ...";
  return s.str();
}

ElementQualityReport check_triangles(const TriangleMesh& mesh, const Points3& vertex_normals, double reference_length,
                                     const ElementQualityLimits& limits, int max_issues) {
  ElementQualityReport r;
  r.mesh_name = mesh.name.empty() ? "<mesh>" : mesh.name;
  r.element_kind = "triangle";
  r.elements = mesh.num_triangles();
  r.reference_length = reference_length;
  r.min_edge = kInf;
  r.min_angle = kInf;
  r.min_jacobian_ratio = kInf;
  r.min_shell_thickness = kInf;
  const double edge_limit = limits.min_edge_fraction * reference_length;
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    const std::array<Vec3, 3> x = {mesh.vertex(mesh.F(t, 0)), mesh.vertex(mesh.F(t, 1)), mesh.vertex(mesh.F(t, 2))};
    const Vec3 centre = (x[0] + x[1] + x[2]) / 3.0;
    double edge = kInf, amin = kInf, jac = kInf;
    const Vec3 n = (x[1] - x[0]).cross(x[2] - x[0]);
    for (int k = 0; k < 3; ++k) {
      edge = std::min(edge, (x[(k + 1) % 3] - x[k]).norm());
      const double a = corner_angle(x[k], x[(k + 1) % 3], x[(k + 2) % 3]);
      amin = std::min(amin, a);
      r.max_angle = std::max(r.max_angle, a);
      const Vec3 d = vertex_normals.row(mesh.F(t, k)).transpose();
      const double nn = n.norm() * d.norm();
      jac = std::min(jac, nn > 0 ? n.dot(d) / nn : 0.0);
    }
    r.min_edge = std::min(r.min_edge, edge);
    r.min_angle = std::min(r.min_angle, amin);
    r.min_jacobian_ratio = std::min(r.min_jacobian_ratio, jac);
    bool bad = false;
    if (!(jac > 0)) add_issue(&r, max_issues, t, "jacobian", jac, 0.0, centre), bad = true;
    if (!bad && !(edge >= edge_limit)) add_issue(&r, max_issues, t, "edge", edge, edge_limit, centre), bad = true;
    if (!bad && !(amin >= limits.min_angle)) add_issue(&r, max_issues, t, "angle", amin, limits.min_angle, centre), bad = true;
    r.failed += bad;
  }
  if (r.elements == 0) r.min_edge = r.min_angle = r.min_jacobian_ratio = 0.0;
  return r;
}

ElementQualityReport check_quads(const QuadMesh& mesh, const Points3& node_normals, double reference_length,
                                 const ElementQualityLimits& limits, int max_issues) {
  ElementQualityReport r;
  r.mesh_name = mesh.name.empty() ? "<mesh>" : mesh.name;
  r.element_kind = "quad";
  r.elements = mesh.num_quads();
  r.reference_length = reference_length;
  r.min_edge = kInf;
  r.min_angle = kInf;
  r.min_jacobian_ratio = kInf;
  r.min_shell_thickness = kInf;
  const double edge_limit = limits.min_edge_fraction * reference_length;
  for (int q = 0; q < mesh.num_quads(); ++q) {
    std::array<Vec3, 4> x, d;
    Vec3 centre = Vec3::Zero();
    for (int k = 0; k < 4; ++k) {
      x[k] = mesh.V.row(mesh.Q(q, k)).transpose();
      d[k] = node_normals.row(mesh.Q(q, k)).transpose();
      centre += 0.25 * x[k];
    }
    double edge = kInf, amin = kInf;
    for (int k = 0; k < 4; ++k) {
      edge = std::min(edge, (x[(k + 1) % 4] - x[k]).norm());
      const double a = corner_angle(x[k], x[(k + 1) % 4], x[(k + 3) % 4]);
      amin = std::min(amin, a);
      r.max_angle = std::max(r.max_angle, a);
    }
    const QuadJacobian j = quad_jacobian(x, d, limits.shell_zeta);
    r.min_edge = std::min(r.min_edge, edge);
    r.min_angle = std::min(r.min_angle, amin);
    r.min_jacobian_ratio = std::min(r.min_jacobian_ratio, j.min_ratio);
    r.min_shell_thickness = std::min(r.min_shell_thickness, j.shell);
    bool bad = false;
    if (!(j.min_ratio > 0)) add_issue(&r, max_issues, q, "jacobian", j.min_ratio, 0.0, centre), bad = true;
    if (!bad && !(edge >= edge_limit)) add_issue(&r, max_issues, q, "edge", edge, edge_limit, centre), bad = true;
    if (!bad && !(amin >= limits.min_angle)) add_issue(&r, max_issues, q, "angle", amin, limits.min_angle, centre), bad = true;
    if (!bad && !(j.shell >= limits.min_shell_thickness))
      add_issue(&r, max_issues, q, "shell thickness", j.shell, limits.min_shell_thickness, centre), bad = true;
    r.failed += bad;
  }
  if (r.elements == 0) r.min_edge = r.min_angle = r.min_jacobian_ratio = r.min_shell_thickness = 0.0;
  return r;
}

}  // namespace arthrosim::common
