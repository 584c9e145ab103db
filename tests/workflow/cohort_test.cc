// Cohort studies (pipelines/cohort.h, workflow/Snakefile, docs/cohorts.md):
// the cohort file's errors, the settings grid, the plan derived from the
// stage table, and a tiny cohort run by Snakemake with the real stage
// programs: 2 subjects x 2 settings on the bundled knee with short trial
// windows runs; a second call runs nothing; editing one subject's trial
// reruns that subject's trial-dependent stages only; a changed post option
// reruns the post stage only; an accuracy study run through the workflow
// gives the local study's errors and recommendation.
#include "pipelines/cohort.h"
#include "pipelines/study.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "common/error.h"
#include "pipelines/json.h"
#include "tests/test_support.h"

namespace arthrosim::pipelines::cohort {
namespace {
namespace fs = std::filesystem;
using test_support::fresh_scratch_dir;
using test_support::message_of;
using test_support::read_text;

const fs::path kSource = ARTHROSIM_SOURCE_DIR;
const fs::path kBin = fs::path(ARTHROSIM_BINARY_DIR) / "bin";

fs::path write(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file) << text;
  return file;
}

// A cohort file in `dir` on the tiny scene (data/cohorts/tiny_knee.yaml).
std::string cohort_text(const std::string& subjects, const std::string& extra = "") {
  return "description: test cohort\nscene: " + (kSource / "data/cohorts/tiny_knee.yaml").string() + "\n" + extra +
         "subjects:\n" + subjects;
}

TEST(CohortFile, BadFilesNameTheFileLineExpectedAndFound) {
  const fs::path dir = fresh_scratch_dir("cohort_file");
  const std::string model = (kSource / "data/models/knee_parametric/coarse").string();
  struct Case {
    std::string text, expected;
  };
  const std::vector<Case> cases = {
      {cohort_text("  a: {model: " + model + "}\n", "sets:\n  trial.end_s: 0.1\n"),
       ":3:1: error: expected a key of a cohort file (description, scene, set, settings, subjects), found 'sets'"},
      {"description: x\n", ":1: error: expected a 'subjects' map"},
      {cohort_text("  a: {model: " + model + "}\n", "settings:\n  prepare.edge_length_mm: 3\n"),
       ":4:27: error: expected a list of values for setting 'prepare.edge_length_mm' (e.g. [0.1, 0.2]), found '3'"},
      {cohort_text("  a: {model: " + model + "}\n", "settings:\n  prepare.edge_length_mm: [3, 3]\n"),
       "error: expected each value of setting 'prepare.edge_length_mm' once, found '3' twice"},
      {cohort_text("  a: {model: no/such/folder}\n"),
       ":4:14: error: expected a model folder or URDF that exists, found no/such/folder"},
      {cohort_text("  a b: {model: " + model + "}\n"),
       "error: expected a subject name of letters, digits, '_', '-' and '.' (a folder name), found 'a b'"},
      {cohort_text("  a: {modle: " + model + "}\n"),
       "error: expected a key of subject 'a' (model, trial, scene, set), found 'modle'"},
      {cohort_text("  a: {set: {trial.end_s: [1, 2]}}\n"), "error: expected a value for trial.end_s (one value), found a list"},
      {"subjects: [a, b]\n", ":1:11: error: expected 'subjects': a map of subject names"},
      {"scene: no/such.yaml\nsubjects:\n  a: {}\n", ":1:8: error: expected a scene file that exists, found no/such.yaml"},
      {"subjects:\n  a: {}\n", ":2:3: error: expected a 'scene' for subject 'a' (or a cohort-wide 'scene'), found none"},
      {"subjects: {a: [\n", "error: expected YAML, found"},
  };
  int i = 0;
  for (const Case& c : cases) {
    const fs::path file = write(dir / ("bad" + std::to_string(i++) + ".yaml"), c.text);
    const std::string m = message_of([&] { load_cohort(file); });
    EXPECT_NE(m.find(file.string()), std::string::npos) << m;
    EXPECT_NE(m.find(c.expected), std::string::npos) << "expected '" << c.expected << "' in\n" << m;
  }
}

TEST(CohortFile, UnknownSceneKeyIsRefusedAtItsLineBeforeAnythingRuns) {
  const fs::path dir = fresh_scratch_dir("cohort_keys");
  const fs::path file = write(dir / "c.yaml", cohort_text("  a:\n    set:\n      prepare.edge_lenght_mm: 2\n"));
  const Cohort c = load_cohort(file);
  const std::string m = message_of([&] { plan_cohort(c, dir / "out", kBin); });
  EXPECT_NE(m.find(file.string() + ":6:7: error: subject 'a'"), std::string::npos) << m;
  EXPECT_NE(m.find("edge_lenght_mm"), std::string::npos) << m;
  EXPECT_NE(m.find("edge_length_mm"), std::string::npos) << m;  // the hint
  EXPECT_FALSE(fs::exists(dir / "out" / "plan.json"));
  // A value out of range: the subject and setting are named.
  const fs::path bad = write(dir / "v.yaml", cohort_text("  a: {}\n", "settings:\n  prepare.edge_length_mm: [3, -1]\n"));
  const std::string mv = message_of([&] { plan_cohort(load_cohort(bad), dir / "out2", kBin); });
  EXPECT_NE(mv.find("subject 'a' at setting 'edge_length_mm--1'"), std::string::npos) << mv;
  EXPECT_NE(mv.find("edge_length_mm"), std::string::npos) << mv;
}

TEST(CohortFile, GridNamesAndPlanComeFromTheStageTable) {
  const fs::path dir = fresh_scratch_dir("cohort_grid");
  const fs::path file =
      write(dir / "c.yaml", cohort_text("  a: {}\n  b: {set: {trial.end_s: 0.1}}\n",
                                        "settings:\n  surface.scenarios.osmotic.osmotic_pressure_mpa: [0.1, 0.2]\n"
                                        "  prepare.edge_length_mm: [3]\n"
                                        "  surface.scenarios.osmotic.end_time_s: [1]\n  surface.end_time_s: [2]\n"));
  const Cohort c = load_cohort(file);
  const std::vector<Setting> grid = settings_grid(c);
  ASSERT_EQ(grid.size(), 2u);
  EXPECT_EQ(grid[0].name,
            "osmotic_pressure_mpa-0.1__edge_length_mm-3__surface.scenarios.osmotic.end_time_s-1__surface.end_time_s-2");
  const Plan plan = plan_cohort(c, dir / "out", kBin);
  ASSERT_EQ(plan.runs.size(), 4u);
  // Per run: the steps plan_stages gives the tiny scene, in the table's order.
  ASSERT_EQ(plan.jobs.size(), 16u);
  const std::vector<std::string> steps = {"prepare", "comak", "surface.osmotic", "post"};
  for (std::size_t k = 0; k < plan.jobs.size(); ++k) EXPECT_EQ(plan.jobs[k].step, steps[k % 4]);
  const Job& comak = plan.jobs[5];
  EXPECT_EQ(comak.subject, "a");
  EXPECT_EQ(comak.outputs, std::vector<std::string>{"runs/a/" + grid[1].name + "/kinematics.h5"});
  // Folder inputs are listed with their files; other jobs' outputs stay relative.
  const std::string trial = (kSource / "data/trials/synthetic_gait").string();
  EXPECT_NE(std::find(comak.inputs.begin(), comak.inputs.end(), trial), comak.inputs.end());
  ASSERT_EQ(plan.folders.count(trial), 1u);
  EXPECT_EQ(plan.folders.at(trial), (std::vector<std::string>{trial + "/grf.mot", trial + "/ik.mot", trial + "/trial.yaml"}));
  EXPECT_NE(std::find(comak.inputs.begin(), comak.inputs.end(), "runs/a/" + grid[1].name + "/prepared.h5"),
            comak.inputs.end());
  EXPECT_NE(plan.jobs[13].options.find("scene.trial.end_s\t0.1"), std::string::npos) << plan.jobs[13].options;
  EXPECT_EQ(plan.jobs[0].executable_sha256.size(), 64u);
  // The scenes are written once: planning again leaves them untouched.
  const auto t = fs::last_write_time(plan.runs[0].scene);
  plan_cohort(c, dir / "out", kBin);
  EXPECT_EQ(fs::last_write_time(plan.runs[0].scene), t);
}

// ---- a tiny cohort through Snakemake --------------------------------------

std::string which(const std::string& program) {
  const char* path = std::getenv("PATH");
  std::stringstream s(path ? path : "");
  std::string d;
  while (std::getline(s, d, ':'))
    if (!d.empty() && access((fs::path(d) / program).c_str(), X_OK) == 0) return (fs::path(d) / program).string();
  return "";
}

struct Result {
  int status = -1;
  std::string output;
};
Result run(const std::string& command) {
  Result r;
  FILE* p = popen((command + " 2>&1").c_str(), "r");
  std::array<char, 4096> buf;
  std::size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), p)) > 0) r.output.append(buf.data(), n);
  const int s = pclose(p);
  r.status = WIFEXITED(s) ? WEXITSTATUS(s) : -1;
  return r;
}

// Every file under OUT/runs with its modification time.
std::map<std::string, fs::file_time_type> outputs(const fs::path& out) {
  std::map<std::string, fs::file_time_type> m;
  for (const auto& e : fs::recursive_directory_iterator(out / "runs"))
    if (e.is_regular_file() && e.path().extension() != ".log")
      m[fs::relative(e.path(), out).string()] = e.last_write_time();
  return m;
}

TEST(CohortWorkflow, RunsOnceThenNothingThenOnlyWhatAnEditedTrialChanges) {
  if (which("snakemake").empty())
    GTEST_SKIP() << "snakemake not found on PATH (scripts/install-deps.sh installs Debian's snakemake)";
  const fs::path dir = fresh_scratch_dir("cohort_workflow");
  for (const char* s : {"trial_a", "trial_b"})
    fs::copy(kSource / "data/trials/synthetic_gait", dir / s, fs::copy_options::recursive);
  const fs::path file =
      write(dir / "cohort.yaml",
            cohort_text("  a:\n    trial: " + (dir / "trial_a").string() + "\n    set: {trial.end_s: 0.05}\n" +
                            "  b:\n    trial: " + (dir / "trial_b").string() +
                            "\n    set: {trial.start_s: 0.1, trial.end_s: 0.15}\n",
                        "settings:\n  surface.scenarios.osmotic.osmotic_pressure_mpa: [0.1, 0.2]\n"));
  const fs::path out = dir / "out";
  const std::string command = (kBin / "arthrosim").string() + " cohort " + file.string() + " --out " + out.string() +
                              " --cores 2";

  const Result first = run(command);
  ASSERT_EQ(first.status, 0) << first.output;
  EXPECT_NE(first.output.find("18 of 18 steps (100%) done"), std::string::npos) << first.output;
  // The report: one row per subject x setting, every key output read.
  const std::string csv = read_text(out / "report/cohort.csv");
  std::stringstream lines(csv);
  std::string header, line;
  std::getline(lines, header);
  EXPECT_NE(header.find("comak peak_tibiofemoral_force [N]"), std::string::npos) << header;
  EXPECT_NE(header.find("surface.osmotic max_deflection[femur] [mm]"), std::string::npos) << header;
  EXPECT_NE(header.find("post mean_angle[osmotic] [deg]"), std::string::npos) << header;
  int rows = 0;
  std::map<std::string, double> peak_force, deflection;
  while (std::getline(lines, line)) {
    ++rows;
    std::vector<std::string> f;
    std::stringstream cells(line);
    std::string cell;
    while (std::getline(cells, cell, ',')) f.push_back(cell);
    ASSERT_GE(f.size(), 5u) << line;
    peak_force[f[0] + "/" + f[1]] = std::stod(f[3]);  // after subject, setting, the grid's value
  }
  EXPECT_EQ(rows, 4) << csv;
  // Each subject's force does not depend on the osmotic pressure (stage 1
  // runs before it) but differs between the two trial windows.
  EXPECT_EQ(peak_force["a/osmotic_pressure_mpa-0.1"], peak_force["a/osmotic_pressure_mpa-0.2"]);
  EXPECT_NE(peak_force["a/osmotic_pressure_mpa-0.1"], peak_force["b/osmotic_pressure_mpa-0.1"]);
  EXPECT_TRUE(fs::exists(out / "report/report.html"));
  // Every plot of the report draws in headless Chromium (exit 77: no chromium).
  const Result drawn = run((kSource / "scripts/report_check.sh").string() + " " + (out / "report/report.html").string());
  if (drawn.status != 77) { EXPECT_EQ(drawn.status, 0) << drawn.output; }

  const auto before = outputs(out);
  const Result second = run(command);
  ASSERT_EQ(second.status, 0) << second.output;
  EXPECT_NE(second.output.find("Nothing to be done"), std::string::npos) << second.output;
  EXPECT_EQ(outputs(out), before);

  // Edit subject a's trial: a comment added to its trial.yaml (results stay
  // the same). Snakemake reruns a job whose input is newer than its outputs
  // unless the input's recorded checksum (files < 100 kB) is unchanged, so a
  // bare `touch` of a small file reruns nothing; a changed file does.
  std::ofstream(dir / "trial_a" / "trial.yaml", std::ios::app) << "# edited by cohort_test\n";
  fs::last_write_time(dir / "trial_a" / "trial.yaml", fs::file_time_type::clock::now() + std::chrono::seconds(2));
  const Result third = run(command);
  ASSERT_EQ(third.status, 0) << third.output;
  const auto after = outputs(out);
  ASSERT_EQ(after.size(), before.size());
  for (const auto& [name, time] : after) {
    // Subject a's COMAK and the post stage (it reads the kinematics) run
    // again; prepare, the osmotic state (no kinematics) and subject b do not.
    const bool a = name.rfind("runs/a/", 0) == 0;
    const std::string file = fs::path(name).filename().string();
    if (a && (file == "kinematics.h5" || file == "report.html" || file == "summary.json")) {
      EXPECT_NE(time, before.at(name)) << name << " was not rerun";
    }
    if (!a || file.rfind("prepared.", 0) == 0 || file.rfind("surface_osmotic.", 0) == 0) {
      EXPECT_EQ(time, before.at(name)) << name << " was rerun";
    }
  }
  // 2 comak, 2 post, the report and the target rule `all`.
  EXPECT_NE(third.output.find("6 of 6 steps (100%) done"), std::string::npos) << third.output;

  // A changed option of one stage (post, for every subject) reruns that
  // stage only: its options are a rule parameter, the scenes are not inputs.
  std::string text = read_text(file);
  text.replace(text.find("settings:"), 0, "set:\n  post.angle_threshold_deg: 15\n");
  write(file, text);
  const Result fourth = run(command);
  ASSERT_EQ(fourth.status, 0) << fourth.output;
  EXPECT_NE(fourth.output.find("6 of 6 steps (100%) done"), std::string::npos) << fourth.output;
  for (const auto& [name, time] : outputs(out)) {
    const std::string f = fs::path(name).filename().string();
    if (f == "summary.json" || f == "report.html") {
      EXPECT_NE(time, after.at(name)) << name << " was not rerun";
    }
    if (f == "kinematics.h5" || f == "prepared.h5" || f == "surface_osmotic.h5") {
      EXPECT_EQ(time, after.at(name)) << name << " was rerun";
    }
  }
}

// `arthrosim study accuracy --workflow` (pipelines/study.h): the same grid run
// by the scene runner and as a one-subject cohort through Snakemake gives the
// same per-stage errors (bit for bit: the same stage programs on the same
// scenes, and stage outputs are deterministic) and the same recommendation.
// Two shell resolutions of the osmotic-only scene: seconds.
TEST(StudyWorkflow, SameErrorsAndRecommendationAsTheLocalStudy) {
  if (which("snakemake").empty())
    GTEST_SKIP() << "snakemake not found on PATH (scripts/install-deps.sh installs Debian's snakemake)";
  const fs::path dir = fresh_scratch_dir("study_workflow");
  ::arthrosim::pipelines::study::StudyOptions o;
  o.scene_file = kSource / "data/scenes/osmotic.yaml";
  o.axes.push_back(::arthrosim::pipelines::study::parse_vary("prepare.edge_length_mm=3,2.5"));
  o.stage_dir = kBin;
  o.out_dir = dir / "local";
  std::ostringstream local_log, wf_log;
  const ::arthrosim::pipelines::study::StudyResult local = ::arthrosim::pipelines::study::run_accuracy_study(o, local_log);
  o.out_dir = dir / "wf";
  o.use_workflow = true;
  o.workflow.workflow_dir = kSource / "workflow";
  o.workflow.cores = 2;
  const ::arthrosim::pipelines::study::StudyResult wf = ::arthrosim::pipelines::study::run_accuracy_study(o, wf_log);
  ::arthrosim::pipelines::study::write_study_outputs(o, wf);
  EXPECT_TRUE(fs::exists(dir / "wf/cohort.yaml"));
  EXPECT_TRUE(fs::exists(dir / "wf/study.csv"));
  ASSERT_EQ(local.settings.size(), 2u);
  ASSERT_EQ(wf.settings.size(), 2u);
  EXPECT_EQ(local.reference, wf.reference);
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_TRUE(local.settings[i].ok) << local_log.str();
    EXPECT_TRUE(wf.settings[i].ok) << wf_log.str();
    EXPECT_EQ(local.settings[i].label, wf.settings[i].label);
    EXPECT_NE(wf.settings[i].dir.string().find("/wf/cohort/runs/study/"), std::string::npos);
    ASSERT_EQ(local.settings[i].stages.size(), wf.settings[i].stages.size());
    for (std::size_t k = 0; k < local.settings[i].stages.size(); ++k) {
      const ::arthrosim::pipelines::study::StageRecord& a = local.settings[i].stages[k];
      const ::arthrosim::pipelines::study::StageRecord& b = wf.settings[i].stages[k];
      EXPECT_EQ(a.stage, b.stage);
      EXPECT_EQ(b.run, "ran");
      EXPECT_TRUE(std::isnan(b.wall_time_s));  // not measured through the workflow
      if (std::isnan(a.stage_error)) {
        EXPECT_TRUE(std::isnan(b.stage_error)) << a.stage;
      } else {
        EXPECT_EQ(a.stage_error, b.stage_error) << a.stage;
      }
      ASSERT_EQ(a.metrics.size(), b.metrics.size());
      for (std::size_t m = 0; m < a.metrics.size(); ++m) {
        EXPECT_EQ(a.metrics[m].name, b.metrics[m].name);
        if (std::isfinite(a.metrics[m].error)) { EXPECT_EQ(a.metrics[m].error, b.metrics[m].error); }
      }
    }
  }
  // The coarse setting's error is a real, non-zero difference (a test that
  // compares two zeros would prove nothing).
  const auto osmotic = [](const ::arthrosim::pipelines::study::SettingResult& r) {
    for (const ::arthrosim::pipelines::study::StageRecord& s : r.stages)
      if (s.stage == "surface.osmotic") return s.stage_error;
    return ::arthrosim::pipelines::study::kNaN;
  };
  EXPECT_GT(osmotic(local.settings[0]), 0.0);
  ASSERT_EQ(local.recommended.size(), wf.recommended.size());
  for (std::size_t k = 0; k < local.recommended.size(); ++k) {
    EXPECT_EQ(local.recommended[k].stage, wf.recommended[k].stage);
    EXPECT_EQ(local.recommended[k].setting, wf.recommended[k].setting);
    EXPECT_GE(wf.recommended[k].setting, 0);
  }
}

}  // namespace
}  // namespace arthrosim::pipelines::cohort
