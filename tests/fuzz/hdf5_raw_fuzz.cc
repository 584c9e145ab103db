// libFuzzer target: common::H5File on arbitrary bytes (a damaged file). The
// input is written to a scratch file, opened read-only and read whole
// (h5walk.h). Not run by CI (scripts/sanitize.sh skips *_raw targets): it
// reaches libhdf5's own parser first, whose defects on corrupt files (leaks,
// a hang in the global heap, huge allocations) arthrosim cannot fix
// (docs/testing.md, "Known library defects"). Run it by hand with
// ASAN_OPTIONS=allocator_may_return_null=1 (a failed malloc is what HDF5
// expects on a huge size).
#include "fuzz_support.h"
#include "h5walk.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arthrosim;
  const std::filesystem::path path = fuzz::scratch_dir() / "input.h5";
  fuzz::write_file(path, fuzz::as_string(data, size));
  return fuzz::run_reader([&] {
    const common::H5File f(path.string(), common::H5File::Mode::kRead);
    int budget = 64;
    fuzz::walk(f, "/", &budget);
  });
}
