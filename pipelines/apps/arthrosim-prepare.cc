// arthrosim-prepare: the prepare stage. Reads a model's bone and cartilage
// surfaces, repairs what is safe, validates, remeshes the cartilage, casts the
// cartilage thickness to the bone, builds the all-quad surfaces for the shell
// stage, and writes one prepared-model HDF5 file plus an XDMF sidecar.
// Schema: docs/prepared_model.md.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <iostream>
#include <sstream>
#include <string>

#include <CLI/CLI.hpp>

#include "common/log.h"
#include "common/mesh_io.h"
#include "common/metadata.h"
#include "pipelines/apps/name_value.h"
#include "common/options.h"
#include "pipelines/prepare.h"
#include "pipelines/stages.h"

using namespace arthrosim;

int main(int argc, char** argv) {
  CLI::App app{
      "arthrosim-prepare: bone + cartilage surfaces -> prepared model (HDF5 + XDMF) for the later stages.\n"
      "Model folder: a meshes.yaml manifest naming each bone's and cartilage's file, unit and body frame\n"
      "(and splitting one tibial cartilage mesh into medial and lateral), or, without one, the naming\n"
      "convention <bone>_bone.{stl,obj,ply} and <name>_cartilage.{stl,obj,ply} (a cartilage lies on the\n"
      "bone named by the first word of its name: tibia_medial -> tibia). Each mesh's size is checked\n"
      "against its unit. Safe repairs (duplicate vertices, degenerate/duplicate triangles, orientation)\n"
      "are made and reported; anything else invalid stops with an error naming the file. Every triangle\n"
      "and quad written is checked (shortest edge, smallest angle, Jacobian sign, admissible shell\n"
      "thickness). Cartilage thickness: the inward ray's entry into the bone; 0 for points inside the\n"
      "bone (overlapping segmentations), closest-point distance where no ray enters; raised to\n"
      "--min-thickness-mm; every case counted and stored. See docs/prepared_model.md."};
  std::string model_dir, out, unit, scene_path;
  double edge_mm = 0, max_cast_mm = 0, min_thickness_mm = 0, max_triangles = 0;
  int iterations = 0;
  bool verbose = false, quiet = false;
  app.add_option("--model", model_dir, "model folder (with meshes.yaml or convention-named files), or a manifest")
      ->required();
  app.add_option("--scene", scene_path,
                 "scene YAML: its prepare block gives the options (docs/scenes.md); a flag below wins over it");
  app.add_option("--edge-length-mm", edge_mm,
                 "target edge length of the remeshed cartilage [mm], 0.2..20 (default: prepare.edge_length_mm)");
  std::vector<std::string> surface_edges;
  app.add_option("--surface-edge-length-mm", surface_edges,
                 "NAME=MM: target edge length of one cartilage surface instead of --edge-length-mm (repeatable)");
  app.add_option("--out", out, "prepared-model HDF5 file to write (XDMF next to it)")->required();
  app.add_option("--unit", unit, "length unit of the input files: mm, cm or m (a manifest's unit: wins; default: prepare.mesh_unit)");
  app.add_option("--max-cast-distance-mm", max_cast_mm,
                 "longest thickness ray [mm], 1..50 (default: prepare.max_cast_distance_mm)");
  app.add_option("--remesh-iterations", iterations,
                 "isotropic remeshing iterations, 1..20 (default: prepare.remesh_iterations)");
  app.add_option("--min-thickness-mm", min_thickness_mm,
                 "thickness floor [mm], 0..2: thinner measured values are raised to it (counted; default: "
                 "prepare.min_thickness_mm)");
  app.add_option("--max-triangles", max_triangles,
                 "refuse a surface whose remesh is estimated to exceed this many triangles, >= 100 (default: "
                 "prepare.max_triangles)");
  app.add_flag("--verbose", verbose, "more messages");
  app.add_flag("--quiet", quiet, "warnings and errors only");
  app.footer(
      "Sample runs:\n"
      "  arthrosim-prepare --model data/models/knee_parametric/coarse --edge-length-mm 3 --out prepared_coarse.h5\n"
      "  arthrosim-prepare --model data/models/knee_parametric/coarse --scene data/scenes/demo.yaml --out prepared.h5\n"
      "      # options from the scene's prepare block (as `arthrosim run` calls it)\n"
      "  arthrosim-prepare --model data/models/knee_parametric/medium --edge-length-mm 2 --out prepared_medium.h5\n"
      "  arthrosim-prepare --model data/models/knee_parametric/coarse --edge-length-mm 3 \\\n"
      "      --surface-edge-length-mm femur=4.2 --out prepared_anchor.h5   # femoral 3,579 shells, tibial 1,059\n"
      "Your own segmentation (files named as above):\n"
      "  arthrosim-prepare --model my_segmentation/ --unit mm --edge-length-mm 1 --out prepared.h5\n"
      "OpenSim-JAM's lenhart2015 meshes (metres, body frames, one tibial cartilage; data/models/lenhart2015/meshes.yaml):\n"
      "  arthrosim-prepare --model data/models/lenhart2015 --edge-length-mm 2 --out prepared_lenhart.h5\n");
  CLI11_PARSE(app, argc, argv);

  common::set_log_program("arthrosim-prepare");
  common::set_log_level(common::log_level_from_flags(verbose, quiet));
  try {
    pipelines::PrepareOptions options;
    if (!scene_path.empty()) options = pipelines::prepare_from_scene(pipelines::load_scene(scene_path));
    if (app.count("--edge-length-mm")) options.edge_length = edge_mm * common::units::mm;
    for (const std::string& item : surface_edges) {  // names and ranges checked by prepare_model
      const auto [name, mm] = pipelines::parse_name_value(item, "--surface-edge-length-mm");
      options.surface_edge_length[name] = mm * common::units::mm;
    }
    if (app.count("--unit")) options.unit = common::parse_length_unit(unit);
    if (app.count("--max-cast-distance-mm")) options.max_cast_distance = max_cast_mm * common::units::mm;
    if (app.count("--remesh-iterations")) options.remesh_iterations = iterations;
    if (app.count("--min-thickness-mm")) options.min_thickness = min_thickness_mm * common::units::mm;
    if (app.count("--max-triangles")) options.max_triangles = max_triangles;
    std::ostringstream echo;
    echo << "model: " << model_dir << "\nscene: " << (scene_path.empty() ? "none" : scene_path)
         << "\nedge_length_mm: " << common::written_value(options.edge_length, common::Unit::kMillimetre)
         << "\nunit: " << common::unit_name(options.unit)
         << "\nmax_cast_distance_mm: " << common::written_value(options.max_cast_distance, common::Unit::kMillimetre)
         << "\nremesh_iterations: " << options.remesh_iterations
         << "\nmin_thickness_mm: " << common::written_value(options.min_thickness, common::Unit::kMillimetre)
         << "\nmax_triangles: " << options.max_triangles << "\n";
    for (const auto& [name, length] : options.surface_edge_length)
      echo << "surface_edge_length_mm: " << name << "=" << common::written_value(length, common::Unit::kMillimetre)
           << "\n";
    common::log_info("options:\n" + echo.str() + "-> " + out);

    const pipelines::ModelFiles files = pipelines::find_model_files(model_dir);
    const pipelines::PreparedModel model = pipelines::prepare_model(files, options);
    if (!model.manifest.empty()) common::log_info("manifest " + model.manifest);
    for (const auto& b : model.bones) {
      for (const auto& r : b.repairs) common::log_warn(b.source_file + ": repaired: " + r);
      common::log_info("bone " + b.name + ": " + std::to_string(b.mesh.num_vertices()) + " vertices, " +
                       std::to_string(b.mesh.num_triangles()) + " triangles" + (b.closed ? ", closed" : ", open") +
                       ", unit " + common::unit_name(b.unit) + (b.body.empty() ? "" : ", frame of body " + b.body));
    }
    for (const auto& s : model.surfaces) {
      for (const auto& r : s.repairs) common::log_warn(s.source_file + ": repaired: " + r);
      char line[600];
      std::snprintf(line, sizeof line,
                    "cartilage %s on %s: %d -> %d triangles (edge %.2f mm, outline %s), %d quads, %zu periphery "
                    "nodes, thickness %.2f..%.2f mm (area mean %.3f, rim mean %.3f); vertices: %d ray, %d inside "
                    "bone, %d closest point, %d raised to the floor; elements: angles >= %.1f deg, admissible "
                    "shell thickness >= %.2f mm",
                    s.name.c_str(), s.bone.c_str(), s.stats.input_triangles, s.stats.triangles,
                    s.stats.mean_edge_length * 1e3, s.stats.outline_resampled ? "resampled" : "kept", s.stats.quads,
                    s.periphery_nodes.size(), s.stats.thickness_min * 1e3, s.stats.thickness_max * 1e3,
                    s.stats.thickness_mean * 1e3, s.stats.thickness_rim_mean * 1e3, s.stats.vertices_ray,
                    s.stats.vertices_inside_bone, s.stats.vertices_closest_point, s.stats.vertices_floored,
                    std::min(s.stats.triangle_quality.min_angle, s.stats.quad_quality.min_angle) * 180.0 / M_PI,
                    s.stats.quad_quality.min_shell_thickness * 1e3);
      common::log_info(line);
    }
    for (const auto& w : model.warnings) common::log_warn(w);
    const common::RunMetadata meta =
        common::collect_run_metadata("arthrosim-prepare", argc, argv, "", echo.str());
    pipelines::write_prepared_model(model, options, meta, out);
    common::log_info("wrote " + out + " and " + pipelines::xdmf_path_for(out));
  } catch (const std::exception& e) {
    common::log_error(e.what());
    return 1;
  }
  return 0;
}
