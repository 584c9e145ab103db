// libFuzzer target: common::parse_vtk with its point/cell fields (then
// validate + repair, mesh_fuzz.h).
#include <vector>

#include "mesh_fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return arthrosim::fuzz::fuzz_mesh(data, size, [](const std::string& s) {
    std::vector<arthrosim::common::VtkField> fields;
    return arthrosim::common::parse_vtk(s, "fuzz.vtk", {}, &fields);
  });
}
