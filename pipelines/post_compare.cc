#include "pipelines/post_compare.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>

#include "common/error.h"
#include "common/hdf5.h"
#include "pipelines/orientation.h"

namespace arthrosim::pipelines {

using common::InputError;

SurfaceField read_surface_field(const std::string& path, const std::string& surface) {
  return surface_output::Reader(path).strain_field(surface);
}

NodeDirections average_node_directions(const SurfaceField& field) {
  const auto N = field.mesh.V.rows();
  NodeDirections out;
  out.direction = Eigen::MatrixXd::Zero(N, 3);
  out.coherence = Eigen::VectorXd::Zero(N);
  out.magnitude = Eigen::VectorXd::Zero(N);
  out.defined.assign(N, false);
  // average_axial_field normalises rows and throws on zero rows: frames with a zero
  // direction carry no information, so give them a unit dummy and zero weight instead.
  const auto T = field.e1.rows();
  Eigen::MatrixXd e1 = field.e1.transpose();
  std::vector<Eigen::MatrixXd> dirs = field.e1_dir;
  for (Eigen::Index t = 0; t < T; ++t)
    for (Eigen::Index i = 0; i < N; ++i)
      if (dirs[t].row(i).norm() == 0.0) {
        dirs[t].row(i) << 1, 0, 0;
        e1(i, t) = 0.0;
      }
  const auto avg = average_axial_field(e1, dirs);
  for (Eigen::Index i = 0; i < N; ++i) {
    out.defined[i] = avg[i].defined;
    out.magnitude(i) = avg[i].mean_magnitude;
    out.coherence(i) = avg[i].coherence;
    if (avg[i].defined) out.direction.row(i) = avg[i].direction.transpose();
  }
  return out;
}

ProjectedView project_view(const common::QuadMesh& mesh, const ViewOptions& view) {
  const double nv = view.direction.norm();
  if (!(nv > 0)) throw InputError("post view: the view direction is zero");
  const Eigen::Vector3d v = view.direction / nv;
  Eigen::Vector3d u = view.up - view.up.dot(v) * v;
  if (!(u.norm() > 1e-9 * std::max(1.0, view.up.norm()))) {
    throw InputError("post view: the up vector is zero or parallel to the view direction");
  }
  u.normalize();
  const Eigen::Vector3d r = v.cross(u);
  ProjectedView pv;
  pv.P.row(0) = r.transpose();
  pv.P.row(1) = u.transpose();
  pv.nodes = (mesh.V * pv.P.transpose());
  const common::TriangleMesh tri = common::triangulate(mesh);
  const common::Points3 n = common::vertex_normals(tri);
  pv.visible.resize(mesh.V.rows());
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) pv.visible[i] = n.row(i).dot(v) < 0.0;
  const auto loops = common::boundary_loops(tri);
  if (loops.empty()) throw InputError("post view: surface '" + mesh.name + "' has no boundary loop to use as outline");
  double best = -1;
  for (const auto& loop : loops) {
    double a = 0;
    for (size_t k = 0; k < loop.size(); ++k) {
      const auto p = pv.nodes.row(loop[k]), q = pv.nodes.row(loop[(k + 1) % loop.size()]);
      a += p.x() * q.y() - q.x() * p.y();
    }
    if (std::abs(a) > best) best = std::abs(a), pv.outline_nodes = loop;
  }
  pv.outline.resize(pv.outline_nodes.size(), 2);
  for (size_t k = 0; k < pv.outline_nodes.size(); ++k) pv.outline.row(k) = pv.nodes.row(pv.outline_nodes[k]);
  return pv;
}

void project_directions(const ProjectedView& view, const Eigen::MatrixXd& d3, Eigen::VectorXd& angle,
                        Eigen::VectorXd& length) {
  angle = Eigen::VectorXd::Zero(d3.rows());
  length = Eigen::VectorXd::Zero(d3.rows());
  for (Eigen::Index i = 0; i < d3.rows(); ++i) {
    const double n = d3.row(i).norm();
    if (!(n > 0)) continue;
    const Eigen::Vector2d p = view.P * (d3.row(i).transpose() / n);
    length(i) = p.norm();
    angle(i) = wrap_axial(std::atan2(p.y(), p.x()));
  }
}

Eigen::MatrixX2d resample_closed(const Eigen::MatrixX2d& poly, int n) {
  const auto m = poly.rows();
  if (m < 3 || n < 3) throw InputError("resample_closed: need a polygon of >= 3 points and n >= 3");
  std::vector<double> s(m + 1, 0.0);
  for (Eigen::Index i = 0; i < m; ++i) s[i + 1] = s[i] + (poly.row((i + 1) % m) - poly.row(i)).norm();
  const double L = s[m];
  if (!(L > 0)) throw InputError("resample_closed: the polygon has zero length");
  Eigen::MatrixX2d out(n, 2);
  Eigen::Index seg = 0;
  for (int k = 0; k < n; ++k) {
    const double t = L * k / n;
    while (seg < m - 1 && s[seg + 1] < t) ++seg;
    const double len = s[seg + 1] - s[seg];
    const double f = len > 0 ? (t - s[seg]) / len : 0.0;
    out.row(k) = (1 - f) * poly.row(seg) + f * poly.row((seg + 1) % m);
  }
  return out;
}

namespace {
double distance_to_polygon(const Eigen::Vector2d& p, const Eigen::MatrixX2d& poly) {
  double best = std::numeric_limits<double>::infinity();
  for (Eigen::Index i = 0; i < poly.rows(); ++i) {
    const Eigen::Vector2d a = poly.row(i).transpose(), b = poly.row((i + 1) % poly.rows()).transpose();
    const Eigen::Vector2d ab = b - a;
    const double t = ab.squaredNorm() > 0 ? std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0.0;
    best = std::min(best, (a + t * ab - p).norm());
  }
  return best;
}
double median_nn(const Eigen::MatrixX2d& p, const std::vector<bool>* use = nullptr) {
  std::vector<double> d;
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    if (use && !(*use)[i]) continue;
    double best = std::numeric_limits<double>::infinity();
    for (Eigen::Index j = 0; j < p.rows(); ++j)
      if (j != i && (!use || (*use)[j])) best = std::min(best, (p.row(i) - p.row(j)).squaredNorm());
    if (std::isfinite(best)) d.push_back(std::sqrt(best));
  }
  if (d.empty()) return 0.0;
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return d[d.size() / 2];
}
}  // namespace

double median_of(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

Eigen::Vector2d Registration::warp(const Eigen::Vector2d& p) const {
  Eigen::MatrixXd y = p.transpose();
  y = affine.transform.apply(y);
  if (has_nonrigid) y = nonrigid.transform.apply(y);
  return y.row(0).transpose();
}

Eigen::Matrix2d Registration::jacobian(const Eigen::Vector2d& p) const {
  Eigen::Matrix2d J1 = affine.transform.jacobian(p);
  if (!has_nonrigid) return J1;
  const Eigen::MatrixXd q = affine.transform.apply(Eigen::MatrixXd(p.transpose()));
  const Eigen::Matrix2d J2 = nonrigid.transform.jacobian(q.row(0).transpose());
  return J2 * J1;  // chain rule for T = T2 o T1
}

Registration register_map(const Eigen::MatrixX2d& map_outline, const Eigen::MatrixX2d& model_outline,
                          const RegistrationOptions& o) {
  if (o.outline_points < 8) throw InputError("register_map: outline_points must be >= 8");
  Registration reg;
  reg.map_outline = resample_closed(map_outline, o.outline_points);
  reg.model_outline = resample_closed(model_outline, o.outline_points);
  CpdOptions a;
  a.method = CpdMethod::kAffine;
  a.w = o.w;
  a.prealign = CpdPrealign::kMoments;
  reg.affine = cpd_register(reg.model_outline, reg.map_outline, a);
  Eigen::MatrixXd moved = reg.affine.transformed;
  if (o.nonrigid) {
    CpdOptions n;
    n.method = CpdMethod::kNonrigid;
    n.w = o.w;
    n.beta = o.beta;
    n.lambda = o.lambda;
    reg.nonrigid = cpd_register(reg.model_outline, moved, n);
    reg.has_nonrigid = true;
    moved = reg.nonrigid.transformed;
  }
  reg.warped_outline = moved;
  double sum = 0, mx = 0;
  for (Eigen::Index i = 0; i < moved.rows(); ++i) {
    const double d = distance_to_polygon(moved.row(i).transpose(), reg.model_outline);
    sum += d;
    mx = std::max(mx, d);
  }
  reg.outline_mean_distance = sum / moved.rows();
  reg.outline_max_distance = mx;
  return reg;
}

Comparison compare_with_map(const SplitLineMap& map, const Registration& reg, const ProjectedView& view,
                            const Eigen::VectorXd& node_angle, const Eigen::VectorXd& node_weight,
                            const std::vector<bool>& node_usable, const ComparisonOptions& o) {
  const auto S = map.samples.rows();
  const auto N = view.nodes.rows();
  if (node_angle.size() != N || node_weight.size() != N || static_cast<Eigen::Index>(node_usable.size()) != N) {
    throw InputError("compare_with_map: node arrays do not match the view's node count");
  }
  Comparison c;
  c.points.resize(S, 2);
  c.map_angle.resize(S);
  c.model_angle = Eigen::VectorXd::Constant(S, std::numeric_limits<double>::quiet_NaN());
  c.error_deg = Eigen::VectorXd::Constant(S, std::numeric_limits<double>::quiet_NaN());
  c.coherence = Eigen::VectorXd::Zero(S);
  c.covered.assign(S, false);
  c.region = map.region;
  if (static_cast<Eigen::Index>(c.region.size()) != S) c.region.assign(S, "all");
  for (Eigen::Index s = 0; s < S; ++s) {
    const Eigen::Vector2d p = map.samples.row(s).transpose();
    c.points.row(s) = reg.warp(p).transpose();
    const Eigen::Vector2d t(std::cos(map.angle_rad(s)), std::sin(map.angle_rad(s)));
    const Eigen::Vector2d tw = reg.jacobian(p) * t;  // tangents are carried by J
    c.map_angle(s) = wrap_axial(std::atan2(tw.y(), tw.x()));
  }
  c.radius = o.radius;
  if (c.radius <= 0) {
    c.radius = std::max(median_nn(c.points), 1.5 * median_nn(view.nodes, &node_usable));
  }
  const double r2 = c.radius * c.radius;
  for (Eigen::Index s = 0; s < S; ++s) {
    std::vector<double> w;
    std::vector<Eigen::Vector2d> d;
    for (Eigen::Index i = 0; i < N; ++i) {
      if (!node_usable[i] || !(node_weight(i) > 0)) continue;
      if ((view.nodes.row(i) - c.points.row(s)).squaredNorm() > r2) continue;
      w.push_back(node_weight(i));
      d.emplace_back(std::cos(node_angle(i)), std::sin(node_angle(i)));
    }
    if (w.empty()) continue;
    Eigen::VectorXd wv(w.size());
    Eigen::MatrixXd dm(w.size(), 2);
    for (size_t k = 0; k < w.size(); ++k) wv(k) = w[k], dm.row(k) = d[k].transpose();
    const AxialAverage a = average_axial(wv, dm);
    if (!a.defined) continue;
    c.covered[s] = true;
    c.model_angle(s) = wrap_axial(std::atan2(a.direction(1), a.direction(0)));
    c.coherence(s) = a.coherence;
    c.error_deg(s) = acute_line_angle_2d(c.model_angle(s), c.map_angle(s)) * 180.0 / std::numbers::pi;
  }
  std::map<std::string, std::vector<Eigen::Index>> groups;
  for (Eigen::Index s = 0; s < S; ++s) {
    groups["all"].push_back(s);
    if (c.region[s] != "all") groups[c.region[s]].push_back(s);
  }
  auto stats = [&](const std::string& name, const std::vector<Eigen::Index>& idx) {
    RegionStatistics r;
    r.region = name;
    r.samples = static_cast<int>(idx.size());
    std::vector<double> e;
    for (auto s : idx)
      if (c.covered[s]) e.push_back(c.error_deg(s));
    r.covered = static_cast<int>(e.size());
    if (!e.empty()) {
      double sum = 0;
      int within = 0;
      for (double x : e) sum += x, within += x <= o.threshold_rad * 180.0 / std::numbers::pi ? 1 : 0;
      r.mean_deg = sum / e.size();
      r.median_deg = median_of(e);
      r.fraction_within = static_cast<double>(within) / e.size();
    } else {
      r.mean_deg = r.median_deg = r.fraction_within = std::numeric_limits<double>::quiet_NaN();
    }
    return r;
  };
  c.stats.push_back(stats("all", groups["all"]));
  for (const auto& [name, idx] : groups)
    if (name != "all") c.stats.push_back(stats(name, idx));
  return c;
}

}  // namespace arthrosim::pipelines
