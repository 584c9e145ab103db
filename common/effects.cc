#include "common/effects.h"

#include <algorithm>
#include <deque>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "common/error.h"
#include "common/hdf5.h"

namespace arthrosim::common {

namespace {

std::vector<EffectInfo>& vocabulary() {
  // The one list of effect names. Descriptions follow issues 3-6 and seed
  // 002_3ffcc11eb7a447d9.txt ("Deformable Cartilage Model", "Contact Methods").
  static std::vector<EffectInfo> kEffects = {
      {"ligaments", EffectStage::kMusculoskeletal,
       "Blankevoort (1991) ligament bundles acting on tibia and patella"},
      {"muscles", EffectStage::kMusculoskeletal,
       "knee-crossing muscles, force = activation x F_max along the path"},
      {"tibiofemoral_contact", EffectStage::kMusculoskeletal,
       "elastic-foundation contact between femoral and tibial cartilage"},
      {"patellofemoral_contact", EffectStage::kMusculoskeletal,
       "elastic-foundation contact between femoral and patellar cartilage"},
      {"foundation_springs", EffectStage::kSurface,
       "compressive spring from each shell node to the underlying bone"},
      {"foundation_damping", EffectStage::kSurface, "the dampers matching the foundation springs"},
      {"osmotic_pressure", EffectStage::kSurface,
       "constant follower pressure on the internal face of the shells"},
      {"periphery_fixed", EffectStage::kSurface,
       "boundary nodes of each cartilage surface constrained to their bone"},
      {"imposed_kinematics", EffectStage::kSurface,
       "bone poses from the musculoskeletal stage's kinematics file"},
      {"inertia", EffectStage::kSurface, "mass terms (without it the run is quasi-static)"},
      {"mesh_contact", EffectStage::kSurface,
       "penalty contact between deformable cartilage surfaces"},
      {"fixed_nodes", EffectStage::kSurface,
       "generic mesh: the nodes in fixed_box_mm clamped (positions and directors)"},
      {"point_loads", EffectStage::kSurface,
       "generic mesh: point_load_n shared by the nodes in load_box_mm"},
      {"pressure", EffectStage::kSurface, "generic mesh: pressure_mpa on the mid-surface (follower load)"},
      {"prescribed_displacement", EffectStage::kSurface,
       "generic mesh: the nodes in displaced_box_mm moved by displacement_mm"},
      {"biphasic_layers", EffectStage::kBiphasic,
       "cartilage layers as linear biphasic (u-p) volumes on their bones (docs/biphasic.md)"},
      {"penetration_contact", EffectStage::kBiphasic,
       "the penetration method's contact conditions from the overlap and stage 1's contact force"},
      {"mca_elastic", EffectStage::kShockwave,
       "movable cellular automata: linear-elastic pair law with the many-body term (A1-A8)"},
      {"pore_fluid", EffectStage::kShockwave, "Biot pore fluid of the poroelastic tissues (A9-A10)"},
      {"filtration", EffectStage::kShockwave, "Darcy filtration of the pore fluid between automata (A11-A12)"},
      {"applicator_pulse", EffectStage::kShockwave,
       "the shockwave pulse through the copper applicator, scaled to each EFD (eqs. 1-2)"},
      {"platen_compression", EffectStage::kShockwave,
       "slow compression of the knee between its cut faces (convergence, validation)"},
  };
  return kEffects;
}

}  // namespace

const std::vector<EffectInfo>& known_effects() { return vocabulary(); }

void register_effect(const std::string& name, EffectStage stage, const std::string& description) {
  if (const EffectInfo* e = find_effect(name)) {
    if (e->stage == stage) return;
    throw std::logic_error("register_effect: '" + name + "' is already an effect of the " +
                           std::string(to_string(e->stage)) + " stage");
  }
  // The names and descriptions live as long as the program (the vocabulary
  // holds string_views).
  static std::deque<std::string> storage;
  storage.push_back(name);
  const std::string_view n = storage.back();
  storage.push_back(description);
  vocabulary().push_back({n, stage, storage.back()});
}

const EffectInfo* find_effect(std::string_view name) {
  for (const EffectInfo& e : known_effects()) {
    if (e.name == name) return &e;
  }
  return nullptr;
}

std::string_view to_string(EffectStage stage) {
  switch (stage) {
    case EffectStage::kMusculoskeletal: return "musculoskeletal";
    case EffectStage::kSurface: return "surface";
    case EffectStage::kBiphasic: return "biphasic";
    case EffectStage::kShockwave: return "shockwave";
  }
  return "";
}

std::string effect_names(EffectStage stage) {
  std::string s;
  for (const EffectInfo& e : known_effects()) {
    if (e.stage != stage) continue;
    if (!s.empty()) s += ", ";
    s += e.name;
  }
  return s;
}

EffectLedger::EffectLedger(std::string stage) : stage_(std::move(stage)) {}

void EffectLedger::record(std::string_view effect, std::int64_t count, std::string_view part) {
  if (find_effect(effect) == nullptr) {
    throw std::logic_error("EffectLedger::record: unknown effect '" + std::string(effect) +
                           "' (add it to known_effects() in common/effects.cc)");
  }
  if (count < 0) {
    throw std::logic_error("EffectLedger::record: negative count " + std::to_string(count) +
                           " for effect '" + std::string(effect) + "'");
  }
  records_.push_back({std::string(effect), std::string(part), count});
}

bool EffectLedger::built(std::string_view effect) const {
  return std::any_of(records_.begin(), records_.end(),
                     [&](const BuiltEffect& r) { return r.effect == effect; });
}

std::int64_t EffectLedger::count(std::string_view effect) const {
  std::int64_t n = 0;
  for (const BuiltEffect& r : records_) {
    if (r.effect == effect) n += r.count;
  }
  return n;
}

std::vector<EffectTotal> EffectLedger::totals() const {
  std::vector<EffectTotal> out;
  for (const BuiltEffect& r : records_) {
    auto it = std::find_if(out.begin(), out.end(),
                           [&](const EffectTotal& t) { return t.effect == r.effect; });
    if (it == out.end()) {
      out.push_back({r.effect, r.count, 1});
    } else {
      it->count += r.count;
      ++it->records;
    }
  }
  return out;
}

std::vector<std::string> EffectLedger::unrequested(
    const std::vector<std::string>& requested) const {
  std::vector<std::string> out;
  for (const EffectTotal& t : totals()) {
    if (std::find(requested.begin(), requested.end(), t.effect) == requested.end()) {
      out.push_back(t.effect);
    }
  }
  return out;
}

void EffectLedger::require_only(const std::vector<std::string>& requested) const {
  const std::vector<std::string> extra = unrequested(requested);
  if (extra.empty()) return;
  std::string names;
  for (const std::string& e : extra) names += (names.empty() ? "" : ", ") + e;
  throw std::logic_error("stage " + stage_ + " built effect(s) the scene did not ask for: " +
                         names);
}

std::string EffectLedger::to_text() const {
  std::ostringstream s;
  s << "effects built" << (stage_.empty() ? "" : " by " + stage_) << ":";
  if (records_.empty()) {
    s << " none\n";
    return s.str();
  }
  s << "\n";
  for (const EffectTotal& t : totals()) {
    s << "  " << t.effect << ": " << t.count;
    std::string parts;
    for (const BuiltEffect& r : records_) {
      if (r.effect != t.effect || r.part.empty()) continue;
      parts += (parts.empty() ? "" : ", ") + r.part + " " + std::to_string(r.count);
    }
    if (!parts.empty()) s << " (" << parts << ")";
    s << "\n";
  }
  return s.str();
}

void EffectLedger::write(const TableWriter& writer) const {
  std::vector<std::string> effect, part;
  std::vector<std::int64_t> count;
  for (const BuiltEffect& r : records_) {
    effect.push_back(r.effect);
    part.push_back(r.part);
    count.push_back(r.count);
  }
  writer(effect, part, count);
}

EffectLedger EffectLedger::from_table(std::string stage, const std::vector<std::string>& effect,
                                      const std::vector<std::string>& part,
                                      const std::vector<std::int64_t>& count,
                                      const std::string& source) {
  if (effect.size() != part.size() || effect.size() != count.size()) {
    throw InputError(source, 0,
                     "effect ledger: expected /effects/built, /effects/part and /effects/count "
                     "of equal length, found " +
                         std::to_string(effect.size()) + ", " + std::to_string(part.size()) +
                         " and " + std::to_string(count.size()));
  }
  EffectLedger ledger(std::move(stage));
  for (std::size_t i = 0; i < effect.size(); ++i) {
    if (find_effect(effect[i]) == nullptr) {
      throw InputError(source, 0,
                       "effect ledger: expected a known effect name, found '" + effect[i] + "'");
    }
    if (count[i] < 0) {
      throw InputError(source, 0,
                       "effect ledger: expected a count >= 0, found " + std::to_string(count[i]));
    }
    ledger.records_.push_back({effect[i], part[i], count[i]});
  }
  return ledger;
}

void write_effect_ledger(H5File& file, const EffectLedger& ledger) {
  if (file.exists("/effects")) file.remove("/effects");
  file.create_group("/effects");
  ledger.write([&](const std::vector<std::string>& effect, const std::vector<std::string>& part,
                   const std::vector<std::int64_t>& count) {
    std::vector<int> count32;
    for (std::int64_t c : count) {
      if (c > std::numeric_limits<int>::max()) {
        throw std::logic_error("write_effect_ledger: count " + std::to_string(c) +
                               " does not fit the int dataset /effects/count");
      }
      count32.push_back(static_cast<int>(c));
    }
    file.write("/effects/built", effect);
    file.write("/effects/part", part);
    file.write("/effects/count", count32);
  });
  file.set_attribute("/effects", "stage", ledger.stage());
}

EffectLedger read_effect_ledger(const H5File& file) {
  const std::vector<std::string> effect = file.read_strings("/effects/built");
  const std::vector<std::string> part = file.read_strings("/effects/part");
  const Eigen::VectorXi count32 = file.read_vector_int("/effects/count");
  std::vector<std::int64_t> count(count32.data(), count32.data() + count32.size());
  return EffectLedger::from_table(file.attribute_string("/effects", "stage"), effect, part, count,
                                  file.path() + ": /effects");
}

}  // namespace arthrosim::common
