// The generic scene reader and self-declaring options (common/options.h,
// common/scene.h) on a toy schema that knows no stage: declarations give the
// schema and its defaults, the reader fills a struct bit for bit, instances
// inherit and override block keys, and errors carry line, column and a hint.
#include "common/scene.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "common/edit_distance.h"
#include "common/error.h"
#include "common/options.h"

namespace arthrosim::common {
namespace {

enum class Mode { kFast, kExact };

// A block of a made-up stage.
struct ToyOptions {
  double length_m = 0.001 * units::mm;  // not exactly 1e-6: written as 0.001 mm
  std::optional<double> end_s;
  int iterations = 5;
  bool verbose = false;
  Mode mode = Mode::kExact;
  std::vector<std::string> parts{"a", "b"};
  std::map<std::string, double> per_part_m;
  std::vector<double> box_m;
  std::vector<std::string> effects;
  void declare_shared(OptionVisitor& v) {
    v.number("length_mm", length_m, Unit::kMillimetre, {0, 10}, "a length");
    v.number("end_s", end_s, Unit::kSecond, {0, 100}, "an optional time");
    v.integer("iterations", iterations, {1, 10}, "a count");
    v.flag("verbose", verbose, "a flag");
    v.choice("mode", mode, {{"fast", Mode::kFast}, {"exact", Mode::kExact}}, "an enum");
    v.text_list("parts", parts, "a|b|c", "words from a list");
    v.named_numbers("per_part_mm", per_part_m, Unit::kMillimetre, {0.5, 5}, "a number per name");
  }
  void declare_instance(OptionVisitor& v) {
    v.number_list("box_mm", box_m, Unit::kMillimetre, {2, 2}, "two numbers");
    v.effect_list("effects", effects, "toy", "effects of the toy stage").required();
  }
  void declare(OptionVisitor& v) {
    declare_shared(v);
    declare_instance(v);
  }
};

SceneSchema toy_schema() {
  SceneSchema s;
  OptionSpec outputs;
  s.top = collect_keys("scene", [](OptionVisitor& v) {
    static std::vector<std::string> outputs;
    v.text_list("outputs", outputs, "x|y", "what to produce").required();
  });
  BlockSchema b;
  b.name = "toy";
  b.doc = "the toy stage";
  ToyOptions shared, own;
  b.keys = collect_keys("toy", [&](OptionVisitor& v) { shared.declare_shared(v); });
  for (OptionSpec& k : b.keys) k.overridable = true;
  b.instances_key = "runs";
  b.instances_doc = "named runs";
  b.instance_label = "run";
  b.instance_keys = collect_keys("run", [&](OptionVisitor& v) { own.declare_instance(v); });
  s.blocks.push_back(b);
  s.effects = {{"spring", "toy", "a spring"}, {"damper", "toy", "a damper"}, {"muscle", "other", "elsewhere"}};
  return s;
}

const SceneSchema& schema() {
  static const SceneSchema s = toy_schema();
  return s;
}

Scene parse(const std::string& text) { return parse_scene(text, "/nowhere/toy.yaml", schema()); }

void expect_error(const std::string& text, int line, int column, const std::string& fragment) {
  try {
    parse(text);
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), line) << e.what();
    EXPECT_EQ(e.column(), column) << e.what();
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(Options, DeclarationsGiveTheSchemaWithDefaultsAsWritten) {
  const BlockSchema& b = *schema().block("toy");
  ASSERT_EQ(b.keys.size(), 7u);
  EXPECT_EQ(b.keys[0].key, "length_mm");
  EXPECT_EQ(b.keys[0].default_value, "0.001");
  EXPECT_EQ(b.keys[0].unit, Unit::kMillimetre);
  EXPECT_EQ(b.keys[0].min, 0);
  EXPECT_EQ(b.keys[0].max, 10);
  EXPECT_EQ(b.keys[1].default_value, "");  // optional: no default
  EXPECT_EQ(b.keys[2].default_value, "5");
  EXPECT_EQ(b.keys[3].default_value, "false");
  EXPECT_EQ(b.keys[4].default_value, "exact");
  EXPECT_EQ(b.keys[4].choices, "fast|exact");
  EXPECT_EQ(b.keys[5].default_value, "[a, b]");
  EXPECT_EQ(b.keys[6].default_value, "[]");
  EXPECT_TRUE(b.instance_keys[1].required);
  EXPECT_EQ(b.instance_keys[1].effect_stage, "toy");
  // A key declared twice is a programming error.
  EXPECT_THROW(collect_keys("x",
                            [](OptionVisitor& v) {
                              bool f = false;
                              v.flag("k", f, "");
                              v.flag("k", f, "");
                            }),
               std::logic_error);
}

TEST(Options, WrittenValueRoundTripsThroughTheReaderExactly) {
  // The reader computes strtod(text) * factor; the printed default must give
  // back the very same double.
  for (double written : {0.001, 3.0, 0.7, 1e-11, 20.0, 0.2, 2.5}) {
    for (Unit u : {Unit::kMillimetre, Unit::kNewtonPerCubicMillimetre, Unit::kMegapascal, Unit::kDegree}) {
      const double si = written * unit_to_si(u);
      const std::string text = written_value(si, u);
      EXPECT_EQ(std::strtod(text.c_str(), nullptr) * unit_to_si(u), si) << written << " " << text;
    }
  }
  EXPECT_EQ(written_value(3 * units::mm, Unit::kMillimetre), "3");
}

TEST(Scene, ReaderFillsTheStructBitForBitAndInstancesInherit) {
  const Scene s = parse(R"(outputs: [x]
toy:
  iterations: 7
  per_part_mm: [a=1.5, c=2]
  runs:
    one: {effects: [spring], box_mm: [1, 2]}
    two:
      iterations: 9
      mode: fast
      effects: [spring, damper]
)");
  ASSERT_EQ(s.instances("toy").size(), 2u);
  const BlockInstance& one = s.instances("toy")[0];
  const BlockInstance& two = s.instances("toy")[1];
  EXPECT_EQ(one.line, 6);
  EXPECT_EQ(one.column, 5);
  const ToyOptions a = read_options<ToyOptions>(one.options);
  const ToyOptions b = read_options<ToyOptions>(two.options);
  const ToyOptions defaults;
  EXPECT_EQ(a.length_m, defaults.length_m);  // the default, through the reader: same bits
  EXPECT_FALSE(a.end_s.has_value());
  EXPECT_EQ(a.iterations, 7);  // from the block
  EXPECT_EQ(b.iterations, 9);  // the instance's own
  EXPECT_EQ(a.mode, Mode::kExact);
  EXPECT_EQ(b.mode, Mode::kFast);
  EXPECT_EQ(a.per_part_m, (std::map<std::string, double>{{"a", 1.5e-3}, {"c", 2e-3}}));
  EXPECT_EQ(a.box_m, (std::vector<double>{1e-3, 2e-3}));
  EXPECT_TRUE(b.box_m.empty());
  EXPECT_EQ(b.effects, (std::vector<std::string>{"spring", "damper"}));
  EXPECT_TRUE(two.wants("damper"));
  EXPECT_EQ(one.options.value("per_part_mm").canonical, "[a=1.5, c=2]");
  EXPECT_EQ(two.options.name(), "toy.two");
  EXPECT_TRUE(s.has_block("toy"));
  // A block that is not written has its defaults.
  const Scene empty = parse("outputs: [y]\n");
  EXPECT_FALSE(empty.has_block("toy"));
  EXPECT_EQ(read_options<ToyOptions>(empty.block("toy")).iterations, 5);
  EXPECT_TRUE(empty.instances("toy").empty());
}

TEST(Scene, ErrorsNameLineColumnAndTheNearestKey) {
  expect_error("outputs: [x]\ntoy:\n  iteratons: 3\n  runs: {r: {effects: [spring]}}\n", 3, 3,
               "unknown key 'iteratons' in 'toy' (did you mean 'iterations'?)");
  expect_error("outputs: [x]\ntoy:\n  runs: {r: {effects: [sprung]}}\n", 3, 24,
               "unknown effect 'sprung' (did you mean 'spring'?); the toy stage knows: spring, damper");
  expect_error("outputs: [x]\ntoy:\n  runs: {r: {effects: [muscle]}}\n", 3, 24,
               "effect 'muscle' belongs to the other stage, not the toy stage");
  expect_error("outputs: [x]\ntoy:\n  runs: {r: {effects: [spring], box_mm: [1]}}\n", 3, 41,
               "'box_mm': expected 2 numbers, found 1");
  expect_error("outputs: [x]\ntoy:\n  per_part_mm: [a=9]\n  runs: {r: {effects: [spring]}}\n", 3, 17,
               "expected a value in [0.5, 5] mm, found 9");
  expect_error("outputs: [x]\ntoy:\n  per_part_mm: [a]\n  runs: {r: {effects: [spring]}}\n", 3, 17,
               "expected items 'name=value', found 'a'");
  expect_error("outputs: [x]\ntoy:\n  mode: exakt\n  runs: {r: {effects: [spring]}}\n", 3, 9,
               "expected one of fast, exact, found 'exakt' (did you mean 'exact'?)");
  expect_error("outputs: [x]\ntoy:\n  runs: {r: {}}\n", 3, 13, "missing required key 'effects' in 'toy.runs.r'");
  expect_error("outputs: [x]\ntoy: {iterations: 2}\n", 2, 6, "missing required key 'runs' in 'toy'");
  expect_error("outputs: [z]\n", 1, 11, "'outputs': unknown item 'z' (did you mean 'x'?); expected any of x, y");
}

TEST(EditDistance, CountsEditsAndSuggestsOnlyCloseWords) {
  EXPECT_EQ(edit_distance("kitten", "sitting"), 3u);
  EXPECT_EQ(edit_distance("", "abc"), 3u);
  EXPECT_EQ(edit_distance("same", "same"), 0u);
  EXPECT_EQ(closest_match("foundation_spring", std::vector<std::string>{"inertia", "foundation_springs"}),
            "foundation_springs");
  EXPECT_EQ(closest_match("xyz", std::vector<std::string>{"inertia"}), "");
  EXPECT_EQ(did_you_mean("inertai", {"inertia"}), " (did you mean 'inertia'?)");
}

}  // namespace
}  // namespace arthrosim::common
