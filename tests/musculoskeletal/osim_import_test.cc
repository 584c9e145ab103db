// The OpenSim importer (musculoskeletal/osim_import.h) on the bundled
// lenhart2015.osim: what it imports (counts the issue names), the model it
// writes loads, its joint chains reproduce OpenSim's SpatialTransform
// (closed forms), and what it cannot represent stops naming the line.
#include "musculoskeletal/osim_import.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>

#include "common/error.h"
#include "tests/test_support.h"
#include "musculoskeletal/model_io.h"

namespace arthrosim::musculoskeletal {
namespace {

namespace fs = std::filesystem;
const fs::path kModelDir = fs::path(ARTHROSIM_SOURCE_DIR) / "data/models/lenhart2015";
const fs::path kOsim = kModelDir / "source/lenhart2015.osim";

using test_support::message_of;
using test_support::read_text;

fs::path scratch(const std::string& name) { return test_support::fresh_scratch_dir("osim_import_" + name); }

OsimImportOptions lenhart_options(bool wrapping) {
  OsimImportOptions o;
  o.geometry_dirs = {(kModelDir / "Geometry").string()};
  o.without_wrapping = !wrapping;
  return o;
}

// One import shared by the tests of this file.
const OsimImportSummary& imported(bool wrapping) {
  static std::map<bool, OsimImportSummary> done;
  if (!done.count(wrapping)) {
    const fs::path out = scratch(wrapping ? "wrapped" : "straight");
    done[wrapping] = import_osim(kOsim.string(), out.string(), lenhart_options(wrapping));
  }
  return done[wrapping];
}

// references.md: 25 bodies (62.0 kg), knee_r and pf_r 6-DOF, 13 muscles
// cross the knee, 76 bundles in 14 groups, 8 wrap cylinders and 31 wrap
// ellipsoids in the model, of which the knee's paths use 3 and 5.
TEST(OsimImport, LenhartCounts) {
  const OsimImportSummary& s = imported(true);
  EXPECT_EQ(s.model_name, "lenhart2015");
  EXPECT_NEAR(s.subject_mass_kg, 62.0, 1e-9);
  // pelvis, femur_r, femur_distal_r, patella_r, tibia_proximal_r, tibia_r,
  // talus_r, calcn_r, toes_r and the ground.
  EXPECT_EQ(s.bodies, 10);
  EXPECT_EQ(s.coordinates, 24);  // pelvis 6, hip 3, knee 6, pf 6, ankle, subtalar, mtp
  EXPECT_EQ(s.free_coordinates, 12);
  EXPECT_EQ(s.muscles, 13);
  EXPECT_EQ(s.ligament_bundles, 76);
  EXPECT_EQ(s.ligament_groups, 14);
  EXPECT_EQ(s.wrap_objects.at("WrapCylinder"), 3);
  EXPECT_EQ(s.wrap_objects.at("WrapEllipsoid"), 5);
  EXPECT_EQ(s.path_wraps, 37);  // 30 ligament bundles + 7 muscles
  EXPECT_EQ(s.contacts, 2);
  EXPECT_EQ(s.surfaces, 3);
  EXPECT_EQ(s.coordinate_springs, 12);
  EXPECT_EQ(s.copied_meshes.size(), 6u);
  // Everything left out is in the report with its line: 15 bodies, the
  // other joints, 31 muscles, the unused wrap objects (5 cylinders, 26
  // ellipsoids), the markers.
  const std::string report = read_text(s.report_path);
  EXPECT_NE(report.find("| femur_l | not on the imported leg"), std::string::npos);
  EXPECT_NE(report.find("| soleus_r | does not cross the knee"), std::string::npos);
  EXPECT_NE(report.find("| WrapEllipsoid | Gmax_at_pelvis_r | not used by an imported path |"), std::string::npos);
  EXPECT_NE(report.find("markers are for inverse kinematics"), std::string::npos);
  EXPECT_NE(report.find("lenhart2015-R-fibula-bone.stl' not found"), std::string::npos);
  // The leg variant (the bundled model) takes every muscle on the imported
  // bodies (44: the right leg's), and the wrap objects they use (3
  // cylinders, 9 ellipsoids, 43 path wraps).
}

// The bundled model is what the importer writes from the bundled .osim with
// every muscle of the leg (data/models/lenhart2015/README.md: regenerated bit
// for bit).
TEST(OsimImport, BundledModelIsTheImportersOutput) {
  OsimImportOptions o = lenhart_options(true);
  o.muscles = ImportMuscles::kLeg;
  const OsimImportSummary s = import_osim(kOsim.string(), scratch("bundled").string(), o);
  EXPECT_EQ(s.muscles, 44);
  EXPECT_EQ(read_text(s.urdf_path), read_text(kModelDir / "lenhart2015.urdf"));
  EXPECT_EQ(read_text(s.report_path), read_text(kModelDir / "import_report.md"));
}

// The written model loads (with its wrap objects, and without them on
// request): roles, free and prescribed coordinates, defaults, subject mass,
// muscles with their fibre lengths, the contact pairs.
TEST(OsimImport, ImportedModelLoads) {
  const Model wrapped = load_model(imported(true).urdf_path);
  int wraps = 0;
  for (const Muscle& mu : wrapped.muscles) wraps += static_cast<int>(mu.path.wraps.size());
  for (const Ligament& l : wrapped.ligaments)
    for (const LigamentBundle& b : l.bundles) wraps += static_cast<int>(b.path.wraps.size());
  EXPECT_EQ(wraps, 37);
  EXPECT_EQ(load_model((kModelDir / "lenhart2015.urdf").string()).muscles.size(), 44u);
  const Model m = load_model(imported(false).urdf_path);
  EXPECT_EQ(m.num_coordinates(), 24);
  EXPECT_EQ(m.free_coordinates.size(), 12u);
  EXPECT_EQ(m.prescribed_coordinates.size(), 12u);
  EXPECT_NEAR(m.subject_mass_kg, 62.0, 1e-9);
  EXPECT_EQ(m.tree.bodies[0].name, "femur_distal_r");  // the root
  EXPECT_EQ(m.role_coordinate("knee_flexion"), m.tree.coordinate_index("knee_flex_r"));
  EXPECT_EQ(m.role_coordinate("ankle_flexion"), m.tree.coordinate_index("ankle_flex_r"));
  EXPECT_EQ(m.role_body("tibia"), m.tree.body_index("tibia_proximal_r"));
  EXPECT_EQ(m.role_body("patella"), m.tree.body_index("patella_r"));
  EXPECT_DOUBLE_EQ(m.default_q[m.tree.coordinate_index("pf_tx_r")], 0.053);
  EXPECT_EQ(m.muscles.size(), 13u);
  EXPECT_EQ(m.num_bundles(), 76);
  EXPECT_EQ(m.ligaments.size(), 14u);
  const Muscle& vl = m.muscles[m.muscle_index("vaslat_r")];
  EXPECT_DOUBLE_EQ(vl.max_isometric_force, 2255.4);
  EXPECT_NEAR(vl.optimal_fiber_length, 0.0915231660637572, 1e-15);
  EXPECT_EQ(m.ligaments[m.ligament_index("MCLd")].bundles[0].name, "MCLd1");
  EXPECT_DOUBLE_EQ(m.ligaments[m.ligament_index("MCLd")].bundles[0].parameters.slack_length, 0.03075);
  ASSERT_EQ(m.contacts.size(), 2u);
  EXPECT_EQ(m.contacts[0].casting().mesh.num_triangles(), 8602);
  EXPECT_EQ(m.contacts[0].target().mesh.num_triangles(), 29782);
  EXPECT_EQ(m.contacts[1].casting().mesh.num_triangles(), 6052);
  // max_proximity 0.02 m over 3 + 3 mm of cartilage.
  EXPECT_NEAR(m.contacts[0].max_overlap(), 0.02, 1e-15);
  EXPECT_EQ(m.coordinate_springs.size(), 12u);
}

// OpenSim's CustomJoint: X_FM = [R1(q1) R2(q2) R3(q3) | t1 b1 + t2 b2 + t3 b3]
// (Simbody's FunctionBased mobilizer); the knee's rotation1 has slope -1
// (flexion turns the tibia about -Z). The imported tree reproduces it, and
// the chain reversed up to the ground puts the femur where ground -> pelvis
// -> hip -> femur puts it. Closed forms with the model's offsets.
TEST(OsimImport, JointChainsMatchOpenSimSpatialTransform) {
  const Model m = load_model(imported(false).urdf_path);
  auto Rx = [](double a) { return Eigen::AngleAxisd(a, Vec3::UnitX()).toRotationMatrix(); };
  auto Ry = [](double a) { return Eigen::AngleAxisd(a, Vec3::UnitY()).toRotationMatrix(); };
  auto Rz = [](double a) { return Eigen::AngleAxisd(a, Vec3::UnitZ()).toRotationMatrix(); };
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.6, 0.6);
  auto idx = [&](const char* c) { return m.tree.coordinate_index(c); };
  for (int trial = 0; trial < 5; ++trial) {
    Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
    for (int i = 0; i < q.size(); ++i) q[i] = m.tree.joints[0].type == JointType::kFixed ? 0 : 0;
    for (const char* c : {"pelvis_tilt", "pelvis_list", "pelvis_rot", "hip_flex_r", "hip_add_r", "hip_rot_r",
                          "knee_flex_r", "knee_add_r", "knee_rot_r"})
      q[idx(c)] = u(rng);
    for (const char* c : {"pelvis_tx", "pelvis_ty", "pelvis_tz", "knee_tx_r", "knee_ty_r", "knee_tz_r"})
      q[idx(c)] = 0.05 * u(rng);
    KinematicsData k;
    forward_kinematics(m.tree, q, k);
    auto X = [&](const char* b) { return k.X_WB[m.tree.body_index(b)]; };
    // Knee: tibia_proximal_r in femur_distal_r (the world).
    const Eigen::Matrix3d R_knee = Rz(-q[idx("knee_flex_r")]) * Rx(q[idx("knee_add_r")]) * Ry(q[idx("knee_rot_r")]);
    const Vec3 t_knee(q[idx("knee_tx_r")], q[idx("knee_ty_r")], q[idx("knee_tz_r")]);
    EXPECT_LT((X("tibia_proximal_r").linear() - R_knee).norm(), 1e-12);
    EXPECT_LT((X("tibia_proximal_r").translation() - t_knee).norm(), 1e-12);
    // The ankle centre: tibia_r = tibia_proximal_r + (0.006, 0, 0); talus at
    // tibia_r's (-0.01008, -0.40331, 0).
    const Vec3 ankle = t_knee + R_knee * (Vec3(0.006, 0, 0) + Vec3(-0.010082668143607483, -0.4033067257442993, 0));
    EXPECT_LT((X("talus_r").translation() - ankle).norm(), 1e-12);
    // Lab: ground -> pelvis (tilt Z, list X, rot Y, then tx ty tz) -> hip
    // offset -> femur_r (flex Z, add X, rot Y) -> weld -> femur_distal_r.
    Eigen::Isometry3d X_GP = Eigen::Isometry3d::Identity();
    X_GP.linear() = Rz(q[idx("pelvis_tilt")]) * Rx(q[idx("pelvis_list")]) * Ry(q[idx("pelvis_rot")]);
    X_GP.translation() = Vec3(q[idx("pelvis_tx")], q[idx("pelvis_ty")], q[idx("pelvis_tz")]);
    Eigen::Isometry3d X_PF = Eigen::Isometry3d::Identity();
    X_PF.translation() = Vec3(-0.06729784863619219, -0.083241463212077774, 0.092391637387735592);
    Eigen::Isometry3d X_hip = Eigen::Isometry3d::Identity();
    X_hip.linear() = Rz(q[idx("hip_flex_r")]) * Rx(q[idx("hip_add_r")]) * Ry(q[idx("hip_rot_r")]);
    Eigen::Isometry3d X_weld = Eigen::Isometry3d::Identity();
    X_weld.translation() = Vec3(-0.0055513564376633642, -0.37418143637169787, -0.0011706232813375212);
    const Eigen::Isometry3d X_G_femur_distal = X_GP * X_PF * X_hip * X_weld;
    const Eigen::Isometry3d X_G_from_tree = X("ground").inverse();  // world = femur_distal_r
    EXPECT_LT((X_G_from_tree.matrix() - X_G_femur_distal.matrix()).norm(), 1e-12);
  }
}

TEST(OsimImport, UnrepresentableElementsNameTheirLine) {
  const std::string osim = read_text(kOsim);
  auto import_text = [&](const std::string& from, const std::string& to, const std::string& name,
                         const std::string& after = "") {
    std::string x = osim;
    const auto p = x.find(from, after.empty() ? 0 : x.find(after));
    EXPECT_NE(p, std::string::npos) << from;
    x.replace(p, from.size(), to);
    const fs::path dir = scratch(name);
    std::ofstream(dir / "m.osim") << x;
    return message_of([&] { import_osim((dir / "m.osim").string(), (dir / "out").string(), lenhart_options(true)); });
  };
  auto line_of = [&](const std::string& needle) {
    const auto p = osim.find(needle);
    return 1 + std::count(osim.begin(), osim.begin() + p, '\n');
  };
  {
    // knee_add_r through a spline of its coordinate.
    const std::string from = "<coordinates>knee_add_r</coordinates>";
    const auto p = osim.find(from);
    const auto f = osim.find("<LinearFunction name=\"function\">", p);
    const auto fe = osim.find("</LinearFunction>", f) + std::string("</LinearFunction>").size();
    std::string x = osim;
    x.replace(f, fe - f, "<SimmSpline name=\"function\"><x>0 1</x><y>0 2</y></SimmSpline>");
    const fs::path dir = scratch("spline");
    std::ofstream(dir / "m.osim") << x;
    const std::string m =
        message_of([&] { import_osim((dir / "m.osim").string(), (dir / "out").string(), lenhart_options(true)); });
    const int axis_line = static_cast<int>(1 + std::count(osim.begin(), osim.begin() + p, '\n')) - 2;
    EXPECT_NE(m.find("m.osim:" + std::to_string(axis_line) + ": error: joint 'knee_r' rotation2: coordinate "
                     "'knee_add_r' through a SimmSpline"),
              std::string::npos)
        << m;
  }
  {
    const std::string m = import_text("<wrap_object>PatTen_r</wrap_object>", "<wrap_object>NoSuchWrap</wrap_object>",
                                      "wrap");
    EXPECT_NE(m.find("error: ligament 'PT1': unknown wrap object 'NoSuchWrap'"), std::string::npos) << m;
  }
  {
    const std::string m =
        import_text("<mesh_file>lenhart2015-R-tibia-cartilage.stl</mesh_file>",
                    "<mesh_file>missing.stl</mesh_file>", "mesh", "<Smith2018ContactMesh name=\"tibia_cartilage\">");
    EXPECT_NE(m.find("error: contact mesh 'tibia_cartilage': mesh file 'missing.stl' not found"), std::string::npos)
        << m;
  }
  {
    const std::string m = import_text("<use_variable_thickness>false</use_variable_thickness>",
                                      "<use_variable_thickness>true</use_variable_thickness>", "thickness");
    EXPECT_NE(m.find(":" + std::to_string(line_of("<use_variable_thickness>")) +
                     ": error: contact mesh 'femur_cartilage': variable thickness"),
              std::string::npos)
        << m;
  }
  {
    const std::string m = import_text("<OpenSimDocument Version=\"40000\">", "<OpenSimDocument Version=\"30000\">",
                                      "version");
    EXPECT_NE(m.find("m.osim:2: error: expected an OpenSim 4.x model"), std::string::npos) << m;
  }
  EXPECT_NE(message_of([&] {
              OsimImportOptions o = lenhart_options(true);
              o.knee_joint = "knee_x";
              import_osim(kOsim.string(), scratch("knee").string(), o);
            }).find("knee joint 'knee_x' not found"),
            std::string::npos);
}

}  // namespace
}  // namespace arthrosim::musculoskeletal
