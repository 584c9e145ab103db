#pragma once
// Scenes: what a researcher asks arthrosim to simulate (docs/scenes.md).
//
// A scene is a YAML file naming the model, optionally a trial, the outputs
// wanted, the effects to simulate and per-stage options. This header is the
// typed view of it; yaml-cpp stays inside scene.cc.
//
// The schema -- every allowed key of every block, its type, unit, default,
// range and meaning -- is the table returned by option_schema() (scene.cc),
// and nowhere else: the parser, the docs check in tests and `arthrosim
// schema` all read it. Every key that is not in it, every effect name not in
// known_effects() (common/effects.h), every value of the wrong type or out of
// range is an InputError "scene.yaml:LINE:COLUMN: error: ..." (a typo must
// never silently disable physics).
//
// Units: a key whose value is not in SI carries its unit as a suffix
// (edge_length_mm, osmotic_pressure_mpa). OptionBlock::si(key) returns the
// value converted to SI (m, rad, s, Pa, N/m^3, ...); as_written(key) returns
// it as written in the file (the unit of the suffix).
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
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
  kTextList,    ///< [a, b, c]
  kNumberList,  ///< [1, -2.5, 3]: numbers (each converted to SI by the unit), length = min..max
  kEffectList,  ///< [effect, ...] from known_effects(), of the block's stage
  kOutputList,  ///< [output, ...]: prepared_model, kinematics, surface, report
  kBlock,       ///< a nested block of options (prepare:, comak:, ...)
  kScenarios,   ///< surface.scenarios: a map of scenario name -> scenario block
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
};

/// Suffix (with leading underscore, "" for kNone), SI factor and SI unit name.
std::string_view unit_suffix(Unit unit);
double unit_to_si(Unit unit);
std::string_view si_unit_name(Unit unit);

/// One allowed key of one block.
struct OptionSpec {
  /// "scene" (top level), "prepare", "comak", "surface", "scenario" (one
  /// entry of surface.scenarios; it also accepts every "surface" key with
  /// kOverridable set), "post".
  std::string_view block;
  std::string_view key;  ///< as written in a scene, unit suffix included
  OptionType type;
  Unit unit;
  /// Default as it would be written in the scene; empty = no default (the
  /// key is then either required or simply absent).
  std::string_view default_value;
  bool required;
  /// Allowed closed range of a number or integer, in the unit as written;
  /// for kNumberList the allowed list length.
  double min;
  double max;
  /// For kText: allowed words separated by '|', empty = any word.
  std::string_view choices;
  /// A "surface" key that a scenario may set for itself.
  bool overridable;
  std::string_view doc;
};

/// The whole schema, in documentation order.
const std::vector<OptionSpec>& option_schema();
/// The spec of `key` in `block`, or nullptr.
const OptionSpec* find_option(std::string_view block, std::string_view key);

/// What a scene can ask for; each comes from one stage (pipelines/runner.h).
enum class Output { kPreparedModel, kKinematics, kSurface, kReport };
std::string_view to_string(Output output);
std::optional<Output> parse_output(std::string_view word);

/// One option's value after parsing. Exactly the member matching the spec's
/// type is meaningful.
struct OptionValue {
  const OptionSpec* spec = nullptr;
  bool given = false;  ///< written in the scene (false: the default)
  int line = 0;        ///< where it was written (1-based; 0 for a default)
  int column = 0;
  double number_as_written = 0.0;
  double number_si = 0.0;
  std::int64_t integer = 0;
  bool flag = false;
  std::string text;                 ///< kText; kPath as written
  std::filesystem::path path;       ///< kPath resolved (absolute, normalised)
  std::vector<std::string> list;    ///< kTextList, kEffectList, kOutputList
  std::vector<double> numbers_as_written;  ///< kNumberList
  std::vector<double> numbers_si;          ///< kNumberList
  /// Canonical text of the value: numbers in shortest round-trip form in the
  /// unit as written ("3", "0.0001"), lists as "[a, b]", paths as written.
  /// Two scenes that mean the same get the same canonical text.
  std::string canonical;
};

/// The options of one block (defaults filled in). Getters take the key as
/// written in scenes; asking for a key that is not in the block's schema, or
/// with the wrong type, or one without a value, throws std::logic_error (a
/// programming error, not a user error).
class OptionBlock {
 public:
  OptionBlock() = default;
  explicit OptionBlock(std::string name) : name_(std::move(name)) {}

  /// "prepare", "comak", "surface", "surface.osmotic", "post".
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

/// One surface-stage run (the seed's osmotic, gait, gait_osmotic).
struct Scenario {
  std::string name;  ///< [a-z0-9_]+, used in file names: surface_<name>.h5
  int line = 0;      ///< where its block starts in the scene
  /// Effects to simulate, in the order written; each a known surface effect.
  std::vector<std::string> effects;
  /// The "surface" options with this scenario's overrides applied; its name
  /// is "surface.<name>". Also holds "effects" and "description".
  OptionBlock options;
  bool wants(std::string_view effect) const;
};

struct Scene {
  std::filesystem::path file;  ///< absolute path of the scene file
  std::string description;
  std::filesystem::path model;               ///< resolved, absolute
  std::optional<std::filesystem::path> trial;  ///< resolved, absolute
  std::vector<Output> outputs;               ///< as requested, no duplicates
  OptionBlock top;                           ///< the top-level keys
  OptionBlock prepare;
  /// Present when the scene has a comak block; holds "effects".
  std::optional<OptionBlock> comak;
  /// The surface block's own options (defaults for every scenario).
  std::optional<OptionBlock> surface;
  std::vector<Scenario> scenarios;
  OptionBlock post;

  bool wants(Output output) const;
  /// The scenario called `name`, or nullptr.
  const Scenario* scenario(std::string_view name) const;
  /// The scenario called `name` (e.g. from a stage's --scenario); InputError
  /// naming the scene file and the scenarios it has when there is none.
  const Scenario& require_scenario(std::string_view name) const;
  /// comak's effect list (empty when there is no comak block).
  std::vector<std::string> musculoskeletal_effects() const;
};

/// Reads and validates a scene file. Relative paths inside are resolved
/// against the scene file's folder first, then against the repository that
/// contains it (nearest ancestor folder holding a .git entry). Throws
/// InputError with file:line:column on any problem.
Scene load_scene(const std::filesystem::path& file);

/// Same from text already in memory; `file` is used for messages and for
/// resolving relative paths (it need not exist).
Scene parse_scene(const std::string& text, const std::filesystem::path& file);

/// The schema as a Markdown table per block (for docs/scenes.md and
/// `arthrosim schema`).
std::string schema_markdown();

}  // namespace arthrosim::common
