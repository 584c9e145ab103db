#pragma once
// Mesh reader targets (mesh_{stl,obj,ply,vtk}_fuzz.cc): parse the input as
// the format, then run what every consumer of a user's mesh runs next
// (arthrosim-prepare): validate() and repair().
//
// Input bound (documented in docs/testing.md): repair() is skipped for meshes
// with a coordinate beyond 100 m, because common/mesh_validation.cc's
// merge_vertices overflows a signed 64-bit cell index there (issue 30 item 4,
// owned by the `meshes` developer; reproducer in tests/fuzz/known/). Remove
// the bound when that is fixed.
#include <cstddef>
#include <cstdint>
#include <string>

#include "common/mesh_io.h"
#include "common/mesh_validation.h"
#include "fuzz_support.h"

namespace arthrosim::fuzz {

constexpr double kRepairCoordinateBound_m = 100.0;

template <class Parse>
int fuzz_mesh(const std::uint8_t* data, std::size_t size, Parse parse) {
  return run_reader([&] {
    const common::TriangleMesh mesh = parse(as_string(data, size));
    const common::ValidationReport report = common::validate(mesh);
    (void)report.summary();
    if (mesh.V.size() > 0 && mesh.V.cwiseAbs().maxCoeff() > kRepairCoordinateBound_m) return;
    const common::RepairResult repaired = common::repair(mesh);
    (void)repaired.report.summary();
  });
}

}  // namespace arthrosim::fuzz
