#pragma once
// The shockwave stage's output file: one HDF5 file per run (one pulse of one
// energy flux density, or the platen compression) with an XDMF sidecar
// (same stem) that opens the automata as points in ParaView. Schema in
// docs/shockwave.md ("Output"); this module is the only writer and reader.
//
//   /model/positions (N, 3) [m], /model/tissue (N) int, /model/topology (N, 1)
//   /model/tissue_names (T), /model/tissue_parameters (T, 7): density,
//     G, K, K_s, porosity, permeability, total density (SI)
//   /time (F) [s]; /fields/pressure, /fields/distortional_strain,
//     /fields/pore_pressure (F, N) [Pa, -, Pa] (when frames are written)
//   /peaks/pressure, /peaks/distortional_strain, /peaks/pore_pressure (N)
//   /criteria/<tissue>/{tissue_m3, compressive_m3, distortional_m3, pore_m3,
//     all_m3} (peaks), /criteria/<tissue>/all_at_once_m3 (F)
//   /pulse/time, /pulse/pressure (applied history at the frames) and
//     attributes; /solver attributes; /energy/* (F); /compression/* (F)
//   /effects/built, /effects/part, /effects/count (the ledger's table layout)
#include <array>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "common/output_file.h"
#include "shockwave/criteria.h"
#include "shockwave/simulation.h"

namespace arthrosim::common {
class H5File;
}

namespace arthrosim::pipelines {

/// One recorded construction of a physics term (the layout of
/// common::EffectLedger's table).
struct ShockwaveEffect {
  std::string effect, part;
  std::int64_t count = 0;
};

/// The values of one written frame: what append_frame writes, and what the
/// stage's checkpoint holds to write the frame again on resume
/// (pipelines/shockwave_checkpoint.h).
struct ShockwaveFrame {
  double time = 0.0, applied_pressure = 0.0;                       ///< [s], [Pa]
  double kinetic = 0.0, potential = 0.0, work = 0.0, dissipation = 0.0;  ///< [J]
  double compression_force = 0.0, compression_displacement = 0.0;  ///< [N], [m]
  /// Per automaton (empty unless frames are written; pore pressure also
  /// without pore fluid).
  std::vector<double> pressure, distortional_strain, pore_pressure;
  std::vector<double> all_at_once_m3;  ///< per tissue: all three criteria at once
};

/// The frame of `sim` at its field time; `fields`: with the per-automaton
/// fields (`fluid`: the pore pressure too).
ShockwaveFrame shockwave_frame(const shockwave::Simulation& sim, double applied_pressure,
                               const shockwave::RegenerationCriteria& criteria, bool fields, bool fluid,
                               double compression_force = 0.0, double compression_displacement = 0.0);

class ShockwaveWriter {
 public:
  /// Writes the model into "<h5_path>.partial" (common/output_file.h); finish()
  /// renames it over `h5_path`, so an earlier complete file stays until then
  /// and a killed run leaves only the .partial. `metadata_options` is the
  /// resolved options text; `argv` the command line.
  ShockwaveWriter(const std::filesystem::path& h5_path, const shockwave::Model& model, const std::string& label,
                  bool frames, bool fluid, const std::string& metadata_options, const std::vector<std::string>& argv);
  ~ShockwaveWriter();

  /// One frame at the simulation's field time (fields if frames are on; the
  /// instantaneous regeneration volumes and the energies always).
  void append_frame(const shockwave::Simulation& sim, double applied_pressure,
                    const shockwave::RegenerationCriteria& criteria, double compression_force = 0.0,
                    double compression_displacement = 0.0);
  /// A frame made by shockwave_frame (with fields when frames are on).
  void append_frame(const ShockwaveFrame& frame);
  bool frames() const;
  bool fluid() const;
  /// Peaks, peak-based volumes, attributes, the effect ledger; then the XDMF
  /// sidecar; closes the file and renames it to its complete name (the
  /// writer takes no more frames). Returns the largest at-once volume per tissue.
  std::vector<double> finish(const shockwave::Simulation& sim, const shockwave::RegenerationCriteria& criteria,
                             const std::vector<ShockwaveEffect>& effects,
                             const std::vector<std::pair<std::string, double>>& attributes);
  const std::filesystem::path& path() const { return path_; }

 private:
  struct Impl;
  std::filesystem::path path_;
  common::AtomicOutput atomic_;
  std::unique_ptr<Impl> impl_;
};

/// What a consumer (a test, the summary) reads back from a run file.
struct ShockwaveFile {
  std::string label;
  std::vector<std::string> tissue_names;
  Eigen::VectorXi tissue;
  Eigen::VectorXd peak_pressure, peak_distortional_strain, peak_pore_pressure;
  std::vector<double> time;
  /// Per tissue: tissue, compressive, distortional, pore, all [m^3].
  std::vector<std::array<double, 5>> volumes;
  std::vector<std::string> effects;  ///< /effects/built
  double efd_j_per_m2 = 0.0;
};
/// Reads a run file (InputError naming file and dataset on a bad file).
ShockwaveFile read_shockwave_file(const std::filesystem::path& h5_path);

}  // namespace arthrosim::pipelines
