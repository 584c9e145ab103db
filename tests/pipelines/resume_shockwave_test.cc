// Checkpoint and resume of the shockwave stage (issue 30; docs/testing.md,
// "Checkpoint and resume"; pipelines/shockwave_checkpoint.h): arthrosim-shockwave
// killed with SIGKILL at a checkpoint and rerun with the same command
// continues, says so, and ends with the files of an uninterrupted run: every
// dataset and attribute of both run files bit-identical (h5diff; only the
// wall-time attributes /solver wall_s and automaton_steps_per_s may differ),
// the XDMF sidecars and the summary JSON byte for byte (but its wall_s).
//
// The stage: the 10 mm poroelastic cartilage bar (120 automata, pore fluid,
// filtration, the velocity-driven plate reading of the EFD), two runs (EFD
// 0.12 and 0.33 mJ/mm^2) of 25 steps and 13 frames each, a checkpoint after
// every step (interval 0): checkpoints 1-24 are run 1's steps, 25 records
// run 1 as finished, 26-49 are run 2's steps. Each stage run takes about
// 0.2 s.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "tests/test_support.h"
#include "pipelines/shockwave_checkpoint.h"

namespace {

namespace fs = std::filesystem;

const fs::path kDir = fs::path(ARTHROSIM_BINARY_DIR) / "test_scratch" / "resume_shockwave_test";
const fs::path kBin = fs::path(ARTHROSIM_BINARY_DIR) / "bin";

std::pair<int, std::string> run(const std::string& command) { return arthrosim::test_support::run_shell(command); }
std::string slurp(const fs::path& p) { return arthrosim::test_support::read_text(p); }

fs::path scratch(const std::string& name) {
  const fs::path d = kDir / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

const char* kRuns[] = {"sw_efd0.12", "sw_efd0.33"};

// Relative --out in each case's own folder: the command line (an attribute
// of the files, and part of the checkpoint's identity) is the same in all.
std::string command(const std::string& extra = "") {
  return (kBin / "arthrosim-shockwave").string() +
         " --geometry bar --bar-tissue cartilage --bar-length-mm 10 --end-time-us 10 --output-interval-us 1"
         " --efd-mj-per-mm2 0.12 0.33 --checkpoint-interval-s 0 --out sw" +
         extra;
}

// The uninterrupted run of command(extra), once per `extra`.
fs::path reference(const std::string& extra = "") {
  static std::map<std::string, fs::path> done;
  if (done.count(extra)) return done[extra];
  const fs::path d = scratch("reference" + std::to_string(done.size()));
  const auto [status, printed] = run("cd " + d.string() + " && " + command(extra));
  EXPECT_EQ(status, 0) << printed;
  EXPECT_FALSE(fs::exists(d / "sw.checkpoint"));
  return done[extra] = d;
}

std::set<std::string> differences(const fs::path& a, const fs::path& b) {
  return arthrosim::test_support::h5diff_differences(a, b);
}

// Wall times: the only attributes allowed to differ.
const std::set<std::string> kWallTimes = {"attribute: <wall_s of </solver>>",
                                          "attribute: <automaton_steps_per_s of </solver>>"};

// The summary without its wall times.
std::string summary_without_wall_times(const fs::path& p) {
  std::istringstream in(slurp(p));
  std::string line, out;
  while (std::getline(in, line))
    if (line.find("\"wall_s\"") == std::string::npos) out += line + "\n";
  return out;
}

void expect_same_as_reference(const fs::path& dir, const std::string& extra = "") {
  const fs::path ref = reference(extra);
  for (const char* r : kRuns) {
    SCOPED_TRACE(r);
    ASSERT_TRUE(fs::exists(dir / (std::string(r) + ".h5")));
    for (const std::string& d : differences(ref / (std::string(r) + ".h5"), dir / (std::string(r) + ".h5")))
      EXPECT_TRUE(kWallTimes.count(d)) << "differs from the uninterrupted run: " << d;
    EXPECT_TRUE(slurp(ref / (std::string(r) + ".xdmf")) == slurp(dir / (std::string(r) + ".xdmf")));
    EXPECT_FALSE(fs::exists(dir / (std::string(r) + ".h5.partial")));
  }
  const std::string a = summary_without_wall_times(ref / "sw_summary.json");
  EXPECT_NE(a.find("\"label\""), std::string::npos);
  EXPECT_EQ(a, summary_without_wall_times(dir / "sw_summary.json"));
  EXPECT_FALSE(fs::exists(dir / "sw.checkpoint"));  // removed once every output is complete
}

void kill_at(const fs::path& dir, const std::string& at, const std::string& extra = "") {
  const auto [killed, printed] =
      run("cd " + dir.string() + " && ARTHROSIM_TEST_KILL_AT_CHECKPOINT=" + at + " exec " + command(extra));
  EXPECT_NE(killed, 0) << "not killed at checkpoint " << at << ": " << printed;
  EXPECT_TRUE(fs::exists(dir / "sw.checkpoint"));
  EXPECT_FALSE(fs::exists(dir / "sw_summary.json"));
}

std::string rerun(const fs::path& dir, const std::string& extra = "") {
  const auto [status, printed] = run("cd " + dir.string() + " && " + command(extra));
  EXPECT_EQ(status, 0) << printed;
  return printed;
}

// Killed after the first step, after a later one, while a checkpoint is
// written (before its rename: the one before stands), right after run 1 was
// recorded as finished, inside run 2, and twice in a row; each rerun of the
// same command resumes where the checkpoint says and ends with the
// uninterrupted run's bytes.
TEST(ResumeShockwave, KilledAtCheckpointsResumesBitIdentical) {
  struct Case {
    std::vector<std::string> kills;
    std::vector<std::string> says;     // in the rerun's log
    std::string never;                 // not in the rerun's log
  };
  const std::string from = "resuming from the checkpoint sw.checkpoint: ";
  const std::string run1_taken = from + "efd0.12 finished before, sw_efd0.12.h5 kept (not simulated again)";
  const std::vector<Case> cases = {
      {{"1"}, {from + "efd0.12, 1 of 25 steps done, frames written: 1 (taken from it)"}, run1_taken},
      {{"17"}, {from + "efd0.12, 17 of 25 steps done, frames written: 9 (taken from it)"}, run1_taken},
      {{"7.partial"}, {from + "efd0.12, 6 of 25 steps done, frames written: 3 (taken from it)"}, run1_taken},
      {{"25"}, {run1_taken}, "efd0.33, "},
      {{"40"}, {run1_taken, from + "efd0.33, 15 of 25 steps done, frames written: 8 (taken from it)"}, ""},
      // The second process resumed at step 3 and did 2 more.
      {{"3", "2"}, {from + "efd0.12, 5 of 25 steps done, frames written: 3 (taken from it)"}, run1_taken},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.kills.front() + " x" + std::to_string(c.kills.size()));
    const fs::path dir = scratch("at_" + c.kills.front() + "_" + std::to_string(c.kills.size()));
    for (const std::string& k : c.kills) kill_at(dir, k);
    const std::string log = rerun(dir);
    for (const std::string& s : c.says) EXPECT_NE(log.find(s), std::string::npos) << s << "\n" << log;
    if (!c.never.empty()) {
      EXPECT_EQ(log.find(c.never), std::string::npos) << log;
    }
    expect_same_as_reference(dir);
  }
}

// write_frames false: the checkpoint holds the frames' scalars and at-once
// volumes only; the same bit-identity.
TEST(ResumeShockwave, WithoutFieldFramesResumesBitIdentical) {
  const std::string extra = " --write-frames false";
  const fs::path dir = scratch("no_frames");
  kill_at(dir, "12", extra);
  const std::string log = rerun(dir, extra);
  EXPECT_NE(log.find("efd0.12, 12 of 25 steps done"), std::string::npos) << log;
  expect_same_as_reference(dir, extra);
}

// A checkpoint of another run (another option) is not used: warned about,
// removed, the stage starts over and still matches; an unreadable one too.
TEST(ResumeShockwave, CheckpointOfAnotherRunIsNotUsed) {
  const fs::path dir = scratch("foreign");
  kill_at(dir, "10", " --pulse-tail-fraction 0.5");
  const std::string log = rerun(dir);
  EXPECT_NE(log.find("not resuming from sw.checkpoint: it belongs to another run"), std::string::npos) << log;
  EXPECT_EQ(log.find("resuming from the checkpoint"), std::string::npos) << log;
  expect_same_as_reference(dir);
  std::ofstream(dir / "sw.checkpoint") << "not a checkpoint\n";
  const std::string log2 = rerun(dir);
  EXPECT_NE(log2.find("not resuming from sw.checkpoint: "), std::string::npos) << log2;
  expect_same_as_reference(dir);
}

// A finished run whose file changed after the checkpoint is simulated again
// (its results are not taken on trust).
TEST(ResumeShockwave, FinishedRunWithAChangedFileIsSimulatedAgain) {
  const fs::path dir = scratch("changed");
  kill_at(dir, "30");
  std::ofstream(dir / "sw_efd0.12.h5", std::ios::app) << "x";
  const std::string log = rerun(dir);
  EXPECT_NE(log.find("not taking efd0.12 from the checkpoint sw.checkpoint: sw_efd0.12.h5 is missing or changed since; "
                     "simulating it again"),
            std::string::npos)
      << log;
  EXPECT_EQ(log.find("resuming from the checkpoint"), std::string::npos) << log;
  expect_same_as_reference(dir);
}

// The comparison can fail: a checkpoint whose bonds' normal stresses are
// zeroed (as if that state array were left out) resumes into other fields,
// and the comparison above would report it.
TEST(ResumeShockwave, CheckpointMissingAStateArrayIsDetected) {
  const fs::path dir = scratch("sabotage");
  kill_at(dir, "12");
  std::string why;
  std::optional<arthrosim::pipelines::ShockwaveCheckpoint> c =
      arthrosim::pipelines::read_shockwave_checkpoint(dir / "sw.checkpoint", why);
  ASSERT_TRUE(c) << why;
  ASSERT_TRUE(c->current);
  bool found = false;
  for (auto& [name, array] : c->current->sim.arrays)
    if (name == "pair_normal_stress") {
      std::fill(array.begin(), array.end(), 0.0);
      found = true;
    }
  ASSERT_TRUE(found);
  arthrosim::pipelines::write_shockwave_checkpoint(dir / "sw.checkpoint", *c, 0);
  EXPECT_NE(rerun(dir).find("efd0.12, 12 of 25 steps done"), std::string::npos);
  std::set<std::string> wrong;
  for (const std::string& d : differences(reference() / "sw_efd0.12.h5", dir / "sw_efd0.12.h5"))
    if (!kWallTimes.count(d)) wrong.insert(d);
  EXPECT_TRUE(wrong.count("dataset: </fields/pressure>")) << "the sabotaged resume was not detected";
  // Run 2 is simulated from the start and is not affected.
  for (const std::string& d : differences(reference() / "sw_efd0.33.h5", dir / "sw_efd0.33.h5"))
    EXPECT_TRUE(kWallTimes.count(d)) << d;
}

// Under the runner: `arthrosim run` of a bar scene whose shockwave stage is
// killed in its second run fails; the plain rerun of the same `arthrosim run`
// (same command line, same stage key) keeps the first run, resumes the second
// and ends with the files of an uninterrupted `arthrosim run`.
TEST(ResumeShockwave, PlainRerunOfArthrosimRunResumesTheStage) {
  const fs::path root = scratch("runner");
  std::ofstream(root / "scene.yaml") << "model: " << ARTHROSIM_SOURCE_DIR << R"(/data/models/knee_parametric/coarse
outputs: [shockwave]
shockwave:
  effects: [mca_elastic, pore_fluid, filtration, applicator_pulse]
  geometry: bar
  bar_tissue: cartilage
  bar_length_mm: 10
  end_time_us: 10
  output_interval_us: 1
  efd_mj_per_mm2: [0.12, 0.33]
  checkpoint_interval_s: 0
)";
  // The same output folder for every run (the runner gives the stages
  // absolute paths, part of the files' metadata): the reference is moved aside.
  const std::string arthrosim = (kBin / "arthrosim").string() + " run " + (root / "scene.yaml").string() +
                                " --out " + (root / "out").string() + " --jobs 1";
  auto [status, log] = run(arthrosim);
  ASSERT_EQ(status, 0) << log;
  fs::rename(root / "out", root / "reference");
  std::tie(status, log) = run("ARTHROSIM_TEST_KILL_AT_CHECKPOINT=30 " + arthrosim);
  EXPECT_NE(status, 0) << log;
  ASSERT_TRUE(fs::exists(root / "out/shockwave.checkpoint")) << log;
  std::tie(status, log) = run(arthrosim);
  ASSERT_EQ(status, 0) << log;
  const std::string from = "resuming from the checkpoint " + (root / "out/shockwave.checkpoint").string() + ": ";
  EXPECT_NE(log.find(from + "efd0.12 finished before"), std::string::npos) << log;
  EXPECT_NE(log.find(from + "efd0.33, 5 of 25 steps done"), std::string::npos) << log;
  for (const char* r : {"shockwave_efd0.12.h5", "shockwave_efd0.33.h5"})
    for (const std::string& d : differences(root / "reference" / r, root / "out" / r))
      EXPECT_TRUE(kWallTimes.count(d)) << r << " differs from the uninterrupted run: " << d;
  EXPECT_EQ(summary_without_wall_times(root / "reference/shockwave_summary.json"),
            summary_without_wall_times(root / "out/shockwave_summary.json"));
  EXPECT_FALSE(fs::exists(root / "out/shockwave.checkpoint"));
}

}  // namespace
