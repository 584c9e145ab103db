// The effect vocabulary and the ledger stages record built terms in.
#include "common/effects.h"

#include <gtest/gtest.h>

#include <set>
#include <filesystem>
#include <unistd.h>

#include "common/error.h"
#include "common/hdf5.h"

namespace arthrosim::common {
namespace {

TEST(EffectVocabulary, IsTheScenesVocabulary) {
  std::set<std::string> ms, surface, biphasic, shockwave;
  for (const EffectInfo& e : known_effects()) {
    EXPECT_FALSE(e.description.empty()) << e.name;
    auto& set = e.stage == EffectStage::kMusculoskeletal ? ms
                : e.stage == EffectStage::kSurface       ? surface
                : e.stage == EffectStage::kBiphasic      ? biphasic
                                                         : shockwave;
    EXPECT_TRUE(set.insert(std::string(e.name)).second) << "duplicate " << e.name;
    EXPECT_EQ(find_effect(e.name), &e);
  }
  EXPECT_EQ(ms, (std::set<std::string>{"ligaments", "muscles", "tibiofemoral_contact",
                                       "patellofemoral_contact"}));
  EXPECT_EQ(surface, (std::set<std::string>{"foundation_springs", "foundation_damping",
                                            "osmotic_pressure", "periphery_fixed",
                                            "imposed_kinematics", "inertia", "mesh_contact",
                                            "fixed_nodes", "point_loads", "pressure",
                                            "prescribed_displacement"}));
  EXPECT_EQ(biphasic, (std::set<std::string>{"biphasic_layers", "penetration_contact"}));
  EXPECT_EQ(shockwave, (std::set<std::string>{"mca_elastic", "pore_fluid", "filtration", "applicator_pulse",
                                              "platen_compression"}));
  EXPECT_EQ(find_effect("foundation_spring"), nullptr);
  EXPECT_EQ(effect_names(EffectStage::kMusculoskeletal),
            "ligaments, muscles, tibiofemoral_contact, patellofemoral_contact");
}

TEST(EffectLedger, RecordsWhatWasBuiltAndCountsIt) {
  EffectLedger ledger("surface:osmotic");
  EXPECT_FALSE(ledger.built("foundation_springs"));
  ledger.record("foundation_springs", 3781, "femur");
  ledger.record("osmotic_pressure", 3616, "femur");
  ledger.record("foundation_springs", 600, "tibia_medial");
  ledger.record("inertia", 0);  // built, with no countable instances
  EXPECT_TRUE(ledger.built("foundation_springs"));
  EXPECT_TRUE(ledger.built("inertia"));
  EXPECT_FALSE(ledger.built("mesh_contact"));
  EXPECT_EQ(ledger.count("foundation_springs"), 4381);
  EXPECT_EQ(ledger.count("mesh_contact"), 0);
  ASSERT_EQ(ledger.records().size(), 4u);
  const std::vector<EffectTotal> t = ledger.totals();
  ASSERT_EQ(t.size(), 3u);
  EXPECT_EQ(t[0].effect, "foundation_springs");
  EXPECT_EQ(t[0].count, 4381);
  EXPECT_EQ(t[0].records, 2);
  EXPECT_EQ(t[1].effect, "osmotic_pressure");
  EXPECT_EQ(t[2].effect, "inertia");
  EXPECT_EQ(ledger.to_text(),
            "effects built by surface:osmotic:\n"
            "  foundation_springs: 4381 (femur 3781, tibia_medial 600)\n"
            "  osmotic_pressure: 3616 (femur 3616)\n"
            "  inertia: 0\n");
  EXPECT_EQ(EffectLedger("comak").to_text(), "effects built by comak: none\n");
}

TEST(EffectLedger, UnrequestedTermsAreNamed) {
  EffectLedger ledger("surface:gait");
  ledger.record("foundation_springs", 10);
  ledger.record("osmotic_pressure", 4);
  ledger.record("mesh_contact", 1);
  const std::vector<std::string> asked = {"foundation_springs", "mesh_contact", "inertia"};
  EXPECT_EQ(ledger.unrequested(asked), (std::vector<std::string>{"osmotic_pressure"}));
  try {
    ledger.require_only(asked);
    ADD_FAILURE() << "require_only accepted an unrequested term";
  } catch (const std::logic_error& e) {
    EXPECT_STREQ(e.what(),
                 "stage surface:gait built effect(s) the scene did not ask for: osmotic_pressure");
  }
  EXPECT_NO_THROW(ledger.require_only({"foundation_springs", "mesh_contact", "osmotic_pressure"}));
}

TEST(EffectLedger, RejectsUnknownNamesAndNegativeCounts) {
  EffectLedger ledger("x");
  EXPECT_THROW(ledger.record("foundation_spring", 1), std::logic_error);
  EXPECT_THROW(ledger.record("muscles", -1), std::logic_error);
  EXPECT_TRUE(ledger.records().empty());
}

TEST(EffectLedger, TableRoundTrip) {
  EffectLedger ledger("comak");
  ledger.record("ligaments", 76);
  ledger.record("muscles", 13);
  ledger.record("tibiofemoral_contact", 8602, "tibia");
  std::vector<std::string> e, p;
  std::vector<std::int64_t> c;
  ledger.write([&](const std::vector<std::string>& effect, const std::vector<std::string>& part,
                   const std::vector<std::int64_t>& count) {
    e = effect;
    p = part;
    c = count;
  });
  EXPECT_EQ(e, (std::vector<std::string>{"ligaments", "muscles", "tibiofemoral_contact"}));
  EXPECT_EQ(p, (std::vector<std::string>{"", "", "tibia"}));
  EXPECT_EQ(c, (std::vector<std::int64_t>{76, 13, 8602}));
  const EffectLedger back = EffectLedger::from_table("comak", e, p, c, "k.h5");
  EXPECT_EQ(back.to_text(), ledger.to_text());

  try {
    EffectLedger::from_table("comak", {"ligaments", "bogus"}, {"", ""}, {1, 2}, "k.h5");
    ADD_FAILURE();
  } catch (const InputError& err) {
    EXPECT_STREQ(err.what(), "k.h5: error: effect ledger: expected a known effect name, found "
                             "'bogus'");
  }
  EXPECT_THROW(EffectLedger::from_table("comak", {"ligaments"}, {}, {1}, "k.h5"), InputError);
  EXPECT_THROW(EffectLedger::from_table("comak", {"ligaments"}, {""}, {-4}, "k.h5"), InputError);
}

TEST(EffectLedger, Hdf5RoundTrip) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("arthrosim_effects_test_" + std::to_string(getpid()) + ".h5"))
                               .string();
  EffectLedger ledger("surface:gait");
  ledger.record("foundation_springs", 3781, "femur");
  ledger.record("mesh_contact", 2, "femur-tibia_medial");
  {
    H5File f(path, H5File::Mode::kTruncate);
    write_effect_ledger(f, EffectLedger("old"));  // replaced below, not appended to
    write_effect_ledger(f, ledger);
  }
  {
    H5File f(path, H5File::Mode::kRead);
    EXPECT_EQ(f.read_strings("/effects/built"),
              (std::vector<std::string>{"foundation_springs", "mesh_contact"}));
    const EffectLedger back = read_effect_ledger(f);
    EXPECT_EQ(back.stage(), "surface:gait");
    EXPECT_EQ(back.to_text(), ledger.to_text());
    EXPECT_FALSE(back.built("osmotic_pressure"));
  }
  {
    H5File f(path, H5File::Mode::kTruncate);
    write_effect_ledger(f, EffectLedger("post"));  // nothing built is recorded too
  }
  {
    H5File f(path, H5File::Mode::kRead);
    EXPECT_TRUE(read_effect_ledger(f).records().empty());
  }
  {
    H5File f(path, H5File::Mode::kTruncate);  // no ledger at all
    f.write("/x", std::vector<int>{1});
  }
  {
    H5File f(path, H5File::Mode::kRead);
    try {
      read_effect_ledger(f);
      ADD_FAILURE() << "missing ledger accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("/effects/built"), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace arthrosim::common
