// Checkpoint and resume (issue 30; docs/testing.md, "Checkpoint and
// resume"): a stage killed with SIGKILL at any point and rerun with the same
// command continues from its last checkpoint, says so, and its final datasets
// are bit-identical to an uninterrupted run's (h5diff: 0 differences; the
// only dataset excepted is named where it is compared: wall times).
//
// The runs are the stage programs on the coarse bundled knee with a few
// frames (about a second each). Kill points: the kill tests' hook of
// common/checkpoint.h (deterministic: right after checkpoint n is in place,
// or after it was written and before its rename) and a SIGKILL from outside
// while a frame is being solved.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>

#include "common/checkpoint.h"
#include "common/hdf5.h"
#include "common/output_file.h"

namespace {

namespace fs = std::filesystem;

const fs::path kDir = fs::path(ARTHROSIM_BINARY_DIR) / "test_scratch" / "resume_test";
const fs::path kBin = fs::path(ARTHROSIM_BINARY_DIR) / "bin";
const fs::path kSource = fs::path(ARTHROSIM_SOURCE_DIR);

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Runs a shell command; returns (exit status or 128 + signal, stdout + stderr).
std::pair<int, std::string> run(const std::string& command) {
  std::string out;
  FILE* p = ::popen((command + " 2>&1").c_str(), "r");
  char buf[4096];
  while (p && std::fgets(buf, sizeof buf, p)) out += buf;
  const int status = p ? ::pclose(p) : -1;
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

fs::path scratch(const std::string& name) {
  const fs::path d = kDir / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

bool wait_until(const std::function<bool()>& f, double seconds) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    if (f()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return f();
}

// h5diff of two files: every dataset and attribute compared exactly, except
// the datasets named in `except`. Returns h5diff's exit status (0: no
// difference) and its report.
std::pair<int, std::string> h5diff(const fs::path& a, const fs::path& b, const std::vector<std::string>& except) {
  std::string cmd = "h5diff";
  for (const std::string& e : except) cmd += " --exclude-path " + e;
  return run(cmd + " -r " + a.string() + " " + b.string());
}

// ---- COMAK: per frame --------------------------------------------------------

// Five frames of the synthetic trial on the coarse knee, a checkpoint after
// every frame. Relative --out in the run's own folder: the command line (an
// attribute of the file) is the same in every folder. A resumed run must be
// the same command (the checkpoint's identity includes it), so no --quiet:
// the "resuming" line is an info message.
const std::string kComak = (kBin / "arthrosim-comak").string() + " --model " +
                           (kSource / "data/models/knee_parametric/coarse").string() + " --trial " +
                           (kSource / "data/trials/synthetic_gait").string() +
                           " --first-frame 10 --last-frame 14 --checkpoint-interval-s 0 --out k.h5";

// The COMAK outputs a resumed run must reproduce byte for byte besides the
// kinematics file: the OpenSim exports and the XDMF sidecar.
const char* kComakSidecars[] = {"k_activations.sto", "k_coordinates.sto", "k_contact_forces.sto", "k.xdmf"};

const fs::path& comak_reference() {
  static const fs::path dir = [] {
    const fs::path d = scratch("comak_reference");
    const auto [status, printed] = run("cd " + d.string() + " && " + kComak);
    EXPECT_EQ(status, 0) << printed;
    return d;
  }();
  return dir;
}

void expect_same_as_reference(const fs::path& dir) {
  const fs::path ref = comak_reference();
  // Wall times are the only datasets that differ between two runs.
  const auto [status, report] = h5diff(ref / "k.h5", dir / "k.h5", {"/solver/wall_time"});
  EXPECT_EQ(status, 0) << report;
  for (const char* f : kComakSidecars) EXPECT_TRUE(slurp(ref / f) == slurp(dir / f)) << f << " differs";
  EXPECT_FALSE(fs::exists(dir / "k.h5.checkpoint"));  // removed once the output is complete
  EXPECT_FALSE(fs::exists(dir / "k.h5.partial"));
}

// Kill at the hook's point, then rerun the same command: it resumes.
std::string kill_and_resume(const fs::path& dir, const std::string& kill_at) {
  const auto [killed, printed] = run("cd " + dir.string() + " && ARTHROSIM_TEST_KILL_AT_CHECKPOINT=" + kill_at +
                                     " exec " + kComak);
  EXPECT_NE(killed, 0) << "not killed at checkpoint " << kill_at << ": " << printed;
  EXPECT_FALSE(fs::exists(dir / "k.h5"));
  EXPECT_TRUE(fs::exists(dir / "k.h5.checkpoint"));
  const auto [status, resumed] = run("cd " + dir.string() + " && " + kComak);
  EXPECT_EQ(status, 0) << resumed;
  return resumed;
}

TEST(ResumeComak, KilledAfterTheFirstFrameResumesBitIdentical) {
  const fs::path dir = scratch("comak_after_1");
  const std::string log = kill_and_resume(dir, "1");
  EXPECT_NE(log.find("resuming from the checkpoint k.h5.checkpoint: 1 of 5 frames done"), std::string::npos) << log;
  expect_same_as_reference(dir);
}

TEST(ResumeComak, KilledDuringTheSecondCheckpointResumesFromTheFirst) {
  // The second checkpoint was written but not renamed: the first one stands.
  const fs::path dir = scratch("comak_during_2");
  const std::string log = kill_and_resume(dir, "2.partial");
  EXPECT_NE(log.find("resuming from the checkpoint k.h5.checkpoint: 1 of 5 frames done"), std::string::npos) << log;
  expect_same_as_reference(dir);
}

TEST(ResumeComak, KilledAfterTheLastCheckpointResumesBitIdentical) {
  // 4 of 5: the last frame is never checkpointed (the output is finished next).
  const fs::path dir = scratch("comak_after_4");
  const std::string log = kill_and_resume(dir, "4");
  EXPECT_NE(log.find("resuming from the checkpoint k.h5.checkpoint: 4 of 5 frames done"), std::string::npos) << log;
  expect_same_as_reference(dir);
}

TEST(ResumeComak, KilledTwiceResumesTheResumedRun) {
  const fs::path dir = scratch("comak_twice");
  // The first checkpoint of each process: frames 1, then 2 (the resumed run's first).
  const auto [first, p1] = run("cd " + dir.string() + " && ARTHROSIM_TEST_KILL_AT_CHECKPOINT=1 exec " + kComak);
  EXPECT_NE(first, 0) << p1;
  const std::string log = kill_and_resume(dir, "1");
  EXPECT_NE(log.find("resuming from the checkpoint k.h5.checkpoint: 2 of 5 frames done"), std::string::npos) << log;
  expect_same_as_reference(dir);
}

TEST(ResumeComak, SigkillWhileSolvingAFrameResumesBitIdentical) {
  const fs::path dir = scratch("comak_sigkill");
  const pid_t child = ::fork();
  if (child == 0) {
    ::execl("/bin/sh", "sh", "-c", ("cd " + dir.string() + " && exec " + kComak).c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  // Killed as soon as the checkpoint of 2 frames is in place: inside frame 3.
  const fs::path checkpoint = dir / "k.h5.checkpoint";
  const bool seen = wait_until(
      [&] {
        if (!fs::exists(checkpoint)) return false;
        try {
          const arthrosim::common::H5File f(checkpoint.string(), arthrosim::common::H5File::Mode::kRead);
          return f.attribute_int("/", "frames_done") >= 2;
        } catch (const std::exception&) {
          return false;
        }
      },
      60);
  ::kill(child, SIGKILL);
  int st = 0;
  ::waitpid(child, &st, 0);
  ASSERT_TRUE(seen);
  ASSERT_TRUE(WIFSIGNALED(st)) << "the run finished before it was killed";
  const auto [status, log] = run("cd " + dir.string() + " && " + kComak);
  ASSERT_EQ(status, 0) << log;
  EXPECT_NE(log.find("resuming from the checkpoint k.h5.checkpoint: "), std::string::npos) << log;
  expect_same_as_reference(dir);
}

TEST(ResumeComak, CheckpointOfAnotherRunIsNotUsed) {
  const fs::path dir = scratch("comak_other");
  const auto [killed, p1] = run("cd " + dir.string() + " && ARTHROSIM_TEST_KILL_AT_CHECKPOINT=2 exec " + kComak);
  EXPECT_NE(killed, 0) << p1;
  ASSERT_TRUE(fs::exists(dir / "k.h5.checkpoint"));
  // Another option: the checkpoint is discarded, never used.
  const auto [status, log] = run("cd " + dir.string() + " && " + kComak + " --activation-min 0.02");
  EXPECT_EQ(status, 0) << log;
  EXPECT_NE(log.find("not resuming from k.h5.checkpoint: it belongs to another run (inputs, options, command line "
                     "or build differ); starting over"),
            std::string::npos)
      << log;
  EXPECT_EQ(log.find("resuming from the checkpoint"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(dir / "k.h5.checkpoint"));
  // An unreadable checkpoint (not HDF5) is discarded too.
  std::ofstream(dir / "k.h5.checkpoint") << "not a checkpoint\n";
  const auto [status2, log2] = run("cd " + dir.string() + " && " + kComak);
  EXPECT_EQ(status2, 0) << log2;
  EXPECT_NE(log2.find("not resuming from k.h5.checkpoint: "), std::string::npos) << log2;
  expect_same_as_reference(dir);
}

}  // namespace
