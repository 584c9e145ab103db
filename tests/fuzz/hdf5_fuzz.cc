// libFuzzer target: common::H5File (the layer every HDF5 reader of arthrosim
// goes through: kinematics, prepared model, surface output) on well-formed
// files of hostile content. The input is an h5spec (h5spec.h): it is turned
// into an HDF5 file in a scratch folder, which is then opened read-only and
// read whole (h5walk.h).
#include "fuzz_support.h"
#include "h5spec.h"
#include "h5walk.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arthrosim;
  const std::filesystem::path path = fuzz::scratch_dir() / "input.h5";
  if (!fuzz::H5Spec(data, size).write(path.string())) return 0;
  return fuzz::run_reader([&] {
    const common::H5File f(path.string(), common::H5File::Mode::kRead);
    int budget = 64;
    fuzz::walk(f, "/", &budget);
  });
}
