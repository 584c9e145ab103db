#include "cartilage/shell_scene.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace arthrosim::cartilage {
namespace {

/// "NAME: rest" -> (NAME, rest); NAME one word.
std::pair<std::string, std::string> split_name(const std::string& text) {
  const auto colon = text.find(':');
  if (colon == std::string::npos)
    throw std::invalid_argument("'" + text + "': expected 'NAME: ...'");
  std::istringstream n(text.substr(0, colon));
  std::string name, extra;
  if (!(n >> name) || (n >> extra))
    throw std::invalid_argument("'" + text + "': expected one word before ':'");
  return {name, text.substr(colon + 1)};
}

std::vector<std::string> words_of(const std::string& s) {
  std::istringstream in(s);
  std::vector<std::string> w;
  std::string x;
  while (in >> x) w.push_back(x);
  return w;
}

double number_of(const std::string& w, const std::string& text) {
  try {
    std::size_t used = 0;
    const double x = std::stod(w, &used);
    if (used == w.size() && std::isfinite(x)) return x;
  } catch (const std::exception&) {
  }
  throw std::invalid_argument("'" + text + "': expected a number, found '" + w + "'");
}

Eigen::Vector3d vector_of(const std::vector<std::string>& w, std::size_t from, const std::string& text) {
  if (w.size() != from + 3) throw std::invalid_argument("'" + text + "': expected three numbers after '" + w[from - 1] + "'");
  return {number_of(w[from], text), number_of(w[from + 1], text), number_of(w[from + 2], text)};
}

/// Removes a trailing "history NAME" from `rest` and returns NAME ("" if none).
std::string take_history(std::string& rest, const std::string& text) {
  std::vector<std::string> w = words_of(rest);
  for (std::size_t k = 0; k < w.size(); ++k) {
    if (w[k] != "history") continue;
    if (k + 2 != w.size())
      throw std::invalid_argument("'" + text + "': expected one history name at the end ('... history NAME')");
    rest.clear();  // the words before "history" (the rest is only read word by word)
    for (std::size_t j = 0; j < k; ++j) rest += " " + w[j];
    return w[k + 1];
  }
  return "";
}

}  // namespace

double HistoryDefinition::at(double t) const {
  if (t <= time_s.front()) return factor.front();
  if (t >= time_s.back()) return factor.back();
  const auto it = std::upper_bound(time_s.begin(), time_s.end(), t);
  const std::size_t k = static_cast<std::size_t>(it - time_s.begin());  // time_s[k-1] <= t < time_s[k]
  const double s = (t - time_s[k - 1]) / (time_s[k] - time_s[k - 1]);
  return factor[k - 1] + s * (factor[k] - factor[k - 1]);
}

HistoryDefinition parse_history(const std::string& text) {
  const auto [name, rest] = split_name(text);
  const std::vector<std::string> w = words_of(rest);
  HistoryDefinition h;
  h.name = name;
  if (w.empty()) throw std::invalid_argument("'" + text + "': expected 'ramp T' or 'table T0 F0 T1 F1 ...' after ':'");
  if (w[0] == "ramp") {
    if (w.size() != 2) throw std::invalid_argument("'" + text + "': expected 'ramp T' (T in s, > 0)");
    const double T = number_of(w[1], text);
    if (!(T > 0)) throw std::invalid_argument("'" + text + "': the ramp time must be > 0 s");
    h.time_s = {0.0, T};
    h.factor = {0.0, 1.0};
  } else if (w[0] == "table") {
    if (w.size() < 3 || (w.size() - 1) % 2 != 0)
      throw std::invalid_argument("'" + text + "': expected 'table T0 F0 T1 F1 ...' ((time [s], factor) pairs)");
    for (std::size_t k = 1; k < w.size(); k += 2) {
      const double t = number_of(w[k], text), f = number_of(w[k + 1], text);
      if (t < 0) throw std::invalid_argument("'" + text + "': time " + w[k] + " s is negative");
      if (!h.time_s.empty() && !(t > h.time_s.back()))
        throw std::invalid_argument("'" + text + "': times must increase strictly, found " + w[k] + " after " +
                                    w[k - 2]);
      h.time_s.push_back(t);
      h.factor.push_back(f);
    }
  } else {
    throw std::invalid_argument("'" + text + "': unknown history kind '" + w[0] + "' (ramp, table)");
  }
  return h;
}

NodeSetDefinition parse_node_set(const std::string& text) {
  const auto [name, rest] = split_name(text);
  const std::vector<std::string> w = words_of(rest);
  NodeSetDefinition s;
  s.name = name;
  if (w.empty()) throw std::invalid_argument("'" + text + "': expected box, plane, nodes or all after ':'");
  if (w[0] == "box") {
    if (w.size() != 7) throw std::invalid_argument("'" + text + "': expected 'box XMIN YMIN ZMIN XMAX YMAX ZMAX' (mm)");
    s.kind = NodeSetDefinition::Kind::kBox;
    for (int k = 1; k < 7; ++k) s.numbers.push_back(number_of(w[k], text) * 1e-3);
    for (int k = 0; k < 3; ++k)
      if (s.numbers[k] > s.numbers[k + 3]) throw std::invalid_argument("'" + text + "': box minimum above maximum");
  } else if (w[0] == "plane") {
    if (w.size() != 5 && w.size() != 6)
      throw std::invalid_argument("'" + text + "': expected 'plane NX NY NZ D [TOL]' (D, TOL in mm)");
    s.kind = NodeSetDefinition::Kind::kPlane;
    Eigen::Vector3d n(number_of(w[1], text), number_of(w[2], text), number_of(w[3], text));
    if (!(n.norm() > 0)) throw std::invalid_argument("'" + text + "': the plane normal is zero");
    n.normalize();
    const double d = number_of(w[4], text) * 1e-3, tol = w.size() == 6 ? number_of(w[5], text) * 1e-3 : 1e-6;
    if (!(tol >= 0)) throw std::invalid_argument("'" + text + "': negative tolerance");
    s.numbers = {n.x(), n.y(), n.z(), d, tol};
  } else if (w[0] == "nodes") {
    if (w.size() < 2) throw std::invalid_argument("'" + text + "': expected 'nodes I J ...' (0-based)");
    s.kind = NodeSetDefinition::Kind::kNodes;
    for (std::size_t k = 1; k < w.size(); ++k) {
      const double x = number_of(w[k], text);
      if (x < 0 || x != std::floor(x)) throw std::invalid_argument("'" + text + "': node index '" + w[k] + "'");
      s.nodes.push_back(static_cast<int>(x));
    }
  } else if (w[0] == "group") {
    if (w.size() != 2) throw std::invalid_argument("'" + text + "': expected 'group G' (an OBJ 'g' name)");
    s.kind = NodeSetDefinition::Kind::kGroup;
    s.group = w[1];
  } else if (w[0] == "vtk_point_field" || w[0] == "vtk_cell_field") {
    if (w.size() != 3)
      throw std::invalid_argument("'" + text + "': expected '" + w[0] + " F V' (a scalar field of the VTK mesh and a value)");
    s.kind = w[0] == "vtk_point_field" ? NodeSetDefinition::Kind::kPointField : NodeSetDefinition::Kind::kCellField;
    s.group = w[1];
    s.field_value = number_of(w[2], text);
  } else if (w[0] == "all") {
    if (w.size() != 1) throw std::invalid_argument("'" + text + "': nothing may follow 'all'");
    s.kind = NodeSetDefinition::Kind::kAll;
  } else {
    throw std::invalid_argument("'" + text + "': unknown set kind '" + w[0] + "' (box, plane, nodes, all, group, vtk_point_field, vtk_cell_field)");
  }
  return s;
}

ConstraintDefinition parse_constraint(const std::string& text) {
  auto [set, rest] = split_name(text);
  ConstraintDefinition c;
  c.set = set;
  c.history = take_history(rest, text);
  const auto eq = rest.find('=');
  const std::vector<std::string> comps = words_of(rest.substr(0, eq));
  std::vector<int> order;
  for (const std::string& x : comps) {
    static const char* names[6] = {"ux", "uy", "uz", "dx", "dy", "dz"};
    std::vector<int> add;
    if (x == "u") add = {0, 1, 2};
    else if (x == "d") add = {3, 4, 5};
    else if (x == "all") add = {0, 1, 2, 3, 4, 5};
    else
      for (int k = 0; k < 6; ++k)
        if (x == names[k]) add = {k};
    if (add.empty())
      throw std::invalid_argument("'" + text + "': unknown component '" + x + "' (ux uy uz dx dy dz, u, d, all)");
    for (int k : add) {
      if (c.mask[k]) throw std::invalid_argument("'" + text + "': component '" + x + "' given twice");
      c.mask[k] = true;
      order.push_back(k);
    }
  }
  if (order.empty()) throw std::invalid_argument("'" + text + "': expected components after ':'");
  if (eq != std::string::npos) {
    const std::vector<std::string> v = words_of(rest.substr(eq + 1));
    if (v.size() != order.size())
      throw std::invalid_argument("'" + text + "': " + std::to_string(order.size()) + " components but " +
                                  std::to_string(v.size()) + " values");
    for (std::size_t i = 0; i < v.size(); ++i) c.value(order[i]) = number_of(v[i], text) * (order[i] < 3 ? 1e-3 : 1.0);
  }
  if (!c.history.empty() && !c.prescribed())
    throw std::invalid_argument("'" + text + "': a history needs prescribed values ('= V ...', not all zero)");
  return c;
}

LoadDefinition parse_load(const std::string& text) {
  auto [set, rest] = split_name(text);
  LoadDefinition l;
  l.history = take_history(rest, text);
  const std::vector<std::string> w = words_of(rest);
  l.set = set;
  if (w.empty()) throw std::invalid_argument("'" + text + "': expected force, force_per_node, traction or gravity");
  if (w[0] == "force") l.kind = LoadDefinition::Kind::kForce;
  else if (w[0] == "force_per_node") l.kind = LoadDefinition::Kind::kForcePerNode;
  else if (w[0] == "traction") l.kind = LoadDefinition::Kind::kTraction;
  else if (w[0] == "gravity") l.kind = LoadDefinition::Kind::kGravity;
  else if (w[0] == "body_force") l.kind = LoadDefinition::Kind::kBodyForce;
  else
    throw std::invalid_argument("'" + text + "': unknown load '" + w[0] + "' (force, force_per_node, traction, gravity, body_force)");
  l.vector = vector_of(w, 1, text);
  if (l.kind == LoadDefinition::Kind::kTraction) l.vector *= 1e6;    // MPa -> Pa
  if (l.kind == LoadDefinition::Kind::kBodyForce) l.vector *= 1e9;   // N/mm^3 -> N/m^3
  return l;
}

std::vector<int> select_nodes(const NodeSetDefinition& s, const common::QuadMesh& m, const FaceGroups& groups,
                              const std::vector<common::VtkField>& fields) {
  std::vector<int> out;
  const int n = m.num_nodes();
  switch (s.kind) {
    case NodeSetDefinition::Kind::kAll:
      for (int i = 0; i < n; ++i) out.push_back(i);
      break;
    case NodeSetDefinition::Kind::kBox:
      for (int i = 0; i < n; ++i) {
        bool in = true;
        for (int k = 0; k < 3; ++k) in = in && m.V(i, k) >= s.numbers[k] && m.V(i, k) <= s.numbers[k + 3];
        if (in) out.push_back(i);
      }
      break;
    case NodeSetDefinition::Kind::kPlane: {
      const Eigen::Vector3d nrm(s.numbers[0], s.numbers[1], s.numbers[2]);
      for (int i = 0; i < n; ++i)
        if (std::abs(m.V.row(i).dot(nrm) - s.numbers[3]) <= s.numbers[4]) out.push_back(i);
      break;
    }
    case NodeSetDefinition::Kind::kGroup: {
      const auto it = groups.find(s.group);
      if (it == groups.end()) {
        std::string have;
        for (const auto& [name, quads] : groups) have += (have.empty() ? "" : ", ") + name;
        throw std::invalid_argument("node set '" + s.name + "': the mesh has no face group '" + s.group +
                                    "' (groups: " + (have.empty() ? "none" : have) + ")");
      }
      for (int q : it->second)
        for (int a = 0; a < 4; ++a) out.push_back(m.Q(q, a));
      std::sort(out.begin(), out.end());
      out.erase(std::unique(out.begin(), out.end()), out.end());
      break;
    }
    case NodeSetDefinition::Kind::kPointField:
    case NodeSetDefinition::Kind::kCellField: {
      const bool point = s.kind == NodeSetDefinition::Kind::kPointField;
      const auto loc = point ? common::VtkField::Location::kPoint : common::VtkField::Location::kCell;
      const common::VtkField* f = nullptr;
      std::string have;
      for (const common::VtkField& x : fields) {
        if (x.location != loc) continue;
        have += (have.empty() ? "" : ", ") + x.name;
        if (x.name == s.group) f = &x;
      }
      if (f == nullptr)
        throw std::invalid_argument("node set '" + s.name + "': the mesh has no VTK " + (point ? "point" : "cell") +
                                    " field '" + s.group + "' (" + (point ? "point" : "cell") +
                                    " fields: " + (have.empty() ? "none" : have) + ")");
      if (f->values.cols() != 1)
        throw std::invalid_argument("node set '" + s.name + "': VTK field '" + s.group + "' has " +
                                    std::to_string(f->values.cols()) + " components, expected a scalar field");
      for (Eigen::Index i = 0; i < f->values.rows(); ++i) {
        if (f->values(i, 0) != s.field_value) continue;
        if (point)
          out.push_back(static_cast<int>(i));
        else
          for (int a = 0; a < 4; ++a) out.push_back(m.Q(i, a));
      }
      std::sort(out.begin(), out.end());
      out.erase(std::unique(out.begin(), out.end()), out.end());
      break;
    }
    case NodeSetDefinition::Kind::kNodes:
      for (int i : s.nodes) {
        if (i >= n)
          throw std::invalid_argument("node set '" + s.name + "': node " + std::to_string(i) + " out of range [0, " +
                                      std::to_string(n) + ")");
        out.push_back(i);
      }
      std::sort(out.begin(), out.end());
      out.erase(std::unique(out.begin(), out.end()), out.end());
      break;
  }
  return out;
}

Eigen::MatrixXd consistent_area_loads(const common::QuadMesh& m, const std::vector<int>& nodes,
                                      const Eigen::Vector3d& f) {
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(m.num_nodes(), 3);
  std::vector<char> in(static_cast<std::size_t>(m.num_nodes()), 0);
  for (int i : nodes) in[static_cast<std::size_t>(i)] = 1;
  const double g = 1 / std::sqrt(3.0);
  // Bilinear quad, corners (-1,-1), (1,-1), (1,1), (-1,1) in node order.
  const double xi_a[4] = {-1, 1, 1, -1}, eta_a[4] = {-1, -1, 1, 1};
  for (int e = 0; e < m.num_quads(); ++e) {
    bool all = true;
    for (int a = 0; a < 4; ++a) all = all && in[static_cast<std::size_t>(m.Q(e, a))];
    if (!all) continue;
    for (double xi : {-g, g})
      for (double eta : {-g, g}) {
        Eigen::Vector3d dxi = Eigen::Vector3d::Zero(), deta = Eigen::Vector3d::Zero();
        double N[4];
        for (int a = 0; a < 4; ++a) {
          N[a] = 0.25 * (1 + xi_a[a] * xi) * (1 + eta_a[a] * eta);
          const Eigen::Vector3d X = m.V.row(m.Q(e, a)).transpose();
          dxi += 0.25 * xi_a[a] * (1 + eta_a[a] * eta) * X;
          deta += 0.25 * eta_a[a] * (1 + xi_a[a] * xi) * X;
        }
        const double dA = dxi.cross(deta).norm();  // Gauss weights 1
        for (int a = 0; a < 4; ++a) out.row(m.Q(e, a)) += (N[a] * dA) * f.transpose();
      }
  }
  return out;
}

}  // namespace arthrosim::cartilage
