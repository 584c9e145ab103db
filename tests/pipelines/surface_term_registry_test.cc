// A surface term added from this file alone (issue 29: a term is its file and
// one registration): a toy uniform load, registered by name at static
// initialisation, becomes an effect of the scene vocabulary, is built only
// when a scenario lists it, and is recorded in the run's ledger. No library
// source knows it.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "cartilage/surface_terms.h"
#include "common/effects.h"
#include "common/hdf5.h"
#include "common/metadata.h"
#include "pipelines/prepare.h"
#include "pipelines/stages.h"
#include "pipelines/surface_stage.h"

namespace arthrosim {
namespace {

namespace fs = std::filesystem;

// The toy term: a force f along world -y (towards the tibial bone) on every
// node; external, so it enters the residual F = f_int - f_ext as +f in y.
// Its tangent is zero.
class ToyUniformLoad : public cartilage::ShellTerm {
 public:
  ToyUniformLoad(int nodes, double f_N) : ShellTerm("toy_uniform_load"), nodes_(nodes), f_(f_N) {}
  void add(const cartilage::TermContext&, Eigen::VectorXd& F, cartilage::TangentAssembler*) const override {
    for (int i = 0; i < nodes_; ++i) F[6 * i + 1] += f_;
  }

 private:
  int nodes_;
  double f_;
};

constexpr double kToyForceN = 0.01;

const bool kToyRegistered = cartilage::register_surface_term(
    {"toy_uniform_load", "test: a uniform force along world -y on every node", {},
     [](const cartilage::SurfaceTermContext& c) {
       c.model.register_term(std::make_unique<ToyUniformLoad>(c.model.num_nodes(), kToyForceN), c.model.num_nodes());
     }});

fs::path work_dir() {
  const fs::path d = fs::path(ARTHROSIM_BINARY_DIR) / "tests" / "surface_term_registry";
  fs::create_directories(d);
  return d;
}

std::string prepared() {
  static const std::string path = [] {
    const std::string p = (work_dir() / "prepared_coarse.h5").string();
    pipelines::PrepareOptions o;
    const pipelines::PreparedModel m = pipelines::prepare_model(
        pipelines::find_model_files(std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/coarse"), o);
    common::RunMetadata md;
    md.program = "surface_term_registry_test";
    pipelines::write_prepared_model(m, o, md, p);
    return p;
  }();
  return path;
}

// Runs a 1 ms quasi-static scenario on the coarse tibial plates with `effects`.
pipelines::SurfaceStageResult run(const std::string& name, const std::string& effects, common::EffectLedger* ledger) {
  const fs::path scene = work_dir() / (name + ".yaml");
  std::ofstream(scene) << "model: " << ARTHROSIM_SOURCE_DIR << "/data/models/knee_parametric/coarse\n"
                       << "outputs: [surface]\nsurface:\n  scenarios:\n    " << name
                       << ":\n      surfaces: [tibia_medial, tibia_lateral]\n      end_time_s: 1e-3\n"
                       << "      time_step_s: 5e-4\n      output_interval_ms: 0.5\n      effects: " << effects
                       << "\n";
  pipelines::SurfaceStageOptions o;
  o.prepared = prepared();
  o.scene = scene.string();
  o.scenario = name;
  o.out = (work_dir() / (name + ".h5")).string();
  o.progress = false;
  o.argv = {"surface_term_registry_test"};
  const pipelines::SurfaceStageResult r = pipelines::run_surface_stage(o);
  *ledger = common::read_effect_ledger(common::H5File(o.out, common::H5File::Mode::kRead));
  return r;
}

TEST(SurfaceTermRegistry, ToyTermFromATestFileIsAnEffectBuiltOnlyWhenListed) {
  ASSERT_TRUE(kToyRegistered);
  // In the vocabulary, for the surface stage (the scene schema's effects).
  const common::EffectInfo* e = common::find_effect("toy_uniform_load");
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->stage, common::EffectStage::kSurface);
  bool in_schema = false;
  for (const common::EffectName& n : pipelines::scene_schema().effects)
    in_schema = in_schema || (n.name == "toy_uniform_load" && n.stage == "surface");
  EXPECT_TRUE(in_schema);

  // Listed: built on each surface (count = its nodes) and it moves the plates.
  common::EffectLedger with, without;
  const pipelines::SurfaceStageResult a = run("toy", "[foundation_springs, periphery_fixed, toy_uniform_load]", &with);
  ASSERT_EQ(a.status, pipelines::SurfaceStageStatus::kCompleted);
  EXPECT_TRUE(with.built("toy_uniform_load"));
  EXPECT_GT(with.count("toy_uniform_load"), 0);
  double moved = 0;
  for (const auto& s : a.surfaces) moved = std::max(moved, std::abs(s.max_deflection_m));
  EXPECT_GT(moved, 1e-9) << "10 mN per node on 20 N/mm^3 springs: about 5e-8 m";

  // Not listed: never built, and nothing moves.
  const pipelines::SurfaceStageResult b = run("no_toy", "[foundation_springs, periphery_fixed]", &without);
  ASSERT_EQ(b.status, pipelines::SurfaceStageStatus::kCompleted);
  EXPECT_FALSE(without.built("toy_uniform_load"));
  for (const auto& s : b.surfaces) EXPECT_LT(std::abs(s.max_deflection_m), 1e-12) << s.name;
}

}  // namespace
}  // namespace arthrosim
