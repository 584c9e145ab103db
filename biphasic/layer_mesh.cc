#include "biphasic/layer_mesh.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>
#include <utility>

#include "biphasic/hex_basis.h"
#include "common/error.h"

namespace arthrosim::biphasic {
namespace {

std::string where(const common::QuadMesh& surface) {
  return "layer '" + (surface.name.empty() ? std::string("(unnamed)") : surface.name) + "'";
}

// In-plane 3 x 3 grid (i, j) of a quad's biquadratic nodes as surface
// entities: corners, side midpoints, centre.
std::array<int, 9> quad_entities(const LayerMesh& m, int q) {
  const auto c = m.surface.Q.row(q);
  const auto e = m.quad_edges.row(q);
  std::array<int, 9> g{};
  g[0 * 3 + 0] = m.vertex_entity(c[0]);
  g[0 * 3 + 1] = m.edge_entity(e[0]);
  g[0 * 3 + 2] = m.vertex_entity(c[1]);
  g[1 * 3 + 2] = m.edge_entity(e[1]);
  g[2 * 3 + 2] = m.vertex_entity(c[2]);
  g[2 * 3 + 1] = m.edge_entity(e[2]);
  g[2 * 3 + 0] = m.vertex_entity(c[3]);
  g[1 * 3 + 0] = m.edge_entity(e[3]);
  g[1 * 3 + 1] = m.quad_entity(q);
  return g;
}

}  // namespace

void validate_surface_data(const common::QuadMesh& surface, const common::Points3& normals,
                           const Eigen::VectorXd& thickness) {
  const std::string w = where(surface);
  const int nv = surface.num_nodes();
  if (surface.num_quads() == 0) throw common::InputError(w + ": expected at least one surface quad, found none");
  if (normals.rows() != nv || thickness.size() != nv) {
    std::ostringstream s;
    s << w << ": expected one normal and one thickness per surface node (" << nv << "), found "
      << normals.rows() << " normals and " << thickness.size() << " thicknesses";
    throw common::InputError(s.str());
  }
  for (int v = 0; v < nv; ++v) {
    const double h = thickness[v];
    if (!std::isfinite(h) || h <= 0.0) {
      std::ostringstream s;
      s << w << ": surface node " << v << ": expected a thickness > 0 m, found " << h << " m";
      throw common::InputError(s.str());
    }
    const double len = normals.row(v).norm();
    if (!std::isfinite(len) || len < 1e-12) {
      std::ostringstream s;
      s << w << ": surface node " << v << ": expected a non-zero finite normal, found (" << normals(v, 0) << ", "
        << normals(v, 1) << ", " << normals(v, 2) << ")";
      throw common::InputError(s.str());
    }
    if (!surface.V.row(v).allFinite()) {
      throw common::InputError(w + ": surface node " + std::to_string(v) + ": expected finite coordinates");
    }
  }
  for (int q = 0; q < surface.num_quads(); ++q) {
    for (int k = 0; k < 4; ++k) {
      const int a = surface.Q(q, k);
      if (a < 0 || a >= nv) {
        std::ostringstream s;
        s << w << ": quad " << q << ": expected node indices in [0, " << nv << "), found " << a;
        throw common::InputError(s.str());
      }
    }
  }
}

LayerMesh extrude_layer(const common::QuadMesh& surface, const common::Points3& normals,
                        const Eigen::VectorXd& thickness, int layers,
                        const std::vector<double>& level_fractions) {
  const std::string w = where(surface);
  const int nv = surface.num_nodes();
  const int nq = surface.num_quads();
  if (layers < 1) {
    throw common::InputError(w + ": expected at least 1 element layer through the thickness, found " +
                             std::to_string(layers));
  }
  validate_surface_data(surface, normals, thickness);
  LayerMesh m;
  m.name = surface.name;
  m.layers = layers;
  if (level_fractions.empty()) {
    for (int L = 0; L <= layers; ++L) m.levels.push_back(static_cast<double>(L) / layers);
  } else {
    bool ok = static_cast<int>(level_fractions.size()) == layers + 1 && level_fractions.front() == 0.0 &&
              level_fractions.back() == 1.0;
    for (size_t L = 1; ok && L < level_fractions.size(); ++L) ok = level_fractions[L] > level_fractions[L - 1];
    if (!ok) {
      throw common::InputError(w + ": expected " + std::to_string(layers + 1) +
                               " strictly increasing level fractions from 0 to 1");
    }
    m.levels = level_fractions;
  }
  m.surface = surface;
  m.normals = normals;
  m.thickness = thickness;
  for (int v = 0; v < nv; ++v) m.normals.row(v) /= normals.row(v).norm();

  // Unique edges and the quad -> edge map.
  std::map<std::pair<int, int>, int> edge_index;
  std::vector<std::pair<int, int>> edge_list;
  std::vector<int> edge_uses;
  m.quad_edges.resize(nq, 4);
  for (int q = 0; q < nq; ++q) {
    for (int k = 0; k < 4; ++k) {
      const int a = surface.Q(q, k);
      const int b = surface.Q(q, (k + 1) % 4);
      if (a < 0 || a >= nv || b < 0 || b >= nv) {
        std::ostringstream s;
        s << w << ": quad " << q << ": expected node indices in [0, " << nv << "), found " << a
          << ", " << b;
        throw common::InputError(s.str());
      }
      const auto key = std::minmax(a, b);
      auto [it, inserted] = edge_index.emplace(key, static_cast<int>(edge_list.size()));
      if (inserted) {
        edge_list.push_back(key);
        edge_uses.push_back(0);
      }
      ++edge_uses[it->second];
      m.quad_edges(q, k) = it->second;
    }
  }
  const int ne = static_cast<int>(edge_list.size());
  m.edges.resize(ne, 2);
  for (int e = 0; e < ne; ++e) m.edges.row(e) << edge_list[e].first, edge_list[e].second;
  std::vector<char> on_outline(nv, 0);
  for (int e = 0; e < ne; ++e) {
    if (edge_uses[e] == 1) {
      m.periphery_edges.push_back(e);
      on_outline[edge_list[e].first] = on_outline[edge_list[e].second] = 1;
    }
  }
  for (int v = 0; v < nv; ++v)
    if (on_outline[v]) m.periphery_vertices.push_back(v);

  // Positions. Bone point b_v = x_v - h_v n_v; level s: b_v + s h_v n_v.
  common::Points3 bone(nv, 3), offset(nv, 3);
  for (int v = 0; v < nv; ++v) {
    offset.row(v) = thickness[v] * m.normals.row(v);
    bone.row(v) = surface.V.row(v) - offset.row(v);
  }
  const int N = layers;
  m.q1_nodes.resize(nv * (N + 1), 3);
  for (int v = 0; v < nv; ++v)
    for (int L = 0; L <= N; ++L)
      m.q1_nodes.row(m.q1_node(v, L)) = bone.row(v) + m.levels[L] * offset.row(v);

  const int n_entities = nv + ne + nq;
  m.q2_nodes.resize(static_cast<Eigen::Index>(n_entities) * (2 * N + 1), 3);
  auto place = [&](int entity, const std::vector<int>& verts) {
    for (int l = 0; l <= 2 * N; ++l) {
      const double s = l % 2 == 0 ? m.levels[l / 2] : 0.5 * (m.levels[l / 2] + m.levels[l / 2 + 1]);
      Eigen::RowVector3d p = Eigen::RowVector3d::Zero();
      for (int v : verts) p += bone.row(v) + s * offset.row(v);
      m.q2_nodes.row(m.q2_node(entity, l)) = p / static_cast<double>(verts.size());
    }
  };
  for (int v = 0; v < nv; ++v) place(m.vertex_entity(v), {v});
  for (int e = 0; e < ne; ++e) place(m.edge_entity(e), {edge_list[e].first, edge_list[e].second});
  for (int q = 0; q < nq; ++q)
    place(m.quad_entity(q), {surface.Q(q, 0), surface.Q(q, 1), surface.Q(q, 2), surface.Q(q, 3)});

  // Connectivity.
  m.hex_q1.resize(static_cast<Eigen::Index>(nq) * N, 8);
  m.hex_q2.resize(static_cast<Eigen::Index>(nq) * N, 27);
  static constexpr int kCorner[2][2] = {{0, 3}, {1, 2}};  // [i][j] -> quad corner
  for (int q = 0; q < nq; ++q) {
    const auto ent = quad_entities(m, q);
    for (int L = 0; L < N; ++L) {
      const int el = m.element(q, L);
      for (int k = 0; k < 2; ++k)
        for (int j = 0; j < 2; ++j)
          for (int i = 0; i < 2; ++i)
            m.hex_q1(el, (k * 2 + j) * 2 + i) = m.q1_node(surface.Q(q, kCorner[i][j]), L + k);
      for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j)
          for (int i = 0; i < 3; ++i)
            m.hex_q2(el, (k * 3 + j) * 3 + i) = m.q2_node(ent[j * 3 + i], 2 * L + k);
    }
  }

  // Jacobian check at the element corners.
  Eigen::VectorXd N1;
  Eigen::MatrixXd dN1;
  for (int el = 0; el < m.num_elements(); ++el) {
    const Eigen::Matrix<double, 8, 3> X = element_corners(m, el);
    for (int c = 0; c < 8; ++c) {
      const Eigen::Vector3d xi(c & 1 ? 1.0 : -1.0, c & 2 ? 1.0 : -1.0, c & 4 ? 1.0 : -1.0);
      hex_basis(1, xi, &N1, &dN1);
      const Eigen::Matrix3d J = X.transpose() * dN1;  // dx/dxi
      const double det = J.determinant();
      const double scale = J.col(0).norm() * J.col(1).norm() * J.col(2).norm();
      if (!(det > 1e-9 * scale)) {
        std::ostringstream s;
        s << w << ": element of surface quad " << el / N << ", layer " << el % N
          << ": expected a positive volume Jacobian at every corner, found " << det
          << " at corner " << c
          << " (thickness too large for the surface curvature, or an inverted quad)";
        throw common::InputError(s.str());
      }
    }
  }
  return m;
}

namespace {

// True when the one-layer element of quad q has positive Jacobians at its 8
// corners (same test as extrude_layer).
bool quad_element_valid(const common::QuadMesh& s, const common::Points3& n, const Eigen::VectorXd& h, int q) {
  static constexpr int kCorner[2][2] = {{0, 3}, {1, 2}};
  Eigen::Matrix<double, 8, 3> X;
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) {
        const int v = s.Q(q, kCorner[i][j]);
        const Eigen::RowVector3d nv = n.row(v).normalized();
        X.row((k * 2 + j) * 2 + i) = s.V.row(v) - (k == 0 ? h[v] : 0.0) * nv;
      }
  Eigen::VectorXd N1;
  Eigen::MatrixXd dN1;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d xi(c & 1 ? 1.0 : -1.0, c & 2 ? 1.0 : -1.0, c & 4 ? 1.0 : -1.0);
    hex_basis(1, xi, &N1, &dN1);
    const Eigen::Matrix3d J = X.transpose() * dN1;
    const double scale = J.col(0).norm() * J.col(1).norm() * J.col(2).norm();
    if (!(J.determinant() > 1e-9 * scale)) return false;
  }
  return true;
}

}  // namespace

std::vector<int> untangle_normals(const common::QuadMesh& s, common::Points3* normals, const Eigen::VectorXd& h,
                                  int max_rounds) {
  const int nv = s.num_nodes(), nq = s.num_quads();
  // Quad normals (bilinear centre normal) and the quads around each vertex.
  common::Points3 qn(nq, 3);
  std::vector<std::vector<int>> around(nv);
  for (int q = 0; q < nq; ++q) {
    const Eigen::Vector3d d1 = (s.V.row(s.Q(q, 2)) - s.V.row(s.Q(q, 0))).transpose();
    const Eigen::Vector3d d2 = (s.V.row(s.Q(q, 3)) - s.V.row(s.Q(q, 1))).transpose();
    qn.row(q) = d1.cross(d2).normalized().transpose();
    for (int k = 0; k < 4; ++k) around[s.Q(q, k)].push_back(q);
  }
  std::vector<char> changed(nv, 0);
  for (int round = 0; round <= max_rounds; ++round) {
    std::vector<int> bad;
    for (int q = 0; q < nq; ++q)
      if (!quad_element_valid(s, *normals, h, q)) bad.push_back(q);
    if (bad.empty()) break;
    if (round == max_rounds) {
      std::ostringstream m;
      m << "layer '" << s.name << "': " << bad.size() << " quads (first " << bad.front()
        << ") still fold at the bone side after " << max_rounds
        << " rounds of normal smoothing: the thickness is too large for the surface curvature there";
      throw common::InputError(m.str());
    }
    // Average over the quads around, then (later rounds) over the neighbours'
    // current normals as well, so the smoothing spreads.
    common::Points3 next = *normals;
    for (int q : bad) {
      for (int k = 0; k < 4; ++k) {
        const int v = s.Q(q, k);
        Eigen::RowVector3d avg = Eigen::RowVector3d::Zero();
        for (int r : around[v]) {
          avg += qn.row(r);
          for (int j = 0; j < 4; ++j) avg += normals->row(s.Q(r, j)).normalized();
        }
        next.row(v) = avg.normalized();
        changed[v] = 1;
      }
    }
    *normals = next;
  }
  std::vector<int> out;
  for (int v = 0; v < nv; ++v)
    if (changed[v]) out.push_back(v);
  return out;
}

Eigen::Matrix<double, 8, 3> element_corners(const LayerMesh& mesh, int element) {
  Eigen::Matrix<double, 8, 3> X;
  for (int a = 0; a < 8; ++a) X.row(a) = mesh.q1_nodes.row(mesh.hex_q1(element, a));
  return X;
}

std::vector<int> LayerMesh::bone_nodes(int order) const {
  std::vector<int> out;
  if (order == 1) {
    for (int v = 0; v < num_vertices(); ++v) out.push_back(q1_node(v, 0));
  } else {
    const int n_entities = num_vertices() + num_edges() + num_quads();
    for (int e = 0; e < n_entities; ++e) out.push_back(q2_node(e, 0));
  }
  return out;
}

std::vector<int> LayerMesh::articular_nodes(int order) const {
  std::vector<int> out;
  if (order == 1) {
    for (int v = 0; v < num_vertices(); ++v) out.push_back(q1_node(v, layers));
  } else {
    const int n_entities = num_vertices() + num_edges() + num_quads();
    for (int e = 0; e < n_entities; ++e) out.push_back(q2_node(e, 2 * layers));
  }
  return out;
}

std::vector<int> LayerMesh::periphery_nodes(int order) const {
  std::vector<int> out;
  if (order == 1) {
    for (int v : periphery_vertices)
      for (int L = 0; L <= layers; ++L) out.push_back(q1_node(v, L));
  } else {
    for (int v : periphery_vertices)
      for (int l = 0; l <= 2 * layers; ++l) out.push_back(q2_node(vertex_entity(v), l));
    for (int e : periphery_edges)
      for (int l = 0; l <= 2 * layers; ++l) out.push_back(q2_node(edge_entity(e), l));
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<double> graded_levels(int layers, double ratio) {
  // Heights from the surface down: 1, r, r^2, ...; levels counted from the bone.
  std::vector<double> height(layers);
  double total = 0.0;
  for (int k = 0; k < layers; ++k) total += (height[k] = std::pow(ratio, k));
  std::vector<double> levels(layers + 1, 0.0);
  double s = 0.0;
  for (int L = 1; L < layers; ++L) {
    s += height[layers - L] / total;  // element L - 1 counted from the bone is surface element layers - L
    levels[L] = s;
  }
  levels[layers] = 1.0;
  return levels;
}

Eigen::VectorXd articular_node_areas(const LayerMesh& mesh) { return surface_node_areas(mesh.surface); }

Eigen::VectorXd surface_node_areas(const common::QuadMesh& surface) {
  Eigen::VectorXd area = Eigen::VectorXd::Zero(surface.num_nodes());
  const QuadratureRule rule = quad_rule(2);
  Eigen::VectorXd N;
  Eigen::MatrixXd dN;
  static constexpr int kLocal[4] = {0, 1, 3, 2};  // quad corner -> bilinear basis index
  for (int q = 0; q < surface.num_quads(); ++q) {
    Eigen::Matrix<double, 4, 3> X;
    for (int k = 0; k < 4; ++k) X.row(kLocal[k]) = surface.V.row(surface.Q(q, k));
    for (size_t g = 0; g < rule.points.size(); ++g) {
      quad_basis(1, rule.points[g][0], rule.points[g][1], &N, &dN);
      const Eigen::Vector3d t1 = X.transpose() * dN.col(0);
      const Eigen::Vector3d t2 = X.transpose() * dN.col(1);
      const double dA = t1.cross(t2).norm() * rule.weights[g];
      for (int k = 0; k < 4; ++k) area[surface.Q(q, k)] += N[kLocal[k]] * dA;
    }
  }
  return area;
}

double layer_volume(const LayerMesh& mesh) {
  const QuadratureRule rule = hex_rule(2);
  Eigen::VectorXd N;
  Eigen::MatrixXd dN;
  double volume = 0.0;
  for (int el = 0; el < mesh.num_elements(); ++el) {
    const Eigen::Matrix<double, 8, 3> X = element_corners(mesh, el);
    for (size_t g = 0; g < rule.points.size(); ++g) {
      hex_basis(1, rule.points[g], &N, &dN);
      volume += (X.transpose() * dN).determinant() * rule.weights[g];
    }
  }
  return volume;
}

}  // namespace arthrosim::biphasic
