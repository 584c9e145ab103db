#pragma once
// arthrosim-post driver (docs/post.md): reads the deformable-surface outputs of one or
// more scenarios, optionally the kinematics file and a split-line map, and writes
// DIR/report.html (pipelines/report_html.h; plotly.js beside it) and DIR/summary.json
// (the same numbers). Optional inputs that are absent are listed in both files under
// "missing"; they never stop the run.
#include <filesystem>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "common/options.h"
#include "pipelines/post_compare.h"

namespace arthrosim::common {
struct Scene;
}

namespace arthrosim::pipelines {

struct StageDescriptor;
/// The post stage's entry in the stage table (pipelines/stages.h).
StageDescriptor post_stage_descriptor();

/// The scene's post block (docs/scenes.md).
struct PostOptions {
  /// Surface of the surface-output files that is projected and compared.
  std::string view_surface = "femur";
  /// Default view: distal view of the femur, looking superiorly, anterior up.
  ViewOptions view{Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(1, 0, 0)};
  RegistrationOptions registration;
  ComparisonOptions comparison;
  std::filesystem::path splitline_map;  ///< empty = none
  double map_sample_spacing = 0.0;  ///< SVG sampling (map units), 0 = automatic
  void declare(common::OptionVisitor& v);
};

/// The scene's post block as options.
PostOptions post_from_scene(const common::Scene& scene);

struct PostInputs {
  std::vector<std::pair<std::string, std::string>> surfaces;  ///< (scenario, file)
  std::string kinematics;  ///< empty = none
  std::vector<std::pair<std::string, std::string>> biphasic;  ///< (label, biphasic.h5); empty = none
  std::vector<std::string> shockwave;                           ///< shockwave run files; empty = none
  std::string scene_file;  ///< for the report header
};

struct ScenarioOutcome {
  std::string scenario, file;
  std::vector<RegionStatistics> stats;  ///< empty without a map
  double outline_mean_distance_m = 0.0;
  double averaging_radius_m = 0.0;
  int nodes = 0, frames = 0;
};

struct PostSummary {
  std::vector<std::string> missing;
  std::vector<ScenarioOutcome> scenarios;
  std::vector<std::string> figures;  ///< ids of the figures in report.html
  std::string report_path, summary_path;
};

/// One scenario of a summary.json, as its readers need it.
struct PostScenarioSummary {
  std::string scenario;
  /// Mean model-map angle [deg]: region "all" when present, else the
  /// covered-sample-weighted mean over the regions; NaN without statistics.
  double mean_angle_deg = std::numeric_limits<double>::quiet_NaN();
};
/// The post stage's summary.json (written by run_post): its scenarios.
/// InputError naming the file for unreadable JSON.
std::vector<PostScenarioSummary> read_post_summary(const std::filesystem::path& file);

/// Runs the post stage into `out_dir` (created). Throws InputError for unreadable or
/// malformed inputs that were given.
PostSummary run_post(const PostInputs& inputs, const PostOptions& options, const std::string& out_dir);

}  // namespace arthrosim::pipelines
