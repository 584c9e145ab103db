#include "pipelines/comak_stage.h"

#include <algorithm>
#include <cmath>
#include <tuple>
#include <fstream>
#include <iterator>
#include <optional>
#include <sstream>

#include "common/checkpoint.h"
#include "common/effects.h"
#include "common/error.h"
#include "common/log.h"
#include "common/metadata.h"
#include "common/output_file.h"
#include "common/progress.h"
#include "common/scene.h"
#include "common/storage.h"
#include "musculoskeletal/ankle_muscles.h"
#include "musculoskeletal/external_loads.h"
#include "musculoskeletal/gait_trial.h"
#include "musculoskeletal/kinematics_file.h"
#include "musculoskeletal/knee_loads.h"
#include "musculoskeletal/model_io.h"
#include "pipelines/comak_checkpoint.h"
#include "pipelines/stages.h"
#include "pipelines/study.h"

namespace arthrosim::pipelines {
namespace fs = std::filesystem;

fs::path comak_model_file(const fs::path& model) {
  if (!fs::is_directory(model)) return model;
  std::vector<fs::path> inside, beside;
  for (const auto& e : fs::directory_iterator(model))
    if (e.path().extension() == ".urdf") inside.push_back(e.path());
  if (inside.size() == 1) return inside[0];
  const fs::path dir = fs::weakly_canonical(model);
  const std::string needle = "\"" + dir.filename().string() + "/";
  for (const auto& e : fs::directory_iterator(dir.parent_path())) {
    if (e.path().extension() != ".urdf") continue;
    std::ifstream in(e.path());
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (text.find(needle) != std::string::npos) beside.push_back(e.path());
  }
  std::sort(beside.begin(), beside.end());
  if (inside.empty() && beside.size() == 1) return beside[0];
  throw common::InputError(model.string() + ": error: model folder: expected one URDF in it or one URDF next to it "
                           "referencing its meshes, found " + std::to_string(inside.size()) + " and " +
                           std::to_string(beside.size()));
}

void ComakStageOptions::declare(common::OptionVisitor& v) {
  using common::Unit;
  v.effect_list("effects", effects, "musculoskeletal", "musculoskeletal effects to simulate").required();
  solver.declare(v);
  v.number("lowpass_cutoff_hz", trial.lowpass.cutoff_hz, Unit::kHertz, {0.1, 1000},
           "low-pass filter of trial kinematics and ground reactions");
  v.number("checkpoint_interval_s", checkpoint_interval_s, Unit::kSecond, {0, 86400},
           "wall time between checkpoints <out>.checkpoint (0: after every frame); a rerun of the same command "
           "continues from the last one (docs/comak.md, \"Checkpoints\")");
}

void check_comak_effects(const std::vector<std::string>& effects, const std::string& where) {
  auto wants = [&](const char* e) { return std::find(effects.begin(), effects.end(), e) != effects.end(); };
  if (!wants("muscles"))
    throw common::InputError(where + ": error: comak effects must include muscles (they balance the flexion "
                             "equation)");
  if (wants("tibiofemoral_contact") != wants("patellofemoral_contact"))
    throw common::InputError(where + ": error: comak effects: tibiofemoral_contact and patellofemoral_contact can "
                             "only be simulated together (the model evaluates all contact pairs as one term)");
}

ComakStageOptions comak_from_scene(const common::Scene& scene) {
  ComakStageOptions o = common::read_options<ComakStageOptions>(scene.block("comak"));
  if (!scene.has_block("comak")) {
    o.effects = {"ligaments", "muscles", "tibiofemoral_contact", "patellofemoral_contact"};
  }
  check_comak_effects(o.effects, scene.file.string());
  const SceneInputs in = scene_inputs(scene);
  if (in.trial_start_s) o.start_time_s = *in.trial_start_s;
  if (in.trial_end_s) o.end_time_s = *in.trial_end_s;
  return o;
}

namespace {
namespace msk = musculoskeletal;

// The stage's text of the options it runs with (log and run metadata).
std::string options_text(const ComakStageConfig& c, const std::string& model_path, int first_frame,
                         int last_frame, bool model_dynamics) {
  const msk::ComakOptions& o = c.options.solver;
  std::ostringstream opts;
  opts << "model: " << model_path << "\nprepared: " << (c.prepared.empty() ? "none" : c.prepared.string())
       << "\ntrial: " << c.trial.string() << "\nfirst_frame: " << first_frame << "\nlast_frame: " << last_frame
       << "\nstride: " << c.stride << "\nforce_tolerance_n: " << o.force_tolerance
       << "\nlength_scale_m: " << o.length_scale << "\nipopt_tolerance: " << o.ipopt_tolerance
       << "\nmax_iterations: " << o.max_iterations << "\nactivation_min: " << o.activation_min
       << "\nacceptable_iterations: " << o.acceptable_iterations
       << "\nreserve_actuators: " << (o.reserve_actuators ? "true" : "false")
       << "\nankle_equilibrium: " << (o.ankle_equilibrium ? "true" : "false")
       << "\nhip_equilibrium: " << (o.hip_equilibrium ? "true" : "false")
       << "\nbody_inertia: " << (o.body_inertia ? "true" : "false")
       << "\nforce_length: " << (o.forces.force_length ? "true" : "false")
       << "\nsecond_start: " << (o.second_start ? "true" : "false") << "\nretries: " << o.retries
       << "\nmove_limits_first: " << (o.move_limits_first ? "true" : "false")
       << "\nmove_limit_m: " << o.move_limit_m << "\nmove_limit_rad: " << o.move_limit_rad
       << "\nsecond_start_move_limit_scale: " << o.second_start_move_limit_scale
       << "\ncoordinate_damping: " << (o.coordinate_damping ? "true" : "false")
       << "\nloads: " << (model_dynamics ? "model dynamics (the model's own leg)" : "generic leg chain (knee_loads.h)")
       << "\nlowpass_cutoff_hz: " << c.options.trial.lowpass.cutoff_hz << "\nhessian: limited-memory\n";
  for (const auto& [name, w] : o.muscle_weights) opts << "muscle_weight." << name << ": " << w << "\n";
  std::string effect_text;
  for (const auto& e : c.options.effects) effect_text += (effect_text.empty() ? "" : ", ") + e;
  opts << "effects: [" << effect_text << "]\n";
  return opts.str();
}

}  // namespace

ComakStageResult run_comak_stage(const ComakStageConfig& config) {
  // ---- build --------------------------------------------------------------
  check_comak_effects(config.options.effects, config.scene.empty() ? std::string("arthrosim-comak")
                                                                  : config.scene.string());
  const auto wants = [&](const char* e) {
    return std::find(config.options.effects.begin(), config.options.effects.end(), e) != config.options.effects.end();
  };
  msk::ComakOptions o = config.options.solver;
  o.forces.ligaments = wants("ligaments");
  o.forces.contact = wants("tibiofemoral_contact");
  const std::string model_path = comak_model_file(config.model).string();
  msk::Model model = msk::load_model(model_path);
  // A model with its own leg to the ground (an imported OpenSim model)
  // takes the trial's coordinates by name and its forces on its bodies.
  const bool model_dynamics = model.role_body("ground") >= 0;
  if (o.ankle_equilibrium && !model_dynamics) {
    // Uniarticular ankle muscles so that the ankle row can be balanced in
    // both directions (musculoskeletal/ankle_muscles.h).
    msk::add_ankle_muscles(model);
    common::log_info("ankle equilibrium: added the ankle muscles soleus and tibant");
  }
  if (!config.prepared.empty()) {
    // The prepare stage's cartilage (its edge length sets the contact
    // resolution of this stage too).
    const auto rep = msk::use_prepared_surfaces(model, config.prepared.string());
    std::string text;
    for (const auto& l : rep.lines) text += "\n  " + l;
    common::log_info("contact surfaces from " + config.prepared.string() + ":" + text);
  }
  msk::GaitTrialOptions to = config.options.trial;
  // A non-finite trial value: run the frames before it, then stop naming
  // the frame, file, line and column (exit 1; the file keeps those frames).
  to.truncate_at_non_finite = true;
  if (model_dynamics) {
    // Angles are the model's revolute coordinates (translations by its prismatic ones).
    to.is_rotational = [&model](const std::string& label) {
      const int c = model.tree.coordinate_index(label);
      if (c < 0) return common::default_is_rotational(label);
      for (const msk::Joint& j : model.tree.joints)
        if (j.coordinate == c) return j.type == msk::JointType::kRevolute;
      return false;
    };
  }
  const std::string trial_path = config.trial.string();
  msk::GaitTrial trial = msk::load_gait_trial(trial_path, to);
  if (!(trial.body_mass_kg > 0)) {
    trial.body_mass_kg = model.subject_mass_kg;
    common::log_info("subject mass from the model: " + std::to_string(model.subject_mass_kg) + " kg");
  }
  int first = config.first_frame, last = config.last_frame;
  const double start_s = config.options.start_time_s, end_s = config.options.end_time_s;
  if (!std::isnan(start_s) || !std::isnan(end_s)) {
    // The time window: frames of the trial's grid inside [start, end].
    std::tie(first, last) = msk::frames_in_window(trial, start_s, end_s);
  }
  if (trial.side != msk::Side::kRight)
    throw common::InputError(trial_path + ": error: the bundled knee models are right knees; this trial is of the "
                             "left leg");
  std::vector<msk::ComakFrameInput> frames;
  if (model_dynamics) {
    std::vector<std::string> ignored;
    frames = msk::comak_model_frame_inputs(model, trial, first, last, config.stride, &ignored);
    for (const auto& i : ignored) common::log_info("external force not applied: " + i);
  } else {
    const msk::LegModel leg = msk::leg_model_for_trial(trial);
    const msk::KneeLoads loads = msk::compute_knee_loads(trial, leg);
    frames = msk::comak_frame_inputs(loads, first, last, config.stride, &leg);
  }
  msk::ComakProblem problem(model, o);

  const std::string opts = options_text(config, model_path, first, last, model_dynamics);
  common::log_info("options:\n" + opts + (trial.synthetic ? "trial is SYNTHETIC\n" : ""));
  std::vector<const char*> argv;
  for (const std::string& a : config.argv) argv.push_back(a.c_str());
  const auto meta = common::collect_run_metadata("arthrosim-comak", static_cast<int>(argv.size()), argv.data(),
                                                 config.scene.string(), opts);
  common::EffectLedger ledger("comak");
  if (o.forces.ligaments) ledger.record("ligaments", model.num_bundles());
  ledger.record("muscles", static_cast<std::int64_t>(model.muscles.size()));
  const int tibia = model.role_body("tibia"), patella = model.role_body("patella");
  for (const auto& c : model.contacts) {
    if (!o.forces.contact) break;
    if (c.casting().body == tibia) ledger.record("tibiofemoral_contact", c.casting().mesh.F.rows(), c.name());
    if (c.casting().body == patella) ledger.record("patellofemoral_contact", c.casting().mesh.F.rows(), c.name());
  }

  // ---- run ----------------------------------------------------------------
  msk::KinematicsFileInfo info;
  info.model_path = model_path;
  info.trial_path = trial_path;
  info.body_mass_kg = trial.body_mass_kg;
  info.synthetic = trial.synthetic;
  info.expected_frames = static_cast<std::int64_t>(frames.size());
  info.pressure_fields = config.pressure_fields;
  const std::string out = config.out.string();
  std::vector<common::NamedInput> inputs = common::files_of(config.model, "--model");
  {  // An output never replaces an input (common/output_file.h).
    for (const auto& f : {common::NamedInput{model_path, "the URDF of --model"}, {config.prepared, "--prepared"},
                          {config.scene, "--scene"}, {trial.source, "--trial"}})
      inputs.push_back(f);
    for (const auto& f : common::files_of(trial_path, "--trial")) inputs.push_back(f);
    const msk::TrialDescription td = msk::read_trial_description(trial_path);
    for (const auto& f : {td.kinematics_file, td.grf_file, td.knee_loads_file, td.external_loads_file})
      inputs.push_back({f, "a file of --trial"});
    common::refuse_output_over_inputs("arthrosim-comak", "--out", out, inputs);
  }
  // Written as <out>.partial, renamed over <out> when the run finishes; a
  // stopped or killed run stays <out>.partial (common/output_file.h).
  common::AtomicOutput atomic(out);
  msk::KinematicsFileWriter writer(atomic.temp().string(), problem, info, meta);
  if (trial.truncated)
    common::log_warn(trial_path + ": the trial ends early at frame " + std::to_string(trial.truncated->frame) + ": " +
                     trial.truncated->reason);
  std::string sto_prefix = config.sto_prefix;
  if (sto_prefix.empty()) {
    sto_prefix = out;
    if (sto_prefix.size() > 3 && sto_prefix.substr(sto_prefix.size() - 3) == ".h5") sto_prefix.resize(sto_prefix.size() - 3);
  }
  common::Progress progress("comak", static_cast<std::int64_t>(frames.size()));
  ComakStageResult result;

  // ---- checkpoint and resume (pipelines/comak_checkpoint.h) ----------------
  // The checkpoint is tied to this run's identity: the program's bytes, its
  // command line, the options and every input file's bytes (and the
  // runner's stage key); any other checkpoint is discarded, never used.
  const fs::path checkpoint_path = common::checkpoint_name(out);
  ComakCheckpoint checkpoint;
  checkpoint.identity = common::run_identity(config.argv, opts, inputs);
  checkpoint.frames_total = static_cast<std::int64_t>(frames.size());
  std::optional<msk::ComakRunState> resume;
  if (fs::exists(checkpoint_path)) {
    std::string why;
    std::optional<ComakCheckpoint> found = read_comak_checkpoint(checkpoint_path, why);
    if (found && found->identity != checkpoint.identity)
      why = "it belongs to another run (inputs, options, command line or build differ)";
    else if (found && found->frames_total != checkpoint.frames_total)
      why = "it is of a run of " + std::to_string(found->frames_total) + " frames, not " +
            std::to_string(checkpoint.frames_total);
    if (found && why.empty()) {
      common::log_info("resuming from the checkpoint " + checkpoint_path.string() + ": " +
                       std::to_string(found->state.frames_done) + " of " + std::to_string(frames.size()) +
                       " frames done (taken from it, not solved again)");
      resume = found->state;
      checkpoint.frames = std::move(found->frames);
    } else {
      common::log_warn("not resuming from " + checkpoint_path.string() + ": " + why + "; starting over");
      fs::remove(checkpoint_path);
    }
  }
  common::CheckpointClock clock(config.options.checkpoint_interval_s);
  msk::ModelData replay_data = msk::make_data(model);
  if (resume) {
    // The frames done, appended again as the uninterrupted run appended
    // them: each evaluated at its stored solution with the inputs it was
    // solved with.
    for (int i = 0; i < resume->frames_done; ++i) {
      const ComakFrameRecord& rec = checkpoint.frames[static_cast<std::size_t>(i)];
      msk::ComakFrameInput f = frames[static_cast<std::size_t>(i)];
      f.has_previous = true;
      f.q_previous = rec.q_previous;
      f.dt_previous = rec.dt_previous;
      problem.residual(replay_data, f, rec.result.q, rec.result.activations, rec.result.reserves);
      writer.append(f, rec.result, replay_data);
      progress.step();
    }
    result.resumed_frames = resume->frames_done;
  }
  auto on_frame = [&](const msk::ComakFrameInput& f, const msk::ComakFrameResult& r, const msk::ModelData& d) {
    writer.append(f, r, d);
    ComakFrameRecord rec;
    rec.result = r;
    rec.result.multipliers = {};
    rec.q_previous = f.q_previous;
    rec.dt_previous = f.dt_previous;
    checkpoint.frames.push_back(std::move(rec));
    progress.step();
  };
  auto on_state = [&](const msk::ComakRunState& state) {
    // After the last frame the output itself is finished next.
    if (state.frames_done >= static_cast<int>(frames.size()) || !clock.due()) return;
    checkpoint.state = state;
    write_comak_checkpoint(checkpoint_path, checkpoint, ++result.checkpoints);
    result.checkpoint_bytes = fs::file_size(checkpoint_path);
    clock.mark();
    common::log_debug("checkpoint " + checkpoint_path.string() + ": " + std::to_string(state.frames_done) +
                      " frames, " + std::to_string(result.checkpoint_bytes) + " bytes");
  };
  try {
    result.summary = msk::run_comak(problem, frames, on_frame, resume ? &*resume : nullptr, on_state);
  } catch (const msk::ComakRunStopped& e) {
    // Finish the file with the frames before the stop (attribute `stopped`);
    // run_comak has logged the reason, naming the frame.
    progress.finish();
    writer.finish(e.summary, ledger, sto_prefix);
    result.summary = e.summary;
    result.stopped = true;
    result.stopped_frame = e.frame;
    fs::remove(checkpoint_path);  // a rerun would stop there again
    return result;
  }
  progress.finish();
  writer.finish(result.summary, ledger, sto_prefix);
  atomic.commit();
  fs::remove(checkpoint_path);
  return result;
}

StageDescriptor comak_stage_descriptor() {
  StageDescriptor d;
  d.name = "comak";
  d.executable = "arthrosim-comak";
  d.summary = "per frame of the trial, Ipopt on muscle activations and the 11 secondary knee coordinates";
  d.block = block_schema<ComakStageOptions>("comak", "effects and options of the musculoskeletal (COMAK) stage");
  d.outputs = {"kinematics"};
  d.runs = [](const common::Scene& scene, const fs::path& out) {
    StageStep s;
    s.name = "comak";
    s.executable = "arthrosim-comak";
    s.provides = {"kinematics"};
    s.origin = "the comak block";
    s.line = scene.block_line("comak");
    const SceneInputs in = scene_inputs(scene);
    if (!scene.has_block("comak")) {
      s.unavailable = "the musculoskeletal stage: add a 'comak' block with its effects";
    } else if (in.trial.empty()) {
      s.unavailable = "a walking trial: add 'trial: PATH'";
    }
    s.inputs.emplace_back("model", in.model);
    // The URDF the stage loads for a model folder (when it can be found; the
    // stage itself says why when it cannot).
    if (scene.has_block("comak") && fs::is_directory(in.model)) {
      try {
        s.inputs.emplace_back("model URDF", comak_model_file(in.model));
      } catch (const common::InputError&) {
      }
    }
    const fs::path prepared = out / "prepared.h5", kinematics = out / "kinematics.h5";
    if (!in.trial.empty()) s.inputs.emplace_back("trial", in.trial);
    // The files a trial.yaml names (they may live outside the trial folder),
    // and the data file its ExternalLoads XML names. A description that
    // cannot be read adds nothing here: the stage itself then fails naming it.
    if (!in.trial.empty() && scene.has_block("comak")) {
      try {
        const msk::TrialDescription td = msk::read_trial_description(in.trial.string());
        std::vector<std::pair<std::string, fs::path>> files = {{"trial kinematics", td.kinematics_file},
                                                               {"trial ground reactions", td.grf_file},
                                                               {"trial knee loads", td.knee_loads_file},
                                                               {"trial external loads", td.external_loads_file}};
        if (!td.external_loads_file.empty())
          files.emplace_back("trial external loads data", msk::read_external_loads(td.external_loads_file).datafile);
        add_referenced_inputs(s, files);
      } catch (const common::InputError&) {
      }
    }
    s.inputs.emplace_back("prepared.h5", prepared);
    const common::OptionBlock& block = scene.block("comak");
    s.options = block.canonical();
    // The trial window (top-level trial.start_s / trial.end_s) decides which
    // frames the stage solves.
    for (const auto& kv : scene.top.canonical())
      if (kv.first.rfind("scene.trial.", 0) == 0) s.options.push_back(kv);
    std::sort(s.options.begin(), s.options.end());
    if (block.has("effects")) s.effects = block.list("effects");
    add_path_inputs(block, s);
    s.outputs = {kinematics};
    s.arguments = {"--model",  in.model.string(),    "--prepared", prepared.string(),
                   "--trial",  in.trial.string(),    "--scene",    scene.file.string(),
                   "--out",    kinematics.string()};
    return std::vector<StageStep>{s};
  };
  for (const common::EffectInfo& e : common::known_effects())
    if (e.stage == common::EffectStage::kMusculoskeletal)
      d.effects.push_back({std::string(e.name), "musculoskeletal", std::string(e.description)});
  d.key_outputs = [](const std::string&, const fs::path& dir, const fs::path& ref) {
    return study::comak_metrics(dir / "kinematics.h5", ref / "kinematics.h5");
  };
  return d;
}

}  // namespace arthrosim::pipelines
