#pragma once
// Safe output files of the stage programs (docs/testing.md, "Crash safety").
//
// 1. An output never overwrites an input: refuse_output_over_inputs() compares
//    the output path with every input the program was given (same file after
//    resolving '..' and symbolic links, or the same inode through a hard link).
// 2. An output is atomic: AtomicOutput hands the writer a temporary name in
//    the output's own folder, "<name>.partial" (same file system, so the final
//    rename is atomic); commit() renames it over the output once the writer has
//    closed it. Until then a previous complete output stays in place, and a
//    killed or failed run leaves only "<name>.partial", a name no stage takes
//    as a complete result.
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace arthrosim::common {

/// One input of a program: its path and how it was given ("--prepared",
/// "the URDF of --model", ...).
struct NamedInput {
  std::filesystem::path path;
  std::string given_as;
};

/// `path` itself when it is a file; the regular files directly inside it
/// (at most 10,000) when it is a folder (a model or trial folder, whose
/// files a program reads).
std::vector<NamedInput> files_of(const std::filesystem::path& path, const std::string& given_as);

/// True when `a` and `b` name the same file: equal after making both absolute
/// and resolving symbolic links and '..', or the same inode (hard links).
/// Paths that do not exist compare by their normalised absolute form.
bool same_file(const std::filesystem::path& a, const std::filesystem::path& b);

/// Throws InputError "<program>: error: <option> <out> is the input <path>
/// (<given_as>); ..." when `out` is the same file as one of `inputs` (empty
/// paths are skipped).
void refuse_output_over_inputs(const std::string& program, const std::string& option,
                               const std::filesystem::path& out, const std::vector<NamedInput>& inputs);

/// The name a partial output is written under: "<out>.partial".
std::filesystem::path partial_name(const std::filesystem::path& out);
/// The inverse: "<out>" for "<out>.partial", any other path unchanged.
std::string complete_name(const std::string& path);

/// Write-then-rename of one output file.
class AtomicOutput {
 public:
  /// Removes a stale "<out>.partial" left by an earlier killed run (the
  /// output itself is not touched).
  explicit AtomicOutput(std::filesystem::path out);
  /// The path to write (in the output's folder).
  const std::filesystem::path& temp() const { return temp_; }
  const std::filesystem::path& out() const { return out_; }
  /// Renames temp() over out() (atomic on POSIX: a reader sees the old or the
  /// new complete file). The writer must have closed temp(). Throws
  /// InputError naming both paths when the rename fails.
  void commit();
  bool committed() const { return committed_; }

 private:
  std::filesystem::path out_, temp_;
  bool committed_ = false;
};

}  // namespace arthrosim::common
