#pragma once
// The surface stage's checkpoint (docs/testing.md, "Checkpoint and resume";
// docs/surface_output.md, "Checkpoints"): `<out>.checkpoint`, an HDF5 file
// holding everything a run needs to continue bit-identically after its last
// accepted step:
//   - the HHT integrator's state (numerics::HhtState: time, adaptive step
//     size and its growth counter, q, v, a, F of the last step, the
//     predictor's last change, the Newton counters and the linear solver in
//     use after a CHOLMOD -> UMFPACK switch, and with
//     newton_reuse_factorization the matrix of the factorisation modified
//     Newton keeps, refactorised on resume);
//   - the coordinates the coupled system's contact pattern was last built
//     around (the pattern, hence the linear solver's ordering and round-off,
//     depends on them) and the system's counters;
//   - the step loop's own state (time, next output frame, penetration
//     counters, the last step's residual) and every step record and frame
//     written so far (a frame as its time and coordinates): the resumed run
//     writes a fresh output and writes these again first (frames recomputed
//     from their coordinates), so no partial HDF5 file of a killed process is
//     reopened;
//   - with contact_augmentations, the contact multipliers (now and at each
//     frame written) and the augmentation totals;
//   - the identity of the run (common::run_identity).
#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "cartilage/coupled_system.h"
#include "numerics/hht_integrator.h"
#include "pipelines/surface_output.h"

namespace arthrosim::pipelines {

struct SurfaceCheckpoint {
  std::string identity;
  // The step loop.
  double t = 0;
  int k_out = 1;
  long penetration_warnings = 0, unfaded_over = 0, rejections_logged = 0;
  long last_iterations = 0, last_rejections = 0;
  double worst_ratio = 0, worst_unfaded_ratio = 0, last_change = 0;
  double final_residual_N = 0, residual_tolerance_N = 0, max_penetration_m = 0;
  long contact_steps = 0, active_contacts_sum = 0;
  // What was written after the first frame (t = 0).
  std::vector<double> frame_times;
  std::vector<Eigen::VectorXd> frame_q;
  std::vector<surface_output::StepRecord> steps;
  // contact_augmentations (augmented Lagrangian, docs/contact.md): each
  // contact pair's multipliers (side a, side b; empty: none yet) now and at
  // every frame written after the first (a frame's contact pressures depend
  // on them), and the stage's augmentation totals.
  using PairMultipliers = std::vector<std::array<Eigen::VectorXd, 2>>;
  PairMultipliers multipliers;
  std::vector<PairMultipliers> frame_multipliers;
  long total_augmentations = 0, total_augmentation_iterations = 0;
  // Integrator and system.
  numerics::HhtState hht;
  Eigen::VectorXd pattern_q;
  cartilage::CoupledSystemStatistics system;
};

/// Writes `c` to `path` through common::AtomicOutput (path.partial, then a
/// rename); `sequence` numbers this process's checkpoints for the kill tests'
/// hook (common::checkpoint_test_kill).
void write_surface_checkpoint(const std::filesystem::path& path, const SurfaceCheckpoint& c, int sequence);

/// The checkpoint at `path`, or nullopt with `why` when it cannot be read as
/// one.
std::optional<SurfaceCheckpoint> read_surface_checkpoint(const std::filesystem::path& path, std::string& why);

}  // namespace arthrosim::pipelines
