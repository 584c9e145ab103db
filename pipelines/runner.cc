#include "pipelines/runner.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>
#include <thread>

#include "common/error.h"
#include "common/effects.h"
#include "common/hashing.h"
#include "common/hdf5.h"
#include "common/process.h"
#include "pipelines/stages.h"

namespace arthrosim::pipelines {
namespace fs = std::filesystem;
using common::Scene;

namespace {

std::string short_key(const std::string& key) { return key.substr(0, 12); }

// ---------------------------------------------------------------------------
// Stamps: DIR/.stamps/<stage>.txt, tab-separated lines, written after a
// successful run.
// ---------------------------------------------------------------------------
struct Stamp {
  std::string key;
  std::string executable;
  std::map<std::string, std::string> inputs;   // label -> sha
  std::map<std::string, std::string> options;  // block.key -> canonical value
  std::map<std::string, std::string> outputs;  // file name -> sha
  /// The stage's command line with machine-specific paths replaced by names
  /// (<model>, <scene>, $OUT/...), so a change in how the runner calls a
  /// stage reruns it while moving the repository or output folder does not.
  std::string arguments;
};

bool read_stamp(const fs::path& file, Stamp& stamp) {
  std::ifstream in(file);
  if (!in) return false;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> f;
    std::size_t start = 0;
    while (true) {
      const std::size_t tab = line.find('\t', start);
      f.push_back(line.substr(start, tab == std::string::npos ? std::string::npos : tab - start));
      if (tab == std::string::npos) break;
      start = tab + 1;
    }
    if (f[0] == "key" && f.size() == 2) stamp.key = f[1];
    if (f[0] == "executable" && f.size() == 2) stamp.executable = f[1];
    if (f[0] == "arguments" && f.size() == 2) stamp.arguments = f[1];
    if (f[0] == "input" && f.size() == 3) stamp.inputs[f[1]] = f[2];
    if (f[0] == "option" && f.size() == 3) stamp.options[f[1]] = f[2];
    if (f[0] == "output" && f.size() == 3) stamp.outputs[f[1]] = f[2];
  }
  return !stamp.key.empty();
}

void write_stamp(const fs::path& file, const StageStep& step, const Stamp& stamp) {
  fs::create_directories(file.parent_path());
  const fs::path tmp = file.string() + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) throw common::InputError(tmp.string(), 0, "cannot write the stage stamp");
    out << "# arthrosim stage stamp of '" << step.name
        << "', written after its last successful run.\n"
        << "# The runner skips the stage while these hashes still match. Delete this file to "
           "force a rerun.\n";
    out << "stage\t" << step.name << "\n";
    out << "key\t" << stamp.key << "\n";
    out << "executable\t" << stamp.executable << "\n";
    out << "arguments\t" << stamp.arguments << "\n";
    for (const auto& [k, v] : stamp.inputs) out << "input\t" << k << "\t" << v << "\n";
    for (const auto& [k, v] : stamp.options) out << "option\t" << k << "\t" << v << "\n";
    for (const auto& [k, v] : stamp.outputs) out << "output\t" << k << "\t" << v << "\n";
    if (!out) throw common::InputError(tmp.string(), 0, "cannot write the stage stamp");
  }
  fs::rename(tmp, file);
}

// The stage key and its parts, computed from the files as they are now.
std::string portable_arguments(const StageStep& step, const fs::path& out_dir,
                               const fs::path& scene_file) {
  std::string out;
  for (const std::string& a : step.arguments) {
    std::string word = a;
    for (const auto& [label, path] : step.inputs) {
      if (fs::path(a) == path) word = "<" + label + ">";
    }
    const std::string prefix = out_dir.string() + "/";
    if (a == out_dir.string()) word = "$OUT";
    if (a.rfind(prefix, 0) == 0) word = "$OUT/" + a.substr(prefix.size());
    // Last: a scene inside the output folder (`arthrosim run --set` writes
    // OUT/scene_set.yaml) is still the scene, whose options are hashed
    // separately; where it lives must not force a rerun.
    if (fs::path(a) == scene_file) word = "<scene>";
    out += (out.empty() ? "" : " ") + word;
  }
  return out;
}

Stamp current_state(const StageStep& step, const fs::path& executable, const fs::path& out_dir,
                    const fs::path& scene_file) {
  Stamp s;
  s.executable = common::sha256_file(executable);
  for (const auto& [label, path] : step.inputs) s.inputs[label] = common::sha256_path(path);
  for (const auto& [k, v] : step.options) s.options[k] = v;
  s.arguments = portable_arguments(step, out_dir, scene_file);
  std::string text = "arthrosim stage key v2\nstage\t" + step.name + "\nexecutable\t" +
                     s.executable + "\narguments\t" + s.arguments + "\n";
  for (const auto& [k, v] : s.inputs) text += "input\t" + k + "\t" + v + "\n";
  for (const auto& [k, v] : s.options) text += "option\t" + k + "\t" + v + "\n";
  s.key = common::sha256_hex(text);
  return s;
}

// Why the stage must run, or "" when it is up to date.
std::string why_run(const StageStep& step, const Stamp& now, const Stamp* last) {
  bool any_output = false;
  for (const fs::path& o : step.outputs) any_output = any_output || fs::exists(o);
  if (last == nullptr) {
    return any_output ? "no record of a previous successful run" : "no previous output";
  }
  std::vector<std::string> why;
  std::string changed_options;
  for (const auto& [k, v] : now.options) {
    auto it = last->options.find(k);
    const std::string before = it == last->options.end() ? "(unset)" : it->second;
    if (before != v) changed_options += (changed_options.empty() ? "" : ", ") + k + " " + before +
                                        " -> " + v;
  }
  for (const auto& [k, v] : last->options) {
    if (!now.options.count(k)) {
      changed_options += (changed_options.empty() ? "" : ", ") + k + " " + v + " -> (unset)";
    }
  }
  if (!changed_options.empty()) why.push_back("options changed: " + changed_options);
  std::vector<std::string> changed_inputs;
  for (const auto& [k, v] : now.inputs) {
    auto it = last->inputs.find(k);
    if (it == last->inputs.end()) {
      why.push_back("new input " + k);
    } else if (it->second != v) {
      changed_inputs.push_back(k);
    }
  }
  if (!changed_inputs.empty()) {
    std::string list;
    for (const std::string& k : changed_inputs) list += (list.empty() ? "" : ", ") + k;
    why.push_back((changed_inputs.size() == 1 ? "input changed: " : "inputs changed: ") + list);
  }
  for (const auto& [k, v] : last->inputs) {
    if (!now.inputs.count(k)) why.push_back("input no longer used: " + k);
  }
  // Options reach stages partly as flags; report the command line only when
  // the options do not already explain the difference.
  if (now.arguments != last->arguments && changed_options.empty()) {
    why.push_back("command line changed: " + last->arguments + " -> " + now.arguments);
  }
  if (now.executable != last->executable) {
    why.push_back("code changed: " + step.executable + " is not the build that wrote the output");
  }
  if (why.empty() && now.key != last->key) why.push_back("stage key changed");
  for (const fs::path& o : step.outputs) {
    const std::string name = o.filename().string();
    auto it = last->outputs.find(name);
    if (!fs::exists(o)) {
      why.push_back("output " + name + " missing");
    } else if (it == last->outputs.end() || common::sha256_file(o) != it->second) {
      why.push_back("output " + name + " changed since the stage wrote it");
    }
  }
  std::string s;
  for (const std::string& w : why) s += (s.empty() ? "" : "; ") + w;
  return s;
}

std::string quote(const std::string& arg) {
  if (!arg.empty() && arg.find_first_of(" \t\n'\"\\$`;&|<>()*?") == std::string::npos) return arg;
  std::string q = "'";
  for (char c : arg) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// Starts `exe args...` and returns its pid (-1 when fork fails). With an
// empty `log_file` the stage shares this process's stdout/stderr (its own
// output and progress display stream through); otherwise both go to that
// file, which the runner shows in parts (stages running side by side would
// interleave on a terminal). `omp_threads` > 0 sets OMP_NUM_THREADS in the
// stage's environment; ARTHROSIM_STAGE_KEY is the stage key.
pid_t launch(const fs::path& exe, const std::vector<std::string>& args, const fs::path& log_file,
             int omp_threads, const std::string& stage_key) {
  std::cout.flush();
  std::cerr.flush();
  std::fflush(nullptr);
  std::vector<std::string> argv_store;
  argv_store.push_back(exe.string());
  argv_store.insert(argv_store.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : argv_store) argv.push_back(a.data());
  argv.push_back(nullptr);
  const std::string threads = std::to_string(omp_threads);
  const pid_t parent = getpid();
  // The stage key: a stage ties its checkpoints to it (common/checkpoint.h).
  const std::string key = stage_key;
  const pid_t pid = fork();
  if (pid != 0) return pid;
  // Child: only async-signal-safe calls until execv. Own process group,
  // SIGTERM when the runner dies (common/process.h).
  common::child_after_fork(parent);
  if (!log_file.empty()) {
    const int fd = ::open(log_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) _exit(127);
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    ::close(fd);
  }
  if (omp_threads > 0) ::setenv("OMP_NUM_THREADS", threads.c_str(), 1);
  ::setenv("ARTHROSIM_STAGE_KEY", key.c_str(), 1);
  execv(argv[0], argv.data());
  std::fprintf(stderr, "arthrosim: cannot execute %s: %s\n", argv[0], std::strerror(errno));
  _exit(127);
}

// The exit code of a waited-for stage, or 128 + signal number when killed.
int exit_code_of(int status) {
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return 127;
}

// The last `n` lines of a text file (a stage's log), each prefixed; with
// `progress_only`, the last line drawn by a progress display ("...% (k/n)
// elapsed ..."; common/progress.h), or else the last line.
std::string tail_lines(const fs::path& file, std::size_t n, const std::string& prefix,
                       bool progress_only = false) {
  std::ifstream in(file);
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    // A progress display redraws with '\r'; keep what was drawn last.
    const std::size_t cr = line.find_last_of('\r', line.size() > 1 ? line.size() - 2 : 0);
    if (cr != std::string::npos && cr + 1 < line.size()) line = line.substr(cr + 1);
    if (line.empty()) continue;
    if (progress_only && !lines.empty() && lines.back().find("% (") != std::string::npos &&
        line.find("% (") == std::string::npos) {
      continue;  // keep the progress line
    }
    lines.push_back(std::move(line));
    if (lines.size() > n) lines.erase(lines.begin());
  }
  std::string out;
  for (const std::string& l : lines) out += prefix + l + "\n";
  return out;
}

// The lock on DIR/.arthrosim.lock for the duration of a run (two runs cannot
// interleave stages and stamps in one folder), held by the stages too, and
// recording its holder: common/process.h.
using OutputFolderLock = common::FolderLock;

}  // namespace

fs::path stamp_path(const fs::path& out_dir, const std::string& run) {
  return out_dir / ".stamps" / (run + ".txt");
}

std::string stamp_executable_hash(const fs::path& out_dir, const std::string& run) {
  Stamp stamp;
  return read_stamp(stamp_path(out_dir, run), stamp) ? stamp.executable : std::string();
}

fs::path default_stage_dir() {
  if (const char* env = std::getenv("ARTHROSIM_STAGE_DIR"); env != nullptr && *env != '\0') {
    return fs::path(env);
  }
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : self.parent_path();
}

std::vector<StageStep> runner_plan(const Scene& scene, const RunnerOptions& options) {
  std::vector<StageStep> plan = plan_stages(scene, fs::absolute(options.out_dir).lexically_normal());
  for (StageStep& s : plan)
    if (const StageDescriptor* d = stage_of_run(s.name); options.allow_partial && d && d->takes_allow_partial)
      s.arguments.push_back("--allow-partial");
  return plan;
}

RunReport run_scene(const Scene& scene, const RunnerOptions& options, std::ostream& log) {
  RunReport report;
  const fs::path out_dir = fs::absolute(options.out_dir).lexically_normal();
  const std::vector<StageStep> plan = runner_plan(scene, options);

  log << "arthrosim: scene " << scene.file.string() << "\n";
  if (const std::string description = scene_inputs(scene).description; !description.empty())
    log << "  " << description << "\n";
  log << "arthrosim: output folder " << out_dir.string() << "\n";
  log << "arthrosim: plan:";
  for (const StageStep& s : plan) log << " " << s.name;
  log << "\n";
  for (const StageStep& s : plan) log << "  " << s.name << ": needed for " << s.needed_for << "\n";
  const auto planned = [&](const std::string& name) {
    for (const StageStep& s : plan) {
      if (s.name == name) return true;
    }
    return false;
  };
  // Say what the scene describes but its outputs do not ask for.
  for (const StageDescriptor& d : stages()) {
    if (!scene.has_block(d.name) || !d.runs) continue;
    for (const StageStep& r : d.runs(scene, out_dir)) {
      if (!planned(r.name) && r.unavailable.empty())
        log << "  not run: " << r.name << " (no requested output needs it)\n";
    }
  }
  for (const StageStep& s : plan) {
    StageOutcome o;
    o.name = s.name;
    report.stages.push_back(o);
  }

  // Every planned executable must exist before anything runs: a stage that is
  // not part of this build is an error, never a silent skip.
  for (const StageStep& s : plan) {
    const fs::path exe = options.stage_dir / s.executable;
    if (!fs::exists(exe)) {
      report.status = RunStatus::kMissingExecutable;
      report.message = "stage " + s.executable + " not available in this build (looked for " +
                       exe.string() + "); the scene needs it for " + s.name + " (" +
                       s.needed_for + ")";
      log << "arthrosim: error: " << report.message << "\n";
      return report;
    }
  }

  std::optional<OutputFolderLock> lock;
  if (!options.dry_run) {
    fs::create_directories(out_dir);
    lock.emplace(out_dir, "arthrosim run " + scene.file.string());
    if (!lock->locked()) {
      report.status = RunStatus::kFolderBusy;
      report.message = "another arthrosim run is using " + out_dir.string() + " (it holds .arthrosim.lock" +
                       (lock->holder().empty() ? "" : ": " + lock->holder()) + "); wait for it or choose another --out";
      log << "arthrosim: error: " << report.message << "\n";
      return report;
    }
    if (!lock->stale().empty())
      log << "arthrosim: note: the previous run in " << out_dir.string() << " did not end cleanly (killed or crashed; "
          << lock->stale() << "); its unfinished stages run again, partial files (*.partial) are replaced\n";
  }
  const std::size_t n = plan.size();
  // deps[i]: the earlier stages that write one of stage i's inputs.
  std::vector<std::vector<std::size_t>> deps(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = 0; j < i; ++j) {
      bool uses = false;
      for (const auto& input : plan[i].inputs) {
        for (const fs::path& o : plan[j].outputs) uses = uses || input.second == o;
      }
      if (uses) deps[i].push_back(j);
    }
  }

  // Why stage i must run ("" when it is up to date), from its key as the
  // files are now (stored in `now` and the outcome) and its last stamp.
  const auto reason_to_run = [&](std::size_t i, Stamp& now) {
    const StageStep& step = plan[i];
    now = current_state(step, options.stage_dir / step.executable, out_dir, scene.file);
    report.stages[i].key = now.key;
    if (options.force) return std::string("--force");
    Stamp last;
    const bool have_last = read_stamp(stamp_path(out_dir, step.name), last);
    return why_run(step, now, have_last ? &last : nullptr);
  };
  const auto log_command = [&](const StageStep& step) {
    log << "  $ " << quote((options.stage_dir / step.executable).string());
    for (const std::string& a : step.arguments) log << " " << quote(a);
    log << "\n";
  };
  const auto up_to_date = [](const Stamp& now) {
    return "inputs, options and code unchanged (hash " + short_key(now.key) + ")";
  };

  // ---- dry run: in plan order, nothing executed ----------------------------
  std::vector<std::string> will_change;  // outputs that would be rewritten
  for (std::size_t i = 0; options.dry_run && i < n; ++i) {
    const StageStep& step = plan[i];
    StageOutcome& outcome = report.stages[i];
    // An input that an earlier stage would (re)write cannot be hashed yet;
    // this stage then runs after it (unless that stage reproduces identical
    // bytes, which only a real run can tell).
    std::string pending;
    for (const auto& [label, path] : step.inputs) {
      for (const std::string& w : will_change) {
        if (path == fs::path(w)) pending += (pending.empty() ? "" : ", ") + label;
      }
    }
    if (!pending.empty()) {
      outcome.status = StageStatus::kWouldRun;
      outcome.reason = "input " + pending + " is written earlier in this run";
      log << step.name << ": would run — " << outcome.reason << "\n";
      for (const fs::path& o : step.outputs) will_change.push_back(o.string());
      continue;
    }
    Stamp now;
    outcome.reason = reason_to_run(i, now);
    if (outcome.reason.empty()) {
      outcome.status = StageStatus::kWouldSkip;
      outcome.reason = up_to_date(now);
      log << step.name << ": would skip — " << outcome.reason << "\n";
      continue;
    }
    outcome.status = StageStatus::kWouldRun;
    log << step.name << ": would run — " << outcome.reason << "\n";
    log_command(step);
    for (const fs::path& o : step.outputs) will_change.push_back(o.string());
  }

  // ---- real run: a stage starts once the stages writing its inputs are done;
  // up to options.jobs run at once -----------------------------------------
  using Clock = std::chrono::steady_clock;
  enum class Phase { kWaiting, kRunning, kFinished };
  std::vector<Phase> phase(n, Phase::kWaiting);
  struct Running {
    std::size_t index;
    pid_t pid;
    Clock::time_point t0;
    fs::path log_file;  // empty: the stage writes to this process's stdout/stderr
  };
  std::vector<Running> running;
  std::vector<bool> checked(n, false);  // stamp compared (once its inputs exist)
  std::vector<Stamp> stamp_now(n);      // the key each stage runs under
  const std::size_t jobs = static_cast<std::size_t>(std::max(1, options.jobs));
  const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const bool user_threads = std::getenv("OMP_NUM_THREADS") != nullptr;
  bool stop = false;  // a stage failed: start nothing more

  const auto is_ready = [&](std::size_t i) {
    if (phase[i] != Phase::kWaiting) return false;
    for (std::size_t j : deps[i]) {
      if (phase[j] != Phase::kFinished) return false;
      const StageStatus st = report.stages[j].status;
      if (st != StageStatus::kRan && st != StageStatus::kSkipped) return false;
    }
    return true;
  };
  const auto fail = [&](std::size_t i) {
    const StageStep& step = plan[i];
    const StageOutcome& outcome = report.stages[i];
    if (report.status == RunStatus::kOk) {
      report.status = RunStatus::kStageFailed;
      report.message = "stage " + step.name + " (" + step.executable + ") " + outcome.reason +
                       "; stopping (outputs of earlier stages are kept in " + out_dir.string() + ")";
    }
    log << step.name << ": FAILED after " << std::fixed << std::setprecision(1) << outcome.wall_time_s
        << " s — " << outcome.reason << "\n";
    log.unsetf(std::ios::floatfield);
    stop = true;
    if (!running.empty()) {
      log << "arthrosim: waiting for " << running.size()
          << " stage(s) already running to finish (their results are kept)\n";
    }
  };
  // Checks a stage that exited: outputs present, effect ledger as asked; stamps it.
  const auto finish = [&](const Running& r, int status, const struct rusage& usage) {
    const std::size_t i = r.index;
    const StageStep& step = plan[i];
    StageOutcome& outcome = report.stages[i];
    phase[i] = Phase::kFinished;
    outcome.exit_code = exit_code_of(status);
    outcome.wall_time_s = std::chrono::duration<double>(Clock::now() - r.t0).count();
    outcome.cpu_time_s = static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
                         1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
    outcome.max_rss_kb = usage.ru_maxrss;  // kilobytes on Linux (getrusage(2))
    if (outcome.exit_code != 0) {
      outcome.status = StageStatus::kFailed;
      outcome.reason = outcome.exit_code > 128 ? "killed by signal " + std::to_string(outcome.exit_code - 128)
                                               : "exited with status " + std::to_string(outcome.exit_code);
    } else {
      for (const fs::path& o : step.outputs) {
        if (!fs::exists(o)) {
          outcome.status = StageStatus::kFailed;
          outcome.reason = "exited with status 0 but did not write " + o.string();
          break;
        }
      }
    }
    if (!r.log_file.empty()) {
      // What the stage printed last: its summary, or the error that stopped it.
      log << step.name << ": last lines of " << r.log_file.string() << ":\n"
          << tail_lines(r.log_file, outcome.status == StageStatus::kFailed ? 30 : 12, "  | ");
    }
    if (outcome.status != StageStatus::kFailed && step.effects) {
      // The stage's own account of what it built must match the scene.
      try {
        const common::H5File h5(step.outputs.front().string(), common::H5File::Mode::kRead);
        const common::EffectLedger ledger = common::read_effect_ledger(h5);
        std::string built;
        for (const common::EffectTotal& t : ledger.totals()) {
          built += (built.empty() ? "" : ", ") + t.effect + " " + std::to_string(t.count);
        }
        log << step.name << ": effects built: " << (built.empty() ? "none" : built) << "\n";
        const std::vector<std::string> extra = ledger.unrequested(*step.effects);
        if (!extra.empty()) {
          std::string names;
          for (const std::string& e : extra) names += (names.empty() ? "" : ", ") + e;
          outcome.status = StageStatus::kFailed;
          outcome.reason = "built effect(s) the scene did not ask for: " + names;
        }
      } catch (const common::InputError& e) {
        outcome.status = StageStatus::kFailed;
        outcome.reason = std::string("has no readable effect ledger: ") + e.what();
      }
    }
    if (outcome.status == StageStatus::kFailed) {
      fail(i);
      return;
    }
    Stamp done = stamp_now[i];
    for (const fs::path& o : step.outputs) done.outputs[o.filename().string()] = common::sha256_file(o);
    write_stamp(stamp_path(out_dir, step.name), step, done);
    outcome.status = StageStatus::kRan;
    log << step.name << ": done in " << std::fixed << std::setprecision(1) << outcome.wall_time_s << " s (hash "
        << short_key(stamp_now[i].key) << ")\n";
    log.unsetf(std::ios::floatfield);
    log.flush();
  };

  auto last_heartbeat = Clock::now();
  while (!options.dry_run) {
    // Skip every ready stage that is up to date (which may make more stages
    // ready), then start ready stages while slots are free.
    for (bool progressed = true; progressed && !stop;) {
      progressed = false;
      for (std::size_t i = 0; i < n; ++i) {
        if (!is_ready(i) || checked[i]) continue;
        StageOutcome& outcome = report.stages[i];
        outcome.reason = reason_to_run(i, stamp_now[i]);
        checked[i] = true;
        if (outcome.reason.empty()) {
          phase[i] = Phase::kFinished;
          outcome.status = StageStatus::kSkipped;
          outcome.reason = up_to_date(stamp_now[i]);
          log << plan[i].name << ": skipping — " << outcome.reason << "\n";
          progressed = true;
        }
      }
    }
    if (common::termination_signal() != 0) stop = true;  // forwarded to the running stages
    for (std::size_t i = 0; i < n && running.size() < jobs && !stop; ++i) {
      if (!is_ready(i)) continue;
      const StageStep& step = plan[i];
      StageOutcome& outcome = report.stages[i];
      std::size_t others_ready = 0;
      for (std::size_t k = 0; k < n; ++k) others_ready += k != i && is_ready(k) ? 1 : 0;
      // Alone, a stage streams to the terminal and uses every core; side by
      // side, each writes a log and gets an equal share of the cores
      // (results do not depend on the thread count: docs/scenes.md).
      const bool alone = jobs == 1 || (running.empty() && others_ready == 0);
      const std::size_t together = std::min(jobs, running.size() + 1 + others_ready);
      const int threads =
          alone || user_threads ? 0 : std::max(1, cores / static_cast<int>(together));
      fs::path log_file;
      if (!alone) {
        fs::create_directories(out_dir / "logs");
        log_file = out_dir / "logs" / (step.name + ".log");
      }
      log << step.name << ": running — " << outcome.reason << "\n";
      log_command(step);
      if (!alone) {
        log << "  (side by side with other stages: " << (threads > 0 ? std::to_string(threads) : "OMP_NUM_THREADS")
            << " thread(s); its output goes to " << log_file.string() << ")\n";
      }
      log.flush();
      // A failed or interrupted run must never look up to date.
      std::error_code ec;
      fs::remove(stamp_path(out_dir, step.name), ec);
      common::forward_termination_signals();
      const pid_t pid = launch(options.stage_dir / step.executable, step.arguments, log_file, threads, stamp_now[i].key);
      if (pid > 0) common::register_child(pid);
      phase[i] = Phase::kRunning;
      if (pid < 0) {
        phase[i] = Phase::kFinished;
        outcome.status = StageStatus::kFailed;
        outcome.exit_code = 127;
        outcome.reason = std::string("could not be started: ") + std::strerror(errno);
        fail(i);
        break;
      }
      running.push_back({i, pid, Clock::now(), log_file});
    }
    if (running.empty()) break;

    // Wait for one of the running stages to exit.
    bool exited = false;
    for (std::size_t r = 0; r < running.size(); ++r) {
      int status = 0;
      struct rusage usage {};
      const pid_t got = wait4(running[r].pid, &status, running.size() == 1 && running[r].log_file.empty() ? 0 : WNOHANG,
                              &usage);
      if (got == 0 || (got < 0 && errno == EINTR)) continue;
      if (got < 0) status = 127 << 8;  // not our child any more: report as failed to start
      const Running done = running[r];
      common::unregister_child(done.pid);
      running.erase(running.begin() + static_cast<std::ptrdiff_t>(r));
      finish(done, status, usage);
      exited = true;
      break;
    }
    if (exited) continue;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (Clock::now() - last_heartbeat > std::chrono::seconds(30)) {
      // Stages writing to logs: their latest progress line.
      last_heartbeat = Clock::now();
      for (const Running& r : running) {
        if (r.log_file.empty()) continue;
        const double t = std::chrono::duration<double>(Clock::now() - r.t0).count();
        std::string last = tail_lines(r.log_file, 1, "", true);
        if (!last.empty() && last.back() == '\n') last.pop_back();
        log << "  " << plan[r.index].name << " (" << std::fixed << std::setprecision(0) << t
            << " s): " << (last.empty() ? "started" : last) << "\n";
        log.unsetf(std::ios::floatfield);
      }
      log.flush();
    }
  }
  if (report.status != RunStatus::kOk) {
    log << "arthrosim: error: " << report.message << "\n";
    return report;
  }
  log << "arthrosim: " << (options.dry_run ? "dry run finished:" : "finished:");
  for (const StageOutcome& o : report.stages) {
    log << " " << o.name << " ";
    switch (o.status) {
      case StageStatus::kRan: {
        std::ostringstream t;
        t << std::fixed << std::setprecision(1) << o.wall_time_s;
        log << "ran (" << t.str() << " s)";
        break;
      }
      case StageStatus::kSkipped:
        log << "reused";
        break;
      case StageStatus::kWouldRun:
        log << "would run";
        break;
      case StageStatus::kWouldSkip:
        log << "would be reused";
        break;
      default:
        log << "not run";
    }
    log << (&o == &report.stages.back() ? "" : ",");
  }
  log << "; outputs in " << out_dir.string() << "\n";
  return report;
}

}  // namespace arthrosim::pipelines
