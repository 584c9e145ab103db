#include "shockwave/knee_model.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>

#include "common/error.h"
#include "common/spatial.h"
#include "shockwave/containment.h"

namespace arthrosim::shockwave {

namespace {

std::string mm(double v) {
  std::ostringstream s;
  s.precision(4);
  s << v * 1e3 << " mm";
  return s.str();
}

int face_axis(BoxFace f) { return (f == BoxFace::kMinusX || f == BoxFace::kPlusX) ? 0 : 2; }
double face_sign(BoxFace f) { return (f == BoxFace::kMinusX || f == BoxFace::kMinusZ) ? -1.0 : 1.0; }

// Largest vertical extent of a closed mesh, sampled on a 1 mm grid of
// vertical rays (each in-out interval measured).
double max_vertical_extent(const common::TriangleMesh& mesh) {
  const common::TriangleTree tree(mesh);
  const common::BoundingBox b = common::bounding_box(mesh);
  const double step = 1e-3;
  double best = 0.0;
  for (double x = b.lo.x() + 0.5 * step; x < b.hi.x(); x += step)
    for (double z = b.lo.z() + 0.5 * step; z < b.hi.z(); z += step) {
      common::Vec3 o(x, b.hi.y() + 1e-3, z);
      const common::Vec3 dir(0, -1, 0);
      double t = 0.0, entered = -1.0;
      const double length = b.hi.y() - b.lo.y() + 2e-3;
      while (t < length) {
        const auto hit = tree.first_hit(o + t * dir, dir, length - t);
        if (!hit) break;
        const double th = t + hit->distance;
        if (entered < 0.0) {
          entered = th;
        } else {
          best = std::max(best, th - entered);
          entered = -1.0;
        }
        t = th + 1e-9;
      }
    }
  return best;
}

// Thickness of a cartilage patch: the given values, else the distance from
// each vertex along its inward normal to the bone.
double max_thickness(const CartilageSurface& c, const common::TriangleTree& bone) {
  if (c.thickness.size() > 0) return c.thickness.maxCoeff();
  const common::Points3 n = common::vertex_normals(c.articular);
  double best = 0.0;
  for (int v = 0; v < c.articular.num_vertices(); ++v) {
    const auto hit = bone.first_hit(c.articular.vertex(v), -n.row(v).transpose(), 20e-3);
    if (hit) best = std::max(best, hit->distance);
  }
  return best;
}

}  // namespace

const char* knee_tissue_name(int t) {
  static const char* names[] = {"cortical", "cancellous", "cartilage", "fibrocartilage",
                                "fibrous", "capsule_shell", "applicator"};
  return (t >= 0 && t < kKneeTissueCount) ? names[t] : "?";
}

std::string to_string(BoxFace f) {
  switch (f) {
    case BoxFace::kMinusX: return "-x";
    case BoxFace::kPlusX: return "+x";
    case BoxFace::kMinusZ: return "-z";
    case BoxFace::kPlusZ: return "+z";
  }
  return "?";
}

BoxFace parse_box_face(const std::string& text, const std::string& source) {
  if (text == "-x") return BoxFace::kMinusX;
  if (text == "+x" || text == "x") return BoxFace::kPlusX;
  if (text == "-z") return BoxFace::kMinusZ;
  if (text == "+z" || text == "z") return BoxFace::kPlusZ;
  throw common::InputError(source, 0, "expected an applicator face '-x', '+x', '-z' or '+z', found '" + text + "'");
}

std::vector<Tissue> default_knee_tissues() {
  return {cortical_bone(), cancellous_bone(), cartilage(), fibrocartilage(), fibrous_tissue(), capsule_shell(), copper()};
}

Model build_knee_model(const KneeMeshes& meshes, const KneeModelOptions& o, KneeModelInfo* info_out,
                       const std::string& source) {
  auto fail = [&](const std::string& message) { throw common::InputError(source, 0, message); };
  const double d = o.diameter;
  if (!(d >= 0.3e-3 && d <= 5e-3)) fail("expected an automaton diameter in [0.3, 5] mm, found " + mm(d));
  if (!(o.femur_cut > 0.0) || !(o.tibia_cut > 0.0)) fail("expected positive femur and tibia cut distances");
  if (!(o.capsule_margin >= 0.0)) fail("expected a capsule margin >= 0, found " + mm(o.capsule_margin));
  if (meshes.femur.num_triangles() == 0 || meshes.tibia.num_triangles() == 0)
    fail("expected closed femur and tibia surfaces, found an empty mesh");
  std::vector<Tissue> tissues = o.tissues.empty() ? default_knee_tissues() : o.tissues;
  if (static_cast<int>(tissues.size()) != kKneeTissueCount)
    fail("expected " + std::to_string(kKneeTissueCount) + " knee tissues, found " + std::to_string(tissues.size()));
  const ApplicatorOptions& ap = o.applicator;
  if (!(ap.size > 0.0 && ap.size <= 0.1)) fail("expected an applicator size in (0, 100] mm, found " + mm(ap.size));
  if (!(ap.thickness > 0.0 && ap.thickness <= 0.01))
    fail("expected an applicator thickness in (0, 10] mm, found " + mm(ap.thickness));

  // Thickness checks: one automaton must fit in every tissue.
  auto check_thickness = [&](const std::string& what, double thickness) {
    if (d > thickness)
      fail("the automaton diameter " + mm(d) + " exceeds the " + what + " thickness " + mm(thickness) +
           ": that tissue cannot be resolved; use automata of at most " + mm(thickness));
  };
  check_thickness("cortical shell", o.cortical_thickness);
  check_thickness("capsule shell", o.shell_thickness);
  const LineContainment femur(meshes.femur), tibia(meshes.tibia);
  double cart_max = 0.0;
  for (const CartilageSurface& c : meshes.cartilage)
    cart_max = std::max(cart_max, max_thickness(c, c.bone == BoneId::kFemur ? femur.tree() : tibia.tree()));
  if (!meshes.cartilage.empty()) check_thickness("thickest cartilage", cart_max);
  double men_max = 0.0;
  for (const auto& [name, mesh] : meshes.menisci) men_max = std::max(men_max, max_vertical_extent(mesh));
  if (!meshes.menisci.empty()) check_thickness("highest meniscus", men_max);

  // Joint line.
  double joint = o.joint_line;
  if (!std::isfinite(joint)) {
    double sum = 0.0;
    int n = 0;
    for (const CartilageSurface& c : meshes.cartilage)
      if (c.bone == BoneId::kTibia)
        for (int v = 0; v < c.articular.num_vertices(); ++v) {
          sum += c.articular.V(v, 1);
          ++n;
        }
    joint = n > 0 ? sum / n : 0.5 * (meshes.femur.V.col(1).minCoeff() + meshes.tibia.V.col(1).maxCoeff());
  }
  const double ylo = joint - o.tibia_cut, yhi = joint + o.femur_cut;

  // Capsule box: the extent of everything between the cuts, plus the margin
  // and the shell.
  common::Vec3 lo = common::Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  auto include = [&](const common::TriangleMesh& m) {
    for (int v = 0; v < m.num_vertices(); ++v) {
      const common::Vec3 p = m.vertex(v);
      if (p.y() < ylo || p.y() > yhi) continue;
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  };
  include(meshes.femur);
  include(meshes.tibia);
  for (const auto& c : meshes.cartilage) include(c.articular);
  for (const auto& [name, m] : meshes.menisci) include(m);
  const double pad = o.capsule_margin + o.shell_thickness;
  lo.x() -= pad;
  lo.z() -= pad;
  hi.x() += pad;
  hi.z() += pad;
  lo.y() = ylo;
  hi.y() = yhi;

  // Applicator placement.
  const Lattice lat = make_lattice(o.lattice, d);
  const double h = lat.spacing;
  const int axis = face_axis(ap.face);
  const double sign = face_sign(ap.face);
  const int layers = std::max(1, static_cast<int>(std::lround(ap.thickness / h)));
  tissues[kApplicator].density *= ap.thickness / (layers * h);
  common::Vec3 centre = ap.centre;
  if (!centre.allFinite()) {
    centre = common::Vec3(0.5 * (lo.x() + hi.x()), joint, 0.5 * (lo.z() + hi.z()));
    for (const auto& [name, m] : meshes.menisci)
      if (name.find("medial") != std::string::npos) centre = m.V.colwise().mean().transpose();
  }
  const int u_axis = axis == 0 ? 2 : 0;  // the horizontal in-face axis
  const double half = 0.5 * ap.size;
  if (centre[u_axis] - half < lo[u_axis] || centre[u_axis] + half > hi[u_axis] || centre.y() - half < lo.y() ||
      centre.y() + half > hi.y())
    fail("the applicator (centre " + mm(centre[u_axis]) + ", " + mm(centre.y()) + " on face " + to_string(ap.face) +
         ", " + mm(ap.size) + " square) lies outside the capsule face (" + mm(lo[u_axis]) + " .. " + mm(hi[u_axis]) +
         " by " + mm(lo.y()) + " .. " + mm(hi.y()) + ")");

  // Grid: the box, plus the applicator's layers outside its face.
  GridSpec g;
  g.origin = lo;
  for (int a = 0; a < 3; ++a) g.count[a] = static_cast<int>(std::floor((hi[a] - lo[a]) / h + 1e-9)) + 1;
  if (sign < 0.0) g.origin[axis] -= layers * h;
  g.count[axis] += layers;
  const common::Vec3 box_hi_grid = lo + h * common::Vec3(g.count[0] - 1 - (axis == 0 ? layers : 0),
                                                         g.count[1] - 1, g.count[2] - 1 - (axis == 2 ? layers : 0));
  // The face the applicator touches, on the grid.
  const double face_coord = sign < 0.0 ? lo[axis] : box_hi_grid[axis];

  // Containment flags per grid point: bit 0 femur, 1 tibia, 2 meniscus.
  const int ni = g.count[0], nj = g.count[1], nk = g.count[2];
  std::vector<std::uint8_t> flags(static_cast<size_t>(ni) * nj * nk, 0);
  std::vector<std::unique_ptr<LineContainment>> menisci;
  for (const auto& [name, m] : meshes.menisci) menisci.push_back(std::make_unique<LineContainment>(m));
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < nk; ++k) {
    std::vector<double> xs;
    std::vector<int> is;
    std::vector<char> in;
    for (int j = 0; j < nj; ++j) {
      xs.clear();
      is.clear();
      for (int i = 0; i < ni; ++i)
        if (lat.is_site(i, j, k)) {
          xs.push_back(i * h + 1e-3);
          is.push_back(i);
        }
      const common::Vec3 origin = g.origin + common::Vec3(-1e-3, j * h, k * h);
      const double length = (ni - 1) * h + 2e-3;
      auto mark = [&](const LineContainment& c, std::uint8_t bit) {
        c.classify_line(origin, length, xs, &in);
        for (size_t q = 0; q < is.size(); ++q)
          if (in[q]) flags[static_cast<size_t>(is[q]) + static_cast<size_t>(ni) * (j + static_cast<size_t>(nj) * k)] |= bit;
      };
      mark(femur, 1);
      mark(tibia, 2);
      for (const auto& m : menisci) mark(*m, 4);
    }
  }
  // Cartilage: trees of the articular patches and their boxes.
  struct Patch {
    std::unique_ptr<common::TriangleTree> tree;
    const common::TriangleTree* bone;
    common::BoundingBox box;
    double reach;
  };
  std::vector<Patch> patches;
  for (const CartilageSurface& c : meshes.cartilage) {
    Patch p;
    p.tree = std::make_unique<common::TriangleTree>(c.articular);
    p.bone = c.bone == BoneId::kFemur ? &femur.tree() : &tibia.tree();
    p.box = common::bounding_box(c.articular);
    p.reach = max_thickness(c, *p.bone) + d;
    patches.push_back(std::move(p));
  }
  auto in_cartilage = [&](const common::Vec3& p) {
    for (const Patch& c : patches) {
      if ((p.array() < c.box.lo.array() - c.reach).any() || (p.array() > c.box.hi.array() + c.reach).any()) continue;
      const common::ClosestPoint q = c.bone->closest_point(p);
      if (q.distance > c.reach) continue;
      common::Vec3 u = p - q.point;
      if (q.distance > 1e-9) u /= q.distance;
      else u = common::triangle_normals(c.bone->mesh()).row(q.triangle).transpose();
      const auto hit = c.tree->first_hit(q.point, u, c.reach + 1e-3);
      if (hit && hit->distance >= q.distance) return true;
    }
    return false;
  };
  const double t_cort = o.cortical_thickness, t_shell = o.shell_thickness;
  auto classify = [&](int i, int j, int k, const common::Vec3& p) -> int {
    // Outside the box: only the applicator's layers.
    const bool outside = (p[axis] < lo[axis] - 1e-12) || (p[axis] > box_hi_grid[axis] + 1e-12);
    if (outside) {
      if (std::abs(p[u_axis] - centre[u_axis]) <= half && std::abs(p.y() - centre.y()) <= half) return kApplicator;
      return -1;
    }
    const std::uint8_t f = flags[static_cast<size_t>(i) + static_cast<size_t>(ni) * (j + static_cast<size_t>(nj) * k)];
    if (f & 3) {
      const LineContainment& bone = (f & 1) ? femur : tibia;
      return bone.tree().closest_point(p).distance <= t_cort ? kCortical : kCancellous;
    }
    if (!patches.empty() && in_cartilage(p)) return kCartilage;
    if (f & 4) return kFibrocartilage;
    for (int a = 0; a < 3; ++a)
      if (p[a] - lo[a] < t_shell - 1e-12 || box_hi_grid[a] - p[a] < t_shell - 1e-12) return kCapsuleShell;
    return kFibrous;
  };
  Model m = build_model(lat, g, tissues, o.fluid, classify, source);

  // The pulse acts on the applicator's outer layer.
  const int outer = sign < 0.0 ? 0 : g.count[axis] - 1;
  common::Vec3 n_in = common::Vec3::Zero();
  n_in[axis] = -sign;
  for (int a = 0; a < m.size(); ++a)
    if (m.tissue[a] == kApplicator && m.cell[a][axis] == outer) {
      m.loaded.automata.push_back(a);
      m.loaded.area.push_back(lat.area_per_surface_site() * n_in);
    }
  m.loaded.normal = n_in;

  KneeModelInfo info;
  info.box_lo = lo;
  info.box_hi = box_hi_grid;
  info.joint_line = joint;
  info.applicator_centre = centre;
  info.applicator_centre[axis] = face_coord;
  info.applicator_normal = n_in;
  info.applicator_layers = layers;
  info.applicator_density = tissues[kApplicator].density;
  info.automata = m.tissue_counts();
  info.max_cartilage_thickness = cart_max;
  info.max_meniscus_height = men_max;
  for (int t = 0; t < kKneeTissueCount; ++t) {
    if (t == kFibrocartilage && meshes.menisci.empty()) continue;
    if (t == kCartilage && meshes.cartilage.empty()) continue;
    if (info.automata[t] == 0)
      fail(std::string("tissue '") + knee_tissue_name(t) + "' received no automaton at diameter " + mm(d) +
           ": it is thinner than the lattice resolves");
  }
  // The applicator must be bonded to the capsule.
  std::int64_t contact = 0;
  for (int a = 0; a < m.size(); ++a) {
    if (m.tissue[a] != kApplicator) continue;
    for (int s = 0; s < lat.directions; ++s) {
      const int b = m.neighbour(s, a);
      if (b >= 0 && m.tissue[b] != kApplicator) ++contact;
    }
  }
  if (contact == 0) fail("the applicator has no contact with the capsule");
  if (info_out) *info_out = info;
  return m;
}

}  // namespace arthrosim::shockwave
