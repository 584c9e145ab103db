// The prepare stage (see prepare.h and docs/prepared_model.md).
#include "pipelines/prepare.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "common/error.h"
#include "common/hdf5.h"
#include "common/log.h"
#include "common/mesh_validation.h"
#include "common/metadata.h"
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

// Reads a mesh, repairs what is safe, validates; throws InputError naming the
// file with the validation summary if the repaired mesh is still invalid.
TriangleMesh load_checked(const std::string& path, const PrepareOptions& options, std::vector<std::string>* repairs,
                          std::vector<std::string>* warnings) {
  common::MeshReadOptions ro;
  ro.unit = options.unit;
  TriangleMesh raw = common::read_mesh(path, ro);
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

}  // namespace

ModelFiles find_model_files(const std::string& folder) {
  ModelFiles files;
  files.folder = folder;
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    throw InputError(folder, 0, "expected a model folder with <bone>_bone and <name>_cartilage surface files, found no folder");
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
    throw InputError(folder, 0, "expected at least one <name>_cartilage.{stl,obj,ply} file, found none");
  for (const auto& [name, path] : files.cartilage) {
    const std::string bone = name.substr(0, name.find('_'));
    if (!files.bones.count(bone))
      throw InputError(path, 0, "expected its bone " + (fs::path(folder) / (bone + "_bone.stl")).string() +
                                    " (or .obj/.ply), found no such file");
    files.cartilage_bone[name] = bone;
  }
  return files;
}

void cast_thickness(const TriangleMesh& bone, bool bone_closed, const Points3& points, const Points3& normals,
                    double max_distance, Eigen::VectorXd* thickness, Eigen::VectorXi* source) {
  const common::TriangleTree tree(bone);
  const Points3 bone_normals = common::triangle_normals(bone);
  const int n = static_cast<int>(points.rows());
  thickness->resize(n);
  source->resize(n);
  for (int i = 0; i < n; ++i) {
    const Vec3 p = points.row(i).transpose();
    const Vec3 dir = -normals.row(i).transpose();
    const auto hit = tree.first_hit(p, dir, max_distance);
    if (hit && !(bone_closed && bone_normals.row(hit->triangle).dot(dir) > 0.0)) {
      (*thickness)[i] = hit->distance;
      (*source)[i] = static_cast<int>(ThicknessSource::kRay);
      continue;
    }
    (*thickness)[i] = tree.closest_point(p).distance;
    (*source)[i] = static_cast<int>(hit ? ThicknessSource::kInsideBone : ThicknessSource::kClosestPoint);
  }
}

PreparedModel prepare_model(const ModelFiles& files, const PrepareOptions& options) {
  if (!(options.edge_length >= 0.2e-3 && options.edge_length <= 20e-3))
    throw InputError("prepare", 0, "expected edge length in [0.2, 20] mm, found " +
                                       std::to_string(options.edge_length * 1e3) + " mm");
  for (const auto& [name, e] : options.surface_edge_length) {
    if (!(e >= 0.2e-3 && e <= 20e-3))
      throw InputError("prepare", 0, "expected the edge length of " + name + " in [0.2, 20] mm, found " +
                                         std::to_string(e * 1e3) + " mm");
    if (!files.cartilage.count(name)) {
      std::string have;
      for (const auto& [c, p] : files.cartilage) have += (have.empty() ? "" : ", ") + c;
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
  PreparedModel model;
  model.folder = files.folder;
  std::map<std::string, int> bone_index;
  for (const auto& [name, path] : files.bones) {
    // Only bones that carry cartilage are needed.
    bool used = false;
    for (const auto& [c, b] : files.cartilage_bone) used = used || b == name;
    if (!used) continue;
    PreparedBone bone;
    bone.name = name;
    bone.source_file = path;
    bone.mesh = load_checked(path, options, &bone.repairs, &model.warnings);
    bone.closed = common::build_topology(bone.mesh).boundary_vertices.empty();
    if (!bone.closed)
      model.warnings.push_back(path + ": bone surface is open (fine for thickness casting; the inside-bone "
                                      "check is skipped for its cartilage)");
    bone_index[name] = static_cast<int>(model.bones.size());
    model.bones.push_back(std::move(bone));
  }
  common::RemeshOptions ro;
  ro.target_edge_length = options.edge_length;
  ro.iterations = options.remesh_iterations;
  ro.protect_boundary = true;
  for (const auto& [name, path] : files.cartilage) {
    const PreparedBone& bone = model.bones[bone_index.at(files.cartilage_bone.at(name))];
    PreparedSurface s;
    s.name = name;
    s.bone = bone.name;
    s.source_file = path;
    TriangleMesh input = load_checked(path, options, &s.repairs, &model.warnings);
    if (!common::build_topology(input).boundary_vertices.size())
      throw InputError(path, 0, "expected an open articular surface patch, found a closed surface "
                                "(export the articular surface, not the cartilage volume)");
    // Outward = away from the bone: flip a patch whose normals mostly point in.
    {
      const common::TriangleTree tree(bone.mesh);
      const Points3 vn = common::vertex_normals(input);
      int inward = 0;
      for (int v = 0; v < input.num_vertices(); ++v) {
        const auto cp = tree.closest_point(input.vertex(v));
        if (vn.row(v).dot(input.vertex(v) - cp.point) < 0) ++inward;
      }
      if (2 * inward > input.num_vertices()) {
        input.F.col(1).swap(input.F.col(2));
        s.repairs.push_back("flipped the orientation so the normals point away from the bone (" +
                            std::to_string(inward) + " of " + std::to_string(input.num_vertices()) +
                            " vertex normals pointed into it)");
      }
    }
    s.stats.input_triangles = input.num_triangles();
    common::RemeshStatistics rs;
    const auto own = options.surface_edge_length.find(name);
    ro.target_edge_length = own != options.surface_edge_length.end() ? own->second : options.edge_length;
    s.stats.target_edge_length = ro.target_edge_length;
    s.triangles = common::isotropic_remesh(input, ro, &rs);
    s.triangles.name = name;
    s.vertex_normals = common::vertex_normals(s.triangles);
    cast_thickness(bone.mesh, bone.closed, s.triangles.V, s.vertex_normals, options.max_cast_distance, &s.thickness,
                   &s.thickness_source);
    s.quads = common::split_triangles_to_quads(s.triangles);
    s.quads.name = name;
    s.node_normals = node_normals_of(s.quads);
    cast_thickness(bone.mesh, bone.closed, s.quads.V, s.node_normals, options.max_cast_distance, &s.node_thickness,
                   &s.node_thickness_source);
    s.periphery_nodes = common::boundary_nodes(s.quads);

    auto& st = s.stats;
    st.triangles = s.triangles.num_triangles();
    st.quads = s.quads.num_quads();
    st.mean_edge_length = rs.mean_edge_length;
    std::vector<int> missed, inside;
    for (int v = 0; v < s.thickness_source.size(); ++v) {
      switch (static_cast<ThicknessSource>(s.thickness_source[v])) {
        case ThicknessSource::kRay: ++st.vertices_ray; break;
        case ThicknessSource::kClosestPoint: ++st.vertices_closest_point; missed.push_back(v); break;
        case ThicknessSource::kInsideBone: ++st.vertices_inside_bone; inside.push_back(v); break;
      }
    }
    for (int v = 0; v < s.node_thickness_source.size(); ++v)
      st.nodes_closest_point += s.node_thickness_source[v] != static_cast<int>(ThicknessSource::kRay);
    st.thickness_min = s.thickness.minCoeff();
    st.thickness_max = s.thickness.maxCoeff();
    st.thickness_mean = s.thickness.mean();
    st.status = (missed.empty() && inside.empty() && st.nodes_closest_point == 0)
                    ? PreparedSurfaceStatistics::Status::kOk
                    : PreparedSurfaceStatistics::Status::kWithFallbacks;
    if (!missed.empty())
      model.warnings.push_back(name + ": " + std::to_string(missed.size()) + " of " +
                               std::to_string(s.triangles.num_vertices()) + " vertices: inward ray missed " +
                               bone.name + " within " + std::to_string(options.max_cast_distance * 1e3) +
                               " mm; closest-point distance used (vertices " + first_indices(missed) + ")");
    if (!inside.empty())
      model.warnings.push_back(name + ": " + std::to_string(inside.size()) + " vertices lie inside " + bone.name +
                               "; closest-point distance used (vertices " + first_indices(inside) + ")");
    if (st.nodes_closest_point > 0)
      model.warnings.push_back(name + ": " + std::to_string(st.nodes_closest_point) +
                               " quad nodes use the closest-point fallback");
    model.surfaces.push_back(std::move(s));
  }
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
  h5.set_attribute("/", "schema", "arthrosim prepared model 1");
  h5.set_attribute("/", "model_folder", model.folder);
  h5.set_attribute("/", "length_unit", "m");
  h5.set_attribute("/", "edge_length_m", options.edge_length);
  h5.set_attribute("/", "max_cast_distance_m", options.max_cast_distance);
  h5.set_attribute("/", "input_unit", common::unit_name(options.unit));
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
    std::string rep;
    for (const auto& r : b.repairs) rep += r + "\n";
    h5.set_attribute(g, "repairs", rep);
    series.surfaces.push_back({b.name + "_bone", g + "/vertices", g + "/faces", common::XdmfCellType::kTriangle, {}});
  }
  std::vector<std::string> names;
  for (const PreparedSurface& s : model.surfaces) {
    names.push_back(s.name);
    const std::string g = "/surfaces/" + s.name;
    h5.create_group(g);
    h5.set_attribute(g, "bone", s.bone);
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
    const std::string t = g + "/triangles", q = g + "/quads";
    h5.write(t + "/vertices", s.triangles.V);
    h5.write(t + "/faces", s.triangles.F);
    h5.write(t + "/normals", s.vertex_normals);
    h5.write(t + "/thickness", s.thickness);
    h5.write(t + "/thickness_source", s.thickness_source);
    h5.write(q + "/nodes", s.quads.V);
    h5.write(q + "/quads", s.quads.Q);
    h5.write(q + "/normals", s.node_normals);
    h5.write(q + "/thickness", s.node_thickness);
    h5.write(q + "/thickness_source", s.node_thickness_source);
    Eigen::VectorXi periphery = Eigen::Map<const Eigen::VectorXi>(s.periphery_nodes.data(),
                                                                  static_cast<Eigen::Index>(s.periphery_nodes.size()));
    h5.write(q + "/periphery", periphery);
    Eigen::VectorXi on_periphery = Eigen::VectorXi::Zero(s.quads.num_nodes());
    for (int i : s.periphery_nodes) on_periphery[i] = 1;
    h5.write(q + "/on_periphery", on_periphery);
    using common::XdmfCenter;
    series.surfaces.push_back({s.name + "_cartilage", t + "/vertices", t + "/faces", common::XdmfCellType::kTriangle,
                               {{"thickness_m", t + "/thickness", XdmfCenter::kNode, false},
                                {"thickness_source", t + "/thickness_source", XdmfCenter::kNode, false},
                                {"normal", t + "/normals", XdmfCenter::kNode, false}}});
    series.surfaces.push_back({s.name + "_quads", q + "/nodes", q + "/quads", common::XdmfCellType::kQuadrilateral,
                               {{"thickness_m", q + "/thickness", XdmfCenter::kNode, false},
                                {"thickness_source", q + "/thickness_source", XdmfCenter::kNode, false},
                                {"on_periphery", q + "/on_periphery", XdmfCenter::kNode, false},
                                {"normal", q + "/normals", XdmfCenter::kNode, false}}});
  }
  h5.write("/surfaces/names", names);
  h5.flush();
  common::write_xdmf(xdmf_path_for(h5_path), h5, series);
}

}  // namespace arthrosim::pipelines
