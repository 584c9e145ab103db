// The surface stage on the bundled knee (coarse model, to keep the test in
// seconds): scenario osmotic of data/scenes/osmotic.yaml, effect accounting
// from the stage's own ledger, and clear errors for effects it cannot build.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/effects.h"
#include "common/error.h"
#include "common/hdf5.h"
#include "common/metadata.h"
#include "pipelines/prepare.h"
#include "pipelines/surface_stage.h"

namespace arthrosim::pipelines {
namespace {

namespace fs = std::filesystem;

std::string work_dir() {
  const fs::path d = fs::path(ARTHROSIM_BINARY_DIR) / "tests" / "surface_stage";
  fs::create_directories(d);
  return d.string();
}

/// Prepared coarse bundled knee (made once per process; prepare takes well
/// under a second on the coarse model).
const std::string& coarse_prepared() {
  static const std::string path = [] {
    const std::string p = work_dir() + "/prepared_coarse.h5";
    PrepareOptions o;
    const PreparedModel m =
        prepare_model(find_model_files(std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/coarse"), o);
    common::RunMetadata md;
    md.program = "surface_stage_test";
    write_prepared_model(m, o, md, p);
    return p;
  }();
  return path;
}

std::string write_scene(const std::string& name, const std::string& body) {
  const std::string p = work_dir() + "/" + name + ".yaml";
  std::ofstream f(p);
  f << "model: " << ARTHROSIM_SOURCE_DIR << "/data/models/knee_parametric/coarse\noutputs: [surface]\n" << body;
  return p;
}

SurfaceStageOptions stage_options(const std::string& scene, const std::string& scenario, const std::string& out) {
  SurfaceStageOptions o;
  o.prepared = coarse_prepared();
  o.scene = scene;
  o.scenario = scenario;
  o.out = work_dir() + "/" + out;
  o.progress = false;
  o.argv = {"surface_stage_test"};
  return o;
}

// The bundled osmotic scenario: the steady state is reached (the residual of
// the last step meets the integrator's tolerance), every value is finite, the
// surface bulges outwards under its internal pressure and stretches (e1 > 0)
// away from the fixed periphery; the ledger holds exactly the listed effects.
TEST(SurfaceStage, BundledOsmoticReachesSteadyStateAndBulgesOutwards) {
  const SurfaceStageOptions o =
      stage_options(std::string(ARTHROSIM_SOURCE_DIR) + "/data/scenes/osmotic.yaml", "osmotic", "osmotic.h5");
  const SurfaceStageResult r = run_surface_stage(o);
  ASSERT_EQ(r.status, SurfaceStageStatus::kCompleted);
  ASSERT_EQ(r.surfaces.size(), 1u);
  const SurfaceSummary& s = r.surfaces[0];
  EXPECT_EQ(s.name, "femur");
  EXPECT_EQ(r.rejected_steps, 0);

  const common::H5File f(o.out, common::H5File::Mode::kRead);
  EXPECT_EQ(f.attribute_string("/", "status"), "completed");
  EXPECT_EQ(f.attribute_string("/", "mode"), "steady_state");
  const Eigen::VectorXd t = f.read_vector("/time");
  ASSERT_EQ(t.size(), 2);  // reference frame and the steady state
  EXPECT_DOUBLE_EQ(t(1), 1.0);
  const Eigen::VectorXd res = f.read_vector("/solver/femur/residual_N");
  const Eigen::VectorXd tol = f.read_vector("/solver/femur/residual_tolerance_N");
  ASSERT_GE(res.size(), 1);
  EXPECT_LE(res(res.size() - 1), tol(tol.size() - 1));
  EXPECT_GT(f.read_vector_int("/solver/femur/newton_iterations")(0), 1);

  const Eigen::MatrixXd w = f.read_matrix("/surfaces/femur/deflection");  // frames x N
  const common::Tensor3d E = f.read_tensor3("/surfaces/femur/strain/E");
  const Eigen::MatrixXd e1 = f.read_matrix("/surfaces/femur/strain/e1");
  const Eigen::MatrixXd e2 = f.read_matrix("/surfaces/femur/strain/e2");
  const common::Tensor3d dir = f.read_tensor3("/surfaces/femur/strain/e1_dir");
  const Eigen::VectorXi fixed = f.read_vector_int("/surfaces/femur/fixed");
  const int N = static_cast<int>(fixed.size());
  ASSERT_EQ(w.cols(), N);
  ASSERT_TRUE(w.allFinite() && e1.allFinite() && e2.allFinite());
  // Frame 0 is the reference: no deflection, no strain (round-off only).
  EXPECT_LT(w.row(0).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_LT(e1.row(0).cwiseAbs().maxCoeff(), 1e-12);
  int interior = 0, stretched = 0, outward = 0;
  double mean_w = 0;
  for (int i = 0; i < N; ++i) {
    ASSERT_NEAR(Eigen::Vector3d(dir(1, i, 0), dir(1, i, 1), dir(1, i, 2)).norm(), 1.0, 1e-12);
    ASSERT_GE(e1(1, i), e2(1, i));
    ASSERT_TRUE(std::isfinite(E(1, i, 0)) && std::isfinite(E(1, i, 1)) && std::isfinite(E(1, i, 2)));
    if (fixed(i)) {
      EXPECT_EQ(w(1, i), 0.0);
      continue;
    }
    ++interior;
    stretched += e1(1, i) > 0;
    outward += w(1, i) > 0;
    mean_w += w(1, i);
  }
  mean_w /= interior;
  std::printf("osmotic coarse femur: %d nodes (%d free), max deflection %.4g mm, mean %.4g mm, e1 %.4g .. %.4g, "
              "e1 > 0 at %d/%d free nodes, outward at %d/%d, residual %.3g N (tolerance %.3g N), %ld Newton "
              "iterations, wall %.1f s\n",
              N, interior, s.max_deflection_m * 1e3, mean_w * 1e3, s.e1_min, s.e1_max, stretched, interior, outward,
              interior, s.final_residual_N, s.residual_tolerance_N, r.newton_iterations, r.wall_s);
  EXPECT_GT(s.max_deflection_m, 0.0);  // the extreme deflection is outwards
  EXPECT_GT(mean_w, 0.0);
  EXPECT_EQ(stretched, interior);  // e1 > 0 at every free node
  EXPECT_NEAR(f.attribute_double("/surfaces/femur", "max_deflection_m"), s.max_deflection_m, 0.0);

  const common::EffectLedger ledger = common::read_effect_ledger(f);
  for (const char* e : {"foundation_springs", "foundation_damping", "osmotic_pressure", "periphery_fixed", "inertia"})
    EXPECT_TRUE(ledger.built(e)) << e;
  EXPECT_FALSE(ledger.built("mesh_contact"));
  EXPECT_FALSE(ledger.built("imposed_kinematics"));
  EXPECT_EQ(ledger.count("foundation_springs"), N);  // one spring per node
  EXPECT_EQ(ledger.count("periphery_fixed"), fixed.sum());
}

// A scenario without osmotic_pressure never builds the pressure term (and the
// state without load stays the reference).
TEST(SurfaceStage, NoPressureTermWhenNotListed) {
  const std::string scene = write_scene("no_pressure", R"(surface:
  scenarios:
    rest:
      surfaces: [tibia_medial, tibia_lateral]
      end_time_s: 1e-3
      time_step_s: 5e-4
      output_interval_ms: 0.5
      effects: [foundation_springs, periphery_fixed]
)");
  const SurfaceStageOptions o = stage_options(scene, "rest", "no_pressure.h5");
  const SurfaceStageResult r = run_surface_stage(o);
  ASSERT_EQ(r.status, SurfaceStageStatus::kCompleted);
  const common::H5File f(o.out, common::H5File::Mode::kRead);
  EXPECT_EQ(f.attribute_string("/", "mode"), "quasi_static");  // no inertia listed
  EXPECT_EQ(f.read_vector("/time").size(), 3);                  // 0, 0.5 ms, 1 ms
  const common::EffectLedger ledger = common::read_effect_ledger(f);
  EXPECT_FALSE(ledger.built("osmotic_pressure"));
  EXPECT_FALSE(ledger.built("foundation_damping"));
  EXPECT_FALSE(ledger.built("inertia"));
  EXPECT_TRUE(ledger.built("foundation_springs"));
  for (const auto& s : r.surfaces) EXPECT_LT(std::abs(s.max_deflection_m), 1e-12) << s.name;
}

// Effects this build cannot simulate stop the run before anything is
// written, naming the effect: never silently ignored.
TEST(SurfaceStage, UnsupportedEffectStopsWithClearError) {
  const std::string scene = write_scene("contact", R"(surface:
  scenarios:
    touch:
      surfaces: [femur]
      end_time_s: 1e-3
      effects: [foundation_springs, periphery_fixed, mesh_contact]
)");
  const SurfaceStageOptions o = stage_options(scene, "touch", "contact.h5");
  fs::remove(o.out);
  try {
    run_surface_stage(o);
    FAIL() << "mesh_contact must not be accepted";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("mesh_contact"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.out));
}

TEST(SurfaceStage, UnknownSurfaceNamesWhatThePreparedModelHas) {
  const std::string scene = write_scene("unknown_surface", R"(surface:
  scenarios:
    s:
      surfaces: [femoral]
      end_time_s: 1e-3
      effects: [periphery_fixed]
)");
  try {
    run_surface_stage(stage_options(scene, "s", "unknown.h5"));
    FAIL();
  } catch (const common::InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("femoral"), std::string::npos) << m;
    EXPECT_NE(m.find("tibia_medial"), std::string::npos) << m;
  }
}

}  // namespace
}  // namespace arthrosim::pipelines
