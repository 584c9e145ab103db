// The prepare stage (see prepare.h and docs/prepared_model.md).
#include "pipelines/prepare.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>
#include <numeric>
#include <set>
#include <sstream>

#include "common/compartments.h"
#include "common/error.h"
#include "common/hdf5.h"
#include "common/log.h"
#include "common/mesh_manifest.h"
#include "common/mesh_quality.h"
#include "common/mesh_validation.h"
#include "common/metadata.h"
#include "common/output_file.h"
#include "common/prepared_model_file.h"
#include "common/remesh.h"
#include "common/spatial.h"
#include "common/xdmf.h"

namespace arthrosim::pipelines {

namespace fs = std::filesystem;
using common::InputError;
using common::Points3;
using common::TriangleMesh;
using common::Vec3;

namespace {

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string first_indices(const std::vector<int>& idx, size_t max_count = 5) {
  std::ostringstream ss;
  for (size_t i = 0; i < idx.size() && i < max_count; ++i) ss << (i ? ", " : "") << idx[i];
  if (idx.size() > max_count) ss << ", ...";
  return ss.str();
}

// Reads a mesh in `unit`, checks its size against the unit, repairs what is
// safe, validates; throws InputError naming the file with the validation
// summary if the repaired mesh is still invalid.
TriangleMesh load_checked(const std::string& path, common::LengthUnit unit, const PrepareOptions& options,
                          bool manifest, std::vector<std::string>* repairs, std::vector<std::string>* warnings) {
  common::MeshReadOptions ro;
  ro.unit = unit;
  TriangleMesh raw = common::read_mesh(path, ro);
  // Unit check first: a mesh in the wrong unit (or with one corrupted
  // coordinate) must stop here, before any work that scales with its size.
  try {
    common::check_plausible_extent(raw, unit, path);
  } catch (const InputError& e) {
    const std::string what = e.what();
    if (what.find("likely unit") == std::string::npos) throw;
    throw InputError(what + (manifest ? " (units are declared by 'unit:' in the manifest)"
                                      : " (declare the unit with --unit, scene key prepare.mesh_unit, or in a "
                                        "meshes.yaml manifest)"));
  }
  // Problems repair() does not touch are reported on the input as read, so
  // the indices in the message are the file's.
  common::ValidationReport before = common::validate(raw);
  if (before.invalid_index_triangles.count > 0 || before.non_finite_vertices.count > 0 ||
      before.non_manifold_edges.count > 0)
    common::throw_if_invalid(before, path);
  common::RepairOptions rep;
  rep.merge_tolerance = options.merge_tolerance;
  common::RepairResult fixed = common::repair(raw, rep);
  if (fixed.report.changed()) {
    std::istringstream lines(fixed.report.summary());
    std::string line;
    while (std::getline(lines, line))
      if (!line.empty()) repairs->push_back(line);
  }
  const common::ValidationReport after = common::validate(fixed.mesh);
  common::throw_if_invalid(after, path + " (after the safe repairs: " +
                                      (repairs->empty() ? std::string("none") : std::to_string(repairs->size())) +
                                      ")");
  // Warnings of the validation (e.g. non-manifold vertices) are passed on;
  // open boundaries are expected for cartilage and reported for bones elsewhere.
  if (after.has_warnings()) {
    std::istringstream lines(after.summary());
    std::string line;
    while (std::getline(lines, line))
      if (line.find("warning") != std::string::npos && line.find("boundary") == std::string::npos)
        warnings->push_back(path + ":" + line);
  }
  if (fixed.report.unorientable_components > 0)
    throw InputError(path, 0, "expected an orientable surface, found " +
                                  std::to_string(fixed.report.unorientable_components) +
                                  " non-orientable component(s)");
  fixed.mesh.name = path;
  return fixed.mesh;
}

Points3 node_normals_of(const common::QuadMesh& q) {
  const Points3 qn = common::quad_normals(q);
  const Eigen::VectorXd qa = common::quad_areas(q);
  Points3 n = Points3::Zero(q.num_nodes(), 3);
  for (int e = 0; e < q.num_quads(); ++e)
    for (int k = 0; k < 4; ++k) n.row(q.Q(e, k)) += qa[e] * qn.row(e);
  for (int i = 0; i < n.rows(); ++i) {
    const double len = n.row(i).norm();
    if (len > 0) n.row(i) /= len;
  }
  return n;
}

std::string mm(double metres, int precision = 3) {
  std::ostringstream s;
  s.precision(precision);
  s << metres * 1e3;
  return s.str();
}

// Total length and edge count of the open boundary of a triangle mesh.
std::pair<double, int> outline_length(const TriangleMesh& m) {
  const common::MeshTopology topo = common::build_topology(m);
  double length = 0.0;
  int edges = 0;
  for (Eigen::Index e = 0; e < topo.edges.rows(); ++e)
    if (topo.edge_triangles[e].size() == 1) {
      length += (m.V.row(topo.edges(e, 0)) - m.V.row(topo.edges(e, 1))).norm();
      ++edges;
    }
  return {length, edges};
}

// The remeshed surface, its quads and normals, checked (steps 4 and 5).
struct Remeshed {
  TriangleMesh triangles;
  Points3 vertex_normals;
  common::QuadMesh quads;
  Points3 node_normals;
  common::RemeshStatistics stats;
  common::ElementQualityReport triangle_quality, quad_quality;
  bool ok() const { return triangle_quality.ok() && quad_quality.ok(); }
};

Remeshed remesh_and_check(const TriangleMesh& input, const std::string& name, double target, bool protect,
                          const PrepareOptions& options) {
  common::RemeshOptions ro;
  ro.target_edge_length = target;
  ro.iterations = options.remesh_iterations;
  ro.protect_boundary = protect;
  Remeshed r;
  r.triangles = common::isotropic_remesh(input, ro, &r.stats);
  r.triangles.name = name;
  r.vertex_normals = common::vertex_normals(r.triangles);
  r.quads = common::split_triangles_to_quads(r.triangles);
  r.quads.name = name;
  r.node_normals = node_normals_of(r.quads);
  r.triangle_quality = common::check_triangles(r.triangles, r.vertex_normals, target, options.quality);
  r.quad_quality = common::check_quads(r.quads, r.node_normals, target, options.quality);
  r.triangle_quality.mesh_name = r.quad_quality.mesh_name = name;
  return r;
}

// Thickness statistics of one surface (area-weighted mean, rim mean).
void thickness_statistics(const TriangleMesh& m, const Eigen::VectorXd& t, PreparedSurfaceStatistics* st) {
  const Eigen::VectorXd area = common::triangle_areas(m);
  double wsum = 0.0, tsum = 0.0;
  for (int f = 0; f < m.num_triangles(); ++f)
    for (int k = 0; k < 3; ++k) {
      wsum += area[f] / 3.0;
      tsum += area[f] / 3.0 * t[m.F(f, k)];
    }
  st->thickness_mean = wsum > 0 ? tsum / wsum : 0.0;
  st->thickness_min = t.minCoeff();
  st->thickness_max = t.maxCoeff();
  const common::MeshTopology topo = common::build_topology(m);
  double lsum = 0.0, rsum = 0.0;
  for (Eigen::Index e = 0; e < topo.edges.rows(); ++e) {
    if (topo.edge_triangles[e].size() != 1) continue;
    const int a = topo.edges(e, 0), b = topo.edges(e, 1);
    const double l = (m.V.row(a) - m.V.row(b)).norm();
    lsum += l;
    rsum += 0.5 * l * (t[a] + t[b]);
  }
  st->thickness_rim_mean = lsum > 0 ? rsum / lsum : 0.0;
}

}  // namespace

ModelFiles find_model_files(const std::string& path) {
  ModelFiles files;
  std::error_code ec;
  const bool is_manifest_file = fs::is_regular_file(path, ec) && lower(fs::path(path).extension().string()) == ".yaml";
  const std::string manifest =
      is_manifest_file ? path : (fs::path(path) / common::kMeshManifestName).string();
  if (is_manifest_file || fs::is_regular_file(manifest, ec)) {
    const common::MeshManifest m = common::read_mesh_manifest(manifest);
    files.folder = is_manifest_file ? m.folder : path;
    files.manifest = manifest;
    for (const auto& [name, b] : m.bones) {
      files.bones[name] = b.file;
      if (b.unit) files.bone_unit[name] = *b.unit;
      if (!b.body.empty()) files.bone_body[name] = b.body;
    }
    for (const auto& [name, c] : m.cartilage) {
      files.cartilage[name] = c.file;
      files.cartilage_bone[name] = c.bone;
      if (c.unit) files.cartilage_unit[name] = *c.unit;
      if (c.split_lateral) files.split_lateral[name] = *c.split_lateral;
    }
    return files;
  }
  files.folder = path;
  const std::string& folder = path;
  if (!fs::is_directory(folder, ec))
    throw InputError(folder, 0,
                     "expected a model folder (with a meshes.yaml manifest, or <bone>_bone and <name>_cartilage "
                     "surface files) or a manifest file, found no folder");
  std::vector<fs::path> entries;
  for (const auto& e : fs::directory_iterator(folder)) entries.push_back(e.path());
  std::sort(entries.begin(), entries.end());
  auto add = [&](std::map<std::string, std::string>& into, const std::string& name, const fs::path& p) {
    auto it = into.find(name);
    if (it != into.end())
      throw InputError(p.string(), 0, "expected one file per surface, found also " + it->second);
    into[name] = p.string();
  };
  for (const fs::path& p : entries) {
    const std::string ext = lower(p.extension().string());
    if (ext != ".stl" && ext != ".obj" && ext != ".ply") continue;
    const std::string stem = p.stem().string();
    const std::string bone_suffix = "_bone", cart_suffix = "_cartilage";
    if (stem.size() > bone_suffix.size() && stem.compare(stem.size() - bone_suffix.size(), bone_suffix.size(), bone_suffix) == 0)
      add(files.bones, stem.substr(0, stem.size() - bone_suffix.size()), p);
    else if (stem.size() > cart_suffix.size() &&
             stem.compare(stem.size() - cart_suffix.size(), cart_suffix.size(), cart_suffix) == 0)
      add(files.cartilage, stem.substr(0, stem.size() - cart_suffix.size()), p);
  }
  if (files.cartilage.empty())
    throw InputError(folder, 0,
                     "expected at least one <name>_cartilage.{stl,obj,ply} file (or a meshes.yaml manifest mapping "
                     "surfaces to files), found none");
  for (const auto& [name, file] : files.cartilage) {
    const std::string bone = name.substr(0, name.find('_'));
    if (!files.bones.count(bone))
      throw InputError(file, 0, "expected its bone " + (fs::path(folder) / (bone + "_bone.stl")).string() +
                                    " (or .obj/.ply), found no such file");
    files.cartilage_bone[name] = bone;
  }
  return files;
}

namespace {

// The queries thickness casting needs on one bone, built once per bone.
struct BoneQueries {
  common::TriangleTree tree;
  std::unique_ptr<common::ClosedSurfaceSide> side;  // closed bones only
  BoneQueries(const TriangleMesh& bone, bool closed) : tree(bone) {
    if (closed) side = std::make_unique<common::ClosedSurfaceSide>(bone);
  }
};

void cast_with(const BoneQueries& q, const Points3& points, const Points3& normals, double max_distance,
               Eigen::VectorXd* thickness, Eigen::VectorXi* source, Eigen::VectorXd* overlap) {
  const int n = static_cast<int>(points.rows());
  thickness->resize(n);
  source->resize(n);
  if (overlap) overlap->setZero(n);
  for (int i = 0; i < n; ++i) {
    const Vec3 p = points.row(i).transpose();
    if (q.side && q.side->inside(p)) {
      // The articular surface lies inside the bone here (overlapping
      // segmentations): no cartilage between the two surfaces.
      (*thickness)[i] = 0.0;
      (*source)[i] = static_cast<int>(ThicknessSource::kInsideBone);
      if (overlap) (*overlap)[i] = q.tree.closest_point(p).distance;
      continue;
    }
    const Vec3 dir = -normals.row(i).transpose();
    // The first entry into the bone: a ray leaving a closed bone's back face
    // first cannot start outside it, so only front faces count there.
    const auto hit = q.tree.first_hit(p, dir, max_distance, q.side ? common::HitSide::kFront : common::HitSide::kBoth);
    if (hit) {
      (*thickness)[i] = hit->distance;
      (*source)[i] = static_cast<int>(ThicknessSource::kRay);
      continue;
    }
    (*thickness)[i] = q.tree.closest_point(p).distance;
    (*source)[i] = static_cast<int>(ThicknessSource::kClosestPoint);
  }
}

}  // namespace

void cast_thickness(const TriangleMesh& bone, bool bone_closed, const Points3& points, const Points3& normals,
                    double max_distance, Eigen::VectorXd* thickness, Eigen::VectorXi* source,
                    Eigen::VectorXd* overlap) {
  cast_with(BoneQueries(bone, bone_closed), points, normals, max_distance, thickness, source, overlap);
}

std::pair<TriangleMesh, TriangleMesh> split_compartments(const TriangleMesh& mesh, const Vec3& lateral,
                                                         const std::string& source, std::string* how) {
  // The rule stage 1 uses too (common/compartments.h).
  const common::CompartmentSplit split = common::split_medial_lateral(mesh, lateral);
  const int nt = mesh.num_triangles();
  const std::vector<char>& is_lateral = split.is_lateral;
  std::ostringstream desc;
  if (split.components >= 2) {
    desc << "by its " << split.components << " connected components (the two largest " << mm(split.separation, 3)
         << " mm apart along the medial-lateral direction)";
  } else {
    desc << "by the plane normal to the medial-lateral direction at " << mm(split.cut, 4)
         << " mm (one connected mesh: the cut follows triangle edges)";
  }
  std::vector<int> med_tris, lat_tris;
  for (int t = 0; t < nt; ++t) (is_lateral[t] ? lat_tris : med_tris).push_back(t);
  if (med_tris.empty() || lat_tris.empty())
    throw InputError(source, 0, "split into medial and lateral compartments: expected triangles on both sides, found " +
                                    std::to_string(med_tris.size()) + " medial and " + std::to_string(lat_tris.size()) +
                                    " lateral");
  if (how) *how = desc.str();
  return {common::submesh(mesh, med_tris), common::submesh(mesh, lat_tris)};
}

namespace {

// Steps 4-6 for one cartilage surface (its input already loaded, oriented
// and, if declared, split).
void prepare_surface(PreparedSurface& s, const TriangleMesh& input, const PreparedBone& bone, const BoneQueries& queries,
                     double target, const PrepareOptions& options, std::vector<std::string>* warnings) {
  auto& st = s.stats;
  st.input_triangles = input.num_triangles();
  st.target_edge_length = target;
  // Bounded work: estimate the remesh before doing it.
  st.estimated_triangles = common::estimate_remesh_triangles(input, target);
  if (!(st.estimated_triangles <= options.max_triangles)) {
    std::ostringstream m;
    m.precision(3);
    m << "cartilage '" << s.name << "': remeshing at " << mm(target) << " mm would make about "
      << st.estimated_triangles << " triangles (area " << common::surface_area(input) * 1e6 << " mm^2, outline "
      << outline_length(input).first * 1e3 << " mm), more than the limit of " << options.max_triangles
      << " (a larger edge length, or check the mesh's unit and extent)";
    throw InputError(s.source_file, 0, m.str());
  }
  // Outline: kept exactly unless over-resolved (mean outline edge below half
  // the target: a dense protected outline leaves slivers next to it).
  const auto [outline, outline_edges] = outline_length(input);
  const double mean_outline_edge = outline_edges > 0 ? outline / outline_edges : 0.0;
  bool resample = outline_edges > 0 && mean_outline_edge < 0.5 * target;
  if (resample)
    st.outline_reason = "the input outline's mean edge (" + mm(mean_outline_edge) + " mm) is below half the target (" +
                        mm(target) + " mm)";
  Remeshed r = remesh_and_check(input, s.name, target, !resample, options);
  if (!r.ok() && !resample) {
    st.outline_reason = "keeping the outline left elements that fail the check (" +
                        std::to_string(r.triangle_quality.failed) + " triangles, " +
                        std::to_string(r.quad_quality.failed) + " quads)";
    resample = true;
    r = remesh_and_check(input, s.name, target, false, options);
  }
  if (!r.ok())
    throw InputError(s.source_file, 0,
                     "cartilage '" + s.name + "' remeshed at " + mm(target) +
                         " mm: expected every element to pass the quality check (docs/prepared_model.md), found:\n" +
                         r.triangle_quality.summary() + "\n" + r.quad_quality.summary() +
                         "\n(a different edge length usually avoids it; or inspect the input near these points)");
  st.outline_resampled = resample;
  if (resample) warnings->push_back(s.name + ": outline resampled by the remesher: " + st.outline_reason);
  s.triangles = std::move(r.triangles);
  s.vertex_normals = std::move(r.vertex_normals);
  s.quads = std::move(r.quads);
  s.node_normals = std::move(r.node_normals);
  st.triangle_quality = r.triangle_quality;
  st.quad_quality = r.quad_quality;
  s.periphery_nodes = common::boundary_nodes(s.quads);

  // Thickness (step 6).
  Eigen::VectorXd overlap;
  cast_with(queries, s.triangles.V, s.vertex_normals, options.max_cast_distance, &s.thickness_measured,
            &s.thickness_source, &overlap);
  cast_with(queries, s.quads.V, s.node_normals, options.max_cast_distance, &s.node_thickness_measured,
            &s.node_thickness_source, nullptr);
  s.thickness = s.thickness_measured.cwiseMax(options.min_thickness);
  s.node_thickness = s.node_thickness_measured.cwiseMax(options.min_thickness);
  st.max_overlap = overlap.size() ? overlap.maxCoeff() : 0.0;

  st.triangles = s.triangles.num_triangles();
  st.quads = s.quads.num_quads();
  st.mean_edge_length = r.stats.mean_edge_length;
  std::vector<int> missed, inside, floored;
  for (int v = 0; v < s.thickness_source.size(); ++v) {
    switch (static_cast<ThicknessSource>(s.thickness_source[v])) {
      case ThicknessSource::kRay: ++st.vertices_ray; break;
      case ThicknessSource::kClosestPoint: ++st.vertices_closest_point; missed.push_back(v); break;
      case ThicknessSource::kInsideBone: ++st.vertices_inside_bone; inside.push_back(v); break;
    }
    if (s.thickness_measured[v] < options.min_thickness) floored.push_back(v);
  }
  st.vertices_floored = static_cast<int>(floored.size());
  for (int v = 0; v < s.node_thickness_source.size(); ++v) {
    st.nodes_closest_point += s.node_thickness_source[v] != static_cast<int>(ThicknessSource::kRay);
    st.nodes_floored += s.node_thickness_measured[v] < options.min_thickness;
  }
  thickness_statistics(s.triangles, s.thickness, &st);
  st.status = (missed.empty() && inside.empty() && st.nodes_closest_point == 0)
                  ? PreparedSurfaceStatistics::Status::kOk
                  : PreparedSurfaceStatistics::Status::kWithFallbacks;
  const int nv = s.triangles.num_vertices();
  if (!missed.empty())
    warnings->push_back(s.name + ": " + std::to_string(missed.size()) + " of " + std::to_string(nv) +
                        " vertices: inward ray entered " + bone.name + " nowhere within " +
                        mm(options.max_cast_distance) + " mm; closest-point distance used (vertices " +
                        first_indices(missed) + ")");
  if (!inside.empty())
    warnings->push_back(s.name + ": " + std::to_string(inside.size()) + " of " + std::to_string(nv) +
                        " vertices lie inside " + bone.name + " (overlapping segmentations, up to " +
                        mm(st.max_overlap) + " mm deep); measured thickness 0 (vertices " + first_indices(inside) +
                        ")");
  if (st.nodes_closest_point > 0)
    warnings->push_back(s.name + ": " + std::to_string(st.nodes_closest_point) + " of " +
                        std::to_string(s.quads.num_nodes()) + " quad nodes without a ray thickness (inside " +
                        bone.name + " or no ray entry)");
  if (!floored.empty())
    warnings->push_back(s.name + ": " + std::to_string(floored.size()) + " of " + std::to_string(nv) + " vertices (" +
                        std::to_string(st.nodes_floored) + " quad nodes) thinner than min_thickness " +
                        mm(options.min_thickness) + " mm, raised to it (vertices " + first_indices(floored) + ")");
}

}  // namespace

PreparedModel prepare_model(const ModelFiles& files, const PrepareOptions& options) {
  if (!(options.edge_length >= 0.2e-3 && options.edge_length <= 20e-3))
    throw InputError("prepare", 0, "expected edge length in [0.2, 20] mm, found " +
                                       std::to_string(options.edge_length * 1e3) + " mm");
  // Per-surface edge lengths name a cartilage surface, or a part of a split one.
  std::set<std::string> surface_names;
  for (const auto& [c, p] : files.cartilage) {
    surface_names.insert(c);
    if (files.split_lateral.count(c)) surface_names.insert({c + "_medial", c + "_lateral"});
  }
  for (const auto& [name, e] : options.surface_edge_length) {
    if (!(e >= 0.2e-3 && e <= 20e-3))
      throw InputError("prepare", 0, "expected the edge length of " + name + " in [0.2, 20] mm, found " +
                                         std::to_string(e * 1e3) + " mm");
    if (!surface_names.count(name)) {
      std::string have;
      for (const auto& c : surface_names) have += (have.empty() ? "" : ", ") + c;
      throw InputError("prepare", 0, "edge length given for '" + name + "', which is not a cartilage surface of " +
                                         files.folder + " (it has: " + have + ")");
    }
  }
  if (!(options.max_cast_distance >= 1e-3 && options.max_cast_distance <= 50e-3))
    throw InputError("prepare", 0, "expected max cast distance in [1, 50] mm, found " +
                                       std::to_string(options.max_cast_distance * 1e3) + " mm");
  if (options.remesh_iterations < 1 || options.remesh_iterations > 20)
    throw InputError("prepare", 0, "expected remesh iterations in [1, 20], found " +
                                       std::to_string(options.remesh_iterations));
  if (!(options.min_thickness >= 0 && options.min_thickness <= 2e-3))
    throw InputError("prepare", 0, "expected min thickness in [0, 2] mm, found " +
                                       std::to_string(options.min_thickness * 1e3) + " mm");
  if (!(options.max_triangles >= 100))
    throw InputError("prepare", 0, "expected max triangles >= 100, found " + std::to_string(options.max_triangles));
  const bool manifest = !files.manifest.empty();
  PreparedModel model;
  model.folder = files.folder;
  model.manifest = files.manifest;
  std::map<std::string, int> bone_index;
  for (const auto& [name, path] : files.bones) {
    // Only bones that carry cartilage are needed.
    bool used = false;
    for (const auto& [c, b] : files.cartilage_bone) used = used || b == name;
    if (!used) continue;
    PreparedBone bone;
    bone.name = name;
    bone.source_file = path;
    const auto u = files.bone_unit.find(name);
    bone.unit = u != files.bone_unit.end() ? u->second : options.unit;
    if (const auto b = files.bone_body.find(name); b != files.bone_body.end()) bone.body = b->second;
    bone.mesh = load_checked(path, bone.unit, options, manifest, &bone.repairs, &model.warnings);
    bone.closed = common::build_topology(bone.mesh).boundary_vertices.empty();
    if (!bone.closed)
      model.warnings.push_back(path + ": bone surface is open (fine for thickness casting; the inside-bone "
                                      "check is skipped for its cartilage)");
    bone_index[name] = static_cast<int>(model.bones.size());
    model.bones.push_back(std::move(bone));
  }
  std::vector<std::unique_ptr<BoneQueries>> queries;
  for (const PreparedBone& b : model.bones) queries.push_back(std::make_unique<BoneQueries>(b.mesh, b.closed));
  for (const auto& [name, path] : files.cartilage) {
    const int bi = bone_index.at(files.cartilage_bone.at(name));
    const PreparedBone& bone = model.bones[bi];
    std::vector<std::string> repairs;
    const auto u = files.cartilage_unit.find(name);
    const common::LengthUnit unit = u != files.cartilage_unit.end() ? u->second : options.unit;
    TriangleMesh input = load_checked(path, unit, options, manifest, &repairs, &model.warnings);
    if (!common::build_topology(input).boundary_vertices.size())
      throw InputError(path, 0, "expected an open articular surface patch, found a closed surface "
                                "(export the articular surface, not the cartilage volume)");
    // Outward = away from the bone: flip a patch whose normals mostly point
    // in. The same distances tell whether the cartilage lies on its bone.
    {
      const common::TriangleTree& tree = queries[bi]->tree;
      const Points3 vn = common::vertex_normals(input);
      int inward = 0;
      std::vector<double> gap(input.num_vertices());
      for (int v = 0; v < input.num_vertices(); ++v) {
        const auto cp = tree.closest_point(input.vertex(v));
        gap[v] = cp.distance;
        if (vn.row(v).dot(input.vertex(v) - cp.point) < 0) ++inward;
      }
      std::nth_element(gap.begin(), gap.begin() + gap.size() / 2, gap.end());
      const double median_gap = gap[gap.size() / 2];
      if (median_gap > options.max_cast_distance)
        throw InputError(path, 0, "expected cartilage '" + name + "' to lie on its bone " + bone.source_file +
                                      " (median distance within max_cast_distance " + mm(options.max_cast_distance) +
                                      " mm), found a median distance of " + mm(median_gap) +
                                      " mm: are both files in the same frame and unit?");
      if (2 * inward > input.num_vertices()) {
        input.F.col(1).swap(input.F.col(2));
        repairs.push_back("flipped the orientation so the normals point away from the bone (" +
                          std::to_string(inward) + " of " + std::to_string(input.num_vertices()) +
                          " vertex normals pointed into it)");
      }
    }
    std::vector<std::pair<std::string, TriangleMesh>> parts;
    std::string split_how;
    const auto split = files.split_lateral.find(name);
    if (split != files.split_lateral.end()) {
      auto [medial, lateral] = split_compartments(input, split->second, path, &split_how);
      parts.emplace_back(name + "_medial", std::move(medial));
      parts.emplace_back(name + "_lateral", std::move(lateral));
    } else {
      parts.emplace_back(name, std::move(input));
    }
    for (auto& [part, mesh] : parts) {
      PreparedSurface s;
      s.name = part;
      s.bone = bone.name;
      s.body = bone.body;
      s.source_file = path;
      s.repairs = repairs;
      if (split != files.split_lateral.end()) {
        s.split_from = name;
        s.compartment = part.substr(name.size() + 1);
        s.repairs.push_back("split from '" + name + "' " + split_how + ": " + s.compartment + " part, " +
                            std::to_string(mesh.num_triangles()) + " triangles");
      }
      mesh.name = part;
      const auto own = options.surface_edge_length.find(part);
      const auto parent = options.surface_edge_length.find(name);
      const double target = own != options.surface_edge_length.end()      ? own->second
                             : parent != options.surface_edge_length.end() ? parent->second
                                                                           : options.edge_length;
      prepare_surface(s, mesh, bone, *queries[bi], target, options, &model.warnings);
      model.surfaces.push_back(std::move(s));
    }
  }
  std::sort(model.surfaces.begin(), model.surfaces.end(),
            [](const PreparedSurface& a, const PreparedSurface& b) { return a.name < b.name; });
  return model;
}

std::string xdmf_path_for(const std::string& h5_path) {
  fs::path p(h5_path);
  p.replace_extension(".xdmf");
  return p.string();
}

void write_prepared_model(const PreparedModel& model, const PrepareOptions& options,
                          const common::RunMetadata& metadata, const std::string& h5_path) {
  common::H5File h5(h5_path, common::H5File::Mode::kTruncate);
  common::write_metadata(h5, metadata);
  common::PreparedModelWriter writer(h5);  // what the stages read (common/prepared_model_file.h)
  writer.identity(model.folder);
  h5.set_attribute("/", "edge_length_m", options.edge_length);
  h5.set_attribute("/", "max_cast_distance_m", options.max_cast_distance);
  h5.set_attribute("/", "input_unit", common::unit_name(options.unit));
  h5.set_attribute("/", "manifest", model.manifest);
  h5.set_attribute("/", "min_thickness_m", options.min_thickness);
  h5.set_attribute("/", "max_triangles", options.max_triangles);
  h5.set_attribute("/", "element_min_edge_fraction", options.quality.min_edge_fraction);
  h5.set_attribute("/", "element_min_angle_deg", options.quality.min_angle * 180.0 / M_PI);
  h5.set_attribute("/", "element_min_shell_thickness_m", options.quality.min_shell_thickness);
  std::string warnings;
  for (const auto& w : model.warnings) warnings += w + "\n";
  h5.set_attribute("/", "warnings", warnings);

  common::XdmfSeries series;
  for (const PreparedBone& b : model.bones) {
    const std::string g = "/bones/" + b.name;
    h5.write(g + "/vertices", b.mesh.V);
    h5.write(g + "/faces", b.mesh.F);
    h5.set_attribute(g, "source_file", b.source_file);
    h5.set_attribute(g, "closed", static_cast<int>(b.closed));
    h5.set_attribute(g, "body", b.body);
    h5.set_attribute(g, "input_unit", common::unit_name(b.unit));
    std::string rep;
    for (const auto& r : b.repairs) rep += r + "\n";
    h5.set_attribute(g, "repairs", rep);
    series.surfaces.push_back({b.name + "_bone", g + "/vertices", g + "/faces", common::XdmfCellType::kTriangle, {}});
  }
  std::vector<std::string> names;
  for (const PreparedSurface& s : model.surfaces) {
    names.push_back(s.name);
    const std::string g = "/surfaces/" + s.name;
    writer.surface(s.name, s.bone);
    h5.set_attribute(g, "source_file", s.source_file);
    std::string rep;
    for (const auto& r : s.repairs) rep += r + "\n";
    h5.set_attribute(g, "repairs", rep);
    h5.set_attribute(g, "status", s.stats.status == PreparedSurfaceStatistics::Status::kOk ? "ok" : "with_fallbacks");
    h5.set_attribute(g, "vertices_closest_point", s.stats.vertices_closest_point);
    h5.set_attribute(g, "vertices_inside_bone", s.stats.vertices_inside_bone);
    h5.set_attribute(g, "nodes_fallback", s.stats.nodes_closest_point);
    h5.set_attribute(g, "mean_edge_length_m", s.stats.mean_edge_length);
    h5.set_attribute(g, "target_edge_length_m", s.stats.target_edge_length);
    h5.set_attribute(g, "body", s.body);
    h5.set_attribute(g, "split_from", s.split_from);
    h5.set_attribute(g, "compartment", s.compartment);
    h5.set_attribute(g, "outline", s.stats.outline_resampled ? "resampled" : "kept");
    h5.set_attribute(g, "estimated_triangles", s.stats.estimated_triangles);
    h5.set_attribute(g, "vertices_floored", s.stats.vertices_floored);
    h5.set_attribute(g, "nodes_floored", s.stats.nodes_floored);
    h5.set_attribute(g, "max_overlap_m", s.stats.max_overlap);
    h5.set_attribute(g, "thickness_mean_m", s.stats.thickness_mean);
    h5.set_attribute(g, "thickness_max_m", s.stats.thickness_max);
    h5.set_attribute(g, "thickness_rim_mean_m", s.stats.thickness_rim_mean);
    h5.set_attribute(g, "min_edge_length_m", std::min(s.stats.triangle_quality.min_edge, s.stats.quad_quality.min_edge));
    h5.set_attribute(g, "min_angle_deg",
                     std::min(s.stats.triangle_quality.min_angle, s.stats.quad_quality.min_angle) * 180.0 / M_PI);
    h5.set_attribute(g, "min_jacobian_ratio",
                     std::min(s.stats.triangle_quality.min_jacobian_ratio, s.stats.quad_quality.min_jacobian_ratio));
    h5.set_attribute(g, "min_admissible_shell_thickness_m", s.stats.quad_quality.min_shell_thickness);
    const std::string t = g + "/triangles", q = common::PreparedModelWriter::quads_group(s.name);
    h5.write(t + "/vertices", s.triangles.V);
    h5.write(t + "/faces", s.triangles.F);
    h5.write(t + "/normals", s.vertex_normals);
    h5.write(t + "/thickness", s.thickness);
    h5.write(t + "/thickness_source", s.thickness_source);
    h5.write(t + "/thickness_measured", s.thickness_measured);
    writer.quads(s.name, s.quads, s.node_normals, s.node_thickness, s.periphery_nodes);
    h5.write(q + "/thickness_source", s.node_thickness_source);
    h5.write(q + "/thickness_measured", s.node_thickness_measured);
    Eigen::VectorXi on_periphery = Eigen::VectorXi::Zero(s.quads.num_nodes());
    for (int i : s.periphery_nodes) on_periphery[i] = 1;
    h5.write(q + "/on_periphery", on_periphery);
    using common::XdmfCenter;
    series.surfaces.push_back({s.name + "_cartilage", t + "/vertices", t + "/faces", common::XdmfCellType::kTriangle,
                               {{"thickness_m", t + "/thickness", XdmfCenter::kNode, false},
                                {"thickness_measured_m", t + "/thickness_measured", XdmfCenter::kNode, false},
                                {"thickness_source", t + "/thickness_source", XdmfCenter::kNode, false},
                                {"normal", t + "/normals", XdmfCenter::kNode, false}}});
    series.surfaces.push_back({s.name + "_quads", q + "/nodes", q + "/quads", common::XdmfCellType::kQuadrilateral,
                               {{"thickness_m", q + "/thickness", XdmfCenter::kNode, false},
                                {"thickness_measured_m", q + "/thickness_measured", XdmfCenter::kNode, false},
                                {"thickness_source", q + "/thickness_source", XdmfCenter::kNode, false},
                                {"on_periphery", q + "/on_periphery", XdmfCenter::kNode, false},
                                {"normal", q + "/normals", XdmfCenter::kNode, false}}});
  }
  writer.surface_names(names);
  h5.flush();
  common::write_xdmf(xdmf_path_for(common::complete_name(h5_path)), h5, series);  // also for <out>.partial
}

}  // namespace arthrosim::pipelines
