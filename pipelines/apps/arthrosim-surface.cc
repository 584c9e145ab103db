// arthrosim-surface: the deformable-surface stage (issue 5). Prepared model +
// scene scenario -> ANCF shell simulation of the cartilage surfaces -> HDF5
// (docs/surface_output.md) + XDMF sidecar.
#include <cstdio>
#include <exception>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>

#include "common/log.h"
#include "common/output_file.h"
#include "pipelines/surface_stage.h"

using namespace arthrosim;

int main(int argc, char** argv) {
  CLI::App app{
      "arthrosim-surface: deformable cartilage surfaces as 4-node ANCF shells (seed 002) on their bones.\n"
      "Builds, per cartilage surface the scenario lists, a shell model with exactly the scenario's effects\n"
      "(foundation_springs, foundation_damping, osmotic_pressure, periphery_fixed, imposed_kinematics from\n"
      "--kinematics, inertia), couples the surfaces of `contact_pairs` by deformable mesh contact when the\n"
      "scenario lists mesh_contact, integrates them as one system (HHT, quasi-static without inertia, or a\n"
      "direct steady-state solve with steady_state: true) and writes displacement, deflection, strains and\n"
      "contact pressure per output frame, the tibiofemoral contact force and the penetration/deflection\n"
      "ratio per step (HDF5 + XDMF for ParaView).\n"
      "Material/effect options and their seed defaults: docs/scenes.md; output: docs/surface_output.md."};
  pipelines::SurfaceStageOptions o;
  bool verbose = false, quiet = false;
  app.add_option("--prepared", o.prepared,
                 "prepared-model HDF5 (arthrosim-prepare); not needed by a scenario with a generic `mesh`");
  app.add_option("--kinematics", o.kinematics, "kinematics HDF5 (arthrosim-comak), for imposed_kinematics");
  app.add_option("--scene", o.scene, "scene YAML")->required();
  app.add_option("--scenario", o.scenario, "scenario of the scene (may be left out if it has only one)");
  app.add_option("--out", o.out, "output HDF5 (XDMF sidecar next to it, same stem)")->required();
  app.add_flag("--allow-partial", o.allow_partial,
               "go on with an incomplete kinematics file (a killed or stopped COMAK run); the output records it");
  app.add_flag("--verbose", verbose, "more messages");
  app.add_flag("--quiet", quiet, "warnings and errors only (no progress)");
  app.footer(
      "Sample runs:\n"
      "  arthrosim-prepare --model data/models/knee_parametric/coarse --out prepared_coarse.h5\n"
      "  arthrosim-surface --prepared prepared_coarse.h5 --scene data/scenes/osmotic.yaml --scenario osmotic \\\n"
      "      --out surface_osmotic.h5      # steady osmotic swelling of the femoral cartilage\n"
      "  paraview surface_osmotic.xdmf    # deflection, e1, e1_dir per frame\n"
      "  arthrosim-surface --scene data/scenes/cantilever_plate.yaml --out cantilever.h5\n"
      "      # generic quad mesh (scene key mesh): cantilever plate vs beam theory\n"
      "  arthrosim run data/scenes/gait.yaml --out out/gait [--dry-run]\n"
      "      # one gait cycle (about 9 min on 2 cores): prepare, COMAK, then this stage with mesh contact\n");
  CLI11_PARSE(app, argc, argv);
  common::set_log_program("arthrosim-surface");
  common::set_log_level(common::log_level_from_flags(verbose, quiet));
  o.progress = !quiet;
  for (int i = 0; i < argc; ++i) o.argv.emplace_back(argv[i]);
  try {
    common::refuse_output_over_inputs("arthrosim-surface", "--out", o.out,
                                      {{o.prepared, "--prepared"}, {o.kinematics, "--kinematics"}, {o.scene, "--scene"}});
    const pipelines::SurfaceStageResult r = pipelines::run_surface_stage(o);
    std::printf("scenario %s: %d frames, %ld steps, %ld Newton iterations, %ld rejected steps, %ld factorizations\n",
                r.scenario.c_str(), r.frames, r.steps, r.newton_iterations, r.rejected_steps, r.factorizations);
    for (const auto& s : r.surfaces)
      std::printf("  %-14s %6d nodes %6d elements  max deflection %.4g mm  e1 %.4g .. %.4g  residual %.3g N "
                  "(tolerance %.3g N)\n",
                  s.name.c_str(), s.nodes, s.elements, s.max_deflection_m * 1e3, s.e1_min, s.e1_max,
                  s.final_residual_N, s.residual_tolerance_N);
    std::printf("timings: wall %.2f s, assembly %.2f s (of which contact %.2f s), factorization %.2f s (%.3f s each), "
                "solve %.2f s\n",
                r.wall_s, r.assembly_s, r.contact_s, r.factorization_s,
                r.factorizations > 0 ? r.factorization_s / r.factorizations : 0.0, r.solve_s);
    std::printf("assembly: %ld evaluations (%ld with the tangent); surfaces %.2f s (elements %.2f s, their "
                "summation %.2f s, other terms %.2f s), contact %.2f s, surface/system copies %.2f s\n",
                r.evaluations, r.tangent_evaluations, r.surfaces_s, r.elements_s, r.element_scatter_s,
                r.surfaces_s - r.elements_s - r.element_scatter_s, r.contact_s, r.coupling_copy_s);
    if (r.contact_steps > 0)
      std::printf("contact: %ld steps in contact, %.1f active contacts per such step, max interpenetration %.4g mm, "
                  "%ld steps broke the accuracy rule (worst penetration/deflection %.3g), %ld pattern changes\n",
                  r.contact_steps, static_cast<double>(r.active_contacts_sum) / r.contact_steps,
                  r.max_penetration_m * 1e3, r.penetration_warnings, r.worst_penetration_ratio, r.pattern_changes);
    if (r.contact_steps > 0)
      std::printf("contact away from rims (unfaded contacts): %ld steps over the accuracy rule's limit (worst %.3g)\n",
                  r.unfaded_penetration_warnings, r.worst_unfaded_penetration_ratio);
    std::printf("wrote %s\n", o.out.c_str());
  } catch (const std::exception& e) {
    std::cerr << "arthrosim-surface: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
