// Basic triangle/quad mesh geometry and topology (see mesh.h for conventions).
#include "common/mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <tuple>

#include "common/error.h"

namespace arthrosim::common {

namespace {

// Twice the vector area of triangle t: (b - a) x (c - a). Its norm is 2 * area,
// its direction the normal (right-hand rule on the vertex order).
Vec3 double_area_vector(const TriangleMesh& mesh, int t) {
  const Vec3 a = mesh.V.row(mesh.F(t, 0)).transpose();
  const Vec3 b = mesh.V.row(mesh.F(t, 1)).transpose();
  const Vec3 c = mesh.V.row(mesh.F(t, 2)).transpose();
  return (b - a).cross(c - a);
}

void check_indices(const TriangleMesh& mesh, const char* where) {
  const int n = mesh.num_vertices();
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const int v = mesh.F(t, k);
      if (v < 0 || v >= n) {
        throw InputError(mesh.name.empty() ? std::string("<mesh>") : mesh.name, 0,
                         std::string(where) + ": expected vertex indices in [0, " +
                             std::to_string(n) + "), found " + std::to_string(v) +
                             " in triangle " + std::to_string(t));
      }
    }
  }
}

}  // namespace

Points3 triangle_normals(const TriangleMesh& mesh) {
  Points3 N(mesh.num_triangles(), 3);
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    const Vec3 n = double_area_vector(mesh, t);
    const double len = n.norm();
    // A triangle with zero area has no normal; report a zero row as documented.
    N.row(t) = (len > 0.0 ? Vec3(n / len) : Vec3::Zero()).transpose();
  }
  return N;
}

Eigen::VectorXd triangle_areas(const TriangleMesh& mesh) {
  Eigen::VectorXd A(mesh.num_triangles());
  for (int t = 0; t < mesh.num_triangles(); ++t) A(t) = 0.5 * double_area_vector(mesh, t).norm();
  return A;
}

Points3 triangle_centroids(const TriangleMesh& mesh) {
  Points3 C(mesh.num_triangles(), 3);
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    C.row(t) = (mesh.V.row(mesh.F(t, 0)) + mesh.V.row(mesh.F(t, 1)) + mesh.V.row(mesh.F(t, 2))) / 3.0;
  }
  return C;
}

Points3 quad_vertex_normals(const QuadMesh& mesh) {
  Points3 N = Points3::Zero(mesh.num_nodes(), 3);
  for (int e = 0; e < mesh.num_quads(); ++e) {
    const Eigen::Vector3d d1 = mesh.V.row(mesh.Q(e, 2)) - mesh.V.row(mesh.Q(e, 0));
    const Eigen::Vector3d d2 = mesh.V.row(mesh.Q(e, 3)) - mesh.V.row(mesh.Q(e, 1));
    const Eigen::Vector3d a = 0.5 * d1.cross(d2);
    for (int k = 0; k < 4; ++k) N.row(mesh.Q(e, k)) += a.transpose();
  }
  for (int i = 0; i < N.rows(); ++i) {
    const double l = N.row(i).norm();
    if (l > 0) N.row(i) /= l;
  }
  return N;
}

Points3 vertex_normals(const TriangleMesh& mesh) {
  // Sum of (b-a)x(c-a) over incident triangles = sum of 2 * area * unit normal,
  // i.e. the area-weighted average direction; normalised at the end.
  Points3 N = Points3::Zero(mesh.num_vertices(), 3);
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    const Vec3 n = double_area_vector(mesh, t);
    for (int k = 0; k < 3; ++k) N.row(mesh.F(t, k)) += n.transpose();
  }
  for (int i = 0; i < N.rows(); ++i) {
    const double len = N.row(i).norm();
    if (len > 0.0) N.row(i) /= len;
  }
  return N;
}

double surface_area(const TriangleMesh& mesh) { return triangle_areas(mesh).sum(); }

TriangleMesh triangulate(const QuadMesh& quads) {
  TriangleMesh out;
  out.V = quads.V;
  out.name = quads.name;
  out.F.resize(2 * quads.num_quads(), 3);
  for (int q = 0; q < quads.num_quads(); ++q) {
    out.F.row(2 * q) << quads.Q(q, 0), quads.Q(q, 1), quads.Q(q, 2);
    out.F.row(2 * q + 1) << quads.Q(q, 0), quads.Q(q, 2), quads.Q(q, 3);
  }
  return out;
}

MeshTopology build_topology(const TriangleMesh& mesh) {
  check_indices(mesh, "build_topology");
  const int nt = mesh.num_triangles();
  // All 3*nt undirected edge uses (lo, hi, triangle, local edge k), where local
  // edge k is the edge opposite vertex k. Sorting groups equal edges and gives
  // a deterministic edge order (lexicographic in (lo, hi)).
  std::vector<std::array<int, 4>> uses;
  uses.reserve(3 * static_cast<size_t>(std::max(nt, 0)));
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(t, (k + 1) % 3);
      const int b = mesh.F(t, (k + 2) % 3);
      if (a == b) continue;  // a repeated index is not an edge
      uses.push_back({std::min(a, b), std::max(a, b), t, k});
    }
  }
  std::sort(uses.begin(), uses.end());

  MeshTopology topo;
  topo.triangle_neighbours = Triangles::Constant(nt, 3, -1);
  std::vector<std::array<int, 2>> edges;
  size_t i = 0;
  while (i < uses.size()) {
    size_t j = i;
    while (j < uses.size() && uses[j][0] == uses[i][0] && uses[j][1] == uses[i][1]) ++j;
    edges.push_back({uses[i][0], uses[i][1]});
    std::vector<int> tris;
    for (size_t u = i; u < j; ++u) tris.push_back(uses[u][2]);
    // Neighbours are only well defined across manifold edges (exactly two
    // triangles); across a non-manifold edge (>2) the entry stays -1.
    if (j - i == 2) {
      topo.triangle_neighbours(uses[i][2], uses[i][3]) = uses[i + 1][2];
      topo.triangle_neighbours(uses[i + 1][2], uses[i + 1][3]) = uses[i][2];
    }
    topo.edge_triangles.push_back(std::move(tris));
    i = j;
  }
  topo.edges.resize(static_cast<Eigen::Index>(edges.size()), 2);
  for (size_t e = 0; e < edges.size(); ++e) {
    topo.edges(static_cast<Eigen::Index>(e), 0) = edges[e][0];
    topo.edges(static_cast<Eigen::Index>(e), 1) = edges[e][1];
  }

  topo.vertex_triangles.assign(mesh.num_vertices(), {});
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 3; ++k) {
      auto& list = topo.vertex_triangles[mesh.F(t, k)];
      if (list.empty() || list.back() != t) list.push_back(t);  // repeated index: once
    }
  }

  for (size_t e = 0; e < edges.size(); ++e) {
    if (topo.edge_triangles[e].size() == 1) {
      topo.boundary_vertices.push_back(edges[e][0]);
      topo.boundary_vertices.push_back(edges[e][1]);
    }
  }
  std::sort(topo.boundary_vertices.begin(), topo.boundary_vertices.end());
  topo.boundary_vertices.erase(
      std::unique(topo.boundary_vertices.begin(), topo.boundary_vertices.end()),
      topo.boundary_vertices.end());
  return topo;
}

BoundingBox bounding_box(const Points3& points) {
  BoundingBox box;
  if (points.rows() == 0) return box;
  box.lo = points.colwise().minCoeff().transpose();
  box.hi = points.colwise().maxCoeff().transpose();
  return box;
}

Points3 quad_normals(const QuadMesh& mesh) {
  Points3 N(mesh.num_quads(), 3);
  for (int q = 0; q < mesh.num_quads(); ++q) {
    const Vec3 p = (mesh.V.row(mesh.Q(q, 2)) - mesh.V.row(mesh.Q(q, 0))).transpose();
    const Vec3 r = (mesh.V.row(mesh.Q(q, 3)) - mesh.V.row(mesh.Q(q, 1))).transpose();
    const Vec3 n = p.cross(r);
    const double len = n.norm();
    N.row(q) = (len > 0.0 ? Vec3(n / len) : Vec3::Zero()).transpose();
  }
  return N;
}

Eigen::VectorXd quad_areas(const QuadMesh& mesh) {
  // x(xi, eta) = sum_i N_i x_i with N_i = (1 + xi_i xi)(1 + eta_i eta) / 4 on
  // [-1, 1]^2; area = integral of |x_xi x x_eta|, 2x2 Gauss points +-1/sqrt(3)
  // with unit weights.
  const double g = 1.0 / std::sqrt(3.0);
  const double xi_n[4] = {-1, 1, 1, -1}, eta_n[4] = {-1, -1, 1, 1};
  Eigen::VectorXd A(mesh.num_quads());
  for (int q = 0; q < mesh.num_quads(); ++q) {
    double a = 0.0;
    for (double xi : {-g, g}) {
      for (double eta : {-g, g}) {
        Vec3 dxi = Vec3::Zero(), deta = Vec3::Zero();
        for (int i = 0; i < 4; ++i) {
          const Vec3 x = mesh.V.row(mesh.Q(q, i)).transpose();
          dxi += 0.25 * xi_n[i] * (1.0 + eta_n[i] * eta) * x;
          deta += 0.25 * eta_n[i] * (1.0 + xi_n[i] * xi) * x;
        }
        a += dxi.cross(deta).norm();
      }
    }
    A(q) = a;
  }
  return A;
}

std::vector<int> boundary_nodes(const QuadMesh& mesh) {
  std::vector<std::array<int, 2>> edges;
  edges.reserve(4 * static_cast<size_t>(std::max(mesh.num_quads(), 0)));
  for (int q = 0; q < mesh.num_quads(); ++q) {
    for (int k = 0; k < 4; ++k) {
      const int a = mesh.Q(q, k), b = mesh.Q(q, (k + 1) % 4);
      edges.push_back({std::min(a, b), std::max(a, b)});
    }
  }
  std::sort(edges.begin(), edges.end());
  std::vector<int> nodes;
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i == 1) {
      nodes.push_back(edges[i][0]);
      nodes.push_back(edges[i][1]);
    }
    i = j;
  }
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  return nodes;
}

std::vector<std::vector<int>> boundary_loops(const TriangleMesh& mesh) {
  const MeshTopology topo = build_topology(mesh);
  const std::string label = mesh.name.empty() ? std::string("<mesh>") : mesh.name;
  // Directed boundary edges a -> b as traversed by their single triangle.
  std::vector<int> next(mesh.num_vertices(), -1), incoming(mesh.num_vertices(), 0);
  for (Eigen::Index e = 0; e < topo.edges.rows(); ++e) {
    if (topo.edge_triangles[e].size() != 1) continue;
    const int t = topo.edge_triangles[e][0];
    const int lo = topo.edges(e, 0), hi = topo.edges(e, 1);
    int a = lo, b = hi;
    for (int k = 0; k < 3; ++k) {
      if (mesh.F(t, k) == hi && mesh.F(t, (k + 1) % 3) == lo) {
        a = hi;
        b = lo;
      }
    }
    if (next[a] >= 0) {
      throw InputError(label, 0, "boundary_loops: expected one outgoing boundary edge per boundary vertex, found "
                                 "two at vertex " + std::to_string(a));
    }
    next[a] = b;
    ++incoming[b];
  }
  for (int v = 0; v < mesh.num_vertices(); ++v) {
    if ((next[v] >= 0) != (incoming[v] == 1) || incoming[v] > 1) {
      throw InputError(label, 0, "boundary_loops: expected one incoming and one outgoing boundary edge at vertex " +
                                     std::to_string(v) + ", found " + std::to_string(incoming[v]) + " incoming and " +
                                     (next[v] >= 0 ? "1" : "0") + " outgoing");
    }
  }
  std::vector<std::vector<int>> loops;
  std::vector<char> done(mesh.num_vertices(), 0);
  for (int v = 0; v < mesh.num_vertices(); ++v) {  // ascending: each loop starts at its smallest vertex
    if (next[v] < 0 || done[v]) continue;
    std::vector<int> loop;
    for (int w = v; !done[w]; w = next[w]) {
      done[w] = 1;
      loop.push_back(w);
    }
    loops.push_back(std::move(loop));
  }
  return loops;
}

QuadMesh split_triangles_to_quads(const TriangleMesh& mesh) {
  const MeshTopology topo = build_topology(mesh);
  const int n = mesh.num_vertices();
  const int ne = static_cast<int>(topo.edges.rows());
  const int nt = mesh.num_triangles();

  // Edge index lookup: topo.edges is sorted lexicographically.
  std::vector<std::array<int, 2>> sorted(ne);
  for (int e = 0; e < ne; ++e) sorted[e] = {topo.edges(e, 0), topo.edges(e, 1)};
  auto edge_node = [&](int a, int b) {
    const std::array<int, 2> key{std::min(a, b), std::max(a, b)};
    const auto it = std::lower_bound(sorted.begin(), sorted.end(), key);
    return n + static_cast<int>(it - sorted.begin());
  };

  QuadMesh out;
  out.name = mesh.name;
  out.V.resize(n + ne + nt, 3);
  out.V.topRows(n) = mesh.V;
  for (int e = 0; e < ne; ++e) {
    out.V.row(n + e) = 0.5 * (mesh.V.row(topo.edges(e, 0)) + mesh.V.row(topo.edges(e, 1)));
  }
  out.Q.resize(3 * nt, 4);
  for (int t = 0; t < nt; ++t) {
    const int g = n + ne + t;
    out.V.row(g) = (mesh.V.row(mesh.F(t, 0)) + mesh.V.row(mesh.F(t, 1)) + mesh.V.row(mesh.F(t, 2))) / 3.0;
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(t, k);
      const int b = mesh.F(t, (k + 1) % 3);
      const int c = mesh.F(t, (k + 2) % 3);
      if (a == b || b == c || c == a) {
        throw InputError(mesh.name.empty() ? std::string("<mesh>") : mesh.name, 0,
                         "split_triangles_to_quads: expected three distinct vertices, found "
                         "triangle " + std::to_string(t) + " with a repeated index");
      }
      // Counter-clockwise like (a, b, c): corner, towards b, centre, back from c.
      out.Q.row(3 * t + k) << a, edge_node(a, b), g, edge_node(c, a);
    }
  }
  return out;
}

std::vector<int> connected_components(const TriangleMesh& mesh, int* count) {
  const int nt = mesh.num_triangles();
  check_indices(mesh, "connected_components");
  std::vector<int> parent(nt);
  for (int t = 0; t < nt; ++t) parent[t] = t;
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  const MeshTopology topo = build_topology(mesh);
  for (const auto& tris : topo.edge_triangles)
    for (size_t i = 1; i < tris.size(); ++i) {
      const int a = find(tris[0]), b = find(tris[i]);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  std::vector<int> id(nt, -1), root_id(nt, -1);
  int n = 0;
  for (int t = 0; t < nt; ++t) {
    const int r = find(t);
    if (root_id[r] < 0) root_id[r] = n++;
    id[t] = root_id[r];
  }
  if (count) *count = n;
  return id;
}

TriangleMesh submesh(const TriangleMesh& mesh, const std::vector<int>& triangles) {
  check_indices(mesh, "submesh");
  TriangleMesh out;
  out.name = mesh.name;
  std::vector<int> index(mesh.num_vertices(), -1);
  std::vector<int> order;
  out.F.resize(static_cast<int>(triangles.size()), 3);
  for (size_t j = 0; j < triangles.size(); ++j) {
    const int t = triangles[j];
    if (t < 0 || t >= mesh.num_triangles())
      throw InputError(mesh.name.empty() ? std::string("<mesh>") : mesh.name, 0,
                       "submesh: expected triangle indices in [0, " + std::to_string(mesh.num_triangles()) +
                           "), found " + std::to_string(t));
    for (int k = 0; k < 3; ++k) {
      int& v = index[mesh.F(t, k)];
      if (v < 0) {
        v = static_cast<int>(order.size());
        order.push_back(mesh.F(t, k));
      }
      out.F(static_cast<int>(j), k) = v;
    }
  }
  out.V.resize(static_cast<int>(order.size()), 3);
  for (size_t i = 0; i < order.size(); ++i) out.V.row(static_cast<int>(i)) = mesh.V.row(order[i]);
  return out;
}

TriangleMesh transformed(const TriangleMesh& mesh, const Eigen::Isometry3d& X) {
  TriangleMesh out = mesh;
  out.V = (mesh.V * X.linear().transpose()).rowwise() + X.translation().transpose();
  return out;
}

QuadMesh transformed(const QuadMesh& mesh, const Eigen::Isometry3d& X) {
  QuadMesh out = mesh;
  out.V = (mesh.V * X.linear().transpose()).rowwise() + X.translation().transpose();
  return out;
}

}  // namespace arthrosim::common
