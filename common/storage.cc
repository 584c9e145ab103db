// OpenSim .sto/.mot reader and writer (see storage.h for the format rules).
#include "common/storage.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <istream>
#include <numbers>
#include <ostream>
#include <set>
#include <sstream>
#include <string_view>
#include <unordered_map>

#include "common/error.h"

namespace arthrosim::common {
namespace {

std::string trim(const std::string& s) {
  size_t b = 0, e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return s.substr(b, e - b);
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::vector<std::string> split_ws(const std::string& line) {
  std::vector<std::string> out;
  std::istringstream in(line);
  for (std::string t; in >> t;) out.push_back(t);
  return out;
}

// Labels are tab-separated (a label may contain spaces); without any tab the
// line is split at whitespace.
std::vector<std::string> split_labels(const std::string& line) {
  if (line.find('\t') == std::string::npos) return split_ws(line);
  std::vector<std::string> out;
  size_t b = 0;
  while (true) {
    const size_t e = line.find('\t', b);
    const std::string t = trim(line.substr(b, e == std::string::npos ? std::string::npos : e - b));
    if (!t.empty()) out.push_back(t);
    if (e == std::string::npos) break;
    b = e + 1;
  }
  return out;
}

bool parse_int(const std::string& s, long long* out) {
  if (s.empty()) return false;
  errno = 0;
  char* end = nullptr;
  const long long v = std::strtoll(s.c_str(), &end, 10);
  if (errno != 0 || end != s.c_str() + s.size()) return false;
  *out = v;
  return true;
}

bool parse_double(const std::string& s, double* out) {
  if (s.empty()) return false;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size()) return false;
  *out = v;
  return true;
}

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

}  // namespace

int StorageTable::column_index(const std::string& label) const {
  for (size_t i = 0; i < labels.size(); ++i) {
    if (labels[i] == label) return static_cast<int>(i);
  }
  return -1;
}

Eigen::VectorXd StorageTable::column(const std::string& label) const {
  const int i = column_index(label);
  if (i < 0) {
    std::string all;
    for (size_t k = 0; k < labels.size(); ++k) all += (k ? ", " : "") + labels[k];
    throw InputError("storage table '" + name + "': no column '" + label + "' (columns: " + all + ")");
  }
  return data.col(i);
}

bool default_is_rotational(const std::string& label) {
  std::string s = lower(trim(label));
  // OpenSim 4 state paths: /jointset/knee_r/knee_angle_r/value -> knee_angle_r.
  if (s.find('/') != std::string::npos) {
    for (const char* suffix : {"/value", "/speed"}) {
      if (ends_with(s, suffix)) s.erase(s.size() - std::string(suffix).size());
    }
    const size_t slash = s.rfind('/');
    if (slash != std::string::npos) s = s.substr(slash + 1);
  }
  if (s == "time") return false;
  if (ends_with(s, "_r") || ends_with(s, "_l")) s.erase(s.size() - 2);
  static const char* const kSuffixes[] = {"_tx", "_ty", "_tz", "_px", "_py", "_pz", "_vx", "_vy", "_vz",
                                          "_fx", "_fy", "_fz", "_mx", "_my", "_mz", "_x",  "_y",  "_z"};
  for (const char* suffix : kSuffixes) {
    if (ends_with(s, suffix)) return false;
  }
  static const char* const kWords[] = {"force",      "torque", "moment", "cop",
                                       "activation", "excitation", "length", "velocity"};
  for (const char* w : kWords) {
    if (s.find(w) != std::string::npos) return false;
  }
  return true;
}

RotationalPredicate rotational_columns(const std::vector<std::string>& labels) {
  std::set<std::string> set(labels.begin(), labels.end());
  return [set](const std::string& label) { return set.count(label) > 0; };
}

StorageTable parse_storage(std::istream& in, const std::string& source, const RotationalPredicate& is_rotational) {
  StorageTable table;
  int line_no = 0;
  std::string line;
  auto next_line = [&]() -> bool {
    if (!std::getline(in, line)) return false;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  };
  auto fail = [&](int at, const std::string& message) -> void { throw InputError(source, at, message); };

  // ---- header ----
  bool end_header = false;
  bool have_version = false;
  int version = 0;
  long long n_rows = -1, n_columns = -1;
  int n_rows_line = 0, n_columns_line = 0;
  bool first = true;
  while (next_line()) {
    const std::string t = trim(line);
    if (lower(t) == "endheader") {
      end_header = true;
      break;
    }
    const size_t eq = t.find('=');
    if (eq == std::string::npos) {
      // The first line is the name; later lines without '=' are free text.
      if (first && !t.empty()) table.name = t;
      if (!t.empty()) first = false;
      continue;
    }
    first = false;
    const std::string key = trim(t.substr(0, eq));
    const std::string value = trim(t.substr(eq + 1));
    const std::string k = lower(key);
    long long iv = 0;
    if (k == "version") {
      if (!parse_int(value, &iv)) fail(line_no, "expected an integer version, found '" + value + "'");
      have_version = true;
      version = static_cast<int>(iv);
    } else if (k == "nrows" || k == "ncolumns") {
      if (!parse_int(value, &iv) || iv < 0) fail(line_no, "expected a count for " + key + ", found '" + value + "'");
      (k == "nrows" ? n_rows : n_columns) = iv;
      (k == "nrows" ? n_rows_line : n_columns_line) = line_no;
    } else if (k == "indegrees") {
      const std::string v = lower(value);
      if (v == "yes" || v == "true") {
        table.in_degrees = true;
      } else if (v == "no" || v == "false") {
        table.in_degrees = false;
      } else {
        fail(line_no, "expected inDegrees=yes or inDegrees=no, found inDegrees=" + value);
      }
    } else {
      table.metadata[key] = value;
    }
  }
  if (!end_header) fail(line_no, "expected a line 'endheader' closing the header, found the end of the file");
  table.style = (have_version ? version == 1 : (n_rows >= 0 || n_columns >= 0)) ? StorageStyle::kOld
                                                                               : StorageStyle::kOpenSim4;

  // ---- column labels ----
  int labels_line = 0;
  while (next_line()) {
    if (!trim(line).empty()) {
      labels_line = line_no;
      break;
    }
  }
  if (labels_line == 0) fail(line_no, "expected a line of column labels after endheader, found the end of the file");
  table.labels = split_labels(line);
  const size_t n_cols = table.labels.size();
  // Hashed (linear in the number of columns: a damaged file can hold a
  // "label line" of a million words).
  std::unordered_map<std::string_view, size_t> first_column;
  for (size_t i = 0; i < n_cols; ++i) {
    const auto [it, added] = first_column.emplace(table.labels[i], i);
    if (!added) {
      fail(labels_line, "duplicate column label '" + table.labels[i] + "' (columns " + std::to_string(it->second + 1) +
                            " and " + std::to_string(i + 1) + ")");
    }
  }

  // ---- data rows ----
  std::vector<double> values;
  int rows = 0;
  int blank_line = 0;  // first blank line after the last row read
  while (next_line()) {
    const std::vector<std::string> tokens = split_ws(line);
    if (tokens.empty()) {
      // Trailing blank lines are allowed; blank lines between rows are not,
      // so that row r is always on line data_line + r.
      if (blank_line == 0) blank_line = line_no;
      continue;
    }
    if (blank_line != 0) fail(blank_line, "expected a data row, found a blank line between data rows");
    if (rows == 0) table.data_line = line_no;
    if (tokens.size() != n_cols) {
      fail(line_no, "expected " + std::to_string(n_cols) + " values (one per column label), found " +
                        std::to_string(tokens.size()));
    }
    for (size_t c = 0; c < n_cols; ++c) {
      double v = 0.0;
      if (!parse_double(tokens[c], &v)) {
        fail(line_no, "expected a number in column " + std::to_string(c + 1) + " ('" + table.labels[c] +
                          "'), found '" + tokens[c] + "'");
      }
      values.push_back(v);
    }
    ++rows;
  }
  if (n_rows >= 0 && n_rows != rows) {
    fail(n_rows_line, "nRows=" + std::to_string(n_rows) + " but the file has " + std::to_string(rows) + " data rows");
  }
  if (n_columns >= 0 && n_columns != static_cast<long long>(n_cols)) {
    fail(n_columns_line, "nColumns=" + std::to_string(n_columns) + " but the file has " + std::to_string(n_cols) +
                             " column labels");
  }
  table.data = Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
      values.data(), rows, static_cast<Eigen::Index>(n_cols));

  // ---- units: degrees -> radians for rotational columns ----
  if (table.in_degrees) {
    for (size_t c = 1; c < n_cols; ++c) {
      if (is_rotational(table.labels[c])) table.data.col(static_cast<Eigen::Index>(c)) *= kDegToRad;
    }
  }
  return table;
}

StorageTable read_storage(const std::string& path, const RotationalPredicate& is_rotational) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, 0, "cannot open the file for reading");
  return parse_storage(in, path, is_rotational);
}

void write_storage(std::ostream& out, const StorageTable& table, const RotationalPredicate& is_rotational,
                   const StorageWriteOptions& options) {
  const Eigen::Index n_cols = static_cast<Eigen::Index>(table.labels.size());
  if (table.data.cols() != n_cols) {
    throw InputError("storage table '" + table.name + "': " + std::to_string(table.labels.size()) +
                     " labels but " + std::to_string(table.data.cols()) + " data columns");
  }
  for (const auto& l : table.labels) {
    if (l.empty() || l.find_first_of("\t\n\r") != std::string::npos) {
      throw InputError("storage table '" + table.name + "': column label '" + l +
                       "' is empty or contains a tab or line break");
    }
  }
  const char* yes_no = table.in_degrees ? "yes" : "no";
  if (table.style == StorageStyle::kOld) {
    out << (table.name.empty() ? std::string("arthrosim") : table.name) << "\n";
    out << "version=1\n";
    out << "nRows=" << table.data.rows() << "\n";
    out << "nColumns=" << n_cols << "\n";
    out << "inDegrees=" << yes_no << "\n";
    for (const auto& [k, v] : table.metadata) out << k << "=" << v << "\n";
  } else {
    if (!table.name.empty()) out << table.name << "\n";
    out << "version=3\n";
    out << "nRows=" << table.data.rows() << "\n";
    out << "nColumns=" << n_cols << "\n";
    out << "inDegrees=" << yes_no << "\n";
    if (!table.metadata.count("DataType")) out << "DataType=double\n";
    for (const auto& [k, v] : table.metadata) out << k << "=" << v << "\n";
  }
  out << "endheader\n";
  for (Eigen::Index c = 0; c < n_cols; ++c) out << (c ? "\t" : "") << table.labels[c];
  out << "\n";
  std::vector<double> scale(n_cols, 1.0);
  if (table.in_degrees) {
    for (Eigen::Index c = 1; c < n_cols; ++c) {
      if (is_rotational(table.labels[c])) scale[c] = kRadToDeg;
    }
  }
  char buf[40];
  for (Eigen::Index r = 0; r < table.data.rows(); ++r) {
    for (Eigen::Index c = 0; c < n_cols; ++c) {
      std::snprintf(buf, sizeof buf, "%.*g", options.precision, table.data(r, c) * scale[c]);
      if (c) out << '\t';
      out << buf;
    }
    out << "\n";
  }
}

void write_storage(const std::string& path, const StorageTable& table, const RotationalPredicate& is_rotational,
                   const StorageWriteOptions& options) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw std::runtime_error(path + ": error: cannot open the file for writing");
  write_storage(out, table, is_rotational, options);
  out.close();
  if (!out) throw std::runtime_error(path + ": error: writing failed");
}

}  // namespace arthrosim::common
