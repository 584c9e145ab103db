#include "biphasic/layer_problem.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace arthrosim::biphasic {

SurfaceLoads interpolate(const SurfaceLoads& a, const SurfaceLoads& b, double s) {
  if (a.traction.size() != b.traction.size() || a.pressure.size() != b.pressure.size()) {
    throw std::invalid_argument("biphasic: interpolating surface loads of different sizes");
  }
  SurfaceLoads out;
  out.traction = (1.0 - s) * a.traction + s * b.traction;
  out.pressure = (1.0 - s) * a.pressure + s * b.pressure;
  return out;
}

SurfaceLoads loads_at(const std::vector<double>& frame_times, const std::vector<SurfaceLoads>& frames,
                      double t) {
  if (frame_times.empty() || frame_times.size() != frames.size()) {
    throw std::invalid_argument("biphasic: loads_at needs one load per frame time, at least one");
  }
  for (size_t i = 1; i < frame_times.size(); ++i) {
    if (!(frame_times[i] > frame_times[i - 1])) {
      throw std::invalid_argument("biphasic: frame times must increase, found " +
                                  std::to_string(frame_times[i - 1]) + " then " +
                                  std::to_string(frame_times[i]));
    }
  }
  if (t <= frame_times.front()) return frames.front();
  if (t >= frame_times.back()) return frames.back();
  const size_t k = static_cast<size_t>(
      std::upper_bound(frame_times.begin(), frame_times.end(), t) - frame_times.begin());
  const double s = (t - frame_times[k - 1]) / (frame_times[k] - frame_times[k - 1]);
  return interpolate(frames[k - 1], frames[k], s);
}

LayerProblem::LayerProblem(LayerSystem system, TrapezoidalOptions time) : system_(std::move(system)) {
  const LayerMesh& m = system_.mesh;
  const int order = system_.u_order();
  for (int node : m.bone_nodes(order))
    for (int c = 0; c < 3; ++c) fixed_u_.push_back(3 * node + c);
  std::sort(fixed_u_.begin(), fixed_u_.end());
  // Pressure: every articular vertex, and the side faces.
  std::vector<int> p = m.periphery_nodes(1);
  for (int v = 0; v < m.num_vertices(); ++v) p.push_back(m.articular_node(1, v));
  std::sort(p.begin(), p.end());
  p.erase(std::unique(p.begin(), p.end()), p.end());
  fixed_p_ = p;
  articular_slot_.resize(m.num_vertices());
  for (int v = 0; v < m.num_vertices(); ++v) {
    const int node = m.articular_node(1, v);
    articular_slot_[v] = static_cast<int>(std::lower_bound(fixed_p_.begin(), fixed_p_.end(), node) - fixed_p_.begin());
    articular_p_.push_back(node);
  }
  integrator_ = std::make_unique<TrapezoidalIntegrator>(system_, fixed_u_, fixed_p_, time);
  input_.u_fixed = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(fixed_u_.size()));
  input_.p_fixed = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(fixed_p_.size()));
}

void LayerProblem::step(const SurfaceLoads& loads) {
  const int nv = system_.mesh.num_vertices();
  if (loads.traction.size() != 3 * nv || loads.pressure.size() != nv) {
    throw std::invalid_argument("layer '" + system_.mesh.name + "': surface loads of size " +
                                std::to_string(loads.traction.size()) + "/" +
                                std::to_string(loads.pressure.size()) + " for " + std::to_string(nv) +
                                " articular vertices");
  }
  input_.p_fixed.setZero();  // side faces and non-contact surface: free-draining
  for (int v = 0; v < nv; ++v) input_.p_fixed[articular_slot_[v]] = loads.pressure[v];
  input_.F_t = system_.surface_load * loads.traction;
  integrator_->step(input_);
}

Eigen::Vector3d LayerProblem::force_on_bone() const {
  const Eigen::VectorXd R = integrator_->reaction();
  Eigen::Vector3d f = Eigen::Vector3d::Zero();
  for (int dof : fixed_u_) f[dof % 3] -= R[dof];
  return f;
}

}  // namespace arthrosim::biphasic
