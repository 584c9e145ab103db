#include "pipelines/comak_stage.h"

#include "common/effects.h"
#include "pipelines/stages.h"

namespace arthrosim::pipelines {

void ComakStageOptions::declare(common::OptionVisitor& v) {
  using common::Unit;
  v.effect_list("effects", effects, "musculoskeletal", "musculoskeletal effects to simulate").required();
  solver.declare(v);
  v.number("lowpass_cutoff_hz", trial.lowpass.cutoff_hz, Unit::kHertz, {0.1, 1000},
           "low-pass filter of trial kinematics and ground reactions");
}

StageDescriptor comak_stage_descriptor() {
  StageDescriptor d;
  d.name = "comak";
  d.executable = "arthrosim-comak";
  d.summary = "per frame of the trial, Ipopt on muscle activations and the 11 secondary knee coordinates";
  d.block = block_schema<ComakStageOptions>("comak", "effects and options of the musculoskeletal (COMAK) stage");
  d.outputs = {"kinematics"};
  for (const common::EffectInfo& e : common::known_effects())
    if (e.stage == common::EffectStage::kMusculoskeletal)
      d.effects.push_back({std::string(e.name), "musculoskeletal", std::string(e.description)});
  return d;
}

}  // namespace arthrosim::pipelines
