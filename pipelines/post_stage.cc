#include "pipelines/post_stage.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <numbers>

#include "common/effects.h"
#include "common/error.h"
#include "common/file_check.h"
#include "common/hdf5.h"
#include "common/log.h"
#include "common/output_file.h"
#include "common/scene.h"
#include "musculoskeletal/kinematics_file.h"
#include "pipelines/json.h"
#include "pipelines/post_report.h"
#include "pipelines/report.h"
#include "pipelines/report_html.h"
#include "pipelines/stages.h"
#include "pipelines/surface_output.h"
#include "pipelines/study.h"

namespace arthrosim::pipelines {

using common::InputError;
namespace fs = std::filesystem;

void PostOptions::declare(common::OptionVisitor& v) {
  using common::Unit;
  v.path("splitline_map", splitline_map, "split-line map (SVG or CSV) to compare the averaged strain directions with");
  v.number("angle_threshold_deg", comparison.threshold_rad, Unit::kDegree, {0, 90},
           "report the fraction of samples whose model-map angle is below this");
  v.number("cpd_outlier_weight", registration.w, Unit::kNone, {0, 0.99}, "Coherent Point Drift outlier weight w");
  v.number("cpd_beta", registration.beta, Unit::kNone, {1e-6, 1e6},
           "Coherent Point Drift kernel width beta (normalised units)");
  v.number("cpd_lambda", registration.lambda, Unit::kNone, {1e-9, 1e9}, "Coherent Point Drift regularisation lambda");
  v.flag("cpd_nonrigid", registration.nonrigid, "register the map non-rigidly after the affine fit (false: affine only)");
  v.integer("outline_points", registration.outline_points, {8, 5000},
            "both outlines are resampled to this many points for registration");
  v.number("average_radius_mm", comparison.radius, Unit::kMillimetre, {0, 100},
           "radius of the spatial averaging of model directions at each map sample; 0 = the registered map's "
           "resolution (at least 1.5 model node spacings)");
  v.text("view_surface", view_surface, "",
         "surface of the surface-output files that is projected and compared with the map");
  const char* dir = "component of the viewing direction (model frame; default (0, 1, 0): distal view of the femur, "
                    "looking superiorly)";
  const char* up = "component of the direction shown upwards in the view (default (1, 0, 0): anterior up)";
  v.number("view_direction_x", view.direction.x(), Unit::kNone, {-1e6, 1e6}, std::string("x ") + dir);
  v.number("view_direction_y", view.direction.y(), Unit::kNone, {-1e6, 1e6}, std::string("y ") + dir);
  v.number("view_direction_z", view.direction.z(), Unit::kNone, {-1e6, 1e6}, std::string("z ") + dir);
  v.number("view_up_x", view.up.x(), Unit::kNone, {-1e6, 1e6}, std::string("x ") + up);
  v.number("view_up_y", view.up.y(), Unit::kNone, {-1e6, 1e6}, std::string("y ") + up);
  v.number("view_up_z", view.up.z(), Unit::kNone, {-1e6, 1e6}, std::string("z ") + up);
}

PostOptions post_from_scene(const common::Scene& scene) {
  return common::read_options<PostOptions>(scene.block("post"));
}

std::vector<PostScenarioSummary> read_post_summary(const std::filesystem::path& file) {
  const json::Value doc = json::read(file);
  std::vector<PostScenarioSummary> out;
  const json::Value* scenarios = doc.get("scenarios");
  if (scenarios == nullptr) return out;
  for (const json::Value& sc : scenarios->array) {
    PostScenarioSummary s;
    const json::Value* name = sc.get("scenario");
    s.scenario = name != nullptr ? name->string : "?";
    const json::Value* stats = sc.get("angle_statistics");
    if (stats != nullptr && !stats->array.empty()) {
      double sum = 0.0, weight = 0.0;
      bool all = false;
      for (const json::Value& r : stats->array) {
        const json::Value* region = r.get("region");
        const json::Value* mean = r.get("mean_deg");
        if (mean == nullptr || mean->kind != json::Value::Kind::kNumber) continue;
        if (region != nullptr && region->string == "all") {
          s.mean_angle_deg = mean->number;
          all = true;
          break;
        }
        const json::Value* covered = r.get("covered");
        const double w = covered != nullptr ? covered->number : 1.0;
        sum += w * mean->number;
        weight += w;
      }
      if (!all && weight > 0.0) s.mean_angle_deg = sum / weight;
    }
    out.push_back(s);
  }
  return out;
}

StageDescriptor post_stage_descriptor() {
  StageDescriptor d;
  d.name = "post";
  d.takes_allow_partial = true;
  d.executable = "arthrosim-post";
  d.summary = "averaged principal strain directions against split-line maps (CPD); report.html, summary.json";
  d.block = block_schema<PostOptions>("post", "options of the post stage");
  d.outputs = {"report"};
  d.runs = [](const common::Scene& scene, const std::filesystem::path& out) {
    StageStep s;
    s.name = "post";
    s.executable = "arthrosim-post";
    s.provides = {"report"};
    s.origin = "the post stage";
    const std::vector<common::BlockInstance>& scenarios = scene.instances("surface");
    if (scenarios.empty() && !scene.has_block("shockwave") && !scene.has_block("biphasic"))
      s.unavailable = "a 'surface' block with at least one scenario, a 'biphasic' or a 'shockwave' block";
    for (const common::BlockInstance& sc : scenarios) {
      const std::filesystem::path file = out / ("surface_" + sc.name + ".h5");
      s.inputs.emplace_back(file.filename().string(), file);
      s.arguments.insert(s.arguments.end(), {"--surface", file.string()});
    }
    const std::filesystem::path kinematics = out / "kinematics.h5";
    s.optional_inputs.push_back({"kinematics.h5", kinematics, {"--kinematics", kinematics.string()}});
    // The biphasic layers' section, when the plan runs that stage.
    const std::filesystem::path biphasic = out / "biphasic.h5";
    s.optional_inputs.push_back({"biphasic.h5", biphasic, {"--biphasic", biphasic.string()}});
    // The shockwave stage's run files (one per energy flux density), when the
    // plan runs that stage: their section and the volumes-vs-EFD plot.
    if (const StageDescriptor* shockwave = find_stage("shockwave"); shockwave != nullptr && shockwave->runs)
      for (const StageStep& run : shockwave->runs(scene, out))
        for (const std::filesystem::path& file : run.outputs)
          if (file.extension() == ".h5")
            s.optional_inputs.push_back({file.filename().string(), file, {"--shockwave", file.string()}});
    const common::OptionBlock& block = scene.block("post");
    s.options = block.canonical();
    add_path_inputs(block, s);
    s.outputs = {out / "report.html", out / "summary.json"};
    s.arguments.insert(s.arguments.end(), {"--scene", scene.file.string(), "--out-dir", out.string()});
    return std::vector<StageStep>{s};
  };
  d.key_outputs = [](const std::string&, const std::filesystem::path& dir, const std::filesystem::path& ref) {
    return study::post_metrics(dir / "summary.json", ref / "summary.json");
  };
  return d;
}

namespace {

using Clock = std::chrono::steady_clock;
constexpr double kStandardGravity = 9.80665;  // [m/s^2], body weight = mass x g
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Every dataset under `group` (the contact group of a kinematics file or a
// surface output) whose name contains "force" and has shape (n) or (n, 3)
// with n = frames becomes a series (|F| for 3 columns), named by its path
// below the group (docs/kinematics_file.md: force, medial_force,
// lateral_force; cop, area and max_pressure are not forces and are skipped).
// The frames' times: the kinematics clock (a surface output with imposed
// kinematics starts with a seating ramp; its /trial_time puts its frames on
// the kinematics file's clock).
struct ForceSeries {
  std::string stage, name;  ///< "stage 1" / "stage 2 gait"; "force |F|"
  std::vector<double> x, y;  ///< [s], [N]
  std::string label() const { return stage + " " + name; }
};
std::vector<ForceSeries> contact_series(const common::H5File& f, const std::string& group, const Eigen::VectorXd& t,
                                        const std::string& stage) {
  std::vector<ForceSeries> out;
  if (!f.is_group(group) || t.size() == 0) return out;
  std::function<void(const std::string&)> walk = [&](const std::string& g) {
    for (const auto& name : f.list(g)) {
      const std::string p = g + "/" + name;
      if (f.is_group(p)) {
        walk(p);
        continue;
      }
      if (f.type(p) != common::H5Type::kDouble || name.find("force") == std::string::npos) continue;
      const auto d = f.dims(p);
      ForceSeries s;
      s.stage = stage;
      s.name = p.substr(group.size() + 1);
      if (d.size() == 1 && d[0] == t.size()) {
        const Eigen::VectorXd v = f.read_vector(p);
        s.y.assign(v.data(), v.data() + v.size());
      } else if (d.size() == 2 && d[0] == t.size() && d[1] == 3) {
        const Eigen::MatrixXd m = f.read_matrix(p);
        s.name += " |F|";
        for (Eigen::Index i = 0; i < m.rows(); ++i) s.y.push_back(m.row(i).norm());
      } else {
        continue;
      }
      s.x.assign(t.data(), t.data() + t.size());
      out.push_back(std::move(s));
    }
  };
  walk(group);
  return out;
}

struct AttrRow {
  std::string file, object, key, value;
};
std::vector<AttrRow> attributes(const common::H5File& f, const std::string& label) {
  std::vector<AttrRow> rows;
  auto add = [&](const std::string& obj) {
    if (!f.exists(obj) && obj != "/") return;
    for (const auto& k : f.attribute_names(obj)) {
      std::string v;
      try {
        v = report::number(f.attribute_double(obj, k));
      } catch (const InputError&) {
        try {
          v = f.attribute_string(obj, k);
        } catch (const InputError&) {
          v = "(unreadable)";
        }
      }
      if (v.size() > 160) v = v.substr(0, 157) + "...";
      rows.push_back({label, obj, k, v});
    }
  };
  add("/");
  for (const std::string top : {"/solver", "/timing", "/statistics"}) {
    if (!f.is_group(top)) continue;
    add(top);
    for (const auto& n : f.list(top))
      if (f.is_group(top + "/" + n)) add(top + "/" + n);
  }
  return rows;
}


}  // namespace

PostSummary run_post(const PostInputs& in, const PostOptions& opt, const std::string& out_dir) {
  namespace rh = report_html;
  const auto t_start = Clock::now();
  fs::create_directories(out_dir);
  PostSummary summary;
  std::vector<std::pair<std::string, double>> timing;  // post's own steps
  post_report::KeyFigures key;

  if (in.surfaces.empty()) {
    summary.missing.push_back("no surface output (--surface): no deflection, strain, direction or split-line figures");
  }
  if (in.kinematics.empty()) {
    summary.missing.push_back("no kinematics file (--kinematics): no stage-1 contact force, key frames are the "
                              "frame of largest deflection and the last frame");
  }
  if (opt.splitline_map.empty()) {
    summary.missing.push_back("no split-line map (--map or post.splitline_map): no registration or angle comparison");
  }

  // ---- contact force (stage 1 kinematics, stage 2 surface outputs) ---------
  std::vector<ForceSeries> force;
  std::vector<AttrRow> attrs;
  json::Writer json;
  json.begin_object();
  json.value("schema", "arthrosim post summary 1");
  json.value("scene", in.scene_file);
  // Stage-1 total force in the tibia frame (for the RMS difference) and its clock.
  Eigen::VectorXd t1;
  Eigen::MatrixXd F1;
  std::vector<bool> converged1;
  if (!in.kinematics.empty()) {
    const auto t0 = Clock::now();
    const musculoskeletal::KinematicsFileReader kin(in.kinematics);
    const common::H5File& k = kin.file();
    if (auto p = kin.require_complete(in.allow_partial); !p.empty())  // kind, version, completeness
      summary.partial_inputs.push_back(p);
    const std::string group = musculoskeletal::KinematicsFileReader::kContactGroup;
    auto s = contact_series(k, group, kin.frames_complete() > 0 ? kin.time() : Eigen::VectorXd(), "stage 1");
    if (s.empty()) summary.missing.push_back("kinematics file " + in.kinematics + " has no " + group + " series over its frames");
    force.insert(force.end(), s.begin(), s.end());
    if (const auto F = kin.tibiofemoral_force()) {
      t1 = kin.time();
      F1 = *F;
      converged1 = kin.converged(t1.size());
    }
    if (kin.body_mass_kg() > 0) key.body_weight_N = kin.body_mass_kg() * kStandardGravity;
    auto a = attributes(k, "kinematics");
    attrs.insert(attrs.end(), a.begin(), a.end());
    timing.emplace_back("read kinematics", seconds_since(t0));
  }
  bool any_stage2 = false;
  for (const auto& [scenario, file] : in.surfaces) {
    const surface_output::Reader out(file);
    const common::H5File& f = out.file();
    if (auto p = common::require_usable_file(f, file, common::StageFile::kSurfaceOutput, in.allow_partial); !p.empty())
      summary.partial_inputs.push_back(p);
    auto s = contact_series(f, surface_output::kContactGroup, out.trial_time(), "stage 2 " + scenario);
    any_stage2 = any_stage2 || !s.empty();
    force.insert(force.end(), s.begin(), s.end());
    auto a = attributes(f, scenario);
    attrs.insert(attrs.end(), a.begin(), a.end());
  }
  if (!in.surfaces.empty() && !any_stage2) {
    summary.missing.push_back(std::string("no surface output holds ") + surface_output::kContactGroup +
                              " (stage-2 contact force)");
  }
  json.begin_array("contact_force");
  for (const auto& s : force) {
    json.begin_object().value("label", s.label()).array("time_s", s.x).array("value_N", s.y).end_object();
  }
  json.end_array();

  // Forces in body weights when the kinematics file knows the subject's mass.
  const bool in_bw = std::isfinite(key.body_weight_N);
  const double to_plot = in_bw ? 1.0 / key.body_weight_N : 1.0;
  std::vector<rh::Section> sections;
  rh::Section stage1{"sec-force", "Tibiofemoral contact force", {}};
  // Key frames: peaks of the total stage-1 force (the first series, "force"),
  // else largest deflection and last frame.
  std::vector<std::pair<std::string, double>> key_times;
  if (!force.empty()) {
    const auto& s = force.front();
    const post_report::GaitPeaks g = post_report::gait_peaks(s.x, s.y);
    if (g.found) {
      key_times = {{"first peak", s.x[g.first]}, {"mid-stance", s.x[g.trough]}, {"second peak", s.x[g.second]}};
      if (s.stage == "stage 1" && in_bw) {
        key.peak1_bw = s.y[g.first] * to_plot, key.peak2_bw = s.y[g.second] * to_plot;
        key.trough_bw = s.y[g.trough] * to_plot;
        key.peak1_s = s.x[g.first], key.peak2_s = s.x[g.second];
        double medial = post_report::kNaN, lateral = post_report::kNaN;
        for (const auto& o : force) {
          if (o.stage != s.stage || o.y.size() != s.y.size()) continue;
          if (o.name.rfind("medial_force", 0) == 0) medial = o.y[g.first];
          if (o.name.rfind("lateral_force", 0) == 0) lateral = o.y[g.first];
        }
        if (medial + lateral > 0) key.medial_share_peak1 = medial / (medial + lateral);
      }
    }
  }
  if (!force.empty()) {
    rh::LinePlot p;
    p.id = "fig-contact";
    p.title = "Tibiofemoral contact force";
    p.caption = std::string("Stage 1 (COMAK, solid lines) against stage 2 (deformable surfaces: total dashed, medial "
                            "dash-dot, lateral dotted), on the trial's clock; |F| of each force dataset") +
                (in_bw ? ", in body weights (BW = " + rh::significant(key.body_weight_N) + " N)." : ", in newtons.") +
                " Click a legend entry to hide its line; drag to zoom.";
    p.x_label = "time [s]";
    p.y_label = in_bw ? "force [BW]" : "force [N]";
    std::map<std::string, int> stage2_colour;
    for (const auto& s : force) {
      rh::Line l;
      l.label = s.name, l.group = s.stage, l.x = s.x;
      for (double v : s.y) l.y.push_back(v * to_plot);
      const bool stage1 = s.stage == "stage 1";
      // Stage 1 solid; stage 2 dashed (total), dash-dot (medial), dotted (lateral).
      const bool medial = s.name.rfind("medial", 0) == 0, lateral = s.name.rfind("lateral", 0) == 0;
      l.dash = stage1 ? rh::Dash::kSolid : medial ? rh::Dash::kDashDot : lateral ? rh::Dash::kDot : rh::Dash::kDash;
      // Colour: stage 1 by dataset (blue total, green medial, orange lateral),
      // stage 2 by scenario (vermillion, purple, sky blue, ...).
      if (stage1) {
        l.colour = medial ? 2 : lateral ? 3 : 0;
      } else {
        const auto it = stage2_colour.emplace(s.stage, 0).first;
        if (it->second == 0) it->second = std::array<int, 3>{1, 4, 5}[(stage2_colour.size() - 1) % 3];
        l.colour = it->second;
      }
      p.lines.push_back(std::move(l));
    }
    stage1.blocks.push_back(std::move(p));
    key.force_figure = "fig-contact";
  }

  // Stage 2 against stage 1 per scenario: peaks and the RMS difference of the
  // superior-inferior force (y of the tibia frame, docs/knee_geometry.md), the
  // seed's comparison (stage-1 frames inside the scenario's span).
  for (const auto& [scenario, file] : in.surfaces) {
    post_report::KeyFigures::Scenario ks;
    ks.name = scenario;
    const surface_output::Reader out(file);
    const auto F2 = out.contact_force();
    if (F2 && F2->values.rows() > 1) {
      const Eigen::VectorXd t2 = out.trial_time();
      if (t2.size() == F2->values.rows()) {
        std::vector<double> x(t2.data(), t2.data() + t2.size()), y;
        for (Eigen::Index i = 0; i < F2->values.rows(); ++i) y.push_back(F2->values.row(i).norm());
        const post_report::GaitPeaks g = post_report::gait_peaks(x, y);
        if (g.found && in_bw && !key_times.empty() && std::abs(x[g.first] - key_times[0].second) < 0.1 &&
            std::abs(x[g.second] - key_times[2].second) < 0.1) {
          ks.peak1_bw = y[g.first] * to_plot, ks.peak2_bw = y[g.second] * to_plot;
        }
        if (F1.rows() > 0) {
          const study::SeriesDifference d = study::compare_series(
              study::TimeSeries{t2, F2->values.col(1), {}}, study::TimeSeries{t1, F1.col(1), converged1});
          if (d.compared > 0 && d.mean_norm_ref > 0) ks.rms_si = d.rms / d.mean_norm_ref, ks.rms_frames = d.compared;
        }
      }
    }
    key.scenarios.push_back(ks);
  }

  // The seed's accuracy rule per step of every scenario with mesh contact
  // (/solver/penetration_ratio, docs/surface_output.md), on the trial clock
  // like the forces: steps with active contacts only, as the stage checks it.
  rh::LinePlot rule_plot;
  rule_plot.id = "fig-accuracy-rule";
  rule_plot.title = "The seed's accuracy rule per step";
  rule_plot.caption = "Largest interpenetration over largest deflection of any surface, per step with active contacts "
                      "(solid: every contact; dotted: the unfaded contacts only, without the faces next to a rim), "
                      "and the run's limit (grey).";
  rule_plot.x_label = "time [s]";
  rule_plot.y_label = "interpenetration / deflection [-]";
  rh::Table rule_table;
  rule_table.id = "tab-accuracy-rule";
  rule_table.title = "Accuracy rule of the mesh contact";
  rule_table.caption = "Per step in contact: largest interpenetration over largest deflection of any surface (the "
                       "seed's rule asks for at most the limit). The last three columns take only the unfaded "
                       "contacts, i.e. leave out the faces next to a rim where the contact fades out (docs/contact.md, "
                       "\"The seed's accuracy rule\").";
  rule_table.header = {"scenario", "steps in contact", "median ratio", "max ratio", "limit", "steps over the limit",
                       "median ratio, unfaded", "max ratio, unfaded", "steps over, unfaded"};
  json.begin_array("accuracy_rule");
  for (std::size_t si_ = 0; si_ < in.surfaces.size(); ++si_) {
    const auto& [scenario, file] = in.surfaces[si_];
    const std::optional<surface_output::PenetrationSeries> pen = surface_output::Reader(file).penetration();
    if (!pen) continue;
    const Eigen::VectorXd& t = pen->time;
    const Eigen::VectorXd& r = pen->ratio;
    const Eigen::VectorXi& n = pen->active_contacts;
    const double offset = pen->trial_offset_s;  // surface clock -> trial clock (seating first)
    const bool has_limit = pen->limit.has_value();
    const double limit = has_limit ? *pen->limit : 0.0;
    // The ratio over unfaded contacts only (a file without it says so in
    // its rows).
    const bool has_unfaded = pen->has_unfaded;
    const Eigen::VectorXd& ri = pen->unfaded_ratio;
    rh::Line s, si;
    s.label = scenario, s.group = "stage 2", s.colour = std::array<int, 3>{1, 4, 5}[si_ % 3];
    si.label = scenario + ", unfaded contacts", si.group = "stage 2", si.colour = s.colour, si.dash = rh::Dash::kDot;
    std::vector<double> in_contact, unfaded;
    int over = 0, unfaded_over = 0;
    for (Eigen::Index i = 0; i < t.size(); ++i) {
      if (n(i) <= 0) continue;
      s.x.push_back(t(i) + offset);
      s.y.push_back(r(i));
      in_contact.push_back(r(i));
      if (has_limit && r(i) > limit) ++over;
      if (has_unfaded) {
        si.x.push_back(t(i) + offset);
        si.y.push_back(ri(i));
        unfaded.push_back(ri(i));
        if (has_limit && ri(i) > limit) ++unfaded_over;
      }
    }
    if (in_contact.empty()) continue;
    const size_t m = in_contact.size();
    const double median = median_of(in_contact);
    const double max_ratio = *std::max_element(in_contact.begin(), in_contact.end());
    json.begin_object().value("scenario", scenario).value("steps_in_contact", static_cast<int>(m))
        .value("median_ratio", median).value("max_ratio", max_ratio);
    if (has_limit) json.value("limit", limit).value("steps_over_limit", over);
    rh::Cell i_median = std::string("(not recorded)"), i_max = std::string("-"), i_over = std::string("-");
    if (has_unfaded) {
      const double im = median_of(unfaded), ix = *std::max_element(unfaded.begin(), unfaded.end());
      json.value("median_unfaded_ratio", im).value("max_unfaded_ratio", ix);
      if (has_limit) json.value("steps_over_limit_unfaded", unfaded_over);
      i_median = im;
      i_max = ix;
      if (has_limit) i_over = static_cast<long long>(unfaded_over);
    }
    json.end_object();
    rule_table.rows.push_back({scenario, static_cast<long long>(m), median, max_ratio,
                               has_limit ? rh::Cell(limit) : rh::Cell(std::string("(not recorded)")),
                               has_limit ? rh::Cell(static_cast<long long>(over)) : rh::Cell(std::string("-")), i_median,
                               i_max, i_over});
    auto& ks = key.scenarios[si_];
    ks.rule_max_ratio = max_ratio, ks.rule_steps = static_cast<int>(m), ks.rule_figure = rule_plot.id;
    if (has_limit) ks.rule_limit = limit, ks.rule_steps_over = over;
    if (has_limit && rule_plot.lines.empty()) {
      rh::Line lim;
      lim.label = "limit " + rh::significant(limit);
      lim.x = {s.x.front(), s.x.back()};
      lim.y = {limit, limit};
      lim.dash = rh::Dash::kDot, lim.colour = -1;
      rule_plot.lines.push_back(std::move(lim));
    }
    rule_plot.lines.push_back(std::move(s));
    if (has_unfaded) rule_plot.lines.push_back(std::move(si));
  }
  json.end_array();
  if (!rule_table.rows.empty()) {
    rh::Section sec{"sec-accuracy-rule", "Accuracy rule of the mesh contact", {}};
    sec.blocks.push_back(std::move(rule_plot));
    sec.blocks.push_back(std::move(rule_table));
    if (!stage1.blocks.empty()) sections.push_back(std::move(stage1));
    sections.push_back(std::move(sec));
  } else if (!stage1.blocks.empty()) {
    sections.push_back(std::move(stage1));
  }

  // ---- scenarios --------------------------------------------------------------
  SplitLineMap map;
  if (!opt.splitline_map.empty()) {
    const auto t0 = Clock::now();
    map = read_splitline_map(opt.splitline_map.string(), opt.map_sample_spacing);
    timing.emplace_back("read split-line map", seconds_since(t0));
    json.begin_object("map")
        .value("file", opt.splitline_map.string())
        .value("synthetic", map.synthetic)
        .value("samples", static_cast<int>(map.samples.rows()))
        .value("outline_points", static_cast<int>(map.outline.rows()))
        .value("spacing_map_units", map.spacing)
        .end_object();
  }
  json.begin_array("scenarios");
  for (std::size_t si_ = 0; si_ < in.surfaces.size(); ++si_) {
    const auto& [scenario, file] = in.surfaces[si_];
    auto& ks = key.scenarios[si_];
    auto t0 = Clock::now();
    const SurfaceField field = read_surface_field(file, opt.view_surface);
    const NodeDirections nd = average_node_directions(field);
    const ProjectedView view = project_view(field.mesh, opt.view);
    Eigen::VectorXd ang, len;
    project_directions(view, nd.direction, ang, len);
    std::vector<bool> usable(view.nodes.rows());
    for (Eigen::Index i = 0; i < view.nodes.rows(); ++i)
      usable[i] = nd.defined[i] && view.visible[i] && len(i) >= opt.comparison.min_projected_length;
    timing.emplace_back(scenario + ": read and average", seconds_since(t0));
    ScenarioOutcome oc;
    oc.scenario = scenario;
    oc.file = file;
    oc.nodes = static_cast<int>(field.mesh.V.rows());
    oc.frames = static_cast<int>(field.e1.rows());
    const std::string sid = "fig-" + std::to_string(summary.scenarios.size());
    rh::Section sec{"sec-scenario-" + std::to_string(si_), "Scenario " + scenario + ": deflection, strain and directions", {}};
    sec.blocks.push_back(rh::Text{"Surface output " + file + " (surface " + opt.view_surface + ", " +
                                      std::to_string(oc.nodes) + " nodes, " + std::to_string(oc.frames) +
                                      " frames). The 2D maps show the nodes facing the viewer in the post stage's view "
                                      "(docs/post.md, section 2); the 3D view shows the whole surface.",
                                  {}, false});
    // Key frames of this scenario.
    std::vector<std::pair<std::string, int>> frames;
    auto nearest = [&](double t) {
      Eigen::Index best = 0;
      (field.time.array() - t).abs().minCoeff(&best);
      return static_cast<int>(best);
    };
    // The gait key times apply only to a scenario that moves with the cycle:
    // one whose effect ledger lists imposed_kinematics, or, for a file without
    // a ledger, one with more than the two frames (start, end) of a steady
    // state. A steady-state scenario (osmotic) falls back to its largest
    // deflection.
    bool follows_cycle = !key_times.empty() && field.time.size() > 2;
    if (follows_cycle) {
      if (const std::optional<common::EffectLedger> ledger = surface_output::Reader(file).ledger())
        follows_cycle = ledger->built("imposed_kinematics");
    }
    if (follows_cycle) {
      // A key time the run does not reach (e.g. a walk that ends before the
      // second peak) gets no map: the nearest frame would be another instant.
      const Eigen::Index nt = field.time.size();
      const double half_step = nt > 1 ? 0.5 * (field.time(nt - 1) - field.time(0)) / double(nt - 1) : 0.0;
      for (const auto& [name, t] : key_times) {
        if (t < field.time(0) - half_step || t > field.time(nt - 1) + half_step) {
          summary.missing.push_back(scenario + ": the run covers " + report::number(field.time(0)) + " to " +
                                    report::number(field.time(nt - 1)) + " s of the trial, not the " + name +
                                    " at " + report::number(t) + " s (no map for it)");
          continue;
        }
        frames.emplace_back(name, nearest(t));
      }
    } else if (field.e1.rows() > 0) {
      Eigen::Index fmax = field.e1.rows() - 1;
      if (field.deflection.size() > 0) field.deflection.cwiseAbs().rowwise().maxCoeff().maxCoeff(&fmax);
      frames.emplace_back("largest deflection", static_cast<int>(fmax));
      if (fmax != field.e1.rows() - 1) frames.emplace_back("last frame", static_cast<int>(field.e1.rows() - 1));
    }
    // Visible nodes in the view (the 2D maps), the whole surface in 3D.
    std::vector<Eigen::Index> shown;
    for (Eigen::Index i = 0; i < view.nodes.rows(); ++i)
      if (view.visible[i]) shown.push_back(i);
    Eigen::MatrixX2d shown_xy(shown.size(), 2);
    for (std::size_t i = 0; i < shown.size(); ++i) shown_xy.row(i) = view.nodes.row(shown[i]) * 1e3;
    const Eigen::MatrixX2d outline_mm = view.outline * 1e3;
    auto field_map = [&](const std::string& id, const std::string& title, const std::string& caption,
                         const Eigen::VectorXd& v, const std::string& unit) {
      rh::MapPlot m;
      m.id = id, m.title = title, m.caption = caption;
      m.outlines.push_back({"outline", outline_mm, true, rh::Dash::kSolid, -1});
      rh::Points pts;
      pts.label = title, pts.unit = unit, pts.xy = shown_xy, pts.values.resize(shown.size());
      for (std::size_t i = 0; i < shown.size(); ++i) pts.values(i) = v(shown[i]);
      m.points.push_back(std::move(pts));
      return m;
    };
    rh::SurfacePlot surf;
    surf.id = sid + "-surface";
    surf.title = scenario + ": fields on the surface (3D)";
    surf.caption = "Drag to rotate, scroll to zoom; the menu chooses the field and key frame. Model frame "
                   "(docs/knee_geometry.md), mm.";
    surf.nodes_mm = field.mesh.V * 1e3;
    surf.triangles.resize(2 * field.mesh.Q.rows(), 3);
    for (Eigen::Index q = 0; q < field.mesh.Q.rows(); ++q) {
      surf.triangles.row(2 * q) << field.mesh.Q(q, 0), field.mesh.Q(q, 1), field.mesh.Q(q, 2);
      surf.triangles.row(2 * q + 1) << field.mesh.Q(q, 0), field.mesh.Q(q, 2), field.mesh.Q(q, 3);
    }
    auto values = [](const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); };
    json.begin_object().value("scenario", scenario).value("file", file).value("nodes", oc.nodes).value("frames", oc.frames);
    json.begin_array("key_frames");
    for (size_t kf = 0; kf < frames.size(); ++kf) {
      const auto& [name, k] = frames[kf];
      const std::string t = report::number(field.time(k));
      const Eigen::VectorXd e1 = field.e1.row(k).transpose();
      const bool summary_frame = kf == 0;  // first peak, or the largest deflection
      if (summary_frame) {
        ks.deflection_when = name, ks.e1_max = e1.maxCoeff(), ks.e1_min = e1.minCoeff();
        ks.deflection_figure = sid + "-e1-0";
      }
      if (field.deflection.size() > 0) {
        const Eigen::VectorXd v = field.deflection.row(k).transpose() * 1e3;
        const std::string id = sid + "-deflection-" + std::to_string(kf);
        sec.blocks.push_back(field_map(id, scenario + ": deflection, " + name + " (t = " + t + " s)",
                                       "Deflection along the surface normal (positive outward).", v, "mm"));
        surf.fields.push_back({"deflection, " + name + " (t = " + t + " s)", "mm", values(v)});
        if (summary_frame) ks.deflection_max_mm = v.cwiseAbs().maxCoeff(), ks.deflection_figure = id;
        json.begin_object().value("name", name).value("time_s", field.time(k)).value("deflection_max_mm", v.maxCoeff())
            .value("deflection_min_mm", v.minCoeff()).value("e1_max", e1.maxCoeff())
            .value("e1_min", e1.minCoeff()).end_object();
      } else {
        json.begin_object().value("name", name).value("time_s", field.time(k)).value("e1_max", e1.maxCoeff())
            .value("e1_min", e1.minCoeff()).end_object();
      }
      sec.blocks.push_back(field_map(sid + "-e1-" + std::to_string(kf),
                                     scenario + ": first principal strain e1, " + name + " (t = " + t + " s)",
                                     "First principal Green-Lagrange strain of the mid-surface.", e1, "strain [-]"));
      surf.fields.push_back({"e1, " + name + " (t = " + t + " s)", "strain [-]", values(e1)});
    }
    json.end_array();
    if (!surf.fields.empty()) sec.blocks.push_back(std::move(surf));
    if (field.deflection.size() == 0) summary.missing.push_back(scenario + ": no deflection dataset in " + file);
    // Averaged directions: segment length ~ sqrt of the time-averaged |e1|,
    // at most 700 segments (every k-th usable node), the longest 0.9 of the
    // mean spacing they would have on the outline's box.
    {
      std::vector<Eigen::Index> use;
      double wmax = 0;
      for (Eigen::Index i = 0; i < view.nodes.rows(); ++i)
        if (usable[i] && std::isfinite(ang(i)) && nd.magnitude(i) > 0) use.push_back(i), wmax = std::max(wmax, nd.magnitude(i));
      const std::size_t stride = std::max<std::size_t>(1, (use.size() + 699) / 700);
      const Eigen::Vector2d box = outline_mm.colwise().maxCoeff() - outline_mm.colwise().minCoeff();
      const std::size_t n = (use.size() + stride - 1) / stride;
      const double L = n > 0 ? 0.9 * std::sqrt(box.x() * box.y() / double(n)) : 1.0;
      rh::Segments seg;
      seg.label = "averaged e1 lines", seg.colour = 0;
      seg.centres.resize(n, 2), seg.angle_rad.resize(n), seg.length.resize(n);
      for (std::size_t j = 0, i = 0; i < use.size(); i += stride, ++j) {
        seg.centres.row(j) = view.nodes.row(use[i]) * 1e3;
        seg.angle_rad(j) = ang(use[i]);
        seg.length(j) = L * std::sqrt(nd.magnitude(use[i]) / wmax);
      }
      rh::MapPlot m;
      m.id = sid + "-directions";
      m.title = scenario + ": time-averaged e1 directions";
      m.caption = "Magnitude-weighted time average of the first principal strain direction per node (axial; "
                  "segment length ~ sqrt of the mean |e1|).";
      m.outlines.push_back({"outline", outline_mm, true, rh::Dash::kSolid, -1});
      m.segments.push_back(std::move(seg));
      sec.blocks.push_back(std::move(m));
    }
    json.value("mean_coherence", nd.coherence.mean()).value("mean_abs_e1", nd.magnitude.mean());
    if (!opt.splitline_map.empty()) {
      t0 = Clock::now();
      const Registration reg = register_map(map.outline, view.outline, opt.registration);
      timing.emplace_back(scenario + ": registration (CPD)", seconds_since(t0));
      t0 = Clock::now();
      const Comparison c = compare_with_map(map, reg, view, ang, nd.magnitude, usable, opt.comparison);
      timing.emplace_back(scenario + ": comparison", seconds_since(t0));
      oc.stats = c.stats;
      oc.outline_mean_distance_m = reg.outline_mean_distance;
      oc.averaging_radius_m = c.radius;
      const Eigen::MatrixX2d pts_mm = c.points * 1e3;
      // Segment length: the median spacing of the samples.
      const double spacing = c.radius > 0 ? c.radius * 1e3 : 1.0;
      rh::MapPlot ov;
      ov.id = sid + "-overlay";
      ov.title = scenario + ": registered split-line map against the model";
      ov.caption = "The map registered onto the model's outline by Coherent Point Drift (its outline dashed) and, at "
                   "every map sample, the map's line and the model's averaged line.";
      ov.outlines.push_back({"model outline", outline_mm, true, rh::Dash::kSolid, -1});
      ov.outlines.push_back({"map outline (registered)", reg.warped_outline * 1e3, true, rh::Dash::kDash, 1});
      rh::Segments ms, mo;
      ms.label = "map lines", ms.colour = 1, ms.centres = pts_mm, ms.angle_rad = c.map_angle;
      ms.length = Eigen::VectorXd::Constant(pts_mm.rows(), spacing);
      mo.label = "model lines", mo.colour = 0, mo.centres = pts_mm, mo.angle_rad = c.model_angle;
      mo.length = Eigen::VectorXd::Constant(pts_mm.rows(), spacing);
      ov.segments = {ms, mo};
      sec.blocks.push_back(std::move(ov));
      rh::MapPlot em;
      em.id = sid + "-error";
      em.title = scenario + ": angle between model and map lines";
      em.caption = "Acute angle per map sample (0-90 deg); hollow: no model node within the averaging radius.";
      em.outlines.push_back({"model outline", outline_mm, true, rh::Dash::kSolid, -1});
      rh::Points ep;
      ep.label = "angle error", ep.unit = "deg", ep.xy = pts_mm, ep.values = c.error_deg, ep.lo = 0, ep.hi = 90;
      em.points.push_back(std::move(ep));
      sec.blocks.push_back(std::move(em));
      for (const auto& r : c.stats)
        if (r.region == "all" || c.stats.size() == 1)
          ks.angle_mean_deg = r.mean_deg, ks.angle_samples = r.covered, ks.angle_figure = sid + "-error";
      ks.angle_threshold_deg = opt.comparison.threshold_rad * 180.0 / std::numbers::pi;
      json.begin_object("registration")
          .value("affine_status", to_string(reg.affine.status))
          .value("affine_iterations", reg.affine.iterations)
          .value("nonrigid", reg.has_nonrigid)
          .value("nonrigid_status", reg.has_nonrigid ? to_string(reg.nonrigid.status) : std::string("not run"))
          .value("nonrigid_iterations", reg.nonrigid.iterations)
          .value("outline_mean_distance_mm", reg.outline_mean_distance * 1e3)
          .value("outline_max_distance_mm", reg.outline_max_distance * 1e3)
          .end_object();
      json.value("averaging_radius_mm", c.radius * 1e3);
      json.begin_array("angle_statistics");
      for (const auto& r : c.stats) {
        json.begin_object().value("region", r.region).value("samples", r.samples).value("covered", r.covered)
            .value("mean_deg", r.mean_deg).value("median_deg", r.median_deg)
            .value("fraction_within_threshold", r.fraction_within).end_object();
      }
      json.end_array();
    }
    json.end_object();
    summary.scenarios.push_back(oc);
    sections.push_back(std::move(sec));
  }
  json.end_array();
  if (!opt.splitline_map.empty() && !summary.scenarios.empty()) {
    rh::Section sec{"sec-splitlines", "Split-line comparison", {}};
    rh::Table t;
    t.id = "tab-splitlines";
    t.title = "Angle between the model's averaged e1 lines and the registered map";
    t.caption = "Map: " + opt.splitline_map.string() +
                ". Acute angle between the model's averaged first principal strain line and the registered map line, "
                "per sample (docs/post.md, section 4).";
    const double thr = opt.comparison.threshold_rad * 180.0 / std::numbers::pi;
    t.header = {"scenario", "region", "samples", "covered", "mean [deg]", "median [deg]",
                "within " + rh::significant(thr) + " deg [%]", "outline distance after registration [mm]",
                "averaging radius [mm]"};
    for (const auto& s : summary.scenarios)
      for (const auto& r : s.stats)
        t.rows.push_back({s.scenario, r.region, static_cast<long long>(r.samples), static_cast<long long>(r.covered),
                          r.mean_deg, r.median_deg, 100.0 * r.fraction_within, s.outline_mean_distance_m * 1e3,
                          s.averaging_radius_m * 1e3});
    sec.blocks.push_back(std::move(t));
    sections.push_back(std::move(sec));
  }
  // Later stages, when their files are given.
  if (!in.biphasic.empty())
    sections.push_back(post_report::biphasic_section(in.biphasic, in.kinematics, key_times, in.surfaces));
  if (!in.shockwave.empty()) sections.push_back(post_report::shockwave_section(in.shockwave));
  json.value("angle_threshold_deg", opt.comparison.threshold_rad * 180.0 / std::numbers::pi);
  json.array("partial_inputs", summary.partial_inputs);
  json.array("missing", summary.missing);
  timing.emplace_back("post total (before writing)", seconds_since(t_start));
  json.begin_array("timing_post");
  for (const auto& [k, v] : timing) json.begin_object().value("step", k).value("seconds", v).end_object();
  json.end_array();
  json.begin_array("input_attributes");
  for (const auto& a : attrs) json.begin_object().value("file", a.file).value("object", a.object).value("key", a.key).value("value", a.value).end_object();
  json.end_array();

  // ---- report.html ------------------------------------------------------------------
  rh::Report rep;
  rep.title = "arthrosim report";
  rep.header = {"Scene: " + (in.scene_file.empty() ? std::string("(none)") : in.scene_file)};
  if (map.synthetic) rep.banner = "The split-line map is SYNTHETIC (a documented test map, not measured data): its angles say nothing about cartilage.";
  // Incomplete inputs taken with --allow-partial come first (common/file_check.h).
  for (auto p = summary.partial_inputs.rbegin(); p != summary.partial_inputs.rend(); ++p)
    rep.banner = *p + (rep.banner.empty() ? "" : " -- " + rep.banner);
  rep.summary = post_report::summary_rows(key);
  {
    rh::Section inputs{"sec-inputs", "Missing inputs", {}};
    if (summary.missing.empty()) inputs.blocks.push_back(rh::Text{"None.", {}, false});
    else inputs.blocks.push_back(rh::Text{"", summary.missing, true});
    sections.insert(sections.begin(), std::move(inputs));
  }
  {
    rh::Section sec{"sec-statistics", "Solver statistics and timing", {}};
    rh::Table a;
    a.id = "tab-attributes";
    a.title = "Attributes of the input files (as the stages wrote them)";
    a.header = {"file", "object", "attribute", "value"};
    for (const auto& r : attrs) a.rows.push_back({r.file, r.object, r.key, r.value});
    if (a.rows.empty()) sec.blocks.push_back(rh::Text{"No input file carries attributes.", {}, false});
    else sec.blocks.push_back(std::move(a));
    rh::Table tp;
    tp.id = "tab-timing";
    tp.title = "Timing of this post run";
    tp.header = {"step", "seconds"};
    for (const auto& [k, v] : timing) tp.rows.push_back({k, v});
    sec.blocks.push_back(std::move(tp));
    sections.push_back(std::move(sec));
  }
  rep.sections = std::move(sections);
  const std::vector<std::string> ids = rh::figure_ids(rep);
  json.array("figures", ids);
  json.end_object();

  summary.report_path = rh::write(rep, out_dir).string();
  summary.summary_path = (fs::path(out_dir) / "summary.json").string();
  {
    common::AtomicOutput atomic(summary.summary_path);  // <path>.partial, renamed when written (common/output_file.h)
    std::ofstream out(atomic.temp(), std::ios::binary);
    if (!out) throw InputError(summary.summary_path, 0, "cannot write the output file");
    out << json.str() << "\n";
    out.close();
    if (!out) throw InputError(summary.summary_path, 0, "write failed");
    atomic.commit();
  }
  summary.figures = ids;
  return summary;
}

}  // namespace arthrosim::pipelines
