#include "pipelines/report.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

namespace arthrosim::pipelines::report {
namespace {

constexpr double kW = 460, kH = 340, kMargin = 44;

std::string fmt(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2f", v);
  return b;
}

// Viridis, 9 control points (matplotlib's table sampled at 0, 1/8, ..., 1), linear between.
std::string viridis(double t) {
  static const std::array<std::array<int, 3>, 9> c = {{{68, 1, 84},
                                                         {71, 44, 122},
                                                         {59, 81, 139},
                                                         {44, 113, 142},
                                                         {33, 144, 141},
                                                         {39, 173, 129},
                                                         {92, 200, 99},
                                                         {170, 220, 50},
                                                         {253, 231, 37}}};
  if (!std::isfinite(t)) t = 0;
  t = std::clamp(t, 0.0, 1.0) * 8;
  const int i = std::min(7, static_cast<int>(t));
  const double f = t - i;
  char b[8];
  std::snprintf(b, sizeof b, "#%02x%02x%02x", static_cast<int>(c[i][0] + f * (c[i + 1][0] - c[i][0])),
                static_cast<int>(c[i][1] + f * (c[i + 1][1] - c[i][1])),
                static_cast<int>(c[i][2] + f * (c[i + 1][2] - c[i][2])));
  return b;
}

// Maps data coordinates into the plot box keeping the aspect ratio (maps) or not (plots).
struct Frame {
  double x0, y0, sx, sy, ox, oy;
  Frame(double xmin, double xmax, double ymin, double ymax, bool equal, double right_reserve = 0) {
    const double w = kW - 2 * kMargin - right_reserve, h = kH - 2 * kMargin;
    double dx = xmax - xmin, dy = ymax - ymin;
    if (!(dx > 0)) dx = 1, xmin -= 0.5;
    if (!(dy > 0)) dy = 1, ymin -= 0.5;
    sx = w / dx, sy = h / dy;
    if (equal) sx = sy = std::min(sx, sy);
    x0 = xmin, y0 = ymin;
    ox = kMargin + 0.5 * (w - sx * dx);
    oy = kMargin + 0.5 * (h - sy * dy);
  }
  double X(double x) const { return ox + (x - x0) * sx; }
  double Y(double y) const { return kH - oy - (y - y0) * sy; }
};

std::string header(const std::string& title) {
  return "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + fmt(kW) + "\" height=\"" + fmt(kH) +
         "\" viewBox=\"0 0 " + fmt(kW) + " " + fmt(kH) + "\" font-family=\"sans-serif\" font-size=\"11\">" +
         "<rect x=\"0\" y=\"0\" width=\"" + fmt(kW) + "\" height=\"" + fmt(kH) + "\" fill=\"white\"/>" +
         "<text x=\"" + fmt(kW / 2) + "\" y=\"18\" text-anchor=\"middle\" font-size=\"13\">" + escape(title) + "</text>";
}

void bounds(const Eigen::MatrixX2d& p, double& xmin, double& xmax, double& ymin, double& ymax) {
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    if (!std::isfinite(p(i, 0)) || !std::isfinite(p(i, 1))) continue;
    xmin = std::min(xmin, p(i, 0)), xmax = std::max(xmax, p(i, 0));
    ymin = std::min(ymin, p(i, 1)), ymax = std::max(ymax, p(i, 1));
  }
}

std::string polygon(const Frame& f, const Eigen::MatrixX2d& p, const std::string& style, bool closed = true) {
  if (p.rows() == 0) return "";
  std::string s = std::string("<") + (closed ? "polygon" : "polyline") + " points=\"";
  for (Eigen::Index i = 0; i < p.rows(); ++i) s += fmt(f.X(p(i, 0))) + "," + fmt(f.Y(p(i, 1))) + " ";
  return s + "\" " + style + "/>";
}

std::string colour_bar(double lo, double hi, const std::string& unit) {
  std::string s;
  const double x = kW - 34, top = kMargin, h = kH - 2 * kMargin;
  for (int k = 0; k < 32; ++k) {
    const double t0 = static_cast<double>(k) / 32;
    s += "<rect x=\"" + fmt(x) + "\" y=\"" + fmt(top + h * (1 - t0 - 1.0 / 32)) + "\" width=\"12\" height=\"" +
         fmt(h / 32 + 0.5) + "\" fill=\"" + viridis(t0 + 0.5 / 32) + "\"/>";
  }
  s += "<text x=\"" + fmt(x + 6) + "\" y=\"" + fmt(top - 4) + "\" text-anchor=\"middle\">" + escape(number(hi)) + "</text>";
  s += "<text x=\"" + fmt(x + 6) + "\" y=\"" + fmt(top + h + 12) + "\" text-anchor=\"middle\">" + escape(number(lo)) +
       "</text>";
  s += "<text x=\"" + fmt(x + 6) + "\" y=\"" + fmt(top + h + 24) + "\" text-anchor=\"middle\">" + escape(unit) + "</text>";
  return s;
}

}  // namespace

std::string escape(const std::string& t) {
  std::string s;
  for (char c : t) {
    switch (c) {
      case '&': s += "&amp;"; break;
      case '<': s += "&lt;"; break;
      case '>': s += "&gt;"; break;
      case '"': s += "&quot;"; break;
      case '\'': s += "&#39;"; break;
      default: s += c;
    }
  }
  return s;
}

std::string number(double v) {
  if (!std::isfinite(v)) return "null";
  char b[32];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

std::string line_plot(const std::string& title, const std::string& xl, const std::string& yl,
                      const std::vector<Series>& series) {
  static const char* colours[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2"};
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = xmin, ymax = -xmin;
  for (const auto& s : series)
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
      if (std::isfinite(s.x[i]) && std::isfinite(s.y[i]))
        xmin = std::min(xmin, s.x[i]), xmax = std::max(xmax, s.x[i]), ymin = std::min(ymin, s.y[i]),
        ymax = std::max(ymax, s.y[i]);
  if (!std::isfinite(xmin)) xmin = 0, xmax = 1, ymin = 0, ymax = 1;
  ymin = std::min(ymin, 0.0);
  const Frame f(xmin, xmax, ymin, ymax + 0.05 * (ymax - ymin), false);
  std::string s = header(title);
  const double L = kMargin, R = kW - kMargin, B = kH - kMargin, T = kMargin;
  s += "<rect x=\"" + fmt(L) + "\" y=\"" + fmt(T) + "\" width=\"" + fmt(R - L) + "\" height=\"" + fmt(B - T) +
       "\" fill=\"none\" stroke=\"#888\"/>";
  for (int k = 0; k <= 4; ++k) {
    const double xv = xmin + (xmax - xmin) * k / 4, yv = ymin + (f.y0 + (B - T) / f.sy - ymin) * k / 4;
    s += "<text x=\"" + fmt(f.X(xv)) + "\" y=\"" + fmt(B + 13) + "\" text-anchor=\"middle\">" + escape(number(xv)) + "</text>";
    s += "<text x=\"" + fmt(L - 3) + "\" y=\"" + fmt(f.Y(yv) + 4) + "\" text-anchor=\"end\">" + escape(number(yv)) + "</text>";
  }
  s += "<text x=\"" + fmt((L + R) / 2) + "\" y=\"" + fmt(kH - 6) + "\" text-anchor=\"middle\">" + escape(xl) + "</text>";
  s += "<text x=\"12\" y=\"" + fmt((T + B) / 2) + "\" transform=\"rotate(-90 12 " + fmt((T + B) / 2) +
       ")\" text-anchor=\"middle\">" + escape(yl) + "</text>";
  for (size_t k = 0; k < series.size(); ++k) {
    const auto& se = series[k];
    std::string pts;
    for (size_t i = 0; i < se.x.size() && i < se.y.size(); ++i)
      if (std::isfinite(se.x[i]) && std::isfinite(se.y[i])) pts += fmt(f.X(se.x[i])) + "," + fmt(f.Y(se.y[i])) + " ";
    const std::string c = colours[k % 7];
    s += "<polyline points=\"" + pts + "\" fill=\"none\" stroke=\"" + c + "\" stroke-width=\"1.5\"/>";
    s += "<text x=\"" + fmt(L + 8) + "\" y=\"" + fmt(T + 14 + 13 * k) + "\" fill=\"" + c + "\">" + escape(se.label) + "</text>";
  }
  return s + "</svg>";
}

std::string field_map(const std::string& title, const Eigen::MatrixX2d& nodes, const Eigen::MatrixXi& quads,
                      const Eigen::VectorXd& values, const std::string& unit) {
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = xmin, ymax = -xmin;
  bounds(nodes, xmin, xmax, ymin, ymax);
  const Frame f(xmin, xmax, ymin, ymax, true, 40);
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (Eigen::Index i = 0; i < values.size(); ++i)
    if (std::isfinite(values(i))) lo = std::min(lo, values(i)), hi = std::max(hi, values(i));
  if (!std::isfinite(lo)) lo = 0, hi = 1;
  const double span = hi > lo ? hi - lo : 1.0;
  std::string s = header(title);
  for (Eigen::Index q = 0; q < quads.rows(); ++q) {
    double v = 0;
    Eigen::MatrixX2d p(quads.cols(), 2);
    for (Eigen::Index k = 0; k < quads.cols(); ++k) v += values(quads(q, k)), p.row(k) = nodes.row(quads(q, k));
    v /= quads.cols();
    const std::string c = viridis((v - lo) / span);
    s += polygon(f, p, "fill=\"" + c + "\" stroke=\"" + c + "\" stroke-width=\"0.3\"");
  }
  return s + colour_bar(lo, hi, unit) + "</svg>";
}

std::string direction_map(const std::string& title, const Eigen::MatrixX2d& outline, const Eigen::MatrixX2d& points,
                          const Eigen::VectorXd& angle, const Eigen::VectorXd& weight, int max_segments) {
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = xmin, ymax = -xmin;
  bounds(outline, xmin, xmax, ymin, ymax);
  bounds(points, xmin, xmax, ymin, ymax);
  const Frame f(xmin, xmax, ymin, ymax, true);
  std::string s = header(title) + polygon(f, outline, "fill=\"#f2f2f2\" stroke=\"#555\"");
  const Eigen::Index n = points.rows();
  const Eigen::Index stride = std::max<Eigen::Index>(1, (n + max_segments - 1) / std::max(1, max_segments));
  double wmax = 0;
  for (Eigen::Index i = 0; i < weight.size(); ++i)
    if (std::isfinite(weight(i))) wmax = std::max(wmax, weight(i));
  const double L = 0.9 * std::sqrt((kW - 2 * kMargin) * (kH - 2 * kMargin) / std::max<double>(1.0, n / stride)) / 2;
  for (Eigen::Index i = 0; i < n; i += stride) {
    if (!std::isfinite(angle(i)) || !(weight(i) > 0)) continue;
    const double l = L * (wmax > 0 ? std::sqrt(weight(i) / wmax) : 1.0);
    const double cx = f.X(points(i, 0)), cy = f.Y(points(i, 1));
    const double dx = l * std::cos(angle(i)), dy = -l * std::sin(angle(i));
    s += "<line x1=\"" + fmt(cx - dx) + "\" y1=\"" + fmt(cy - dy) + "\" x2=\"" + fmt(cx + dx) + "\" y2=\"" +
         fmt(cy + dy) + "\" stroke=\"#1f4e9c\" stroke-width=\"1.2\"/>";
  }
  return s + "</svg>";
}

std::string overlay(const std::string& title, const Eigen::MatrixX2d& model_outline, const Eigen::MatrixX2d& warped_outline,
                    const Eigen::MatrixX2d& points, const Eigen::VectorXd& map_angle, const Eigen::VectorXd& model_angle) {
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = xmin, ymax = -xmin;
  bounds(model_outline, xmin, xmax, ymin, ymax);
  bounds(warped_outline, xmin, xmax, ymin, ymax);
  const Frame f(xmin, xmax, ymin, ymax, true);
  std::string s = header(title) + polygon(f, model_outline, "fill=\"#f2f2f2\" stroke=\"#555\" stroke-width=\"1.5\"") +
                  polygon(f, warped_outline, "fill=\"none\" stroke=\"#d62728\" stroke-dasharray=\"4 2\"");
  const double L = 4.0;
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const double cx = f.X(points(i, 0)), cy = f.Y(points(i, 1));
    for (int k = 0; k < 2; ++k) {
      const double a = k == 0 ? map_angle(i) : model_angle(i);
      if (!std::isfinite(a)) continue;
      const double dx = L * std::cos(a), dy = -L * std::sin(a);
      s += "<line x1=\"" + fmt(cx - dx) + "\" y1=\"" + fmt(cy - dy) + "\" x2=\"" + fmt(cx + dx) + "\" y2=\"" +
           fmt(cy + dy) + "\" stroke=\"" + (k == 0 ? "#d62728" : "#1f4e9c") + "\" stroke-width=\"1\"/>";
    }
  }
  s += "<text x=\"" + fmt(kMargin) + "\" y=\"" + fmt(kH - 8) +
       "\" fill=\"#d62728\">map (registered)</text><text x=\"" + fmt(kMargin + 130) + "\" y=\"" + fmt(kH - 8) +
       "\" fill=\"#1f4e9c\">model (averaged)</text>";
  return s + "</svg>";
}

std::string error_map(const std::string& title, const Eigen::MatrixX2d& outline, const Eigen::MatrixX2d& points,
                      const Eigen::VectorXd& err) {
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = xmin, ymax = -xmin;
  bounds(outline, xmin, xmax, ymin, ymax);
  const Frame f(xmin, xmax, ymin, ymax, true, 40);
  std::string s = header(title) + polygon(f, outline, "fill=\"#f2f2f2\" stroke=\"#555\"");
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const double cx = f.X(points(i, 0)), cy = f.Y(points(i, 1));
    if (std::isfinite(err(i))) {
      s += "<circle cx=\"" + fmt(cx) + "\" cy=\"" + fmt(cy) + "\" r=\"2.2\" fill=\"" + viridis(err(i) / 90.0) + "\"/>";
    } else {
      s += "<circle cx=\"" + fmt(cx) + "\" cy=\"" + fmt(cy) + "\" r=\"2.2\" fill=\"none\" stroke=\"#999\"/>";
    }
  }
  return s + colour_bar(0, 90, "deg") + "</svg>";
}

std::string table(const std::vector<std::string>& header_row, const std::vector<std::vector<std::string>>& rows) {
  std::string s = "<table><thead><tr>";
  for (const auto& h : header_row) s += "<th>" + escape(h) + "</th>";
  s += "</tr></thead><tbody>";
  for (const auto& r : rows) {
    s += "<tr>";
    for (const auto& c : r) s += "<td>" + escape(c) + "</td>";
    s += "</tr>";
  }
  return s + "</tbody></table>";
}


}  // namespace arthrosim::pipelines::report
