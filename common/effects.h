#pragma once
// The effect vocabulary of scenes and the ledger in which a stage records
// every physics term it actually constructs.
//
// Why a ledger: "simulate only the effects a scene calls for" (issue 2, 8) is
// a claim about what the code built, so it must be checked against what the
// code built. Each stage creates one EffectLedger, calls record() at the
// moment it constructs a term (e.g. after building the foundation springs of
// one surface, with the number of springs), writes the ledger into its output
// file and prints it. Tests then read the ledger back and assert that a term a
// scene does not ask for was never constructed.
//
// The vocabulary (kEffects in effects.cc) is the single list of effect names a
// scene may use; the scene parser rejects any other name with file:line, and
// record() rejects any other name with std::logic_error (a programming error).
// A later stage that adds a physics term adds its name there, with a one-line
// description, and documents it in docs/scenes.md.
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace arthrosim::common {

class H5File;

/// The stage whose scene block lists an effect.
enum class EffectStage { kMusculoskeletal, kSurface, kBiphasic, kShockwave };

struct EffectInfo {
  std::string_view name;         ///< as written in a scene, e.g. "foundation_springs"
  EffectStage stage;             ///< which stage builds it
  std::string_view description;  ///< one line for --help and docs
};

/// Every known effect, in documentation order (the list in effects.cc, then
/// what register_effect added).
const std::vector<EffectInfo>& known_effects();
/// Adds an effect a stage registered (e.g. a surface term,
/// cartilage::register_surface_term) to the vocabulary. A name already known
/// for the same stage is left as it is; a name of another stage is a
/// std::logic_error. Register before the scene schema is first used
/// (pipelines::scene_schema() reads the vocabulary once).
void register_effect(const std::string& name, EffectStage stage, const std::string& description);
/// The entry for `name`, or nullptr when no such effect exists.
const EffectInfo* find_effect(std::string_view name);
/// "musculoskeletal", "surface", "biphasic" or "shockwave".
std::string_view to_string(EffectStage stage);
/// Comma-separated names of the effects of one stage (for error messages).
std::string effect_names(EffectStage stage);

/// One recorded construction of a term.
struct BuiltEffect {
  std::string effect;  ///< a known effect name
  std::string part;    ///< what it was built on, e.g. "femur" (may be empty)
  std::int64_t count;  ///< number of instances built, e.g. springs (>= 0)
};

/// Per-effect total over all parts.
struct EffectTotal {
  std::string effect;
  std::int64_t count;  ///< sum of counts over all records of this effect
  int records;         ///< how many times record() was called for it
};

class EffectLedger {
 public:
  /// `stage` names the recording program in printouts, e.g. "surface:osmotic".
  explicit EffectLedger(std::string stage = {});

  /// Records that `count` instances of `effect` were constructed on `part`.
  /// Throws std::logic_error for an unknown effect name or a negative count.
  void record(std::string_view effect, std::int64_t count, std::string_view part = {});

  /// True when record() was called for `effect` at least once (even with
  /// count 0: the term object exists).
  bool built(std::string_view effect) const;
  /// Total instance count of `effect` (0 when never built).
  std::int64_t count(std::string_view effect) const;
  /// Records in the order they were made.
  const std::vector<BuiltEffect>& records() const { return records_; }
  /// Totals per effect, in order of first construction.
  std::vector<EffectTotal> totals() const;
  /// Names of built effects that are not in `requested` (empty = consistent).
  std::vector<std::string> unrequested(const std::vector<std::string>& requested) const;
  /// Throws std::logic_error naming every built effect not in `requested`.
  /// A stage calls this before writing its output as a last self-check.
  void require_only(const std::vector<std::string>& requested) const;

  const std::string& stage() const { return stage_; }

  /// Human-readable lines, one per record then one per total:
  ///   "effects built by surface:osmotic:"
  ///   "  foundation_springs  femur  3781"
  ///   ...
  std::string to_text() const;

  /// Hands the ledger to a writer in table form so any file format can store
  /// it without this header knowing the format. Arrays are parallel, one entry
  /// per record (not per total). With the HDF5 layer the convention is:
  ///   /effects/built (string, per record), /effects/part (string),
  ///   /effects/count (int64), attribute "stage" on /effects.
  using TableWriter = std::function<void(const std::vector<std::string>& effect,
                                         const std::vector<std::string>& part,
                                         const std::vector<std::int64_t>& count)>;
  void write(const TableWriter& writer) const;

  /// Rebuilds a ledger from the table written by write() (e.g. read back from
  /// an output file in a test). Throws InputError if the arrays differ in
  /// length or hold an unknown effect name; `source` names the file.
  static EffectLedger from_table(std::string stage, const std::vector<std::string>& effect,
                                 const std::vector<std::string>& part,
                                 const std::vector<std::int64_t>& count,
                                 const std::string& source);

 private:
  std::string stage_;
  std::vector<BuiltEffect> records_;
};

/// Writes `ledger` into an output file (replacing an existing /effects):
///   /effects/built  string (n)  effect name per record
///   /effects/part   string (n)  what it was built on ("" when not per part)
///   /effects/count  int (n)     instances built per record
///   attribute "stage" on /effects
/// n may be 0 (a stage that built no term). Every stage writes this.
void write_effect_ledger(H5File& file, const EffectLedger& ledger);
/// Reads what write_effect_ledger wrote; InputError naming the file and the
/// dataset when it is missing or inconsistent.
EffectLedger read_effect_ledger(const H5File& file);

}  // namespace arthrosim::common
