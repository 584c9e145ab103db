// Isotropic remeshing through CGAL::Polygon_mesh_processing (see remesh.h).
// CGAL's incremental remesher (Botsch & Kobbelt 2004, "A remeshing approach to
// multiresolution modeling") targets edge lengths in [4/5 L, 4/3 L]: split
// edges longer than 4/3 L, collapse edges shorter than 4/5 L, flip edges to
// bring valences towards 6, tangential relaxation, projection of the moved
// vertices back onto the input surface (CGAL AABB tree).
//
// Boundaries: CGAL always treats border edges as constrained (never flipped,
// end points not smoothed). With protect_boundary the border edges are first
// split (PMP::split_long_edges, midpoints, so new vertices lie exactly on the
// input outline) until none exceeds the target, then protected from further
// splits and collapses: the outline polyline is preserved exactly. Without it,
// border edges may also be collapsed (CGAL's default), so the outline is
// resampled and may cut corners of the input polyline. Sharp edges
// (feature_angle) are handled exactly like the boundary.
#include "common/remesh.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/border.h>
#include <CGAL/Polygon_mesh_processing/detect_features.h>
#include <CGAL/Polygon_mesh_processing/remesh.h>
#include <CGAL/Surface_mesh.h>

#include <boost/function_output_iterator.hpp>

#include <cmath>
#include <string>
#include <vector>

#include "common/error.h"
#include "common/mesh_validation.h"

namespace arthrosim::common {

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using SurfaceMesh = CGAL::Surface_mesh<K::Point_3>;
namespace PMP = CGAL::Polygon_mesh_processing;

std::string label(const TriangleMesh& m) { return m.name.empty() ? std::string("<mesh>") : m.name; }

SurfaceMesh to_surface_mesh(const TriangleMesh& mesh) {
  SurfaceMesh sm;
  std::vector<SurfaceMesh::Vertex_index> vid(mesh.num_vertices());
  for (int i = 0; i < mesh.num_vertices(); ++i) vid[i] = sm.add_vertex(K::Point_3(mesh.V(i, 0), mesh.V(i, 1), mesh.V(i, 2)));
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    const auto f = sm.add_face(vid[mesh.F(t, 0)], vid[mesh.F(t, 1)], vid[mesh.F(t, 2)]);
    if (f == SurfaceMesh::null_face()) {
      // validate() has excluded non-manifold edges and inconsistent orientation;
      // what remains is a non-manifold vertex (two fans touching at a vertex).
      throw InputError(label(mesh), 0,
                       "isotropic_remesh: expected a manifold surface, found triangle " + std::to_string(t) +
                           " cannot be added (a non-manifold vertex among " + std::to_string(mesh.F(t, 0)) + ", " +
                           std::to_string(mesh.F(t, 1)) + ", " + std::to_string(mesh.F(t, 2)) + ")");
    }
  }
  return sm;
}

TriangleMesh from_surface_mesh(SurfaceMesh& sm, const std::string& name) {
  sm.collect_garbage();
  // Keep only vertices used by faces (isolated input vertices are dropped).
  std::vector<int> index(sm.number_of_vertices(), -1);
  int n = 0;
  for (auto f : sm.faces())
    for (auto v : sm.vertices_around_face(sm.halfedge(f)))
      if (index[v.idx()] < 0) index[v.idx()] = 0;
  for (auto v : sm.vertices())
    if (index[v.idx()] == 0) index[v.idx()] = n++;
  TriangleMesh out;
  out.name = name;
  out.V.resize(n, 3);
  for (auto v : sm.vertices()) {
    if (index[v.idx()] < 0) continue;
    const auto& p = sm.point(v);
    out.V.row(index[v.idx()]) << p.x(), p.y(), p.z();
  }
  out.F.resize(static_cast<int>(sm.number_of_faces()), 3);
  int t = 0;
  for (auto f : sm.faces()) {
    int k = 0;
    for (auto v : sm.vertices_around_face(sm.halfedge(f))) {
      if (k >= 3) throw NumericalError("isotropic_remesh: CGAL returned a non-triangular face");
      out.F(t, k++) = index[v.idx()];
    }
    ++t;
  }
  return out;
}

}  // namespace

double estimate_remesh_triangles(const TriangleMesh& mesh, double target_edge_length) {
  const double L = target_edge_length;
  const double area = surface_area(mesh);
  double outline = 0.0;
  const MeshTopology topo = build_topology(mesh);
  for (Eigen::Index e = 0; e < topo.edges.rows(); ++e)
    if (topo.edge_triangles[e].size() == 1) outline += (mesh.V.row(topo.edges(e, 0)) - mesh.V.row(topo.edges(e, 1))).norm();
  return area / (std::sqrt(3.0) / 4.0 * L * L) + outline / L;
}

RemeshStatistics edge_length_statistics(const TriangleMesh& mesh) {
  RemeshStatistics s;
  s.input_triangles = mesh.num_triangles();
  s.output_triangles = mesh.num_triangles();
  const MeshTopology topo = build_topology(mesh);
  const Eigen::Index ne = topo.edges.rows();
  if (ne == 0) return s;
  double sum = 0.0, lo = INFINITY, hi = 0.0;
  for (Eigen::Index e = 0; e < ne; ++e) {
    const double l = (mesh.V.row(topo.edges(e, 0)) - mesh.V.row(topo.edges(e, 1))).norm();
    sum += l;
    lo = std::min(lo, l);
    hi = std::max(hi, l);
  }
  s.mean_edge_length = sum / static_cast<double>(ne);
  s.min_edge_length = lo;
  s.max_edge_length = hi;
  return s;
}

TriangleMesh isotropic_remesh(const TriangleMesh& mesh, const RemeshOptions& options, RemeshStatistics* stats) {
  if (!(options.target_edge_length > 0.0) || !std::isfinite(options.target_edge_length)) {
    throw InputError(label(mesh), 0, "isotropic_remesh: expected target_edge_length > 0 [m], found " +
                                         std::to_string(options.target_edge_length));
  }
  if (options.iterations < 1 || options.relaxation_steps < 1) {
    throw InputError(label(mesh), 0, "isotropic_remesh: expected iterations >= 1 and relaxation_steps >= 1, found " +
                                         std::to_string(options.iterations) + " and " +
                                         std::to_string(options.relaxation_steps));
  }
  // Refuse what the remesher cannot handle, with the validation summary.
  const ValidationReport report = validate(mesh);
  if (!report.ok()) {
    throw InputError(label(mesh), 0, "isotropic_remesh: expected a valid manifold triangle mesh, found:\n" +
                                         report.summary());
  }
  SurfaceMesh sm = to_surface_mesh(mesh);
  const double L = options.target_edge_length;

  if (!(options.feature_angle >= 0.0) || options.feature_angle >= M_PI) {
    throw InputError(label(mesh), 0, "isotropic_remesh: expected feature_angle in [0, pi) [rad], found " +
                                         std::to_string(options.feature_angle));
  }
  const auto params = CGAL::parameters::number_of_iterations(options.iterations)
                          .number_of_relaxation_steps(options.relaxation_steps);
  if (options.feature_angle == 0.0) {
    // Boundary only: CGAL treats border edges as constrained by itself.
    if (options.protect_boundary) {
      std::vector<SurfaceMesh::Edge_index> border;
      PMP::border_halfedges(sm.faces(), sm, boost::make_function_output_iterator([&](SurfaceMesh::Halfedge_index h) {
                              border.push_back(sm.edge(h));
                            }));
      if (!border.empty()) PMP::split_long_edges(border, L, sm);
      PMP::isotropic_remeshing(sm.faces(), L, sm, params.protect_constraints(true));
    } else {
      PMP::isotropic_remeshing(sm.faces(), L, sm, params);
    }
  } else {
    // Boundary plus sharp edges, in an explicit constrained-edge map.
    auto constrained = sm.add_property_map<SurfaceMesh::Edge_index, bool>("e:arthrosim_constrained", false).first;
    PMP::border_halfedges(sm.faces(), sm, boost::make_function_output_iterator([&](SurfaceMesh::Halfedge_index h) {
                            constrained[sm.edge(h)] = true;
                          }));
    auto sharp = sm.add_property_map<SurfaceMesh::Edge_index, bool>("e:arthrosim_sharp", false).first;
    PMP::detect_sharp_edges(sm, options.feature_angle * 180.0 / M_PI, sharp);
    std::vector<SurfaceMesh::Edge_index> constrained_edges;
    for (auto e : sm.edges()) {
      if (sharp[e]) constrained[e] = true;
      if (constrained[e]) constrained_edges.push_back(e);
    }
    sm.remove_property_map(sharp);
    if (options.protect_boundary) {
      // Protected edges must not exceed 4/3 L (CGAL precondition): split them
      // first at midpoints, which keeps them on the input polylines; sub-edges
      // inherit the constrained flag.
      if (!constrained_edges.empty())
        PMP::split_long_edges(constrained_edges, L, sm, CGAL::parameters::edge_is_constrained_map(constrained));
      PMP::isotropic_remeshing(sm.faces(), L, sm, params.edge_is_constrained_map(constrained).protect_constraints(true));
    } else {
      PMP::isotropic_remeshing(sm.faces(), L, sm, params.edge_is_constrained_map(constrained));
    }
    sm.remove_property_map(constrained);
  }
  TriangleMesh out = from_surface_mesh(sm, mesh.name);
  if (stats) {
    *stats = edge_length_statistics(out);
    stats->input_triangles = mesh.num_triangles();
  }
  return out;
}

}  // namespace arthrosim::common
