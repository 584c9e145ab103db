#pragma once
// Options that declare themselves (docs/architecture.md, "How to add an option").
//
// An options struct holds its values in SI units with their one default in the
// field's initializer, and declares its scene keys next to the fields in one
// member function that visits every field:
//
//   struct PrepareOptions {
//     double edge_length_m = 3 * common::units::mm;
//     int remesh_iterations = 5;
//     void declare(common::OptionVisitor& v) {
//       v.number("edge_length_mm", edge_length_m, common::Unit::kMillimetre, {0.2, 20},
//                "target edge length of the remeshed cartilage surfaces");
//       v.integer("remesh_iterations", remesh_iterations, {1, 20}, "isotropic remeshing iterations");
//     }
//   };
//
// The same declaration serves three visitors: declared_keys<T>() collects the
// schema (key, type, unit, range, doc, and the default printed from a
// default-constructed T), which the scene reader, `arthrosim schema` and
// docs/scenes.md use; read_options<T>(block) fills a T from a parsed scene
// block; and any other OptionVisitor (e.g. a writer) can be added the same way.
//
// Units: a key whose value is not in SI ends with its unit (edge_length_mm);
// the field is SI (edge_length_m). Write a non-SI default as the number as
// written times its unit from common::units (3 * units::mm), so that the
// default is bit-for-bit what the scene reader makes of the text "3".
#include <cstdint>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <limits>
#include <map>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace arthrosim::common {

enum class OptionType {
  kNumber,      ///< real number (finite), converted to SI by its unit
  kInteger,     ///< whole number
  kFlag,        ///< true / false
  kText,        ///< one word; `choices` may restrict it
  kPath,        ///< file or folder, relative to the scene file (see docs)
  kTextList,    ///< [a, b, c]; `choices` may restrict the items
  kNumberList,  ///< [1, -2.5, 3]: numbers (each converted to SI by the unit), length = min..max
  kNamedNumberList,  ///< [name=1.5, other=2]: a number per name (SI by the unit), each in min..max
  kEffectList,  ///< [effect, ...] from the effect vocabulary, of the block's stage
  kBlock,       ///< a nested block of options (prepare:, comak:, ...)
  kInstances,   ///< named instances of the enclosing block (surface.scenarios)
};

/// Unit of a value as written in the scene. The key's suffix names it
/// (checked by a test over the schema).
enum class Unit {
  kNone,                            ///< dimensionless or not a number
  kMillimetre,                      ///< _mm   -> m      (x 1e-3)
  kDegree,                          ///< _deg  -> rad    (x pi/180)
  kSecond,                          ///< _s    -> s
  kMillisecond,                     ///< _ms   -> s      (x 1e-3)
  kMegapascal,                      ///< _mpa  -> Pa     (x 1e6)
  kHertz,                           ///< _hz   -> 1/s
  kKilogramPerCubicMetre,           ///< _kg_per_m3
  kNewtonPerCubicMillimetre,        ///< _n_per_mm3   -> N/m^3   (x 1e9)
  kNewtonSecondPerCubicMillimetre,  ///< _n_s_per_mm3 -> N s/m^3 (x 1e9)
  kMicrosecond,                     ///< _us   -> s      (x 1e-6)
  kMillijoulePerSquareMillimetre,   ///< _mj_per_mm2 -> J/m^2 (x 1e3)
};

/// Suffix (with leading underscore, "" for kNone), SI factor and SI unit name.
std::string_view unit_suffix(Unit unit);
double unit_to_si(Unit unit);
std::string_view si_unit_name(Unit unit);

/// SI value of one unit as written, for defaults: 3 * units::mm. The same
/// factors as unit_to_si().
namespace units {
inline constexpr double mm = 1e-3;
inline constexpr double ms = 1e-3;
inline constexpr double us = 1e-6;
inline constexpr double deg = std::numbers::pi / 180.0;
inline constexpr double mpa = 1e6;
inline constexpr double n_per_mm3 = 1e9;
inline constexpr double n_s_per_mm3 = 1e9;
// 1 mJ/mm^2 = 1e-3 J / (1e-3 m)^2 = 1e3 J/m^2.
inline constexpr double mj_per_mm2 = 1e3;
}  // namespace units

/// Closed range of a number or whole number, in the unit as written; for a
/// number list its allowed length.
struct Range {
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
};

/// One allowed key of one block (what declared_keys() collects).
struct OptionSpec {
  /// "scene" (top level), a block name ("prepare", "comak", "surface",
  /// "post", ...) or an instance label ("scenario": one entry of
  /// surface.scenarios).
  std::string block;
  std::string key;  ///< as written in a scene, unit suffix included
  OptionType type = OptionType::kText;
  Unit unit = Unit::kNone;
  /// Default as it would be written in the scene; empty = no default (the
  /// key is then either required or simply absent).
  std::string default_value;
  bool required = false;
  double min = 0, max = 0;  ///< see Range
  /// For kText and kTextList: allowed words separated by '|', empty = any.
  std::string choices;
  /// A key of a block with instances that each instance may set for itself.
  bool overridable = false;
  /// kEffectList: the stage whose effects the list takes.
  std::string effect_stage;
  std::string doc;
};

/// Visits every declared option of an options struct (see the file comment).
/// Each call declares one key bound to one field; a field's value in a
/// default-constructed struct is the key's default.
class OptionVisitor {
 public:
  virtual ~OptionVisitor() = default;
  /// A real number, stored in SI.
  virtual OptionVisitor& number(std::string_view key, double& si, Unit unit, Range range, std::string_view doc) = 0;
  /// A real number without a default (nullopt unless written).
  virtual OptionVisitor& number(std::string_view key, std::optional<double>& si, Unit unit, Range range,
                                std::string_view doc) = 0;
  virtual OptionVisitor& integer(std::string_view key, int& value, Range range, std::string_view doc) = 0;
  virtual OptionVisitor& flag(std::string_view key, bool& value, std::string_view doc) = 0;
  /// One word; choices "a|b|c" restrict it ("" = any word; an empty value
  /// means no default).
  virtual OptionVisitor& text(std::string_view key, std::string& value, std::string_view choices,
                              std::string_view doc) = 0;
  /// A file or folder (resolved against the scene file); empty = not given.
  virtual OptionVisitor& path(std::string_view key, std::filesystem::path& value, std::string_view doc) = 0;
  /// [a, b]; choices "a|b|c" restrict the items ("" = any word).
  virtual OptionVisitor& text_list(std::string_view key, std::vector<std::string>& value, std::string_view choices,
                                   std::string_view doc) = 0;
  /// [1, 2.5] in SI; `length` bounds the number of items; empty = not given.
  virtual OptionVisitor& number_list(std::string_view key, std::vector<double>& si, Unit unit, Range length,
                                     std::string_view doc) = 0;
  /// [name=value, ...]: a number per name, in SI; `range` bounds each value.
  virtual OptionVisitor& named_numbers(std::string_view key, std::map<std::string, double>& si, Unit unit,
                                       Range range, std::string_view doc) = 0;
  /// [effect, ...] of `stage` (the effect vocabulary, common/effects.h).
  virtual OptionVisitor& effect_list(std::string_view key, std::vector<std::string>& value, std::string_view stage,
                                     std::string_view doc) = 0;
  /// A word mapped to an enum (or any copyable type): choice("contact_rim",
  /// rim, {{"fade_inside", Rim::kFade}, {"rim_contacts", Rim::kContacts}}, doc).
  template <class E>
  OptionVisitor& choice(std::string_view key, E& value, std::initializer_list<std::pair<std::string_view, E>> words,
                        std::string_view doc) {
    std::vector<std::string_view> names;
    int index = -1;
    for (const auto& [name, v] : words) {
      if (v == value && index < 0) index = static_cast<int>(names.size());
      names.push_back(name);
    }
    choice_index(key, names, index, doc);
    if (index >= 0) value = std::data(words)[index].second;
    return *this;
  }
  /// Modifier of the key declared last: it must be written (no default).
  virtual OptionVisitor& required() { return *this; }

 protected:
  /// choice(): `index` is the current value's word (in: the default; out:
  /// the word read, or unchanged).
  virtual void choice_index(std::string_view key, const std::vector<std::string_view>& words, int& index,
                            std::string_view doc) = 0;
};

/// The schema of one block: visits a default-constructed T with a collector.
/// Throws std::logic_error for a default that cannot be written exactly in
/// its unit (see units), or a key declared twice.
std::vector<OptionSpec> collect_keys(const std::string& block, const std::function<void(OptionVisitor&)>& declare);
template <class T>
std::vector<OptionSpec> declared_keys(const std::string& block) {
  T defaults{};
  return collect_keys(block, [&](OptionVisitor& v) { defaults.declare(v); });
}

/// Shortest text of `si` in `unit` as written that the scene reader turns
/// into exactly `si` (e.g. 0.003 in mm -> "3"); throws std::logic_error if
/// there is none.
std::string written_value(double si, Unit unit);
/// Shortest round-trip text of a number ("3", "0.0001").
std::string shortest_text(double v);

// ---------------------------------------------------------------------------
// Parsed values
// ---------------------------------------------------------------------------

/// One option's value after parsing. Exactly the member matching the spec's
/// type is meaningful.
struct OptionValue {
  const OptionSpec* spec = nullptr;
  bool given = false;  ///< written in the scene (false: the default)
  int line = 0;        ///< where its key was written (1-based; 0 for a default)
  int column = 0;
  int value_line = 0;  ///< where its value starts
  int value_column = 0;
  double number_as_written = 0.0;
  double number_si = 0.0;
  std::int64_t integer = 0;
  bool flag = false;
  std::string text;                 ///< kText; kPath as written
  std::filesystem::path path;       ///< kPath resolved (absolute, normalised)
  std::vector<std::string> list;    ///< kTextList, kEffectList; kNamedNumberList: the names
  std::vector<double> numbers_as_written;  ///< kNumberList, kNamedNumberList
  std::vector<double> numbers_si;          ///< kNumberList, kNamedNumberList
  /// Canonical text of the value: numbers in shortest round-trip form in the
  /// unit as written ("3", "0.0001"), lists as "[a, b]", paths as written.
  /// Two scenes that mean the same get the same canonical text.
  std::string canonical;
};

/// The options of one block (defaults filled in). Getters take the key as
/// written in scenes; asking for a key that is not in the block's schema, or
/// with the wrong type, or one without a value, throws std::logic_error (a
/// programming error, not a user error). Stages read their options through
/// read_options<T>() rather than these getters.
class OptionBlock {
 public:
  OptionBlock() = default;
  explicit OptionBlock(std::string name) : name_(std::move(name)) {}

  /// "prepare", "comak", "surface", "surface.osmotic", "post", "scene".
  const std::string& name() const { return name_; }

  double si(std::string_view key) const;          ///< number in SI units
  double as_written(std::string_view key) const;  ///< number in the key's unit
  std::int64_t integer(std::string_view key) const;
  bool flag(std::string_view key) const;
  const std::string& text(std::string_view key) const;
  const std::filesystem::path& path(std::string_view key) const;
  const std::vector<std::string>& list(std::string_view key) const;
  /// kNumberList values in SI units.
  const std::vector<double>& numbers_si(std::string_view key) const;
  /// kNamedNumberList values in SI units by name.
  std::map<std::string, double> named_si(std::string_view key) const;
  /// True when the key has a value (given in the scene or by default).
  bool has(std::string_view key) const;
  /// True when the key was written in the scene.
  bool given(std::string_view key) const;
  const OptionValue& value(std::string_view key) const;

  /// ("<name>.<key>", canonical value) for every key with a value, sorted by
  /// key. This is what the runner hashes and compares between runs.
  std::vector<std::pair<std::string, std::string>> canonical() const;
  /// canonical() as "name.key = value" lines.
  std::string canonical_text() const;

  /// Used by the parser.
  void set(const std::string& key, OptionValue value);
  const std::map<std::string, OptionValue, std::less<>>& values() const { return values_; }

 private:
  const OptionValue& checked(std::string_view key, OptionType type) const;
  std::string name_;
  std::map<std::string, OptionValue, std::less<>> values_;
};

/// Fills the declared fields of an options struct from a parsed block (keys
/// without a value keep the struct's value).
void read_block(const OptionBlock& block, const std::function<void(OptionVisitor&)>& declare);
template <class T>
T read_options(const OptionBlock& block) {
  T t{};
  read_block(block, [&](OptionVisitor& v) { t.declare(v); });
  return t;
}

/// "a number", "a whole number", ... (for messages).
std::string_view type_word(OptionType type);

}  // namespace arthrosim::common
