#include "pipelines/surface_output.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/error.h"
#include "common/hdf5.h"
#include "common/metadata.h"
#include "common/output_file.h"
#include "common/xdmf.h"

namespace arthrosim::pipelines::surface_output {

using common::H5File;

std::string file_name(const std::string& scenario) { return "surface_" + scenario + ".h5"; }

namespace {
std::string surface_group(const std::string& name) { return "/surfaces/" + name; }
}  // namespace

// ---------------------------------------------------------------------------
// Writer
// ---------------------------------------------------------------------------
struct Writer::Impl {
  Impl(const std::string& path) : atomic(path), out(atomic.temp().string(), H5File::Mode::kTruncate), path(path) {}
  common::AtomicOutput atomic;
  H5File out;
  std::string path;
  Layout layout;
  struct SurfaceSeries {
    std::string name;
    H5File::Appender displacement, deflection, E, e1, e1_dir, e2;
    std::optional<H5File::Appender> contact_pressure;
  };
  std::vector<SurfaceSeries> surfaces;
  struct SolverSeries {
    H5File::Appender time, dt, newton_iterations, residual_N, residual_tolerance_N, rejections, wall_s,
        max_deflection_m;
    std::optional<H5File::Appender> change_m, augmentations;
    std::optional<H5File::Appender> max_penetration_m, penetration_ratio, active_contacts, max_rim_depth_m,
        max_unfaded_penetration_m, unfaded_penetration_ratio;
  };
  std::optional<SolverSeries> solver;
  struct ContactSeries {
    H5File::Appender force, medial_force, lateral_force, area, max_penetration;
  };
  std::optional<ContactSeries> contact;
  std::optional<H5File::Appender> time, trial_time;
  std::vector<double> times;

  void write_sidecar() {
    common::XdmfSeries series;
    series.times = times;
    for (const SurfaceSeries& r : surfaces) {
      const std::string g = surface_group(r.name) + "/";
      common::XdmfSurface s;
      s.name = r.name;
      s.geometry_dataset = g + "nodes";
      s.topology_dataset = g + "quads";
      s.cell_type = common::XdmfCellType::kQuadrilateral;
      s.fields = {{"displacement", g + "displacement"}, {"deflection", g + "deflection"},
                  {"E", g + "strain/E"},                {"e1", g + "strain/e1"},
                  {"e1_dir", g + "strain/e1_dir"},      {"e2", g + "strain/e2"}};
      if (layout.contact) s.fields.push_back({"contact_pressure", g + "contact_pressure"});
      series.surfaces.push_back(std::move(s));
    }
    common::write_xdmf(std::filesystem::path(path).replace_extension(".xdmf").string(), out, series);
  }
};

Writer::Writer(const std::string& path, const common::RunMetadata& metadata, const Layout& layout,
               const common::EffectLedger& ledger)
    : impl_(std::make_unique<Impl>(path)) {
  Impl& m = *impl_;
  m.layout = layout;
  H5File& out = m.out;
  common::write_metadata(out, metadata);
  out.set_attribute("/", "schema", kSchema);
  out.set_attribute("/", "scenario", layout.scenario);
  out.set_attribute("/", "prepared_model", layout.prepared_model);
  out.set_attribute("/", "mesh", layout.mesh);
  out.set_attribute("/", "mode", layout.mode);
  out.set_attribute("/", "status", "running");
  out.set_attribute("/", "seating_time_s", layout.seating_time_s);
  if (!layout.partial_input.empty()) out.set_attribute("/", "partial_input", layout.partial_input);
  common::write_effect_ledger(out, ledger);
  m.time.emplace(out.appender("/time", {}, {layout.frames_expected, 0}));
  if (layout.trial_time) m.trial_time.emplace(out.appender("/trial_time", {}, {layout.frames_expected, 0}));
}

Writer::~Writer() = default;

void Writer::add_surface(const SurfaceGeometry& s) {
  Impl& m = *impl_;
  H5File& out = m.out;
  const std::string g = surface_group(s.name) + "/";
  const std::int64_t N = s.nodes.rows();
  out.write(g + "nodes", s.nodes);
  out.write(g + "quads", Eigen::MatrixXi(s.quads));
  out.write(g + "normals", Eigen::MatrixXd(s.normals));
  out.write(g + "basis_a1", Eigen::MatrixXd(s.basis_a1));
  out.write(g + "basis_a2", Eigen::MatrixXd(s.basis_a2));
  if (!s.bone.empty()) out.set_attribute(surface_group(s.name), "bone", s.bone);
  out.write(g + "fixed", s.fixed);
  const common::H5AppendOptions fo{m.layout.frames_expected, 0};
  Impl::SurfaceSeries series{s.name,
                             out.appender(g + "displacement", {N, 3}, fo),
                             out.appender(g + "deflection", {N}, fo),
                             out.appender(g + "strain/E", {N, 3}, fo),
                             out.appender(g + "strain/e1", {N}, fo),
                             out.appender(g + "strain/e1_dir", {N, 3}, fo),
                             out.appender(g + "strain/e2", {N}, fo),
                             {}};
  if (m.layout.contact) series.contact_pressure.emplace(out.appender(g + "contact_pressure", {N}, fo));
  m.surfaces.push_back(std::move(series));
}

void Writer::flush() {
  Impl& m = *impl_;
  H5File& out = m.out;
  if (!m.solver) {
    // The per-step and contact series (created after the surfaces).
    const common::H5AppendOptions so{m.layout.steps_expected, 0};
    Impl::SolverSeries s{out.appender("/solver/time", {}, so),
                         out.appender("/solver/dt", {}, so),
                         out.appender_int("/solver/newton_iterations", {}, so),
                         out.appender("/solver/residual_N", {}, so),
                         out.appender("/solver/residual_tolerance_N", {}, so),
                         out.appender_int("/solver/rejections", {}, so),
                         out.appender("/solver/wall_s", {}, so),
                         out.appender("/solver/max_deflection_m", {}, so),
                         {}, {}, {}, {}, {}, {}, {}, {}};
    // steady_state_change_mm: the largest weighted coordinate change per step.
    if (m.layout.change) s.change_m.emplace(out.appender("/solver/change_m", {}, so));
    if (m.layout.augmentations) s.augmentations.emplace(out.appender_int("/solver/contact_augmentations", {}, so));
    if (m.layout.contact) {
      s.max_penetration_m.emplace(out.appender("/solver/max_penetration_m", {}, so));
      s.penetration_ratio.emplace(out.appender("/solver/penetration_ratio", {}, so));
      s.active_contacts.emplace(out.appender_int("/solver/active_contacts", {}, so));
      s.max_rim_depth_m.emplace(out.appender("/solver/max_rim_depth_m", {}, so));
      s.max_unfaded_penetration_m.emplace(out.appender("/solver/max_unfaded_penetration_m", {}, so));
      s.unfaded_penetration_ratio.emplace(out.appender("/solver/unfaded_penetration_ratio", {}, so));
    }
    m.solver.emplace(std::move(s));
    // Tibiofemoral contact force per frame (on the second surface of each
    // pair, in its bone's frame; pairs named medial/lateral are the
    // compartments), as in the kinematics file.
    if (m.layout.contact) {
      const common::H5AppendOptions fo{m.layout.frames_expected, 0};
      m.contact.emplace(Impl::ContactSeries{out.appender(kContactForce, {3}, fo),
                                            out.appender(std::string(kContactGroup) + "/medial_force", {3}, fo),
                                            out.appender(std::string(kContactGroup) + "/lateral_force", {3}, fo),
                                            out.appender(std::string(kContactGroup) + "/area", {}, fo),
                                            out.appender(std::string(kContactGroup) + "/max_penetration", {}, fo)});
      out.write("/contact/pairs", m.layout.contact_pairs);
    }
  }
  out.flush();
}

void Writer::append_frame(double t, double trial_time, const std::vector<SurfaceFrame>& frames,
                          const ContactFrame* contact) {
  Impl& m = *impl_;
  if (frames.size() != m.surfaces.size())
    throw std::logic_error("surface_output::Writer::append_frame: " + std::to_string(frames.size()) +
                           " surfaces for " + std::to_string(m.surfaces.size()));
  for (std::size_t k = 0; k < frames.size(); ++k) {
    Impl::SurfaceSeries& s = m.surfaces[k];
    const SurfaceFrame& f = frames[k];
    s.displacement.append(f.displacement);
    s.deflection.append(f.deflection);
    s.E.append(f.E);
    s.e1.append(f.e1);
    s.e1_dir.append(f.e1_dir);
    s.e2.append(f.e2);
    if (s.contact_pressure) s.contact_pressure->append(f.contact_pressure);
  }
  if (m.contact && contact) {
    m.contact->force.append(contact->force);
    m.contact->medial_force.append(contact->medial_force);
    m.contact->lateral_force.append(contact->lateral_force);
    m.contact->area.append(contact->area);
    m.contact->max_penetration.append(contact->max_penetration);
  }
  m.time->append(t);
  if (m.trial_time) m.trial_time->append(trial_time);
  m.times.push_back(t);
  m.write_sidecar();
}

void Writer::append_step(const StepRecord& r) {
  Impl::SolverSeries& s = *impl_->solver;
  s.time.append(r.time);
  s.dt.append(r.dt);
  s.newton_iterations.append(r.newton_iterations);
  s.residual_N.append(r.residual_N);
  s.residual_tolerance_N.append(r.residual_tolerance_N);
  s.rejections.append(r.rejections);
  s.wall_s.append(r.wall_s);
  s.max_deflection_m.append(r.max_deflection_m);
  if (s.change_m) s.change_m->append(r.change_m);
  if (s.augmentations) s.augmentations->append(r.augmentations);
  if (s.max_penetration_m) {
    s.max_penetration_m->append(r.max_penetration_m);
    s.penetration_ratio->append(r.penetration_ratio);
    s.active_contacts->append(r.active_contacts);
    s.max_rim_depth_m->append(r.max_rim_depth_m);
    s.max_unfaded_penetration_m->append(r.max_unfaded_penetration_m);
    s.unfaded_penetration_ratio->append(r.unfaded_penetration_ratio);
  }
}

void Writer::set_surface_summary(const std::string& surface, const SurfaceSummaryAttributes& a) {
  H5File& out = impl_->out;
  const std::string g = surface_group(surface);
  out.set_attribute(g, "max_deflection_m", a.max_deflection_m);
  out.set_attribute(g, "max_deflection_time_s", a.max_deflection_time_s);
  out.set_attribute(g, "e1_min", a.e1_min);
  out.set_attribute(g, "e1_max", a.e1_max);
  out.set_attribute(g, "e2_min", a.e2_min);
  out.set_attribute(g, "final_residual_N", a.final_residual_N);
  out.set_attribute(g, "residual_tolerance_N", a.residual_tolerance_N);
}

void Writer::set_reactions(const std::string& surface, const std::string& name, const std::string& set,
                           const std::string& components, const Eigen::MatrixXd& frames_x3) {
  H5File& out = impl_->out;
  const std::string g = surface_group(surface) + "/reactions";
  if (!out.exists(g)) out.create_group(g);
  out.write(g + "/" + name, frames_x3);
  out.set_attribute(g + "/" + name, "set", set);
  out.set_attribute(g + "/" + name, "components", components);
  out.set_attribute(g + "/" + name, "unit", "N");
}

void Writer::set_solver_attribute(const std::string& name, double value) {
  impl_->out.set_attribute("/solver", name, value);
}
void Writer::set_solver_attribute(const std::string& name, std::int64_t value) {
  impl_->out.set_attribute("/solver", name, value);
}
void Writer::set_solver_attribute(const std::string& name, const std::string& value) {
  impl_->out.set_attribute("/solver", name, value);
}
void Writer::set_root_attribute(const std::string& name, double value) { impl_->out.set_attribute("/", name, value); }

void Writer::complete() {
  Impl& m = *impl_;
  for (Impl::SurfaceSeries& s : m.surfaces) {
    s.displacement.close();
    s.deflection.close();
    s.E.close();
    s.e1.close();
    s.e1_dir.close();
    s.e2.close();
    if (s.contact_pressure) s.contact_pressure->close();
  }
  if (m.solver) {
    Impl::SolverSeries& s = *m.solver;
    for (H5File::Appender* a : {&s.time, &s.dt, &s.newton_iterations, &s.residual_N, &s.residual_tolerance_N,
                                &s.rejections, &s.wall_s, &s.max_deflection_m})
      a->close();
    for (std::optional<H5File::Appender>* a :
         {&s.change_m, &s.augmentations, &s.max_penetration_m, &s.penetration_ratio, &s.active_contacts, &s.max_rim_depth_m,
          &s.max_unfaded_penetration_m, &s.unfaded_penetration_ratio})
      if (*a) (*a)->close();
  }
  if (m.contact) {
    for (H5File::Appender* a : {&m.contact->force, &m.contact->medial_force, &m.contact->lateral_force,
                                &m.contact->area, &m.contact->max_penetration})
      a->close();
  }
  m.time->close();
  if (m.trial_time) m.trial_time->close();
  m.out.set_attribute("/", "status", "completed");
  m.out.flush();
  m.write_sidecar();
  m.atomic.commit();
}

void Writer::fail(const std::string& why) {
  impl_->out.set_attribute("/", "status", "failed: " + why);
  impl_->out.flush();
}

// ---------------------------------------------------------------------------
// Reader
// ---------------------------------------------------------------------------
Reader::Reader(const std::string& path) : f_(std::make_unique<H5File>(path, H5File::Mode::kRead)) {}
Reader::~Reader() = default;
const std::string& Reader::path() const { return f_->path(); }
const H5File& Reader::file() const { return *f_; }

std::vector<std::string> Reader::surfaces() const {
  return f_->exists("/surfaces") ? f_->list("/surfaces") : std::vector<std::string>{};
}

Eigen::VectorXd Reader::time() const { return f_->read_vector("/time"); }

Eigen::VectorXd Reader::trial_time() const {
  return f_->read_vector(f_->exists("/trial_time") ? "/trial_time" : "/time");
}

StrainField Reader::strain_field(const std::string& surface) const {
  const H5File& f = *f_;
  const std::string& path = f.path();
  const std::string g = surface_group(surface);
  if (!f.is_group(g)) {
    std::string have;
    if (f.is_group("/surfaces"))
      for (const auto& n : f.list("/surfaces")) have += (have.empty() ? "" : ", ") + n;
    throw common::InputError(path, 0, "expected group " + g + " (the view's surface), found " +
                                          (have.empty() ? std::string("no /surfaces group") : "surfaces: " + have));
  }
  StrainField s;
  s.file = path;
  s.surface = surface;
  s.mesh.name = surface;
  s.mesh.V = f.read_matrix(g + "/nodes", 3);
  s.mesh.Q = f.read_matrix_int(g + "/quads", 4);
  s.e1 = f.read_matrix(g + "/strain/e1");
  const common::Tensor3d d = f.read_tensor3(g + "/strain/e1_dir");
  const auto N = s.mesh.V.rows();
  const auto T = s.e1.rows();
  if (s.e1.cols() != N) {
    throw common::InputError(path, 0, "dataset " + g + "/strain/e1: expected dims (frames, " + std::to_string(N) +
                                          "), found (" + std::to_string(T) + ", " + std::to_string(s.e1.cols()) +
                                          ")");
  }
  if (d.dims[0] != T || d.dims[1] != N || d.dims[2] != 3) {
    throw common::InputError(path, 0, "dataset " + g + "/strain/e1_dir: expected dims (" + std::to_string(T) + ", " +
                                          std::to_string(N) + ", 3), found (" + std::to_string(d.dims[0]) + ", " +
                                          std::to_string(d.dims[1]) + ", " + std::to_string(d.dims[2]) + ")");
  }
  if (s.mesh.Q.size() > 0 && (s.mesh.Q.minCoeff() < 0 || s.mesh.Q.maxCoeff() >= N)) {
    throw common::InputError(path, 0, "dataset " + g + "/quads: node index out of range [0, " + std::to_string(N) + ")");
  }
  s.e1_dir.resize(T);
  for (Eigen::Index t = 0; t < T; ++t) {
    s.e1_dir[t].resize(N, 3);
    for (Eigen::Index i = 0; i < N; ++i)
      for (int k = 0; k < 3; ++k) s.e1_dir[t](i, k) = d(t, i, k);
  }
  // A run with imposed kinematics starts with a seating ramp: /trial_time
  // puts its frames on the kinematics file's clock.
  if (f.exists("/trial_time")) {
    s.time = f.read_vector("/trial_time");
    if (s.time.size() != T)
      throw common::InputError(path, 0, "dataset /trial_time: expected " + std::to_string(T) + " frames, found " +
                                            std::to_string(s.time.size()));
  } else if (f.exists("/time")) {
    s.time = f.read_vector("/time");
  } else {
    s.time = Eigen::VectorXd::LinSpaced(T, 0, T - 1);
  }
  if (f.exists(g + "/deflection")) {
    s.deflection = f.read_matrix(g + "/deflection");
    if (s.deflection.rows() != T || s.deflection.cols() != N) {
      throw common::InputError(path, 0, "dataset " + g + "/deflection: expected dims (" + std::to_string(T) + ", " +
                                            std::to_string(N) + ")");
    }
  }
  if (!s.e1.allFinite()) throw common::InputError(path, 0, "dataset " + g + "/strain/e1 contains NaN/Inf");
  return s;
}

std::optional<Eigen::MatrixXd> Reader::deflection(const std::string& surface, std::string& why) const {
  const std::string ds = surface_group(surface) + "/deflection";
  if (!f_->exists(ds)) {
    why = "no " + ds + " in " + f_->path();
    return std::nullopt;
  }
  const Eigen::MatrixXd d = f_->read_matrix(ds);
  // /time counts the complete frames (docs/surface_output.md).
  const Eigen::Index n = std::min<Eigen::Index>(d.rows(), time().size());
  return Eigen::MatrixXd(d.topRows(n));
}

std::optional<Series> Reader::contact_force() const {
  if (!f_->exists(kContactForce)) return std::nullopt;
  Series s{time(), f_->read_matrix(kContactForce, 3)};
  // Frames of the force beyond /time are incomplete.
  const Eigen::Index n = std::min(s.values.rows(), s.time.size());
  s.values.conservativeResize(n, 3);
  s.time.conservativeResize(n);
  return s;
}

std::optional<Series> Reader::max_contact_pressure(std::string& why) const {
  const H5File& f = *f_;
  if (!f.exists("/trial_time")) {
    why = f.path() + " has no /trial_time (not on the kinematics clock)";
    return std::nullopt;
  }
  const Eigen::VectorXd t = f.read_vector("/trial_time");
  // /time counts the complete frames (docs/surface_output.md).
  const Eigen::Index n = std::min<Eigen::Index>(t.size(), time().size());
  Series s{t.head(n), Eigen::MatrixXd::Constant(n, 1, -std::numeric_limits<double>::infinity())};
  bool any = false;
  for (const std::string& name : surfaces()) {
    const std::string ds = surface_group(name) + "/contact_pressure";
    if (!f.exists(ds)) continue;
    const Eigen::MatrixXd p = f.read_matrix(ds);
    if (p.rows() < n)
      throw common::InputError(f.path(), 0, "dataset " + ds + ": expected at least " + std::to_string(n) +
                                                " frames (/time), found " + std::to_string(p.rows()));
    if (p.cols() == 0) continue;
    s.values.col(0) = s.values.col(0).cwiseMax(p.topRows(n).rowwise().maxCoeff());
    any = true;
  }
  if (!any) {
    why = "no surface of " + f.path() + " has contact_pressure";
    return std::nullopt;
  }
  return s;
}

std::optional<common::EffectLedger> Reader::ledger() const {
  if (!f_->exists("/effects/built")) return std::nullopt;
  return common::read_effect_ledger(*f_);
}

std::optional<PenetrationSeries> Reader::penetration() const {
  const H5File& f = *f_;
  if (!f.exists("/solver/penetration_ratio") || !f.exists("/solver/time") || !f.exists("/solver/active_contacts"))
    return std::nullopt;
  PenetrationSeries p;
  p.time = f.read_vector("/solver/time");
  p.ratio = f.read_vector("/solver/penetration_ratio");
  p.active_contacts = f.read_vector_int("/solver/active_contacts");  // int, as the stage writes it
  if (p.ratio.size() != p.time.size() || p.active_contacts.size() != p.time.size())
    throw common::InputError(f.path(), 0,
                             "/solver/penetration_ratio, /solver/active_contacts and /solver/time have different "
                             "lengths (" + std::to_string(p.ratio.size()) + ", " +
                                 std::to_string(p.active_contacts.size()) + ", " + std::to_string(p.time.size()) + ")");
  if (f.exists("/trial_time") && f.exists("/time")) {
    const Eigen::VectorXd tt = f.read_vector("/trial_time"), ts = f.read_vector("/time");
    if (tt.size() > 0 && tt.size() == ts.size()) p.trial_offset_s = tt(tt.size() - 1) - ts(ts.size() - 1);
  }
  if (f.has_attribute("/solver", "penetration_limit")) p.limit = f.attribute_double("/solver", "penetration_limit");
  p.has_unfaded = f.exists("/solver/unfaded_penetration_ratio");
  if (p.has_unfaded) {
    p.unfaded_ratio = f.read_vector("/solver/unfaded_penetration_ratio");
    if (p.unfaded_ratio.size() != p.time.size())
      throw common::InputError(f.path(), 0, "/solver/unfaded_penetration_ratio has " +
                                                std::to_string(p.unfaded_ratio.size()) + " values, /solver/time " +
                                                std::to_string(p.time.size()));
  }
  return p;
}

}  // namespace arthrosim::pipelines::surface_output
