#include "pipelines/biphasic_stage.h"

#include <cstdio>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <set>
#include <sstream>

#include "biphasic/joint_run.h"
#include "biphasic/output_file.h"
#include "common/checkpoint.h"
#include "common/effects.h"
#include "common/error.h"
#include "common/file_check.h"
#include "common/hdf5.h"
#include "common/log.h"
#include "common/metadata.h"
#include "common/prepared_model_file.h"
#include "common/progress.h"
#include "musculoskeletal/kinematics_file.h"
#include "pipelines/biphasic_checkpoint.h"
#include "pipelines/prepare.h"
#include "pipelines/stages.h"
#include "pipelines/study.h"

namespace arthrosim::pipelines {
namespace {

using biphasic::JointFrame;
using biphasic::JointLayer;
using biphasic::JointPair;

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string options_text(const BiphasicStageOptions& o) {
  std::ostringstream s;
  s << "layers: [";
  for (size_t i = 0; i < o.layers.size(); ++i) s << (i ? ", " : "") << o.layers[i];
  s << "]\nelement_layers: " << o.element_layers << "\ngrading: " << o.grading << "\ntime_step_s: " << o.time_step_s
    << "\nomega: " << o.omega << "\naggregate_modulus_Pa: " << o.aggregate_modulus_Pa
    << "\npoisson_ratio: " << o.poisson_ratio << "\npermeability_m4_per_Ns: " << o.permeability_m4_per_Ns
    << "\ncrop_margin_m: " << o.crop_margin_m << "\nend_time_s: "
    << (o.end_time_s ? std::to_string(*o.end_time_s) : std::string("(whole trial)")) << "\n";
  return s.str();
}

// The prepared model's articular quad surface of one layer, in the model
// (bone) frame.
JointLayer read_layer(const common::PreparedModelReader& f, const std::string& name,
                      const biphasic::Material& material) {
  const std::vector<std::string> names = f.surface_names();
  if (std::find(names.begin(), names.end(), name) == names.end()) {
    std::string list;
    for (const std::string& n : names) list += (list.empty() ? "" : ", ") + n;
    throw common::InputError(f.path(), 0,
                             "expected a cartilage surface '" + name + "' (prepared surfaces: " + list + "), found none");
  }
  common::PreparedModelReader::QuadSurface q = f.quads(name);
  JointLayer l;
  l.name = name;
  l.bone = f.bone(name);
  l.surface.name = name;
  l.surface.V = q.mesh.V;
  l.surface.Q = q.mesh.Q;
  l.normals = q.normals;
  l.thickness = f.quad_thickness(name);
  l.material = material;
  return l;
}

struct KinematicsInput {
  std::vector<JointFrame> frames;
  int failed = 0;
  std::string partial_input;  ///< "PARTIAL INPUT: ..." for an incomplete file read with allow_partial
};

// Frames of the kinematics file: bone poses and the compartment forces.
KinematicsInput read_kinematics(const std::string& path, const std::set<std::string>& bones,
                                const std::set<std::string>& compartments, double end_time_s, bool allow_partial) {
  const musculoskeletal::KinematicsFileReader reader(path);
  // Kind, version and completeness (a killed or stopped COMAK run): refused
  // naming the file and what it holds unless allow_partial (common/file_check.h).
  const std::string partial_input = reader.require_complete(allow_partial);
  const Eigen::VectorXd time = reader.time();
  const Eigen::Index n = time.size();
  std::map<std::string, std::vector<Eigen::Isometry3d>> poses;
  for (const std::string& bone : bones) {
    const std::string ds = musculoskeletal::KinematicsFileReader::body_poses_dataset(bone);
    if (!reader.file().exists(ds)) throw common::InputError(path, 0, "expected the pose series " + ds + ", found none");
    poses[bone] = reader.body_poses(bone);  // frames x 4 x 4, checked
  }
  using musculoskeletal::KinematicsFileReader;
  std::map<std::string, Eigen::MatrixXd> forces;
  for (const std::string& c : compartments) {
    const std::string ds = KinematicsFileReader::contact_force_dataset(c);
    std::optional<Eigen::MatrixXd> F = reader.contact_force(c);
    if (!F) {
      throw common::InputError(path, 0,
                               "expected the contact-force series " + ds +
                                   " (written by arthrosim-comak when the model has contact), found none; the "
                                   "penetration method scales each compartment's tractions to this force");
    }
    forces[c] = std::move(*F);
    if (forces[c].rows() != n) {
      throw common::InputError(path, 0, "dataset " + ds + ": expected " + std::to_string(n) + " frames, found " +
                                            std::to_string(forces[c].rows()));
    }
    // Zero split series beside a non-zero total (stage 1 could not split: a
    // model with one tibial contact surface and no split_lateral, or a file
    // from before the split existed): the layers would go unloaded without a
    // word.
    auto all_zero = [&](const char* split) {
      const std::optional<Eigen::MatrixXd> m = reader.contact_force(split);
      return !m || m->size() == 0 || m->cwiseAbs().maxCoeff() == 0.0;
    };
    const std::optional<Eigen::MatrixXd> total =
        c != "patellofemoral" ? reader.tibiofemoral_force() : std::optional<Eigen::MatrixXd>();
    if (total && all_zero("medial") && all_zero("lateral")) {
      const double peak = total->rows() ? total->rowwise().norm().maxCoeff() : 0.0;
      if (peak > 0.0) {
        char buf[32];
        std::snprintf(buf, sizeof buf, "%.0f", peak);
        throw common::InputError(
            path, 0,
            ds + " (and the other compartment's) is zero at every frame while " +
                KinematicsFileReader::contact_force_dataset("tibiofemoral") + " reaches " + buf +
                " N: stage 1 did not split the tibiofemoral contact into compartments (a tibial contact surface holding "
                "both plateaus needs split_lateral in the model, or prepared compartments; see the file's " +
                KinematicsFileReader::kContactGroup +
                " attribute 'compartments'), and the penetration method scales each compartment "
                "to its own force (docs/biphasic.md, \"The real subject\")");
      }
    }
  }
  const std::vector<bool> converged = reader.converged(n);
  KinematicsInput in;
  in.partial_input = partial_input;
  for (Eigen::Index k = 0; k < n; ++k) {
    if (end_time_s >= 0.0 && time[k] > end_time_s + 1e-12) break;
    if (!converged[static_cast<std::size_t>(k)]) {
      ++in.failed;
      common::log_warn("kinematics frame " + std::to_string(k) + " (t = " + std::to_string(time[k]) +
                       " s): stage 1 did not converge there; frame left out (its neighbours are interpolated)");
      continue;
    }
    JointFrame fr;
    fr.time_s = time[k];
    for (auto& [bone, X] : poses) fr.X_WB[bone] = X[static_cast<std::size_t>(k)];
    for (auto& [c, F] : forces) {
      const double m = F.row(k).norm();
      if (!std::isfinite(m)) {
        throw common::InputError(path, 0, KinematicsFileReader::contact_force_dataset(c) + ": expected finite forces, found " + std::to_string(m) +
                                              " at frame " + std::to_string(k));
      }
      fr.force_N[c] = m;
    }
    in.frames.push_back(std::move(fr));
  }
  return in;
}

// Pose of a bone at time t between frames: linear translation, slerp rotation.
Eigen::Isometry3d pose_at(const std::vector<JointFrame>& frames, const std::string& bone, double t) {
  if (t <= frames.front().time_s) return frames.front().X_WB.at(bone);
  if (t >= frames.back().time_s) return frames.back().X_WB.at(bone);
  size_t k = 1;
  while (frames[k].time_s < t) ++k;
  const double s = (t - frames[k - 1].time_s) / (frames[k].time_s - frames[k - 1].time_s);
  const Eigen::Isometry3d& A = frames[k - 1].X_WB.at(bone);
  const Eigen::Isometry3d& B = frames[k].X_WB.at(bone);
  const Eigen::Quaterniond qa(A.linear()), qb(B.linear());
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = qa.slerp(s, qb).toRotationMatrix();
  X.translation() = (1 - s) * A.translation() + s * B.translation();
  return X;
}

}  // namespace

void BiphasicOptions::declare(common::OptionVisitor& v) {
  using common::Unit;
  v.effect_list("effects", effects, "biphasic",
                "biphasic effects to simulate: biphasic_layers and penetration_contact (both)")
      .required();
  v.text_list("layers", layers, "femur|tibia_medial|tibia_lateral|patella",
              "cartilage layers (prepared surfaces): the femur and its partners; patella adds the patellofemoral pair");
  v.integer("element_layers", element_layers, {1, 16}, "element layers through the thickness");
  v.number("grading", grading, Unit::kNone, {1, 4},
           "height ratio of successive element layers from the articular surface to the bone (1: equal)");
  v.number("time_step_ms", time_step_s, Unit::kMillisecond, {1e-3, 1e6}, "constant time step");
  v.number("omega", omega, Unit::kNone, {0.5, 1}, "generalised trapezoidal parameter (1/2: trapezoidal, 1: backward Euler)");
  v.number("aggregate_modulus_mpa", aggregate_modulus_Pa, Unit::kMegapascal, {1e-6, 1e6},
           "aggregate modulus H_A of every layer (Keenan et al. 2009: 0.48-1.58 MPa)");
  v.number("poisson_ratio", poisson_ratio, Unit::kNone, {0, 0.499}, "drained Poisson's ratio of the solid matrix");
  v.number("permeability", permeability_m4_per_Ns, Unit::kNone, {1e-25, 1e-5},
           "permeability k in m^4/(N s) (SI; Keenan et al. 2009: 1.7e-15 to 5.4e-15)");
  v.number("crop_margin_mm", crop_margin_m, Unit::kMillimetre, {0, 1e3},
           "keep each layer's quads within this distance of a vertex in contact in some frame (0: whole surface)");
  v.number("end_time_s", end_time_s, Unit::kSecond, {0, 1e4}, "last frame time simulated (default: the whole trial)");
  v.number("checkpoint_interval_s", checkpoint_interval_s, Unit::kSecond, {0, 86400},
           "wall time between checkpoints <out>.checkpoint (0: after every step); a rerun of the same command "
           "continues from the last one (docs/biphasic.md, \"Checkpoints\")");
}

StageDescriptor biphasic_stage_descriptor() {
  StageDescriptor d;
  d.name = "biphasic";
  d.executable = "arthrosim-biphasic";
  d.takes_allow_partial = true;  // an incomplete kinematics file (arthrosim run --allow-partial)
  d.summary = "cartilage layers as linear biphasic volumes loaded by the penetration method from stage 1's kinematics";
  d.block = block_schema<BiphasicOptions>("biphasic", "effects and options of the biphasic stage (docs/biphasic.md)");
  d.outputs = {"biphasic"};
  for (const common::EffectInfo& e : common::known_effects())
    if (e.stage == common::EffectStage::kBiphasic)
      d.effects.push_back({std::string(e.name), "biphasic", std::string(e.description)});
  d.check = [](const common::Scene& scene) {
    if (!wants_output(scene, "biphasic")) return;
    const common::OptionValue& outputs = scene.top.value("outputs");
    auto fail = [&](const std::string& what) {
      throw common::InputError(scene.file.string(), outputs.value_line, outputs.value_column,
                               "output 'biphasic' " + what);
    };
    if (!scene.has_block("biphasic")) fail("needs a 'biphasic' block with its effects");
    if (!scene.has_block("comak"))
      fail("needs stage 1's kinematics: add a 'comak' block with its effects (tibiofemoral_contact gives the forces)");
    if (!scene.top.has("trial")) fail("needs stage 1's kinematics, which needs a walking trial: add 'trial: PATH'");
    const common::OptionBlock& b = scene.block("biphasic");
    const std::vector<std::string>& effects = b.list("effects");
    for (const char* needed : {"biphasic_layers", "penetration_contact"}) {
      if (std::find(effects.begin(), effects.end(), needed) == effects.end()) {
        const common::OptionValue& v = b.value("effects");
        throw common::InputError(scene.file.string(), v.value_line, v.value_column,
                                 std::string("biphasic effects: expected biphasic_layers and penetration_contact "
                                             "together (the layers carry nothing without the contact conditions, "
                                             "and the conditions need the layers), found no ") +
                                     needed);
      }
    }
  };
  d.no_runs = "a 'biphasic' block with its effects";
  d.runs = [](const common::Scene& scene, const std::filesystem::path& out) {
    std::vector<StageStep> runs;
    if (!scene.has_block("biphasic")) return runs;
    const common::OptionBlock& block = scene.block("biphasic");
    const std::filesystem::path prepared = out / "prepared.h5", kinematics = out / "kinematics.h5",
                                file = out / "biphasic.h5";
    StageStep s;
    s.name = "biphasic";
    s.executable = "arthrosim-biphasic";
    s.provides = {"biphasic"};
    s.origin = "the biphasic block";
    s.line = scene.block_line("biphasic");
    s.inputs.emplace_back("prepared.h5", prepared);
    s.inputs.emplace_back("kinematics.h5", kinematics);
    s.input_reasons["kinematics.h5"] = "reads the bone poses and contact forces of stage 1";
    s.options = block.canonical();
    s.effects = block.list("effects");
    add_path_inputs(block, s);
    s.outputs = {file, out / "biphasic.xdmf"};
    s.arguments = {"--prepared", prepared.string(), "--kinematics", kinematics.string(),
                   "--scene",    scene.file.string(), "--out",       file.string()};
    runs.push_back(std::move(s));
    return runs;
  };
  d.key_outputs = [](const std::string&, const std::filesystem::path& dir, const std::filesystem::path& ref) {
    return study::biphasic_metrics(dir / "biphasic.h5", ref / "biphasic.h5");
  };
  return d;
}

void check_options(const BiphasicStageOptions& o) {
  auto fail = [](const std::string& what) { throw common::InputError("biphasic options: " + what); };
  for (const char* needed : {"biphasic_layers", "penetration_contact"}) {
    if (std::find(o.effects.begin(), o.effects.end(), needed) == o.effects.end())
      fail(std::string("effects: expected biphasic_layers and penetration_contact, found no ") + needed);
  }
  if (o.prepared.empty()) fail("expected a prepared model (--prepared), found none");
  if (o.kinematics.empty()) fail("expected a kinematics file (--kinematics), found none");
  if (o.out.empty()) fail("expected an output file (--out), found none");
  if (o.layers.empty()) fail("expected at least two layers, found none");
  const std::set<std::string> allowed = {"femur", "tibia_medial", "tibia_lateral", "patella"};
  std::set<std::string> seen;
  for (const std::string& l : o.layers) {
    if (!allowed.count(l)) fail("layers: expected femur, tibia_medial, tibia_lateral or patella, found '" + l + "'");
    if (!seen.insert(l).second) fail("layers: '" + l + "' given twice");
  }
  if (!seen.count("femur")) fail("layers: every contact pair involves the femur, which is not listed");
  if (seen.size() < 2) fail("layers: expected the femur and at least one partner (tibia_medial, tibia_lateral, patella)");
  if (o.element_layers < 1 || o.element_layers > 16)
    fail("element_layers: expected 1..16, found " + std::to_string(o.element_layers));
  if (!(o.grading >= 1.0 && o.grading <= 4.0)) fail("grading: expected a value in [1, 4], found " + std::to_string(o.grading));
  if (!(o.time_step_s > 0.0) || !std::isfinite(o.time_step_s))
    fail("time_step_s: expected a value > 0 s, found " + std::to_string(o.time_step_s));
  if (!(o.omega >= 0.5 && o.omega <= 1.0)) fail("omega: expected a value in [0.5, 1], found " + std::to_string(o.omega));
  biphasic::validate({o.aggregate_modulus_Pa, o.poisson_ratio, o.permeability_m4_per_Ns}, "biphasic options");
  if (!(o.checkpoint_interval_s >= 0.0) || !std::isfinite(o.checkpoint_interval_s))
    fail("checkpoint_interval_s: expected a value >= 0 s, found " + std::to_string(o.checkpoint_interval_s));
  if (!(o.crop_margin_m >= 0.0) || !std::isfinite(o.crop_margin_m))
    fail("crop_margin_m: expected a value >= 0 m, found " + std::to_string(o.crop_margin_m));
}

BiphasicStageResult run_biphasic_stage(const BiphasicStageOptions& o) {
  const auto t_start = std::chrono::steady_clock::now();
  check_options(o);
  BiphasicStageResult result;
  const biphasic::Material material{o.aggregate_modulus_Pa, o.poisson_ratio, o.permeability_m4_per_Ns};

  // Inputs.
  std::vector<JointLayer> full;
  {
    const common::PreparedModelReader prepared(o.prepared);
    for (const std::string& name : o.layers) full.push_back(read_layer(prepared, name, material));
  }
  std::vector<JointPair> pairs;
  auto has = [&](const std::string& n) { return std::find(o.layers.begin(), o.layers.end(), n) != o.layers.end(); };
  if (has("tibia_medial")) pairs.push_back({"femur", "tibia_medial", "medial"});
  if (has("tibia_lateral")) pairs.push_back({"femur", "tibia_lateral", "lateral"});
  if (has("patella")) pairs.push_back({"femur", "patella", "patellofemoral"});
  std::set<std::string> bones, compartments;
  for (const JointLayer& l : full) bones.insert(l.bone);
  for (const JointPair& p : pairs) compartments.insert(p.compartment);
  const KinematicsInput kin = read_kinematics(o.kinematics, bones, compartments, o.end_time_s.value_or(-1.0), o.allow_partial);
  result.partial_input = kin.partial_input;
  result.frames_failed = kin.failed;
  const std::vector<JointFrame>& frames = kin.frames;
  if (frames.size() < 2) {
    throw common::InputError(o.kinematics, 0,
                             "expected at least two converged frames up to end_time_s, found " +
                                 std::to_string(frames.size()));
  }
  result.frames = static_cast<int>(frames.size());

  // Crop each layer to its contact region over the trial, plus the margin.
  auto t0 = std::chrono::steady_clock::now();
  std::vector<JointLayer> layers;
  std::vector<int> quads_total;
  if (o.crop_margin_m > 0.0) {
    const std::vector<std::vector<char>> touched = biphasic::contact_vertices(full, pairs, frames);
    for (size_t i = 0; i < full.size(); ++i) {
      JointLayer cropped = biphasic::crop_layer(full[i], touched[i], o.crop_margin_m);
      if (cropped.surface.num_quads() == 0) {
        throw common::InputError("biphasic: layer '" + full[i].name +
                                 "' is in contact in no frame; leave it out of `layers`");
      }
      quads_total.push_back(full[i].surface.num_quads());
      layers.push_back(std::move(cropped));
    }
  } else {
    for (const JointLayer& l : full) quads_total.push_back(l.surface.num_quads());
    layers = full;
  }
  result.preprocessing_s += seconds_since(t0);

  // Build: extrusion, assembly, one factorisation per layer.
  t0 = std::chrono::steady_clock::now();
  biphasic::JointOptions jo;
  jo.element_layers = o.element_layers;
  jo.grading = o.grading;
  jo.time = {o.time_step_s, o.omega};
  biphasic::JointRun run(layers, pairs, jo);
  result.build_s = seconds_since(t0);
  common::EffectLedger ledger("biphasic");
  for (size_t i = 0; i < layers.size(); ++i)
    ledger.record("biphasic_layers", run.problem(static_cast<int>(i)).system().mesh.num_elements(), layers[i].name);
  for (size_t i = 0; i < layers.size(); ++i) {
    const biphasic::LayerProblem& p = run.problem(static_cast<int>(i));
    common::log_info("layer " + layers[i].name + ": " + std::to_string(layers[i].surface.num_quads()) + " of " +
                     std::to_string(quads_total[i]) + " quads, " +
                     std::to_string(p.system().num_u_dofs() + p.system().num_p_dofs()) + " unknowns, factorised in " +
                     std::to_string(p.integrator().counters().factorization_s) + " s");
    if (!run.untangled(static_cast<int>(i)).empty())
      common::log_warn("layer " + layers[i].name + ": extrusion direction smoothed at " +
                       std::to_string(run.untangled(static_cast<int>(i)).size()) +
                       " vertices where the bone side would fold (sharp outline; docs/biphasic.md)");
  }

  // Preprocessing of every frame: the penetration conditions and the loads.
  t0 = std::chrono::steady_clock::now();
  std::vector<double> frame_times;
  std::vector<std::vector<biphasic::SurfaceLoads>> frame_loads;
  std::vector<std::vector<biphasic::CompartmentFrame>> records;
  for (const JointFrame& f : frames) {
    const std::vector<biphasic::PairFrame> c = run.contact(f);
    frame_times.push_back(f.time_s);
    frame_loads.push_back(run.layer_loads(f, c));
    std::vector<biphasic::CompartmentFrame> rec;
    for (size_t k = 0; k < pairs.size(); ++k) {
      biphasic::CompartmentFrame r;
      r.force_N = f.force_N.at(pairs[k].compartment);
      r.gamma_a_Pa = c[k].a.gamma;
      r.gamma_b_Pa = c[k].b.gamma;
      r.area_a_m2 = c[k].a.contact_area;
      r.area_b_m2 = c[k].b.contact_area;
      r.negative_pressure_nodes = c[k].a.nodes_negative_pressure + c[k].b.nodes_negative_pressure;
      r.beyond_thickness_nodes = c[k].a.nodes_beyond_thickness + c[k].b.nodes_beyond_thickness;
      r.skipped_no_overlap = (c[k].a.skipped_no_overlap || c[k].b.skipped_no_overlap) ? 1 : 0;
      if (r.skipped_no_overlap) {
        ++result.skipped_pair_frames;
        common::log_warn("frame t = " + std::to_string(f.time_s) + " s, " + pairs[k].compartment +
                         ": a contact force of " + std::to_string(r.force_N) +
                         " N but no overlap of the layers; no contact conditions this frame");
      }
      r.unloaded_overlap_m2 = std::max(c[k].a.unloaded_overlap_area, c[k].b.unloaded_overlap_area);
      if (r.unloaded_overlap_m2 > 0.0) {
        ++result.unloaded_pair_frames;
        common::log_warn("frame t = " + std::to_string(f.time_s) + " s, " + pairs[k].compartment +
                         ": stage 1's contact force is 0 N but the layers overlap over " +
                         std::to_string(r.unloaded_overlap_m2 * 1e6) +
                         " mm^2; no contact conditions this frame (free-draining, no traction)");
      }
      if (r.beyond_thickness_nodes > 0)
        common::log_warn("frame t = " + std::to_string(f.time_s) + " s, " + pairs[k].compartment + ": " +
                         std::to_string(r.beyond_thickness_nodes) +
                         " nodes overlap by more than both thicknesses (bone against bone)");
      rec.push_back(r);
    }
    records.push_back(std::move(rec));
  }
  for (const JointPair& p : pairs)
    ledger.record("penetration_contact", static_cast<std::int64_t>(frames.size()), p.compartment);
  ledger.require_only(o.effects);
  result.preprocessing_s += seconds_since(t0);

  // Step and write.
  t0 = std::chrono::steady_clock::now();
  const double dt = o.time_step_s;
  const int expected = static_cast<int>(std::floor((frame_times.back() - frame_times.front()) / dt + 1e-9));
  // Written as <out>.partial and renamed when complete: an earlier complete
  // result at `out` survives a failed run.
  std::filesystem::path out_path(o.out);
  if (out_path.has_parent_path()) std::filesystem::create_directories(out_path.parent_path());
  const std::string partial = o.out + ".partial";
  biphasic::OutputWriter writer(partial, run, expected);
  writer.write_frames(frame_times, records);
  std::vector<const char*> argv;
  for (const std::string& a : o.argv) argv.push_back(a.c_str());
  common::write_metadata(writer.file(),
                         common::collect_run_metadata("arthrosim-biphasic", static_cast<int>(argv.size()),
                                                      argv.data(), "", options_text(o)));
  if (!kin.partial_input.empty()) writer.file().set_attribute("/", "partial_input", kin.partial_input);
  common::ProgressOptions po;
  if (!o.progress) po.mode = common::ProgressOptions::Mode::kOff;
  common::Progress progress("biphasic", expected, po);
  result.layers.resize(layers.size());
  // Summed compartment force at time t (interpolated as the loads are).
  auto force_at = [&](double t) {
    size_t k = 1;
    while (k + 1 < frames.size() && frames[k].time_s < t) ++k;
    const double s = std::clamp((t - frames[k - 1].time_s) / (frames[k].time_s - frames[k - 1].time_s), 0.0, 1.0);
    double f = 0.0;
    for (const auto& [c, F] : frames[k].force_N) f += (1 - s) * frames[k - 1].force_N.at(c) + s * F;
    return f;
  };
  const double t_mid = 0.5 * (frame_times.front() + frame_times.back());
  result.key_steps.resize(2);
  std::vector<double> fls_sum(layers.size(), 0.0);
  std::vector<int> fls_count(layers.size(), 0);
  auto key_layers = [&](const std::vector<biphasic::LayerStep>& r) {
    std::vector<BiphasicKeyLayer> out;
    for (size_t i = 0; i < r.size(); ++i) {
      BiphasicKeyLayer k;
      k.name = layers[i].name;
      k.contact_area_m2 = r[i].contact_area_m2;
      k.fluid_load_support = r[i].fluid_load_support;
      k.max_tensile_Pa = r[i].max_tensile_Pa;
      k.max_shear_Pa = r[i].max_shear_Pa;
      k.max_tensile_region = r[i].max_tensile_vertex >= 0 ? biphasic::to_string(r[i].max_tensile_region) : "none";
      k.max_shear_region = biphasic::to_string(r[i].max_shear_region);
      k.max_surface_fluid_pressure_Pa = r[i].loads.pressure.size() ? r[i].loads.pressure.maxCoeff() : 0.0;
      out.push_back(k);
    }
    return out;
  };
  // Checkpoint and resume (pipelines/biphasic_checkpoint.h), tied to this
  // run's identity (program, command line, options, the inputs' bytes, the
  // runner's key).
  const std::filesystem::path checkpoint_path = common::checkpoint_name(o.out);
  BiphasicCheckpoint checkpoint;
  checkpoint.identity = common::run_identity(
      o.argv, options_text(o), {{o.prepared, "--prepared"}, {o.kinematics, "--kinematics"}});
  std::optional<BiphasicCheckpoint> found;
  const bool resume = common::resume_from_checkpoint(
      checkpoint_path, checkpoint.identity, [&](std::string& identity, std::string& why) {
        found = read_biphasic_checkpoint(checkpoint_path, why);
        if (!found) return false;
        if (found->layers.size() != layers.size() || found->steps_done < 0 || found->steps_done >= expected) {
          why = "it holds " + std::to_string(found->layers.size()) + " layers and " +
                std::to_string(found->steps_done) + " steps for a run of " + std::to_string(layers.size()) +
                " layers and " + std::to_string(expected) + " steps";
          return false;
        }
        identity = found->identity;
        return true;
      });
  if (resume) {
    checkpoint = std::move(*found);
  } else {
    checkpoint.u_history.assign(layers.size(), {});
    checkpoint.p_history.assign(layers.size(), {});
  }
  common::CheckpointClock checkpoint_clock(o.checkpoint_interval_s);
  auto on_step = [&](int step, double t, const std::vector<biphasic::LayerStep>& r) {
    const double force = force_at(t);
    BiphasicKeyStep& key = result.key_steps[t <= t_mid ? 0 : 1];
    if (key.step == 0 || force > key.force_N) {
      key.step = step;
      key.time_s = t;
      key.force_N = force;
      key.layers = key_layers(r);
    }
    for (size_t i = 0; i < r.size(); ++i) {
      if (r[i].contact_area_m2 > 0.0) {
        fls_sum[i] += r[i].fluid_load_support;
        ++fls_count[i];
      }
      if (r[i].loads.pressure.size())
        result.layers[i].peak_surface_fluid_pressure_Pa =
            std::max(result.layers[i].peak_surface_fluid_pressure_Pa, r[i].loads.pressure.maxCoeff());
    }
    std::vector<Eigen::Isometry3d> X;
    for (const JointLayer& l : layers) X.push_back(pose_at(frames, l.bone, t));
    writer.append_step(t, X, r);
    for (size_t i = 0; i < r.size(); ++i) {
      BiphasicLayerSummary& s = result.layers[i];
      s.peak_fluid_pressure_Pa = std::max(s.peak_fluid_pressure_Pa, r[i].fields.pressure.maxCoeff());
      s.peak_tensile_Pa = std::max(s.peak_tensile_Pa, r[i].max_tensile_Pa);
      s.peak_shear_Pa = std::max(s.peak_shear_Pa, r[i].max_shear_Pa);
    }
    progress.step();
  };
  if (resume) {
    common::log_info("resuming from the checkpoint " + checkpoint_path.string() + ": " +
                     std::to_string(checkpoint.steps_done) + " of " + std::to_string(expected) +
                     " steps done (taken from it)");
    const double t_first = frame_times.front();
    for (int i = 1; i <= checkpoint.steps_done; ++i) {
      std::vector<Eigen::VectorXd> u, p;
      for (size_t l = 0; l < layers.size(); ++l) {
        u.push_back(checkpoint.u_history[l][static_cast<size_t>(i - 1)]);
        p.push_back(checkpoint.p_history[l][static_cast<size_t>(i - 1)]);
      }
      const double t = t_first + i * dt;  // as JointRun::run computes it
      on_step(i, t, run.results_at(frame_times, frame_loads, t, u, p));
    }
    run.restore(checkpoint.layers);
    result.resumed_steps = checkpoint.steps_done;
  }
  result.steps = run.run(
      frame_times, frame_loads,
      [&](int step, double t, const std::vector<biphasic::LayerStep>& r) {
        on_step(step, t, r);
        for (size_t l = 0; l < layers.size(); ++l) {
          const biphasic::TrapezoidalIntegrator& in = run.problem(static_cast<int>(l)).integrator();
          checkpoint.u_history[l].push_back(in.u());
          checkpoint.p_history[l].push_back(in.p());
        }
        if (step < expected && checkpoint_clock.due()) {
          checkpoint.steps_done = step;
          checkpoint.layers.clear();
          for (size_t l = 0; l < layers.size(); ++l)
            checkpoint.layers.push_back(run.problem(static_cast<int>(l)).integrator().state());
          write_biphasic_checkpoint(checkpoint_path, checkpoint, ++result.checkpoints);
          checkpoint_clock.mark();
        }
      },
      checkpoint.steps_done + 1);
  progress.finish();
  result.stepping_s = seconds_since(t0);
  for (size_t i = 0; i < layers.size(); ++i)
    result.mean_fluid_load_support.push_back(fls_count[i] ? fls_sum[i] / fls_count[i] : 0.0);
  common::write_effect_ledger(writer.file(), ledger);
  writer.finish(run);
  std::filesystem::rename(partial, o.out);
  biphasic::write_output_xdmf(o.out, xdmf_path_for(o.out));
  std::filesystem::remove(checkpoint_path);
  for (size_t i = 0; i < layers.size(); ++i) {
    const biphasic::LayerProblem& p = run.problem(static_cast<int>(i));
    const biphasic::IntegratorCounters& c = p.integrator().counters();
    BiphasicLayerSummary& s = result.layers[i];
    s.name = layers[i].name;
    s.quads_total = quads_total[i];
    s.quads_kept = layers[i].surface.num_quads();
    s.unknowns = p.system().num_u_dofs() + p.system().num_p_dofs();
    s.free_unknowns = c.free_dofs;
    s.matrix_nonzeros = c.matrix_nonzeros;
    s.factorizations = c.factorizations;
    s.solves = c.solves;
    s.factorization_s = c.factorization_s;
    s.solve_s = c.solve_s;
    s.step_s = c.step_s;
    s.max_relative_residual = c.max_relative_residual;
  }
  result.wall_s = seconds_since(t_start);
  return result;
}

namespace {

// A square surface over the X-Z plane, facing +Y (up, flat) or -Y (down, the
// paraboloid y = (x^2 + z^2) / (2 R); R = 0 is flat).
void write_square_surface(common::PreparedModelWriter& f, const std::string& name, const std::string& bone, int n,
                          double size, bool up, double R, double thickness) {
  const int nv = (n + 1) * (n + 1);
  Eigen::MatrixXd V(nv, 3), N(nv, 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = size * i / n - size / 2, z = size * j / n - size / 2;
      const double y = R > 0 ? (x * x + z * z) / (2 * R) : 0.0;
      V.row(j * (n + 1) + i) << x, y, z;
      Eigen::Vector3d nv3 = up ? Eigen::Vector3d(0, 1, 0)
                               : Eigen::Vector3d(R > 0 ? x / R : 0.0, -1.0, R > 0 ? z / R : 0.0).normalized();
      N.row(j * (n + 1) + i) = nv3.transpose();
    }
  // (i, j) -> (X, Z): counter-clockwise seen from -Y for (a, a+1, a+n+2, a+n+1).
  Eigen::MatrixXi Q(n * n, 4);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i;
      if (up) Q.row(j * n + i) << a, a + n + 1, a + n + 2, a + 1;
      else Q.row(j * n + i) << a, a + 1, a + n + 2, a + n + 1;
    }
  common::QuadMesh mesh;
  mesh.V = V;
  mesh.Q = Q;
  std::vector<int> periphery;  // the square's outline
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i)
      if (i == 0 || j == 0 || i == n || j == n) periphery.push_back(j * (n + 1) + i);
  f.surface(name, bone);
  f.quads(name, mesh, N, Eigen::VectorXd::Constant(nv, thickness), periphery);
}

}  // namespace

std::pair<std::string, std::string> write_two_layer_case(const std::string& dir) {
  std::filesystem::create_directories(dir);
  const std::string prepared = (std::filesystem::path(dir) / "two_layers_prepared.h5").string();
  const std::string kinematics = (std::filesystem::path(dir) / "two_layers_kinematics.h5").string();
  {
    common::H5File h5(prepared, common::H5File::Mode::kTruncate);
    common::PreparedModelWriter f(h5);
    f.identity("canonical two-layer case (arthrosim-biphasic --canonical)");
    f.surface_names({"femur", "tibia_medial"});
    write_square_surface(f, "femur", "femur", 12, 12e-3, false, 30e-3, 1.5e-3);
    write_square_surface(f, "tibia_medial", "tibia", 16, 16e-3, true, 0.0, 2e-3);
  }
  {
    musculoskeletal::PrescribedKinematics k;
    k.world_frame = "femur frame of the canonical case: Y superior";
    const int n = 101;
    k.time_s.resize(n);
    std::vector<Eigen::Isometry3d> femur(n, Eigen::Isometry3d::Identity()), tibia(n, Eigen::Isometry3d::Identity());
    Eigen::MatrixXd medial(n, 3), lateral = Eigen::MatrixXd::Zero(n, 3);
    for (int i = 0; i < n; ++i) {
      k.time_s[i] = 0.01 * i;
      const double ramp = std::min(k.time_s[i] / 0.5, 1.0);
      femur[i].translation().y() = -0.15e-3 * ramp;
      medial.row(i) << 0.0, -200.0 * ramp, 0.0;
    }
    k.body_poses = {{"femur", femur}, {"tibia", tibia}};
    k.contact_forces = {{"medial", medial}, {"lateral", lateral}};
    musculoskeletal::write_prescribed_kinematics(kinematics, k);
  }
  return {prepared, kinematics};
}

}  // namespace arthrosim::pipelines
