// Inputs found by fuzzing the common readers (tests/fuzz, docs/testing.md):
// each test is the minimised input of one defect, so that the normal suite
// keeps it fixed; the same input is in tests/fuzz/corpus/<target>/regression-*.
#include <gtest/gtest.h>

#include <string>

#include "common/error.h"
#include "common/mesh_io.h"

namespace common = arthrosim::common;

// fuzz_mesh_ply, regression-element-without-properties.ply: an element with
// no properties holds no data, but the reader looped over its count, so
// "element junk 999999999999" kept it busy for hours (ASCII and binary).
TEST(PlyFuzz, ElementWithoutPropertiesAndAHugeCountIsSkipped) {
  const std::string header_tail =
      " 1.0\nelement junk 999999999999\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  const std::string ascii = "ply\nformat ascii" + header_tail + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  std::string binary = "ply\nformat binary_little_endian" + header_tail;
  for (float v : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f}) binary.append(reinterpret_cast<const char*>(&v), 4);
  binary += '\3';
  for (int i : {0, 1, 2}) binary.append(reinterpret_cast<const char*>(&i), 4);
  for (const std::string& content : {ascii, binary}) {
    const common::TriangleMesh m = common::parse_ply(content, "junk.ply");
    EXPECT_EQ(m.num_vertices(), 3);
    ASSERT_EQ(m.num_triangles(), 1);
    EXPECT_DOUBLE_EQ(m.V(1, 0), 1e-3);  // mm -> m
  }
}
