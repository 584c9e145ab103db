#include "musculoskeletal/osim_import.h"

#include <tinyxml2.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

namespace {

namespace fs = std::filesystem;
using common::InputError;
using tinyxml2::XMLElement;
using Vec3 = Eigen::Vector3d;
using Pose = Eigen::Isometry3d;

// ------------------------------------------------------------ formatting --

// Shortest text that reads back to the same double.
std::string num(double v) {
  if (v == 0.0) return "0";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}
std::string vec(const Vec3& v) { return num(v.x()) + " " + num(v.y()) + " " + num(v.z()); }

// URDF rpy of R = Rz(yaw) Ry(pitch) Rx(roll).
Vec3 rpy_of(const Eigen::Matrix3d& R) {
  const double pitch = std::asin(std::clamp(-R(2, 0), -1.0, 1.0));
  double roll, yaw;
  if (std::abs(R(2, 0)) < 1.0 - 1e-12) {
    roll = std::atan2(R(2, 1), R(2, 2));
    yaw = std::atan2(R(1, 0), R(0, 0));
  } else {  // gimbal lock: put everything in yaw
    roll = 0.0;
    yaw = std::atan2(-R(0, 1), R(1, 1));
  }
  return Vec3(roll, pitch, yaw);
}

std::string origin(const Pose& X) {
  Vec3 rpy = rpy_of(X.linear());
  for (int k = 0; k < 3; ++k)
    if (std::abs(rpy[k]) < 1e-15) rpy[k] = 0.0;
  return "<origin xyz=\"" + vec(X.translation()) + "\" rpy=\"" + vec(rpy) + "\"/>";
}

std::string xml_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '&': o += "&amp;"; break;
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

// OpenSim's body-fixed X-Y-Z Euler angles: R = Rx(a) Ry(b) Rz(c).
Eigen::Matrix3d body_xyz(const Vec3& a) {
  return (Eigen::AngleAxisd(a.x(), Vec3::UnitX()) * Eigen::AngleAxisd(a.y(), Vec3::UnitY()) *
          Eigen::AngleAxisd(a.z(), Vec3::UnitZ()))
      .toRotationMatrix();
}

// ----------------------------------------------------------------- input --

struct Doc {
  std::string file;

  [[noreturn]] void fail(const XMLElement* e, const std::string& msg) const {
    throw InputError(file, e ? e->GetLineNum() : 0, msg);
  }
  static std::string trim(const char* s) {
    if (!s) return "";
    std::string v(s);
    const auto b = v.find_first_not_of(" \t\r\n");
    if (b == std::string::npos) return "";
    return v.substr(b, v.find_last_not_of(" \t\r\n") - b + 1);
  }
  static const XMLElement* child(const XMLElement* e, const char* tag) {
    return e ? e->FirstChildElement(tag) : nullptr;
  }
  static std::string text(const XMLElement* e, const char* tag) {
    const XMLElement* c = child(e, tag);
    return c ? trim(c->GetText()) : "";
  }
  std::vector<double> numbers_of(const XMLElement* at, const std::string& s, const std::string& what) const {
    std::istringstream in(s);
    std::vector<double> v;
    std::string tok;
    while (in >> tok) {
      char* end = nullptr;
      const double x = std::strtod(tok.c_str(), &end);
      if (*end != '\0' || !std::isfinite(x)) fail(at, what + ": expected numbers, found '" + s + "'");
      v.push_back(x);
    }
    return v;
  }
  // n numbers from child `tag` (def when absent and def given).
  std::vector<double> numbers(const XMLElement* e, const char* tag, std::size_t n,
                              const std::vector<double>* def = nullptr) const {
    const XMLElement* c = child(e, tag);
    if (!c || trim(c->GetText()).empty()) {
      if (def) return *def;
      fail(e, std::string("<") + e->Name() + "> expected <" + tag + ">, found none");
    }
    std::vector<double> v = numbers_of(c, trim(c->GetText()), std::string("<") + tag + ">");
    if (v.size() != n)
      fail(c, std::string("<") + tag + "> expected " + std::to_string(n) + " numbers, found " +
                  std::to_string(v.size()));
    return v;
  }
  double number(const XMLElement* e, const char* tag, std::optional<double> def = std::nullopt) const {
    std::vector<double> d;
    if (def) d = {*def};
    return numbers(e, tag, 1, def ? &d : nullptr)[0];
  }
  Vec3 vec3(const XMLElement* e, const char* tag, std::optional<Vec3> def = std::nullopt) const {
    std::vector<double> d;
    if (def) d = {def->x(), def->y(), def->z()};
    const auto v = numbers(e, tag, 3, def ? &d : nullptr);
    return Vec3(v[0], v[1], v[2]);
  }
  bool flag(const XMLElement* e, const char* tag, bool def) const {
    const std::string t = text(e, tag);
    if (t.empty()) return def;
    if (t == "true") return true;
    if (t == "false") return false;
    fail(child(e, tag), std::string("<") + tag + "> expected true or false, found '" + t + "'");
  }
};

// Last segment of an OpenSim component path ("/bodyset/femur_r" -> femur_r).
std::string leaf(const std::string& path) {
  const auto s = path.find_last_of('/');
  return s == std::string::npos ? path : path.substr(s + 1);
}

// A TransformAxis / MovingPathPoint function.
struct Function {
  std::string tag;  // OpenSim element name
  int line = 0;
  bool linear = false;             // Constant, LinearFunction, Multiplier of them
  double slope = 0.0, intercept = 0.0;
  std::vector<double> x, y;        // SimmSpline, NaturalCubicSpline, PiecewiseLinearFunction
  double scale = 1.0;              // MultiplierFunction
  std::shared_ptr<Function> inner;
};

std::shared_ptr<Function> read_function(const Doc& d, const XMLElement* f) {
  auto fn = std::make_shared<Function>();
  fn->tag = f->Name();
  fn->line = f->GetLineNum();
  if (fn->tag == "Constant") {
    fn->linear = true;
    fn->intercept = d.number(f, "value");
  } else if (fn->tag == "LinearFunction") {
    const auto c = d.numbers(f, "coefficients", 2);
    fn->linear = true;
    fn->slope = c[0];
    fn->intercept = c[1];
  } else if (fn->tag == "MultiplierFunction") {
    fn->scale = d.number(f, "scale", 1.0);
    const XMLElement* in = nullptr;
    for (const XMLElement* c = f->FirstChildElement(); c; c = c->NextSiblingElement())
      if (std::string(c->Name()) != "scale") in = c;
    if (in && std::string(in->Name()) == "function") in = in->FirstChildElement();
    if (!in) d.fail(f, "MultiplierFunction: expected a function inside, found none");
    fn->inner = read_function(d, in);
    fn->linear = fn->inner->linear;
    fn->slope = fn->scale * fn->inner->slope;
    fn->intercept = fn->scale * fn->inner->intercept;
  } else if (fn->tag == "SimmSpline" || fn->tag == "NaturalCubicSpline" || fn->tag == "PiecewiseLinearFunction") {
    fn->x = d.numbers_of(f, Doc::text(f, "x"), fn->tag + " <x>");
    fn->y = d.numbers_of(f, Doc::text(f, "y"), fn->tag + " <y>");
    if (fn->x.size() != fn->y.size() || fn->x.size() < 2)
      d.fail(f, fn->tag + ": expected <x> and <y> of equal length >= 2, found " + std::to_string(fn->x.size()) +
                    " and " + std::to_string(fn->y.size()));
  } else {
    d.fail(f, "unknown function type <" + fn->tag + "> (expected Constant, LinearFunction, "
              "MultiplierFunction, SimmSpline, NaturalCubicSpline or PiecewiseLinearFunction)");
  }
  return fn;
}

// The function of a TransformAxis or a MovingPathPoint component:
// <LinearFunction name="function">, or <function><LinearFunction/></function>.
std::shared_ptr<Function> function_of(const Doc& d, const XMLElement* owner, const char* name) {
  for (const XMLElement* c = owner->FirstChildElement(); c; c = c->NextSiblingElement()) {
    const std::string tag = c->Name();
    if (tag == name) {
      const XMLElement* in = c->FirstChildElement();
      if (!in) d.fail(c, std::string("<") + name + "> expected a function inside, found none");
      return read_function(d, in);
    }
    if (c->Attribute("name") && std::string(c->Attribute("name")) == name) return read_function(d, c);
  }
  return nullptr;
}

// ---------------------------------------------------------------- model --

struct Mesh {
  std::string name, file;
  Vec3 scale = Vec3::Ones();
  int line = 0;
};

struct WrapObject {
  std::string name, kind, body, quadrant = "all";
  Vec3 translation = Vec3::Zero(), rotation = Vec3::Zero();  // xyz_body_rotation
  double radius = 0, length = 0, inner = 0, outer = 0;
  Vec3 dimensions = Vec3::Zero();
  bool active = true;
  int line = 0;
};

struct BodyInfo {
  std::string name;
  double mass = 0.0;
  Vec3 com = Vec3::Zero();
  Eigen::Matrix<double, 6, 1> inertia = Eigen::Matrix<double, 6, 1>::Zero();  // xx yy zz xy xz yz
  std::vector<Mesh> meshes;
  int line = 0;
};

// A frame resolved to (body, pose of the frame in the body).
struct Frame {
  std::string body;
  Pose X_BF = Pose::Identity();
};

struct Coordinate {
  std::string name, joint;
  bool rotational = true;
  double default_value = 0.0, lower = -1e30, upper = 1e30;
  bool clamped = false, locked = false, prescribed = false;
  int line = 0;
};

// One step of a joint's chain from parent to child.
struct Element {
  enum Kind { kFixed, kRevolute, kPrismatic } kind = kFixed;
  Pose X = Pose::Identity();  // kFixed
  Vec3 axis = Vec3::UnitZ();  // unit, in the frame before the element
  std::string coordinate;
};

struct JointInfo {
  std::string name, type;
  std::string parent_body, child_body;
  std::vector<Element> elements;  // forward: parent body frame -> child body frame
  std::vector<std::string> coordinates;
  std::vector<std::string> rotation_coordinates;  // rotation1..3 with a coordinate, in order
  int line = 0;
  std::string error;  // why it cannot be represented (an error only if it is imported)
};

std::vector<Element> inverse(const std::vector<Element>& f) {
  std::vector<Element> r;
  for (auto it = f.rbegin(); it != f.rend(); ++it) {
    Element e = *it;
    if (e.kind == Element::kFixed)
      e.X = e.X.inverse();
    else
      e.axis = -e.axis;
    r.push_back(e);
  }
  return r;
}

struct PathPointOut {
  std::string kind;  // point, conditional_point, moving_point
  std::string body;
  Vec3 p = Vec3::Zero();
  std::string coordinate;  // conditional
  double lo = 0, hi = 0;
  std::array<std::string, 3> moving_coordinate;
  std::array<std::shared_ptr<Function>, 3> moving;
  std::string name;
  int line = 0;
};

struct PathWrapOut {
  std::string object, method;
  int first = -1, last = -1;
  int line = 0;
};

struct PathOut {
  std::vector<PathPointOut> points;
  std::vector<PathWrapOut> wraps;
};

struct ReportEntry {
  std::string what, name, why;
  int line = 0;
};

class Importer {
 public:
  Importer(std::string file, const OsimImportOptions& o) : d_{std::move(file)}, o_(o) {}

  OsimImportSummary run(const std::string& out_dir);

 private:
  void read_model(const XMLElement* model);
  void read_body(const XMLElement* b);
  void read_joint(const XMLElement* j);
  Frame resolve_frame(const XMLElement* at, const std::string& path, const std::string& joint = "") const;
  void select_bodies();
  PathOut read_path(const XMLElement* gp, const std::string& owner, bool* on_imported,
                    std::set<std::string>* bodies);
  void note(const std::string& what, const std::string& name, std::string why, int line) {
    // The report names lines of the .osim, not where it was read from.
    for (std::size_t p; (p = why.find(d_.file + ":")) != std::string::npos;) why.replace(p, d_.file.size() + 1, "line ");
    report_.push_back({what, name, why, line});
  }
  std::string find_mesh(const std::string& file) const;
  void write_path(std::ostream& out, const PathOut& p, const std::string& indent);
  void write_function(std::ostream& out, const Function& f);

  Doc d_;
  OsimImportOptions o_;
  std::string model_name_;
  double total_mass_ = 0.0;
  std::map<std::string, BodyInfo> bodies_;
  std::vector<std::string> body_order_;
  std::map<std::string, Frame> frames_;  // absolute path -> resolved frame
  std::map<std::string, std::map<std::string, const XMLElement*>> joint_frames_;  // joint -> frame name -> element
  std::map<std::string, JointInfo> joints_;
  std::vector<std::string> joint_order_;
  std::map<std::string, Coordinate> coords_;
  std::map<std::string, WrapObject> wraps_;
  std::set<std::string> imported_;       // bodies (incl. ground)
  std::set<std::string> knee_side_;      // bodies moved by the knee's or pf joint's coordinates
  std::string root_;
  std::vector<std::string> up_chain_;    // joints from the root up to ground
  std::vector<ReportEntry> report_;
  std::vector<std::string> used_wraps_;  // in first-use order
  const XMLElement* model_ = nullptr;
  fs::path osim_dir_;
};

Frame Importer::resolve_frame(const XMLElement* at, const std::string& path, const std::string& joint) const {
  if (path == "/ground" || path == "ground" || path == "../ground") return {"ground", Pose::Identity()};
  if (auto it = frames_.find(path); it != frames_.end()) return it->second;
  if (path.rfind("/bodyset/", 0) == 0) {
    const std::string b = path.substr(9);
    if (bodies_.count(b)) return {b, Pose::Identity()};
  }
  if (!joint.empty()) {  // a joint's own frame, named relative to it
    if (auto it = frames_.find("/jointset/" + joint + "/" + path); it != frames_.end()) return it->second;
  }
  if (bodies_.count(path)) return {path, Pose::Identity()};  // OpenSim 3 style bare body name
  d_.fail(at, "unknown frame '" + path + "' (expected /ground, /bodyset/<body> or a PhysicalOffsetFrame)");
}

void Importer::read_body(const XMLElement* b) {
  BodyInfo bi;
  bi.name = Doc::trim(b->Attribute("name"));
  if (bi.name.empty()) d_.fail(b, "expected a name on <Body>, found none");
  bi.line = b->GetLineNum();
  bi.mass = d_.number(b, "mass", 0.0);
  if (!(bi.mass >= 0)) d_.fail(b, "body '" + bi.name + "': expected mass >= 0");
  bi.com = d_.vec3(b, "mass_center", Vec3::Zero());
  std::vector<double> zero6(6, 0.0);
  const auto I = d_.numbers(b, "inertia", 6, &zero6);
  for (int k = 0; k < 6; ++k) bi.inertia[k] = I[k];
  if (const XMLElement* g = Doc::child(b, "attached_geometry"))
    for (const XMLElement* m = g->FirstChildElement(); m; m = m->NextSiblingElement()) {
      if (std::string(m->Name()) != "Mesh") {
        note("attached geometry", bi.name + "/" + Doc::trim(m->Attribute("name")),
             std::string("<") + m->Name() + "> (visual only) is not imported", m->GetLineNum());
        continue;
      }
      const std::string sock = Doc::text(m, "socket_frame");
      if (!sock.empty() && sock != "..")
        note("attached geometry", bi.name + "/" + Doc::trim(m->Attribute("name")),
             "attached to frame '" + sock + "', not the body: not imported (visual only)", m->GetLineNum());
      else
        bi.meshes.push_back({Doc::trim(m->Attribute("name")), Doc::text(m, "mesh_file"),
                             d_.vec3(m, "scale_factors", Vec3::Ones()), m->GetLineNum()});
    }
  if (const XMLElement* ws = Doc::child(Doc::child(b, "WrapObjectSet"), "objects"))
    for (const XMLElement* w = ws->FirstChildElement(); w; w = w->NextSiblingElement()) {
      WrapObject wo;
      wo.kind = w->Name();
      wo.name = Doc::trim(w->Attribute("name"));
      wo.body = bi.name;
      wo.line = w->GetLineNum();
      wo.active = d_.flag(w, "active", true);
      wo.translation = d_.vec3(w, "translation", Vec3::Zero());
      wo.rotation = d_.vec3(w, "xyz_body_rotation", Vec3::Zero());
      wo.quadrant = Doc::text(w, "quadrant");
      if (wo.quadrant.empty()) wo.quadrant = "all";
      if (wo.kind == "WrapCylinder") {
        wo.radius = d_.number(w, "radius");
        wo.length = d_.number(w, "length", 1.0);
      } else if (wo.kind == "WrapEllipsoid") {
        wo.dimensions = d_.vec3(w, "dimensions");
      } else if (wo.kind == "WrapSphere") {
        wo.radius = d_.number(w, "radius");
      } else if (wo.kind == "WrapTorus") {
        wo.inner = d_.number(w, "inner_radius");
        wo.outer = d_.number(w, "outer_radius");
      } else {
        note("wrap object", wo.name, "type <" + wo.kind + "> is not supported (not imported)", wo.line);
        continue;
      }
      if (wo.name.empty() || !wraps_.emplace(wo.name, wo).second)
        d_.fail(w, "expected a unique wrap object name, found '" + wo.name + "'");
    }
  // Frames owned by the body (components), resolved later with the joints'.
  bodies_[bi.name] = bi;
  body_order_.push_back(bi.name);
}

void Importer::read_joint(const XMLElement* j) {
  JointInfo ji;
  ji.name = Doc::trim(j->Attribute("name"));
  ji.type = j->Name();
  ji.line = j->GetLineNum();
  // Offset frames of the joint.
  if (const XMLElement* fr = Doc::child(j, "frames"))
    for (const XMLElement* f = fr->FirstChildElement(); f; f = f->NextSiblingElement()) {
      if (std::string(f->Name()) != "PhysicalOffsetFrame")
        d_.fail(f, "joint '" + ji.name + "': expected PhysicalOffsetFrame in <frames>, found <" + f->Name() + ">");
      const std::string fname = Doc::trim(f->Attribute("name"));
      const Frame parent = resolve_frame(f, Doc::text(f, "socket_parent"), ji.name);
      Pose X = Pose::Identity();
      X.translation() = d_.vec3(f, "translation", Vec3::Zero());
      X.linear() = body_xyz(d_.vec3(f, "orientation", Vec3::Zero()));
      frames_["/jointset/" + ji.name + "/" + fname] = {parent.body, parent.X_BF * X};
    }
  const Frame P = resolve_frame(j, Doc::text(j, "socket_parent_frame"), ji.name);
  const Frame C = resolve_frame(j, Doc::text(j, "socket_child_frame"), ji.name);
  ji.parent_body = P.body;
  ji.child_body = C.body;
  // Coordinates.
  std::map<std::string, const XMLElement*> coord_el;
  if (const XMLElement* cs = Doc::child(j, "coordinates"))
    for (const XMLElement* c = cs->FirstChildElement("Coordinate"); c; c = c->NextSiblingElement("Coordinate")) {
      Coordinate co;
      co.name = Doc::trim(c->Attribute("name"));
      co.joint = ji.name;
      co.line = c->GetLineNum();
      co.default_value = d_.number(c, "default_value", 0.0);
      std::vector<double> inf = {-1e30, 1e30};
      const auto r = d_.numbers(c, "range", 2, &inf);
      co.lower = r[0];
      co.upper = r[1];
      if (co.lower > co.upper) d_.fail(c, "coordinate '" + co.name + "': expected range min <= max");
      co.clamped = d_.flag(c, "clamped", false);
      co.locked = d_.flag(c, "locked", false);
      co.prescribed = d_.flag(c, "prescribed", false);
      const std::string mt = Doc::text(c, "motion_type");
      if (mt == "translational") co.rotational = false;
      if (co.name.empty() || coords_.count(co.name)) d_.fail(c, "expected a unique coordinate name, found '" + co.name + "'");
      coords_[co.name] = co;
      coord_el[co.name] = c;
      ji.coordinates.push_back(co.name);
    }
  std::vector<Element>& el = ji.elements;
  el.push_back({Element::kFixed, P.X_BF, Vec3::UnitZ(), ""});
  auto require_coordinate = [&](const XMLElement* at, const std::string& c) {
    if (!coord_el.count(c))
      d_.fail(at, "joint '" + ji.name + "': coordinate '" + c + "' is not one of the joint's <coordinates>");
  };
  try {
  if (ji.type == "CustomJoint") {
    const XMLElement* st = Doc::child(j, "SpatialTransform");
    if (!st) d_.fail(j, "CustomJoint '" + ji.name + "': expected a <SpatialTransform>, found none");
    struct Axis {
      std::string coordinate;
      Vec3 axis;
      std::shared_ptr<Function> f;
      const XMLElement* at;
    };
    std::map<std::string, Axis> axes;
    for (const XMLElement* t = st->FirstChildElement("TransformAxis"); t; t = t->NextSiblingElement("TransformAxis")) {
      Axis a;
      a.at = t;
      const std::string n = Doc::trim(t->Attribute("name"));
      std::istringstream cs(Doc::text(t, "coordinates"));
      std::string c;
      std::vector<std::string> cl;
      while (cs >> c) cl.push_back(c);
      if (cl.size() > 1)
        d_.fail(t, "joint '" + ji.name + "' " + n + ": a function of " + std::to_string(cl.size()) +
                       " coordinates cannot be represented (expected at most one)");
      if (!cl.empty()) a.coordinate = cl[0];
      a.axis = d_.vec3(t, "axis");
      if (!(a.axis.norm() > 0)) d_.fail(t, "joint '" + ji.name + "' " + n + ": expected a non-zero axis");
      a.axis.normalize();
      a.f = function_of(d_, t, "function");
      axes[n] = a;
    }
    // Translations (in the parent offset frame F, they commute), then the
    // rotations in order: X_FM = [R1 R2 R3 | sum t_i b_i].
    for (const char* n : {"translation1", "translation2", "translation3", "rotation1", "rotation2", "rotation3"}) {
      auto it = axes.find(n);
      if (it == axes.end()) continue;
      const Axis& a = it->second;
      const bool rot = std::string(n).rfind("rotation", 0) == 0;
      if (!a.f) {
        if (a.coordinate.empty()) continue;  // no function, no coordinate: zero
        d_.fail(a.at, "joint '" + ji.name + "' " + n + ": coordinate '" + a.coordinate + "' without a function");
      }
      if (!a.f->linear) {
        if (a.coordinate.empty())
          d_.fail(a.at, "joint '" + ji.name + "' " + n + ": a constant " + a.f->tag + " is not supported");
        d_.fail(a.at, "joint '" + ji.name + "' " + n + ": coordinate '" + a.coordinate + "' through a " + a.f->tag +
                          " (line " + std::to_string(a.f->line) +
                          ") cannot be represented (a URDF joint moves linearly with its coordinate)");
      }
      auto constant = [&](double c) {
        if (c == 0.0) return;
        Pose X = Pose::Identity();
        if (rot)
          X.linear() = Eigen::AngleAxisd(c, a.axis).toRotationMatrix();
        else
          X.translation() = c * a.axis;
        el.push_back({Element::kFixed, X, Vec3::UnitZ(), ""});
      };
      if (a.coordinate.empty()) {
        constant(a.f->intercept);
        continue;
      }
      require_coordinate(a.at, a.coordinate);
      if (std::abs(std::abs(a.f->slope) - 1.0) > 1e-12)
        d_.fail(a.at, "joint '" + ji.name + "' " + n + ": coordinate '" + a.coordinate + "' with slope " +
                          num(a.f->slope) + " cannot be represented (expected +1 or -1)");
      Coordinate& co = coords_[a.coordinate];
      co.rotational = rot;
      constant(a.f->intercept);
      el.push_back({rot ? Element::kRevolute : Element::kPrismatic, Pose::Identity(), a.f->slope * a.axis,
                    a.coordinate});
      if (rot) ji.rotation_coordinates.push_back(a.coordinate);
    }
    for (const auto& c : ji.coordinates) {
      bool used = false;
      for (const auto& e : el) used = used || e.coordinate == c;
      if (!used) d_.fail(coord_el[c], "joint '" + ji.name + "': coordinate '" + c + "' drives no TransformAxis");
    }
  } else if (ji.type == "WeldJoint") {
    if (!ji.coordinates.empty()) d_.fail(j, "WeldJoint '" + ji.name + "': expected no coordinates");
  } else if (ji.type == "PinJoint" || ji.type == "SliderJoint") {
    if (ji.coordinates.size() != 1) d_.fail(j, ji.type + " '" + ji.name + "': expected one coordinate");
    const bool pin = ji.type == "PinJoint";
    coords_[ji.coordinates[0]].rotational = pin;
    el.push_back({pin ? Element::kRevolute : Element::kPrismatic, Pose::Identity(),
                  pin ? Vec3::UnitZ() : Vec3::UnitX(), ji.coordinates[0]});
    if (pin) ji.rotation_coordinates.push_back(ji.coordinates[0]);
  } else {
    // Represented only if outside the imported tree (checked in select_bodies).
    ji.elements.clear();
    ji.error = d_.file + ":" + std::to_string(ji.line) + ": error: joint '" + ji.name + "' of type " + ji.type +
               " lies on the imported leg and cannot be represented (expected CustomJoint, WeldJoint, PinJoint "
               "or SliderJoint)";
  }
  } catch (const InputError& e) {
    // An error only if the joint is imported (select_bodies).
    ji.elements.clear();
    ji.error = e.what();
  }
  if (!ji.elements.empty()) el.push_back({Element::kFixed, C.X_BF.inverse(), Vec3::UnitZ(), ""});
  if (joints_.count(ji.name)) d_.fail(j, "duplicate joint '" + ji.name + "'");
  joints_[ji.name] = ji;
  joint_order_.push_back(ji.name);
}

void Importer::read_model(const XMLElement* model) {
  model_ = model;
  model_name_ = Doc::trim(model->Attribute("name"));
  for (const char* units : {"length_units", "force_units"}) {
    const std::string u = Doc::text(model, units);
    const bool length = std::string(units) == "length_units";
    const bool ok = u.empty() || (length ? (u == "m" || u == "meters") : (u == "N" || u == "newtons"));
    if (!ok)
      d_.fail(Doc::child(model, units), std::string(units) + ": expected " + (length ? "m (meters)" : "N (newtons)") +
                                             ", found '" + u + "'");
  }
  const Vec3 g = d_.vec3(model, "gravity", Vec3(0, -9.80665, 0));
  if ((g - Vec3(0, -9.80665, 0)).norm() > 1e-3 * 9.80665)
    note("gravity", vec(g), "arthrosim's gravity is (0, -9.80665, 0) m/s^2 in the lab; this model's differs", 0);
  const XMLElement* bs = Doc::child(Doc::child(model, "BodySet"), "objects");
  if (!bs) d_.fail(model, "expected <BodySet><objects>, found none");
  for (const XMLElement* b = bs->FirstChildElement(); b; b = b->NextSiblingElement()) {
    if (std::string(b->Name()) != "Body") d_.fail(b, std::string("expected <Body> in the BodySet, found <") + b->Name() + ">");
    read_body(b);
    total_mass_ += bodies_[body_order_.back()].mass;
  }
  // Frames owned by bodies (<components><PhysicalOffsetFrame>).
  for (const XMLElement* b = bs->FirstChildElement(); b; b = b->NextSiblingElement()) {
    const std::string bn = Doc::trim(b->Attribute("name"));
    if (const XMLElement* cs = Doc::child(b, "components"))
      for (const XMLElement* f = cs->FirstChildElement("PhysicalOffsetFrame"); f;
           f = f->NextSiblingElement("PhysicalOffsetFrame")) {
        const std::string sp = Doc::text(f, "socket_parent");
        const Frame parent = (sp == ".." || sp.empty()) ? Frame{bn, Pose::Identity()} : resolve_frame(f, sp);
        Pose X = Pose::Identity();
        X.translation() = d_.vec3(f, "translation", Vec3::Zero());
        X.linear() = body_xyz(d_.vec3(f, "orientation", Vec3::Zero()));
        frames_["/bodyset/" + bn + "/" + Doc::trim(f->Attribute("name"))] = {parent.body, parent.X_BF * X};
      }
  }
  const XMLElement* js = Doc::child(Doc::child(model, "JointSet"), "objects");
  if (!js) d_.fail(model, "expected <JointSet><objects>, found none");
  for (const XMLElement* j = js->FirstChildElement(); j; j = j->NextSiblingElement()) read_joint(j);
}

void Importer::select_bodies() {
  auto knee = joints_.find(o_.knee_joint);
  if (knee == joints_.end()) d_.fail(model_, "knee joint '" + o_.knee_joint + "' not found in the JointSet");
  root_ = knee->second.parent_body;
  // Children per body.
  std::map<std::string, std::vector<std::string>> below;  // body -> joints
  std::map<std::string, std::string> above;                // body -> joint
  for (const auto& jn : joint_order_) {
    const JointInfo& j = joints_[jn];
    below[j.parent_body].push_back(jn);
    if (above.count(j.child_body)) d_.fail(model_, "body '" + j.child_body + "' is the child of two joints (a loop)");
    above[j.child_body] = jn;
  }
  // The root's subtree.
  std::vector<std::string> stack{root_};
  imported_.insert(root_);
  while (!stack.empty()) {
    const std::string b = stack.back();
    stack.pop_back();
    for (const auto& jn : below[b]) {
      imported_.insert(joints_[jn].child_body);
      stack.push_back(joints_[jn].child_body);
    }
  }
  // The chain up to the ground.
  for (std::string b = root_; b != "ground";) {
    auto it = above.find(b);
    if (it == above.end()) d_.fail(model_, "body '" + b + "' has no path to the ground");
    up_chain_.push_back(it->second);
    b = joints_[it->second].parent_body;
    imported_.insert(b);
  }
  // Bodies the knee's and the patellofemoral joint's coordinates move.
  std::function<void(const std::string&)> mark = [&](const std::string& b) {
    knee_side_.insert(b);
    for (const auto& jn : below[b]) mark(joints_[jn].child_body);
  };
  mark(knee->second.child_body);
  if (!o_.patellofemoral_joint.empty()) {
    auto pf = joints_.find(o_.patellofemoral_joint);
    if (pf == joints_.end())
      d_.fail(model_, "patellofemoral joint '" + o_.patellofemoral_joint + "' not found in the JointSet");
    if (pf->second.parent_body != root_)
      d_.fail(model_, "patellofemoral joint '" + o_.patellofemoral_joint + "': expected parent '" + root_ +
                          "' (the knee's parent), found '" + pf->second.parent_body + "'");
    mark(pf->second.child_body);
  }
  // Joints inside the imported tree must be representable.
  for (const auto& jn : joint_order_) {
    const JointInfo& j = joints_[jn];
    const bool in = imported_.count(j.child_body) && imported_.count(j.parent_body);
    if (in && !j.error.empty()) throw InputError(j.error);
    if (!in)
      note("joint", jn,
           "not on the imported leg (" + j.parent_body + " -> " + j.child_body + ")" +
               (j.error.empty() ? "" : "; it could not be represented anyway: " + j.error),
           j.line);
  }
  for (const auto& b : body_order_)
    if (!imported_.count(b))
      note("body", b, "not on the imported leg (its mass " + num(bodies_[b].mass) + " kg counts in the subject mass)",
           bodies_[b].line);
}

PathOut Importer::read_path(const XMLElement* gp, const std::string& owner, bool* on_imported,
                            std::set<std::string>* bodies) {
  PathOut p;
  *on_imported = true;
  const XMLElement* pts = Doc::child(Doc::child(gp, "PathPointSet"), "objects");
  if (!pts) d_.fail(gp, owner + ": expected <PathPointSet><objects>, found none");
  for (const XMLElement* e = pts->FirstChildElement(); e; e = e->NextSiblingElement()) {
    PathPointOut q;
    const std::string tag = e->Name();
    q.name = Doc::trim(e->Attribute("name"));
    q.line = e->GetLineNum();
    std::string sock = Doc::text(e, "socket_parent_frame");
    if (sock.empty()) sock = Doc::text(e, "body");  // OpenSim 3
    const Frame f = resolve_frame(e, sock);
    q.body = f.body;
    if (bodies) bodies->insert(f.body);
    if (!imported_.count(f.body)) *on_imported = false;
    auto coordinate_of = [&](const char* sock_tag, const char* old_tag) {
      std::string c = Doc::text(e, sock_tag);
      if (c.empty()) c = Doc::text(e, old_tag);
      c = leaf(c);
      if (c.empty() || !coords_.count(c)) d_.fail(e, owner + " point '" + q.name + "': unknown coordinate '" + c + "'");
      return c;
    };
    if (tag == "PathPoint") {
      q.kind = "point";
      q.p = f.X_BF * d_.vec3(e, "location");
    } else if (tag == "ConditionalPathPoint") {
      q.kind = "conditional_point";
      q.p = f.X_BF * d_.vec3(e, "location");
      q.coordinate = coordinate_of("socket_coordinate", "coordinate");
      const auto r = d_.numbers(e, "range", 2);
      q.lo = r[0];
      q.hi = r[1];
    } else if (tag == "MovingPathPoint") {
      q.kind = "moving_point";
      if (!f.X_BF.isApprox(Pose::Identity()))
        d_.fail(e, owner + " point '" + q.name + "': a MovingPathPoint on an offset frame cannot be represented");
      const char* comps[3] = {"x_location", "y_location", "z_location"};
      const char* socks[3] = {"socket_x_coordinate", "socket_y_coordinate", "socket_z_coordinate"};
      const char* olds[3] = {"x_coordinate", "y_coordinate", "z_coordinate"};
      for (int k = 0; k < 3; ++k) {
        q.moving[k] = function_of(d_, e, comps[k]);
        if (!q.moving[k]) d_.fail(e, owner + " point '" + q.name + "': expected <" + comps[k] + ">");
        q.moving_coordinate[k] = coordinate_of(socks[k], olds[k]);
      }
    } else {
      d_.fail(e, owner + ": path point type <" + tag + "> is not supported");
    }
    p.points.push_back(q);
  }
  if (const XMLElement* ws = Doc::child(Doc::child(gp, "PathWrapSet"), "objects"))
    for (const XMLElement* w = ws->FirstChildElement("PathWrap"); w; w = w->NextSiblingElement("PathWrap")) {
      PathWrapOut pw;
      pw.line = w->GetLineNum();
      pw.object = Doc::text(w, "wrap_object");
      pw.method = Doc::text(w, "method");
      std::vector<double> def = {-1, -1};
      const auto r = d_.numbers(w, "range", 2, &def);
      pw.first = static_cast<int>(r[0]);
      pw.last = static_cast<int>(r[1]);
      auto it = wraps_.find(pw.object);
      if (it == wraps_.end()) d_.fail(w, owner + ": unknown wrap object '" + pw.object + "'");
      if (!imported_.count(it->second.body)) *on_imported = false;
      p.wraps.push_back(pw);
    }
  return p;
}

void Importer::write_function(std::ostream& out, const Function& f) {
  if (f.tag == "Constant") {
    out << "<constant value=\"" << num(f.intercept) << "\"/>";
  } else if (f.tag == "LinearFunction") {
    out << "<linear_function coefficients=\"" << num(f.slope) << " " << num(f.intercept) << "\"/>";
  } else if (f.tag == "MultiplierFunction") {
    out << "<multiplier_function scale=\"" << num(f.scale) << "\">";
    write_function(out, *f.inner);
    out << "</multiplier_function>";
  } else {
    const std::string tag = f.tag == "SimmSpline"           ? "simm_spline"
                            : f.tag == "NaturalCubicSpline" ? "natural_cubic_spline"
                                                            : "piecewise_linear_function";
    out << "<" << tag << " x=\"";
    for (std::size_t i = 0; i < f.x.size(); ++i) out << (i ? " " : "") << num(f.x[i]);
    out << "\" y=\"";
    for (std::size_t i = 0; i < f.y.size(); ++i) out << (i ? " " : "") << num(f.y[i]);
    out << "\"/>";
  }
}

void Importer::write_path(std::ostream& out, const PathOut& p, const std::string& indent) {
  for (const auto& q : p.points) {
    if (q.kind == "point") {
      out << indent << "<point body=\"" << q.body << "\" xyz=\"" << vec(q.p) << "\"/>\n";
    } else if (q.kind == "conditional_point") {
      out << indent << "<conditional_point body=\"" << q.body << "\" xyz=\"" << vec(q.p) << "\" coordinate=\""
          << q.coordinate << "\" range=\"" << num(q.lo) << " " << num(q.hi) << "\"/>\n";
    } else {
      out << indent << "<moving_point body=\"" << q.body << "\">\n";
      const char* axes[3] = {"x", "y", "z"};
      for (int k = 0; k < 3; ++k) {
        out << indent << "  <" << axes[k] << " coordinate=\"" << q.moving_coordinate[k] << "\">";
        write_function(out, *q.moving[k]);
        out << "</" << axes[k] << ">\n";
      }
      out << indent << "</moving_point>\n";
    }
  }
  if (o_.without_wrapping) return;
  for (const auto& w : p.wraps) {
    out << indent << "<wrap object=\"" << w.object << "\"";
    if (w.first != -1 || w.last != -1) out << " range=\"" << w.first << " " << w.last << "\"";
    if (!w.method.empty()) out << " method=\"" << w.method << "\"";
    out << "/>\n";
    if (std::find(used_wraps_.begin(), used_wraps_.end(), w.object) == used_wraps_.end())
      used_wraps_.push_back(w.object);
  }
}

std::string Importer::find_mesh(const std::string& file) const {
  std::vector<fs::path> dirs = {osim_dir_ / "Geometry", osim_dir_};
  for (const auto& g : o_.geometry_dirs) dirs.emplace_back(g);
  for (const auto& d : dirs)
    if (fs::is_regular_file(d / file)) return (d / file).string();
  return "";
}

// Ligament group of a bundle: the name without trailing digits (MCLd1 -> MCLd).
std::string group_of(const std::string& name) {
  std::size_t e = name.size();
  while (e > 0 && std::isdigit(static_cast<unsigned char>(name[e - 1]))) --e;
  return e == 0 ? name : name.substr(0, e);
}

OsimImportSummary Importer::run(const std::string& out_dir) {
  std::ifstream in(d_.file, std::ios::binary);
  if (!in) throw InputError(d_.file, 0, "expected a readable .osim file, found none");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string xml = ss.str();
  osim_dir_ = fs::path(d_.file).parent_path();
  tinyxml2::XMLDocument doc;
  if (doc.Parse(xml.c_str(), xml.size()) != tinyxml2::XML_SUCCESS)
    throw InputError(d_.file, doc.ErrorLineNum(), std::string("expected well-formed XML: ") + doc.ErrorStr());
  const XMLElement* root = doc.RootElement();
  const XMLElement* model = root ? root->FirstChildElement("Model") : nullptr;
  if (!root || std::string(root->Name()) != "OpenSimDocument" || !model)
    throw InputError(d_.file, root ? root->GetLineNum() : 0,
                     "expected <OpenSimDocument><Model>, found " + std::string(root ? root->Name() : "nothing"));
  const int version = root->IntAttribute("Version", 0);
  if (version < 40000)
    throw InputError(d_.file, root->GetLineNum(),
                     "expected an OpenSim 4.x model (Version >= 40000), found Version " + std::to_string(version));
  read_model(model);
  select_bodies();

  OsimImportSummary sum;
  sum.model_name = model_name_;
  sum.subject_mass_kg = total_mass_;
  const fs::path out(out_dir);
  fs::create_directories(out / "Geometry");

  // ---- forces
  std::ostringstream ligaments, muscles, contacts, springs;
  std::map<std::string, std::vector<std::string>> groups;  // group -> bundle XML
  std::vector<std::string> group_order;
  std::map<std::string, const XMLElement*> contact_meshes;
  std::set<std::string> knee_coordinates;
  for (const auto& jn : {o_.knee_joint, o_.patellofemoral_joint})
    if (!jn.empty())
      for (const auto& c : joints_[jn].coordinates) knee_coordinates.insert(c);
  if (const XMLElement* cg = Doc::child(Doc::child(model, "ContactGeometrySet"), "objects"))
    for (const XMLElement* g = cg->FirstChildElement(); g; g = g->NextSiblingElement())
      contact_meshes[Doc::trim(g->Attribute("name"))] = g;
  std::set<std::string> used_meshes;
  struct SurfaceOut {
    std::string name, body, file;
    Pose X_BM;
    double E, nu, h;
  };
  std::map<std::string, SurfaceOut> surfaces;
  std::vector<std::string> surface_order;
  auto surface = [&](const XMLElement* at, const std::string& path) -> const SurfaceOut& {
    const std::string n = leaf(path);
    if (auto it = surfaces.find(n); it != surfaces.end()) return it->second;
    auto it = contact_meshes.find(n);
    if (it == contact_meshes.end()) d_.fail(at, "unknown contact mesh '" + path + "'");
    const XMLElement* g = it->second;
    const std::string type = g->Name();
    if (type != "Smith2018ContactMesh")
      d_.fail(g, "contact geometry '" + n + "' of type " + type + " is not supported (expected Smith2018ContactMesh)");
    if (d_.flag(g, "use_variable_thickness", false))
      d_.fail(Doc::child(g, "use_variable_thickness"),
              "contact mesh '" + n + "': variable thickness (from the back mesh) is not supported; give a "
              "uniform thickness or prepare the cartilage with arthrosim-prepare");
    const Vec3 sc = d_.vec3(g, "scale_factors", Vec3::Ones());
    if ((sc - Vec3::Ones()).norm() > 1e-12)
      d_.fail(Doc::child(g, "scale_factors"), "contact mesh '" + n + "': expected scale_factors 1 1 1, found " + vec(sc));
    const Frame f = resolve_frame(g, Doc::text(g, "socket_frame"));
    if (!imported_.count(f.body)) d_.fail(g, "contact mesh '" + n + "' lies on body '" + f.body + "', not imported");
    SurfaceOut s;
    s.name = n;
    s.body = f.body;
    Pose X = Pose::Identity();
    X.translation() = d_.vec3(g, "location", Vec3::Zero());
    X.linear() = body_xyz(d_.vec3(g, "orientation", Vec3::Zero()));
    s.X_BM = f.X_BF * X;
    s.E = d_.number(g, "elastic_modulus", 1e6);
    s.nu = d_.number(g, "poissons_ratio", 0.5);
    s.h = d_.number(g, "thickness", 0.005);
    const std::string mesh = Doc::text(g, "mesh_file");
    const std::string found = find_mesh(mesh);
    if (found.empty())
      d_.fail(g, "contact mesh '" + n + "': mesh file '" + mesh + "' not found in " + (osim_dir_ / "Geometry").string() +
                     ", " + osim_dir_.string() + " or the --geometry folders");
    if (fs::file_size(found) == 0) d_.fail(g, "contact mesh '" + n + "': mesh file " + found + " is empty (0 bytes)");
    s.file = mesh;
    used_meshes.insert(mesh);
    const std::string back = Doc::text(g, "mesh_back_file");
    if (!back.empty())
      note("contact mesh", n, "mesh_back_file '" + back + "' is used by OpenSim-JAM only for variable thickness (off here); "
                              "the bone mesh is imported as the body's visual if found", g->GetLineNum());
    surfaces[n] = s;
    surface_order.push_back(n);
    return surfaces[n];
  };

  const XMLElement* fs_objects = Doc::child(Doc::child(model, "ForceSet"), "objects");
  for (const XMLElement* f = fs_objects ? fs_objects->FirstChildElement() : nullptr; f; f = f->NextSiblingElement()) {
    const std::string type = f->Name();
    const std::string name = Doc::trim(f->Attribute("name"));
    const int line = f->GetLineNum();
    if (!d_.flag(f, "appliesForce", true)) {
      note(type, name, "appliesForce is false (not imported)", line);
      continue;
    }
    const bool muscle = type.size() >= 6 && type.compare(type.size() - 6, 6, "Muscle") == 0;
    if (type == "Blankevoort1991Ligament") {
      bool on = false;
      std::set<std::string> bodies;
      const XMLElement* gp = Doc::child(f, "GeometryPath");
      if (!gp) d_.fail(f, "ligament '" + name + "': expected a <GeometryPath>");
      const PathOut p = read_path(gp, "ligament '" + name + "'", &on, &bodies);
      if (!on) {
        note(type, name, "its path leaves the imported leg", line);
        continue;
      }
      const double k = d_.number(f, "linear_stiffness", 1.0);
      const double et = d_.number(f, "transition_strain", 0.06);
      const double c = d_.number(f, "damping_coefficient", 0.003);
      const double l0 = d_.number(f, "slack_length", 0.0);
      if (!(k > 0) || !(et > 0) || !(c >= 0) || !(l0 > 0))
        d_.fail(f, "ligament '" + name + "': expected linear_stiffness > 0, transition_strain > 0, "
                   "damping_coefficient >= 0 and slack_length > 0");
      std::ostringstream b;
      b << "    <bundle name=\"" << name << "\" stiffness=\"" << num(k) << "\" transition_strain=\"" << num(et)
        << "\" damping=\"" << num(c) << "\" slack_length=\"" << num(l0) << "\">\n";
      write_path(b, p, "      ");
      b << "    </bundle>\n";
      const std::string g = group_of(name);
      if (!groups.count(g)) group_order.push_back(g);
      groups[g].push_back(b.str());
      ++sum.ligament_bundles;
      sum.path_wraps += o_.without_wrapping ? 0 : static_cast<int>(p.wraps.size());
    } else if (muscle) {
      bool on = false;
      std::set<std::string> bodies;
      const XMLElement* gp = Doc::child(f, "GeometryPath");
      if (!gp) d_.fail(f, "muscle '" + name + "': expected a <GeometryPath>");
      const PathOut p = read_path(gp, "muscle '" + name + "'", &on, &bodies);
      bool knee_side = false, other_side = false;
      for (const auto& b : bodies) (knee_side_.count(b) ? knee_side : other_side) = true;
      const bool crosses = knee_side && other_side;
      if (!on || (o_.muscles == ImportMuscles::kKnee && !crosses)) {
        note(type, name,
             !on ? "its path leaves the imported leg" : "does not cross the knee or the patellofemoral joint "
                                                        "(import with muscles = leg to include it)",
             line);
        continue;
      }
      const double fmax = d_.number(f, "max_isometric_force");
      const double lopt = d_.number(f, "optimal_fiber_length");
      const double lts = d_.number(f, "tendon_slack_length");
      const double penn = d_.number(f, "pennation_angle_at_optimal", 0.0);
      if (!(fmax > 0) || !(lopt > 0) || !(lts > 0))
        d_.fail(f, "muscle '" + name + "': expected max_isometric_force, optimal_fiber_length and "
                   "tendon_slack_length > 0");
      muscles << "  <arthrosim:muscle name=\"" << name << "\" type=\"" << type << "\" max_isometric_force=\""
              << num(fmax) << "\" optimal_fiber_length=\"" << num(lopt) << "\" tendon_slack_length=\"" << num(lts)
              << "\" pennation_angle=\"" << num(penn) << "\">\n";
      write_path(muscles, p, "    ");
      muscles << "  </arthrosim:muscle>\n";
      ++sum.muscles;
      sum.path_wraps += o_.without_wrapping ? 0 : static_cast<int>(p.wraps.size());
    } else if (type == "Smith2018ArticularContactForce") {
      const SurfaceOut& target = surface(f, Doc::text(f, "socket_target_mesh"));
      const SurfaceOut& casting = surface(f, Doc::text(f, "socket_casting_mesh"));
      const double pmin = d_.number(f, "min_proximity", 0.0);
      const double pmax = d_.number(f, "max_proximity", 0.01);
      if (pmin != 0.0)
        d_.fail(Doc::child(f, "min_proximity"), "contact '" + name + "': expected min_proximity 0, found " + num(pmin));
      std::string law = Doc::text(f, "elastic_foundation_formulation");
      if (law.empty()) law = "linear";
      if (law != "linear" && law != "nonlinear")
        d_.fail(f, "contact '" + name + "': expected elastic_foundation_formulation linear or nonlinear, found '" + law + "'");
      const bool lumped = d_.flag(f, "use_lumped_contact_model", true);
      if (!lumped && (casting.E != target.E || casting.nu != target.nu))
        d_.fail(f, "contact '" + name + "': the non-lumped model with different materials on the two meshes "
                   "cannot be represented (arthrosim's pair has one material)");
      // Lumped (OpenSim-JAM): mean E and nu, summed thickness; equal
      // materials make the non-lumped model the same springs in series.
      const double E = 0.5 * (casting.E + target.E), nu = 0.5 * (casting.nu + target.nu);
      contacts << "  <arthrosim:contact name=\"" << name << "\" casting=\"" << casting.name << "\" target=\""
               << target.name << "\" youngs_modulus_mpa=\"" << num(E * 1e-6) << "\" poisson_ratio=\"" << num(nu)
               << "\" law=\"" << law << "\" max_overlap_factor=\"" << num(pmax / (casting.h + target.h))
               << "\"/>  <!-- max_proximity " << num(pmax) << " m -->\n";
      ++sum.contacts;
    } else if (type == "SpringGeneralizedForce") {
      const std::string c = Doc::text(f, "coordinate");
      if (!coords_.count(c)) d_.fail(f, "SpringGeneralizedForce '" + name + "': unknown coordinate '" + c + "'");
      const Coordinate& co = coords_[c];
      const JointInfo& j = joints_[co.joint];
      if (!imported_.count(j.child_body) || !imported_.count(j.parent_body)) {
        note(type, name, "acts on coordinate '" + c + "', not imported", line);
        continue;
      }
      springs << "  <arthrosim:coordinate_spring name=\"" << name << "\" joint=\"" << c << "\" stiffness=\""
              << num(d_.number(f, "stiffness", 0.0)) << "\" rest_length=\"" << num(d_.number(f, "rest_length", 0.0))
              << "\" viscosity=\"" << num(d_.number(f, "viscosity", 0.0)) << "\"/>\n";
      ++sum.coordinate_springs;
    } else {
      note(type, name, "force type not supported by the importer (not imported)", line);
    }
  }
  for (const auto& [n, g] : contact_meshes)
    if (!surfaces.count(n)) note(g->Name(), n, "not used by an imported contact force", g->GetLineNum());

  // ---- roles, prescribed and free coordinates
  const JointInfo& knee = joints_[o_.knee_joint];
  std::string flexion = o_.knee_flexion;
  if (flexion.empty()) {
    if (knee.rotation_coordinates.empty())
      throw InputError(d_.file, knee.line, "knee joint '" + knee.name + "': no rotational coordinate for the flexion");
    flexion = knee.rotation_coordinates[0];
  } else if (std::find(knee.coordinates.begin(), knee.coordinates.end(), flexion) == knee.coordinates.end()) {
    throw InputError(d_.file, knee.line, "knee flexion '" + flexion + "' is not a coordinate of '" + knee.name + "'");
  }
  std::vector<std::pair<std::string, std::string>> coordinate_roles = {{"knee_flexion", flexion}};
  std::vector<std::pair<std::string, std::string>> body_roles = {
      {"femur", root_}, {"tibia", knee.child_body}, {"ground", "ground"}};
  if (!o_.patellofemoral_joint.empty()) {
    const JointInfo& pf = joints_[o_.patellofemoral_joint];
    body_roles.push_back({"patella", pf.child_body});
    if (!pf.rotation_coordinates.empty()) coordinate_roles.push_back({"pf_flexion", pf.rotation_coordinates[0]});
  }
  // Hip: the first joint with coordinates above the root; ankle: below the tibia.
  for (const auto& jn : up_chain_) {
    const JointInfo& j = joints_[jn];
    if (j.coordinates.empty()) continue;
    if (j.rotation_coordinates.size() == 3) {
      coordinate_roles.push_back({"hip_flexion", j.rotation_coordinates[0]});
      coordinate_roles.push_back({"hip_adduction", j.rotation_coordinates[1]});
      coordinate_roles.push_back({"hip_rotation", j.rotation_coordinates[2]});
    }
    break;
  }
  for (std::string b = knee.child_body;;) {
    const JointInfo* next = nullptr;
    for (const auto& jn : joint_order_)
      if (joints_[jn].parent_body == b && jn != o_.patellofemoral_joint) {
        next = &joints_[jn];
        break;
      }
    if (!next) break;
    if (!next->rotation_coordinates.empty()) {
      coordinate_roles.push_back({"ankle_flexion", next->rotation_coordinates[0]});
      break;
    }
    b = next->child_body;
  }

  // ---- URDF
  std::ostringstream u;
  u << "<?xml version=\"1.0\"?>\n"
    << "<!-- Imported by `arthrosim import-osim` from " << xml_escape(fs::path(d_.file).filename().string())
    << " (OpenSim model '" << xml_escape(model_name_) << "'); do not edit by hand, re-import instead.\n"
    << "     What was and was not imported: import_report.md. Format: docs/model_format.md, docs/import.md. -->\n"
    << "<robot name=\"" << xml_escape(model_name_) << "\" xmlns:arthrosim=\"https://arthrosim.invalid/model\">\n";
  // Links: imported bodies, then the massless links inside joint chains.
  std::vector<std::string> links;
  std::ostringstream joints_xml;
  std::set<std::string> link_names;
  auto add_link = [&](const std::string& n) {
    if (!link_names.insert(n).second)
      throw InputError(d_.file, 0, "link name '" + n + "' would be used twice (rename the body or joint)");
    links.push_back(n);
  };
  for (const auto& b : body_order_)
    if (imported_.count(b)) add_link(b);
  if (imported_.count("ground")) add_link("ground");
  int coordinates = 0;
  // Emits a joint's chain of elements from link `from` to link `to`.
  auto emit_chain = [&](const std::string& jname, const std::vector<Element>& els, const std::string& from,
                        const std::string& to) {
    Pose pending = Pose::Identity();
    std::string current = from;
    int fixed_k = 0;
    // Index of the last movable element: after it, the pending fixed
    // transform becomes the joint to `to`.
    int last_movable = -1;
    for (int i = 0; i < static_cast<int>(els.size()); ++i)
      if (els[i].kind != Element::kFixed) last_movable = i;
    for (int i = 0; i < static_cast<int>(els.size()); ++i) {
      const Element& e = els[i];
      if (e.kind == Element::kFixed) {
        pending = pending * e.X;
        continue;
      }
      // Any fixed transforms after the last movable one go into a fixed joint.
      bool trailing_fixed = false;
      for (int k = i + 1; k < static_cast<int>(els.size()); ++k)
        if (!els[k].X.isApprox(Pose::Identity(), 1e-15)) trailing_fixed = true;
      const bool last = i == last_movable;
      const std::string child = last && !trailing_fixed ? to : jname + "__" + e.coordinate;
      if (child != to) add_link(child);
      const Coordinate& co = coords_[e.coordinate];
      joints_xml << "  <joint name=\"" << e.coordinate << "\" type=\""
                 << (e.kind == Element::kRevolute ? "revolute" : "prismatic") << "\">\n"
                 << "    <parent link=\"" << current << "\"/>\n    <child link=\"" << child << "\"/>\n    "
                 << origin(pending) << "\n    <axis xyz=\"" << vec(e.axis) << "\"/>\n"
                 << "    <limit lower=\"" << num(co.lower) << "\" upper=\"" << num(co.upper)
                 << "\" effort=\"0\" velocity=\"0\"/>\n  </joint>\n";
      ++coordinates;
      pending = Pose::Identity();
      current = child;
    }
    if (current != to) {
      joints_xml << "  <joint name=\"" << jname << "__fixed" << fixed_k++ << "\" type=\"fixed\">\n"
                 << "    <parent link=\"" << current << "\"/>\n    <child link=\"" << to << "\"/>\n    "
                 << origin(pending) << "\n  </joint>\n";
    }
  };
  // Root's subtree (forward) and the chain to the ground (reversed).
  for (const auto& jn : joint_order_) {
    const JointInfo& j = joints_[jn];
    if (!imported_.count(j.child_body) || !imported_.count(j.parent_body)) continue;
    if (std::find(up_chain_.begin(), up_chain_.end(), jn) != up_chain_.end()) continue;
    joints_xml << "  <!-- " << j.type << " '" << jn << "' (line " << j.line << "): " << j.parent_body << " -> "
               << j.child_body << " -->\n";
    emit_chain(jn, j.elements, j.parent_body, j.child_body);
  }
  for (const auto& jn : up_chain_) {
    const JointInfo& j = joints_[jn];
    joints_xml << "  <!-- " << j.type << " '" << jn << "' (line " << j.line << ") reversed: " << j.child_body
               << " -> " << j.parent_body << " (inverse transforms, negated axes, same coordinates) -->\n";
    emit_chain(jn + "__reversed", inverse(j.elements), j.child_body, j.parent_body);
  }
  sum.coordinates = coordinates;

  // Visual meshes of imported bodies: copied when arthrosim can read them.
  std::map<std::string, std::vector<std::string>> visuals;  // body -> file names
  for (const auto& bn : body_order_) {
    if (!imported_.count(bn)) continue;
    for (const Mesh& m : bodies_[bn].meshes) {
      const std::string ext = fs::path(m.file).extension().string();
      std::string lower = ext;
      std::transform(lower.begin(), lower.end(), lower.begin(), ::tolower);
      const std::string found = find_mesh(m.file);
      const bool readable = lower == ".stl" || lower == ".obj" || lower == ".ply";
      if (!readable || found.empty() || fs::file_size(found) == 0 || (m.scale - Vec3::Ones()).norm() > 1e-12) {
        note("visual mesh", bn + "/" + m.name,
             !readable ? "'" + m.file + "': format not read by arthrosim (visual only, not copied)"
             : found.empty() ? "'" + m.file + "' not found (visual only)"
             : fs::file_size(found) == 0 ? "'" + m.file + "' is empty (0 bytes; visual only)"
                                         : "'" + m.file + "' is scaled by " + vec(m.scale) + " (visual only, not copied)",
             m.line);
        continue;
      }
      used_meshes.insert(m.file);
      visuals[bn].push_back(m.file);
    }
  }
  for (const auto& m : used_meshes) {
    const std::string found = find_mesh(m);
    const fs::path to = out / "Geometry" / m;
    if (!fs::exists(to) || !fs::equivalent(found, to)) fs::copy_file(found, to, fs::copy_options::overwrite_existing);
    sum.copied_meshes.push_back(m);
  }
  for (const auto& l : links) {
    u << "  <link name=\"" << l << "\">\n";
    if (bodies_.count(l) && bodies_[l].mass > 0) {
      const BodyInfo& b = bodies_[l];
      u << "    <inertial>\n      <origin xyz=\"" << vec(b.com) << "\"/>\n      <mass value=\"" << num(b.mass)
        << "\"/>\n      <inertia ixx=\"" << num(b.inertia[0]) << "\" iyy=\"" << num(b.inertia[1]) << "\" izz=\""
        << num(b.inertia[2]) << "\" ixy=\"" << num(b.inertia[3]) << "\" ixz=\"" << num(b.inertia[4])
        << "\" iyz=\"" << num(b.inertia[5]) << "\"/>\n    </inertial>\n";
    }
    for (const auto& v : visuals[l])
      u << "    <visual><geometry><mesh filename=\"Geometry/" << v << "\" scale=\"1 1 1\"/></geometry></visual>\n";
    u << "  </link>\n";
  }
  u << joints_xml.str();
  sum.links = static_cast<int>(links.size());
  for (const auto& b : imported_) (void)b;
  sum.bodies = static_cast<int>(imported_.size());

  // ---- extension elements
  u << "  <arthrosim:subject mass_kg=\"" << num(total_mass_) << "\"/>  <!-- all "
    << body_order_.size() << " bodies of " << xml_escape(fs::path(d_.file).filename().string()) << " -->\n";
  std::set<std::string> free;
  for (const auto& jn : {o_.knee_joint, o_.patellofemoral_joint})
    if (!jn.empty())
      for (const auto& c : joints_[jn].coordinates) free.insert(c);
  sum.free_coordinates = static_cast<int>(free.size());
  std::ostringstream defaults;
  for (const auto& [n, co] : coords_) {
    const JointInfo& j = joints_[co.joint];
    if (!imported_.count(j.child_body) || !imported_.count(j.parent_body)) continue;
    if (!free.count(n)) u << "  <arthrosim:prescribed joint=\"" << n << "\"/>\n";
    else if (co.locked)
      throw InputError(d_.file, co.line, "coordinate '" + n + "' of the knee is locked (a free coordinate cannot be)");
    if (co.default_value != 0.0)
      defaults << "  <arthrosim:default joint=\"" << n << "\" value=\"" << num(co.default_value) << "\"/>\n";
  }
  u << defaults.str();
  for (const auto& [role, c] : coordinate_roles)
    u << "  <arthrosim:role name=\"" << role << "\" joint=\"" << c << "\"/>\n";
  for (const auto& [role, b] : body_roles) u << "  <arthrosim:role name=\"" << role << "\" link=\"" << b << "\"/>\n";
  u << springs.str();
  // Wrap objects used by imported paths, in first-use order.
  for (const auto& wn : used_wraps_) {
    const WrapObject& w = wraps_[wn];
    if (!w.active) {
      throw InputError(d_.file, w.line, "wrap object '" + wn + "' is inactive but used by an imported path");
    }
    const std::string tag = w.kind == "WrapCylinder"    ? "wrap_cylinder"
                            : w.kind == "WrapEllipsoid" ? "wrap_ellipsoid"
                            : w.kind == "WrapSphere"    ? "wrap_sphere"
                                                        : "wrap_torus";
    u << "  <arthrosim:" << tag << " name=\"" << wn << "\" body=\"" << w.body << "\" xyz=\"" << vec(w.translation)
      << "\" xyz_body_rotation=\"" << vec(w.rotation) << "\"";
    if (w.kind == "WrapCylinder") u << " radius=\"" << num(w.radius) << "\" length=\"" << num(w.length) << "\"";
    if (w.kind == "WrapEllipsoid") u << " dimensions=\"" << vec(w.dimensions) << "\"";
    if (w.kind == "WrapSphere") u << " radius=\"" << num(w.radius) << "\"";
    if (w.kind == "WrapTorus") u << " inner_radius=\"" << num(w.inner) << "\" outer_radius=\"" << num(w.outer) << "\"";
    u << " quadrant=\"" << w.quadrant << "\"/>\n";
    ++sum.wrap_objects[w.kind];
  }
  for (const auto& [wn, w] : wraps_) {
    if (std::find(used_wraps_.begin(), used_wraps_.end(), wn) != used_wraps_.end()) continue;
    note(w.kind, wn,
         o_.without_wrapping ? "omitted on request (--without-wrapping)" : "not used by an imported path", w.line);
  }
  // One tibial cartilage mesh holds both plateaus: its compartments are told
  // apart along the medial-lateral direction (docs/model_format.md,
  // split_lateral). OpenSim's body frames have Z to the subject's right, so
  // lateral is +Z for a right knee and -Z for a left one (the knee joint's
  // suffix _r / _l); no attribute when the side is not known.
  int tibial_surfaces = 0;
  for (const auto& sn : surface_order) tibial_surfaces += surfaces[sn].body == knee.child_body;
  const std::string& kj = o_.knee_joint;
  const std::string lateral = kj.size() > 2 && kj.compare(kj.size() - 2, 2, "_r") == 0   ? "+z"
                              : kj.size() > 2 && kj.compare(kj.size() - 2, 2, "_l") == 0 ? "-z"
                                                                                          : "";
  for (const auto& sn : surface_order) {
    const SurfaceOut& s = surfaces[sn];
    Vec3 rpy = rpy_of(s.X_BM.linear());
    u << "  <arthrosim:surface name=\"" << sn << "\" body=\"" << s.body << "\" mesh=\"Geometry/" << s.file
      << "\" unit=\"m\" thickness_mm=\"" << num(s.h * 1e3) << "\"";
    if (!s.X_BM.isApprox(Pose::Identity(), 1e-15))
      u << " xyz=\"" << vec(s.X_BM.translation()) << "\" rpy=\"" << vec(rpy) << "\"";
    if (s.body == knee.child_body && tibial_surfaces == 1 && !lateral.empty())
      u << " split_lateral=\"" << lateral << "\"";
    u << "/>\n";
    ++sum.surfaces;
  }
  u << contacts.str();
  for (const auto& g : group_order) {
    u << "  <arthrosim:ligament name=\"" << g << "\">\n";
    for (const auto& b : groups[g]) u << b;
    u << "  </arthrosim:ligament>\n";
  }
  sum.ligament_groups = static_cast<int>(group_order.size());
  u << muscles.str();
  u << "</robot>\n";

  // Elements of the model not looked at above.
  for (const char* set : {"MarkerSet", "ControllerSet", "ConstraintSet", "ProbeSet", "ComponentSet"}) {
    const XMLElement* s = Doc::child(Doc::child(model, set), "objects");
    int n = 0;
    for (const XMLElement* e = s ? s->FirstChildElement() : nullptr; e; e = e->NextSiblingElement()) ++n;
    if (n == 0) continue;
    if (std::string(set) == "ConstraintSet")
      throw InputError(d_.file, s->GetLineNum(),
                       "the model has " + std::to_string(n) + " constraints; arthrosim's tree cannot represent them");
    note(set, std::to_string(n) + " objects",
         std::string(set) == "MarkerSet" ? "markers are for inverse kinematics, which stays OpenSim's job"
                                         : "not imported",
         s->GetLineNum());
  }

  const std::string urdf = o_.urdf_name.empty() ? model_name_ + ".urdf" : o_.urdf_name;
  sum.urdf_path = (out / urdf).string();
  std::ofstream(sum.urdf_path) << u.str();

  // ---- report
  sum.not_imported = static_cast<int>(report_.size());
  sum.report_path = (out / "import_report.md").string();
  std::ofstream r(sum.report_path);
  r << "# Import report: " << fs::path(d_.file).filename().string() << " -> " << urdf << "\n\n"
    << "Written by `arthrosim import-osim` (musculoskeletal/osim_import.h; method: docs/import.md).\n\n"
    << "## Imported\n\n"
    << "- model '" << model_name_ << "', subject mass " << num(total_mass_) << " kg (all " << body_order_.size()
    << " bodies)\n"
    << "- root body (the knee joint's parent): " << root_ << "\n"
    << "- " << sum.bodies << " bodies (incl. ground), " << sum.links << " URDF links, " << sum.coordinates
    << " coordinates (" << sum.free_coordinates << " free: the knee's and the patellofemoral joint's)\n"
    << "- " << sum.ligament_bundles << " ligament bundles in " << sum.ligament_groups << " groups, " << sum.muscles
    << " muscles (" << (o_.muscles == ImportMuscles::kKnee ? "crossing the knee" : "every muscle on the leg")
    << "), " << sum.path_wraps << " path wraps\n";
  for (const auto& [k, n] : sum.wrap_objects) r << "- " << n << " " << k << "\n";
  r << "- " << sum.surfaces << " contact surfaces, " << sum.contacts << " contact pairs, " << sum.coordinate_springs
    << " coordinate springs\n"
    << "- roles:";
  for (const auto& [role, c] : coordinate_roles) r << " " << role << " = " << c << ";";
  for (const auto& [role, b] : body_roles) r << " " << role << " = " << b << ";";
  r << "\n- meshes copied to Geometry/:";
  for (const auto& m : sum.copied_meshes) r << " " << m;
  r << "\n\n## Not imported (" << report_.size() << ")\n\n| line | element | name | why |\n| --- | --- | --- | --- |\n";
  for (const auto& e : report_)
    r << "| " << (e.line > 0 ? std::to_string(e.line) : "") << " | " << e.what << " | " << e.name << " | " << e.why
      << " |\n";
  return sum;
}

}  // namespace

OsimImportSummary import_osim(const std::string& osim_path, const std::string& out_dir,
                              const OsimImportOptions& options) {
  Importer im(osim_path, options);
  return im.run(out_dir);
}

}  // namespace arthrosim::musculoskeletal
