// The knee of the shockwave model (shockwave/knee_model.h): tissues where
// the meshes put them, the applicator on the capsule, and bad input.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>

#include "common/error.h"
#include "shockwave/knee_model.h"
#include "tests/shockwave/knee_support.h"

namespace arthrosim::shockwave {
namespace {

TEST(KneeModel, TissuesOfTheBundledKnee) {
  const KneeMeshes k = testing::load_bundled_knee("coarse");
  KneeModelOptions o;
  o.diameter = 2e-3;
  KneeModelInfo info;
  const auto t0 = std::chrono::steady_clock::now();
  const Model m = build_knee_model(k, o, &info);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("knee at d = 2 mm (FCC): %d automata, %lld bonds, built in %.2f s; box %.1f x %.1f x %.1f mm, joint line %.1f mm\n",
              m.size(), static_cast<long long>(m.bonds()), secs, (info.box_hi - info.box_lo).x() * 1e3,
              (info.box_hi - info.box_lo).y() * 1e3, (info.box_hi - info.box_lo).z() * 1e3, info.joint_line * 1e3);
  for (int t = 0; t < kKneeTissueCount; ++t) std::printf("  %-15s %lld\n", knee_tissue_name(t), static_cast<long long>(info.automata[t]));
  for (int t = 0; t < kKneeTissueCount; ++t) EXPECT_GT(info.automata[t], 0) << knee_tissue_name(t);
  EXPECT_EQ(info.applicator_layers, 1);
}

// Where the automata are: a site deep in the femoral condyle is cancellous,
// one just under the femoral surface cortical, one in the joint space under
// the femoral condyle cartilage; the applicator's outer layer carries the load.
TEST(KneeModel, TissuesWhereTheMeshesPutThem) {
  const KneeMeshes k = testing::load_bundled_knee("coarse");
  KneeModelOptions o;
  o.diameter = 1.5e-3;
  KneeModelInfo info;
  const Model m = build_knee_model(k, o, &info);
  auto nearest = [&](const common::Vec3& p) {
    int best = 0;
    double dist = 1e9;
    for (int a = 0; a < m.size(); ++a) {
      const double dd = (m.position(a) - p).norm();
      if (dd < dist) { dist = dd; best = a; }
    }
    return m.tissue[best];
  };
  // Medial condyle centre (0, 0, -21 mm), radius ~21 mm: cancellous inside.
  EXPECT_EQ(nearest(common::Vec3(0, 0, -21e-3)), kCancellous);
  // Far from the knee inside the box: fibrous; at the box corner: shell.
  EXPECT_EQ(nearest(info.box_lo + common::Vec3(0.2e-3, 0.2e-3, 0.2e-3)), kCapsuleShell);
  // The load acts on the applicator's outer layer, pointing into the box.
  ASSERT_FALSE(m.loaded.automata.empty());
  for (int a : m.loaded.automata) EXPECT_EQ(m.tissue[a], kApplicator);
  EXPECT_GT(m.loaded.normal.dot(info.applicator_normal), 0.99);
  // Applicator footprint: 20 x 20 mm, total area of the loaded layer.
  double area = 0.0;
  for (const auto& A : m.loaded.area) area += A.norm();
  EXPECT_NEAR(area, 400e-6, 0.2 * 400e-6);
  // Plate mass = 8950 kg/m^3 * 20 x 20 x 1 mm^3 (density scaled to the layers).
  const double mass = info.automata[kApplicator] * m.constants[kApplicator].total_density * m.lattice.cell_volume;
  EXPECT_NEAR(mass, 8950 * 400e-6 * 1e-3, 0.2 * 8950 * 400e-6 * 1e-3);
}

// Bad input: clear errors, naming what and why.
TEST(KneeModel, BadInput) {
  const KneeMeshes k = testing::load_bundled_knee("coarse");
  auto expect_error = [&](const KneeModelOptions& o, const std::string& needle) {
    try {
      build_knee_model(k, o, nullptr, "shockwave.yaml");
      ADD_FAILURE() << "no error, expected: " << needle;
    } catch (const common::InputError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("shockwave.yaml"), std::string::npos) << e.what();
    }
  };
  KneeModelOptions o;
  o.diameter = 2.5e-3;  // thicker than the 2 mm cortical shell
  expect_error(o, "exceeds the cortical shell thickness");
  o = KneeModelOptions{};
  o.diameter = 2e-3;
  o.shell_thickness = 1.5e-3;
  expect_error(o, "exceeds the capsule shell thickness");
  o = KneeModelOptions{};
  o.diameter = 3.2e-3;
  o.cortical_thickness = 4e-3;
  o.shell_thickness = 4e-3;  // the cartilage (at most 3 mm) is the thinnest left
  expect_error(o, "exceeds the thickest cartilage thickness");
  o = KneeModelOptions{};
  o.diameter = 2e-3;
  o.applicator.centre = common::Vec3(0.0, 0.3, 0.0);  // 300 mm above the knee
  expect_error(o, "applicator");
  o = KneeModelOptions{};
  o.diameter = 2e-3;
  o.tissues = default_knee_tissues();
  o.tissues[kCartilage].bulk_modulus = -1.0;
  expect_error(o, "bulk modulus K > 0");
  o.tissues = default_knee_tissues();
  o.tissues[kFibrous].porosity = 1.2;
  expect_error(o, "porosity in (0, 1)");
}

}  // namespace
}  // namespace arthrosim::shockwave
