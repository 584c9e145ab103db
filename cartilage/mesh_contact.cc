#include "cartilage/mesh_contact.h"

#include <unsupported/Eigen/AutoDiff>

#include <algorithm>
#include <cmath>
#include <limits>

#include "cartilage/shell_model.h"
#include "common/broad_phase.h"
#include "common/error.h"

namespace arthrosim::cartilage {

void ContactOptions::declare(common::OptionVisitor& v) {
  using common::Unit;
  v.number("contact_stiffness_n_per_mm3", stiffness_N_m3, Unit::kNewtonPerCubicMillimetre, {1e-6, 1e9},
           "penalty pressure per unit interpenetration; the seed's accuracy rule (penetration below a tenth of the "
           "deflection) needs about ten times the foundation stiffness or more");
  v.number("contact_damping_n_s_per_mm3", damping_N_s_m3, Unit::kNewtonSecondPerCubicMillimetre, {0, 1e12},
           "penalty damping per unit interpenetration rate (0: none, symmetric tangent)");
  v.number("contact_max_depth_mm", max_depth_m, Unit::kMillimetre, {1e-3, 100},
           "deeper overlaps are not contacts (the far side of a surface)");
  v.number("contact_smoothing_mm", smoothing_m, Unit::kMillimetre, {1e-9, 1},
           "width of the quadratic toe of the penalty law (continuous tangent at first touch)");
  v.flag("contact_edge_edge", edge_edge,
         "also evaluate edge-edge pairs (sharp features); the vertex test with edge and corner features covers smooth "
         "surfaces");
  v.choice("contact_rim", rim, {{"fade_inside", RimTreatment::kFadeInside}, {"rim_contacts", RimTreatment::kRimContacts}},
           "how contact ends at a surface's rim: fade_inside weights contacts on the faces next to a rim by a node weight "
           "interpolated from 0 on the rim to 1 inside (continuous, never sideways); rim_contacts: a vertex beyond a rim "
           "keeps its distance to it, faded by angle (docs/contact.md)");
  v.number("contact_rim_max_depth_mm", rim_max_depth_m, Unit::kMillimetre, {0, 100},
           "contact_rim: rim_contacts: cut-off depth of rim contacts (a vertex beside the other surface's rim), faded "
           "over its last quarter; 0: contact_max_depth_mm");
  v.flag("contact_rim_vertices", rim_vertices,
         "nodes on a surface's rim may be penetrating vertices; by default they only carry their triangles, as stage 1 "
         "samples the casting surface at triangle centres, never at its rim (docs/contact.md)");
  v.choice("contact_vertex_weights", faded_vertex_weights, {{"tributary", false}, {"faded", true}},
           "a node's weight as the penetrating vertex of a contact: tributary = a third of its triangles' areas (rim "
           "nodes per contact_rim_vertices); faded = the integral of the rim fade times its shape function over its "
           "triangles, so each surface samples itself with the fade the other surface's vertices see, and rim nodes "
           "carry a reduced weight (fade_inside only, not with contact_rim_vertices; docs/contact.md, \"Rims\")");
  v.integer("contact_augmentations", augmentations, {0, 50},
            "augmented Lagrangian (Uzawa): at most this many multiplier updates per step, each followed by the step "
            "solved again, while the max penetration exceeds contact_augment_tolerance x the max deflection; 0: pure "
            "penalty (docs/contact.md, \"Augmented Lagrangian\")");
  v.number("contact_augment_tolerance", augment_tolerance, Unit::kNone, {1e-6, 1},
           "contact_augmentations: augmenting stops once the step's max penetration is at most this fraction of its "
           "max deflection (the seed's accuracy rule is 0.1)");
}
namespace {

using Vec12 = Eigen::Matrix<double, 12, 1>;
using Ad = Eigen::AutoDiffScalar<Vec12>;
template <class T>
using V3 = Eigen::Matrix<T, 3, 1>;

// The four weights w_k and the unit normal n of a contact, as functions of
// the four points (templated so that the same code gives values and, with
// Ad, their derivatives). Returns g = n . sum_k w_k x_k.
//  vertex-face: x0 vertex, x1..x3 triangle; w = (1, -N1, -N2, -N3).
//  edge-edge:   x0, x1 first edge, x2, x3 second; w = (1-s, s, -(1-u), -u).
template <class T>
T gap_kernel(ContactKind kind, const V3<T>* x, double sign, V3<T>& n, T* w, T* p1 = nullptr, T* p2 = nullptr) {
  using std::sqrt;
  if (kind == ContactKind::kVertexFace) {
    const V3<T> e1 = x[2] - x[1], e2 = x[3] - x[1], d = x[0] - x[1];
    const V3<T> c = e1.cross(e2);
    n = c / sqrt(c.squaredNorm());
    const T a11 = e1.dot(e1), a12 = e1.dot(e2), a22 = e2.dot(e2);
    const T b1 = d.dot(e1), b2 = d.dot(e2);
    const T det = a11 * a22 - a12 * a12;
    const T xi = (a22 * b1 - a12 * b2) / det, eta = (a11 * b2 - a12 * b1) / det;
    w[0] = T(1.0);
    w[1] = -(T(1.0) - xi - eta);
    w[2] = -xi;
    w[3] = -eta;
    if (p1) *p1 = xi;
    if (p2) *p2 = eta;
    return d.dot(n);
  }
  if (kind == ContactKind::kVertexEdge || kind == ContactKind::kVertexVertex) {
    // Closest point c on the segment x1-x2 (or the point x1); the vertex is
    // behind the surface, so g = -|x0 - c| and n = (c - x0)/|c - x0|.
    T u = T(0.0);
    if (kind == ContactKind::kVertexEdge) {
      const V3<T> e = x[2] - x[1];
      u = (x[0] - x[1]).dot(e) / e.squaredNorm();
    }
    const V3<T> c = x[1] + u * (x[2] - x[1]);
    const V3<T> r = c - x[0];
    const T l = sqrt(r.squaredNorm());
    // sign = -1: the vertex is in front (an augmented contact at a
    // positive gap): n = (x0 - c)/|x0 - c| and g = +|x0 - c|.
    n = r / l;
    if (sign < 0) n = -n;
    w[0] = T(1.0);
    w[1] = -(T(1.0) - u);
    w[2] = -u;
    w[3] = T(0.0);
    if (p1) *p1 = u;
    return -sign * l;
  }
  const V3<T> ea = x[1] - x[0], eb = x[3] - x[2], r = x[0] - x[2];
  const V3<T> m = ea.cross(eb);
  n = (sign / sqrt(m.squaredNorm())) * m;
  const T A = ea.dot(ea), B = ea.dot(eb), C = eb.dot(eb), D = ea.dot(r), E = eb.dot(r);
  const T den = A * C - B * B;
  const T s = (B * E - C * D) / den, u = (A * E - B * D) / den;
  w[0] = T(1.0) - s;
  w[1] = s;
  w[2] = -(T(1.0) - u);
  w[3] = -u;
  if (p1) *p1 = s;
  if (p2) *p2 = u;
  return r.dot(n);
}

// Closest point of p on triangle (a, b, c) (Ericson, Real-Time Collision
// Detection, 5.1.5): barycentric weights and the feature it lies on
// (0 face, 1..3 edge ab/bc/ca, 4..6 vertex a/b/c).
struct TriangleClosest {
  Eigen::Vector3d point;
  double bary[3];
  int feature;
};
TriangleClosest closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {a, {1, 0, 0}, 4};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {b, {0, 1, 0}, 5};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {a + v * ab, {1 - v, v, 0}, 1};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {c, {0, 0, 1}, 6};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {a + w * ac, {1 - w, 0, w}, 3};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {b + w * (c - b), {0, 1 - w, w}, 2};
  }
  const double den = 1.0 / (va + vb + vc);
  const double v = vb * den, w = vc * den;
  return {a + ab * v + ac * w, {1 - v - w, v, w}, 0};
}

// One contact's geometry: g, n, w and G = dg/dx; with H != nullptr one
// forward-AD pass gives H = d2g/dx2 and, for a rim contact, fade_grad.
// Rim contacts (rim = true): fade = clamp(n . n_T / cos 45 deg, 0, 1), n_T the
// normal of the triangle x1, x2, x3 (mesh_contact.h).
struct ContactGeometry {
  double g = 0;
  Eigen::Vector3d n;
  double w[4];
  Vec12 G;
  double fade = 1;
  Vec12 fade_grad = Vec12::Zero();
};
// rho (kFadeInside, nullptr otherwise): the node weights of x1..x3 (0 on the
// rim, 1 elsewhere); fade = s(r), r = -(w1 rho1 + w2 rho2 + w3 rho3) the
// barycentric interpolation of rho at the closest point and s the smoothstep
// r^2 (3 - 2 r): zero with zero slope at the rim (C1 with the region beyond
// it, where nothing is a contact); its gradient by the same AD pass.
// Crease blend half-width as a fraction of the smaller of the two
// triangles' heights over their common edge.
constexpr double kCreaseBlend = 0.05;

template <class T>
T inside_fade(const T* w, const double* rho) {
  T r = -(w[1] * rho[0] + w[2] * rho[1] + w[3] * rho[2]);
  if (r <= 0.0) return T(0.0);
  if (r >= 1.0) return T(1.0);
  return r * r * (T(3.0) - T(2.0) * r);
}
ContactGeometry contact_geometry(ContactKind kind, const Eigen::Vector3d* x, double sign, bool rim,
                                 const double* rho, Eigen::Matrix<double, 12, 12>* H) {
  ContactGeometry c;
  c.g = gap_kernel<double>(kind, x, sign, c.n, c.w);
  for (int k = 0; k < 4; ++k) c.G.segment<3>(3 * k) = c.w[k] * c.n;
  if (rho) c.fade = inside_fade<double>(c.w, rho);
  const double cos0 = std::sqrt(0.5);
  double cosang = 0;
  if (rim) {
    const Eigen::Vector3d nt = (x[2] - x[1]).cross(x[3] - x[1]).normalized();
    cosang = c.n.dot(nt) / cos0;
    c.fade = std::clamp(cosang, 0.0, 1.0);
  }
  if (!H) return c;
  V3<Ad> xa[4];
  for (int k = 0; k < 4; ++k)
    for (int d = 0; d < 3; ++d) xa[k](d) = Ad(x[k](d), 12, 3 * k + d);
  V3<Ad> na;
  Ad wa[4];
  gap_kernel<Ad>(kind, xa, sign, na, wa);
  for (int k = 0; k < 4; ++k)
    for (int d = 0; d < 3; ++d) H->row(3 * k + d) = (wa[k] * na(d)).derivatives().transpose();
  if (rho && c.fade > 0 && c.fade < 1) c.fade_grad = inside_fade<Ad>(wa, rho).derivatives();
  if (rim && cosang > 0 && cosang < 1) {
    V3<Ad> nt = (xa[2] - xa[1]).cross(xa[3] - xa[1]);
    nt = nt / sqrt(nt.squaredNorm());
    c.fade_grad = (na.dot(nt) / cos0).derivatives();
  }
  return c;
}

Eigen::Vector3d row(const common::Points3& P, int i) { return P.row(i).transpose(); }

// Current unit normals of triangles and area-weighted vertex normals.
void current_normals(const ContactSurface& s, const common::Points3& x, common::Points3& tn, common::Points3& vn) {
  tn.resize(s.F.rows(), 3);
  vn = common::Points3::Zero(s.num_nodes, 3);
  for (int t = 0; t < s.F.rows(); ++t) {
    const Eigen::Vector3d c =
        (row(x, s.F(t, 1)) - row(x, s.F(t, 0))).cross(row(x, s.F(t, 2)) - row(x, s.F(t, 0)));
    const double l = c.norm();
    tn.row(t) = (l > 0 ? Eigen::Vector3d(c / l) : Eigen::Vector3d::Zero()).transpose();
    for (int k = 0; k < 3; ++k) vn.row(s.F(t, k)) += 0.5 * c.transpose();
  }
  for (int i = 0; i < s.num_nodes; ++i) {
    const double l = vn.row(i).norm();
    if (l > 0) vn.row(i) /= l;
  }
}

common::Box3 point_box(const Eigen::Vector3d& p, double r) {
  return {p.array() - r, p.array() + r};
}
common::Box3 triangle_box(const ContactSurface& s, const common::Points3& x, int t, double r) {
  Eigen::Vector3d lo = row(x, s.F(t, 0)), hi = lo;
  for (int k = 1; k < 3; ++k) {
    lo = lo.cwiseMin(row(x, s.F(t, k)));
    hi = hi.cwiseMax(row(x, s.F(t, k)));
  }
  return {lo.array() - r, hi.array() + r};
}
common::Box3 edge_box(const ContactSurface& s, const common::Points3& x, int e, double r) {
  const Eigen::Vector3d a = row(x, s.edges(e, 0)), b = row(x, s.edges(e, 1));
  return {a.cwiseMin(b).array() - r, a.cwiseMax(b).array() + r};
}

void check_positions(const ContactSurface& s, const common::Points3& x, const char* which, const std::string& name) {
  if (x.rows() != s.num_nodes)
    throw common::InputError("mesh contact " + name + ": surface " + which + " has " + std::to_string(s.num_nodes) +
                             " nodes, positions for " + std::to_string(x.rows()) + " given");
}

void build_from_triangles(ContactSurface& s, const common::TriangleMesh& tri) {
  s.num_nodes = tri.num_vertices();
  s.F = tri.F;
  const common::MeshTopology topo = common::build_topology(tri);
  s.edges = topo.edges;
  s.edge_triangles.resize(topo.edges.rows());
  for (int e = 0; e < topo.edges.rows(); ++e) {
    const auto& et = topo.edge_triangles[e];
    s.edge_triangles[e] = {et.size() > 0 ? et[0] : -1, et.size() > 1 ? et[1] : -1};
  }
  s.triangle_edges.resize(tri.num_triangles(), 3);
  {
    std::vector<std::vector<std::pair<int, int>>> by_vertex(s.num_nodes);  // (other vertex, edge)
    for (int e = 0; e < s.edges.rows(); ++e) by_vertex[s.edges(e, 0)].emplace_back(s.edges(e, 1), e);
    for (int t = 0; t < tri.num_triangles(); ++t)
      for (int k = 0; k < 3; ++k) {
        const int u = std::min(tri.F(t, k), tri.F(t, (k + 1) % 3)), v = std::max(tri.F(t, k), tri.F(t, (k + 1) % 3));
        s.triangle_edges(t, k) = -1;
        for (const auto& [w, e] : by_vertex[u])
          if (w == v) s.triangle_edges(t, k) = e;
      }
  }
  const Eigen::VectorXd area = common::triangle_areas(tri);
  s.triangle_area = area;
  s.vertex_area = Eigen::VectorXd::Zero(s.num_nodes);
  for (int t = 0; t < tri.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) s.vertex_area(tri.F(t, k)) += area(t) / 3.0;
  s.vertex_triangles = topo.vertex_triangles;
  s.boundary_vertex.assign(s.num_nodes, 0);
  for (int v : topo.boundary_vertices) s.boundary_vertex[v] = 1;
  s.triangle_height.resize(tri.num_triangles(), 3);
  for (int t = 0; t < tri.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d a = tri.V.row(tri.F(t, (k + 1) % 3)).transpose(), b = tri.V.row(tri.F(t, (k + 2) % 3)).transpose();
      const double len = (b - a).norm();
      s.triangle_height(t, k) = len > 0 ? 2 * area(t) / len : 0.0;
    }
  s.edge_area = Eigen::VectorXd::Zero(s.edges.rows());
  for (int e = 0; e < s.edges.rows(); ++e)
    for (int t : s.edge_triangles[e])
      if (t >= 0) s.edge_area(e) += area(t) / 3.0;
}

// The closest point of surface Sf to every vertex of Sv within `radius`
// (broad phase: vertex boxes of half-width radius against tight triangle
// boxes, so every triangle within radius is a candidate), with the signed
// distance: negative behind Sf. The sign comes from the pseudo-normal of the
// closest point's feature (face normal; edge: sum of the adjacent face
// normals; corner: vertex normal; Baerentzen & Aanaes 2005). The signed
// distance is continuous as a vertex slides from one facet to the next (no
// force jumps at kinks). Vertices whose normal does not oppose the
// pseudo-normal (surfaces not facing each other) get no hit.
struct VertexHit {
  int vertex = -1, triangle = -1;
  TriangleClosest closest{};
  double signed_distance = 0;
  int fade_edge = -1;  // 1: the closest point is on the open boundary (rim contact, faded)
};
std::vector<VertexHit> vertex_hits(const ContactSurface& Sv, const common::Points3& Xv, const common::Points3& vnv,
                                   const ContactSurface& Sf, const common::Points3& Xf, const common::Points3& tnf,
                                   const common::Points3& vnf, double radius, double min_opposition,
                                   const Eigen::VectorXd& weight, bool rim_contacts, long* candidates,
                                   common::CachedOverlaps* cache) {
  std::vector<common::Box3> vb(Sv.num_nodes), fb(Sf.F.rows());
  for (int i = 0; i < Sv.num_nodes; ++i) vb[i] = point_box(row(Xv, i), radius);
  for (int t = 0; t < Sf.F.rows(); ++t) fb[t] = triangle_box(Sf, Xf, t, 0.0);
  // With a cache: the same pairs as overlapping_boxes(vb, fb), from a
  // superset kept while the surfaces move less than the cache's margin.
  const auto pairs = cache ? cache->pairs(vb, fb, Xv, Xf) : common::overlapping_boxes(vb, fb);
  if (candidates) *candidates += static_cast<long>(pairs.size());
  // Group by vertex (pairs are sorted by vertex, then triangle).
  std::vector<size_t> starts;
  for (size_t k = 0; k < pairs.size(); ++k)
    if (k == 0 || pairs[k].first != pairs[k - 1].first) starts.push_back(k);
  starts.push_back(pairs.size());
  const int ng = static_cast<int>(starts.size()) - 1;
  std::vector<VertexHit> hits(std::max(ng, 0));
#pragma omp parallel for schedule(dynamic, 64) if (ng > 256)
  for (int gi = 0; gi < ng; ++gi) {
    const int i = pairs[starts[gi]].first;
    if (!(weight(i) > 0)) continue;  // not a penetrating vertex
    const Eigen::Vector3d p = row(Xv, i);
    double best = std::numeric_limits<double>::infinity();
    VertexHit h;
    for (size_t k = starts[gi]; k < starts[gi + 1]; ++k) {
      const int t = pairs[k].second;
      if (tnf.row(t).squaredNorm() == 0) continue;
      const TriangleClosest cp = closest_on_triangle(p, row(Xf, Sf.F(t, 0)), row(Xf, Sf.F(t, 1)), row(Xf, Sf.F(t, 2)));
      const double d2 = (p - cp.point).squaredNorm();
      if (d2 < best) {  // ties: the first (lower) triangle index
        best = d2;
        h.triangle = t;
        h.closest = cp;
      }
    }
    if (h.triangle < 0) continue;
    // Beyond the open boundary of Sf nothing is behind it: a closest point on
    // a boundary edge or corner is no contact (otherwise a vertex beside the
    // boundary, nearly in the surface's plane, would flip between "in front"
    // and "behind" with a gap as large as its distance to the boundary).
    const int f = h.closest.feature;
    const bool on_boundary = (f >= 1 && f <= 3 && Sf.edge_triangles[Sf.triangle_edges(h.triangle, f - 1)][1] < 0) ||
                             (f >= 4 && Sf.boundary_vertex[Sf.F(h.triangle, f - 4)]);
    if (on_boundary && !rim_contacts) continue;  // beyond the rim: nothing behind it (kFadeInside)
    if (on_boundary) {
      // Beyond the open boundary (the other surface's rim): the distance to
      // the rim edge or corner, behind the plane of this boundary triangle;
      // detect() weights it by how squarely p lies behind the rim
      // (mesh_contact.h), so nothing jumps when p slides off the rim.
      const double dist = std::sqrt(best);
      if (!(dist > 0 && dist < radius)) continue;
      const Eigen::Vector3d n = tnf.row(h.triangle).transpose();
      if (!(vnv.row(i).dot(n.transpose()) < -min_opposition)) continue;
      h.vertex = i;
      h.fade_edge = 1;
      h.signed_distance = (p - h.closest.point).dot(n) < 0 ? -dist : dist;
      hits[gi] = h;
      continue;
    }
    const double dist = std::sqrt(best);
    if (!(dist > 0 && dist < radius)) continue;
    Eigen::Vector3d pseudo;
    if (h.closest.feature == 0) {
      pseudo = tnf.row(h.triangle).transpose();
    } else if (h.closest.feature <= 3) {
      pseudo.setZero();
      for (int t : Sf.edge_triangles[Sf.triangle_edges(h.triangle, h.closest.feature - 1)])
        if (t >= 0) pseudo += tnf.row(t).transpose();
    } else {
      pseudo = vnf.row(Sf.F(h.triangle, h.closest.feature - 4)).transpose();
    }
    if (!(vnv.row(i).dot(pseudo.transpose()) < -min_opposition * pseudo.norm())) continue;
    h.vertex = i;
    h.signed_distance = (p - h.closest.point).dot(pseudo) < 0 ? -dist : dist;
    hits[gi] = h;
  }
  std::vector<VertexHit> out;
  for (const VertexHit& h : hits)
    if (h.vertex >= 0) out.push_back(h);
  return out;
}

}  // namespace

ContactSurface::ContactSurface(const common::QuadMesh& mesh) {
  build_from_triangles(*this, common::triangulate(mesh));
}

ContactSurface::ContactSurface(const ShellModel& model) {
  common::QuadMesh m;
  m.V.resize(model.num_nodes(), 3);
  for (int i = 0; i < model.num_nodes(); ++i) m.V.row(i) = model.reference_position(i).transpose();
  m.Q = model.quads();
  build_from_triangles(*this, common::triangulate(m));
}

double contact_gap(ContactKind kind, const std::array<Eigen::Vector3d, 4>& x, double sign,
                   Eigen::Matrix<double, 12, 1>* G, Eigen::Matrix<double, 12, 12>* H) {
  const ContactGeometry c = contact_geometry(kind, x.data(), sign, false, nullptr, H);
  if (G) *G = c.G;
  return c.g;
}

Eigen::VectorXd faded_vertex_weights(const ContactSurface& s) {
  Eigen::VectorXd w = Eigen::VectorXd::Zero(s.num_nodes);
  for (int t = 0; t < s.F.rows(); ++t) {
    const double A = s.triangle_area(t);
    int rim = 0;
    for (int k = 0; k < 3; ++k) rim += s.boundary_vertex[s.F(t, k)] ? 1 : 0;
    // Integrals of s(r) N_i over the triangle (docs/contact.md, "Rims"): with
    // r = lambda_j (one interior node j) or 1 - lambda_i (one rim node i) and
    // lambda's density 2 (1 - lambda) on the triangle.
    static constexpr double kInterior[4] = {1.0 / 3, 4.0 / 15, 1.0 / 6, 0};
    static constexpr double kRim[4] = {0, 1.0 / 6, 1.0 / 15, 0};
    for (int k = 0; k < 3; ++k) w(s.F(t, k)) += A * (s.boundary_vertex[s.F(t, k)] ? kRim[rim] : kInterior[rim]);
  }
  return w;
}

MeshContact::MeshContact(std::string name, const ContactSurface& a, const ContactSurface& b,
                         const ContactOptions& options)
    : name_(std::move(name)), a_(a), b_(b), opts_(options) {
  const auto bad = [&](const std::string& what) {
    throw common::InputError("mesh contact " + name_ + ": " + what);
  };
  if (!(opts_.stiffness_N_m3 > 0) || !std::isfinite(opts_.stiffness_N_m3))
    bad("stiffness must be > 0 N/m^3, found " + std::to_string(opts_.stiffness_N_m3));
  if (!(opts_.damping_N_s_m3 >= 0) || !std::isfinite(opts_.damping_N_s_m3))
    bad("damping must be >= 0 N s/m^3, found " + std::to_string(opts_.damping_N_s_m3));
  if (!(opts_.max_depth_m > 0) || !std::isfinite(opts_.max_depth_m))
    bad("max_depth must be > 0 m, found " + std::to_string(opts_.max_depth_m));
  if (!(opts_.rim_max_depth_m == 0 || (opts_.rim_max_depth_m > opts_.smoothing_m && std::isfinite(opts_.rim_max_depth_m))))
    bad("rim max depth must be 0 (= max depth) or larger than the smoothing width, found " +
        std::to_string(opts_.rim_max_depth_m));
  if (!(opts_.smoothing_m > 0) || !(opts_.smoothing_m < opts_.max_depth_m))
    bad("smoothing must be in (0, max_depth), found " + std::to_string(opts_.smoothing_m) + " m");
  if (!(opts_.min_opposition >= -1 && opts_.min_opposition < 1))
    bad("min_opposition must be in [-1, 1), found " + std::to_string(opts_.min_opposition));
  if (a_.F.rows() == 0 || b_.F.rows() == 0) bad("both surfaces need triangles");
  for (auto& c : broad_phase_) c = std::make_unique<common::CachedOverlaps>(0.2 * opts_.max_depth_m);
  if (opts_.faded_vertex_weights && opts_.rim != RimTreatment::kFadeInside)
    bad("faded vertex weights need the fade_inside rim treatment");
  for (int side = 0; side < 2; ++side) {
    const ContactSurface& s = side == 0 ? a_ : b_;
    if (opts_.faded_vertex_weights) {
      vertex_weight_[side] = faded_vertex_weights(s);
    } else {
      vertex_weight_[side] = s.vertex_area;
      if (!opts_.rim_vertices)
        for (int i = 0; i < s.num_nodes; ++i)
          if (s.boundary_vertex[i]) vertex_weight_[side](i) = 0;
    }
  }
}

std::vector<ContactPoint> MeshContact::detect(const common::Points3& xa, const common::Points3& xb,
                                              const common::Points3* va, const common::Points3* vb, bool want_hessian,
                                              ContactCounts* counts) const {
  check_positions(a_, xa, "a", name_);
  check_positions(b_, xb, "b", name_);
  const std::lock_guard<std::mutex> lock(broad_phase_mutex_);
  const ContactSurface* S[2] = {&a_, &b_};
  const common::Points3* X[2] = {&xa, &xb};
  const common::Points3* V[2] = {va, vb};
  common::Points3 tn[2], vn[2];
  current_normals(a_, xa, tn[0], vn[0]);
  current_normals(b_, xb, tn[1], vn[1]);
  const double dmax = opts_.max_depth_m;
  ContactCounts cnt;
  std::vector<ContactPoint> out;
  // Which vertices are in vertex-face contact, per surface (edge-edge exclusion).
  std::vector<char> vf_active[2] = {std::vector<char>(a_.num_nodes, 0), std::vector<char>(b_.num_nodes, 0)};


  // ---- vertex-face, both directions --------------------------------------
  for (int pass = 0; pass < 2; ++pass) {
    const int sv = pass, sf = 1 - pass;  // vertex side, face side
    const ContactSurface& Sf = *S[sf];
    for (const VertexHit& h : vertex_hits(*S[sv], *X[sv], vn[sv], Sf, *X[sf], tn[sf], vn[sf], dmax,
                                          opts_.min_opposition, vertex_weight_[sv],
                                          opts_.rim == RimTreatment::kRimContacts, &cnt.candidate_vertex_face,
                                          broad_phase_[pass].get())) {
      // Augmented: a vertex with multiplier lambda > 0 is in contact while
      // g < lambda / k + delta / 2 (its pressure p(g - offset) > 0).
      const double lam = lambda_[sv].size() ? lambda_[sv](h.vertex) : 0.0;
      const double offset = lam > 0 ? lam / opts_.stiffness_N_m3 + 0.5 * opts_.smoothing_m : 0.0;
      if (!(h.signed_distance < offset)) continue;  // in front: no contact
      ContactPoint c;
      c.offset = offset;
      c.gap = h.signed_distance;  // its sign orients edge and corner contacts below
      const int tri[3] = {Sf.F(h.triangle, 0), Sf.F(h.triangle, 1), Sf.F(h.triangle, 2)};
      const int f = h.closest.feature;
      if (f == 0) {
        c.kind = ContactKind::kVertexFace;
        c.node = {h.vertex, tri[0], tri[1], tri[2]};
      } else if (f <= 3) {
        c.kind = ContactKind::kVertexEdge;  // edge (k, k+1 mod 3)
        c.node = {h.vertex, tri[f - 1], tri[f % 3], tri[(f + 1) % 3]};
      } else {
        c.kind = ContactKind::kVertexVertex;
        c.node = {h.vertex, tri[f - 4], tri[(f - 3) % 3], tri[(f - 2) % 3]};
      }
      c.fade_edge = h.fade_edge;
      if (opts_.rim == RimTreatment::kFadeInside &&
          (Sf.boundary_vertex[c.node[1]] || (c.kind != ContactKind::kVertexVertex && Sf.boundary_vertex[c.node[2]]) ||
           (c.kind == ContactKind::kVertexFace && Sf.boundary_vertex[c.node[3]])))
        c.fade_edge = 0;  // a face (or its edge / corner) touching the rim: faded
      c.side = {sv, sf, sf, sf};
      c.area = 0.5 * vertex_weight_[sv](h.vertex);
      vf_active[sv][h.vertex] = 1;
      // Crease blend (augmented contacts only): within a band of half-width
      // b of an interior edge, the contact is shared with the face across
      // that edge, weights s(1/2 + d/(2b)) and s(1/2 - d/(2b)) (d: the
      // in-plane distance of the projection from the edge, positive on the
      // closest face), so the force turns continuously from one face's
      // normal to the other's when the closest face changes. A closest point
      // on the edge itself (d = 0: a vertex in front of a convex kink or
      // behind a concave one) becomes the same pair of face contacts instead
      // of the edge contact, whose normal (p - c)/|p - c| turns through the
      // whole kink angle within a distance of the order of the gap. With a
      // multiplier the force does not vanish at g = 0, and without the blend
      // it jumps by the angle between the faces there.
      const bool edge_feature = c.kind == ContactKind::kVertexEdge;
      if (offset > 0 && (c.kind == ContactKind::kVertexFace || edge_feature) && c.fade_edge < 0 &&
          kCreaseBlend > 0) {
        const int t = h.triangle;
        int j = 0;  // the node opposite the edge
        if (edge_feature) {
          j = (f + 1) % 3;  // edge f - 1 joins tri[f - 1] and tri[f % 3]
        } else {
          for (int k = 1; k < 3; ++k)
            if (h.closest.bary[k] < h.closest.bary[j]) j = k;
        }
        const int e = Sf.triangle_edges(t, (j + 1) % 3);
        const int t2 = e < 0 ? -1 : (Sf.edge_triangles[e][0] == t ? Sf.edge_triangles[e][1] : Sf.edge_triangles[e][0]);
        int j2 = -1;
        if (t2 >= 0 && tn[sf].row(t2).squaredNorm() > 0) {
          for (int k = 0; k < 3; ++k)
            if (Sf.F(t2, k) != tri[(j + 1) % 3] && Sf.F(t2, k) != tri[(j + 2) % 3]) j2 = k;
          for (int k = 0; k < 3 && j2 >= 0; ++k)
            if (opts_.rim == RimTreatment::kFadeInside && Sf.boundary_vertex[Sf.F(t2, k)]) j2 = -1;
        }
        if (j2 >= 0) {
          const double ht = Sf.triangle_height(t, j), h2 = Sf.triangle_height(t2, j2);
          const double b = kCreaseBlend * std::min(ht, h2);
          if (b > 0 && (edge_feature || h.closest.bary[j] * ht < b) &&
              !(opts_.rim == RimTreatment::kFadeInside &&
                (Sf.boundary_vertex[tri[0]] || Sf.boundary_vertex[tri[1]] || Sf.boundary_vertex[tri[2]]))) {
            c.kind = ContactKind::kVertexFace;
            c.node = {h.vertex, tri[0], tri[1], tri[2]};
            c.blend = true;
            c.blend_rho = {0.5, 0.5, 0.5};
            c.blend_rho[j] = 0.5 + ht / (2 * b);
            ContactPoint c2 = c;
            c2.node = {h.vertex, Sf.F(t2, 0), Sf.F(t2, 1), Sf.F(t2, 2)};
            c2.blend_rho = {0.5, 0.5, 0.5};
            c2.blend_rho[j2] = 0.5 + h2 / (2 * b);
            out.push_back(std::move(c2));
          }
        }
      }
      out.push_back(std::move(c));
    }
  }
  // ---- edge-edge ------------------------------------------------------------
  std::vector<ContactPoint> ee;
  if (opts_.edge_edge) {
    std::vector<common::Box3> ea(a_.edges.rows()), eb(b_.edges.rows());
    for (int e = 0; e < a_.edges.rows(); ++e) ea[e] = edge_box(a_, xa, e, 0.5 * dmax);
    for (int e = 0; e < b_.edges.rows(); ++e) eb[e] = edge_box(b_, xb, e, 0.5 * dmax);
    const auto pairs = common::overlapping_boxes(ea, eb);
    cnt.candidate_edge_edge += static_cast<long>(pairs.size());
    auto edge_normal = [&](int side, int e) {
      Eigen::Vector3d n = Eigen::Vector3d::Zero();
      for (int t : S[side]->edge_triangles[e])
        if (t >= 0) n += tn[side].row(t).transpose();
      const double l = n.norm();
      return l > 0 ? Eigen::Vector3d(n / l) : n;
    };
    std::vector<ContactPoint> cand(pairs.size());
    std::vector<char> ok(pairs.size(), 0);
#pragma omp parallel for schedule(dynamic, 256) if (pairs.size() > 1024)
    for (long k = 0; k < static_cast<long>(pairs.size()); ++k) {
      const int e1 = pairs[k].first, e2 = pairs[k].second;
      const int a0 = a_.edges(e1, 0), a1 = a_.edges(e1, 1), b0 = b_.edges(e2, 0), b1 = b_.edges(e2, 1);
      if (vf_active[0][a0] || vf_active[0][a1] || vf_active[1][b0] || vf_active[1][b1]) continue;
      Eigen::Vector3d x[4] = {row(xa, a0), row(xa, a1), row(xb, b0), row(xb, b1)};
      const Eigen::Vector3d da = x[1] - x[0], db = x[3] - x[2];
      const Eigen::Vector3d m = da.cross(db);
      // Nearly parallel edges have no well-defined crossing (sin < 0.05).
      if (!(m.norm() > 0.05 * da.norm() * db.norm())) continue;
      const Eigen::Vector3d nb = edge_normal(1, e2), na = edge_normal(0, e1);
      const double sign = m.dot(nb) >= 0 ? 1.0 : -1.0;
      Eigen::Vector3d n;
      double w[4], s = 0, u = 0;
      const double g = gap_kernel<double>(ContactKind::kEdgeEdge, x, sign, n, w, &s, &u);
      if (s <= 0 || s >= 1 || u <= 0 || u >= 1) continue;
      if (!(g < 0 && g > -dmax)) continue;
      if (!(na.dot(n) < -opts_.min_opposition)) continue;
      ContactPoint& c = cand[k];
      c.kind = ContactKind::kEdgeEdge;
      c.node = {a0, a1, b0, b1};
      c.side = {0, 0, 1, 1};
      c.area = std::min(a_.edge_area(e1), b_.edge_area(e2));
      c.normal = n;  // orientation sign is re-derived from it below
      ok[k] = 1;
    }
    for (size_t k = 0; k < pairs.size(); ++k)
      if (ok[k]) out.push_back(std::move(cand[k]));
  }
  // ---- gap, derivatives, pressure -------------------------------------------
  const double kc = opts_.stiffness_N_m3, cc = opts_.damping_N_s_m3;
  std::vector<char> keep(out.size(), 0);
#pragma omp parallel for schedule(static) if (out.size() > 512)
  for (long k = 0; k < static_cast<long>(out.size()); ++k) {
    ContactPoint& c = out[k];
    Eigen::Vector3d x[4];
    for (int j = 0; j < 4; ++j) x[j] = row(*X[c.side[j]], c.node[j]);
    double sign = 1.0;
    if (c.kind == ContactKind::kEdgeEdge) sign = c.normal.dot((x[1] - x[0]).cross(x[3] - x[2])) >= 0 ? 1.0 : -1.0;
    else if (c.kind != ContactKind::kVertexFace && c.gap > 0)
      sign = -1.0;  // augmented contact in front of an edge or corner: g = +|x0 - c|
    double rho[3] = {1, 1, 1};
    if (c.fade_edge == 0) {
      const ContactSurface& Sf = *S[c.side[1]];
      for (int j = 0; j < 3; ++j) rho[j] = Sf.boundary_vertex[c.node[j + 1]] ? 0.0 : 1.0;
    } else if (c.blend) {
      for (int j = 0; j < 3; ++j) rho[j] = c.blend_rho[j];
    }
    const ContactGeometry geo = contact_geometry(c.kind, x, sign, c.fade_edge == 1,
                                                 (c.fade_edge == 0 || c.blend) ? rho : nullptr,
                                                 want_hessian ? &c.H : nullptr);
    c.gap = geo.g;
    c.G = geo.G;
    c.normal = geo.n;
    c.fade = geo.fade;
    c.fade_grad = geo.fade_grad;
    const Vec12& G = geo.G;
    c.point = c.kind == ContactKind::kEdgeEdge ? Eigen::Vector3d(-geo.w[2] * x[2] - geo.w[3] * x[3])
                                               : Eigen::Vector3d(x[0] - c.gap * geo.n);
    c.gap_rate = 0;
    for (int j = 0; j < 4; ++j) {
      const common::Points3* vel = V[c.side[j]];
      if (vel) c.gap_rate += G.segment<3>(3 * j).dot(row(*vel, c.node[j]));
    }
    // Penalty with a quadratic toe of width delta: p and dp/dg are
    // continuous at g = 0, so the tangent does not jump when a contact
    // switches on (no Newton cycling at the contact boundary).
    const double delta = opts_.smoothing_m;
    // Augmented law: the same function of the shifted gap g - offset.
    const double gs = c.gap - c.offset;
    double p = 0, dp = 0;  // p(g) and -dp/dg
    if (gs <= -delta) {
      p = kc * (-gs - 0.5 * delta);
      dp = kc;
    } else {  // (-delta, 0); round-off may give a gap just above 0, as the penalty always had
      p = 0.5 * kc * gs * gs / delta;
      dp = -kc * gs / delta;
    }
    // Depth fade: over the last quarter of max_depth the elastic pressure
    // goes smoothly to zero, p s(d) with s the smoothstep from 1 at
    // d0 = 0.75 max_depth to 0 at max_depth (d = -g), so a contact that
    // reaches the cut-off (the far side; in practice a vertex beside and
    // below a rim) leaves without a force jump.
    // Rim contacts have their own, shorter cut-off (rim_max_depth_m).
    const double cut = (c.fade_edge == 1 && opts_.rim_max_depth_m > 0) ? std::min(dmax, opts_.rim_max_depth_m) : dmax;
    const double depth = -c.gap, d0 = 0.75 * cut;
    if (depth > d0) {
      const double u = std::min((depth - d0) / (cut - d0), 1.0);
      const double s = 1 - u * u * (3 - 2 * u), ds = -6 * u * (1 - u) / (cut - d0);  // ds/dd
      dp = s * dp + p * ds;  // -d(p s)/dg = s (-dp/dg) + p ds/dd
      p *= s;
    }
    c.pressure = p - cc * c.gap_rate;
    c.stiffness = dp;
    keep[k] = c.pressure > 0;
    if (!(c.fade > 0)) keep[k] = 0;  // rim contact beside the rim, or an inactive one
  }
  std::vector<ContactPoint> active;
  active.reserve(out.size());
  for (size_t k = 0; k < out.size(); ++k) {
    if (!keep[k]) continue;
    ContactPoint& c = out[k];
    if (c.kind == ContactKind::kEdgeEdge)
      ++cnt.edge_edge;
    else
      ++cnt.vertex_face;
    cnt.max_penetration_m = std::max(cnt.max_penetration_m, c.fade_edge == 1 ? c.fade * -c.gap : -c.gap);
    if (c.fade_edge >= 0)
      cnt.max_rim_depth_m = std::max(cnt.max_rim_depth_m, -c.gap);
    else
      cnt.max_unfaded_penetration_m = std::max(cnt.max_unfaded_penetration_m, -c.gap);
    active.push_back(std::move(c));
  }
  if (counts) *counts = cnt;
  return active;
}

void MeshContact::set_multipliers(const std::array<Eigen::VectorXd, 2>& lambda) {
  for (int side = 0; side < 2; ++side) {
    const int n = surface(side).num_nodes;
    if (lambda[side].size() != 0 && lambda[side].size() != n)
      throw common::InputError("mesh contact " + name_ + ": " + std::to_string(lambda[side].size()) +
                               " multipliers for surface " + (side ? "b" : "a") + " of " + std::to_string(n) +
                               " nodes");
    if (lambda[side].size() && !(lambda[side].array() >= 0).all())
      throw common::InputError("mesh contact " + name_ + ": multipliers must be >= 0 Pa");
  }
  lambda_ = lambda;
}

std::array<Eigen::VectorXd, 2> MeshContact::updated_multipliers(const common::Points3& xa,
                                                                const common::Points3& xb) const {
  std::array<Eigen::VectorXd, 2> out = {Eigen::VectorXd::Zero(a_.num_nodes), Eigen::VectorXd::Zero(b_.num_nodes)};
  // At rest (no velocities): the elastic pressure, damping excluded.
  // A vertex in a crease blend has two contacts: its multiplier is their
  // fade-weighted pressure.
  std::array<Eigen::VectorXd, 2> blend_sum = out, blend_weight = out;
  for (const ContactPoint& c : detect(xa, xb, nullptr, nullptr, false)) {
    if (c.kind == ContactKind::kEdgeEdge) continue;
    if (!c.blend) {
      out[c.side[0]](c.node[0]) = c.pressure;
    } else {
      blend_sum[c.side[0]](c.node[0]) += c.fade * c.pressure;
      blend_weight[c.side[0]](c.node[0]) += c.fade;
    }
  }
  for (int s = 0; s < 2; ++s)
    for (Eigen::Index i = 0; i < out[s].size(); ++i)
      if (blend_weight[s](i) > 0) out[s](i) = blend_sum[s](i) / blend_weight[s](i);
  return out;
}

std::vector<std::pair<int, int>> MeshContact::coupling_candidates(const common::Points3& xa,
                                                                  const common::Points3& xb, double margin) const {
  check_positions(a_, xa, "a", name_);
  check_positions(b_, xb, "b", name_);
  const ContactSurface* S[2] = {&a_, &b_};
  const common::Points3* X[2] = {&xa, &xb};
  common::Points3 tn[2], vn[2];
  current_normals(a_, xa, tn[0], vn[0]);
  current_normals(b_, xb, tn[1], vn[1]);
  // Every vertex within `margin` of penetrating (signed distance < margin)
  // is coupled with the nodes of the triangles around its closest triangle
  // (the triangles sharing a vertex with it), so that it can slide by about
  // one element, or penetrate, before the pattern must be rebuilt.
  std::vector<std::pair<int, int>> nodes;
  for (int pass = 0; pass < 2; ++pass) {
    const int sv = pass, sf = 1 - pass;
    const ContactSurface& Sf = *S[sf];
    for (const VertexHit& h : vertex_hits(*S[sv], *X[sv], vn[sv], Sf, *X[sf], tn[sf], vn[sf],
                                          std::max(opts_.max_depth_m, margin), opts_.min_opposition,
                                          vertex_weight_[sv], opts_.rim == RimTreatment::kRimContacts, nullptr, nullptr)) {
      if (!(h.signed_distance < margin)) continue;
      for (int k = 0; k < 3; ++k)
        for (int t : Sf.vertex_triangles[Sf.F(h.triangle, k)])
          for (int j = 0; j < 3; ++j) {
            const int other = Sf.F(t, j);
            nodes.push_back(pass == 0 ? std::make_pair(h.vertex, other) : std::make_pair(other, h.vertex));
          }
    }
  }
  if (opts_.edge_edge) {
    // Edge pairs whose boxes (grown by margin) overlap near the other
    // surface: their four nodes.
    std::vector<common::Box3> ea(a_.edges.rows()), eb(b_.edges.rows());
    for (int e = 0; e < a_.edges.rows(); ++e) ea[e] = edge_box(a_, xa, e, 0.5 * margin);
    for (int e = 0; e < b_.edges.rows(); ++e) eb[e] = edge_box(b_, xb, e, 0.5 * margin);
    for (const auto& [e1, e2] : common::overlapping_boxes(ea, eb))
      for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j) nodes.emplace_back(a_.edges(e1, i), b_.edges(e2, j));
  }
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  return nodes;
}

}  // namespace arthrosim::cartilage
