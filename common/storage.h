#pragma once
// OpenSim storage files (.sto, .mot): a header, a tab-separated line of column
// labels, then one row of numbers per time sample.
//
// Two header styles are read and written:
//  - old style (OpenSim <= 3, SIMM):      - OpenSim 4:
//      <name>                                  [<name>]
//      version=1                               inDegrees=no
//      nRows=<rows>                            DataType=double
//      nColumns=<columns incl. time>           version=3
//      inDegrees=yes|no                        OpenSimVersion=4.x
//      endheader                               endheader
//    A file is "old style" when its header has version=1 (or no version key
//    but nRows/nColumns); everything else is OpenSim 4 style. Header lines
//    without '=' after the first (free text such as "Units are S.I. units")
//    and blank lines are accepted and ignored. nRows/nColumns, when present,
//    must match the data (error otherwise). The writer writes version=1
//    (old) or version=3 (OpenSim 4), and nRows/nColumns in both styles.
//  Data rows are split at any whitespace; "nan"/"inf" are accepted as
//  numbers (callers that cannot handle them use check_finite). Blank lines
//  may follow the last row but not separate rows.
//
// Units: inside arthrosim angles are radians. When the file says
// inDegrees=yes, read_storage converts every *rotational* column from degrees
// to radians (speeds deg/s -> rad/s alike); write_storage converts back when
// the table's in_degrees is true. Which columns are rotational is decided by a
// predicate on the label; default_is_rotational() implements the rule below.
#include <Eigen/Core>
#include <functional>
#include <iosfwd>
#include <map>
#include <string>
#include <vector>

namespace arthrosim::common {

enum class StorageStyle { kOld, kOpenSim4 };

struct StorageTable {
  std::string name;                 ///< first header line (may be empty for OpenSim 4)
  std::vector<std::string> labels;  ///< column labels; labels[0] is the time column
  /// rows = time samples, column 0 = time [s]; rotational columns in radians.
  Eigen::MatrixXd data;
  /// Whether the file stores rotational columns in degrees (read: as found in
  /// the header; write: convert radians -> degrees and write inDegrees=yes).
  bool in_degrees = false;
  /// Header keys other than name/version/nRows/nColumns/inDegrees/endheader,
  /// e.g. DataType, OpenSimVersion (written back sorted by key).
  std::map<std::string, std::string> metadata;
  StorageStyle style = StorageStyle::kOpenSim4;
  /// Set by the reader: line number (1-based) of the first data row; rows are
  /// contiguous (blank lines only after the last row), so row r is on line
  /// data_line + r. 0 when there are no rows or the table was not read.
  int data_line = 0;

  int num_rows() const { return static_cast<int>(data.rows()); }
  int num_columns() const { return static_cast<int>(data.cols()); }
  /// Index of a label, -1 if absent.
  int column_index(const std::string& label) const;
  /// Column by label; throws InputError listing the labels if absent.
  Eigen::VectorXd column(const std::string& label) const;
  Eigen::VectorXd time() const { return data.col(0); }
};

/// Decides whether a column holds an angle (or angular speed).
using RotationalPredicate = std::function<bool(const std::string& label)>;

/// Default rule. A label is NOT rotational when, after taking the last path
/// segment of an OpenSim 4 state path (dropping a trailing "/value" or
/// "/speed"), lower-casing and removing a trailing side suffix "_r"/"_l":
///  - it is the time column ("time"), or
///  - it ends in a translation / vector-component suffix: _tx _ty _tz
///    (translational coordinates), _px _py _pz (centre of pressure),
///    _vx _vy _vz (force vectors in GRF files), _fx _fy _fz _mx _my _mz
///    (joint reaction force/moment components), _x _y _z (positions,
///    components), or
///  - it contains one of: force, torque, moment, cop, activation,
///    excitation, length, velocity (non-angle quantities).
/// Every other column is rotational (e.g. knee_angle_r, hip_flexion_l,
/// /jointset/knee_r/knee_angle_r/speed, pelvis_tilt).
bool default_is_rotational(const std::string& label);
/// Predicate: rotational iff the label is in `labels` (exact match).
RotationalPredicate rotational_columns(const std::vector<std::string>& labels);

/// Reads a .sto/.mot file. Errors throw InputError "<file>:<line>: error: ..."
/// (missing endheader, no labels, wrong number of values on a row,
/// non-numeric value, nRows/nColumns not matching the data, missing file).
StorageTable read_storage(const std::string& path,
                          const RotationalPredicate& is_rotational = default_is_rotational);
/// Same from a stream; `source_name` is used as the file name in messages.
StorageTable parse_storage(std::istream& in, const std::string& source_name,
                           const RotationalPredicate& is_rotational = default_is_rotational);

struct StorageWriteOptions {
  /// Significant digits of every value (17 round-trips doubles exactly).
  int precision = 17;
};

/// Writes `table` in its `style`, tab-separated, converting rotational
/// columns to degrees when table.in_degrees. Throws InputError if labels and
/// data columns disagree, std::runtime_error if the file cannot be written.
void write_storage(const std::string& path, const StorageTable& table,
                   const RotationalPredicate& is_rotational = default_is_rotational,
                   const StorageWriteOptions& options = {});
void write_storage(std::ostream& out, const StorageTable& table,
                   const RotationalPredicate& is_rotational = default_is_rotational,
                   const StorageWriteOptions& options = {});

}  // namespace arthrosim::common
