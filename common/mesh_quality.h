#pragma once
// Element quality of the meshes arthrosim writes for its solvers: the
// remeshed triangles (contact surfaces) and the quads (shell elements) of the
// prepare stage. Every element is measured; limits make a report fail, so a
// degenerate element is refused where it is made, naming it, instead of
// reaching a solver that refuses it later.
//
// Measures, per element:
//  - shortest edge [m] (limit relative to a reference length, the remeshing
//    target of the surface);
//  - smallest interior angle at a corner (3D angle between its two edges);
//  - Jacobian sign against the directors (the unit node normals the shell
//    stage uses as directors; for a triangle its vertex normals): the
//    mid-surface map x(xi, eta) with director field d(xi, eta) = sum N_k d_k
//    must have (x_xi x x_eta) . d > 0 at the corners, the 2x2 Gauss points and
//    the centre (quads), or at each corner (triangles);
//  - quads only: the admissible shell thickness, i.e. the largest thickness h
//    for which the shell's reference Jacobian
//      det[x_xi + s d_xi, x_eta + s d_eta, (h/2) d],  s = zeta h / 2,
//    stays positive at those points for every |zeta| <= zeta_max, the
//    through-thickness points where the shell stage evaluates it
//    (cartilage/shell_element.cc: 1/sqrt(3) with its default 2-point rule).
//    det/(h/2) is the quadratic p0 + p1 s + p2 s^2 (p0 the mid-surface
//    value), so h_max = 2 |s*| / zeta_max with s* its real root of smallest
//    magnitude (infinite without one). A quad with h_max above the shell
//    thickness passes the shell element's own check. (The Jacobian of the
//    whole shell volume, |zeta| <= 1, stays positive up to zeta_max h_max.)
#include <array>
#include <string>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::common {

struct ElementQualityLimits {
  /// Shortest edge, as a fraction of the reference length. Default 0.01: a
  /// remesh at target L has no edge shorter than ~0.1 L on well-resolved
  /// input (quads from a split triangle: the centroid-midpoint segment);
  /// the sliver this refuses had 0.0007 L.
  double min_edge_fraction = 0.01;
  /// Smallest corner angle [rad]. Default 5 deg.
  double min_angle = 5.0 * 3.14159265358979323846 / 180.0;
  /// Quads: smallest admissible shell thickness [m] (see above). Default
  /// 1 mm, the shell stage's default shell thickness. 0 checks the sign only.
  double min_shell_thickness = 1e-3;
  /// Largest |zeta| at which the shell's Jacobian is evaluated: 1/sqrt(3),
  /// the shell stage's 2-point through-thickness rule.
  double shell_zeta = 0.57735026918962576;
};

/// One element that fails a limit.
struct ElementQualityIssue {
  int element = -1;
  std::string check;   ///< "edge", "angle", "jacobian", "shell thickness"
  double value = 0.0;  ///< SI (m, rad, or the Jacobian ratio p0 / |x_xi||x_eta|)
  double limit = 0.0;
  Vec3 centre = Vec3::Zero();  ///< element centroid [m], to find it in a viewer
};

struct ElementQualityReport {
  std::string mesh_name;
  std::string element_kind;  ///< "triangle" or "quad"
  int elements = 0;
  double reference_length = 0.0;  ///< [m]
  double min_edge = 0.0;          ///< [m]
  double min_angle = 0.0;         ///< [rad]
  double max_angle = 0.0;         ///< [rad]
  /// Smallest (x_xi x x_eta) . d / (|x_xi| |x_eta| |d|) over the check points
  /// (1 for a flat element with normal directors; <= 0: inverted).
  double min_jacobian_ratio = 0.0;
  /// Quads: smallest admissible shell thickness [m] (+inf if unbounded).
  double min_shell_thickness = 0.0;
  int failed = 0;                            ///< elements failing any limit
  std::vector<ElementQualityIssue> issues;  ///< the first few failures (by element index)

  bool ok() const { return failed == 0; }
  /// One line of figures, then one line per listed failure.
  std::string summary() const;
};

/// Measures every triangle against `limits` (min_shell_thickness unused).
/// `vertex_normals` are unit rows, one per vertex.
ElementQualityReport check_triangles(const TriangleMesh& mesh, const Points3& vertex_normals, double reference_length,
                                     const ElementQualityLimits& limits = {}, int max_issues = 5);

/// Measures every quad against `limits`; `node_normals` are the directors.
ElementQualityReport check_quads(const QuadMesh& mesh, const Points3& node_normals, double reference_length,
                                 const ElementQualityLimits& limits = {}, int max_issues = 5);

/// Admissible shell thickness of one quad (corners counter-clockwise,
/// directors at the corners) for a Jacobian evaluated at |zeta| <= zeta_max,
/// see the header comment. +inf when the Jacobian stays positive for any
/// thickness; 0 when it is not positive on the mid-surface.
double admissible_shell_thickness(const std::array<Vec3, 4>& x, const std::array<Vec3, 4>& d,
                                  double zeta_max = 0.57735026918962576);

}  // namespace arthrosim::common
