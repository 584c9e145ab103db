// The surface stage on the bundled knee (coarse model, to keep the test in
// seconds): scenario osmotic of data/scenes/osmotic.yaml, effect accounting
// from the stage's own ledger, and clear errors for effects it cannot build.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <sstream>
#include <tuple>

#include <Eigen/SparseCore>
#include <unsupported/Eigen/SparseExtra>

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

/// Prepared coarse bundled knee (made once per process, under a file named
/// after the test so that CTest's parallel processes never share it; prepare
/// takes well under a second on the coarse model).
const std::string& coarse_prepared() {
  static const std::string path = [] {
    const std::string p = work_dir() + "/prepared_coarse_" +
                          ::testing::UnitTest::GetInstance()->current_test_info()->name() + ".h5";
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
  const Eigen::VectorXd res = f.read_vector("/solver/residual_N");
  const Eigen::VectorXd tol = f.read_vector("/solver/residual_tolerance_N");
  ASSERT_GE(res.size(), 1);
  EXPECT_LE(res(res.size() - 1), tol(tol.size() - 1));
  EXPECT_GT(f.read_vector_int("/solver/newton_iterations")(0), 1);

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

  // XDMF sidecar (same stem): a temporal collection with one femur grid per
  // frame, each carrying the six per-frame fields of docs/surface_output.md.
  std::string x = o.out;
  x.replace(x.rfind(".h5"), 3, ".xdmf");
  std::ifstream xin(x);
  ASSERT_TRUE(xin.good()) << x;
  const std::string xml((std::istreambuf_iterator<char>(xin)), std::istreambuf_iterator<char>());
  auto count = [&xml](const std::string& needle) {
    int c = 0;
    for (auto p = xml.find(needle); p != std::string::npos; p = xml.find(needle, p + 1)) ++c;
    return c;
  };
  EXPECT_EQ(count("CollectionType=\"Temporal\""), 1);
  EXPECT_EQ(count("<Time Value="), 2);  // the reference and the steady state
  for (const char* field : {"displacement", "deflection", "E", "e1", "e1_dir", "e2"})
    EXPECT_EQ(count(std::string("<Attribute Name=\"") + field + "\""), 2) << field;
  EXPECT_GE(count("/surfaces/femur/strain/e1_dir"), 2);
  EXPECT_GE(count("Quadrilateral"), 2);
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

// osmotic_surfaces: the pressure term is built on the listed surfaces only
// (the ledger counts one term per loaded quad), the others stay unloaded; a
// name that is not simulated stops with the scene line.
TEST(SurfaceStage, OsmoticPressureOnTheListedSurfacesOnly) {
  const std::string scene = write_scene("osmotic_some", R"(surface:
  scenarios:
    swell:
      surfaces: [tibia_medial, tibia_lateral]
      osmotic_surfaces: [tibia_lateral]
      steady_state: true
      end_time_s: 1.0
      foundation_stiffness_n_per_mm3: 5
      effects: [foundation_springs, osmotic_pressure, periphery_fixed]
)");
  const SurfaceStageOptions o = stage_options(scene, "swell", "osmotic_some.h5");
  const SurfaceStageResult r = run_surface_stage(o);
  ASSERT_EQ(r.status, SurfaceStageStatus::kCompleted);
  const common::H5File f(o.out, common::H5File::Mode::kRead);
  const common::EffectLedger ledger = common::read_effect_ledger(f);
  const long lateral_quads = f.read_matrix_int("/surfaces/tibia_lateral/quads").rows();
  EXPECT_EQ(ledger.count("osmotic_pressure"), lateral_quads);
  for (const auto& s : r.surfaces) {
    std::printf("%s: max deflection %.4e m\n", s.name.c_str(), s.max_deflection_m);
    if (s.name == "tibia_medial") { EXPECT_LT(std::abs(s.max_deflection_m), 1e-12); }
    if (s.name == "tibia_lateral") { EXPECT_GT(std::abs(s.max_deflection_m), 1e-6); }
  }
  const std::string bad = write_scene("osmotic_bad", R"(surface:
  scenarios:
    swell:
      surfaces: [tibia_medial]
      osmotic_surfaces: [femur]
      steady_state: true
      end_time_s: 1.0
      effects: [foundation_springs, osmotic_pressure, periphery_fixed]
)");
  try {
    run_surface_stage(stage_options(bad, "swell", "osmotic_bad.h5"));
    FAIL() << "an osmotic surface that is not simulated must not be accepted";
  } catch (const common::InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("osmotic surface 'femur'"), std::string::npos) << m;
    EXPECT_NE(m.find("osmotic_bad.yaml:7:"), std::string::npos) << m;  // the osmotic_surfaces line
  }
}

// The dynamic osmotic path with the opt-in keys (osmotic_ramp_s,
// steady_state_change_mm, newton_reuse_factorization): the bundled osmotic
// scenario's effects on the coarse lateral tibial cartilage (the smallest
// surface of the smallest prepared knee the tests use; the femur takes ten
// times longer), HHT alpha -0.2 from rest with dt 1e-3 s, the
// pressure ramped over 10 ms and foundation damping 7e6 N s/m^3 (the value
// docs/shell_element.md section 4 uses; the seed's printed 7e6 N s/mm^3 has
// c/k = 1e7 s), must stop by itself at the steady state, and its deflection
// must equal the direct steady-state solve (steady_state: true) of the same
// scenario. Tolerance: when the stop fires the step change is at most
// tol = 1e-6 mm; if the transient then decays by a factor rho per step, the
// distance still to go is at most change rho / (1 - rho) per coordinate
// (numerics::HhtIntegrator::advance_to_steady_state); rho is measured from the run's
// last recorded changes (/solver/change_m) and the deflection (a projection
// of the position change, so bounded by sqrt(3) x the largest coordinate
// change) gets that bound x 2 for the rho estimate, plus 1e-12 m for the two
// Newton solves (relative tolerance 1e-8 of sub-millimetre changes). A run
// too short for the stop says so: stop_reason "end_time".
TEST(SurfaceStage, DynamicOsmoticStopsAtTheStaticSteadyState) {
  const std::string body = R"(surface:
  scenarios:
    static:
      surfaces: [tibia_lateral]
      end_time_s: 1.0
      steady_state: true
      effects: [foundation_springs, foundation_damping, osmotic_pressure, periphery_fixed, inertia]
    dynamic:
      surfaces: [tibia_lateral]
      end_time_s: 1.0
      time_step_s: 1e-3
      output_interval_ms: 5
      foundation_damping_n_s_per_mm3: 7e-3
      osmotic_ramp_s: 0.01
      steady_state_change_mm: 1e-6
      newton_reuse_factorization: true
      effects: [foundation_springs, foundation_damping, osmotic_pressure, periphery_fixed, inertia]
    short:
      surfaces: [tibia_lateral]
      end_time_s: 0.01
      time_step_s: 1e-3
      foundation_damping_n_s_per_mm3: 7e-3
      osmotic_ramp_s: 0.01
      steady_state_change_mm: 1e-6
      effects: [foundation_springs, foundation_damping, osmotic_pressure, periphery_fixed, inertia]
)";
  const std::string scene = write_scene("osmotic_dynamic", body);
  const SurfaceStageOptions os = stage_options(scene, "static", "osmotic_dyn_static.h5");
  const SurfaceStageResult rs = run_surface_stage(os);
  ASSERT_EQ(rs.status, SurfaceStageStatus::kCompleted);
  EXPECT_FALSE(rs.steady_state_stop);
  const SurfaceStageOptions od = stage_options(scene, "dynamic", "osmotic_dyn.h5");
  const SurfaceStageResult rd = run_surface_stage(od);
  ASSERT_EQ(rd.status, SurfaceStageStatus::kCompleted);
  EXPECT_TRUE(rd.steady_state_stop);
  ASSERT_TRUE(rd.steady_state_reached);
  EXPECT_GT(rd.stop_time_s, 0.01);  // never before the end of the ramp
  EXPECT_LT(rd.stop_time_s, 1.0);
  EXPECT_LE(rd.last_change_m, 1e-9);
  EXPECT_EQ(rd.rejected_steps, 0);

  const common::H5File fs_(os.out, common::H5File::Mode::kRead), fd(od.out, common::H5File::Mode::kRead);
  EXPECT_FALSE(fs_.exists("/solver/change_m"));  // keys off: nothing new written
  EXPECT_FALSE(fs_.has_attribute("/solver", "stop_reason"));
  EXPECT_EQ(fd.attribute_string("/", "mode"), "hht");
  EXPECT_EQ(fd.attribute_string("/", "status"), "completed");
  EXPECT_EQ(fd.attribute_string("/solver", "stop_reason"), "steady_state");
  EXPECT_DOUBLE_EQ(fd.attribute_double("/solver", "stop_time_s"), rd.stop_time_s);
  EXPECT_DOUBLE_EQ(fd.attribute_double("/solver", "last_change_m"), rd.last_change_m);
  EXPECT_DOUBLE_EQ(fd.attribute_double("/solver", "steady_state_change_tol_m"), 1e-9);
  EXPECT_DOUBLE_EQ(fd.attribute_double("/", "osmotic_ramp_s"), 0.01);
  const Eigen::VectorXd t = fd.read_vector("/time"), ts = fd.read_vector("/solver/time");
  const Eigen::VectorXd change = fd.read_vector("/solver/change_m");
  ASSERT_EQ(ts.size(), rd.steps);
  ASSERT_EQ(change.size(), rd.steps);
  EXPECT_DOUBLE_EQ(t(t.size() - 1), rd.stop_time_s);  // the last frame is the steady state
  EXPECT_DOUBLE_EQ(ts(ts.size() - 1), rd.stop_time_s);
  EXPECT_DOUBLE_EQ(change(change.size() - 1), rd.last_change_m);
  // Every earlier step past the ramp changed by more than the tolerance.
  for (Eigen::Index k = 0; k + 1 < change.size(); ++k)
    if (ts(k) >= 0.01) { EXPECT_GT(change(k), 1e-9) << "step " << k; }
  ASSERT_GE(change.size(), 4);
  double rho = 0;
  for (Eigen::Index k = change.size() - 3; k < change.size(); ++k) rho = std::max(rho, change(k) / change(k - 1));
  ASSERT_LT(rho, 1.0);
  const double tol = 2 * std::sqrt(3.0) * rd.last_change_m * rho / (1 - rho) + 1e-12;

  const Eigen::MatrixXd ws = fs_.read_matrix("/surfaces/tibia_lateral/deflection");
  const Eigen::MatrixXd wd = fd.read_matrix("/surfaces/tibia_lateral/deflection");
  ASSERT_EQ(ws.cols(), wd.cols());
  const double diff = (wd.row(wd.rows() - 1) - ws.row(ws.rows() - 1)).cwiseAbs().maxCoeff();
  const double wmax = ws.row(ws.rows() - 1).cwiseAbs().maxCoeff();
  std::printf("dynamic osmotic (coarse lateral tibia): stopped at t = %.4g s after %ld steps (%ld Newton iterations, %ld "
              "factorizations), last change %.3g m, rho %.3g; max |w_dyn - w_static| %.3g m (bound %.3g m) of max "
              "|w| %.4g m\n",
              rd.stop_time_s, rd.steps, rd.newton_iterations, rd.factorizations, rd.last_change_m, rho, diff, tol,
              wmax);
  EXPECT_GT(wmax, 1e-6);
  EXPECT_LE(diff, tol);
  // Factorisation reuse: fewer factorisations than Newton iterations.
  EXPECT_LT(rd.factorizations, rd.newton_iterations);

  // Too short a run: end_time_s comes first, and the output says so.
  const SurfaceStageOptions oq = stage_options(scene, "short", "osmotic_dyn_short.h5");
  const SurfaceStageResult rq = run_surface_stage(oq);
  EXPECT_TRUE(rq.steady_state_stop);
  EXPECT_FALSE(rq.steady_state_reached);
  EXPECT_GT(rq.last_change_m, 1e-9);
  const common::H5File fq(oq.out, common::H5File::Mode::kRead);
  EXPECT_EQ(fq.attribute_string("/solver", "stop_reason"), "end_time");
  EXPECT_DOUBLE_EQ(fq.attribute_double("/solver", "stop_time_s"), 0.01);
}

// Scenario `scenario` of `scene` is refused with an input error whose message
// names `needle`, before its output file (removed first) is written.
void expect_refused(const std::string& scene, const std::string& scenario, const std::string& out,
                    const std::string& needle) {
  const SurfaceStageOptions o = stage_options(scene, scenario, out);
  fs::remove(o.out);
  try {
    run_surface_stage(o);
    ADD_FAILURE() << scenario << " must not be accepted";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.out)) << scenario;
}

// The opt-in keys are refused where they cannot apply: the stop with the
// direct steady-state solve, a ramp longer than the run. (A scene is checked
// whole when it is read, so each bad scenario has a scene of its own.)
TEST(SurfaceStage, DynamicOsmoticKeysRefusedWhereMeaningless) {
  const std::string stop_static = write_scene("osmotic_dynamic_bad_stop", R"(surface:
  scenarios:
    stop_static:
      surfaces: [femur]
      end_time_s: 1.0
      steady_state: true
      steady_state_change_mm: 1e-6
      effects: [foundation_springs, osmotic_pressure, periphery_fixed]
)");
  const std::string long_ramp = write_scene("osmotic_dynamic_bad_ramp", R"(surface:
  scenarios:
    long_ramp:
      surfaces: [femur]
      end_time_s: 0.01
      time_step_s: 1e-3
      osmotic_ramp_s: 0.02
      effects: [foundation_springs, osmotic_pressure, periphery_fixed]
)");
  expect_refused(stop_static, "stop_static", "osmotic_dynamic_bad_stop_static.h5", "steady_state_change_mm");
  expect_refused(long_ramp, "long_ramp", "osmotic_dynamic_bad_long_ramp.h5", "osmotic_ramp_s");
}

// mesh_contact needs both surfaces of each contact pair: a scenario that
// simulates only one of them stops before anything is written, naming the
// pair.
TEST(SurfaceStage, ContactPairWithoutItsSurfacesStopsWithClearError) {
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
    FAIL() << "a contact pair with an unsimulated surface must not be accepted";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("femur:tibia_medial"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.out));
}

// contact_vertex_weights: faded is the fade_inside fade's own weighting and
// gives rim nodes their own weight: with contact_rim_vertices or the
// rim_contacts treatment it stops before anything is written, naming what
// conflicts.
TEST(SurfaceStage, FadedVertexWeightsRefusedWithConflictingRimKeys) {
  const std::string rim_vertices = write_scene("faded_weights_bad_rim_vertices", R"(surface:
  scenarios:
    with_rim_vertices:
      end_time_s: 1e-3
      contact_vertex_weights: faded
      contact_rim_vertices: true
      effects: [foundation_springs, periphery_fixed, mesh_contact]
)");
  const std::string rim_contacts = write_scene("faded_weights_bad_rim_contacts", R"(surface:
  scenarios:
    with_rim_contacts:
      end_time_s: 1e-3
      contact_vertex_weights: faded
      contact_rim: rim_contacts
      effects: [foundation_springs, periphery_fixed, mesh_contact]
)");
  expect_refused(rim_vertices, "with_rim_vertices", "faded_weights_bad_rim_vertices.h5", "contact_rim_vertices");
  expect_refused(rim_contacts, "with_rim_contacts", "faded_weights_bad_rim_contacts.h5", "fade_inside");
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

// imposed_kinematics: a kinematics file (docs/kinematics_file.md layout)
// moving the tibia rigidly (10 degrees about an oblique axis and 2 mm) over
// 1 ms. With the periphery fixed to the bone and the foundation moving with
// it, the quasi-static solution is the rigid motion itself: displacement
// X(t) X(0)^-1 r0 - r0 at every node and zero strain (SVK is frame
// invariant). Tolerance 1e-9 m: Newton's increment tolerance is 1e-8 relative
// on mm-sized motions.
TEST(SurfaceStage, ImposedKinematicsMoveTheSurfaceRigidly) {
  const std::string kin_path = work_dir() + "/kinematics_rigid.h5";
  Eigen::Isometry3d X1 = Eigen::Isometry3d::Identity();
  X1.linear() = Eigen::AngleAxisd(10 * M_PI / 180, Eigen::Vector3d(1, 2, 0.5).normalized()).toRotationMatrix();
  X1.translation() << 0.002, -0.001, 0.0005;
  {
    common::H5File k(kin_path, common::H5File::Mode::kTruncate);
    k.set_attribute("/", "format", "arthrosim kinematics file");  // a finished run (common/file_check.h)
    k.set_attribute("/", "format_version", 1);
    k.set_attribute("/", "frames", 3);
    k.write("/time", std::vector<double>{0.2, 0.2005, 0.201});
    std::vector<double> tib, fem;
    for (int f = 0; f < 3; ++f) {
      // Frame 1 halfway (slerp/linear); frame 0 the identity.
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      if (f == 1) {
        const Eigen::AngleAxisd aa(X1.linear());
        X.linear() = Eigen::AngleAxisd(0.5 * aa.angle(), aa.axis()).toRotationMatrix();
        X.translation() = 0.5 * X1.translation();
      }
      if (f == 2) X = X1;
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
          tib.push_back(X.matrix()(i, j));
          fem.push_back(i == j ? 1.0 : 0.0);
        }
    }
    k.write_tensor3("/bodies/tibia/X_W", {3, 4, 4}, tib);
    k.write_tensor3("/bodies/femur/X_W", {3, 4, 4}, fem);
  }
  // The scene parser requires a comak block and a trial for imposed_kinematics
  // (the runner would run COMAK); the stage itself reads only the file given.
  const std::string scene = write_scene("moving", "trial: " + std::string(ARTHROSIM_SOURCE_DIR) +
                                                      "/data/trials/synthetic_gait\ncomak: {effects: [ligaments]}\n" +
                                                      R"(surface:
  scenarios:
    moving:
      surfaces: [tibia_medial]
      time_step_s: 2.5e-4
      output_interval_ms: 0.5
      seating_time_s: 0
      effects: [foundation_springs, periphery_fixed, imposed_kinematics]
)");
  SurfaceStageOptions o = stage_options(scene, "moving", "moving.h5");
  o.kinematics = kin_path;
  const SurfaceStageResult r = run_surface_stage(o);
  ASSERT_EQ(r.status, SurfaceStageStatus::kCompleted);
  const common::H5File f(o.out, common::H5File::Mode::kRead);
  const Eigen::VectorXd t = f.read_vector("/time");
  ASSERT_EQ(t.size(), 3);  // the kinematics file's duration, 1 ms
  EXPECT_NEAR(t(2), 1e-3, 1e-15);
  const Eigen::MatrixXd X0 = f.read_matrix("/surfaces/tibia_medial/nodes");
  const common::Tensor3d u = f.read_tensor3("/surfaces/tibia_medial/displacement");
  const Eigen::MatrixXd e1 = f.read_matrix("/surfaces/tibia_medial/strain/e1");
  const Eigen::MatrixXd e2 = f.read_matrix("/surfaces/tibia_medial/strain/e2");
  double err = 0, moved = 0;
  for (int i = 0; i < X0.rows(); ++i) {
    const Eigen::Vector3d r0 = X0.row(i).transpose();
    // Displacements are written relative to the bone's rigid motion: a
    // surface carried rigidly by its bone has none.
    const Eigen::Vector3d rigid = X1 * r0 - r0;
    const Eigen::Vector3d got(u(2, i, 0), u(2, i, 1), u(2, i, 2));
    err = std::max(err, got.norm());
    moved = std::max(moved, rigid.norm());
  }
  std::printf("rigid tibia motion: %ld steps, %ld Newton iterations, %ld rejected, wall %.2f s; max |u - u_rigid| "
              "%.3g m (max motion %.3g m), max |e| %.3g\n",
              r.steps, r.newton_iterations, r.rejected_steps, r.wall_s, err, moved,
              std::max(e1.row(2).cwiseAbs().maxCoeff(), e2.row(2).cwiseAbs().maxCoeff()));
  EXPECT_GT(moved, 1e-3);
  EXPECT_LT(err, 1e-9);
  EXPECT_LT(e1.row(2).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT(e2.row(2).cwiseAbs().maxCoeff(), 1e-9);
  const common::EffectLedger ledger = common::read_effect_ledger(f);
  EXPECT_EQ(ledger.count("imposed_kinematics"), 1);
  EXPECT_FALSE(ledger.built("mesh_contact"));
  EXPECT_FALSE(ledger.built("osmotic_pressure"));
  const Eigen::VectorXd trial_t = f.read_vector("/trial_time");
  EXPECT_NEAR(trial_t(0), 0.2, 1e-15);  // trial time of frame 0: the first kinematics frame
  // Without --kinematics the scenario cannot run.
  o.kinematics.clear();
  EXPECT_THROW(run_surface_stage(o), common::InputError);
}

/// Runs build/bin/arthrosim-surface (the executable, as a user would) and
/// returns its exit code; env: an environment assignment ("NAME=value") in front, if any.
int run_executable(const std::string& args, const std::string& env = "") {
  const std::string exe = std::string(ARTHROSIM_BINARY_DIR) + "/bin/arthrosim-surface";
  EXPECT_TRUE(fs::exists(exe)) << exe << " not built";
  return std::system(((env.empty() ? "" : env + " ") + exe + " --quiet " + args + " > /dev/null 2>&1").c_str());
}

/// OBJ of an L x W plate (mm), nx x 1 quads in z = 0.
std::string write_plate_obj(const std::string& name, int nx, double L_mm, double W_mm) {
  const std::string p = work_dir() + "/" + name + ".obj";
  std::ofstream f(p);
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i <= nx; ++i) f << "v " << i * L_mm / nx << " " << j * W_mm << " 0\n";
  for (int i = 0; i < nx; ++i) f << "f " << i + 1 << " " << i + 2 << " " << nx + i + 3 << " " << nx + i + 2 << "\n";
  return p;
}

// Diagnostic hook of numerics::SparseDirectSolver (tests/benchmarks/factorization_bench.cc):
// ARTHROSIM_SAVE_TANGENT=N:FILE saves the N-th factorised matrix in Matrix
// Market form. On the bundled cantilever (17 x 2 nodes, 6 coordinates each,
// 4 factorisations) the first one is the Newton matrix at the reference
// state: 204 x 204, and symmetric (fixed point loads, no follower term; the
// element tangent is assembled from its lower half, so to round-off). A
// malformed value stops the program with a non-zero exit code; an N beyond
// the run's factorisations writes nothing.
TEST(SurfaceStageGeneric, SaveTangentHookWritesTheRequestedMatrix) {
  const std::string scene = std::string(ARTHROSIM_SOURCE_DIR) + "/data/scenes/cantilever_plate.yaml";
  const std::string mtx = work_dir() + "/tangent_1.mtx", none = work_dir() + "/tangent_99.mtx";
  fs::remove(mtx);
  fs::remove(none);
  auto run_with = [&](const std::string& value, const std::string& out) {
    return run_executable("--scene " + scene + " --out " + out, "ARTHROSIM_SAVE_TANGENT='" + value + "'");
  };
  ASSERT_EQ(run_with("1:" + mtx, work_dir() + "/cantilever_save.h5"), 0);
  Eigen::SparseMatrix<double> K;
  ASSERT_TRUE(Eigen::loadMarket(K, mtx)) << mtx;
  EXPECT_EQ(K.rows(), 204);
  EXPECT_EQ(K.cols(), 204);
  const Eigen::SparseMatrix<double> Kt = K.transpose();
  EXPECT_LT((K - Kt).norm(), 1e-12 * K.norm());
  EXPECT_EQ(run_with("99:" + none, work_dir() + "/cantilever_save99.h5"), 0);
  EXPECT_FALSE(fs::exists(none));
  EXPECT_NE(run_with("first", work_dir() + "/cantilever_save_bad.h5"), 0);
  EXPECT_NE(run_with("0:" + none, work_dir() + "/cantilever_save_bad.h5"), 0);
}

// Generic case through the executable: the bundled cantilever plate scene
// (data/scenes/cantilever_plate.yaml), and the same plate refined, against
// Euler-Bernoulli beam theory w = P L^3 / (3 E I) (nu = 0: the one-element
// wide strip is a beam; shear adds (E / kG)(t/L)^2 ~ 2e-4 relative,
// geometric nonlinearity ~ (w/L)^2 = 1e-6).
TEST(SurfaceStageGeneric, CantileverPlateTipDeflectionMatchesBeamTheory) {
  const double L = 0.1, W = 0.01, t = 1e-3, E = 400e6, P = 1e-4;
  const double w_beam = P * L * L * L / (3 * E * W * t * t * t / 12);
  {
    const std::string out = work_dir() + "/cantilever_bundled.h5";
    ASSERT_EQ(run_executable("--scene " + std::string(ARTHROSIM_SOURCE_DIR) +
                             "/data/scenes/cantilever_plate.yaml --out " + out),
              0);
    const common::H5File f(out, common::H5File::Mode::kRead);
    const Eigen::MatrixXd w = f.read_matrix("/surfaces/cantilever_plate/deflection");
    const double w_tip = w(1, 16);  // node (16, 0): the tip
    std::printf("bundled cantilever (16 quads): tip %.6g m, beam %.6g m, error %.3g%%\n", w_tip, w_beam,
                100 * (w_tip / w_beam - 1));
    EXPECT_NEAR(w_tip / w_beam, 1.0, 5e-3);
    const common::EffectLedger ledger = common::read_effect_ledger(f);
    EXPECT_EQ(ledger.count("fixed_nodes"), 2);
    EXPECT_EQ(ledger.count("point_loads"), 2);
    EXPECT_FALSE(ledger.built("foundation_springs"));
    EXPECT_FALSE(ledger.built("periphery_fixed"));
  }
  std::vector<double> errors;
  for (int nx : {2, 4, 8}) {
    const std::string name = "cantilever_" + std::to_string(nx);
    write_plate_obj(name, nx, 100, 10);
    const std::string scene = write_scene(name, "surface:\n  scenarios:\n    c:\n      mesh: " + name +
                                                    ".obj\n      poisson_ratio: 0\n      end_time_s: 1\n"
                                                    "      steady_state: true\n"
                                                    "      fixed_box_mm: [-0.001, -1, -1, 0.001, 11, 1]\n"
                                                    "      load_box_mm: [99.999, -1, -1, 100.001, 11, 1]\n"
                                                    "      point_load_n: [0, 0, 1e-4]\n"
                                                    "      effects: [fixed_nodes, point_loads]\n");
    const std::string out = work_dir() + "/" + name + ".h5";
    ASSERT_EQ(run_executable("--scene " + scene + " --out " + out), 0);
    const common::H5File f(out, common::H5File::Mode::kRead);
    const Eigen::MatrixXd w = f.read_matrix("/surfaces/" + name + "/deflection");
    errors.push_back(std::abs(w(1, nx) / w_beam - 1));
    std::printf("cantilever %d quads: tip %.6g m, relative error %.3g\n", nx, w(1, nx), errors.back());
  }
  for (size_t i = 1; i < errors.size(); ++i) {
    const double rate = std::log2(errors[i - 1] / errors[i]);
    std::printf("  observed rate %.2f\n", rate);
    EXPECT_GT(rate, 1.5);  // second order expected for the bilinear element's bending
  }
}

/// OBJ of an n x n plate of side a (mm) in z = 0, node (i, j) = j (n+1) + i.
std::string write_square_obj(const std::string& name, int n, double a_mm) {
  const std::string p = work_dir() + "/" + name + ".obj";
  std::ofstream f(p);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) f << "v " << i * a_mm / n << " " << j * a_mm / n << " 0\n";
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i + 1;
      f << "f " << a << " " << a + 1 << " " << a + n + 2 << " " << a + n + 1 << "\n";
    }
  return p;
}

// The dynamic (HHT) path: a 40 mm square plate (10 x 10 quads) with its periphery fixed on the
// foundation, inertia on, pressure -0.07 MPa (towards the bone) ramped over
// 5 ms, HHT alpha -0.2, dt 1e-4 s. Far from the edge (20 mm >> the bending
// length (D/k)^(1/4) = 2.7 mm) the deflection is -p/k = -0.1 mm. The ramp is
// slow against the foundation mode (omega = sqrt(k / (rho t)) = 2.6e4 rad/s,
// 1/(omega T) = 0.8%) and HHT damps that mode strongly (omega dt = 2.6), so the
// lag at the end of the ramp is below 1%: tolerance 2%.
TEST(SurfaceStageGeneric, HhtPlateOnFoundationSettlesAtPOverK) {
  write_square_obj("foundation_plate", 10, 40);
  const std::string scene = write_scene("foundation_plate", R"(surface:
  scenarios:
    dyn:
      mesh: foundation_plate.obj
      end_time_s: 5e-3
      time_step_s: 1e-4
      output_interval_ms: 1
      pressure_mpa: -0.07
      effects: [foundation_springs, periphery_fixed, pressure, inertia]
)");
  SurfaceStageOptions o = stage_options(scene, "dyn", "foundation_plate.h5");
  const SurfaceStageResult r = run_surface_stage(o);
  ASSERT_EQ(r.status, SurfaceStageStatus::kCompleted);
  const common::H5File f(o.out, common::H5File::Mode::kRead);
  EXPECT_EQ(f.attribute_string("/", "mode"), "hht");
  EXPECT_EQ(f.read_vector("/time").size(), 6);  // 0, 1, ..., 5 ms
  EXPECT_EQ(f.read_vector("/solver/time").size(), r.steps);
  EXPECT_EQ(r.steps, 50);
  const Eigen::MatrixXd w = f.read_matrix("/surfaces/foundation_plate/deflection");
  const double w_center = w(5, 5 * 11 + 5), expected = -0.07e6 / 0.7e9;
  std::printf("HHT plate on foundation: centre deflection %.6g m, -p/k %.6g m, %ld steps, %ld Newton iterations\n",
              w_center, expected, r.steps, r.newton_iterations);
  EXPECT_NEAR(w_center / expected, 1.0, 0.02);
  const common::EffectLedger ledger = common::read_effect_ledger(f);
  EXPECT_TRUE(ledger.built("inertia"));
  EXPECT_TRUE(ledger.built("pressure"));
  EXPECT_FALSE(ledger.built("osmotic_pressure"));
  EXPECT_FALSE(ledger.built("foundation_damping"));
}

// The same 8-quad cantilever given as legacy VTK (with a POINT_DATA section
// after the geometry) and as OBJ: identical meshes, so bit-identical tip
// deflections; a triangle in the VTK file is an error naming file:line.
TEST(SurfaceStageGeneric, VtkQuadMeshGivesTheSameResultAsObj) {
  write_plate_obj("cant_obj", 8, 100, 10);
  {
    std::ofstream f(work_dir() + "/cant_vtk.vtk");
    f << "# vtk DataFile Version 3.0\nplate\nASCII\nDATASET POLYDATA\nPOINTS 18 double\n";
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i <= 8; ++i) f << i * 12.5 << " " << j * 10.0 << " 0\n";
    f << "POLYGONS 8 40\n";
    for (int i = 0; i < 8; ++i) f << "4 " << i << " " << i + 1 << " " << i + 10 << " " << i + 9 << "\n";
    f << "POINT_DATA 18\nSCALARS s double 1\nLOOKUP_TABLE default\n";
    for (int i = 0; i < 18; ++i) f << "0\n";
  }
  std::vector<double> tips;
  for (const std::string name : {"cant_obj", "cant_vtk"}) {
    const std::string ext = name == "cant_obj" ? ".obj" : ".vtk";
    const std::string scene = write_scene(name, "surface:\n  scenarios:\n    c:\n      mesh: " + name + ext +
                                                    "\n      poisson_ratio: 0\n      end_time_s: 1\n"
                                                    "      steady_state: true\n"
                                                    "      fixed_box_mm: [-0.001, -1, -1, 0.001, 11, 1]\n"
                                                    "      load_box_mm: [99.999, -1, -1, 100.001, 11, 1]\n"
                                                    "      point_load_n: [0, 0, 1e-4]\n"
                                                    "      effects: [fixed_nodes, point_loads]\n");
    const SurfaceStageResult r = run_surface_stage(stage_options(scene, "c", name + ".h5"));
    tips.push_back(r.surfaces.at(0).max_deflection_m);
  }
  EXPECT_EQ(tips[0], tips[1]);
  EXPECT_GT(tips[0], 0.0);
  {
    std::ofstream f(work_dir() + "/bad.vtk");
    f << "# vtk DataFile Version 3.0\nbad\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0\n1 0 0\n0 1 0\n"
         "POLYGONS 1 4\n3 0 1 2\n";
  }
  const std::string scene = write_scene("bad_vtk", "surface:\n  scenarios:\n    c:\n      mesh: bad.vtk\n"
                                                   "      end_time_s: 1\n      effects: [periphery_fixed]\n");
  try {
    run_surface_stage(stage_options(scene, "c", "bad_vtk.h5"));
    FAIL();
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.vtk:10"), std::string::npos) << e.what();
  }
}

// prescribed_displacement: a 100 x 10 mm strip (nu = 0) clamped at x = 0 and
// pulled by 2 mm at x = L is in uniaxial stretch lambda = 1.02 (no lateral
// contraction with nu = 0, directors unchanged), so E_xx = (lambda^2 - 1)/2 =
// 0.0202 at every node (a1 = x) and E_yy = E_xy = 0; e1 along x. Tolerance
// 1e-9: Newton's converged residual on an exactly representable state.
TEST(SurfaceStageGeneric, PrescribedDisplacementGivesUniformStretch) {
  write_plate_obj("pulled", 8, 100, 10);
  const std::string scene = write_scene("pulled", R"(surface:
  scenarios:
    pull:
      mesh: pulled.obj
      poisson_ratio: 0
      end_time_s: 1
      steady_state: true
      fixed_box_mm: [-0.001, -1, -1, 0.001, 11, 1]
      displaced_box_mm: [99.999, -1, -1, 100.001, 11, 1]
      displacement_mm: [2, 0, 0]
      effects: [fixed_nodes, prescribed_displacement]
)");
  const SurfaceStageOptions o = stage_options(scene, "pull", "pulled.h5");
  run_surface_stage(o);
  const common::H5File f(o.out, common::H5File::Mode::kRead);
  const common::Tensor3d E = f.read_tensor3("/surfaces/pulled/strain/E");
  const common::Tensor3d dir = f.read_tensor3("/surfaces/pulled/strain/e1_dir");
  const common::Tensor3d u = f.read_tensor3("/surfaces/pulled/displacement");
  const double expected = 0.5 * (1.02 * 1.02 - 1);
  for (int i = 0; i < 18; ++i) {
    EXPECT_NEAR(E(1, i, 0), expected, 1e-9) << i;
    EXPECT_NEAR(E(1, i, 1), 0.0, 1e-9) << i;
    EXPECT_NEAR(E(1, i, 2), 0.0, 1e-9) << i;
    EXPECT_NEAR(std::abs(dir(1, i, 0)), 1.0, 1e-9) << i;
    EXPECT_NEAR(u(1, i, 0), 0.02 * (i % 9) * 0.0125, 1e-12) << i;  // linear along x
  }
  const common::EffectLedger ledger = common::read_effect_ledger(f);
  EXPECT_EQ(ledger.count("prescribed_displacement"), 2);
  EXPECT_EQ(ledger.count("fixed_nodes"), 2);
}

TEST(SurfaceStageGeneric, GenericEffectWithoutMeshIsAnError) {
  const std::string scene = write_scene("generic_without_mesh", R"(surface:
  scenarios:
    g:
      surfaces: [femur]
      end_time_s: 1
      load_box_mm: [0, 0, 0, 1, 1, 1]
      point_load_n: [0, 0, 1]
      effects: [point_loads]
)");
  try {
    run_surface_stage(stage_options(scene, "g", "generic_without_mesh.h5"));
    FAIL();
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("needs a generic `mesh`"), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------------------
// Issue 34: the generic scene as a general shell solver.
// ---------------------------------------------------------------------------

/// Scene of the 16-quad cantilever strip (100 x 10 x 1 mm, nu = 0) clamped at
/// x = 0 with a total tip load P [N] along +z; `extra` adds scenario keys.
std::string cantilever_scene(const std::string& name, double E_mpa, double P, const std::string& extra = "") {
  write_plate_obj(name, 16, 100, 10);
  std::ostringstream s;
  s.precision(17);
  s << "surface:\n  scenarios:\n    c:\n      mesh: " << name << ".obj\n      youngs_modulus_mpa: " << E_mpa
    << "\n      poisson_ratio: 0\n      end_time_s: 1\n      steady_state: true\n"
       "      fixed_box_mm: [-0.001, -1, -1, 0.001, 11, 1]\n"
       "      load_box_mm: [99.999, -1, -1, 100.001, 11, 1]\n"
       "      point_load_n: [0, 0, "
    << P << "]\n" << extra << "      effects: [fixed_nodes, point_loads]\n";
  return write_scene(name, s.str());
}

double cantilever_tip(const std::string& file, const std::string& name) {
  const common::H5File f(file, common::H5File::Mode::kRead);
  return f.read_matrix("/surfaces/" + name + "/deflection")(1, 16);  // node (16, 0): the tip
}

/// Euler-Bernoulli tip deflection P L^3 / (3 E I) of that strip [m].
double beam_tip(double E_Pa, double P) {
  const double L = 0.1, W = 0.01, t = 1e-3;
  return P * L * L * L / (3 * E_Pa * W * t * t * t / 12);
}

// Material limits are those of physics: E > 0 without an upper cap (a steel
// or the Scordelis-Lo roof's E = 4.32e8 in its own units is a valid scene),
// -1 < nu < 0.5, thickness > 0; the open ends are refused naming the key.
TEST(SurfaceStageGeneric, MaterialLimitsArePhysical) {
  // Above the former 1e6 MPa cap: the same strip, load scaled with E, gives
  // the same tip deflection relative to beam theory (tolerance as in
  // CantileverPlateTipDeflectionMatchesBeamTheory).
  const double E = 4.32e8, P = 1e-4 * E / 400;
  const std::string scene = cantilever_scene("stiff_strip", E, P);
  const SurfaceStageOptions o = stage_options(scene, "c", "stiff_strip.h5");
  run_surface_stage(o);
  EXPECT_NEAR(cantilever_tip(o.out, "stiff_strip") / beam_tip(E * 1e6, P), 1.0, 5e-3);
  // An auxetic material (nu < 0) is accepted and runs.
  const std::string auxetic = write_scene("auxetic", R"(surface:
  scenarios:
    c:
      mesh: stiff_strip.obj
      poisson_ratio: -0.5
      end_time_s: 1
      steady_state: true
      fixed_box_mm: [-0.001, -1, -1, 0.001, 11, 1]
      load_box_mm: [99.999, -1, -1, 100.001, 11, 1]
      point_load_n: [0, 0, 1e-4]
      effects: [fixed_nodes, point_loads]
)");
  const SurfaceStageOptions oa = stage_options(auxetic, "c", "auxetic.h5");
  run_surface_stage(oa);
  EXPECT_GT(cantilever_tip(oa.out, "stiff_strip"), 0.0);
  for (const auto& [key, value] : std::vector<std::pair<std::string, std::string>>{
           {"poisson_ratio", "0.5"}, {"poisson_ratio", "-1"}, {"youngs_modulus_mpa", "0"},
           {"shell_thickness_mm", "0"}}) {
    const std::string bad = cantilever_scene("bad_material", 400, 1e-4, "      " + key + ": " + value + "\n");
    try {
      run_surface_stage(stage_options(bad, "c", "bad_material.h5"));
      ADD_FAILURE() << key << " = " << value << " accepted";
    } catch (const common::InputError& e) {
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  }
}

// linear: true -- one solve with the reference tangent. At P L^2 / (E I) =
// 0.9 (linear w/L = 0.3) the linear tip matches Euler-Bernoulli to the
// discretisation error of the 16-quad strip (0.09% at small load, see
// CantileverPlateTipDeflectionMatchesBeamTheory; tolerance 5e-3), while the
// geometrically nonlinear run is stiffer (elastica tables, e.g. Bisshopp &
// Drucker 1945, give w/L = 0.3017 at P L^2 / (E I) = 1, 9.5% below linear;
// at 0.9 the run gives 7.9%; the test asks for more than 2%).
TEST(SurfaceStageGeneric, LinearAnalysisMatchesEulerBernoulliAtLargeLoad) {
  const double E = 400, P = 3e-2;
  const std::string lin = cantilever_scene("linear_strip", E, P, "      linear: true\n");
  const SurfaceStageOptions ol = stage_options(lin, "c", "linear_strip.h5");
  const SurfaceStageResult rl = run_surface_stage(ol);
  EXPECT_EQ(rl.newton_iterations, 1);
  const double w_lin = cantilever_tip(ol.out, "linear_strip"), w_beam = beam_tip(E * 1e6, P);
  std::printf("linear cantilever: tip %.6g m, beam %.6g m (w/L %.2f), error %.3g%%\n", w_lin, w_beam, w_beam / 0.1,
              100 * (w_lin / w_beam - 1));
  EXPECT_NEAR(w_lin / w_beam, 1.0, 5e-3);
  const std::string nl = cantilever_scene("nonlinear_strip", E, P);
  const SurfaceStageOptions on = stage_options(nl, "c", "nonlinear_strip.h5");
  run_surface_stage(on);
  const double w_nl = cantilever_tip(on.out, "nonlinear_strip");
  std::printf("nonlinear cantilever: tip %.6g m (%.3g%% below linear)\n", w_nl, 100 * (1 - w_nl / w_lin));
  EXPECT_LT(w_nl / w_lin, 0.98);
  // linear needs steady_state.
  const std::string bad = write_scene("linear_dynamic", R"(surface:
  scenarios:
    c:
      mesh: linear_strip.obj
      end_time_s: 1
      linear: true
      fixed_box_mm: [-0.001, -1, -1, 0.001, 11, 1]
      effects: [fixed_nodes]
)");
  try {
    run_surface_stage(stage_options(bad, "c", "linear_dynamic.h5"));
    FAIL() << "linear without steady_state accepted";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("steady_state"), std::string::npos) << e.what();
  }
}

// newton_load_tolerance: on a stiff strip (E = 4.32e8 MPa) under a small load
// (1e-2 N, tip 9.3e-9 m) the residual cannot fall below its round-off floor
// (about eps E t h per node, ~1e-5 N here), which is above the absolute floor,
// the relative test (1e-8 of the first residual 7e-3 N) and the round-off
// stagnation rule (1e-3 of it): the default criteria fail after every
// halving. With the load-relative pair at 5e-3 (residual against the applied
// load, increment against the solution) the step converges and the tip has
// the strip's discretisation error against beam theory (tolerance 5e-3).
TEST(SurfaceStageGeneric, LoadRelativeCriterionConvergesWhereTheFloorsFail) {
  const double E = 4.32e8, P = 1e-2;
  const std::string plain = cantilever_scene("small_load", E, P);
  EXPECT_THROW(run_surface_stage(stage_options(plain, "c", "small_load.h5")), common::NumericalError);
  const std::string rel = cantilever_scene("small_load_rel", E, P, "      newton_load_tolerance: 5e-3\n");
  const SurfaceStageOptions o = stage_options(rel, "c", "small_load_rel.h5");
  const SurfaceStageResult r = run_surface_stage(o);
  EXPECT_EQ(r.rejected_steps, 0);
  const double w = cantilever_tip(o.out, "small_load_rel"), w_beam = beam_tip(E * 1e6, P);
  std::printf("stiff strip, small load: tip %.6g m, beam %.6g m, error %.3g%%\n", w, w_beam, 100 * (w / w_beam - 1));
  EXPECT_NEAR(w / w_beam, 1.0, 5e-3);
}

/// OBJ of an L x W plate (mm) of nx x ny quads in z = 0, node (i, j) = j (nx+1) + i.
std::string write_grid_obj(const std::string& name, int nx, int ny, double L_mm, double W_mm) {
  const std::string p = work_dir() + "/" + name + ".obj";
  std::ofstream f(p);
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) f << "v " << i * L_mm / nx << " " << j * W_mm / ny << " 0\n";
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i + 1;
      f << "f " << a << " " << a + 1 << " " << a + nx + 2 << " " << a + nx + 1 << "\n";
    }
  return p;
}

// Named sets: the bundled cantilever written with a plane set, a clamp on
// `all` components and a total force gives the bundled box-scene result
// (same nodes, same shares: bit for bit).
TEST(SurfaceStageGeneric, NamedSetsReproduceTheBoxScene) {
  const std::string box = cantilever_scene("sets_box", 400, 1e-4);
  const SurfaceStageOptions ob = stage_options(box, "c", "sets_box.h5");
  run_surface_stage(ob);
  write_plate_obj("sets_named", 16, 100, 10);
  const std::string named = write_scene("sets_named", R"(surface:
  scenarios:
    c:
      mesh: sets_named.obj
      poisson_ratio: 0
      end_time_s: 1
      steady_state: true
      node_sets: ["root: plane 1 0 0 0", "tip: box 99.999 -1 -1 100.001 11 1"]
      constraints: ["root: all"]
      loads: ["tip: force 0 0 1e-4"]
      effects: [fixed_nodes, point_loads]
)");
  const SurfaceStageOptions on = stage_options(named, "c", "sets_named.h5");
  run_surface_stage(on);
  EXPECT_EQ(cantilever_tip(on.out, "sets_named"), cantilever_tip(ob.out, "sets_box"));
}

// Masked constraints: a symmetry plane (normal displacement and the
// director's normal component held: "uy dy") on the half of a 2-quad-wide
// strip (nu = 0.3, so the plate bends anticlastically and the symmetry
// condition matters) gives the full strip's deflection field with half the
// load. The discrete problems are identical up to round-off: tolerance 1e-9
// relative.
TEST(SurfaceStageGeneric, SymmetryPlaneHalfModelMatchesTheFullModel) {
  write_grid_obj("sym_full", 8, 2, 100, 20);
  write_grid_obj("sym_half", 8, 1, 100, 10);
  // Loaded: the tip corners off the symmetry plane (full: nodes 8 and 26;
  // half: node 8), 1e-4 N each, so the half model carries half the load.
  auto scene = [](const std::string& name, const std::string& tip_nodes, const std::string& extra_sets,
                  const std::string& extra_cons, double P) {
    std::ostringstream s;
    s << "surface:\n  scenarios:\n    c:\n      mesh: " << name << ".obj\n      end_time_s: 1\n"
      << "      steady_state: true\n      node_sets: [\"root: plane 1 0 0 0\", \"tip: nodes " << tip_nodes << "\""
      << extra_sets << "]\n      constraints: [\"root: all\"" << extra_cons << "]\n"
      << "      loads: [\"tip: force_per_node 0 0 " << P << "\"]\n      effects: [fixed_nodes, point_loads]\n";
    return write_scene(name, s.str());
  };
  const SurfaceStageOptions of = stage_options(scene("sym_full", "8 26", "", "", 1e-4), "c", "sym_full.h5");
  run_surface_stage(of);
  const SurfaceStageOptions oh =
      stage_options(scene("sym_half", "8", ", \"sym: plane 0 1 0 10\"", ", \"sym: uy dy\"", 1e-4), "c", "sym_half.h5");
  run_surface_stage(oh);
  const common::H5File ff(of.out, common::H5File::Mode::kRead), fh(oh.out, common::H5File::Mode::kRead);
  const common::Tensor3d uf = ff.read_tensor3("/surfaces/sym_full/displacement");
  const common::Tensor3d uh = fh.read_tensor3("/surfaces/sym_half/displacement");
  // Half-model node (i, j) = full-model node (i, j) for j = 0, 1.
  double scale = 0, worst = 0;
  for (int j = 0; j <= 1; ++j)
    for (int i = 0; i <= 8; ++i) {
      const int nf = j * 9 + i, nh = j * 9 + i;
      for (int c = 0; c < 3; ++c) {
        scale = std::max(scale, std::abs(uf(1, nf, c)));
        worst = std::max(worst, std::abs(uf(1, nf, c) - uh(1, nh, c)));
      }
    }
  std::printf("symmetry half model: largest difference %.3g of the largest displacement %.3g m\n", worst / scale,
              scale);
  EXPECT_GT(scale, 0.0);
  EXPECT_LT(worst, 1e-9 * scale);
}

// Reactions balance the applied loads: a clamped plate (nu = 0.3) under a
// point force, a fixed-direction traction and its own weight, with a
// symmetry-type masked support on one side; the reactions written per
// constraint plus the applied loads sum to zero up to the converged Newton
// residual (below 1e-11 of the load here), with the consistent traction and
// self-weight totalling traction x area and rho t g x area.
TEST(SurfaceStageGeneric, ReactionsBalanceTheAppliedLoads) {
  write_grid_obj("reactions_plate", 6, 3, 60, 30);
  const std::string scene = write_scene("reactions_plate", R"(surface:
  scenarios:
    c:
      mesh: reactions_plate.obj
      density_kg_per_m3: 7800
      end_time_s: 1
      steady_state: true
      node_sets: ["root: plane 1 0 0 0", "side: plane 0 1 0 0", "corner: nodes 27", "all: all"]
      constraints: ["root: all", "side: uy dy"]
      loads: ["corner: force 0.01 0.02 -0.05", "all: traction 0 1e-6 -2e-6", "all: gravity 0 0 -9.81"]
      effects: [fixed_nodes, point_loads]
)");
  const SurfaceStageOptions o = stage_options(scene, "c", "reactions_plate.h5");
  const SurfaceStageResult r = run_surface_stage(o);
  const common::H5File f(o.out, common::H5File::Mode::kRead);
  const Eigen::MatrixXd R0 = f.read_matrix("/surfaces/reactions_plate/reactions/0_root");
  const Eigen::MatrixXd R1 = f.read_matrix("/surfaces/reactions_plate/reactions/1_side");
  ASSERT_EQ(R0.rows(), 2);
  const double area = 0.06 * 0.03, t = 1e-3;
  const Eigen::Vector3d applied = Eigen::Vector3d(0.01, 0.02, -0.05) + area * Eigen::Vector3d(0, 1, -2) +
                                  7800 * t * area * Eigen::Vector3d(0, 0, -9.81);
  const Eigen::Vector3d sum = R0.row(1).transpose() + R1.row(1).transpose() + applied;
  std::printf("reactions: root (%.6g, %.6g, %.6g) N, side (%.6g, %.6g, %.6g) N, imbalance %.3g N of %.3g N\n", R0(1, 0),
              R0(1, 1), R0(1, 2), R1(1, 0), R1(1, 1), R1(1, 2), sum.norm(), applied.norm());
  // Exact balance holds at equilibrium: the internal forces have no net
  // translation, so sum(R) + applied = sum of the residual left on the free
  // coordinates, at most sqrt(n_free) ||G|| (28 nodes x 6), plus round-off.
  const double bound = std::sqrt(6.0 * 28) * r.final_residual_N + 1e-13 * applied.norm();
  std::printf("  final residual %.3g N, bound %.3g N\n", r.final_residual_N, bound);
  EXPECT_LT(sum.norm(), bound);
  EXPECT_EQ(R1(1, 0), 0.0);  // the side holds uy only among the translations
  EXPECT_EQ(R1(1, 2), 0.0);
  EXPECT_NE(R1(1, 1), 0.0);
  EXPECT_EQ(R0.row(0).norm(), 0.0);  // t = 0: nothing applied yet
}

// Self-weight with linear: true against the cantilever under a uniform line
// load q = rho g t W: w_tip = q L^4 / (8 E I) (nu = 0 strip, 16 quads). The
// element's discretisation error for the point load is 0.09%; tolerance 5e-3.
TEST(SurfaceStageGeneric, SelfWeightCantileverMatchesBeamTheory) {
  write_plate_obj("self_weight", 16, 100, 10);
  const std::string scene = write_scene("self_weight", R"(surface:
  scenarios:
    c:
      mesh: self_weight.obj
      poisson_ratio: 0
      density_kg_per_m3: 1000
      end_time_s: 1
      steady_state: true
      linear: true
      node_sets: ["root: plane 1 0 0 0", "all: all"]
      constraints: ["root: all"]
      loads: ["all: gravity 0 0 9.81"]
      effects: [fixed_nodes, point_loads]
)");
  const SurfaceStageOptions o = stage_options(scene, "c", "self_weight.h5");
  run_surface_stage(o);
  const double L = 0.1, W = 0.01, t = 1e-3, E = 400e6, q = 1000 * 9.81 * t * W;
  const double w_beam = q * std::pow(L, 4) / (8 * E * W * t * t * t / 12);
  const double w = cantilever_tip(o.out, "self_weight");
  std::printf("self-weight cantilever: tip %.6g m, beam %.6g m, error %.3g%%\n", w, w_beam, 100 * (w / w_beam - 1));
  EXPECT_NEAR(w / w_beam, 1.0, 5e-3);
  // The same load per unit volume (rho g = 9.81e-6 N/mm^3): the same tip up
  // to the rounding of rho t g against t (rho g).
  std::ifstream in(work_dir() + "/self_weight.yaml");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  text.replace(text.find("gravity 0 0 9.81"), 16, "body_force 0 0 9.81e-6");
  const std::string body = work_dir() + "/body_force.yaml";
  std::ofstream(body) << text;
  const SurfaceStageOptions ob = stage_options(body, "c", "body_force.h5");
  run_surface_stage(ob);
  EXPECT_NEAR(cantilever_tip(ob.out, "self_weight") / w, 1.0, 1e-12);
}

// Bad set definitions are refused with the key and what is wrong.
TEST(SurfaceStageGeneric, BadSetDefinitionsAreRefused) {
  write_plate_obj("bad_sets", 4, 100, 10);
  for (const auto& [key, line, expect] : std::vector<std::tuple<std::string, std::string, std::string>>{
           {"node_sets", "[\"a: cube 0 0 0\"]", "unknown set kind"},
           {"constraints", "[\"nowhere: all\"]", "unknown node set 'nowhere'"},
           {"constraints", "[\"a: ux wz\"]", "unknown component 'wz'"},
           {"constraints", "[\"a: ux uy = 1\"]", "2 components but 1 values"},
           {"loads", "[\"a: torque 0 0 1\"]", "unknown load 'torque'"}}) {
    std::string body = "surface:\n  scenarios:\n    c:\n      mesh: bad_sets.obj\n      end_time_s: 1\n"
                       "      steady_state: true\n      fixed_box_mm: [-0.001, -1, -1, 0.001, 11, 1]\n";
    if (key != "node_sets") body += "      node_sets: [\"a: plane 1 0 0 100\"]\n";
    body += "      " + key + ": " + line + "\n      effects: [fixed_nodes]\n";
    const std::string scene = write_scene("bad_sets", body);
    try {
      run_surface_stage(stage_options(scene, "c", "bad_sets.h5"));
      ADD_FAILURE() << key << ": " << line << " accepted";
    } catch (const common::InputError& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
}

// The Scordelis-Lo roof (data/scenes/verification/scordelis_lo_roof.yaml,
// MacNeal & Harder 1985): linear, quarter model with symmetry planes and a
// rigid diaphragm written as masked constraints, self-weight as a traction.
// Reference: vertical deflection 0.3024 at the midpoint of the free edge. The
// bundled 16 x 16 scene and the meshes 4, 8, 32 of the same generator
// (make_scordelis_lo_mesh.py, mirrored here) give the convergence series of
// docs/shell_element.md. Tolerance 1% at 16 x 16 and 32 x 32: the series
// levels off 0.4% below the reference (0.9976 at 16, 0.9963 at 32), and
// commercial bilinear shell quads are quoted within 1.3% at 10 nodes per side
// for this problem (Altair OptiStruct verification OS-V 0730: QUAD4 1.013).
TEST(SurfaceStageGeneric, ScordelisLoRoofMatchesTheReference) {
  const std::string dir = std::string(ARTHROSIM_SOURCE_DIR) + "/data/scenes/verification";
  auto tip_ratio = [](const std::string& file, const std::string& surface, int n) {
    const common::H5File f(file, common::H5File::Mode::kRead);
    const common::Tensor3d u = f.read_tensor3("/surfaces/" + surface + "/displacement");
    return u(1, n * (n + 1), 2) / -0.3024e-3;  // free-edge midpoint, mm -> m
  };
  std::vector<std::pair<int, double>> series;
  for (int n : {4, 8, 32}) {
    const std::string name = "roof_" + std::to_string(n);
    {
      std::ofstream f(work_dir() + "/" + name + ".obj");
      f.precision(17);
      const double R = 25, half = 25, angle = 40 * std::numbers::pi / 180;
      for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
          const double th = angle * j / n;
          f << "v " << half * i / n << " " << R * std::sin(th) << " " << R * std::cos(th) << "\n";
        }
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          const int a = j * (n + 1) + i + 1;
          f << "f " << a << " " << a + 1 << " " << a + n + 2 << " " << a + n + 1 << "\n";
        }
    }
    std::ifstream in(dir + "/scordelis_lo_roof.yaml");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    text.replace(text.find("scordelis_lo_roof_16.obj"), 24, name + ".obj");
    text.replace(text.find("../../models"), 12, std::string(ARTHROSIM_SOURCE_DIR) + "/data/models");
    const std::string scene = work_dir() + "/" + name + ".yaml";
    std::ofstream(scene) << text;
    const SurfaceStageOptions o = stage_options(scene, "roof", name + ".h5");
    run_surface_stage(o);
    series.emplace_back(n, tip_ratio(o.out, name, n));
  }
  const SurfaceStageOptions o = stage_options(dir + "/scordelis_lo_roof.yaml", "roof", "scordelis_lo_roof_16.h5");
  const SurfaceStageResult r = run_surface_stage(o);
  EXPECT_EQ(r.newton_iterations, 1);
  series.insert(series.begin() + 2, {16, tip_ratio(o.out, "scordelis_lo_roof_16", 16)});
  for (const auto& [n, ratio] : series) std::printf("Scordelis-Lo roof %2d x %2d: w / 0.3024 = %.4f\n", n, n, ratio);
  EXPECT_NEAR(series[2].second, 1.0, 1e-2);
  EXPECT_NEAR(series[3].second, 1.0, 1e-2);
  for (size_t i = 1; i < series.size(); ++i)  // the error shrinks with refinement
    EXPECT_LT(std::abs(series[i].second - series[3].second), std::abs(series[i - 1].second - series[3].second) + 1e-12);
}

// OBJ `g` groups as node sets: a traction on the faces of group `tip` (the
// last quad of the strip) equals the same traction on a box holding exactly
// that quad's nodes, bit for bit; an unknown group names the groups there are.
TEST(SurfaceStageGeneric, ObjGroupsAreNodeSets) {
  {
    std::ofstream f(work_dir() + "/grouped_strip.obj");
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i <= 16; ++i) f << "v " << i * 6.25 << " " << j * 10 << " 0\n";
    for (int i = 0; i < 16; ++i) {
      if (i == 0) f << "g root\n";
      if (i == 1) f << "g body\n";
      if (i == 15) f << "g tip loaded\n";
      f << "f " << i + 1 << " " << i + 2 << " " << 17 + i + 2 << " " << 17 + i + 1 << "\n";
    }
  }
  auto scene = [](const std::string& name, const std::string& tip_set) {
    return write_scene(name, "surface:\n  scenarios:\n    c:\n      mesh: grouped_strip.obj\n      poisson_ratio: 0\n"
                             "      end_time_s: 1\n      steady_state: true\n"
                             "      node_sets: [\"root: plane 1 0 0 0\", \"tip: " +
                                 tip_set +
                                 "\"]\n      constraints: [\"root: all\"]\n      loads: [\"tip: traction 0 0 1e-6\"]\n"
                                 "      effects: [fixed_nodes, point_loads]\n");
  };
  const SurfaceStageOptions og = stage_options(scene("grouped", "group loaded"), "c", "grouped.h5");
  run_surface_stage(og);
  const SurfaceStageOptions ob = stage_options(scene("grouped_box", "box 93.749 -1 -1 100.001 11 1"), "c", "grouped_box.h5");
  run_surface_stage(ob);
  const double wg = cantilever_tip(og.out, "grouped_strip"), wb = cantilever_tip(ob.out, "grouped_strip");
  EXPECT_GT(wg, 0.0);
  EXPECT_EQ(wg, wb);
  try {
    run_surface_stage(stage_options(scene("grouped_bad", "group nowhere"), "c", "grouped_bad.h5"));
    FAIL() << "unknown group accepted";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no face group 'nowhere' (groups: body, loaded, root, tip)"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace arthrosim::pipelines
