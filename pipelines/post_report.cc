#include "pipelines/post_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "biphasic/output_file.h"
#include "common/error.h"
#include "musculoskeletal/kinematics_file.h"
#include "pipelines/shockwave_output.h"
#include "pipelines/surface_output.h"

namespace arthrosim::pipelines::post_report {
namespace {

using report_html::significant;
using report_html::SummaryRow;
using report_html::Verdict;

bool finite(double v) { return std::isfinite(v); }

std::string pct(double fraction) { return significant(100.0 * fraction) + " %"; }

Verdict in_range(double v, double lo, double hi) { return v >= lo && v <= hi ? Verdict::kPass : Verdict::kFail; }

std::vector<double> to_vector(const Eigen::VectorXd& v, double scale = 1.0) {
  std::vector<double> out(v.size());
  for (Eigen::Index i = 0; i < v.size(); ++i) out[i] = scale * v(i);
  return out;
}

}  // namespace

GaitPeaks gait_peaks(const std::vector<double>& t, const std::vector<double>& y) {
  GaitPeaks g;
  if (t.empty() || t.size() != y.size()) return g;
  const double t0 = t.front(), T = t.back() - t.front();
  auto arg = [&](double a, double b, bool max) {
    int best = -1;
    for (std::size_t i = 0; i < t.size(); ++i)
      if (t[i] >= t0 + a * T && t[i] <= t0 + b * T && (best < 0 || (max ? y[i] > y[best] : y[i] < y[best])))
        best = static_cast<int>(i);
    return best;
  };
  g.first = arg(0.0, 0.3, true);
  g.second = arg(0.3, 0.65, true);
  if (g.first < 0 || g.second < 0) return g;
  g.trough = g.first;
  for (int i = g.first; i <= g.second; ++i)
    if (y[i] < y[g.trough]) g.trough = i;
  // A peak is a local maximum inside the series and the trough lies below
  // both: a window's edge (a run that covers only part of stance) is no peak.
  const int n = static_cast<int>(y.size());
  auto local_max = [&](int i) { return i > 0 && i < n - 1 && y[i] >= y[i - 1] && y[i] >= y[i + 1]; };
  g.found = local_max(g.first) && local_max(g.second) && y[g.trough] < std::min(y[g.first], y[g.second]);
  return g;
}

std::vector<SummaryRow> summary_rows(const KeyFigures& k) {
  std::vector<SummaryRow> rows;
  const std::string range = significant(kPeakLowBW) + "-" + significant(kPeakHighBW) +
                            " BW (in vivo, instrumented implants; Kutzner et al. 2010, cited by the seed)";
  if (finite(k.peak1_bw) && finite(k.peak2_bw)) {
    rows.push_back({"stage 1 first peak of the tibiofemoral force",
                    significant(k.peak1_bw) + " BW at " + significant(k.peak1_s) + " s", range,
                    in_range(k.peak1_bw, kPeakLowBW, kPeakHighBW), k.force_figure});
    rows.push_back({"stage 1 second peak", significant(k.peak2_bw) + " BW at " + significant(k.peak2_s) + " s", range,
                    in_range(k.peak2_bw, kPeakLowBW, kPeakHighBW), k.force_figure});
    if (finite(k.trough_bw))
      rows.push_back({"stage 1 double peak: mid-stance trough", significant(k.trough_bw) + " BW",
                      "below 90 % of the lower peak (the seed: the characteristic double peak)",
                      k.trough_bw < 0.9 * std::min(k.peak1_bw, k.peak2_bw) ? Verdict::kPass : Verdict::kFail,
                      k.force_figure});
  }
  if (finite(k.medial_share_peak1))
    rows.push_back({"stage 1 medial share at the first peak", pct(k.medial_share_peak1),
                    "above 50 % (the seed: the majority through the medial compartment)",
                    k.medial_share_peak1 > 0.5 ? Verdict::kPass : Verdict::kFail, k.force_figure});
  for (const auto& s : k.scenarios) {
    const std::string who = s.name + ": ";
    if (finite(s.peak1_bw) && finite(s.peak2_bw)) {
      std::string ref = range;
      if (finite(k.peak1_bw)) ref = "stage 1: " + significant(k.peak1_bw) + " / " + significant(k.peak2_bw) + " BW; " + range;
      rows.push_back({who + "stage 2 peaks", significant(s.peak1_bw) + " / " + significant(s.peak2_bw) + " BW", ref,
                      in_range(s.peak1_bw, kPeakLowBW, kPeakHighBW) == Verdict::kPass &&
                              in_range(s.peak2_bw, kPeakLowBW, kPeakHighBW) == Verdict::kPass
                          ? Verdict::kPass
                          : Verdict::kFail,
                      k.force_figure});
    }
    if (finite(s.rms_si))
      rows.push_back({who + "RMS difference to stage 1, superior-inferior force",
                      pct(s.rms_si) + " (" + std::to_string(s.rms_frames) + " stage-1 frames)",
                      "the seed: " + pct(kSeedRmsDifference) + " (deformable against solid surfaces); pass at or below",
                      s.rms_si <= kSeedRmsDifference ? Verdict::kPass : Verdict::kFail, k.force_figure});
    if (finite(s.rule_max_ratio)) {
      std::string value = "max " + significant(s.rule_max_ratio) + " over " + std::to_string(s.rule_steps) + " steps";
      if (finite(s.rule_limit)) value += ", " + std::to_string(s.rule_steps_over) + " over the limit";
      rows.push_back({who + "accuracy rule (interpenetration / deflection per step)", value,
                      finite(s.rule_limit) ? "at most " + significant(s.rule_limit) + " every step (the seed's rule)"
                                           : std::string("limit not recorded in the file"),
                      finite(s.rule_limit) ? (s.rule_steps_over == 0 ? Verdict::kPass : Verdict::kFail) : Verdict::kInfo,
                      s.rule_figure});
    }
    if (finite(s.deflection_max_mm))
      rows.push_back({who + "largest femoral deflection (" + s.deflection_when + ")", significant(s.deflection_max_mm) + " mm",
                      "the seed: " + significant(kSeedDeflectionMm) + " mm at the first peak (its knee, its mesh)",
                      Verdict::kInfo, s.deflection_figure});
    if (finite(s.e1_max) && finite(s.e1_min))
      rows.push_back({who + "first principal strain e1, largest / smallest (" + s.deflection_when + ")",
                      pct(s.e1_max) + " / " + pct(s.e1_min),
                      "the seed: " + pct(kSeedE1Max) + " / " + pct(kSeedE1Min) + " at the first peak", Verdict::kInfo,
                      s.deflection_figure});
    if (finite(s.angle_mean_deg))
      rows.push_back({who + "split-line angle error, mean", significant(s.angle_mean_deg) + " deg over " +
                                                                  std::to_string(s.angle_samples) + " samples",
                      "below " + significant(s.angle_threshold_deg) +
                          " deg (post.angle_threshold_deg; the seed compared the maps by eye)",
                      s.angle_mean_deg < s.angle_threshold_deg ? Verdict::kPass : Verdict::kFail, s.angle_figure});
  }
  return rows;
}

report_html::Section biphasic_section(const std::vector<std::pair<std::string, std::string>>& files,
                                      const std::string& kinematics,
                                      const std::vector<std::pair<std::string, double>>& key_times,
                                      const std::vector<std::pair<std::string, std::string>>& surfaces) {
  report_html::Section sec;
  sec.id = "sec-biphasic";
  sec.title = "Biphasic layers";
  sec.blocks.push_back(report_html::Text{
      "Per layer and step (docs/biphasic.md, \"Output\"): the area in contact, the fluid load support (fluid "
      "pressure over total normal stress, integrated over the contact), the largest tensile effective stress at a "
      "contact vertex and the largest shear stress at the cartilage-bone interface; the table names where each "
      "largest stress is: the central, anterior, posterior, medial or lateral region of the layer's plate, and when.",
      {}, false});
  struct Quantity {
    const char* key;
    const char* title;
    const char* axis;
    double scale;
  };
  const Quantity qs[] = {{"area", "Contact area", "contact area [mm^2]", 1e6},
                         {"fls", "Fluid load support", "fluid load support [%]", 100.0},
                         {"tensile", "Largest tensile effective stress (contact)", "stress [MPa]", 1e-6},
                         {"shear", "Largest shear stress (cartilage-bone interface)", "stress [MPa]", 1e-6}};
  report_html::Table peaks;
  peaks.id = "tab-biphasic";
  peaks.title = "Biphasic layers: peaks over the run";
  peaks.header = {"file", "layer", "steps", "largest contact area [mm^2]", "largest fluid load support [%]",
                  "largest tensile stress [MPa]", "where (region of the plate, time)", "largest shear stress [MPa]",
                  "where (region of the plate, time)", "unknowns", "factorisations"};
  std::vector<report_html::LinePlot> plots;
  for (const auto& q : qs) {
    report_html::LinePlot p;
    p.id = std::string("fig-biphasic-") + q.key;
    p.title = q.title;
    p.x_label = "time [s]";
    p.y_label = q.axis;
    plots.push_back(p);
  }
  int colour = 0;
  for (const auto& [label, path] : files) {
    const std::vector<biphasic::LayerSeries> layers = biphasic::read_layer_series(path);
    for (const auto& l : layers) {
      const Eigen::VectorXd* v[] = {&l.contact_area, &l.fluid_load_support, &l.max_tensile, &l.max_shear};
      for (int k = 0; k < 4; ++k) {
        report_html::Line line;
        line.label = l.name;
        line.group = files.size() > 1 ? label : "";
        line.x = to_vector(l.time);
        line.y = to_vector(*v[k], qs[k].scale);
        line.colour = colour;
        line.markers = l.time.size() < 30;
        plots[k].lines.push_back(std::move(line));
      }
      auto mx = [](const Eigen::VectorXd& x, double s) { return x.size() ? s * x.maxCoeff() : kNaN; };
      // The region (named by the biphasic reader) and time of the step with the largest value.
      auto where = [&](const Eigen::VectorXd& x, const std::vector<std::string>& names) -> std::string {
        if (x.size() == 0 || names.size() != static_cast<size_t>(x.size())) return "-";
        Eigen::Index i = 0;
        x.maxCoeff(&i);
        return names[static_cast<size_t>(i)] + " at " + significant(l.time[i]) + " s";
      };
      peaks.rows.push_back({label, l.name, static_cast<long long>(l.time.size()), mx(l.contact_area, 1e6),
                            mx(l.fluid_load_support, 100.0), mx(l.max_tensile, 1e-6),
                            where(l.max_tensile, l.max_tensile_where), mx(l.max_shear, 1e-6),
                            where(l.max_shear, l.max_shear_where), static_cast<long long>(l.unknowns),
                            static_cast<long long>(l.factorizations)});
      ++colour;
    }
  }
  for (auto& p : plots) sec.blocks.push_back(std::move(p));
  sec.blocks.push_back(std::move(peaks));

  // ---- contact pressure beside stage 1's elastic-foundation pressure ------
  struct Source {
    std::string label;
    std::vector<double> t, p_MPa;
  };
  std::vector<Source> sources;
  std::vector<std::string> missing;
  for (const auto& [label, path] : files) {
    for (const auto& l : biphasic::read_layer_series(path)) {
      const std::string who = (files.size() > 1 ? label + " " : std::string()) + l.name;
      if (l.max_contact_stress.size() == l.time.size() && l.time.size() > 0)
        sources.push_back({"biphasic " + who + ": total normal stress", to_vector(l.time),
                           to_vector(l.max_contact_stress, 1e-6)});
      else
        missing.push_back("biphasic " + who + ": no surface/total_normal_stress");
      if (l.max_contact_fluid_pressure.size() == l.time.size() && l.time.size() > 0)
        sources.push_back({"biphasic " + who + ": fluid pressure", to_vector(l.time),
                           to_vector(l.max_contact_fluid_pressure, 1e-6)});
      else
        missing.push_back("biphasic " + who + ": no surface/fluid_pressure");
    }
  }
  if (kinematics.empty()) {
    missing.push_back("stage 1 elastic-foundation pressure: no kinematics file");
  } else {
    const musculoskeletal::KinematicsFileReader k(kinematics);
    if (const auto p = k.tibiofemoral_max_pressure()) {
      sources.push_back({"stage 1 elastic foundation (tibiofemoral)", to_vector(k.time()), to_vector(*p, 1e-6)});
    } else {
      missing.push_back("stage 1 elastic-foundation pressure: " + kinematics + " has no " +
                        musculoskeletal::KinematicsFileReader::tibiofemoral_max_pressure_dataset());
    }
  }
  if (surfaces.empty()) missing.push_back("shell stage contact pressure: no surface-stage file");
  for (const auto& [scenario, path] : surfaces) {
    std::string why;
    const std::optional<surface_output::Series> s = surface_output::Reader(path).max_contact_pressure(why);
    if (!s || s->time.size() == 0) {
      missing.push_back("shell stage " + scenario + ": " + (s ? path + " has no complete frame" : why));
      continue;
    }
    sources.push_back({"shell stage " + scenario + ": contact pressure", to_vector(s->time),
                       to_vector(Eigen::VectorXd(s->values.col(0)), 1e-6)});
  }
  sec.blocks.push_back(report_html::Text{
      "Peak contact pressure: per biphasic layer the largest applied total normal stress and contact fluid "
      "pressure over its articular vertices per step (surface/total_normal_stress, surface/fluid_pressure), beside "
      "stage 1's largest elastic-foundation pressure over the tibiofemoral contact (kinematics file " + musculoskeletal::KinematicsFileReader::tibiofemoral_max_pressure_dataset() +
          ") and, per surface-stage scenario, the shell stage's largest contact pressure over its surfaces' nodes per "
          "stored frame on the trial clock (surface_<scenario>.h5 contact_pressure at /trial_time; the seating "
          "ramp's frames come before the trial's first frame). The table gives them at the key frames: each source at its stored "
          "step or frame nearest each key time (not interpolated), with the time used; \"-\" where the key time is "
          "farther from the source's stored times than their largest spacing. Not shown: " +
          [&] {
            std::string m;
            for (const auto& x : missing) m += (m.empty() ? "" : "; ") + x;
            return m;
          }() + ".",
      {}, false});
  report_html::LinePlot pp;
  pp.id = "fig-biphasic-pressure";
  pp.title = "Peak contact pressure: biphasic layers, stage-1 elastic foundation and shell stage";
  pp.x_label = "time [s]";
  pp.y_label = "pressure [MPa]";
  int c = 0;
  for (const auto& s : sources) {
    report_html::Line line;
    line.label = s.label;
    line.x = s.t;
    line.y = s.p_MPa;
    line.colour = c++;
    line.markers = s.t.size() < 30;
    pp.lines.push_back(std::move(line));
  }
  sec.blocks.push_back(std::move(pp));
  if (!key_times.empty()) {
    report_html::Table kt;
    kt.id = "tab-biphasic-pressure";
    kt.title = "Peak contact pressure at the key frames [MPa]";
    kt.header = {"source"};
    for (const auto& [name, t] : key_times) {
      kt.header.push_back(name + " (" + significant(t) + " s) [MPa]");
      kt.header.push_back(name + ": time used [s]");
    }
    for (const auto& s : sources) {
      std::vector<report_html::Cell> row{s.label};
      // A key time outside the source's stored times by more than its largest
      // spacing has no nearby frame: "-" rather than the last frame's value.
      double gap = 0.0;
      for (std::size_t i = 1; i < s.t.size(); ++i) gap = std::max(gap, s.t[i] - s.t[i - 1]);
      for (const auto& kv : key_times) {
        const double tk = kv.second;
        std::size_t best = 0;
        for (std::size_t i = 1; i < s.t.size(); ++i)
          if (std::abs(s.t[i] - tk) < std::abs(s.t[best] - tk)) best = i;
        if (s.t.empty() || std::abs(s.t[best] - tk) > gap) {
          row.push_back(kNaN);
          row.push_back(kNaN);
        } else {
          row.push_back(s.p_MPa[best]);
          row.push_back(s.t[best]);
        }
      }
      kt.rows.push_back(std::move(row));
    }
    sec.blocks.push_back(std::move(kt));
    // Maps at the key frames: per layer, the applied total normal stress over
    // its articular vertices (bone frame X anterior, Z lateral for a right
    // knee) at the step nearest each key time, one colour range per layer.
    for (const auto& [label, path] : files) {
      const biphasic::SurfaceMaps maps = biphasic::read_surface_maps(path);
      const Eigen::VectorXd& t = maps.time;
      if (t.size() == 0) continue;
      for (const biphasic::LayerSurfaceMap& layer : maps.layers) {
        const std::string& name = layer.name;
        const Eigen::MatrixXd& sigma = layer.total_normal_stress;
        const Eigen::MatrixXd& v = layer.articular_vertices;
        std::vector<Eigen::Index> steps;
        double hi = 0.0;
        for (const auto& kv : key_times) {
          Eigen::Index best = 0;
          (t.array() - kv.second).abs().minCoeff(&best);
          steps.push_back(best);
          hi = std::max(hi, 1e-6 * sigma.row(best).maxCoeff());
        }
        for (std::size_t k = 0; k < key_times.size(); ++k) {
          report_html::MapPlot m;
          m.id = "fig-biphasic-map-" + std::to_string(sec.blocks.size());
          m.title = (files.size() > 1 ? label + " " : std::string()) + name + ": total normal stress at the " +
                    key_times[k].first + " (step " + significant(t[steps[k]]) + " s)";
          m.x_label = "bone frame X (anterior) [mm]";
          m.y_label = "bone frame Z [mm]";
          report_html::Points pts;
          pts.label = "sigma_Tot_nn";
          pts.xy.resize(v.rows(), 2);
          pts.xy.col(0) = 1e3 * v.col(0);
          pts.xy.col(1) = 1e3 * v.col(2);
          pts.values = 1e-6 * sigma.row(steps[k]).transpose();
          pts.unit = "MPa";
          pts.lo = 0.0;
          pts.hi = hi > 0.0 ? hi : 1.0;
          pts.marker_px = 4;
          m.points.push_back(std::move(pts));
          sec.blocks.push_back(std::move(m));
        }
      }
    }
  }
  return sec;
}

std::string seed_conclusion_text(const std::vector<std::pair<std::string, std::vector<EfdVolume>>>& by_tissue) {
  // Seed 001 (seeds/001_8413b035bc6d0ea6.txt, Conclusions): below 0.3 mJ/mm^2
  // the regeneration conditions "are not formed", above it they are. Read
  // here as: every run below the threshold has a volume meeting all three
  // criteria at most a tenth of the smallest such volume of the runs above it,
  // and that smallest volume is not zero.
  constexpr double kThreshold = 0.3;  // [mJ/mm^2]
  std::string text;
  for (const auto& [tissue, pts] : by_tissue) {
    double below = -1.0, above = -1.0;  // largest below, smallest above; -1 = no run
    for (const EfdVolume& q : pts) {
      if (q.efd < kThreshold) below = std::max(below, q.all_mm3);
      else if (q.efd > kThreshold) above = above < 0.0 ? q.all_mm3 : std::min(above, q.all_mm3);
    }
    if (below < 0.0 || above < 0.0) continue;
    const bool reproduced = above > 0.0 && below <= 0.1 * above;
    char line[400];
    std::snprintf(line, sizeof line,
                  "%s: the largest volume meeting all three criteria below 0.3 mJ/mm^2 is %.4g mm^3, the smallest above "
                  "it %.4g mm^3: the seed's conclusion (conditions formed only above 0.3 mJ/mm^2) is %s. ",
                  tissue.c_str(), below, above, reproduced ? "reproduced" : "not reproduced");
    text += line;
  }
  if (!text.empty())
    text += "(Criterion: every run below 0.3 mJ/mm^2 reaches at most a tenth of the smallest volume of the runs above "
            "it, and that volume is not zero; docs/shockwave.md.)";
  return text;
}

report_html::Section shockwave_section(const std::vector<std::string>& files) {
  report_html::Section sec;
  sec.id = "sec-shockwave";
  sec.title = "Shockwave treatment";
  sec.blocks.push_back(report_html::Text{
      "Per run (docs/shockwave.md, \"Output\"): the volume of each tissue that met each regeneration criterion at "
      "its peak (compressive stress, distortional strain, pore pressure, and all three), and the largest peaks.",
      {}, false});
  report_html::Table vol;
  vol.id = "tab-shockwave";
  vol.title = "Regeneration volumes per run and tissue";
  vol.header = {"run", "EFD [mJ/mm^2]", "tissue", "volume [mm^3]", "compressive [mm^3]", "distortional [mm^3]",
                "pore pressure [mm^3]", "all three [mm^3]", "largest peak pressure [MPa]",
                "largest distortional strain"};
  std::vector<std::pair<std::string, std::vector<EfdVolume>>> by_tissue;
  for (const auto& path : files) {
    const ShockwaveFile f = read_shockwave_file(path);
    const double efd = f.efd_j_per_m2 * 1e-3;  // J/m^2 -> mJ/mm^2
    for (std::size_t t = 0; t < f.tissue_names.size(); ++t) {
      double pmax = kNaN, smax = kNaN;
      for (Eigen::Index i = 0; i < f.tissue.size(); ++i) {
        if (f.tissue(i) != static_cast<int>(t)) continue;
        if (i < f.peak_pressure.size()) pmax = std::isfinite(pmax) ? std::max(pmax, f.peak_pressure(i)) : f.peak_pressure(i);
        if (i < f.peak_distortional_strain.size())
          smax = std::isfinite(smax) ? std::max(smax, f.peak_distortional_strain(i)) : f.peak_distortional_strain(i);
      }
      const auto& v = f.volumes[t];
      vol.rows.push_back({f.label, efd > 0 ? report_html::Cell(efd) : report_html::Cell(std::string("-")),
                          f.tissue_names[t], v[0] * 1e9, v[1] * 1e9, v[2] * 1e9, v[3] * 1e9, v[4] * 1e9, pmax * 1e-6,
                          smax});
      if (efd > 0) {
        auto it = std::find_if(by_tissue.begin(), by_tissue.end(), [&](const auto& p) { return p.first == f.tissue_names[t]; });
        if (it == by_tissue.end()) it = by_tissue.insert(by_tissue.end(), {f.tissue_names[t], {}});
        it->second.push_back({efd, v[4] * 1e9});
      }
    }
  }
  // Volume against EFD when at least two runs differ in EFD.
  report_html::LinePlot p;
  p.id = "fig-shockwave-volume";
  p.title = "Volume meeting every regeneration criterion";
  p.x_label = "energy flux density [mJ/mm^2]";
  p.y_label = "volume [mm^3]";
  int colour = 0;
  for (auto& [tissue, pts] : by_tissue) {
    std::sort(pts.begin(), pts.end(), [](const EfdVolume& a, const EfdVolume& b) { return a.efd < b.efd; });
    if (pts.size() < 2) continue;
    report_html::Line l;
    l.label = tissue, l.colour = colour++, l.markers = true;
    for (const auto& q : pts) l.x.push_back(q.efd), l.y.push_back(q.all_mm3);
    p.lines.push_back(std::move(l));
  }
  if (!p.lines.empty()) sec.blocks.push_back(std::move(p));
  sec.blocks.push_back(std::move(vol));
  // The seed's conclusion concerns cartilage and menisci (fibrocartilage) only.
  std::vector<std::pair<std::string, std::vector<EfdVolume>>> seed_tissues;
  for (const auto& entry : by_tissue)
    if (entry.first == "cartilage" || entry.first == "fibrocartilage") seed_tissues.push_back(entry);
  if (const std::string verdict = seed_conclusion_text(seed_tissues); !verdict.empty())
    sec.blocks.push_back(report_html::Text{verdict, {}, false});
  return sec;
}

}  // namespace arthrosim::pipelines::post_report
