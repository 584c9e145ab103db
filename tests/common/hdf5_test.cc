// Tests of the HDF5 layer: round trips of every supported type and rank,
// attributes, error messages, determinism, and the "killed mid-run" case: a
// child process appending frames is SIGKILLed after it reported N frames; the
// parent must then read at least N complete, correct frames.
#include "common/hdf5.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <iostream>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <thread>

#include "common/error.h"

namespace arthrosim::common {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

fs::path temp_dir() {
  fs::path d = fs::path(ARTHROSIM_BINARY_DIR) / "test_output" / "hdf5_test";
  fs::create_directories(d);
  return d;
}

// Value stored at (frame, i, j) by the kill-test child: exactly representable
// and distinct per element, so a torn or zero-filled frame is detected.
double frame_value(std::int64_t frame, int i, int j) { return 1000.0 * static_cast<double>(frame) + 10.0 * i + j + 0.25; }
constexpr int kKillRows = 50;
constexpr int kKillCols = 3;

// ---- child mode -------------------------------------------------------------
// When the test binary is started with ARTHROSIM_HDF5_KILL_CHILD=<file> it
// does not run tests: this static initializer (which runs before gtest's
// main) appends frames forever, reporting each completed frame index on the
// file descriptor ARTHROSIM_HDF5_KILL_FD, until it is killed.
struct KillChildMode {
  KillChildMode() {
    const char* file = std::getenv("ARTHROSIM_HDF5_KILL_CHILD");
    const char* fd_text = std::getenv("ARTHROSIM_HDF5_KILL_FD");
    if (file == nullptr || fd_text == nullptr) return;
    const int fd = std::atoi(fd_text);
    const char* sleep_text = std::getenv("ARTHROSIM_HDF5_KILL_SLEEP_US");
    const int sleep_us = sleep_text ? std::atoi(sleep_text) : 0;
    const char* chunk_text = std::getenv("ARTHROSIM_HDF5_KILL_CHUNK");
    const int frames_per_chunk = chunk_text ? std::atoi(chunk_text) : 4;
    const char* expected_text = std::getenv("ARTHROSIM_HDF5_KILL_EXPECTED");
    const int expected = expected_text ? std::atoi(expected_text) : 0;
    try {
      H5File f(file, H5File::Mode::kTruncate);
      f.write("static/before", Eigen::VectorXd::LinSpaced(5, 0.0, 1.0));
      auto app = f.appender("frames/points", {kKillRows, kKillCols}, {expected, frames_per_chunk});
      auto times = f.appender("frames/time", {}, {expected, 0});
      auto ids = f.appender_int("frames/ids", {kKillRows}, {expected, 0});
      for (std::int64_t k = 0; k < 1000000; ++k) {
        Eigen::MatrixXd m(kKillRows, kKillCols);
        Eigen::VectorXi id(kKillRows);
        for (int i = 0; i < kKillRows; ++i) {
          id(i) = static_cast<int>(k) * 100 + i;
          for (int j = 0; j < kKillCols; ++j) m(i, j) = frame_value(k, i, j);
        }
        // Order: ids, time, points; a frame counts as complete when all
        // three appends returned.
        ids.append(id);
        times.append(0.01 * static_cast<double>(k));
        app.append(m);
        const std::int64_t done = k + 1;
        if (write(fd, &done, sizeof done) != static_cast<ssize_t>(sizeof done)) _exit(3);
        if (sleep_us > 0) usleep(sleep_us);
      }
    } catch (const std::exception& e) {
      fprintf(stderr, "kill child: %s\n", e.what());
      _exit(2);
    }
    _exit(0);
  }
};
const KillChildMode kill_child_mode;

// ---- round trips --------------------------------------------------------------
TEST(Hdf5, RoundTripEveryTypeAndRank) {
  const fs::path p = temp_dir() / "roundtrip.h5";
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> u(-1e3, 1e3);
  Eigen::MatrixXd md(7, 3);
  for (int i = 0; i < md.size(); ++i) md(i) = u(rng);
  md(0, 0) = -0.0;
  md(1, 1) = 1e-310;  // subnormal survives bit-exactly
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> md_rm = md;
  Eigen::VectorXd vd = Eigen::VectorXd::LinSpaced(11, -2.0, 3.0);
  Eigen::MatrixXi mi(4, 5);
  for (int i = 0; i < mi.size(); ++i) mi(i) = static_cast<int>(rng() % 2000) - 1000;
  Eigen::VectorXi vi(6);
  vi << 0, -1, 2147483647, -2147483647 - 1, 5, 6;
  Eigen::RowVectorXd row = Eigen::RowVectorXd::LinSpaced(4, 1.0, 4.0);
  std::vector<std::string> strings{"femur", "tibia medial", "", "ünïcode µm", std::string(300, 'x')};
  Tensor3d t3;
  t3.dims = {2, 3, 4};
  for (int i = 0; i < 24; ++i) t3.data.push_back(0.5 * i - 3.0);
  std::vector<int> t3i(2 * 1 * 5);
  for (int i = 0; i < 10; ++i) t3i[i] = i * i;
  {
    H5File f(p.string(), H5File::Mode::kTruncate);
    f.write("/m/double", md);
    f.write("m/double_rowmajor", md_rm);
    f.write("v/double", vd);
    f.write("deep/a/b/c/int_matrix", mi);
    f.write("v/int", vi);
    f.write("v/row", row);
    f.write("s/names", strings);
    f.write("s/empty", std::vector<std::string>{});
    f.write_tensor3("t/d", t3);
    f.write_tensor3("t/i", {2, 1, 5}, t3i);
    f.write("std/vec", std::vector<double>{1.5, 2.5});
    f.write("std/ivec", std::vector<int>{7, 8, 9});
    f.write("m/empty", Eigen::MatrixXd(0, 3));
  }
  H5File f(p.string(), H5File::Mode::kRead);
  const Eigen::MatrixXd md2 = f.read_matrix("m/double");
  ASSERT_EQ(md2.rows(), 7);
  ASSERT_EQ(md2.cols(), 3);
  // Bit-exact: memcmp, not a tolerance (no conversion happens).
  EXPECT_EQ(0, std::memcmp(md2.data(), md.data(), sizeof(double) * md.size()));
  EXPECT_TRUE(std::signbit(md2(0, 0)));
  EXPECT_EQ(f.read_matrix("m/double_rowmajor"), md);  // storage order does not matter
  EXPECT_EQ(f.dims("m/double"), (std::vector<std::int64_t>{7, 3}));
  EXPECT_EQ(f.read_vector("v/double"), vd);
  EXPECT_EQ(f.dims("v/double"), (std::vector<std::int64_t>{11}));
  EXPECT_EQ(f.read_matrix_int("deep/a/b/c/int_matrix"), mi);
  EXPECT_EQ(f.read_vector_int("v/int"), vi);
  EXPECT_EQ(f.read_vector("v/row"), row.transpose());
  EXPECT_EQ(f.read_strings("s/names"), strings);
  EXPECT_TRUE(f.read_strings("s/empty").empty());
  const Tensor3d t3r = f.read_tensor3("t/d");
  EXPECT_EQ(t3r.dims, t3.dims);
  EXPECT_EQ(t3r.data, t3.data);
  EXPECT_EQ(t3r(1, 2, 3), 0.5 * 23 - 3.0);
  const Tensor3i t3ir = f.read_tensor3_int("t/i");
  EXPECT_EQ(t3ir.dims, (std::array<std::int64_t, 3>{2, 1, 5}));
  EXPECT_EQ(t3ir.data, t3i);
  EXPECT_EQ(f.read_vector("std/vec"), Eigen::Vector2d(1.5, 2.5));
  EXPECT_EQ(f.read_vector_int("std/ivec"), Eigen::Vector3i(7, 8, 9));
  EXPECT_EQ(f.read_matrix("m/empty").rows(), 0);
  EXPECT_EQ(f.read_matrix("m/empty").cols(), 3);
  EXPECT_EQ(f.type("v/int"), H5Type::kInt);
  EXPECT_EQ(f.type("s/names"), H5Type::kString);
  EXPECT_EQ(f.type("t/d"), H5Type::kDouble);
  // Structure queries.
  EXPECT_TRUE(f.exists("/deep/a/b"));
  EXPECT_TRUE(f.is_group("deep/a/b"));
  EXPECT_TRUE(f.is_dataset("deep/a/b/c/int_matrix"));
  EXPECT_FALSE(f.exists("deep/x/y"));
  EXPECT_FALSE(f.exists("v/double/inside"));  // a dataset has no members
  EXPECT_EQ(f.list("/"), (std::vector<std::string>{"deep", "m", "s", "std", "t", "v"}));
  EXPECT_EQ(f.list("v"), (std::vector<std::string>{"double", "int", "row"}));
}

// Files written by other tools: tests/common/data/h5py_interop.h5 was made by
// h5py 3.7 (Debian 12) with
//   f['fixed'] = np.array([b'femur', b'tibia', b'patellar'], dtype='S8')
//   f['f32'] = np.arange(6, dtype=np.float32).reshape(2, 3)
//   f['i64'] = np.arange(4, dtype=np.int64)
//   f.attrs['fixed_attr'] = np.bytes_('hello')   # fixed length 5, NULLPAD
//   f.attrs['f32'] = np.float32(0.5); f.attrs['i32'] = np.int32(7)
// Fixed-length strings that fill their whole length ('patellar' in S8,
// 'hello' in 5 bytes) must come back whole; float32/int64 convert.
TEST(Hdf5, ReadsFilesWrittenByH5py) {
  H5File f(std::string(ARTHROSIM_SOURCE_DIR) + "/tests/common/data/h5py_interop.h5", H5File::Mode::kRead);
  EXPECT_EQ(f.read_strings("fixed"), (std::vector<std::string>{"femur", "tibia", "patellar"}));
  Eigen::MatrixXd expected(2, 3);
  expected << 0, 1, 2, 3, 4, 5;
  EXPECT_EQ(f.read_matrix("f32"), expected);
  EXPECT_EQ(f.read_vector_int("i64"), Eigen::Vector4i(0, 1, 2, 3));
  EXPECT_EQ(f.attribute_string("/", "fixed_attr"), "hello");
  EXPECT_EQ(f.attribute_double("/", "f32"), 0.5);
  EXPECT_EQ(f.attribute_int("/", "i32"), 7);
}

TEST(Hdf5, OverwriteReplacesDataset) {
  const fs::path p = temp_dir() / "overwrite.h5";
  H5File f(p.string(), H5File::Mode::kTruncate);
  f.write("a", Eigen::MatrixXd::Ones(3, 3));
  f.write("a", Eigen::MatrixXd::Zero(3, 3));  // same shape: in place
  EXPECT_EQ(f.read_matrix("a"), Eigen::MatrixXd::Zero(3, 3));
  f.write("a", Eigen::VectorXi::Constant(4, 9));  // other shape and type
  EXPECT_EQ(f.read_vector_int("a"), Eigen::VectorXi::Constant(4, 9));
  f.write("a", std::vector<std::string>{"x"});
  EXPECT_EQ(f.read_strings("a"), std::vector<std::string>{"x"});
  f.remove("a");
  EXPECT_FALSE(f.exists("a"));
  f.write("g/d", Eigen::VectorXd::Ones(2));
  EXPECT_THROW(f.write("g", Eigen::VectorXd::Ones(2)), InputError);  // g is a group
}

TEST(Hdf5, ReadWriteModeKeepsContentAndCreatesMissingFile) {
  const fs::path p = temp_dir() / "rw.h5";
  fs::remove(p);
  {
    H5File f(p.string(), H5File::Mode::kReadWrite);  // creates
    f.write("a", Eigen::VectorXd::Constant(2, 1.0));
  }
  {
    H5File f(p.string(), H5File::Mode::kReadWrite);  // reopens, keeps a
    f.write("b", Eigen::VectorXd::Constant(2, 2.0));
  }
  H5File f(p.string(), H5File::Mode::kRead);
  EXPECT_EQ(f.read_vector("a"), Eigen::VectorXd::Constant(2, 1.0));
  EXPECT_EQ(f.read_vector("b"), Eigen::VectorXd::Constant(2, 2.0));
  EXPECT_FALSE(f.writable());
  try {
    f.write("c", Eigen::VectorXd::Ones(1));
    FAIL() << "write to a read-only file did not throw";
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), HasSubstr("read-only"));
  }
}

TEST(Hdf5, AttributesRoundTrip) {
  const fs::path p = temp_dir() / "attributes.h5";
  {
    H5File f(p.string(), H5File::Mode::kTruncate);
    f.write("g/d", Eigen::VectorXd::Ones(3));
    f.set_attribute("/", "version", "0.1.0");
    f.set_attribute("/", "long_text", std::string(100000, 'y'));  // > 64 KiB header limit
    f.set_attribute("/", "pi", 3.141592653589793);
    f.set_attribute("/", "count", std::int64_t{1} << 40);
    f.set_attribute("g", "units", "m");
    f.set_attribute("g/d", "frames", 3);
    f.set_attribute("g/d", "frames", 4);  // replace
  }
  H5File f(p.string(), H5File::Mode::kRead);
  EXPECT_EQ(f.attribute_string("/", "version"), "0.1.0");
  EXPECT_EQ(f.attribute_string("/", "long_text"), std::string(100000, 'y'));
  EXPECT_EQ(f.attribute_double("/", "pi"), 3.141592653589793);
  EXPECT_EQ(f.attribute_int("/", "count"), std::int64_t{1} << 40);
  EXPECT_EQ(f.attribute_double("/", "count"), std::ldexp(1.0, 40));  // int readable as double
  EXPECT_EQ(f.attribute_string("/g", "units"), "m");
  EXPECT_EQ(f.attribute_int("g/d", "frames"), 4);
  EXPECT_TRUE(f.has_attribute("g/d", "frames"));
  EXPECT_FALSE(f.has_attribute("g/d", "nope"));
  EXPECT_FALSE(f.has_attribute("no/such/object", "x"));
  EXPECT_EQ(f.attribute_names("/"), (std::vector<std::string>{"count", "long_text", "pi", "version"}));
  try {
    f.attribute_int("/", "pi");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), HasSubstr("attribute 'pi' of /: expected an integer, found floating-point"));
  }
  try {
    f.attribute_string("g", "missing");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), HasSubstr("attributes.h5: error: attribute 'missing' of /g not found"));
  }
}

TEST(Hdf5, MissingDatasetAndMismatchesNameFileAndDataset) {
  const fs::path p = temp_dir() / "errors.h5";
  {
    H5File f(p.string(), H5File::Mode::kTruncate);
    f.write("a/b", Eigen::MatrixXd::Ones(2, 3));
    f.write("a/i", Eigen::VectorXi::Ones(2));
  }
  H5File f(p.string(), H5File::Mode::kRead);
  const std::string file = p.string();
  auto message = [](auto&& fn) -> std::string {
    try {
      fn();
    } catch (const InputError& e) {
      return e.what();
    }
    return "(no exception)";
  };
  EXPECT_EQ(message([&] { f.read_matrix("/a/missing"); }), file + ": error: dataset /a/missing not found");
  EXPECT_EQ(message([&] { f.read_vector("x/y/z"); }), file + ": error: dataset /x/y/z not found");
  EXPECT_EQ(message([&] { f.read_matrix("a"); }), file + ": error: dataset /a not found (/a is a group)");
  EXPECT_EQ(message([&] { f.read_vector("a/b"); }),
            file + ": error: dataset /a/b: expected a rank-1 floating-point array, found floating-point dims (2, 3)");
  EXPECT_EQ(message([&] { f.read_matrix("a/i"); }),
            file + ": error: dataset /a/i: expected a rank-2 floating-point array, found integer dims (2)");
  EXPECT_EQ(message([&] { f.read_matrix_int("a/b"); }),
            file + ": error: dataset /a/b: expected a rank-2 integer array, found floating-point dims (2, 3)");
  EXPECT_EQ(message([&] { f.read_strings("a/b"); }),
            file + ": error: dataset /a/b: expected a rank-1 string array, found floating-point dims (2, 3)");
  EXPECT_EQ(message([&] { f.read_matrix("a/b", 4); }), file + ": error: dataset /a/b: expected dims (*, 4), found (2, 3)");
  EXPECT_EQ(message([&] { f.read_tensor3("a/b"); }),
            file + ": error: dataset /a/b: expected a rank-3 floating-point array, found floating-point dims (2, 3)");
  // Missing and non-HDF5 files.
  const fs::path missing = temp_dir() / "does_not_exist.h5";
  EXPECT_EQ(message([&] { H5File g(missing.string(), H5File::Mode::kRead); }),
            missing.string() + ": error: cannot open HDF5 file: no such file");
  const fs::path text = temp_dir() / "not_hdf5.h5";
  std::ofstream(text) << "hello\n";
  EXPECT_THAT(message([&] { H5File g(text.string(), H5File::Mode::kRead); }),
              HasSubstr(text.string() + ": error: cannot open HDF5 file for reading: "));
  // Wrong tensor size on write.
  H5File w((temp_dir() / "errors_w.h5").string(), H5File::Mode::kTruncate);
  EXPECT_THAT(message([&] { w.write_tensor3("t", {2, 2, 2}, std::vector<double>(7)); }),
              HasSubstr("dataset /t: expected 8 values for dims (2, 2, 2), found 7"));
}

// Writing the same data twice gives bit-identical files: no timestamps or
// other run-dependent bytes are stored (needed by the determinism tests of the
// stages, which compare outputs).
TEST(Hdf5, SameDataGivesIdenticalFiles) {
  auto write_file = [](const fs::path& p) {
    H5File f(p.string(), H5File::Mode::kTruncate);
    f.write("a/m", Eigen::MatrixXd::Constant(10, 3, 0.5));
    f.write("a/s", std::vector<std::string>{"x", "y"});
    f.set_attribute("/", "k", "v");
    auto app = f.appender("b/frames", {4});
    for (int k = 0; k < 5; ++k) app.append(Eigen::Vector4d::Constant(k));
  };
  const fs::path p1 = temp_dir() / "det1.h5", p2 = temp_dir() / "det2.h5";
  write_file(p1);
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));  // a timestamp would now differ
  write_file(p2);
  auto bytes = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string b1 = bytes(p1), b2 = bytes(p2);
  EXPECT_GT(b1.size(), 0u);
  EXPECT_TRUE(b1 == b2) << "files differ: " << b1.size() << " vs " << b2.size() << " bytes";
}

// ---- appending ------------------------------------------------------------------
TEST(Hdf5, AppenderFramesOfRank0To2) {
  const fs::path p = temp_dir() / "append.h5";
  {
    H5File f(p.string(), H5File::Mode::kTruncate);
    auto s = f.appender("time", {});
    auto v = f.appender("v", {3}, {.expected_frames = 0, .frames_per_chunk = 2});
    auto m = f.appender("m", {2, 3});
    auto mi = f.appender_int("mi", {2, 2});
    for (int k = 0; k < 5; ++k) {
      s.append(0.1 * k);
      v.append(Eigen::Vector3d(k, k + 1, k + 2));
      Eigen::Matrix<double, 2, 3> mm;
      mm << k, 1, 2, 3, 4, -k;
      m.append(mm);
      mi.append(Eigen::Matrix2i::Constant(k));
    }
    EXPECT_EQ(v.num_frames(), 5);
    // While appending, space is allocated ahead: the extent is a whole number
    // of chunks (2 frames per chunk for v: 5 frames -> grown 2, 4, 8), the
    // readable dims are the complete frames.
    EXPECT_EQ(f.dims("v"), (std::vector<std::int64_t>{5, 3}));
    EXPECT_EQ(f.extent("v"), (std::vector<std::int64_t>{8, 3}));
    EXPECT_EQ(f.read_matrix("v").rows(), 5);
    // Shape and type errors name the dataset and frame.
    try {
      v.append(Eigen::Vector4d::Zero());
      FAIL();
    } catch (const InputError& e) {
      EXPECT_THAT(e.what(), HasSubstr("dataset /v: frame 5: expected frame dims (3), found (4, 1)"));
    }
    EXPECT_THROW(m.append(Eigen::Matrix<double, 3, 2>::Zero()), InputError);
    EXPECT_THROW(mi.append(Eigen::Matrix2d::Zero()), InputError);
    EXPECT_THROW(f.appender("w", {1, 2, 3}), InputError);  // rank 4 not supported
  }
  {
    // Reopen and continue appending to an existing dataset.
    H5File f(p.string(), H5File::Mode::kReadWrite);
    auto v = f.appender("v", {3});
    EXPECT_EQ(v.num_frames(), 5);
    v.append(Eigen::Vector3d(50, 51, 52));
    EXPECT_THROW(f.appender("v", {4}), InputError);        // other frame dims
    EXPECT_THROW(f.appender_int("v", {3}), InputError);    // other type
    f.write("fixed", Eigen::MatrixXd::Zero(2, 3));
    EXPECT_THROW(f.appender("fixed", {3}), InputError);    // not appendable
  }
  H5File f(p.string(), H5File::Mode::kRead);
  // Closed appenders shrank their datasets to the frames written.
  for (const char* name : {"time", "v", "m", "mi"}) EXPECT_EQ(f.extent(name), f.dims(name)) << name;
  EXPECT_EQ(f.attribute_int("v", "arthrosim_frames_complete"), 6);
  const Eigen::VectorXd t = f.read_vector("time");
  ASSERT_EQ(t.size(), 5);
  for (int k = 0; k < 5; ++k) EXPECT_EQ(t(k), 0.1 * k);
  const Eigen::MatrixXd v = f.read_matrix("v");
  ASSERT_EQ(v.rows(), 6);
  EXPECT_EQ(v.row(3), Eigen::RowVector3d(3, 4, 5));
  EXPECT_EQ(v.row(5), Eigen::RowVector3d(50, 51, 52));
  const Tensor3d m = f.read_tensor3("m");
  EXPECT_EQ(m.dims, (std::array<std::int64_t, 3>{5, 2, 3}));
  EXPECT_EQ(m(4, 0, 0), 4.0);
  EXPECT_EQ(m(4, 1, 2), -4.0);
  EXPECT_EQ(m(2, 1, 0), 3.0);
  const Tensor3i mi = f.read_tensor3_int("mi");
  EXPECT_EQ(mi(3, 1, 1), 3);
}

// The kill case. The child (this binary re-executed in child mode) appends a
// 50 x 3 frame plus a time and an int frame, reports each completed frame
// through a pipe, and gets SIGKILL as soon as the parent has seen N reports.
// With sleep 0 the kill lands while the child is inside HDF5 (extending,
// writing or flushing the next frame), the interesting case.
void run_kill_case(int frames_before_kill, int sleep_us, int frames_per_chunk, int expected_frames,
                   const std::string& tag) {
  const fs::path file = temp_dir() / ("killed_" + tag + ".h5");
  fs::remove(file);
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    close(fds[0]);
    setenv("ARTHROSIM_HDF5_KILL_CHILD", file.c_str(), 1);
    setenv("ARTHROSIM_HDF5_KILL_FD", std::to_string(fds[1]).c_str(), 1);
    setenv("ARTHROSIM_HDF5_KILL_SLEEP_US", std::to_string(sleep_us).c_str(), 1);
    setenv("ARTHROSIM_HDF5_KILL_CHUNK", std::to_string(frames_per_chunk).c_str(), 1);
    setenv("ARTHROSIM_HDF5_KILL_EXPECTED", std::to_string(expected_frames).c_str(), 1);
    char arg0[] = "hdf5_test_kill_child";
    char* argv[] = {arg0, nullptr};
    execv("/proc/self/exe", argv);
    _exit(127);
  }
  close(fds[1]);
  std::int64_t reported = 0;
  while (reported < frames_before_kill) {
    std::int64_t v = 0;
    const ssize_t r = read(fds[0], &v, sizeof v);
    if (r != static_cast<ssize_t>(sizeof v)) break;
    reported = v;
  }
  kill(pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  // The child may have run ahead of our reading: drain the pipe to learn the
  // last frame it completed before it died.
  std::int64_t last_completed = reported;
  for (std::int64_t v = 0; read(fds[0], &v, sizeof v) == static_cast<ssize_t>(sizeof v);) last_completed = v;
  close(fds[0]);
  ASSERT_EQ(reported, frames_before_kill) << "child stopped early, status " << status;
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << "child was not killed, status " << status;

  // The file left behind opens (no "file in use" flag) and holds every frame
  // the child reported, each complete and correct.
  H5File f(file.string(), H5File::Mode::kRead);
  EXPECT_EQ(f.read_vector("static/before"), Eigen::VectorXd::LinSpaced(5, 0.0, 1.0));
  const Tensor3d pts = f.read_tensor3("frames/points");
  const Eigen::VectorXd time = f.read_vector("frames/time");
  const Eigen::MatrixXi ids = f.read_matrix_int("frames/ids");
  ASSERT_GE(pts.dims[0], reported);
  ASSERT_GE(time.size(), reported);
  ASSERT_GE(ids.rows(), reported);
  // Every completed frame is there; at most one more (appended after the
  // last report) may be, and anything present must be correct. Appends go
  // ids, time, points, so ids >= times >= points frames.
  EXPECT_GE(pts.dims[0], last_completed);
  EXPECT_LE(ids.rows(), last_completed + 1);
  EXPECT_GE(ids.rows(), time.size());
  EXPECT_GE(time.size(), pts.dims[0]);
  for (std::int64_t k = 0; k < pts.dims[0]; ++k) {
    for (int i = 0; i < kKillRows; ++i) {
      for (int j = 0; j < kKillCols; ++j) {
        ASSERT_EQ(pts(k, i, j), frame_value(k, i, j)) << "frame " << k << " (" << i << ", " << j << ")";
      }
    }
  }
  for (Eigen::Index k = 0; k < time.size(); ++k) ASSERT_EQ(time(k), 0.01 * static_cast<double>(k));
  for (Eigen::Index k = 0; k < ids.rows(); ++k) {
    for (int i = 0; i < kKillRows; ++i) ASSERT_EQ(ids(k, i), static_cast<int>(k) * 100 + i);
  }
  std::cout << "[ kill " << tag << " ] killed after " << reported << " reports (" << last_completed
            << " frames completed); file holds " << pts.dims[0]
            << " point frames, " << time.size() << " times, " << ids.rows() << " id frames\n";
}

TEST(Hdf5Kill, ChildKilledWhileSleepingLeavesReportedFrames) {
  run_kill_case(20, 2000, 4, 0, "sleeping");  // capacity grows by doubling here
}

// A killed run's file can be reopened for writing and appending resumes after
// the last complete frame (what a restarted stage would do); closing then
// shrinks the dataset to exactly the frames written.
TEST(Hdf5Kill, AppendingResumesAfterKill) {
  run_kill_case(12, 2000, 4, 0, "resume");
  const fs::path file = temp_dir() / "killed_resume.h5";
  std::int64_t before = 0;
  {
    H5File f(file.string(), H5File::Mode::kReadWrite);
    before = f.dims("frames/time")[0];
    ASSERT_GE(before, 12);
    EXPECT_GT(f.extent("frames/time")[0], before);  // capacity allocated ahead by the child
    auto times = f.appender("frames/time", {});
    EXPECT_EQ(times.num_frames(), before);
    times.append(-1.0);
    times.append(-2.0);
  }
  H5File f(file.string(), H5File::Mode::kRead);
  const Eigen::VectorXd t = f.read_vector("frames/time");
  ASSERT_EQ(t.size(), before + 2);
  EXPECT_EQ(f.extent("frames/time")[0], before + 2);
  for (std::int64_t k = 0; k < before; ++k) EXPECT_EQ(t(k), 0.01 * static_cast<double>(k));
  EXPECT_EQ(t(before), -1.0);
  EXPECT_EQ(t(before + 1), -2.0);
}

TEST(Hdf5Kill, ChildKilledInsideWritesLeavesReportedFrames) {
  // Repeated with different N so the kill lands at different points of the
  // append/flush sequence (often inside HDF5), with 4 frames per chunk and
  // with one frame per chunk (the chunk index B-tree then splits every few
  // dozen frames). The expected frame count (4000, more than the child reaches) is passed, so every
  // append is a steady-state one (see H5File::Appender).
  for (int chunk : {4, 1}) {
    for (int n : {1, 7, 33, 64, 101}) {
      run_kill_case(n, 0, chunk, 4000, "busy_" + std::to_string(n) + "_chunk" + std::to_string(chunk));
    }
  }
}

}  // namespace
}  // namespace arthrosim::common
