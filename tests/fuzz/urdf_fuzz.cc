// libFuzzer target: the model file reader (musculoskeletal::parse_model:
// urdfdom for the tree, tinyxml2 for the <arthrosim:...> extensions). Mesh and
// thickness paths resolve against the bundled knee's folder, so a corpus
// entry may name its small meshes (coarse/patella_cartilage.stl, ...).
#include "fuzz_support.h"
#include "musculoskeletal/model_io.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arthrosim;
  static const std::string base = std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric";
  return fuzz::run_reader([&] {
    const musculoskeletal::Model m = musculoskeletal::parse_model(fuzz::as_string(data, size), "fuzz.urdf", base);
    (void)m.num_coordinates();
  });
}
