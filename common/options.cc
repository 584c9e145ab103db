#include "common/options.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace arthrosim::common {

using T = OptionType;
using U = Unit;

// ---------------------------------------------------------------------------
// Units
// ---------------------------------------------------------------------------
std::string_view unit_suffix(Unit unit) {
  switch (unit) {
    case U::kNone:
      return "";
    case U::kMillimetre:
      return "_mm";
    case U::kDegree:
      return "_deg";
    case U::kSecond:
      return "_s";
    case U::kMillisecond:
      return "_ms";
    case U::kMegapascal:
      return "_mpa";
    case U::kHertz:
      return "_hz";
    case U::kKilogramPerCubicMetre:
      return "_kg_per_m3";
    case U::kNewtonPerCubicMillimetre:
      return "_n_per_mm3";
    case U::kNewtonSecondPerCubicMillimetre:
      return "_n_s_per_mm3";
    case U::kMicrosecond:
      return "_us";
    case U::kMillijoulePerSquareMillimetre:
      return "_mj_per_mm2";
  }
  return "";
}

double unit_to_si(Unit unit) {
  switch (unit) {
    case U::kMillimetre:
      return units::mm;
    case U::kMillisecond:
      return units::ms;
    case U::kDegree:
      return units::deg;
    case U::kMegapascal:
      return units::mpa;
    // 1 N/mm^3 = 1 N / (1e-3 m)^3 = 1e9 N/m^3; likewise N s/mm^3.
    case U::kNewtonPerCubicMillimetre:
      return units::n_per_mm3;
    case U::kNewtonSecondPerCubicMillimetre:
      return units::n_s_per_mm3;
    case U::kMicrosecond:
      return units::us;
    case U::kMillijoulePerSquareMillimetre:
      return units::mj_per_mm2;
    case U::kNone:
    case U::kSecond:
    case U::kHertz:
    case U::kKilogramPerCubicMetre:
      return 1.0;
  }
  return 1.0;
}

std::string_view si_unit_name(Unit unit) {
  switch (unit) {
    case U::kNone:
      return "";
    case U::kMillimetre:
      return "m";
    case U::kDegree:
      return "rad";
    case U::kSecond:
    case U::kMillisecond:
    case U::kMicrosecond:
      return "s";
    case U::kMegapascal:
      return "Pa";
    case U::kHertz:
      return "1/s";
    case U::kKilogramPerCubicMetre:
      return "kg/m^3";
    case U::kNewtonPerCubicMillimetre:
      return "N/m^3";
    case U::kNewtonSecondPerCubicMillimetre:
      return "N s/m^3";
    case U::kMillijoulePerSquareMillimetre:
      return "J/m^2";
  }
  return "";
}

std::string_view type_word(OptionType t) {
  switch (t) {
    case T::kNumber:
      return "a number";
    case T::kInteger:
      return "a whole number";
    case T::kFlag:
      return "true or false";
    case T::kText:
      return "text";
    case T::kPath:
      return "a path";
    case T::kTextList:
      return "a list like [a, b]";
    case T::kNumberList:
      return "a list of numbers like [1, 2.5]";
    case T::kNamedNumberList:
      return "a list like [name=1.5]";
    case T::kEffectList:
      return "a list of effects like [a, b]";
    case T::kBlock:
    case T::kInstances:
      return "a block of keys";
  }
  return "a value";
}

std::string shortest_text(double v) {
  char buf[64];
  auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, end);
}

std::string written_value(double si, Unit unit) {
  const double f = unit_to_si(unit);
  if (f == 1.0) return shortest_text(si);
  // The scene reader computes strtod(text) * f; find the shortest text for
  // which that is exactly `si`.
  for (int digits = 1; digits <= 17; ++digits) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*g", digits, si / f);
    const double d = std::strtod(buf, nullptr);
    if (d * f == si) return shortest_text(d);
  }
  throw std::logic_error("option default " + shortest_text(si) + " " + std::string(si_unit_name(unit)) +
                         " cannot be written exactly in " + std::string(unit_suffix(unit).substr(1)) +
                         " (write it as <number> * units::<unit>)");
}

// ---------------------------------------------------------------------------
// The collector: declarations -> OptionSpec list
// ---------------------------------------------------------------------------
namespace {

std::string list_text(const std::vector<std::string>& words) {
  std::string s = "[";
  for (std::size_t i = 0; i < words.size(); ++i) s += (i ? ", " : "") + words[i];
  return s + "]";
}

class SpecCollector final : public OptionVisitor {
 public:
  explicit SpecCollector(std::string block) : block_(std::move(block)) {}
  std::vector<OptionSpec> take() { return std::move(specs_); }

  OptionVisitor& number(std::string_view key, double& si, Unit unit, Range range, std::string_view doc) override {
    add(key, T::kNumber, unit, written_value(si, unit), range, "", doc);
    return *this;
  }
  OptionVisitor& number(std::string_view key, std::optional<double>& si, Unit unit, Range range,
                        std::string_view doc) override {
    add(key, T::kNumber, unit, si ? written_value(*si, unit) : "", range, "", doc);
    return *this;
  }
  OptionVisitor& integer(std::string_view key, int& value, Range range, std::string_view doc) override {
    add(key, T::kInteger, U::kNone, std::to_string(value), range, "", doc);
    return *this;
  }
  OptionVisitor& flag(std::string_view key, bool& value, std::string_view doc) override {
    add(key, T::kFlag, U::kNone, value ? "true" : "false", {0, 0}, "", doc);
    return *this;
  }
  OptionVisitor& text(std::string_view key, std::string& value, std::string_view choices,
                      std::string_view doc) override {
    add(key, T::kText, U::kNone, value, {0, 0}, choices, doc);
    return *this;
  }
  OptionVisitor& path(std::string_view key, std::filesystem::path& value, std::string_view doc) override {
    add(key, T::kPath, U::kNone, value.string(), {0, 0}, "", doc);
    return *this;
  }
  OptionVisitor& text_list(std::string_view key, std::vector<std::string>& value, std::string_view choices,
                           std::string_view doc) override {
    add(key, T::kTextList, U::kNone, list_text(value), {0, 0}, choices, doc);
    return *this;
  }
  OptionVisitor& number_list(std::string_view key, std::vector<double>& si, Unit unit, Range length,
                             std::string_view doc) override {
    std::vector<std::string> words;
    for (double x : si) words.push_back(written_value(x, unit));
    add(key, T::kNumberList, unit, si.empty() ? "" : list_text(words), length, "", doc);
    return *this;
  }
  OptionVisitor& named_numbers(std::string_view key, std::map<std::string, double>& si, Unit unit, Range range,
                               std::string_view doc) override {
    std::vector<std::string> words;
    for (const auto& [name, x] : si) words.push_back(name + "=" + written_value(x, unit));
    add(key, T::kNamedNumberList, unit, list_text(words), range, "", doc);
    return *this;
  }
  OptionVisitor& effect_list(std::string_view key, std::vector<std::string>& value, std::string_view stage,
                             std::string_view doc) override {
    add(key, T::kEffectList, U::kNone, value.empty() ? "" : list_text(value), {0, 0}, "", doc);
    specs_.back().effect_stage = std::string(stage);
    return *this;
  }
  OptionVisitor& required() override {
    if (specs_.empty()) throw std::logic_error("required() before any key of block " + block_);
    specs_.back().required = true;
    specs_.back().default_value.clear();
    return *this;
  }

 protected:
  void choice_index(std::string_view key, const std::vector<std::string_view>& words, int& index,
                    std::string_view doc) override {
    std::string choices;
    for (std::string_view w : words) choices += (choices.empty() ? "" : "|") + std::string(w);
    add(key, T::kText, U::kNone, index >= 0 ? std::string(words[static_cast<std::size_t>(index)]) : "", {0, 0},
        choices, doc);
  }

 private:
  void add(std::string_view key, OptionType type, Unit unit, std::string default_value, Range range,
           std::string_view choices, std::string_view doc) {
    for (const OptionSpec& s : specs_)
      if (s.key == key) throw std::logic_error("key " + block_ + "." + std::string(key) + " declared twice");
    OptionSpec s;
    s.block = block_;
    s.key = std::string(key);
    s.type = type;
    s.unit = unit;
    s.default_value = std::move(default_value);
    s.min = range.min;
    s.max = range.max;
    s.choices = std::string(choices);
    s.doc = std::string(doc);
    specs_.push_back(std::move(s));
  }
  std::string block_;
  std::vector<OptionSpec> specs_;
};

// The reader: a parsed block -> the declared fields.
class BlockReader final : public OptionVisitor {
 public:
  explicit BlockReader(const OptionBlock& block) : b_(block) {}

  OptionVisitor& number(std::string_view key, double& si, Unit, Range, std::string_view) override {
    if (b_.has(key)) si = b_.si(key);
    return *this;
  }
  OptionVisitor& number(std::string_view key, std::optional<double>& si, Unit, Range, std::string_view) override {
    if (b_.has(key)) si = b_.si(key);
    return *this;
  }
  OptionVisitor& integer(std::string_view key, int& value, Range, std::string_view) override {
    if (b_.has(key)) value = static_cast<int>(b_.integer(key));
    return *this;
  }
  OptionVisitor& flag(std::string_view key, bool& value, std::string_view) override {
    if (b_.has(key)) value = b_.flag(key);
    return *this;
  }
  OptionVisitor& text(std::string_view key, std::string& value, std::string_view, std::string_view) override {
    if (b_.has(key)) value = b_.text(key);
    return *this;
  }
  OptionVisitor& path(std::string_view key, std::filesystem::path& value, std::string_view) override {
    if (b_.has(key)) value = b_.path(key);
    return *this;
  }
  OptionVisitor& text_list(std::string_view key, std::vector<std::string>& value, std::string_view,
                           std::string_view) override {
    if (b_.has(key)) value = b_.list(key);
    return *this;
  }
  OptionVisitor& number_list(std::string_view key, std::vector<double>& si, Unit, Range, std::string_view) override {
    if (b_.has(key)) si = b_.numbers_si(key);
    return *this;
  }
  OptionVisitor& named_numbers(std::string_view key, std::map<std::string, double>& si, Unit, Range,
                               std::string_view) override {
    if (b_.has(key)) si = b_.named_si(key);
    return *this;
  }
  OptionVisitor& effect_list(std::string_view key, std::vector<std::string>& value, std::string_view,
                             std::string_view) override {
    if (b_.has(key)) value = b_.list(key);
    return *this;
  }

 protected:
  void choice_index(std::string_view key, const std::vector<std::string_view>& words, int& index,
                    std::string_view) override {
    if (!b_.has(key)) return;
    const std::string& word = b_.text(key);
    for (std::size_t i = 0; i < words.size(); ++i)
      if (words[i] == word) index = static_cast<int>(i);
  }

 private:
  const OptionBlock& b_;
};

}  // namespace

std::vector<OptionSpec> collect_keys(const std::string& block, const std::function<void(OptionVisitor&)>& declare) {
  SpecCollector c(block);
  declare(c);
  return c.take();
}

void read_block(const OptionBlock& block, const std::function<void(OptionVisitor&)>& declare) {
  BlockReader r(block);
  declare(r);
}

// ---------------------------------------------------------------------------
// OptionBlock
// ---------------------------------------------------------------------------
const OptionValue& OptionBlock::value(std::string_view key) const {
  auto it = values_.find(key);
  if (it == values_.end()) {
    throw std::logic_error("option block '" + name_ + "' has no value for '" + std::string(key) +
                           "' (not in the schema, or no default and not given; check has())");
  }
  return it->second;
}

const OptionValue& OptionBlock::checked(std::string_view key, OptionType type) const {
  const OptionValue& v = value(key);
  if (v.spec->type != type) {
    throw std::logic_error("option '" + name_ + "." + std::string(key) +
                           "' read with the wrong type (the schema says " +
                           std::string(type_word(v.spec->type)) + ")");
  }
  return v;
}

double OptionBlock::si(std::string_view key) const { return checked(key, T::kNumber).number_si; }
double OptionBlock::as_written(std::string_view key) const {
  return checked(key, T::kNumber).number_as_written;
}
std::int64_t OptionBlock::integer(std::string_view key) const {
  return checked(key, T::kInteger).integer;
}
bool OptionBlock::flag(std::string_view key) const { return checked(key, T::kFlag).flag; }
const std::string& OptionBlock::text(std::string_view key) const {
  return checked(key, T::kText).text;
}
const std::filesystem::path& OptionBlock::path(std::string_view key) const {
  return checked(key, T::kPath).path;
}
const std::vector<double>& OptionBlock::numbers_si(std::string_view key) const {
  return checked(key, T::kNumberList).numbers_si;
}
std::map<std::string, double> OptionBlock::named_si(std::string_view key) const {
  const OptionValue& v = checked(key, T::kNamedNumberList);
  std::map<std::string, double> out;
  for (std::size_t i = 0; i < v.list.size(); ++i) out[v.list[i]] = v.numbers_si[i];
  return out;
}

const std::vector<std::string>& OptionBlock::list(std::string_view key) const {
  const OptionValue& v = value(key);
  if (v.spec->type != T::kTextList && v.spec->type != T::kEffectList) {
    throw std::logic_error("option '" + name_ + "." + std::string(key) +
                           "' read as a list but is " + std::string(type_word(v.spec->type)));
  }
  return v.list;
}
bool OptionBlock::has(std::string_view key) const { return values_.find(key) != values_.end(); }
bool OptionBlock::given(std::string_view key) const {
  auto it = values_.find(key);
  return it != values_.end() && it->second.given;
}

std::vector<std::pair<std::string, std::string>> OptionBlock::canonical() const {
  std::vector<std::pair<std::string, std::string>> out;
  for (const auto& [key, v] : values_) out.emplace_back(name_ + "." + key, v.canonical);
  return out;  // std::map: already sorted by key
}

std::string OptionBlock::canonical_text() const {
  std::string s;
  for (const auto& [k, v] : canonical()) s += k + " = " + v + "\n";
  return s;
}

void OptionBlock::set(const std::string& key, OptionValue value) {
  values_[key] = std::move(value);
}

}  // namespace arthrosim::common
