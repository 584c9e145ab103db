// libFuzzer target: common::parse_stl (then validate + repair, mesh_fuzz.h).
#include "mesh_fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return arthrosim::fuzz::fuzz_mesh(data, size, [](const std::string& s) {
    return arthrosim::common::parse_stl(s, "fuzz.stl");
  });
}
