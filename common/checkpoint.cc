#include "common/checkpoint.h"

#include <signal.h>
#include <unistd.h>

#include <cstdlib>

#include "common/hashing.h"

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

}  // namespace arthrosim::common
