// arthrosim-biphasic: biphasic cartilage layers loaded by the penetration
// method (seed 000) from the stage-1 kinematics. Prepared model + kinematics
// file -> HDF5 (docs/biphasic.md, "Output") + XDMF sidecar.
#include <cstdio>
#include <exception>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>

#include "biphasic/output_file.h"
#include "common/error.h"
#include "common/log.h"
#include "common/output_file.h"
#include "pipelines/biphasic_stage.h"
#include "pipelines/stages.h"

using namespace arthrosim;

int main(int argc, char** argv) {
  CLI::App app{
      "arthrosim-biphasic: cartilage layers as linear biphasic (solid + fluid) volumes on rigid bones, loaded by\n"
      "the penetration method of seed 000. Each layer of the prepared model is extruded from its articular quad\n"
      "surface to the bone through the thickness map (Taylor-Hood Q2-Q1 hexahedra). Per stage-1 frame the bones\n"
      "are placed by the kinematics file, the overlap of the undeformed layers is split between them by their\n"
      "moduli and thicknesses (eq 24), the elastic normal stress is H g/h, the total normal stress is scaled to\n"
      "the compartment's contact force (eq 26) and the fluid pressure on the contact area is their difference\n"
      "(eq 17); the rest of the surface drains freely. The boundary conditions are interpolated in time between\n"
      "frames; each layer's matrix is factorised once and every step is one forward/back substitution.\n"
      "Writes displacement, fluid pressure, stresses and fluid flux per step and node, and per step the contact\n"
      "area, fluid load support, maximum tensile stress on the contact surface and maximum shear stress at the\n"
      "cartilage-bone interface with their regions. Method, parameters and limits: docs/biphasic.md."};
  pipelines::BiphasicStageOptions o;
  const pipelines::BiphasicOptions defaults;
  bool verbose = false, quiet = false;
  std::string scene;
  std::vector<std::string> layers = defaults.layers;
  int element_layers = defaults.element_layers;
  double grading = defaults.grading, time_step_ms = defaults.time_step_s * 1e3, omega = defaults.omega;
  double h_mpa = defaults.aggregate_modulus_Pa * 1e-6, nu = defaults.poisson_ratio, k = defaults.permeability_m4_per_Ns;
  double margin_mm = defaults.crop_margin_m * 1e3, end_time_s = -1.0;
  app.add_option("--prepared", o.prepared, "prepared-model HDF5 (arthrosim-prepare)");
  app.add_option("--kinematics", o.kinematics, "kinematics HDF5 (arthrosim-comak)");
  app.add_option("--out", o.out, "output HDF5 (XDMF sidecar next to it, same stem)")->required();
  app.add_option("--scene", scene,
                 "scene YAML: its biphasic block gives effects and options (flags given here win)");
  auto* o_layers = app.add_option("--layers", layers, "cartilage layers (femur, tibia_medial, tibia_lateral, patella)")
                       ->delimiter(',')
                       ->capture_default_str();
  auto* o_el = app.add_option("--element-layers", element_layers, "element layers through the thickness (1..16)")
                   ->capture_default_str();
  auto* o_grading =
      app.add_option("--grading", grading,
                     "height ratio of successive element layers from the surface to the bone (1 = equal, 1..4)")
          ->capture_default_str();
  auto* o_dt = app.add_option("--time-step-ms", time_step_ms, "time step [ms]")->capture_default_str();
  auto* o_omega = app.add_option("--omega", omega, "generalised trapezoidal parameter in [0.5, 1]")->capture_default_str();
  auto* o_h = app.add_option("--aggregate-modulus-mpa", h_mpa, "aggregate modulus H_A of every layer [MPa]")
                  ->capture_default_str();
  auto* o_nu = app.add_option("--poisson-ratio", nu, "drained Poisson's ratio of the solid matrix")->capture_default_str();
  auto* o_k = app.add_option("--permeability", k, "permeability k [m^4/(N s)]")->capture_default_str();
  auto* o_margin =
      app.add_option("--crop-margin-mm", margin_mm,
                     "keep the quads within this distance of a vertex in contact in some frame [mm]; 0 = whole surface")
          ->capture_default_str();
  auto* o_end = app.add_option("--end-time-s", end_time_s, "last frame time simulated [s] (default: the whole trial)");
  double checkpoint_interval_s = 60.0;
  auto* o_ckpt = app.add_option("--checkpoint-interval-s", checkpoint_interval_s,
                                "wall time between checkpoints <out>.checkpoint [s] (0: after every step); rerun the "
                                "same command to continue a killed run from its last checkpoint")
                     ->capture_default_str();
  std::string compare_to;
  app.add_option("--compare-to", compare_to,
                 "after the run (or instead of it, with --compare-only), print the relative difference of the key "
                 "outputs of --out against this earlier output file (common step times)");
  std::string canonical;
  app.add_option("--canonical", canonical,
                 "write the canonical two-layer case (two flat layers pressed together) into this folder and run "
                 "it (--prepared, --kinematics and --layers are then those of the case)");
  bool compare_only = false;
  app.add_flag("--compare-only", compare_only, "do not run; compare --out with --compare-to");
  app.add_flag("--allow-partial", o.allow_partial,
               "go on with an incomplete kinematics file (a killed or stopped COMAK run; refused otherwise): "
               "the output says so (root attribute partial_input)");
  app.add_flag("--verbose", verbose, "more messages");
  app.add_flag("--quiet", quiet, "warnings and errors only (no progress)");
  app.footer(
      "Sample runs:\n"
      "  arthrosim-prepare --model data/models/knee_parametric/coarse --out prepared.h5\n"
      "  arthrosim-comak --model data/models/knee_parametric/coarse --prepared prepared.h5 \\\n"
      "      --trial data/trials/synthetic_gait --first-frame 10 --last-frame 14 --out kinematics.h5\n"
      "  arthrosim-biphasic --prepared prepared.h5 --kinematics kinematics.h5 --element-layers 1 \\\n"
      "      --out biphasic.h5                       # five frames of stance, three layers (about 10 s)\n"
      "  arthrosim-biphasic --out biphasic.h5 --compare-to other.h5 --compare-only\n"
      "      # key outputs of one run against another (scripts/biphasic_study.sh)\n"
      "  paraview biphasic.xdmf                      # fluid pressure, stresses, flux per step\n"
      "  arthrosim-biphasic --canonical two_layers --out two_layers/biphasic.h5\n"
      "      # two flat layers pressed together (docs/biphasic.md, \"Canonical case\")\n"
      "  arthrosim run data/scenes/biphasic_gait.yaml --out out/biphasic_gait [--dry-run]\n"
      "      # the whole gait cycle: prepare, COMAK, then this stage with the scene's biphasic block\n");
  CLI11_PARSE(app, argc, argv);
  common::set_log_program("arthrosim-biphasic");
  common::set_log_level(common::log_level_from_flags(verbose, quiet));
  o.progress = !quiet;
  for (int i = 0; i < argc; ++i) o.argv.emplace_back(argv[i]);
  auto compare = [&]() {
    double worst = 0.0;
    for (const auto& d : biphasic::compare_outputs(o.out, compare_to)) {
      std::printf("compare %-13s %-20s %.4g (reference peak %.4g, %d common steps)\n", d.layer.c_str(),
                  d.metric.c_str(), d.relative, d.reference_peak, d.common_times);
      worst = std::max(worst, d.relative);
    }
    std::printf("compare worst relative difference %.4g\n", worst);
  };
  try {
    // Options: the defaults, then the scene's biphasic block, then the flags given.
    if (!scene.empty()) {
      const common::Scene sc = pipelines::load_scene(scene);
      static_cast<pipelines::BiphasicOptions&>(o) = common::read_options<pipelines::BiphasicOptions>(sc.block("biphasic"));
    }
    if (o_layers->count()) o.layers = layers;
    if (o_el->count()) o.element_layers = element_layers;
    if (o_grading->count()) o.grading = grading;
    if (o_dt->count()) o.time_step_s = time_step_ms * 1e-3;
    if (o_omega->count()) o.omega = omega;
    if (o_h->count()) o.aggregate_modulus_Pa = h_mpa * 1e6;
    if (o_nu->count()) o.poisson_ratio = nu;
    if (o_k->count()) o.permeability_m4_per_Ns = k;
    if (o_margin->count()) o.crop_margin_m = margin_mm * 1e-3;
    if (o_end->count()) o.end_time_s = end_time_s;
    if (o_ckpt->count()) o.checkpoint_interval_s = checkpoint_interval_s;
    if (compare_only) {
      if (compare_to.empty()) throw common::InputError("--compare-only needs --compare-to");
      compare();
      return 0;
    }
    if (!canonical.empty()) {
      const auto files = pipelines::write_two_layer_case(canonical);
      o.prepared = files.first;
      o.kinematics = files.second;
      o.layers = {"femur", "tibia_medial"};
      std::printf("canonical case: %s, %s\n", files.first.c_str(), files.second.c_str());
    }
    common::refuse_output_over_inputs("arthrosim-biphasic", "--out", o.out,
                                      {{o.prepared, "--prepared"}, {o.kinematics, "--kinematics"}, {scene, "--scene"}});
    const pipelines::BiphasicStageResult r = pipelines::run_biphasic_stage(o);
    std::printf("%d frames (%d left out: stage 1 failed), %d steps of %.4g ms, %d (pair, frame) skipped without overlap, "
                "%d without force\n",
                r.frames, r.frames_failed, r.steps, o.time_step_s * 1e3, r.skipped_pair_frames, r.unloaded_pair_frames);
    for (const auto& l : r.layers)
      std::printf("  %-13s %5d/%5d quads %7d unknowns  factorised %d x in %.2f s, %d solves %.1f ms each; peak "
                  "fluid pressure %.3g MPa, tensile %.3g MPa, interface shear %.3g MPa\n",
                  l.name.c_str(), l.quads_kept, l.quads_total, l.unknowns, l.factorizations, l.factorization_s,
                  l.solves, l.solves ? 1e3 * l.solve_s / l.solves : 0.0, l.peak_fluid_pressure_Pa * 1e-6,
                  l.peak_tensile_Pa * 1e-6, l.peak_shear_Pa * 1e-6);
    for (size_t i = 0; i < r.layers.size(); ++i)
      std::printf("  %-13s peak contact (prescribed) fluid pressure %.3g MPa, mean fluid load support over the steps "
                  "in contact %.3f\n",
                  r.layers[i].name.c_str(), r.layers[i].peak_surface_fluid_pressure_Pa * 1e-6,
                  r.mean_fluid_load_support[i]);
    for (const auto& k : r.key_steps) {
      if (k.step == 0) continue;
      std::printf("key step %d (t = %.3f s, summed contact force %.0f N):\n", k.step, k.time_s, k.force_N);
      for (const auto& l : k.layers)
        std::printf("  %-13s contact area %6.1f mm^2, fluid load support %.3f, contact fluid pressure up to %.3g MPa, "
                    "max tensile %.3g MPa (%s), max interface shear %.3g MPa (%s)\n",
                    l.name.c_str(), l.contact_area_m2 * 1e6, l.fluid_load_support,
                    l.max_surface_fluid_pressure_Pa * 1e-6, l.max_tensile_Pa * 1e-6, l.max_tensile_region.c_str(),
                    l.max_shear_Pa * 1e-6, l.max_shear_region.c_str());
    }
    std::printf("timings: preprocessing %.2f s, build (assembly + factorisation) %.2f s, stepping %.2f s, wall %.2f s\n",
                r.preprocessing_s, r.build_s, r.stepping_s, r.wall_s);
    std::printf("wrote %s\n", o.out.c_str());
    if (!compare_to.empty()) compare();
  } catch (const std::exception& e) {
    std::cerr << "arthrosim-biphasic: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
