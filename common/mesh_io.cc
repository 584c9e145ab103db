// Mesh file readers and writers (see mesh_io.h for the supported subsets).
#include "common/mesh_io.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <functional>
#include <iomanip>
#include <sstream>
#include <string_view>
#include <unordered_map>

#include "common/error.h"

namespace arthrosim::common {

double metres_per_unit(LengthUnit unit) {
  switch (unit) {
    case LengthUnit::kMillimetre: return 1e-3;
    case LengthUnit::kCentimetre: return 1e-2;
    case LengthUnit::kMetre: return 1.0;
  }
  return 1.0;
}

std::string unit_name(LengthUnit unit) {
  switch (unit) {
    case LengthUnit::kMillimetre: return "mm";
    case LengthUnit::kCentimetre: return "cm";
    case LengthUnit::kMetre: return "m";
  }
  return "m";
}

LengthUnit parse_length_unit(const std::string& text) {
  std::string s = text;
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  if (s == "mm" || s == "millimetre" || s == "millimetres" || s == "millimeter" || s == "millimeters")
    return LengthUnit::kMillimetre;
  if (s == "cm" || s == "centimetre" || s == "centimetres" || s == "centimeter" || s == "centimeters")
    return LengthUnit::kCentimetre;
  if (s == "m" || s == "metre" || s == "metres" || s == "meter" || s == "meters") return LengthUnit::kMetre;
  throw InputError("length unit: expected one of mm, cm, m, found '" + text + "'");
}

namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

std::string extension_of(const std::string& path) {
  const auto slash = path.find_last_of('/');
  const auto dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  return lower(path.substr(dot + 1));
}

std::string read_whole_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw InputError(path, 0, "expected a readable mesh file, found none (" + std::string(std::strerror(errno)) + ")");
  }
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string shown(std::string_view s) {
  constexpr size_t kMax = 40;
  std::string out(s.substr(0, kMax));
  if (s.size() > kMax) out += "...";
  return "'" + out + "'";
}

// Whitespace tokenizer over text that tracks line numbers (1-based).
class Tokens {
 public:
  Tokens(std::string_view text, size_t start = 0, int first_line = 1)
      : text_(text), pos_(start), line_(first_line) {}

  // Next token on any line; false at end of text. *line is the token's line.
  bool next(std::string_view* token, int* line) {
    skip_space(true);
    if (pos_ >= text_.size()) return false;
    const size_t b = pos_;
    while (pos_ < text_.size() && !is_space(text_[pos_])) ++pos_;
    *token = text_.substr(b, pos_ - b);
    *line = line_;
    return true;
  }
  // Next token on the current line only (false if the line ends first).
  bool next_on_line(std::string_view* token) {
    skip_space(false);
    if (pos_ >= text_.size() || text_[pos_] == '\n' || text_[pos_] == '\r') return false;
    const size_t b = pos_;
    while (pos_ < text_.size() && !is_space(text_[pos_])) ++pos_;
    *token = text_.substr(b, pos_ - b);
    return true;
  }
  // Skips the remainder of the current line (including its newline).
  void skip_line() {
    while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
    if (pos_ < text_.size()) {
      ++pos_;
      ++line_;
    }
  }
  int line() const { return line_; }
  size_t pos() const { return pos_; }

 private:
  static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }
  void skip_space(bool newlines) {
    while (pos_ < text_.size() && is_space(text_[pos_])) {
      if (text_[pos_] == '\n') {
        if (!newlines) return;
        ++line_;
      }
      ++pos_;
    }
  }
  std::string_view text_;
  size_t pos_;
  int line_;
};

double to_double(std::string_view tok, const std::string& file, int line, const std::string& what) {
  double v = 0.0;
  const char* b = tok.data();
  const char* e = tok.data() + tok.size();
  if (!tok.empty() && *b == '+') ++b;  // from_chars rejects a leading '+'
  const auto r = std::from_chars(b, e, v);
  if (r.ec != std::errc() || r.ptr != e) {
    throw InputError(file, line, "expected a number (" + what + "), found " + shown(tok));
  }
  if (!std::isfinite(v)) {
    throw InputError(file, line, "expected a finite number (" + what + "), found " + shown(tok));
  }
  return v;
}

long long to_integer(std::string_view tok, const std::string& file, int line, const std::string& what) {
  long long v = 0;
  const char* b = tok.data();
  const char* e = tok.data() + tok.size();
  if (!tok.empty() && *b == '+') ++b;
  const auto r = std::from_chars(b, e, v);
  if (r.ec != std::errc() || r.ptr != e) {
    throw InputError(file, line, "expected an integer (" + what + "), found " + shown(tok));
  }
  return v;
}

// Vertices and triangles being assembled in file units.
struct Builder {
  std::vector<std::array<double, 3>> V;
  std::vector<std::array<int, 3>> F;
};

// Merges bit-identical points (after mapping -0.0 to +0.0) in order of first
// appearance: deterministic, no tolerance (STL corners of one vertex are
// written from the same value, so exact equality is the right test).
class Welder {
 public:
  int add(std::array<double, 3> p, Builder* b) {
    for (double& x : p) x = x + 0.0;  // -0.0 -> +0.0
    const auto [it, inserted] = index_.try_emplace(p, static_cast<int>(b->V.size()));
    if (inserted) b->V.push_back(p);
    return it->second;
  }

 private:
  struct Hash {
    size_t operator()(const std::array<double, 3>& p) const {
      size_t h = 0;
      for (double x : p) {
        uint64_t bits;
        std::memcpy(&bits, &x, sizeof bits);
        h ^= std::hash<uint64_t>()(bits) + 0x9e3779b97f4a7c15ULL + (h << 6) + (h >> 2);
      }
      return h;
    }
  };
  std::unordered_map<std::array<double, 3>, int, Hash> index_;
};

TriangleMesh finish(const Builder& b, const std::string& name, const MeshReadOptions& options,
                    const std::string& format) {
  if (b.F.empty()) {
    throw InputError(name, 0, "expected at least one triangle in the " + format + " file, found none");
  }
  TriangleMesh m;
  m.name = name;
  const double s = metres_per_unit(options.unit);
  m.V.resize(static_cast<Eigen::Index>(b.V.size()), 3);
  for (size_t i = 0; i < b.V.size(); ++i)
    for (int k = 0; k < 3; ++k) m.V(static_cast<Eigen::Index>(i), k) = b.V[i][k] * s;
  m.F.resize(static_cast<Eigen::Index>(b.F.size()), 3);
  for (size_t i = 0; i < b.F.size(); ++i)
    for (int k = 0; k < 3; ++k) m.F(static_cast<Eigen::Index>(i), k) = b.F[i][k];
  return m;
}

// ---------------------------------------------------------------- STL ------

template <class T>
T load_le(const std::string& data, size_t offset) {
  T v;
  std::memcpy(&v, data.data() + offset, sizeof(T));  // x86-64: little endian in memory
  return v;
}

bool looks_like_binary_stl(const std::string& data) {
  if (data.size() < 84) return false;
  const uint64_t n = load_le<uint32_t>(data, 80);
  return data.size() == 84 + 50 * n;
}

bool looks_textual(const std::string& data) {
  const size_t n = std::min<size_t>(data.size(), 1024);
  for (size_t i = 0; i < n; ++i) {
    const unsigned char c = static_cast<unsigned char>(data[i]);
    if (c < 32 && c != '\n' && c != '\r' && c != '\t' && c != '\f' && c != '\v') return false;
  }
  return true;
}

bool starts_with_solid(const std::string& data) {
  size_t i = 0;
  while (i < data.size() && std::isspace(static_cast<unsigned char>(data[i]))) ++i;
  return data.compare(i, 5, "solid") == 0 &&
         (i + 5 == data.size() || std::isspace(static_cast<unsigned char>(data[i + 5])));
}

TriangleMesh parse_binary_stl(const std::string& data, const std::string& name, const MeshReadOptions& options) {
  if (data.size() < 84) {
    throw InputError(name, 0, "binary STL: expected an 84-byte header and triangle count, found " +
                                  std::to_string(data.size()) + " bytes");
  }
  const uint64_t n = load_le<uint32_t>(data, 80);
  const uint64_t expected = 84 + 50 * n;
  if (data.size() < expected) {
    const uint64_t complete = (data.size() - 84) / 50;
    throw InputError(name, 0,
                     "binary STL truncated: expected " + std::to_string(expected) + " bytes for " +
                         std::to_string(n) + " triangles, found " + std::to_string(data.size()) +
                         " bytes (triangle " + std::to_string(complete) + " at byte offset " +
                         std::to_string(84 + 50 * complete) + " is incomplete)");
  }
  if (data.size() > expected) {
    throw InputError(name, 0,
                     "binary STL: expected " + std::to_string(expected) + " bytes for " + std::to_string(n) +
                         " triangles (count at byte offset 80), found " + std::to_string(data.size()) +
                         " bytes");
  }
  Builder b;
  Welder welder;
  b.F.reserve(n);
  for (uint64_t t = 0; t < n; ++t) {
    const size_t base = 84 + 50 * t;
    std::array<int, 3> tri{};
    for (int k = 0; k < 3; ++k) {
      std::array<double, 3> p{};
      for (int c = 0; c < 3; ++c) {
        const size_t off = base + 12 + 12 * k + 4 * c;
        const float f = load_le<float>(data, off);
        if (!std::isfinite(f)) {
          throw InputError(name, 0, "binary STL: expected finite coordinates, found " + std::to_string(f) +
                                        " in triangle " + std::to_string(t) + " (byte offset " +
                                        std::to_string(off) + ")");
        }
        p[c] = static_cast<double>(f);
      }
      if (options.weld_stl_vertices) {
        tri[k] = welder.add(p, &b);
      } else {
        tri[k] = static_cast<int>(b.V.size());
        b.V.push_back(p);
      }
    }
    b.F.push_back(tri);
  }
  return finish(b, name, options, "binary STL");
}

TriangleMesh parse_ascii_stl(const std::string& data, const std::string& name, const MeshReadOptions& options) {
  Tokens tk(data);
  Builder b;
  Welder welder;
  std::string_view tok;
  int line = 0;
  auto expect = [&](std::string_view word, const char* context) {
    if (!tk.next(&tok, &line)) {
      throw InputError(name, tk.line(), std::string("ASCII STL: expected '") + std::string(word) + "' " + context +
                                            ", found end of file");
    }
    if (lower(std::string(tok)) != word) {
      throw InputError(name, line, std::string("ASCII STL: expected '") + std::string(word) + "' " + context +
                                       ", found " + shown(tok));
    }
  };
  bool any_solid = false;
  while (tk.next(&tok, &line)) {
    if (lower(std::string(tok)) != "solid") {
      throw InputError(name, line, "ASCII STL: expected 'solid', found " + shown(tok));
    }
    any_solid = true;
    tk.skip_line();  // the solid's name
    while (true) {
      if (!tk.next(&tok, &line)) {
        throw InputError(name, tk.line(), "ASCII STL: expected 'facet' or 'endsolid', found end of file");
      }
      const std::string word = lower(std::string(tok));
      if (word == "endsolid") {
        tk.skip_line();
        break;
      }
      if (word != "facet") {
        throw InputError(name, line, "ASCII STL: expected 'facet' or 'endsolid', found " + shown(tok));
      }
      expect("normal", "after 'facet'");
      for (int c = 0; c < 3; ++c) {
        if (!tk.next(&tok, &line)) throw InputError(name, tk.line(), "ASCII STL: expected a normal component, found end of file");
        // Facet normals are not used (they are recomputed from the vertices);
        // exporters write "nan" for degenerate facets, so only the syntax is checked.
        double ignored;
        const auto r = std::from_chars(tok.data() + (!tok.empty() && tok[0] == '+'), tok.data() + tok.size(), ignored);
        if (r.ec != std::errc() || r.ptr != tok.data() + tok.size())
          throw InputError(name, line, "ASCII STL: expected a number (facet normal component), found " + shown(tok));
      }
      expect("outer", "to start a facet's vertices");
      expect("loop", "after 'outer'");
      std::array<int, 3> tri{};
      for (int k = 0; k < 3; ++k) {
        expect("vertex", k == 0 ? "(first of 3)" : (k == 1 ? "(second of 3)" : "(third of 3)"));
        std::array<double, 3> p{};
        for (int c = 0; c < 3; ++c) {
          if (!tk.next(&tok, &line)) throw InputError(name, tk.line(), "ASCII STL: expected a vertex coordinate, found end of file");
          p[c] = to_double(tok, name, line, std::string("vertex ") + "xyz"[c] + " coordinate");
        }
        if (options.weld_stl_vertices) {
          tri[k] = welder.add(p, &b);
        } else {
          tri[k] = static_cast<int>(b.V.size());
          b.V.push_back(p);
        }
      }
      expect("endloop", "after 3 vertices");
      expect("endfacet", "after 'endloop'");
      b.F.push_back(tri);
    }
  }
  if (!any_solid) throw InputError(name, 0, "ASCII STL: expected 'solid', found an empty file");
  return finish(b, name, options, "ASCII STL");
}

// ---------------------------------------------------------------- OBJ ------

TriangleMesh parse_obj_impl(const std::string& data, const std::string& name, const MeshReadOptions& options) {
  Builder b;
  std::vector<int> face_line;  // line of each triangle, for index errors
  std::vector<std::array<long long, 3>> raw;  // 0-based indices, checked at the end
  Tokens tk(data);
  std::string_view tok;
  int line = 0;
  while (tk.next(&tok, &line)) {
    if (tok[0] == '#') {
      tk.skip_line();
      continue;
    }
    if (tok == "v") {
      std::array<double, 3> p{};
      for (int c = 0; c < 3; ++c) {
        if (!tk.next_on_line(&tok)) {
          throw InputError(name, line, std::string("OBJ: expected 3 coordinates after 'v', found ") +
                                           std::to_string(c));
        }
        p[c] = to_double(tok, name, line, std::string("vertex ") + "xyz"[c] + " coordinate");
      }
      b.V.push_back(p);
      tk.skip_line();  // optional w / colour
    } else if (tok == "f") {
      std::vector<long long> poly;
      while (tk.next_on_line(&tok)) {
        if (tok[0] == '#') break;  // trailing comment
        const std::string_view first = tok.substr(0, tok.find('/'));
        const long long idx = to_integer(first, name, line, "face vertex index");
        if (idx == 0) throw InputError(name, line, "OBJ: expected a non-zero face index (1-based or negative), found 0");
        // Negative indices count back from the latest vertex (-1 = last so far).
        poly.push_back(idx > 0 ? idx - 1 : static_cast<long long>(b.V.size()) + idx);
        if (poly.back() < 0) {
          throw InputError(name, line, "OBJ: expected a relative index within the " + std::to_string(b.V.size()) +
                                           " vertices defined so far, found " + std::to_string(idx));
        }
      }
      if (poly.size() < 3) {
        throw InputError(name, line, "OBJ: expected at least 3 vertices in a face, found " + std::to_string(poly.size()));
      }
      for (size_t k = 1; k + 1 < poly.size(); ++k) {  // fan triangulation
        raw.push_back({poly[0], poly[k], poly[k + 1]});
        face_line.push_back(line);
      }
      tk.skip_line();
    } else if (tok == "vt" || tok == "vn" || tok == "vp" || tok == "g" || tok == "o" || tok == "s" || tok == "l" ||
               tok == "usemtl" || tok == "mtllib") {
      tk.skip_line();  // texture/normal data, groups, materials, polylines: not geometry we use
    } else {
      throw InputError(name, line,
                       "OBJ: expected a statement (v, f, vt, vn, vp, g, o, s, l, usemtl, mtllib or a # comment), found " +
                           shown(tok));
    }
  }
  const long long nv = static_cast<long long>(b.V.size());
  b.F.reserve(raw.size());
  for (size_t t = 0; t < raw.size(); ++t) {
    for (long long i : raw[t]) {
      if (i >= nv) {
        throw InputError(name, face_line[t], "OBJ: expected face indices in 1.." + std::to_string(nv) + ", found " +
                                                 std::to_string(i + 1));
      }
    }
    b.F.push_back({static_cast<int>(raw[t][0]), static_cast<int>(raw[t][1]), static_cast<int>(raw[t][2])});
  }
  return finish(b, name, options, "OBJ");
}

// ---------------------------------------------------------------- PLY ------

enum class PlyType { kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kFloat32, kFloat64 };

bool ply_type(std::string_view s, PlyType* t) {
  if (s == "char" || s == "int8") *t = PlyType::kInt8;
  else if (s == "uchar" || s == "uint8") *t = PlyType::kUInt8;
  else if (s == "short" || s == "int16") *t = PlyType::kInt16;
  else if (s == "ushort" || s == "uint16") *t = PlyType::kUInt16;
  else if (s == "int" || s == "int32") *t = PlyType::kInt32;
  else if (s == "uint" || s == "uint32") *t = PlyType::kUInt32;
  else if (s == "float" || s == "float32") *t = PlyType::kFloat32;
  else if (s == "double" || s == "float64") *t = PlyType::kFloat64;
  else return false;
  return true;
}

size_t ply_size(PlyType t) {
  switch (t) {
    case PlyType::kInt8: case PlyType::kUInt8: return 1;
    case PlyType::kInt16: case PlyType::kUInt16: return 2;
    case PlyType::kInt32: case PlyType::kUInt32: case PlyType::kFloat32: return 4;
    case PlyType::kFloat64: return 8;
  }
  return 0;
}

bool ply_is_integer(PlyType t) { return t != PlyType::kFloat32 && t != PlyType::kFloat64; }

struct PlyProperty {
  std::string name;
  bool is_list = false;
  PlyType count_type = PlyType::kUInt8;
  PlyType type = PlyType::kFloat32;
};

struct PlyElement {
  std::string name;
  long long count = 0;
  int header_line = 0;
  std::vector<PlyProperty> properties;
};

// Reads one value of a binary PLY body, advancing *offset.
double ply_binary_value(const std::string& data, size_t* offset, PlyType t, const std::string& name,
                        const std::string& what) {
  const size_t sz = ply_size(t);
  if (*offset + sz > data.size()) {
    throw InputError(name, 0, "binary PLY truncated: expected " + std::to_string(sz) + " more bytes for " + what +
                                  " at byte offset " + std::to_string(*offset) + ", found " +
                                  std::to_string(data.size() - *offset));
  }
  double v = 0.0;
  switch (t) {
    case PlyType::kInt8: v = load_le<int8_t>(data, *offset); break;
    case PlyType::kUInt8: v = load_le<uint8_t>(data, *offset); break;
    case PlyType::kInt16: v = load_le<int16_t>(data, *offset); break;
    case PlyType::kUInt16: v = load_le<uint16_t>(data, *offset); break;
    case PlyType::kInt32: v = load_le<int32_t>(data, *offset); break;
    case PlyType::kUInt32: v = load_le<uint32_t>(data, *offset); break;
    case PlyType::kFloat32: v = load_le<float>(data, *offset); break;
    case PlyType::kFloat64: v = load_le<double>(data, *offset); break;
  }
  *offset += sz;
  return v;
}

// Reads a text (LF or CRLF line ends) line by line, counting lines for error
// messages; pos is where the next line starts, so a binary payload or a token
// reader can go on from there.
struct LineReader {
  const std::string& data;
  size_t pos = 0;
  int line_no = 0;
  bool next(std::string* out) {
    if (pos >= data.size()) return false;
    size_t e = data.find('\n', pos);
    if (e == std::string::npos) e = data.size();
    *out = data.substr(pos, e - pos);
    if (!out->empty() && out->back() == '\r') out->pop_back();
    pos = std::min(e + 1, data.size());
    ++line_no;
    return true;
  }
};

TriangleMesh parse_ply_impl(const std::string& data, const std::string& name, const MeshReadOptions& options) {
  // --- header (text, one statement per line) ---
  LineReader lines{data};
  size_t& pos = lines.pos;
  int& line_no = lines.line_no;
  auto next_line = [&](std::string* out) { return lines.next(out); };
  std::string text;
  if (!next_line(&text) || text != "ply") {
    throw InputError(name, 1, "PLY: expected 'ply' on the first line, found " + shown(text));
  }
  bool binary = false, have_format = false, end_header = false;
  std::vector<PlyElement> elements;
  while (next_line(&text)) {
    std::istringstream ls(text);
    std::string kw;
    ls >> kw;
    if (kw.empty() || kw == "comment" || kw == "obj_info") continue;
    if (kw == "format") {
      std::string f, version;
      ls >> f >> version;
      if (f == "ascii") binary = false;
      else if (f == "binary_little_endian") binary = true;
      else
        throw InputError(name, line_no, "PLY: expected format ascii or binary_little_endian, found " + shown(f));
      have_format = true;
    } else if (kw == "element") {
      PlyElement e;
      std::string count;
      ls >> e.name >> count;
      e.count = to_integer(count, name, line_no, "element count");
      if (e.count < 0) throw InputError(name, line_no, "PLY: expected a non-negative element count, found " + count);
      e.header_line = line_no;
      elements.push_back(e);
    } else if (kw == "property") {
      if (elements.empty()) throw InputError(name, line_no, "PLY: expected 'element' before 'property', found " + shown(text));
      PlyProperty p;
      std::string t1;
      ls >> t1;
      if (t1 == "list") {
        std::string ct, it;
        ls >> ct >> it >> p.name;
        p.is_list = true;
        if (!ply_type(ct, &p.count_type) || !ply_is_integer(p.count_type))
          throw InputError(name, line_no, "PLY: expected an integer list count type, found " + shown(ct));
        if (!ply_type(it, &p.type)) throw InputError(name, line_no, "PLY: expected a property type, found " + shown(it));
      } else {
        if (!ply_type(t1, &p.type)) throw InputError(name, line_no, "PLY: expected a property type, found " + shown(t1));
        ls >> p.name;
      }
      if (p.name.empty()) throw InputError(name, line_no, "PLY: expected a property name, found end of line");
      elements.back().properties.push_back(p);
    } else if (kw == "end_header") {
      end_header = true;
      break;
    } else {
      throw InputError(name, line_no,
                       "PLY: expected a header statement (format, element, property, comment, end_header), found " +
                           shown(kw));
    }
  }
  if (!end_header) throw InputError(name, line_no, "PLY: expected 'end_header', found end of file");
  if (!have_format) throw InputError(name, line_no, "PLY: expected a 'format' line in the header, found none");

  const PlyElement* vertex_el = nullptr;
  const PlyElement* face_el = nullptr;
  int xyz[3] = {-1, -1, -1};
  int face_prop = -1;
  for (const auto& e : elements) {
    if (e.name == "vertex") {
      vertex_el = &e;
      for (size_t i = 0; i < e.properties.size(); ++i) {
        for (int c = 0; c < 3; ++c) {
          if (e.properties[i].name == std::string(1, "xyz"[c])) {
            if (e.properties[i].is_list)
              throw InputError(name, e.header_line, "PLY: expected a scalar vertex coordinate, found a list");
            xyz[c] = static_cast<int>(i);
          }
        }
      }
      for (int c = 0; c < 3; ++c)
        if (xyz[c] < 0)
          throw InputError(name, e.header_line, std::string("PLY: expected a vertex property '") + "xyz"[c] + "', found none");
    } else if (e.name == "face") {
      face_el = &e;
      for (size_t i = 0; i < e.properties.size(); ++i) {
        if (e.properties[i].name == "vertex_indices" || e.properties[i].name == "vertex_index") {
          if (!e.properties[i].is_list || !ply_is_integer(e.properties[i].type))
            throw InputError(name, e.header_line, "PLY: expected 'vertex_indices' to be a list of integers");
          face_prop = static_cast<int>(i);
        }
      }
      if (face_prop < 0)
        throw InputError(name, e.header_line, "PLY: expected a face property list 'vertex_indices', found none");
    }
  }
  if (!vertex_el) throw InputError(name, 0, "PLY: expected an 'element vertex' in the header, found none");
  if (!face_el) throw InputError(name, 0, "PLY: expected an 'element face' in the header, found none");

  Builder b;
  std::vector<std::vector<long long>> polys;
  std::vector<int> poly_line;  // ascii line (0 for binary)
  std::vector<long long> poly_index;

  if (binary) {
    size_t off = pos;
    for (const auto& e : elements) {
      if (e.properties.empty()) continue;  // no data, whatever its count (10^12 would loop for hours)
      for (long long i = 0; i < e.count; ++i) {
        std::array<double, 3> p{};
        std::vector<long long> poly;
        for (size_t k = 0; k < e.properties.size(); ++k) {
          const PlyProperty& prop = e.properties[k];
          const std::string what = e.name + " " + std::to_string(i) + " property '" + prop.name + "'";
          if (prop.is_list) {
            const double cnt = ply_binary_value(data, &off, prop.count_type, name, what + " (list count)");
            if (cnt < 0) throw InputError(name, 0, "binary PLY: expected a non-negative list count for " + what + ", found " + std::to_string(cnt));
            const bool is_face = (&e == face_el && static_cast<int>(k) == face_prop);
            for (long long j = 0; j < static_cast<long long>(cnt); ++j) {
              const double v = ply_binary_value(data, &off, prop.type, name, what);
              if (is_face) poly.push_back(static_cast<long long>(v));
            }
          } else {
            const double v = ply_binary_value(data, &off, prop.type, name, what);
            if (&e == vertex_el) {
              for (int c = 0; c < 3; ++c) {
                if (static_cast<int>(k) == xyz[c]) {
                  if (!std::isfinite(v))
                    throw InputError(name, 0, "binary PLY: expected a finite coordinate for " + what + ", found " +
                                                  std::to_string(v) + " (ending at byte offset " + std::to_string(off) + ")");
                  p[c] = v;
                }
              }
            }
          }
        }
        if (&e == vertex_el) b.V.push_back(p);
        if (&e == face_el) {
          polys.push_back(std::move(poly));
          poly_line.push_back(0);
          poly_index.push_back(i);
        }
      }
    }
  } else {
    Tokens tk(data, pos, line_no + 1);
    std::string_view tok;
    int line = 0;
    for (const auto& e : elements) {
      if (e.properties.empty()) continue;  // no data, whatever its count (10^12 would loop for hours)
      for (long long i = 0; i < e.count; ++i) {
        std::array<double, 3> p{};
        std::vector<long long> poly;
        int first_line = tk.line();
        for (size_t k = 0; k < e.properties.size(); ++k) {
          const PlyProperty& prop = e.properties[k];
          const std::string what = e.name + " " + std::to_string(i) + " property '" + prop.name + "'";
          auto need = [&]() {
            if (!tk.next(&tok, &line))
              throw InputError(name, tk.line(), "PLY: expected a value for " + what + ", found end of file");
          };
          if (prop.is_list) {
            need();
            if (k == 0) first_line = line;
            const long long cnt = to_integer(tok, name, line, what + " list count");
            if (cnt < 0) throw InputError(name, line, "PLY: expected a non-negative list count, found " + std::to_string(cnt));
            const bool is_face = (&e == face_el && static_cast<int>(k) == face_prop);
            for (long long j = 0; j < cnt; ++j) {
              need();
              if (is_face) poly.push_back(to_integer(tok, name, line, "face vertex index"));
              else to_double(tok, name, line, what);
            }
          } else {
            need();
            if (k == 0) first_line = line;
            const double v = ply_is_integer(prop.type) ? static_cast<double>(to_integer(tok, name, line, what))
                                                       : to_double(tok, name, line, what);
            if (&e == vertex_el)
              for (int c = 0; c < 3; ++c)
                if (static_cast<int>(k) == xyz[c]) p[c] = v;
          }
        }
        if (&e == vertex_el) b.V.push_back(p);
        if (&e == face_el) {
          polys.push_back(std::move(poly));
          poly_line.push_back(first_line);
          poly_index.push_back(i);
        }
      }
    }
  }

  const long long nv = static_cast<long long>(b.V.size());
  for (size_t f = 0; f < polys.size(); ++f) {
    const auto& poly = polys[f];
    if (poly.size() < 3) {
      throw InputError(name, poly_line[f], "PLY: expected at least 3 indices in face " + std::to_string(poly_index[f]) +
                                               ", found " + std::to_string(poly.size()));
    }
    for (long long v : poly) {
      if (v < 0 || v >= nv) {
        throw InputError(name, poly_line[f], "PLY: expected vertex indices in 0.." + std::to_string(nv - 1) +
                                                 " in face " + std::to_string(poly_index[f]) + ", found " +
                                                 std::to_string(v));
      }
    }
    for (size_t k = 1; k + 1 < poly.size(); ++k)
      b.F.push_back({static_cast<int>(poly[0]), static_cast<int>(poly[k]), static_cast<int>(poly[k + 1])});
  }
  return finish(b, name, options, "PLY");
}


// ---------------------------------------------------------------- VTK ------

/// The points, polygons (checked: >= 3 points, indices in range) and fields
/// of a legacy VTK polydata file.
struct VtkPolydata {
  Builder b;
  std::vector<std::vector<long long>> polys;
  std::vector<int> poly_line;
};

VtkPolydata parse_vtk_polydata(const std::string& data, const std::string& name, std::vector<VtkField>* fields) {
  // Lines 1-4: version, title, ASCII, DATASET POLYDATA.
  LineReader lines{data};
  size_t& pos = lines.pos;
  int& line_no = lines.line_no;
  auto next_line = [&](std::string* out) { return lines.next(out); };
  std::string text;
  if (!next_line(&text) || text.rfind("# vtk DataFile Version", 0) != 0)
    throw InputError(name, 1, "VTK: expected '# vtk DataFile Version ...', found " + shown(text));
  next_line(&text);  // title
  if (!next_line(&text) || lower(text).rfind("ascii", 0) != 0)
    throw InputError(name, 3, "VTK: expected ASCII (binary legacy VTK is not read), found " + shown(text));
  Tokens tk(data, pos, line_no + 1);
  std::string_view tok;
  int line = 0;
  auto need = [&](const std::string& what) {
    if (!tk.next(&tok, &line)) throw InputError(name, tk.line(), "VTK: expected " + what + ", found end of file");
  };
  need("DATASET");
  if (tok != "DATASET") throw InputError(name, line, "VTK: expected DATASET, found " + shown(tok));
  need("POLYDATA");
  if (tok != "POLYDATA") throw InputError(name, line, "VTK: expected DATASET POLYDATA, found " + shown(tok));

  VtkPolydata out;
  Builder& b = out.b;
  long long n_cells = 0;
  std::vector<std::vector<long long>>& polys = out.polys;
  std::vector<int>& poly_line = out.poly_line;
  auto count = [&](const std::string& what) {
    need(what);
    const long long c = to_integer(tok, name, line, what);
    if (c < 0) throw InputError(name, line, "VTK: expected a non-negative " + what + ", found " + std::to_string(c));
    return c;
  };
  VtkField::Location location = VtkField::Location::kPoint;
  long long n_values = -1;
  while (tk.next(&tok, &line)) {
    const std::string kw(tok);
    if (kw == "POINTS") {
      const long long n = count("point count");
      need("point data type");
      for (long long i = 0; i < n; ++i) {
        std::array<double, 3> p{};
        for (int c = 0; c < 3; ++c) {
          need("a point coordinate");
          p[c] = to_double(tok, name, line, "point " + std::to_string(i) + " coordinate");
        }
        b.V.push_back(p);
      }
    } else if (kw == "POLYGONS" || kw == "VERTICES" || kw == "LINES") {
      const long long n = count("cell count");
      count("cell list size");
      for (long long i = 0; i < n; ++i) {
        const long long k = count("cell size");
        const int first = line;
        std::vector<long long> poly;
        for (long long j = 0; j < k; ++j) {
          need("a point index");
          poly.push_back(to_integer(tok, name, line, "point index"));
        }
        if (kw == "POLYGONS") {
          polys.push_back(std::move(poly));
          poly_line.push_back(first);
        }
      }
      if (kw == "POLYGONS") n_cells = n;
    } else if (kw == "POINT_DATA" || kw == "CELL_DATA") {
      location = kw == "POINT_DATA" ? VtkField::Location::kPoint : VtkField::Location::kCell;
      n_values = count("data count");
      const long long expected = kw == "POINT_DATA" ? static_cast<long long>(b.V.size()) : n_cells;
      if (n_values != expected)
        throw InputError(name, line, "VTK: expected " + kw + " " + std::to_string(expected) + ", found " +
                                         std::to_string(n_values));
    } else if (kw == "SCALARS" || kw == "VECTORS" || kw == "NORMALS") {
      if (n_values < 0) throw InputError(name, line, "VTK: expected POINT_DATA or CELL_DATA before " + kw);
      VtkField f;
      f.location = location;
      need("a field name");
      f.name = std::string(tok);
      need("a data type");
      int ncomp = 3;
      if (kw == "SCALARS") {
        // Optional component count, then the mandatory-in-practice LOOKUP_TABLE.
        need("LOOKUP_TABLE");
        if (tok != "LOOKUP_TABLE") {
          ncomp = static_cast<int>(to_integer(tok, name, line, "number of components"));
          if (ncomp != 1) throw InputError(name, line, "VTK: expected 1 component in SCALARS, found " + std::to_string(ncomp));
          need("LOOKUP_TABLE");
        }
        if (tok != "LOOKUP_TABLE") throw InputError(name, line, "VTK: expected LOOKUP_TABLE, found " + shown(tok));
        need("a lookup table name");
        ncomp = 1;
      }
      f.values.resize(n_values, ncomp);
      for (long long i = 0; i < n_values; ++i)
        for (int c = 0; c < ncomp; ++c) {
          need("a field value");
          f.values(i, c) = to_double(tok, name, line, "value of field '" + f.name + "'");
        }
      if (fields) fields->push_back(std::move(f));
    } else {
      throw InputError(name, line,
                       "VTK: expected POINTS, POLYGONS, VERTICES, LINES, POINT_DATA, CELL_DATA, SCALARS, VECTORS or "
                       "NORMALS, found " + shown(tok));
    }
  }
  const long long nv = static_cast<long long>(b.V.size());
  for (size_t f = 0; f < polys.size(); ++f) {
    if (polys[f].size() < 3)
      throw InputError(name, poly_line[f], "VTK: expected at least 3 points in polygon " + std::to_string(f) + ", found " +
                                               std::to_string(polys[f].size()));
    for (long long v : polys[f])
      if (v < 0 || v >= nv)
        throw InputError(name, poly_line[f], "VTK: expected point indices in 0.." + std::to_string(nv - 1) +
                                                 " in polygon " + std::to_string(f) + ", found " + std::to_string(v));
  }
  return out;
}

TriangleMesh parse_vtk_impl(const std::string& data, const std::string& name, const MeshReadOptions& options,
                            std::vector<VtkField>* fields) {
  VtkPolydata d = parse_vtk_polydata(data, name, fields);
  for (const auto& poly : d.polys)
    for (size_t k = 1; k + 1 < poly.size(); ++k)
      d.b.F.push_back({static_cast<int>(poly[0]), static_cast<int>(poly[k]), static_cast<int>(poly[k + 1])});
  return finish(d.b, name, options, "VTK");
}

// ---------------------------------------------------------------- writers --

void check_writable(const Points3& V, const Eigen::MatrixXi& F, const std::string& path) {
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    if (!V.row(i).allFinite()) {
      throw InputError(path, 0, "cannot write mesh: expected finite coordinates, found non-finite vertex " +
                                    std::to_string(i));
    }
  }
  for (Eigen::Index t = 0; t < F.rows(); ++t) {
    for (Eigen::Index k = 0; k < F.cols(); ++k) {
      if (F(t, k) < 0 || F(t, k) >= V.rows()) {
        throw InputError(path, 0, "cannot write mesh: expected indices in [0, " + std::to_string(V.rows()) +
                                      "), found " + std::to_string(F(t, k)) + " in face " + std::to_string(t));
      }
    }
  }
}

std::ofstream open_out(const std::string& path, bool binary) {
  std::ofstream out(path, binary ? std::ios::binary | std::ios::trunc : std::ios::trunc);
  if (!out) throw InputError(path, 0, "expected a writable file, found it cannot be opened (" + std::string(std::strerror(errno)) + ")");
  return out;
}

void close_out(std::ofstream& out, const std::string& path) {
  out.close();
  if (!out) throw InputError(path, 0, "expected to write the whole file, found a write error");
}

std::string header_name(const std::string& name) {
  std::string s = name.empty() ? "arthrosim" : name;
  for (char& c : s)
    if (std::isspace(static_cast<unsigned char>(c))) c = '_';
  return s;
}

void write_faces_obj(const Points3& V, const Eigen::MatrixXi& F, const std::string& path, const std::string& name,
                     const MeshWriteOptions& options) {
  check_writable(V, F, path);
  std::ofstream out = open_out(path, false);
  const double s = 1.0 / metres_per_unit(options.unit);
  out << "# arthrosim mesh '" << name << "', unit " << unit_name(options.unit) << "\n";
  out << std::setprecision(options.precision);
  for (Eigen::Index i = 0; i < V.rows(); ++i) out << "v " << V(i, 0) * s << ' ' << V(i, 1) * s << ' ' << V(i, 2) * s << '\n';
  for (Eigen::Index t = 0; t < F.rows(); ++t) {
    out << 'f';
    for (Eigen::Index k = 0; k < F.cols(); ++k) out << ' ' << F(t, k) + 1;
    out << '\n';
  }
  close_out(out, path);
}

void write_faces_vtk(const Points3& V, const Eigen::MatrixXi& F, const std::string& path, const std::string& name,
                     const std::vector<VtkField>& fields, const MeshWriteOptions& options) {
  check_writable(V, F, path);
  for (const auto& f : fields) {
    const Eigen::Index expected = f.location == VtkField::Location::kPoint ? V.rows() : F.rows();
    if (f.values.rows() != expected || (f.values.cols() != 1 && f.values.cols() != 3)) {
      throw InputError(path, 0, "VTK field '" + f.name + "': expected " + std::to_string(expected) +
                                    " rows and 1 or 3 columns, found " + std::to_string(f.values.rows()) + " x " +
                                    std::to_string(f.values.cols()));
    }
    if (f.name.empty() || std::any_of(f.name.begin(), f.name.end(), [](unsigned char c) { return std::isspace(c); })) {
      throw InputError(path, 0, "VTK field: expected a non-empty name without whitespace, found '" + f.name + "'");
    }
    if (!f.values.allFinite()) {
      throw InputError(path, 0, "VTK field '" + f.name + "': expected finite values, found NaN or Inf");
    }
  }
  std::ofstream out = open_out(path, false);
  const double s = 1.0 / metres_per_unit(options.unit);
  out << "# vtk DataFile Version 3.0\n"
      << header_name(name) << " (arthrosim, unit " << unit_name(options.unit) << ")\nASCII\nDATASET POLYDATA\n";
  out << std::setprecision(options.precision);
  out << "POINTS " << V.rows() << " double\n";
  for (Eigen::Index i = 0; i < V.rows(); ++i) out << V(i, 0) * s << ' ' << V(i, 1) * s << ' ' << V(i, 2) * s << '\n';
  out << "POLYGONS " << F.rows() << ' ' << F.rows() * (F.cols() + 1) << '\n';
  for (Eigen::Index t = 0; t < F.rows(); ++t) {
    out << F.cols();
    for (Eigen::Index k = 0; k < F.cols(); ++k) out << ' ' << F(t, k);
    out << '\n';
  }
  for (auto loc : {VtkField::Location::kPoint, VtkField::Location::kCell}) {
    bool header = false;
    for (const auto& f : fields) {
      if (f.location != loc) continue;
      if (!header) {
        out << (loc == VtkField::Location::kPoint ? "POINT_DATA " : "CELL_DATA ") << f.values.rows() << '\n';
        header = true;
      }
      if (f.values.cols() == 1) {
        out << "SCALARS " << f.name << " double 1\nLOOKUP_TABLE default\n";
        for (Eigen::Index i = 0; i < f.values.rows(); ++i) out << f.values(i, 0) << '\n';
      } else {
        out << "VECTORS " << f.name << " double\n";
        for (Eigen::Index i = 0; i < f.values.rows(); ++i)
          out << f.values(i, 0) << ' ' << f.values(i, 1) << ' ' << f.values(i, 2) << '\n';
      }
    }
  }
  close_out(out, path);
}

template <class T>
void put_le(std::string* buf, T v) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &v, sizeof(T));
  buf->append(bytes, sizeof(T));
}

}  // namespace

MeshFormat format_from_extension(const std::string& path) {
  const std::string ext = extension_of(path);
  if (ext == "stl") return MeshFormat::kStl;
  if (ext == "obj") return MeshFormat::kObj;
  if (ext == "ply") return MeshFormat::kPly;
  if (ext == "vtk") return MeshFormat::kVtk;
  throw InputError(path, 0, "expected a mesh file extension .stl, .obj, .ply or .vtk, found " +
                                (ext.empty() ? std::string("none") : "'." + ext + "'"));
}

TriangleMesh parse_stl(const std::string& content, const std::string& name, const MeshReadOptions& options) {
  // Binary STL is recognised by its size (84 + 50 * count), not by the first
  // word: many exporters write "solid ..." into the binary header too.
  if (looks_like_binary_stl(content)) return parse_binary_stl(content, name, options);
  // A truncated binary file may also start with "solid": it is ASCII only if
  // its first kilobyte is text (binary counts/floats contain NUL and control bytes).
  if (starts_with_solid(content) && looks_textual(content)) return parse_ascii_stl(content, name, options);
  if (content.size() >= 84) return parse_binary_stl(content, name, options);  // reports the size mismatch
  throw InputError(name, 0, "STL: expected an ASCII file starting with 'solid' or a binary file of 84 + 50 * n bytes, found " +
                                std::to_string(content.size()) + " bytes");
}

TriangleMesh parse_obj(const std::string& content, const std::string& name, const MeshReadOptions& options) {
  return parse_obj_impl(content, name, options);
}

TriangleMesh parse_ply(const std::string& content, const std::string& name, const MeshReadOptions& options) {
  return parse_ply_impl(content, name, options);
}

TriangleMesh read_stl(const std::string& path, const MeshReadOptions& options) {
  return parse_stl(read_whole_file(path), path, options);
}
TriangleMesh read_obj(const std::string& path, const MeshReadOptions& options) {
  return parse_obj(read_whole_file(path), path, options);
}
TriangleMesh read_ply(const std::string& path, const MeshReadOptions& options) {
  return parse_ply(read_whole_file(path), path, options);
}


QuadMesh read_quad_obj(const std::string& path, const MeshReadOptions& options, Points3* normals,
                       FaceGroups* groups) {
  const double unit = metres_per_unit(options.unit);
  std::ifstream in(path);
  if (!in) throw InputError(path + ": error: cannot open the mesh file");
  std::vector<Eigen::Vector3d> V, VN;
  std::vector<Eigen::Vector4i> Q;
  std::vector<std::string> current_groups;  // names on the last 'g' line
  std::vector<int> node_normal;  // per vertex: index into VN, -1 none
  std::vector<int> normal_line;  // per vertex: line that gave it
  int faces_with_normals = 0;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream ls(line);
    std::string kw;
    if (!(ls >> kw)) continue;
    if (kw == "v") {
      Eigen::Vector3d p;
      if (!(ls >> p.x() >> p.y() >> p.z()) || !p.allFinite())
        throw InputError(path, line_no, "expected 'v x y z' with three finite numbers");
      V.push_back(p * unit);
    } else if (kw == "vn") {
      Eigen::Vector3d n;
      if (!(ls >> n.x() >> n.y() >> n.z()) || !n.allFinite() || !(n.norm() > 0))
        throw InputError(path, line_no, "expected 'vn x y z' with three finite numbers, not all zero");
      VN.push_back(n.normalized());
    } else if (kw == "f") {
      std::vector<int> idx, nidx;
      std::string tok;
      while (ls >> tok) {
        const std::string head = tok.substr(0, tok.find('/'));
        std::size_t used = 0;
        int k = 0;
        try {
          k = std::stoi(head, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used != head.size() || head.empty() || k == 0)
          throw InputError(path, line_no, "expected a vertex index, found '" + tok + "'");
        const int i = k > 0 ? k - 1 : static_cast<int>(V.size()) + k;
        if (i < 0 || i >= static_cast<int>(V.size()))
          throw InputError(path, line_no,
                                   "vertex index " + head + " out of range (" + std::to_string(V.size()) +
                                       " vertices so far)");
        idx.push_back(i);
        // normal index: the third field of i/j/k or i//k
        const std::size_t s1 = tok.find('/'), s2 = s1 == std::string::npos ? s1 : tok.find('/', s1 + 1);
        if (s2 != std::string::npos) {
          const std::string nh = tok.substr(s2 + 1);
          int kn = 0;
          std::size_t un = 0;
          try {
            kn = std::stoi(nh, &un);
          } catch (const std::exception&) {
            un = 0;
          }
          const int in = kn > 0 ? kn - 1 : static_cast<int>(VN.size()) + kn;
          if (un != nh.size() || nh.empty() || kn == 0 || in < 0 || in >= static_cast<int>(VN.size()))
            throw InputError(path, line_no,
                                     "expected a normal index in 1.." + std::to_string(VN.size()) + ", found '" + tok +
                                         "'");
          nidx.push_back(in);
        }
      }
      if (idx.size() != 4)
        throw InputError(path, line_no,
                                 "expected a quad (4 vertices), found a face with " + std::to_string(idx.size()));
      if (!nidx.empty() && nidx.size() != 4)
        throw InputError(path, line_no, "expected a normal index on all four vertices of the face or none");
      if (!nidx.empty()) {
        ++faces_with_normals;
        node_normal.resize(V.size(), -1);
        normal_line.resize(V.size(), 0);
        for (int a = 0; a < 4; ++a) {
          int& nn = node_normal[static_cast<size_t>(idx[static_cast<size_t>(a)])];
          if (nn >= 0 && (VN[static_cast<size_t>(nn)] - VN[static_cast<size_t>(nidx[static_cast<size_t>(a)])]).norm() > 1e-12)
            throw InputError(path, line_no,
                                     "vertex " + std::to_string(idx[static_cast<size_t>(a)] + 1) +
                                         " has two different normals (the first on line " +
                                         std::to_string(normal_line[static_cast<size_t>(idx[static_cast<size_t>(a)])]) +
                                         "): a shell node has one director");
          if (nn < 0) {
            nn = nidx[static_cast<size_t>(a)];
            normal_line[static_cast<size_t>(idx[static_cast<size_t>(a)])] = line_no;
          }
        }
      }
      if (groups)
        for (const std::string& g : current_groups) (*groups)[g].push_back(static_cast<int>(Q.size()));
      Q.emplace_back(idx[0], idx[1], idx[2], idx[3]);
    } else if (kw == "g") {
      current_groups.clear();
      std::string g;
      while (ls >> g) current_groups.push_back(g);
    } else if (kw == "vt" || kw == "vp" || kw == "o" || kw == "s" || kw == "usemtl" ||
               kw == "mtllib" || kw == "l") {
      continue;
    } else {
      throw InputError(path, line_no, "unknown OBJ keyword '" + kw + "'");
    }
  }
  if (Q.empty()) throw InputError(path + ": error: no quad faces");
  QuadMesh m;
  m.V.resize(static_cast<Eigen::Index>(V.size()), 3);
  for (size_t i = 0; i < V.size(); ++i) m.V.row(static_cast<Eigen::Index>(i)) = V[i].transpose();
  m.Q.resize(static_cast<Eigen::Index>(Q.size()), 4);
  for (size_t i = 0; i < Q.size(); ++i) m.Q.row(static_cast<Eigen::Index>(i)) = Q[i].transpose();
  if (normals) normals->resize(0, 3);
  if (faces_with_normals > 0) {
    if (faces_with_normals != static_cast<int>(Q.size()))
      throw InputError(path + ": error: " + std::to_string(faces_with_normals) + " of " +
                               std::to_string(Q.size()) +
                               " faces give vertex normals: give them on every face (they are the directors) or none");
    const Points3 faces = quad_vertex_normals(m);
    Points3 N(m.num_nodes(), 3);
    for (int i = 0; i < m.num_nodes(); ++i) {
      const int nn = node_normal[static_cast<size_t>(i)];
      if (nn < 0) {  // a vertex of no face: keep the (zero) face normal
        N.row(i) = faces.row(i);
        continue;
      }
      N.row(i) = VN[static_cast<size_t>(nn)].transpose();
      if (!(N.row(i).dot(faces.row(i)) > 0))
        throw InputError(path, normal_line[static_cast<size_t>(i)],
                                 "the normal of vertex " + std::to_string(i + 1) +
                                     " points away from the side the faces' orientation gives (counter-clockwise "
                                     "faces seen from the normal's side)");
    }
    if (normals) *normals = N;
  }
  return m;
}

QuadMesh parse_quad_vtk(const std::string& content, const std::string& name, const MeshReadOptions& options,
                        std::vector<VtkField>* fields) {
  const VtkPolydata d = parse_vtk_polydata(content, name, fields);
  if (d.polys.empty()) throw InputError(name, 0, "VTK: expected a non-empty POLYGONS section of quads, found none");
  QuadMesh m;
  m.name = name;
  const double s = metres_per_unit(options.unit);
  m.V.resize(static_cast<Eigen::Index>(d.b.V.size()), 3);
  for (size_t i = 0; i < d.b.V.size(); ++i)
    for (int k = 0; k < 3; ++k) m.V(static_cast<Eigen::Index>(i), k) = d.b.V[i][k] * s;
  m.Q.resize(static_cast<Eigen::Index>(d.polys.size()), 4);
  for (size_t f = 0; f < d.polys.size(); ++f) {
    if (d.polys[f].size() != 4)
      throw InputError(name, d.poly_line[f], "VTK: expected a quad (4 points) in polygon " + std::to_string(f) +
                                                 ", found " + std::to_string(d.polys[f].size()) + " points");
    for (int k = 0; k < 4; ++k) m.Q(static_cast<Eigen::Index>(f), k) = static_cast<int>(d.polys[f][static_cast<size_t>(k)]);
  }
  return m;
}

QuadMesh read_quad_vtk(const std::string& path, const MeshReadOptions& options, std::vector<VtkField>* fields) {
  return parse_quad_vtk(read_whole_file(path), path, options, fields);
}

TriangleMesh parse_vtk(const std::string& content, const std::string& name, const MeshReadOptions& options,
                       std::vector<VtkField>* fields) {
  return parse_vtk_impl(content, name, options, fields);
}
TriangleMesh read_vtk(const std::string& path, const MeshReadOptions& options, std::vector<VtkField>* fields) {
  return parse_vtk(read_whole_file(path), path, options, fields);
}

TriangleMesh read_mesh(const std::string& path, const MeshReadOptions& options) {
  switch (format_from_extension(path)) {
    case MeshFormat::kStl: return read_stl(path, options);
    case MeshFormat::kObj: return read_obj(path, options);
    case MeshFormat::kPly: return read_ply(path, options);
    case MeshFormat::kVtk: return read_vtk(path, options);
  }
  return read_stl(path, options);  // unreachable: every enumerator is handled above
}

void write_stl(const TriangleMesh& mesh, const std::string& path, StlEncoding encoding, const MeshWriteOptions& options) {
  check_writable(mesh.V, mesh.F, path);
  const double s = 1.0 / metres_per_unit(options.unit);
  const Points3 N = triangle_normals(mesh);
  if (encoding == StlEncoding::kBinary) {
    std::string buf;
    buf.reserve(84 + 50 * static_cast<size_t>(mesh.num_triangles()));
    // The header must not begin with "solid" (some readers would take the file
    // for ASCII).
    std::string header = "binary STL by arthrosim, unit " + unit_name(options.unit) + ", " + header_name(mesh.name);
    header.resize(80, ' ');
    buf += header;
    put_le<uint32_t>(&buf, static_cast<uint32_t>(mesh.num_triangles()));
    for (int t = 0; t < mesh.num_triangles(); ++t) {
      for (int c = 0; c < 3; ++c) put_le<float>(&buf, static_cast<float>(N(t, c)));
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) put_le<float>(&buf, static_cast<float>(mesh.V(mesh.F(t, k), c) * s));
      put_le<uint16_t>(&buf, 0);
    }
    std::ofstream out = open_out(path, true);
    out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
    close_out(out, path);
    return;
  }
  std::ofstream out = open_out(path, false);
  out << std::setprecision(options.precision);
  const std::string solid = header_name(mesh.name);
  out << "solid " << solid << '\n';
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    out << "  facet normal " << N(t, 0) << ' ' << N(t, 1) << ' ' << N(t, 2) << "\n    outer loop\n";
    for (int k = 0; k < 3; ++k) {
      const int v = mesh.F(t, k);
      out << "      vertex " << mesh.V(v, 0) * s << ' ' << mesh.V(v, 1) * s << ' ' << mesh.V(v, 2) * s << '\n';
    }
    out << "    endloop\n  endfacet\n";
  }
  out << "endsolid " << solid << '\n';
  close_out(out, path);
}

void write_obj(const TriangleMesh& mesh, const std::string& path, const MeshWriteOptions& options) {
  write_faces_obj(mesh.V, mesh.F, path, mesh.name, options);
}
void write_obj(const QuadMesh& mesh, const std::string& path, const MeshWriteOptions& options) {
  write_faces_obj(mesh.V, mesh.Q, path, mesh.name, options);
}
void write_vtk(const TriangleMesh& mesh, const std::string& path, const std::vector<VtkField>& fields,
               const MeshWriteOptions& options) {
  write_faces_vtk(mesh.V, mesh.F, path, mesh.name, fields, options);
}
void write_vtk(const QuadMesh& mesh, const std::string& path, const std::vector<VtkField>& fields,
               const MeshWriteOptions& options) {
  write_faces_vtk(mesh.V, mesh.Q, path, mesh.name, fields, options);
}

void write_ply(const TriangleMesh& mesh, const std::string& path, PlyEncoding encoding, const MeshWriteOptions& options) {
  check_writable(mesh.V, mesh.F, path);
  const double s = 1.0 / metres_per_unit(options.unit);
  std::ostringstream hdr;
  hdr << "ply\nformat " << (encoding == PlyEncoding::kBinaryLittleEndian ? "binary_little_endian" : "ascii")
      << " 1.0\ncomment arthrosim mesh " << header_name(mesh.name) << ", unit " << unit_name(options.unit)
      << "\nelement vertex " << mesh.num_vertices() << "\nproperty double x\nproperty double y\nproperty double z\n"
      << "element face " << mesh.num_triangles() << "\nproperty list uchar int vertex_indices\nend_header\n";
  std::string buf = hdr.str();
  if (encoding == PlyEncoding::kBinaryLittleEndian) {
    for (int i = 0; i < mesh.num_vertices(); ++i)
      for (int c = 0; c < 3; ++c) put_le<double>(&buf, mesh.V(i, c) * s);
    for (int t = 0; t < mesh.num_triangles(); ++t) {
      put_le<uint8_t>(&buf, 3);
      for (int k = 0; k < 3; ++k) put_le<int32_t>(&buf, mesh.F(t, k));
    }
  } else {
    std::ostringstream body;
    body << std::setprecision(options.precision);
    for (int i = 0; i < mesh.num_vertices(); ++i) body << mesh.V(i, 0) * s << ' ' << mesh.V(i, 1) * s << ' ' << mesh.V(i, 2) * s << '\n';
    for (int t = 0; t < mesh.num_triangles(); ++t) body << "3 " << mesh.F(t, 0) << ' ' << mesh.F(t, 1) << ' ' << mesh.F(t, 2) << '\n';
    buf += body.str();
  }
  std::ofstream out = open_out(path, true);
  out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
  close_out(out, path);
}

void write_mesh(const TriangleMesh& mesh, const std::string& path, const MeshWriteOptions& options) {
  switch (format_from_extension(path)) {
    case MeshFormat::kStl: return write_stl(mesh, path, StlEncoding::kBinary, options);
    case MeshFormat::kObj: return write_obj(mesh, path, options);
    case MeshFormat::kPly: return write_ply(mesh, path, PlyEncoding::kBinaryLittleEndian, options);
    case MeshFormat::kVtk: return write_vtk(mesh, path, {}, options);
  }
}

}  // namespace arthrosim::common
