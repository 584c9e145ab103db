#pragma once
// The musculoskeletal (COMAK) stage: its scene block (comak:) and descriptor.
// Method: musculoskeletal/comak.h, docs/comak.md; output: the kinematics
// file (docs/kinematics_file.md).
#include <string>
#include <vector>

#include "common/options.h"
#include "musculoskeletal/comak.h"
#include "musculoskeletal/gait_trial.h"

namespace arthrosim::pipelines {

struct StageDescriptor;

/// The comak block of a scene.
struct ComakStageOptions {
  /// Effects to simulate: muscles (required: they balance the flexion row),
  /// ligaments, and tibiofemoral_contact with patellofemoral_contact (one
  /// contact term: both or neither).
  std::vector<std::string> effects;
  musculoskeletal::ComakOptions solver;
  /// The trial's processing (its low-pass filter).
  musculoskeletal::GaitTrialOptions trial;
  void declare(common::OptionVisitor& v);
};

/// The comak stage's entry in the stage table (pipelines/stages.h).
StageDescriptor comak_stage_descriptor();

}  // namespace arthrosim::pipelines
