#include "pipelines/report_html.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <set>
#include <stdexcept>

#include "common/error.h"
#include "pipelines/report.h"
#include "pipelines/report_assets.h"

namespace arthrosim::pipelines::report_html {
namespace {

using Json = report::Json;
namespace fs = std::filesystem;

// Okabe-Ito: distinguishable with the common colour-vision deficiencies.
const char* const kPalette[] = {"#0072B2", "#D55E00", "#009E73", "#E69F00", "#CC79A7", "#56B4E9", "#000000"};
constexpr const char* kGrey = "#777777";
std::string colour(int k) { return k < 0 ? kGrey : kPalette[k % 7]; }

const char* dash_name(Dash d) {
  switch (d) {
    case Dash::kDash: return "dash";
    case Dash::kDot: return "dot";
    case Dash::kDashDot: return "dashdot";
    default: return "solid";
  }
}

std::string esc(const std::string& s) { return report::escape(s); }

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("report: " + what);
}

// Finite range of v; (0, 1) when none.
std::pair<double, double> finite_range(const std::vector<double>& v) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (double x : v)
    if (std::isfinite(x)) lo = std::min(lo, x), hi = std::max(hi, x);
  if (!std::isfinite(lo)) return {0.0, 1.0};
  if (!(hi > lo)) {
    const double pad = lo != 0 ? 0.5 * std::abs(lo) : 1.0;
    return {lo - pad, hi + pad};
  }
  return {lo, hi};
}

// Colour scale of a field: a diverging scale centred at zero when the values
// have both signs (deflection, e1), viridis otherwise.
struct Scale {
  std::string name;
  bool reverse = false;
  double lo = 0, hi = 1;
};
Scale scale_for(const std::vector<double>& v, double lo_fixed = 0, double hi_fixed = 0) {
  Scale s;
  if (hi_fixed > lo_fixed) {
    s.name = "Viridis", s.lo = lo_fixed, s.hi = hi_fixed;
    return s;
  }
  const auto [lo, hi] = finite_range(v);
  if (lo < 0 && hi > 0) {
    const double m = std::max(-lo, hi);
    s.name = "RdBu", s.reverse = false, s.lo = -m, s.hi = m;  // plotly's RdBu: negative blue, positive red
  } else {
    s.name = "Viridis", s.lo = lo, s.hi = hi;
  }
  return s;
}

void axis(Json& j, const std::string& key, const std::string& title) {
  require(!title.empty(), "an axis without a label (" + key + ")");
  j.begin_object(key);
  j.begin_object("title").value("text", title).end_object();
  j.value("hoverformat", ".3~g").value("exponentformat", "power").value("ticks", "outside");
  j.value("showline", true).value("mirror", true).value("linecolor", "#444").value("zeroline", false);
  j.value("automargin", true);
}

void title(Json& j, const std::string& text) {
  j.begin_object("title").value("text", text).value("x", 0.0).value("xanchor", "left").end_object();
}

void colourbar(Json& j, const std::string& unit) {
  j.begin_object("colorbar").begin_object("title").value("text", unit).end_object();
  j.value("thickness", 14).value("exponentformat", "power").value("len", 0.9).end_object();
}

std::vector<double> col(const Eigen::MatrixXd& m, int c) {
  std::vector<double> v(m.rows());
  for (Eigen::Index i = 0; i < m.rows(); ++i) v[i] = m(i, c);
  return v;
}

void spec_lines(Json& j, const LinePlot& p) {
  j.value("kind", "2d");
  j.begin_array("data");
  std::set<std::string> groups_seen;
  for (const auto& l : p.lines) {
    require(l.x.size() == l.y.size(), p.id + ": series '" + l.label + "' has x and y of different lengths");
    j.begin_object().value("type", "scatter").value("mode", l.markers ? "lines+markers" : "lines").value("name", l.label);
    j.array("x", l.x).array("y", l.y);
    j.begin_object("line").value("color", colour(l.colour)).value("dash", dash_name(l.dash)).value("width", 2).end_object();
    if (!l.group.empty()) {
      j.value("legendgroup", l.group);
      if (groups_seen.insert(l.group).second)
        j.begin_object("legendgrouptitle").value("text", l.group).end_object();
    }
    j.end_object();
  }
  j.end_array();
  j.begin_object("layout");
  title(j, p.title);
  axis(j, "xaxis", p.x_label);
  j.end_object();
  axis(j, "yaxis", p.y_label);
  j.value("rangemode", "tozero").end_object();
  // Legend outside the data, right of the axes; a click toggles one line.
  j.begin_object("legend").value("x", 1.02).value("xanchor", "left").value("y", 1.0).value("yanchor", "top");
  j.value("groupclick", "toggleitem").end_object();
  j.value("hovermode", "x").value("height", 420);
  j.begin_object("margin").value("l", 70).value("r", 10).value("t", 50).value("b", 60).end_object();
  j.end_object();
}

void spec_map(Json& j, const MapPlot& p) {
  j.value("kind", "2d");
  j.begin_array("data");
  for (const auto& o : p.outlines) {
    std::vector<double> x = col(o.points, 0), y = col(o.points, 1);
    if (o.closed && !x.empty()) x.push_back(x.front()), y.push_back(y.front());
    j.begin_object().value("type", "scatter").value("mode", "lines").value("name", o.label).array("x", x).array("y", y);
    j.begin_object("line").value("color", colour(o.colour)).value("dash", dash_name(o.dash)).value("width", 1.5).end_object();
    if (o.closed && o.colour < 0) j.value("fill", "toself").value("fillcolor", "rgba(0,0,0,0.05)");
    j.value("hoverinfo", "skip").end_object();
  }
  for (const auto& s : p.segments) {
    require(s.angle_rad.size() == s.centres.rows() && s.length.size() == s.centres.rows(),
            p.id + ": segments '" + s.label + "' have inconsistent sizes");
    std::vector<double> x, y;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    for (Eigen::Index i = 0; i < s.centres.rows(); ++i) {
      if (!std::isfinite(s.angle_rad(i)) || !(s.length(i) > 0)) continue;
      const double dx = 0.5 * s.length(i) * std::cos(s.angle_rad(i)), dy = 0.5 * s.length(i) * std::sin(s.angle_rad(i));
      x.insert(x.end(), {s.centres(i, 0) - dx, s.centres(i, 0) + dx, nan});
      y.insert(y.end(), {s.centres(i, 1) - dy, s.centres(i, 1) + dy, nan});
    }
    j.begin_object().value("type", "scatter").value("mode", "lines").value("name", s.label).array("x", x).array("y", y);
    j.begin_object("line").value("color", colour(s.colour)).value("width", 1.3).end_object();
    j.value("hoverinfo", "skip").end_object();
  }
  bool scale_shown = false;
  for (const auto& pt : p.points) {
    require(pt.values.size() == pt.xy.rows(), p.id + ": points '" + pt.label + "' have " +
                                                  std::to_string(pt.values.size()) + " values for " +
                                                  std::to_string(pt.xy.rows()) + " points");
    std::vector<double> x, y, v, hx, hy;
    for (Eigen::Index i = 0; i < pt.xy.rows(); ++i) {
      if (std::isfinite(pt.values(i))) {
        x.push_back(pt.xy(i, 0)), y.push_back(pt.xy(i, 1)), v.push_back(pt.values(i));
      } else {
        hx.push_back(pt.xy(i, 0)), hy.push_back(pt.xy(i, 1));
      }
    }
    const Scale sc = scale_for(v, pt.lo, pt.hi);
    j.begin_object().value("type", "scatter").value("mode", "markers").value("name", pt.label).array("x", x).array("y", y);
    j.begin_object("marker").array("color", v).value("colorscale", sc.name).value("reversescale", sc.reverse);
    j.value("cmin", sc.lo).value("cmax", sc.hi).value("size", pt.marker_px).value("showscale", !scale_shown);
    j.begin_object("line").value("width", 0).end_object();
    if (!scale_shown) colourbar(j, pt.unit);
    j.end_object();
    j.value("hovertemplate", "%{marker.color:.3~g} " + pt.unit + "<extra>" + pt.label + "</extra>").end_object();
    scale_shown = true;
    if (!hx.empty()) {
      j.begin_object().value("type", "scatter").value("mode", "markers").value("name", pt.label + ": no value");
      j.array("x", hx).array("y", hy);
      j.begin_object("marker").value("symbol", "circle-open").value("color", kGrey).value("size", pt.marker_px).end_object();
      j.value("hoverinfo", "skip").end_object();
    }
  }
  j.end_array();
  j.begin_object("layout");
  title(j, p.title);
  axis(j, "xaxis", p.x_label);
  j.value("scaleanchor", "y").value("scaleratio", 1).value("constrain", "domain").end_object();
  axis(j, "yaxis", p.y_label);
  j.value("constrain", "domain").end_object();
  // Legend below the axes (the colour bar takes the right side).
  j.begin_object("legend").value("orientation", "h").value("x", 0.0).value("y", -0.2).value("yanchor", "top");
  j.value("entrywidthmode", "fraction").value("entrywidth", 0.5).end_object();
  j.value("hovermode", "closest").value("height", 480);
  j.begin_object("margin").value("l", 60).value("r", 90).value("t", 50).value("b", 40).end_object();
  j.end_object();
}

void spec_surface(Json& j, const SurfacePlot& p) {
  require(!p.fields.empty(), p.id + ": a surface plot without fields");
  const Eigen::Index n = p.nodes_mm.rows();
  for (const auto& f : p.fields)
    require(static_cast<Eigen::Index>(f.values.size()) == n,
            p.id + ": field '" + f.label + "' has " + std::to_string(f.values.size()) + " values for " + std::to_string(n) +
                " nodes");
  j.value("kind", "3d");
  std::vector<double> ti, tj, tk;
  for (Eigen::Index t = 0; t < p.triangles.rows(); ++t) {
    for (int c = 0; c < 3; ++c) require(p.triangles(t, c) >= 0 && p.triangles(t, c) < n, p.id + ": triangle index out of range");
    ti.push_back(p.triangles(t, 0)), tj.push_back(p.triangles(t, 1)), tk.push_back(p.triangles(t, 2));
  }
  const Field& f0 = p.fields.front();
  const Scale s0 = scale_for(f0.values);
  j.begin_array("data").begin_object().value("type", "mesh3d").value("name", p.title);
  j.array("x", col(p.nodes_mm, 0)).array("y", col(p.nodes_mm, 1)).array("z", col(p.nodes_mm, 2));
  j.array("i", ti).array("j", tj).array("k", tk);
  j.array("intensity", f0.values).value("intensitymode", "vertex");
  j.value("colorscale", s0.name).value("reversescale", s0.reverse).value("cmin", s0.lo).value("cmax", s0.hi);
  colourbar(j, f0.unit);
  j.value("hovertemplate", "%{intensity:.3~g}<extra></extra>");
  j.begin_object("lighting").value("ambient", 0.7).value("diffuse", 0.5).value("specular", 0.05).end_object();
  j.end_object().end_array();
  j.begin_object("layout");
  title(j, p.title);
  j.begin_object("scene").value("aspectmode", "data");
  for (const char* a : {"x", "y", "z"}) {
    j.begin_object(std::string(a) + "axis").begin_object("title").value("text", std::string("model ") + a + " [mm]").end_object();
    j.value("exponentformat", "power").end_object();
  }
  j.end_object();
  // One button per field: the menu restyles the mesh's colours, range and unit.
  if (p.fields.size() > 1) {
    j.begin_array("updatemenus").begin_object().value("type", "dropdown").value("x", 0.0).value("xanchor", "left");
    j.value("y", 1.0).value("yanchor", "top").value("showactive", true);
    j.begin_array("buttons");
    for (const auto& f : p.fields) {
      const Scale s = scale_for(f.values);
      j.begin_object().value("label", f.label).value("method", "restyle");
      j.begin_array("args").begin_object();
      j.begin_array("intensity").array("", f.values).end_array();
      j.array("colorscale", std::vector<std::string>{s.name});
      j.begin_array("reversescale").value("", s.reverse).end_array();
      j.array("cmin", std::vector<double>{s.lo}).array("cmax", std::vector<double>{s.hi});
      j.array("colorbar.title.text", std::vector<std::string>{f.unit});
      j.end_object().end_array().end_object();
    }
    j.end_array().end_object().end_array();
  }
  j.value("height", 560);
  j.begin_object("margin").value("l", 0).value("r", 0).value("t", 50).value("b", 0).end_object();
  j.end_object();
}

std::string cell(const Cell& c) {
  if (const auto* s = std::get_if<std::string>(&c)) return esc(*s);
  if (const auto* i = std::get_if<long long>(&c)) return std::to_string(*i);
  return esc(significant(std::get<double>(c)));
}

std::string table_html(const Table& t) {
  std::string s = "<table class=\"data\"><thead><tr>";
  for (const auto& h : t.header) s += "<th>" + esc(h) + "</th>";
  s += "</tr></thead><tbody>";
  for (const auto& r : t.rows) {
    require(r.size() == t.header.size(), t.id + ": a row with " + std::to_string(r.size()) + " cells for " +
                                             std::to_string(t.header.size()) + " columns");
    s += "<tr>";
    for (const auto& c : r) s += std::string("<td") + (std::holds_alternative<std::string>(c) ? "" : " class=\"num\"") + ">" + cell(c) + "</td>";
    s += "</tr>";
  }
  return s + "</tbody></table>";
}

std::string block_id(const Block& b) {
  return std::visit(
      [](const auto& x) -> std::string {
        if constexpr (std::is_same_v<std::decay_t<decltype(x)>, Text>) return "";
        else return x.id;
      },
      b);
}
std::string block_title(const Block& b) {
  return std::visit(
      [](const auto& x) -> std::string {
        if constexpr (std::is_same_v<std::decay_t<decltype(x)>, Text>) return "";
        else return x.title;
      },
      b);
}

// JSON inside <script>: '<', '>' and '&' occur only inside strings there and
// are written as \u escapes, so the page stays well-formed XML and no label
// can close the script element.
std::string script_safe(const std::string& json) {
  std::string s;
  s.reserve(json.size());
  for (char c : json) {
    if (c == '<') s += "\\u003c";
    else if (c == '>') s += "\\u003e";
    else if (c == '&') s += "\\u0026";
    else s += c;
  }
  return s;
}

// Draws every figure, then checks that each drew; the result goes into
// <pre id="report-check"> and, on a failure, a banner names the figures.
constexpr const char* kPageScript = R"JS(
(function () {
  var errors = [];
  window.addEventListener('error', function (e) { errors.push(String(e.message || e)); });
  var specs = JSON.parse(document.getElementById('report-figures').textContent);
  function finish(failed) {
    var result = {ok: failed.length === 0 && errors.length === 0, figures: specs.length, failed: failed, errors: errors};
    document.getElementById('report-check').textContent = JSON.stringify(result);
    document.body.setAttribute('data-report-check', result.ok ? 'ok' : 'failed');
    if (!result.ok) {
      var b = document.getElementById('report-problem');
      b.textContent = 'Some figures did not draw: ' + failed.concat(errors).join('; ');
      b.hidden = false;
    }
  }
  if (typeof Plotly === 'undefined') {
    errors.push('plotly-gl3d.min.js was not loaded: it must be in the folder of report.html');
    finish(specs.map(function (s) { return s.id; }));
    return;
  }
  var config = {responsive: true, displaylogo: false,
                toImageButtonOptions: {format: 'png', scale: 2}};
  var jobs = specs.map(function (s) {
    var el = document.getElementById(s.id + '-plot');
    return Plotly.newPlot(el, s.data, s.layout, config).then(
        function () { return null; }, function (e) { return s.id + ': ' + e; });
  });
  Promise.all(jobs).then(function (results) {
    var failed = results.filter(function (r) { return r !== null; });
    specs.forEach(function (s) {
      var el = document.getElementById(s.id + '-plot');
      var box = el.getBoundingClientRect();
      var ok = box.width > 0 && box.height > 0 && el.classList.contains('js-plotly-plot');
      if (s.kind === '3d') {
        var c = el.querySelector('canvas');
        ok = ok && c !== null && c.width > 0 && c.height > 0 && !/WebGL/i.test(el.textContent);
      } else {
        var svg = el.querySelector('svg.main-svg');
        ok = ok && svg !== null && svg.getBoundingClientRect().width > 0 &&
             el.querySelectorAll('.scatterlayer .trace').length === s.data.length;
      }
      if (!ok) failed.push(s.id);
    });
    finish(failed);
  });
})();
)JS";

constexpr const char* kStyle =
    "body{font-family:system-ui,sans-serif;max-width:1150px;margin:auto;padding:1em;color:#222}"
    "h1{margin-bottom:0.2em}h2{border-bottom:1px solid #ccc;padding-bottom:0.2em;margin-top:1.6em}"
    "figure{box-sizing:border-box;margin:1em 0;border:1px solid #e3e3e3;border-radius:4px;padding:0.5em}"
    "div.maps{display:grid;grid-template-columns:repeat(auto-fill,minmax(460px,1fr));gap:0 0.8em}"
    "div.maps>figure{margin:0.4em 0;min-width:0}"
    "figcaption{font-size:0.9em;color:#444;margin-top:0.3em}"
    "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ccc;padding:3px 8px;font-size:0.9em}"
    "th{background:#f4f4f4;text-align:left}td.num{text-align:right;font-variant-numeric:tabular-nums}"
    ".banner{background:#fff3cd;border:1px solid #e0c36c;padding:0.5em 1em;border-radius:4px}"
    ".problem{background:#f8d7da;border:1px solid #d88;padding:0.5em 1em;border-radius:4px}"
    ".warning{color:#a00}.pass{color:#1a7f37;font-weight:bold}.fail{color:#c62828;font-weight:bold}"
    ".info{color:#666}table.summary td{font-size:0.95em}nav{font-size:0.9em}"
    "nav ol ol{display:inline;padding:0}nav ol ol li{display:inline}nav ol ol li:before{content:' \\00b7  '}";

}  // namespace

std::string significant(double v, int digits) {
  if (!std::isfinite(v)) return "-";
  if (v == 0) return "0";
  digits = std::max(1, digits);
  // Round first ("%.Ne" rounds the mantissa), then choose the notation by the
  // rounded value's exponent (999.6 -> 1000).
  char b[64];
  std::snprintf(b, sizeof b, "%.*e", digits - 1, v);
  std::string s = b;
  const auto epos = s.find('e');
  const int e = std::stoi(s.substr(epos + 1));
  std::string mant = s.substr(0, epos);
  if (e >= -4 && e < 6) {
    std::snprintf(b, sizeof b, "%.*f", std::max(0, digits - 1 - e), std::stod(s));
    mant = b;
    s.clear();
  } else {
    s = "e" + std::to_string(e);
  }
  if (mant.find('.') != std::string::npos) {  // trailing zeros of the fraction
    while (mant.back() == '0') mant.pop_back();
    if (mant.back() == '.') mant.pop_back();
  }
  return mant + s;
}

std::filesystem::path write(const Report& report, const std::filesystem::path& dir) {
  const std::string html = render(report);
  fs::create_directories(dir);
  const fs::path page = dir / "report.html";
  const std::string_view js = plotly_js();
  for (const auto& [path, text] : {std::pair{page, std::string_view(html)}, std::pair{dir / kPlotlyFile, js}}) {
    // Written under a temporary name and renamed: an earlier complete report
    // is never left half overwritten.
    const fs::path tmp = path.string() + ".tmp";
    {
      std::ofstream out(tmp, std::ios::binary);
      if (!out) throw common::InputError(tmp.string(), 0, "cannot write the report file");
      out.write(text.data(), static_cast<std::streamsize>(text.size()));
      if (!out) throw common::InputError(tmp.string(), 0, "write failed");
    }
    fs::rename(tmp, path);
  }
  return page;
}

std::vector<std::string> figure_ids(const Report& r) {
  std::vector<std::string> ids;
  for (const auto& s : r.sections)
    for (const auto& b : s.blocks)
      if (!std::holds_alternative<Text>(b) && !std::holds_alternative<Table>(b)) ids.push_back(block_id(b));
  return ids;
}

std::string render(const Report& r) {
  // Ids: unique, and every summary link resolves.
  std::set<std::string> ids;
  for (const auto& s : r.sections) {
    require(!s.id.empty() && ids.insert(s.id).second, "section id '" + s.id + "' empty or used twice");
    for (const auto& b : s.blocks)
      if (const std::string id = block_id(b); !std::holds_alternative<Text>(b))
        require(!id.empty() && ids.insert(id).second, "figure id '" + id + "' empty or used twice");
  }
  for (const auto& row : r.summary)
    require(row.figure.empty() || ids.count(row.figure), "summary row '" + row.quantity + "' links to no figure ('" + row.figure + "')");

  Json figs;
  figs.begin_array();
  std::string body;
  for (const auto& s : r.sections) {
    body += "<section id=\"" + esc(s.id) + "\"><h2>" + esc(s.title) + "</h2>\n";
    bool in_grid = false;  // consecutive 2D maps share a grid (two or more per row)
    for (const auto& b : s.blocks) {
      const bool is_map = std::holds_alternative<MapPlot>(b);
      if (is_map && !in_grid) body += "<div class=\"maps\">\n";
      if (!is_map && in_grid) body += "</div>\n";
      in_grid = is_map;
      if (const auto* t = std::get_if<Text>(&b)) {
        const std::string cls = t->warning ? " class=\"warning\"" : "";
        if (!t->paragraph.empty()) body += "<p" + cls + ">" + esc(t->paragraph) + "</p>\n";
        if (!t->list.empty()) {
          body += "<ul" + cls + ">";
          for (const auto& item : t->list) body += "<li>" + esc(item) + "</li>";
          body += "</ul>\n";
        }
        continue;
      }
      if (const auto* t = std::get_if<Table>(&b)) {
        body += "<figure id=\"" + esc(t->id) + "\" class=\"table\">";
        if (!t->title.empty()) body += "<h3>" + esc(t->title) + "</h3>";
        body += table_html(*t);
        if (!t->caption.empty()) body += "<figcaption>" + esc(t->caption) + "</figcaption>";
        body += "</figure>\n";
        continue;
      }
      figs.begin_object();
      std::string caption, id, cls = "plot";
      if (const auto* p = std::get_if<LinePlot>(&b)) {
        id = p->id, caption = p->caption;
        figs.value("id", id);
        spec_lines(figs, *p);
      } else if (const auto* p = std::get_if<MapPlot>(&b)) {
        id = p->id, caption = p->caption, cls = "map";
        figs.value("id", id);
        spec_map(figs, *p);
      } else if (const auto* p = std::get_if<SurfacePlot>(&b)) {
        id = p->id, caption = p->caption, cls = "surface";
        figs.value("id", id);
        spec_surface(figs, *p);
      }
      figs.end_object();
      body += "<figure id=\"" + esc(id) + "\" class=\"" + cls + "\"><div id=\"" + esc(id) + "-plot\" class=\"figure\"></div>";
      if (!caption.empty()) body += "<figcaption>" + esc(caption) + "</figcaption>";
      body += "</figure>\n";
    }
    if (in_grid) body += "</div>\n";
    body += "</section>\n";
  }
  figs.end_array();

  std::string h = "<!DOCTYPE html>\n<html xmlns=\"http://www.w3.org/1999/xhtml\" lang=\"en\">\n<head><meta charset=\"UTF-8\"/>";
  h += "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"/><title>" + esc(r.title) + "</title>";
  h += "<style>" + std::string(kStyle) + "</style>";
  h += "<script src=\"" + std::string(kPlotlyFile) + "\"></script></head>\n<body>\n";
  h += "<h1>" + esc(r.title) + "</h1>\n";
  for (const auto& line : r.header) h += "<p>" + esc(line) + "</p>\n";
  h += "<p id=\"report-problem\" class=\"problem\" hidden=\"hidden\"></p>\n";
  if (!r.banner.empty()) h += "<p class=\"banner\"><strong>" + esc(r.banner) + "</strong></p>\n";
  if (!r.summary.empty()) {
    h += "<section id=\"summary\"><h2>Summary</h2><table class=\"summary\"><thead><tr><th>key figure</th><th>value</th>"
         "<th>target or the seed's value</th><th>check</th><th>figure</th></tr></thead><tbody>";
    for (const auto& row : r.summary) {
      const char* mark = row.verdict == Verdict::kPass ? "<td class=\"pass\">&#10003; pass</td>"
                         : row.verdict == Verdict::kFail ? "<td class=\"fail\">&#10007; fail</td>"
                                                         : "<td class=\"info\">compare</td>";
      h += "<tr><td>" + esc(row.quantity) + "</td><td class=\"num\">" + esc(row.value) + "</td><td>" + esc(row.reference) +
           "</td>" + mark + "<td>" + (row.figure.empty() ? std::string("-") : "<a href=\"#" + esc(row.figure) + "\">see</a>") +
           "</td></tr>";
    }
    h += "</tbody></table></section>\n";
  }
  h += "<nav><h2>Contents</h2><ol>";
  for (const auto& s : r.sections) {
    h += "<li><a href=\"#" + esc(s.id) + "\">" + esc(s.title) + "</a>";
    std::string sub;
    for (const auto& b : s.blocks)
      if (const std::string id = block_id(b); !id.empty())
        sub += "<li><a href=\"#" + esc(id) + "\">" + esc(block_title(b).empty() ? id : block_title(b)) + "</a></li>";
    if (!sub.empty()) h += "<ol>" + sub + "</ol>";
    h += "</li>";
  }
  h += "</ol></nav>\n";
  h += body;
  h += "<pre id=\"report-check\" hidden=\"hidden\"></pre>\n";
  h += "<script type=\"application/json\" id=\"report-figures\">" + script_safe(figs.str()) + "</script>\n";
  // CDATA for XML parsers, inside JavaScript comments for HTML parsers.
  h += "<script>//<![CDATA[" + std::string(kPageScript) + "//]]></script>\n</body>\n</html>\n";
  return h;
}

}  // namespace arthrosim::pipelines::report_html
