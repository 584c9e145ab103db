#include "musculoskeletal/kinematics_file.h"

#include <filesystem>
#include <map>
#include <stdexcept>

#include "common/effects.h"
#include "common/finite.h"
#include "common/error.h"
#include "common/file_check.h"
#include "common/hdf5.h"
#include "common/metadata.h"
#include "common/output_file.h"
#include "common/storage.h"
#include "common/xdmf.h"

namespace arthrosim::musculoskeletal {

namespace {

bool contains(const std::string& s, const char* w) { return s.find(w) != std::string::npos; }

ContactSummary summarize(const Model& model, const ModelData& data, int body, bool split) {
  ContactSummary s;
  const Pose& X_WB = data.kinematics.X_WB[body];
  const Eigen::Matrix3d R_BW = X_WB.linear().transpose();
  double weight = 0.0;
  for (size_t i = 0; i < model.contacts.size(); ++i) {
    const ContactPair& pair = model.contacts[i];
    if (pair.casting().body != body) continue;
    const ContactResult& r = data.contacts[i].result;
    const Eigen::Vector3d f_B = R_BW * r.force_on_casting_W;
    s.force += f_B;
    // Compartments (docs/kinematics_file.md): a pair named after one takes
    // its whole force there; a pair whose casting surface holds both plateaus
    // splits per casting triangle (prepare's rule, common/compartments.h).
    const bool named = contains(pair.name(), "medial") || contains(pair.name(), "lateral");
    if (split && contains(pair.name(), "medial")) s.medial_force += f_B;
    if (split && contains(pair.name(), "lateral")) s.lateral_force += f_B;
    if (split && !named && !pair.casting().compartment.empty()) {
      const CompartmentForces c = casting_force_by_compartment(pair, r);  // casting body == body
      s.medial_force += c.medial;
      s.lateral_force += c.lateral;
    }
    s.area += r.contact_area;
    s.max_pressure = std::max(s.max_pressure, r.max_pressure);
    // Combined centre of pressure: the pairs' centres weighted by their
    // force magnitudes (each pair's own centre is the pressure-weighted one).
    const double w = r.force_on_casting_W.norm();
    if (r.num_contacting > 0 && w > 0) {
      s.cop += w * (X_WB.inverse() * r.center_of_pressure_W);
      weight += w;
    }
  }
  if (weight > 0) s.cop /= weight;
  return s;
}

Eigen::Matrix4d pose_matrix(const Pose& X) { return X.matrix(); }

}  // namespace

ContactSummary tibiofemoral_contact(const Model& model, const ModelData& data) {
  return summarize(model, data, model.role_body("tibia"), true);
}

ContactSummary patellofemoral_contact(const Model& model, const ModelData& data) {
  return summarize(model, data, model.role_body("patella"), false);
}

std::string tibiofemoral_compartment_rule(const Model& model) {
  const int tibia = model.role_body("tibia");
  std::string rule;
  for (const ContactPair& pair : model.contacts) {
    if (pair.casting().body != tibia || tibia < 0) continue;
    std::string how;
    if (contains(pair.name(), "medial") || contains(pair.name(), "lateral")) {
      how = std::string(contains(pair.name(), "medial") ? "medial" : "") +
            (contains(pair.name(), "medial") && contains(pair.name(), "lateral") ? " and " : "") +
            (contains(pair.name(), "lateral") ? "lateral" : "") + " by the pair's name";
    } else if (!pair.casting().compartment.empty()) {
      how = "per casting triangle: " + pair.casting().compartment_rule;
    } else {
      how = "not split (one compartment surface without split_lateral: counted in force only)";
    }
    rule += (rule.empty() ? "" : "; ") + pair.name() + ": " + how;
  }
  return rule;
}

struct KinematicsFileWriter::Impl {
  std::string path;
  const ComakProblem& problem;
  KinematicsFileInfo info;
  common::H5File file;
  std::map<std::string, common::H5File::Appender> app;
  std::vector<std::string> coordinate_names, muscle_names, pair_names;
  std::vector<int> pair_rows;  ///< triangles per pair
  // .sto rows
  std::vector<double> times;
  std::vector<Eigen::VectorXd> sto_act, sto_q, sto_contact;
  bool finished = false;

  Impl(const std::string& p, const ComakProblem& pr, const KinematicsFileInfo& i)
      : path(p), problem(pr), info(i), file(p, common::H5File::Mode::kTruncate) {}

  common::H5File::Appender& a(const std::string& name, std::vector<std::int64_t> dims,
                              bool is_int = false) {
    auto it = app.find(name);
    if (it != app.end()) return it->second;
    common::H5AppendOptions o;
    o.expected_frames = info.expected_frames;
    return app.emplace(name, is_int ? file.appender_int(name, dims, o) : file.appender(name, dims, o))
        .first->second;
  }
};

KinematicsFileWriter::KinematicsFileWriter(const std::string& path, const ComakProblem& problem,
                                           const KinematicsFileInfo& info,
                                           const common::RunMetadata& metadata)
    : impl_(std::make_unique<Impl>(path, problem, info)) {
  const Model& m = problem.model();
  auto& f = impl_->file;
  common::write_metadata(f, metadata);
  f.set_attribute("/", "format", "arthrosim kinematics file");
  f.set_attribute("/", "format_version", 1);
  // Consumers compare it with `frames` (common/file_check.h).
  f.set_attribute("/", "frames_expected", info.expected_frames);
  f.set_attribute("/", "body_mass_kg", info.body_mass_kg);
  f.set_attribute("/", "synthetic_trial", info.synthetic ? 1 : 0);
  f.set_attribute("/", "model", info.model_path);
  f.set_attribute("/", "trial", info.trial_path);
  f.set_attribute("/", "world_frame", "femur (the model's root body; its pose is the identity)");
  f.set_attribute("/", "ankle_equilibrium", problem.options().ankle_equilibrium ? 1 : 0);
  // 1: the tibia and patella carried their own weight and d'Alembert forces and
  // the applied external load was the foot's moved to the knee; /external_loads
  // still holds the inverse dynamics' F_ext, M_ext (shank included).
  f.set_attribute("/", "body_inertia", problem.options().body_inertia ? 1 : 0);
  // "model dynamics": the model's own leg carried the trial's forces and its
  // bodies' weight and inertia (no /external_loads datasets); otherwise the
  // generic leg chain's knee loads (/external_loads).
  f.set_attribute("/", "external_loads",
                  problem.model_dynamics() ? "model dynamics" : "generic leg chain (knee_loads.h)");
  for (int c : problem.free_coordinates()) impl_->coordinate_names.push_back(m.tree.coordinates[c]);
  f.write("/coordinates/names", impl_->coordinate_names);
  std::vector<std::string> pres;
  for (int c : m.prescribed_coordinates) pres.push_back(m.tree.coordinates[c]);
  f.write("/coordinates/prescribed_names", pres);
  for (const auto& mu : m.muscles) impl_->muscle_names.push_back(mu.name);
  f.write("/muscles/names", impl_->muscle_names);
  f.write("/muscles/max_isometric_force", [&] {
    Eigen::VectorXd v(m.muscles.size());
    for (size_t i = 0; i < m.muscles.size(); ++i) v[i] = m.muscles[i].max_isometric_force;
    return v;
  }());
  f.write("/muscles/volume_weight", problem.volume_weights());
  std::vector<std::string> bundles, groups;
  for (const auto& l : m.ligaments)
    for (size_t b = 0; b < l.bundles.size(); ++b) {
      bundles.push_back(l.bundles[b].name.empty() ? l.name + "/" + std::to_string(b + 1) : l.bundles[b].name);
      groups.push_back(l.name);
    }
  f.write("/ligaments/names", bundles);
  f.write("/ligaments/group", groups);
  if (info.pressure_fields) {
    for (const auto& pair : m.contacts) {
      const std::string g = "/contact/pairs/" + pair.name();
      f.write(g + "/vertices", pair.casting().mesh.V);
      f.write(g + "/triangles", pair.casting().mesh.F);
      f.set_attribute(g, "casting_body", m.tree.bodies[pair.casting().body].name);
      f.set_attribute(g, "target_body", m.tree.bodies[pair.target().body].name);
      impl_->pair_names.push_back(pair.name());
      impl_->pair_rows.push_back(static_cast<int>(pair.casting().mesh.F.rows()));
    }
  }
  f.flush();
}

KinematicsFileWriter::~KinematicsFileWriter() = default;

void KinematicsFileWriter::append(const ComakFrameInput& in, const ComakFrameResult& r,
                                  const ModelData& d) {
  Impl& w = *impl_;
  const ComakProblem& p = w.problem;
  const Model& m = p.model();
  const int nf = static_cast<int>(p.free_coordinates().size());
  const int nm = static_cast<int>(m.muscles.size());
  w.a("/time", {}).append(in.time);
  w.a("/frame_index", {}, true).append(in.index);
  Eigen::VectorXd qf(nf);
  for (int k = 0; k < nf; ++k) qf[k] = r.q[p.free_coordinates()[k]];
  w.a("/coordinates/values", {nf}).append(qf);
  Eigen::VectorXd qp(m.prescribed_coordinates.size());
  for (size_t k = 0; k < m.prescribed_coordinates.size(); ++k) qp[k] = r.q[m.prescribed_coordinates[k]];
  w.a("/coordinates/prescribed_values", {qp.size()}).append(qp);
  for (const char* b : {"femur", "tibia", "patella"}) {
    const int bi = m.role_body(b);
    if (bi < 0) continue;
    w.a(std::string("/bodies/") + b + "/X_W", {4, 4}).append(pose_matrix(d.kinematics.X_WB[bi]));
  }
  w.a("/muscles/activation", {nm}).append(r.activations);
  w.a("/muscles/force", {nm}).append(d.muscle_forces);
  const int nb = m.num_bundles();
  Eigen::VectorXd lf(nb), ls(nb), ll(nb);
  int b = 0;
  for (const auto& lig : d.ligaments)
    for (const auto& br : lig) lf[b] = br.force.total, ls[b] = br.force.strain, ll[b] = br.path.length, ++b;
  w.a("/ligaments/force", {nb}).append(lf);
  w.a("/ligaments/strain", {nb}).append(ls);
  w.a("/ligaments/length", {nb}).append(ll);
  const ContactSummary tf = tibiofemoral_contact(m, d), pf = patellofemoral_contact(m, d);
  for (const auto& [name, s] : {std::pair{"tibiofemoral", tf}, std::pair{"patellofemoral", pf}}) {
    const std::string g = std::string("/contact/") + name;
    w.a(g + "/force", {3}).append(s.force);
    if (std::string(name) == "tibiofemoral") {
      w.a(g + "/medial_force", {3}).append(s.medial_force);
      w.a(g + "/lateral_force", {3}).append(s.lateral_force);
    }
    w.a(g + "/cop", {3}).append(s.cop);
    w.a(g + "/area", {}).append(s.area);
    w.a(g + "/max_pressure", {}).append(s.max_pressure);
  }
  for (size_t i = 0; i < w.pair_names.size(); ++i) {
    const std::string g = "/contact/pairs/" + w.pair_names[i];
    w.a(g + "/pressure", {w.pair_rows[i]}).append(d.contacts[i].result.pressure);
  }
  if (!in.model_dynamics) {  // model dynamics: the trial's own forces, see the root attribute
    w.a("/external_loads/force_T", {3}).append(in.F_ext_T);
    w.a("/external_loads/moment_T", {3}).append(in.M_ext_T);
  }
  if (p.options().ankle_equilibrium)
    w.a("/external_loads/ankle_moment", {}).append(p.external_ankle_moment(in));
  if (p.options().reserve_actuators) w.a("/reserves/values", {nf}).append(r.reserves);
  w.a("/solver/status", {}, true).append(static_cast<int>(r.status));
  w.a("/solver/ipopt_status", {}, true).append(r.ipopt_status);
  w.a("/solver/iterations", {}, true).append(r.iterations);
  w.a("/solver/attempts", {}, true).append(r.attempts);
  w.a("/solver/constraint_violation", {2})
      .append(Eigen::Vector2d(r.max_force_residual, r.max_moment_residual));
  w.a("/solver/objective", {}).append(r.objective);
  w.a("/solver/wall_time", {}).append(r.wall_time);

  w.times.push_back(in.time);
  w.sto_act.push_back(r.activations);
  w.sto_q.push_back(qf);
  Eigen::VectorXd c(12);
  c << tf.force, tf.medial_force, tf.lateral_force, pf.force;
  w.sto_contact.push_back(c);
}

void KinematicsFileWriter::finish(const ComakRunSummary& s, const common::EffectLedger& ledger,
                                  const std::string& sto_prefix) {
  Impl& w = *impl_;
  if (w.finished) return;
  w.finished = true;
  for (auto& [name, ap] : w.app) ap.close();
  auto& f = w.file;
  f.set_attribute("/", "frames", s.frames);
  f.set_attribute("/", "frames_converged", s.converged);
  f.set_attribute("/", "frames_failed", s.failed);
  if (!s.stopped.empty()) f.set_attribute("/", "stopped", s.stopped);
  f.write("/solver/failed_frames", s.failed_frames);
  if (f.exists(KinematicsFileReader::kContactGroup))
    f.set_attribute(KinematicsFileReader::kContactGroup, "compartments",
                    tibiofemoral_compartment_rule(w.problem.model()));
  f.set_attribute("/solver", "first_settle", s.first_settle.message);
  common::write_effect_ledger(f, ledger);
  if (!w.pair_names.empty() && !w.times.empty()) {
    common::XdmfSeries series;
    series.times = w.times;
    for (const auto& n : w.pair_names) {
      const std::string g = "/contact/pairs/" + n;
      common::XdmfSurface surf;
      surf.name = n;
      surf.geometry_dataset = g + "/vertices";
      surf.topology_dataset = g + "/triangles";
      surf.fields.push_back({"pressure", g + "/pressure", common::XdmfCenter::kCell, true});
      series.surfaces.push_back(surf);
    }
    // Next to the name the file has when complete (common/output_file.h).
    common::write_xdmf(std::filesystem::path(common::complete_name(w.path)).replace_extension(".xdmf").string(), f,
                       series);
  }
  f.flush();
  if (sto_prefix.empty() || w.times.empty()) return;
  auto table = [&](const std::string& name, const std::vector<std::string>& labels,
                   const std::vector<Eigen::VectorXd>& rows, bool degrees) {
    common::StorageTable t;
    t.name = name;
    t.labels = {"time"};
    t.labels.insert(t.labels.end(), labels.begin(), labels.end());
    t.data.resize(static_cast<int>(rows.size()), static_cast<int>(labels.size()) + 1);
    for (size_t i = 0; i < rows.size(); ++i) {
      t.data(i, 0) = w.times[i];
      t.data.row(i).tail(labels.size()) = rows[i].transpose();
    }
    t.in_degrees = degrees;
    common::write_storage(sto_prefix + "_" + name + ".sto", t);
  };
  table("activations", w.muscle_names, w.sto_act, false);
  table("coordinates", w.coordinate_names, w.sto_q, true);
  std::vector<std::string> cl;
  for (const char* g : {"tibiofemoral_force", "tibiofemoral_medial_force",
                        "tibiofemoral_lateral_force", "patellofemoral_force"})
    for (const char* x : {"_x", "_y", "_z"}) cl.push_back(std::string(g) + x);
  table("contact_forces", cl, w.sto_contact, false);
}

void write_prescribed_kinematics(const std::string& path, const PrescribedKinematics& k) {
  common::H5File f(path, common::H5File::Mode::kTruncate);
  f.set_attribute("/", "format", "arthrosim kinematics file");
  f.set_attribute("/", "format_version", 1);
  f.set_attribute("/", "world_frame", k.world_frame);
  const std::int64_t n = k.time_s.size();
  f.set_attribute("/", "frames_expected", n);  // a complete, finished run (KinematicsFileReader::require_complete)
  f.set_attribute("/", "frames", n);
  f.write("/time", k.time_s);
  for (const auto& [body, poses] : k.body_poses) {
    if (static_cast<std::int64_t>(poses.size()) != n)
      throw std::invalid_argument("write_prescribed_kinematics: " + std::to_string(poses.size()) + " poses of " +
                                  body + " for " + std::to_string(n) + " frames");
    std::vector<double> X;
    X.reserve(static_cast<std::size_t>(16 * n));
    for (const Eigen::Isometry3d& p : poses)
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) X.push_back(p.matrix()(r, c));
    f.write_tensor3(KinematicsFileReader::body_poses_dataset(body), {n, 4, 4}, X);
  }
  for (const auto& [series, F] : k.contact_forces) {
    if (F.rows() != n || F.cols() != 3)
      throw std::invalid_argument("write_prescribed_kinematics: contact force " + series + " is not frames x 3");
    f.write(KinematicsFileReader::contact_force_dataset(series), F);
  }
  f.write("/solver/status", Eigen::VectorXi(Eigen::VectorXi::Zero(n)));
}

// ---------------------------------------------------------------------------
// Reader
// ---------------------------------------------------------------------------
KinematicsFileReader::KinematicsFileReader(const std::string& path)
    : f_(std::make_unique<common::H5File>(path, common::H5File::Mode::kRead)) {}
KinematicsFileReader::~KinematicsFileReader() = default;
const std::string& KinematicsFileReader::path() const { return f_->path(); }
const common::H5File& KinematicsFileReader::file() const { return *f_; }

Eigen::VectorXd KinematicsFileReader::time() const { return f_->read_vector("/time"); }

std::int64_t KinematicsFileReader::frames_complete() const {
  return f_->exists("/time") ? f_->dims("/time").at(0) : 0;
}
std::int64_t KinematicsFileReader::frames_expected() const {
  return f_->has_attribute("/", "frames_expected") ? f_->attribute_int("/", "frames_expected") : -1;
}
bool KinematicsFileReader::finished() const {
  return f_->has_attribute("/", "frames") && !f_->has_attribute("/", "stopped");
}
std::string KinematicsFileReader::incompleteness() const {
  return common::incompleteness(*f_, common::StageFile::kKinematics);
}
std::string KinematicsFileReader::require_complete(bool allow_partial) const {
  return common::require_usable_file(*f_, f_->path(), common::StageFile::kKinematics, allow_partial);
}

std::string KinematicsFileReader::body_poses_dataset(const std::string& body) { return "/bodies/" + body + "/X_W"; }

std::vector<Eigen::Isometry3d> KinematicsFileReader::body_poses(const std::string& body) const {
  const std::string& path = f_->path();
  const std::size_t frames = static_cast<std::size_t>(time().size());
  const std::string ds = body_poses_dataset(body);
  const common::Tensor3d X = f_->read_tensor3(ds);
  if (X.dims[0] != static_cast<std::int64_t>(frames) || X.dims[1] != 4 || X.dims[2] != 4)
    throw common::InputError(path + ": error: dataset " + ds + ": expected dims (" + std::to_string(frames) +
                             ", 4, 4), found (" + std::to_string(X.dims[0]) + ", " + std::to_string(X.dims[1]) + ", " +
                             std::to_string(X.dims[2]) + ")");
  std::vector<Eigen::Isometry3d> poses(frames);
  for (std::int64_t k = 0; k < X.dims[0]; ++k) {
    Eigen::Matrix4d M;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) M(i, j) = X(k, i, j);
    common::check_finite(M, path + ": dataset " + ds + ", frame " + std::to_string(k));
    if ((M.topLeftCorner<3, 3>().transpose() * M.topLeftCorner<3, 3>() - Eigen::Matrix3d::Identity()).norm() > 1e-6)
      throw common::InputError(path + ": error: dataset " + ds + ", frame " + std::to_string(k) +
                               ": expected a rotation in the top-left 3 x 3 block");
    poses[static_cast<std::size_t>(k)].matrix() = M;
  }
  return poses;
}

std::optional<Eigen::MatrixXd> KinematicsFileReader::tibiofemoral_force() const {
  if (!f_->exists(kTibiofemoralForce)) return std::nullopt;
  return f_->read_matrix(kTibiofemoralForce, 3);
}

std::string KinematicsFileReader::contact_force_dataset(const std::string& series) {
  if (series == "tibiofemoral") return kTibiofemoralForce;
  if (series == "medial" || series == "lateral") return std::string(kContactGroup) + "/" + series + "_force";
  if (series == "patellofemoral") return "/contact/patellofemoral/force";
  throw std::invalid_argument("kinematics file: no contact-force series '" + series +
                              "' (tibiofemoral, medial, lateral, patellofemoral)");
}

std::optional<Eigen::MatrixXd> KinematicsFileReader::contact_force(const std::string& series) const {
  const std::string ds = contact_force_dataset(series);
  if (!f_->exists(ds)) return std::nullopt;
  return f_->read_matrix(ds, 3);
}

std::string KinematicsFileReader::tibiofemoral_max_pressure_dataset() {
  return std::string(kContactGroup) + "/max_pressure";
}

std::optional<Eigen::VectorXd> KinematicsFileReader::tibiofemoral_max_pressure() const {
  const std::string ds = tibiofemoral_max_pressure_dataset();
  if (!f_->exists(ds)) return std::nullopt;
  const Eigen::VectorXd p = f_->read_vector(ds);
  const Eigen::Index frames = time().size();
  if (p.size() != frames)
    throw common::InputError(path(), 0, "dataset " + ds + ": expected " + std::to_string(frames) +
                             " values (one per frame of /time), found " + std::to_string(p.size()));
  return p;
}

std::vector<bool> KinematicsFileReader::converged(Eigen::Index n) const {
  std::vector<bool> valid(static_cast<std::size_t>(n), true);
  if (!f_->exists("/solver/status")) return valid;
  const Eigen::VectorXi status = f_->read_vector_int("/solver/status");
  for (Eigen::Index k = 0; k < std::min<Eigen::Index>(n, status.size()); ++k) {
    valid[static_cast<std::size_t>(k)] = status(k) == 0;
  }
  return valid;
}

double KinematicsFileReader::body_mass_kg() const {
  return f_->has_attribute("/", "body_mass_kg") ? f_->attribute_double("/", "body_mass_kg") : 0.0;
}

std::optional<std::pair<std::vector<std::string>, Eigen::MatrixXd>> KinematicsFileReader::activations() const {
  if (!f_->exists(kActivations)) return std::nullopt;
  return std::make_pair(f_->read_strings("/muscles/names"), f_->read_matrix(kActivations));
}

}  // namespace arthrosim::musculoskeletal
