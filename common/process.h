#pragma once
// Process hygiene of a program that runs other programs (the scene runner,
// docs/runner.md "Interrupted runs"):
// - each child runs in a process group of its own and receives SIGTERM when
//   its parent dies, however the parent dies (kill -9 included:
//   PR_SET_PDEATHSIG), so no stage keeps writing after its runner is gone;
// - SIGINT and SIGTERM received by the parent are forwarded to the process
//   group of every running child (forward_termination_signals);
// - the output folder's lock records who holds it; a run that finds the
//   record of a run that did not end cleanly says so (FolderLock).
#include <sys/types.h>

#include <filesystem>
#include <string>

namespace arthrosim::common {

/// In the child between fork() and exec(): only async-signal-safe calls.
/// Puts the child in a process group of its own, asks for SIGTERM when
/// `parent` dies (and exits at once if it already has). Returns false if a
/// call failed (the child may go on).
bool child_after_fork(pid_t parent) noexcept;

/// Installs (once) SIGINT/SIGTERM handlers that forward the signal to the
/// process group of every child registered here and remember it; the
/// program goes on (its children end, it reports them) unless it checks
/// termination_signal(). Async-signal-safe registry of up to 64 children.
void forward_termination_signals();
void register_child(pid_t child) noexcept;
void unregister_child(pid_t child) noexcept;
/// The signal received (SIGINT or SIGTERM), or 0.
int termination_signal() noexcept;

/// An exclusive flock on <dir>/.arthrosim.lock for the lifetime of the
/// object. The descriptor is inherited by children (no FD_CLOEXEC), so the
/// lock is held while any stage of the run is alive, not only the runner.
/// The file records the holder ("pid <n>, started <time>: <command>") while
/// the lock is held and is emptied when the object is destroyed; a record
/// found on taking the lock is that of a run that did not end cleanly
/// (killed, crashed, power loss).
class FolderLock {
 public:
  /// Throws InputError if the lock file cannot be created.
  FolderLock(const std::filesystem::path& dir, const std::string& command);
  ~FolderLock();
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;

  bool locked() const { return locked_; }
  /// When not locked: who holds it, as recorded ("" if not recorded).
  const std::string& holder() const { return holder_; }
  /// When locked: the record of an earlier run that did not end cleanly, or "".
  const std::string& stale() const { return stale_; }
  const std::filesystem::path& file() const { return file_; }

 private:
  std::filesystem::path file_;
  int fd_ = -1;
  bool locked_ = false;
  std::string holder_, stale_;
};

}  // namespace arthrosim::common
