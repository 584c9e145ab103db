#include "pipelines/study.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <set>
#include <sstream>

#include "biphasic/output_file.h"
#include "common/error.h"
#include "common/file_check.h"
#include "common/hashing.h"
#include "common/hdf5.h"
#include "common/scene.h"
#include "musculoskeletal/kinematics_file.h"
#include "pipelines/json.h"
#include "pipelines/post_stage.h"
#include "pipelines/stages.h"
#include "pipelines/surface_output.h"
#include "common/scene_edit.h"
#include "pipelines/report.h"
#include "pipelines/runner.h"

namespace arthrosim::pipelines::study {
namespace fs = std::filesystem;
using common::InputError;

namespace {

// ---------------------------------------------------------------------------
// Small helpers
// ---------------------------------------------------------------------------
std::string fixed(double v, int digits) {
  if (!std::isfinite(v)) return "-";
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

std::string sci(double v) {
  if (!std::isfinite(v)) return "-";
  char b[32];
  std::snprintf(b, sizeof b, "%.3g", v);
  return b;
}

std::string percent(double v) {
  if (!std::isfinite(v)) return "-";
  char b[32];
  std::snprintf(b, sizeof b, "%.3g %%", 100.0 * v);
  return b;
}

// A folder name for a setting: the label with anything unusual replaced; a
// long label (paths) is shortened and made unique by a hash.
std::string folder_name(const std::string& label) {
  std::string s;
  for (char c : label) {
    // No '=': stage programs take NAME=FILE arguments (arthrosim-post
    // --surface), so a path holding '=' would be split.
    const bool plain = std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' ||
                       c == '+' || c == '_';
    s += plain ? c : '_';
  }
  if (s.size() > 80) s = s.substr(0, 60) + "_" + common::sha256_hex(label).substr(0, 12);
  return s;
}

std::string csv_number(double v) { return std::isfinite(v) ? report::number(v) : std::string(); }

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

// ---------------------------------------------------------------------------
// Key outputs of each stage
// ---------------------------------------------------------------------------

// Where the first non-finite entry of a series is, or "".
std::string non_finite(const TimeSeries& s, const std::string& where) {
  for (Eigen::Index k = 0; k < s.x.rows(); ++k) {
    if (!std::isfinite(s.t(k)) || !s.x.row(k).allFinite()) {
      return "non-finite value in " + where + " at frame " + std::to_string(k);
    }
  }
  return "";
}

std::string frames_note(const SeriesDifference& d) {
  return "compared at " + std::to_string(d.compared) + " reference frames" +
         (d.skipped > 0 ? " (" + std::to_string(d.skipped) +
                              " left out: failed, or outside the other run's time span)"
                        : "");
}

Metric relative_series_metric(const std::string& name, const std::string& description,
                              const TimeSeries& x, const TimeSeries& ref,
                              const std::string& where, const std::string& ref_where) {
  Metric m;
  m.name = name;
  m.description = description;
  m.output_unit = "N";
  double sum = 0.0;
  int n = 0;
  for (Eigen::Index k = 0; k < x.x.rows(); ++k) {
    if (!x.valid.empty() && !x.valid[static_cast<std::size_t>(k)]) continue;
    sum += x.x.row(k).norm();
    ++n;
  }
  if (n > 0) m.output = sum / n;
  for (const std::string& bad : {non_finite(x, where), non_finite(ref, ref_where)}) {
    if (!bad.empty()) {
      m.note = bad;
      return m;
    }
  }
  const SeriesDifference d = compare_series(x, ref);
  if (d.compared == 0) {
    m.note = "no reference frame inside this run's time span";
  } else if (!(d.mean_norm_ref > 0.0)) {
    m.note = "the reference force is zero over the cycle; a relative error is undefined";
  } else {
    m.error = d.rms / d.mean_norm_ref;
    m.note = frames_note(d);
  }
  return m;
}

}  // namespace

bool has_key_outputs(const std::string& run) {
  const StageDescriptor* stage = stage_of_run(run);
  return stage != nullptr && static_cast<bool>(stage->key_outputs);
}

std::vector<Metric> comak_metrics(const fs::path& file, const fs::path& ref_file) {
  const musculoskeletal::KinematicsFileReader a(file.string());
  const musculoskeletal::KinematicsFileReader b(ref_file.string());
  common::require_file_format(a.file(), file.string(), common::StageFile::kKinematics);  // common/file_check.h
  common::require_file_format(b.file(), ref_file.string(), common::StageFile::kKinematics);
  // A killed or stopped COMAK run's file: its frames are not the whole run.
  a.require_complete(false);
  b.require_complete(false);
  std::vector<Metric> out;
  const std::string force = musculoskeletal::KinematicsFileReader::kTibiofemoralForce;
  const std::string force_description =
      "RMS over the cycle of |F - F_ref| / mean |F_ref|, F the tibiofemoral contact force";
  const std::optional<Eigen::MatrixXd> fa = a.tibiofemoral_force(), fb = b.tibiofemoral_force();
  if (!fa || !fb) {
    Metric m;
    m.name = "contact_force";
    m.description = force_description;
    m.output_unit = "N";
    m.note = "no " + force + " in " + (fa ? ref_file : file).string();
    out.push_back(m);
  } else {
    TimeSeries x{a.time(), *fa, {}};
    TimeSeries r{b.time(), *fb, {}};
    x.valid = a.converged(x.t.size());
    r.valid = b.converged(r.t.size());
    out.push_back(relative_series_metric("contact_force", force_description, x, r, file.string() + ":" + force,
                                         ref_file.string() + ":" + force));
  }

  Metric act;
  act.name = "activations";
  act.description = "RMS over frames and muscles of a - a_ref (activations in [0, 1])";
  act.output_unit = "mean activation";
  const std::string ds = musculoskeletal::KinematicsFileReader::kActivations;
  const auto aa = a.activations(), ab = b.activations();
  if (!aa || !ab) {
    act.note = "no " + ds + " in " + (aa ? ref_file : file).string();
    out.push_back(act);
    return out;
  }
  const std::vector<std::string>& names_a = aa->first;
  const std::vector<std::string>& names_b = ab->first;
  const Eigen::MatrixXd& xa = aa->second;
  const Eigen::MatrixXd& xb = ab->second;
  std::vector<Eigen::Index> ca, cb;
  for (std::size_t j = 0; j < names_b.size(); ++j) {
    const auto it = std::find(names_a.begin(), names_a.end(), names_b[j]);
    if (it == names_a.end()) continue;
    ca.push_back(it - names_a.begin());
    cb.push_back(static_cast<Eigen::Index>(j));
  }
  TimeSeries x{a.time(), Eigen::MatrixXd(xa.rows(), ca.size()), {}};
  TimeSeries r{b.time(), Eigen::MatrixXd(xb.rows(), cb.size()), {}};
  for (std::size_t j = 0; j < ca.size(); ++j) {
    x.x.col(static_cast<Eigen::Index>(j)) = xa.col(ca[j]);
    r.x.col(static_cast<Eigen::Index>(j)) = xb.col(cb[j]);
  }
  x.valid = a.converged(x.t.size());
  r.valid = b.converged(r.t.size());
  if (x.x.size() > 0) act.output = x.x.mean();
  const std::string bad_a = non_finite(x, file.string() + ":" + ds);
  const std::string bad_b = non_finite(r, ref_file.string() + ":" + ds);
  if (ca.empty()) {
    act.note = "no muscle in common with the reference";
  } else if (!bad_a.empty() || !bad_b.empty()) {
    act.note = bad_a.empty() ? bad_b : bad_a;
  } else {
    const SeriesDifference d = compare_series(x, r);
    if (d.compared == 0) {
      act.note = "no reference frame inside this run's time span";
    } else {
      act.error = d.rms_per_component;
      act.note = frames_note(d) + ", " + std::to_string(ca.size()) + " muscles" +
                 (ca.size() < names_b.size() || ca.size() < names_a.size() ? " (only those in both runs)" : "");
    }
  }
  out.push_back(act);
  return out;
}

namespace {

// The deflection of largest magnitude over every complete frame and node
// (signed), or NaN with `why` set.
double peak_deflection(const surface_output::Reader& file, const std::string& surface, std::string& why) {
  const std::optional<Eigen::MatrixXd> d = file.deflection(surface, why);
  if (!d) return kNaN;
  double peak = 0.0;
  for (Eigen::Index k = 0; k < d->rows(); ++k) {
    for (Eigen::Index i = 0; i < d->cols(); ++i) {
      if (!std::isfinite((*d)(k, i))) {
        why = "non-finite deflection of surface " + surface + " in " + file.path() + " at frame " +
              std::to_string(k) + ", node " + std::to_string(i);
        return kNaN;
      }
      if (std::abs((*d)(k, i)) > std::abs(peak)) peak = (*d)(k, i);
    }
  }
  if (d->rows() == 0) {
    why = "no complete frame in " + file.path();
    return kNaN;
  }
  return peak;
}

}  // namespace

std::vector<Metric> surface_metrics(const fs::path& file, const fs::path& ref_file) {
  const surface_output::Reader a(file.string());
  const surface_output::Reader b(ref_file.string());
  std::vector<Metric> out;
  const std::vector<std::string> surfaces = b.surfaces();
  const std::vector<std::string> own = a.surfaces();
  for (const std::string& s : surfaces) {
    Metric m;
    m.name = "max_deflection[" + s + "]";
    // A generic mesh's surface is named after its file, which a study may
    // vary: one surface on each side is the same surface whatever its name.
    std::string mine = s;
    if (std::find(own.begin(), own.end(), s) == own.end() && own.size() == 1 && surfaces.size() == 1) {
      mine = own.front();
      m.note = "surface " + mine + " compared with the reference's " + s;
    }
    m.description = "|d - d_ref| / |d_ref|, d the deflection of largest magnitude over all "
                    "frames and nodes of surface " + s;
    m.output_unit = "mm";
    std::string why_a, why_b;
    const double da = peak_deflection(a, mine, why_a);
    const double db = peak_deflection(b, s, why_b);
    if (std::isfinite(da)) m.output = 1e3 * da;
    if (!why_a.empty() || !why_b.empty()) {
      m.note = why_a.empty() ? why_b : why_a;
    } else if (db == 0.0) {
      m.note = "the reference deflection is zero; a relative error is undefined";
    } else {
      m.error = std::abs(da - db) / std::abs(db);
    }
    out.push_back(m);
  }
  const std::string force = surface_output::kContactForce;
  const std::string description =
      "RMS over time of |F - F_ref| / mean |F_ref|, F the stage-2 tibiofemoral contact force";
  const std::optional<surface_output::Series> fa = a.contact_force(), fb = b.contact_force();
  if (fa && fb) {
    const TimeSeries xs{fa->time, fa->values, {}};
    const TimeSeries rs{fb->time, fb->values, {}};
    out.push_back(relative_series_metric("contact_force", description, xs, rs, file.string() + ":" + force,
                                         ref_file.string() + ":" + force));
  } else {
    Metric m;
    m.name = "contact_force";
    m.description = description;
    m.output_unit = "N";
    m.note = "not in the surface output (" + force + " absent from " + (fa ? ref_file : file).filename().string() +
             "): this scenario or build writes no stage-2 contact force";
    out.push_back(m);
  }
  return out;
}

namespace {

}  // namespace

std::vector<Metric> biphasic_metrics(const fs::path& file, const fs::path& ref_file) {
  std::vector<Metric> out;
  for (const biphasic::OutputDifference& d : biphasic::compare_outputs(file.string(), ref_file.string())) {
    Metric m;
    m.name = d.metric + "[" + d.layer + "]";
    m.description = "max over the common steps of |x - x_ref| / max |x_ref|, x the " + d.metric + " series of layer " +
                    d.layer;
    m.error = d.relative;
    m.output = d.metric == "fluid_load_support" ? d.peak : d.metric == "contact_area" ? d.peak * 1e6 : d.peak * 1e-6;
    m.output_unit = d.metric == "fluid_load_support" ? "" : d.metric == "contact_area" ? "mm^2" : "MPa";
    m.note = std::to_string(d.common_times) + " common steps; output: the series' peak";
    out.push_back(m);
  }
  return out;
}

std::vector<Metric> post_metrics(const fs::path& file, const fs::path& ref_file) {
  const std::vector<PostScenarioSummary> a = read_post_summary(file);
  const std::vector<PostScenarioSummary> b = read_post_summary(ref_file);
  std::vector<Metric> out;
  if (b.empty()) {
    Metric m;
    m.name = "mean_angle";
    m.description = "|m - m_ref| / m_ref, m the mean model-map angle";
    m.output_unit = "deg";
    m.note = "no scenario in " + ref_file.string();
    out.push_back(m);
    return out;
  }
  for (const PostScenarioSummary& scenario_ref : b) {
    const std::string& sname = scenario_ref.scenario;
    Metric m;
    m.name = "mean_angle[" + sname + "]";
    m.description = "|m - m_ref| / m_ref, m the mean acute angle between the model's averaged "
                    "strain lines and the split-line map, scenario " + sname;
    m.output_unit = "deg";
    const PostScenarioSummary* scenario = nullptr;
    for (const PostScenarioSummary& s : a)
      if (s.scenario == sname) scenario = &s;
    const double mb = scenario_ref.mean_angle_deg;
    const double ma = scenario != nullptr ? scenario->mean_angle_deg : kNaN;
    m.output = ma;
    if (scenario == nullptr) {
      m.note = "scenario " + sname + " missing from " + file.string();
    } else if (!std::isfinite(mb) || !std::isfinite(ma)) {
      m.note = "no angle statistics in summary.json (the scene names no post.splitline_map, "
               "or no sample was covered)";
    } else if (mb == 0.0) {
      m.note = "the reference mean angle is zero; a relative error is undefined";
    } else {
      m.error = std::abs(ma - mb) / mb;
    }
    out.push_back(m);
  }
  return out;
}

namespace {

// ---------------------------------------------------------------------------
// Stage reuse across settings
// ---------------------------------------------------------------------------

// What decides a stage's result apart from files made in the run folder: its
// options and the inputs that live outside the folder.
std::string stage_signature(const StageStep& step, const fs::path& run_dir) {
  std::string s = step.name + "\n";
  for (const auto& [k, v] : step.options) s += k + "=" + v + "\n";
  const std::string prefix = run_dir.string() + "/";
  for (const auto& [label, path] : step.inputs) {
    if (path.string().rfind(prefix, 0) == 0) {
      s += label + "<-run folder\n";
    } else {
      s += label + "<-" + path.string() + "\n";
    }
  }
  return s;
}

// Stage -> every stage it depends on (transitively), from the plan's files.
std::map<std::string, std::set<std::string>> upstream_stages(const std::vector<StageStep>& plan) {
  std::map<std::string, std::set<std::string>> up;
  for (const StageStep& s : plan) {
    std::set<std::string>& u = up[s.name];
    for (const auto& [label, path] : s.inputs) {
      for (const StageStep& p : plan) {
        if (&p == &s) continue;
        for (const fs::path& o : p.outputs) {
          if (o == path) {
            u.insert(p.name);
            u.insert(up[p.name].begin(), up[p.name].end());
          }
        }
      }
    }
  }
  return up;
}

// Copies the outputs (and files sharing their stem, e.g. .xdmf and .sto
// sidecars) and the stamp of every stage of `donor` whose signature equals the
// same stage of `target`, when the target folder has no stamp of its own for
// it, or one written by another build of the stage program. The runner then
// decides from the stamps, as in any other folder: a copied stage is reused
// only if its inputs' hashes still match. Copies, not links: a stage rerun
// may rewrite its output file in place.
std::vector<std::string> seed_run_folder(const std::vector<StageStep>& donor_plan,
                                         const fs::path& donor_dir,
                                         const std::vector<StageStep>& target_plan,
                                         const fs::path& target_dir) {
  std::vector<std::string> seeded;
  std::set<std::string> same;  // stages equal in both settings, upstream included
  const std::map<std::string, std::set<std::string>> upstream = upstream_stages(target_plan);
  for (const StageStep& t : target_plan) {
    const auto d = std::find_if(donor_plan.begin(), donor_plan.end(),
                                [&](const StageStep& s) { return s.name == t.name; });
    if (d == donor_plan.end()) continue;
    if (stage_signature(*d, donor_dir) != stage_signature(t, target_dir)) continue;
    // A stage fed by a stage that differs gets other input files: copying
    // its output would only be rerun.
    const std::set<std::string>& up = upstream.at(t.name);
    if (!std::all_of(up.begin(), up.end(), [&](const std::string& u) { return same.count(u) > 0; })) {
      continue;
    }
    same.insert(t.name);
    const fs::path donor_stamp = stamp_path(donor_dir, t.name);
    const fs::path target_stamp = stamp_path(target_dir, t.name);
    // The donor ran (or was checked) earlier in this study with the current
    // stage program; a target stamp written by another build of it is stale
    // and is replaced too. (A target stamp of the current build is left
    // alone: it may differ from the donor's only through its own upstream
    // files, and then it is the right one.)
    if (!fs::exists(donor_stamp)) continue;
    if (fs::exists(target_stamp) &&
        stamp_executable_hash(target_dir, t.name) == stamp_executable_hash(donor_dir, t.name)) {
      continue;
    }
    fs::create_directories(target_stamp.parent_path());
    for (const fs::path& o : d->outputs) {
      const std::string stem = o.stem().string();
      for (const fs::directory_entry& e : fs::directory_iterator(donor_dir)) {
        if (!e.is_regular_file()) continue;
        const std::string name = e.path().filename().string();
        if (name.rfind(stem, 0) != 0) continue;
        fs::copy_file(e.path(), target_dir / name, fs::copy_options::overwrite_existing);
      }
    }
    fs::copy_file(donor_stamp, target_stamp, fs::copy_options::overwrite_existing);
    seeded.push_back(t.name);
  }
  return seeded;
}

int count_matching_stages(const std::vector<StageStep>& a, const fs::path& a_dir,
                          const std::vector<StageStep>& b, const fs::path& b_dir) {
  int n = 0;
  for (const StageStep& s : a) {
    for (const StageStep& t : b) {
      if (s.name == t.name && stage_signature(s, a_dir) == stage_signature(t, b_dir)) ++n;
    }
  }
  return n;
}

// Measured runs, by stage key, kept in DIR/.stage_measurements.tsv so that a
// stage reused from an earlier study run still has its cost.
struct Measurement {
  double wall_s = kNaN, cpu_s = kNaN;
  std::int64_t rss_kb = 0;
  std::string label;
};

std::map<std::string, Measurement> read_measurements(const fs::path& file) {
  std::map<std::string, Measurement> m;
  std::ifstream in(file);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string key, stage, wall, cpu, rss, label;
    if (!std::getline(s, key, '\t') || !std::getline(s, stage, '\t') ||
        !std::getline(s, wall, '\t') || !std::getline(s, cpu, '\t') ||
        !std::getline(s, rss, '\t') || !std::getline(s, label)) {
      continue;
    }
    m[key] = {std::stod(wall), std::stod(cpu), std::stoll(rss), label};
  }
  return m;
}

// ---------------------------------------------------------------------------
// Planning the grid
// ---------------------------------------------------------------------------
struct PlannedSetting {
  std::vector<std::pair<std::string, std::string>> values;
  std::vector<std::size_t> index;
  std::string label;
  std::string text;  // the edited scene
};

std::string setting_label(const std::vector<std::pair<std::string, std::string>>& values) {
  std::string s;
  for (const auto& [k, v] : values) s += (s.empty() ? "" : ", ") + k + "=" + v;
  return s;
}

// The edited scene for `values`, parsed to check it; a bad value is an
// InputError naming the setting.
std::string checked_scene_text(const fs::path& scene_file,
                               const std::vector<std::pair<std::string, std::string>>& values,
                               const fs::path& where, common::Scene* parsed = nullptr) {
  const std::string text = common::edit_scene_text(scene_file, scene_schema(), values);
  try {
    common::Scene s = parse_scene(text, where);
    if (parsed != nullptr) *parsed = std::move(s);
  } catch (const InputError& e) {
    throw InputError("--vary " + setting_label(values) + ": " + e.what() +
                     " (in the scene written for this setting)");
  }
  return text;
}

}  // namespace

// ---------------------------------------------------------------------------
// Public pieces
// ---------------------------------------------------------------------------
VaryAxis parse_vary(const std::string& argument) {
  const std::size_t eq = argument.find('=');
  if (eq == std::string::npos || eq == 0) {
    throw InputError("--vary", 0, "expected KEY=V1,V2,... (e.g. prepare.edge_length_mm=4,3,2), "
                                  "found '" + argument + "'");
  }
  VaryAxis axis;
  axis.key = argument.substr(0, eq);
  const std::string list = argument.substr(eq + 1);
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = list.find(',', start);
    std::string v = list.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    const auto b = v.find_first_not_of(" \t");
    const auto e = v.find_last_not_of(" \t");
    v = b == std::string::npos ? std::string() : v.substr(b, e - b + 1);
    if (v.empty()) {
      throw InputError("--vary", 0, axis.key + ": expected a comma-separated list of values, "
                                    "found an empty value in '" + list + "'");
    }
    if (std::find(axis.values.begin(), axis.values.end(), v) != axis.values.end()) {
      throw InputError("--vary", 0, axis.key + ": value '" + v + "' listed twice");
    }
    axis.values.push_back(v);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  axis.reference = axis.values.size() - 1;
  return axis;
}

SeriesDifference compare_series(const TimeSeries& x, const TimeSeries& ref) {
  SeriesDifference d;
  if (x.x.cols() != ref.x.cols()) {
    throw std::invalid_argument("compare_series: different column counts");
  }
  const Eigen::Index n = x.t.size();
  auto valid = [](const TimeSeries& s, Eigen::Index k) {
    return s.valid.empty() || s.valid[static_cast<std::size_t>(k)];
  };
  double sum_sq = 0.0, sum_norm = 0.0;
  const double cols = static_cast<double>(std::max<Eigen::Index>(1, ref.x.cols()));
  Eigen::Index seg = 0;  // x.t is increasing; ref times too
  for (Eigen::Index k = 0; k < ref.t.size(); ++k) {
    const double t = ref.t(k);
    if (!valid(ref, k) || n == 0 || t < x.t(0) || t > x.t(n - 1)) {
      ++d.skipped;
      continue;
    }
    Eigen::VectorXd xi;
    bool ok = true;
    if (n == 1) {
      xi = x.x.row(0).transpose();
      ok = valid(x, 0);
    } else {
      while (seg + 2 < n && x.t(seg + 1) < t) ++seg;
      while (seg > 0 && x.t(seg) > t) --seg;
      const double t0 = x.t(seg), t1 = x.t(seg + 1);
      const double w = t1 > t0 ? (t - t0) / (t1 - t0) : 0.0;
      // Exactly on a sample: only that sample must be valid.
      if (w == 0.0) {
        ok = valid(x, seg);
      } else if (w == 1.0) {
        ok = valid(x, seg + 1);
      } else {
        ok = valid(x, seg) && valid(x, seg + 1);
      }
      xi = ((1.0 - w) * x.x.row(seg) + w * x.x.row(seg + 1)).transpose();
    }
    if (!ok) {
      ++d.skipped;
      continue;
    }
    sum_sq += (xi - ref.x.row(k).transpose()).squaredNorm();
    sum_norm += ref.x.row(k).norm();
    ++d.compared;
  }
  if (d.compared > 0) {
    d.rms = std::sqrt(sum_sq / d.compared);
    d.rms_per_component = std::sqrt(sum_sq / (d.compared * cols));
    d.mean_norm_ref = sum_norm / d.compared;
  }
  return d;
}

namespace {
bool at_least_as_fine(const std::vector<std::vector<std::size_t>>& grid, std::size_t t, std::size_t s) {
  for (std::size_t a = 0; a < grid[s].size(); ++a) {
    if (grid[t][a] < grid[s][a]) return false;
  }
  return true;
}
// Setting s qualifies when it and every setting at least as fine have a
// known error within the tolerance.
std::vector<bool> qualifying(const std::vector<std::vector<std::size_t>>& grid,
                             const std::vector<double>& error, double tolerance) {
  const std::size_t n = grid.size();
  std::vector<bool> ok(n, false);
  for (std::size_t s = 0; s < n; ++s) {
    bool all = true;
    for (std::size_t t = 0; t < n && all; ++t) {
      if (at_least_as_fine(grid, t, s)) all = std::isfinite(error[t]) && error[t] <= tolerance;
    }
    ok[s] = all;
  }
  return ok;
}
}  // namespace

int cheapest_qualifying_setting(const std::vector<std::vector<std::size_t>>& grid,
                                const std::vector<double>& error, const std::vector<double>& cost,
                                double tolerance) {
  const std::vector<bool> ok = qualifying(grid, error, tolerance);
  int best = -1;
  for (std::size_t s = 0; s < ok.size(); ++s) {
    if (ok[s] && std::isfinite(cost[s]) && (best < 0 || cost[s] < cost[static_cast<std::size_t>(best)]))
      best = static_cast<int>(s);
  }
  return best;
}

int recommend_setting(const std::vector<std::vector<std::size_t>>& grid,
                      const std::vector<double>& error, const std::vector<double>& cost,
                      double tolerance) {
  const std::size_t n = grid.size();
  const std::vector<bool> ok = qualifying(grid, error, tolerance);
  int best = -1;
  for (std::size_t s = 0; s < n; ++s) {
    if (!ok[s]) continue;
    bool coarsest = true;
    for (std::size_t u = 0; u < n && coarsest; ++u) {
      if (u != s && ok[u] && at_least_as_fine(grid, s, u) && grid[u] != grid[s]) coarsest = false;
    }
    if (!coarsest) continue;
    const double c = std::isfinite(cost[s]) ? cost[s] : std::numeric_limits<double>::infinity();
    const double cb = best < 0 ? 0.0
                               : (std::isfinite(cost[static_cast<std::size_t>(best)])
                                      ? cost[static_cast<std::size_t>(best)]
                                      : std::numeric_limits<double>::infinity());
    if (best < 0 || c < cb) best = static_cast<int>(s);
  }
  return best;
}

std::vector<int> pareto_front(const std::vector<double>& time, const std::vector<double>& error) {
  std::vector<int> front;
  for (std::size_t i = 0; i < time.size(); ++i) {
    if (!std::isfinite(time[i]) || !std::isfinite(error[i])) continue;
    bool dominated = false;
    for (std::size_t j = 0; j < time.size() && !dominated; ++j) {
      if (j == i || !std::isfinite(time[j]) || !std::isfinite(error[j])) continue;
      dominated = time[j] <= time[i] && error[j] <= error[i] &&
                  (time[j] < time[i] || error[j] < error[i]);
    }
    if (!dominated) front.push_back(static_cast<int>(i));
  }
  std::sort(front.begin(), front.end(), [&](int a, int b) {
    return time[static_cast<std::size_t>(a)] < time[static_cast<std::size_t>(b)];
  });
  return front;
}

namespace {
// The grid as a cohort of one subject ("study") run by Snakemake
// (pipelines/cohort.h): OUT/cohort.yaml, run folders
// OUT/cohort/runs/study/<setting>. A stage counts as run when every output
// it plans exists after the workflow (Snakemake removes the outputs of a
// failed job); its key is the hash of its options and external inputs and
// those of every stage it depends on (the runner's key also hashes the
// files, which the workflow's own triggers cover). Time, CPU and memory are
// not measured here.
void run_grid_by_workflow(const StudyOptions& options, const fs::path& out_dir,
                          const std::vector<VaryAxis>& axes, StudyResult& result,
                          std::vector<std::vector<StageStep>>& plans,
                          std::vector<std::map<std::string, std::set<std::string>>>& upstream,
                          std::ostream& log) {
  const fs::path cohort_file = out_dir / "cohort.yaml";
  const fs::path cohort_out = out_dir / "cohort";
  std::string text = "# written by arthrosim study accuracy --workflow: the study's grid as a cohort\n";
  text += "description: accuracy study of " + fs::absolute(options.scene_file).lexically_normal().string() + "\n";
  text += "scene: \"" + fs::absolute(options.scene_file).lexically_normal().string() + "\"\n";
  text += "settings:\n";
  for (const VaryAxis& a : axes) {
    text += "  " + a.key + ": [";
    for (std::size_t k = 0; k < a.values.size(); ++k) text += (k ? ", " : "") + a.values[k];
    text += "]\n";
  }
  text += "subjects:\n  study: {}\n";
  cohort::write_if_changed(cohort_file, text);
  const cohort::Cohort c = cohort::load_cohort(cohort_file);
  const std::vector<cohort::Setting> names = cohort::settings_grid(c);
  if (names.size() != result.settings.size()) {
    throw InputError(cohort_file.string(), 0, "expected " + std::to_string(result.settings.size()) +
                                                  " settings in the cohort, found " + std::to_string(names.size()));
  }
  const std::vector<std::string> command =
      cohort::workflow_command(c, cohort_out, options.stage_dir, options.workflow, log);
  std::string shown;
  for (const std::string& w : command) shown += (shown.empty() ? "" : " ") + w;
  log << "study: " << result.settings.size() << " settings through the workflow: $ " << shown << "\n";
  log.flush();
  const auto t0 = std::chrono::steady_clock::now();
  const int status = cohort::run_command(command);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  log << "study: the workflow " << (status == 0 ? "finished" : "FAILED (exit status " + std::to_string(status) + ")")
      << " in " << fixed(wall, 1) << " s\n";
  for (std::size_t i = 0; i < result.settings.size(); ++i) {
    SettingResult& r = result.settings[i];
    // Grids are in the same order: first axis slowest.
    if (names[i].values != r.values) {
      throw InputError(cohort_file.string(), 0, "setting " + std::to_string(i + 1) + " of the cohort is not " + r.label);
    }
    r.dir = cohort_out / "runs" / "study" / names[i].name;
    r.scene = cohort_out / "scenes" / "study" / (names[i].name + ".yaml");
    const common::Scene s = load_scene(r.scene);
    plans[i] = plan_stages(s, r.dir);
    upstream[i] = upstream_stages(plans[i]);
    std::map<std::string, std::string> signature;
    for (const StageStep& st : plans[i]) signature[st.name] = stage_signature(st, r.dir);
    bool ok = true;
    for (const StageStep& st : plans[i]) {
      StageRecord rec;
      rec.stage = st.name;
      std::string key = signature[st.name];
      for (const std::string& u : upstream[i][st.name]) key += signature[u];
      rec.key = common::sha256_hex(key);
      const bool have = std::all_of(st.outputs.begin(), st.outputs.end(),
                                    [](const fs::path& f) { return fs::exists(f); });
      rec.run = have ? "ran" : "not run";
      rec.produced_by = have ? "the workflow" : "";
      if (!have) rec.failure = "an output is missing after the workflow (see its log)";
      ok = ok && have;
      r.stages.push_back(rec);
    }
    r.ok = ok;
    r.study_wall_time_s = kNaN;
    if (!ok) r.failure = "the workflow did not produce every output of this setting (exit status " +
                         std::to_string(status) + ")";
  }
  result.notes.push_back("run through the workflow (Snakemake, " + cohort_file.string() +
                         "): time, CPU and memory per stage are not measured, so no cost enters the "
                         "recommendation");
}
}  // namespace

namespace {
// The errors of every stage of every setting against the reference and the
// recommendation per stage, from the settings' run folders and stage records
// (filled by the scene runner or from a workflow run): both paths end here.
void evaluate_grid(const StudyOptions& options,
                   std::vector<std::map<std::string, std::set<std::string>>> upstream,
                   StudyResult& result, std::ostream& log) {
  // Time to each output from scratch.
  for (std::size_t i = 0; i < result.settings.size(); ++i) {
    SettingResult& r = result.settings[i];
    std::map<std::string, double> wall;
    for (const StageRecord& rec : r.stages) wall[rec.stage] = rec.wall_time_s;
    for (StageRecord& rec : r.stages) {
      double t = rec.wall_time_s;
      for (const std::string& u : upstream[i][rec.stage]) t += wall.count(u) ? wall[u] : kNaN;
      rec.time_to_output_s = t;
    }
  }

  // Errors against the reference.
  const SettingResult& ref = result.settings[result.reference];
  if (!ref.ok) {
    result.notes.push_back("the reference setting " + ref.label + " failed (" + ref.failure +
                           "): errors exist only for stages whose reference output was written");
  }
  std::set<std::string> noted;
  for (SettingResult& r : result.settings) {
    for (StageRecord& rec : r.stages) {
      const StageDescriptor* stage = stage_of_run(rec.stage);
      if (stage == nullptr || !stage->key_outputs) continue;
      const auto usable = [](const StageRecord& x) {
        return x.run == "ran" || x.run == "reused" || x.failed_with_output;
      };
      const bool have = usable(rec);
      const auto ref_rec = std::find_if(ref.stages.begin(), ref.stages.end(),
                                        [&](const StageRecord& x) { return x.stage == rec.stage; });
      const bool have_ref = ref_rec != ref.stages.end() && usable(*ref_rec);
      try {
        if (have && have_ref) rec.metrics = stage->key_outputs(rec.stage, r.dir, ref.dir);
      } catch (const InputError& e) {
        Metric m;
        m.name = "read";
        m.note = std::string("cannot read the output: ") + e.what();
        rec.metrics = {m};
      }
      std::string caveat;
      if (have && rec.failed_with_output) {
        caveat = "the stage failed (" + rec.failure + ") but wrote its output; compared over it. ";
      }
      if (have_ref && ref_rec->failed_with_output) {
        caveat += "The reference's stage failed (" + ref_rec->failure +
                  ") but wrote its output; compared with it. ";
      }
      if (!caveat.empty()) {
        for (Metric& m : rec.metrics) m.note = caveat + m.note;
      }
      if (!have || !have_ref) {
        Metric m;
        m.name = "not compared";
        m.note = !have ? "the stage did not complete in this setting"
                       : "the stage did not complete in the reference setting";
        rec.metrics = {m};
      }
      for (const Metric& m : rec.metrics) {
        if (std::isfinite(m.error)) {
          rec.stage_error = std::isfinite(rec.stage_error) ? std::max(rec.stage_error, m.error) : m.error;
        } else if (&r == &ref && !m.note.empty() && noted.insert(rec.stage + m.name).second) {
          result.notes.push_back(rec.stage + ": " + m.name + " not compared: " + m.note);
        }
      }
    }
  }

  // Recommendations per stage (prepare has no key output of its own: its
  // resolution shows in the later stages' errors).
  std::vector<std::string> stage_names;
  for (const SettingResult& r : result.settings) {
    for (const StageRecord& rec : r.stages) {
      if (has_key_outputs(rec.stage) &&
          std::find(stage_names.begin(), stage_names.end(), rec.stage) == stage_names.end()) {
        stage_names.push_back(rec.stage);
      }
    }
  }
  std::vector<std::vector<std::size_t>> gi;
  for (const SettingResult& r : result.settings) gi.push_back(r.index);
  for (const std::string& stage : stage_names) {
    std::vector<double> err, cost;
    for (const SettingResult& r : result.settings) {
      const auto it = std::find_if(r.stages.begin(), r.stages.end(),
                                   [&](const StageRecord& x) { return x.stage == stage; });
      // A stage that failed (even with an output) never qualifies.
      err.push_back(it != r.stages.end() && it->run != "failed" ? it->stage_error : kNaN);
      cost.push_back(it != r.stages.end() ? it->time_to_output_s : kNaN);
    }
    Recommendation rec;
    rec.stage = stage;
    rec.setting = recommend_setting(gi, err, cost, options.tolerance);
    rec.cheapest = cheapest_qualifying_setting(gi, err, cost, options.tolerance);
    std::set<std::string> keys;
    for (const SettingResult& r : result.settings) {
      for (const StageRecord& x : r.stages) {
        if (x.stage == stage) keys.insert(x.key);
      }
    }
    if (keys.size() == 1 && !keys.begin()->empty() && result.settings.size() > 1) {
      rec.setting = -1;
      rec.reason = "not affected by the varied keys: the same stage key (inputs, options, code) "
                   "in every setting";
    } else if (rec.setting >= 0 && static_cast<std::size_t>(rec.setting) == result.reference) {
      rec.reason = "only the reference itself qualifies: every coarser setting, or one finer than "
                   "it, differs from the reference by more than " + percent(options.tolerance) +
                   " or failed; convergence to " + percent(options.tolerance) +
                   " is not shown by this study";
    } else if (rec.setting >= 0) {
      const std::size_t s = static_cast<std::size_t>(rec.setting);
      rec.reason = "coarsest setting from which every finer setting stays within " +
                   percent(options.tolerance) + " of the reference (stage error " +
                   percent(err[s]) + ", " + fixed(cost[s], 1) + " s to this output)";
      if (rec.cheapest >= 0 && rec.cheapest != rec.setting) {
        const std::size_t c = static_cast<std::size_t>(rec.cheapest);
        rec.reason += "; the finer " + result.settings[c].label + " also qualifies and took less time (" +
                      fixed(cost[c], 1) + " s, stage error " + percent(err[c]) +
                      "): coarser is not cheaper here";
      }
    } else if (std::none_of(err.begin(), err.end(), [](double e) { return std::isfinite(e); })) {
      rec.reason = "no error available for this stage (see the notes)";
    } else {
      rec.reason = "no setting qualifies: a setting at least as fine as every candidate differs "
                   "from the reference by more than " + percent(options.tolerance) +
                   " or has no error";
    }
    result.recommended.push_back(rec);
  }

  log << "study: errors against " << ref.label << " (tolerance " << percent(options.tolerance) << "):\n";
  for (const SettingResult& r : result.settings) {
    log << "  " << r.label << ":";
    for (const StageRecord& rec : r.stages) {
      if (!has_key_outputs(rec.stage)) continue;
      log << " " << rec.stage << " " << percent(rec.stage_error) << " (" << fixed(rec.time_to_output_s, 1)
          << " s)";
    }
    log << "\n";
  }
  for (const Recommendation& rec : result.recommended) {
    log << "study: recommended for " << rec.stage << ": "
        << (rec.setting >= 0 ? result.settings[static_cast<std::size_t>(rec.setting)].label : "none")
        << " — " << rec.reason << "\n";
  }
}
}  // namespace

// ---------------------------------------------------------------------------
// The study
// ---------------------------------------------------------------------------
StudyResult run_accuracy_study(const StudyOptions& options, std::ostream& log) {
  if (options.axes.empty()) {
    throw InputError("--vary", 0, "expected at least one --vary KEY=V1,V2,...");
  }
  const common::Scene scene = load_scene(options.scene_file);
  const fs::path out_dir = fs::absolute(options.out_dir).lexically_normal();

  // Keys and reference values.
  std::vector<VaryAxis> axes = options.axes;
  std::set<std::string> seen_keys;
  for (const VaryAxis& a : axes) {
    common::find_settable_key(scene, a.key);  // throws for an unknown key
    if (!seen_keys.insert(a.key).second) {
      throw InputError("--vary", 0, a.key + " varied twice; give all its values in one --vary");
    }
  }
  for (const std::string& r : options.reference) {
    const std::size_t eq = r.find('=');
    std::string key = eq == std::string::npos ? std::string() : r.substr(0, eq);
    std::string value = eq == std::string::npos ? r : r.substr(eq + 1);
    if (key.empty() || std::none_of(axes.begin(), axes.end(), [&](const VaryAxis& a) { return a.key == key; })) {
      // "V" alone, or "KEY=V" whose key is not an axis: a value of the only axis.
      if (axes.size() != 1 || !key.empty()) {
        throw InputError("--reference", 0,
                         "expected KEY=VALUE with KEY one of the varied keys"
                         " (or VALUE alone with a single --vary), found '" + r + "'");
      }
      key = axes[0].key;
      value = r;
    }
    for (VaryAxis& a : axes) {
      if (a.key != key) continue;
      const auto it = std::find(a.values.begin(), a.values.end(), value);
      if (it == a.values.end()) {
        std::string list;
        for (const std::string& v : a.values) list += (list.empty() ? "" : ", ") + v;
        throw InputError("--reference", 0, "'" + value + "' is not one of the values of " +
                                               key + " (" + list + ")");
      }
      a.reference = static_cast<std::size_t>(it - a.values.begin());
    }
  }

  // Every value alone (the other keys as in the scene), so a bad value is
  // named by itself; and two values of one key must change what some stage
  // runs, or the axis measures nothing.
  const fs::path probe_dir = out_dir / "runs" / "probe";
  for (const VaryAxis& a : axes) {
    std::vector<std::pair<std::string, std::vector<StageStep>>> plans;
    for (const std::string& v : a.values) {
      common::Scene s;
      checked_scene_text(options.scene_file, {{a.key, v}}, out_dir / "scenes" / "check.yaml", &s);
      plans.emplace_back(v, plan_stages(s, probe_dir));
    }
    for (std::size_t i = 0; i < plans.size(); ++i) {
      for (std::size_t j = i + 1; j < plans.size(); ++j) {
        std::string si, sj;
        for (const StageStep& st : plans[i].second) si += stage_signature(st, probe_dir);
        for (const StageStep& st : plans[j].second) sj += stage_signature(st, probe_dir);
        if (si == sj) {
          throw InputError("--vary", 0,
                           a.key + ": the values '" + plans[i].first + "' and '" + plans[j].first +
                               "' run every stage with the same options and inputs (no stage "
                               "this scene runs reads " + a.key + ", e.g. because a scenario "
                               "sets it itself, or the two values mean the same)");
        }
      }
    }
  }

  // The grid, last axis fastest (an odometer over the value indices).
  std::vector<PlannedSetting> grid;
  std::vector<std::size_t> idx(axes.size(), 0);
  while (true) {
    PlannedSetting p;
    p.index = idx;
    for (std::size_t a = 0; a < axes.size(); ++a) p.values.emplace_back(axes[a].key, axes[a].values[idx[a]]);
    p.label = setting_label(p.values);
    grid.push_back(std::move(p));
    bool done = true;
    for (std::size_t a = axes.size(); a-- > 0;) {
      if (++idx[a] < axes[a].values.size()) {
        done = false;
        break;
      }
      idx[a] = 0;
    }
    if (done) break;
  }

  StudyResult result;
  std::set<std::string> folders;
  for (std::size_t i = 0; i < grid.size(); ++i) {
    SettingResult r;
    r.values = grid[i].values;
    r.index = grid[i].index;
    r.label = grid[i].label;
    std::string folder = folder_name(r.label);
    if (!folders.insert(folder).second) folder += "_" + std::to_string(i);
    r.dir = out_dir / "runs" / folder;
    r.scene = out_dir / "scenes" / (folder + ".yaml");
    grid[i].text = checked_scene_text(options.scene_file, r.values, r.scene);
    bool is_ref = true;
    for (std::size_t a = 0; a < axes.size(); ++a) is_ref = is_ref && r.index[a] == axes[a].reference;
    if (is_ref) result.reference = i;
    result.settings.push_back(std::move(r));
  }

  fs::create_directories(out_dir / "scenes");
  fs::create_directories(out_dir / "runs");
  for (std::size_t i = 0; i < grid.size(); ++i) {
    std::ofstream f(result.settings[i].scene, std::ios::binary);
    f << grid[i].text;
    if (!f) throw InputError(result.settings[i].scene.string(), 0, "cannot write the scene copy");
  }

  const fs::path measurements_file = out_dir / ".stage_measurements.tsv";
  std::map<std::string, Measurement> measured = read_measurements(measurements_file);

  log << "study: " << grid.size() << " setting" << (grid.size() == 1 ? "" : "s") << " of "
      << scene.file.string() << ", reference " << result.settings[result.reference].label
      << "; output in " << out_dir.string() << "\n";
  log.flush();

  std::vector<std::vector<StageStep>> plans(grid.size());
  std::vector<std::map<std::string, std::set<std::string>>> upstream(grid.size());
  if (options.use_workflow) {
    run_grid_by_workflow(options, out_dir, axes, result, plans, upstream, log);
    evaluate_grid(options, upstream, result, log);
    return result;
  }
  for (std::size_t i = 0; i < grid.size(); ++i) {
    SettingResult& r = result.settings[i];
    const common::Scene s = load_scene(r.scene);
    plans[i] = plan_stages(s, r.dir);
    upstream[i] = upstream_stages(plans[i]);
    fs::create_directories(r.dir);
    // Seed from the earlier setting that shares the most stages.
    int donor = -1, best = 0;
    for (std::size_t j = 0; j < i; ++j) {
      if (options.force) continue;  // a failed setting still has the stamps of what worked
      const int m = count_matching_stages(plans[j], result.settings[j].dir, plans[i], r.dir);
      if (m > best) best = m, donor = static_cast<int>(j);
    }
    log << "study: [" << i + 1 << "/" << grid.size() << "] " << r.label
        << (i == result.reference ? " (reference)" : "") << "\n";
    if (donor >= 0) {
      const std::vector<std::string> seeded = seed_run_folder(
          plans[static_cast<std::size_t>(donor)], result.settings[static_cast<std::size_t>(donor)].dir,
          plans[i], r.dir);
      if (!seeded.empty()) {
        std::string list;
        for (const std::string& n : seeded) list += (list.empty() ? "" : ", ") + n;
        log << "study: outputs of " << list << " copied from setting "
            << result.settings[static_cast<std::size_t>(donor)].label
            << " (same options and inputs; the runner checks their hashes)\n";
      }
    }
    log.flush();
    RunnerOptions ro;
    ro.out_dir = r.dir;
    ro.stage_dir = options.stage_dir;
    ro.force = options.force;
    const auto t0 = std::chrono::steady_clock::now();
    const RunReport rep = run_scene(s, ro, log);
    r.study_wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    r.ok = rep.status == RunStatus::kOk;
    r.failure = rep.message;
    for (const StageOutcome& o : rep.stages) {
      StageRecord rec;
      rec.stage = o.name;
      rec.key = o.key;
      switch (o.status) {
        case StageStatus::kRan: rec.run = "ran"; break;
        case StageStatus::kSkipped: rec.run = "reused"; break;
        case StageStatus::kFailed: rec.run = "failed"; break;
        default: rec.run = "not run";
      }
      if (o.status == StageStatus::kFailed) {
        rec.failure = o.reason;
        for (const StageStep& st : plans[i]) {
          if (st.name != o.name) continue;
          rec.failed_with_output = std::all_of(st.outputs.begin(), st.outputs.end(),
                                               [](const fs::path& f) { return fs::exists(f); });
        }
      }
      if (o.status == StageStatus::kRan || o.status == StageStatus::kFailed) {
        rec.wall_time_s = o.wall_time_s;
        rec.cpu_time_s = o.cpu_time_s;
        rec.max_rss_mb = static_cast<double>(o.max_rss_kb) / 1024.0;
      }
      if (o.status == StageStatus::kRan) {
        measured[o.key] = {o.wall_time_s, o.cpu_time_s, o.max_rss_kb, r.label};
        std::ofstream m(measurements_file, std::ios::app);
        m << std::setprecision(17) << o.key << "\t" << o.name << "\t" << o.wall_time_s << "\t"
          << o.cpu_time_s << "\t" << o.max_rss_kb << "\t" << r.label << "\n";
      } else if (o.status == StageStatus::kSkipped) {
        const auto it = measured.find(o.key);
        if (it != measured.end()) {
          rec.wall_time_s = it->second.wall_s;
          rec.cpu_time_s = it->second.cpu_s;
          rec.max_rss_mb = static_cast<double>(it->second.rss_kb) / 1024.0;
          rec.produced_by = it->second.label == r.label ? "an earlier study run of this setting"
                                                        : it->second.label;
        } else {
          rec.produced_by = "an earlier run (no measurement recorded)";
        }
      }
      r.stages.push_back(rec);
    }
    std::ostringstream line;
    line << "study: [" << i + 1 << "/" << grid.size() << "] " << (r.ok ? "done" : "FAILED") << " in "
         << fixed(r.study_wall_time_s, 1) << " s:";
    for (const StageRecord& rec : r.stages) {
      line << " " << rec.stage << " " << rec.run;
      if (rec.run == "ran") {
        line << " (" << fixed(rec.wall_time_s, 1) << " s, " << fixed(rec.max_rss_mb, 0) << " MB)";
      }
      if (rec.run == "reused") line << " (from " << rec.produced_by << ")";
      line << (&rec == &r.stages.back() ? "" : ",");
    }
    log << line.str() << "\n";
    if (!r.ok) log << "study: " << r.failure << "\n";
    log.flush();
  }

  evaluate_grid(options, upstream, result, log);
  return result;
}

// ---------------------------------------------------------------------------
// Outputs
// ---------------------------------------------------------------------------
namespace {

const char* kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b",
                          "#e377c2", "#17becf"};

struct PlotPoint {
  double time, error;
  std::string label;
  bool reference;
};

// Log-log error versus time, one colour per stage, its Pareto front as a
// line, the tolerance as a dashed line; reference points (error 0) sit on the
// bottom edge, hollow.
std::string error_time_plot(const std::vector<std::string>& stages,
                            const std::vector<std::vector<PlotPoint>>& points, double tolerance) {
  const double W = 720, H = 440, L = 80, R = 190, T = 30, B = 60;
  double tmin = 1e300, tmax = -1e300, emin = 1e300, emax = -1e300;
  for (const auto& ps : points) {
    for (const PlotPoint& p : ps) {
      if (!(p.time > 0) || !std::isfinite(p.time)) continue;
      tmin = std::min(tmin, p.time);
      tmax = std::max(tmax, p.time);
      if (p.error > 0 && std::isfinite(p.error)) {
        emin = std::min(emin, p.error);
        emax = std::max(emax, p.error);
      }
    }
  }
  emin = std::min(emin, tolerance);
  emax = std::max(emax, tolerance);
  if (tmin > tmax) tmin = 0.1, tmax = 1;
  const double lt0 = std::floor(std::log10(tmin)), lt1 = std::max(lt0 + 1, std::ceil(std::log10(tmax)));
  const double le0 = std::floor(std::log10(emin)) - 1;  // one decade below for the reference row
  const double le1 = std::max(le0 + 2, std::ceil(std::log10(emax)));
  auto X = [&](double t) { return L + (std::log10(t) - lt0) / (lt1 - lt0) * (W - L - R); };
  auto Y = [&](double e) { return H - B - (std::log10(e) - le0) / (le1 - le0) * (H - T - B); };
  std::ostringstream s;
  s << std::setprecision(6);
  s << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << H
    << "\" viewBox=\"0 0 " << W << " " << H << "\" font-family=\"sans-serif\" font-size=\"11\">\n";
  s << "<rect x=\"" << L << "\" y=\"" << T << "\" width=\"" << W - L - R << "\" height=\"" << H - T - B
    << "\" fill=\"none\" stroke=\"#000\"/>\n";
  for (double d = lt0; d <= lt1 + 1e-9; d += 1) {
    const double x = X(std::pow(10.0, d));
    s << "<line x1=\"" << x << "\" y1=\"" << T << "\" x2=\"" << x << "\" y2=\"" << H - B
      << "\" stroke=\"#ddd\"/><text x=\"" << x << "\" y=\"" << H - B + 15
      << "\" text-anchor=\"middle\">" << report::number(std::pow(10.0, d)) << "</text>\n";
  }
  for (double d = le0 + 1; d <= le1 + 1e-9; d += 1) {
    const double y = Y(std::pow(10.0, d));
    s << "<line x1=\"" << L << "\" y1=\"" << y << "\" x2=\"" << W - R << "\" y2=\"" << y
      << "\" stroke=\"#ddd\"/><text x=\"" << L - 5 << "\" y=\"" << y + 4
      << "\" text-anchor=\"end\">" << report::number(std::pow(10.0, d)) << "</text>\n";
  }
  s << "<text x=\"" << L - 5 << "\" y=\"" << Y(std::pow(10.0, le0)) + 4
    << "\" text-anchor=\"end\">0 (ref)</text>\n";
  const double yt = Y(tolerance);
  s << "<line x1=\"" << L << "\" y1=\"" << yt << "\" x2=\"" << W - R << "\" y2=\"" << yt
    << "\" stroke=\"#555\" stroke-dasharray=\"6,4\"/><text x=\"" << W - R - 4 << "\" y=\"" << yt - 4
    << "\" text-anchor=\"end\">" << report::escape(percent(tolerance)) << "</text>\n";
  s << "<text x=\"" << (L + W - R) / 2 << "\" y=\"" << H - 20
    << "\" text-anchor=\"middle\">wall time to the stage's output from scratch [s]</text>\n";
  s << "<text transform=\"translate(18," << (T + H - B) / 2
    << ") rotate(-90)\" text-anchor=\"middle\">stage error against the reference [-]</text>\n";
  for (std::size_t k = 0; k < stages.size(); ++k) {
    const std::string c = kColours[k % (sizeof kColours / sizeof *kColours)];
    const auto& ps = points[k];
    std::vector<double> tt, ee;
    for (const PlotPoint& p : ps) {
      tt.push_back(p.time > 0 ? p.time : kNaN);
      // The reference (error 0) is on the front at the bottom edge.
      ee.push_back(p.reference ? std::pow(10.0, le0) : (p.error > 0 ? p.error : kNaN));
    }
    const std::vector<int> front = pareto_front(tt, ee);
    if (front.size() > 1) {
      s << "<polyline fill=\"none\" stroke=\"" << c << "\" stroke-width=\"1.5\" points=\"";
      for (int i : front) s << X(tt[static_cast<std::size_t>(i)]) << "," << Y(ee[static_cast<std::size_t>(i)]) << " ";
      s << "\"/>\n";
    }
    for (std::size_t i = 0; i < ps.size(); ++i) {
      if (!std::isfinite(tt[i]) || !std::isfinite(ee[i])) continue;
      s << "<circle cx=\"" << X(tt[i]) << "\" cy=\"" << Y(ee[i]) << "\" r=\"4\" "
        << (ps[i].reference ? "fill=\"#fff\"" : "fill=\"" + c + "\"") << " stroke=\"" << c
        << "\"><title>" << report::escape(stages[k] + ": " + ps[i].label + " — " +
                                          fixed(ps[i].time, 2) + " s, error " + percent(ps[i].error))
        << "</title></circle>\n";
    }
    const double ly = T + 14 + 18.0 * static_cast<double>(k);
    s << "<circle cx=\"" << W - R + 16 << "\" cy=\"" << ly - 4 << "\" r=\"4\" fill=\"" << c
      << "\"/><text x=\"" << W - R + 26 << "\" y=\"" << ly << "\">" << report::escape(stages[k])
      << "</text>\n";
  }
  s << "<text x=\"" << W - R + 10 << "\" y=\"" << T + 14 + 18.0 * static_cast<double>(stages.size()) + 6
    << "\" fill=\"#555\">lines: Pareto fronts</text>\n";
  s << "</svg>";
  return s.str();
}

}  // namespace

void write_study_outputs(const StudyOptions& options, const StudyResult& result) {
  const fs::path out_dir = fs::absolute(options.out_dir).lexically_normal();
  fs::create_directories(out_dir);
  const SettingResult& ref = result.settings.at(result.reference);
  auto recommended_for = [&](const std::string& stage) {
    for (const Recommendation& r : result.recommended) {
      if (r.stage == stage) return r.setting;
    }
    return -1;
  };

  // ---- study.json ----------------------------------------------------------
  report::Json j;
  j.begin_object();
  j.value("schema", "arthrosim accuracy study 1");
  j.value("scene", fs::absolute(options.scene_file).lexically_normal().string());
  j.value("command_line", options.command_line);
  j.value("tolerance", options.tolerance);
  j.begin_array("axes");
  for (const VaryAxis& a : options.axes) {
    j.begin_object().value("key", a.key).array("values", a.values).end_object();
  }
  j.end_array();
  j.value("reference", ref.label);
  j.begin_array("settings");
  for (std::size_t i = 0; i < result.settings.size(); ++i) {
    const SettingResult& r = result.settings[i];
    j.begin_object().value("label", r.label).value("reference", i == result.reference);
    j.begin_object("values");
    for (const auto& [k, v] : r.values) j.value(k, v);
    j.end_object();
    j.value("scene", r.scene.string()).value("run_folder", r.dir.string()).value("ok", r.ok);
    if (!r.ok) j.value("failure", r.failure);
    j.value("study_wall_time_s", r.study_wall_time_s);
    j.begin_array("stages");
    for (const StageRecord& rec : r.stages) {
      j.begin_object().value("stage", rec.stage).value("run", rec.run);
      if (!rec.produced_by.empty()) j.value("produced_by", rec.produced_by);
      if (!rec.failure.empty()) j.value("failure", rec.failure);
      j.value("stage_key", rec.key)
          .value("wall_time_s", rec.wall_time_s)
          .value("cpu_time_s", rec.cpu_time_s)
          .value("max_rss_mb", rec.max_rss_mb)
          .value("time_to_output_s", rec.time_to_output_s)
          .value("stage_error", rec.stage_error)
          .value("within_tolerance", std::isfinite(rec.stage_error) && rec.stage_error <= options.tolerance)
          .value("recommended", recommended_for(rec.stage) == static_cast<int>(i));
      j.begin_array("metrics");
      for (const Metric& m : rec.metrics) {
        j.begin_object().value("name", m.name).value("error", m.error).value("output", m.output)
            .value("output_unit", m.output_unit).value("description", m.description)
            .value("note", m.note).end_object();
      }
      j.end_array();
      j.end_object();
    }
    j.end_array();
    j.end_object();
  }
  j.end_array();
  j.begin_array("recommended");
  for (const Recommendation& r : result.recommended) {
    j.begin_object().value("stage", r.stage)
        .value("setting", r.setting >= 0 ? result.settings[static_cast<std::size_t>(r.setting)].label : "")
        .value("cheapest_qualifying",
               r.cheapest >= 0 ? result.settings[static_cast<std::size_t>(r.cheapest)].label : "")
        .value("reason", r.reason).end_object();
  }
  j.end_array();
  j.array("notes", result.notes);
  j.end_object();
  {
    std::ofstream f(out_dir / "study.json", std::ios::binary);
    f << j.str() << "\n";
    if (!f) throw InputError((out_dir / "study.json").string(), 0, "cannot write");
  }

  // ---- study.csv: one row per (setting, stage) ------------------------------
  std::vector<std::string> metric_names;
  for (const SettingResult& r : result.settings) {
    for (const StageRecord& rec : r.stages) {
      for (const Metric& m : rec.metrics) {
        const std::string n = rec.stage + ":" + m.name;
        if (std::isfinite(m.error) || std::isfinite(m.output)) {
          if (std::find(metric_names.begin(), metric_names.end(), n) == metric_names.end()) {
            metric_names.push_back(n);
          }
        }
      }
    }
  }
  {
    std::ofstream f(out_dir / "study.csv", std::ios::binary);
    f << "setting";
    for (const VaryAxis& a : options.axes) f << "," << csv_field(a.key);
    f << ",stage,run,produced_by,wall_time_s,cpu_time_s,max_rss_mb,time_to_output_s,stage_error,"
         "within_tolerance,recommended";
    for (const std::string& n : metric_names) f << "," << csv_field("error " + n) << "," << csv_field("output " + n);
    f << "\n";
    for (std::size_t i = 0; i < result.settings.size(); ++i) {
      const SettingResult& r = result.settings[i];
      for (const StageRecord& rec : r.stages) {
        f << csv_field(r.label);
        for (const auto& kv : r.values) f << "," << csv_field(kv.second);
        f << "," << rec.stage << "," << rec.run << "," << csv_field(rec.produced_by) << ","
          << csv_number(rec.wall_time_s) << "," << csv_number(rec.cpu_time_s) << ","
          << csv_number(rec.max_rss_mb) << "," << csv_number(rec.time_to_output_s) << ","
          << csv_number(rec.stage_error) << ","
          << (std::isfinite(rec.stage_error) ? (rec.stage_error <= options.tolerance ? "yes" : "no") : "")
          << "," << (recommended_for(rec.stage) == static_cast<int>(i) ? "yes" : "");
        for (const std::string& n : metric_names) {
          const Metric* found = nullptr;
          for (const Metric& m : rec.metrics) {
            if (rec.stage + ":" + m.name == n) found = &m;
          }
          f << "," << (found ? csv_number(found->error) : "") << ","
            << (found ? csv_number(found->output) : "");
        }
        f << "\n";
      }
    }
    if (!f) throw InputError((out_dir / "study.csv").string(), 0, "cannot write");
  }

  // ---- report.html (XHTML, inline SVG) --------------------------------------
  std::vector<std::string> stages;
  for (const Recommendation& r : result.recommended) stages.push_back(r.stage);
  std::vector<std::vector<PlotPoint>> points(stages.size());
  for (std::size_t k = 0; k < stages.size(); ++k) {
    for (std::size_t i = 0; i < result.settings.size(); ++i) {
      for (const StageRecord& rec : result.settings[i].stages) {
        if (rec.stage == stages[k]) {
          points[k].push_back({rec.time_to_output_s, rec.stage_error, result.settings[i].label,
                               i == result.reference});
        }
      }
    }
  }
  std::string h;
  h += "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<!DOCTYPE html>\n<html xmlns=\"http://www.w3.org/1999/xhtml\">\n"
       "<head><meta charset=\"UTF-8\"/><title>arthrosim accuracy study</title><style>"
       "body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}table{border-collapse:collapse;"
       "margin:0.5em 0}td,th{border:1px solid #bbb;padding:2px 6px;font-size:0.85em}"
       "tr.rec td{background:#e6f4e6;font-weight:bold}.note{color:#a00}code{background:#f4f4f4}"
       "</style></head>\n<body>\n<h1>arthrosim accuracy study</h1>\n";
  h += "<p>Scene: <code>" + report::escape(fs::absolute(options.scene_file).lexically_normal().string()) +
       "</code></p>\n<p>Command: <code>" + report::escape(options.command_line) + "</code></p>\n";
  h += "<p>Varied:</p><ul>";
  for (const VaryAxis& a : options.axes) {
    std::string list;
    for (const std::string& v : a.values) list += (list.empty() ? "" : ", ") + v;
    h += "<li><code>" + report::escape(a.key) + "</code> = " + report::escape(list) + "</li>";
  }
  h += "</ul>\n<p>Reference (finest) setting: <strong>" + report::escape(ref.label) +
       "</strong>. Errors are measured against it; the recommended setting of a stage is the "
       "coarsest one from which refining further changes the stage's key outputs by no more than " +
       report::escape(percent(options.tolerance)) +
       " (convergence rule of seeds/001_8413b035bc6d0ea6.txt).</p>\n";
  h += "<h2>Recommended settings</h2>\n<ul>";
  for (const Recommendation& r : result.recommended) {
    h += "<li><strong>" + report::escape(r.stage) + "</strong>: " +
         report::escape(r.setting >= 0 ? result.settings[static_cast<std::size_t>(r.setting)].label : "none") +
         " — " + report::escape(r.reason) + "</li>";
  }
  h += "</ul>\n";
  h += "<h2>Error versus time</h2>\n<figure id=\"error-time\">" + error_time_plot(stages, points, options.tolerance) +
       "<figcaption>Stage error (largest of the stage's key-output errors) against the wall time needed "
       "to produce that output from scratch (the stage and every stage before it; reused stages counted "
       "at their measured time). Log-log; lines join each stage's Pareto front; the reference sits on "
       "the bottom edge (error 0, hollow marker).</figcaption></figure>\n";
  h += "<h2>Per stage</h2>\n<p>run: <em>ran</em> = executed in this setting; <em>reused</em> = the runner "
       "found the output up to date (same stage key), produced by the setting named. Time and memory are "
       "those of the run that produced the output (wall time, CPU time of the stage process, its peak "
       "resident set size).</p>\n";
  std::vector<std::string> all_stages;
  for (const SettingResult& r : result.settings) {
    for (const StageRecord& rec : r.stages) {
      if (std::find(all_stages.begin(), all_stages.end(), rec.stage) == all_stages.end()) all_stages.push_back(rec.stage);
    }
  }
  for (const std::string& stage : all_stages) {
    std::vector<std::string> metric_cols;
    for (const SettingResult& r : result.settings) {
      for (const StageRecord& rec : r.stages) {
        if (rec.stage != stage) continue;
        for (const Metric& m : rec.metrics) {
          if (std::find(metric_cols.begin(), metric_cols.end(), m.name) == metric_cols.end()) metric_cols.push_back(m.name);
        }
      }
    }
    h += "<h3>" + report::escape(stage) + "</h3>\n<table><tr><th>setting</th><th>run</th><th>wall [s]</th>"
         "<th>CPU [s]</th><th>peak RSS [MB]</th><th>time to output [s]</th>";
    for (const std::string& m : metric_cols) h += "<th>" + report::escape(m) + " error</th><th>output</th>";
    if (has_key_outputs(stage)) h += "<th>stage error</th><th>within " + report::escape(percent(options.tolerance)) + "</th>";
    h += "</tr>\n";
    const int rec_setting = recommended_for(stage);
    for (std::size_t i = 0; i < result.settings.size(); ++i) {
      const SettingResult& r = result.settings[i];
      for (const StageRecord& rec : r.stages) {
        if (rec.stage != stage) continue;
        const bool marked = rec_setting == static_cast<int>(i) && has_key_outputs(stage);
        h += std::string(marked ? "<tr class=\"rec\">" : "<tr>") + "<td>" + report::escape(r.label) +
             (i == result.reference ? " (reference)" : "") + (marked ? " — recommended" : "") + "</td><td>" +
             report::escape(rec.run + (rec.produced_by.empty() ? "" : " (" + rec.produced_by + ")") +
                            (rec.failure.empty() ? "" : " (" + rec.failure + ")")) +
             "</td><td>" + fixed(rec.wall_time_s, 2) + "</td><td>" + fixed(rec.cpu_time_s, 2) + "</td><td>" +
             fixed(rec.max_rss_mb, 0) + "</td><td>" + fixed(rec.time_to_output_s, 2) + "</td>";
        for (const std::string& name : metric_cols) {
          const Metric* found = nullptr;
          for (const Metric& m : rec.metrics) {
            if (m.name == name) found = &m;
          }
          if (found == nullptr) {
            h += "<td>-</td><td>-</td>";
            continue;
          }
          h += "<td" + (found->note.empty() ? std::string() : " title=\"" + report::escape(found->note) + "\"") +
               ">" + report::escape(percent(found->error)) + "</td><td>" +
               report::escape(sci(found->output) + (found->output_unit.empty() ? "" : " " + found->output_unit)) + "</td>";
        }
        if (has_key_outputs(stage)) {
          h += "<td>" + report::escape(percent(rec.stage_error)) + "</td><td>" +
               (std::isfinite(rec.stage_error) ? (rec.stage_error <= options.tolerance ? "yes" : "no") : "-") + "</td>";
        }
        h += "</tr>\n";
      }
    }
    h += "</table>\n";
    if (!has_key_outputs(stage)) {
      h += "<p>" + report::escape(stage) +
           " has no key output of its own; its resolution shows in the errors of the later stages.</p>\n";
    }
  }
  h += "<h2>Metrics</h2>\n<ul>";
  std::set<std::string> described;
  for (const SettingResult& r : result.settings) {
    for (const StageRecord& rec : r.stages) {
      for (const Metric& m : rec.metrics) {
        if (m.description.empty() || !described.insert(rec.stage + m.name).second) continue;
        h += "<li>" + report::escape(rec.stage + " " + m.name + ": " + m.description) + "</li>";
      }
    }
  }
  h += "</ul>\n<h2>Notes</h2>\n";
  std::vector<std::string> notes = result.notes;
  for (const SettingResult& r : result.settings) {
    if (!r.ok) notes.push_back("setting " + r.label + " failed: " + r.failure);
  }
  if (notes.empty()) {
    h += "<p>None.</p>\n";
  } else {
    h += "<ul>";
    for (const std::string& n : notes) h += "<li class=\"note\">" + report::escape(n) + "</li>";
    h += "</ul>\n";
  }
  h += "<p>Files: <code>study.json</code> (every number above), <code>study.csv</code> (one row per "
       "setting and stage), <code>scenes/</code> (the scene of each setting), <code>runs/</code> (each "
       "setting's output folder).</p>\n</body>\n</html>\n";
  std::ofstream f(out_dir / "report.html", std::ios::binary);
  f << h;
  if (!f) throw InputError((out_dir / "report.html").string(), 0, "cannot write");
}

}  // namespace arthrosim::pipelines::study
