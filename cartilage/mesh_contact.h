#pragma once
// Deformable mesh-to-mesh penalty contact between two shell surfaces (issue 6;
// seed seeds/002_3ffcc11eb7a447d9.txt, "Contact Methods").
//
// Geometry. Each quad shell surface is seen as triangles, two per quad (split
// along the 0-2 diagonal, common::triangulate), whose vertices are the shell
// nodes (mid-surface positions r_i). Triangle normals (b - a) x (c - a) point
// away from the bone, into the joint space (docs/prepared_model.md).
//
// Narrow phase, per candidate pair from the broad phase (common/broad_phase.h,
// boxes rebuilt from the current positions at every evaluation):
//  - vertex-face: vertex p of one surface against the faceted other surface:
//    c, the closest point of that surface; p is behind it when (p - c) . m < 0
//    with m the pseudo-normal of c's feature (face normal, sum of the two
//    face normals at an edge, vertex normal at a corner), and the surfaces
//    face each other when p's vertex normal opposes m. If c is inside a face,
//    g = (p - x1) . n with n the face normal; if it is on an edge or corner
//    (convex kinks between facets), g = -|p - c| with n = (c - p)/|c - p|.
//    A closest point on the open boundary (the other surface's rim, an edge
//    or corner used by one triangle side only) means p has slid beyond the
//    edge of that surface. RimTreatment::kFadeInside (default): that is no
//    contact, and contacts whose closest point lies on a face touching the
//    rim are weighted by phi = s(r), r = sum_k N_k rho_k the barycentric
//    interpolation of a node weight rho (0 on the rim, 1 elsewhere) and s the
//    smoothstep r^2 (3 - 2 r): the force falls to zero, C1, before the rim.
//    RimTreatment::kRimContacts (the earlier treatment, below): the
//    edge/corner gap g = -|p - c| is kept while p
//    is behind the boundary triangle's plane, weighted by
//    phi = clamp(n . n_T / cos 45 deg, 0, 1) (n_T that triangle's normal):
//    full weight when p lies squarely behind the rim, fading to zero as it
//    comes beside it, so the force does not jump when a penetrating vertex
//    slides off a rim (the fade's gradient is in the tangent, which is then
//    not symmetric). This is the signed distance to the faceted
//    surface, continuous as p slides across facets (no force jumps). Active
//    when 0 < -g < max_depth. Both directions are evaluated (two-pass, each
//    with half the vertex's tributary area), so neither surface is
//    privileged.
//  - edge-edge: edges (a0, a1) and (b0, b1); n = +-(ea x eb)/|ea x eb| oriented
//    along the second edge's surface normal, g = (a0 - b0) . n, the signed
//    distance of the two lines; active when the closest points lie inside
//    both edges, -max_depth < g < 0, and no endpoint of either edge is already
//    in vertex-face contact: it catches edges crossing where no vertex
//    penetrates (sharp features), and never double counts a smooth contact.
//    Weight: the smaller of the two edges' tributary areas.
// In all cases the gap is g = n . sum_k w_k x_k over the four nodes with
// weights w (face: 1, -N1, -N2, -N3 with N the barycentric coordinates of the
// projection; edge: 1, -(1 - u), -u, 0; corner: 1, -1, 0, 0; edge-edge:
// 1 - s, s, -(1 - u), -u with s, u the closest-point parameters), and its
// exact gradient is dg/dx_k = w_k n (the envelope property of the closest
// point). The Hessian d2g/dx2 is obtained by forward
// automatic differentiation of that gradient (Eigen's AutoDiffScalar).
//
// Penalty law (per active contact, area weight A):
//   pressure  lambda = p(g) - c g_dot  (c: damping [N s/m^3], g_dot = dg/dx . v),
//             only while lambda > 0, with
//             p(g) = k (-g - delta/2) for g <= -delta, k g^2 / (2 delta) for -delta < g < 0
//             (k: stiffness per unit area [N/m^3]; the quadratic toe of width
//             delta makes p and p' continuous at g = 0: no tangent jump when a
//             contact switches on, so Newton does not cycle), times the depth
//             fade s(-g): 1 up to 0.75 max_depth, a smoothstep to 0 at
//             max_depth (a contact reaching the cut-off leaves without a
//             force jump; the damping part is not faded)
//   residual  F += -A phi lambda G   (F = f_int - f_ext convention of ShellModel;
//             phi the boundary fade, 1 away from open boundaries)
//   tangent   dF/dx = A (phi (-p' G G^T + c G (H v)^T - lambda H) - lambda G grad phi^T),
//             dF/dv = A phi c G G^T
// (G = dg/dx, H = d2g/dx2). With c = 0 the force derives from the potential
// A int p dg and the tangent is symmetric. The force on node k is
// A lambda w_k n: it pushes the penetrating vertex out along n and the
// triangle nodes the other way, distributed by the triangle's shape functions.
#include <Eigen/Core>
#include <array>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "common/broad_phase.h"
#include "common/mesh.h"
#include "common/options.h"

namespace arthrosim::cartilage {

class ShellModel;

/// A shell surface seen as triangles for contact.
struct ContactSurface {
  /// From a shell model: its quads (split in two) and reference positions.
  explicit ContactSurface(const ShellModel& model);
  /// From a quad mesh (reference positions [m]).
  explicit ContactSurface(const common::QuadMesh& mesh);

  int num_nodes = 0;
  common::Triangles F;                             ///< 2 per quad
  Eigen::Matrix<int, Eigen::Dynamic, 2> edges;     ///< unique, sorted (a < b)
  std::vector<std::array<int, 2>> edge_triangles;  ///< adjacent triangles (-1: none)
  /// Edge k of triangle t joins F(t, k) and F(t, (k + 1) % 3).
  Eigen::Matrix<int, Eigen::Dynamic, 3> triangle_edges;
  std::vector<std::vector<int>> vertex_triangles;  ///< triangles around each node
  std::vector<char> boundary_vertex;               ///< 1 on the open boundary
  Eigen::VectorXd triangle_area;  ///< reference area per triangle [m^2]
  Eigen::VectorXd vertex_area;  ///< reference tributary area per node [m^2] (1/3 of adjacent triangles)
  Eigen::VectorXd edge_area;    ///< reference tributary area per edge [m^2] (1/3 of adjacent triangles)
  /// Reference height of node k of triangle t over its opposite edge [m].
  Eigen::Matrix<double, Eigen::Dynamic, 3> triangle_height;
};

/// How contact ends at a surface's open boundary (rim); docs/contact.md, "Rims".
enum class RimTreatment {
  /// Contacts with the faces next to a rim are weighted by the barycentric
  /// interpolation of a node weight that is 0 on the rim and 1 elsewhere:
  /// the force goes continuously to zero at the rim, beyond which nothing is
  /// a contact. Continuous, tangent exact, never a sideways force.
  kFadeInside,
  /// The earlier treatment: a vertex beyond the rim keeps its distance to the
  /// rim edge or corner as gap, weighted by how squarely it lies behind the
  /// rim (phi = clamp(n . n_T / cos 45 deg, 0, 1)). Its force points along
  /// p - c, up to 45 deg off the rim's normal with the penalty of the whole
  /// distance; with stiff penalties Newton stalls at rims (docs/contact.md,
  /// "Stiff contact").
  kRimContacts,
};

struct ContactOptions {
  /// k: penalty pressure per unit penetration [N/m^3], > 0. The seed's
  /// accuracy rule (penetration below a tenth of the deflection) needs about
  /// ten times the foundation stiffness or more.
  double stiffness_N_m3 = 20 * common::units::n_per_mm3;
  double damping_N_s_m3 = 0;     ///< c [N s/m^3], >= 0 (0: symmetric tangent)
  double max_depth_m = 1 * common::units::mm;  ///< deeper overlaps are not contacts (far side), > 0
  /// Width delta of the quadratic toe of the penalty law [m], in (0, max_depth).
  double smoothing_m = 0.001 * common::units::mm;
  /// Evaluate edge-edge pairs (for sharp features). Off by default: the
  /// vertex test with edge and corner features already covers smooth
  /// surfaces, and the edge-edge exclusion rule switches forces on and off
  /// discontinuously, which can stall Newton (docs/contact.md).
  bool edge_edge = false;
  /// A vertex-face pair needs n_vertex . n_triangle < -min_opposition
  /// (the surfaces face each other); in [-1, 1).
  double min_opposition = 0.0;
  /// Nodes on a surface's open boundary (its rim, where periphery_fixed
  /// acts) may be the penetrating vertex of a vertex contact. false: rim
  /// nodes only carry their triangles, which the other surface's vertices
  /// still contact; there only those vertices sample the contact, at half
  /// weight (two-pass). Stage 1 samples its casting surface at triangle
  /// centres and never at the rim; on the bundled knee the rim nodes of the
  /// tibial eminence slopes otherwise end up 3 mm deep in the condyles' flanks
  /// (docs/contact.md, "Rims").
  bool rim_vertices = false;
  /// kFadeInside only: a node's weight as the penetrating vertex is its
  /// fade-weighted tributary area, sum over its triangles of the integral of
  /// phi N_i dA (phi the rim fade that the other surface's vertices see on
  /// that triangle, N_i its linear shape function), instead of a third of
  /// each triangle's area. Each surface then samples itself with the same
  /// fade near its rim as the other surface's vertices do; rim nodes get a
  /// nonzero weight (1/15 or 1/6 of a rim-row triangle's area) and so
  /// support the rim; rim_vertices must then be false (docs/contact.md, "Rims").
  bool faded_vertex_weights = false;
  /// Cut-off depth of rim contacts [m] (a vertex beside the other surface's
  /// open boundary and behind its boundary triangle's plane), with the same
  /// depth fade over its last quarter; 0: max_depth_m. A rim contact stands
  /// for a penetrating vertex sliding off an edge, so its depth is of the
  /// order of the penetrations; a vertex millimetres beside and below a rim
  /// has crossed no triangle and is not a contact.
  double rim_max_depth_m = 0.5 * common::units::mm;
  RimTreatment rim = RimTreatment::kFadeInside;
  /// Augmented Lagrangian (Uzawa, docs/contact.md "Augmented Lagrangian"):
  /// at most this many augmentations per step (multiplier updates, each
  /// followed by the step solved again); 0: pure penalty. The stage
  /// augments while the step's max penetration exceeds augment_tolerance
  /// times its max deflection.
  int augmentations = 0;
  /// Target of the augmentations: max penetration / max deflection, in (0, 1].
  double augment_tolerance = 0.05;

  /// Scene keys (common/options.h): contact_stiffness_n_per_mm3,
  /// contact_damping_n_s_per_mm3, contact_max_depth_mm, contact_smoothing_mm,
  /// contact_edge_edge, contact_rim, contact_rim_max_depth_mm,
  /// contact_rim_vertices, contact_vertex_weights, contact_augmentations,
  /// contact_augment_tolerance.
  void declare(common::OptionVisitor& v);
};

/// Vertex contacts are classified by the feature of the other surface that
/// is closest to the vertex: a face (x1..x3 the triangle), an edge (x1, x2;
/// x3 unused) or a corner (x1). Edge-edge: x0, x1 and x2, x3 are the edges.
enum class ContactKind { kVertexFace = 0, kEdgeEdge = 1, kVertexEdge = 2, kVertexVertex = 3 };

/// One active contact. Nodes k = 0..3 belong to surface side[k] (0: the
/// pair's surface a, 1: surface b).
struct ContactPoint {
  ContactKind kind = ContactKind::kVertexFace;
  std::array<int, 4> node{};
  std::array<int, 4> side{};
  double gap = 0;        ///< g < 0 [m]
  double gap_rate = 0;   ///< dg/dt [m/s] (0 without velocities)
  double area = 0;       ///< weight A [m^2]
  double pressure = 0;   ///< lambda > 0 [Pa]
  double stiffness = 0;  ///< -d lambda/dg [Pa/m] (the penalty law's slope)
  /// Gap offset of the augmented law [m]: lambda_v / k + delta / 2 for a
  /// vertex contact whose vertex carries a multiplier lambda_v > 0, else 0;
  /// the pressure is p(g - offset).
  double offset = 0;
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  ///< n (out of the face / second edge's surface)
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   ///< contact point on the face / second edge [m]
  Eigen::Matrix<double, 12, 1> G = Eigen::Matrix<double, 12, 1>::Zero();   ///< dg/dx
  Eigen::Matrix<double, 12, 12> H = Eigen::Matrix<double, 12, 12>::Zero(); ///< d2g/dx2 (if requested)
  /// Faded contact: fade_edge = 0, a contact with a face next to the other
  /// surface's rim (RimTreatment::kFadeInside); 1, a rim contact (the closest
  /// point on the other surface's open boundary, kRimContacts); -1 neither.
  /// Weight fade in [0, 1] and fade_grad = d fade/dx.
  int fade_edge = -1;
  double fade = 1;
  Eigen::Matrix<double, 12, 1> fade_grad = Eigen::Matrix<double, 12, 1>::Zero();
  /// Crease blend of an augmented vertex-face contact (docs/contact.md,
  /// "Augmented Lagrangian"): the contact with one of the two faces beside
  /// an edge, weighted by fade = s(sum_k N_k blend_rho_k) (s the smoothstep,
  /// N the barycentric coordinates of the projection on this face's plane).
  bool blend = false;
  std::array<double, 3> blend_rho{};
};

/// Counts of one evaluation.
struct ContactCounts {
  long candidate_vertex_face = 0, candidate_edge_edge = 0;
  long vertex_face = 0, edge_edge = 0;  ///< active
  /// max over active contacts of the interpenetration -g, times the fade
  /// phi for rim contacts (kRimContacts: a vertex beside the other surface's
  /// rim has crossed no triangle; phi (-g) is the depth its faded force
  /// stands for). Faded contacts next to a rim (kFadeInside) count with
  /// their whole depth: they have crossed a triangle.
  double max_penetration_m = 0;
  double max_rim_depth_m = 0;  ///< max(-g) over active faded contacts (either kind), unweighted (diagnostics)
  /// max(-g) over active contacts that are not faded (fade_edge < 0): the
  /// penalty's own interpenetration, away from the rims where kFadeInside
  /// deliberately lets a surface pass (docs/contact.md, accuracy rule).
  double max_unfaded_penetration_m = 0;
};

/// Contact between surface a and surface b.
class MeshContact {
 public:
  MeshContact(std::string name, const ContactSurface& a, const ContactSurface& b, const ContactOptions& options);

  const std::string& name() const { return name_; }
  const ContactOptions& options() const { return opts_; }
  const ContactSurface& surface(int side) const { return side == 0 ? a_ : b_; }

  /// Active contacts for the node positions of both surfaces (rows = nodes,
  /// [m]); va/vb: node velocities (nullptr: at rest). Deterministic order.
  std::vector<ContactPoint> detect(const common::Points3& xa, const common::Points3& xb, const common::Points3* va,
                                   const common::Points3* vb, bool want_hessian, ContactCounts* counts = nullptr) const;

  /// Node pairs (node of a, node of b) that contacts could couple once the
  /// surfaces have moved by up to about `margin` [m] (or slid by about one
  /// element) from the current positions: for the tangent's sparsity
  /// pattern. Sorted, unique.
  std::vector<std::pair<int, int>> coupling_candidates(const common::Points3& xa, const common::Points3& xb,
                                                       double margin) const;

  /// Augmented Lagrangian multipliers: per side (0: a, 1: b), a pressure per
  /// node as the penetrating vertex of a vertex contact [Pa] (>= 0; empty:
  /// all zero). With lambda_v > 0 the vertex's contact pressure is
  /// p(g - lambda_v / k - delta / 2), = lambda_v - k g on the linear branch,
  /// so a converged augmentation (lambda_v = the pressure) means g = 0.
  /// Edge-edge contacts carry no multiplier.
  void set_multipliers(const std::array<Eigen::VectorXd, 2>& lambda);
  const std::array<Eigen::VectorXd, 2>& multipliers() const { return lambda_; }
  /// The Uzawa update at the positions xa, xb: each vertex's new multiplier
  /// is the elastic pressure of its vertex contact there (0 without one),
  /// lambda <- max(0, lambda + k (-g)) on the linear branch.
  std::array<Eigen::VectorXd, 2> updated_multipliers(const common::Points3& xa, const common::Points3& xb) const;

 private:
  std::string name_;
  ContactSurface a_, b_;
  ContactOptions opts_;
  /// Per surface: a node's weight as the penetrating vertex [m^2] (0: not a
  /// penetrating vertex), from the options (rim_vertices, faded_vertex_weights).
  std::array<Eigen::VectorXd, 2> vertex_weight_;
  std::array<Eigen::VectorXd, 2> lambda_;  ///< augmented Lagrangian multipliers [Pa] (empty: none)
  /// Broad phase of the two vertex-face passes (vertices of a against the
  /// faces of b, then b against a), each reusing its candidate pairs while
  /// the surfaces move less than a fifth of max_depth_m
  /// (common::CachedOverlaps: the same pairs, hence the same contacts, as a
  /// fresh search). They change how fast detect() is, not what it returns;
  /// the mutex makes detect() safe to call from several threads.
  mutable std::array<std::unique_ptr<common::CachedOverlaps>, 2> broad_phase_;
  mutable std::mutex broad_phase_mutex_;
};

/// The weights of a surface's nodes as penetrating vertices [m^2] under
/// ContactOptions::faded_vertex_weights: per triangle, the integrals of
/// phi N_i over it, phi = s(r) the rim fade (s(r) = r^2 (3 - 2 r), r the
/// interpolation of 0 on rim nodes and 1 elsewhere). Closed forms per
/// triangle of area A: no rim node A/3 each; one rim node: it A/6, the others
/// 4A/15; two rim nodes: they A/15, the other A/6; three: 0.
Eigen::VectorXd faded_vertex_weights(const ContactSurface& s);

/// The gap function and its exact gradient for four points (for tests):
/// vertex-face (x0 = vertex, x1..x3 = triangle) or edge-edge (x0, x1 = first
/// edge, x2, x3 = second edge; `sign` orients n; for vertex-edge and vertex-vertex, sign = -1
/// is a vertex in front of the feature, g = +|x0 - c|). Returns g; G = dg/dx.
double contact_gap(ContactKind kind, const std::array<Eigen::Vector3d, 4>& x, double sign,
                   Eigen::Matrix<double, 12, 1>* G, Eigen::Matrix<double, 12, 12>* H);

}  // namespace arthrosim::cartilage
