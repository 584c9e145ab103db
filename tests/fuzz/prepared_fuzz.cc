// libFuzzer target: the prepared-model reader of the COMAK stage
// (musculoskeletal::use_prepared_surfaces), which replaces a model's contact
// surfaces by those of a prepared-model HDF5 file (docs/prepared_model.md).
// The input is an h5spec (h5spec.h), turned into an HDF5 file in a scratch
// folder; the corpus holds valid prepared files for the model below.
// The model is tests/fuzz/knee_small.urdf (two contact surfaces of the
// bundled coarse knee), read afresh per input (the reader replaces its
// surfaces).
#include <fstream>
#include <sstream>

#include "fuzz_support.h"
#include "h5spec.h"
#include "musculoskeletal/model_io.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arthrosim;
  static const std::string model_text = [] {
    std::ifstream in(std::string(ARTHROSIM_SOURCE_DIR) + "/tests/fuzz/knee_small.urdf");
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }();
  static const std::string base = std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric";
  const std::filesystem::path path = fuzz::scratch_dir() / "prepared.h5";
  if (!fuzz::H5Spec(data, size).write(path.string())) return 0;
  musculoskeletal::Model model = musculoskeletal::parse_model(model_text, "knee_small.urdf", base);
  return fuzz::run_reader([&] {
    const musculoskeletal::PreparedSurfacesReport report = musculoskeletal::use_prepared_surfaces(model, path.string());
    (void)report.lines.size();
  });
}
