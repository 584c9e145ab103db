// libFuzzer target: the scene reader as the runner and stages call it
// (pipelines::parse_scene: yaml-cpp, the schema the stages declare, every
// stage's own check), then what the runner reads from it: the top-level
// inputs and the canonical text of every block and block instance (what it
// hashes). The scene "lives" in data/scenes/ so relative paths resolve to
// bundled data.
#include "fuzz_support.h"
#include "pipelines/stages.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arthrosim;
  static const std::filesystem::path file = std::filesystem::path(ARTHROSIM_SOURCE_DIR) / "data/scenes/fuzz.yaml";
  return fuzz::run_reader([&] {
    const common::Scene scene = pipelines::parse_scene(fuzz::as_string(data, size), file);
    (void)pipelines::scene_inputs(scene);
    (void)scene.top.canonical_text();
    for (const auto& [name, block] : scene.blocks) (void)block.canonical_text();
    for (const auto& [name, instances] : scene.block_instances)
      for (const auto& instance : instances) (void)instance.options.canonical_text();
  });
}
