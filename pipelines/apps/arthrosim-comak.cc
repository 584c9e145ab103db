// arthrosim-comak: the musculoskeletal stage. Per frame of a walking trial,
// one Ipopt NLP (muscle activations + 11 secondary knee coordinates, static
// equilibrium of all 12 knee coordinates under muscles, ligaments,
// elastic-foundation contact and the external knee loads; musculoskeletal/
// comak.h, docs/comak.md), written frame by frame into the kinematics file
// (docs/kinematics_file.md).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>
#include <string>

#include "common/effects.h"
#include "common/error.h"
#include "common/log.h"
#include "common/metadata.h"
#include "common/output_file.h"
#include "common/progress.h"
#include "common/scene.h"
#include "common/storage.h"
#include "musculoskeletal/ankle_muscles.h"
#include "musculoskeletal/comak.h"
#include "musculoskeletal/gait_trial.h"
#include "musculoskeletal/kinematics_file.h"
#include "musculoskeletal/knee_loads.h"
#include "musculoskeletal/model_io.h"
#include "pipelines/apps/name_value.h"
#include "pipelines/comak_stage.h"
#include "pipelines/stages.h"

using namespace arthrosim;
namespace msk = arthrosim::musculoskeletal;
namespace fs = std::filesystem;

namespace {
// --model may name a URDF or a model folder (as scenes do). A folder is
// resolved to the one URDF inside it, or else to the one URDF next to it
// that references meshes in it ("<folder>/" in the file, as the bundled
// knee.urdf references medium/...). Anything else is an error naming what
// was found.
std::string resolve_model(const std::string& given) {
  const fs::path p(given);
  if (!fs::is_directory(p)) return given;
  std::vector<fs::path> inside, beside;
  for (const auto& e : fs::directory_iterator(p))
    if (e.path().extension() == ".urdf") inside.push_back(e.path());
  if (inside.size() == 1) return inside[0].string();
  const fs::path dir = fs::weakly_canonical(p);
  const std::string needle = "\"" + dir.filename().string() + "/";
  for (const auto& e : fs::directory_iterator(dir.parent_path())) {
    if (e.path().extension() != ".urdf") continue;
    std::ifstream in(e.path());
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (text.find(needle) != std::string::npos) beside.push_back(e.path());
  }
  std::sort(beside.begin(), beside.end());
  if (inside.empty() && beside.size() == 1) return beside[0].string();
  throw common::InputError(given + ": error: model folder: expected one URDF in it or one URDF next to "
                           "it referencing its meshes, found " + std::to_string(inside.size()) +
                           " and " + std::to_string(beside.size()));
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "arthrosim-comak: COMAK over a walking trial. Per frame one Ipopt NLP: muscle activations and the\n"
      "11 secondary knee coordinates minimising sum w V a^2 subject to static equilibrium of the 12 knee\n"
      "coordinates (flexion prescribed from the trial) under muscles, ligaments, elastic-foundation contact\n"
      "and the external knee loads. Writes the kinematics file (HDF5, docs/kinematics_file.md), an XDMF\n"
      "sidecar with per-triangle contact pressure, and .sto exports. Method: docs/comak.md."};
  std::string model_path, trial_path, out, sto_prefix, scene_path, prepared_path;
  int first = 0, last = -1, stride = 1;
  msk::ComakOptions o;
  double lowpass_hz = msk::GaitTrialOptions().lowpass.cutoff_hz;  // the one default (signal.h)
  bool verbose = false, quiet = false, no_pressure = false;
  app.add_option("--model", model_path,
                 "model URDF (e.g. data/models/knee_parametric/knee.urdf) or a model folder")
      ->required();
  app.add_option("--scene", scene_path,
                 "scene YAML: its comak block gives effects and options (explicit flags win)");
  app.add_option("--prepared", prepared_path,
                 "prepared-model HDF5 (arthrosim-prepare): contact uses its remeshed cartilage "
                 "surfaces and cast thickness instead of the model file's meshes");
  app.add_option("--trial", trial_path, "trial description or its folder")->required();
  app.add_option("--out", out, "kinematics file to write (.h5)")->required();
  app.add_option("--first-frame", first, "first trial frame (0-based)")->capture_default_str();
  app.add_option("--last-frame", last, "last trial frame (-1 = the last)")->capture_default_str();
  app.add_option("--stride", stride, "use every stride-th frame")->capture_default_str();
  double start_time = std::numeric_limits<double>::quiet_NaN(), end_time = start_time;
  app.add_option("--start-time", start_time,
                 "first time of the trial to solve [s] (the frames from the first at or after it; "
                 "the whole trial is still filtered and differentiated)");
  app.add_option("--end-time", end_time, "last time of the trial to solve [s] (frames at or before it)");
  app.add_option("--tolerance", o.force_tolerance,
                 "equilibrium tolerance of the force rows [N]; moment rows x length scale 0.03 m")
      ->capture_default_str();
  app.add_option("--ipopt-tolerance", o.ipopt_tolerance, "Ipopt 'tol' (scaled NLP)")->capture_default_str();
  app.add_option("--max-iterations", o.max_iterations, "Ipopt iteration limit per attempt")
      ->capture_default_str();
  app.add_option("--acceptable-iterations", o.acceptable_iterations,
                 "consecutive iterates at Ipopt's acceptable level that end a solve as 'acceptable' "
                 "(a larger value keeps iterating towards --ipopt-tolerance)")
      ->capture_default_str();
  app.add_option("--activation-min", o.activation_min, "lower bound of the activations, 0..1")
      ->capture_default_str();
  std::vector<std::string> weight_args;
  app.add_option("--muscle-weight", weight_args,
                 "objective weight w_i of a muscle, name=value (> 0; default 1), repeatable");
  app.add_flag("--reserve-actuators", o.reserve_actuators,
               "reserve actuators on the 11 secondary coordinates (heavy weight, reported)");
  CLI::Option* ankle_flag = app.add_flag("--ankle-equilibrium,!--no-ankle-equilibrium", o.ankle_equilibrium,
               "also balance the ankle moment of the foot (one more row): adds a soleus and a tibialis "
               "anterior stand-in to the generated knee; a model with its own leg uses its own ankle "
               "muscles (docs/comak.md)");
  CLI::Option* hip_flag = app.add_flag("--hip-equilibrium,!--no-hip-equilibrium", o.hip_equilibrium,
               "also balance the leg about the hip's three axes (3 rows; a model with its own leg and the "
               "hip muscles: arthrosim import-osim --muscles leg; docs/comak.md)");
  app.add_flag("--body-inertia", o.body_inertia,
               "weight and d'Alembert forces of the tibia and patella bodies from their URDF "
               "inertials, moving with the model (the shank's terms leave the external load; "
               "docs/comak.md)");
  app.add_flag("--force-length", o.forces.force_length,
               "muscle force a F_max f_L(l~) (Thelen 2003 active force-length; every muscle of the "
               "model must give optimal_fiber_length and tendon_slack_length, docs/model_format.md)");
  bool single_start = false;
  bool no_damping = false;
  app.add_flag("--no-coordinate-damping", no_damping,
               "leave the model's coordinate dampers (SpringGeneralizedForce viscosity on the secondary "
               "coordinates' frame-to-frame speed) out: each frame static (docs/comak.md)");
  app.add_flag("--single-start", single_start,
               "solve each frame from the previous frame's solution only (no second start from the "
               "passive settle; about half the time, may keep a worse local optimum)");
  bool no_move_limits = false;
  app.add_flag("--no-move-limits", no_move_limits,
               "solve attempt 1 and the second start as one Ipopt solve each, without the step "
               "control of moving limits (as before 2026-12-03; faster on some frames, can leave "
               "the patella's groove; docs/comak.md)");
  app.add_option("--retries", o.retries, "retry attempts of a failed frame: 0..3 (docs/comak.md)")
      ->capture_default_str();
  app.add_option("--lowpass-hz", lowpass_hz, "low-pass cutoff of the trial kinematics [Hz]")
      ->capture_default_str();
  app.add_option("--sto-prefix", sto_prefix,
                 "prefix of the .sto exports (default: --out without .h5)");
  app.add_flag("--no-pressure", no_pressure, "do not store per-triangle pressure / XDMF");
  app.add_option("--ipopt-print-level", o.print_level, "Ipopt output, 0..12")->capture_default_str();
  app.add_flag("-v,--verbose", verbose, "one line per frame");
  app.add_flag("-q,--quiet", quiet, "warnings and errors only");
  app.footer(
      "Sample runs:\n"
      "  arthrosim-comak --model data/models/knee_parametric/knee_coarse.urdf \\\n"
      "      --trial data/trials/synthetic_gait --out comak_coarse.h5 --first-frame 0 --last-frame 2\n"
      "  arthrosim-comak --model data/models/knee_parametric/knee.urdf \\\n"
      "      --trial data/trials/synthetic_gait --out kinematics.h5 -v      # whole SYNTHETIC cycle\n"
      "  arthrosim-comak --model data/models/knee_parametric/coarse --scene data/scenes/demo.yaml \\\n"
      "      --trial data/trials/synthetic_gait --out comak_scene.h5 --first-frame 0 --last-frame 2\n"
      "      # model folder + the scene's comak block (as `arthrosim run` calls it)\n"
      "  arthrosim-comak --model data/models/knee_parametric/knee_coarse.urdf --ankle-equilibrium \\\n"
      "      --trial data/trials/synthetic_gait --out comak_ankle.h5 --first-frame 50 --last-frame 52\n"
      "      # ankle moment balanced too (gastrocnemii, soleus, tibialis anterior)\n"
      "  arthrosim-comak --model data/models/knee_parametric/knee_coarse.urdf --no-move-limits \\\n"
      "      --trial data/trials/synthetic_gait --out comak_plain.h5 -v\n"
      "      # without step control, to compare (scripts/kinematics_branches.py comak_plain.h5)\n"
      "  arthrosim-comak --model data/models/lenhart2015 --scene data/scenes/lenhart2015_gait.yaml \\\n"
      "      --trial data/trials/lenhart2015_overground17 --out lenhart2015.h5 -v\n"
      "      # the real subject (OpenSim-JAM's lenhart2015, walking window 1.21-2.32 s from the scene);\n"
      "      # then scripts/compare_opensim_jam.py lenhart2015.h5 --plot lenhart2015.png\n");
  CLI11_PARSE(app, argc, argv);
  common::set_log_program("arthrosim-comak");
  common::set_log_level(common::log_level_from_flags(verbose, quiet));

  try {
    std::vector<std::string> effects = {"ligaments", "muscles", "tibiofemoral_contact",
                                        "patellofemoral_contact"};
    if (!scene_path.empty()) {
      const common::Scene scene = pipelines::load_scene(scene_path);
      // The trial window of the scene (explicit flags win).
      const pipelines::SceneInputs in = pipelines::scene_inputs(scene);
      if (in.trial_start_s && !app.count("--start-time") && !app.count("--first-frame"))
        start_time = *in.trial_start_s;
      if (in.trial_end_s && !app.count("--end-time") && !app.count("--last-frame")) end_time = *in.trial_end_s;
      if (scene.has_block("comak")) {
        const pipelines::ComakStageOptions c = common::read_options<pipelines::ComakStageOptions>(scene.block("comak"));
        effects = c.effects;
        if (!app.count("--ipopt-tolerance")) o.ipopt_tolerance = c.solver.ipopt_tolerance;
        if (!app.count("--acceptable-iterations")) o.acceptable_iterations = c.solver.acceptable_iterations;
        if (!app.count("--max-iterations")) o.max_iterations = c.solver.max_iterations;
        if (!app.count("--activation-min")) o.activation_min = c.solver.activation_min;
        if (!app.count("--reserve-actuators")) o.reserve_actuators = c.solver.reserve_actuators;
        if (!ankle_flag->count()) o.ankle_equilibrium = c.solver.ankle_equilibrium;
        if (!app.count("--body-inertia")) o.body_inertia = c.solver.body_inertia;
        if (!hip_flag->count()) o.hip_equilibrium = c.solver.hip_equilibrium;
        if (!no_damping) o.coordinate_damping = c.solver.coordinate_damping;
        if (!app.count("--lowpass-hz")) lowpass_hz = c.trial.lowpass.cutoff_hz;
        if (!single_start) o.second_start = c.solver.second_start;
      }
    }
    if (single_start) o.second_start = false;
    if (no_damping) o.coordinate_damping = false;
    if (no_move_limits) o.move_limits_first = false;
    for (const std::string& wa : weight_args) {
      const auto [name, w] = pipelines::parse_name_value(wa, "--muscle-weight");
      o.muscle_weights[name] = w;  // name and range checked by ComakProblem
    }
    auto wants = [&](const char* e) { return std::find(effects.begin(), effects.end(), e) != effects.end(); };
    if (!wants("muscles"))
      throw common::InputError(scene_path + ": error: comak effects must include muscles (they balance the "
                               "flexion equation)");
    if (wants("tibiofemoral_contact") != wants("patellofemoral_contact"))
      throw common::InputError(scene_path + ": error: comak effects: tibiofemoral_contact and "
                               "patellofemoral_contact can only be simulated together (the model "
                               "evaluates all contact pairs as one term)");
    o.forces.ligaments = wants("ligaments");
    o.forces.contact = wants("tibiofemoral_contact");
    const std::string given_model = model_path;
    model_path = resolve_model(model_path);
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
    if (!prepared_path.empty()) {
      // The prepare stage's cartilage (its edge length sets the contact
      // resolution of this stage too).
      const auto rep = msk::use_prepared_surfaces(model, prepared_path);
      std::string text;
      for (const auto& l : rep.lines) text += "\n  " + l;
      common::log_info("contact surfaces from " + prepared_path + ":" + text);
    }
    msk::GaitTrialOptions to;
    to.lowpass.cutoff_hz = lowpass_hz;
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
    msk::GaitTrial trial = msk::load_gait_trial(trial_path, to);
    if (!(trial.body_mass_kg > 0)) {
      trial.body_mass_kg = model.subject_mass_kg;
      common::log_info("subject mass from the model: " + std::to_string(model.subject_mass_kg) + " kg");
    }
    if (!std::isnan(start_time) || !std::isnan(end_time)) {
      // The time window: frames of the trial's grid inside [start, end].
      const auto [f0, f1] = msk::frames_in_window(trial, start_time, end_time);
      if ((app.count("--start-time") || app.count("--end-time")) &&
          (app.count("--first-frame") || app.count("--last-frame")))
        throw common::InputError("arthrosim-comak: give --start-time/--end-time or --first-frame/--last-frame, "
                                 "not both");
      first = f0;
      last = f1;
    }
    if (trial.side != msk::Side::kRight)
      throw common::InputError(trial_path + ": error: the bundled knee models are right knees; "
                               "this trial is of the left leg");
    std::vector<msk::ComakFrameInput> frames;
    if (model_dynamics) {
      std::vector<std::string> ignored;
      frames = msk::comak_model_frame_inputs(model, trial, first, last, stride, &ignored);
      for (const auto& i : ignored) common::log_info("external force not applied: " + i);
    } else {
      const msk::LegModel leg = msk::leg_model_for_trial(trial);
      const msk::KneeLoads loads = msk::compute_knee_loads(trial, leg);
      frames = msk::comak_frame_inputs(loads, first, last, stride, &leg);
    }
    msk::ComakProblem problem(model, o);

    std::ostringstream opts;
    opts << "model: " << model_path << "\nprepared: " << (prepared_path.empty() ? "none" : prepared_path)
         << "\ntrial: " << trial_path << "\nfirst_frame: " << first
         << "\nlast_frame: " << last << "\nstride: " << stride
         << "\nforce_tolerance_n: " << o.force_tolerance << "\nlength_scale_m: " << o.length_scale
         << "\nipopt_tolerance: " << o.ipopt_tolerance << "\nmax_iterations: " << o.max_iterations
         << "\nactivation_min: " << o.activation_min
         << "\nacceptable_iterations: " << o.acceptable_iterations
         << "\nreserve_actuators: " << (o.reserve_actuators ? "true" : "false")
         << "\nankle_equilibrium: " << (o.ankle_equilibrium ? "true" : "false")
         << "\nhip_equilibrium: " << (o.hip_equilibrium ? "true" : "false")
         << "\nbody_inertia: " << (o.body_inertia ? "true" : "false")
         << "\nforce_length: " << (o.forces.force_length ? "true" : "false")
         << "\nsecond_start: " << (o.second_start ? "true" : "false")
         << "\nretries: " << o.retries
         << "\nmove_limits_first: " << (o.move_limits_first ? "true" : "false")
         << "\nmove_limit_m: " << o.move_limit_m << "\nmove_limit_rad: " << o.move_limit_rad
         << "\nsecond_start_move_limit_scale: " << o.second_start_move_limit_scale
         << "\ncoordinate_damping: " << (o.coordinate_damping ? "true" : "false")
         << "\nloads: " << (model_dynamics ? "model dynamics (the model's own leg)" : "generic leg chain (knee_loads.h)")
         << "\nlowpass_cutoff_hz: " << lowpass_hz
         << "\nhessian: limited-memory\n";
    for (const auto& [name, w] : o.muscle_weights) opts << "muscle_weight." << name << ": " << w << "\n";
    std::string effect_text;
    for (const auto& e : effects) effect_text += (effect_text.empty() ? "" : ", ") + e;
    opts << "effects: [" << effect_text << "]\n";
    common::log_info("options:\n" + opts.str() + (trial.synthetic ? "trial is SYNTHETIC\n" : ""));
    const auto meta = common::collect_run_metadata("arthrosim-comak", argc, argv, scene_path, opts.str());

    common::EffectLedger ledger("comak");
    if (o.forces.ligaments) ledger.record("ligaments", model.num_bundles());
    ledger.record("muscles", static_cast<std::int64_t>(model.muscles.size()));
    const int tibia = model.role_body("tibia"), patella = model.role_body("patella");
    for (const auto& c : model.contacts) {
      if (!o.forces.contact) break;
      if (c.casting().body == tibia) ledger.record("tibiofemoral_contact", c.casting().mesh.F.rows(), c.name());
      if (c.casting().body == patella) ledger.record("patellofemoral_contact", c.casting().mesh.F.rows(), c.name());
    }

    msk::KinematicsFileInfo info;
    info.model_path = model_path;
    info.trial_path = trial_path;
    info.body_mass_kg = trial.body_mass_kg;
    info.synthetic = trial.synthetic;
    info.expected_frames = static_cast<std::int64_t>(frames.size());
    info.pressure_fields = !no_pressure;
    {
      std::vector<common::NamedInput> inputs = common::files_of(given_model, "--model");
      for (const auto& f : {common::NamedInput{model_path, "the URDF of --model"}, {prepared_path, "--prepared"},
                            {scene_path, "--scene"}, {trial.source, "--trial"}})
        inputs.push_back(f);
      for (const auto& f : common::files_of(trial_path, "--trial")) inputs.push_back(f);
      const msk::TrialDescription td = msk::read_trial_description(trial_path);
      for (const auto& f : {td.kinematics_file, td.grf_file, td.knee_loads_file, td.external_loads_file})
        inputs.push_back({f, "a file of --trial"});
      common::refuse_output_over_inputs("arthrosim-comak", "--out", out, inputs);
    }
    // Written as <out>.partial, renamed over <out> when finished (common/output_file.h).
    common::AtomicOutput atomic(out);
    msk::KinematicsFileWriter writer(atomic.temp().string(), problem, info, meta);
    if (trial.truncated)
      common::log_warn(trial_path + ": the trial ends early at frame " +
                       std::to_string(trial.truncated->frame) + ": " + trial.truncated->reason);
    if (sto_prefix.empty()) {
      sto_prefix = out;
      if (sto_prefix.size() > 3 && sto_prefix.substr(sto_prefix.size() - 3) == ".h5")
        sto_prefix.resize(sto_prefix.size() - 3);
    }
    common::Progress progress("comak", static_cast<std::int64_t>(frames.size()));
    msk::ComakRunSummary summary;
    try {
      summary = msk::run_comak(problem, frames, [&](const auto& f, const auto& r, const auto& d) {
        writer.append(f, r, d);
        progress.step();
      });
    } catch (const msk::ComakRunStopped& e) {
      // Finish the file with the frames before the stop (attribute `stopped`).
      progress.finish();
      writer.finish(e.summary, ledger, sto_prefix);
      // (run_comak has logged the reason, naming the frame.) A previous
      // complete <out> is kept; the stopped run stays under its partial name.
      std::cerr << "arthrosim-comak: stopped at frame " << e.frame << "; the " << e.summary.frames
                << " frames before it are in " << atomic.temp().string() << "\n";
      return 1;
    }
    progress.finish();
    writer.finish(summary, ledger, sto_prefix);
    atomic.commit();
    std::printf("arthrosim-comak: %d frames, %d converged, %d failed, %d Ipopt iterations, %.2f s "
                "(%.3f s/frame) -> %s\n",
                summary.frames, summary.converged, summary.failed, summary.total_iterations,
                summary.wall_time, summary.wall_time / std::max(1, summary.frames), out.c_str());
    if (summary.failed) {
      std::string list;
      for (int i : summary.failed_frames) list += " " + std::to_string(i);
      common::log_error("failed frames (marked in /solver/status):" + list);
      return 2;
    }
  } catch (const std::exception& e) {
    std::cerr << "arthrosim-comak: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
