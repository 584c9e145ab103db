#pragma once
// JSON for arthrosim's own files (post summary.json, study.json): one writer
// producing pretty, deterministic output, and one reader of what it writes
// (objects, arrays, strings, numbers, true/false/null). Numbers are written
// with report::number ("%.6g"; NaN/Inf as null).
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace arthrosim::pipelines::json {

class Writer {
 public:
  Writer& begin_object(const std::string& key = "");
  Writer& end_object();
  Writer& begin_array(const std::string& key = "");
  Writer& end_array();
  Writer& value(const std::string& key, double v);
  Writer& value(const std::string& key, const std::string& v);
  Writer& value(const std::string& key, const char* v) { return value(key, std::string(v)); }
  Writer& value(const std::string& key, bool v);
  Writer& value(const std::string& key, int v) { return value(key, static_cast<double>(v)); }
  /// An exact integer (counts beyond six significant digits).
  Writer& integer(const std::string& key, long long v);
  Writer& array(const std::string& key, const std::vector<double>& v);
  Writer& array(const std::string& key, const std::vector<std::string>& v);
  const std::string& str() const { return out_; }

 private:
  void key(const std::string& k);
  std::string out_;
  std::vector<bool> first_;  // per open container: nothing written yet
  std::vector<bool> is_object_;
};

/// A parsed JSON value.
struct Value {
  // Declared (not an aggregate): clang with libstdc++ would otherwise need
  // std::pair<std::string, Value> complete inside this class.
  Value() = default;
  enum class Kind { kNull, kBool, kNumber, kString, kArray, kObject } kind = Kind::kNull;
  bool boolean = false;
  double number = 0.0;
  std::string string;
  std::vector<Value> array;
  std::vector<std::pair<std::string, Value>> object;
  /// The member `key` of an object, or nullptr.
  const Value* get(const std::string& key) const;
};

/// Parses `text`; InputError naming `file` and the byte offset on bad input.
Value parse(const std::string& text, const std::string& file);
/// Reads and parses a file.
Value read(const std::filesystem::path& file);

}  // namespace arthrosim::pipelines::json
