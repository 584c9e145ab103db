#pragma once
// The biphasic stage's checkpoint (docs/testing.md, "Checkpoint and resume";
// docs/biphasic.md, "Checkpoints"): `<out>.checkpoint`, an HDF5 file (frame
// and identity: common/checkpoint.h) holding everything a run needs to
// continue bit-identically after its first steps_done time steps:
//   - each layer's integrator state (biphasic::TrapezoidalState: u, v, p and
//     the last step's loads, time, step count, solve counters); the
//     factorisation is not saved: the resumed process factorises the same
//     matrix again, which gives the same factors (the resume test's
//     bit-identical output after the resumed steps checks this);
//   - each layer's displacement and pressure after every step done: the
//     resumed run writes a fresh output and first reports these steps again
//     (their fields and indicators evaluated from them, the stage's peaks,
//     key steps and means accumulated as in the first run), so no partial
//     HDF5 file of a killed process is reopened.
// The file grows with the steps done (steps x unknowns doubles per layer).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "biphasic/trapezoidal.h"

namespace arthrosim::pipelines {

struct BiphasicCheckpoint {
  std::string identity;
  int steps_done = 0;
  std::vector<biphasic::TrapezoidalState> layers;          ///< after step steps_done
  std::vector<std::vector<Eigen::VectorXd>> u_history;     ///< [layer][step - 1]: u after each step done
  std::vector<std::vector<Eigen::VectorXd>> p_history;     ///< [layer][step - 1]: p after each step done
};

/// Writes `c` to `path` (common::write_checkpoint: atomic, the kill tests' hook).
void write_biphasic_checkpoint(const std::filesystem::path& path, const BiphasicCheckpoint& c, int sequence);

/// The checkpoint at `path`, or nullopt with `why` when it cannot be read as one.
std::optional<BiphasicCheckpoint> read_biphasic_checkpoint(const std::filesystem::path& path, std::string& why);

}  // namespace arthrosim::pipelines
