#include "common/process.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <ctime>

#include "common/error.h"

namespace arthrosim::common {

bool child_after_fork(pid_t parent) noexcept {
  bool ok = ::setpgid(0, 0) == 0;
  ok = ::prctl(PR_SET_PDEATHSIG, SIGTERM) == 0 && ok;
  // The parent may have died before prctl: then no signal will come.
  if (::getppid() != parent) ::_exit(128 + SIGTERM);
  return ok;
}

namespace {

constexpr int kMaxChildren = 64;
std::atomic<pid_t> g_children[kMaxChildren];
volatile sig_atomic_t g_signal = 0;

void forward(int sig) {
  g_signal = sig;
  for (auto& c : g_children) {
    const pid_t pid = c.load();
    if (pid > 0) ::kill(-pid, sig);  // its process group (child_after_fork)
  }
}

}  // namespace

void forward_termination_signals() {
  static const bool installed = [] {
    struct sigaction sa {};
    sa.sa_handler = forward;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = 0;  // no SA_RESTART: a blocking wait returns EINTR
    ::sigaction(SIGINT, &sa, nullptr);
    ::sigaction(SIGTERM, &sa, nullptr);
    return true;
  }();
  (void)installed;
}

void register_child(pid_t child) noexcept {
  for (auto& c : g_children) {
    pid_t empty = 0;
    if (c.compare_exchange_strong(empty, child)) break;
  }
  // A signal that arrived while the child was being started.
  if (g_signal != 0) ::kill(-child, g_signal);
}

void unregister_child(pid_t child) noexcept {
  for (auto& c : g_children) {
    pid_t mine = child;
    if (c.compare_exchange_strong(mine, 0)) break;
  }
}

int termination_signal() noexcept { return g_signal; }

FolderLock::FolderLock(const std::filesystem::path& dir, const std::string& command)
    : file_(dir / ".arthrosim.lock") {
  // No O_CLOEXEC: stages inherit the descriptor and with it the lock.
  fd_ = ::open(file_.c_str(), O_RDWR | O_CREAT, 0644);
  if (fd_ < 0) throw InputError(file_.string(), 0, std::string("cannot create the lock file: ") + std::strerror(errno));
  locked_ = ::flock(fd_, LOCK_EX | LOCK_NB) == 0;
  std::string record;
  char buf[1024];
  ssize_t n = 0;
  while ((n = ::pread(fd_, buf, sizeof buf, static_cast<off_t>(record.size()))) > 0 && record.size() < 8192)
    record.append(buf, static_cast<std::size_t>(n));
  while (!record.empty() && (record.back() == '\n' || record.back() == '\0')) record.pop_back();
  if (!locked_) {
    holder_ = record;
    return;
  }
  stale_ = record;
  char when[64];
  const std::time_t now = std::time(nullptr);
  std::strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S", std::localtime(&now));
  const std::string mine = "pid " + std::to_string(::getpid()) + ", started " + when + ": " + command + "\n";
  if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, mine.data(), mine.size(), 0) != static_cast<ssize_t>(mine.size())) {
    // The record is informative only; the lock itself holds.
  }
}

FolderLock::~FolderLock() {
  if (fd_ < 0) return;
  if (locked_) (void)::ftruncate(fd_, 0);  // ended cleanly: nothing stale
  ::close(fd_);
}

}  // namespace arthrosim::common
