// The biphasic stage end to end on small synthetic inputs: a prepared model
// with a flat "femur" layer over a flat "tibia_medial" plate (knee frame
// convention: Y superior, X anterior, Z lateral) and a kinematics file whose
// femur moves down into the plate and back. Checks the counters (one
// factorisation per layer, one solve per step), the output file and its
// XDMF, determinism, and the refusals and reported skips of bad input.
#include "pipelines/biphasic_stage.h"

#include <cmath>
#include <gtest/gtest.h>

#include <filesystem>
#include <cstring>
#include <fstream>
#include <sstream>

#include "biphasic/output_file.h"
#include "biphasic_fixtures.h"
#include "common/error.h"
#include "common/hdf5.h"
#include "common/prepared_model_file.h"
#include "common/log.h"
#include "pipelines/runner.h"
#include "pipelines/stages.h"

namespace arthrosim {
namespace {

namespace fs = std::filesystem;

fs::path scratch() {
  const fs::path p = fs::path(ARTHROSIM_BINARY_DIR) / "test_scratch" / "biphasic_stage";
  fs::create_directories(p);
  return p;
}

// A flat square surface in the X-Z plane at height y, facing +Y (up) or -Y.
void write_surface(common::PreparedModelWriter& f, const std::string& name, const std::string& bone, int n, double size,
                   double y, bool up, double thickness) {
  common::QuadMesh s = biphasic::testing::grid_surface(n, n, size, size, 0.0);
  common::Points3 V(s.num_nodes(), 3), N(s.num_nodes(), 3);
  for (int v = 0; v < s.num_nodes(); ++v) {
    V.row(v) << s.V(v, 0) - size / 2, y, s.V(v, 1) - size / 2;  // grid (x, y) -> (X, Z)
    N.row(v) << 0.0, up ? 1.0 : -1.0, 0.0;
  }
  // grid quads are counter-clockwise seen from +z of the grid, i.e. from -Y
  // after the map (x, y) -> (X, Z); reverse them for an upward surface.
  Eigen::MatrixXi Q = s.Q;
  if (up)
    for (int q = 0; q < Q.rows(); ++q) Q.row(q) = Eigen::RowVector4i(Q(q, 0), Q(q, 3), Q(q, 2), Q(q, 1));
  std::vector<int> periphery;  // the square's outline
  for (int v = 0; v < s.num_nodes(); ++v)
    if (std::abs(std::abs(V(v, 0)) - size / 2) < 1e-12 || std::abs(std::abs(V(v, 2)) - size / 2) < 1e-12)
      periphery.push_back(v);
  common::QuadMesh mesh;
  mesh.V = V;
  mesh.Q = Q;
  f.surface(name, bone);
  f.quads(name, mesh, N, Eigen::VectorXd::Constant(s.num_nodes(), thickness), periphery);
}

std::string write_prepared(const std::string& file, double femur_thickness = 1.5e-3) {
  const std::string path = (scratch() / file).string();
  common::H5File h5(path, common::H5File::Mode::kTruncate);
  common::PreparedModelWriter f(h5);  // a prepared model as the stage reads it (common/prepared_model_file.h)
  f.identity("biphasic stage test");
  f.surface_names({"femur", "tibia_medial"});
  write_surface(f, "femur", "femur", 4, 8e-3, 0.0, false, femur_thickness);
  write_surface(f, "tibia_medial", "tibia", 6, 12e-3, 0.0, true, 2e-3);
  return path;
}

struct KinematicsSpec {
  std::vector<double> overlap_m = {0.05e-3, 0.1e-3, 0.15e-3, 0.1e-3, -0.1e-3, 0.05e-3};
  std::vector<double> force_N = {50, 120, 200, 150, 30, 60};
  std::vector<int> status = {0, 0, 0, 0, 0, 0};
  bool with_medial_force = true;
  /// Stage 1 without a medial/lateral split (one tibiofemoral pair): the split
  /// series are zero, the total carries the force.
  bool unsplit = false;
};

std::string write_kinematics(const std::string& file, const KinematicsSpec& k) {
  const std::string path = (scratch() / file).string();
  common::H5File f(path, common::H5File::Mode::kTruncate);
  f.set_attribute("/", "format", "arthrosim kinematics file");  // what the stage checks (common/file_check.h)
  f.set_attribute("/", "format_version", 1);
  const int n = static_cast<int>(k.overlap_m.size());
  f.set_attribute("/", "frames_expected", n);  // complete (the stage refuses an incomplete file)
  f.set_attribute("/", "frames", n);
  Eigen::VectorXd t(n);
  std::vector<double> femur, tibia;
  Eigen::MatrixXd medial(n, 3), lateral = Eigen::MatrixXd::Zero(n, 3);
  for (int i = 0; i < n; ++i) {
    t[i] = 0.01 * i;
    Eigen::Matrix4d Xf = Eigen::Matrix4d::Identity(), Xt = Eigen::Matrix4d::Identity();
    Xf(1, 3) = -k.overlap_m[i];  // the femoral surface moves down into the plate
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) {
        femur.push_back(Xf(r, c));
        tibia.push_back(Xt(r, c));
      }
    medial.row(i) << 0.0, -k.force_N[i], 0.0;
  }
  f.write("/time", t);
  f.write_tensor3("/bodies/femur/X_W", {n, 4, 4}, femur);
  f.write_tensor3("/bodies/tibia/X_W", {n, 4, 4}, tibia);
  if (k.unsplit) f.write("/contact/tibiofemoral/force", medial);
  if (k.unsplit) medial.setZero();
  if (k.with_medial_force) f.write("/contact/tibiofemoral/medial_force", medial);
  f.write("/contact/tibiofemoral/lateral_force", lateral);
  f.write("/solver/status", Eigen::VectorXi(Eigen::Map<const Eigen::VectorXi>(k.status.data(), n)));
  return path;
}

pipelines::BiphasicStageOptions options(const std::string& prepared, const std::string& kinematics,
                                        const std::string& out) {
  pipelines::BiphasicStageOptions o;
  o.prepared = prepared;
  o.kinematics = kinematics;
  o.out = (scratch() / out).string();
  o.layers = {"femur", "tibia_medial"};
  o.element_layers = 1;
  o.progress = false;
  return o;
}

TEST(BiphasicStage, RunsFactorsOnceAndWritesItsFile) {
  common::set_log_level(common::LogLevel::kError);
  const std::string prepared = write_prepared("prepared.h5");
  KinematicsSpec spec;
  const std::string kinematics = write_kinematics("kinematics.h5", spec);
  const pipelines::BiphasicStageResult r = pipelines::run_biphasic_stage(options(prepared, kinematics, "out.h5"));
  EXPECT_EQ(r.frames, 6);
  EXPECT_EQ(r.steps, 5);
  // Frame 4 separates the layers while stage 1 still reports 30 N: a
  // reported skip (no conditions that frame), never a NaN.
  EXPECT_EQ(r.skipped_pair_frames, 1);
  ASSERT_EQ(r.layers.size(), 2u);
  for (const auto& l : r.layers) {
    EXPECT_EQ(l.factorizations, 1) << l.name;
    EXPECT_EQ(l.solves, 5) << l.name;
    EXPECT_LT(l.max_relative_residual, 1e-10);
  }
  const auto series = biphasic::read_layer_series(options(prepared, kinematics, "out.h5").out);
  ASSERT_EQ(series.size(), 2u);
  EXPECT_EQ(series[0].time.size(), 5);
  EXPECT_EQ(series[0].factorizations, 1);
  EXPECT_EQ(series[1].solves, 5);
  for (int i = 0; i < 5; ++i) {
    EXPECT_TRUE(std::isfinite(series[1].max_shear[i]));
    EXPECT_GE(series[1].fluid_load_support[i], 0.0);
    EXPECT_LE(series[1].fluid_load_support[i], 1.0);
  }
  // At the frame times the femur's contact area is its whole 8 x 8 mm
  // surface while in contact (t = 0.01 .. 0.03) and 0 at the skipped frame.
  EXPECT_NEAR(series[0].contact_area[1], 64e-6, 1e-12);
  EXPECT_EQ(series[0].contact_area[3], 0.0);
  // The XDMF sidecar describes hexahedra.
  std::ifstream x((scratch() / "out.xdmf").string());
  std::stringstream text;
  text << x.rdbuf();
  EXPECT_NE(text.str().find("Hexahedron"), std::string::npos);
  // Frame table: the skipped frame is marked.
  const common::H5File f(options(prepared, kinematics, "out.h5").out, common::H5File::Mode::kRead);
  EXPECT_EQ(f.read_vector_int("/frames/medial/skipped_no_overlap")[4], 1);
  EXPECT_EQ(f.attribute_string("/", "schema"), "arthrosim biphasic output 1");
}

TEST(BiphasicStage, SameInputsGiveBitIdenticalDatasets) {
  common::set_log_level(common::LogLevel::kError);
  const std::string prepared = write_prepared("prepared_det.h5");
  const std::string kinematics = write_kinematics("kinematics_det.h5", KinematicsSpec{});
  pipelines::run_biphasic_stage(options(prepared, kinematics, "det_a.h5"));
  pipelines::run_biphasic_stage(options(prepared, kinematics, "det_b.h5"));
  const common::H5File a((scratch() / "det_a.h5").string(), common::H5File::Mode::kRead);
  const common::H5File b((scratch() / "det_b.h5").string(), common::H5File::Mode::kRead);
  for (const std::string ds : {"/layers/tibia_medial/pressure", "/layers/femur/surface/fluid_pressure"}) {
    const Eigen::MatrixXd A = a.read_matrix(ds), B = b.read_matrix(ds);
    ASSERT_EQ(A.size(), B.size());
    EXPECT_EQ(std::memcmp(A.data(), B.data(), sizeof(double) * A.size()), 0) << ds;
  }
  for (const std::string ds : {"/layers/femur/displacement", "/layers/tibia_medial/effective_stress"}) {
    const common::Tensor3d A = a.read_tensor3(ds), B = b.read_tensor3(ds);
    ASSERT_EQ(A.data.size(), B.data.size());
    EXPECT_EQ(std::memcmp(A.data.data(), B.data.data(), sizeof(double) * A.data.size()), 0) << ds;
  }
  const Eigen::VectorXd A = a.read_vector("/layers/tibia_medial/series/max_shear_stress");
  const Eigen::VectorXd B = b.read_vector("/layers/tibia_medial/series/max_shear_stress");
  EXPECT_EQ(std::memcmp(A.data(), B.data(), sizeof(double) * A.size()), 0);
}

TEST(BiphasicStage, RefusesAKinematicsFileWithoutTheContactForceSeries) {
  common::set_log_level(common::LogLevel::kError);
  const std::string prepared = write_prepared("prepared_nf.h5");
  KinematicsSpec spec;
  spec.with_medial_force = false;
  const std::string kinematics = write_kinematics("kinematics_nf.h5", spec);
  const auto o = options(prepared, kinematics, "nf.h5");
  try {
    pipelines::run_biphasic_stage(o);
    ADD_FAILURE() << "no error";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("expected the contact-force series /contact/tibiofemoral/medial_force"),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find(kinematics), std::string::npos);
  }
  EXPECT_FALSE(fs::exists(o.out));  // nothing written
}

// A kinematics file whose compartment series are zero at every frame while
// the total is not (stage 1 could not split: one tibial surface without
// split_lateral or prepared compartments, or an older file; constructed here):
// the layers would silently go unloaded, so it is refused.
TEST(BiphasicStage, RefusesZeroSplitForcesWhenTheTotalIsNotZero) {
  common::set_log_level(common::LogLevel::kError);
  const std::string prepared = write_prepared("prepared_us.h5");
  KinematicsSpec spec;
  spec.unsplit = true;
  const std::string kinematics = write_kinematics("kinematics_us.h5", spec);
  const auto o = options(prepared, kinematics, "us.h5");
  try {
    pipelines::run_biphasic_stage(o);
    ADD_FAILURE() << "no error";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/contact/tibiofemoral/medial_force (and the other compartment's) is zero at every frame while "
                                         "/contact/tibiofemoral/force reaches 200 N"),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find(kinematics), std::string::npos);
  }
  EXPECT_FALSE(fs::exists(o.out));  // nothing written
}

TEST(BiphasicStage, LeavesOutFramesWhereStageOneFailed) {
  common::set_log_level(common::LogLevel::kError);
  const std::string prepared = write_prepared("prepared_fail.h5");
  KinematicsSpec spec;
  spec.status[2] = 1;
  const std::string kinematics = write_kinematics("kinematics_fail.h5", spec);
  const auto r = pipelines::run_biphasic_stage(options(prepared, kinematics, "fail.h5"));
  EXPECT_EQ(r.frames, 5);
  EXPECT_EQ(r.frames_failed, 1);
  EXPECT_EQ(r.steps, 5);  // still 0 .. 0.05 s: the neighbours are interpolated
}

TEST(BiphasicStage, RefusesBadThicknessAndPermeability) {
  common::set_log_level(common::LogLevel::kError);
  const std::string kinematics = write_kinematics("kinematics_bad.h5", KinematicsSpec{});
  try {
    pipelines::run_biphasic_stage(options(write_prepared("prepared_zero.h5", 0.0), kinematics, "bad.h5"));
    ADD_FAILURE() << "zero thickness accepted";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("layer 'femur': surface node 0: expected a thickness > 0 m, found 0 m"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW(
      pipelines::run_biphasic_stage(options(write_prepared("prepared_neg.h5", -1e-3), kinematics, "bad.h5")),
      common::InputError);
  auto o = options(write_prepared("prepared_ok.h5"), kinematics, "bad.h5");
  o.permeability_m4_per_Ns = 0.0;
  try {
    pipelines::run_biphasic_stage(o);
    ADD_FAILURE() << "zero permeability accepted";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("permeability: expected a value > 0 m^4/(N s), found 0"), std::string::npos)
        << e.what();
  }
  o.permeability_m4_per_Ns = 3e-15;
  o.layers = {"tibia_medial", "tibia_lateral"};
  EXPECT_THROW(pipelines::run_biphasic_stage(o), common::InputError);  // no femur: no pair
}

TEST(BiphasicStage, CanonicalCaseSatisfiesTheContactConditionsOnBothLayers) {
  // The canonical case (a paraboloid pressed into a flat plate, contact
  // radius sqrt(2 R d) = 3 mm at the end of the ramp): the two layers see the
  // same contact (eq 18: the same prescribed fluid pressure at the apex; the
  // same contact area) up to the discretisation of the contact edge by node
  // areas. Measured at t = 0.5 s: areas 27.1 / 27.0 mm^2 (the circle:
  // 28.3), apex pressures 14.3 / 14.4 MPa. Bounds 2 % between the layers,
  // 10 % against the circle's area (the edge of a 1 mm grid).
  common::set_log_level(common::LogLevel::kError);
  const auto files = pipelines::write_two_layer_case((scratch() / "canonical").string());
  pipelines::BiphasicStageOptions o = options(files.first, files.second, "canonical/out.h5");
  o.end_time_s = 0.5;
  const auto r = pipelines::run_biphasic_stage(o);
  EXPECT_EQ(r.steps, 50);
  const auto& key = r.key_steps[1];  // the largest force in the second half: t = 0.5 s
  ASSERT_EQ(key.layers.size(), 2u);
  const double a0 = key.layers[0].contact_area_m2, a1 = key.layers[1].contact_area_m2;
  EXPECT_NEAR(a0, a1, 0.02 * a1);
  EXPECT_NEAR(a1, biphasic::testing::kPi * 9e-6, 0.1 * biphasic::testing::kPi * 9e-6) << "contact radius 3 mm";
  const double p0 = key.layers[0].max_surface_fluid_pressure_Pa, p1 = key.layers[1].max_surface_fluid_pressure_Pa;
  EXPECT_NEAR(p0, p1, 0.02 * p1);
  EXPECT_NEAR(key.layers[0].fluid_load_support, key.layers[1].fluid_load_support, 1e-3);
  for (const auto& l : r.layers) EXPECT_EQ(l.factorizations, 1);
}

// The scene block and the runner's plan (no stage is run).
TEST(BiphasicStage, SceneBlockAndPlan) {
  const fs::path dir = scratch() / "scene";
  fs::create_directories(dir / "models" / "knee");
  fs::create_directories(dir / "trials" / "walk");
  const std::string head = "model: models/knee\ntrial: trials/walk\noutputs: [biphasic]\n"
                           "comak: {effects: [muscles, tibiofemoral_contact, patellofemoral_contact]}\n";
  const common::Scene scene = pipelines::parse_scene(
      head + "biphasic:\n  effects: [biphasic_layers, penetration_contact]\n  element_layers: 3\n"
             "  time_step_ms: 20\n  aggregate_modulus_mpa: 1.2\n",
      dir / "s.yaml");
  const auto o = common::read_options<pipelines::BiphasicOptions>(scene.block("biphasic"));
  EXPECT_EQ(o.element_layers, 3);
  EXPECT_DOUBLE_EQ(o.time_step_s, 0.02);
  EXPECT_DOUBLE_EQ(o.aggregate_modulus_Pa, 1.2e6);
  EXPECT_DOUBLE_EQ(o.permeability_m4_per_Ns, 3e-15);  // the default
  EXPECT_FALSE(o.end_time_s.has_value());
  const auto plan = pipelines::plan_stages(scene, dir / "out");
  ASSERT_EQ(plan.size(), 3u);
  EXPECT_EQ(plan[0].name, "prepare");
  EXPECT_EQ(plan[1].name, "comak");
  EXPECT_EQ(plan[2].name, "biphasic");
  EXPECT_EQ(plan[2].executable, "arthrosim-biphasic");
  EXPECT_EQ(plan[2].effects, (std::vector<std::string>{"biphasic_layers", "penetration_contact"}));
  EXPECT_EQ(plan[2].outputs.front(), dir / "out" / "biphasic.h5");
  EXPECT_NE(std::find(plan[2].arguments.begin(), plan[2].arguments.end(), "--kinematics"), plan[2].arguments.end());
  // Refusals with the scene's line: one effect missing, no comak block, no trial.
  auto refused = [&](const std::string& text, const std::string& needle) {
    try {
      pipelines::parse_scene(text, dir / "bad.yaml");
      ADD_FAILURE() << "accepted: " << needle;
    } catch (const common::InputError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("bad.yaml:"), std::string::npos) << e.what();
    }
  };
  refused(head + "biphasic: {effects: [biphasic_layers]}\n", "found no penetration_contact");
  refused("model: models/knee\ntrial: trials/walk\noutputs: [biphasic]\nbiphasic: {effects: [biphasic_layers, "
          "penetration_contact]}\n",
          "needs stage 1's kinematics: add a 'comak' block");
  refused(head + "biphasic: {effects: [biphasic_layers, penetration_contact], element_layers: 0}\n",
          "element_layers");
  refused(head + "biphasic: {effects: [biphasic_layers, penetration_contact], layers: [femur, meniscus]}\n",
          "meniscus");
}

}  // namespace
}  // namespace arthrosim
