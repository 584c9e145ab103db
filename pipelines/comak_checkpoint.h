#pragma once
// The COMAK stage's checkpoint (docs/testing.md, "Checkpoint and resume";
// docs/comak.md, "Checkpoints"): `<out>.checkpoint`, an HDF5 file holding
// everything a run needs to continue bit-identically after its first
// frames_done frames:
//   - the run state (musculoskeletal::ComakRunState: the next frame's start
//     point and activations, the dampers' previous pose and time, Ipopt's
//     multipliers of the last converged frame for the warm start, the run
//     summary so far with the first frame's passive settle);
//   - every frame done, as the writer needs it again (its result and the
//     dampers' previous pose it was solved with): the resumed run writes a
//     fresh kinematics file and appends these frames first (each evaluated
//     once more at its stored solution), so no partial HDF5 file of a killed
//     process is ever reopened;
//   - the identity of the run (common::run_identity) and its frame count.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "musculoskeletal/comak.h"

namespace arthrosim::pipelines {

/// One frame done: what KinematicsFileWriter::append reads of it.
struct ComakFrameRecord {
  musculoskeletal::ComakFrameResult result;  ///< without multipliers (the state holds the warm start)
  Eigen::VectorXd q_previous;                ///< the frame's ComakFrameInput::q_previous
  double dt_previous = 0.0;                  ///< and dt_previous
};

struct ComakCheckpoint {
  std::string identity;
  std::int64_t frames_total = 0;  ///< frames of the run
  musculoskeletal::ComakRunState state;
  std::vector<ComakFrameRecord> frames;  ///< state.frames_done of them
};

/// Writes `c` to `path` through common::AtomicOutput (path.partial, then a
/// rename). `sequence` (1, 2, ...: the checkpoints of this process) is for the
/// kill tests' hook (common::checkpoint_test_kill).
void write_comak_checkpoint(const std::filesystem::path& path, const ComakCheckpoint& c, int sequence);

/// The checkpoint at `path`, or nullopt with `why` when it cannot be read as
/// one (another format or version, a missing dataset, inconsistent counts).
std::optional<ComakCheckpoint> read_comak_checkpoint(const std::filesystem::path& path, std::string& why);

}  // namespace arthrosim::pipelines
