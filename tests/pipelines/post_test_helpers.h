#pragma once
// Shared by the post-stage tests that lay a known direction field on a surface
// and compare it with a SYNTHETIC split-line map (post_synthetic_test,
// post_femur_map_test): the surface-output writer and the comparison as
// arthrosim-post runs it (average, project, register, compare).
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/hdf5.h"
#include "common/mesh.h"
#include "pipelines/post_compare.h"
#include "pipelines/splitline.h"

namespace arthrosim::pipelines::test {

/// Writes `m` (as surface "femur", node positions n_W = R_WM m.V) and T frames of
/// first principal strain lines in the surface-output layout: node i carries the
/// line R_WM line(i) with a random sign and a random magnitude in [mag_lo, mag_hi]
/// per frame (std::mt19937_64 seeded with `seed`: deterministic). Returns `path`.
inline std::string write_surface_field(const std::string& path, const common::QuadMesh& m, int T,
                                       const std::function<Eigen::Vector3d(Eigen::Index)>& line,
                                       std::uint64_t seed, double mag_lo, double mag_hi, double t_end,
                                       const Eigen::Matrix3d& R_WM = Eigen::Matrix3d::Identity()) {
  const Eigen::Index N = m.V.rows();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> mag(mag_lo, mag_hi);
  Eigen::MatrixXd e1(T, N);
  common::Tensor3d dir;
  dir.dims = {T, N, 3};
  dir.data.resize(T * N * 3);
  for (int t = 0; t < T; ++t)
    for (Eigen::Index i = 0; i < N; ++i) {
      const double s = (rng() & 1) ? 1.0 : -1.0;
      e1(t, i) = mag(rng);
      const Eigen::Vector3d d_W = s * (R_WM * line(i));
      for (int k = 0; k < 3; ++k) dir(t, i, k) = d_W(k);
    }
  common::H5File f(path, common::H5File::Mode::kTruncate);
  f.write("/time", Eigen::VectorXd::LinSpaced(T, 0.0, t_end));
  f.write("/surfaces/femur/nodes", Eigen::MatrixXd(m.V * R_WM.transpose()));
  f.write("/surfaces/femur/quads", Eigen::MatrixXi(m.Q));
  f.write("/surfaces/femur/strain/e1", e1);
  f.write_tensor3("/surfaces/femur/strain/e1_dir", dir);
  return path;
}

struct MapComparison {
  Comparison c;
  Registration reg;
};

/// The post stage's comparison of the surface "femur" of `model` with `map` in `view`,
/// default registration and comparison options.
inline MapComparison compare_model_with_map(const std::string& model, const SplitLineMap& map,
                                            const ViewOptions& view_options) {
  const SurfaceField field = read_surface_field(model, "femur");
  const NodeDirections nd = average_node_directions(field);
  const ProjectedView view = project_view(field.mesh, view_options);
  Eigen::VectorXd ang, len;
  project_directions(view, nd.direction, ang, len);
  std::vector<bool> usable(view.nodes.rows());
  for (Eigen::Index i = 0; i < view.nodes.rows(); ++i) usable[i] = nd.defined[i] && view.visible[i] && len(i) > 0.3;
  MapComparison r;
  r.reg = register_map(map.outline, view.outline, RegistrationOptions{});
  r.c = compare_with_map(map, r.reg, view, ang, nd.magnitude, usable, ComparisonOptions{});
  return r;
}

/// The map with every line turned by alpha [rad] (axial).
inline SplitLineMap rotated_lines(SplitLineMap m, double alpha) {
  for (Eigen::Index s = 0; s < m.angle_rad.size(); ++s) m.angle_rad(s) = wrap_axial(m.angle_rad(s) + alpha);
  return m;
}

}  // namespace arthrosim::pipelines::test
