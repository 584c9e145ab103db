// Mesh validation and safe repairs (see mesh_validation.h).
#include "common/mesh_validation.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <numeric>
#include <queue>
#include <sstream>
#include <unordered_map>

#include "common/error.h"

namespace arthrosim::common {

namespace {

void note(IndexIssues* issue, int index, int max_examples) {
  ++issue->count;
  if (static_cast<int>(issue->first.size()) < max_examples) issue->first.push_back(index);
}

void note(EdgeIssues* issue, int a, int b, int max_examples) {
  ++issue->count;
  if (static_cast<int>(issue->first.size()) < max_examples) issue->first.push_back({a, b});
}

bool has_valid_indices(const TriangleMesh& m, int t) {
  const int n = m.num_vertices();
  for (int k = 0; k < 3; ++k)
    if (m.F(t, k) < 0 || m.F(t, k) >= n) return false;
  return true;
}

bool has_repeated_index(const TriangleMesh& m, int t) {
  return m.F(t, 0) == m.F(t, 1) || m.F(t, 1) == m.F(t, 2) || m.F(t, 2) == m.F(t, 0);
}

// Scale-free degeneracy test: 2 * area <= tol * (longest edge)^2, i.e. the
// height over the longest edge is below tol times its length. Assumes finite
// coordinates and distinct indices.
bool is_sliver(const TriangleMesh& m, int t, double tol) {
  const Vec3 a = m.vertex(m.F(t, 0)), b = m.vertex(m.F(t, 1)), c = m.vertex(m.F(t, 2));
  const double l2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  const double twice_area = (b - a).cross(c - a).norm();
  return twice_area <= tol * l2;
}

std::array<int, 3> sorted_triple(const TriangleMesh& m, int t) {
  std::array<int, 3> s{m.F(t, 0), m.F(t, 1), m.F(t, 2)};
  std::sort(s.begin(), s.end());
  return s;
}

// Directed edge uses of the triangles in `use`: (lo, hi, triangle, +1 if the
// triangle runs lo->hi, -1 if hi->lo, local edge k = edge from vertex k to k+1).
struct EdgeUse {
  int lo, hi, tri, dir, k;
  bool operator<(const EdgeUse& o) const {
    return std::tie(lo, hi, tri, k) < std::tie(o.lo, o.hi, o.tri, o.k);
  }
};

std::vector<EdgeUse> edge_uses(const TriangleMesh& m, const std::vector<char>& use) {
  std::vector<EdgeUse> uses;
  for (int t = 0; t < m.num_triangles(); ++t) {
    if (!use[t]) continue;
    for (int k = 0; k < 3; ++k) {
      const int a = m.F(t, k), b = m.F(t, (k + 1) % 3);
      uses.push_back({std::min(a, b), std::max(a, b), t, a < b ? 1 : -1, k});
    }
  }
  std::sort(uses.begin(), uses.end());
  return uses;
}

std::string list_indices(const std::vector<int>& v, int count) {
  std::ostringstream s;
  for (size_t i = 0; i < v.size(); ++i) s << (i ? ", " : "") << v[i];
  if (count > static_cast<int>(v.size())) s << ", ...";
  return s.str();
}

std::string list_edges(const std::vector<std::array<int, 2>>& v, int count) {
  std::ostringstream s;
  for (size_t i = 0; i < v.size(); ++i) s << (i ? ", " : "") << "(" << v[i][0] << "," << v[i][1] << ")";
  if (count > static_cast<int>(v.size())) s << ", ...";
  return s.str();
}

}  // namespace

bool ValidationReport::ok() const {
  return invalid_index_triangles.count == 0 && non_finite_vertices.count == 0 && degenerate_triangles.count == 0 &&
         duplicate_triangles.count == 0 && non_manifold_edges.count == 0 && inconsistent_edges.count == 0 &&
         (!require_closed || boundary_edges.count == 0);
}

bool ValidationReport::has_warnings() const {
  return unreferenced_vertices.count > 0 || non_manifold_vertices.count > 0 ||
         (!require_closed && boundary_edges.count > 0);
}

std::string ValidationReport::summary() const {
  std::ostringstream s;
  s << "mesh '" << mesh_name << "': " << num_vertices << " vertices, " << num_triangles << " triangles";
  auto line = [&](bool error, int count, const std::string& what, const std::string& first) {
    if (count == 0) return;
    s << "\n  " << (error ? "error: " : "warning: ") << count << " " << what << ", first: " << first;
  };
  line(true, invalid_index_triangles.count, "triangles with a vertex index outside [0, " + std::to_string(num_vertices) + ")",
       "triangles " + list_indices(invalid_index_triangles.first, invalid_index_triangles.count));
  line(true, non_finite_vertices.count, "vertices with NaN/Inf coordinates",
       "vertices " + list_indices(non_finite_vertices.first, non_finite_vertices.count));
  line(true, degenerate_triangles.count, "degenerate triangles (repeated vertex or (near-)zero area)",
       "triangles " + list_indices(degenerate_triangles.first, degenerate_triangles.count));
  line(true, duplicate_triangles.count, "duplicate triangles (same vertices as an earlier triangle)",
       "triangles " + list_indices(duplicate_triangles.first, duplicate_triangles.count));
  line(true, non_manifold_edges.count, "non-manifold edges (shared by more than 2 triangles)",
       "edges " + list_edges(non_manifold_edges.first, non_manifold_edges.count));
  line(true, inconsistent_edges.count, "edges with inconsistent orientation (same direction in both triangles)",
       "edges " + list_edges(inconsistent_edges.first, inconsistent_edges.count));
  line(require_closed, boundary_edges.count,
       require_closed ? "open boundary edges (a closed surface is required)" : "open boundary edges",
       "edges " + list_edges(boundary_edges.first, boundary_edges.count));
  line(false, unreferenced_vertices.count, "unreferenced vertices",
       "vertices " + list_indices(unreferenced_vertices.first, unreferenced_vertices.count));
  line(false, non_manifold_vertices.count, "non-manifold vertices (more than one fan of triangles)",
       "vertices " + list_indices(non_manifold_vertices.first, non_manifold_vertices.count));
  if (ok() && !has_warnings()) s << "\n  no problems found";
  return s.str();
}

ValidationReport validate(const TriangleMesh& mesh, const ValidationOptions& options) {
  ValidationReport r;
  r.mesh_name = mesh.name.empty() ? "<mesh>" : mesh.name;
  r.num_vertices = mesh.num_vertices();
  r.num_triangles = mesh.num_triangles();
  r.require_closed = options.require_closed;
  const int max_ex = std::max(0, options.max_examples);
  const int nt = mesh.num_triangles();
  const int nv = mesh.num_vertices();

  std::vector<char> finite(nv, 1);
  for (int i = 0; i < nv; ++i) {
    if (!mesh.V.row(i).allFinite()) {
      finite[i] = 0;
      note(&r.non_finite_vertices, i, max_ex);
    }
  }

  // Triangles usable for topology: valid indices, three distinct vertices.
  std::vector<char> topo(nt, 0);
  std::vector<char> referenced(nv, 0);
  for (int t = 0; t < nt; ++t) {
    if (!has_valid_indices(mesh, t)) {
      note(&r.invalid_index_triangles, t, max_ex);
      continue;
    }
    for (int k = 0; k < 3; ++k) referenced[mesh.F(t, k)] = 1;
    if (has_repeated_index(mesh, t)) {
      note(&r.degenerate_triangles, t, max_ex);
      continue;
    }
    topo[t] = 1;
    const bool all_finite = finite[mesh.F(t, 0)] && finite[mesh.F(t, 1)] && finite[mesh.F(t, 2)];
    if (all_finite && is_sliver(mesh, t, options.degenerate_relative_tolerance)) {
      note(&r.degenerate_triangles, t, max_ex);
    }
  }

  // Duplicates: same vertex set as an earlier triangle (in index order).
  {
    std::map<std::array<int, 3>, int> seen;
    for (int t = 0; t < nt; ++t) {
      if (!topo[t]) continue;
      if (!seen.emplace(sorted_triple(mesh, t), t).second) note(&r.duplicate_triangles, t, max_ex);
    }
  }

  // Edges.
  const std::vector<EdgeUse> uses = edge_uses(mesh, topo);
  for (size_t i = 0; i < uses.size();) {
    size_t j = i;
    while (j < uses.size() && uses[j].lo == uses[i].lo && uses[j].hi == uses[i].hi) ++j;
    const size_t n = j - i;
    if (n == 1) {
      note(&r.boundary_edges, uses[i].lo, uses[i].hi, max_ex);
    } else if (n == 2) {
      if (uses[i].dir == uses[i + 1].dir) note(&r.inconsistent_edges, uses[i].lo, uses[i].hi, max_ex);
    } else {
      note(&r.non_manifold_edges, uses[i].lo, uses[i].hi, max_ex);
    }
    i = j;
  }

  for (int i = 0; i < nv; ++i)
    if (!referenced[i]) note(&r.unreferenced_vertices, i, max_ex);

  // Non-manifold vertices: per vertex v, group its triangles into fans joined
  // through the edges at v (union-find restricted to v's triangles); more than
  // one fan is a non-manifold vertex.
  {
    std::vector<std::vector<int>> vt(nv);
    for (int t = 0; t < nt; ++t)
      if (topo[t])
        for (int k = 0; k < 3; ++k) vt[mesh.F(t, k)].push_back(t);
    std::vector<int> parent(nt);
    std::iota(parent.begin(), parent.end(), 0);
    auto find = [&](int x) {
      while (parent[x] != x) x = parent[x] = parent[parent[x]];
      return x;
    };
    for (int v = 0; v < nv; ++v) {
      const auto& tris = vt[v];
      if (tris.size() < 2) continue;
      for (int t : tris) parent[t] = t;
      // Triangles of v keyed by their other vertices: two triangles of v that
      // share another vertex w share the edge (v, w).
      std::vector<std::pair<int, int>> other;  // (w, triangle)
      for (int t : tris)
        for (int k = 0; k < 3; ++k)
          if (mesh.F(t, k) != v) other.push_back({mesh.F(t, k), t});
      std::sort(other.begin(), other.end());
      for (size_t i = 1; i < other.size(); ++i)
        if (other[i].first == other[i - 1].first) parent[find(other[i].second)] = find(other[i - 1].second);
      const int root = find(tris[0]);
      bool one_fan = true;
      for (int t : tris) one_fan = one_fan && find(t) == root;
      if (!one_fan) note(&r.non_manifold_vertices, v, max_ex);
    }
  }
  return r;
}

void throw_if_invalid(const ValidationReport& report, const std::string& source) {
  if (report.ok()) return;
  throw InputError(source.empty() ? report.mesh_name : source, 0,
                   "expected a valid triangle mesh, found problems:\n" + report.summary());
}

ValidationReport validate_or_throw(const TriangleMesh& mesh, const ValidationOptions& options,
                                   const std::string& source) {
  ValidationReport r = validate(mesh, options);
  throw_if_invalid(r, source);
  return r;
}

// ------------------------------------------------------------ unit check --

void check_plausible_extent(const TriangleMesh& mesh, LengthUnit declared, const std::string& source,
                            const ExtentLimits& limits) {
  const int n = mesh.num_vertices();
  if (n == 0) return;
  auto largest_side = [](const BoundingBox& b) { return b.empty() ? 0.0 : b.size().maxCoeff(); };
  const double extent = largest_side(bounding_box(mesh.V));
  if (extent >= limits.min && extent <= limits.max) return;
  const double to_file = 1.0 / metres_per_unit(declared);  // metres -> numbers in the file
  const std::string u = unit_name(declared);
  auto num = [](double v) {
    std::ostringstream s;
    s.precision(4);
    s << v;
    return s.str();
  };
  std::ostringstream msg;
  msg << "expected a knee surface whose largest extent is " << num(limits.min * to_file) << " to "
      << num(limits.max * to_file) << " " << u;
  if (declared != LengthUnit::kMillimetre) msg << " (" << num(limits.min * 1e3) << " to " << num(limits.max * 1e3) << " mm)";
  msg << " in the declared unit " << u << ", found " << num(extent * to_file) << " " << u;
  // Far vertices: distance from the per-axis median vertex.
  Vec3 median;
  for (int k = 0; k < 3; ++k) {
    std::vector<double> c(mesh.V.col(k).data(), mesh.V.col(k).data() + n);
    std::nth_element(c.begin(), c.begin() + n / 2, c.end());
    median[k] = c[n / 2];
  }
  std::vector<double> dist(n);
  for (int i = 0; i < n; ++i) dist[i] = (mesh.vertex(i) - median).norm();
  std::vector<double> sorted = dist;
  const int q = std::min(n - 1, static_cast<int>(0.9 * n));
  std::nth_element(sorted.begin(), sorted.begin() + q, sorted.end());
  const double q90 = sorted[q];
  std::vector<int> far;
  Points3 rest(n, 3);
  int kept = 0;
  for (int i = 0; i < n; ++i) {
    if (dist[i] > 10.0 * q90 && std::isfinite(dist[i])) {
      far.push_back(i);
    } else {
      rest.row(kept++) = mesh.V.row(i);
    }
  }
  rest.conservativeResize(kept, 3);
  const double rest_extent = largest_side(bounding_box(rest));
  if (!far.empty() && static_cast<double>(far.size()) <= 0.01 * n && rest_extent >= limits.min &&
      rest_extent <= limits.max) {
    const Vec3 p = mesh.vertex(far[0]) * to_file;
    msg << ": " << far.size() << " vertex" << (far.size() > 1 ? "es lie" : " lies")
        << " far from all others (vertex " << far[0] << " at (" << num(p.x()) << ", " << num(p.y()) << ", "
        << num(p.z()) << ") " << u << ", " << num(dist[far[0]] * to_file) << " " << u
        << " from the median vertex, while 90 % of the vertices lie within " << num(q90 * to_file) << " " << u
        << "; without them the extent is " << num(rest_extent * to_file) << " " << u
        << "): a corrupted coordinate?";
    throw InputError(source, 0, msg.str());
  }
  struct Candidate {
    const char* name;
    double metres;
    bool readable;
  };
  const Candidate candidates[] = {{"um (micrometres)", 1e-6, false}, {"mm", 1e-3, true}, {"cm", 1e-2, true},
                                  {"m", 1.0, true},                  {"inch", 0.0254, false}};
  std::string likely;
  for (const Candidate& c : candidates) {
    if (c.metres == metres_per_unit(declared)) continue;
    const double e = extent * to_file * c.metres;
    if (e >= limits.min && e <= limits.max) {
      likely += std::string(likely.empty() ? "" : "; or ") + c.name + " (its extent would be " + num(e * 1e3) +
                " mm" + (c.readable ? "" : ", convert the file: arthrosim reads mm, cm and m") + ")";
    }
  }
  if (!likely.empty()) {
    msg << ": likely unit " << likely;
  } else {
    msg << ": no unit makes it plausible (" << (extent < limits.min ? "too small" : "too large")
        << " in every one of um, mm, cm, m, inch)";
  }
  throw InputError(source, 0, msg.str());
}

// ------------------------------------------------------------------ repair --

bool RepairReport::changed() const {
  return merged_vertices > 0 || removed_degenerate > 0 || removed_duplicate > 0 || removed_unreferenced > 0 ||
         flipped_triangles > 0;
}

std::string RepairReport::summary() const {
  std::ostringstream s;
  if (merged_vertices) s << "merged " << merged_vertices << " duplicate vertices\n";
  if (removed_degenerate) s << "removed " << removed_degenerate << " degenerate triangles\n";
  if (removed_duplicate) s << "removed " << removed_duplicate << " duplicate triangles\n";
  if (removed_unreferenced) s << "removed " << removed_unreferenced << " unreferenced vertices\n";
  if (flipped_triangles) s << "flipped " << flipped_triangles << " triangles to make the orientation consistent\n";
  if (unorientable_components)
    s << "left " << unorientable_components << " non-orientable components unchanged\n";
  if (!changed() && !unorientable_components) s << "no repair needed\n";
  std::string out = s.str();
  out.pop_back();
  return out;
}

namespace {

// Greedy vertex merging: in index order, a vertex joins the lowest-index
// earlier representative within `tol` (Euclidean), else becomes one. No
// chaining (a vertex is compared with representatives only), deterministic.
// Non-finite vertices are never merged.
std::vector<int> merge_vertices(const Points3& V, double tol) {
  const int n = static_cast<int>(V.rows());
  std::vector<int> rep(n);
  std::iota(rep.begin(), rep.end(), 0);
  if (tol <= 0.0) {
    std::map<std::array<double, 3>, int> exact;
    for (int i = 0; i < n; ++i) {
      if (!V.row(i).allFinite()) continue;
      const std::array<double, 3> key{V(i, 0) + 0.0, V(i, 1) + 0.0, V(i, 2) + 0.0};
      const auto [it, inserted] = exact.emplace(key, i);
      if (!inserted) rep[i] = it->second;
    }
    return rep;
  }
  // Grid of cells at least `tol` wide (so vertices within tol lie in the
  // same or adjacent cells), indexed from the lower corner of the finite
  // vertices. The cell is widened when the extent would need more than 2^40
  // cells per axis, so every index is a non-negative integer far below the
  // int64 range (no overflow for any finite coordinate; a coordinate so large
  // that x - lo overflows is clamped into the last cell, where candidates are
  // still compared by their true distance). Hashing in unsigned arithmetic.
  constexpr double kMaxCells = 1099511627776.0;  // 2^40
  Vec3 lo = Vec3::Constant(INFINITY), hi = Vec3::Constant(-INFINITY);
  for (int i = 0; i < n; ++i) {
    if (!V.row(i).allFinite()) continue;
    lo = lo.cwiseMin(V.row(i).transpose());
    hi = hi.cwiseMax(V.row(i).transpose());
  }
  double span = 0.0;
  for (int k = 0; k < 3; ++k)
    if (hi[k] >= lo[k]) span = std::max(span, hi[k] - lo[k]);  // inf if the extent overflows
  const double cell = std::isfinite(span) ? std::max(tol, span / kMaxCells) : std::numeric_limits<double>::max();
  auto index = [&](double x, int k) -> int64_t {
    const double r = std::floor((x - lo[k]) / cell);
    if (!(r >= 0.0)) return 0;  // NaN from inf - inf as well
    return r >= kMaxCells ? static_cast<int64_t>(kMaxCells) : static_cast<int64_t>(r);
  };
  using Cell = std::array<int64_t, 3>;
  struct CellHash {
    size_t operator()(const Cell& c) const {
      return static_cast<size_t>(static_cast<uint64_t>(c[0]) * 73856093ULL ^ static_cast<uint64_t>(c[1]) * 19349663ULL ^
                                 static_cast<uint64_t>(c[2]) * 83492791ULL);
    }
  };
  std::unordered_map<Cell, std::vector<int>, CellHash> grid;
  const double tol2 = tol * tol;
  for (int i = 0; i < n; ++i) {
    if (!V.row(i).allFinite()) continue;
    const Cell c{index(V(i, 0), 0), index(V(i, 1), 1), index(V(i, 2), 2)};
    int best = -1;
    for (int64_t dx = -1; dx <= 1; ++dx)
      for (int64_t dy = -1; dy <= 1; ++dy)
        for (int64_t dz = -1; dz <= 1; ++dz) {
          const auto it = grid.find({c[0] + dx, c[1] + dy, c[2] + dz});
          if (it == grid.end()) continue;
          for (int j : it->second)
            if ((V.row(i) - V.row(j)).squaredNorm() <= tol2 && (best < 0 || j < best)) best = j;
        }
    if (best >= 0) {
      rep[i] = best;
    } else {
      grid[c].push_back(i);
    }
  }
  return rep;
}

double signed_volume6(const TriangleMesh& m, const std::vector<int>& tris, const std::vector<char>& flip) {
  double v = 0.0;
  for (int t : tris) {
    const double s = m.vertex(m.F(t, 0)).dot(m.vertex(m.F(t, 1)).cross(m.vertex(m.F(t, 2))));
    v += flip[t] ? -s : s;
  }
  return v;
}

}  // namespace

RepairResult repair(const TriangleMesh& mesh, const RepairOptions& options) {
  const int nv = mesh.num_vertices();
  const int nt = mesh.num_triangles();
  for (int t = 0; t < nt; ++t) {
    if (!has_valid_indices(mesh, t)) {
      throw InputError(mesh.name.empty() ? "<mesh>" : mesh.name, 0,
                       "repair: expected vertex indices in [0, " + std::to_string(nv) + "), found triangle " +
                           std::to_string(t) + " = (" + std::to_string(mesh.F(t, 0)) + ", " +
                           std::to_string(mesh.F(t, 1)) + ", " + std::to_string(mesh.F(t, 2)) + ")");
    }
  }
  RepairResult result;
  RepairReport& rep = result.report;

  // 1. Merge vertices.
  const std::vector<int> rep_of = merge_vertices(mesh.V, options.merge_tolerance);
  for (int i = 0; i < nv; ++i)
    if (rep_of[i] != i) ++rep.merged_vertices;
  TriangleMesh m;
  m.name = mesh.name;
  m.V = mesh.V;
  m.F = mesh.F;
  for (int t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) m.F(t, k) = rep_of[mesh.F(t, k)];

  // 2. Drop degenerate, then duplicate triangles (keep the first of a set).
  std::vector<int> keep;
  keep.reserve(nt);
  std::map<std::array<int, 3>, int> seen;
  for (int t = 0; t < nt; ++t) {
    const bool finite = m.V.row(m.F(t, 0)).allFinite() && m.V.row(m.F(t, 1)).allFinite() && m.V.row(m.F(t, 2)).allFinite();
    if (has_repeated_index(m, t) || (finite && is_sliver(m, t, options.degenerate_relative_tolerance))) {
      ++rep.removed_degenerate;
      continue;
    }
    if (!seen.emplace(sorted_triple(m, t), t).second) {
      ++rep.removed_duplicate;
      continue;
    }
    keep.push_back(t);
  }

  // 3. Drop unreferenced vertices (renumber in index order).
  std::vector<int> new_index(nv, -1);
  int next = 0;
  {
    std::vector<char> used(nv, 0);
    for (int t : keep)
      for (int k = 0; k < 3; ++k) used[m.F(t, k)] = 1;
    for (int i = 0; i < nv; ++i)
      if (used[i]) new_index[i] = next++;
    // Merged-away vertices are not "unreferenced": count only representatives.
    for (int i = 0; i < nv; ++i)
      if (!used[i] && rep_of[i] == i) ++rep.removed_unreferenced;
  }
  TriangleMesh out;
  out.name = mesh.name;
  out.V.resize(next, 3);
  for (int i = 0; i < nv; ++i)
    if (new_index[i] >= 0) out.V.row(new_index[i]) = m.V.row(i);
  out.F.resize(static_cast<int>(keep.size()), 3);
  for (size_t j = 0; j < keep.size(); ++j)
    for (int k = 0; k < 3; ++k) out.F(static_cast<int>(j), k) = new_index[m.F(keep[j], k)];
  rep.vertex_map.resize(nv);
  for (int i = 0; i < nv; ++i) rep.vertex_map[i] = new_index[rep_of[i]];
  rep.triangle_source = keep;

  // 4. Components through edges, orientation through manifold edges.
  const int mt = out.num_triangles();
  std::vector<char> all(mt, 1);
  const std::vector<EdgeUse> uses = edge_uses(out, all);
  // Adjacency: for each triangle, (neighbour, same_direction) across manifold edges.
  std::vector<std::vector<std::pair<int, bool>>> adj(mt);
  std::vector<std::vector<int>> any_adj(mt);  // connectivity through every edge
  std::vector<char> on_open_edge(mt, 0);      // has a boundary or non-manifold edge
  for (size_t i = 0; i < uses.size();) {
    size_t j = i;
    while (j < uses.size() && uses[j].lo == uses[i].lo && uses[j].hi == uses[i].hi) ++j;
    if (j - i == 2) {
      const bool same = uses[i].dir == uses[i + 1].dir;
      adj[uses[i].tri].push_back({uses[i + 1].tri, same});
      adj[uses[i + 1].tri].push_back({uses[i].tri, same});
    } else {
      for (size_t u = i; u < j; ++u) on_open_edge[uses[u].tri] = 1;
    }
    for (size_t u = i; u < j; ++u)
      for (size_t w = i; w < j; ++w)
        if (u != w) any_adj[uses[u].tri].push_back(uses[w].tri);
    i = j;
  }
  std::vector<int> component(mt, -1);
  std::vector<char> flip(mt, 0);
  std::vector<signed char> state(mt, -1);  // orientation relative to a seed; -1 = not reached
  const Eigen::VectorXd area = triangle_areas(out);
  for (int seed = 0; seed < mt; ++seed) {
    if (component[seed] >= 0) continue;
    const int cid = rep.components++;
    std::vector<int> tris;
    std::queue<int> q;
    component[seed] = cid;
    q.push(seed);
    while (!q.empty()) {
      const int t = q.front();
      q.pop();
      tris.push_back(t);
      for (int n : any_adj[t]) {
        if (component[n] < 0) {
          component[n] = cid;
          q.push(n);
        }
      }
    }
    if (!options.orient) continue;
    // Orientation propagation (BFS over manifold edges): across an edge both
    // triangles traverse in the same direction, the neighbour must be flipped
    // relative to t. A contradiction means the component is non-orientable
    // through its manifold edges: leave it unchanged (not a safe repair).
    bool orientable = true;
    for (int s : tris) {
      if (state[s] >= 0) continue;  // manifold sub-patches joined only by non-manifold edges start anew
      state[s] = 0;
      std::queue<int> oq;
      oq.push(s);
      while (!oq.empty() && orientable) {
        const int t = oq.front();
        oq.pop();
        for (const auto& [n, same] : adj[t]) {
          const signed char want = static_cast<signed char>(same ? !state[t] : state[t]);
          if (state[n] < 0) {
            state[n] = want;
            oq.push(n);
          } else if (state[n] != want) {
            orientable = false;
            break;
          }
        }
      }
      if (!orientable) break;
    }
    if (!orientable) {
      ++rep.unorientable_components;
      continue;
    }
    for (int t : tris) flip[t] = state[t];
    const bool closed = std::none_of(tris.begin(), tris.end(), [&](int t) { return on_open_edge[t] != 0; });
    bool invert = false;
    if (closed) {
      invert = signed_volume6(out, tris, flip) < 0.0;  // outward normals: positive volume
    } else {
      double a_flipped = 0.0, a_kept = 0.0;
      for (int t : tris) (flip[t] ? a_flipped : a_kept) += area(t);
      invert = a_flipped > a_kept;  // tie: keep the lowest-index triangle's orientation
    }
    if (invert)
      for (int t : tris) flip[t] = !flip[t];
  }
  for (int t = 0; t < mt; ++t) {
    if (flip[t]) {
      std::swap(out.F(t, 1), out.F(t, 2));
      ++rep.flipped_triangles;
    }
  }
  result.mesh = std::move(out);
  return result;
}

}  // namespace arthrosim::common
