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
    const Vec3 rpy = vec3(e, "rpy", Vec3::Zero(), false);
    Pose X = Pose::Identity();
    // URDF convention: R = Rz(yaw) Ry(pitch) Rx(roll).
    X.linear() = (Eigen::AngleAxisd(rpy.z(), Vec3::UnitZ()) *
                  Eigen::AngleAxisd(rpy.y(), Vec3::UnitY()) *
                  Eigen::AngleAxisd(rpy.x(), Vec3::UnitX()))
                     .toRotationMatrix();
    X.translation() = xyz;
    return X;
  }
};

bool is_ext(const XMLElement* e, const char* local) {
  return std::string(e->Name()) == std::string(kNs) + local;
}

// --- URDF structure pre-check (urdfdom reports no line numbers) -------------
void precheck_urdf(const Reader& rd, const XMLElement* robot, std::map<std::string, int>& link_line,
                   std::map<std::string, int>& joint_line) {
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
    if ((type == "revolute" || type == "prismatic") && !j->FirstChildElement("limit"))
      rd.fail(j, "joint '" + n + "' (" + type + ") expected a <limit> element, found none");
    if (const XMLElement* lim = j->FirstChildElement("limit")) {
      if (rd.has(lim, "lower") && rd.has(lim, "upper") &&
          rd.number(lim, "lower") > rd.number(lim, "upper"))
        rd.fail(lim, "joint '" + n + "' expected lower <= upper limit");
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
  std::map<std::string, WrapCylinder> cylinders;
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

Path read_path(Context& c, const XMLElement* e, const std::string& what) {
  Path p;
  for (const XMLElement* pt = e->FirstChildElement("point"); pt; pt = pt->NextSiblingElement("point"))
  {
    const int b = body_of(c, pt);
    const XMLElement* frame_src = c.rd.has(pt, "frame") ? pt : e;  // point overrides its parent
    p.points.push_back({b, to_body(c, frame_src, b) * c.rd.vec3(pt, "xyz", Vec3::Zero(), true)});
  }
  if (p.points.size() < 2)
    c.rd.fail(e, what + ": expected at least 2 <point> elements, found " +
                     std::to_string(p.points.size()));
  if (c.rd.has(e, "wrap")) {
    const std::string w = c.rd.attr(e, "wrap");
    auto it = c.cylinders.find(w);
    if (it == c.cylinders.end()) c.rd.fail(e, what + ": unknown wrap cylinder '" + w + "'");
    if (p.points.size() != 2)
      c.rd.fail(e, what + ": cylinder wrapping expected exactly 2 points, found " +
                       std::to_string(p.points.size()));
    p.cylinder = it->second;
  }
  return p;
}

void read_cylinder(Context& c, const XMLElement* e) {
  const std::string n = c.rd.attr(e, "name");
  WrapCylinder w;
  w.body = body_of(c, e);
  w.X_BC = to_body(c, e, w.body) * c.rd.pose(e);
  w.radius = c.rd.number(e, "radius");
  if (!(w.radius > 0)) c.rd.fail(e, "wrap cylinder '" + n + "' expected radius > 0 m");
  if (!c.cylinders.emplace(n, w).second) c.rd.fail(e, "duplicate wrap cylinder '" + n + "'");
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
  // Mesh coordinates given in the reference (model) frame move to the body frame.
  const Pose X = to_body(c, e, s.body);
  for (int i = 0; i < s.mesh.num_vertices(); ++i)
    s.mesh.V.row(i) = (X * Vec3(s.mesh.V.row(i).transpose())).transpose();
  s.name = n;
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
      p.slack_length = evaluate_path(lb.path, ref.X_WB).length / (1.0 + e_ref);
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
  for (const XMLElement* e = robot->FirstChildElement(); e; e = e->NextSiblingElement()) {
    const std::string name = e->Name();
    if (name.rfind(kNs, 0) != 0) continue;
    if (is_ext(e, "prescribed")) {
      const std::string j = rd.attr(e, "joint");
      const int ci = model.tree.coordinate_index(j);
      if (ci < 0) rd.fail(e, "prescribed: expected a revolute or prismatic joint, found '" + j + "'");
      prescribed.insert(ci);
    } else if (is_ext(e, "wrap_cylinder")) {
      read_cylinder(c, e);
    } else if (is_ext(e, "surface")) {
      read_surface(c, e);
    } else if (is_ext(e, "contact")) {
      read_contact(c, e);
    } else if (is_ext(e, "ligament")) {
      read_ligament(c, e);
    } else if (is_ext(e, "muscle")) {
      read_muscle(c, e);
    } else {
      rd.fail(e, "unknown element <" + name +
                     "> (expected arthrosim:prescribed, wrap_cylinder, surface, contact, "
                     "ligament or muscle)");
    }
  }
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
  // Prepared surfaces by the file name of their source mesh.
  std::map<std::string, std::string> by_file;
  for (const auto& n : names) by_file[std::filesystem::path(f.source_file(n)).filename().string()] = n;
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
    common::PreparedModelReader::TriangleSurface prepared = f.triangles(it->second);
    const std::string& g = prepared.group;
    common::TriangleMesh mesh = std::move(prepared.mesh);
    const Eigen::VectorXd tv = std::move(prepared.thickness);
    if (tv.size() != mesh.num_vertices() || mesh.num_triangles() == 0)
      throw InputError(prepared_path, 0, g + ": expected one thickness per vertex and triangles, found " +
                                             std::to_string(tv.size()) + " values for " +
                                             std::to_string(mesh.num_vertices()) + " vertices");
    // Same place as the model's own mesh (in the file frame): the centroids
    // of the two surfaces must agree to within 2 mm, else the prepared file
    // belongs to another geometry.
    const double offset = centroid_offset(s, mesh);
    if (offset > 2e-3) {
      std::ostringstream m;
      m << g << ": the prepared surface's centroid lies " << offset * 1e3 << " mm from that of the model's '"
        << s.name << "' (" << s.mesh_file << "); expected <= 2 mm (prepared from another geometry?)";
      throw InputError(prepared_path, 0, m.str());
    }
    return with_mesh(s, std::move(mesh), tv, prepared_path + ":" + g);
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
