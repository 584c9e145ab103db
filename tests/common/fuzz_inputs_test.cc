// Inputs found by fuzzing the common readers (tests/fuzz, docs/testing.md):
// each test is the minimised input of one defect, so that the normal suite
// keeps it fixed; the same input is in tests/fuzz/corpus/<target>/regression-*.
#include <gtest/gtest.h>

#include <ctime>
#include <cstdint>
#include <functional>
#include <limits>
#include <sstream>
#include <string>

#include "common/error.h"
#include "common/hdf5.h"
#include "common/mesh_io.h"
#include "common/storage.h"

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

// A "label line" of 100,000 words: the duplicate-label check compared every
// pair (5e9 string comparisons: 14 s of CPU on this machine, 200,000 labels 35 s).
// Now hashed: linear. CPU time (std::clock), not wall time, so a loaded
// machine does not make it fail; the bound is 20 times the hashed check's
// time under ASan.
TEST(StorageFuzz, ManyColumnLabelsAreCheckedInLinearTime) {
  std::string text = "endheader\ntime";
  for (int i = 1; i < 100000; ++i) text += "\tc" + std::to_string(i);
  text += "\n0";
  for (int i = 1; i < 100000; ++i) text += " 1";
  text += "\n";
  std::istringstream in(text);
  const std::clock_t c0 = std::clock();
  const common::StorageTable t = common::parse_storage(in, "wide.sto");
  const double cpu_s = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
  EXPECT_EQ(t.num_columns(), 100000);
  EXPECT_LT(cpu_s, 2.0);
  // The duplicate is still named with both columns.
  std::istringstream dup("endheader\ntime\ta\tb\ta\n");
  try {
    common::parse_storage(dup, "dup.sto");
    FAIL() << "expected an InputError";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("dup.sto:2: error: duplicate column label 'a' (columns 2 and 4)"),
              std::string::npos)
        << e.what();
  }
}

namespace {

std::string read_error(const std::function<void()>& read) {
  try {
    read();
  } catch (const common::InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

// tests/common/data/hdf5_sparse.h5 (tests/fuzz/make_corpus.py; fuzz_hdf5
// corpus entry types_and_links.h5spec declares the same): datasets of 2^40,
// 2^31 x 3 and 2^30 elements that were never written. HDF5 reads them as
// fill values, so the readers allocated 8 TB, 24 GB and 8 GB (std::bad_alloc
// or the OOM killer, not an InputError). Now refused naming the dataset;
// stored datasets, compressed or not, read as before.
TEST(Hdf5Fuzz, DatasetsTheFileDoesNotStoreAreInputErrors) {
  const std::string path = ARTHROSIM_SOURCE_DIR "/tests/common/data/hdf5_sparse.h5";
  const common::H5File f(path, common::H5File::Mode::kRead);
  const std::string vector = read_error([&] { f.read_vector("sparse_vector"); });
  EXPECT_NE(vector.find("dataset /sparse_vector: dims (1099511627776) need 8796093022208 bytes, but the file "
                        "stores 0 (a truncated or never written dataset)"),
            std::string::npos)
      << vector;
  const std::string matrix = read_error([&] { f.read_matrix_int("sparse_matrix"); });
  EXPECT_NE(matrix.find("dataset /sparse_matrix: dims (2147483648, 3) need 25769803776 bytes"), std::string::npos)
      << matrix;
  const std::string strings = read_error([&] { f.read_strings("sparse_strings"); });
  EXPECT_NE(strings.find("dataset /sparse_strings: dims (1073741824) need"), std::string::npos) << strings;
  EXPECT_EQ(f.read_vector("compressed"), Eigen::VectorXd::Zero(1000));
  EXPECT_EQ(f.read_vector("written"), Eigen::Vector3d(1, 2, 3));
}

// fuzz_hdf5, regression-empty-wide-matrix.h5spec: a never-written dataset of
// dims 0 x 2^35 stores nothing and passed the storage check, but building the
// 0-row matrix walked its 2^35 columns (over 10 s under ASan) and any caller
// looping over the columns with an int index would overflow. An empty
// dataset whose other dimension exceeds the int range is now refused; one
// within it reads as an empty matrix of its dims without touching a column.
TEST(Hdf5Fuzz, EmptyDatasetWithAHugeDimensionIsAnInputError) {
  const std::string path = ::testing::TempDir() + "hdf5_empty_wide.h5";
  {
    common::H5File f(path, common::H5File::Mode::kTruncate);
    f.write("wide", Eigen::MatrixXd(0, std::int64_t{1} << 35));
    f.write("widest_readable", Eigen::MatrixXi(0, std::numeric_limits<std::int32_t>::max()));
  }
  const common::H5File f(path, common::H5File::Mode::kRead);
  const std::clock_t c0 = std::clock();
  const std::string wide = read_error([&] { f.read_matrix("wide"); });
  EXPECT_NE(wide.find("dataset /wide: dims (0, 34359738368) have a dimension over 2147483647, the largest the "
                      "readers index"),
            std::string::npos)
      << wide;
  const Eigen::MatrixXi m = f.read_matrix_int("widest_readable");
  // CPU time, not wall time. Both reads take about 1 ms; the bound matters in
  // the sanitizer suite (-O1 with coverage), where walking the 2^31 - 1
  // empty columns took 27 s (at -O2 the compiler drops that loop).
  EXPECT_LT(static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC, 1.0);
  EXPECT_EQ(m.rows(), 0);
  EXPECT_EQ(m.cols(), std::numeric_limits<std::int32_t>::max());
}
