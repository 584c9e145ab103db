#include "musculoskeletal/gait_trial.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>

#include "common/error.h"
#include "common/storage.h"
#include "musculoskeletal/external_loads.h"

namespace arthrosim::musculoskeletal {

using common::InputError;

const std::vector<std::string>& trial_coordinate_names() {
  static const std::vector<std::string> names = {
      "pelvis_tilt", "pelvis_list", "pelvis_rotation", "pelvis_tx", "pelvis_ty", "pelvis_tz",
      "hip_flexion", "hip_adduction", "hip_rotation", "knee_flexion", "ankle_flexion"};
  return names;
}

namespace {

const std::vector<std::string> kGrfQuantities = {
    "grf_force_x", "grf_force_y", "grf_force_z", "grf_cop_x",    "grf_cop_y",
    "grf_cop_z",   "grf_torque_x", "grf_torque_y", "grf_torque_z"};
const std::vector<std::string> kKneeLoadQuantities = {"knee_force_x",  "knee_force_y",
                                                      "knee_force_z",  "knee_moment_x",
                                                      "knee_moment_y", "knee_moment_z"};
const std::vector<std::string> kLegKeys = {"thigh_length_m", "shank_length_m", "ankle_height_m",
                                           "foot_length_m",  "hip_x_m",        "hip_y_m",
                                           "hip_z_m"};
constexpr const char* kLabFrame = "opensim_x_forward_y_up_z_right";
// Most samples a trial may have on its uniform grid (2.8 hours at 100 Hz).
constexpr double kMaxTrialSamples = 1e6;

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

std::string join(const std::vector<std::string>& v) {
  std::string out;
  for (const auto& s : v) out += (out.empty() ? "" : ", ") + s;
  return out;
}

bool is_angle_quantity(const std::string& q) {
  return q.rfind("pelvis_t", 0) != 0 || q == "pelvis_tilt";
}

double parse_number(const std::string& value, const std::string& file, int line,
                    const std::string& key) {
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != value.size() || !std::isfinite(v)) {
    throw InputError(file, line, "expected a finite number for '" + key + "', found '" + value + "'");
  }
  return v;
}

}  // namespace

TrialDescription parse_trial_description(std::istream& in, const std::string& source_name,
                                         const std::string& directory) {
  TrialDescription d;
  d.path = source_name;
  std::set<std::string> quantities(trial_coordinate_names().begin(), trial_coordinate_names().end());
  quantities.insert(kGrfQuantities.begin(), kGrfQuantities.end());
  quantities.insert(kKneeLoadQuantities.begin(), kKneeLoadQuantities.end());
  const std::set<std::string> plain_keys = {"synthetic", "periodic", "description", "subject_mass_kg",
                                            "subject_height_m", "side",           "lab_frame",
                                            "kinematics_file",  "grf_file",       "knee_loads_file",
                                            "external_loads_file", "foot_body"};
  auto resolve = [&](const std::string& f) {
    const std::filesystem::path p(f);
    return (p.is_absolute() || directory.empty()) ? p.string()
                                                  : (std::filesystem::path(directory) / p).string();
  };
  std::string raw;
  int line = 0;
  while (std::getline(in, raw)) {
    ++line;
    // A '#' at the start or after a blank starts a comment.
    std::string s = raw;
    for (std::size_t i = 0; i < s.size(); ++i) {
      if (s[i] == '#' && (i == 0 || s[i - 1] == ' ' || s[i - 1] == '\t')) {
        s.resize(i);
        break;
      }
    }
    if (trim(s).empty()) continue;
    if (s[0] == ' ' || s[0] == '\t' || trim(s)[0] == '-') {
      throw InputError(source_name, line,
                       "expected a flat 'key: value' line (nested YAML and lists are not "
                       "supported; write e.g. 'column.knee_flexion: knee_angle_r'), found '" +
                           trim(raw) + "'");
    }
    const auto colon = s.find(':');
    if (colon == std::string::npos) {
      throw InputError(source_name, line, "expected 'key: value', found '" + trim(raw) + "'");
    }
    const std::string key = trim(s.substr(0, colon));
    std::string value = trim(s.substr(colon + 1));
    if (value.size() >= 2 && (value.front() == '"' || value.front() == '\'') &&
        value.back() == value.front()) {
      value = value.substr(1, value.size() - 2);
    }
    if (value.empty()) {
      throw InputError(source_name, line,
                       "expected a value after '" + key + ":' (nested YAML is not supported)");
    }
    if (d.key_lines.count(key)) {
      throw InputError(source_name, line,
                       "duplicate key '" + key + "' (first on line " +
                           std::to_string(d.key_lines[key]) + ")");
    }
    d.key_lines[key] = line;
    if (key.rfind("column.", 0) == 0) {
      const std::string q = key.substr(7);
      if (!quantities.count(q)) {
        throw InputError(source_name, line,
                         "unknown quantity '" + q + "' in '" + key + "'; expected one of: " +
                             join(std::vector<std::string>(quantities.begin(), quantities.end())));
      }
      ColumnMapping m;
      m.line = line;
      m.label = value;
      if (value[0] == '-') {
        m.sign = -1.0;
        m.label = trim(value.substr(1));
      }
      if (m.label.empty()) throw InputError(source_name, line, "expected a column label after '-'");
      d.columns[q] = m;
    } else if (key.rfind("leg.", 0) == 0) {
      const std::string k = key.substr(4);
      if (std::find(kLegKeys.begin(), kLegKeys.end(), k) == kLegKeys.end()) {
        throw InputError(source_name, line,
                         "unknown leg geometry key '" + key + "'; expected leg. followed by one of: " +
                             join(kLegKeys));
      }
      d.leg_overrides[k] = parse_number(value, source_name, line, key);
    } else if (!plain_keys.count(key)) {
      throw InputError(source_name, line,
                       "unknown key '" + key + "'; expected one of: " +
                           join(std::vector<std::string>(plain_keys.begin(), plain_keys.end())) +
                           ", column.<quantity>, leg.<geometry>");
    } else if (key == "synthetic" || key == "periodic") {
      if (value != "true" && value != "false") {
        throw InputError(source_name, line,
                         "expected true or false for '" + key + "', found '" + value + "'");
      }
      (key == "synthetic" ? d.synthetic : d.periodic) = value == "true";
    } else if (key == "description") {
      d.description = value;
    } else if (key == "subject_mass_kg" || key == "subject_height_m") {
      const double v = parse_number(value, source_name, line, key);
      const bool mass = key == "subject_mass_kg";
      if (mass ? !(v >= 10 && v <= 300) : !(v >= 0.5 && v <= 2.5)) {
        throw InputError(source_name, line,
                         "expected " + std::string(mass ? "10 <= mass <= 300 kg" : "0.5 <= height <= 2.5 m") +
                             " for '" + key + "', found " + value);
      }
      (mass ? d.subject_mass_kg : d.subject_height_m) = v;
    } else if (key == "side") {
      if (value != "right" && value != "left") {
        throw InputError(source_name, line, "expected right or left for 'side', found '" + value + "'");
      }
      d.side = value == "right" ? Side::kRight : Side::kLeft;
    } else if (key == "lab_frame") {
      if (value != kLabFrame) {
        throw InputError(source_name, line,
                         std::string("expected lab_frame: ") + kLabFrame +
                             " (the only supported convention; rotate the data first), found '" +
                             value + "'");
      }
    } else if (key == "kinematics_file") {
      d.kinematics_file = resolve(value);
    } else if (key == "grf_file") {
      d.grf_file = resolve(value);
    } else if (key == "knee_loads_file") {
      d.knee_loads_file = resolve(value);
    } else if (key == "external_loads_file") {
      d.external_loads_file = resolve(value);
    } else if (key == "foot_body") {
      d.foot_body = value;
    }
  }
  const int end_line = line;
  auto require = [&](const std::string& key) {
    if (!d.key_lines.count(key)) {
      throw InputError(source_name, end_line, "missing required key '" + key + "'");
    }
  };
  for (const char* k : {"side", "lab_frame", "kinematics_file"}) require(k);
  if (d.grf_file.empty() && d.knee_loads_file.empty() && d.external_loads_file.empty()) {
    throw InputError(source_name, end_line,
                     "expected grf_file, knee_loads_file or external_loads_file, found none");
  }
  if (!d.grf_file.empty() && !d.external_loads_file.empty()) {
    throw InputError(source_name, d.key_lines["external_loads_file"],
                     "expected either grf_file or external_loads_file, found both (grf_file on line " +
                         std::to_string(d.key_lines["grf_file"]) + ")");
  }
  if (!d.foot_body.empty() && d.external_loads_file.empty()) {
    throw InputError(source_name, d.key_lines["foot_body"],
                     "foot_body names a body of the external_loads_file, found no external_loads_file");
  }
  // Without an ExternalLoads file the generic leg chain is the only way to
  // use the trial, and it needs the five joint angles (and the stature).
  if (d.external_loads_file.empty()) {
    for (const char* k : {"subject_mass_kg", "subject_height_m"}) require(k);
    for (const char* q : {"hip_flexion", "hip_adduction", "hip_rotation", "knee_flexion", "ankle_flexion"})
      require(std::string("column.") + q);
  }
  int pelvis = 0;
  for (int c = kPelvisTilt; c <= kPelvisTz; ++c) pelvis += d.columns.count(trial_coordinate_names()[c]);
  if (pelvis != 0 && pelvis != 6) {
    throw InputError(source_name, end_line,
                     "expected all six pelvis columns (column.pelvis_tilt ... column.pelvis_tz) or "
                     "none, found " + std::to_string(pelvis));
  }
  auto require_all = [&](const std::vector<std::string>& qs, const std::string& file_key) {
    for (const auto& q : qs) {
      if (!d.columns.count(q)) {
        throw InputError(source_name, d.key_lines[file_key],
                         "'" + file_key + "' needs column." + q + " (missing)");
      }
    }
  };
  if (!d.grf_file.empty()) require_all(kGrfQuantities, "grf_file");
  if (!d.knee_loads_file.empty()) require_all(kKneeLoadQuantities, "knee_loads_file");
  return d;
}

TrialDescription read_trial_description(const std::string& given) {
  // A folder stands for the trial.yaml inside it (scenes name a trial folder).
  const std::string path = std::filesystem::is_directory(given)
                               ? (std::filesystem::path(given) / "trial.yaml").string()
                               : given;
  std::ifstream in(path);
  if (!in) throw InputError(path, 0, "cannot open the trial description");
  return parse_trial_description(in, path, std::filesystem::path(path).parent_path().string());
}

namespace {

// Line number (1-based) of the column-label line of a storage file: the line
// after "endheader". Data row r (0-based) is then on line offset + 1 + r (the
// reader accepts no blank lines among the data). Used only to put line
// numbers in messages about values the reader accepted (time order, NaN).
int label_line(const std::string& file) {
  std::ifstream in(file);
  std::string s;
  int line = 0;
  while (std::getline(in, s)) {
    ++line;
    if (trim(s) == "endheader") return line + 1;
  }
  return 0;
}

struct LoadedTable {
  Eigen::VectorXd time;
  Eigen::MatrixXd values;  // columns in the order of `quantities`, signs applied
};

// A non-finite value met while reading (truncate_at_non_finite).
struct BadValue {
  double time = 0.0;         // [s] of the bad row
  double last_good = 0.0;    // [s] of the row before it
  double file_end = 0.0;     // [s] of the file's last row (rows after the bad one unchecked)
  std::string file;
  int line = 0;
  std::string message;       // "non-finite value in column ..."
  std::string reason() const { return file + ":" + std::to_string(line) + ": " + message; }
};

// Reads the mapped columns of `file`. A non-finite value throws InputError
// unless `bad` is given: then the table ends before that row and *bad says
// where (a bad value in the first row still throws: nothing to keep).
LoadedTable load_columns(const TrialDescription& d, const std::string& file,
                         const std::vector<std::string>& quantities, bool angles_possible,
                         std::optional<BadValue>* bad = nullptr,
                         const common::StorageTable* pre_read = nullptr) {
  // Angle columns are exactly the mapped angle quantities; the rest keep the
  // storage reader's default rule (translations, forces, ... are not angles).
  std::set<std::string> angle_labels;
  if (angles_possible) {
    for (const auto& q : quantities) {
      auto it = d.columns.find(q);
      if (it != d.columns.end() && is_angle_quantity(q)) angle_labels.insert(it->second.label);
    }
  }
  std::set<std::string> mapped;
  for (const auto& q : quantities) {
    auto it = d.columns.find(q);
    if (it != d.columns.end()) mapped.insert(it->second.label);
  }
  common::RotationalPredicate pred = [angle_labels, mapped, angles_possible](const std::string& l) {
    if (!angles_possible) return false;
    if (angle_labels.count(l)) return true;
    if (mapped.count(l)) return false;
    return common::default_is_rotational(l);
  };
  const common::StorageTable table = pre_read ? *pre_read : common::read_storage(file, pred);
  LoadedTable out;
  out.time = table.time();
  out.values.resize(table.num_rows(), static_cast<Eigen::Index>(quantities.size()));
  for (std::size_t k = 0; k < quantities.size(); ++k) {
    auto it = d.columns.find(quantities[k]);
    if (it == d.columns.end()) {
      out.values.col(k).setZero();
      continue;
    }
    const int c = table.column_index(it->second.label);
    if (c < 0) {
      std::vector<std::string> labels(table.labels.begin(), table.labels.end());
      throw InputError(d.path, it->second.line,
                       "column '" + it->second.label + "' (for " + quantities[k] + ") not found in " +
                           file + "; its columns are: " + join(labels));
    }
    out.values.col(k) = it->second.sign * table.data.col(c);
  }
  const int labels_at = label_line(file);
  auto line_of = [&](Eigen::Index r) { return labels_at > 0 ? labels_at + 1 + static_cast<int>(r) : 0; };
  if (out.time.size() < 2) {
    throw InputError(file, line_of(out.time.size()),
                     "expected at least 2 data rows (a time series), found " + std::to_string(out.time.size()));
  }
  for (Eigen::Index r = 0; r < out.values.rows(); ++r) {
    if (!std::isfinite(out.time(r))) throw InputError(file, line_of(r), "non-finite time");
    if (r > 0 && !(out.time(r) > out.time(r - 1))) {
      std::ostringstream s;
      s << "time must increase strictly, found " << out.time(r) << " s after " << out.time(r - 1) << " s";
      throw InputError(file, line_of(r), s.str());
    }
    for (Eigen::Index k = 0; k < out.values.cols(); ++k) {
      if (!std::isfinite(out.values(r, k))) {
        std::ostringstream s;
        s << "non-finite value in column '" << d.columns.at(quantities[k]).label << "' (time "
          << out.time(r) << " s)";
        if (!bad || r == 0) throw InputError(file, line_of(r), s.str());
        *bad = BadValue{out.time(r), out.time(r - 1), out.time(out.time.size() - 1), file, line_of(r),
                        s.str()};
        // Rows r.. are dropped (their times were checked up to here only).
        out.time.conservativeResize(r);
        out.values.conservativeResize(r, Eigen::NoChange);
        return out;
      }
    }
  }
  return out;
}

}  // namespace

GaitTrial load_gait_trial(const TrialDescription& d, const GaitTrialOptions& options) {
  if (!(options.rate_hz > 0)) {
    throw InputError(d.path, 0, "load_gait_trial: rate_hz must be > 0, found " +
                                    std::to_string(options.rate_hz));
  }
  GaitTrial t;
  t.source = d.path;
  t.synthetic = d.synthetic;
  t.periodic = d.periodic;
  t.body_mass_kg = d.subject_mass_kg;
  t.height_m = d.subject_height_m;
  t.side = d.side;
  t.rate_hz = options.rate_hz;
  t.leg_overrides = d.leg_overrides;
  t.has_pelvis = d.columns.count("pelvis_tilt") > 0;
  t.has_joint_angles = true;
  for (const char* q : {"hip_flexion", "hip_adduction", "hip_rotation", "knee_flexion", "ankle_flexion"})
    t.has_joint_angles = t.has_joint_angles && d.columns.count(q) > 0;

  // With truncate_at_non_finite each file reports its first bad value; the
  // trial then ends at the earliest one (`bad`), in every file.
  std::optional<BadValue> bad_kin, bad_grf, bad_loads;
  const bool truncate = options.truncate_at_non_finite;
  const LoadedTable kin = load_columns(d, d.kinematics_file, trial_coordinate_names(), true,
                                       truncate ? &bad_kin : nullptr);
  std::optional<LoadedTable> grf, loads;
  if (!d.grf_file.empty())
    grf = load_columns(d, d.grf_file, kGrfQuantities, false, truncate ? &bad_grf : nullptr);
  if (!d.knee_loads_file.empty())
    loads = load_columns(d, d.knee_loads_file, kKneeLoadQuantities, false,
                         truncate ? &bad_loads : nullptr);
  // An ExternalLoads file: every force's columns (force, point, torque; 9
  // per force, zero where an identifier is empty) through the same reader,
  // mapped as "ext.<force>.<k>" quantities of a description of its own.
  std::optional<ExternalLoadsSpec> ext_spec;
  std::optional<LoadedTable> ext;
  std::optional<BadValue> bad_ext;
  if (!d.external_loads_file.empty()) {
    ext_spec = read_external_loads(d.external_loads_file);
    const common::StorageTable table =
        common::read_storage(ext_spec->datafile, [](const std::string&) { return false; });
    TrialDescription dx;
    dx.path = d.external_loads_file;
    std::vector<std::string> quantities;
    for (std::size_t f = 0; f < ext_spec->forces.size(); ++f) {
      const ExternalForceSpec& fs = ext_spec->forces[f];
      const std::string* ids[3] = {&fs.force_identifier, &fs.point_identifier, &fs.torque_identifier};
      const int lines[3] = {fs.force_line, fs.point_line, fs.torque_line};
      for (int part = 0; part < 3; ++part) {
        std::array<int, 3> cols = {-1, -1, -1};
        if (!ids[part]->empty())
          cols = identifier_columns(table.labels, *ids[part], ext_spec->datafile, d.external_loads_file,
                                    lines[part]);
        for (int k = 0; k < 3; ++k) {
          const std::string q = "ext." + std::to_string(f) + "." + std::to_string(3 * part + k);
          quantities.push_back(q);
          if (cols[k] >= 0) dx.columns[q] = ColumnMapping{table.labels[cols[k]], 1.0, lines[part]};
        }
      }
    }
    ext = load_columns(dx, ext_spec->datafile, quantities, false, truncate ? &bad_ext : nullptr, &table);
  }
  std::optional<BadValue> bad;
  for (const auto* b : {&bad_kin, &bad_grf, &bad_loads, &bad_ext})
    if (*b && (!bad || (*b)->last_good < bad->last_good)) bad = **b;

  // Common time range (and, for a truncated trial, the range without the cut).
  double t0 = kin.time(0), t1 = kin.time(kin.time.size() - 1);
  for (const auto* tab : {grf ? &*grf : nullptr, loads ? &*loads : nullptr, ext ? &*ext : nullptr}) {
    if (!tab) continue;
    t0 = std::max(t0, tab->time(0));
    t1 = std::min(t1, tab->time(tab->time.size() - 1));
  }
  // Bounded work: a time column in the wrong unit or a damaged time value
  // (1e6 s, 1e300 s) would make the uniform grid need gigabytes or overflow
  // its size.
  auto check_grid = [&](double a, double b) {
    if (!((b - a) * options.rate_hz <= kMaxTrialSamples)) {
      std::ostringstream s;
      s << "the time range common to the trial's files, [" << a << ", " << b << "] s, needs "
        << (b - a) * options.rate_hz << " samples at " << options.rate_hz << " Hz; expected at most "
        << kMaxTrialSamples << " (times in seconds?)";
      throw InputError(d.path, 0, s.str());
    }
  };
  check_grid(t0, t1);
  if (bad) {
    // The grid of the whole trial had the value been finite (for the frame
    // selection; its rows after the bad value are not checked).
    double t1_full = bad_kin ? bad_kin->file_end : kin.time(kin.time.size() - 1);
    if (grf) t1_full = std::min(t1_full, bad_grf ? bad_grf->file_end : grf->time(grf->time.size() - 1));
    if (loads)
      t1_full = std::min(t1_full, bad_loads ? bad_loads->file_end
                                            : loads->time(loads->time.size() - 1));
    if (ext)
      t1_full = std::min(t1_full, bad_ext ? bad_ext->file_end : ext->time(ext->time.size() - 1));
    const Eigen::Index kept = t1 >= t0 ? uniform_grid(t0, t1, options.rate_hz).size() : 0;
    check_grid(t0, t1_full);
    const Eigen::Index full = t1_full >= t0 ? uniform_grid(t0, t1_full, options.rate_hz).size() : 0;
    if (kept < full) {  // else the bad value lies outside the common time range
      if (kept < 4)
        throw InputError(bad->file, bad->line, bad->message + "; fewer than 4 samples before it");
      TrialTruncation cut;
      cut.frame = static_cast<int>(kept);
      cut.time = t0 + static_cast<double>(kept) / options.rate_hz;
      cut.full_samples = static_cast<int>(full);
      cut.reason = bad->reason();
      t.truncated = cut;
    }
  }
  if (!(t1 > t0)) {
    std::ostringstream s;
    s << "the kinematics and load files share no time range (common range [" << t0 << ", " << t1
      << "] s)";
    throw InputError(d.path, 0, s.str());
  }
  t.time = uniform_grid(t0, t1, options.rate_hz);
  if (t.time.size() < 4) {
    throw InputError(d.path, 0, "fewer than 4 samples at " + std::to_string(options.rate_hz) +
                                    " Hz in the common time range");
  }
  const double h = 1.0 / options.rate_hz;
  const Eigen::Index last = kin.time.size() - 1;
  // A truncated trial is no longer one cycle: filter and differentiate it
  // as an open record.
  t.periodic = d.periodic && !t.truncated;
  if (t.periodic) {
    // One whole cycle: the grid must end on the kinematics' last row, and the
    // first and last rows must describe the same posture (pelvis_tx/tz may
    // drift; 2 deg and 2 cm tolerances catch a trial that is not one cycle).
    const double t_last = t.time(t.time.size() - 1);
    if (std::abs(t_last - kin.time(last)) > 1e-9 || std::abs(t.time(0) - kin.time(0)) > 1e-9) {
      std::ostringstream s;
      s << "periodic: true needs the load files to cover the kinematics' time range ["
        << kin.time(0) << ", " << kin.time(last) << "] s and that range to be a whole number of "
        << "samples at " << options.rate_hz << " Hz; the common grid is [" << t.time(0) << ", "
        << t_last << "] s";
      throw InputError(d.path, d.key_lines.at("periodic"), s.str());
    }
    for (int c = 0; c < kNumTrialCoordinates; ++c) {
      if (c == kPelvisTx || c == kPelvisTz) continue;
      const double jump = std::abs(kin.values(last, c) - kin.values(0, c));
      const bool length = c == kPelvisTy;
      if (jump > (length ? 0.02 : 2.0 * M_PI / 180.0)) {
        std::ostringstream s;
        s << "periodic: true but " << trial_coordinate_names()[c] << " differs between the first and "
          << "last rows of " << d.kinematics_file << " by " << (length ? jump : jump * 180.0 / M_PI)
          << (length ? " m" : " deg") << " (allowed " << (length ? "0.02 m" : "2 deg") << ")";
        throw InputError(d.path, d.key_lines.at("periodic"), s.str());
      }
    }
  }

  Eigen::MatrixXd q = resample_linear(kin.time, kin.values, t.time, d.kinematics_file);
  if (options.filter_kinematics) {
    LowPassOptions lp = options.lowpass;
    lp.periodic = t.periodic;
    q = filtfilt_lowpass(q, options.rate_hz, lp, d.kinematics_file);
  }
  t.q = q;
  t.qd = first_derivative(q, h, t.periodic);
  t.qdd = second_derivative(q, h, t.periodic);

  if (grf) {
    Eigen::MatrixXd g = resample_linear(grf->time, grf->values, t.time, d.grf_file);
    if (options.filter_grf) g = filtfilt_lowpass(g, options.rate_hz, options.lowpass, d.grf_file);
    for (Eigen::Index i = 0; i < g.rows(); ++i) {
      if (g(i, 1) < options.min_vertical_grf_n) g.row(i).setZero();
    }
    t.has_grf = true;
    t.grf_force_W = g.leftCols(3);
    t.grf_cop_W = g.middleCols(3, 3);
    t.grf_torque_W = g.rightCols(3);
  }
  if (loads) {
    const Eigen::MatrixXd l = resample_linear(loads->time, loads->values, t.time, d.knee_loads_file);
    t.has_knee_loads = true;
    t.knee_force_T = l.leftCols(3);
    t.knee_moment_T = l.rightCols(3);
  }
  if (ext) {
    Eigen::MatrixXd g = resample_linear(ext->time, ext->values, t.time, ext_spec->datafile);
    if (options.filter_grf) g = filtfilt_lowpass(g, options.rate_hz, options.lowpass, ext_spec->datafile);
    t.external_loads_file = d.external_loads_file;
    for (std::size_t f = 0; f < ext_spec->forces.size(); ++f) {
      const ExternalForceSpec& fs = ext_spec->forces[f];
      TrialExternalForce tf;
      tf.name = fs.name;
      tf.body = fs.applied_to_body;
      tf.has_point = !fs.point_identifier.empty();
      tf.has_torque = !fs.torque_identifier.empty();
      Eigen::MatrixXd block = g.middleCols(9 * static_cast<Eigen::Index>(f), 9);
      for (Eigen::Index i = 0; i < block.rows(); ++i)
        if (block(i, 1) < options.min_vertical_grf_n) block.row(i).setZero();
      tf.force_W = block.leftCols(3);
      tf.point_W = block.middleCols(3, 3);
      tf.torque_W = block.rightCols(3);
      t.external_forces.push_back(std::move(tf));
    }
    if (!d.foot_body.empty()) {
      // The generic leg chain's ground reaction: the one force on foot_body.
      std::vector<const TrialExternalForce*> on_foot;
      std::string bodies;
      for (const auto& tf : t.external_forces) {
        if (tf.body == d.foot_body) on_foot.push_back(&tf);
        bodies += (bodies.empty() ? "" : ", ") + tf.name + " -> " + tf.body;
      }
      if (on_foot.size() != 1 || !on_foot[0]->has_point)
        throw InputError(d.path, d.key_lines.at("foot_body"),
                         "foot_body '" + d.foot_body + "': expected exactly one ExternalForce with a point "
                         "acting on it in " + d.external_loads_file + ", found " +
                             std::to_string(on_foot.size()) + " (" + bodies + ")");
      t.has_grf = true;
      t.grf_force_W = on_foot[0]->force_W;
      t.grf_cop_W = on_foot[0]->point_W;
      t.grf_torque_W = on_foot[0]->torque_W;
    }
  }
  {
    // Every column of the kinematics file, processed like the mapped ones.
    common::RotationalPredicate rot = options.is_rotational ? common::RotationalPredicate(options.is_rotational)
                                                            : common::RotationalPredicate(common::default_is_rotational);
    const common::StorageTable table = common::read_storage(d.kinematics_file, rot);
    // Rows up to the first one at or after the grid's end (enough to
    // interpolate; a truncated trial's bad row lies after it) must be finite.
    const double t_end = t.time(t.time.size() - 1);
    Eigen::Index rows = 0;
    while (rows < table.data.rows() && (rows == 0 || table.data(rows - 1, 0) < t_end)) ++rows;
    for (Eigen::Index r = 0; r < rows; ++r)
      for (Eigen::Index c = 1; c < table.data.cols(); ++c)
        if (!std::isfinite(table.data(r, c))) {
          std::ostringstream s;
          s << "non-finite value in column '" << table.labels[c] << "' (time " << table.data(r, 0) << " s)";
          throw InputError(d.kinematics_file, table.data_line > 0 ? table.data_line + static_cast<int>(r) : 0,
                           s.str());
        }
    t.kinematics_labels.assign(table.labels.begin() + 1, table.labels.end());
    const Eigen::VectorXd times = table.data.col(0).head(rows);
    const Eigen::MatrixXd values = table.data.block(0, 1, rows, table.data.cols() - 1);
    Eigen::MatrixXd all = resample_linear(times, values, t.time, d.kinematics_file);
    if (options.filter_kinematics) {
      LowPassOptions lp = options.lowpass;
      lp.periodic = t.periodic;
      all = filtfilt_lowpass(all, options.rate_hz, lp, d.kinematics_file);
    }
    t.kinematics_q = all;
    t.kinematics_qd = first_derivative(all, h, t.periodic);
    t.kinematics_qdd = second_derivative(all, h, t.periodic);
  }
  return t;
}

std::pair<int, int> frames_in_window(const GaitTrial& trial, double start_s, double end_s) {
  const int n = trial.num_samples();
  if (n == 0) throw InputError(trial.source, 0, "the trial has no samples");
  const double t0 = trial.time(0), t1 = trial.time(n - 1);
  const double a = std::isnan(start_s) ? t0 : start_s, b = std::isnan(end_s) ? t1 : end_s;
  constexpr double eps = 1e-9;
  auto fail = [&](const std::string& why) {
    std::ostringstream s;
    s << "time window [" << a << ", " << b << "] s: " << why << " (the trial covers [" << t0 << ", " << t1
      << "] s at " << trial.rate_hz << " Hz)";
    throw InputError(trial.source, 0, s.str());
  };
  if (!std::isfinite(a) || !std::isfinite(b)) fail("expected finite times");
  if (b < a) fail("expected start <= end");
  if (a < t0 - eps || b > t1 + eps) fail("expected a window inside the trial");
  int first = 0;
  while (first < n && trial.time(first) < a - eps) ++first;
  int last = n - 1;
  while (last >= 0 && trial.time(last) > b + eps) --last;
  if (first > last) fail("expected at least one sample in it, found none");
  return {first, last};
}

int GaitTrial::kinematics_column(const std::string& label) const {
  for (std::size_t i = 0; i < kinematics_labels.size(); ++i)
    if (kinematics_labels[i] == label) return static_cast<int>(i);
  return -1;
}

GaitTrial load_gait_trial(const std::string& trial_path, const GaitTrialOptions& options) {
  return load_gait_trial(read_trial_description(trial_path), options);
}

}  // namespace arthrosim::musculoskeletal
