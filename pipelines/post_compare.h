#pragma once
// Post stage, comparison part (issue 7; seed 002_3ffcc11eb7a447d9.txt, "Comparison with
// Cartilage Split Lines"): time-averaged magnitude-weighted first principal strain
// directions of a surface, projected onto a view plane, compared with a split-line map
// registered onto that view by Coherent Point Drift (Myronenko & Song 2010).
//
// Pipeline (docs/post.md):
//  1. average:  per node, T = sum_t |e1_t| d_t d_t^T / sum_t |e1_t| (pipelines/orientation.h)
//  2. view:     x_2D = P x with P = [r; u] (2 x 3), u = up made orthogonal to the view
//               direction v, r = v x u (so a view along -z with up +y has r = +x); the
//               outline is the projected boundary loop enclosing the largest area
//  3. register: map outline -> view outline, CPD affine (principal-axes prealignment),
//               then CPD non-rigid on the result; the composite warp T carries the map's
//               samples, and their orientations through its Jacobian, v' = J v
//  4. compare:  at each warped sample, model directions of the visible nodes within
//               `radius` are averaged as an orientation tensor (weights = time-averaged
//               |e1|), and the acute angle to the warped map line is taken (0..90 deg)
#include <Eigen/Core>

#include <string>
#include <vector>

#include "pipelines/cpd.h"
#include "common/mesh.h"
#include "common/options.h"
#include "pipelines/splitline.h"
#include "pipelines/surface_output.h"

namespace arthrosim::pipelines {

/// One surface of a deformable-surface output file (docs/surface_output.md):
/// /surfaces/<name>/nodes (N x 3, m), quads (Q x 4), strain/e1 (T x N),
/// strain/e1_dir (T x N x 3), optional deflection (T x N, m); /time (T, s).
/// A surface's strain field over the frames of a surface output
/// (surface_output::Reader::strain_field).
using SurfaceField = surface_output::StrainField;

/// Reads `surface` from the surface output `path`. Throws InputError naming
/// file and dataset.
SurfaceField read_surface_field(const std::string& path, const std::string& surface);

struct NodeDirections {
  Eigen::MatrixXd direction;   ///< N x 3 averaged line (unit; zero row when undefined)
  Eigen::VectorXd coherence;   ///< N, (l1 - l2)/(l1 + l2)
  Eigen::VectorXd magnitude;   ///< N, time-averaged |e1|
  std::vector<bool> defined;
};
NodeDirections average_node_directions(const SurfaceField& field);

/// A view plane (scene keys post.view_*).
struct ViewOptions {
  Eigen::Vector3d direction{0, 0, -1};  ///< viewing direction (from the eye into the scene)
  Eigen::Vector3d up{0, 1, 0};          ///< roughly up on the page; not parallel to direction
};

struct ProjectedView {
  Eigen::Matrix<double, 2, 3> P;  ///< rows r and u
  Eigen::MatrixX2d nodes;         ///< N x 2 projected node positions (m)
  std::vector<int> outline_nodes; ///< boundary loop used as outline
  Eigen::MatrixX2d outline;       ///< its projected positions
  std::vector<bool> visible;      ///< node normal faces the viewer (n . v < 0)
};
/// Throws InputError for a degenerate view (zero/parallel vectors) or a mesh without boundary.
ProjectedView project_view(const common::QuadMesh& mesh, const ViewOptions& view);

/// Projects unit 3D lines into the view: returns angles (rad, axial) and the projected
/// length |P d| (0 for undefined/zero rows).
void project_directions(const ProjectedView& view, const Eigen::MatrixXd& d3, Eigen::VectorXd& angle_rad,
                        Eigen::VectorXd& projected_length);

struct RegistrationOptions {
  int outline_points = 200;  ///< both outlines are resampled to this many points (>= 8)
  double w = 0.1;            ///< CPD outlier weight
  double beta = 2.0;         ///< CPD non-rigid kernel width (normalised units)
  double lambda = 3.0;       ///< CPD non-rigid regularisation
  bool nonrigid = true;      ///< false: affine only
};

struct Registration {
  CpdResult affine, nonrigid;
  bool has_nonrigid = false;
  Eigen::MatrixX2d map_outline, model_outline;  ///< the resampled outlines
  Eigen::MatrixX2d warped_outline;              ///< T(map outline)
  double outline_mean_distance = 0.0;  ///< mean distance warped outline -> model outline polygon (m)
  double outline_max_distance = 0.0;

  Eigen::Vector2d warp(const Eigen::Vector2d& p) const;
  Eigen::Matrix2d jacobian(const Eigen::Vector2d& p) const;
};

/// Resamples a closed polygon to n points equally spaced in arc length.
Eigen::MatrixX2d resample_closed(const Eigen::MatrixX2d& polygon, int n);

/// Median of the values (mean of the middle two for an even count); NaN when empty.
double median_of(std::vector<double> v);

Registration register_map(const Eigen::MatrixX2d& map_outline, const Eigen::MatrixX2d& model_outline,
                          const RegistrationOptions& options);

struct ComparisonOptions {
  /// Averaging radius in view units (m); 0 = max(warped map resolution, 1.5 x median
  /// projected node spacing), so each sample sees the model at the map's resolution.
  double radius = 0.0;
  double threshold_rad = 20 * common::units::deg;  ///< "within" threshold
  double min_projected_length = 0.3;  ///< nodes whose line is this foreshortened are skipped
};

struct RegionStatistics {
  std::string region;
  int samples = 0, covered = 0;
  double mean_deg = 0, median_deg = 0, fraction_within = 0;
};

struct Comparison {
  Eigen::MatrixX2d points;       ///< warped sample positions (view units)
  Eigen::VectorXd map_angle;     ///< warped map line angle (rad)
  Eigen::VectorXd model_angle;   ///< spatially averaged model line angle (rad)
  Eigen::VectorXd error_deg;     ///< acute angle (deg); NaN where not covered
  Eigen::VectorXd coherence;     ///< spatial coherence of the averaged model line
  std::vector<bool> covered;     ///< a defined model node within the radius
  std::vector<std::string> region;
  double radius = 0.0;
  std::vector<RegionStatistics> stats;  ///< "all" first, then each region, sorted
};

/// Warps the map's samples with `reg` (angles through the Jacobian) and compares.
Comparison compare_with_map(const SplitLineMap& map, const Registration& reg, const ProjectedView& view,
                            const Eigen::VectorXd& node_angle, const Eigen::VectorXd& node_weight,
                            const std::vector<bool>& node_usable, const ComparisonOptions& options);

}  // namespace arthrosim::pipelines
