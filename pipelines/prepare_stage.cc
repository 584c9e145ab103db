// The prepare stage's scene block and descriptor (the stage's algorithms are
// in prepare.cc).
#include "common/error.h"
#include "common/mesh_io.h"
#include "pipelines/prepare.h"
#include "pipelines/stages.h"

namespace arthrosim::pipelines {

void PrepareOptions::declare(common::OptionVisitor& v) {
  using common::Unit;
  v.number("edge_length_mm", edge_length, Unit::kMillimetre, {0.2, 20},
           "target edge length of the remeshed cartilage surfaces");
  v.named_numbers("surface_edge_length_mm", surface_edge_length, Unit::kMillimetre, {0.2, 20},
                  "per-surface target edge lengths in place of edge_length_mm, items 'name=mm' (e.g. [femur=3.7])");
  v.choice("mesh_unit", unit,
           {{"mm", common::LengthUnit::kMillimetre},
            {"cm", common::LengthUnit::kCentimetre},
            {"m", common::LengthUnit::kMetre}},
           "length unit of the model's mesh files (STL carries none)");
  v.number("max_cast_distance_mm", max_cast_distance, Unit::kMillimetre, {1, 50},
           "longest ray cast from cartilage to bone when measuring thickness");
  v.integer("remesh_iterations", remesh_iterations, {1, 20}, "isotropic remeshing iterations");
  v.number("min_thickness_mm", min_thickness, Unit::kMillimetre, {0, 2},
           "thickness floor: measured cartilage thickness below it (a rim on the bone, a point inside the bone) is "
           "raised to it and counted");
  v.number("max_triangles", max_triangles, Unit::kNone, {100, 1e9},
           "refuse a cartilage surface whose remesh is estimated to exceed this many triangles");
}

PrepareOptions prepare_from_scene(const common::Scene& scene) {
  return common::read_options<PrepareOptions>(scene.block("prepare"));
}

StageDescriptor prepare_stage_descriptor() {
  StageDescriptor d;
  d.name = "prepare";
  d.executable = "arthrosim-prepare";
  d.summary = "validated, remeshed cartilage and bone surfaces, thickness, quad articular meshes";
  d.block = block_schema<PrepareOptions>("prepare", "options of the prepare stage");
  d.outputs = {"prepared_model"};
  d.runs = [](const common::Scene& scene, const std::filesystem::path& out) {
    StageStep s;
    s.name = "prepare";
    s.executable = "arthrosim-prepare";
    s.provides = {"prepared_model"};
    s.origin = "the prepare stage";
    const SceneInputs in = scene_inputs(scene);
    s.inputs.emplace_back("model", in.model);
    // A manifest's meshes may live outside the model folder (or the model is
    // the manifest file itself). Unreadable: the stage fails naming why.
    try {
      const ModelFiles files = find_model_files(in.model.string());
      std::vector<std::pair<std::string, std::filesystem::path>> refs;
      for (const auto& [name, file] : files.bones) refs.emplace_back("model mesh " + name + "_bone", file);
      for (const auto& [name, file] : files.cartilage) refs.emplace_back("model mesh " + name + "_cartilage", file);
      add_referenced_inputs(s, refs);
    } catch (const common::InputError&) {
    }
    const common::OptionBlock& block = scene.block("prepare");
    s.options = block.canonical();
    add_path_inputs(block, s);
    const std::filesystem::path prepared = out / "prepared.h5";
    // arthrosim-prepare writes prepared.xdmf next to prepared.h5.
    s.outputs = {prepared, out / "prepared.xdmf"};
    s.arguments = {"--model", in.model.string(), "--scene", scene.file.string(), "--out", prepared.string()};
    return std::vector<StageStep>{s};
  };
  return d;
}

}  // namespace arthrosim::pipelines
