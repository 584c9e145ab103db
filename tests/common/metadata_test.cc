// Run metadata: the scene hash, the dependency registry, command-line
// quoting, and the round trip through HDF5 root attributes (with no host name
// or time recorded).
#include "common/metadata.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/error.h"
#include "common/hashing.h"
#include "common/hdf5.h"
#include "common/version.h"

namespace arthrosim::common {
namespace {

namespace fs = std::filesystem;

fs::path temp_dir() {
  fs::path d = fs::path(ARTHROSIM_BINARY_DIR) / "test_output" / "metadata_test";
  fs::create_directories(d);
  return d;
}

TEST(Metadata, CommandLineQuoting) {
  const char* argv[] = {"arthrosim", "run", "data/scenes/demo.yaml", "--out", "my dir", "it's", "--x=1"};
  EXPECT_EQ(join_command_line(7, argv), "arthrosim run data/scenes/demo.yaml --out 'my dir' 'it'\\''s' --x=1");
}

TEST(Metadata, CollectWriteReadRoundTrip) {
  const fs::path scene = temp_dir() / "scene.yaml";
  std::ofstream(scene) << "model: knee\nstages: [prepare]\n";
  register_dependency_version("testlib", "1.2.3");
  const char* argv[] = {"arthrosim-prepare", scene.c_str()};
  const RunMetadata m = collect_run_metadata("arthrosim-prepare", 2, argv, scene.string(), "edge_length_mm: 1.5\n");
  EXPECT_EQ(m.version, kVersion);
  EXPECT_EQ(m.git_revision, kGitRevision);
  EXPECT_EQ(m.scene_sha256, sha256_hex("model: knee\nstages: [prepare]\n"));
  EXPECT_EQ(m.dependencies.at("testlib"), "1.2.3");
  EXPECT_THAT(m.dependencies.at("hdf5"), ::testing::StartsWith("1."));
  EXPECT_THAT(m.dependencies.at("eigen"), ::testing::StartsWith("3."));
  EXPECT_FALSE(m.dependencies.at("cgal").empty());

  const fs::path h5 = temp_dir() / "meta.h5";
  {
    H5File f(h5.string(), H5File::Mode::kTruncate);
    write_metadata(f, m);
  }
  H5File f(h5.string(), H5File::Mode::kRead);
  const RunMetadata r = read_metadata(f);
  EXPECT_EQ(r.program, m.program);
  EXPECT_EQ(r.version, m.version);
  EXPECT_EQ(r.git_revision, m.git_revision);
  EXPECT_EQ(r.scene_path, m.scene_path);
  EXPECT_EQ(r.scene_sha256, m.scene_sha256);
  EXPECT_EQ(r.command_line, m.command_line);
  EXPECT_EQ(r.options, m.options);
  EXPECT_EQ(r.dependencies, m.dependencies);
  // Nothing host- or time-dependent among the attributes.
  for (const std::string& key : f.attribute_names("/")) {
    EXPECT_EQ(key.find("host"), std::string::npos) << key;
    EXPECT_EQ(key.find("time"), std::string::npos) << key;
    EXPECT_EQ(key.find("date"), std::string::npos) << key;
  }
  EXPECT_EQ(f.attribute_string("/", "version_testlib"), "1.2.3");
  // A missing scene is an input error naming it.
  EXPECT_THROW(collect_run_metadata("x", 0, nullptr, (temp_dir() / "nope.yaml").string(), ""), InputError);
}

}  // namespace
}  // namespace arthrosim::common
