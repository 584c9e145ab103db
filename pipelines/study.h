#pragma once
// Accuracy versus time: `arthrosim study accuracy` (docs/studies.md).
//
// Runs one scene at several settings of one or more scalar scene keys (the
// full grid of the --vary axes), each setting through the scene runner
// (pipelines/runner.h) in its own folder, and measures per stage the wall
// time, CPU time and peak memory of the stage process, and the error of the
// stage's key outputs against a reference setting (by default the last value
// of every axis: values are listed from coarsest to finest):
//
//   comak (stage 1)  tibiofemoral contact force: RMS over the cycle of
//                    |F(t) - F_ref(t)| divided by the mean |F_ref|;
//                    muscle activations: RMS over frames and muscles of
//                    a(t) - a_ref(t) (activations are in [0, 1], so this is
//                    already a fraction of their range)
//   surface.<S>      max deflection: |d - d_ref| / |d_ref| with d the
//   (stage 2)        deflection of largest magnitude over all frames and
//                    nodes, per surface; contact force: like stage 1 from
//                    /contact/tibiofemoral/force of the surface output when
//                    the file has it
//   biphasic         per layer the series of the maximum tensile stress on the
//                    contact surface, the maximum interface shear stress, the
//                    fluid load support, the contact area and the largest fluid
//                    pressure: max |x - x_ref| / max |x_ref| at common steps
//   post             mean direction angle per scenario (summary.json):
//                    |m - m_ref| / m_ref
//
// Series are compared at the reference's frame times, the other series
// interpolated linearly in time (frame counts may differ); frames marked
// failed by COMAK are left out. Meshes of different resolution are never
// compared node by node: only frame-level scalars and vectors are.
//
// The stage error is the largest of its metrics; the recommended setting of a
// stage follows the convergence rule of seeds/001_8413b035bc6d0ea6.txt: the
// coarsest setting for which refining further changes the key outputs by no
// more than 5 % (recommend_setting below).
#include <Eigen/Core>

#include <cstddef>
#include <filesystem>
#include <iosfwd>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "pipelines/cohort.h"
#include "pipelines/stages.h"

namespace arthrosim::pipelines::study {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// One --vary axis: a dotted scene key (common/scene_edit.h) and its values
/// as written in a scene, coarsest first.
struct VaryAxis {
  std::string key;
  std::vector<std::string> values;
  std::size_t reference = 0;  ///< index of the reference value in `values`
};

/// "KEY=V1,V2,..." -> axis with the last value as reference. Throws
/// common::InputError ("--vary: ...") on a missing '=', an empty value, a
/// value given twice.
VaryAxis parse_vary(const std::string& argument);

struct StudyOptions {
  std::filesystem::path scene_file;
  std::vector<VaryAxis> axes;
  /// --reference: "V" (only with one axis) or "KEY=V" per axis; empty = the
  /// last value of every axis.
  std::vector<std::string> reference;
  std::filesystem::path out_dir = "study";
  std::filesystem::path stage_dir;  ///< folder of the arthrosim-<stage> programs
  bool force = false;               ///< rerun every stage of every setting
  /// The convergence rule's threshold: 5 % (seed 001). Every metric is a
  /// fraction (relative error, or activation RMS on its [0, 1] range), so one
  /// threshold applies to all.
  double tolerance = 0.05;
  /// The command line as typed, for the report.
  std::string command_line;
  /// --workflow: run the grid as a one-subject cohort (OUT/cohort.yaml, run
  /// folders OUT/cohort/runs/study/<setting>) through Snakemake
  /// (pipelines/cohort.h) instead of the scene runner; the errors and
  /// recommendations are computed from those folders exactly as for a local
  /// run. Per-stage time, CPU and memory are not measured then (NaN).
  bool use_workflow = false;
  cohort::WorkflowOptions workflow;
};

/// One key output of a stage, compared with the reference (pipelines/stages.h).
using Metric = OutputMetric;

/// One stage of one setting.
struct StageRecord {
  std::string stage;        ///< "prepare", "comak", "surface.osmotic", "post"
  /// "ran", "reused" (up to date: output of an earlier run with the same stage
  /// key), "failed", "not run" (an earlier stage failed).
  std::string run;
  /// For a reused stage: the setting whose run produced the output (or "an
  /// earlier study run"); empty when it ran here.
  std::string produced_by;
  std::string key;                ///< the runner's stage key
  /// For a failed stage: the runner's reason ("exited with status 2").
  std::string failure;
  /// A failed stage whose output files all exist (e.g. arthrosim-comak exits
  /// 2 when frames failed, with them marked in the file): its metrics are
  /// computed over what it wrote, but the setting never qualifies for the
  /// recommendation.
  bool failed_with_output = false;
  double wall_time_s = kNaN;      ///< of the run that produced the output
  double cpu_time_s = kNaN;
  double max_rss_mb = kNaN;       ///< peak resident set size of the stage process
  /// Wall time to produce this output from scratch: this stage plus every
  /// stage it depends on (reused ones counted at their measured time).
  double time_to_output_s = kNaN;
  std::vector<Metric> metrics;    ///< empty for prepare (no key output of its own)
  double stage_error = kNaN;      ///< largest metric error (NaN: none available)
};

struct SettingResult {
  std::vector<std::pair<std::string, std::string>> values;  ///< (key, value) per axis
  std::vector<std::size_t> index;  ///< value index per axis
  std::string label;               ///< "prepare.edge_length_mm=2"
  std::filesystem::path scene;     ///< the edited scene copy
  std::filesystem::path dir;       ///< the runner's output folder
  bool ok = false;                 ///< every stage ran or was reused
  std::string failure;             ///< the runner's message when !ok
  double study_wall_time_s = 0.0;  ///< what this setting cost in this study run
  std::vector<StageRecord> stages;
};

struct Recommendation {
  std::string stage;
  int setting = -1;     ///< index into StudyResult::settings; -1: none qualifies
  std::string reason;
  /// cheapest_qualifying_setting(); reported when it is not `setting`.
  int cheapest = -1;
};

struct StudyResult {
  std::vector<SettingResult> settings;
  std::size_t reference = 0;  ///< index of the reference setting
  std::vector<Recommendation> recommended;
  std::vector<std::string> notes;  ///< missing metrics etc., for the report
};

/// Validates everything first (keys, values, reference, that each value
/// changes what some stage runs), then runs every setting and computes the
/// errors and recommendations. Progress goes to `log`. Throws
/// common::InputError for bad input before anything runs. A failing setting
/// does not stop the study (it is recorded); a failing reference leaves every
/// error unavailable.
StudyResult run_accuracy_study(const StudyOptions& options, std::ostream& log);

/// Writes DIR/study.json, DIR/study.csv and DIR/report.html.
void write_study_outputs(const StudyOptions& options, const StudyResult& result);

// ---- pieces, public for tests ------------------------------------------------

/// A sampled series: times (n) and values (n x d); `valid` (empty = all
/// valid) marks frames that may be used.
struct TimeSeries {
  Eigen::VectorXd t;
  Eigen::MatrixXd x;
  std::vector<bool> valid;
};

struct SeriesDifference {
  double rms = kNaN;             ///< sqrt(mean_k |x(t_k) - x_ref(t_k)|^2), |.| the row norm
  double rms_per_component = kNaN;  ///< sqrt(mean_k mean_j (x_j - x_ref_j)^2)
  double mean_norm_ref = kNaN;   ///< mean_k |x_ref(t_k)|
  int compared = 0;              ///< reference frames used
  int skipped = 0;               ///< reference frames outside the other's span or invalid
};

/// Compares `x` with `ref` at the reference's frame times t_k inside the span
/// of `x`, interpolating `x` linearly in time (a frame between two samples is
/// used only when both are valid). Needs equal column counts.
SeriesDifference compare_series(const TimeSeries& x, const TimeSeries& ref);

/// Key outputs of stage 1 (kinematics files, docs/kinematics_file.md):
/// "contact_force" and "activations" of `file` against `ref_file`.
std::vector<Metric> comak_metrics(const std::filesystem::path& file,
                                  const std::filesystem::path& ref_file);
/// Key outputs of stage 2 (surface outputs, docs/surface_output.md):
/// "max_deflection[<surface>]" per surface of the reference, and
/// "contact_force" (error NaN with a note when a file has no
/// /contact/tibiofemoral/force).
std::vector<Metric> surface_metrics(const std::filesystem::path& file,
                                    const std::filesystem::path& ref_file);
/// Key outputs of the biphasic stage (biphasic.h5, docs/biphasic.md):
/// "<series>[<layer>]" for the maximum tensile stress on the contact surface,
/// the maximum interface shear stress, the fluid load support, the contact
/// area and the largest fluid pressure of every layer: max over the common
/// step times of |x - x_ref| divided by max |x_ref|
/// (biphasic::compare_outputs).
std::vector<Metric> biphasic_metrics(const std::filesystem::path& file,
                                     const std::filesystem::path& ref_file);
/// Key output of post (summary.json, docs/post.md): "mean_angle[<scenario>]"
/// per scenario of the reference.
std::vector<Metric> post_metrics(const std::filesystem::path& file,
                                 const std::filesystem::path& ref_file);

/// The seed-001 rule on a grid. grid[s][a] = value index of setting s on axis
/// a (order = coarse to fine); error[s] = its stage error (NaN = unknown);
/// cost[s] = its time (tie-break). A setting qualifies when it and every
/// setting at least as fine on every axis have error <= tolerance (so
/// refining further from it changes the outputs by no more than the
/// tolerance). Returns the qualifying setting that is coarsest (no other
/// qualifying setting is coarser or equal on every axis), the cheapest among
/// several such, or -1 when none qualifies. One axis: the coarsest value from
/// which every finer value is within tolerance.
int recommend_setting(const std::vector<std::vector<std::size_t>>& grid,
                      const std::vector<double>& error, const std::vector<double>& cost,
                      double tolerance);

/// The cheapest (cost) of all qualifying settings in the sense of
/// recommend_setting, coarsest or not; -1 when none qualifies or no
/// qualifying setting has a finite cost. Coarser is not always cheaper: a
/// looser Newton floor can cost more rejected steps than it saves.
int cheapest_qualifying_setting(const std::vector<std::vector<std::size_t>>& grid,
                                const std::vector<double>& error, const std::vector<double>& cost,
                                double tolerance);

/// Settings on the Pareto front of (time, error): none other is at most as
/// slow and at most as wrong, and strictly better in one. NaN points excluded.
std::vector<int> pareto_front(const std::vector<double>& time, const std::vector<double>& error);

}  // namespace arthrosim::pipelines::study
