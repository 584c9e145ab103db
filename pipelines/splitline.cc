#include "pipelines/splitline.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "common/error.h"

namespace arthrosim::pipelines {
namespace {

using common::InputError;
using Affine2 = Eigen::Matrix<double, 2, 3>;  // [A | t]

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, 0, "cannot open the split-line map file");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

Affine2 identity2() {
  Affine2 m;
  m << 1, 0, 0, 0, 1, 0;
  return m;
}
Affine2 compose(const Affine2& a, const Affine2& b) {  // a * b (apply b first)
  Affine2 r;
  r.leftCols<2>() = a.leftCols<2>() * b.leftCols<2>();
  r.col(2) = a.leftCols<2>() * b.col(2) + a.col(2);
  return r;
}
Eigen::Vector2d apply(const Affine2& m, const Eigen::Vector2d& p) { return m.leftCols<2>() * p + m.col(2); }

// ---- number lists (SVG: comma/space separated, signs and exponents, "1.5.5" = 1.5 .5)
class NumberScanner {
 public:
  NumberScanner(const std::string& s, const std::string& file, int line) : s_(s), file_(file), line_(line) {}
  void skip_separators() {
    while (i_ < s_.size() && (std::isspace(static_cast<unsigned char>(s_[i_])) || s_[i_] == ',')) ++i_;
  }
  bool at_end() {
    skip_separators();
    return i_ >= s_.size();
  }
  bool next_is_number() {
    skip_separators();
    if (i_ >= s_.size()) return false;
    const char c = s_[i_];
    return std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '+' || c == '.';
  }
  char peek() {
    skip_separators();
    return i_ < s_.size() ? s_[i_] : '\0';
  }
  char take_char() { return s_[i_++]; }
  double number(const std::string& what) {
    skip_separators();
    const size_t start = i_;
    if (i_ < s_.size() && (s_[i_] == '+' || s_[i_] == '-')) ++i_;
    bool digits = false, dot = false;
    while (i_ < s_.size()) {
      const char c = s_[i_];
      if (std::isdigit(static_cast<unsigned char>(c))) {
        digits = true;
      } else if (c == '.' && !dot) {
        dot = true;
      } else {
        break;
      }
      ++i_;
    }
    if (digits && i_ < s_.size() && (s_[i_] == 'e' || s_[i_] == 'E')) {
      size_t j = i_ + 1;
      if (j < s_.size() && (s_[j] == '+' || s_[j] == '-')) ++j;
      if (j < s_.size() && std::isdigit(static_cast<unsigned char>(s_[j]))) {
        i_ = j;
        while (i_ < s_.size() && std::isdigit(static_cast<unsigned char>(s_[i_]))) ++i_;
      }
    }
    if (!digits) {
      throw InputError(file_, line_, "expected a number in " + what + ", found '" +
                                         s_.substr(start, std::min<size_t>(12, s_.size() - start)) + "'");
    }
    const std::string text = s_.substr(start, i_ - start);
    double v = 0;
    try {
      v = std::stod(text);
    } catch (const std::out_of_range&) {
      throw InputError(file_, line_, "number out of range in " + what + ": '" + text.substr(0, 24) + "'");
    }
    if (!std::isfinite(v)) throw InputError(file_, line_, "non-finite number in " + what);
    return v;
  }

 private:
  const std::string& s_;
  const std::string& file_;
  int line_;
  size_t i_ = 0;
};

Affine2 parse_transform(const std::string& text, const std::string& file, int line) {
  Affine2 total = identity2();
  size_t i = 0;
  while (true) {
    while (i < text.size() && (std::isspace(static_cast<unsigned char>(text[i])) || text[i] == ',')) ++i;
    if (i >= text.size()) break;
    size_t name_end = i;
    while (name_end < text.size() && std::isalpha(static_cast<unsigned char>(text[name_end]))) ++name_end;
    const std::string name = text.substr(i, name_end - i);
    const size_t open = text.find('(', name_end);
    const size_t close = text.find(')', name_end);
    if (name.empty() || open == std::string::npos || close == std::string::npos || close < open) {
      throw InputError(file, line, "expected a transform like translate(x,y), found '" + text.substr(i) + "'");
    }
    const std::string args_text = text.substr(open + 1, close - open - 1);
    NumberScanner sc(args_text, file, line);
    std::vector<double> a;
    while (!sc.at_end()) a.push_back(sc.number("transform " + name));
    Affine2 m = identity2();
    auto need = [&](size_t lo, size_t hi) {
      if (a.size() < lo || a.size() > hi) {
        throw InputError(file, line, "transform " + name + " expects " + std::to_string(lo) +
                                         (lo == hi ? "" : ".." + std::to_string(hi)) + " numbers, found " +
                                         std::to_string(a.size()));
      }
    };
    if (name == "translate") {
      need(1, 2);
      m(0, 2) = a[0];
      m(1, 2) = a.size() > 1 ? a[1] : 0.0;
    } else if (name == "scale") {
      need(1, 2);
      m(0, 0) = a[0];
      m(1, 1) = a.size() > 1 ? a[1] : a[0];
    } else if (name == "rotate") {
      need(1, 3);
      const double t = a[0] * std::numbers::pi / 180.0;
      Affine2 r = identity2();
      r(0, 0) = std::cos(t), r(0, 1) = -std::sin(t), r(1, 0) = std::sin(t), r(1, 1) = std::cos(t);
      if (a.size() == 3) {
        Affine2 to = identity2(), back = identity2();
        to(0, 2) = a[1], to(1, 2) = a[2], back(0, 2) = -a[1], back(1, 2) = -a[2];
        m = compose(to, compose(r, back));
      } else {
        need(1, 1);
        m = r;
      }
    } else if (name == "matrix") {
      need(6, 6);
      m << a[0], a[2], a[4], a[1], a[3], a[5];
    } else {
      throw InputError(file, line, "unsupported transform '" + name +
                                       "' (expected translate, scale, rotate or matrix)");
    }
    total = compose(total, m);  // "A B" applies B first
    i = close + 1;
  }
  return total;
}

struct XmlElement {
  std::string name;
  std::map<std::string, std::string> attributes;
  bool closing = false, self_closing = false;
  int line = 0;
};

// Minimal XML tag scanner: enough for SVG from vector editors (comments, processing
// instructions, DOCTYPE and CDATA are skipped; entities are not expanded -- no attribute
// we read needs them).
class XmlScanner {
 public:
  XmlScanner(const std::string& text, const std::string& file) : t_(text), file_(file) {}
  bool next(XmlElement& e) {
    while (true) {
      const size_t lt = t_.find('<', i_);
      if (lt == std::string::npos) return false;
      advance_to(lt);
      if (t_.compare(i_, 4, "<!--") == 0) {
        const size_t end = t_.find("-->", i_);
        if (end == std::string::npos) throw InputError(file_, line_, "unterminated XML comment");
        advance_to(end + 3);
        continue;
      }
      if (t_.compare(i_, 9, "<![CDATA[") == 0) {
        const size_t end = t_.find("]]>", i_);
        if (end == std::string::npos) throw InputError(file_, line_, "unterminated CDATA section");
        advance_to(end + 3);
        continue;
      }
      if (t_.compare(i_, 2, "<?") == 0 || t_.compare(i_, 2, "<!") == 0) {
        const size_t end = t_.find('>', i_);
        if (end == std::string::npos) throw InputError(file_, line_, "unterminated XML declaration");
        advance_to(end + 1);
        continue;
      }
      break;
    }
    e = XmlElement{};
    e.line = line_;
    ++i_;
    if (i_ < t_.size() && t_[i_] == '/') {
      e.closing = true;
      ++i_;
    }
    e.name = word();
    if (e.name.empty()) throw InputError(file_, line_, "expected an element name after '<'");
    while (true) {
      skip_space();
      if (i_ >= t_.size()) throw InputError(file_, e.line, "unterminated tag <" + e.name + ">");
      if (t_[i_] == '>') {
        ++i_;
        return true;
      }
      if (t_[i_] == '/' && i_ + 1 < t_.size() && t_[i_ + 1] == '>') {
        e.self_closing = true;
        i_ += 2;
        return true;
      }
      const int attr_line = line_;
      const std::string key = word();
      if (key.empty()) {
        throw InputError(file_, line_, std::string("expected an attribute name in <") + e.name + ">, found '" +
                                           t_[i_] + "'");
      }
      skip_space();
      if (i_ >= t_.size() || t_[i_] != '=') {
        throw InputError(file_, attr_line, "expected '=' after attribute " + key + " of <" + e.name + ">");
      }
      ++i_;
      skip_space();
      if (i_ >= t_.size() || (t_[i_] != '"' && t_[i_] != '\'')) {
        throw InputError(file_, line_, "expected a quoted value for attribute " + key + " of <" + e.name + ">");
      }
      const char q = t_[i_];
      const size_t end = t_.find(q, i_ + 1);
      if (end == std::string::npos) {
        throw InputError(file_, attr_line, "unterminated value of attribute " + key + " of <" + e.name + ">");
      }
      e.attributes[key] = t_.substr(i_ + 1, end - i_ - 1);
      advance_to(end + 1);
    }
  }
  int line() const { return line_; }

 private:
  void advance_to(size_t pos) {
    for (; i_ < pos && i_ < t_.size(); ++i_)
      if (t_[i_] == '\n') ++line_;
    i_ = pos;
  }
  void skip_space() {
    while (i_ < t_.size() && std::isspace(static_cast<unsigned char>(t_[i_]))) {
      if (t_[i_] == '\n') ++line_;
      ++i_;
    }
  }
  std::string word() {
    const size_t s = i_;
    while (i_ < t_.size() && (std::isalnum(static_cast<unsigned char>(t_[i_])) || t_[i_] == '-' || t_[i_] == '_' ||
                              t_[i_] == ':' || t_[i_] == '.'))
      ++i_;
    return t_.substr(s, i_ - s);
  }
  const std::string& t_;
  const std::string& file_;
  size_t i_ = 0;
  int line_ = 1;
};

struct Subpath {
  std::vector<Eigen::Vector2d> points;
  bool closed = false;
};

// SVG path data: M L H V C Z, absolute (upper case) and relative (lower case).
std::vector<Subpath> parse_path(const std::string& d, const std::string& file, int line, int curve_samples) {
  std::vector<Subpath> out;
  NumberScanner sc(d, file, line);
  Eigen::Vector2d cur(0, 0), start(0, 0);
  char cmd = '\0';
  while (!sc.at_end()) {
    if (!sc.next_is_number()) {
      cmd = sc.take_char();
      if (std::string("MmLlHhVvCcZz").find(cmd) == std::string::npos) {
        throw InputError(file, line, std::string("unsupported path command '") + cmd +
                                         "' (expected one of M L H V C Z, absolute or relative)");
      }
      if (cmd == 'Z' || cmd == 'z') {
        if (out.empty()) throw InputError(file, line, "path closes (Z) before any moveto");
        out.back().closed = true;
        cur = start;
        continue;
      }
    } else if (cmd == '\0') {
      throw InputError(file, line, "path data must start with a moveto (M or m)");
    } else if (cmd == 'Z' || cmd == 'z') {
      throw InputError(file, line, "numbers after Z in path data");
    }
    const bool rel = std::islower(static_cast<unsigned char>(cmd));
    const Eigen::Vector2d base = rel ? cur : Eigen::Vector2d(0, 0);
    switch (std::toupper(static_cast<unsigned char>(cmd))) {
      case 'M': {
        const double x = sc.number("path moveto"), y = sc.number("path moveto");
        cur = base + Eigen::Vector2d(x, y);
        start = cur;
        out.push_back({{cur}, false});
        cmd = rel ? 'l' : 'L';  // implicit lineto after the first pair
        break;
      }
      case 'L': {
        if (out.empty()) throw InputError(file, line, "path lineto before any moveto");
        const double x = sc.number("path lineto"), y = sc.number("path lineto");
        cur = base + Eigen::Vector2d(x, y);
        out.back().points.push_back(cur);
        break;
      }
      case 'H': {
        if (out.empty()) throw InputError(file, line, "path lineto before any moveto");
        const double x = sc.number("path H");
        cur.x() = (rel ? cur.x() : 0.0) + x;
        out.back().points.push_back(cur);
        break;
      }
      case 'V': {
        if (out.empty()) throw InputError(file, line, "path lineto before any moveto");
        const double y = sc.number("path V");
        cur.y() = (rel ? cur.y() : 0.0) + y;
        out.back().points.push_back(cur);
        break;
      }
      case 'C': {
        if (out.empty()) throw InputError(file, line, "path curveto before any moveto");
        Eigen::Vector2d c[3];
        for (auto& p : c) {
          const double x = sc.number("path curveto"), y = sc.number("path curveto");
          p = base + Eigen::Vector2d(x, y);
        }
        const Eigen::Vector2d p0 = cur;
        for (int k = 1; k <= curve_samples; ++k) {  // Bernstein form of the cubic
          const double t = static_cast<double>(k) / curve_samples, u = 1.0 - t;
          out.back().points.push_back(u * u * u * p0 + 3 * u * u * t * c[0] + 3 * u * t * t * c[1] + t * t * t * c[2]);
        }
        cur = c[2];
        break;
      }
    }
  }
  return out;
}

std::vector<Eigen::Vector2d> parse_points(const std::string& s, const std::string& file, int line,
                                          const std::string& element) {
  NumberScanner sc(s, file, line);
  std::vector<double> v;
  while (!sc.at_end()) v.push_back(sc.number(element + " points"));
  if (v.size() % 2 != 0) {
    throw InputError(file, line, element + " points: expected an even count of numbers, found " +
                                     std::to_string(v.size()));
  }
  std::vector<Eigen::Vector2d> p;
  for (size_t i = 0; i + 1 < v.size(); i += 2) p.emplace_back(v[i], v[i + 1]);
  return p;
}

double attr_number(const XmlElement& e, const std::string& key, const std::string& file) {
  const auto it = e.attributes.find(key);
  if (it == e.attributes.end()) {
    throw InputError(file, e.line, "<" + e.name + "> needs attribute " + key);
  }
  NumberScanner sc(it->second, file, e.line);
  return sc.number("attribute " + key);
}

Eigen::MatrixX2d to_matrix(const std::vector<Eigen::Vector2d>& p) {
  Eigen::MatrixX2d m(p.size(), 2);
  for (size_t i = 0; i < p.size(); ++i) m.row(i) = p[i].transpose();
  return m;
}

double median_nn_distance(const Eigen::MatrixX2d& p) {
  if (p.rows() < 2) return 0.0;
  std::vector<double> d(p.rows());
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    double best = std::numeric_limits<double>::infinity();
    for (Eigen::Index j = 0; j < p.rows(); ++j)
      if (j != i) best = std::min(best, (p.row(i) - p.row(j)).squaredNorm());
    d[i] = std::sqrt(best);
  }
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return d[d.size() / 2];
}

}  // namespace

double wrap_axial(double a) {
  const double pi = std::numbers::pi;
  double r = std::fmod(a, pi);
  if (r <= -pi / 2) r += pi;
  if (r > pi / 2) r -= pi;
  return r;
}

void sample_split_lines(SplitLineMap& map, double spacing) {
  if (!(spacing > 0)) throw InputError(map.source, 0, "split-line sample spacing must be > 0");
  std::vector<Eigen::Vector2d> pts;
  std::vector<double> ang;
  std::vector<std::string> reg;
  for (const SplitLine& l : map.lines) {
    const auto& P = l.points;
    std::vector<double> s(P.rows(), 0.0);
    for (Eigen::Index i = 1; i < P.rows(); ++i) s[i] = s[i - 1] + (P.row(i) - P.row(i - 1)).norm();
    const double L = s.back();
    if (!(L > 0)) continue;
    // A map is a drawing of one cartilage: a million samples is far beyond
    // any real one (the bundled map has ~1,000); more means a split line far
    // longer than the outline (a typo'd coordinate), refused before sampling.
    constexpr double kMaxSamples = 1e6;
    const double count = std::floor(L / spacing);
    if (!(count + static_cast<double>(pts.size()) <= kMaxSamples)) {
      throw InputError(map.source, 0,
                       "split lines of total length " + std::to_string(L) + " would give more than 1e6 samples at spacing " +
                           std::to_string(spacing) + " (outline diagonal / 100 by default); is a coordinate wrong?");
    }
    const int n = std::max(1, static_cast<int>(count));
    const double step = L / n;
    Eigen::Index seg = 1;
    for (int k = 0; k < n; ++k) {
      const double t = (k + 0.5) * step;
      while (seg < P.rows() - 1 && s[seg] < t) ++seg;
      const Eigen::Vector2d a = P.row(seg - 1).transpose(), b = P.row(seg).transpose();
      const double len = s[seg] - s[seg - 1];
      const double f = len > 0 ? (t - s[seg - 1]) / len : 0.0;
      pts.push_back(a + f * (b - a));
      ang.push_back(wrap_axial(std::atan2(b.y() - a.y(), b.x() - a.x())));
      reg.push_back(l.region);
    }
  }
  map.samples = to_matrix(pts);
  map.angle_rad = Eigen::Map<Eigen::VectorXd>(ang.data(), static_cast<Eigen::Index>(ang.size()));
  map.region = reg;
  map.spacing = spacing;
}

SplitLineMap parse_splitline_svg(const std::string& text, const std::string& path, double sample_spacing) {
  constexpr int kCurveSamples = 16;
  SplitLineMap map;
  map.source = path;
  map.synthetic = text.find("SYNTHETIC") != std::string::npos;
  XmlScanner xml(text, path);
  XmlElement e;
  struct Frame {
    std::string name;
    Affine2 transform;
    std::string region;
  };
  std::vector<Frame> stack;
  bool seen_svg = false;
  int outline_line = 0;
  std::vector<Eigen::Vector2d> outline;
  auto add_shape = [&](const std::vector<Subpath>& subs, const XmlElement& el, const Affine2& M,
                       const std::string& region) {
    for (const Subpath& s : subs) {
      std::vector<Eigen::Vector2d> p;
      for (const auto& q : s.points) {
        const Eigen::Vector2d u = apply(M, q);
        p.emplace_back(u.x(), -u.y());  // SVG y down -> map y up
      }
      if (s.closed) {
        if (!outline.empty()) {
          throw InputError(path, el.line, "a second closed shape (the outline was already given on line " +
                                              std::to_string(outline_line) +
                                              "); expected exactly one closed path = the cartilage outline");
        }
        if (p.size() > 1 && (p.front() - p.back()).norm() <= 1e-12 * (1 + p.front().norm())) p.pop_back();
        if (p.size() < 3) throw InputError(path, el.line, "the outline needs at least 3 points");
        outline = p;
        outline_line = el.line;
      } else {
        if (p.size() < 2) throw InputError(path, el.line, "a split line needs at least 2 points");
        map.lines.push_back({to_matrix(p), region, el.line});
      }
    }
  };
  while (xml.next(e)) {
    if (e.closing) {
      if (stack.empty() || stack.back().name != e.name) {
        throw InputError(path, e.line, "closing tag </" + e.name + "> does not match " +
                                           (stack.empty() ? std::string("any open element")
                                                          : "<" + stack.back().name + ">"));
      }
      stack.pop_back();
      continue;
    }
    if (!seen_svg && e.name != "svg") throw InputError(path, e.line, "expected the root element <svg>, found <" + e.name + ">");
    seen_svg = true;
    Affine2 M = stack.empty() ? identity2() : stack.back().transform;
    if (auto it = e.attributes.find("transform"); it != e.attributes.end()) {
      M = compose(M, parse_transform(it->second, path, e.line));
    }
    std::string region = stack.empty() ? "all" : stack.back().region;
    if (e.name == "g") {
      if (auto it = e.attributes.find("id"); it != e.attributes.end()) region = it->second;
    }
    if (auto it = e.attributes.find("data-region"); it != e.attributes.end()) region = it->second;
    if (e.name == "path") {
      const auto it = e.attributes.find("d");
      if (it == e.attributes.end()) throw InputError(path, e.line, "<path> without a d attribute");
      add_shape(parse_path(it->second, path, e.line, kCurveSamples), e, M, region);
    } else if (e.name == "polyline" || e.name == "polygon") {
      const auto it = e.attributes.find("points");
      if (it == e.attributes.end()) throw InputError(path, e.line, "<" + e.name + "> without a points attribute");
      add_shape({{parse_points(it->second, path, e.line, "<" + e.name + ">"), e.name == "polygon"}}, e, M, region);
    } else if (e.name == "line") {
      add_shape({{{Eigen::Vector2d(attr_number(e, "x1", path), attr_number(e, "y1", path)),
                   Eigen::Vector2d(attr_number(e, "x2", path), attr_number(e, "y2", path))},
                  false}},
                e, M, region);
    }
    if (!e.self_closing) stack.push_back({e.name, M, region});
  }
  if (!seen_svg) throw InputError(path, 1, "expected an <svg> document, found no element");
  if (!stack.empty()) throw InputError(path, xml.line(), "end of file inside <" + stack.back().name + ">");
  if (outline.empty()) {
    throw InputError(path, xml.line(), "expected one closed path (ending in Z) or <polygon> as the cartilage outline, found none");
  }
  if (map.lines.empty()) throw InputError(path, xml.line(), "expected split lines (open paths, polylines or lines), found none");
  map.outline = to_matrix(outline);
  double spacing = sample_spacing;
  if (spacing <= 0) {
    const Eigen::Vector2d lo = map.outline.colwise().minCoeff(), hi = map.outline.colwise().maxCoeff();
    spacing = (hi - lo).norm() / 100.0;
  }
  sample_split_lines(map, spacing);
  if (map.samples.rows() == 0) throw InputError(path, xml.line(), "the split lines have zero length");
  return map;
}

SplitLineMap read_splitline_svg(const std::string& path, double sample_spacing) {
  return parse_splitline_svg(read_text(path), path, sample_spacing);
}

SplitLineMap parse_splitline_csv(const std::string& text, const std::string& path) {
  SplitLineMap map;
  map.source = path;
  map.synthetic = text.find("SYNTHETIC") != std::string::npos;
  std::istringstream in(text);
  std::string raw;
  int line_no = 0;
  enum class Section { kNone, kSamples, kOutline } section = Section::kNone;
  bool need_header = false;
  bool has_region = false;
  std::vector<Eigen::Vector2d> samples, outline;
  std::vector<double> angles;
  bool seen_samples = false, seen_outline = false;
  auto trim = [](std::string s) {
    const auto b = s.find_first_not_of(" \t\r");
    const auto e = s.find_last_not_of(" \t\r");
    return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
  };
  auto split = [&](const std::string& s) {
    std::vector<std::string> f;
    std::string cur;
    std::istringstream ss(s);
    while (std::getline(ss, cur, ',')) f.push_back(trim(cur));
    if (!s.empty() && s.back() == ',') f.push_back("");
    return f;
  };
  auto number = [&](const std::string& s, const std::string& what) {
    size_t used = 0;
    double v = 0;
    try {
      v = std::stod(s, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != s.size()) throw InputError(path, line_no, "expected a number for " + what + ", found '" + s + "'");
    if (!std::isfinite(v)) throw InputError(path, line_no, "non-finite " + what + " '" + s + "'");
    return v;
  };
  while (std::getline(in, raw)) {
    ++line_no;
    const std::string l = trim(raw);
    if (l.empty() || l[0] == '#') continue;
    if (l == "[samples]" || l == "[outline]") {
      const bool s = l == "[samples]";
      if ((s && seen_samples) || (!s && seen_outline)) throw InputError(path, line_no, "section " + l + " given twice");
      (s ? seen_samples : seen_outline) = true;
      section = s ? Section::kSamples : Section::kOutline;
      need_header = true;
      continue;
    }
    if (section == Section::kNone) {
      throw InputError(path, line_no, "expected a section header [samples] or [outline], found '" + l + "'");
    }
    const auto f = split(l);
    if (need_header) {
      need_header = false;
      if (section == Section::kSamples) {
        const bool ok3 = f.size() == 3 && f[0] == "x" && f[1] == "y" && f[2] == "angle_deg";
        const bool ok4 = f.size() == 4 && f[0] == "x" && f[1] == "y" && f[2] == "angle_deg" && f[3] == "region";
        if (!ok3 && !ok4) throw InputError(path, line_no, "expected the header 'x,y,angle_deg' (optionally ',region'), found '" + l + "'");
        has_region = ok4;
      } else if (!(f.size() == 2 && f[0] == "x" && f[1] == "y")) {
        throw InputError(path, line_no, "expected the header 'x,y', found '" + l + "'");
      }
      continue;
    }
    if (section == Section::kSamples) {
      const size_t want = has_region ? 4 : 3;
      if (f.size() != want) {
        throw InputError(path, line_no, "expected " + std::to_string(want) + " fields (x,y,angle_deg" +
                                            (has_region ? ",region" : "") + "), found " + std::to_string(f.size()));
      }
      samples.emplace_back(number(f[0], "x"), number(f[1], "y"));
      angles.push_back(wrap_axial(number(f[2], "angle_deg") * std::numbers::pi / 180.0));
      map.region.push_back(has_region && !f[3].empty() ? f[3] : "all");
    } else {
      if (f.size() != 2) throw InputError(path, line_no, "expected 2 fields (x,y), found " + std::to_string(f.size()));
      outline.emplace_back(number(f[0], "x"), number(f[1], "y"));
    }
  }
  if (!seen_samples || samples.empty()) throw InputError(path, line_no, "expected a [samples] section with at least one sample, found none");
  if (!seen_outline || outline.size() < 3) {
    throw InputError(path, line_no, "expected an [outline] section with at least 3 points, found " + std::to_string(outline.size()));
  }
  map.samples = to_matrix(samples);
  map.angle_rad = Eigen::Map<Eigen::VectorXd>(angles.data(), static_cast<Eigen::Index>(angles.size()));
  map.outline = to_matrix(outline);
  map.spacing = median_nn_distance(map.samples);
  return map;
}

SplitLineMap read_splitline_csv(const std::string& path) { return parse_splitline_csv(read_text(path), path); }

SplitLineMap read_splitline_map(const std::string& path, double sample_spacing) {
  std::string ext = path.size() >= 4 ? path.substr(path.size() - 4) : "";
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == ".svg") return read_splitline_svg(path, sample_spacing);
  if (ext == ".csv") return read_splitline_csv(path);
  throw InputError(path, 0, "expected a split-line map ending in .svg or .csv");
}

}  // namespace arthrosim::pipelines
