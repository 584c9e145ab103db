#include "pipelines/json.h"

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "common/error.h"
#include "pipelines/report.h"

namespace arthrosim::pipelines::json {

using report::number;

namespace {

std::string json_string(const std::string& t) {
  std::string s = "\"";
  for (unsigned char c : t) {
    if (c == '"' || c == '\\') {
      s += '\\';
      s += static_cast<char>(c);
    } else if (c < 0x20) {
      char b[8];
      std::snprintf(b, sizeof b, "\\u%04x", c);
      s += b;
    } else {
      s += static_cast<char>(c);
    }
  }
  return s + "\"";
}

class Parser {
 public:
  Parser(std::string text, std::string file) : text_(std::move(text)), file_(std::move(file)) {}

  Value document() {
    Value v = value();
    space();
    if (pos_ != text_.size()) fail("expected the end of the document");
    return v;
  }

 private:
  [[noreturn]] void fail(const std::string& what) {
    throw common::InputError(file_, 0, what + " at byte " + std::to_string(pos_));
  }
  void space() {
    while (pos_ < text_.size() && std::isspace(static_cast<unsigned char>(text_[pos_]))) ++pos_;
  }
  bool literal(const char* word) {
    const std::size_t n = std::char_traits<char>::length(word);
    if (text_.compare(pos_, n, word) != 0) return false;
    pos_ += n;
    return true;
  }
  std::string string_body() {
    ++pos_;  // opening quote
    std::string s;
    while (pos_ < text_.size() && text_[pos_] != '"') {
      char c = text_[pos_++];
      if (c != '\\') {
        s += c;
        continue;
      }
      if (pos_ >= text_.size()) fail("unterminated escape");
      c = text_[pos_++];
      switch (c) {
        case 'n': s += '\n'; break;
        case 't': s += '\t'; break;
        case 'r': s += '\r'; break;
        case 'b': s += '\b'; break;
        case 'f': s += '\f'; break;
        case 'u': {
          if (pos_ + 4 > text_.size()) fail("short \\u escape");
          const unsigned code = static_cast<unsigned>(std::stoul(text_.substr(pos_, 4), nullptr, 16));
          pos_ += 4;
          // UTF-8 of a code point of the basic plane (enough for our files).
          if (code < 0x80) {
            s += static_cast<char>(code);
          } else if (code < 0x800) {
            s += static_cast<char>(0xC0 | (code >> 6));
            s += static_cast<char>(0x80 | (code & 0x3F));
          } else {
            s += static_cast<char>(0xE0 | (code >> 12));
            s += static_cast<char>(0x80 | ((code >> 6) & 0x3F));
            s += static_cast<char>(0x80 | (code & 0x3F));
          }
          break;
        }
        default: s += c;  // \" \\ \/
      }
    }
    if (pos_ >= text_.size()) fail("unterminated string");
    ++pos_;
    return s;
  }
  Value value() {
    space();
    if (pos_ >= text_.size()) fail("expected a value, found the end of the file");
    Value v;
    const char c = text_[pos_];
    if (c == '{') {
      v.kind = Value::Kind::kObject;
      ++pos_;
      space();
      if (pos_ < text_.size() && text_[pos_] == '}') {
        ++pos_;
        return v;
      }
      while (true) {
        space();
        if (pos_ >= text_.size() || text_[pos_] != '"') fail("expected a key");
        std::string k = string_body();
        space();
        if (pos_ >= text_.size() || text_[pos_] != ':') fail("expected ':'");
        ++pos_;
        v.object.emplace_back(std::move(k), value());
        space();
        if (pos_ < text_.size() && text_[pos_] == ',') {
          ++pos_;
          continue;
        }
        if (pos_ < text_.size() && text_[pos_] == '}') {
          ++pos_;
          return v;
        }
        fail("expected ',' or '}'");
      }
    }
    if (c == '[') {
      v.kind = Value::Kind::kArray;
      ++pos_;
      space();
      if (pos_ < text_.size() && text_[pos_] == ']') {
        ++pos_;
        return v;
      }
      while (true) {
        v.array.push_back(value());
        space();
        if (pos_ < text_.size() && text_[pos_] == ',') {
          ++pos_;
          continue;
        }
        if (pos_ < text_.size() && text_[pos_] == ']') {
          ++pos_;
          return v;
        }
        fail("expected ',' or ']'");
      }
    }
    if (c == '"') {
      v.kind = Value::Kind::kString;
      v.string = string_body();
      return v;
    }
    if (literal("true")) {
      v.kind = Value::Kind::kBool;
      v.boolean = true;
      return v;
    }
    if (literal("false")) {
      v.kind = Value::Kind::kBool;
      return v;
    }
    if (literal("null")) return v;
    const char* begin = text_.c_str() + pos_;
    char* end = nullptr;
    v.number = std::strtod(begin, &end);
    if (end == begin) fail("expected a value");
    pos_ += static_cast<std::size_t>(end - begin);
    v.kind = Value::Kind::kNumber;
    return v;
  }

  std::string text_;
  std::string file_;
  std::size_t pos_ = 0;
};

}  // namespace

void Writer::key(const std::string& k) {
  if (!first_.empty()) {
    if (!first_.back()) out_ += ",";
    first_.back() = false;
    out_ += "\n" + std::string(2 * first_.size(), ' ');
    if (is_object_.back()) out_ += json_string(k) + ": ";
  }
}
Writer& Writer::begin_object(const std::string& k) {
  key(k);
  out_ += "{";
  first_.push_back(true);
  is_object_.push_back(true);
  return *this;
}
Writer& Writer::end_object() {
  first_.pop_back();
  is_object_.pop_back();
  out_ += "\n" + std::string(2 * first_.size(), ' ') + "}";
  return *this;
}
Writer& Writer::begin_array(const std::string& k) {
  key(k);
  out_ += "[";
  first_.push_back(true);
  is_object_.push_back(false);
  return *this;
}
Writer& Writer::end_array() {
  first_.pop_back();
  is_object_.pop_back();
  out_ += "\n" + std::string(2 * first_.size(), ' ') + "]";
  return *this;
}
Writer& Writer::value(const std::string& k, double v) {
  key(k);
  out_ += number(v);
  return *this;
}
Writer& Writer::integer(const std::string& k, long long v) {
  key(k);
  out_ += std::to_string(v);
  return *this;
}
Writer& Writer::value(const std::string& k, const std::string& v) {
  key(k);
  out_ += json_string(v);
  return *this;
}
Writer& Writer::value(const std::string& k, bool v) {
  key(k);
  out_ += v ? "true" : "false";
  return *this;
}
Writer& Writer::array(const std::string& k, const std::vector<double>& v) {
  key(k);
  out_ += "[";
  for (size_t i = 0; i < v.size(); ++i) out_ += (i ? ", " : "") + number(v[i]);
  out_ += "]";
  return *this;
}
Writer& Writer::array(const std::string& k, const std::vector<std::string>& v) {
  key(k);
  out_ += "[";
  for (size_t i = 0; i < v.size(); ++i) out_ += (i ? ", " : "") + json_string(v[i]);
  out_ += "]";
  return *this;
}

const Value* Value::get(const std::string& key) const {
  for (const auto& [k, v] : object) {
    if (k == key) return &v;
  }
  return nullptr;
}

Value parse(const std::string& text, const std::string& file) { return Parser(text, file).document(); }

Value read(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw common::InputError(file.string(), 0, "cannot open");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse(ss.str(), file.string());
}

}  // namespace arthrosim::pipelines::json
