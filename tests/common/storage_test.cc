// .sto/.mot tests: reading literal files of both header styles (values
// checked by hand), degrees -> radians on the rotational columns only, round
// trips through the writer in both styles, and every error with its line.
#include "common/storage.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>

#include "common/error.h"

namespace arthrosim::common {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr double kDeg = std::numbers::pi / 180.0;

fs::path temp_dir() {
  fs::path d = fs::path(ARTHROSIM_BINARY_DIR) / "test_output" / "storage_test";
  fs::create_directories(d);
  return d;
}

StorageTable parse(const std::string& text, const RotationalPredicate& pred = default_is_rotational) {
  std::istringstream in(text);
  return parse_storage(in, "test.mot", pred);
}

// Old style (OpenSim 3 / SIMM), with free-text header lines and CRLF endings.
const char* kOldStyle =
    "Coordinates\r\n"
    "version=1\r\n"
    "nRows=3\r\n"
    "nColumns=5\r\n"
    "inDegrees=yes\r\n"
    "\r\n"
    "Units are S.I. units (second, meters, Newtons, ...)\r\n"
    "Angles are in degrees.\r\n"
    "\r\n"
    "endheader\r\n"
    "time\tknee_angle_r\tknee_tx_r\tpelvis_ty\thip_flexion_l\r\n"
    "0.00\t-5.0\t0.001\t0.95\t30\r\n"
    "0.01\t-10.0\t0.002\t0.96\t31.5\r\n"
    "0.02\t90\t-0.003\t0.97\t-45\r\n";

TEST(Storage, ReadsOldStyleAndConvertsDegreesOnRotationalColumns) {
  const StorageTable t = parse(kOldStyle);
  EXPECT_EQ(t.style, StorageStyle::kOld);
  EXPECT_EQ(t.name, "Coordinates");
  EXPECT_TRUE(t.in_degrees);
  EXPECT_TRUE(t.metadata.empty());
  ASSERT_EQ(t.labels, (std::vector<std::string>{"time", "knee_angle_r", "knee_tx_r", "pelvis_ty", "hip_flexion_l"}));
  ASSERT_EQ(t.num_rows(), 3);
  ASSERT_EQ(t.num_columns(), 5);
  EXPECT_EQ(t.time(), Eigen::Vector3d(0.0, 0.01, 0.02));
  EXPECT_EQ(t.data_line, 12);  // row r is on line 12 + r
  // Rotational: converted (a single multiplication by pi/180 -> exact match
  // with the same expression).
  EXPECT_EQ(t.column("knee_angle_r"), Eigen::Vector3d(-5.0 * kDeg, -10.0 * kDeg, 90 * kDeg));
  EXPECT_DOUBLE_EQ(t.column("knee_angle_r")(2), std::numbers::pi / 2);
  EXPECT_EQ(t.column("hip_flexion_l"), Eigen::Vector3d(30 * kDeg, 31.5 * kDeg, -45 * kDeg));
  // Translations: untouched.
  EXPECT_EQ(t.column("knee_tx_r"), Eigen::Vector3d(0.001, 0.002, -0.003));
  EXPECT_EQ(t.column("pelvis_ty"), Eigen::Vector3d(0.95, 0.96, 0.97));
  EXPECT_EQ(t.column_index("pelvis_ty"), 3);
  EXPECT_EQ(t.column_index("nope"), -1);
  try {
    t.column("nope");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), HasSubstr("no column 'nope' (columns: time, knee_angle_r, knee_tx_r"));
  }
}

// OpenSim 4 style: key=value lines, no nRows, state paths as labels.
const char* kOpenSim4 =
    "walk_states\n"
    "inDegrees=no\n"
    "DataType=double\n"
    "version=3\n"
    "OpenSimVersion=4.4\n"
    "endheader\n"
    "time\t/jointset/knee_r/knee_angle_r/value\t/jointset/knee_r/knee_angle_r/speed\t/forceset/soleus_r/activation\n"
    "0\t0.1\t-1.5\t0.02\n"
    "0.5\t0.2\t1e-3\t0.5\n"
    "\n";

TEST(Storage, ReadsOpenSim4Style) {
  const StorageTable t = parse(kOpenSim4);
  EXPECT_EQ(t.style, StorageStyle::kOpenSim4);
  EXPECT_EQ(t.name, "walk_states");
  EXPECT_FALSE(t.in_degrees);
  EXPECT_EQ(t.metadata, (std::map<std::string, std::string>{{"DataType", "double"}, {"OpenSimVersion", "4.4"}}));
  ASSERT_EQ(t.num_rows(), 2);
  EXPECT_EQ(t.column("/jointset/knee_r/knee_angle_r/speed"), Eigen::Vector2d(-1.5, 1e-3));  // no conversion
  // No name line at all is also OpenSim 4.
  const StorageTable u = parse("inDegrees=no\nendheader\ntime a\n1 2\n");
  EXPECT_EQ(u.style, StorageStyle::kOpenSim4);
  EXPECT_EQ(u.name, "");
  EXPECT_EQ(u.data, Eigen::RowVector2d(1, 2));
}

TEST(Storage, DegreesInOpenSim4StatesConvertAnglesAndSpeedsOnly) {
  std::string text = kOpenSim4;
  text.replace(text.find("inDegrees=no"), 12, "inDegrees=yes");
  const StorageTable t = parse(text);
  EXPECT_EQ(t.column("/jointset/knee_r/knee_angle_r/value"), Eigen::Vector2d(0.1 * kDeg, 0.2 * kDeg));
  EXPECT_EQ(t.column("/jointset/knee_r/knee_angle_r/speed"), Eigen::Vector2d(-1.5 * kDeg, 1e-3 * kDeg));
  EXPECT_EQ(t.column("/forceset/soleus_r/activation"), Eigen::Vector2d(0.02, 0.5));
}

TEST(Storage, DefaultRotationalRule) {
  for (const char* l : {"knee_angle_r", "hip_flexion_l", "pelvis_tilt", "pelvis_list", "pelvis_rotation",
                        "knee_adduction_r", "/jointset/hip_r/hip_rotation_r/value", "lumbar_extension"}) {
    EXPECT_TRUE(default_is_rotational(l)) << l;
  }
  for (const char* l : {"time", "pelvis_tx", "pelvis_ty", "pelvis_tz", "knee_tx_r", "pf_ty_l", "ground_force_vx",
                        "ground_force_px", "1_ground_force_vy", "ground_torque_x", "r_ground_moment_z",
                        "knee_r_on_tibia_in_tibia_fx", "/forceset/soleus_r/activation",
                        "/forceset/soleus_r/normalized_tendon_force", "/forceset/vasmed_r/fiber_length",
                        "center_of_mass_X", "soleus_r_excitation", "cop_x", "RKNE_y"}) {
    EXPECT_FALSE(default_is_rotational(l)) << l;
  }
  // A caller-supplied list overrides the rule.
  const StorageTable t = parse(kOldStyle, rotational_columns({"pelvis_ty"}));
  EXPECT_EQ(t.column("knee_angle_r"), Eigen::Vector3d(-5.0, -10.0, 90.0));
  EXPECT_EQ(t.column("pelvis_ty"), Eigen::Vector3d(0.95 * kDeg, 0.96 * kDeg, 0.97 * kDeg));
}

// Write -> read returns the same table in both styles; in degrees, the
// rad -> deg -> rad trip is exact to a few ulps (two roundings of a
// multiplication each), so 4 ulp-sized relative tolerance is used there.
TEST(Storage, RoundTripBothStyles) {
  for (StorageStyle style : {StorageStyle::kOld, StorageStyle::kOpenSim4}) {
    for (bool degrees : {false, true}) {
      StorageTable t;
      t.name = "round_trip";
      t.style = style;
      t.in_degrees = degrees;
      t.labels = {"time", "knee_angle_r", "knee_tx_r", "ground_force_vy"};
      t.metadata = {{"DataType", "double"}, {"source", "arthrosim test"}};
      t.data.resize(50, 4);
      for (int r = 0; r < 50; ++r) {
        t.data(r, 0) = 0.01 * r;
        t.data(r, 1) = std::sin(0.1 * r) * 1.2;       // rad
        t.data(r, 2) = 1e-3 * std::cos(0.3 * r) / 3;  // m
        t.data(r, 3) = 700.0 + r / 7.0;               // N
      }
      const fs::path p = temp_dir() / (std::string("rt_") + (style == StorageStyle::kOld ? "old" : "os4") +
                                       (degrees ? "_deg" : "_rad") + ".sto");
      write_storage(p.string(), t);
      const StorageTable u = read_storage(p.string());
      SCOPED_TRACE(p.string());
      EXPECT_EQ(u.style, style);
      EXPECT_EQ(u.name, t.name);
      EXPECT_EQ(u.in_degrees, degrees);
      EXPECT_EQ(u.labels, t.labels);
      EXPECT_EQ(u.metadata, t.metadata);
      ASSERT_EQ(u.data.rows(), 50);
      for (int r = 0; r < 50; ++r) {
        for (int c = 0; c < 4; ++c) {
          if (degrees && c == 1) {
            EXPECT_NEAR(u.data(r, c), t.data(r, c), 4 * std::numeric_limits<double>::epsilon() * std::abs(t.data(r, c)));
          } else {
            EXPECT_EQ(u.data(r, c), t.data(r, c)) << r << "," << c;  // %.17g round-trips doubles exactly
          }
        }
      }
      if (degrees) {
        // The file itself holds degrees for the angle and metres for the translation.
        std::ifstream in(p);
        std::string line;
        while (std::getline(in, line) && line != "endheader") {
        }
        std::getline(in, line);  // labels
        std::getline(in, line);  // row 0
        std::getline(in, line);  // row 1
        std::istringstream row(line);
        double time = 0, angle = 0, tx = 0;
        row >> time >> angle >> tx;
        EXPECT_NEAR(angle, std::sin(0.1) * 1.2 * 180 / std::numbers::pi, 1e-12);
        EXPECT_EQ(tx, t.data(1, 2));
      }
    }
  }
}

std::string error_of(const std::string& text) {
  try {
    parse(text);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no exception)";
}

TEST(Storage, ErrorsNameFileAndLine) {
  // Wrong number of values on row 2 (file line 6).
  EXPECT_EQ(error_of("x\nversion=1\nendheader\ntime\ta\tb\n0\t1\t2\n0.1\t1\n"),
            "test.mot:6: error: expected 3 values (one per column label), found 2");
  // Non-numeric value.
  EXPECT_EQ(error_of("inDegrees=no\nendheader\ntime\ta\n0\t1\n0.1\tabc\n"),
            "test.mot:5: error: expected a number in column 2 ('a'), found 'abc'");
  EXPECT_EQ(error_of("endheader\ntime\ta\n0\t1.5x\n"), "test.mot:3: error: expected a number in column 2 ('a'), found '1.5x'");
  // Missing endheader: reported at the last line.
  EXPECT_EQ(error_of("name\nversion=1\nnRows=1\ntime\ta\n0\t1\n"),
            "test.mot:5: error: expected a line 'endheader' closing the header, found the end of the file");
  // nRows / nColumns that do not match the data: reported at their own line.
  EXPECT_EQ(error_of("name\nversion=1\nnRows=3\nnColumns=2\nendheader\ntime\ta\n0\t1\n1\t2\n"),
            "test.mot:3: error: nRows=3 but the file has 2 data rows");
  EXPECT_EQ(error_of("name\nversion=1\nnRows=2\nnColumns=3\nendheader\ntime\ta\n0\t1\n1\t2\n"),
            "test.mot:4: error: nColumns=3 but the file has 2 column labels");
  // Bad header values.
  EXPECT_EQ(error_of("name\ninDegrees=maybe\nendheader\ntime\n0\n"),
            "test.mot:2: error: expected inDegrees=yes or inDegrees=no, found inDegrees=maybe");
  EXPECT_EQ(error_of("name\nnRows=many\nendheader\ntime\n0\n"), "test.mot:2: error: expected a count for nRows, found 'many'");
  // No labels.
  EXPECT_EQ(error_of("name\nendheader\n\n"),
            "test.mot:3: error: expected a line of column labels after endheader, found the end of the file");
  EXPECT_EQ(error_of("name\nendheader\ntime\ta\ta\n"), "test.mot:3: error: duplicate column label 'a' (columns 2 and 3)");
  // A blank line between rows (rows must be contiguous; trailing blanks are fine).
  EXPECT_EQ(error_of("endheader\ntime\ta\n0\t1\n\n1\t2\n\n"),
            "test.mot:4: error: expected a data row, found a blank line between data rows");
  // Missing file.
  try {
    read_storage((temp_dir() / "missing.mot").string());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), HasSubstr("missing.mot: error: cannot open the file for reading"));
  }
}

TEST(Storage, WriterRejectsInconsistentTables) {
  StorageTable t;
  t.labels = {"time", "a"};
  t.data = Eigen::MatrixXd::Zero(2, 3);
  std::ostringstream out;
  EXPECT_THROW(write_storage(out, t), InputError);
  t.data = Eigen::MatrixXd::Zero(2, 2);
  t.labels = {"time", "a\tb"};
  EXPECT_THROW(write_storage(out, t), InputError);
}

}  // namespace
}  // namespace arthrosim::common
