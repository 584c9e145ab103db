#include "pipelines/cohort.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <sstream>
#include <ostream>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <iostream>

#include <sys/wait.h>
#include <unistd.h>

#include "common/effects.h"
#include "common/error.h"
#include "common/hdf5.h"
#include "common/hashing.h"
#include "common/scene.h"
#include "common/scene_edit.h"
#include "common/yaml_error.h"
#include "musculoskeletal/kinematics_file.h"
#include "pipelines/json.h"
#include "pipelines/report.h"
#include "pipelines/report_html.h"
#include "pipelines/stages.h"

namespace arthrosim::pipelines::cohort {
namespace fs = std::filesystem;
using common::InputError;

namespace {

// ---- reading the cohort file (yaml-cpp stays in this file) ------------------

using common::yaml::where;
using common::yaml::Where;

// What a node holds, for "expected ..., found <kind_of>" messages.
std::string kind_of(const YAML::Node& n) { return common::yaml::describe(n); }

[[noreturn]] void fail(const fs::path& file, const YAML::Node& n, const std::string& message) {
  common::yaml::fail(file.string(), n.Mark(), message);
}

std::string scalar(const fs::path& file, const YAML::Node& n, const std::string& what) {
  if (!n.IsScalar() || n.Scalar().empty()) fail(file, n, "expected " + what + " (one value), found " + kind_of(n));
  return n.Scalar();
}

void check_keys(const fs::path& file, const YAML::Node& map, const std::string& what,
                const std::vector<std::string>& known) {
  for (const auto& kv : map) {
    const std::string key = kv.first.Scalar();
    if (std::find(known.begin(), known.end(), key) != known.end()) continue;
    std::string list;
    for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
    fail(file, kv.first, "expected a key of " + what + " (" + list + "), found '" + key + "'");
  }
}

// A path written in the cohort file: relative to the file's folder, then to
// its repository (like a scene's paths).
fs::path resolve(const fs::path& file, const YAML::Node& n, const std::string& what) {
  const fs::path written = scalar(file, n, what);
  if (written.is_absolute()) {
    if (!fs::exists(written)) fail(file, n, "expected " + what + " that exists, found " + written.string());
    return written.lexically_normal();
  }
  const fs::path here = (file.parent_path() / written).lexically_normal();
  if (fs::exists(here)) return here;
  const fs::path repo = common::repository_of(file.parent_path());
  if (!repo.empty() && fs::exists(repo / written)) return (repo / written).lexically_normal();
  fail(file, n, "expected " + what + " that exists, found " + written.string() + " (looked in " +
                    file.parent_path().string() + (repo.empty() ? "" : " and " + repo.string()) + ")");
}

std::vector<Override> read_set(const fs::path& file, const YAML::Node& n, const std::string& what) {
  if (!n.IsMap()) fail(file, n, "expected " + what + ": a map of dotted scene keys to values, found " + kind_of(n));
  std::vector<Override> out;
  for (const auto& kv : n) {
    Override o;
    o.key = kv.first.Scalar();
    o.value = scalar(file, kv.second, "a value for " + o.key);
    const Where w = where(file.string(), kv.first.Mark());
    o.line = w.line;
    o.column = w.column;
    out.push_back(o);
  }
  return out;
}

bool valid_name(const std::string& s) {
  if (s.empty() || s[0] == '.' || s[0] == '-') return false;
  return std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

}  // namespace

Cohort load_cohort(const fs::path& file_in) {
  const fs::path file = fs::absolute(file_in).lexically_normal();
  YAML::Node root;
  try {
    root = YAML::LoadFile(file.string());
  } catch (const YAML::BadFile&) {
    throw InputError(file.string(), 0, "cannot read the cohort file");
  } catch (const YAML::Exception& e) {
    common::yaml::fail(file.string(), e.mark, "expected YAML, found: " + e.msg);
  }
  if (!root.IsMap()) throw InputError(file.string(), 1, "expected a cohort (a map with 'subjects'), found " + kind_of(root));
  check_keys(file, root, "a cohort file", {"description", "scene", "set", "settings", "subjects"});
  Cohort c;
  c.file = file;
  if (root["description"]) c.description = scalar(file, root["description"], "a description");
  fs::path default_scene;
  if (root["scene"]) default_scene = resolve(file, root["scene"], "a scene file");
  if (root["set"]) c.set = read_set(file, root["set"], "'set'");
  if (const YAML::Node g = root["settings"]) {
    if (!g.IsMap()) fail(file, g, "expected 'settings': a map of dotted scene keys to lists of values, found " + kind_of(g));
    for (const auto& kv : g) {
      Axis a;
      a.key = kv.first.Scalar();
      const Where w = where(file.string(), kv.first.Mark());
      a.line = w.line;
      a.column = w.column;
      if (!kv.second.IsSequence() || kv.second.size() == 0)
        fail(file, kv.second, "expected a list of values for setting '" + a.key + "' (e.g. [0.1, 0.2]), found " +
                                  kind_of(kv.second));
      for (const auto& v : kv.second) {
        const std::string value = scalar(file, v, "a value of setting '" + a.key + "'");
        if (std::find(a.values.begin(), a.values.end(), value) != a.values.end())
          fail(file, v, "expected each value of setting '" + a.key + "' once, found '" + value + "' twice");
        a.values.push_back(value);
      }
      c.settings.push_back(a);
    }
  }
  const YAML::Node subjects = root["subjects"];
  if (!subjects) throw InputError(file.string(), 1, "expected a 'subjects' map (name: {model, trial, scene, set}), found none");
  if (!subjects.IsMap() || subjects.size() == 0)
    fail(file, subjects, "expected 'subjects': a map of subject names to their model, trial, scene and set, found " +
                             kind_of(subjects));
  for (const auto& kv : subjects) {
    Subject s;
    s.name = kv.first.Scalar();
    const Where w = where(file.string(), kv.first.Mark());
    s.line = w.line;
    s.column = w.column;
    if (!valid_name(s.name))
      fail(file, kv.first, "expected a subject name of letters, digits, '_', '-' and '.' (a folder name), found '" +
                               s.name + "'");
    const YAML::Node n = kv.second;
    if (!n.IsMap()) fail(file, n, "expected subject '" + s.name + "': a map (model, trial, scene, set), found " + kind_of(n));
    check_keys(file, n, "subject '" + s.name + "'", {"model", "trial", "scene", "set"});
    s.scene = n["scene"] ? resolve(file, n["scene"], "a scene file") : default_scene;
    if (s.scene.empty())
      fail(file, kv.first, "expected a 'scene' for subject '" + s.name + "' (or a cohort-wide 'scene'), found none");
    if (n["model"]) s.model = resolve(file, n["model"], "a model folder or URDF");
    if (n["trial"]) s.trial = resolve(file, n["trial"], "a trial folder or file");
    if (n["set"]) s.set = read_set(file, n["set"], "'set' of subject '" + s.name + "'");
    c.subjects.push_back(s);
  }
  return c;
}

std::vector<Setting> settings_grid(const Cohort& cohort) {
  // The key's last dotted part, or the whole key when two axes share it.
  std::vector<std::string> last, label;
  for (const Axis& a : cohort.settings) last.push_back(a.key.substr(a.key.rfind('.') + 1));
  for (std::size_t i = 0; i < last.size(); ++i)
    label.push_back(std::count(last.begin(), last.end(), last[i]) > 1 ? cohort.settings[i].key : last[i]);
  auto clean = [](std::string s) {
    for (char& c : s)
      if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '+' || c == '-' || c == '_')) c = '-';
    return s;
  };
  std::vector<Setting> grid(1);
  for (std::size_t i = 0; i < cohort.settings.size(); ++i) {
    std::vector<Setting> next;
    for (const Setting& g : grid)
      for (const std::string& v : cohort.settings[i].values) {
        Setting s = g;
        s.values.emplace_back(cohort.settings[i].key, v);
        s.name += (s.name.empty() ? "" : "__") + clean(label[i] + "-" + v);
        next.push_back(s);
      }
    grid = next;
  }
  if (cohort.settings.empty()) grid.front().name = "default";
  return grid;
}

bool write_if_changed(const fs::path& file, const std::string& text) {
  {
    std::ifstream in(file, std::ios::binary);
    if (in) {
      const std::string old((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      if (old == text) return false;
    }
  }
  fs::create_directories(file.parent_path());
  const fs::path tmp = file.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary);
    out << text;
    if (!out) throw InputError(tmp.string(), 0, "cannot write the file");
  }
  fs::rename(tmp, file);
  return true;
}

namespace {

// A folder's regular files, recursive, sorted.
std::vector<std::string> files_in(const fs::path& dir) {
  std::vector<std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) files.push_back(e.path().string());
  std::sort(files.begin(), files.end());
  return files;
}

}  // namespace

Plan plan_cohort(const Cohort& cohort, const fs::path& out_dir, const fs::path& stage_dir) {
  Plan plan;
  plan.settings = settings_grid(cohort);
  std::map<std::string, std::string> executable_sha;
  auto sha_of = [&](const std::string& exe) {
    auto it = executable_sha.find(exe);
    if (it != executable_sha.end()) return it->second;
    const fs::path program = stage_dir / exe;
    if (!fs::is_regular_file(program))
      throw InputError(program.string(), 0, "expected the stage program " + exe + " in " + stage_dir.string() +
                                                " (build it: cmake --build build --target " + exe + "), found none");
    return executable_sha[exe] = common::sha256_file(program);
  };
  for (const Subject& subject : cohort.subjects) {
    // Every key the subject's runs set must be a key of its scene: checked on
    // the original scene, so the message points at the cohort file's line.
    const common::Scene original = load_scene(subject.scene);
    std::vector<Override> keys = cohort.set;
    keys.insert(keys.end(), subject.set.begin(), subject.set.end());
    for (const Axis& a : cohort.settings) keys.push_back({a.key, a.values.front(), a.line, a.column});
    for (const Override& o : keys) {
      try {
        common::find_settable_key(original, o.key);
      } catch (const InputError& e) {
        throw InputError(cohort.file.string(), o.line, o.column,
                         "subject '" + subject.name + "' (scene " + subject.scene.string() + "): " + e.what());
      }
    }
    for (const Setting& setting : plan.settings) {
      std::vector<std::pair<std::string, std::string>> edits;
      if (!subject.model.empty()) edits.emplace_back("model", subject.model.string());
      if (!subject.trial.empty()) edits.emplace_back("trial", subject.trial.string());
      for (const Override& o : cohort.set) edits.emplace_back(o.key, o.value);
      for (const Override& o : subject.set) edits.emplace_back(o.key, o.value);
      for (const auto& kv : setting.values) edits.emplace_back(kv);
      const std::string context = "subject '" + subject.name + "' at setting '" + setting.name + "'";
      const fs::path scene_file =
          fs::absolute(out_dir / "scenes" / subject.name / (setting.name + ".yaml")).lexically_normal();
      common::Scene scene;
      try {
        const std::string text = common::edit_scene_text(subject.scene, scene_schema(), edits);
        write_if_changed(scene_file, text);
        scene = load_scene(scene_file);
      } catch (const InputError& e) {
        throw InputError(cohort.file.string(), subject.line, subject.column, context + ": " + e.what());
      }
      const std::string dir = "runs/" + subject.name + "/" + setting.name;
      plan.runs.push_back({subject.name, setting.name, scene_file, dir});
      for (const StageStep& step : plan_stages(scene, dir)) {
        Job j;
        j.subject = subject.name;
        j.setting = setting.name;
        j.step = step.name;
        const StageDescriptor* stage = stage_of_run(step.name);
        j.stage = stage != nullptr ? stage->name : step.name;
        j.executable = step.executable;
        j.executable_sha256 = sha_of(step.executable);
        j.arguments = step.arguments;
        for (const auto& [label, path] : step.inputs) {
          const std::string p = path.string();
          if (std::find(j.inputs.begin(), j.inputs.end(), p) != j.inputs.end()) continue;
          j.inputs.push_back(p);
          if (path.is_absolute() && !plan.folders.count(p) && fs::is_directory(path)) plan.folders[p] = files_in(path);
        }
        for (const fs::path& o : step.outputs) j.outputs.push_back(o.string());
        for (const auto& [k, v] : step.options) j.options += k + "\t" + v + "\n";
        j.options_sha256 = common::sha256_hex(j.options);
        j.check_effects = step.effects.has_value();
        if (step.effects) j.effects = *step.effects;
        plan.jobs.push_back(std::move(j));
      }
    }
  }
  return plan;
}

std::string plan_json(const Cohort& cohort, const Plan& plan, const fs::path& stage_dir) {
  json::Writer w;
  w.begin_object();
  w.value("schema", "arthrosim cohort plan 1");
  w.value("cohort", cohort.file.string());
  w.value("description", cohort.description);
  w.value("stage_dir", fs::absolute(stage_dir).lexically_normal().string());
  std::vector<std::string> keys;
  for (const Axis& a : cohort.settings) keys.push_back(a.key);
  w.array("setting_keys", keys);
  w.begin_array("settings");
  for (const Setting& s : plan.settings) {
    w.begin_object().value("name", s.name);
    std::vector<std::string> values;
    for (const auto& kv : s.values) values.push_back(kv.second);
    w.array("values", values).end_object();
  }
  w.end_array();
  std::vector<std::string> subjects;
  for (const Subject& s : cohort.subjects) subjects.push_back(s.name);
  w.array("subjects", subjects);
  w.begin_array("runs");
  for (const Plan::Run& r : plan.runs)
    w.begin_object()
        .value("subject", r.subject)
        .value("setting", r.setting)
        .value("scene", r.scene.string())
        .value("dir", r.dir)
        .end_object();
  w.end_array();
  w.begin_object("folders");
  for (const auto& [folder, files] : plan.folders) w.array(folder, files);
  w.end_object();
  w.begin_array("jobs");
  for (const Job& j : plan.jobs) {
    w.begin_object()
        .value("subject", j.subject)
        .value("setting", j.setting)
        .value("step", j.step)
        .value("stage", j.stage)
        .value("executable", j.executable)
        .value("executable_sha256", j.executable_sha256)
        .array("arguments", j.arguments)
        .array("inputs", j.inputs)
        .array("outputs", j.outputs)
        .value("options_sha256", j.options_sha256)
        .value("check_effects", j.check_effects)
        .array("effects", j.effects)
        .end_object();
  }
  w.end_array();
  w.end_object();
  return w.str() + "\n";
}

std::string check_effects(const fs::path& file, const std::vector<std::string>& requested, std::string& built) {
  try {
    const common::H5File h5(file.string(), common::H5File::Mode::kRead);
    const common::EffectLedger ledger = common::read_effect_ledger(h5);
    for (const common::EffectTotal& t : ledger.totals())
      built += (built.empty() ? "" : ", ") + t.effect + " " + std::to_string(t.count);
    std::string names;
    for (const std::string& e : ledger.unrequested(requested)) names += (names.empty() ? "" : ", ") + e;
    return names.empty() ? "" : "built effect(s) the scene did not ask for: " + names;
  } catch (const InputError& e) {
    return std::string("has no readable effect ledger: ") + e.what();
  }
}

// ---- the cohort report --------------------------------------------------------

namespace {

std::string text_of(const json::Value* v) { return v != nullptr && v->kind == json::Value::Kind::kString ? v->string : ""; }

// A CSV field, quoted when it holds a comma, a quote or a line break.
std::string csv_field(const std::string& v) {
  if (v.find_first_of(",\"\n") == std::string::npos) return v;
  std::string q = "\"";
  for (char c : v) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

struct Column {
  std::string name, unit, description;
};

// Peak |F| of stage 1's tibiofemoral contact force over its converged frames.
double peak_tibiofemoral_force(const fs::path& file, std::string& note) {
  const musculoskeletal::KinematicsFileReader r(file.string());
  const std::optional<Eigen::MatrixXd> f = r.tibiofemoral_force();
  if (!f) {
    note = "no tibiofemoral force in " + file.string();
    return std::nan("");
  }
  const std::vector<bool> ok = r.converged(f->rows());
  double peak = std::nan("");
  for (Eigen::Index k = 0; k < f->rows(); ++k) {
    if (!ok[static_cast<std::size_t>(k)]) continue;
    const double n = f->row(k).norm();
    if (!(peak >= n)) peak = n;
  }
  return peak;
}

}  // namespace

int write_cohort_report(const fs::path& plan_file, const fs::path& report_dir) {
  const json::Value plan = json::read(plan_file);
  if (text_of(plan.get("schema")) != "arthrosim cohort plan 1")
    throw InputError(plan_file.string(), 0, "expected an arthrosim cohort plan (schema 'arthrosim cohort plan 1'), found " +
                                                (plan.get("schema") ? "'" + text_of(plan.get("schema")) + "'" : "none"));
  const fs::path base = plan_file.parent_path();
  std::vector<std::string> setting_keys;
  if (const json::Value* k = plan.get("setting_keys"))
    for (const json::Value& v : k->array) setting_keys.push_back(v.string);
  std::map<std::string, std::vector<std::string>> setting_values;
  std::vector<std::string> setting_order;
  if (const json::Value* s = plan.get("settings"))
    for (const json::Value& v : s->array) {
      setting_order.push_back(text_of(v.get("name")));
      std::vector<std::string>& values = setting_values[setting_order.back()];
      if (const json::Value* vals = v.get("values"))
        for (const json::Value& x : vals->array) values.push_back(x.string);
    }

  std::vector<Column> columns;
  auto column = [&](const std::string& name, const std::string& unit, const std::string& description) {
    for (std::size_t i = 0; i < columns.size(); ++i)
      if (columns[i].name == name) return i;
    columns.push_back({name, unit, description});
    return columns.size() - 1;
  };
  struct Row {
    std::string subject, setting;
    std::map<std::size_t, double> values;
  };
  std::vector<Row> rows;
  std::vector<std::string> notes;
  const json::Value* runs = plan.get("runs");
  const json::Value* jobs = plan.get("jobs");
  if (runs == nullptr || jobs == nullptr) throw InputError(plan_file.string(), 0, "expected 'runs' and 'jobs', found none");
  for (const json::Value& run : runs->array) {
    Row row{text_of(run.get("subject")), text_of(run.get("setting")), {}};
    const fs::path dir = base / text_of(run.get("dir"));
    for (const json::Value& job : jobs->array) {
      if (text_of(job.get("subject")) != row.subject || text_of(job.get("setting")) != row.setting) continue;
      const std::string step = text_of(job.get("step"));
      const StageDescriptor* stage = stage_of_run(step);
      const std::string where = row.subject + " / " + row.setting + " / " + step;
      try {
        if (stage != nullptr && stage->name == "comak") {
          std::string note;
          const std::size_t c = column(step + " peak_tibiofemoral_force", "N",
                                       "peak |F| over the converged frames of stage 1's tibiofemoral contact force");
          row.values[c] = peak_tibiofemoral_force(dir / "kinematics.h5", note);
          if (!note.empty()) notes.push_back(where + ": " + note);
        }
        if (stage == nullptr || !stage->key_outputs) continue;
        // A run compared with itself: the metrics' `output` is the value.
        for (const OutputMetric& m : stage->key_outputs(step, dir, dir)) {
          const std::size_t c = column(step + " " + m.name, m.output_unit, m.description);
          row.values[c] = m.output;
          if (!std::isfinite(m.output) && !m.note.empty()) notes.push_back(where + " " + m.name + ": " + m.note);
        }
      } catch (const std::exception& e) {
        notes.push_back(where + ": not read: " + e.what());
      }
    }
    rows.push_back(row);
  }

  // CSV: one row per subject x setting.
  std::string csv = "subject,setting";
  for (const std::string& k : setting_keys) csv += "," + csv_field(k);
  for (const Column& c : columns) csv += "," + csv_field(c.name + (c.unit.empty() ? "" : " [" + c.unit + "]"));
  csv += "\n";
  for (const Row& r : rows) {
    csv += r.subject + "," + r.setting;
    for (const std::string& v : setting_values[r.setting]) csv += "," + csv_field(v);
    for (std::size_t c = 0; c < columns.size(); ++c) {
      auto it = r.values.find(c);
      csv += "," + (it == r.values.end() || !std::isfinite(it->second) ? std::string() : report::number(it->second));
    }
    csv += "\n";
  }
  fs::create_directories(report_dir);
  {  // Always written (a Snakemake output must be newer than its inputs).
    std::ofstream out(report_dir / "cohort.csv", std::ios::binary);
    out << csv;
    if (!out) throw InputError((report_dir / "cohort.csv").string(), 0, "cannot write the file");
  }

  namespace rh = report_html;
  rh::Report rep;
  rep.title = "arthrosim cohort report";
  rep.header.push_back("cohort: " + text_of(plan.get("cohort")));
  if (!text_of(plan.get("description")).empty()) rep.header.push_back(text_of(plan.get("description")));
  rep.header.push_back(std::to_string(rows.size()) + " runs (subject x setting); table: cohort.csv");
  rh::Section table_section{"table", "Key outputs per subject and setting", {}};
  rh::Table table;
  table.id = "cohort-table";
  table.title = "Key outputs";
  table.caption = "Read from each run's output files by the stages' own readers (runs/<subject>/<setting>/).";
  table.header = {"subject", "setting"};
  for (const std::string& k : setting_keys) table.header.push_back(k);
  for (const Column& c : columns) table.header.push_back(c.name + (c.unit.empty() ? "" : " [" + c.unit + "]"));
  for (const Row& r : rows) {
    std::vector<rh::Cell> cells{r.subject, r.setting};
    for (const std::string& v : setting_values[r.setting]) cells.emplace_back(v);
    for (std::size_t c = 0; c < columns.size(); ++c) {
      auto it = r.values.find(c);
      if (it == r.values.end() || !std::isfinite(it->second))
        cells.emplace_back(std::string("-"));
      else
        cells.emplace_back(it->second);
    }
    table.rows.push_back(cells);
  }
  table_section.blocks.emplace_back(table);
  if (!notes.empty()) {
    rh::Text t;
    t.paragraph = "Values not available:";
    t.list = notes;
    t.warning = true;
    table_section.blocks.emplace_back(t);
  }
  rep.sections.push_back(table_section);

  rh::Section plots{"plots", "Across subjects", {}};
  std::vector<std::string> subjects;
  for (const Row& r : rows)
    if (std::find(subjects.begin(), subjects.end(), r.subject) == subjects.end()) subjects.push_back(r.subject);
  for (std::size_t c = 0; c < columns.size(); ++c) {
    bool any = false;
    for (const Row& r : rows) {
      auto it = r.values.find(c);
      any = any || (it != r.values.end() && std::isfinite(it->second));
    }
    if (!any) continue;  // nothing to draw (the table and its notes say why)
    rh::LinePlot p;
    p.id = "metric-" + std::to_string(c);
    p.title = columns[c].name;
    p.caption = columns[c].description + ". x: the setting's index in the grid (table above: " +
                std::to_string(setting_order.size()) + " settings); one line per subject.";
    p.x_label = "setting index";
    p.y_label = columns[c].name + (columns[c].unit.empty() ? "" : " [" + columns[c].unit + "]");
    for (std::size_t s = 0; s < subjects.size(); ++s) {
      rh::Line line;
      line.label = subjects[s];
      line.colour = static_cast<int>(s);
      line.markers = true;
      for (const Row& r : rows) {
        if (r.subject != subjects[s]) continue;
        auto it = r.values.find(c);
        if (it == r.values.end() || !std::isfinite(it->second)) continue;
        const auto idx = std::find(setting_order.begin(), setting_order.end(), r.setting) - setting_order.begin();
        line.x.push_back(static_cast<double>(idx));
        line.y.push_back(it->second);
      }
      p.lines.push_back(line);
    }
    plots.blocks.emplace_back(p);
  }
  rep.sections.push_back(plots);
  rh::write(rep, report_dir);
  return static_cast<int>(rows.size());
}

std::vector<std::string> workflow_command(const Cohort& cohort, const fs::path& out_dir, const fs::path& stage_dir,
                                          WorkflowOptions o, std::ostream& log) {
  const fs::path out = fs::absolute(out_dir).lexically_normal();
  fs::path workflow = o.workflow_dir;
  if (workflow.empty() && std::getenv("ARTHROSIM_WORKFLOW_DIR")) workflow = std::getenv("ARTHROSIM_WORKFLOW_DIR");
  if (workflow.empty()) workflow = common::repository_of(stage_dir) / "workflow";
  workflow = fs::absolute(workflow).lexically_normal();
  if (!fs::is_regular_file(workflow / "Snakefile")) {
    throw InputError((workflow / "Snakefile").string(), 0,
                     "expected the workflow's Snakefile (give its folder with --workflow), found none");
  }
  const Plan plan = plan_cohort(cohort, out, stage_dir);
  const fs::path plan_file = out / "plan.json";
  write_if_changed(plan_file, plan_json(cohort, plan, stage_dir));
  log << "arthrosim cohort: " << cohort.subjects.size() << " subject(s) x " << plan.settings.size()
      << " setting(s): " << plan.jobs.size() << " stage runs planned in " << plan_file.string() << "\n";
  std::vector<std::string> command = {o.snakemake, "--snakefile", (workflow / "Snakefile").string(),
                                      "--configfile", (workflow / "config.yaml").string(),
                                      "--directory", out.string(), "--rerun-incomplete"};
  if (o.slurm && o.profile.empty()) o.profile = (workflow / "profiles" / "slurm").string();
  if (!o.profile.empty()) {
    command.insert(command.end(), {"--profile", fs::absolute(o.profile).lexically_normal().string()});
    if (o.cores_given) command.insert(command.end(), {"--cores", std::to_string(o.cores)});
  } else {
    command.insert(command.end(), {"--cores", std::to_string(o.cores)});
  }
  if (o.dry_run) command.push_back("--dry-run");
  for (const std::string& extra : o.extra) command.push_back(extra);
  // Last: --config takes every following word up to the next option.
  command.insert(command.end(), {"--config", "plan=" + plan_file.string()});
  return command;
}

int run_command(const std::vector<std::string>& command) {
  std::vector<std::string> words = command;
  std::vector<char*> argv;
  for (std::string& w : words) argv.push_back(w.data());
  argv.push_back(nullptr);
  std::cout.flush();
  const pid_t pid = fork();
  if (pid < 0) {
    std::cerr << "error: cannot start " << command.front() << " (" << std::strerror(errno) << ")\n";
    return 127;
  }
  if (pid == 0) {
    execvp(argv[0], argv.data());
    std::cerr << "error: cannot run " << command.front() << " (" << std::strerror(errno)
              << "): install it (scripts/install-deps.sh installs Debian's snakemake) or name it with --snakemake\n";
    _exit(127);
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return 127;
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

}  // namespace arthrosim::pipelines::cohort
