#pragma once
// Split-line maps (issue 7; seed 002_3ffcc11eb7a447d9.txt, "Comparison with Cartilage
// Split Lines"): the superficial collagen orientation revealed by ink-needle split lines,
// as traced by a researcher over a published figure. Formats (docs/post.md):
//
//  * SVG from any vector editor: exactly one closed path/polygon (Z-closed <path>,
//    <polygon>) is the cartilage outline; every open <path>, <polyline> and <line> is a
//    split line. Path commands M L H V C Z (absolute and relative; implicit repeats);
//    cubic curves are sampled. Group/element transforms: translate, scale, rotate,
//    matrix (composed in document order). SVG's y axis points down: the reader returns
//    (x, -y) so that map coordinates are right-handed (y up) like every model view.
//    A split line's region is its own `data-region` attribute, else the id of its
//    nearest enclosing <g> that has one, else "all".
//  * CSV: `[samples]` section with header `x,y,angle_deg[,region]` and one sample per
//    line (map units, y up, angle counter-clockwise from +x, axial); `[outline]` section
//    with header `x,y` and the outline polygon in order. '#' starts a comment line.
//
// Orientation is axial everywhere: an angle theta and theta + pi are the same line.
// Errors are common::InputError "file:line: error: expected ..., found ...".
#include <Eigen/Core>

#include <string>
#include <vector>

namespace arthrosim::pipelines {

struct SplitLine {
  Eigen::MatrixX2d points;  ///< polyline vertices in map units (y up), in drawing order
  std::string region = "all";
  int source_line = 0;      ///< line in the file where the element starts
};

struct SplitLineMap {
  std::string source;             ///< file it was read from
  Eigen::MatrixX2d outline;       ///< closed polygon (first vertex not repeated)
  std::vector<SplitLine> lines;   ///< empty for CSV maps
  Eigen::MatrixX2d samples;       ///< sample points (map units)
  Eigen::VectorXd angle_rad;      ///< axial orientation of each sample, in (-pi/2, pi/2]
  std::vector<std::string> region;  ///< region of each sample
  double spacing = 0.0;           ///< sample spacing along the lines (map units)
  bool synthetic = false;         ///< the file says SYNTHETIC (documented test maps)
};

/// Reads an SVG map. `sample_spacing` (map units, > 0; 0 = 1/100 of the outline's
/// bounding-box diagonal) sets the distance between samples along each split line;
/// each sample's angle is that of the polyline segment it lies on. Throws InputError.
SplitLineMap read_splitline_svg(const std::string& path, double sample_spacing = 0.0);
/// Same from text in memory (`path` is used in messages).
SplitLineMap parse_splitline_svg(const std::string& text, const std::string& path, double sample_spacing = 0.0);

/// Reads a CSV map (see above). spacing = median nearest-neighbour distance of the samples.
SplitLineMap read_splitline_csv(const std::string& path);
SplitLineMap parse_splitline_csv(const std::string& text, const std::string& path);

/// By extension (.svg / .csv, case-insensitive); anything else is an InputError.
SplitLineMap read_splitline_map(const std::string& path, double sample_spacing = 0.0);

/// Samples polylines every `spacing` (arc length, from half a spacing in), angle of the
/// segment at each sample. Polylines shorter than a spacing give one sample at their middle.
void sample_split_lines(SplitLineMap& map, double spacing);

/// Axial angle wrapped to (-pi/2, pi/2].
double wrap_axial(double angle_rad);

}  // namespace arthrosim::pipelines
