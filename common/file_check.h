#pragma once
// What a stage checks of a file another stage wrote before it uses it
// (docs/testing.md, "Crash safety"):
// 1. the kind and version: a file of another kind, or of a format version
//    this build does not read, is an InputError naming the file, what it
//    holds and what was expected;
// 2. completeness: a kinematics file without its run summary (the COMAK run
//    was killed) or with fewer frames than the run set out to solve, or a
//    surface output whose status is not "completed", is refused unless the
//    user allows partial inputs (--allow-partial); then the consumer goes on
//    and puts the returned line at the top of what it reports.
#include <string>

namespace arthrosim::common {

class H5File;

enum class StageFile {
  kKinematics,     ///< arthrosim-comak (docs/kinematics_file.md)
  kPreparedModel,  ///< arthrosim-prepare
  kSurfaceOutput,  ///< arthrosim-surface
};

/// "kinematics file", "prepared model", "surface output".
std::string stage_file_name(StageFile kind);

/// Throws InputError "<path>: error: ..." when `f` is not a `kind` file in
/// the format version this build reads: root attribute format ==
/// "arthrosim kinematics file" with format_version 1; schema == "arthrosim
/// prepared model 1"; schema == "arthrosim surface output 2".
void require_file_format(const H5File& f, const std::string& path, StageFile kind);

/// "" when `f` is complete; otherwise what it holds, e.g. "18 of 21 frames
/// (the run that wrote it did not finish: killed or crashed)".
std::string incompleteness(const H5File& f, StageFile kind);

/// require_file_format, then: complete -> "". Incomplete -> InputError
/// "<path>: error: incomplete <kind>: <what it holds>; ..." naming
/// --allow-partial, or with `allow_partial` a logged warning and the line
/// "PARTIAL INPUT: <path> is an incomplete <kind>: <what it holds>" returned.
std::string require_usable_file(const H5File& f, const std::string& path, StageFile kind, bool allow_partial);

}  // namespace arthrosim::common
