#include "biphasic/output_file.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "common/error.h"
#include "common/xdmf.h"

namespace arthrosim::biphasic {
namespace {

// hex_basis (lexicographic) corner order -> VTK hexahedron order.
constexpr int kVtkFromLexicographic[8] = {0, 1, 3, 2, 4, 5, 7, 6};

struct LayerAppenders {
  common::H5File::Appender X_WB, nodes_W, displacement, pressure, effective_stress, flux, max_principal,
      max_shear, surface_total, surface_fluid, contact_area, fls, max_tensile, max_tensile_vertex,
      max_tensile_region, max_shear_value, max_shear_vertex, max_shear_region;
};

}  // namespace

std::string layer_group(const std::string& layer) { return "/layers/" + layer; }

struct OutputWriter::Impl {
  std::unique_ptr<common::H5File::Appender> time;
  std::vector<LayerAppenders> layers;
  std::vector<std::string> names;
  std::vector<int> num_nodes, num_vertices;
  std::vector<Eigen::MatrixXd> nodes_B;
  std::vector<std::string> compartments;
};

OutputWriter::OutputWriter(const std::string& path, const JointRun& run, int expected_steps)
    : impl_(std::make_unique<Impl>()),
      file_(std::make_unique<common::H5File>(path, common::H5File::Mode::kTruncate)) {
  common::H5File& f = *file_;
  f.set_attribute("/", "schema", "arthrosim biphasic output 1");
  f.set_attribute("/", "length_unit", "m");
  common::H5AppendOptions ao;
  ao.expected_frames = std::max(expected_steps, 0);
  impl_->time = std::make_unique<common::H5File::Appender>(f.appender("/time", {}, ao));
  std::vector<std::string> names;
  for (const JointLayer& l : run.layers()) names.push_back(l.name);
  f.write("/layers/names", names);
  for (size_t i = 0; i < run.layers().size(); ++i) {
    const LayerMesh& m = run.problem(static_cast<int>(i)).system().mesh;
    const LayerSystem& sys = run.problem(static_cast<int>(i)).system();
    const std::string g = layer_group(m.name);
    f.write(g + "/nodes", Eigen::MatrixXd(m.q1_nodes));
    Eigen::MatrixXi hex(m.num_elements(), 8);
    for (int e = 0; e < m.num_elements(); ++e)
      for (int c = 0; c < 8; ++c) hex(e, c) = m.hex_q1(e, kVtkFromLexicographic[c]);
    f.write(g + "/hexahedra", hex);
    Eigen::MatrixXi top(m.num_quads(), 4), bottom(m.num_quads(), 4);
    for (int q = 0; q < m.num_quads(); ++q)
      for (int k = 0; k < 4; ++k) {
        top(q, k) = m.q1_node(m.surface.Q(q, k), m.layers);
        bottom(q, k) = m.q1_node(m.surface.Q(q, k), 0);
      }
    f.write(g + "/articular_quads", top);
    f.write(g + "/bone_quads", bottom);
    Eigen::VectorXi art(m.num_vertices()), bone(m.num_vertices()), region(m.num_vertices());
    for (int v = 0; v < m.num_vertices(); ++v) {
      art[v] = m.q1_node(v, m.layers);
      bone[v] = m.q1_node(v, 0);
      region[v] = static_cast<int>(run.regions(static_cast<int>(i))[v]);
    }
    f.write(g + "/articular_nodes", art);
    f.write(g + "/bone_nodes", bone);
    f.write(g + "/vertex_region", region);
    f.write(g + "/articular_vertices", Eigen::MatrixXd(m.surface.V));
    f.set_attribute(g, "bone", run.layers()[i].bone);
    f.set_attribute(g, "element_layers", m.layers);
    f.set_attribute(g, "element_pair", to_string(sys.pair));
    f.set_attribute(g, "aggregate_modulus_Pa", sys.material().aggregate_modulus_Pa);
    f.set_attribute(g, "poisson_ratio", sys.material().poisson_ratio);
    f.set_attribute(g, "permeability_m4_per_Ns", sys.material().permeability_m4_per_Ns);
    f.set_attribute(g, "unknowns", sys.num_u_dofs() + sys.num_p_dofs());
    const int n = m.num_q1_nodes(), nv = m.num_vertices();
    impl_->names.push_back(m.name);
    impl_->nodes_B.push_back(m.q1_nodes);
    impl_->num_nodes.push_back(n);
    impl_->num_vertices.push_back(nv);
    LayerAppenders a{f.appender(g + "/X_WB", {4, 4}, ao),
                     f.appender(g + "/nodes_W", {n, 3}, ao),
                     f.appender(g + "/displacement", {n, 3}, ao),
                     f.appender(g + "/pressure", {n}, ao),
                     f.appender(g + "/effective_stress", {n, 6}, ao),
                     f.appender(g + "/fluid_flux", {n, 3}, ao),
                     f.appender(g + "/max_principal_stress", {n}, ao),
                     f.appender(g + "/max_shear_stress", {n}, ao),
                     f.appender(g + "/surface/total_normal_stress", {nv}, ao),
                     f.appender(g + "/surface/fluid_pressure", {nv}, ao),
                     f.appender(g + "/series/contact_area", {}, ao),
                     f.appender(g + "/series/fluid_load_support", {}, ao),
                     f.appender(g + "/series/max_tensile_stress", {}, ao),
                     f.appender_int(g + "/series/max_tensile_vertex", {}, ao),
                     f.appender_int(g + "/series/max_tensile_region", {}, ao),
                     f.appender(g + "/series/max_shear_stress", {}, ao),
                     f.appender_int(g + "/series/max_shear_vertex", {}, ao),
                     f.appender_int(g + "/series/max_shear_region", {}, ao)};
    impl_->layers.push_back(std::move(a));
  }
  f.write("/regions/names", std::vector<std::string>{"central", "anterior", "posterior", "medial", "lateral"});
  std::vector<std::string> pa, pb, pc;
  for (const JointPair& p : run.pairs()) {
    pa.push_back(p.a);
    pb.push_back(p.b);
    pc.push_back(p.compartment);
    impl_->compartments.push_back(p.compartment);
  }
  f.write("/pairs/layer_a", pa);
  f.write("/pairs/layer_b", pb);
  f.write("/pairs/compartment", pc);
  f.flush();
}

OutputWriter::~OutputWriter() = default;

void OutputWriter::append_step(double time_s, const std::vector<Eigen::Isometry3d>& X_WB,
                               const std::vector<LayerStep>& layers) {
  impl_->time->append(time_s);
  for (size_t i = 0; i < layers.size(); ++i) {
    LayerAppenders& a = impl_->layers[i];
    const LayerStep& s = layers[i];
    const Eigen::Matrix4d X = X_WB[i].matrix();
    a.X_WB.append(X);
    // Deformed positions in the world: X_WB (x + u).
    const Eigen::MatrixXd& nodes_B = impl_->nodes_B[i];
    Eigen::MatrixXd nodes_W = ((nodes_B + s.fields.displacement) * X_WB[i].linear().transpose()).rowwise() +
                              X_WB[i].translation().transpose();
    a.nodes_W.append(nodes_W);
    a.displacement.append(Eigen::MatrixXd(s.fields.displacement));
    a.pressure.append(s.fields.pressure);
    a.effective_stress.append(Eigen::MatrixXd(s.fields.effective_stress));
    a.flux.append(Eigen::MatrixXd(s.fields.flux));
    a.max_principal.append(s.fields.max_principal);
    a.max_shear.append(s.fields.max_shear);
    const int nv = impl_->num_vertices[i];
    Eigen::VectorXd total(nv);
    for (int v = 0; v < nv; ++v) total[v] = s.loads.traction.segment<3>(3 * v).norm();
    a.surface_total.append(total);
    a.surface_fluid.append(s.loads.pressure);
    a.contact_area.append(s.contact_area_m2);
    a.fls.append(s.fluid_load_support);
    a.max_tensile.append(s.max_tensile_Pa);
    a.max_tensile_vertex.append(s.max_tensile_vertex);
    a.max_tensile_region.append(static_cast<int>(s.max_tensile_region));
    a.max_shear_value.append(s.max_shear_Pa);
    a.max_shear_vertex.append(s.max_shear_vertex);
    a.max_shear_region.append(static_cast<int>(s.max_shear_region));
  }
  file_->flush();
}

void OutputWriter::write_frames(const std::vector<double>& frame_times,
                                const std::vector<std::vector<CompartmentFrame>>& frames) {
  common::H5File& f = *file_;
  f.write("/frames/time", frame_times);
  const size_t nf = frames.size();
  for (size_t k = 0; k < impl_->compartments.size(); ++k) {
    const std::string g = "/frames/" + impl_->compartments[k];
    Eigen::VectorXd force(nf), ga(nf), gb(nf), aa(nf), ab(nf), unloaded(nf);
    Eigen::VectorXi neg(nf), beyond(nf), skipped(nf);
    for (size_t i = 0; i < nf; ++i) {
      const CompartmentFrame& c = frames[i].at(k);
      force[i] = c.force_N;
      ga[i] = c.gamma_a_Pa;
      gb[i] = c.gamma_b_Pa;
      aa[i] = c.area_a_m2;
      ab[i] = c.area_b_m2;
      neg[i] = c.negative_pressure_nodes;
      beyond[i] = c.beyond_thickness_nodes;
      skipped[i] = c.skipped_no_overlap;
      unloaded[i] = c.unloaded_overlap_m2;
    }
    f.write(g + "/force_magnitude", force);
    f.write(g + "/gamma_a", ga);
    f.write(g + "/gamma_b", gb);
    f.write(g + "/contact_area_a", aa);
    f.write(g + "/contact_area_b", ab);
    f.write(g + "/negative_pressure_nodes", neg);
    f.write(g + "/beyond_thickness_nodes", beyond);
    f.write(g + "/skipped_no_overlap", skipped);
    f.write(g + "/unloaded_overlap_area", unloaded);
  }
  f.flush();
}

void OutputWriter::finish(const JointRun& run) {
  common::H5File& f = *file_;
  for (size_t i = 0; i < run.layers().size(); ++i) {
    const IntegratorCounters& c = run.problem(static_cast<int>(i)).integrator().counters();
    const std::string g = layer_group(impl_->names[i]);
    f.set_attribute(g, "factorizations", c.factorizations);
    f.set_attribute(g, "solves", c.solves);
    f.set_attribute(g, "free_unknowns", c.free_dofs);
    f.set_attribute(g, "matrix_nonzeros", static_cast<std::int64_t>(c.matrix_nonzeros));
    f.set_attribute(g, "factorization_s", c.factorization_s);
    f.set_attribute(g, "solve_s", c.solve_s);
    f.set_attribute(g, "step_s", c.step_s);
    f.set_attribute(g, "max_relative_residual", c.max_relative_residual);
  }
  impl_->time.reset();
  impl_->layers.clear();
  file_.reset();
}

void write_output_xdmf(const std::string& h5_path, const std::string& xdmf_path) {
  const common::H5File f(h5_path, common::H5File::Mode::kRead);
  common::XdmfSeries series;
  const Eigen::VectorXd t = f.read_vector("/time");
  series.times.assign(t.data(), t.data() + t.size());
  for (const std::string& name : f.read_strings("/layers/names")) {
    const std::string g = layer_group(name);
    common::XdmfSurface volume;
    volume.name = name;
    volume.geometry_dataset = g + "/nodes_W";
    volume.topology_dataset = g + "/hexahedra";
    volume.cell_type = common::XdmfCellType::kHexahedron;
    volume.fields = {{"displacement_m", g + "/displacement"},
                     {"fluid_pressure_Pa", g + "/pressure"},
                     {"fluid_flux_m_per_s", g + "/fluid_flux"},
                     {"max_principal_stress_Pa", g + "/max_principal_stress"},
                     {"max_shear_stress_Pa", g + "/max_shear_stress"}};
    series.surfaces.push_back(volume);
  }
  common::write_xdmf(xdmf_path, f, series);
}

SurfaceMaps read_surface_maps(const std::string& path) {
  const common::H5File f(path, common::H5File::Mode::kRead);
  SurfaceMaps out;
  out.time = f.read_vector("/time");
  for (const std::string& name : f.read_strings("/layers/names")) {
    const std::string g = layer_group(name);
    const std::string stress = g + "/surface/total_normal_stress", vertices = g + "/articular_vertices";
    if (!f.exists(stress) || !f.exists(vertices)) continue;
    LayerSurfaceMap m;
    m.name = name;
    m.total_normal_stress = f.read_matrix(stress);
    m.articular_vertices = f.read_matrix(vertices, 3);
    if (m.total_normal_stress.rows() != out.time.size() ||
        m.total_normal_stress.cols() != m.articular_vertices.rows())
      throw common::InputError(path, 0, "dataset " + stress + ": expected " + std::to_string(out.time.size()) +
                               " x " + std::to_string(m.articular_vertices.rows()) + ", found " +
                               std::to_string(m.total_normal_stress.rows()) + " x " +
                               std::to_string(m.total_normal_stress.cols()));
    out.layers.push_back(std::move(m));
  }
  return out;
}

std::vector<LayerSeries> read_layer_series(const std::string& path) {
  const common::H5File f(path, common::H5File::Mode::kRead);
  std::vector<LayerSeries> out;
  const Eigen::VectorXd time = f.read_vector("/time");
  const std::vector<std::string> region_names = f.read_strings("/regions/names");
  // Region code of each step -> its name; a vertex index < 0 means no vertex.
  auto where = [&](const std::string& dataset, const Eigen::VectorXi& code, const Eigen::VectorXi& vertex) {
    std::vector<std::string> names(static_cast<size_t>(code.size()));
    for (Eigen::Index i = 0; i < code.size(); ++i) {
      if (i < vertex.size() && vertex[i] < 0) {
        names[i] = "none";
        continue;
      }
      if (code[i] < 0 || code[i] >= static_cast<int>(region_names.size()))
        throw common::InputError(path, 0, "dataset " + dataset + ", step " + std::to_string(i) +
                                 ": expected a region code in [0, " + std::to_string(region_names.size()) +
                                 ") (/regions/names), found " + std::to_string(code[i]));
      names[i] = region_names[static_cast<size_t>(code[i])];
    }
    return names;
  };
  for (const std::string& name : f.read_strings("/layers/names")) {
    const std::string g = layer_group(name);
    LayerSeries s;
    s.name = name;
    s.time = time;
    s.contact_area = f.read_vector(g + "/series/contact_area");
    s.fluid_load_support = f.read_vector(g + "/series/fluid_load_support");
    s.max_tensile = f.read_vector(g + "/series/max_tensile_stress");
    s.max_shear = f.read_vector(g + "/series/max_shear_stress");
    s.max_tensile_region = f.read_vector_int(g + "/series/max_tensile_region");
    s.max_shear_region = f.read_vector_int(g + "/series/max_shear_region");
    s.max_tensile_where = where(g + "/series/max_tensile_region", s.max_tensile_region,
                                f.read_vector_int(g + "/series/max_tensile_vertex"));
    s.max_shear_where = where(g + "/series/max_shear_region", s.max_shear_region,
                              f.read_vector_int(g + "/series/max_shear_vertex"));
    for (auto [dataset, dest] : {std::pair{g + "/surface/total_normal_stress", &s.max_contact_stress},
                                 std::pair{g + "/surface/fluid_pressure", &s.max_contact_fluid_pressure}}) {
      if (!f.exists(dataset)) continue;
      const Eigen::MatrixXd m = f.read_matrix(dataset);
      if (m.rows() != time.size())
        throw common::InputError(path, 0, "dataset " + dataset + ": expected " + std::to_string(time.size()) +
                                 " rows (one per step of /time), found " + std::to_string(m.rows()));
      *dest = m.cols() ? Eigen::VectorXd(m.rowwise().maxCoeff()) : Eigen::VectorXd::Zero(m.rows());
    }
    s.factorizations = static_cast<int>(f.attribute_int(g, "factorizations"));
    s.solves = static_cast<int>(f.attribute_int(g, "solves"));
    s.unknowns = static_cast<int>(f.attribute_int(g, "unknowns"));
    s.factorization_s = f.attribute_double(g, "factorization_s");
    s.solve_s = f.attribute_double(g, "solve_s");
    out.push_back(std::move(s));
  }
  return out;
}

}  // namespace arthrosim::biphasic

namespace arthrosim::biphasic {

std::vector<OutputDifference> compare_outputs(const std::string& path, const std::string& reference_path) {
  const common::H5File a(path, common::H5File::Mode::kRead), r(reference_path, common::H5File::Mode::kRead);
  const Eigen::VectorXd ta = a.read_vector("/time"), tr = r.read_vector("/time");
  std::vector<std::pair<Eigen::Index, Eigen::Index>> common_steps;
  for (Eigen::Index i = 0, j = 0; i < ta.size() && j < tr.size();) {
    if (std::abs(ta[i] - tr[j]) < 1e-9) common_steps.emplace_back(i++, j++);
    else if (ta[i] < tr[j]) ++i;
    else ++j;
  }
  if (common_steps.empty()) {
    throw common::InputError(path, 0, "no step time in common with " + reference_path);
  }
  const std::vector<std::string> names_a = a.read_strings("/layers/names");
  std::vector<OutputDifference> out;
  for (const std::string& name : r.read_strings("/layers/names")) {
    if (std::find(names_a.begin(), names_a.end(), name) == names_a.end()) continue;
    const std::string g = layer_group(name);
    auto series = [&](const common::H5File& f, const std::string& metric) -> Eigen::VectorXd {
      if (metric == "peak_fluid_pressure") return f.read_matrix(g + "/pressure").rowwise().maxCoeff();
      return f.read_vector(g + "/series/" + metric);
    };
    for (const std::string metric :
         {"max_tensile_stress", "max_shear_stress", "fluid_load_support", "contact_area", "peak_fluid_pressure"}) {
      const Eigen::VectorXd xa = series(a, metric), xr = series(r, metric);
      OutputDifference d;
      d.layer = name;
      d.metric = metric;
      d.common_times = static_cast<int>(common_steps.size());
      double diff = 0.0;
      for (const auto& [i, j] : common_steps) {
        diff = std::max(diff, std::abs(xa[i] - xr[j]));
        d.reference_peak = std::max(d.reference_peak, std::abs(xr[j]));
        d.peak = std::max(d.peak, std::abs(xa[i]));
      }
      d.relative = d.reference_peak > 0.0 ? diff / d.reference_peak : diff;
      out.push_back(d);
    }
  }
  return out;
}

}  // namespace arthrosim::biphasic
