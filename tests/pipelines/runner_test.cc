// The scene runner with fake stage programs (small shell scripts written into
// a scratch bin folder), so these tests depend on no real stage: stage
// selection from outputs, reuse and its reasons, reruns on changed options,
// inputs, code and outputs, failure propagation, missing programs, dry runs.
#include "pipelines/runner.h"
#include "pipelines/stages.h"

#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "common/effects.h"
#include "common/hdf5.h"
#include "common/scene.h"

namespace arthrosim::pipelines {
namespace {
namespace fs = std::filesystem;
using common::Scene;

// A fake stage: appends "<stage> <args>" to $ARTHROSIM_FAKE_LOG, then writes
// into each output (--out FILE, or report.html + summary.json in --out-dir)
// its command line followed by the contents of every input file or folder
// named on it, and of the scene only its own block (the test scenes write
// `prepare: {...}` on one line; the other fake stages read no option). So its
// output changes exactly when its arguments, its options or one of its
// inputs do, like a deterministic stage.
constexpr const char* kFakeStage = R"SH(#!/bin/sh
stage="$(basename "$0")"
echo "$stage $*" >> "$ARTHROSIM_FAKE_LOG"
out=""; outdir=""; prev=""
for a in "$@"; do
  case "$prev" in --out) out="$a" ;; --out-dir) outdir="$a" ;; esac
  prev="$a"
done
content() {
  echo "$stage $*"
  prev=""
  for a in "$@"; do
    case "$prev" in --scene) [ "$stage" = arthrosim-prepare ] && grep '^prepare' "$a"; prev="$a"; continue ;; esac
    case "$prev" in --out|--out-dir) prev="$a"; continue ;; esac
    if [ -f "$a" ]; then cat "$a"; elif [ -d "$a" ]; then cat "$a"/*; fi
    prev="$a"
  done
}
scenario=""; prev=""
for a in "$@"; do
  case "$prev" in --scenario) scenario="$a" ;; esac
  prev="$a"
done
# comak and surface outputs start with an HDF5 file holding an effect ledger
# (written by the test; extra bytes after an HDF5 file's end leave it readable).
ledger="$ARTHROSIM_FAKE_LEDGERS/$stage.h5"
if [ -n "$scenario" ] && [ -f "$ARTHROSIM_FAKE_LEDGERS/$stage-$scenario.h5" ]; then
  ledger="$ARTHROSIM_FAKE_LEDGERS/$stage-$scenario.h5"
fi
if [ -n "$out" ] && [ -f "$ledger" ]; then cp "$ledger" "$out"; content "$@" >> "$out";
elif [ -n "$out" ]; then content "$@" > "$out"; fi
if [ "$stage" = arthrosim-prepare ]; then echo xdmf > "${out%.h5}.xdmf"; fi
if [ -n "$outdir" ]; then content "$@" > "$outdir/report.html"; content "$@" > "$outdir/summary.json"; fi
echo "$stage: done"
)SH";

class RunnerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() /
            ("arthrosim_runner_test_" + std::to_string(getpid()) + "_" +
             ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    fs::create_directories(root_ / "bin");
    fs::create_directories(root_ / "scenes");
    fs::create_directories(root_ / "models" / "knee");
    fs::create_directories(root_ / "trials" / "walk");
    std::ofstream(root_ / "models" / "knee" / "femur.stl") << "femur v1\n";
    std::ofstream(root_ / "trials" / "walk" / "ik.mot") << "ik v1\n";
    for (const char* s : {"prepare", "comak", "surface", "post"}) {
      write_stage(std::string("arthrosim-") + s, kFakeStage);
    }
    log_file_ = root_ / "calls.log";
    setenv("ARTHROSIM_FAKE_LOG", log_file_.c_str(), 1);
    // Fake comak and surface stages report building nothing by default.
    fs::create_directories(root_ / "ledgers");
    setenv("ARTHROSIM_FAKE_LEDGERS", (root_ / "ledgers").c_str(), 1);
    write_ledger("arthrosim-comak", common::EffectLedger("comak"));
    write_ledger("arthrosim-surface", common::EffectLedger("surface"));
    options_.out_dir = root_ / "out";
    options_.stage_dir = root_ / "bin";
  }
  void TearDown() override { fs::remove_all(root_); }

  // The ledger a fake stage copies into its output ("arthrosim-surface" or
  // "arthrosim-surface-<scenario>").
  void write_ledger(const std::string& name, const common::EffectLedger& ledger) {
    common::H5File f((root_ / "ledgers" / (name + ".h5")).string(),
                     common::H5File::Mode::kTruncate);
    common::write_effect_ledger(f, ledger);
  }

  void write_stage(const std::string& name, const std::string& script) {
    const fs::path p = root_ / "bin" / name;
    std::ofstream(p) << script;
    fs::permissions(p, fs::perms::owner_all);
  }

  Scene scene(const std::string& text) {
    const fs::path p = root_ / "scenes" / "s.yaml";
    std::ofstream(p) << text;
    return load_scene(p);
  }

  RunReport run(const Scene& s, std::string* printed = nullptr) {
    std::ostringstream log;
    RunReport r = run_scene(s, options_, log);
    if (printed) *printed = log.str();
    std::cout << log.str();
    return r;
  }

  // Stage programs called so far, one line each ("arthrosim-prepare --model ...").
  std::vector<std::string> calls() const {
    std::vector<std::string> out;
    std::ifstream in(log_file_);
    for (std::string line; std::getline(in, line);) out.push_back(line.substr(0, line.find(' ')));
    return out;
  }


 public:
  static std::vector<std::string> names(const std::vector<StageStep>& plan) {
    std::vector<std::string> n;
    for (const StageStep& s : plan) n.push_back(s.name);
    return n;
  }


 protected:
  static StageStatus status(const RunReport& r, const std::string& stage) {
    for (const StageOutcome& o : r.stages) {
      if (o.name == stage) return o.status;
    }
    ADD_FAILURE() << "no stage " << stage;
    return StageStatus::kNotReached;
  }
  static std::string reason(const RunReport& r, const std::string& stage) {
    for (const StageOutcome& o : r.stages) {
      if (o.name == stage) return o.reason;
    }
    return "(no stage " + stage + ")";
  }

  fs::path root_;
  fs::path log_file_;
  RunnerOptions options_;
};

constexpr const char* kPrepareOnly =
    "model: ../models/knee\noutputs: [prepared_model]\nprepare: {edge_length_mm: 3}\n";

// Three scenarios as in the seed; `outputs` filled in by each test.
std::string three_scenarios(const std::string& outputs, const std::string& edge = "3") {
  return "model: ../models/knee\ntrial: ../trials/walk\noutputs: " + outputs +
         "\nprepare: {edge_length_mm: " + edge +
         "}\ncomak: {effects: [ligaments, muscles]}\nsurface:\n  scenarios:\n"
         "    osmotic: {effects: [foundation_springs, osmotic_pressure], end_time_s: 1}\n"
         "    gait: {effects: [foundation_springs, imposed_kinematics, mesh_contact]}\n"
         "    gait_osmotic: {effects: [osmotic_pressure, imposed_kinematics, mesh_contact]}\n";
}

TEST_F(RunnerTest, StagesFollowFromOutputs) {
  const fs::path out = root_ / "out";
  using V = std::vector<std::string>;
  EXPECT_EQ(names(plan_stages(scene(three_scenarios("[prepared_model]")), out)), V{"prepare"});
  EXPECT_EQ(names(plan_stages(scene(three_scenarios("[kinematics]")), out)),
            (V{"prepare", "comak"}));
  EXPECT_EQ(names(plan_stages(scene(three_scenarios("[surface]")), out)),
            (V{"prepare", "comak", "surface.osmotic", "surface.gait", "surface.gait_osmotic"}));
  EXPECT_EQ(names(plan_stages(scene(three_scenarios("[report]")), out)),
            (V{"prepare", "comak", "surface.osmotic", "surface.gait", "surface.gait_osmotic",
               "post"}));
  // The osmotic scenario alone needs no musculoskeletal stage.
  const Scene osmotic = scene(
      "model: ../models/knee\noutputs: [surface]\nsurface:\n  scenarios:\n"
      "    osmotic: {effects: [foundation_springs, osmotic_pressure], end_time_s: 1}\n");
  const std::vector<StageStep> plan = plan_stages(osmotic, out);
  EXPECT_EQ(names(plan), (V{"prepare", "surface.osmotic"}));
  const StageStep& surf = plan[1];
  EXPECT_EQ(surf.executable, "arthrosim-surface");
  ASSERT_EQ(surf.inputs.size(), 1u);
  EXPECT_EQ(surf.inputs[0].first, "prepared.h5");
  EXPECT_EQ(surf.outputs, std::vector<fs::path>{out / "surface_osmotic.h5"});
  const std::vector<std::string> expect_args = {
      "--prepared", (out / "prepared.h5").string(), "--scene", osmotic.file.string(),
      "--scenario", "osmotic", "--out", (out / "surface_osmotic.h5").string()};
  EXPECT_EQ(surf.arguments, expect_args);
  // Post gets kinematics only when COMAK is part of the run.
  const Scene report_osmotic = scene(
      "model: ../models/knee\noutputs: [report]\nsurface:\n  scenarios:\n"
      "    osmotic: {effects: [inertia], end_time_s: 1}\n");
  const StageStep post = plan_stages(report_osmotic, out).back();
  EXPECT_EQ(post.name, "post");
  for (const std::string& a : post.arguments) EXPECT_NE(a, "--kinematics");
  const StageStep post_all = plan_stages(scene(three_scenarios("[report]")), out).back();
  EXPECT_NE(std::find(post_all.arguments.begin(), post_all.arguments.end(), "--kinematics"),
            post_all.arguments.end());
  // The gait scenario reads the kinematics; its options are its own.
  const StageStep gait = plan_stages(scene(three_scenarios("[surface]")), out)[3];
  EXPECT_EQ(gait.name, "surface.gait");
  EXPECT_EQ(gait.inputs.back().first, "kinematics.h5");
  EXPECT_NE(std::find(gait.options.begin(), gait.options.end(),
                      std::pair<std::string, std::string>(
                          "surface.gait.effects",
                          "[foundation_springs, imposed_kinematics, mesh_contact]")),
            gait.options.end());
  // Every stage reads its options from the scene (its block): prepare's
  // command line names the model, the scene and its output.
  const Scene edge25 = scene(three_scenarios("[prepared_model]", "2.5"));
  const StageStep prep = plan_stages(edge25, out)[0];
  const std::vector<std::string> prep_args = {"--model", (root_ / "models" / "knee").string(), "--scene",
                                              edge25.file.string(), "--out", (out / "prepared.h5").string()};
  EXPECT_EQ(prep.arguments, prep_args);
  EXPECT_NE(std::find(prep.options.begin(), prep.options.end(),
                      std::pair<std::string, std::string>("prepare.edge_length_mm", "2.5")),
            prep.options.end());
  // Why each run is planned.
  const std::vector<StageStep> all = plan_stages(scene(three_scenarios("[report]")), out);
  EXPECT_EQ(all[0].needed_for, "prepared.h5 for surface.osmotic");  // the first run that reads it
  EXPECT_EQ(all[1].needed_for, "kinematics.h5 for surface.gait");
  EXPECT_EQ(all[2].needed_for, "surface_osmotic.h5 for post");
  EXPECT_EQ(all.back().needed_for, "output report");
}

TEST_F(RunnerTest, RunsOnlyNeededStagesInOrderAndReusesThem) {
  const Scene s = scene(three_scenarios("[surface]"));
  std::string printed;
  RunReport r = run(s, &printed);
  ASSERT_EQ(r.status, RunStatus::kOk) << r.message;
  EXPECT_EQ(calls(), (std::vector<std::string>{"arthrosim-prepare", "arthrosim-comak",
                                               "arthrosim-surface", "arthrosim-surface",
                                               "arthrosim-surface"}));
  EXPECT_EQ(status(r, "prepare"), StageStatus::kRan);
  EXPECT_EQ(reason(r, "prepare"), "no previous output");
  EXPECT_NE(printed.find("prepare: running — no previous output"), std::string::npos);
  for (const char* f : {"prepared.h5", "kinematics.h5", "surface_osmotic.h5", "surface_gait.h5",
                        "surface_gait_osmotic.h5", ".stamps/prepare.txt",
                        ".stamps/surface.gait.txt"}) {
    EXPECT_TRUE(fs::exists(root_ / "out" / f)) << f;
  }
  EXPECT_FALSE(fs::exists(root_ / "out" / "report.html"));  // post was not asked for

  // Second run: nothing changed, nothing runs.
  r = run(s, &printed);
  ASSERT_EQ(r.status, RunStatus::kOk);
  EXPECT_EQ(calls().size(), 5u);
  for (const StageOutcome& o : r.stages) {
    EXPECT_EQ(o.status, StageStatus::kSkipped) << o.name;
    EXPECT_EQ(o.reason.rfind("inputs, options and code unchanged (hash ", 0), 0u) << o.reason;
    EXPECT_EQ(o.key.size(), 64u);
  }
  EXPECT_NE(printed.find("prepare: skipping — inputs, options and code unchanged (hash "),
            std::string::npos);
}

TEST_F(RunnerTest, ChangedOptionRerunsThatStageAndWhatDependsOnIt) {
  ASSERT_EQ(run(scene(three_scenarios("[surface]", "3"))).status, RunStatus::kOk);
  std::string printed;
  // edge_length_mm changes prepare's command line, so its output changes, so
  // every later stage reruns too (their input prepared.h5 changed).
  const RunReport r = run(scene(three_scenarios("[surface]", "2")), &printed);
  ASSERT_EQ(r.status, RunStatus::kOk);
  EXPECT_EQ(reason(r, "prepare"), "options changed: prepare.edge_length_mm 3 -> 2");
  EXPECT_NE(printed.find("prepare: running — options changed: prepare.edge_length_mm 3 -> 2"),
            std::string::npos);
  EXPECT_EQ(status(r, "comak"), StageStatus::kRan);
  EXPECT_EQ(reason(r, "comak"), "input changed: prepared.h5");
  EXPECT_EQ(status(r, "surface.osmotic"), StageStatus::kRan);
  EXPECT_EQ(calls().size(), 10u);
}

TEST_F(RunnerTest, ChangedScenarioOptionRerunsOnlyThatScenario) {
  ASSERT_EQ(run(scene(three_scenarios("[surface]"))).status, RunStatus::kOk);
  std::string text = three_scenarios("[surface]");
  const std::string from = "gait: {effects: [foundation_springs, imposed_kinematics, mesh_contact]}";
  text.replace(text.find(from), from.size(),
               "gait: {time_step_s: 5e-5, effects: [foundation_springs, imposed_kinematics, "
               "mesh_contact]}");
  const RunReport r = run(scene(text));
  ASSERT_EQ(r.status, RunStatus::kOk);
  EXPECT_EQ(status(r, "prepare"), StageStatus::kSkipped);
  EXPECT_EQ(status(r, "comak"), StageStatus::kSkipped);
  EXPECT_EQ(status(r, "surface.osmotic"), StageStatus::kSkipped);
  EXPECT_EQ(status(r, "surface.gait"), StageStatus::kRan);
  EXPECT_EQ(reason(r, "surface.gait"), "options changed: surface.gait.time_step_s 1e-04 -> 5e-05");
  EXPECT_EQ(status(r, "surface.gait_osmotic"), StageStatus::kSkipped);
  EXPECT_EQ(calls().size(), 6u);
}

TEST_F(RunnerTest, ChangedInputFileReruns) {
  const Scene s = scene(three_scenarios("[kinematics]"));
  ASSERT_EQ(run(s).status, RunStatus::kOk);
  // A trial file edited: COMAK reruns, prepare does not.
  std::ofstream(root_ / "trials" / "walk" / "ik.mot") << "ik v2\n";
  RunReport r = run(s);
  ASSERT_EQ(r.status, RunStatus::kOk);
  EXPECT_EQ(status(r, "prepare"), StageStatus::kSkipped);
  EXPECT_EQ(status(r, "comak"), StageStatus::kRan);
  EXPECT_EQ(reason(r, "comak"), "input changed: trial");
  // A mesh added to the model folder: both rerun.
  std::ofstream(root_ / "models" / "knee" / "tibia.stl") << "tibia\n";
  r = run(s);
  EXPECT_EQ(reason(r, "prepare"), "input changed: model");
  EXPECT_EQ(reason(r, "comak"), "inputs changed: model, prepared.h5");
  EXPECT_EQ(calls().size(), 5u);
}

TEST_F(RunnerTest, ChangedExecutableBytesRerunAndIdenticalOutputStopsThePropagation) {
  const Scene s = scene(three_scenarios("[kinematics]"));
  ASSERT_EQ(run(s).status, RunStatus::kOk);
  // A rebuilt prepare (different bytes) that writes the same output: prepare
  // reruns, COMAK is skipped because its inputs are bit-identical.
  write_stage("arthrosim-prepare", std::string(kFakeStage) + "# rebuilt\n");
  const RunReport r = run(s);
  ASSERT_EQ(r.status, RunStatus::kOk);
  EXPECT_EQ(status(r, "prepare"), StageStatus::kRan);
  EXPECT_EQ(reason(r, "prepare"),
            "code changed: arthrosim-prepare is not the build that wrote the output");
  EXPECT_EQ(status(r, "comak"), StageStatus::kSkipped);
  EXPECT_EQ(calls(), (std::vector<std::string>{"arthrosim-prepare", "arthrosim-comak",
                                               "arthrosim-prepare"}));
}

TEST_F(RunnerTest, MissingOrEditedOutputReruns) {
  const Scene s = scene(kPrepareOnly);
  ASSERT_EQ(run(s).status, RunStatus::kOk);
  fs::remove(root_ / "out" / "prepared.h5");
  RunReport r = run(s);
  EXPECT_EQ(reason(r, "prepare"), "output prepared.h5 missing");
  fs::remove(root_ / "out" / "prepared.xdmf");  // the sidecar counts as an output too
  r = run(s);
  EXPECT_EQ(reason(r, "prepare"), "output prepared.xdmf missing");
  std::ofstream(root_ / "out" / "prepared.h5", std::ios::app) << "tampered\n";
  r = run(s);
  EXPECT_EQ(reason(r, "prepare"), "output prepared.h5 changed since the stage wrote it");
  fs::remove(root_ / "out" / ".stamps" / "prepare.txt");
  r = run(s);
  EXPECT_EQ(reason(r, "prepare"), "no record of a previous successful run");
  EXPECT_EQ(calls().size(), 5u);
}

TEST_F(RunnerTest, StampRecordsAPortableCommandLine) {
  const Scene s = scene(three_scenarios("[kinematics]"));
  ASSERT_EQ(run(s).status, RunStatus::kOk);
  const fs::path stamp = root_ / "out" / ".stamps" / "comak.txt";
  std::ifstream in(stamp);
  std::stringstream text;
  text << in.rdbuf();
  in.close();
  const std::string line =
      "arguments\t--model <model> --prepared $OUT/prepared.h5 --trial <trial> --scene <scene> "
      "--out $OUT/kinematics.h5\n";
  ASSERT_NE(text.str().find(line), std::string::npos) << text.str();
  // The folder moved elsewhere: still up to date (no machine paths in keys).
  fs::rename(root_ / "out", root_ / "moved");
  options_.out_dir = root_ / "moved";
  for (const StageOutcome& o : run(s).stages) EXPECT_EQ(o.status, StageStatus::kSkipped) << o.name;
  fs::rename(root_ / "moved", root_ / "out");
  options_.out_dir = root_ / "out";
  // A runner that called the stage differently (here: the stamp says so)
  // reruns it and says what changed.
  std::string edited = text.str();
  edited.replace(edited.find(line), line.size(),
                 "arguments\t--model <model> --trial <trial> --out $OUT/kinematics.h5\n");
  std::ofstream(stamp) << edited;
  const RunReport r = run(s);
  EXPECT_EQ(status(r, "prepare"), StageStatus::kSkipped);
  EXPECT_EQ(reason(r, "comak"),
            "command line changed: --model <model> --trial <trial> --out $OUT/kinematics.h5 -> "
            "--model <model> --prepared $OUT/prepared.h5 --trial <trial> --scene <scene> --out "
            "$OUT/kinematics.h5");
}

TEST_F(RunnerTest, StageThatBuildsAnUnrequestedTermFails) {
  // The gait scenario asks for foundation_springs, imposed_kinematics and
  // mesh_contact; its (fake) stage reports building osmotic_pressure as well.
  common::EffectLedger good("surface:osmotic");
  good.record("foundation_springs", 5817, "femur");
  good.record("osmotic_pressure", 5568, "femur");
  write_ledger("arthrosim-surface-osmotic", good);
  common::EffectLedger bad("surface:gait");
  bad.record("foundation_springs", 5817, "femur");
  bad.record("osmotic_pressure", 5568, "femur");
  write_ledger("arthrosim-surface-gait", bad);
  std::string printed;
  const RunReport r = run(scene(three_scenarios("[surface]")), &printed);
  EXPECT_EQ(r.status, RunStatus::kStageFailed);
  EXPECT_EQ(status(r, "surface.osmotic"), StageStatus::kRan);
  EXPECT_NE(printed.find("surface.osmotic: effects built: foundation_springs 5817, "
                         "osmotic_pressure 5568"),
            std::string::npos)
      << printed;
  EXPECT_EQ(status(r, "surface.gait"), StageStatus::kFailed);
  EXPECT_EQ(reason(r, "surface.gait"), "built effect(s) the scene did not ask for: osmotic_pressure");
  EXPECT_EQ(status(r, "surface.gait_osmotic"), StageStatus::kNotReached);
  EXPECT_FALSE(fs::exists(root_ / "out" / ".stamps" / "surface.gait.txt"));
  EXPECT_TRUE(fs::exists(root_ / "out" / ".stamps" / "surface.osmotic.txt"));
}

TEST_F(RunnerTest, StageWithoutEffectLedgerFails) {
  fs::remove(root_ / "ledgers" / "arthrosim-comak.h5");  // comak writes a plain file
  const RunReport r = run(scene(three_scenarios("[kinematics]")));
  EXPECT_EQ(r.status, RunStatus::kStageFailed);
  EXPECT_EQ(reason(r, "comak").rfind("has no readable effect ledger: ", 0), 0u) << reason(r, "comak");
}

TEST_F(RunnerTest, FailingStageStopsTheRunAndKeepsEarlierOutputs) {
  write_stage("arthrosim-comak", "#!/bin/sh\necho 'comak: Ipopt failed at frame 7' >&2\nexit 3\n");
  const Scene s = scene(three_scenarios("[surface]"));
  std::string printed;
  RunReport r = run(s, &printed);
  EXPECT_EQ(r.status, RunStatus::kStageFailed);
  EXPECT_EQ(r.message.rfind("stage comak (arthrosim-comak) exited with status 3; stopping", 0),
            0u)
      << r.message;
  EXPECT_EQ(status(r, "prepare"), StageStatus::kRan);
  EXPECT_EQ(status(r, "comak"), StageStatus::kFailed);
  EXPECT_EQ(r.stages[1].exit_code, 3);
  EXPECT_EQ(status(r, "surface.osmotic"), StageStatus::kNotReached);
  EXPECT_TRUE(fs::exists(root_ / "out" / "prepared.h5"));
  EXPECT_FALSE(fs::exists(root_ / "out" / ".stamps" / "comak.txt"));
  EXPECT_NE(printed.find("comak: FAILED after"), std::string::npos);
  EXPECT_EQ(calls(), std::vector<std::string>{"arthrosim-prepare"});  // comak's fake logs nothing

  // Fixed: the next run reuses prepare and retries COMAK.
  write_stage("arthrosim-comak", kFakeStage);
  r = run(s);
  ASSERT_EQ(r.status, RunStatus::kOk);
  EXPECT_EQ(status(r, "prepare"), StageStatus::kSkipped);
  EXPECT_EQ(status(r, "comak"), StageStatus::kRan);
  EXPECT_EQ(reason(r, "comak"), "no previous output");
}

// A surface stage that records when it starts and ends (nanoseconds) and the
// OMP_NUM_THREADS it was given, sleeps 1 s (the walking scenarios), and then
// does what the fake does.
// Its scenario "gait" fails when $ARTHROSIM_FAIL_GAIT is set.
constexpr const char* kTimedSurface = R"SH(#!/bin/sh
scenario=""; prev=""
for a in "$@"; do
  case "$prev" in --scenario) scenario="$a" ;; esac
  prev="$a"
done
echo "start $scenario $(date +%s%N) threads=${OMP_NUM_THREADS:-unset}" >> "$ARTHROSIM_FAKE_TIMES"
echo "surface $scenario: 50% (1/2)"
case "$scenario" in gait*) sleep 1 ;; esac
echo "end $scenario $(date +%s%N)" >> "$ARTHROSIM_FAKE_TIMES"
if [ "$scenario" = gait ] && [ -n "$ARTHROSIM_FAIL_GAIT" ]; then echo "gait: diverged at t = 0.3 s" >&2; exit 3; fi
exec "$ARTHROSIM_FAKE_REAL" "$@"
)SH";

class RunnerJobsTest : public RunnerTest {
 protected:
  void SetUp() override {
    RunnerTest::SetUp();
    fs::create_directories(root_ / "real");
    const fs::path real = root_ / "real" / "arthrosim-surface";
    std::ofstream(real) << kFakeStage;
    fs::permissions(real, fs::perms::owner_all);
    setenv("ARTHROSIM_FAKE_REAL", real.c_str(), 1);
    times_ = root_ / "times.log";
    setenv("ARTHROSIM_FAKE_TIMES", times_.c_str(), 1);
    write_stage("arthrosim-surface", kTimedSurface);
    unsetenv("OMP_NUM_THREADS");
    unsetenv("ARTHROSIM_FAIL_GAIT");
  }
  void TearDown() override {
    unsetenv("ARTHROSIM_FAIL_GAIT");
    RunnerTest::TearDown();
  }
  // scenario -> (start, end) in ns, and scenario -> OMP_NUM_THREADS seen.
  void read_times(std::map<std::string, std::pair<long long, long long>>& span,
                  std::map<std::string, std::string>& threads) const {
    std::ifstream in(times_);
    for (std::string what, scenario; in >> what >> scenario;) {
      long long t = 0;
      in >> t;
      if (what == "start") {
        std::string th;
        in >> th;
        span[scenario].first = t;
        threads[scenario] = th;
      } else {
        span[scenario].second = t;
      }
    }
  }
  fs::path times_;
};

TEST_F(RunnerJobsTest, ReadyStagesRunSideBySideWithTheSameResults) {
  const Scene s = scene(three_scenarios("[report]"));
  options_.jobs = 2;
  std::string printed;
  const RunReport r = run(s, &printed);
  ASSERT_EQ(r.status, RunStatus::kOk) << r.message;
  for (const StageOutcome& o : r.stages) EXPECT_EQ(o.status, StageStatus::kRan) << o.name;
  std::map<std::string, std::pair<long long, long long>> span;
  std::map<std::string, std::string> threads;
  read_times(span, threads);
  ASSERT_EQ(span.size(), 3u);
  // gait and gait_osmotic both wait for COMAK and then overlap in time (each
  // sleeps 1 s; run one after the other they could not overlap at all).
  EXPECT_LT(span["gait"].first, span["gait_osmotic"].second);
  EXPECT_LT(span["gait_osmotic"].first, span["gait"].second);
  // Each of two stages side by side gets half the cores (at least one).
  const std::string expect = "threads=" + std::to_string(std::max(1, static_cast<int>(std::thread::hardware_concurrency()) / 2));
  EXPECT_EQ(threads["gait"], expect);
  EXPECT_EQ(threads["gait_osmotic"], expect);
  // Their output went to logs, and the runner showed each log's last lines.
  std::ifstream gait_log(root_ / "out" / "logs" / "surface.gait.log");
  std::stringstream gl;
  gl << gait_log.rdbuf();
  EXPECT_NE(gl.str().find("arthrosim-surface: done"), std::string::npos) << gl.str();
  EXPECT_NE(printed.find("surface.gait: last lines of "), std::string::npos);
  EXPECT_NE(printed.find("  | arthrosim-surface: done"), std::string::npos);

  // One stage after the other (jobs 1) in another folder: byte-identical outputs.
  const fs::path parallel_out = options_.out_dir;
  options_.jobs = 1;
  options_.out_dir = root_ / "out_serial";
  fs::remove(times_);
  std::string serial_printed;
  ASSERT_EQ(run(s, &serial_printed).status, RunStatus::kOk);
  EXPECT_EQ(serial_printed.find("last lines of"), std::string::npos);  // streamed, no logs
  span.clear();
  threads.clear();
  read_times(span, threads);
  EXPECT_GE(span["gait_osmotic"].first, span["gait"].second);
  EXPECT_EQ(threads["gait"], "threads=unset");
  for (const char* f : {"prepared.h5", "kinematics.h5", "surface_osmotic.h5", "surface_gait.h5",
                        "surface_gait_osmotic.h5", "report.html"}) {
    std::ifstream a(parallel_out / f), b(options_.out_dir / f);
    std::stringstream sa, sb;
    sa << a.rdbuf();
    sb << b.rdbuf();
    // The fakes write their command lines, which name the output folder.
    std::string pa = sa.str(), pb = sb.str();
    for (std::string* t : {&pa, &pb}) {
      // The longer folder name first: one is a prefix of the other.
      for (const std::string& dir : {options_.out_dir.string(), parallel_out.string()}) {
        for (std::size_t k; (k = t->find(dir)) != std::string::npos;) t->replace(k, dir.size(), "$OUT");
      }
    }
    EXPECT_TRUE(pa == pb) << f << " differs between --jobs 2 and --jobs 1";
  }
}

TEST_F(RunnerJobsTest, AFailureStartsNothingMoreButLetsRunningStagesFinish) {
  setenv("ARTHROSIM_FAIL_GAIT", "1", 1);
  options_.jobs = 2;
  std::string printed;
  const RunReport r = run(scene(three_scenarios("[report]")), &printed);
  EXPECT_EQ(r.status, RunStatus::kStageFailed);
  EXPECT_EQ(r.message.rfind("stage surface.gait (arthrosim-surface) exited with status 3; stopping", 0), 0u)
      << r.message;
  EXPECT_EQ(status(r, "surface.gait"), StageStatus::kFailed);
  // The scenario running beside it finished, was checked and stamped: a rerun reuses it.
  EXPECT_EQ(status(r, "surface.gait_osmotic"), StageStatus::kRan);
  EXPECT_TRUE(fs::exists(root_ / "out" / ".stamps" / "surface.gait_osmotic.txt"));
  EXPECT_FALSE(fs::exists(root_ / "out" / ".stamps" / "surface.gait.txt"));
  EXPECT_EQ(status(r, "post"), StageStatus::kNotReached);
  // The failed stage's own message reaches the user through its log.
  EXPECT_NE(printed.find("  | gait: diverged at t = 0.3 s"), std::string::npos) << printed;

  unsetenv("ARTHROSIM_FAIL_GAIT");
  const RunReport again = run(scene(three_scenarios("[report]")));
  ASSERT_EQ(again.status, RunStatus::kOk) << again.message;
  EXPECT_EQ(status(again, "surface.gait_osmotic"), StageStatus::kSkipped);
  EXPECT_EQ(status(again, "surface.gait"), StageStatus::kRan);
}

TEST_F(RunnerTest, KilledStageAndStageWithoutOutputFail) {
  write_stage("arthrosim-prepare", "#!/bin/sh\nkill -9 $$\n");
  RunReport r = run(scene(kPrepareOnly));
  EXPECT_EQ(r.status, RunStatus::kStageFailed);
  EXPECT_EQ(r.stages[0].exit_code, 128 + 9);
  EXPECT_EQ(r.stages[0].reason, "killed by signal 9");
  write_stage("arthrosim-prepare", "#!/bin/sh\nexit 0\n");
  r = run(scene(kPrepareOnly));
  EXPECT_EQ(r.status, RunStatus::kStageFailed);
  EXPECT_EQ(r.stages[0].reason,
            "exited with status 0 but did not write " + (root_ / "out" / "prepared.h5").string());
  EXPECT_FALSE(fs::exists(root_ / "out" / ".stamps" / "prepare.txt"));
}

TEST_F(RunnerTest, MissingStageProgramIsAnErrorBeforeAnythingRuns) {
  fs::remove(root_ / "bin" / "arthrosim-surface");
  const RunReport r = run(scene(three_scenarios("[surface]")));
  EXPECT_EQ(r.status, RunStatus::kMissingExecutable);
  EXPECT_EQ(r.message.rfind("stage arthrosim-surface not available in this build (looked for " +
                                (root_ / "bin" / "arthrosim-surface").string() + ")",
                            0),
            0u)
      << r.message;
  EXPECT_TRUE(calls().empty());
  for (const StageOutcome& o : r.stages) EXPECT_EQ(o.status, StageStatus::kNotReached);
}

TEST_F(RunnerTest, DryRunRunsNothingAndForceRunsEverything) {
  const Scene s = scene(three_scenarios("[kinematics]"));
  options_.dry_run = true;
  std::string printed;
  RunReport r = run(s, &printed);
  ASSERT_EQ(r.status, RunStatus::kOk);
  EXPECT_TRUE(calls().empty());
  EXPECT_FALSE(fs::exists(root_ / "out"));
  EXPECT_EQ(status(r, "prepare"), StageStatus::kWouldRun);
  EXPECT_EQ(status(r, "comak"), StageStatus::kWouldRun);
  EXPECT_EQ(reason(r, "comak"), "input prepared.h5 is written earlier in this run");
  EXPECT_NE(printed.find("not run: surface.osmotic"), std::string::npos) << printed;

  options_.dry_run = false;
  ASSERT_EQ(run(s).status, RunStatus::kOk);
  options_.dry_run = true;
  r = run(s);
  EXPECT_EQ(status(r, "prepare"), StageStatus::kWouldSkip);
  EXPECT_EQ(status(r, "comak"), StageStatus::kWouldSkip);
  EXPECT_EQ(calls().size(), 2u);

  options_.dry_run = false;
  options_.force = true;
  r = run(s);
  EXPECT_EQ(reason(r, "prepare"), "--force");
  EXPECT_EQ(status(r, "comak"), StageStatus::kRan);
  EXPECT_EQ(calls().size(), 4u);
}

TEST_F(RunnerTest, OutputFolderInUseIsRefused) {
  // Stand in for a concurrent run: hold the folder's lock on another open
  // file description (flock locks conflict between descriptions).
  fs::create_directories(root_ / "out");
  const int fd = ::open((root_ / "out" / ".arthrosim.lock").c_str(), O_RDWR | O_CREAT, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);
  RunReport r = run(scene(kPrepareOnly));
  EXPECT_EQ(r.status, RunStatus::kFolderBusy);
  EXPECT_NE(r.message.find("another arthrosim run is using"), std::string::npos);
  EXPECT_TRUE(calls().empty());
  ::close(fd);  // released: the run goes ahead
  r = run(scene(kPrepareOnly));
  EXPECT_EQ(r.status, RunStatus::kOk);
  EXPECT_EQ(calls().size(), 1u);
}

TEST_F(RunnerTest, ReportRunsPostWithEverySurfaceOutput) {
  const RunReport r = run(scene(three_scenarios("[report]")));
  ASSERT_EQ(r.status, RunStatus::kOk) << r.message;
  EXPECT_EQ(status(r, "post"), StageStatus::kRan);
  EXPECT_TRUE(fs::exists(root_ / "out" / "report.html"));
  EXPECT_TRUE(fs::exists(root_ / "out" / "summary.json"));
  std::ifstream in(log_file_);
  std::string line, post_line;
  while (std::getline(in, line)) {
    if (line.rfind("arthrosim-post ", 0) == 0) post_line = line;
  }
  for (const char* f : {"surface_osmotic.h5", "surface_gait.h5", "surface_gait_osmotic.h5",
                        "kinematics.h5"}) {
    EXPECT_NE(post_line.find(f), std::string::npos) << f << " not passed to post: " << post_line;
  }
}

// The bundled scenes parse and plan as issue 8 requires: the osmotic scene
// runs no musculoskeletal stage and asks for no mesh contact; the walking
// scene without osmotic pressure does not ask for the pressure term.
TEST(BundledScenes, ParseAndPlanOnlyWhatTheyNeed) {
  const fs::path dir = fs::path(ARTHROSIM_SOURCE_DIR) / "data" / "scenes";
  const fs::path out = "/nonexistent/out";
  using V = std::vector<std::string>;
  const Scene demo = load_scene(dir / "demo.yaml");
  // The demo runs every stage and the seed's three surface scenarios.
  EXPECT_EQ(RunnerTest::names(plan_stages(demo, out)),
            (V{"prepare", "comak", "surface.osmotic", "surface.gait", "surface.gait_osmotic", "post"}));
  EXPECT_EQ(demo.instances("surface").size(), 3u);
  EXPECT_FALSE(demo.require_instance("surface", "osmotic").wants("mesh_contact"));

  const Scene osmotic = load_scene(dir / "osmotic.yaml");
  EXPECT_EQ(RunnerTest::names(plan_stages(osmotic, out)), (V{"prepare", "surface.osmotic"}));
  EXPECT_FALSE(osmotic.require_instance("surface", "osmotic").wants("mesh_contact"));
  EXPECT_TRUE(osmotic.require_instance("surface", "osmotic").wants("osmotic_pressure"));
  // The same scenario run dynamically to the steady state (opt-in keys of the
  // surface stage): same plan, model, prepared resolution and effects.
  const Scene dynamic = load_scene(dir / "osmotic_dynamic.yaml");
  EXPECT_EQ(RunnerTest::names(plan_stages(dynamic, out)), (V{"prepare", "surface.osmotic"}));
  EXPECT_EQ(scene_inputs(dynamic).model, scene_inputs(osmotic).model);
  EXPECT_EQ(dynamic.block("prepare").canonical_text(), osmotic.block("prepare").canonical_text());
  EXPECT_EQ(dynamic.require_instance("surface", "osmotic").effects, osmotic.require_instance("surface", "osmotic").effects);
  EXPECT_FALSE(dynamic.require_instance("surface", "osmotic").options.flag("steady_state"));
  EXPECT_GT(dynamic.require_instance("surface", "osmotic").options.si("steady_state_change_mm"), 0.0);

  const Scene gait = load_scene(dir / "gait.yaml");
  EXPECT_EQ(RunnerTest::names(plan_stages(gait, out)), (V{"prepare", "comak", "surface.gait"}));
  EXPECT_FALSE(gait.require_instance("surface", "gait").wants("osmotic_pressure"));
  EXPECT_TRUE(gait.require_instance("surface", "gait").wants("mesh_contact"));

  const Scene both = load_scene(dir / "gait_osmotic.yaml");
  EXPECT_EQ(RunnerTest::names(plan_stages(both, out)),
            (V{"prepare", "comak", "surface.gait_osmotic"}));
  EXPECT_TRUE(both.require_instance("surface", "gait_osmotic").wants("osmotic_pressure"));
  EXPECT_TRUE(both.require_instance("surface", "gait_osmotic").wants("mesh_contact"));

  // The demo's walking scenarios are the bundled walking scenes': every
  // option (the whole cycle: no end_time_s in either), effect and the
  // prepared resolution the same, apart from the description (the demo file
  // repeats the settings).
  EXPECT_EQ(demo.block("prepare").canonical_text(), gait.block("prepare").canonical_text());
  EXPECT_EQ(scene_inputs(demo).model, scene_inputs(gait).model);
  for (const Scene* whole : {&gait, &both}) {
    const common::BlockInstance& whole_walk = whole->instances("surface").front();
    const std::string name = whole_walk.name;
    const common::BlockInstance& walk = demo.require_instance("surface", name);
    EXPECT_EQ(walk.effects, whole_walk.effects) << name;
    auto options = [](const common::BlockInstance& sc) {
      std::vector<std::pair<std::string, std::string>> kept;
      for (const auto& kv : sc.options.canonical())
        if (kv.first.find("description") == std::string::npos)
          kept.push_back(kv);
      return kept;
    };
    EXPECT_EQ(options(walk), options(whole_walk)) << name;
  }
}

}  // namespace
}  // namespace arthrosim::pipelines
