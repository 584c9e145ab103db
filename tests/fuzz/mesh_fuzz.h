#pragma once
// Mesh reader targets (mesh_{stl,obj,ply,vtk}_fuzz.cc): parse the input as
// the format, then run what every consumer of a user's mesh runs next
// (arthrosim-prepare): validate() and repair().
// Any finite coordinate is repaired (the merge_vertices overflow at ~1e5 mm
// is fixed: MeshValidation.RepairMergesVerticesFarFromTheOrigin).
#include <cstddef>
#include <cstdint>
#include <string>

#include "common/mesh_io.h"
#include "common/mesh_validation.h"
#include "fuzz_support.h"

namespace arthrosim::fuzz {

template <class Parse>
int fuzz_mesh(const std::uint8_t* data, std::size_t size, Parse parse) {
  return run_reader([&] {
    const common::TriangleMesh mesh = parse(as_string(data, size));
    const common::ValidationReport report = common::validate(mesh);
    (void)report.summary();
    const common::RepairResult repaired = common::repair(mesh);
    (void)repaired.report.summary();
  });
}

}  // namespace arthrosim::fuzz
