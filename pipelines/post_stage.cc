#include "pipelines/post_stage.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <numbers>

#include "common/error.h"
#include "common/effects.h"
#include "common/hdf5.h"
#include "common/log.h"
#include "common/scene.h"
#include "musculoskeletal/kinematics_file.h"
#include "pipelines/json.h"
#include "pipelines/stages.h"
#include "pipelines/surface_output.h"
#include "pipelines/study.h"
#include "pipelines/report.h"

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
    if (scenarios.empty()) s.unavailable = "a 'surface' block with at least one scenario";
    for (const common::BlockInstance& sc : scenarios) {
      const std::filesystem::path file = out / ("surface_" + sc.name + ".h5");
      s.inputs.emplace_back(file.filename().string(), file);
      s.arguments.insert(s.arguments.end(), {"--surface", file.string()});
    }
    const std::filesystem::path kinematics = out / "kinematics.h5";
    s.optional_inputs.push_back({"kinematics.h5", kinematics, {"--kinematics", kinematics.string()}});
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
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Every dataset under `group` (the contact group of a kinematics file or a
// surface output) whose name contains "force" and has shape (n) or (n, 3)
// with n = frames becomes a series (|F| for 3 columns), labelled by its path
// below the group (docs/kinematics_file.md: force, medial_force,
// lateral_force; cop, area and max_pressure are not forces and are skipped).
// The frames' times: the kinematics clock (a surface output with imposed
// kinematics starts with a seating ramp; its /trial_time puts its frames on
// the kinematics file's clock).
std::vector<report::Series> contact_series(const common::H5File& f, const std::string& group, const std::string& prefix) {
  std::vector<report::Series> out;
  if (!f.is_group(group) || !f.exists("/time")) return out;
  const Eigen::VectorXd t = f.read_vector(f.exists("/trial_time") ? "/trial_time" : "/time");
  std::function<void(const std::string&)> walk = [&](const std::string& g) {
    for (const auto& name : f.list(g)) {
      const std::string p = g + "/" + name;
      if (f.is_group(p)) {
        walk(p);
        continue;
      }
      if (f.type(p) != common::H5Type::kDouble || name.find("force") == std::string::npos) continue;
      const auto d = f.dims(p);
      report::Series s;
      s.label = prefix + p.substr(group.size() + 1);
      if (d.size() == 1 && d[0] == t.size()) {
        const Eigen::VectorXd v = f.read_vector(p);
        s.y.assign(v.data(), v.data() + v.size());
      } else if (d.size() == 2 && d[0] == t.size() && d[1] == 3) {
        const Eigen::MatrixXd m = f.read_matrix(p);
        s.label += " |F|";
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
  const auto t_start = Clock::now();
  fs::create_directories(out_dir);
  PostSummary summary;
  std::vector<std::pair<std::string, double>> timing;  // post's own steps
  struct Figure {
    std::string id, caption, svg;
  };
  std::vector<Figure> figures;
  auto add_figure = [&](const std::string& id, const std::string& caption, std::string svg) {
    figures.push_back({id, caption, std::move(svg)});
  };

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
  std::vector<report::Series> force;
  std::vector<AttrRow> attrs;
  report::Json json;
  json.begin_object();
  json.value("schema", "arthrosim post summary 1");
  json.value("scene", in.scene_file);
  if (!in.kinematics.empty()) {
    const auto t0 = Clock::now();
    const musculoskeletal::KinematicsFileReader kin(in.kinematics);
    const common::H5File& k = kin.file();
    const std::string group = musculoskeletal::KinematicsFileReader::kContactGroup;
    auto s = contact_series(k, group, "stage 1 ");
    if (s.empty()) summary.missing.push_back("kinematics file " + in.kinematics + " has no " + group + " series over its frames");
    force.insert(force.end(), s.begin(), s.end());
    auto a = attributes(k, "kinematics");
    attrs.insert(attrs.end(), a.begin(), a.end());
    timing.emplace_back("read kinematics", seconds_since(t0));
  }
  bool any_stage2 = false;
  for (const auto& [scenario, file] : in.surfaces) {
    const surface_output::Reader out(file);
    const common::H5File& f = out.file();
    auto s = contact_series(f, surface_output::kContactGroup, "stage 2 " + scenario + " ");
    any_stage2 = any_stage2 || !s.empty();
    force.insert(force.end(), s.begin(), s.end());
    auto a = attributes(f, scenario);
    attrs.insert(attrs.end(), a.begin(), a.end());
  }
  if (!in.surfaces.empty() && !any_stage2) {
    summary.missing.push_back(std::string("no surface output holds ") + surface_output::kContactGroup +
                              " (stage-2 contact force)");
  }
  if (!force.empty()) add_figure("fig-contact", "Tibiofemoral contact force over the cycle (stage 1 vs stage 2)",
                                 report::line_plot("Tibiofemoral contact force", "time [s]", "force [N]", force));
  json.begin_array("contact_force");
  for (const auto& s : force) {
    json.begin_object().value("label", s.label).array("time_s", s.x).array("value_N", s.y).end_object();
  }
  json.end_array();
  // The seed's accuracy rule per step of every scenario with mesh contact
  // (/solver/penetration_ratio, docs/surface_output.md), on the trial clock
  // like the forces: steps with active contacts only, as the stage checks it.
  std::vector<report::Series> ratio_series;
  std::vector<std::vector<std::string>> rule_rows;
  json.begin_array("accuracy_rule");
  for (const auto& [scenario, file] : in.surfaces) {
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
    report::Series s, si;
    s.label = "stage 2 " + scenario;
    si.label = "stage 2 " + scenario + ", unfaded contacts";
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
    std::string i_median = "(not recorded)", i_max = "-", i_over = "-";
    if (has_unfaded) {
      const double im = median_of(unfaded), ix = *std::max_element(unfaded.begin(), unfaded.end());
      json.value("median_unfaded_ratio", im).value("max_unfaded_ratio", ix);
      if (has_limit) json.value("steps_over_limit_unfaded", unfaded_over);
      i_median = report::number(im);
      i_max = report::number(ix);
      if (has_limit) i_over = std::to_string(unfaded_over);
    }
    json.end_object();
    rule_rows.push_back({scenario, std::to_string(m), report::number(median), report::number(max_ratio),
                         has_limit ? report::number(limit) : std::string("(not recorded)"),
                         has_limit ? std::to_string(over) : std::string("-"), i_median, i_max, i_over});
    if (has_limit && ratio_series.empty()) {
      report::Series lim;
      lim.label = "limit " + report::number(limit);
      lim.x = {s.x.front(), s.x.back()};
      lim.y = {limit, limit};
      ratio_series.push_back(std::move(lim));
    }
    ratio_series.push_back(std::move(s));
    if (has_unfaded) ratio_series.push_back(std::move(si));
  }
  json.end_array();
  if (!rule_rows.empty())
    add_figure("fig-accuracy-rule", "The seed's accuracy rule per step: largest interpenetration / largest deflection "
                                    "(steps with active contacts; 'unfaded': without the contacts next to a rim)",
               report::line_plot("Interpenetration / deflection", "time [s]", "ratio", ratio_series));
  // Key frames: peaks of the total stage-1 force, else largest deflection and last frame.
  std::vector<std::pair<std::string, double>> key_times;
  if (!force.empty()) {
    const auto& s = force.front();
    const double t0 = s.x.front(), T = s.x.back() - s.x.front();
    auto arg = [&](double a, double b, bool mx) {
      int best = -1;
      for (size_t i = 0; i < s.x.size(); ++i)
        if (s.x[i] >= t0 + a * T && s.x[i] <= t0 + b * T && (best < 0 || (mx ? s.y[i] > s.y[best] : s.y[i] < s.y[best])))
          best = static_cast<int>(i);
      return best;
    };
    const int p1 = arg(0.0, 0.3, true), p2 = arg(0.3, 0.65, true);
    if (p1 >= 0 && p2 >= 0) {
      int mid = p1;
      for (int i = p1; i <= p2; ++i)
        if (s.y[i] < s.y[mid]) mid = i;
      key_times = {{"first peak", s.x[p1]}, {"mid-stance", s.x[mid]}, {"second peak", s.x[p2]}};
    }
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
  for (const auto& [scenario, file] : in.surfaces) {
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
    const Eigen::MatrixXi quads = field.mesh.Q;
    const std::string sid = "fig-" + std::to_string(summary.scenarios.size());
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
    json.begin_object().value("scenario", scenario).value("file", file).value("nodes", oc.nodes).value("frames", oc.frames);
    json.begin_array("key_frames");
    for (size_t kf = 0; kf < frames.size(); ++kf) {
      const auto& [name, k] = frames[kf];
      const std::string t = report::number(field.time(k));
      if (field.deflection.size() > 0) {
        const Eigen::VectorXd v = field.deflection.row(k).transpose() * 1e3;
        add_figure(sid + "-deflection-" + std::to_string(kf), scenario + ": deflection at " + name + " (t = " + t + " s)",
                   report::field_map(scenario + " deflection, " + name, view.nodes, quads, v, "mm"));
        json.begin_object().value("name", name).value("time_s", field.time(k)).value("deflection_max_mm", v.maxCoeff())
            .value("deflection_min_mm", v.minCoeff()).value("e1_max", field.e1.row(k).maxCoeff())
            .value("e1_min", field.e1.row(k).minCoeff()).end_object();
      } else {
        json.begin_object().value("name", name).value("time_s", field.time(k)).value("e1_max", field.e1.row(k).maxCoeff())
            .value("e1_min", field.e1.row(k).minCoeff()).end_object();
      }
      const Eigen::VectorXd e1 = field.e1.row(k).transpose();
      add_figure(sid + "-e1-" + std::to_string(kf), scenario + ": first principal strain e1 at " + name + " (t = " + t + " s)",
                 report::field_map(scenario + " e1, " + name, view.nodes, quads, e1, "strain"));
    }
    json.end_array();
    if (field.deflection.size() == 0) summary.missing.push_back(scenario + ": no deflection dataset in " + file);
    Eigen::VectorXd w = nd.magnitude;
    for (Eigen::Index i = 0; i < w.size(); ++i)
      if (!usable[i]) w(i) = 0;
    add_figure(sid + "-directions", scenario + ": time-averaged magnitude-weighted e1 directions (segment length ~ sqrt of mean |e1|)",
               report::direction_map(scenario + " averaged e1 directions", view.outline, view.nodes, ang, w));
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
      add_figure(sid + "-overlay", scenario + ": registered split-line map (red) over the model's averaged directions (blue)",
                 report::overlay(scenario + " registered split lines", view.outline, reg.warped_outline, c.points,
                                 c.map_angle, c.model_angle));
      add_figure(sid + "-error", scenario + ": acute angle between model and map lines per sample",
                 report::error_map(scenario + " angle error", view.outline, c.points, c.error_deg));
      json.begin_object("registration")
          .value("affine_status", common::to_string(reg.affine.status))
          .value("affine_iterations", reg.affine.iterations)
          .value("nonrigid", reg.has_nonrigid)
          .value("nonrigid_status", reg.has_nonrigid ? common::to_string(reg.nonrigid.status) : std::string("not run"))
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
  }
  json.end_array();
  json.value("angle_threshold_deg", opt.comparison.threshold_rad * 180.0 / std::numbers::pi);
  json.array("missing", summary.missing);
  timing.emplace_back("post total (before writing)", seconds_since(t_start));
  json.begin_array("timing_post");
  for (const auto& [k, v] : timing) json.begin_object().value("step", k).value("seconds", v).end_object();
  json.end_array();
  json.begin_array("input_attributes");
  for (const auto& a : attrs) json.begin_object().value("file", a.file).value("object", a.object).value("key", a.key).value("value", a.value).end_object();
  json.end_array();
  std::vector<std::string> ids;
  for (const auto& f : figures) ids.push_back(f.id);
  json.array("figures", ids);
  json.end_object();

  // ---- report.html (XHTML) ---------------------------------------------------------
  std::string h;
  h += "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<!DOCTYPE html>\n<html xmlns=\"http://www.w3.org/1999/xhtml\">\n<head>"
       "<meta charset=\"UTF-8\"/><title>arthrosim post report</title><style>"
       "body{font-family:sans-serif;max-width:1000px;margin:auto;padding:1em}figure{display:inline-block;margin:0.5em;"
       "vertical-align:top}figcaption{max-width:460px;font-size:0.9em}table{border-collapse:collapse;margin:0.5em 0}"
       "td,th{border:1px solid #bbb;padding:2px 6px;font-size:0.9em}.missing{color:#a00}</style></head>\n<body>\n";
  h += "<h1>arthrosim post report</h1>\n<p>Scene: " + report::escape(in.scene_file.empty() ? "(none)" : in.scene_file) + "</p>\n";
  if (map.synthetic) h += "<p><strong>The split-line map is SYNTHETIC (a documented test map, not measured data).</strong></p>\n";
  h += "<h2>Missing inputs</h2>\n";
  if (summary.missing.empty()) {
    h += "<p>None.</p>\n";
  } else {
    h += "<ul>";
    for (const auto& m : summary.missing) h += "<li class=\"missing\">" + report::escape(m) + "</li>";
    h += "</ul>\n";
  }
  if (!opt.splitline_map.empty() && !summary.scenarios.empty()) {
    h += "<h2>Split-line comparison</h2>\n<p>Map: " + report::escape(opt.splitline_map.string()) +
         ". Acute angle between the model's averaged first principal strain line and the registered map line, per sample.</p>\n";
    std::vector<std::vector<std::string>> rows;
    for (const auto& s : summary.scenarios)
      for (const auto& r : s.stats)
        rows.push_back({s.scenario, r.region, std::to_string(r.samples), std::to_string(r.covered), report::number(r.mean_deg),
                        report::number(r.median_deg), report::number(r.fraction_within),
                        report::number(s.outline_mean_distance_m * 1e3), report::number(s.averaging_radius_m * 1e3)});
    h += report::table({"scenario", "region", "samples", "covered", "mean [deg]", "median [deg]",
                        "fraction within " + report::number(opt.comparison.threshold_rad * 180.0 / std::numbers::pi) + " deg",
                        "outline distance after registration [mm]", "averaging radius [mm]"},
                       rows);
  }
  if (!rule_rows.empty()) {
    h += "<h2>Accuracy rule of the mesh contact</h2>\n<p>Per step in contact: largest interpenetration over largest "
         "deflection of any surface (the seed's rule asks for at most the limit, 0.1 by default). The last three "
         "columns take only the unfaded contacts, i.e. leave out the faces next to a rim where the contact fades out "
         "(docs/contact.md, \"The seed's accuracy rule\").</p>\n";
    h += report::table({"scenario", "steps in contact", "median ratio", "max ratio", "limit", "steps over the limit",
                        "median ratio, unfaded", "max ratio, unfaded", "steps over, unfaded"},
                       rule_rows);
  }
  h += "<h2>Figures</h2>\n<ol>";
  for (const auto& f : figures) h += "<li><a href=\"#" + f.id + "\">" + report::escape(f.caption) + "</a></li>";
  h += "</ol>\n";
  for (const auto& f : figures) {
    h += "<figure id=\"" + f.id + "\">" + f.svg + "<figcaption>" + report::escape(f.caption) + "</figcaption></figure>\n";
  }
  h += "<h2>Solver statistics and timing (from the input files)</h2>\n";
  {
    std::vector<std::vector<std::string>> rows;
    for (const auto& a : attrs) rows.push_back({a.file, a.object, a.key, a.value});
    if (rows.empty()) h += "<p>No input file carries attributes.</p>"; else h += report::table({"file", "object", "attribute", "value"}, rows);
  }
  h += "\n<h2>Timing of this post run</h2>\n";
  {
    std::vector<std::vector<std::string>> rows;
    for (const auto& [k, v] : timing) rows.push_back({k, report::number(v)});
    h += report::table({"step", "seconds"}, rows);
  }
  h += "\n</body>\n</html>\n";

  summary.report_path = (fs::path(out_dir) / "report.html").string();
  summary.summary_path = (fs::path(out_dir) / "summary.json").string();
  for (const auto& [path, text] : {std::pair{summary.report_path, h}, std::pair{summary.summary_path, json.str() + "\n"}}) {
    std::ofstream out(path, std::ios::binary);
    if (!out) throw InputError(path, 0, "cannot write the output file");
    out << text;
    if (!out) throw InputError(path, 0, "write failed");
  }
  summary.figures = ids;
  return summary;
}

}  // namespace arthrosim::pipelines
