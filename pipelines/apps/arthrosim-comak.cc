// arthrosim-comak: the musculoskeletal stage's program: command line ->
// pipelines::ComakStageConfig -> pipelines::run_comak_stage (the driver,
// pipelines/comak_stage.h). Per frame of a walking trial, one Ipopt NLP
// (musculoskeletal/comak.h, docs/comak.md), written frame by frame into the
// kinematics file (docs/kinematics_file.md).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <iostream>
#include <limits>
#include <string>

#include "common/error.h"
#include "common/log.h"
#include "musculoskeletal/comak.h"
#include "pipelines/apps/name_value.h"
#include "pipelines/comak_stage.h"
#include "pipelines/stages.h"

using namespace arthrosim;
namespace msk = arthrosim::musculoskeletal;

int main(int argc, char** argv) {
  CLI::App app{
      "arthrosim-comak: COMAK over a walking trial (driver: pipelines/comak_stage.h). Per frame one Ipopt NLP:\n"
      "muscle activations and the\n"
      "11 secondary knee coordinates minimising sum w V a^2 subject to static equilibrium of the 12 knee\n"
      "coordinates (flexion prescribed from the trial) under muscles, ligaments, elastic-foundation contact\n"
      "and the external knee loads. Writes the kinematics file (HDF5, docs/kinematics_file.md), an XDMF\n"
      "sidecar with per-triangle contact pressure, and .sto exports. Method: docs/comak.md."};
  std::string model_path, trial_path, out, sto_prefix, scene_path, prepared_path;
  int first = 0, last = -1, stride = 1;
  msk::ComakOptions o;
  double lowpass_hz = 0;  // used only when given
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
                 "the whole trial is still filtered and differentiated; default: the scene's trial.start_s)");
  app.add_option("--end-time", end_time,
                 "last time of the trial to solve [s] (frames at or before it; default: the scene's trial.end_s)");
  app.add_option("--tolerance", o.force_tolerance,
                 "equilibrium tolerance of the force rows [N]; moment rows x length scale 0.03 m")
      ->capture_default_str();
  app.add_option("--ipopt-tolerance", o.ipopt_tolerance, "Ipopt 'tol' (scaled NLP; default: comak.ipopt_tolerance)");
  app.add_option("--max-iterations", o.max_iterations,
                 "Ipopt iteration limit per attempt (default: comak.ipopt_max_iterations)");
  app.add_option("--acceptable-iterations", o.acceptable_iterations,
                 "consecutive iterates at Ipopt's acceptable level that end a solve as 'acceptable' "
                 "(a larger value keeps iterating towards --ipopt-tolerance; default: "
                 "comak.ipopt_acceptable_iterations)");
  app.add_option("--activation-min", o.activation_min,
                 "lower bound of the activations, 0..1 (default: comak.activation_min)");
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
               "control of moving limits (faster on some frames, can leave the patella's groove; "
               "docs/comak.md)");
  app.add_option("--retries", o.retries, "retry attempts of a failed frame: 0..3 (docs/comak.md)")
      ->capture_default_str();
  app.add_option("--lowpass-hz", lowpass_hz,
                 "low-pass cutoff of the trial kinematics [Hz] (default: comak.lowpass_cutoff_hz)");
  app.add_option("--sto-prefix", sto_prefix,
                 "prefix of the .sto exports (default: --out without .h5)");
  double checkpoint_interval_s = 60.0;
  app.add_option("--checkpoint-interval-s", checkpoint_interval_s,
                 "wall time between checkpoints <out>.checkpoint [s] (0: after every frame; default: "
                 "comak.checkpoint_interval_s, 60); a rerun of the same command continues from the last one");
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
      "  arthrosim-comak --model data/models/knee_parametric/knee_coarse.urdf --checkpoint-interval-s 0 \\\n"
      "      --trial data/trials/synthetic_gait --out comak_checkpoints.h5 --first-frame 0 --last-frame 4\n"
      "      # a checkpoint after every frame; killed, the same command continues from the last one\n"
      "  arthrosim-comak --model data/models/lenhart2015 --scene data/scenes/lenhart2015_gait.yaml \\\n"
      "      --trial data/trials/lenhart2015_overground17 --out lenhart2015.h5 -v\n"
      "      # the real subject (OpenSim-JAM's lenhart2015, walking window 1.21-2.32 s from the scene);\n"
      "      # then scripts/compare_opensim_jam.py lenhart2015.h5 --plot lenhart2015.png\n");
  CLI11_PARSE(app, argc, argv);
  common::set_log_program("arthrosim-comak");
  common::set_log_level(common::log_level_from_flags(verbose, quiet));

  try {
    pipelines::ComakStageConfig c;
    c.options = scene_path.empty() ? pipelines::ComakStageOptions{}
                                   : pipelines::comak_from_scene(pipelines::load_scene(scene_path));
    if (scene_path.empty()) c.options.effects = {"ligaments", "muscles", "tibiofemoral_contact", "patellofemoral_contact"};
    // Explicit flags win over the scene.
    msk::ComakOptions& so = c.options.solver;
    if (app.count("--tolerance")) so.force_tolerance = o.force_tolerance;
    if (app.count("--ipopt-tolerance")) so.ipopt_tolerance = o.ipopt_tolerance;
    if (app.count("--max-iterations")) so.max_iterations = o.max_iterations;
    if (app.count("--activation-min")) so.activation_min = o.activation_min;
    if (app.count("--reserve-actuators")) so.reserve_actuators = o.reserve_actuators;
    if (app.count("--acceptable-iterations")) so.acceptable_iterations = o.acceptable_iterations;
    if (ankle_flag->count()) so.ankle_equilibrium = o.ankle_equilibrium;
    if (hip_flag->count()) so.hip_equilibrium = o.hip_equilibrium;
    if (app.count("--body-inertia")) so.body_inertia = o.body_inertia;
    if (app.count("--force-length")) so.forces.force_length = o.forces.force_length;
    if (app.count("--retries")) so.retries = o.retries;
    if (app.count("--ipopt-print-level")) so.print_level = o.print_level;
    if (app.count("--lowpass-hz")) c.options.trial.lowpass.cutoff_hz = lowpass_hz;
    if (app.count("--checkpoint-interval-s")) c.options.checkpoint_interval_s = checkpoint_interval_s;
    if (single_start) so.second_start = false;
    if (no_move_limits) so.move_limits_first = false;
    if (no_damping) so.coordinate_damping = false;
    // The trial window: explicit flags win over the scene's trial.start_s/end_s.
    const bool frame_flags = app.count("--first-frame") || app.count("--last-frame");
    const bool time_flags = app.count("--start-time") || app.count("--end-time");
    if (frame_flags && time_flags)
      throw common::InputError("arthrosim-comak: give --start-time/--end-time or --first-frame/--last-frame, "
                               "not both");
    if (frame_flags) c.options.start_time_s = c.options.end_time_s = std::numeric_limits<double>::quiet_NaN();
    if (app.count("--start-time")) c.options.start_time_s = start_time;
    if (app.count("--end-time")) c.options.end_time_s = end_time;
    for (const std::string& wa : weight_args) {
      const auto [name, w] = pipelines::parse_name_value(wa, "--muscle-weight");
      so.muscle_weights[name] = w;  // name and range checked by ComakProblem
    }
    c.model = model_path;
    c.prepared = prepared_path;
    c.trial = trial_path;
    c.out = out;
    c.sto_prefix = sto_prefix;
    c.first_frame = first;
    c.last_frame = last;
    c.stride = stride;
    c.pressure_fields = !no_pressure;
    c.scene = scene_path;
    for (int i = 0; i < argc; ++i) c.argv.emplace_back(argv[i]);
    const pipelines::ComakStageResult r = pipelines::run_comak_stage(c);
    const msk::ComakRunSummary& summary = r.summary;
    if (r.stopped) {
      std::cerr << "arthrosim-comak: stopped at frame " << r.stopped_frame << "; the " << summary.frames
                << " frames before it are in " << out << ".partial\n";
      return 1;
    }
    std::printf("arthrosim-comak: %d frames, %d converged, %d failed, %d Ipopt iterations, %.2f s "
                "(%.3f s/frame) -> %s\n",
                summary.frames, summary.converged, summary.failed, summary.total_iterations, summary.wall_time,
                summary.wall_time / std::max(1, summary.frames), out.c_str());
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
