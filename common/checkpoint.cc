#include "common/checkpoint.h"

#include <signal.h>
#include <unistd.h>

#include <cstdlib>

#include <exception>
#include <stdexcept>

#include "common/hashing.h"
#include "common/hdf5.h"
#include "common/log.h"

namespace arthrosim::common {
namespace fs = std::filesystem;

fs::path checkpoint_name(const fs::path& out) { return fs::path(out.string() + ".checkpoint"); }

std::string run_identity(const std::vector<std::string>& argv, const std::string& options_text,
                         const std::vector<NamedInput>& inputs) {
  std::string text = "arthrosim checkpoint identity v1\nprogram\t" + sha256_file("/proc/self/exe") + "\n";
  for (const std::string& a : argv) text += "argument\t" + a + "\n";
  text += "options\t" + sha256_hex(options_text) + "\n";
  for (const NamedInput& in : inputs) {
    if (in.path.empty()) continue;
    for (const NamedInput& f : files_of(in.path, in.given_as)) {
      std::error_code ec;
      text += "input\t" + f.given_as + "\t" + f.path.string() + "\t" +
              (fs::is_regular_file(f.path, ec) ? sha256_file(f.path) : std::string("(none)")) + "\n";
    }
  }
  if (const char* key = std::getenv("ARTHROSIM_STAGE_KEY"); key != nullptr) text += "stage key\t" + std::string(key) + "\n";
  return sha256_hex(text);
}

CheckpointClock::CheckpointClock(double interval_s)
    : interval_s_(interval_s), last_(std::chrono::steady_clock::now()) {}

bool CheckpointClock::due() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - last_).count() >= interval_s_;
}

void CheckpointClock::mark() { last_ = std::chrono::steady_clock::now(); }

void checkpoint_test_kill(int n, bool before_rename) {
  const char* at = std::getenv("ARTHROSIM_TEST_KILL_AT_CHECKPOINT");
  if (at == nullptr) return;
  const std::string want = std::to_string(n) + (before_rename ? ".partial" : "");
  if (want == at) ::kill(::getpid(), SIGKILL);
}

Eigen::MatrixXd stack_rows(const std::vector<Eigen::VectorXd>& v) {
  Eigen::MatrixXd M(static_cast<Eigen::Index>(v.size()), v.empty() ? 0 : v.front().size());
  for (size_t i = 0; i < v.size(); ++i) M.row(static_cast<Eigen::Index>(i)) = v[i].transpose();
  return M;
}

std::vector<Eigen::VectorXd> unstack_rows(const Eigen::MatrixXd& M, std::int64_t rows, const std::string& name) {
  if (M.rows() != rows)
    throw std::runtime_error(name + ": expected " + std::to_string(rows) + " rows, found " + std::to_string(M.rows()));
  std::vector<Eigen::VectorXd> v;
  v.reserve(static_cast<size_t>(M.rows()));
  for (Eigen::Index i = 0; i < M.rows(); ++i) v.push_back(M.row(i).transpose());
  return v;
}

void write_checkpoint(const fs::path& path, const std::string& format, std::int64_t format_version,
                      const std::string& identity, int sequence, const std::function<void(H5File&)>& body) {
  AtomicOutput atomic(path);
  {
    H5File f(atomic.temp().string(), H5File::Mode::kTruncate);
    f.set_attribute("/", "format", format);
    f.set_attribute("/", "format_version", format_version);
    f.set_attribute("/", "identity", identity);
    body(f);
    f.flush();
  }
  checkpoint_test_kill(sequence, true);
  atomic.commit();
  checkpoint_test_kill(sequence, false);
}

bool read_checkpoint(const fs::path& path, const std::string& format, std::int64_t format_version,
                     std::string& identity, std::string& why, const std::function<void(const H5File&)>& body) {
  try {
    const H5File f(path.string(), H5File::Mode::kRead);
    if (!f.has_attribute("/", "format") || f.attribute_string("/", "format") != format) {
      why = "not an " + format;
      return false;
    }
    if (f.attribute_int("/", "format_version") != format_version) {
      why = "format_version " + std::to_string(f.attribute_int("/", "format_version")) + " (this build writes " +
            std::to_string(format_version) + ")";
      return false;
    }
    identity = f.attribute_string("/", "identity");
    body(f);
    return true;
  } catch (const std::exception& e) {
    why = e.what();
    return false;
  }
}

bool resume_from_checkpoint(const fs::path& path, const std::string& identity,
                            const std::function<bool(std::string& found_identity, std::string& why)>& read) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return false;
  std::string found, why;
  const bool ok = read(found, why);
  if (ok && found == identity) return true;
  if (ok) why = "it belongs to another run (inputs, options, command line or build differ)";
  log_warn("not resuming from " + path.string() + ": " + why + "; starting over");
  fs::remove(path, ec);
  return false;
}

}  // namespace arthrosim::common
