#include "musculoskeletal/model_io.h"

#include <tinyxml2.h>
#include <urdf_parser/urdf_parser.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>

#include "common/compartments.h"
#include "common/error.h"
#include "common/prepared_model_file.h"
#include "common/hdf5.h"
#include "common/mesh_io.h"

namespace arthrosim::musculoskeletal {

namespace fs = std::filesystem;
using common::InputError;
using tinyxml2::XMLElement;

namespace {

constexpr const char* kNs = "arthrosim:";

struct Reader {
  std::string file, base_dir;

  [[noreturn]] void fail(const XMLElement* e, const std::string& msg) const {
    throw InputError(file, e ? e->GetLineNum() : 0, msg);
  }
  const char* attr(const XMLElement* e, const char* name, bool required = true) const {
    const char* v = e->Attribute(name);
    if (!v && required)
      fail(e, std::string("<") + e->Name() + "> expected attribute '" + name + "', found none");
    return v;
  }
  bool has(const XMLElement* e, const char* name) const { return e->Attribute(name) != nullptr; }
  double number(const XMLElement* e, const char* name) const {
    const std::string s = attr(e, name);
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    while (end && *end && std::isspace(static_cast<unsigned char>(*end))) ++end;
    if (s.empty() || !end || *end != '\0' || !std::isfinite(v))
      fail(e, std::string("attribute '") + name + "' expected a finite number, found '" + s + "'");
    return v;
  }
  double number_or(const XMLElement* e, const char* name, double def) const {
    return has(e, name) ? number(e, name) : def;
  }
  Vec3 vec3(const XMLElement* e, const char* name, const Vec3& def, bool required) const {
    if (!has(e, name)) {
      if (required) attr(e, name);
      return def;
    }
    const std::string s = attr(e, name);
    std::istringstream in(s);
    Vec3 v;
    std::string extra;
    if (!(in >> v.x() >> v.y() >> v.z()) || (in >> extra) || !v.allFinite())
      fail(e, std::string("attribute '") + name + "' expected three numbers, found '" + s + "'");
    return v;
  }
  std::string resolve(const std::string& p) const {
    fs::path path(p);
    return path.is_absolute() ? path.string() : (fs::path(base_dir) / path).string();
  }
  std::string existing_file(const XMLElement* e, const char* name) const {
    const std::string p = attr(e, name);
    const std::string r = resolve(p);
    if (!fs::is_regular_file(r))
      fail(e, std::string("attribute '") + name + "' expected an existing file, found '" + p +
                  "' (resolved to " + r + ")");
    return r;
  }
  Pose pose(const XMLElement* e) const {
    const Vec3 xyz = vec3(e, "xyz", Vec3::Zero(), false);
    Pose X = Pose::Identity();
    if (has(e, "xyz_body_rotation")) {
      if (has(e, "rpy"))
        fail(e, std::string("<") + e->Name() + "> expected one of rpy or xyz_body_rotation, found both");
      // OpenSim's body-fixed X-Y-Z Euler angles: R = Rx(a) Ry(b) Rz(c).
      const Vec3 a = vec3(e, "xyz_body_rotation", Vec3::Zero(), true);
      X.linear() = (Eigen::AngleAxisd(a.x(), Vec3::UnitX()) * Eigen::AngleAxisd(a.y(), Vec3::UnitY()) *
                    Eigen::AngleAxisd(a.z(), Vec3::UnitZ()))
                       .toRotationMatrix();
    } else {
      const Vec3 rpy = vec3(e, "rpy", Vec3::Zero(), false);
      // URDF convention: R = Rz(yaw) Ry(pitch) Rx(roll).
      X.linear() = (Eigen::AngleAxisd(rpy.z(), Vec3::UnitZ()) *
                    Eigen::AngleAxisd(rpy.y(), Vec3::UnitY()) *
                    Eigen::AngleAxisd(rpy.x(), Vec3::UnitX()))
                       .toRotationMatrix();
    }
    X.translation() = xyz;
    return X;
  }
  // Whitespace-separated finite numbers (at least one).
  std::vector<double> numbers(const XMLElement* e, const char* name) const {
    const std::string str = attr(e, name);
    std::istringstream in(str);
    std::vector<double> v;
    std::string tok;
    while (in >> tok) {
      char* end = nullptr;
      const double x = std::strtod(tok.c_str(), &end);
      if (!end || *end != '\0' || !std::isfinite(x))
        fail(e, std::string("attribute '") + name + "' expected finite numbers, found '" + tok + "'");
      v.push_back(x);
    }
    if (v.empty()) fail(e, std::string("attribute '") + name + "' expected numbers, found none");
    return v;
  }
};

bool is_ext(const XMLElement* e, const char* local) {
  return std::string(e->Name()) == std::string(kNs) + local;
}

// --- URDF structure pre-check (urdfdom reports no line numbers) -------------
void precheck_urdf(const Reader& rd, const XMLElement* robot, std::map<std::string, int>& link_line,
                   std::map<std::string, int>& joint_line) {
  // The joint whose child each link is: a tree has one per link (but the
  // root) and no loop. urdfdom refuses other graphs too, but only after
  // building them with owning pointers in a cycle, which it never frees.
  std::map<std::string, const XMLElement*> parent_joint;
  std::map<std::string, std::string> parent_link;
  for (const XMLElement* l = robot->FirstChildElement("link"); l; l = l->NextSiblingElement("link")) {
    const std::string n = rd.attr(l, "name");
    if (!link_line.emplace(n, l->GetLineNum()).second)
      rd.fail(l, "duplicate link '" + n + "' (first at line " + std::to_string(link_line[n]) + ")");
    // Every referenced mesh must exist.
    for (const char* tag : {"visual", "collision"})
      for (const XMLElement* v = l->FirstChildElement(tag); v; v = v->NextSiblingElement(tag))
        if (const XMLElement* g = v->FirstChildElement("geometry"))
          if (const XMLElement* m = g->FirstChildElement("mesh")) rd.existing_file(m, "filename");
  }
  for (const XMLElement* j = robot->FirstChildElement("joint"); j;
       j = j->NextSiblingElement("joint")) {
    const std::string n = rd.attr(j, "name");
    if (!joint_line.emplace(n, j->GetLineNum()).second)
      rd.fail(j, "duplicate joint '" + n + "'");
    const std::string type = rd.attr(j, "type");
    if (type != "revolute" && type != "prismatic" && type != "fixed" && type != "continuous")
      rd.fail(j, "joint '" + n + "' expected type revolute, continuous, prismatic or fixed, found '" +
                     type + "'");
    for (const char* role : {"parent", "child"}) {
      const XMLElement* pc = j->FirstChildElement(role);
      if (!pc) rd.fail(j, "joint '" + n + "' expected a <" + role + "> element, found none");
      const std::string link = rd.attr(pc, "link");
      if (!link_line.count(link)) rd.fail(pc, "joint '" + n + "': unknown " + role + " link '" + link + "'");
    }
    const std::string parent = rd.attr(j->FirstChildElement("parent"), "link");
    const std::string child = rd.attr(j->FirstChildElement("child"), "link");
    if (parent == child) rd.fail(j, "joint '" + n + "' expected different parent and child links, found '" + child + "' for both");
    if (const auto [it, added] = parent_joint.emplace(child, j); !added)
      rd.fail(j, "joint '" + n + "': link '" + child + "' is already the child of joint '" +
                     rd.attr(it->second, "name") + "' (line " + std::to_string(it->second->GetLineNum()) +
                     "); a kinematic tree gives each link one parent");
    parent_link[child] = parent;
    if ((type == "revolute" || type == "prismatic") && !j->FirstChildElement("limit"))
      rd.fail(j, "joint '" + n + "' (" + type + ") expected a <limit> element, found none");
    if (const XMLElement* lim = j->FirstChildElement("limit")) {
      if (rd.has(lim, "lower") && rd.has(lim, "upper") &&
          rd.number(lim, "lower") > rd.number(lim, "upper"))
        rd.fail(lim, "joint '" + n + "' expected lower <= upper limit");
    }
  }
  // No loop: going up from any link must reach a link without a parent.
  for (const auto& [start, joint] : parent_joint) {
    std::string link = start;
    for (std::size_t steps = 0; parent_link.count(link); ++steps) {
      if (steps > parent_link.size())
        rd.fail(joint, "joint '" + std::string(rd.attr(joint, "name")) + "' is part of a loop of joints through link '" +
                           start + "'; a kinematic tree has none");
      link = parent_link[link];
    }
  }
}

void build_tree(const Reader& rd, const urdf::ModelInterface& urdf, Model& model) {
  auto root = urdf.getRoot();
  const auto mass_of = [](const urdf::LinkConstSharedPtr& l) {
    return l->inertial ? l->inertial->mass : 0.0;
  };
  // Centre of mass and inertia tensor (about the COM, body axes) from the
  // link's <inertial> (origin and <inertia> in the inertial frame).
  const auto set_inertia = [&](const urdf::LinkConstSharedPtr& l, int b) {
    if (!l->inertial) return;
    const auto& o = l->inertial->origin;
    double x, y, z, w;
    o.rotation.getQuaternion(x, y, z, w);
    const Eigen::Matrix3d R = Eigen::Quaterniond(w, x, y, z).normalized().toRotationMatrix();
    const auto& in = *l->inertial;
    Eigen::Matrix3d I;
    I << in.ixx, in.ixy, in.ixz, in.ixy, in.iyy, in.iyz, in.ixz, in.iyz, in.izz;
    Body& body = model.tree.bodies[b];
    body.com = Vec3(o.position.x, o.position.y, o.position.z);
    body.inertia = R * I * R.transpose();
  };
  model.tree.add_root(root->name, mass_of(root));
  set_inertia(root, 0);
  std::vector<urdf::LinkConstSharedPtr> queue{root};
  for (size_t qi = 0; qi < queue.size(); ++qi) {
    const auto link = queue[qi];
    for (const auto& uj : link->child_joints) {
      Joint j;
      j.name = uj->name;
      j.parent = model.tree.body_index(link->name);
      switch (uj->type) {
        case urdf::Joint::REVOLUTE:
        case urdf::Joint::CONTINUOUS: j.type = JointType::kRevolute; break;
        case urdf::Joint::PRISMATIC: j.type = JointType::kPrismatic; break;
        case urdf::Joint::FIXED: j.type = JointType::kFixed; break;
        default: throw InputError(rd.file, 0, "joint '" + uj->name + "': unsupported joint type");
      }
      const auto& o = uj->parent_to_joint_origin_transform;
      double x, y, z, w;
      o.rotation.getQuaternion(x, y, z, w);
      j.X_PJ.linear() = Eigen::Quaterniond(w, x, y, z).normalized().toRotationMatrix();
      j.X_PJ.translation() = Vec3(o.position.x, o.position.y, o.position.z);
      j.axis_J = Vec3(uj->axis.x, uj->axis.y, uj->axis.z);
      if (uj->limits && uj->type != urdf::Joint::CONTINUOUS) {
        j.lower = uj->limits->lower;
        j.upper = uj->limits->upper;
      }
      const auto child = urdf.getLink(uj->child_link_name);
      set_inertia(child, model.tree.add_body(child->name, mass_of(child), j));
      queue.push_back(child);
    }
  }
}

// --- extension elements -----------------------------------------------------
struct Context {
  const Reader& rd;
  Model& model;
  const KinematicsData& ref;  ///< kinematics at the reference pose q = 0
  std::map<std::string, WrapSurface> wraps;
  std::map<std::string, ContactSurface> surfaces;
  std::map<std::string, int> surface_line;
};

int body_of(const Context& c, const XMLElement* e, const char* attr = "body") {
  const std::string n = c.rd.attr(e, attr);
  const int b = c.model.tree.body_index(n);
  if (b < 0) c.rd.fail(e, std::string("attribute '") + attr + "': unknown body '" + n + "'");
  return b;
}

// frame="body" (default): coordinates in the body's frame; frame="reference":
// in the model frame at the reference pose q = 0 (converted with X_WB(0)^-1).
Pose to_body(const Context& c, const XMLElement* e, int body) {
  const std::string f = c.rd.has(e, "frame") ? c.rd.attr(e, "frame") : "body";
  if (f == "body") return Pose::Identity();
  if (f == "reference") return c.ref.X_WB[body].inverse();
  c.rd.fail(e, "attribute 'frame' expected body or reference, found '" + f + "'");
}

int coordinate_of(const Context& c, const XMLElement* e) {
  const std::string n = c.rd.attr(e, "coordinate");
  const int ci = c.model.tree.coordinate_index(n);
  if (ci < 0)
    c.rd.fail(e, "attribute 'coordinate': expected a revolute or prismatic joint, found '" + n + "'");
  return ci;
}

// A function of a coordinate (the single child element of e).
CoordinateFunction read_function(const Context& c, const XMLElement* e, const std::string& what) {
  const XMLElement* f = e->FirstChildElement();
  if (!f || f->NextSiblingElement())
    c.rd.fail(e, what + ": expected exactly one function element (constant, linear_function, simm_spline, "
                        "natural_cubic_spline, piecewise_linear_function, multiplier_function)");
  const std::string kind = f->Name();
  try {
    if (kind == "constant") return CoordinateFunction::constant(c.rd.number(f, "value"));
    if (kind == "linear_function") {
      const std::vector<double> k = c.rd.numbers(f, "coefficients");
      if (k.size() != 2) c.rd.fail(f, what + ": linear_function expected coefficients=\"slope intercept\"");
      return CoordinateFunction::linear(k[0], k[1]);
    }
    if (kind == "simm_spline" || kind == "natural_cubic_spline")
      return CoordinateFunction::cubic_spline(c.rd.numbers(f, "x"), c.rd.numbers(f, "y"));
    if (kind == "piecewise_linear_function")
      return CoordinateFunction::piecewise_linear(c.rd.numbers(f, "x"), c.rd.numbers(f, "y"));
    if (kind == "multiplier_function") return read_function(c, f, what).scaled(c.rd.number(f, "scale"));
  } catch (const InputError& err) {
    if (err.line() > 0) throw;
    c.rd.fail(f, what + ": " + err.what());
  }
  c.rd.fail(f, what + ": unknown function type <" + kind +
                   "> (expected constant, linear_function, simm_spline, natural_cubic_spline, "
                   "piecewise_linear_function or multiplier_function)");
}

Path read_path(Context& c, const XMLElement* e, const std::string& what) {
  Path p;
  std::vector<const XMLElement*> wrap_elements;
  int fixed = 0;
  for (const XMLElement* pt = e->FirstChildElement(); pt; pt = pt->NextSiblingElement()) {
    const std::string tag = pt->Name();
    const XMLElement* frame_src = c.rd.has(pt, "frame") ? pt : e;  // a point overrides its parent
    if (tag == "point" || tag == "conditional_point") {
      PathPoint pp;
      pp.body = body_of(c, pt);
      pp.p_B = to_body(c, frame_src, pp.body) * c.rd.vec3(pt, "xyz", Vec3::Zero(), true);
      if (tag == "conditional_point") {
        pp.condition_coordinate = coordinate_of(c, pt);
        const std::vector<double> r = c.rd.numbers(pt, "range");
        if (r.size() != 2 || !(r[0] <= r[1]))
          c.rd.fail(pt, what + ": conditional_point expected range=\"min max\" with min <= max");
        pp.range_min = r[0];
        pp.range_max = r[1];
      } else {
        ++fixed;
      }
      p.points.push_back(pp);
    } else if (tag == "moving_point") {
      PathPoint pp;
      pp.body = body_of(c, pt);
      if (c.rd.has(frame_src, "frame") && std::string(c.rd.attr(frame_src, "frame")) != "body")
        c.rd.fail(pt, what + ": a moving_point's functions give body-frame coordinates; expected frame=\"body\"");
      const char* axes[3] = {"x", "y", "z"};
      for (int j = 0; j < 3; ++j) {
        const XMLElement* f = pt->FirstChildElement(axes[j]);
        if (!f) c.rd.fail(pt, what + ": moving_point expected an <" + std::string(axes[j]) + "> element");
        pp.moving_coordinate[j] = coordinate_of(c, f);
        pp.moving[j] = std::make_shared<const CoordinateFunction>(
            read_function(c, f, what + " moving_point " + axes[j]));
      }
      ++fixed;
      p.points.push_back(pp);
    } else if (tag == "wrap") {
      wrap_elements.push_back(pt);
    } else {
      c.rd.fail(pt, what + ": unknown element <" + tag +
                        "> (expected point, conditional_point, moving_point or wrap)");
    }
  }
  if (p.points.size() < 2 || fixed < 2)
    c.rd.fail(e, what + ": expected at least 2 <point> elements that are not conditional, found " +
                     std::to_string(fixed));
  const int n = static_cast<int>(p.points.size());
  auto add_wrap = [&](const XMLElement* we, const std::string& name) {
    auto it = c.wraps.find(name);
    if (it == c.wraps.end())
      c.rd.fail(we, what + ": unknown wrap object '" + name + "' (wrap objects must be declared before use)");
    PathWrap pw;
    pw.surface = it->second;
    if (we != e && c.rd.has(we, "range")) {
      const std::vector<double> r = c.rd.numbers(we, "range");
      bool ok = r.size() == 2;
      for (double v : r) ok = ok && v == std::floor(v) && (v == -1 || (v >= 1 && v <= n));
      if (ok && r[0] != -1 && r[1] != -1) ok = r[0] <= r[1];
      if (!ok)
        c.rd.fail(we, what + ": wrap range expected \"first last\" (1-based point indices in 1.." +
                          std::to_string(n) + ", -1 = first/last, first <= last), found '" +
                          c.rd.attr(we, "range") + "'");
      pw.first_point = r[0] < 0 ? -1 : static_cast<int>(r[0]) - 1;
      pw.last_point = r[1] < 0 ? -1 : static_cast<int>(r[1]) - 1;
    }
    if (we != e && c.rd.has(we, "method")) {
      const std::string m = c.rd.attr(we, "method");
      if (m == "hybrid") pw.method = WrapMethod::kHybrid;
      else if (m == "midpoint") pw.method = WrapMethod::kMidpoint;
      else if (m == "axial") pw.method = WrapMethod::kAxial;
      else if (m == "shortest") pw.method = WrapMethod::kShortest;
      else c.rd.fail(we, what + ": wrap method expected hybrid, midpoint, axial or shortest, found '" + m + "'");
    }
    p.wraps.push_back(pw);
  };
  for (const XMLElement* we : wrap_elements) add_wrap(we, c.rd.attr(we, "object"));
  if (c.rd.has(e, "wrap")) add_wrap(e, c.rd.attr(e, "wrap"));
  return p;
}

WrapQuadrant read_quadrant(const Context& c, const XMLElement* e) {
  if (!c.rd.has(e, "quadrant")) return WrapQuadrant::kAll;
  const std::string q = c.rd.attr(e, "quadrant");
  if (q == "all") return WrapQuadrant::kAll;
  if (q == "+x" || q == "x") return WrapQuadrant::kPosX;
  if (q == "-x") return WrapQuadrant::kNegX;
  if (q == "+y" || q == "y") return WrapQuadrant::kPosY;
  if (q == "-y") return WrapQuadrant::kNegY;
  if (q == "+z" || q == "z") return WrapQuadrant::kPosZ;
  if (q == "-z") return WrapQuadrant::kNegZ;
  c.rd.fail(e, "attribute 'quadrant' expected all, +x, -x, +y, -y, +z or -z, found '" + q + "'");
}

void read_wrap_surface(Context& c, const XMLElement* e, WrapShape shape) {
  WrapSurface w;
  w.name = c.rd.attr(e, "name");
  w.shape = shape;
  w.body = body_of(c, e);
  w.X_BS = to_body(c, e, w.body) * c.rd.pose(e);
  w.quadrant = read_quadrant(c, e);
  switch (shape) {
    case WrapShape::kCylinder:
      w.radius = c.rd.number(e, "radius");
      w.length = c.rd.number_or(e, "length", w.length);
      break;
    case WrapShape::kSphere:
      w.radius = c.rd.number(e, "radius");
      break;
    case WrapShape::kEllipsoid:
      w.semi_axes = c.rd.vec3(e, "dimensions", Vec3::Zero(), true);
      if (c.rd.has(e, "chords")) {
        const double n = c.rd.number(e, "chords");
        if (n != std::floor(n) || n < 2 || n > 1000)
          c.rd.fail(e, "attribute 'chords' expected an integer in 2..1000, found " + std::to_string(n));
        w.ellipsoid_chords = static_cast<int>(n);
      }
      break;
    case WrapShape::kTorus:
      w.radius = c.rd.number(e, "inner_radius");
      w.ring_radius = c.rd.number(e, "outer_radius");
      break;
  }
  try {
    validate(w);
  } catch (const InputError& err) {
    c.rd.fail(e, err.what());
  }
  if (!c.wraps.emplace(w.name, w).second) c.rd.fail(e, "duplicate wrap object '" + w.name + "'");
}

Eigen::VectorXd read_thickness_file(const Reader& rd, const XMLElement* e, const std::string& path,
                                    int n) {
  std::ifstream in(path);
  std::vector<double> v;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream ls(line);
    std::string tok;
    while (ls >> tok) {
      char* end = nullptr;
      const double x = std::strtod(tok.c_str(), &end);
      if (*end != '\0' || !std::isfinite(x) || x < 0)
        throw InputError(path, line_no, "expected a thickness >= 0 (mm), found '" + tok + "'");
      v.push_back(x * 1e-3);
    }
  }
  if (static_cast<int>(v.size()) != n)
    rd.fail(e, "thickness file '" + path + "' expected " + std::to_string(n) +
                   " values (one per triangle), found " + std::to_string(v.size()));
  return Eigen::Map<Eigen::VectorXd>(v.data(), n);
}

// Per-vertex thickness rows "x_mm,y_mm,z_mm,thickness_mm" (one per mesh vertex
// in order; '#' comment lines and one header line before the rows are skipped), checked against the mesh vertices
// to 1e-6 m; the per-triangle thickness is the mean of its three vertices.
Eigen::VectorXd read_thickness_csv(const Reader& rd, const XMLElement* e, const std::string& path,
                                   const common::TriangleMesh& mesh) {
  std::ifstream in(path);
  std::string line;
  int line_no = 0, row = 0;
  bool seen_line = false;
  Eigen::VectorXd tv(mesh.num_vertices());
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    for (char& ch : line)
      if (ch == ',') ch = ' ';
    std::istringstream ls(line);
    double x, y, z, t;
    const bool first = !seen_line;
    seen_line = true;
    if (!(ls >> x >> y >> z >> t)) {
      if (first) continue;  // the header line
      throw InputError(path, line_no, "expected x_mm,y_mm,z_mm,thickness_mm, found '" + line + "'");
    }
    if (row >= mesh.num_vertices())
      throw InputError(path, line_no, "expected " + std::to_string(mesh.num_vertices()) +
                                          " rows (one per mesh vertex), found more");
    const Vec3 p(x * 1e-3, y * 1e-3, z * 1e-3);
    if ((p - mesh.vertex(row)).norm() > 1e-6)
      throw InputError(path, line_no, "row " + std::to_string(row) +
                                          " expected the position of mesh vertex " +
                                          std::to_string(row) + " (to 1e-6 m), found another point");
    if (!(t >= 0) || !std::isfinite(t))
      throw InputError(path, line_no, "expected thickness_mm >= 0, found " + std::to_string(t));
    tv[row++] = t * 1e-3;
  }
  if (row != mesh.num_vertices())
    rd.fail(e, "thickness csv '" + path + "' expected " + std::to_string(mesh.num_vertices()) +
                   " rows, found " + std::to_string(row));
  Eigen::VectorXd tt(mesh.num_triangles());
  for (int i = 0; i < mesh.num_triangles(); ++i)
    tt[i] = (tv[mesh.F(i, 0)] + tv[mesh.F(i, 1)] + tv[mesh.F(i, 2)]) / 3.0;
  return tt;
}

// Compartment labels of a surface holding both tibial plateaus, by prepare's
// rule (common/compartments.h) on its mesh in the mesh file's frame.
void label_compartments(ContactSurface& s, const common::TriangleMesh& mesh_M, const std::string& source) {
  const common::CompartmentSplit split = common::split_medial_lateral(mesh_M, s.lateral_M);
  std::ostringstream how;
  const Vec3 u = s.lateral_M.normalized();
  how << "split_lateral (" << u.x() << ", " << u.y() << ", " << u.z() << ") of '" << s.name << "' ("
      << std::filesystem::path(source).filename().string() << "), ";
  if (split.components >= 2)
    how << split.components << " connected components";
  else
    how << "one connected piece cut at the 2-means plane";
  how << ": " << split.medial_triangles() << " medial, " << split.lateral_triangles() << " lateral triangles";
  if (split.medial_triangles() == 0 || split.lateral_triangles() == 0)
    throw InputError(source, 0, "surface '" + s.name + "': split into medial and lateral compartments by " +
                                    how.str() + ": expected triangles on both sides");
  s.compartment = split.is_lateral;
  s.compartment_rule = how.str();
}

// The model file's direction attribute: +x, -x, +y, -y, +z, -z or "x y z".
Vec3 direction_attr(const Reader& rd, const XMLElement* e, const char* name) {
  const std::string v = rd.attr(e, name);
  static const std::map<std::string, Vec3> axes = {{"+x", Vec3::UnitX()}, {"-x", -Vec3::UnitX()},
                                                   {"+y", Vec3::UnitY()}, {"-y", -Vec3::UnitY()},
                                                   {"+z", Vec3::UnitZ()}, {"-z", -Vec3::UnitZ()}};
  if (auto it = axes.find(v); it != axes.end()) return it->second;
  const Vec3 d = rd.vec3(e, name, Vec3::Zero(), true);
  if (!(d.norm() > 0))
    rd.fail(e, std::string("attribute '") + name + "' expected a direction (+x, -x, +y, -y, +z, -z or three numbers "
                                                   "not all zero), found '" + v + "'");
  return d;
}

void read_surface(Context& c, const XMLElement* e) {
  const std::string n = c.rd.attr(e, "name");
  ContactSurface s;
  s.body = body_of(c, e);
  const std::string mesh = c.rd.existing_file(e, "mesh");
  common::MeshReadOptions mo;
  if (c.rd.has(e, "unit")) {
    try {
      mo.unit = common::parse_length_unit(c.rd.attr(e, "unit"));
    } catch (const InputError& err) {
      c.rd.fail(e, err.what());
    }
  }
  try {
    s.mesh = common::read_mesh(mesh, mo);
  } catch (const InputError& err) {
    c.rd.fail(e, std::string("surface '") + n + "': " + err.what());
  }
  const int n_src = int(c.rd.has(e, "thickness_mm")) + int(c.rd.has(e, "thickness_file")) +
                    int(c.rd.has(e, "thickness_csv"));
  if (n_src != 1)
    c.rd.fail(e, "surface '" + n +
                     "' expected exactly one of thickness_mm, thickness_file, thickness_csv");
  if (c.rd.has(e, "thickness_mm")) {
    const double t = c.rd.number(e, "thickness_mm");
    if (!(t >= 0)) c.rd.fail(e, "surface '" + n + "' expected thickness_mm >= 0");
    s.thickness = Eigen::VectorXd::Constant(s.mesh.num_triangles(), t * 1e-3);
  } else if (c.rd.has(e, "thickness_file")) {
    s.thickness = read_thickness_file(c.rd, e, c.rd.existing_file(e, "thickness_file"),
                                      s.mesh.num_triangles());
  } else {
    s.thickness = read_thickness_csv(c.rd, e, c.rd.existing_file(e, "thickness_csv"), s.mesh);
  }
  // Mesh coordinates given in the reference (model) frame move to the body
  // frame; xyz/rpy place the mesh file's frame in that frame (default identity).
  const Pose X = to_body(c, e, s.body) * c.rd.pose(e);
  s.name = n;
  if (c.rd.has(e, "split_lateral")) {
    s.lateral_M = direction_attr(c.rd, e, "split_lateral");
    try {
      label_compartments(s, s.mesh, mesh);  // in the mesh file's frame, as prepare
    } catch (const InputError& err) {
      c.rd.fail(e, err.what());
    }
  }
  for (int i = 0; i < s.mesh.num_vertices(); ++i)
    s.mesh.V.row(i) = (X * Vec3(s.mesh.V.row(i).transpose())).transpose();
  s.mesh_file = mesh;
  s.X_BM = X;
  if (!c.surfaces.emplace(n, std::move(s)).second) c.rd.fail(e, "duplicate surface '" + n + "'");
  c.surface_line[n] = e->GetLineNum();
}

void read_contact(Context& c, const XMLElement* e) {
  const std::string n = c.rd.attr(e, "name");
  if (c.model.contact_index(n) >= 0) c.rd.fail(e, "duplicate contact '" + n + "'");
  auto surface = [&](const char* role) {
    const std::string s = c.rd.attr(e, role);
    auto it = c.surfaces.find(s);
    if (it == c.surfaces.end())
      c.rd.fail(e, std::string("contact '") + n + "' " + role + ": unknown surface '" + s +
                       "' (surfaces must be declared before the contact)");
    return it->second;
  };
  ElasticFoundationParameters m;
  m.youngs_modulus = c.rd.number(e, "youngs_modulus_mpa") * 1e6;
  m.poisson_ratio = c.rd.number(e, "poisson_ratio");
  m.max_overlap_factor = c.rd.number_or(e, "max_overlap_factor", m.max_overlap_factor);
  const std::string law = c.rd.has(e, "law") ? c.rd.attr(e, "law") : "linear";
  if (law == "linear")
    m.law = FoundationLaw::kLinear;
  else if (law == "nonlinear")
    m.law = FoundationLaw::kNonlinear;
  else
    c.rd.fail(e, "contact '" + n + "' expected law linear or nonlinear, found '" + law + "'");
  ContactSurface casting = surface("casting");
  ContactSurface target = surface("target");
  try {
    c.model.contacts.emplace_back(n, std::move(casting), std::move(target), m);
  } catch (const InputError& err) {
    c.rd.fail(e, err.what());
  }
}

void read_ligament(Context& c, const XMLElement* e) {
  const KinematicsData& ref = c.ref;
  Ligament lig;
  lig.name = c.rd.attr(e, "name");
  if (c.model.ligament_index(lig.name) >= 0) c.rd.fail(e, "duplicate ligament '" + lig.name + "'");
  int k = 0;
  for (const XMLElement* b = e->FirstChildElement("bundle"); b;
       b = b->NextSiblingElement("bundle"), ++k) {
    const std::string where = "ligament '" + lig.name + "' bundle " + std::to_string(k);
    LigamentBundle lb;
    if (c.rd.has(b, "name")) lb.name = c.rd.attr(b, "name");
    BlankevoortParameters& p = lb.parameters;
    // Bundle attributes override the group's.
    auto value = [&](const char* name, double def) {
      return c.rd.has(b, name) ? c.rd.number(b, name) : c.rd.number_or(e, name, def);
    };
    if (!c.rd.has(b, "stiffness") && !c.rd.has(e, "stiffness"))
      c.rd.fail(b, where + " expected attribute 'stiffness' (on the bundle or the ligament)");
    p.stiffness = value("stiffness", 0.0);
    p.transition_strain = value("transition_strain", p.transition_strain);
    p.damping = value("damping", p.damping);
    lb.path = read_path(c, b, where);
    const bool has_l0 = c.rd.has(b, "slack_length");
    const bool has_e = c.rd.has(b, "reference_strain") || c.rd.has(e, "reference_strain");
    if (has_l0 == has_e)
      c.rd.fail(b, where + " expected exactly one of slack_length or reference_strain");
    if (has_l0) {
      p.slack_length = c.rd.number(b, "slack_length");
    } else {
      // l0 = l_ref / (1 + e_ref) with l_ref the length at the reference pose (q = 0).
      const double e_ref = value("reference_strain", 0.0);
      if (!(e_ref > -1.0)) c.rd.fail(b, where + " expected reference_strain > -1");
      p.slack_length =
          evaluate_path(lb.path, ref.X_WB, Eigen::VectorXd::Zero(c.model.num_coordinates())).length / (1.0 + e_ref);
    }
    try {
      validate(p, where);
    } catch (const InputError& err) {
      c.rd.fail(b, err.what());
    }
    lig.bundles.push_back(std::move(lb));
  }
  if (lig.bundles.empty()) c.rd.fail(e, "ligament '" + lig.name + "' expected at least one <bundle>");
  c.model.ligaments.push_back(std::move(lig));
}

void read_muscle(Context& c, const XMLElement* e) {
  Muscle m;
  m.name = c.rd.attr(e, "name");
  if (c.model.muscle_index(m.name) >= 0) c.rd.fail(e, "duplicate muscle '" + m.name + "'");
  m.max_isometric_force = c.rd.number(e, "max_isometric_force");
  if (!(m.max_isometric_force > 0))
    c.rd.fail(e, "muscle '" + m.name + "' expected max_isometric_force > 0 N");
  const bool lo = c.rd.has(e, "optimal_fiber_length"), ts = c.rd.has(e, "tendon_slack_length");
  if (lo != ts)
    c.rd.fail(e, "muscle '" + m.name + "' expected both optimal_fiber_length and tendon_slack_length, or neither");
  if (lo) {
    m.optimal_fiber_length = c.rd.number(e, "optimal_fiber_length");
    m.tendon_slack_length = c.rd.number(e, "tendon_slack_length");
    if (!(m.optimal_fiber_length > 0) || !(m.tendon_slack_length > 0))
      c.rd.fail(e, "muscle '" + m.name + "' expected optimal_fiber_length > 0 m and tendon_slack_length > 0 m");
  }
  m.pennation_angle = c.rd.number_or(e, "pennation_angle", 0.0);
  if (!(m.pennation_angle >= 0 && m.pennation_angle < M_PI / 2))
    c.rd.fail(e, "muscle '" + m.name + "' expected 0 <= pennation_angle < pi/2 rad");
  m.path = read_path(c, e, "muscle '" + m.name + "'");
  c.model.muscles.push_back(std::move(m));
}

}  // namespace

Model parse_model(const std::string& xml, const std::string& file_name,
                  const std::string& base_dir) {
  Reader rd{file_name, base_dir};
  tinyxml2::XMLDocument doc;
  if (doc.Parse(xml.c_str(), xml.size()) != tinyxml2::XML_SUCCESS)
    throw InputError(file_name, doc.ErrorLineNum(),
                     std::string("expected well-formed XML: ") + doc.ErrorStr());
  const XMLElement* robot = doc.RootElement();
  if (!robot || std::string(robot->Name()) != "robot")
    throw InputError(file_name, robot ? robot->GetLineNum() : 0,
                     "expected a <robot> root element");
  std::map<std::string, int> link_line, joint_line;
  precheck_urdf(rd, robot, link_line, joint_line);
  const auto urdf = urdf::parseURDF(xml);
  if (!urdf)
    throw InputError(file_name, robot->GetLineNum(),
                     "urdfdom could not build a kinematic tree (expected exactly one root link "
                     "and a tree of joints; see urdfdom's console message)");

  Model model;
  model.name = robot->Attribute("name") ? robot->Attribute("name") : "";
  model.source = file_name;
  build_tree(rd, *urdf, model);

  KinematicsData ref;
  forward_kinematics(model.tree, Eigen::VectorXd::Zero(model.num_coordinates()), ref);
  Context c{rd, model, ref, {}, {}, {}};
  std::set<int> prescribed;
  bool have_subject = false;
  model.default_q = Eigen::VectorXd::Zero(model.num_coordinates());
  for (const XMLElement* e = robot->FirstChildElement(); e; e = e->NextSiblingElement()) {
    const std::string name = e->Name();
    if (name.rfind(kNs, 0) != 0) continue;
    if (is_ext(e, "prescribed")) {
      const std::string j = rd.attr(e, "joint");
      const int ci = model.tree.coordinate_index(j);
      if (ci < 0) rd.fail(e, "prescribed: expected a revolute or prismatic joint, found '" + j + "'");
      prescribed.insert(ci);
    } else if (is_ext(e, "wrap_cylinder")) {
      read_wrap_surface(c, e, WrapShape::kCylinder);
    } else if (is_ext(e, "wrap_ellipsoid")) {
      read_wrap_surface(c, e, WrapShape::kEllipsoid);
    } else if (is_ext(e, "wrap_sphere")) {
      read_wrap_surface(c, e, WrapShape::kSphere);
    } else if (is_ext(e, "wrap_torus")) {
      read_wrap_surface(c, e, WrapShape::kTorus);
    } else if (is_ext(e, "surface")) {
      read_surface(c, e);
    } else if (is_ext(e, "contact")) {
      read_contact(c, e);
    } else if (is_ext(e, "ligament")) {
      read_ligament(c, e);
    } else if (is_ext(e, "muscle")) {
      read_muscle(c, e);
    } else if (is_ext(e, "default")) {
      const std::string j = rd.attr(e, "joint");
      const int ci = model.tree.coordinate_index(j);
      if (ci < 0) rd.fail(e, "default: expected a revolute or prismatic joint, found '" + j + "'");
      model.default_q[ci] = rd.number(e, "value");
    } else if (is_ext(e, "role")) {
      const std::string role = rd.attr(e, "name");
      const bool joint = rd.has(e, "joint"), link = rd.has(e, "link");
      if (joint == link) rd.fail(e, "role '" + role + "': expected exactly one of joint or link");
      if (joint) {
        const std::string j = rd.attr(e, "joint");
        const int ci = model.tree.coordinate_index(j);
        if (ci < 0) rd.fail(e, "role '" + role + "': expected a revolute or prismatic joint, found '" + j + "'");
        if (!model.coordinate_roles.emplace(role, ci).second) rd.fail(e, "duplicate role '" + role + "'");
      } else {
        const int b = body_of(c, e, "link");
        if (!model.body_roles.emplace(role, b).second) rd.fail(e, "duplicate role '" + role + "'");
      }
    } else if (is_ext(e, "coordinate_spring")) {
      CoordinateSpring sp;
      sp.name = rd.has(e, "name") ? rd.attr(e, "name") : rd.attr(e, "joint");
      const std::string j = rd.attr(e, "joint");
      sp.coordinate = model.tree.coordinate_index(j);
      if (sp.coordinate < 0) rd.fail(e, "coordinate_spring: expected a revolute or prismatic joint, found '" + j + "'");
      sp.stiffness = rd.number_or(e, "stiffness", 0.0);
      sp.rest_length = rd.number_or(e, "rest_length", 0.0);
      sp.viscosity = rd.number_or(e, "viscosity", 0.0);
      if (!(sp.stiffness >= 0) || !(sp.viscosity >= 0))
        rd.fail(e, "coordinate_spring '" + sp.name + "': expected stiffness >= 0 and viscosity >= 0");
      model.coordinate_springs.push_back(sp);
    } else if (is_ext(e, "subject")) {
      if (have_subject) rd.fail(e, "expected one <arthrosim:subject>, found a second");
      have_subject = true;
      model.subject_mass_kg = rd.number(e, "mass_kg");
      if (!(model.subject_mass_kg > 0)) rd.fail(e, "subject: expected mass_kg > 0");
    } else {
      rd.fail(e, "unknown element <" + name +
                     "> (expected arthrosim:prescribed, default, role, wrap_cylinder, wrap_ellipsoid, "
                     "wrap_sphere, wrap_torus, surface, contact, ligament, muscle, coordinate_spring or "
                     "subject)");
    }
  }
  if (!have_subject)
    for (const Body& b : model.tree.bodies) model.subject_mass_kg += b.mass;
  for (int i = 0; i < model.num_coordinates(); ++i)
    (prescribed.count(i) ? model.prescribed_coordinates : model.free_coordinates).push_back(i);
  return model;
}

Model load_model(const std::string& urdf_path) {
  std::ifstream in(urdf_path, std::ios::binary);
  if (!in) throw InputError(urdf_path, 0, "expected a readable model file, found none");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_model(ss.str(), urdf_path, fs::path(urdf_path).parent_path().string());
}

}  // namespace arthrosim::musculoskeletal

// ------------------------------------------------------ prepared surfaces --

namespace arthrosim::musculoskeletal {

namespace {

// Distance [m] between the centroid of the model's own mesh of s (taken back
// to the file frame) and that of `mesh` (file frame): a replacement mesh
// must lie where the model's does.
double centroid_offset(const ContactSurface& s, const common::TriangleMesh& mesh) {
  const Vec3 c_model = s.X_BM.inverse() * Vec3(s.mesh.V.colwise().mean().transpose());
  return (c_model - Vec3(mesh.V.colwise().mean().transpose())).norm();
}

// A copy of s with `mesh` (file frame) placed by s.X_BM, the triangle
// thickness the mean of its vertices' values, and mesh_file = label.
ContactSurface with_mesh(const ContactSurface& s, common::TriangleMesh mesh, const Eigen::VectorXd& vertex_thickness,
                         std::string label) {
  ContactSurface r = s;
  r.mesh_file = std::move(label);
  r.thickness.resize(mesh.num_triangles());
  for (int t = 0; t < mesh.num_triangles(); ++t)
    r.thickness[t] =
        (vertex_thickness[mesh.F(t, 0)] + vertex_thickness[mesh.F(t, 1)] + vertex_thickness[mesh.F(t, 2)]) / 3.0;
  // The model's labels belong to its own mesh: relabel the new one by the
  // same rule (mesh still in the file frame here), or none.
  r.compartment.clear();
  r.compartment_rule.clear();
  if (r.lateral_M.norm() > 0) label_compartments(r, mesh, r.mesh_file);
  for (int i = 0; i < mesh.num_vertices(); ++i) mesh.V.row(i) = (s.X_BM * Vec3(mesh.V.row(i).transpose())).transpose();
  r.mesh = std::move(mesh);
  return r;
}

// Rebuilds every contact pair with its surfaces replaced by make(surface,
// pair name), each model surface made once (shared by the pairs that use
// it), and reports each replacement with the new mesh's origin.
PreparedSurfacesReport replace_contact_surfaces(
    Model& model, const std::function<ContactSurface(const ContactSurface&, const std::string&)>& make) {
  PreparedSurfacesReport report;
  std::map<std::string, ContactSurface> replaced;  // by model surface name
  auto replace = [&](const ContactSurface& s, const std::string& pair) -> ContactSurface {
    if (auto it = replaced.find(s.name); it != replaced.end()) return it->second;
    ContactSurface r = make(s, pair);
    report.lines.push_back(s.name + ": " + std::to_string(s.mesh.num_triangles()) + " -> " +
                           std::to_string(r.mesh.num_triangles()) + " triangles (" + r.mesh_file + ")");
    replaced.emplace(s.name, r);
    return r;
  };
  std::vector<ContactPair> pairs;
  for (const ContactPair& c : model.contacts)
    pairs.emplace_back(c.name(), replace(c.casting(), c.name()), replace(c.target(), c.name()), c.material());
  model.contacts = std::move(pairs);
  return report;
}

}  // namespace

PreparedSurfacesReport use_prepared_surfaces(Model& model, const std::string& prepared_path) {
  const common::PreparedModelReader f(prepared_path);
  const std::vector<std::string> names = f.surface_names();
  // Prepared surfaces by the file name of their source mesh; several for one
  // file when prepare split it into compartments (a tibial cartilage mesh
  // holding both plateaus): the model's surface is then their union.
  std::map<std::string, std::vector<std::string>> by_file;
  for (const auto& n : names) by_file[std::filesystem::path(f.source_file(n)).filename().string()].push_back(n);
  auto make = [&](const ContactSurface& s, const std::string& pair) -> ContactSurface {
    const std::string file = std::filesystem::path(s.mesh_file).filename().string();
    auto it = by_file.find(file);
    if (s.mesh_file.empty() || it == by_file.end()) {
      std::string list;
      for (const auto& [k, v] : by_file) list += (list.empty() ? "" : ", ") + k;
      throw InputError(prepared_path, 0,
                       "contact pair '" + pair + "': expected a prepared surface made from '" +
                           file + "' (surface '" + s.name + "'), found surfaces from: " + list);
    }
    common::TriangleMesh mesh;
    Eigen::VectorXd tv;
    std::string groups;
    // Compartments of the parts prepare split from this file (all or none).
    std::vector<char> compartment;
    std::string parts_rule;
    int labelled = 0;
    for (const std::string& part : it->second) {
      // Checked by the reader (indices in range, finite, thickness >= 0).
      const common::PreparedModelReader::TriangleSurface p = f.triangles(part);
      const std::string comp = f.compartment(part);
      if (comp == "medial" || comp == "lateral") {
        ++labelled;
        compartment.insert(compartment.end(), static_cast<std::size_t>(p.mesh.F.rows()), comp == "lateral" ? 1 : 0);
        parts_rule += (parts_rule.empty() ? "" : " + ") + part + " (" + comp + ", " +
                      std::to_string(p.mesh.F.rows()) + " triangles)";
      }
      const int n0 = mesh.num_vertices(), t0 = mesh.num_triangles();
      mesh.V.conservativeResize(n0 + p.mesh.V.rows(), 3);
      mesh.V.bottomRows(p.mesh.V.rows()) = p.mesh.V;
      mesh.F.conservativeResize(t0 + p.mesh.F.rows(), 3);
      mesh.F.bottomRows(p.mesh.F.rows()) = p.mesh.F.array() + n0;
      tv.conservativeResize(n0 + p.thickness.size());
      tv.tail(p.thickness.size()) = p.thickness;
      groups += (groups.empty() ? "" : "+") + p.group;
    }
    // Same place as the model's own mesh (in the file frame): the centroids
    // of the two surfaces must agree to within 2 mm, else the prepared file
    // belongs to another geometry.
    const double offset = centroid_offset(s, mesh);
    if (!(offset <= 2e-3)) {
      std::ostringstream m;
      m << groups << ": the prepared surface's centroid lies " << offset * 1e3 << " mm from that of the model's '"
        << s.name << "' (" << s.mesh_file << "); expected <= 2 mm (prepared from another geometry?)";
      throw InputError(prepared_path, 0, m.str());
    }
    const bool parts_labelled = labelled > 0 && labelled == static_cast<int>(it->second.size());
    ContactSurface base = s;
    if (parts_labelled) base.lateral_M.setZero();  // the parts' labels, not a relabelling
    ContactSurface r = with_mesh(base, std::move(mesh), tv, prepared_path + ":" + groups);
    r.lateral_M = s.lateral_M;
    if (parts_labelled) {
      // The prepare stage's own split (common/compartments.h), part by part.
      r.compartment = std::move(compartment);
      r.compartment_rule = "the prepared compartments " + parts_rule + " (prepare's split of " + file + ")";
    }
    return r;
  };
  return replace_contact_surfaces(model, make);
}

PreparedSurfacesReport use_contact_meshes(Model& model, const std::map<std::string, SurfaceMesh>& by_file,
                                          const std::string& source) {
  auto make = [&](const ContactSurface& s, const std::string& pair) -> ContactSurface {
    const std::string file = std::filesystem::path(s.mesh_file).filename().string();
    auto it = by_file.find(file);
    if (s.mesh_file.empty() || it == by_file.end())
      throw InputError(source, 0, "contact pair '" + pair + "': no mesh given for '" + file + "'");
    const SurfaceMesh& in = it->second;
    if (in.vertex_thickness.size() != in.mesh.num_vertices() || in.mesh.num_triangles() == 0)
      throw InputError(source, 0, file + ": expected triangles and one thickness per vertex");
    const double offset = centroid_offset(s, in.mesh);
    if (offset > 2e-3)
      throw InputError(source, 0, file + ": the mesh's centroid lies " + std::to_string(offset * 1e3) +
                                      " mm from the model's; expected <= 2 mm");
    return with_mesh(s, in.mesh, in.vertex_thickness, source + ":" + file);
  };
  return replace_contact_surfaces(model, make);
}

}  // namespace arthrosim::musculoskeletal
