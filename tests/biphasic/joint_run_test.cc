// A joint run on the canonical case: a lower plate ("tibia" bone) and an
// upper layer ("femur" bone) whose bone moves down over four frames. Checks
// the per-step indicators against what the conditions imply (contact area,
// fluid load support = 1 - H/gamma for a uniform overlap, the force passed to
// each bone), the regions, and the refusals of incomplete frames.
#include "biphasic/joint_run.h"

#include <gtest/gtest.h>

#include "biphasic_fixtures.h"
#include "common/error.h"

namespace arthrosim::biphasic {
namespace {

constexpr double kW = 12e-3;

JointLayer lower() {
  JointLayer l;
  l.name = "plate";
  l.bone = "tibia";
  l.surface = testing::grid_surface(6, 6, kW, kW, 0.0);
  for (int v = 0; v < l.surface.num_nodes(); ++v) l.surface.V.row(v).head<2>() -= Eigen::RowVector2d(kW / 2, kW / 2);
  l.normals = testing::constant_normals(49, Eigen::Vector3d::UnitZ());
  l.thickness = Eigen::VectorXd::Constant(49, 2e-3);
  l.material = {0.6e6, 0.1, 2e-15};
  return l;
}

// The upper layer in its own bone frame: surface at z = 0 facing -z, bone above.
JointLayer upper() {
  JointLayer l;
  l.name = "cap";
  l.bone = "femur";
  l.surface = testing::grid_surface(4, 4, 8e-3, 8e-3, 0.0);
  for (int v = 0; v < l.surface.num_nodes(); ++v) l.surface.V.row(v).head<2>() -= Eigen::RowVector2d(4e-3, 4e-3);
  for (int q = 0; q < l.surface.num_quads(); ++q)
    l.surface.Q.row(q) = Eigen::RowVector4i(l.surface.Q(q, 0), l.surface.Q(q, 3), l.surface.Q(q, 2), l.surface.Q(q, 1));
  l.normals = testing::constant_normals(25, -Eigen::Vector3d::UnitZ());
  l.thickness = Eigen::VectorXd::Constant(25, 1.5e-3);
  l.material = {1.0e6, 0.1, 3e-15};
  return l;
}

JointFrame frame(double t, double overlap, double force) {
  JointFrame f;
  f.time_s = t;
  f.X_WB["tibia"] = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() << 0.0, 0.0, -overlap;  // the cap's surface at z = -overlap
  f.X_WB["femur"] = X;
  f.force_N["medial"] = force;
  return f;
}

TEST(JointRun, IndicatorsFollowTheConditions) {
  JointOptions o;
  o.element_layers = 2;
  o.time = {0.01, 0.5};
  JointRun run({lower(), upper()}, {{"plate", "cap", "medial"}}, o);
  const std::vector<JointFrame> frames = {frame(0.0, 0.05e-3, 30.0), frame(0.02, 0.1e-3, 80.0),
                                          frame(0.04, 0.08e-3, 60.0), frame(0.06, -0.1e-3, 20.0)};
  std::vector<double> times;
  std::vector<std::vector<SurfaceLoads>> loads;
  std::vector<std::vector<PairFrame>> conditions;
  for (const JointFrame& f : frames) {
    times.push_back(f.time_s);
    conditions.push_back(run.contact(f));
    loads.push_back(run.layer_loads(f, conditions.back()));
  }
  // The cap (8 x 8 mm) lies inside the plate: all its 25 nodes touch; the
  // plate's nodes under it (5 x 5 of its 2 mm grid) too.
  EXPECT_EQ(conditions[1][0].b.contact_nodes, 25);
  EXPECT_EQ(conditions[1][0].a.contact_nodes, 25);
  EXPECT_TRUE(conditions[3][0].a.skipped_no_overlap);  // the last frame separates
  int steps_seen = 0;
  const int steps = run.run(times, loads, [&](int step, double t, const std::vector<LayerStep>& r) {
    ++steps_seen;
    ASSERT_EQ(r.size(), 2u);
    // At frame times the loads are the frame's: check the indicators there.
    for (size_t k = 0; k < 3; ++k) {
      if (std::abs(t - frames[k].time_s) > 1e-12) continue;
      const ContactConditions& cp = conditions[k][0].a;  // plate
      const ContactConditions& cc = conditions[k][0].b;  // cap
      EXPECT_NEAR(r[0].contact_area_m2, cp.contact_area, 1e-15);
      EXPECT_NEAR(r[1].contact_area_m2, 64e-6, 1e-15);
      // Uniform overlap: FLS = 1 - H / gamma on each layer.
      EXPECT_NEAR(r[0].fluid_load_support, 1.0 - 0.6e6 / cp.gamma, 1e-12);
      EXPECT_NEAR(r[1].fluid_load_support, 1.0 - 1.0e6 / cc.gamma, 1e-12);
      // Force passed to each bone: |F| along the contact normal.
      EXPECT_NEAR(run.problem(0).force_on_bone().z(), -frames[k].force_N.at("medial"), 1e-8);
      EXPECT_NEAR(run.problem(1).force_on_bone().z(), frames[k].force_N.at("medial"), 1e-8);
      EXPECT_GE(r[0].max_tensile_vertex, 0);
    }
    EXPECT_GE(r[0].max_shear_vertex, 0);
    EXPECT_TRUE(std::isfinite(r[0].max_shear_Pa));
    (void)step;
  });
  EXPECT_EQ(steps, 6);
  EXPECT_EQ(steps_seen, 6);
  EXPECT_EQ(run.problem(0).integrator().counters().factorizations, 1);
  EXPECT_EQ(run.problem(1).integrator().counters().solves, 6);
}

TEST(JointRun, RegionsOfAFlatPlate) {
  // Anterior = +x, lateral = +z by default; the plate lies in the x-y plane
  // here, so use lateral = +y for it.
  JointOptions o;
  o.element_layers = 1;
  o.time = {0.01, 1.0};
  o.lateral_B = Eigen::Vector3d::UnitY();
  JointRun run({lower()}, {}, o);
  const auto& r = run.regions(0);
  const common::QuadMesh& s = run.problem(0).system().mesh.surface;
  for (int v = 0; v < s.num_nodes(); ++v) {
    const double x = s.V(v, 0) / (kW / 2), y = s.V(v, 1) / (kW / 2);
    // Ties (on a diagonal, on the central square's edge) may go either way.
    if (std::abs(std::abs(x) - std::abs(y)) < 1e-9 && std::abs(x) > 1.0 / 3) continue;
    if (std::abs(std::abs(x) - 1.0 / 3) < 1e-9 || std::abs(std::abs(y) - 1.0 / 3) < 1e-9) continue;
    Region expected;
    if (std::abs(x) <= 1.0 / 3 && std::abs(y) <= 1.0 / 3) expected = Region::kCentral;
    else if (std::abs(x) >= std::abs(y)) expected = x > 0 ? Region::kAnterior : Region::kPosterior;
    else expected = y > 0 ? Region::kLateral : Region::kMedial;
    EXPECT_EQ(r[v], expected) << v << " at " << x << ", " << y;
  }
  EXPECT_EQ(r[24], Region::kCentral);  // the centre node
}

TEST(JointRun, RefusesIncompleteFramesAndUnknownLayers) {
  JointOptions o;
  o.element_layers = 1;
  o.time = {0.01, 1.0};
  EXPECT_THROW(JointRun({lower()}, {{"plate", "nothing", "medial"}}, o), common::InputError);
  JointRun run({lower(), upper()}, {{"plate", "cap", "medial"}}, o);
  JointFrame no_force = frame(0.0, 0.1e-3, 10.0);
  no_force.force_N.clear();
  try {
    run.contact(no_force);
    ADD_FAILURE();
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("expected the contact force of compartment 'medial'"), std::string::npos);
  }
  JointFrame no_pose = frame(0.0, 0.1e-3, 10.0);
  no_pose.X_WB.erase("femur");
  EXPECT_THROW(run.contact(no_pose), common::InputError);
  // Layers with a permeability <= 0 are refused when the run is built.
  JointLayer bad = lower();
  bad.material.permeability_m4_per_Ns = 0.0;
  EXPECT_THROW(JointRun({bad}, {}, o), common::InputError);
}

}  // namespace
}  // namespace arthrosim::biphasic
