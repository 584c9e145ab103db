// The knee model: URDF + extension parsing from inline XML (with file:line
// errors), generalized forces of ligaments, muscles and contact, moment arms
// vs -dl/dq, equal and opposite forces, dQ/dq (Taylor remainder test and
// symmetry of a conservative system).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "common/error.h"
#include "musculoskeletal/model.h"
#include "musculoskeletal/comak.h"
#include "musculoskeletal/model_io.h"

namespace msk = arthrosim::musculoskeletal;
using msk::Vec3;
namespace fs = std::filesystem;

namespace {

// A 6-DOF chain "prefix_{flexion,adduction,rotation,tx,ty,tz}" from parent to child.
std::string chain(const std::string& p, const std::string& parent, const std::string& child,
                  const std::string& origin) {
  const char* names[6] = {"flexion", "adduction", "rotation", "tx", "ty", "tz"};
  const char* axes[6] = {"0 0 1", "1 0 0", "0 1 0", "1 0 0", "0 1 0", "0 0 1"};
  std::ostringstream s;
  std::string prev = parent;
  for (int i = 0; i < 6; ++i) {
    const std::string link = i == 5 ? child : p + "_" + names[i] + "_link";
    if (i < 5) s << "  <link name=\"" << link << "\"/>\n";
    s << "  <joint name=\"" << p << "_" << names[i] << "\" type=\""
      << (i < 3 ? "revolute" : "prismatic") << "\">\n"
      << "    <parent link=\"" << prev << "\"/><child link=\"" << link << "\"/>\n"
      << "    <origin xyz=\"" << (i == 0 ? origin : "0 0 0") << "\" rpy=\"0 0 0\"/>\n"
      << "    <axis xyz=\"" << axes[i] << "\"/>\n"
      << "    <limit lower=\"-2.5\" upper=\"2.5\" effort=\"0\" velocity=\"0\"/>\n  </joint>\n";
    prev = link;
  }
  return s.str();
}

// Femur root; tibia and patella on 6-DOF chains; pelvis on 3 prescribed hip
// joints; calcaneus on a prescribed ankle joint. `extra` goes inside <robot>.
std::string model_xml(const std::string& extra) {
  std::ostringstream s;
  s << "<?xml version=\"1.0\"?>\n<robot name=\"test_knee\" xmlns:arthrosim=\"https://arthrosim.org/model\">\n"
    << "  <link name=\"femur\"><inertial><mass value=\"9\"/><inertia ixx=\"0.1\" ixy=\"0\" ixz=\"0\" iyy=\"0.02\" iyz=\"0\" izz=\"0.1\"/></inertial></link>\n"
    << "  <link name=\"tibia\"/>\n  <link name=\"patella\"/>\n  <link name=\"calcaneus\"/>\n"
    << "  <link name=\"hip_flexion_link\"/><link name=\"hip_adduction_link\"/><link name=\"pelvis\"/>\n"
    << chain("knee", "femur", "tibia", "0 0 0") << chain("pf", "femur", "patella", "0.045 0.01 0.002")
    << "  <joint name=\"hip_flexion\" type=\"revolute\"><parent link=\"femur\"/><child link=\"hip_flexion_link\"/>"
       "<origin xyz=\"0 0.4 -0.03\"/><axis xyz=\"0 0 1\"/><limit lower=\"-2\" upper=\"2\" effort=\"0\" velocity=\"0\"/></joint>\n"
    << "  <joint name=\"hip_adduction\" type=\"revolute\"><parent link=\"hip_flexion_link\"/><child link=\"hip_adduction_link\"/>"
       "<axis xyz=\"1 0 0\"/><limit lower=\"-1\" upper=\"1\" effort=\"0\" velocity=\"0\"/></joint>\n"
    << "  <joint name=\"hip_rotation\" type=\"revolute\"><parent link=\"hip_adduction_link\"/><child link=\"pelvis\"/>"
       "<axis xyz=\"0 1 0\"/><limit lower=\"-1\" upper=\"1\" effort=\"0\" velocity=\"0\"/></joint>\n"
    << "  <joint name=\"ankle_flexion\" type=\"revolute\"><parent link=\"tibia\"/><child link=\"calcaneus\"/>"
       "<origin xyz=\"0 -0.4 0\"/><axis xyz=\"0 0 1\"/><limit lower=\"-1\" upper=\"1\" effort=\"0\" velocity=\"0\"/></joint>\n"
    << "  <arthrosim:prescribed joint=\"hip_flexion\"/>\n  <arthrosim:prescribed joint=\"hip_adduction\"/>\n"
    << "  <arthrosim:prescribed joint=\"hip_rotation\"/>\n  <arthrosim:prescribed joint=\"ankle_flexion\"/>\n"
    << extra << "</robot>\n";
  return s.str();
}

const char* kSoftTissue = R"(
  <arthrosim:wrap_cylinder name="condyle" body="femur" xyz="0 0 0" rpy="0 0 0" radius="0.02"/>
  <arthrosim:ligament name="MCL" stiffness="500" reference_strain="0.05" damping="0.003">
    <bundle><point body="femur" xyz="-0.005 0.03 -0.04"/><point body="tibia" xyz="-0.01 -0.06 -0.035"/></bundle>
    <bundle stiffness="600"><point body="femur" xyz="0.0 0.03 -0.04"/><point body="tibia" xyz="-0.0 -0.07 -0.035"/></bundle>
  </arthrosim:ligament>
  <arthrosim:ligament name="PCL" stiffness="900" reference_strain="-0.02">
    <bundle><point body="femur" xyz="0.005 0.005 -0.005"/><point body="tibia" xyz="-0.025 -0.02 0.0"/></bundle>
  </arthrosim:ligament>
  <arthrosim:ligament name="PT" stiffness="3000">
    <bundle slack_length="0.045"><point body="patella" xyz="0 -0.02 0" frame="body"/><point body="tibia" xyz="0.04 -0.07 0.002"/></bundle>
  </arthrosim:ligament>
  <arthrosim:ligament name="wrapped" stiffness="400" reference_strain="0.03">
    <bundle wrap="condyle"><point body="femur" xyz="-0.03 0.04 0.01"/><point body="tibia" xyz="-0.001 -0.05 0.012"/></bundle>
  </arthrosim:ligament>
  <arthrosim:muscle name="vasmed" max_isometric_force="1443.7">
    <point body="femur" xyz="0.01 0.2 -0.02"/><point body="femur" xyz="0.035 0.05 -0.015"/><point body="patella" xyz="0.0 0.02 0.0"/>
  </arthrosim:muscle>
  <arthrosim:muscle name="recfem" max_isometric_force="848.8">
    <point body="pelvis" xyz="0.03 0.05 0.0"/><point body="femur" xyz="0.04 0.06 0.0"/><point body="patella" xyz="0.0 0.02 0.002"/>
  </arthrosim:muscle>
  <arthrosim:muscle name="gasmed" max_isometric_force="1308">
    <point body="femur" xyz="-0.02 0.03 -0.025"/><point body="tibia" xyz="-0.04 -0.1 -0.02"/><point body="calcaneus" xyz="-0.05 -0.03 0.0"/>
  </arthrosim:muscle>
  <arthrosim:muscle name="bfsh" max_isometric_force="631.6">
    <point body="femur" xyz="-0.01 0.15 0.02"/><point body="tibia" xyz="-0.02 -0.05 0.04"/>
  </arthrosim:muscle>
)";

Eigen::VectorXd some_q(const msk::Model& m, double scale) {
  Eigen::VectorXd q(m.num_coordinates());
  for (int i = 0; i < q.size(); ++i) {
    bool prismatic = false;
    for (const auto& j : m.tree.joints)
      if (j.coordinate == i) prismatic = j.type == msk::JointType::kPrismatic;
    q[i] = (prismatic ? 0.003 : 0.15) * scale * std::sin(1.3 * i + 0.4);
  }
  return q;
}

std::string error_of(const std::string& xml) {
  try {
    msk::parse_model(xml, "inline.urdf", ".");
  } catch (const arthrosim::common::InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(ModelIo, ParsesTreeExtensionsAndReferenceStrains) {
  const auto m = msk::parse_model(model_xml(kSoftTissue), "inline.urdf", ".");
  EXPECT_EQ(m.name, "test_knee");
  EXPECT_EQ(m.num_coordinates(), 16);
  EXPECT_EQ(m.free_coordinates.size(), 12u);
  EXPECT_EQ(m.prescribed_coordinates.size(), 4u);
  EXPECT_EQ(m.ligaments.size(), 4u);
  EXPECT_EQ(m.num_bundles(), 5);
  EXPECT_EQ(m.muscles.size(), 4u);
  EXPECT_DOUBLE_EQ(m.ligaments[0].bundles[1].parameters.stiffness, 600.0);  // bundle overrides
  EXPECT_DOUBLE_EQ(m.ligaments[0].bundles[0].parameters.stiffness, 500.0);  // group default
  EXPECT_DOUBLE_EQ(m.ligaments[2].bundles[0].parameters.slack_length, 0.045);
  EXPECT_DOUBLE_EQ(m.muscles[0].max_isometric_force, 1443.7);
  // Mass from <inertial>.
  EXPECT_DOUBLE_EQ(m.tree.bodies[0].mass, 9.0);
  // Reference strain: at q = 0 every bundle has exactly its reference strain.
  auto d = msk::make_data(m);
  msk::evaluate_forces(m, d, Eigen::VectorXd::Zero(16), {}, {});
  EXPECT_NEAR(d.ligaments[0][0].force.strain, 0.05, 1e-14);
  EXPECT_NEAR(d.ligaments[1][0].force.strain, -0.02, 1e-14);
  EXPECT_NEAR(d.ligaments[3][0].force.strain, 0.03, 1e-14);
  EXPECT_TRUE(d.ligaments[3][0].path.wrapped);
  EXPECT_DOUBLE_EQ(d.ligaments[1][0].force.total, 0.0);  // slack PCL
  // Joint limits from <limit>.
  const auto& j = m.tree.joints[m.tree.bodies[m.tree.body_index("hip_flexion_link")].parent_joint];
  EXPECT_DOUBLE_EQ(j.lower, -2.0);
  EXPECT_DOUBLE_EQ(j.upper, 2.0);
  EXPECT_NEAR(j.X_PJ.translation().y(), 0.4, 1e-15);
}

TEST(ModelIo, BadFilesGiveFileLineErrors) {
  struct Case {
    std::string extra, expect;
  };
  const std::vector<Case> cases = {
      {"<arthrosim:ligament name=\"X\" stiffness=\"500\" reference_strain=\"0\">\n"
       "<bundle><point body=\"femur\" xyz=\"0 0 0\"/><point body=\"fibula\" xyz=\"0 -0.05 0\"/></bundle>\n"
       "</arthrosim:ligament>\n",
       "unknown body 'fibula'"},
      {"<arthrosim:ligament name=\"X\" stiffness=\"-500\" reference_strain=\"0\">\n"
       "<bundle><point body=\"femur\" xyz=\"0 0 0\"/><point body=\"tibia\" xyz=\"0 -0.05 0\"/></bundle>\n"
       "</arthrosim:ligament>\n",
       "stiffness > 0"},
      {"<arthrosim:ligament name=\"X\" stiffness=\"500\">\n"
       "<bundle slack_length=\"0\"><point body=\"femur\" xyz=\"0 0 0\"/><point body=\"tibia\" xyz=\"0 -0.05 0\"/></bundle>\n"
       "</arthrosim:ligament>\n",
       "slack length > 0"},
      {"<arthrosim:surface name=\"s\" body=\"tibia\" mesh=\"no_such_mesh.stl\" thickness_mm=\"3\"/>\n",
       "expected an existing file"},
      {"<arthrosim:muscle name=\"m\" max_isometric_force=\"abc\"><point body=\"femur\" xyz=\"0 0 0\"/>"
       "<point body=\"tibia\" xyz=\"0 0 0\"/></arthrosim:muscle>\n",
       "expected a finite number"},
      {"<arthrosim:muscle name=\"m\" max_isometric_force=\"100\"><point body=\"femur\" xyz=\"0 0\"/>"
       "<point body=\"tibia\" xyz=\"0 0 0\"/></arthrosim:muscle>\n",
       "expected three numbers"},
      {"<arthrosim:contact name=\"c\" casting=\"a\" target=\"b\" youngs_modulus_mpa=\"10\" poisson_ratio=\"0.45\"/>\n",
       "unknown surface 'a'"},
      {"<arthrosim:spring name=\"x\"/>\n", "unknown element <arthrosim:spring>"},
      {"<arthrosim:prescribed joint=\"knee\"/>\n", "prescribed: expected a revolute"},
      // Negative slack length (the issue's "slack length <= 0": 0 above, < 0 here).
      {"<arthrosim:ligament name=\"X\" stiffness=\"500\">\n"
       "<bundle slack_length=\"-0.02\"><point body=\"femur\" xyz=\"0 0 0\"/><point body=\"tibia\" xyz=\"0 -0.05 0\"/></bundle>\n"
       "</arthrosim:ligament>\n",
       "slack length > 0"},
      // A reference strain <= -1 would give a negative or infinite slack length.
      {"<arthrosim:ligament name=\"X\" stiffness=\"500\">\n"
       "<bundle reference_strain=\"-1\"><point body=\"femur\" xyz=\"0 0 0\"/><point body=\"tibia\" xyz=\"0 -0.05 0\"/></bundle>\n"
       "</arthrosim:ligament>\n",
       "reference_strain > -1"},
      {"<arthrosim:ligament name=\"X\" stiffness=\"500\" reference_strain=\"0\" damping=\"-0.1\">\n"
       "<bundle><point body=\"femur\" xyz=\"0 0 0\"/><point body=\"tibia\" xyz=\"0 -0.05 0\"/></bundle>\n"
       "</arthrosim:ligament>\n",
       "damping >= 0"},
      // Unknown body on a muscle point; F_max <= 0.
      {"<arthrosim:muscle name=\"m\" max_isometric_force=\"100\"><point body=\"femur\" xyz=\"0 0 0\"/>"
       "<point body=\"foot\" xyz=\"0 0 0\"/></arthrosim:muscle>\n",
       "unknown body 'foot'"},
      {"<arthrosim:muscle name=\"m\" max_isometric_force=\"0\"><point body=\"femur\" xyz=\"0 0 0\"/>"
       "<point body=\"tibia\" xyz=\"0 0 0\"/></arthrosim:muscle>\n",
       "max_isometric_force > 0"},
      // Missing mesh of a URDF link (<visual>), reported at the <mesh> line.
      {"<link name=\"extra\"><visual><geometry>\n<mesh filename=\"no_such_bone.stl\"/></geometry></visual></link>\n",
       "expected an existing file, found 'no_such_bone.stl'"},
      {"<arthrosim:ligament name=\"X\" stiffness=\"500\" reference_strain=\"0\">\n"
       "<bundle wrap=\"nope\"><point body=\"femur\" xyz=\"0 0 0\"/><point body=\"tibia\" xyz=\"0 -0.05 0\"/></bundle>\n"
       "</arthrosim:ligament>\n",
       "unknown wrap object 'nope'"},
  };
  for (const auto& c : cases) {
    const std::string xml = model_xml(c.extra);
    const std::string err = error_of(xml);
    EXPECT_NE(err.find(c.expect), std::string::npos) << "got: " << err;
    // The reported line is the line of the offending element (which lies in `extra`).
    const int first_extra_line =
        static_cast<int>(std::count(xml.begin(), xml.begin() + xml.find(c.extra), '\n')) + 1;
    const auto colon = err.find(':');
    ASSERT_NE(colon, std::string::npos);
    const int line = std::atoi(err.c_str() + colon + 1);
    EXPECT_GE(line, first_extra_line) << err;
    EXPECT_LE(line, first_extra_line + 2) << err;
    EXPECT_EQ(err.rfind("inline.urdf:", 0), 0u) << err;
  }
  // Structure errors: unknown joint link, bad XML, bad joint type.
  std::string xml = model_xml("");
  xml.replace(xml.find("<parent link=\"femur\"/>"), 22, "<parent link=\"femurx\"/>");
  EXPECT_NE(error_of(xml).find("unknown parent link 'femurx'"), std::string::npos);
  EXPECT_NE(error_of("<robot name=\"x\"><link name=\"a\"></robot>").find("inline.urdf:1"),
            std::string::npos);
  xml = model_xml("");
  xml.replace(xml.find("type=\"prismatic\""), 16, "type=\"floating\"");
  EXPECT_NE(error_of(xml).find("expected type revolute"), std::string::npos);
}

TEST(ModelForces, MomentArmsEqualMinusLengthGradient) {
  const auto m = msk::parse_model(model_xml(kSoftTissue), "inline.urdf", ".");
  auto d = msk::make_data(m);
  const Eigen::VectorXd q = some_q(m, 1.0);
  msk::evaluate_forces(m, d, q, {}, {});
  const double h = 1e-6;
  auto lengths = [&](const Eigen::VectorXd& qq) {
    auto dd = msk::make_data(m);
    msk::evaluate_forces(m, dd, qq, {}, {});
    std::vector<double> l;
    for (const auto& p : dd.muscle_paths) l.push_back(p.length);
    for (const auto& lig : dd.ligaments)
      for (const auto& b : lig) l.push_back(b.path.length);
    return l;
  };
  std::vector<Eigen::VectorXd> r;
  for (const auto& p : d.muscle_paths) r.push_back(msk::moment_arms(m, d, p));
  for (const auto& lig : d.ligaments)
    for (const auto& b : lig) r.push_back(msk::moment_arms(m, d, b.path));
  for (int i = 0; i < m.num_coordinates(); ++i) {
    Eigen::VectorXd qp = q, qm = q;
    qp[i] += h;
    qm[i] -= h;
    const auto lp = lengths(qp), lm = lengths(qm);
    for (size_t k = 0; k < r.size(); ++k)
      // Central differences: truncation h^2 l''' ~ 1e-12, round-off 1e-16/1e-6: 1e-8 m is tight.
      EXPECT_NEAR(r[k][i], -(lp[k] - lm[k]) / (2 * h), 1e-8) << "path " << k << " coord " << i;
  }
  // Muscles crossing the hip/ankle have moment arms there; the vasti do not.
  const int hip = m.tree.coordinate_index("hip_flexion"), ankle = m.tree.coordinate_index("ankle_flexion");
  EXPECT_GT(std::abs(r[1][hip]), 1e-3);    // rectus femoris
  EXPECT_EQ(r[0][hip], 0.0);               // vastus medialis
  EXPECT_GT(std::abs(r[2][ankle]), 1e-3);  // gastrocnemius
}

TEST(ModelForces, MuscleForcesAreEqualAndOppositeAndScaleWithActivation) {
  const auto m = msk::parse_model(model_xml(kSoftTissue), "inline.urdf", ".");
  auto d = msk::make_data(m);
  const Eigen::VectorXd q = some_q(m, 0.7);
  Eigen::VectorXd a(4);
  a << 0.3, 0.0, 0.0, 0.0;
  msk::ForceOptions only_muscles;
  only_muscles.ligaments = only_muscles.contact = false;
  msk::evaluate_forces(m, d, q, {}, a, only_muscles);
  const Eigen::VectorXd Q1 = d.Q;
  EXPECT_NEAR(d.muscle_forces[0], 0.3 * 1443.7, 1e-12);
  // Sum of the applied forces on all bodies is zero; the force on the patella
  // has magnitude F (one segment ends there).
  Vec3 net = Vec3::Zero(), on_patella = Vec3::Zero();
  for (const auto& ap : d.muscle_paths[0].applications) {
    net += ap.direction_W;
    if (ap.body == m.tree.body_index("patella")) on_patella += ap.direction_W;
  }
  EXPECT_LT(net.norm(), 1e-14);
  EXPECT_NEAR(on_patella.norm(), 1.0, 1e-14);
  // Linear in activation.
  a[0] = 0.6;
  msk::evaluate_forces(m, d, q, {}, a, only_muscles);
  EXPECT_LT((d.Q - 2 * Q1).norm(), 1e-12 * Q1.norm());
  // Generalized force = F r.
  EXPECT_LT((d.Q - 0.6 * 1443.7 * msk::moment_arms(m, d, d.muscle_paths[0])).norm(), 1e-9);
}

namespace {
// Q must satisfy Q(q + e v) = Q(q) + e J v + O(e^2): the remainder shrinks 4x when e halves.
void expect_taylor_second_order(const msk::Model& m, const Eigen::VectorXd& q,
                                const msk::ForceOptions& opt, const std::vector<int>& cols,
                                const Eigen::VectorXd& activations = {}) {
  auto d = msk::make_data(m);
  msk::evaluate_jacobian(m, d, q, {}, activations, opt, cols);
  const Eigen::MatrixXd J = d.dQ_dq;
  const Eigen::VectorXd Q0 = d.Q;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(q.size());
  for (int c : cols) v[c] = u(rng) * 0.01;  // mixed rad / ~1 cm scale per unit e
  std::vector<double> rem;
  for (double e : {0.2, 0.1, 0.05}) {
    msk::evaluate_forces(m, d, q + e * v, {}, activations, opt);
    rem.push_back((d.Q - Q0 - e * J * v).norm());
  }
  std::printf("Taylor remainders %.3e %.3e %.3e (ratios %.2f %.2f), |Jv| %.3e\n", rem[0], rem[1],
              rem[2], rem[0] / rem[1], rem[1] / rem[2], (J * v).norm());
  // Second order: ratios ~4 (3 allows for the third-order term at the larger e).
  EXPECT_GT(rem[0] / rem[1], 3.0);
  EXPECT_GT(rem[1] / rem[2], 3.0);
}
}  // namespace

TEST(ModelForces, LigamentJacobianPassesTaylorTestAndIsSymmetric) {
  // Undamped bundles are conservative (Q = -dV/dq), so dQ/dq is symmetric.
  std::string tissue = kSoftTissue;
  for (size_t p = tissue.find("damping=\"0.003\""); p != std::string::npos;
       p = tissue.find("damping=\"0.003\""))
    tissue.replace(p, 15, "damping=\"0\"");
  const auto m = msk::parse_model(model_xml(tissue), "inline.urdf", ".");
  msk::ForceOptions opt;
  opt.muscles = opt.contact = false;
  // A pose where the bundles are taut (in the linear region of most of them).
  Eigen::VectorXd q = some_q(m, 1.0);
  q[m.tree.coordinate_index("knee_ty")] = -0.004;
  q[m.tree.coordinate_index("pf_ty")] = -0.006;
  auto d = msk::make_data(m);
  msk::evaluate_jacobian(m, d, q, {}, {}, opt);
  int taut = 0;
  for (const auto& lig : d.ligaments)
    for (const auto& b : lig) taut += b.force.total > 0;
  ASSERT_GE(taut, 4);
  const Eigen::MatrixXd& J = d.dQ_dq;
  // FD error ~h^2 Q''' + round-off 1e-16 * |Q| / h: relative 1e-6 of the largest entry.
  EXPECT_LT((J - J.transpose()).cwiseAbs().maxCoeff(), 1e-6 * J.cwiseAbs().maxCoeff());
  std::vector<int> all;
  for (int i = 0; i < m.num_coordinates(); ++i) all.push_back(i);
  expect_taylor_second_order(m, q, opt, all);
}

// Muscles: Q = a F_max r(q) with via points on four bodies (pelvis and
// calcaneus on the prescribed hip and ankle joints): the finite-difference
// dQ/dq over all 16 coordinates passes the same Taylor test, and the columns
// of the prescribed coordinates are non-zero (the hip and ankle angles move
// the biarticular paths).
TEST(ModelForces, MuscleJacobianPassesTaylorTest) {
  const auto m = msk::parse_model(model_xml(kSoftTissue), "inline.urdf", ".");
  msk::ForceOptions opt;
  opt.ligaments = opt.contact = false;
  const Eigen::VectorXd q = some_q(m, 1.0);
  const Eigen::Vector4d a(0.4, 0.3, 0.5, 0.2);
  std::vector<int> all;
  for (int i = 0; i < m.num_coordinates(); ++i) all.push_back(i);
  auto d = msk::make_data(m);
  msk::evaluate_jacobian(m, d, q, {}, a, opt, all);
  // Rectus femoris (pelvis -> patella) and gastrocnemius (femur -> calcaneus).
  EXPECT_GT(d.dQ_dq.col(m.tree.coordinate_index("hip_flexion")).norm(), 1.0);
  EXPECT_GT(d.dQ_dq.col(m.tree.coordinate_index("ankle_flexion")).norm(), 1.0);
  expect_taylor_second_order(m, q, opt, all, a);
}

#include "common/mesh_io.h"

namespace {

// Grid patch in the xy plane (normal +z) mapped by (x, y, z) -> (x, z, -y) so
// that the normal becomes +y; `height(x, y)` gives the z before mapping.
template <class H>
arthrosim::common::TriangleMesh patch(double L, int n, bool flip, H height) {
  arthrosim::common::TriangleMesh m;
  m.V.resize((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = -L + 2 * L * i / n + 1.234e-5, y = -L + 2 * L * j / n + 0.987e-5;
      const double z = height(x, y);
      m.V.row(j * (n + 1) + i) << x, z, -y;
    }
  m.F.resize(2 * n * n, 3);
  int t = 0;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
      if (flip) {
        m.F.row(t++) << a, c, b;
        m.F.row(t++) << a, d, c;
      } else {
        m.F.row(t++) << a, b, c;
        m.F.row(t++) << a, c, d;
      }
    }
  return m;
}

// Tibial plane (casting, thickness from a per-vertex csv) against a femoral
// sphere cap (target, radius 20 mm, 1 mm indentation at q = 0).
std::string contact_files() {
  const fs::path dir = fs::path(ARTHROSIM_BINARY_DIR) / "tmp" / "model_test";
  fs::create_directories(dir);
  const auto plane = patch(0.01, 50, false, [](double, double) { return 0.0; });
  const double R = 0.02, delta = 0.001;
  const auto cap = patch(0.009, 90, true, [&](double x, double y) {
    return (R - delta) - std::sqrt(R * R - x * x - y * y);
  });
  arthrosim::common::write_stl(plane, (dir / "tibia_plane.stl").string());
  arthrosim::common::write_stl(cap, (dir / "femur_cap.stl").string());
  // Re-read so the csv rows follow the welded STL vertex order.
  const auto back = arthrosim::common::read_mesh((dir / "tibia_plane.stl").string());
  std::ofstream csv(dir / "tibia_plane_thickness.csv");
  csv << "# per-vertex thickness of tibia_plane.stl\nx_mm,y_mm,z_mm,thickness_mm\n";
  csv.precision(17);
  for (int i = 0; i < back.num_vertices(); ++i)
    csv << back.V(i, 0) * 1e3 << "," << back.V(i, 1) * 1e3 << "," << back.V(i, 2) * 1e3 << ","
        << 2.0 + 100.0 * back.V(i, 0) << "\n";  // 1..3 mm, varying along x
  return dir.string();
}

const char* kContact = R"(
  <arthrosim:surface name="tib" body="tibia" mesh="tibia_plane.stl" unit="mm" thickness_csv="tibia_plane_thickness.csv" frame="reference"/>
  <arthrosim:surface name="fem" body="femur" mesh="femur_cap.stl" unit="mm" thickness_mm="1"/>
  <arthrosim:contact name="tf" casting="tib" target="fem" youngs_modulus_mpa="10" poisson_ratio="0.45" law="linear"/>
)";

}  // namespace

TEST(ModelForces, ContactGeneralizedForcesMatchPerTriangleAssembly) {
  const std::string dir = contact_files();
  const auto m = msk::parse_model(model_xml(kContact), "inline.urdf", dir);
  ASSERT_EQ(m.contacts.size(), 1u);
  // Per-triangle thickness = mean of the vertex values + 1 mm of the femur.
  EXPECT_GT(m.contacts[0].casting().thickness.maxCoeff(), 2.5e-3);
  EXPECT_LT(m.contacts[0].casting().thickness.minCoeff(), 1.5e-3);
  auto d = msk::make_data(m);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
  q[m.tree.coordinate_index("knee_flexion")] = 0.02;
  q[m.tree.coordinate_index("knee_adduction")] = -0.01;
  q[m.tree.coordinate_index("knee_tx")] = 0.0005;
  msk::evaluate_forces(m, d, q, {}, {});
  const auto& r = d.contacts[0].result;
  ASSERT_GT(r.num_contacting, 50);
  // Independent assembly: every triangle's force through its own point Jacobians.
  const auto& pair = m.contacts[0];
  const int tib = pair.casting().body, fem = pair.target().body;
  Eigen::VectorXd Q = Eigen::VectorXd::Zero(m.num_coordinates());
  for (int i = 0; i < r.pressure.size(); ++i) {
    if (r.pressure[i] == 0) continue;
    const Vec3 c = d.kinematics.X_WB[tib] * Vec3(pair.casting_centres().row(i).transpose());
    const Vec3 n = d.kinematics.X_WB[tib].linear() * Vec3(pair.casting_normals().row(i).transpose());
    const Vec3 f = -r.pressure[i] * pair.casting_areas()[i] * n;  // on the tibia
    Q += msk::point_jacobian(m.tree, d.kinematics, tib, c).transpose() * f;
    Q -= msk::point_jacobian(m.tree, d.kinematics, fem, c).transpose() * f;
  }
  // Same sums in another order: round-off only (1e-12 relative to |Q|).
  EXPECT_LT((Q - d.Q_contact).norm(), 1e-10 * d.Q_contact.norm());
  EXPECT_GT(d.Q_contact.norm(), 10.0);
  // The femur is the root: nothing acts on its (non-existent) coordinates, and
  // the force pushes the tibia down (-y): Q for knee_ty is negative.
  EXPECT_LT(d.Q_contact[m.tree.coordinate_index("knee_ty")], 0.0);
}

TEST(ModelForces, ContactJacobianPassesTaylorTest) {
  const std::string dir = contact_files();
  const auto m = msk::parse_model(model_xml(kContact), "inline.urdf", dir);
  msk::ForceOptions opt;
  opt.ligaments = opt.muscles = false;
  Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
  q[m.tree.coordinate_index("knee_flexion")] = 0.02;
  std::vector<int> knee;
  for (const char* c : {"knee_flexion", "knee_adduction", "knee_rotation", "knee_tx", "knee_ty", "knee_tz"})
    knee.push_back(m.tree.coordinate_index(c));
  expect_taylor_second_order(m, q, opt, knee);
}

#include "musculoskeletal/settle.h"

TEST(Settle, TibiaOnPlaneReachesEquilibriumFromDifferentStarts) {
  const std::string dir = contact_files();
  const auto m = msk::parse_model(model_xml(std::string(kSoftTissue) + kContact), "inline.urdf", dir);
  auto d = msk::make_data(m);
  msk::SettleOptions opt;
  opt.muscle_tone = 0.0;
  // Flexion held; the patella (no patellofemoral contact in this model) held too.
  for (const char* c : {"knee_flexion", "pf_flexion", "pf_adduction", "pf_rotation", "pf_tx", "pf_ty", "pf_tz"})
    opt.fixed.push_back(m.tree.coordinate_index(c));
  std::vector<Eigen::VectorXd> solutions;
  for (double start : {0.0, 1.0}) {
    Eigen::VectorXd q0 = Eigen::VectorXd::Zero(m.num_coordinates());
    q0[m.tree.coordinate_index("knee_tx")] = 0.001 * start;
    q0[m.tree.coordinate_index("knee_rotation")] = 0.03 * start;
    const auto res = msk::settle(m, d, q0, opt);
    std::printf("%s\n", res.message.c_str());
    ASSERT_EQ(res.status, msk::SettleStatus::kConverged) << res.message;
    EXPECT_LE(res.max_force_residual, opt.force_tolerance);
    EXPECT_LE(res.max_moment_residual, opt.moment_tolerance);
    // Independent re-evaluation at the returned point.
    auto d2 = msk::make_data(m);
    msk::evaluate_forces(m, d2, res.q, {}, Eigen::VectorXd::Zero(4));
    for (const char* c : {"knee_tx", "knee_ty", "knee_tz"})
      EXPECT_LE(std::abs(d2.Q[m.tree.coordinate_index(c)]), opt.force_tolerance);
    EXPECT_GT(d2.contacts[0].result.force_on_target_W.norm(), 1.0);  // loaded contact
    solutions.push_back(res.q);
  }
  // Same equilibrium from both starts (to the accuracy the residual tolerance
  // allows: 0.1 N over a stiffness >~1e4 N/m -> 1e-5 m).
  EXPECT_LT((solutions[0] - solutions[1]).head(6).cwiseAbs().maxCoeff(), 2e-4);
}

// Force-length scaling (ForceOptions::force_length): the curve's closed
// form (Thelen 2003, gamma 0.45), the muscle force a F_max f_L((l - l_ts) /
// l_opt) at a pose, and the activation columns of COMAK's Jacobian (F_max
// f_L r, exact) against central differences in a (the residual is linear in
// a, so the quotient is exact to rounding: 1e-9 relative).
TEST(ModelForces, ForceLengthScaling) {
  EXPECT_EQ(msk::active_force_length(1.0), 1.0);
  EXPECT_NEAR(msk::active_force_length(0.5), std::exp(-0.25 / 0.45), 1e-15);
  EXPECT_NEAR(msk::active_force_length(1.5), 0.5738, 1e-4);
  EXPECT_NEAR(msk::active_force_length(1.5, 0.1), std::exp(-2.5), 1e-15);
  const std::string muscles = R"(
  <arthrosim:muscle name="vasmed" max_isometric_force="1443.7" optimal_fiber_length="0.089" tendon_slack_length="0.126">
    <point body="femur" xyz="0.01 0.2 -0.02"/><point body="femur" xyz="0.035 0.05 -0.015"/><point body="patella" xyz="0.0 0.02 0.0"/>
  </arthrosim:muscle>
  <arthrosim:muscle name="bfsh" max_isometric_force="631.6" optimal_fiber_length="0.173" tendon_slack_length="0.02">
    <point body="femur" xyz="-0.01 0.15 0.02"/><point body="tibia" xyz="-0.02 -0.05 0.04"/>
  </arthrosim:muscle>
)";
  const auto m = msk::parse_model(model_xml(muscles), "inline.urdf", ".");
  EXPECT_EQ(m.muscles[0].optimal_fiber_length, 0.089);
  EXPECT_EQ(m.muscles[1].tendon_slack_length, 0.02);
  auto d = msk::make_data(m);
  const Eigen::VectorXd q = some_q(m, 0.7);
  const Eigen::Vector2d a(0.3, 0.2);
  msk::ForceOptions o;
  o.ligaments = o.contact = false;
  o.force_length = true;
  msk::evaluate_forces(m, d, q, {}, a, o);
  for (int i = 0; i < 2; ++i) {
    const auto& mu = m.muscles[i];
    const double x = (d.muscle_paths[i].length - mu.tendon_slack_length) / mu.optimal_fiber_length;
    std::printf("%s: path %.4f m, l~ = %.3f, f_L = %.4f\n", mu.name.c_str(), d.muscle_paths[i].length, x,
                d.muscle_force_length[i]);
    EXPECT_NEAR(d.muscle_force_length[i], std::exp(-(x - 1) * (x - 1) / 0.45), 1e-14);
    EXPECT_NEAR(d.muscle_forces[i], a[i] * mu.max_isometric_force * d.muscle_force_length[i], 1e-9);
    EXPECT_LT(d.muscle_force_length[i], 1.0);  // this pose is not at l_opt: the scaling acts
  }
  // COMAK activation columns.
  msk::ComakOptions co;
  co.forces = o;
  msk::ComakProblem p(m, co);
  msk::ComakFrameInput in;
  in.knee_flexion = 0.3;
  const Eigen::VectorXd qq = p.coordinates(in, q);
  const Eigen::MatrixXd J = p.residual_jacobian(d, in, qq, a);
  for (int i = 0; i < 2; ++i) {
    const double h = 1e-3;
    Eigen::VectorXd ap = a, am = a;
    ap[i] += h, am[i] -= h;
    const Eigen::VectorXd fd = (p.residual(d, in, qq, ap, {}) - p.residual(d, in, qq, am, {})) / (2 * h);
    EXPECT_LT((J.col(i) - fd).cwiseAbs().maxCoeff(), 1e-9 * std::max(1.0, fd.cwiseAbs().maxCoeff())) << i;
  }
  // A model without the lengths cannot use the option; a file giving one of
  // the two is rejected with its line.
  const auto plain = msk::parse_model(model_xml(kSoftTissue), "inline.urdf", ".");
  auto dp = msk::make_data(plain);
  EXPECT_THROW(msk::evaluate_forces(plain, dp, some_q(plain, 0.5), {}, Eigen::VectorXd::Constant(4, 0.1), o),
               arthrosim::common::InputError);
  const std::string half = R"(
  <arthrosim:muscle name="x" max_isometric_force="10" optimal_fiber_length="0.1">
    <point body="femur" xyz="0 0.1 0"/><point body="tibia" xyz="0 -0.1 0"/>
  </arthrosim:muscle>
)";
  EXPECT_NE(error_of(model_xml(half)).find("inline.urdf:"), std::string::npos) << error_of(model_xml(half));
}

// split_lateral on a surface holding both tibial plateaus: labels by
// prepare's rule (here one connected plane: the 2-means cut), a bad
// direction names the line.
TEST(ModelIo, SplitLateralLabelsTheSurfaceAndBadDirectionsAreRefused) {
  const std::string dir = contact_files();
  std::string extra = kContact;
  const std::string tib = "thickness_csv=\"tibia_plane_thickness.csv\"";
  extra.replace(extra.find(tib), tib.size(), tib + " split_lateral=\"+x\"");
  const auto m = msk::parse_model(model_xml(extra), "inline.urdf", dir);
  const msk::ContactSurface& s = m.contacts[0].casting();
  ASSERT_EQ(static_cast<int>(s.compartment.size()), s.mesh.num_triangles());
  const int lateral = static_cast<int>(std::count(s.compartment.begin(), s.compartment.end(), 1));
  EXPECT_GT(lateral, 0);
  EXPECT_LT(lateral, s.mesh.num_triangles());
  EXPECT_NE(s.compartment_rule.find("one connected piece"), std::string::npos) << s.compartment_rule;
  for (const char* bad : {"+q", "0 0 0", "1 2"}) {
    std::string e = kContact;
    e.replace(e.find(tib), tib.size(), tib + " split_lateral=\"" + bad + "\"");
    const std::string err = [&] {
      try {
        msk::parse_model(model_xml(e), "inline.urdf", dir);
      } catch (const std::exception& x) {
        return std::string(x.what());
      }
      return std::string();
    }();
    EXPECT_NE(err.find("split_lateral"), std::string::npos) << bad << ": " << err;
    EXPECT_EQ(err.rfind("inline.urdf:", 0), 0u) << err;
  }
}
