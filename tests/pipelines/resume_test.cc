// Checkpoint and resume (issue 30; docs/testing.md, "Checkpoint and
// resume"): a stage killed with SIGKILL at any point and rerun with the same
// command continues from its last checkpoint, says so, and its final datasets
// are bit-identical to an uninterrupted run's (h5diff: 0 differences; the
// only dataset excepted is named where it is compared: wall times).
//
// The runs are the stage programs on the coarse bundled knee with a few
// frames or steps (COMAK about 1 s, the surface stage a few seconds, the
// biphasic stage 12 steps of the canonical two-layer case, about 1 s). Kill points: the kill tests' hook of
// common/checkpoint.h (deterministic: right after checkpoint n is in place,
// or after it was written and before its rename) and a SIGKILL from outside
// while a frame is being solved.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <set>
#include <tuple>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/test_support.h"
#include "common/checkpoint.h"
#include "common/hdf5.h"
#include "common/output_file.h"
#include "pipelines/biphasic_checkpoint.h"
#include "pipelines/surface_checkpoint.h"

namespace {

namespace fs = std::filesystem;

const fs::path kDir = fs::path(ARTHROSIM_BINARY_DIR) / "test_scratch" / "resume_test";
const fs::path kBin = fs::path(ARTHROSIM_BINARY_DIR) / "bin";
const fs::path kSource = fs::path(ARTHROSIM_SOURCE_DIR);

std::string slurp(const fs::path& p) { return arthrosim::test_support::read_text(p); }

// Runs a shell command; returns (exit status or 128 + signal, stdout + stderr).
std::pair<int, std::string> run(const std::string& command) { return arthrosim::test_support::run_shell(command); }

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

// One test case for the kill points (ctest runs each case in its own
// process; they share the reference run). Each: killed, rerun with the same
// command, which says where it resumes; datasets compared with the reference.
TEST(ResumeComak, KilledAtCheckpointsResumesBitIdentical) {
  struct Point {
    const char* kill_at;  // the hook's kill point (common/checkpoint.h)
    const char* resumes;  // what the rerun says
  };
  // 4 of 5: the last frame is never checkpointed (the output is finished
  // next); "2.partial": the second checkpoint was written but not renamed, so
  // the first one stands.
  for (const Point& p : {Point{"1", "1 of 5 frames done"}, Point{"2.partial", "1 of 5 frames done"},
                         Point{"4", "4 of 5 frames done"}}) {
    SCOPED_TRACE(p.kill_at);
    const fs::path dir = scratch(std::string("comak_at_") + p.kill_at);
    const std::string log = kill_and_resume(dir, p.kill_at);
    EXPECT_NE(log.find(std::string("resuming from the checkpoint k.h5.checkpoint: ") + p.resumes), std::string::npos)
        << log;
    expect_same_as_reference(dir);
  }
  // Killed twice: the first checkpoint of each process (frames 1, then 2).
  const fs::path dir = scratch("comak_twice");
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

// ---- the runner: a plain rerun of `arthrosim run` ------------------------------

// The comak stage under `arthrosim run`, killed after its second checkpoint
// (the hook's variable reaches the stage through the runner's environment):
// the run fails naming the stage; the same `arthrosim run` again resumes the
// stage (same command line, same stage key) and ends with the kinematics file
// of an uninterrupted `arthrosim run`.
TEST(ResumeRunner, PlainRerunOfArthrosimRunResumesTheKilledStage) {
  const fs::path root = scratch("runner");
  std::ofstream(root / "scene.yaml") << "model: " << (kSource / "data/models/knee_parametric/coarse").string()
                                     << "\ntrial: " << (kSource / "data/trials/synthetic_gait").string() << R"(
trial.start_s: 0.10
trial.end_s: 0.14
outputs: [kinematics]
prepare: {edge_length_mm: 6}
comak:
  effects: [ligaments, muscles, tibiofemoral_contact, patellofemoral_contact]
  checkpoint_interval_s: 0
)";
  // The same output folder for both runs (the runner gives the stages
  // absolute paths, part of the files' metadata): the reference is moved aside.
  const std::string arthrosim = (kBin / "arthrosim").string() + " run " + (root / "scene.yaml").string() +
                                " --out " + (root / "out").string() + " --jobs 1";
  auto [status, log] = run(arthrosim);
  ASSERT_EQ(status, 0) << log;
  fs::rename(root / "out", root / "reference");
  std::tie(status, log) = run("ARTHROSIM_TEST_KILL_AT_CHECKPOINT=2 " + arthrosim);
  EXPECT_NE(status, 0) << log;
  EXPECT_NE(log.find("comak"), std::string::npos) << log;
  ASSERT_TRUE(fs::exists(root / "out/kinematics.h5.checkpoint")) << log;
  std::tie(status, log) = run(arthrosim);
  ASSERT_EQ(status, 0) << log;
  EXPECT_NE(log.find("resuming from the checkpoint " + (root / "out/kinematics.h5.checkpoint").string() +
                     ": 2 of 5 frames done"),
            std::string::npos)
      << log;
  std::tie(status, log) = h5diff(root / "reference/kinematics.h5", root / "out/kinematics.h5", {"/solver/wall_time"});
  EXPECT_EQ(status, 0) << log;
  EXPECT_FALSE(fs::exists(root / "out/kinematics.h5.checkpoint"));
}

// ---- surface stage: per step --------------------------------------------------

// A short walking scenario: femur and medial tibial cartilage (prepared at
// 10 mm edges: 628 nodes) in mesh contact, driven by the COMAK reference
// run's kinematics (frames 10-14 of the synthetic trial) after a 10 ms
// seating: 5 HHT steps of 10 ms, a frame after each, a checkpoint after
// every step but the last (checkpoints 1-4).
const fs::path& surface_inputs() {
  static const fs::path dir = [] {
    const fs::path d = scratch("surface_inputs");
    const auto [status, printed] = run((kBin / "arthrosim-prepare").string() + " --model " +
                                       (kSource / "data/models/knee_parametric/coarse").string() +
                                       " --edge-length-mm 10 --out " + (d / "prepared.h5").string());
    EXPECT_EQ(status, 0) << printed;
    std::ofstream(d / "walk.yaml") << "model: " << (kSource / "data/models/knee_parametric/coarse").string()
                                   << "\ntrial: " << (kSource / "data/trials/synthetic_gait").string() << R"(
outputs: [surface]
comak: {effects: [ligaments, muscles, tibiofemoral_contact, patellofemoral_contact]}
surface:
  scenarios:
    walk:
      surfaces: [femur, tibia_medial]
      contact_pairs: ["femur:tibia_medial"]
      time_step_s: 1e-2
      output_interval_ms: 10
      seating_time_s: 0.01
      seating_offset_mm: 2.5
      newton_tolerance: 1e-5
      newton_residual_floor_n: 2
      newton_increment_floor_mm: 1e-2
      max_newton_iterations: 25
      foundation_from_thickness: true
      foundation_damping_n_s_per_mm3: 1e-3
      contact_stiffness_n_per_mm3: 300
      contact_max_depth_mm: 3
      contact_smoothing_mm: 0.02
      periphery_normal: foundation
      checkpoint_interval_s: 0
      effects: [foundation_springs, foundation_damping, periphery_fixed, imposed_kinematics, inertia, mesh_contact]
)";
    return d;
  }();
  return dir;
}

std::string surface_command() {
  const fs::path in = surface_inputs();
  return (kBin / "arthrosim-surface").string() + " --prepared " + (in / "prepared.h5").string() + " --kinematics " +
         (comak_reference() / "k.h5").string() + " --scene " + (in / "walk.yaml").string() + " --out s.h5";
}

const fs::path& surface_reference() {
  static const fs::path dir = [] {
    const fs::path d = scratch("surface_reference");
    const auto [status, printed] = run("cd " + d.string() + " && " + surface_command());
    EXPECT_EQ(status, 0) << printed;
    return d;
  }();
  return dir;
}

// Every dataset and attribute of the two surface outputs equal, except the
// step wall times (/solver/wall_s) and the timing attributes of /solver
// (and its symbolic_analyses count, below).
// `min_compared`: attributes of /solver compared at least (the contact
// scenarios have their penetration figures besides the solver's).
void expect_same_surface_output(const fs::path& a, const fs::path& b, int min_compared = 15) {
  auto [status, report] = h5diff(a, b, {"/solver"});
  EXPECT_EQ(status, 0) << report;
  const arthrosim::common::H5File fa(a.string(), arthrosim::common::H5File::Mode::kRead);
  const arthrosim::common::H5File fb(b.string(), arthrosim::common::H5File::Mode::kRead);
  ASSERT_EQ(fa.list("/solver"), fb.list("/solver"));
  for (const std::string& d : fa.list("/solver")) {
    if (d == "wall_s") continue;
    std::tie(status, report) = run("h5diff " + a.string() + " " + b.string() + " /solver/" + d);
    EXPECT_EQ(status, 0) << "/solver/" << d << ": " << report;
  }
  // Timing attributes, and symbolic_analyses: a resumed process analyses the
  // sparsity pattern once more (the pattern itself is restored exactly, and
  // the analysis depends on nothing else).
  const std::set<std::string> excepted = {"assembly_s", "contact_s",  "coupling_copy_s", "element_scatter_s",
                                          "elements_s", "factorization_s", "solve_s",   "surfaces_s",
                                          "total_s",    "wall_s",          "symbolic_analyses"};
  ASSERT_EQ(fa.attribute_names("/solver"), fb.attribute_names("/solver"));
  int compared = 0;
  for (const std::string& k : fa.attribute_names("/solver")) {
    if (excepted.count(k)) continue;
    ++compared;
    try {
      EXPECT_EQ(fa.attribute_string("/solver", k), fb.attribute_string("/solver", k)) << k;
    } catch (const std::exception&) {  // a number: compared bit for bit
      const double x = fa.attribute_double("/solver", k), y = fb.attribute_double("/solver", k);
      EXPECT_EQ(std::memcmp(&x, &y, sizeof x), 0) << k << ": " << x << " vs " << y;
    }
  }
  EXPECT_GE(compared, min_compared);  // steps, newton_iterations, factorizations, symbolic_analyses, penetration ...
}

std::string surface_kill_and_resume(const fs::path& dir, const std::string& kill_at) {
  const auto [killed, printed] =
      run("cd " + dir.string() + " && ARTHROSIM_TEST_KILL_AT_CHECKPOINT=" + kill_at + " exec " + surface_command());
  EXPECT_NE(killed, 0) << "not killed at checkpoint " << kill_at << ": " << printed;
  EXPECT_FALSE(fs::exists(dir / "s.h5"));
  EXPECT_TRUE(fs::exists(dir / "s.h5.checkpoint"));
  const auto [status, resumed] = run("cd " + dir.string() + " && " + surface_command());
  EXPECT_EQ(status, 0) << resumed;
  expect_same_surface_output(surface_reference() / "s.h5", dir / "s.h5");
  EXPECT_TRUE(slurp(surface_reference() / "s.xdmf") == slurp(dir / "s.xdmf"));
  EXPECT_FALSE(fs::exists(dir / "s.h5.checkpoint"));
  EXPECT_FALSE(fs::exists(dir / "s.h5.partial"));
  return resumed;
}

// The kill points in one test case (they share the reference runs): after
// the first step's checkpoint, while the third is written (the second stands),
// after the last (4 of 5 steps).
TEST(ResumeSurface, KilledAtCheckpointsResumesBitIdentical) {
  for (const auto& [kill_at, resumes] :
       std::vector<std::pair<std::string, std::string>>{{"1", "t = 0.010000 s, steps done: 1, frames written: 1"},
                                                        {"3.partial", "t = 0.020000 s, steps done: 2, frames written: 2"},
                                                        {"4", "t = 0.040000 s, steps done: 4, frames written: 4"}}) {
    SCOPED_TRACE(kill_at);
    const std::string log = surface_kill_and_resume(scratch("surface_at_" + kill_at), kill_at);
    EXPECT_NE(log.find("resuming from the checkpoint s.h5.checkpoint: " + resumes), std::string::npos) << log;
  }
}

// Modified Newton (newton_reuse_factorization) keeps a factorisation across
// steps; the checkpoint holds the matrix it factorised and the resumed run
// refactorises it. The scenario: the dynamic osmotic swelling of the coarse
// lateral tibial cartilage from rest (the bundled osmotic scenario's effects,
// as SurfaceStage.DynamicOsmoticStopsAtTheStaticSteadyState runs it), 6 HHT
// steps of 1 ms, a checkpoint after every step.
std::string swell_command() {
  const fs::path in = surface_inputs();
  static const bool written = [&] {
    std::ofstream(in / "swell.yaml") << "model: " << (kSource / "data/models/knee_parametric/coarse").string()
                                     << "\ntrial: " << (kSource / "data/trials/synthetic_gait").string() << R"(
outputs: [surface]
surface:
  scenarios:
    swell:
      surfaces: [tibia_lateral]
      end_time_s: 0.006
      time_step_s: 1e-3
      output_interval_ms: 1
      foundation_damping_n_s_per_mm3: 7e-3
      osmotic_ramp_s: 0.004
      newton_reuse_factorization: true
      checkpoint_interval_s: 0
      effects: [foundation_springs, foundation_damping, osmotic_pressure, periphery_fixed, inertia]
)";
    return true;
  }();
  (void)written;
  return (kBin / "arthrosim-surface").string() + " --prepared " + (in / "prepared.h5").string() + " --kinematics " +
         (comak_reference() / "k.h5").string() + " --scene " + (in / "swell.yaml").string() + " --out s.h5";
}

const fs::path& swell_reference() {
  static const fs::path dir = [] {
    const fs::path d = scratch("swell_reference");
    const auto [status, printed] = run("cd " + d.string() + " && " + swell_command());
    EXPECT_EQ(status, 0) << printed;
    return d;
  }();
  return dir;
}

// Killed at checkpoint `kill_at`: the checkpoint holds a kept factorisation.
void swell_kill(const fs::path& dir, const std::string& kill_at) {
  const auto [killed, printed] =
      run("cd " + dir.string() + " && ARTHROSIM_TEST_KILL_AT_CHECKPOINT=" + kill_at + " exec " + swell_command());
  EXPECT_NE(killed, 0) << "not killed at checkpoint " << kill_at << ": " << printed;
  std::string why;
  const auto c = arthrosim::pipelines::read_surface_checkpoint(dir / "s.h5.checkpoint", why);
  ASSERT_TRUE(c) << why;
  EXPECT_TRUE(c->hht.kept.valid) << "no kept factorisation at checkpoint " << kill_at;
  EXPECT_GT(c->hht.kept.matrix.nonZeros(), 0);
}

TEST(ResumeSurface, ModifiedNewtonResumesWithItsKeptFactorisationBitIdentical) {
  for (const std::string kill_at : {"2", "5"}) {
    SCOPED_TRACE(kill_at);
    const fs::path dir = scratch("swell_at_" + kill_at);
    swell_kill(dir, kill_at);
    const auto [status, log] = run("cd " + dir.string() + " && " + swell_command());
    EXPECT_EQ(status, 0) << log;
    EXPECT_NE(log.find("resuming from the checkpoint s.h5.checkpoint: t = 0.00" + kill_at), std::string::npos) << log;
    expect_same_surface_output(swell_reference() / "s.h5", dir / "s.h5", 11);
    EXPECT_FALSE(fs::exists(dir / "s.h5.checkpoint"));
  }
}

// The comparison can fail: the same checkpoint without its kept
// factorisation (the resumed run factorises a fresh tangent) ends in other
// coordinates.
TEST(ResumeSurface, ModifiedNewtonWithoutTheKeptFactorisationIsDetected) {
  const fs::path dir = scratch("swell_sabotage");
  swell_kill(dir, "2");
  std::string why;
  auto c = arthrosim::pipelines::read_surface_checkpoint(dir / "s.h5.checkpoint", why);
  ASSERT_TRUE(c) << why;
  c->hht.kept = arthrosim::numerics::KeptFactorization();
  arthrosim::pipelines::write_surface_checkpoint(dir / "s.h5.checkpoint", *c, 0);
  const auto [status, log] = run("cd " + dir.string() + " && " + swell_command());
  EXPECT_EQ(status, 0) << log;
  const auto [diff, report] = h5diff(swell_reference() / "s.h5", dir / "s.h5", {"/solver"});
  EXPECT_NE(diff, 0) << "the resume without the kept factorisation was not detected";
}

// The walking scenario with contact_augmentations (augmented Lagrangian,
// docs/contact.md) over its first three steps: per step it records its
// multiplier updates, and a step that stopped updating before the limit
// meets the tolerance (0.1 of the max deflection); the totals agree with the
// per-step records (Newton iterations include the discarded attempts'), and
// the penalty-only run of the same steps breaks the rule in the first step
// that was augmented. Killed after step 2, the run resumes with its
// multipliers (the checkpoint holds them, now and per frame written) and
// ends bit-identical; the same checkpoint with the multipliers dropped
// resumes into another result (the comparison can fail).
TEST(ResumeSurface, AugmentedContactRecordsItsUpdatesAndResumesBitIdentical) {
  const fs::path dir = scratch("surface_augmented");
  std::ifstream in(surface_inputs() / "walk.yaml");
  std::stringstream scene;
  scene << in.rdbuf() << "      end_time_s: 0.03\n";
  std::ofstream(dir / "penalty.yaml") << scene.str();
  std::ofstream(dir / "augmented.yaml") << scene.str()
                                        << "      contact_augmentations: 2\n      contact_augment_tolerance: 0.1\n";
  const std::string surface = (kBin / "arthrosim-surface").string() + " --prepared " +
                              (surface_inputs() / "prepared.h5").string() + " --kinematics " +
                              (comak_reference() / "k.h5").string() + " --quiet";
  auto [status, log] = run("cd " + dir.string() + " && " + surface + " --scene augmented.yaml --out a.h5");
  ASSERT_EQ(status, 0) << log;
  EXPECT_FALSE(fs::exists(dir / "a.h5.checkpoint"));  // removed once the output is complete
  for (const std::string kill_at : {"2", "2 sabotaged"}) {
    SCOPED_TRACE(kill_at);
    const bool sabotage = kill_at.size() > 1;
    const fs::path d = scratch("surface_augmented_at_" + std::string(sabotage ? "2_sabotaged" : kill_at));
    fs::copy_file(dir / "augmented.yaml", d / "augmented.yaml");
    const std::string cmd = "cd " + d.string() + " && " + surface + " --scene augmented.yaml --out a.h5";
    const auto [killed, printed] =
        run("cd " + d.string() + " && ARTHROSIM_TEST_KILL_AT_CHECKPOINT=" + kill_at.substr(0, 1) + " exec " +
            surface + " --scene augmented.yaml --out a.h5");
    EXPECT_NE(killed, 0) << printed;
    std::string why;
    auto c = arthrosim::pipelines::read_surface_checkpoint(d / "a.h5.checkpoint", why);
    ASSERT_TRUE(c) << why;
    ASSERT_EQ(c->multipliers.size(), 1u);  // one contact pair
    ASSERT_EQ(c->frame_multipliers.size(), c->frame_times.size());
    EXPECT_GT(c->total_augmentations, 0);
    EXPECT_GT(c->multipliers[0][0].size() + c->multipliers[0][1].size(), 0) << "no multipliers at checkpoint 2";
    if (sabotage) {
      c->multipliers[0] = {Eigen::VectorXd(), Eigen::VectorXd()};
      arthrosim::pipelines::write_surface_checkpoint(d / "a.h5.checkpoint", *c, 0);
    }
    const auto [resumed, rlog] = run(cmd);
    EXPECT_EQ(resumed, 0) << rlog;
    if (sabotage) {
      EXPECT_NE(h5diff(dir / "a.h5", d / "a.h5", {"/solver"}).first, 0) << "the resume without multipliers was not detected";
    } else {
      expect_same_surface_output(dir / "a.h5", d / "a.h5");
    }
  }
  std::tie(status, log) = run("cd " + dir.string() + " && " + surface + " --scene penalty.yaml --out p.h5");
  ASSERT_EQ(status, 0) << log;
  const arthrosim::common::H5File a((dir / "a.h5").string(), arthrosim::common::H5File::Mode::kRead);
  const arthrosim::common::H5File p((dir / "p.h5").string(), arthrosim::common::H5File::Mode::kRead);
  const Eigen::VectorXi updates = a.read_vector_int("/solver/contact_augmentations");
  const Eigen::VectorXd ratio = a.read_vector("/solver/penetration_ratio");
  const Eigen::VectorXd ratio_penalty = p.read_vector("/solver/penetration_ratio");
  const Eigen::VectorXi newton = a.read_vector_int("/solver/newton_iterations");
  EXPECT_FALSE(p.exists("/solver/contact_augmentations"));
  ASSERT_EQ(updates.size(), ratio.size());
  ASSERT_EQ(ratio_penalty.size(), ratio.size());
  int first_augmented = -1;
  for (Eigen::Index k = 0; k < updates.size(); ++k) {
    if (updates(k) > 0 && first_augmented < 0) first_augmented = static_cast<int>(k);
    if (updates(k) < 2) {
      EXPECT_LE(ratio(k), 0.1) << "step " << k;
    }
  }
  ASSERT_GE(first_augmented, 0) << "no step was augmented";
  EXPECT_GT(ratio_penalty(first_augmented), 0.1);
  EXPECT_EQ(a.attribute_int("/solver", "contact_augmentations"), static_cast<std::int64_t>(updates.sum()));
  EXPECT_EQ(a.attribute_int("/solver", "newton_iterations"), static_cast<std::int64_t>(newton.sum()));
  EXPECT_GT(a.attribute_int("/solver", "augmentation_newton_iterations"), 0);
}

// ---- biphasic: per step ------------------------------------------------------

// The canonical two-layer case (arthrosim-biphasic --canonical), one element
// layer, 12 steps of 10 ms, a checkpoint after every step. Between two uninterrupted runs the
// output differs only in the layers' wall-time attributes.
const fs::path& biphasic_case() {
  static const fs::path dir = [] {
    const fs::path d = scratch("biphasic_case");
    const auto [status, printed] =
        run("cd " + d.string() + " && " + (kBin / "arthrosim-biphasic").string() + " --canonical . --out c.h5 --quiet");
    EXPECT_EQ(status, 0) << printed;
    return d;
  }();
  return dir;
}

std::string biphasic_command() {
  const fs::path c = biphasic_case();
  return (kBin / "arthrosim-biphasic").string() + " --prepared " + (c / "two_layers_prepared.h5").string() +
         " --kinematics " + (c / "two_layers_kinematics.h5").string() +
         " --layers femur,tibia_medial --end-time-s 0.12 --element-layers 1 --checkpoint-interval-s 0 --out b.h5";
}

const fs::path& biphasic_reference() {
  static const fs::path dir = [] {
    const fs::path d = scratch("biphasic_reference");
    const auto [status, printed] = run("cd " + d.string() + " && " + biphasic_command());
    EXPECT_EQ(status, 0) << printed;
    return d;
  }();
  return dir;
}

// The objects (datasets or attributes) in which the output in `dir` differs
// from the reference's.
std::set<std::string> biphasic_differences(const fs::path& dir) {
  return arthrosim::test_support::h5diff_differences(biphasic_reference() / "b.h5", dir / "b.h5");
}

// Wall times of the run: the only attributes allowed to differ.
const std::set<std::string> kBiphasicWallTimes = [] {
  std::set<std::string> s;
  for (const char* layer : {"femur", "tibia_medial"})
    for (const char* a : {"factorization_s", "solve_s", "step_s"})
      s.insert(std::string("attribute: <") + a + " of </layers/" + layer + ">>");
  return s;
}();

void expect_biphasic_same_as_reference(const fs::path& dir) {
  for (const std::string& d : biphasic_differences(dir))
    EXPECT_TRUE(kBiphasicWallTimes.count(d)) << "differs from the uninterrupted run: " << d;
  EXPECT_TRUE(slurp(biphasic_reference() / "b.xdmf") == slurp(dir / "b.xdmf"));
  EXPECT_FALSE(fs::exists(dir / "b.h5.checkpoint"));
  EXPECT_FALSE(fs::exists(dir / "b.h5.partial"));
}

std::string biphasic_kill(const fs::path& dir, const std::string& kill_at) {
  const auto [killed, printed] =
      run("cd " + dir.string() + " && ARTHROSIM_TEST_KILL_AT_CHECKPOINT=" + kill_at + " exec " + biphasic_command());
  EXPECT_NE(killed, 0) << "not killed at checkpoint " << kill_at << ": " << printed;
  EXPECT_FALSE(fs::exists(dir / "b.h5"));
  EXPECT_TRUE(fs::exists(dir / "b.h5.checkpoint"));
  return printed;
}

std::string biphasic_rerun(const fs::path& dir) {
  const auto [status, resumed] = run("cd " + dir.string() + " && " + biphasic_command());
  EXPECT_EQ(status, 0) << resumed;
  return resumed;
}

// Killed after the first step, mid-run, before a checkpoint's rename, and
// twice in a row; each rerun of the same command resumes and matches the
// uninterrupted run.
TEST(ResumeBiphasic, KilledAtCheckpointsResumesBitIdentical) {
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"1"}, "1 of 12 steps done"},
      {{"7"}, "7 of 12 steps done"},
      {{"4.partial"}, "3 of 12 steps done"},
      {{"3", "2"}, "5 of 12 steps done"},  // the second process resumed at 3 and did 2 more
  };
  for (const auto& [kills, resumes] : cases) {
    SCOPED_TRACE(kills.front());
    const fs::path dir = scratch("biphasic_at_" + kills.front() + "_" + std::to_string(kills.size()));
    for (const std::string& k : kills) biphasic_kill(dir, k);
    const std::string log = biphasic_rerun(dir);
    EXPECT_NE(log.find("resuming from the checkpoint b.h5.checkpoint: " + resumes), std::string::npos) << log;
    expect_biphasic_same_as_reference(dir);
  }
}

// The comparison can fail: a checkpoint without the solid velocity (v
// zeroed, as if the state array were left out) resumes into a different
// result, and the test above would report it.
TEST(ResumeBiphasic, CheckpointMissingAStateArrayIsDetected) {
  const fs::path dir = scratch("biphasic_sabotage");
  biphasic_kill(dir, "5");
  std::string why;
  std::optional<arthrosim::pipelines::BiphasicCheckpoint> c =
      arthrosim::pipelines::read_biphasic_checkpoint(dir / "b.h5.checkpoint", why);
  ASSERT_TRUE(c) << why;
  c->layers[0].v.setZero();
  arthrosim::pipelines::write_biphasic_checkpoint(dir / "b.h5.checkpoint", *c, 0);
  EXPECT_NE(biphasic_rerun(dir).find("5 of 12 steps done"), std::string::npos);
  std::set<std::string> wrong;
  for (const std::string& d : biphasic_differences(dir))
    if (!kBiphasicWallTimes.count(d)) wrong.insert(d);
  EXPECT_TRUE(wrong.count("dataset: </layers/femur/displacement>")) << "the sabotaged resume was not detected";
}

// A checkpoint of another run (other options) is not used: warned about,
// removed, the run starts over and still matches.
TEST(ResumeBiphasic, CheckpointOfAnotherRunIsNotUsed) {
  const fs::path dir = scratch("biphasic_foreign");
  const auto [killed, p1] = run("cd " + dir.string() + " && ARTHROSIM_TEST_KILL_AT_CHECKPOINT=3 exec " +
                                biphasic_command() + " --omega 1");
  EXPECT_NE(killed, 0) << p1;
  const std::string log = biphasic_rerun(dir);
  EXPECT_NE(log.find("not resuming from b.h5.checkpoint: it belongs to another run"), std::string::npos) << log;
  EXPECT_EQ(log.find("resuming from the checkpoint"), std::string::npos) << log;
  expect_biphasic_same_as_reference(dir);
}

}  // namespace
