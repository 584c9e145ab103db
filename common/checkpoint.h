#pragma once
// Checkpoints of long stages (docs/testing.md, "Checkpoint and resume"): the
// parts every stage shares. A stage writes `<out>.checkpoint` (an HDF5 file of
// its own layout, through AtomicOutput: "<out>.checkpoint.partial", then a
// rename, so a kill leaves the previous checkpoint or the new one, never half
// of one) at an interval of wall time, and on start continues from a
// checkpoint whose identity is its own run's.
#include <Eigen/Core>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "common/output_file.h"

namespace arthrosim::common {

class H5File;

/// "<out>.checkpoint".
std::filesystem::path checkpoint_name(const std::filesystem::path& out);

/// The identity a checkpoint is tied to: SHA-256 of the running program's
/// own bytes (/proc/self/exe: another build never resumes), its command line,
/// the options text the stage runs with, the bytes of every input file (a
/// folder: every regular file directly in it; files_of), and the runner's
/// stage key (environment ARTHROSIM_STAGE_KEY, set by `arthrosim run` for the
/// stages it starts) when set. A checkpoint of another identity is never used.
std::string run_identity(const std::vector<std::string>& argv, const std::string& options_text,
                         const std::vector<NamedInput>& inputs);

/// Wall-time interval between checkpoints: due() is true once interval_s
/// has passed since construction or the last mark() (interval 0: always).
class CheckpointClock {
 public:
  explicit CheckpointClock(double interval_s);
  bool due() const;
  void mark();

 private:
  double interval_s_;
  std::chrono::steady_clock::time_point last_;
};

/// Test hook of the kill tests (tests/pipelines/resume_test.cc): with the
/// environment variable ARTHROSIM_TEST_KILL_AT_CHECKPOINT = "<n>" the process
/// kills itself (SIGKILL) right after its n-th checkpoint of this run is in
/// place; "<n>.partial": after the n-th was written, before its rename. No
/// effect without the variable.
void checkpoint_test_kill(int n, bool before_rename);

/// A history of equal-length vectors (one per frame or step) as the rows of
/// one matrix, the form checkpoints store it in; and back, where
/// std::runtime_error names the dataset `name` unless `M` has `rows` rows.
Eigen::MatrixXd stack_rows(const std::vector<Eigen::VectorXd>& v);
std::vector<Eigen::VectorXd> unstack_rows(const Eigen::MatrixXd& M, std::int64_t rows, const std::string& name);

/// The frame of every checkpoint file: the root attributes format,
/// format_version and identity, the stage's own datasets (`body`), then the
/// atomic rename with the kill tests' hook around it (`sequence`: 1, 2, ...,
/// the checkpoints of this process).
void write_checkpoint(const std::filesystem::path& path, const std::string& format, std::int64_t format_version,
                      const std::string& identity, int sequence, const std::function<void(H5File&)>& body);

/// Reads a checkpoint written by write_checkpoint: checks format and version,
/// then `body` reads the stage's datasets. False with `why` when the file is
/// not one of this format and version or `body` throws (a missing dataset,
/// inconsistent counts). `identity` receives the root attribute.
bool read_checkpoint(const std::filesystem::path& path, const std::string& format, std::int64_t format_version,
                     std::string& identity, std::string& why, const std::function<void(const H5File&)>& body);

/// The decision at a stage's start: resume from `path` when it exists, was
/// read (`read` returns false with a reason otherwise) and its identity is
/// `identity`. Otherwise, when the file exists, warns "not resuming from
/// <path>: <why>; starting over", removes it and returns false.
bool resume_from_checkpoint(const std::filesystem::path& path, const std::string& identity,
                            const std::function<bool(std::string& found_identity, std::string& why)>& read);

}  // namespace arthrosim::common
