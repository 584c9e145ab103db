#pragma once
// The biphasic stage's output file (schema in docs/biphasic.md, "Output"):
// its writer and its reader. No dataset path appears outside this module.
//
// Written step by step through appenders (space for every expected step
// allocated up front, flushed after each step): a run stopped at step k
// leaves steps 1..k-1 readable.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <memory>
#include <string>
#include <vector>

#include "biphasic/joint_run.h"
#include "common/hdf5.h"

namespace arthrosim::biphasic {

/// Per-frame preprocessing record of one contact pair (stage-1 frames).
struct CompartmentFrame {
  double force_N = 0.0;
  double gamma_a_Pa = 0.0, gamma_b_Pa = 0.0;
  double area_a_m2 = 0.0, area_b_m2 = 0.0;
  int negative_pressure_nodes = 0;   ///< both layers
  int beyond_thickness_nodes = 0;    ///< both layers
  int skipped_no_overlap = 0;        ///< 1 when |F| > 0 but no overlap
  /// |F| = 0 while the layers overlap: largest overlap area of the two
  /// layers [m^2], no contact conditions applied (0 otherwise).
  double unloaded_overlap_m2 = 0.0;
};

class OutputWriter {
 public:
  /// Creates `path` (replacing it), writes the static part: every layer's
  /// mesh (corner nodes in its bone frame, hexahedra in VTK order, the
  /// articular surface quads and which corner node each articular / bone
  /// vertex is), the regions, and prepares appenders for `expected_steps`.
  OutputWriter(const std::string& path, const JointRun& run, int expected_steps);
  ~OutputWriter();

  common::H5File& file() { return *file_; }

  /// One step: time, the pose of each layer's bone at that time, and the
  /// layers' results (order of run.layers()).
  void append_step(double time_s, const std::vector<Eigen::Isometry3d>& X_WB,
                   const std::vector<LayerStep>& layers);
  /// The per-frame preprocessing table of every pair (frames x pairs, pairs
  /// in the order of run.pairs()).
  void write_frames(const std::vector<double>& frame_times,
                    const std::vector<std::vector<CompartmentFrame>>& frames);
  /// Writes the counters of every layer's integrator and closes the file.
  void finish(const JointRun& run);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::unique_ptr<common::H5File> file_;
};

/// Writes the XDMF sidecar of a finished output file (volume meshes of every
/// layer, placed in the world per step, with displacement, fluid pressure,
/// flux, max principal and max shear stress).
void write_output_xdmf(const std::string& h5_path, const std::string& xdmf_path);

/// What tests and the report read back: the per-step series of one layer.
struct LayerSeries {
  std::string name;
  Eigen::VectorXd time;
  Eigen::VectorXd contact_area, fluid_load_support, max_tensile, max_shear;
  Eigen::VectorXi max_tensile_region, max_shear_region;
  /// Where the maxima are, by name (the file's /regions/names: central,
  /// anterior, posterior, medial, lateral region of this layer's plate), per
  /// step; "none" where no contact vertex is in tension.
  std::vector<std::string> max_tensile_where, max_shear_where;
  /// Largest applied total normal stress sigma_Tot_nn and contact fluid
  /// pressure p over the articular vertices per step [Pa] (from
  /// surface/total_normal_stress and surface/fluid_pressure; empty when the
  /// file has no such datasets).
  Eigen::VectorXd max_contact_stress, max_contact_fluid_pressure;
  int factorizations = 0, solves = 0, unknowns = 0;
  double factorization_s = 0.0, solve_s = 0.0;
};

/// Reads every layer's series (InputError naming the file and dataset when
/// something is missing or a region code is not in /regions/names).
std::vector<LayerSeries> read_layer_series(const std::string& path);

/// One layer's applied total normal stress over its articular vertices.
struct LayerSurfaceMap {
  std::string name;
  Eigen::MatrixXd total_normal_stress;  ///< steps x articular vertices [Pa]
  Eigen::MatrixXd articular_vertices;   ///< vertices x 3, bone frame [m]
};
/// The steps' times and every layer that has surface/total_normal_stress
/// and articular_vertices (InputError naming the file and dataset when the
/// shapes disagree with /time and the vertices).
struct SurfaceMaps {
  Eigen::VectorXd time;
  std::vector<LayerSurfaceMap> layers;
};
SurfaceMaps read_surface_maps(const std::string& path);

/// Difference of one key output between a run and a reference run.
struct OutputDifference {
  std::string layer, metric;
  double relative = 0.0;   ///< max over common times |a - ref| / max |ref|
  double reference_peak = 0.0;
  double peak = 0.0;         ///< max |a| over the common times
  int common_times = 0;
};

/// Key outputs of `path` against `reference_path` at the times both have
/// (within 1e-9 s): per layer the series max_tensile_stress, max_shear_stress,
/// fluid_load_support, contact_area and the largest fluid pressure anywhere in
/// the layer (peak_fluid_pressure). Layers missing from either file are
/// skipped. Throws InputError when the files have no time in common.
std::vector<OutputDifference> compare_outputs(const std::string& path, const std::string& reference_path);

/// Dataset paths (for tools that inspect the file directly, e.g. h5diff).
std::string layer_group(const std::string& layer);

}  // namespace arthrosim::biphasic
