// Issue 30 ("nothing stale, nothing lost, nothing hangs"): one test per
// numbered failure this branch fixes, each failing before its fix.
//   3. consumers took incomplete inputs: a kinematics file of a killed COMAK
//      run, a surface output of a killed run (status running)
//   5. versions were never checked (format_version 99, another schema)
//   2. a rerun truncated the complete surface output at its start
//   3. a killed runner orphaned its stage (it kept writing outside the
//      lock); SIGTERM was not passed on; the lock named no holder
//   6. --set injected YAML with a line break; an output path equal to an
//      input overwrote it
// Plus the helpers behind them (common/output_file.h, common/file_check.h).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <string>

#include "tests/test_support.h"
#include "common/effects.h"
#include "common/error.h"
#include "common/hashing.h"
#include "common/file_check.h"
#include "common/hdf5.h"
#include "common/metadata.h"
#include "common/output_file.h"
#include "common/scene_edit.h"
#include "musculoskeletal/kinematics_file.h"
#include "musculoskeletal/model.h"
#include "musculoskeletal/model_io.h"
#include "pipelines/biphasic_stage.h"
#include "pipelines/post_stage.h"
#include "pipelines/prepare.h"
#include "pipelines/runner.h"
#include "pipelines/shockwave_stage.h"
#include "pipelines/stages.h"
#include "pipelines/study.h"
#include "pipelines/surface_stage.h"

namespace arthrosim::pipelines {
namespace {

namespace fs = std::filesystem;

const fs::path kDir = fs::path(ARTHROSIM_BINARY_DIR) / "test_scratch" / "safety_test";
const fs::path kBin = fs::path(ARTHROSIM_BINARY_DIR) / "bin";
const fs::path kCoarse = fs::path(ARTHROSIM_SOURCE_DIR) / "data/models/knee_parametric/coarse";

template <typename F>
std::string error_of(F f) {
  try {
    f();
  } catch (const common::InputError& e) {
    return e.what();
  }
  return "";
}

std::string slurp(const fs::path& p) { return arthrosim::test_support::read_text(p); }

// Runs a shell command; returns (exit status, stdout + stderr).
std::pair<int, std::string> run(const std::string& command) { return arthrosim::test_support::run_shell(command); }

fs::path scratch(const std::string& name) {
  const fs::path d = kDir / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

// The prepared coarse bundled knee (prepare takes well under a second).
const fs::path& coarse_prepared() {
  static const fs::path path = [] {
    const fs::path p = scratch("prepared") / "prepared_coarse.h5";
    PrepareOptions o;
    const PreparedModel m = prepare_model(find_model_files(kCoarse.string()), o);
    common::RunMetadata md;
    md.program = "safety_test";
    write_prepared_model(m, o, md, p.string());
    return p;
  }();
  return path;
}

// ---- 6. --set values: one scalar on one line ------------------------------

TEST(SafetySet, ValueWithALineBreakListOrMapIsRefused) {
  const fs::path dir = scratch("set");
  const fs::path scene = dir / "plate.yaml";
  fs::copy_file(fs::path(ARTHROSIM_SOURCE_DIR) / "data/scenes/cantilever_plate.yaml", scene);
  fs::copy_file(fs::path(ARTHROSIM_SOURCE_DIR) / "data/scenes/cantilever_plate.obj", dir / "cantilever_plate.obj");
  std::string text = slurp(scene);
  const std::string model = "model: ../models/knee_parametric/coarse";
  text.replace(text.find(model), model.size(), "model: " + kCoarse.string());
  std::ofstream(scene) << text;
  const std::string key = "surface.scenarios.cantilever.youngs_modulus_mpa";
  // Before: the line break ended the header comment and "outputs: []" became
  // a key of the written scene.
  std::string msg = error_of([&] { common::edit_scene_text(scene, scene_schema(), {{key, "400\noutputs: []"}}); });
  EXPECT_NE(msg.find("the value of '" + key + "' must be a single scalar on one line"), std::string::npos) << msg;
  EXPECT_NE(msg.find("found a line break"), std::string::npos) << msg;
  msg = error_of([&] { common::edit_scene_text(scene, scene_schema(), {{key, "[400, 500]"}}); });
  EXPECT_NE(msg.find("found the list '[400, 500]'"), std::string::npos) << msg;
  msg = error_of([&] { common::edit_scene_text(scene, scene_schema(), {{"description", "a: b"}}); });
  EXPECT_NE(msg.find("found the map 'a: b'"), std::string::npos) << msg;
  msg = error_of([&] { common::edit_scene_text(scene, scene_schema(), {{"description", std::string("a\x1b[2Jb")}}); });
  EXPECT_NE(msg.find("found the control character 27"), std::string::npos) << msg;
  // A single scalar still works, including text with ':' and '#'.
  const std::string ok = common::edit_scene_text(scene, scene_schema(), {{key, "4e2"}, {"description", "C:/x #1"}});
  const common::Scene copy = parse_scene(ok, dir / "copy.yaml");
  EXPECT_EQ(copy.top.text("description"), "C:/x #1");
}

// ---- 6. an output never replaces an input ----------------------------------

TEST(SafetyOutput, SameFileSeesThroughDotDotSymlinksAndHardLinks) {
  const fs::path dir = scratch("same_file");
  std::ofstream(dir / "a.h5") << "x";
  fs::create_directories(dir / "sub");
  fs::create_symlink(dir / "a.h5", dir / "link.h5");
  fs::create_hard_link(dir / "a.h5", dir / "hard.h5");
  EXPECT_TRUE(common::same_file(dir / "a.h5", dir / "sub" / ".." / "a.h5"));
  EXPECT_TRUE(common::same_file(dir / "link.h5", dir / "a.h5"));
  EXPECT_TRUE(common::same_file(dir / "hard.h5", dir / "a.h5"));
  EXPECT_FALSE(common::same_file(dir / "b.h5", dir / "a.h5"));
  EXPECT_TRUE(common::same_file(dir / "sub" / ".." / "new.h5", dir / "new.h5"));  // neither exists
  const std::string msg = error_of([&] {
    common::refuse_output_over_inputs("prog", "--out", dir / "link.h5", {{"", "--none"}, {dir / "a.h5", "--prepared"}});
  });
  EXPECT_NE(msg.find("prog: error: --out " + (dir / "link.h5").string() + " is the input " + (dir / "a.h5").string() +
                     " (--prepared)"),
            std::string::npos)
      << msg;
}

// Before: exit 0 and the input STL replaced by an HDF5 file.
TEST(SafetyOutput, PrepareRefusesToWriteOntoAnInputMesh) {
  const fs::path dir = scratch("prepare_onto_input");
  fs::copy(kCoarse, dir / "model", fs::copy_options::recursive);
  fs::path cartilage;
  for (const auto& e : fs::directory_iterator(dir / "model"))
    if (e.path().filename().string().find("cartilage") != std::string::npos) cartilage = e.path();
  ASSERT_FALSE(cartilage.empty());
  const std::string before = slurp(cartilage);
  const auto [status, out] = run((kBin / "arthrosim-prepare").string() + " --model " + (dir / "model").string() +
                                 " --out " + (dir / "model" / "." / cartilage.filename()).string());
  EXPECT_EQ(status, 1) << out;
  EXPECT_NE(out.find("is the input " + cartilage.string()), std::string::npos) << out;
  EXPECT_EQ(slurp(cartilage), before);
}

// Before: exit 0 and the prepared model replaced by the kinematics file.
TEST(SafetyOutput, ComakRefusesToWriteOntoItsPreparedModel) {
  const fs::path dir = scratch("comak_onto_prepared");
  fs::copy_file(coarse_prepared(), dir / "prepared.h5");
  const std::string before = slurp(dir / "prepared.h5");
  const auto [status, out] =
      run((kBin / "arthrosim-comak").string() + " --model " + kCoarse.string() + " --prepared " +
          (dir / "prepared.h5").string() + " --trial " + ARTHROSIM_SOURCE_DIR +
          "/data/trials/synthetic_gait --first-frame 0 --last-frame 0 --out " + (dir / "prepared.h5").string());
  EXPECT_EQ(status, 1) << out;
  EXPECT_NE(out.find("--out " + (dir / "prepared.h5").string() + " is the input"), std::string::npos) << out;
  EXPECT_NE(out.find("(--prepared)"), std::string::npos) << out;
  EXPECT_EQ(slurp(dir / "prepared.h5"), before);
}

// ---- 5. versions are checked -----------------------------------------------

void write_kinematics_header(common::H5File& f, int version) {
  f.set_attribute("/", "format", "arthrosim kinematics file");
  f.set_attribute("/", "format_version", version);
}

TEST(SafetyVersions, KinematicsFormatVersionAndPreparedSchemaAreChecked) {
  const fs::path dir = scratch("versions");
  {
    common::H5File f((dir / "k99.h5").string(), common::H5File::Mode::kTruncate);
    write_kinematics_header(f, 99);
    f.set_attribute("/", "frames", 1);
    f.write("/time", std::vector<double>{0.0});
  }
  // Before: read as if current. The surface stage reads the kinematics first.
  SurfaceStageOptions o;
  o.kinematics = (dir / "k99.h5").string();
  o.prepared = coarse_prepared().string();
  o.scene = (fs::path(ARTHROSIM_SOURCE_DIR) / "data/scenes/gait.yaml").string();
  o.out = (dir / "surface.h5").string();
  o.progress = false;
  std::string msg = error_of([&] { run_surface_stage(o); });
  EXPECT_NE(msg.find(o.kinematics + ": error: a kinematics file of format_version 99; this build reads version 1"),
            std::string::npos)
      << msg;
  EXPECT_FALSE(fs::exists(o.out));

  // A prepared model of another schema, as COMAK and the surface stage read it.
  fs::copy_file(coarse_prepared(), dir / "p2.h5");
  {
    common::H5File f((dir / "p2.h5").string(), common::H5File::Mode::kReadWrite);
    f.set_attribute("/", "schema", "arthrosim prepared model 2");
  }
  msg = error_of([&] {
    musculoskeletal::Model model = musculoskeletal::load_model((kCoarse.parent_path() / "knee_coarse.urdf").string());
    musculoskeletal::use_prepared_surfaces(model, (dir / "p2.h5").string());
  });
  EXPECT_NE(msg.find("p2.h5: error: a prepared model of another version: found schema 'arthrosim prepared model 2', "
                     "this build reads 'arthrosim prepared model 1'"),
            std::string::npos)
      << msg;
  // Another kind of file altogether.
  msg = error_of([&] {
    const common::H5File f((dir / "k99.h5").string(), common::H5File::Mode::kRead);
    common::require_file_format(f, "k99.h5", common::StageFile::kPreparedModel);
  });
  EXPECT_NE(msg.find("k99.h5: error: expected a prepared model (root attribute schema = 'arthrosim prepared model 1'), "
                     "found no attribute 'schema'"),
            std::string::npos)
      << msg;
}

// ---- 3. consumers refuse incomplete inputs -----------------------------------

// A kinematics file as a COMAK run killed after `written` of `expected`
// frames leaves it: no run summary (`frames`), the bones at rest.
void write_killed_kinematics(const fs::path& file, int written, int expected) {
  common::H5File k(file.string(), common::H5File::Mode::kTruncate);
  write_kinematics_header(k, 1);
  k.set_attribute("/", "frames_expected", expected);
  std::vector<double> t, X;
  for (int f = 0; f < written; ++f) {
    t.push_back(0.2 + 5e-4 * f);
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) X.push_back(i == j ? 1.0 : 0.0);
  }
  k.write("/time", t);
  k.write_tensor3("/bodies/tibia/X_W", {written, 4, 4}, X);
  k.write_tensor3("/bodies/femur/X_W", {written, 4, 4}, X);
}

std::string moving_scene(const fs::path& dir) {
  const fs::path p = dir / "moving.yaml";
  std::ofstream(p) << "model: " << kCoarse.string() << "\noutputs: [surface]\ntrial: " << ARTHROSIM_SOURCE_DIR
                   << "/data/trials/synthetic_gait\ncomak: {effects: [ligaments]}\n"
                   << R"(surface:
  scenarios:
    moving:
      surfaces: [femur]
      time_step_s: 2.5e-4
      output_interval_ms: 0.5
      seating_time_s: 0
      effects: [foundation_springs, periphery_fixed, imposed_kinematics]
)";
  return p.string();
}

TEST(SafetyPartial, SurfaceStageAndPostRefuseKilledRunsUnlessAllowed) {
  const fs::path dir = scratch("partial");
  write_killed_kinematics(dir / "killed.h5", 3, 21);
  SurfaceStageOptions o;
  o.kinematics = (dir / "killed.h5").string();
  o.prepared = coarse_prepared().string();
  o.scene = moving_scene(dir);
  o.out = (dir / "surface_moving.h5").string();
  o.progress = false;
  o.argv = {"safety_test"};
  // Before: the 3 frames were simulated as if they were the whole walk.
  std::string msg = error_of([&] { run_surface_stage(o); });
  EXPECT_NE(msg.find(o.kinematics + ": error: incomplete kinematics file: it holds 3 frames and no run summary (the "
                                    "run that wrote it did not finish: killed or crashed); rerun the stage that writes "
                                    "it, or pass --allow-partial"),
            std::string::npos)
      << msg;
  EXPECT_FALSE(fs::exists(o.out));

  o.allow_partial = true;
  const SurfaceStageResult r = run_surface_stage(o);
  ASSERT_EQ(r.status, SurfaceStageStatus::kCompleted);
  {
    const common::H5File f(o.out, common::H5File::Mode::kRead);
    ASSERT_TRUE(f.has_attribute("/", "partial_input"));
    EXPECT_NE(f.attribute_string("/", "partial_input").find("PARTIAL INPUT: " + o.kinematics), std::string::npos);
  }

  // A surface output of a killed run: status "running".
  fs::copy_file(o.out, dir / "surface_killed.h5");
  {
    common::H5File f((dir / "surface_killed.h5").string(), common::H5File::Mode::kReadWrite);
    f.set_attribute("/", "status", "running");
  }
  PostInputs in;
  in.surfaces = {{"moving", (dir / "surface_killed.h5").string()}};
  // Before: exit 0 and a report of the frames it held.
  msg = error_of([&] { run_post(in, PostOptions{}, (dir / "post").string()); });
  EXPECT_NE(msg.find("surface_killed.h5: error: incomplete surface output: it holds status 'running' with 3 frames"),
            std::string::npos)
      << msg;
  EXPECT_FALSE(fs::exists(dir / "post" / "report.html"));
  // The finished run on the partial kinematics is refused too (it says so).
  in.surfaces = {{"moving", o.out}};
  msg = error_of([&] { run_post(in, PostOptions{}, (dir / "post").string()); });
  EXPECT_NE(msg.find("incomplete surface output: it holds a run on a partial input (PARTIAL INPUT: "), std::string::npos)
      << msg;

  in.surfaces = {{"moving", (dir / "surface_killed.h5").string()}};
  in.allow_partial = true;
  const PostSummary s = run_post(in, PostOptions{}, (dir / "post").string());
  ASSERT_EQ(s.partial_inputs.size(), 1u);
  const std::string html = slurp(s.report_path);
  const std::size_t partial = html.find("PARTIAL INPUT: " + (dir / "surface_killed.h5").string());
  ASSERT_NE(partial, std::string::npos);
  EXPECT_LT(partial, html.find("<h2>"));  // at the top, before the first section
  EXPECT_NE(slurp(s.summary_path).find("\"partial_inputs\""), std::string::npos);
}

TEST(SafetyPartial, StoppedAndShortKinematicsFilesAreIncomplete) {
  const fs::path dir = scratch("incomplete");
  {
    common::H5File k((dir / "stopped.h5").string(), common::H5File::Mode::kTruncate);
    write_kinematics_header(k, 1);
    k.set_attribute("/", "frames_expected", 21);
    k.set_attribute("/", "frames", 18);
    k.set_attribute("/", "stopped", "frame 18: non-finite trial value");
    k.write("/time", std::vector<double>(18, 0.0));
  }
  const common::H5File f((dir / "stopped.h5").string(), common::H5File::Mode::kRead);
  EXPECT_EQ(common::incompleteness(f, common::StageFile::kKinematics),
            "18 of 21 frames (the run stopped: frame 18: non-finite trial value)");
  const std::string line = common::require_usable_file(f, "stopped.h5", common::StageFile::kKinematics, true);
  EXPECT_EQ(line, "PARTIAL INPUT: stopped.h5 is an incomplete kinematics file: it holds 18 of 21 frames (the run "
                  "stopped: frame 18: non-finite trial value)");
  {
    common::H5File k((dir / "done.h5").string(), common::H5File::Mode::kTruncate);
    write_kinematics_header(k, 1);
    k.set_attribute("/", "frames_expected", 2);
    k.set_attribute("/", "frames", 2);
    k.write("/time", std::vector<double>{0.0, 0.01});
  }
  const common::H5File g((dir / "done.h5").string(), common::H5File::Mode::kRead);
  EXPECT_EQ(common::require_usable_file(g, "done.h5", common::StageFile::kKinematics, false), "");
}

// ---- 3. process hygiene of the runner -----------------------------------------

// A stage that records its pid and then runs for a minute (exec keeps the pid).
const char* kSlowStage = R"SH(#!/bin/sh
echo $$ > "$ARTHROSIM_SAFETY_PIDFILE"
exec sleep 60
)SH";

bool alive(pid_t pid) {
  // A zombie (nobody reaped it yet) is dead too.
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return false;
  const std::size_t close = line.rfind(')');
  return close != std::string::npos && close + 2 < line.size() && line[close + 2] != 'Z';
}

bool wait_until(const std::function<bool()>& f, double seconds) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    if (f()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return f();
}

// ---- 2. a complete output stays until its replacement is complete -----------

// A finished kinematics file of `frames` frames at rest, 0.5 ms apart.
void write_resting_kinematics(const fs::path& file, int frames) {
  common::H5File k(file.string(), common::H5File::Mode::kTruncate);
  write_kinematics_header(k, 1);
  k.set_attribute("/", "frames_expected", frames);
  k.set_attribute("/", "frames", frames);
  std::vector<double> t, X;
  for (int f = 0; f < frames; ++f) {
    t.push_back(0.2 + 5e-4 * f);
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) X.push_back(i == j ? 1.0 : 0.0);
  }
  k.write("/time", t);
  k.write_tensor3("/bodies/tibia/X_W", {frames, 4, 4}, X);
  k.write_tensor3("/bodies/femur/X_W", {frames, 4, 4}, X);
}

// Before: the rerun truncated surface_moving.h5 when it started, and the kill
// left a file of a few frames in its place.
TEST(SafetyAtomic, KilledRerunKeepsTheCompleteSurfaceOutput) {
  const fs::path dir = scratch("atomic");
  write_resting_kinematics(dir / "short.h5", 3);
  write_resting_kinematics(dir / "long.h5", 4001);  // 2 s of walk: 8,000 steps
  const fs::path out = dir / "surface_moving.h5";
  const std::string surface = (kBin / "arthrosim-surface").string() + " --quiet --prepared " +
                              coarse_prepared().string() + " --scene " + moving_scene(dir) + " --out " + out.string();
  const auto [status, printed] = run(surface + " --kinematics " + (dir / "short.h5").string());
  ASSERT_EQ(status, 0) << printed;
  ASSERT_FALSE(fs::exists(common::partial_name(out)));
  const std::string complete = slurp(out);

  const pid_t child = ::fork();
  if (child == 0) {
    ::execl("/bin/sh", "sh", "-c", ("exec " + surface + " --kinematics " + (dir / "long.h5").string()).c_str(),
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ASSERT_TRUE(wait_until([&] { return fs::exists(common::partial_name(out)); }, 30));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ::kill(child, SIGKILL);
  int st = 0;
  ::waitpid(child, &st, 0);
  ASSERT_TRUE(WIFSIGNALED(st)) << "the rerun finished before it was killed; make long.h5 longer";
  EXPECT_EQ(slurp(out), complete);  // untouched
  EXPECT_TRUE(fs::exists(common::partial_name(out)));  // what the killed run wrote, under a name no stage reads
  const common::H5File partial(common::partial_name(out).string(), common::H5File::Mode::kRead);
  EXPECT_EQ(partial.attribute_string("/", "status"), "running");
  // The sidecar names the complete file, not the partial one.
  EXPECT_EQ(slurp(dir / "surface_moving.xdmf").find(".partial"), std::string::npos);
}

// Before: a shockwave rerun truncated <stem>_efd<EFD>.h5 at its start, so a
// kill destroyed the complete result of the earlier run.
TEST(SafetyAtomic, KilledShockwaveRerunKeepsTheCompleteRunFile) {
  const fs::path dir = scratch("atomic_shockwave");
  const std::string shockwave =
      (kBin / "arthrosim-shockwave").string() + " --quiet --geometry bar --out " + (dir / "sw").string();
  const auto [status, printed] = run(shockwave + " --end-time-us 5");
  ASSERT_EQ(status, 0) << printed;
  const fs::path out = dir / "sw_efd0.33.h5";
  ASSERT_TRUE(fs::exists(out)) << printed;
  ASSERT_FALSE(fs::exists(common::partial_name(out)));
  const std::string complete = slurp(out), summary = slurp(dir / "sw_summary.json");

  const pid_t child = ::fork();
  if (child == 0) {
    // 100 ms of simulated time: minutes; killed well before.
    ::execl("/bin/sh", "sh", "-c", ("exec " + shockwave + " --end-time-us 100000").c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const bool started = wait_until([&] { return fs::exists(common::partial_name(out)); }, 30);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ::kill(child, SIGKILL);
  int st = 0;
  ::waitpid(child, &st, 0);
  ASSERT_TRUE(WIFSIGNALED(st)) << "the rerun finished before it was killed";
  EXPECT_TRUE(started) << "the rerun wrote no " << common::partial_name(out);
  EXPECT_TRUE(slurp(out) == complete) << out << " changed";  // untouched (binary: not printed)
  EXPECT_EQ(slurp(dir / "sw_summary.json"), summary);        // untouched
  const common::H5File partial(common::partial_name(out).string(), common::H5File::Mode::kRead);
  EXPECT_FALSE(partial.exists("/effects"));  // the killed run never finished its file
}

// Before: <stem>_volumes.svg was truncated and rewritten in place (a kill
// in between destroyed the previous plot), and the bar geometry left it
// empty. Now it is written as <name>.partial and renamed: a hard link to the
// previous plot keeps the previous bytes (the old inode is never written),
// and the bar writes no plot.
TEST(SafetyAtomic, ShockwaveVolumesPlotIsReplacedByRename) {
  const fs::path dir = scratch("atomic_shockwave_svg");
  const fs::path svg = dir / "sw_volumes.svg", previous = dir / "previous.svg";
  std::ofstream(svg) << "<svg>previous plot</svg>\n";
  fs::create_hard_link(svg, previous);
  ShockwaveStageOptions o;
  o.prepared = coarse_prepared().string();
  o.model = kCoarse.string();
  o.out = (dir / "sw").string();
  o.automaton_diameter_m = 2e-3;  // the shockwave stage test's short pulse run
  o.end_time_s = 6e-6;
  o.output_interval_s = 2e-6;
  o.efd_j_per_m2 = {330.0};
  const ShockwaveStageResult r = run_shockwave_stage(o, {"safety_test"}, false);
  EXPECT_EQ(r.volumes_svg, svg);
  EXPECT_NE(slurp(svg).find("Regeneration volumes"), std::string::npos);
  EXPECT_EQ(slurp(previous), "<svg>previous plot</svg>\n");  // the old inode untouched
  EXPECT_FALSE(fs::exists(common::partial_name(svg)));

  const fs::path bar = scratch("atomic_shockwave_svg_bar");
  const auto [status, printed] = run((kBin / "arthrosim-shockwave").string() + " --quiet --geometry bar --out " +
                                     (bar / "sw").string() + " --end-time-us 5");
  ASSERT_EQ(status, 0) << printed;
  EXPECT_FALSE(fs::exists(bar / "sw_volumes.svg"));  // before: an empty file
}

class SafetyRunner : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = scratch(std::string("runner_") + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(root_ / "bin");
    fs::create_directories(root_ / "models" / "knee");
    std::ofstream(root_ / "models" / "knee" / "femur.stl") << "femur\n";
    const fs::path stage = root_ / "bin" / "arthrosim-prepare";
    std::ofstream(stage) << kSlowStage;
    fs::permissions(stage, fs::perms::owner_all);
    std::ofstream(root_ / "s.yaml") << "model: models/knee\noutputs: [prepared_model]\nprepare: {edge_length_mm: 3}\n";
    pidfile_ = root_ / "stage.pid";
    setenv("ARTHROSIM_SAFETY_PIDFILE", pidfile_.c_str(), 1);
  }

  // Forks a runner of the scene; returns its pid once its stage has started
  // (and the stage's pid in *stage).
  pid_t start_runner(pid_t* stage) {
    const pid_t runner = ::fork();
    if (runner == 0) {
      RunnerOptions o;
      o.out_dir = root_ / "out";
      o.stage_dir = root_ / "bin";
      std::ostringstream log;
      const RunReport r = run_scene(load_scene(root_ / "s.yaml"), o, log);
      ::_exit(r.status == RunStatus::kOk ? 0 : 3);
    }
    EXPECT_TRUE(wait_until([&] { return fs::exists(pidfile_) && fs::file_size(pidfile_) > 0; }, 20));
    std::ifstream(pidfile_) >> *stage;
    return runner;
  }

  fs::path root_, pidfile_;
};

// Before: the stage was orphaned and ran on (here: its full minute).
TEST_F(SafetyRunner, KillNineOfTheRunnerEndsItsStage) {
  pid_t stage = 0;
  const pid_t runner = start_runner(&stage);
  ASSERT_GT(stage, 0);
  ASSERT_TRUE(alive(stage));
  ASSERT_EQ(::kill(runner, SIGKILL), 0);
  int status = 0;
  ::waitpid(runner, &status, 0);
  EXPECT_TRUE(wait_until([&] { return !alive(stage); }, 5)) << "stage " << stage << " outlived its runner";
  if (alive(stage)) ::kill(stage, SIGKILL);

  // The next run finds the killed run's record in the lock file and says so.
  fs::remove(pidfile_);
  std::ofstream(root_ / "bin" / "arthrosim-prepare") << "#!/bin/sh\nexit 0\n";
  RunnerOptions o;
  o.out_dir = root_ / "out";
  o.stage_dir = root_ / "bin";
  std::ostringstream log;
  run_scene(load_scene(root_ / "s.yaml"), o, log);
  EXPECT_NE(log.str().find("the previous run in " + (root_ / "out").string() +
                           " did not end cleanly (killed or crashed; pid " + std::to_string(runner)),
            std::string::npos)
      << log.str();
}

// Before: SIGTERM ended the runner and left the stage running.
TEST_F(SafetyRunner, SigtermIsForwardedToTheStageAndTheLockNamesItsHolder) {
  pid_t stage = 0;
  const pid_t runner = start_runner(&stage);
  ASSERT_GT(stage, 0);
  {  // While it runs, a second run is refused and told who holds the folder.
    RunnerOptions o;
    o.out_dir = root_ / "out";
    o.stage_dir = root_ / "bin";
    std::ostringstream log;
    const RunReport r = run_scene(load_scene(root_ / "s.yaml"), o, log);
    EXPECT_EQ(r.status, RunStatus::kFolderBusy);
    EXPECT_NE(r.message.find(".arthrosim.lock: pid " + std::to_string(runner) + ", started "), std::string::npos)
        << r.message;
  }
  ASSERT_EQ(::kill(runner, SIGTERM), 0);
  EXPECT_TRUE(wait_until([&] { return !alive(stage); }, 5)) << "SIGTERM was not forwarded to stage " << stage;
  int status = 0;
  ASSERT_EQ(::waitpid(runner, &status, 0), runner);
  ASSERT_TRUE(WIFEXITED(status));   // the runner ended on its own, after its stage
  EXPECT_EQ(WEXITSTATUS(status), 3);  // with the stage reported as failed
  if (alive(stage)) ::kill(stage, SIGKILL);
}


// Before: `arthrosim run` had no --allow-partial, so a user could not go on
// with a killed COMAK run's kinematics through the runner.
TEST(SafetyPartial, RunPassesAllowPartialToTheStagesThatTakeIt) {
  const fs::path dir = scratch("allow_partial");
  const fs::path scene_file = dir / "s.yaml";
  std::ofstream(scene_file) << "model: " << kCoarse.string() << "\ntrial: " << ARTHROSIM_SOURCE_DIR
                            << "/data/trials/synthetic_gait\noutputs: [report]\n"
                               "comak: {effects: [ligaments, muscles]}\nsurface:\n  scenarios:\n"
                               "    gait: {effects: [foundation_springs, imposed_kinematics, mesh_contact]}\n";
  const common::Scene scene = load_scene(scene_file);
  RunnerOptions options;
  options.out_dir = dir / "out";
  const auto flagged = [&] {
    std::vector<std::string> runs;
    for (const StageStep& s : runner_plan(scene, options))
      if (std::find(s.arguments.begin(), s.arguments.end(), "--allow-partial") != s.arguments.end())
        runs.push_back(s.name);
    return runs;
  };
  EXPECT_EQ(flagged(), std::vector<std::string>{});
  options.allow_partial = true;
  EXPECT_EQ(flagged(), (std::vector<std::string>{"surface.gait", "post"}));
  // Every stage that says it takes the flag does (its program's --help).
  for (const StageDescriptor& d : stages()) {
    if (!d.takes_allow_partial) continue;
    const auto [status, help] = run((kBin / d.executable).string() + " --help");
    EXPECT_EQ(status, 0) << help;
    EXPECT_NE(help.find("--allow-partial"), std::string::npos) << d.executable;
  }
}

// Before: the biphasic stage and the accuracy study read a kinematics file of
// format_version 99 (or of another kind) as if it were current.
TEST(SafetyVersions, BiphasicStageAndStudyCheckTheKinematicsVersion) {
  const fs::path dir = scratch("versions_biphasic");
  const auto [prepared, kinematics] = write_two_layer_case((dir / "case").string());
  const fs::path v99 = dir / "kinematics_v99.h5", foreign = dir / "kinematics_foreign.h5";
  fs::copy_file(kinematics, v99);
  fs::copy_file(kinematics, foreign);
  {
    common::H5File f(v99.string(), common::H5File::Mode::kReadWrite);
    f.set_attribute("/", "format_version", 99);
  }
  {
    common::H5File f(foreign.string(), common::H5File::Mode::kReadWrite);
    f.set_attribute("/", "format", "some other file");
  }
  for (const fs::path& k : {v99, foreign}) {
    SCOPED_TRACE(k.string());
    const auto [status, printed] = run((kBin / "arthrosim-biphasic").string() + " --quiet --layers femur tibia_medial --prepared " + prepared +
                                       " --kinematics " + k.string() + " --out " + (dir / "out.h5").string());
    EXPECT_NE(status, 0) << printed;
    EXPECT_NE(printed.find(k.string()), std::string::npos) << printed;
    EXPECT_FALSE(fs::exists(dir / "out.h5"));
    const std::string study = error_of([&] { study::comak_metrics(k, kinematics); });
    EXPECT_NE(study.find(k.string()), std::string::npos) << study;
  }
  // File, version found, version read.
  const auto [status, printed] = run((kBin / "arthrosim-biphasic").string() + " --quiet --layers femur tibia_medial --prepared " + prepared +
                                     " --kinematics " + v99.string() + " --out " + (dir / "out.h5").string());
  EXPECT_NE(printed.find("format_version 99; this build reads version 1"), std::string::npos) << printed;
  EXPECT_NE(error_of([&] { study::comak_metrics(kinematics, v99); }).find("format_version 99"), std::string::npos);
  EXPECT_NE(error_of([&] { study::comak_metrics(foreign, kinematics); }).find("found format 'some other file'"),
            std::string::npos);
  // The canonical case itself passes.
  EXPECT_EQ(error_of([&] { study::comak_metrics(kinematics, kinematics); }), "");
}

// Before: arthrosim-biphasic run by hand on the kinematics file of a killed
// or stopped COMAK run simulated the frames it held as if they were the
// whole trial. Now it is refused naming the file and what it holds, unless
// --allow-partial, and the output then says so.
TEST(SafetyPartial, BiphasicRefusesAnIncompleteKinematicsFileUnlessAllowed) {
  const fs::path dir = scratch("partial_biphasic");
  const auto [prepared, kinematics] = write_two_layer_case((dir / "case").string());
  const fs::path stopped = dir / "kinematics_stopped.h5";
  fs::copy_file(kinematics, stopped);
  {
    common::H5File f(stopped.string(), common::H5File::Mode::kReadWrite);
    f.set_attribute("/", "frames_expected", 150);
    f.set_attribute("/", "stopped", "COMAK frame 101 (t = 1.01 s): non-finite trial value");
  }
  const musculoskeletal::KinematicsFileReader reader(stopped.string());
  EXPECT_EQ(reader.frames_complete(), 101);
  EXPECT_EQ(reader.frames_expected(), 150);
  EXPECT_FALSE(reader.finished());
  EXPECT_EQ(reader.incompleteness(), "101 of 150 frames (the run stopped: COMAK frame 101 (t = 1.01 s): non-finite "
                                     "trial value)");
  EXPECT_TRUE(musculoskeletal::KinematicsFileReader(kinematics).finished());
  EXPECT_EQ(musculoskeletal::KinematicsFileReader(kinematics).incompleteness(), "");

  const std::string biphasic = (kBin / "arthrosim-biphasic").string() +
                               " --quiet --layers femur tibia_medial --end-time-s 0.03 --prepared " + prepared +
                               " --kinematics " + stopped.string() + " --out " + (dir / "out.h5").string();
  auto [status, printed] = run(biphasic);
  EXPECT_NE(status, 0) << printed;
  EXPECT_NE(printed.find(stopped.string() + ": error: incomplete kinematics file: it holds 101 of 150 frames"),
            std::string::npos)
      << printed;
  EXPECT_NE(printed.find("--allow-partial"), std::string::npos) << printed;
  EXPECT_FALSE(fs::exists(dir / "out.h5"));

  // The accuracy study compares complete runs only (before: it checked kind
  // and version, and compared the 101 frames as if they were the run).
  const std::string study = error_of([&] { study::comak_metrics(stopped, kinematics); });
  EXPECT_NE(study.find(stopped.string() + ": error: incomplete kinematics file: it holds 101 of 150 frames"),
            std::string::npos)
      << study;
  EXPECT_NE(error_of([&] { study::comak_metrics(kinematics, stopped); }).find("incomplete kinematics file"),
            std::string::npos);

  std::tie(status, printed) = run(biphasic + " --allow-partial");
  ASSERT_EQ(status, 0) << printed;
  const common::H5File out((dir / "out.h5").string(), common::H5File::Mode::kRead);
  EXPECT_EQ(out.attribute_string("/", "partial_input"),
            "PARTIAL INPUT: " + stopped.string() + " is an incomplete kinematics file: it holds 101 of 150 frames "
            "(the run stopped: COMAK frame 101 (t = 1.01 s): non-finite trial value)");
}

// ---- 1. complete input identity -------------------------------------------

// A fake stage program for the runner: writes its --out file (a fixed text,
// so an unchanged rerun writes the same bytes); arthrosim-comak's output
// starts with an HDF5 file holding an empty effect ledger (the runner checks
// it), arthrosim-prepare also writes prepared.xdmf.
constexpr const char* kFakeStage = R"SH(#!/bin/sh
stage="$(basename "$0")"; out=""; prev=""
for a in "$@"; do case "$prev" in --out) out="$a" ;; esac; prev="$a"; done
if [ "$stage" = arthrosim-comak ]; then cp "$SAFETY_FAKE_LEDGER" "$out"; echo comak >> "$out";
else echo "$stage" > "$out"; echo xdmf > "${out%.h5}.xdmf"; fi
)SH";

// Before: the runner hashed the trial and model paths only, so the .mot and
// ExternalLoads files a trial.yaml names outside its folder (and the data
// file the XML names), and a manifest's meshes outside the model folder,
// could change without rerunning anything. Fake stages: only the runner's
// plan and stamps are under test, so this takes well under a second.
TEST(SafetyInputs, EditingEachReferencedFileRerunsItsStep) {
  const fs::path root = scratch("inputs");
  const fs::path trial = fs::path(ARTHROSIM_SOURCE_DIR) / "data/trials/lenhart2015_overground17";
  for (const char* d : {"bin", "scenes", "models/knee", "meshes", "trials/walk", "shared/xml", "shared/grf", "ledger"})
    fs::create_directories(root / d);
  for (const char* s : {"arthrosim-prepare", "arthrosim-comak"}) {
    std::ofstream(root / "bin" / s) << kFakeStage;
    fs::permissions(root / "bin" / s, fs::perms::owner_all);
  }
  {
    common::H5File f((root / "ledger/comak.h5").string(), common::H5File::Mode::kTruncate);
    common::write_effect_ledger(f, common::EffectLedger("comak"));
  }
  setenv("SAFETY_FAKE_LEDGER", (root / "ledger/comak.h5").c_str(), 1);
  // The trial: its description in trials/walk, its files elsewhere.
  std::string yaml = slurp(trial / "trial.yaml");
  const auto replace = [](std::string& s, const std::string& from, const std::string& to) {
    const std::size_t at = s.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    s.replace(at, from.size(), to);
  };
  replace(yaml, "kinematics_file: overground_17_ik.mot", "kinematics_file: ../../shared/ik.mot");
  replace(yaml, "external_loads_file: overground_17_ext_loads.xml", "external_loads_file: ../../shared/xml/ext.xml");
  std::ofstream(root / "trials/walk/trial.yaml") << yaml;
  std::string xml = slurp(trial / "overground_17_ext_loads.xml");
  replace(xml, "<datafile>overground_17_grf.mot</datafile>", "<datafile>../grf/grf.mot</datafile>");
  std::ofstream(root / "shared/xml/ext.xml") << xml;
  fs::copy_file(trial / "overground_17_ik.mot", root / "shared/ik.mot");
  fs::copy_file(trial / "overground_17_grf.mot", root / "shared/grf/grf.mot");
  // The model: a manifest whose cartilage meshes live outside its folder.
  std::ofstream(root / "models/knee/meshes.yaml")
      << "unit: mm\nbones:\n  femur: {file: femur_bone.stl}\n  tibia: {file: tibia_bone.stl}\n"
         "cartilage:\n  femur: {file: ../../meshes/femur_cartilage.stl, bone: femur}\n"
         "  tibia: {file: ../../meshes/tibia_cartilage.stl, bone: tibia}\n";
  for (const char* m : {"models/knee/femur_bone.stl", "models/knee/tibia_bone.stl", "meshes/femur_cartilage.stl",
                        "meshes/tibia_cartilage.stl"})
    fs::copy_file(kCoarse / (fs::path(m).filename() == "tibia_cartilage.stl" ? fs::path("tibia_medial_cartilage.stl")
                                                                              : fs::path(m).filename()),
                  root / m);
  const fs::path scene_file = root / "scenes/s.yaml";
  std::ofstream(scene_file) << "model: ../models/knee\ntrial: ../trials/walk\noutputs: [kinematics]\n"
                               "comak: {effects: [ligaments, muscles]}\n";
  const common::Scene scene = load_scene(scene_file);

  RunnerOptions options;
  options.out_dir = root / "out";
  options.stage_dir = root / "bin";
  const auto outcome = [&](bool dry) {
    options.dry_run = dry;
    std::ostringstream log;
    const RunReport r = run_scene(scene, options, log);
    EXPECT_EQ(r.status, RunStatus::kOk) << log.str();
    std::map<std::string, std::pair<StageStatus, std::string>> m;
    for (const StageOutcome& o : r.stages) m[o.name] = {o.status, o.reason};
    return m;
  };
  auto first = outcome(false);
  ASSERT_EQ(first["prepare"].first, StageStatus::kRan);
  ASSERT_EQ(first["comak"].first, StageStatus::kRan);
  auto same = outcome(true);
  EXPECT_EQ(same["prepare"].first, StageStatus::kWouldSkip) << same["prepare"].second;
  EXPECT_EQ(same["comak"].first, StageStatus::kWouldSkip) << same["comak"].second;

  struct Edit {
    const char* file;
    const char* stage;  // the step that must rerun
    const char* label;  // the input its reason names
  };
  for (const Edit& e : {Edit{"shared/ik.mot", "comak", "trial kinematics"},
                        Edit{"shared/xml/ext.xml", "comak", "trial external loads"},
                        Edit{"shared/grf/grf.mot", "comak", "trial external loads data"},
                        Edit{"meshes/tibia_cartilage.stl", "prepare", "model mesh tibia_cartilage"}}) {
    SCOPED_TRACE(e.file);
    std::ofstream(root / e.file, std::ios::app) << "\n";  // one byte more
    auto dry = outcome(true);
    EXPECT_EQ(dry[e.stage].first, StageStatus::kWouldRun);
    EXPECT_NE(dry[e.stage].second.find("input changed: " + std::string(e.label)), std::string::npos)
        << dry[e.stage].second;
    if (std::string(e.stage) == "comak") {
      EXPECT_EQ(dry["prepare"].first, StageStatus::kWouldSkip) << dry["prepare"].second;
    }
    auto rerun = outcome(false);  // restamp
    EXPECT_EQ(rerun[e.stage].first, StageStatus::kRan);
    auto after = outcome(true);
    EXPECT_EQ(after["prepare"].first, StageStatus::kWouldSkip) << after["prepare"].second;
    EXPECT_EQ(after["comak"].first, StageStatus::kWouldSkip) << after["comak"].second;
  }
}

// Before: `model: /usr` hashed every file below it (11 GB) with no output.
TEST(SafetyInputs, HashingAHugeFolderIsRefusedAtItsLimit) {
  const fs::path dir = scratch("huge");
  for (int i = 0; i < 12; ++i) std::ofstream(dir / ("f" + std::to_string(i))) << std::string(1000, 'x');
  common::HashLimits few;
  few.max_files = 10;
  const std::string files = error_of([&] { common::sha256_path(dir, few); });
  EXPECT_NE(files.find(dir.string()), std::string::npos) << files;
  EXPECT_NE(files.find("more than 10 files"), std::string::npos) << files;
  common::HashLimits small;
  small.max_bytes = 5000;
  const std::string bytes = error_of([&] { common::sha256_path(dir, small); });
  EXPECT_NE(bytes.find("more than 5000 bytes"), std::string::npos) << bytes;
  EXPECT_EQ(error_of([&] { common::sha256_path(dir); }), "");  // within the default limits
  // A system folder fails at the default file limit after a walk, not a hash
  // of gigabytes (a generous 20 s for a loaded machine; ~0.1 s idle).
  if (fs::is_directory("/usr/lib")) {
    const auto t0 = std::chrono::steady_clock::now();
    const std::string usr = error_of([&] { common::sha256_path("/usr"); });
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_NE(usr.find("more than 10000 files"), std::string::npos) << usr;
    EXPECT_LT(s, 20.0);
  }
}

}  // namespace
}  // namespace arthrosim::pipelines
