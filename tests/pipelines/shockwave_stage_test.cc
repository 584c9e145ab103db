// The shockwave stage (pipelines/shockwave_stage.h): the files it writes, the
// effects it builds (a dry run builds no fluid), bad options.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/error.h"
#include "common/hdf5.h"
#include "common/metadata.h"
#include "pipelines/prepare.h"
#include "pipelines/shockwave_output.h"
#include "pipelines/shockwave_stage.h"
#include "pipelines/stages.h"

namespace arthrosim::pipelines {
namespace {

namespace fs = std::filesystem;

const std::string kModel = std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/coarse";
const std::string kDir = std::string(ARTHROSIM_BINARY_DIR) + "/tests/shockwave_stage";

const std::string& prepared() {
  static const std::string path = [] {
    fs::create_directories(kDir);
    const std::string p = kDir + "/prepared_coarse.h5";
    const PreparedModel model = prepare_model(find_model_files(kModel), PrepareOptions{});
    const common::RunMetadata meta = common::collect_run_metadata("shockwave_stage_test", 0, nullptr, "", "");
    write_prepared_model(model, PrepareOptions{}, meta, p);
    return p;
  }();
  return path;
}

ShockwaveStageOptions quick(const std::string& stem) {
  ShockwaveStageOptions o;
  o.prepared = prepared();
  o.model = kModel;
  o.out = kDir + "/" + stem;
  o.automaton_diameter_m = 2e-3;
  o.end_time_s = 6e-6;
  o.output_interval_s = 2e-6;
  return o;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A short pulse run: the HDF5 run file with its fields per frame, peaks,
// criteria and ledger; the XDMF points; the summary and the plot.
TEST(ShockwaveStage, PulseRunWritesItsFiles) {
  ShockwaveStageOptions o = quick("pulse");
  o.efd_j_per_m2 = {330.0};
  const ShockwaveStageResult r = run_shockwave_stage(o, {"shockwave_stage_test"}, false);
  ASSERT_EQ(r.runs.size(), 1u);
  const fs::path h5 = kDir + "/pulse_efd0.33.h5";
  EXPECT_EQ(r.runs[0].file, h5);
  ASSERT_TRUE(fs::exists(h5));
  const ShockwaveFile f = read_shockwave_file(h5);
  EXPECT_EQ(f.label, "efd0.33");
  EXPECT_DOUBLE_EQ(f.efd_j_per_m2, 330.0);
  EXPECT_EQ(f.effects, (std::vector<std::string>{"mca_elastic", "pore_fluid", "filtration", "applicator_pulse"}));
  EXPECT_EQ(f.tissue.size(), r.automata);
  EXPECT_GE(f.time.size(), 3u);
  // The pulse reached the tissue: positive peak pressure next to the applicator.
  EXPECT_GT(f.peak_pressure.maxCoeff(), 1e5);
  EXPECT_GT(f.peak_pore_pressure.maxCoeff(), 1e4);
  const common::H5File file(h5.string(), common::H5File::Mode::kRead);
  EXPECT_EQ(file.dims("/fields/pressure"), (std::vector<std::int64_t>{static_cast<std::int64_t>(f.time.size()), r.automata}));
  EXPECT_TRUE(file.exists("/fields/pore_pressure"));
  EXPECT_EQ(file.attribute_string("/", "schema"), "arthrosim shockwave 1");
  const std::string xdmf = slurp(kDir + "/pulse_efd0.33.xdmf");
  EXPECT_NE(xdmf.find("Polyvertex"), std::string::npos);
  EXPECT_NE(xdmf.find("pore_pressure_pa"), std::string::npos);
  EXPECT_TRUE(fs::exists(kDir + "/pulse_summary.json"));
  EXPECT_NE(slurp(kDir + "/pulse_volumes.svg").find("<svg"), std::string::npos);
}

// A dry run (no pore fluid) builds and writes nothing of the fluid.
TEST(ShockwaveStage, DryRunBuildsNoFluid) {
  ShockwaveStageOptions o = quick("dry");
  o.effects = {"mca_elastic", "applicator_pulse"};
  const ShockwaveStageResult r = run_shockwave_stage(o, {"shockwave_stage_test"}, false);
  const ShockwaveFile f = read_shockwave_file(r.runs[0].file);
  EXPECT_EQ(f.effects, (std::vector<std::string>{"mca_elastic", "applicator_pulse"}));
  EXPECT_EQ(f.peak_pore_pressure.maxCoeff(), 0.0);
  const common::H5File file(r.runs[0].file.string(), common::H5File::Mode::kRead);
  EXPECT_FALSE(file.exists("/fields/pore_pressure"));
  EXPECT_EQ(r.filtration_substeps, 0);
}

TEST(ShockwaveStage, BadOptions) {
  auto expect_error = [](ShockwaveStageOptions o, const std::string& needle) {
    try {
      build_shockwave_model(o, "shockwave.yaml");
      ADD_FAILURE() << "no error, expected: " << needle;
    } catch (const common::InputError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  ShockwaveStageOptions o = quick("bad");
  o.effects = {"mca_elastic"};
  expect_error(o, "one loading");
  o.effects = {"mca_elastic", "filtration", "applicator_pulse"};
  expect_error(o, "pore_fluid with filtration");
  o.effects = {"mca_elastic", "applicator_pulse", "gravity"};
  expect_error(o, "found 'gravity'");
  o = quick("bad");
  o.automaton_diameter_m = 2.5e-3;
  expect_error(o, "exceeds the cortical shell thickness");
  o = quick("bad");
  o.applicator_centre_m = {0.0, 0.2, 0.0};
  expect_error(o, "applicator");
  o = quick("bad");
  const std::string table = kDir + "/bad_tissues.csv";
  std::ofstream(table) << "name,density_kg_per_m3,shear_modulus_mpa,bulk_modulus_mpa,solid_bulk_modulus_mpa,porosity,"
                          "permeability_m2\ncartilage,800,4.3,0,3400,0.8,4.8e-18\n";
  o.tissue_table = table;
  expect_error(o, "bulk modulus K > 0");
  std::ofstream(table) << "name,density_kg_per_m3,shear_modulus_mpa,bulk_modulus_mpa,solid_bulk_modulus_mpa,porosity,"
                          "permeability_m2\ncartilage,800,4.3,4.16,3400,1.5,4.8e-18\n";
  expect_error(o, "porosity in (0, 1)");
}

// The scene block (the stage table): keys in their written units, the checks
// with the scene's file, and the runner's plan (no stage is run).
TEST(ShockwaveStage, SceneBlockAndPlan) {
  const fs::path dir = fs::path(kDir) / "scene";
  fs::create_directories(dir / "models" / "knee");
  const std::string head = "model: models/knee\noutputs: [shockwave]\n";
  const common::Scene scene = parse_scene(
      head + "shockwave:\n  effects: [mca_elastic, pore_fluid, filtration, applicator_pulse]\n"
             "  automaton_diameter_mm: 1.5\n  efd_mj_per_mm2: [0.12, 0.8]\n  end_time_us: 50\n",
      dir / "s.yaml");
  const ShockwaveStageOptions o = shockwave_from_scene(scene);
  EXPECT_DOUBLE_EQ(o.automaton_diameter_m, 1.5e-3);
  EXPECT_EQ(o.efd_j_per_m2, (std::vector<double>{0.12 * 1e3, 0.8 * 1e3}));
  EXPECT_EQ(o.end_time_s, 50 * 1e-6);
  EXPECT_EQ(o.pulse_tail_duration_s, ShockwaveStageOptions{}.pulse_tail_duration_s);  // the default
  EXPECT_EQ(shockwave_run_labels(o), (std::vector<std::string>{"efd0.12", "efd0.8"}));
  const std::vector<StageStep> plan = plan_stages(scene, dir / "out");
  ASSERT_EQ(plan.size(), 2u);
  EXPECT_EQ(plan[0].name, "prepare");
  EXPECT_EQ(plan[1].name, "shockwave");
  EXPECT_EQ(plan[1].executable, "arthrosim-shockwave");
  EXPECT_EQ(plan[1].outputs.front(), dir / "out" / "shockwave_efd0.12.h5");  // holds the effect ledger
  EXPECT_EQ(plan[1].effects, (std::vector<std::string>{"mca_elastic", "pore_fluid", "filtration", "applicator_pulse"}));
  // The bar needs no prepared model: the stage runs alone.
  const common::Scene bar = parse_scene(
      head + "shockwave: {effects: [mca_elastic, applicator_pulse], geometry: bar}\n", dir / "bar.yaml");
  const std::vector<StageStep> bar_plan = plan_stages(bar, dir / "out");
  ASSERT_EQ(bar_plan.size(), 1u);
  EXPECT_EQ(bar_plan[0].name, "shockwave");
  // Refused when the scene is read, naming the file: no loading, an effect of another stage.
  auto refused = [&](const std::string& text, const std::string& needle) {
    try {
      parse_scene(text, dir / "bad.yaml");
      ADD_FAILURE() << "accepted: " << needle;
    } catch (const common::InputError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("bad.yaml"), std::string::npos) << e.what();
    }
  };
  refused(head + "shockwave: {effects: [mca_elastic, pore_fluid]}\n", "one loading");
  refused(head + "shockwave: {effects: [mca_elastic, applicator_pulse, inertia]}\n", "inertia");
}

// A scene asking for the report next to the runs: the post stage reads every
// run file of the plan (its section and the volumes-vs-EFD plot), and needs
// no surface block for that.
TEST(ShockwaveStage, ReportTakesEveryRunOfThePlan) {
  const fs::path dir = fs::path(kDir) / "scene_report";
  fs::create_directories(dir / "models" / "knee");
  const common::Scene scene = parse_scene(
      "model: models/knee\noutputs: [shockwave, report]\n"
      "shockwave: {effects: [mca_elastic, applicator_pulse], geometry: bar, efd_mj_per_mm2: [0.12, 0.8]}\n",
      dir / "s.yaml");
  const std::vector<StageStep> plan = plan_stages(scene, dir / "out");
  ASSERT_EQ(plan.size(), 2u);
  EXPECT_EQ(plan[0].name, "shockwave");
  EXPECT_EQ(plan[1].name, "post");
  std::vector<std::string> files;
  for (std::size_t i = 0; i + 1 < plan[1].arguments.size(); ++i)
    if (plan[1].arguments[i] == "--shockwave") files.push_back(plan[1].arguments[i + 1]);
  EXPECT_EQ(files, (std::vector<std::string>{(dir / "out" / "shockwave_efd0.12.h5").string(),
                                             (dir / "out" / "shockwave_efd0.8.h5").string()}));
  // Without the runs in the plan the report has nothing to show: refused.
  try {
    parse_scene("model: models/knee\noutputs: [report]\n", dir / "bad.yaml");
    ADD_FAILURE() << "a report without surface, biphasic or shockwave accepted";
  } catch (const common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("'shockwave' block"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace arthrosim::pipelines
