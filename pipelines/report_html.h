#pragma once
// The HTML report of arthrosim (docs/post.md, "Report"): a plain data model of
// what a report shows (a summary of key figures with their targets, sections of
// time plots, 2D maps, 3D surface fields and tables) and its renderer.
//
// The renderer writes DIR/report.html and DIR/plotly-gl3d.min.js (plotly.js,
// vendored in third_party/ and embedded in the program), so the report opens
// offline from its folder. Every figure is a plotly.js figure (data + layout as
// JSON inside the page): ticks, zoom, hover and legend toggling are plotly's.
// Numbers in tables and the summary are rounded to three significant digits.
// The page checks after drawing that every figure drew (no script error, every
// figure element of non-zero size) and writes the result into
// <pre id="report-check"> (JSON), which tests read with headless Chromium; a
// figure that failed is named in a banner at the top of the page.
#include <Eigen/Core>

#include <filesystem>
#include <string>
#include <variant>
#include <vector>

namespace arthrosim::pipelines::report_html {

/// Line style of a series. Stages are told apart by style as well as colour:
/// by convention stage 1 kSolid, stage 2 kDash, limits and targets kDot.
enum class Dash { kSolid, kDash, kDot, kDashDot };

struct Line {
  std::string label;   ///< legend entry
  std::string group;   ///< legend group title (e.g. "stage 1"); lines of a group toggle together
  std::vector<double> x, y;
  Dash dash = Dash::kSolid;
  int colour = 0;      ///< index into the report's qualitative palette
  bool markers = false;  ///< a marker at every point (few points)
};

/// Zoomable line plot, e.g. a time series (x and y labels carry their unit: "time [s]").
struct LinePlot {
  std::string id, title, caption, x_label, y_label;
  std::vector<Line> lines;
};

/// One nodal field on a surface (value per node; NaN = none).
struct Field {
  std::string label;   ///< e.g. "deflection, first peak (t = 0.16 s)"
  std::string unit;    ///< colour-bar unit, e.g. "mm"
  std::vector<double> values;
};

/// A surface mesh with fields: a rotatable 3D view (one figure, a menu to
/// switch the field). Coordinates in mm.
struct SurfacePlot {
  std::string id, title, caption;
  Eigen::MatrixX3d nodes_mm;
  Eigen::MatrixX3i triangles;
  std::vector<Field> fields;
};

/// A 2D map in a view plane (mm, equal aspect): outlines, axial direction
/// segments and coloured points, in that drawing order.
struct Polyline {
  std::string label;
  Eigen::MatrixX2d points;
  bool closed = true;
  Dash dash = Dash::kSolid;
  int colour = 0;  ///< palette index; -1 = grey
};
struct Segments {
  std::string label;
  Eigen::MatrixX2d centres;
  Eigen::VectorXd angle_rad;  ///< counter-clockwise from +x; NaN = skip
  Eigen::VectorXd length;     ///< full length [mm] per segment
  int colour = 0;
};
struct Points {
  std::string label;
  Eigen::MatrixX2d xy;
  Eigen::VectorXd values;     ///< colour; NaN = drawn hollow (e.g. "not covered")
  std::string unit;           ///< colour-bar title
  double lo = 0, hi = 0;      ///< colour range; lo == hi: the finite values' range
  double marker_px = 6;
};
struct MapPlot {
  std::string id, title, caption;
  std::string x_label = "view right [mm]", y_label = "view up [mm]";
  std::vector<Polyline> outlines;
  std::vector<Segments> segments;
  std::vector<Points> points;
};

/// A table cell: text, an integer (exact) or a real (three significant digits).
using Cell = std::variant<std::string, long long, double>;
struct Table {
  std::string id, title, caption;
  std::vector<std::string> header;  ///< units in the header: "mean [deg]"
  std::vector<std::vector<Cell>> rows;
};

/// Free text (escaped); `list` items become a bulleted list.
struct Text {
  std::string paragraph;
  std::vector<std::string> list;
  bool warning = false;  ///< drawn as a warning (missing inputs)
};

using Block = std::variant<Text, LinePlot, MapPlot, SurfacePlot, Table>;

struct Section {
  std::string id, title;
  std::vector<Block> blocks;
};

/// One key figure of the summary block at the top of the report.
enum class Verdict { kPass, kFail, kInfo };
struct SummaryRow {
  std::string quantity;   ///< "stage 1 first peak"
  std::string value;      ///< formatted with its unit
  std::string reference;  ///< target or the seed's value, with its source
  Verdict verdict = Verdict::kInfo;
  std::string figure;     ///< id the row links to (empty: none)
};

struct Report {
  std::string title = "arthrosim report";
  std::vector<std::string> header;  ///< lines under the title (scene, inputs)
  std::string banner;               ///< e.g. "the split-line map is SYNTHETIC"; empty = none
  std::vector<SummaryRow> summary;
  std::vector<Section> sections;
};

/// `v` with `digits` significant digits, trailing zeros dropped, no exponent
/// for 1e-4 <= |v| < 1e6 ("1470", "0.039", "-1.7e-17" -> "-1.73e-17");
/// NaN/Inf -> "-".
std::string significant(double v, int digits = 3);

/// Ids of every plot (line, map, surface; not the tables) of the report, in order.
std::vector<std::string> figure_ids(const Report& report);

/// The page (report.html's text). Throws std::invalid_argument on a model
/// that cannot be drawn honestly (an axis without a label, duplicate ids,
/// a field whose size is not the mesh's, a summary row linking to no figure).
std::string render(const Report& report);

/// Writes DIR/report.html and DIR/plotly-gl3d.min.js (replacing them).
/// Returns report.html's path. Throws common::InputError when a file cannot be written.
std::filesystem::path write(const Report& report, const std::filesystem::path& dir);

/// File name of the plotly.js bundle written next to report.html.
inline constexpr const char* kPlotlyFile = "plotly-gl3d.min.js";

}  // namespace arthrosim::pipelines::report_html
