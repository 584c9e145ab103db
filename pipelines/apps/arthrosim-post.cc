// arthrosim-post: the post stage (issue 7, docs/post.md). Averages the first principal
// strain directions of each scenario over time (magnitude-weighted orientation tensor),
// projects the view's surface onto the scene's view plane, registers a split-line map
// onto the projected outline with Coherent Point Drift (affine, then non-rigid), compares
// the line orientations sample by sample, and writes DIR/report.html + DIR/summary.json.
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "common/error.h"
#include "common/hdf5.h"
#include "common/scene.h"
#include "pipelines/stages.h"
#include "pipelines/post_stage.h"

using namespace arthrosim;

int main(int argc, char** argv) {
  CLI::App app{
      "arthrosim-post: split-line comparison and report of deformable-surface results (docs/post.md).\n"
      "Writes DIR/report.html with DIR/plotly-gl3d.min.js beside it (interactive figures, opens offline from DIR)\n"
      "and DIR/summary.json. Missing optional inputs (kinematics, map, deflection) are listed in the report\n"
      "instead of stopping the run."};
  std::vector<std::string> surfaces, biphasic, shockwave;
  std::string kinematics, map, scene_file, out, out_dir;
  double spacing = 0.0;
  app.add_option("--surface", surfaces,
                 "surface output of one scenario, NAME=FILE or FILE (name from the file's 'scenario' attribute); repeat");
  app.add_option("--kinematics", kinematics, "kinematics file of the musculoskeletal stage (contact force, key frames)");
  app.add_option("--biphasic", biphasic,
                 "output of the biphasic stage (biphasic.h5), NAME=FILE or FILE: adds its section; repeat");
  app.add_option("--shockwave", shockwave, "a run file of the shockwave stage (<out>_efd<EFD>.h5): adds its section; repeat");
  app.add_option("--map", map, "split-line map (.svg or .csv); overrides the scene's post.splitline_map");
  app.add_option("--map-sample-spacing", spacing, "SVG maps: sample spacing along split lines [map units], 0 = auto")
      ->capture_default_str();
  app.add_option("--scene", scene_file, "scene file: its post block sets the view, CPD and comparison options");
  app.add_option("--out", out, "output folder");
  app.add_option("--out-dir", out_dir, "same as --out (the runner's spelling)");
  app.footer(
      "Sample run on bundled data (a CTest; no surface output, so the report lists what is missing):\n"
      "  arthrosim-post --map data/splitlines/synthetic_femur.svg --scene data/scenes/osmotic.yaml --out out/post_map_only\n"
      "With your own runs' files:\n"
      "  arthrosim-post --surface osmotic=out/demo/surface_osmotic.h5 --map data/splitlines/synthetic_femur.csv \\\n"
      "      --scene data/scenes/osmotic.yaml --out out/post\n"
      "  arthrosim-post --surface osmotic=F1.h5 --surface gait=F2.h5 --kinematics K.h5 --scene S.yaml --out DIR\n"
      "Stage 1 with the biphasic and shockwave sections (a CTest, from the build folder after the biphasic samples):\n"
      "  arthrosim-post --kinematics sample_runs/biphasic_kinematics.h5 --biphasic sample_runs/biphasic_five_frames.h5 \\\n"
      "      --shockwave sample_runs/post_sw_bar_efd0.33.h5 --out sample_runs/post_stages\n");
  CLI11_PARSE(app, argc, argv);
  try {
    if (out.empty()) out = out_dir;
    if (out.empty()) throw common::InputError("arthrosim-post: --out DIR is required");
    pipelines::PostOptions options;
    pipelines::PostInputs inputs;
    if (!scene_file.empty()) {
      options = pipelines::post_from_scene(pipelines::load_scene(scene_file));
      inputs.scene_file = scene_file;
    }
    if (!map.empty()) options.splitline_map = map;
    options.map_sample_spacing = spacing;
    inputs.kinematics = kinematics;
    for (const auto& b : biphasic) {
      const auto eq = b.find('=');
      if (eq != std::string::npos) inputs.biphasic.emplace_back(b.substr(0, eq), b.substr(eq + 1));
      else inputs.biphasic.emplace_back(std::filesystem::path(b).stem().string(), b);
    }
    inputs.shockwave = shockwave;
    for (const auto& s : surfaces) {
      const auto eq = s.find('=');
      std::string name, file;
      if (eq != std::string::npos) {
        name = s.substr(0, eq), file = s.substr(eq + 1);
      } else {
        file = s;
        common::H5File f(file, common::H5File::Mode::kRead);
        if (f.has_attribute("/", "scenario")) {
          name = f.attribute_string("/", "scenario");
        } else {
          name = std::filesystem::path(file).stem().string();
          if (name.rfind("surface_", 0) == 0) name = name.substr(8);
        }
      }
      if (name.empty() || file.empty()) throw common::InputError("--surface '" + s + "': expected NAME=FILE or FILE");
      inputs.surfaces.emplace_back(name, file);
    }
    std::printf("arthrosim-post: %zu surface file(s), kinematics %s, map %s, view surface '%s' direction (%g, %g, %g) "
                "up (%g, %g, %g), CPD w %g beta %g lambda %g %s -> %s\n",
                inputs.surfaces.size(), kinematics.empty() ? "(none)" : kinematics.c_str(),
                options.splitline_map.empty() ? "(none)" : options.splitline_map.c_str(), options.view_surface.c_str(),
                options.view.direction.x(), options.view.direction.y(), options.view.direction.z(), options.view.up.x(),
                options.view.up.y(), options.view.up.z(), options.registration.w, options.registration.beta,
                options.registration.lambda, options.registration.nonrigid ? "non-rigid" : "affine only", out.c_str());
    const auto summary = pipelines::run_post(inputs, options, out);
    for (const auto& m : summary.missing) std::printf("  missing: %s\n", m.c_str());
    for (const auto& s : summary.scenarios)
      for (const auto& r : s.stats)
        std::printf("  %-14s %-10s %5d samples (%d covered): mean %.2f deg, median %.2f deg, within threshold %.3f\n",
                    s.scenario.c_str(), r.region.c_str(), r.samples, r.covered, r.mean_deg, r.median_deg, r.fraction_within);
    std::printf("wrote %s (%zu figures) and %s\n", summary.report_path.c_str(), summary.figures.size(),
                summary.summary_path.c_str());
  } catch (const std::exception& e) {
    std::cerr << e.what() << "\n";
    return 1;
  }
  return 0;
}
