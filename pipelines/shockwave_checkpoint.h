#pragma once
// The shockwave stage's checkpoint (docs/testing.md, "Checkpoint and resume";
// docs/shockwave.md, "Checkpoints"): `<out>.checkpoint` next to the output
// stem (`shockwave.checkpoint` for `--out shockwave`), an HDF5 file (frame
// and identity: common/checkpoint.h) holding everything a rerun of the same
// command needs to end with the same bytes:
//   - each run of the stage already finished (one per EFD): its results as
//     the summary reports them and the SHA-256 of its HDF5 file, so the rerun
//     takes them instead of simulating the run again (a finished run whose
//     file is missing or changed is simulated again);
//   - the run in progress, if any: the automata's state
//     (shockwave::SimulationState), the run loop's state (the driven plate's
//     peak face pressure so far; the bar's two station pressures of every
//     step done) and every frame written so far (ShockwaveFrame: its scalars,
//     the regeneration volumes at once and, with write_frames, the fields).
//     The resumed run writes a fresh output and first writes these frames
//     again, so no partial HDF5 file of a killed process is reopened.
// It grows with the frames written (3 fields x automata doubles per frame
// with write_frames) on top of the state (53 doubles per automaton in FCC:
// both halves of positions, velocities and rotations, 4 x 6 pair values, the
// fluid, fields, peaks and energies).
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "pipelines/shockwave_output.h"
#include "pipelines/shockwave_stage.h"
#include "shockwave/simulation.h"

namespace arthrosim::pipelines {

/// A run of the stage that finished: its results and its file's SHA-256.
struct ShockwaveFinishedRun {
  ShockwaveRunResult result;
  std::string file_sha256;
};

/// The run in progress after `sim.steps` steps.
struct ShockwaveRunProgress {
  int run = 0;  ///< index into the stage's runs (= the finished runs before it)
  shockwave::SimulationState sim;
  double peak_pressure_pa = 0.0;  ///< driven plate: the peak face pressure so far
  std::vector<ShockwaveFrame> frames;
  std::vector<double> bar_p1, bar_p2;  ///< bar: station pressures after each step
};

struct ShockwaveCheckpoint {
  std::string identity;
  std::vector<ShockwaveFinishedRun> finished;
  std::optional<ShockwaveRunProgress> current;
};

/// Writes `c` to `path` (common::write_checkpoint: atomic, the kill tests' hook).
void write_shockwave_checkpoint(const std::filesystem::path& path, const ShockwaveCheckpoint& c, int sequence);

/// The checkpoint at `path`, or nullopt with `why` when it cannot be read as one.
std::optional<ShockwaveCheckpoint> read_shockwave_checkpoint(const std::filesystem::path& path, std::string& why);

}  // namespace arthrosim::pipelines
