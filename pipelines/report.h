#pragma once
// Self-contained report pieces for arthrosim-post (docs/post.md): inline SVG figures
// drawn here (no plotting library) and XHTML-safe escaping (JSON: pipelines/json.h).
// Every figure is a complete <svg> element in the SVG namespace, so the report is
// well-formed XML (XHTML) and can be checked with any XML parser.
#include <Eigen/Core>

#include <string>
#include <vector>

#include "pipelines/json.h"

namespace arthrosim::pipelines::report {

/// &, <, >, " and ' escaped for XML text and attribute values.
std::string escape(const std::string& text);
/// Shortest round-trip-ish decimal for tables/JSON ("%.6g"); NaN/Inf -> "null".
std::string number(double value);

struct Series {
  std::string label;
  std::vector<double> x, y;
};

/// Line plot of several series with axes, ticks and a legend.
std::string line_plot(const std::string& title, const std::string& x_label, const std::string& y_label,
                      const std::vector<Series>& series);

/// Quads filled by a nodal value (mean of the quad's nodes), viridis colours, colour bar.
std::string field_map(const std::string& title, const Eigen::MatrixX2d& nodes, const Eigen::MatrixXi& quads,
                      const Eigen::VectorXd& values, const std::string& unit);

/// Short line segments (axial directions) centred at `points`, length proportional to
/// `weight` (normalised to the largest), drawn over an outline polygon.
std::string direction_map(const std::string& title, const Eigen::MatrixX2d& outline, const Eigen::MatrixX2d& points,
                          const Eigen::VectorXd& angle_rad, const Eigen::VectorXd& weight, int max_segments = 700);

/// Registered split-line overlay: model outline (grey), warped map outline (red), map
/// lines (red) and model lines (blue) at the warped samples.
std::string overlay(const std::string& title, const Eigen::MatrixX2d& model_outline,
                    const Eigen::MatrixX2d& warped_outline, const Eigen::MatrixX2d& points,
                    const Eigen::VectorXd& map_angle, const Eigen::VectorXd& model_angle);

/// Samples coloured by angle error (0..90 deg; NaN = not covered, drawn hollow).
std::string error_map(const std::string& title, const Eigen::MatrixX2d& outline, const Eigen::MatrixX2d& points,
                      const Eigen::VectorXd& error_deg);

/// <table> with a header row; cells are escaped.
std::string table(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows);

/// The JSON writer (pipelines/json.h).
using Json = json::Writer;

}  // namespace arthrosim::pipelines::report
