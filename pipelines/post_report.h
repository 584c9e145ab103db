#pragma once
// Pieces of the post stage's report (docs/post.md, "Report") that are the same
// whatever the run: the gait key instants of a contact force, the summary's
// key figures against their targets or the seed's values, and the sections of
// the later stages (biphasic, shockwave) built from their files through their
// readers. run_post (pipelines/post_stage.cc) assembles the report from these.
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "pipelines/report_html.h"

namespace arthrosim::pipelines::post_report {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// The key instants of a stance-phase contact force y(t): the first peak (max
/// in the first 30 % of the time span), the second peak (max in 30-65 %) and
/// the trough between them (min). Indices into t; found = false unless both
/// peaks are local maxima inside the series with the trough below them (a run
/// covering only part of stance has no key instants).
struct GaitPeaks {
  bool found = false;
  int first = -1, trough = -1, second = -1;
};
GaitPeaks gait_peaks(const std::vector<double>& t, const std::vector<double>& y);

/// Targets the summary compares with, and where they come from.
/// Tibiofemoral contact force peaks in walking: 2-3.5 body weights, the in vivo
/// range of instrumented implants (Kutzner et al. 2010, cited by the seed).
inline constexpr double kPeakLowBW = 2.0, kPeakHighBW = 3.5;
/// Seed 002: time-averaged RMS difference of the net superior-inferior tibial
/// force, deformable-surface model against the solid-surface model: 17 %.
inline constexpr double kSeedRmsDifference = 0.17;
/// Seed 002: largest femoral cartilage deflection 1.1 mm at the first peak;
/// largest tensile / compressive first principal strain then 3 % / -1 %.
inline constexpr double kSeedDeflectionMm = 1.1, kSeedE1Max = 0.03, kSeedE1Min = -0.01;

/// What the summary states; NaN = not available (the row is left out).
struct KeyFigures {
  // Stage 1 (kinematics file).
  double body_weight_N = kNaN;
  double peak1_bw = kNaN, peak2_bw = kNaN, trough_bw = kNaN;
  double peak1_s = kNaN, peak2_s = kNaN;
  double medial_share_peak1 = kNaN;  ///< medial / (medial + lateral) |F| at the first peak
  std::string force_figure;
  struct Scenario {
    std::string name;
    double peak1_bw = kNaN, peak2_bw = kNaN;  ///< stage-2 force at its own peaks
    double rms_si = kNaN;                      ///< RMS(F_SI - F_SI,1) / mean |F_SI,1|
    int rms_frames = 0;
    double rule_max_ratio = kNaN, rule_limit = kNaN;
    int rule_steps = 0, rule_steps_over = 0;
    std::string rule_figure;
    double deflection_max_mm = kNaN;  ///< largest |deflection| at the first peak (or the frame shown)
    double e1_max = kNaN, e1_min = kNaN;
    std::string deflection_when;      ///< "first peak", "largest deflection"
    std::string deflection_figure;
    double angle_mean_deg = kNaN, angle_threshold_deg = kNaN;
    int angle_samples = 0;
    std::string angle_figure;
  };
  std::vector<Scenario> scenarios;
};

/// The summary block: each key figure with its target or the seed's value
/// and a pass/fail mark where there is a rule (docs/post.md, "Summary").
std::vector<report_html::SummaryRow> summary_rows(const KeyFigures& k);

/// Biphasic layers (biphasic.h5, docs/biphasic.md) through
/// biphasic::read_layer_series: contact area, fluid load support, largest
/// tensile and shear stress per layer over time, and a table of their peaks.
/// `files`: (label, path).
/// With `kinematics` (a stage-1 file, may be empty) and the key frames
/// (name, time [s]): a plot of the peak contact pressure per layer (applied
/// total normal stress and contact fluid pressure) beside stage 1's
/// elastic-foundation max_pressure and, per surface-stage file given in
/// `surfaces` ((scenario, path), may be empty), the shell stage's largest
/// contact pressure per frame on the kinematics clock
/// (surface_output::Reader::max_contact_pressure), and a table of these at
/// the key frames (the step / frame nearest each key time, with that time).
report_html::Section biphasic_section(const std::vector<std::pair<std::string, std::string>>& files,
                                      const std::string& kinematics = {},
                                      const std::vector<std::pair<std::string, double>>& key_times = {},
                                      const std::vector<std::pair<std::string, std::string>>& surfaces = {});

/// One shockwave run's volume meeting every regeneration criterion.
struct EfdVolume {
  double efd;      ///< energy flux density [mJ/mm^2]
  double all_mm3;  ///< volume meeting all three criteria [mm^3]
};

/// Whether runs per tissue reproduce seed 001's conclusion (regeneration
/// conditions formed only above 0.3 mJ/mm^2): one sentence per tissue with
/// runs on both sides of 0.3 mJ/mm^2 and the criterion used; empty without
/// such runs.
std::string seed_conclusion_text(const std::vector<std::pair<std::string, std::vector<EfdVolume>>>& by_tissue);

/// Shockwave runs (docs/shockwave.md) through read_shockwave_file: the
/// regeneration volumes per tissue and run, the largest peaks, and the volume
/// meeting every criterion against the energy flux density.
report_html::Section shockwave_section(const std::vector<std::string>& files);

}  // namespace arthrosim::pipelines::post_report
