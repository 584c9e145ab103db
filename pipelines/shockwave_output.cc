#include "pipelines/shockwave_output.h"

#include <algorithm>
#include <stdexcept>

#include "common/hdf5.h"
#include "common/metadata.h"
#include "common/xdmf.h"
#include "shockwave/knee_model.h"

namespace arthrosim::pipelines {

namespace fs = std::filesystem;

struct ShockwaveWriter::Impl {
  const shockwave::Model& model;
  common::H5File h5;
  bool frames, fluid;
  std::vector<common::H5File::Appender> fields;  // pressure, distortional, pore
  std::unique_ptr<common::H5File::Appender> time, pulse, kinetic, potential, work, dissipation, force, displacement;
  std::vector<std::unique_ptr<common::H5File::Appender>> at_once;  // per tissue
  std::vector<double> times;
  std::vector<double> best_at_once;
  Impl(const fs::path& p, const shockwave::Model& m) : model(m), h5(p.string(), common::H5File::Mode::kTruncate) {}
};

ShockwaveWriter::ShockwaveWriter(const fs::path& h5_path, const shockwave::Model& m, const std::string& label,
                                 bool frames, bool fluid, const std::string& metadata_options,
                                 const std::vector<std::string>& argv)
    : path_(h5_path), atomic_(h5_path), impl_(std::make_unique<Impl>(atomic_.temp(), m)) {
  Impl& d = *impl_;
  d.frames = frames;
  d.fluid = fluid;
  std::vector<const char*> cargv;
  for (const std::string& a : argv) cargv.push_back(a.c_str());
  const common::RunMetadata meta = common::collect_run_metadata("arthrosim-shockwave", static_cast<int>(cargv.size()),
                                                                cargv.data(), "", metadata_options);
  common::write_metadata(d.h5, meta);
  d.h5.set_attribute("/", "schema", "arthrosim shockwave 1");
  d.h5.set_attribute("/", "run", label);
  const int n = m.size();
  Eigen::MatrixXd pos(n, 3);
  Eigen::VectorXi tissue(n);
  Eigen::MatrixXi topo(n, 1);
  for (int i = 0; i < n; ++i) {
    pos.row(i) << m.x[i], m.y[i], m.z[i];
    tissue[i] = m.tissue[i];
    topo(i, 0) = i;
  }
  d.h5.write("/model/positions", pos);
  d.h5.write("/model/tissue", tissue);
  d.h5.write("/model/topology", topo);
  std::vector<std::string> names;
  Eigen::MatrixXd params(static_cast<Eigen::Index>(m.tissues.size()), 7);
  for (size_t t = 0; t < m.tissues.size(); ++t) {
    const shockwave::Tissue& ts = m.tissues[t];
    names.push_back(ts.name);
    params.row(static_cast<Eigen::Index>(t)) << ts.density, ts.shear_modulus, ts.bulk_modulus, ts.solid_bulk_modulus,
        ts.porosity, m.constants[t].permeability, m.constants[t].total_density;
  }
  d.h5.write("/model/tissue_names", names);
  d.h5.write("/model/tissue_parameters", params);
  d.h5.set_attribute("/model", "lattice", shockwave::to_string(m.lattice.kind));
  d.h5.set_attribute("/model", "diameter_m", m.lattice.diameter);
  d.h5.set_attribute("/model", "cell_volume_m3", m.lattice.cell_volume);
  d.h5.set_attribute("/model", "contact_area_m2", m.lattice.contact_area);
  d.h5.set_attribute("/model", "bonds", static_cast<std::int64_t>(m.bonds()));
  d.time = std::make_unique<common::H5File::Appender>(d.h5.appender("/time", {}));
  d.pulse = std::make_unique<common::H5File::Appender>(d.h5.appender("/pulse/pressure", {}));
  for (const char* e : {"kinetic", "potential", "work", "dissipation"}) {
    auto a = std::make_unique<common::H5File::Appender>(d.h5.appender(std::string("/energy/") + e, {}));
    if (std::string(e) == "kinetic") d.kinetic = std::move(a);
    else if (std::string(e) == "potential") d.potential = std::move(a);
    else if (std::string(e) == "work") d.work = std::move(a);
    else d.dissipation = std::move(a);
  }
  d.force = std::make_unique<common::H5File::Appender>(d.h5.appender("/compression/force", {}));
  d.displacement = std::make_unique<common::H5File::Appender>(d.h5.appender("/compression/displacement", {}));
  if (frames) {
    d.fields.push_back(d.h5.appender("/fields/pressure", {n}));
    d.fields.push_back(d.h5.appender("/fields/distortional_strain", {n}));
    if (fluid) d.fields.push_back(d.h5.appender("/fields/pore_pressure", {n}));
  }
  for (size_t t = 0; t < m.tissues.size(); ++t)
    d.at_once.push_back(std::make_unique<common::H5File::Appender>(
        d.h5.appender("/criteria/" + m.tissues[t].name + "/all_at_once_m3", {})));
  d.best_at_once.assign(m.tissues.size(), 0.0);
}

ShockwaveWriter::~ShockwaveWriter() = default;

ShockwaveFrame shockwave_frame(const shockwave::Simulation& sim, double applied_pressure,
                               const shockwave::RegenerationCriteria& criteria, bool fields, bool fluid,
                               double compression_force, double compression_displacement) {
  const shockwave::Model& m = sim.model();
  ShockwaveFrame f;
  f.time = sim.time();
  f.applied_pressure = applied_pressure;
  const shockwave::EnergyBalance e = sim.energy();
  f.kinetic = e.kinetic;
  f.potential = e.potential;
  f.work = e.external_work;
  f.dissipation = e.dissipation;
  f.compression_force = compression_force;
  f.compression_displacement = compression_displacement;
  if (fields) {
    f.pressure = sim.pressure();
    f.distortional_strain = sim.distortional_strain();
    if (fluid) f.pore_pressure = sim.pore_pressure();
  }
  for (size_t t = 0; t < m.tissues.size(); ++t)
    f.all_at_once_m3.push_back(shockwave::regeneration_volumes(m, static_cast<int>(t), sim.pressure(),
                                                               sim.distortional_strain(), sim.pore_pressure(), criteria)
                                   .all);
  return f;
}

void ShockwaveWriter::append_frame(const shockwave::Simulation& sim, double applied_pressure,
                                   const shockwave::RegenerationCriteria& criteria, double compression_force,
                                   double compression_displacement) {
  append_frame(shockwave_frame(sim, applied_pressure, criteria, impl_->frames, impl_->fluid, compression_force,
                               compression_displacement));
}

bool ShockwaveWriter::frames() const { return impl_->frames; }
bool ShockwaveWriter::fluid() const { return impl_->fluid; }

void ShockwaveWriter::append_frame(const ShockwaveFrame& f) {
  Impl& d = *impl_;
  const size_t n = static_cast<size_t>(d.model.size());
  if (f.all_at_once_m3.size() != d.model.tissues.size() ||
      (d.frames && (f.pressure.size() != n || f.distortional_strain.size() != n ||
                    (d.fluid && f.pore_pressure.size() != n))))
    throw std::logic_error("ShockwaveWriter::append_frame: a frame of another model or without its fields");
  d.times.push_back(f.time);
  d.time->append(f.time);
  d.pulse->append(f.applied_pressure);
  d.kinetic->append(f.kinetic);
  d.potential->append(f.potential);
  d.work->append(f.work);
  d.dissipation->append(f.dissipation);
  d.force->append(f.compression_force);
  d.displacement->append(f.compression_displacement);
  if (d.frames) {
    const Eigen::Index N = static_cast<Eigen::Index>(n);
    d.fields[0].append(Eigen::Map<const Eigen::VectorXd>(f.pressure.data(), N));
    d.fields[1].append(Eigen::Map<const Eigen::VectorXd>(f.distortional_strain.data(), N));
    if (d.fluid) d.fields[2].append(Eigen::Map<const Eigen::VectorXd>(f.pore_pressure.data(), N));
  }
  for (size_t t = 0; t < d.model.tissues.size(); ++t) {
    d.at_once[t]->append(f.all_at_once_m3[t]);
    d.best_at_once[t] = std::max(d.best_at_once[t], f.all_at_once_m3[t]);
  }
}

std::vector<double> ShockwaveWriter::finish(const shockwave::Simulation& sim,
                                            const shockwave::RegenerationCriteria& criteria,
                                            const std::vector<ShockwaveEffect>& effects,
                                            const std::vector<std::pair<std::string, double>>& attributes) {
  Impl& d = *impl_;
  const shockwave::Model& m = d.model;
  const int n = m.size();
  d.h5.write("/peaks/pressure", sim.peak_pressure());
  d.h5.write("/peaks/distortional_strain", sim.peak_distortional_strain());
  d.h5.write("/peaks/pore_pressure", sim.peak_pore_pressure());
  d.h5.create_group("/criteria");
  for (size_t t = 0; t < m.tissues.size(); ++t) {
    const shockwave::RegenerationVolumes v =
        shockwave::regeneration_volumes(m, static_cast<int>(t), sim.peak_pressure(), sim.peak_distortional_strain(),
                                        sim.peak_pore_pressure(), criteria);
    const std::string g = "/criteria/" + m.tissues[t].name;
    d.h5.set_attribute(g, "tissue_m3", v.tissue);
    d.h5.set_attribute(g, "compressive_m3", v.compressive);
    d.h5.set_attribute(g, "distortional_m3", v.distortional);
    d.h5.set_attribute(g, "pore_m3", v.pore);
    d.h5.set_attribute(g, "all_m3", v.all);
  }
  d.h5.set_attribute("/criteria", "compressive_stress_min_pa", criteria.compressive_min);
  d.h5.set_attribute("/criteria", "distortional_strain_min", criteria.distortional_min);
  d.h5.set_attribute("/criteria", "distortional_strain_max", criteria.distortional_max);
  d.h5.set_attribute("/criteria", "pore_pressure_min_pa", criteria.pore_min);
  d.h5.set_attribute("/criteria", "pore_pressure_max_pa", criteria.pore_max);
  d.h5.set_attribute("/criteria", "volume",
                     "summed automaton volume of the tissue whose peak over the run lies in the range; "
                     "all_at_once_m3: automata meeting all three at one frame");
  d.h5.create_group("/solver");
  for (const auto& [k, v] : attributes) d.h5.set_attribute("/solver", k, v);
  std::vector<std::string> built, part;
  std::vector<int> count;
  for (const ShockwaveEffect& e : effects) {
    built.push_back(e.effect);
    part.push_back(e.part);
    count.push_back(static_cast<int>(e.count));
  }
  d.h5.write("/effects/built", built);
  d.h5.write("/effects/part", part);
  d.h5.write("/effects/count", count);
  d.h5.set_attribute("/effects", "stage", "shockwave");
  d.h5.flush();
  // XDMF: the automata as points, the fields per frame, peaks and tissue static.
  common::XdmfSeries series;
  common::XdmfSurface pts;
  pts.name = "automata";
  pts.geometry_dataset = "/model/positions";
  pts.topology_dataset = "/model/topology";
  pts.cell_type = common::XdmfCellType::kPolyvertex;
  const bool frames = d.frames && !d.times.empty();
  if (frames) {
    series.times = d.times;
    pts.fields.push_back({"pressure_pa", "/fields/pressure", common::XdmfCenter::kNode, true});
    pts.fields.push_back({"distortional_strain", "/fields/distortional_strain", common::XdmfCenter::kNode, true});
    if (d.fluid) pts.fields.push_back({"pore_pressure_pa", "/fields/pore_pressure", common::XdmfCenter::kNode, true});
  }
  pts.fields.push_back({"tissue", "/model/tissue", common::XdmfCenter::kNode, false});
  pts.fields.push_back({"peak_pressure_pa", "/peaks/pressure", common::XdmfCenter::kNode, false});
  pts.fields.push_back({"peak_distortional_strain", "/peaks/distortional_strain", common::XdmfCenter::kNode, false});
  if (d.fluid) pts.fields.push_back({"peak_pore_pressure_pa", "/peaks/pore_pressure", common::XdmfCenter::kNode, false});
  series.surfaces.push_back(pts);
  (void)n;
  fs::path xdmf = path_;
  xdmf.replace_extension(".xdmf");
  common::write_xdmf(xdmf.string(), d.h5, series);
  std::vector<double> best = d.best_at_once;
  impl_.reset();  // closes the appenders, then the file
  atomic_.commit();
  return best;
}

ShockwaveFile read_shockwave_file(const fs::path& p) {
  const common::H5File h5(p.string(), common::H5File::Mode::kRead);
  ShockwaveFile f;
  f.label = h5.attribute_string("/", "run");
  f.tissue_names = h5.read_strings("/model/tissue_names");
  f.tissue = h5.read_vector_int("/model/tissue");
  f.peak_pressure = h5.read_vector("/peaks/pressure");
  f.peak_distortional_strain = h5.read_vector("/peaks/distortional_strain");
  f.peak_pore_pressure = h5.read_vector("/peaks/pore_pressure");
  const Eigen::VectorXd t = h5.read_vector("/time");
  f.time.assign(t.data(), t.data() + t.size());
  for (const std::string& name : f.tissue_names) {
    const std::string g = "/criteria/" + name;
    f.volumes.push_back({h5.attribute_double(g, "tissue_m3"), h5.attribute_double(g, "compressive_m3"),
                         h5.attribute_double(g, "distortional_m3"), h5.attribute_double(g, "pore_m3"),
                         h5.attribute_double(g, "all_m3")});
  }
  f.effects = h5.read_strings("/effects/built");
  if (h5.has_attribute("/solver", "efd_j_per_m2")) f.efd_j_per_m2 = h5.attribute_double("/solver", "efd_j_per_m2");
  return f;
}

}  // namespace arthrosim::pipelines
