// arthrosim's scenes (the schema assembled from the stage table): a full
// example, every kind of error with its line and column, unit conversion at
// the edge, canonical option text, schema consistency, and docs/scenes.md (its
// generated reference is current, its complete example parses).
#include "pipelines/stages.h"

#include "pipelines/comak_stage.h"
#include "pipelines/surface_stage.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <regex>
#include <sstream>

#include "common/error.h"
#include "common/scene.h"

namespace arthrosim::pipelines {
using common::InputError;
using common::OptionBlock;
using common::OptionSpec;
using common::OptionType;
using common::Scene;
using common::Unit;
namespace {
namespace fs = std::filesystem;

// A scratch folder laid out like the repository: scenes/, models/knee/,
// trials/walk/.
class SceneTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() /
            ("arthrosim_scene_test_" + std::to_string(getpid()) + "_" +
             ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    fs::create_directories(root_ / "scenes");
    fs::create_directories(root_ / "models" / "knee");
    fs::create_directories(root_ / "trials" / "walk");
    std::ofstream(root_ / "models" / "knee" / "femur.stl") << "solid femur\nendsolid femur\n";
    std::ofstream(root_ / "trials" / "walk" / "trial.yaml") << "synthetic: true\n";
  }
  void TearDown() override { fs::remove_all(root_); }

  fs::path write(const std::string& text, const std::string& name = "scene.yaml") {
    const fs::path p = root_ / "scenes" / name;
    std::ofstream(p) << text;
    return p;
  }
  Scene load(const std::string& text) { return load_scene(write(text)); }

  // Loads `text`, expects an InputError, and checks its line, column and that
  // the message contains every fragment.
  void expect_error(const std::string& text, int line, int column,
                    const std::vector<std::string>& fragments) {
    const fs::path p = write(text);
    try {
      load_scene(p);
      ADD_FAILURE() << "no error for:\n" << text;
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_EQ(e.line(), line) << what;
      EXPECT_EQ(e.column(), column) << what;
      const std::string prefix =
          p.string() + ":" + std::to_string(line) + ":" + std::to_string(column) + ": error: ";
      EXPECT_EQ(what.rfind(prefix, 0), 0u) << what;
      for (const std::string& f : fragments) {
        EXPECT_NE(what.find(f), std::string::npos) << "'" << f << "' not in: " << what;
      }
    }
  }

  fs::path root_;
};

constexpr const char* kFull = R"(# a complete scene
description: full example
model: ../models/knee
trial: ../trials/walk
outputs: [report, kinematics]
prepare:
  edge_length_mm: 2
comak:
  effects: [ligaments, muscles, tibiofemoral_contact]
  ipopt_tolerance: 1e-6
  ipopt_max_iterations: 200
  reserve_actuators: yes
surface:
  time_step_s: 2e-4
  youngs_modulus_mpa: 400
  scenarios:
    osmotic:
      surfaces: [femur]
      end_time_s: 0.5
      effects: [foundation_springs, osmotic_pressure, periphery_fixed]
    gait:
      time_step_s: 5e-5
      effects: [foundation_springs, imposed_kinematics, mesh_contact]
post:
  angle_threshold_deg: 15
)";

TEST_F(SceneTest, FullExampleParsesEveryBlock) {
  const Scene s = load(kFull);
  const SceneInputs in = scene_inputs(s);
  EXPECT_EQ(in.description, "full example");
  EXPECT_EQ(in.model, fs::weakly_canonical(root_ / "models" / "knee"));
  EXPECT_EQ(in.trial, fs::weakly_canonical(root_ / "trials" / "walk"));
  EXPECT_EQ(in.outputs, (std::vector<std::string>{"report", "kinematics"}));
  EXPECT_TRUE(wants_output(s, "report"));
  EXPECT_FALSE(wants_output(s, "prepared_model"));

  EXPECT_EQ(s.block("prepare").as_written("edge_length_mm"), 2.0);
  EXPECT_DOUBLE_EQ(s.block("prepare").si("edge_length_mm"), 2e-3);
  EXPECT_TRUE(s.block("prepare").given("edge_length_mm"));

  ASSERT_TRUE(s.has_block("comak"));
  const OptionBlock& comak = s.block("comak");
  EXPECT_EQ(comak.list("effects"), (std::vector<std::string>{"ligaments", "muscles", "tibiofemoral_contact"}));
  EXPECT_EQ(comak.si("ipopt_tolerance"), 1e-6);
  EXPECT_EQ(comak.integer("ipopt_max_iterations"), 200);
  EXPECT_TRUE(comak.flag("reserve_actuators"));
  // Defaults are filled in and marked as such.
  EXPECT_EQ(comak.si("activation_min"), 0.01);
  EXPECT_FALSE(comak.given("activation_min"));
  EXPECT_EQ(comak.si("lowpass_cutoff_hz"), 6.0);
  // The stage's options struct reads the same values.
  const ComakStageOptions co = common::read_options<ComakStageOptions>(comak);
  EXPECT_EQ(co.solver.ipopt_tolerance, 1e-6);
  EXPECT_EQ(co.solver.max_iterations, 200);
  EXPECT_TRUE(co.solver.reserve_actuators);
  EXPECT_EQ(co.solver.activation_min, 0.01);
  EXPECT_EQ(co.trial.lowpass.cutoff_hz, 6.0);

  const auto& scenarios = s.instances("surface");
  ASSERT_EQ(scenarios.size(), 2u);
  const common::BlockInstance* osm = s.instance("surface", "osmotic");
  const common::BlockInstance* gait = s.instance("surface", "gait");
  ASSERT_NE(osm, nullptr);
  ASSERT_NE(gait, nullptr);
  EXPECT_EQ(s.instance("surface", "nope"), nullptr);
  EXPECT_EQ(&s.require_instance("surface", "gait"), gait);
  try {
    s.require_instance("surface", "gait_osmotic");
    ADD_FAILURE() << "no error for a missing scenario";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()),
              s.file.string() + ": error: expected a scenario named 'gait_osmotic' under "
                                "surface.scenarios, found osmotic, gait");
  }
  EXPECT_EQ(scenarios[0].name, "osmotic");  // file order kept
  EXPECT_EQ(osm->line, 17);
  EXPECT_EQ(osm->effects,
            (std::vector<std::string>{"foundation_springs", "osmotic_pressure", "periphery_fixed"}));
  EXPECT_TRUE(osm->wants("osmotic_pressure"));
  EXPECT_FALSE(osm->wants("mesh_contact"));
  EXPECT_EQ(osm->options.name(), "surface.osmotic");
  EXPECT_EQ(osm->options.list("surfaces"), (std::vector<std::string>{"femur"}));
  EXPECT_EQ(gait->options.list("surfaces"),
            (std::vector<std::string>{"femur", "tibia_medial", "tibia_lateral"}));
  // Inherited from the surface block, overridden per scenario, defaults.
  EXPECT_EQ(osm->options.si("time_step_s"), 2e-4);
  EXPECT_EQ(gait->options.si("time_step_s"), 5e-5);
  EXPECT_EQ(osm->options.si("end_time_s"), 0.5);
  EXPECT_FALSE(gait->options.has("end_time_s"));
  EXPECT_EQ(gait->options.si("hht_alpha"), -0.2);
  EXPECT_EQ(gait->options.si("youngs_modulus_mpa"), 400e6);
  EXPECT_EQ(s.block("surface").si("time_step_s"), 2e-4);
  const SurfaceScenarioOptions go = common::read_options<SurfaceScenarioOptions>(gait->options);
  EXPECT_EQ(go.integrator.dt_s, 5e-5);
  EXPECT_FALSE(go.end_time_s.has_value());
  EXPECT_EQ(go.effects, (std::vector<std::string>{"foundation_springs", "imposed_kinematics", "mesh_contact"}));

  EXPECT_DOUBLE_EQ(s.block("post").si("angle_threshold_deg"), 15.0 * std::numbers::pi / 180.0);
  EXPECT_EQ(s.block("post").as_written("angle_threshold_deg"), 15.0);
  EXPECT_FALSE(s.block("post").has("splitline_map"));
}

TEST_F(SceneTest, UnitsAreConvertedToSiAtTheEdge) {
  const Scene s = load(R"(model: ../models/knee
outputs: [surface]
prepare: {edge_length_mm: 1.5}
surface:
  shell_thickness_mm: 2
  output_interval_ms: 10
  osmotic_pressure_mpa: 0.25
  foundation_stiffness_n_per_mm3: 0.7
  foundation_damping_n_s_per_mm3: 7e6
  density_kg_per_m3: 1100
  scenarios:
    a: {effects: [inertia], end_time_s: 3}
post: {angle_threshold_deg: 90}
)");
  const OptionBlock& o = s.instances("surface").at(0).options;
  // Exact factors: mm -> m 1e-3, ms -> s 1e-3, MPa -> Pa 1e6,
  // N/mm^3 -> N/m^3 1e9 (1 mm^3 = 1e-9 m^3), deg -> rad pi/180.
  EXPECT_DOUBLE_EQ(s.block("prepare").si("edge_length_mm"), 1.5e-3);
  EXPECT_DOUBLE_EQ(o.si("shell_thickness_mm"), 2e-3);
  EXPECT_DOUBLE_EQ(o.si("output_interval_ms"), 1e-2);
  EXPECT_DOUBLE_EQ(o.si("osmotic_pressure_mpa"), 0.25e6);
  EXPECT_DOUBLE_EQ(o.si("foundation_stiffness_n_per_mm3"), 0.7e9);
  EXPECT_DOUBLE_EQ(o.si("foundation_damping_n_s_per_mm3"), 7e15);
  EXPECT_DOUBLE_EQ(o.si("density_kg_per_m3"), 1100.0);
  EXPECT_DOUBLE_EQ(o.si("end_time_s"), 3.0);
  EXPECT_DOUBLE_EQ(s.block("post").si("angle_threshold_deg"), std::numbers::pi / 2);
  EXPECT_EQ(o.as_written("osmotic_pressure_mpa"), 0.25);
  // The seed's defaults, in SI.
  const Scene d = load("model: ../models/knee\noutputs: [surface]\nsurface:\n  scenarios:\n"
                       "    a: {effects: [inertia], end_time_s: 1}\n");
  const OptionBlock& od = d.instances("surface").at(0).options;
  EXPECT_DOUBLE_EQ(od.si("youngs_modulus_mpa"), 400e6);
  EXPECT_DOUBLE_EQ(od.si("shell_thickness_mm"), 1e-3);
  EXPECT_DOUBLE_EQ(od.si("osmotic_pressure_mpa"), 0.2e6);
  EXPECT_DOUBLE_EQ(od.si("time_step_s"), 1e-4);
  EXPECT_DOUBLE_EQ(d.block("prepare").si("edge_length_mm"), 3e-3);
  // A default is bit for bit what the reader makes of its text: the struct's
  // default and the parsed default are the same double.
  const SurfaceScenarioOptions defaults;
  const SurfaceScenarioOptions parsed = common::read_options<SurfaceScenarioOptions>(od);
  EXPECT_EQ(parsed.physics.foundation_stiffness_N_m3, defaults.physics.foundation_stiffness_N_m3);
  EXPECT_EQ(parsed.contact.smoothing_m, defaults.contact.smoothing_m);
  EXPECT_EQ(parsed.integrator.increment_atol_m, defaults.integrator.increment_atol_m);
  EXPECT_EQ(od.si("contact_smoothing_mm"), 0.001 * 1e-3);
}

TEST_F(SceneTest, GettersRejectProgrammingErrors) {
  const Scene s = load("model: ../models/knee\noutputs: [prepared_model]\n");
  EXPECT_THROW(s.block("prepare").si("edge_length"), std::logic_error);       // not a key
  EXPECT_THROW(s.block("prepare").integer("edge_length_mm"), std::logic_error);  // wrong type
  EXPECT_THROW(s.block("post").path("splitline_map"), std::logic_error);       // no value
  EXPECT_THROW(s.block("nope"), std::logic_error);                             // not a block
  EXPECT_FALSE(s.has_block("comak"));
  EXPECT_FALSE(s.block("comak").has("effects"));
}

TEST_F(SceneTest, CanonicalTextIgnoresSpelling) {
  const Scene a = load("model: ../models/knee\noutputs: [prepared_model]\n"
                       "prepare: {edge_length_mm: 3}\n");
  const Scene b = load("model: ../models/knee\noutputs: [prepared_model]\n"
                       "prepare:\n  edge_length_mm: 3.000\n");
  const Scene c = load("model: ../models/knee\noutputs: [prepared_model]\n");  // default 3
  const Scene d = load("model: ../models/knee\noutputs: [prepared_model]\n"
                       "prepare: {edge_length_mm: 2.5}\n");
  EXPECT_EQ(a.block("prepare").canonical_text(),
            "prepare.edge_length_mm = 3\nprepare.max_cast_distance_mm = 10\nprepare.max_triangles = 1e+06\n"
            "prepare.mesh_unit = mm\nprepare.min_thickness_mm = 0.2\nprepare.remesh_iterations = 5\n"
            "prepare.surface_edge_length_mm = []\n");
  EXPECT_EQ(a.block("prepare").canonical_text(), b.block("prepare").canonical_text());
  EXPECT_EQ(a.block("prepare").canonical_text(), c.block("prepare").canonical_text());
  EXPECT_EQ(d.block("prepare").value("edge_length_mm").canonical, "2.5");
  const Scene e = load("model: ../models/knee\noutputs: [surface]\nsurface:\n  scenarios:\n"
                       "    x: {effects: [inertia, mesh_contact], end_time_s: 0.0001}\n");
  const std::string t = e.instances("surface")[0].options.canonical_text();
  EXPECT_NE(t.find("surface.x.effects = [inertia, mesh_contact]\n"), std::string::npos) << t;
  EXPECT_NE(t.find("surface.x.end_time_s = 1e-04\n"), std::string::npos) << t;
  EXPECT_NE(t.find("surface.x.time_step_s = 1e-04\n"), std::string::npos) << t;
}

TEST_F(SceneTest, UnknownTopLevelKey) {
  expect_error("model: ../models/knee\noutputs: [prepared_model]\nouputs: [x]\n", 3, 1,
               {"unknown key 'ouputs'", "did you mean 'outputs'"});
}

TEST_F(SceneTest, UnknownKeyInStageBlock) {
  expect_error("model: ../models/knee\noutputs: [prepared_model]\nprepare:\n"
               "  edge_lenght_mm: 2\n",
               4, 3, {"unknown key 'edge_lenght_mm' in 'prepare'", "did you mean 'edge_length_mm'"});
}

TEST_F(SceneTest, UnknownKeyInScenario) {
  expect_error("model: ../models/knee\noutputs: [surface]\nsurface:\n  scenarios:\n    a:\n"
               "      end_time_s: 1\n      effects: [inertia]\n      time_stepp_s: 1\n",
               8, 7, {"unknown key 'time_stepp_s' in 'surface.scenarios.a'", "'time_step_s'"});
}

TEST_F(SceneTest, UnknownEffect) {
  expect_error("model: ../models/knee\noutputs: [surface]\nsurface:\n  scenarios:\n    a:\n"
               "      end_time_s: 1\n      effects: [inertia, foundation_spring]\n",
               7, 26, {"unknown effect 'foundation_spring'", "did you mean 'foundation_springs'",
                       "the surface stage knows:"});
}

TEST_F(SceneTest, EffectOfTheWrongStage) {
  expect_error("model: ../models/knee\ntrial: ../trials/walk\noutputs: [kinematics]\n"
               "comak:\n  effects:\n    - ligaments\n    - mesh_contact\n",
               7, 7, {"effect 'mesh_contact' belongs to the surface stage, not the "
                      "musculoskeletal stage"});
}

TEST_F(SceneTest, WrongTypes) {
  expect_error("model: ../models/knee\noutputs: [prepared_model]\nprepare: {edge_length_mm: abc}\n",
               3, 27, {"'edge_length_mm': expected a number, found 'abc'"});
  expect_error("model: ../models/knee\ntrial: ../trials/walk\noutputs: [kinematics]\ncomak:\n"
               "  effects: [muscles]\n  ipopt_max_iterations: 2.5\n",
               6, 25, {"expected a whole number, found '2.5'"});
  expect_error("model: ../models/knee\ntrial: ../trials/walk\noutputs: [kinematics]\ncomak:\n"
               "  effects: [muscles]\n  reserve_actuators: maybe\n",
               6, 22, {"expected true or false, found 'maybe'"});
  expect_error("model: ../models/knee\noutputs: prepared_model\n", 2, 10,
               {"'outputs': expected a list like [a, b], found 'prepared_model'"});
  expect_error("model: ../models/knee\noutputs: [prepared_model]\nprepare:\n  edge_length_mm: [1, 2]\n",
               4, 19, {"expected a number, found a list"});
  expect_error("model: ../models/knee\noutputs: [prepared_model]\nprepare: 3\n", 3, 10,
               {"expected a block of keys for 'prepare', found '3'"});
  expect_error("model: ../models/knee\noutputs: [prepared_model]\nprepare: {edge_length_mm: 1e999}\n",
               3, 27, {"expected a finite number, found '1e999'"});
}

TEST_F(SceneTest, OutOfRange) {
  expect_error("model: ../models/knee\noutputs: [surface]\nsurface:\n  hht_alpha: -0.5\n"
               "  scenarios: {a: {effects: [inertia], end_time_s: 1}}\n",
               4, 14, {"'hht_alpha': expected a value in [-0.333", "found -0.5"});
  expect_error("model: ../models/knee\noutputs: [prepared_model]\nprepare: {edge_length_mm: 0}\n",
               3, 27, {"expected a value in [0.2, 20] mm, found 0"});
}

TEST_F(SceneTest, MissingRequiredKeys) {
  expect_error("outputs: [prepared_model]\n", 1, 1, {"missing required key 'model'"});
  expect_error("model: ../models/knee\n", 1, 1, {"missing required key 'outputs'"});
  expect_error("model: ../models/knee\noutputs: [surface]\nsurface:\n  scenarios:\n    a:\n"
               "      end_time_s: 1\n",
               6, 7, {"missing required key 'effects' in 'surface.scenarios.a'"});
  expect_error("model: ../models/knee\ntrial: ../trials/walk\noutputs: [kinematics]\ncomak:\n"
               "  ipopt_tolerance: 1e-6\n",
               5, 3, {"missing required key 'effects' in 'comak'"});
  expect_error("model: ../models/knee\noutputs: [surface]\nsurface:\n  scenarios:\n"
               "    a: {effects: [inertia]}\n",
               5, 5, {"scenario 'a' does not use imposed_kinematics, so it needs 'end_time_s'"});
}

TEST_F(SceneTest, OutputsNeedTheirBlocks) {
  expect_error("model: ../models/knee\noutputs: [prepared_model, report]\n", 2, 10,
               {"output 'report' is requested, which needs a 'surface' block with at least one scenario"});
  expect_error("model: ../models/knee\ntrial: ../trials/walk\noutputs: [kinematics]\n", 3, 10,
               {"output 'kinematics' is requested", "add a 'comak' block"});
  expect_error("model: ../models/knee\noutputs: [surface]\ncomak: {effects: [muscles]}\n"
               "surface:\n  scenarios:\n    gait:\n      effects: [imposed_kinematics]\n",
               6, 5, {"scenario 'gait' uses imposed_kinematics", "add 'trial: PATH'"});
  expect_error("model: ../models/knee\noutputs: [prepared_model, bogus]\n", 2, 27,
               {"'outputs': unknown item 'bogus'", "expected any of prepared_model, kinematics, surface, "
                                                   "biphasic, shockwave, report"});
}

TEST_F(SceneTest, PathsAndDuplicates) {
  expect_error("model: ../models/kne\noutputs: [prepared_model]\n", 1, 8,
               {"'model': expected an existing file or folder, found '../models/kne'",
                (root_ / "models" / "kne").string()});
  expect_error("model: ../models/knee\noutputs: [prepared_model]\nmodel: ../models/knee\n", 3, 1,
               {"key 'model' given twice", "first on line 1"});
  expect_error("model: ../models/knee\noutputs: [surface]\nsurface:\n  scenarios:\n"
               "    a: {effects: [inertia, inertia], end_time_s: 1}\n",
               5, 28, {"'inertia' listed twice"});
  expect_error("model: ../models/knee\noutputs: [surface]\nsurface:\n  scenarios:\n"
               "    Gait-1: {effects: [inertia], end_time_s: 1}\n",
               5, 5, {"expected a scenario name of lowercase letters", "found 'Gait-1'"});
}

TEST_F(SceneTest, YamlSyntaxErrorHasALine) {
  // yaml-cpp reports where it gave up: the start of the next block.
  expect_error("model: ../models/knee\noutputs: [prepared_model\nprepare: {}\n", 3, 8,
               {"not valid YAML"});
}

TEST_F(SceneTest, RepositoryRelativePaths) {
  // Not next to the scene, but in the repository (marked by .git) holding it.
  fs::create_directories(root_ / ".git");
  fs::create_directories(root_ / "scenes" / "nested");
  const fs::path p = write("model: models/knee\noutputs: [prepared_model]\n", "nested/s.yaml");
  const Scene s = load_scene(p);
  EXPECT_EQ(scene_inputs(s).model, fs::weakly_canonical(root_ / "models" / "knee"));
}

TEST(SceneSchema, UnitSuffixesMatchUnitsAndDefaultsAreValid) {
  const std::vector<std::string> suffixes = {"_mm", "_deg", "_s", "_ms", "_mpa", "_hz",
                                             "_kg_per_m3", "_n_per_mm3", "_n_s_per_mm3", "_us",
                                             "_mj_per_mm2"};
  for (const OptionSpec* op : scene_schema().all()) {
    const OptionSpec& o = *op;
    const std::string key(o.key);
    const std::string suffix(unit_suffix(o.unit));
    if (o.unit != Unit::kNone) {
      EXPECT_TRUE(o.type == OptionType::kNumber || o.type == OptionType::kNumberList ||
                  o.type == OptionType::kNamedNumberList)
          << key;
      ASSERT_GE(key.size(), suffix.size());
      EXPECT_EQ(key.substr(key.size() - suffix.size()), suffix) << key;
    } else if (o.type == OptionType::kNumber) {
      // A unitless number must not look like it has a unit.
      for (const std::string& s : suffixes) {
        EXPECT_FALSE(key.size() > s.size() && key.substr(key.size() - s.size()) == s) << key;
      }
    }
    EXPECT_FALSE(o.doc.empty()) << key;
    EXPECT_EQ(scene_schema().find(o.block, o.key), &o);
    if (o.type == OptionType::kNumber || o.type == OptionType::kInteger) {
      EXPECT_LE(o.min, o.max) << key;
    }
  }
}

TEST_F(SceneTest, EveryDefaultParses) {
  // A scene using every block with nothing but required keys fills every
  // default through the same parser as user text (types and ranges checked).
  const Scene s = load("model: ../models/knee\ntrial: ../trials/walk\noutputs: [report]\n"
                       "comak: {effects: [muscles]}\nsurface:\n  scenarios:\n"
                       "    a: {effects: [imposed_kinematics]}\n");
  for (const OptionSpec* op : scene_schema().all()) {
    const OptionSpec& o = *op;
    if (o.default_value.empty()) continue;
    const OptionBlock* b = o.block == "scene"      ? &s.top
                           : o.block == "scenario" ? &s.instances("surface")[0].options
                           : o.block == "surface"  ? &s.instances("surface")[0].options
                                                   : &s.block(o.block);
    ASSERT_NE(b, nullptr) << o.key;
    EXPECT_TRUE(b->has(o.key)) << o.key;
    EXPECT_FALSE(b->given(o.key)) << o.key;
  }
}

// docs/scenes.md documents every key and its complete example is a valid scene.
TEST_F(SceneTest, DocumentationCoversTheSchemaAndItsExampleParses) {
  std::ifstream in(fs::path(ARTHROSIM_SOURCE_DIR) / "docs" / "scenes.md");
  ASSERT_TRUE(in) << "docs/scenes.md missing";
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string doc = ss.str();
  // The reference section is generated from the declarations, verbatim.
  EXPECT_EQ(with_schema_reference(doc, "docs/scenes.md"), doc)
      << "docs/scenes.md's reference is out of date: run build/bin/arthrosim schema --write-docs docs/scenes.md";
  for (const OptionSpec* o : scene_schema().all()) {
    EXPECT_NE(doc.find("`" + o->key + "`"), std::string::npos)
        << "docs/scenes.md does not mention " << o->block << "." << o->key;
  }
  for (const common::EffectName& e : scene_schema().effects) {
    EXPECT_NE(doc.find("`" + e.name + "`"), std::string::npos) << e.name;
  }
  const std::string open = "<!-- complete example -->\n```yaml\n";
  const std::size_t a = doc.find(open);
  ASSERT_NE(a, std::string::npos);
  const std::size_t b = doc.find("```", a + open.size());
  ASSERT_NE(b, std::string::npos);
  const std::string example = doc.substr(a + open.size(), b - a - open.size());
  // The example refers to ../models/knee_parametric/medium and ../trials/synthetic_gait.
  fs::create_directories(root_ / "models" / "knee_parametric" / "medium");
  fs::create_directories(root_ / "trials" / "synthetic_gait");
  const Scene s = load(example);
  EXPECT_TRUE(wants_output(s, "report"));
  EXPECT_EQ(s.instances("surface").size(), 3u);
  ASSERT_NE(s.instance("surface", "gait"), nullptr);
  EXPECT_FALSE(s.instance("surface", "gait")->wants("osmotic_pressure"));
  EXPECT_FALSE(s.instance("surface", "osmotic")->wants("mesh_contact"));
}

}  // namespace
}  // namespace arthrosim::pipelines
