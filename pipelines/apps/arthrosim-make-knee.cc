// arthrosim-make-knee: generates the bundled parametric right knee (bones,
// cartilage with analytic thickness, landmarks) at a requested resolution.
// Geometry, frame and sources: docs/knee_geometry.md.
#include <chrono>
#include <cstdio>
#include <exception>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>

#include "common/remesh.h"
#include "pipelines/knee_generator.h"

using namespace arthrosim;
using pipelines::KneeBone;
using pipelines::KneeCartilage;

int main(int argc, char** argv) {
  CLI::App app{
      "arthrosim-make-knee: deterministic parametric right knee at full extension (adult female, 1.65 m).\n"
      "Writes femur/tibia/patella bones (closed STL, mm), four cartilage surfaces (open STL, mm, normals\n"
      "towards the joint space) with their analytic thickness (<name>_thickness.csv) and landmarks.yaml\n"
      "(metres, model frame: origin mid flexion axis, X anterior, Y superior, Z lateral). See\n"
      "docs/knee_geometry.md."};
  double edge_mm = 2.0, grid_mm = 0.0, overlap_mm = 0.25;
  int iterations = 5;
  std::string out;
  app.add_option("--edge-length-mm", edge_mm, "target edge length of every mesh [mm], 0.5..6")
      ->capture_default_str();
  app.add_option("--grid-spacing-mm", grid_mm,
                 "implicit sampling grid [mm], 0 = clamp(edge/2.5, 0.4, 1.0)")
      ->capture_default_str();
  app.add_option("--overlap-mm", overlap_mm, "designed cartilage overlap at first contact [mm], 0..0.5")
      ->capture_default_str();
  app.add_option("--remesh-iterations", iterations, "isotropic remeshing iterations, 1..20")->capture_default_str();
  app.add_option("--out", out, "output directory (created)")->required();
  app.footer(
      "Sample runs:\n"
      "  arthrosim-make-knee --edge-length-mm 3 --out data/models/knee_parametric/coarse\n"
      "  arthrosim-make-knee --edge-length-mm 2 --out data/models/knee_parametric/medium\n"
      "On demand (benchmarks, about a minute):\n"
      "  arthrosim-make-knee --edge-length-mm 1 --out knee_fine\n");
  CLI11_PARSE(app, argc, argv);

  try {
    pipelines::KneeGeneratorOptions options;
    options.edge_length = edge_mm * 1e-3;
    options.grid_spacing = grid_mm * 1e-3;
    options.remesh_iterations = iterations;
    std::printf("arthrosim-make-knee: edge %.3g mm, grid %s mm, overlap %.3g mm, %d remesh iterations -> %s\n",
                edge_mm, grid_mm > 0 ? std::to_string(grid_mm).c_str() : "auto", overlap_mm, iterations,
                out.c_str());
    const auto t0 = std::chrono::steady_clock::now();
    const pipelines::ParametricKnee knee(overlap_mm * 1e-3);
    const pipelines::KneeGeometry g = knee.generate(options);
    pipelines::write_knee_geometry(g, options, out);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    for (KneeBone b : {KneeBone::kFemur, KneeBone::kTibia, KneeBone::kPatella}) {
      const auto st = common::edge_length_statistics(g.bone(b));
      std::printf("  %-24s %6d vertices %6d triangles  edge mean %.2f mm\n", pipelines::bone_file_stem(b).c_str(),
                  g.bone(b).num_vertices(), g.bone(b).num_triangles(), st.mean_edge_length * 1e3);
    }
    for (const auto& c : g.cartilage) {
      const auto st = common::edge_length_statistics(c.mesh);
      std::printf("  %-24s %6d vertices %6d triangles  edge mean %.2f mm  thickness %.2f..%.2f mm\n",
                  pipelines::cartilage_file_stem(c.which).c_str(), c.mesh.num_vertices(), c.mesh.num_triangles(),
                  st.mean_edge_length * 1e3, c.thickness.minCoeff() * 1e3, c.thickness.maxCoeff() * 1e3);
    }
    const auto& fem = g.patch(KneeCartilage::kFemur).mesh;
    for (KneeCartilage c : {KneeCartilage::kTibiaMedial, KneeCartilage::kTibiaLateral, KneeCartilage::kPatella}) {
      const auto o = pipelines::surface_overlap(g.patch(c).mesh, fem);
      std::printf("  overlap %s vs femur_cartilage: max %.3f mm (%d vertices)\n",
                  pipelines::cartilage_file_stem(c).c_str(), o.max_depth * 1e3, o.penetrating_vertices);
    }
    std::printf("done in %.1f s\n", seconds);
  } catch (const std::exception& e) {
    std::cerr << e.what() << "\n";
    return 1;
  }
  return 0;
}
