// Inputs found by fuzzing the musculoskeletal readers (tests/fuzz, docs/testing.md):
// each test is the minimised input of one defect, rebuilt here so that the
// normal suite keeps it fixed; the raw fuzz input is in
// tests/fuzz/corpus/<target>/regression-*.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>

#include "common/error.h"
#include "common/hdf5.h"
#include "musculoskeletal/gait_trial.h"
#include "musculoskeletal/model_io.h"

namespace msk = arthrosim::musculoskeletal;
namespace common = arthrosim::common;
namespace fs = std::filesystem;

namespace {

const std::string kSource = ARTHROSIM_SOURCE_DIR;

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

fs::path scratch(const std::string& name) {
  const fs::path dir = fs::path(ARTHROSIM_BINARY_DIR) / "msk_fuzz_inputs";
  fs::create_directories(dir);
  return dir / name;
}

// The fuzz targets' model: two contact surfaces of the bundled coarse knee.
msk::Model small_knee() {
  return msk::parse_model(read_text(kSource + "/tests/fuzz/knee_small.urdf"), "knee_small.urdf",
                          kSource + "/data/models/knee_parametric");
}

struct PreparedSurface {
  std::string name, source_file;
  Eigen::MatrixXd V;
  Eigen::MatrixXi F;
  Eigen::VectorXd thickness;
};

// One triangle centred on the model mesh's centroid (as the fuzz corpus
// entry small_one_triangle.h5spec, tests/fuzz/make_corpus.py).
PreparedSurface one_triangle(const msk::Model& m, const std::string& surface, const std::string& name) {
  for (const auto& pair : m.contacts) {
    for (const msk::ContactSurface* s : {&pair.casting(), &pair.target()}) {
      if (s->name != surface) continue;
      const Eigen::Vector3d c = s->X_BM.inverse() * Eigen::Vector3d(s->mesh.V.colwise().mean().transpose());
      PreparedSurface p;
      p.name = name;
      p.source_file = "coarse/" + fs::path(s->mesh_file).filename().string();
      p.V.resize(3, 3);
      p.V.row(0) = (c + Eigen::Vector3d(0.002, 0, 0)).transpose();
      p.V.row(1) = (c + Eigen::Vector3d(-0.001, 0.002, 0)).transpose();
      p.V.row(2) = (c + Eigen::Vector3d(-0.001, -0.002, 0)).transpose();
      p.F.resize(1, 3);
      p.F << 0, 1, 2;
      p.thickness = Eigen::VectorXd::Constant(3, 0.002);
      return p;
    }
  }
  throw std::logic_error("no surface " + surface);
}

std::string write_prepared(const std::string& file, const std::vector<PreparedSurface>& surfaces) {
  const std::string path = scratch(file).string();
  common::H5File f(path, common::H5File::Mode::kTruncate);
  f.set_attribute("/", "schema", "arthrosim prepared model 1");  // the version the reader takes (common/file_check.h)
  std::vector<std::string> names;
  for (const auto& s : surfaces) names.push_back(s.name);
  f.write("/surfaces/names", names);
  for (const auto& s : surfaces) {
    const std::string g = "/surfaces/" + s.name;
    f.write(g + "/triangles/vertices", s.V);
    f.write(g + "/triangles/faces", s.F);
    f.write(g + "/triangles/thickness", s.thickness);
    f.set_attribute(g, "source_file", s.source_file);
  }
  return path;
}

std::vector<PreparedSurface> valid_prepared(const msk::Model& m) {
  return {one_triangle(m, "patella_cartilage", "patella"),
          one_triangle(m, "tibia_lateral_cartilage", "tibia_lateral")};
}

std::string error_of(msk::Model& m, const std::string& path) {
  try {
    msk::use_prepared_surfaces(m, path);
  } catch (const common::InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

// The fixture itself is accepted, so the tests below fail for their own reason.
TEST(PreparedSurfacesFuzz, OneTrianglePerSurfaceIsAccepted) {
  msk::Model m = small_knee();
  const std::string path = write_prepared("valid.h5", valid_prepared(m));
  const auto report = msk::use_prepared_surfaces(m, path);
  EXPECT_EQ(report.lines.size(), 2u);
}

// fuzz_prepared, regression-face-index-beyond-vertices.h5spec: a face
// indexing past the vertices read the thickness (and vertex) arrays out of
// bounds (Eigen assertion / heap read) in use_prepared_surfaces.
TEST(PreparedSurfacesFuzz, FaceIndexBeyondTheVerticesIsAnInputError) {
  msk::Model m = small_knee();
  auto s = valid_prepared(m);
  s[0].F(0, 2) = 7;
  const std::string message = error_of(m, write_prepared("face_index.h5", s));
  EXPECT_NE(message.find("/surfaces/patella/triangles/faces: expected vertex indices in [0, 3), found 7"),
            std::string::npos)
      << message;
}

TEST(PreparedSurfacesFuzz, NegativeFaceIndexIsAnInputError) {
  msk::Model m = small_knee();
  auto s = valid_prepared(m);
  s[1].F(0, 0) = -1;
  const std::string message = error_of(m, write_prepared("face_negative.h5", s));
  EXPECT_NE(message.find("tibia_lateral/triangles/faces: expected vertex indices in [0, 3), found -1"),
            std::string::npos)
      << message;
}

// A NaN vertex made the centroid NaN, and "offset > 2 mm" is false for NaN:
// the surface was accepted with NaN geometry.
TEST(PreparedSurfacesFuzz, NonFiniteVertexIsAnInputError) {
  msk::Model m = small_knee();
  auto s = valid_prepared(m);
  s[0].V(1, 1) = std::numeric_limits<double>::quiet_NaN();
  const std::string message = error_of(m, write_prepared("vertex_nan.h5", s));
  EXPECT_NE(message.find("patella/triangles/vertices: expected finite coordinates"), std::string::npos) << message;
}

TEST(PreparedSurfacesFuzz, NegativeOrNonFiniteThicknessIsAnInputError) {
  for (const double bad : {-1e-3, std::numeric_limits<double>::infinity()}) {
    msk::Model m = small_knee();
    auto s = valid_prepared(m);
    s[1].thickness(2) = bad;
    const std::string message = error_of(m, write_prepared("thickness_bad.h5", s));
    EXPECT_NE(message.find("tibia_lateral/triangles/thickness: expected finite values >= 0"), std::string::npos)
        << bad << ": " << message;
  }
}

namespace {

// The bundled synthetic trial cut to 10 rows per file, in a folder of its
// own; `edit` may change the rows of ik.mot / grf.mot (tab-separated, after
// the label line) before they are written.
std::string small_trial(const std::string& folder,
                        const std::function<void(std::vector<std::string>& ik, std::vector<std::string>& grf)>& edit) {
  const fs::path dir = scratch(folder);
  fs::create_directories(dir);
  auto head = [](const std::string& file, std::vector<std::string>* rows) {
    std::istringstream in(read_text(kSource + "/data/trials/synthetic_gait/" + file));
    std::string header, line;
    bool data = false;
    int n = 0;
    while (std::getline(in, line)) {
      if (data) {
        if (n++ < 10) rows->push_back(line);
        continue;
      }
      if (line.rfind("nRows=", 0) == 0) continue;  // the row count changes
      header += line + "\n";
      if (line == "endheader") {
        std::getline(in, line);
        header += line + "\n";  // labels
        data = true;
      }
    }
    return header;
  };
  std::vector<std::string> ik, grf;
  const std::string ik_header = head("ik.mot", &ik), grf_header = head("grf.mot", &grf);
  edit(ik, grf);
  auto write = [&](const std::string& file, const std::string& header, const std::vector<std::string>& rows) {
    std::ofstream out(dir / file);
    out << header;
    for (const auto& r : rows) out << r << "\n";
  };
  write("ik.mot", ik_header, ik);
  write("grf.mot", grf_header, grf);
  std::string description = read_text(kSource + "/data/trials/synthetic_gait/trial.yaml");
  description.replace(description.find("periodic: true"), 14, "periodic: false");
  std::ofstream(dir / "trial.yaml") << description;
  return (dir / "trial.yaml").string();
}

std::string set_time(const std::string& row, const std::string& time) {
  return time + row.substr(row.find('\t'));
}

std::string trial_error(const std::string& trial) {
  try {
    msk::load_gait_trial(trial);
  } catch (const common::InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(GaitTrialFuzz, TheCutTrialIsAccepted) {
  const msk::GaitTrial t = msk::load_gait_trial(small_trial("trial_ok", [](auto&, auto&) {}));
  EXPECT_EQ(t.num_samples(), 10);
}

// fuzz_trial, regression-kinematics-without-rows.txt: a kinematics file with
// labels but no data row read time(0) of an empty vector (Eigen assertion;
// a null read in Release).
TEST(GaitTrialFuzz, KinematicsWithoutRowsIsAnInputError) {
  const std::string message = trial_error(small_trial("trial_no_rows", [](auto& ik, auto&) { ik.clear(); }));
  EXPECT_NE(message.find("ik.mot:9: error: expected at least 2 data rows (a time series), found 0"),
            std::string::npos)
      << message;
}

// fuzz_trial, regression-time-1e300.txt: a last time of 1e300 s overflowed
// the grid size (UBSan: 1e+302 is outside the range of 'long', signal.cc);
// regression-time-1e6-seconds.txt: 1e6 s asked for 8.8 GB.
TEST(GaitTrialFuzz, AHugeTimeRangeIsAnInputError) {
  for (const std::string time : {"1e300", "1000000"}) {
    const std::string message = trial_error(small_trial("trial_long", [&](auto& ik, auto& grf) {
      ik.back() = set_time(ik.back(), time);
      grf.back() = set_time(grf.back(), time);
    }));
    EXPECT_NE(message.find("trial.yaml: error: the time range common to the trial's files"), std::string::npos)
        << time << ": " << message;
    EXPECT_NE(message.find("expected at most 1e+06 (times in seconds?)"), std::string::npos) << message;
  }
}

namespace {

std::string model_error(const std::string& xml) {
  try {
    msk::parse_model(xml, "graph.urdf", kSource);
  } catch (const common::InputError& e) {
    return e.what();
  }
  return "";
}

std::string joint(const std::string& name, const std::string& parent, const std::string& child) {
  return "<joint name=\"" + name + "\" type=\"revolute\"><parent link=\"" + parent + "\"/><child link=\"" + child +
         "\"/><limit lower=\"-1\" upper=\"1\" effort=\"0\" velocity=\"0\"/></joint>\n";
}

}  // namespace

// fuzz_urdf, regression-joint-parent-is-child.urdf (minimised): a joint whose
// parent and child are the same link made urdfdom build a cycle of owning
// pointers, which it never freed (LeakSanitizer: 608 bytes in 8 allocations)
// before refusing the model with a message naming no line.
TEST(ModelGraphFuzz, JointWithTheSameParentAndChildIsAnInputError) {
  const std::string message = model_error(
      "<robot name=\"\"><link name=\"tibia\"></link><joint name=\"\"type=\"revolute\"><child link=\"tibia\"/>"
      "<parent link=\"tibia\"/><limit effort=\"0\"velocity=\"0\"/></joint></robot>");
  EXPECT_NE(message.find("graph.urdf:1: error: joint '' expected different parent and child links, found 'tibia' for both"),
            std::string::npos)
      << message;
}

TEST(ModelGraphFuzz, LinkWithTwoParentJointsIsAnInputError) {
  const std::string message = model_error("<robot name=\"r\">\n<link name=\"a\"/><link name=\"b\"/><link name=\"c\"/>\n" +
                                          joint("j1", "a", "c") + joint("j2", "b", "c") + "</robot>\n");
  EXPECT_NE(message.find("graph.urdf:4: error: joint 'j2': link 'c' is already the child of joint 'j1' (line 3)"),
            std::string::npos)
      << message;
}

TEST(ModelGraphFuzz, LoopOfJointsIsAnInputError) {
  const std::string message = model_error("<robot name=\"r\">\n<link name=\"root\"/><link name=\"a\"/><link name=\"b\"/>\n" +
                                          joint("j1", "a", "b") + joint("j2", "b", "a") + "</robot>\n");
  EXPECT_NE(message.find("is part of a loop of joints through link"), std::string::npos) << message;
}
