// Model-file support for wrapping (docs/model_format.md, "Wrapping"): the
// wrap_cylinder/ellipsoid/sphere/torus elements, conditional and moving
// points with their functions, wrap sets with ranges and methods; file:line
// errors for bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "common/error.h"
#include "musculoskeletal/model.h"
#include "musculoskeletal/model_io.h"

namespace msk = arthrosim::musculoskeletal;
using msk::Vec3;

namespace {

// Femur root; tibia on a revolute "knee_flexion" joint; patella on a
// prismatic "pf_tx" joint.
std::string model_xml(const std::string& extra) {
  std::ostringstream s;
  s << "<?xml version=\"1.0\"?>\n<robot name=\"wrap_test\" xmlns:arthrosim=\"https://arthrosim.org/model\">\n"
    << "  <link name=\"femur\"/>\n  <link name=\"tibia\"/>\n  <link name=\"patella\"/>\n"
    << "  <joint name=\"knee_flexion\" type=\"revolute\"><parent link=\"femur\"/><child link=\"tibia\"/>"
       "<origin xyz=\"0 -0.01 0\"/><axis xyz=\"0 0 1\"/><limit lower=\"-2.5\" upper=\"0.5\" effort=\"0\" velocity=\"0\"/></joint>\n"
    << "  <joint name=\"pf_tx\" type=\"prismatic\"><parent link=\"femur\"/><child link=\"patella\"/>"
       "<origin xyz=\"0.04 0 0\"/><axis xyz=\"1 0 0\"/><limit lower=\"-0.05\" upper=\"0.05\" effort=\"0\" velocity=\"0\"/></joint>\n"
    << extra << "</robot>\n";
  return s.str();
}

const char* kWraps = R"(
  <arthrosim:wrap_cylinder name="KnExt" body="femur" xyz="0.009 -0.02 0" xyz_body_rotation="0 0 0" radius="0.025" length="0.185" quadrant="x"/>
  <arthrosim:wrap_ellipsoid name="Gastroc" body="femur" xyz="0 -0.02 0" xyz_body_rotation="0.059 -0.087 0.023" dimensions="0.0277566 0.0231305 0.138783" chords="6"/>
  <arthrosim:wrap_sphere name="ball" body="tibia" xyz="0 -0.03 0" radius="0.01"/>
  <arthrosim:wrap_torus name="ring" body="patella" xyz="0 0 0" rpy="0 0 0" inner_radius="0.005" outer_radius="0.02"/>
  <arthrosim:ligament name="L" stiffness="500" reference_strain="0.02">
    <bundle><point body="femur" xyz="-0.02 0.03 0.001"/><point body="tibia" xyz="-0.02 -0.06 0.0"/>
      <wrap object="Gastroc" method="hybrid"/></bundle>
  </arthrosim:ligament>
  <arthrosim:muscle name="m" max_isometric_force="800">
    <point body="femur" xyz="0.03 0.2 0"/>
    <conditional_point body="femur" xyz="0.035 0.0 0" coordinate="knee_flexion" range="-2.0 -0.5"/>
    <moving_point body="tibia">
      <x coordinate="knee_flexion"><multiplier_function scale="0.5"><simm_spline x="-2 -1 0 0.5" y="0.02 0.03 0.04 0.041"/></multiplier_function></x>
      <y coordinate="knee_flexion"><linear_function coefficients="0.01 -0.02"/></y>
      <z coordinate="pf_tx"><constant value="0.001"/></z>
    </moving_point>
    <point body="patella" xyz="0 0.01 0"/>
    <wrap object="KnExt" range="1 3"/>
    <wrap object="ball" range="-1 -1" method="midpoint"/>
  </arthrosim:muscle>
)";

std::string error_of(const std::string& xml) {
  try {
    msk::parse_model(xml, "inline.urdf", ".");
  } catch (const arthrosim::common::InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(WrapIo, ParsesWrapObjectsPointsAndWrapSets) {
  const msk::Model m = msk::parse_model(model_xml(kWraps), "inline.urdf", ".");
  ASSERT_EQ(m.muscles.size(), 1u);
  const msk::Path& bp = m.ligaments[0].bundles[0].path;
  ASSERT_EQ(bp.wraps.size(), 1u);
  const msk::WrapSurface& e = bp.wraps[0].surface;
  EXPECT_EQ(e.shape, msk::WrapShape::kEllipsoid);
  EXPECT_EQ(e.semi_axes, Vec3(0.0277566, 0.0231305, 0.138783));
  EXPECT_EQ(e.ellipsoid_chords, 6);
  EXPECT_EQ(bp.wraps[0].method, msk::WrapMethod::kHybrid);
  // OpenSim's body-fixed X-Y-Z angles: R = Rx(a) Ry(b) Rz(c).
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(0.059, Vec3::UnitX()) * Eigen::AngleAxisd(-0.087, Vec3::UnitY()) *
                             Eigen::AngleAxisd(0.023, Vec3::UnitZ()))
                                .toRotationMatrix();
  EXPECT_LT((e.X_BS.linear() - R).norm(), 1e-15);
  EXPECT_EQ(e.X_BS.translation(), Vec3(0, -0.02, 0));

  const msk::Path& mp = m.muscles[0].path;
  ASSERT_EQ(mp.points.size(), 4u);
  EXPECT_TRUE(mp.points[1].is_conditional());
  EXPECT_EQ(mp.points[1].range_min, -2.0);
  EXPECT_TRUE(mp.points[2].is_moving());
  EXPECT_NEAR(mp.points[2].moving[0]->value(-1.0), 0.015, 1e-15);  // 0.5 x 0.03
  EXPECT_NEAR(mp.points[2].moving[1]->value(-1.0), -0.03, 1e-15);
  EXPECT_EQ(mp.points[2].moving_coordinate[2], m.tree.coordinate_index("pf_tx"));
  ASSERT_EQ(mp.wraps.size(), 2u);
  const msk::WrapSurface& c = mp.wraps[0].surface;
  EXPECT_EQ(c.shape, msk::WrapShape::kCylinder);
  EXPECT_EQ(c.quadrant, msk::WrapQuadrant::kPosX);
  EXPECT_EQ(c.length, 0.185);
  EXPECT_EQ(mp.wraps[0].first_point, 0);  // "1 3" -> 0-based 0..2
  EXPECT_EQ(mp.wraps[0].last_point, 2);
  EXPECT_EQ(mp.wraps[1].first_point, -1);
  EXPECT_EQ(mp.wraps[1].method, msk::WrapMethod::kMidpoint);

  // The model evaluates; the bundle's slack length came from its wrapped
  // length at q = 0.
  msk::ModelData d = msk::make_data(m);
  const Eigen::VectorXd q0 = Eigen::VectorXd::Zero(m.num_coordinates());
  msk::evaluate_forces(m, d, q0, Eigen::VectorXd(), Eigen::VectorXd::Constant(1, 0.3));
  EXPECT_NEAR(m.ligaments[0].bundles[0].parameters.slack_length * 1.02, d.ligaments[0][0].path.length, 1e-15);
  EXPECT_TRUE(d.ligaments[0][0].path.wrapped);
  EXPECT_TRUE(d.Q.allFinite());
}

TEST(WrapIo, BadWrappingInputGivesFileLineErrors) {
  const std::string bundle_open =
      "<arthrosim:ligament name=\"X\" stiffness=\"500\" reference_strain=\"0\">\n<bundle>";
  const std::string two_points = "<point body=\"femur\" xyz=\"0 0 0\"/><point body=\"tibia\" xyz=\"0 -0.05 0\"/>";
  const std::string bundle_close = "</bundle>\n</arthrosim:ligament>\n";
  const std::string ell = "<arthrosim:wrap_ellipsoid name=\"E\" body=\"femur\" dimensions=\"0.02 0.02 0.03\"/>\n";
  struct Case {
    std::string extra, expect;
  };
  const std::vector<Case> cases = {
      {"<arthrosim:wrap_ellipsoid name=\"E\" body=\"femur\" dimensions=\"0.02 0 0.03\"/>\n", "semi-axis b > 0"},
      {"<arthrosim:wrap_cylinder name=\"C\" body=\"femur\" radius=\"-0.01\"/>\n", "radius > 0"},
      {"<arthrosim:wrap_cylinder name=\"C\" body=\"femur\" radius=\"0.01\" length=\"0\"/>\n", "length > 0"},
      {"<arthrosim:wrap_torus name=\"T\" body=\"femur\" inner_radius=\"0.03\" outer_radius=\"0.02\"/>\n",
       "inner_radius < outer_radius"},
      {"<arthrosim:wrap_sphere name=\"S\" body=\"femur\" radius=\"0.01\" quadrant=\"+q\"/>\n",
       "attribute 'quadrant' expected all"},
      {"<arthrosim:wrap_sphere name=\"S\" body=\"femur\" radius=\"0.01\" quadrant=\"-x\"/>\n",
       "quadrant restriction is implemented for cylinders only"},
      {"<arthrosim:wrap_sphere name=\"S\" body=\"femur\" radius=\"0.01\" rpy=\"0 0 0\" xyz_body_rotation=\"0 0 0\"/>\n",
       "expected one of rpy or xyz_body_rotation"},
      {"<arthrosim:wrap_sphere name=\"S\" body=\"fibula\" radius=\"0.01\"/>\n", "unknown body 'fibula'"},
      {ell + ell, "duplicate wrap object 'E'"},
      {ell + "<arthrosim:wrap_ellipsoid name=\"F\" body=\"femur\" dimensions=\"0.02 0.02 0.03\" chords=\"1\"/>\n",
       "attribute 'chords' expected an integer"},
      {bundle_open + two_points + "<wrap object=\"nope\"/>" + bundle_close, "unknown wrap object 'nope'"},
      {ell + bundle_open + two_points + "<wrap object=\"E\" range=\"1 3\"/>" + bundle_close,
       "wrap range expected \"first last\" (1-based point indices in 1..2"},
      {ell + bundle_open + two_points + "<wrap object=\"E\" range=\"2 1\"/>" + bundle_close, "first <= last"},
      {ell + bundle_open + two_points + "<wrap object=\"E\" method=\"fast\"/>" + bundle_close,
       "wrap method expected hybrid"},
      {bundle_open + two_points +
           "<moving_point body=\"tibia\"><x coordinate=\"knee_flexion\"><gcv_spline x=\"0 1\" y=\"0 1\"/></x>"
           "<y coordinate=\"knee_flexion\"><constant value=\"0\"/></y><z coordinate=\"knee_flexion\"><constant value=\"0\"/></z>"
           "</moving_point>" +
           bundle_close,
       "unknown function type <gcv_spline>"},
      {bundle_open + two_points +
           "<moving_point body=\"tibia\"><x coordinate=\"knee_flexion\"><simm_spline x=\"0 0\" y=\"0 1\"/></x>"
           "<y coordinate=\"knee_flexion\"><constant value=\"0\"/></y><z coordinate=\"knee_flexion\"><constant value=\"0\"/></z>"
           "</moving_point>" +
           bundle_close,
       "strictly increasing x"},
      {bundle_open + two_points +
           "<moving_point body=\"tibia\"><x coordinate=\"knee_flexion\"><constant value=\"0\"/></x>"
           "<y coordinate=\"knee_flexion\"><constant value=\"0\"/></y></moving_point>" +
           bundle_close,
       "moving_point expected an <z> element"},
      {bundle_open + two_points +
           "<moving_point body=\"tibia\" frame=\"reference\"><x coordinate=\"knee_flexion\"><constant value=\"0\"/></x>"
           "<y coordinate=\"knee_flexion\"><constant value=\"0\"/></y><z coordinate=\"knee_flexion\"><constant value=\"0\"/></z>"
           "</moving_point>" +
           bundle_close,
       "expected frame=\"body\""},
      {bundle_open + two_points +
           "<conditional_point body=\"tibia\" xyz=\"0 0 0\" coordinate=\"hip\" range=\"0 1\"/>" + bundle_close,
       "expected a revolute or prismatic joint, found 'hip'"},
      {bundle_open + two_points +
           "<conditional_point body=\"tibia\" xyz=\"0 0 0\" coordinate=\"knee_flexion\" range=\"1 0\"/>" +
           bundle_close,
       "range=\"min max\" with min <= max"},
      {bundle_open + "<point body=\"femur\" xyz=\"0 0 0\"/>"
                     "<conditional_point body=\"tibia\" xyz=\"0 0 0\" coordinate=\"knee_flexion\" range=\"0 1\"/>" +
           bundle_close,
       "at least 2 <point> elements that are not conditional, found 1"},
      {bundle_open + two_points + "<via body=\"femur\"/>" + bundle_close, "unknown element <via>"},
  };
  for (const auto& c : cases) {
    const std::string xml = model_xml(c.extra);
    const std::string err = error_of(xml);
    EXPECT_NE(err.find(c.expect), std::string::npos) << "expected '" << c.expect << "', got: " << err;
    const int first_extra_line =
        static_cast<int>(std::count(xml.begin(), xml.begin() + xml.find(c.extra), '\n')) + 1;
    const auto colon = err.find(':');
    ASSERT_NE(colon, std::string::npos) << err;
    const int line = std::atoi(err.c_str() + colon + 1);
    EXPECT_GE(line, first_extra_line) << err;
    EXPECT_LE(line, first_extra_line + 2) << err;
    EXPECT_EQ(err.rfind("inline.urdf:", 0), 0u) << err;
  }
}
