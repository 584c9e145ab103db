#pragma once
// One cartilage layer under the penetration method's boundary conditions:
//   bone side (level 0): solid displacement prescribed by the bone, which in
//     the bone's own frame is u = 0 (linear theory: the bone's rigid motion
//     strains nothing; the pose enters through the overlap), impermeable;
//   articular surface: pressure prescribed at every vertex (eq 17 on the
//     contact area, 0 elsewhere: free-draining) and the total traction
//     -sigma_Tot_nn n on the contact area (traction-free elsewhere);
//   side faces (the outline extruded through the thickness): free-draining
//     (p = 0) and traction-free.
// The prescribed sets never change, so the integrator factors once for the
// run. Loads are given per frame and interpolated linearly in time between
// frames (the seed interpolates its contact conditions the same way).
#include <Eigen/Core>
#include <memory>
#include <vector>

#include "biphasic/layer_system.h"
#include "biphasic/penetration.h"
#include "biphasic/trapezoidal.h"

namespace arthrosim::biphasic {

/// Linear interpolation (1 - s) a + s b of two frames' surface loads.
SurfaceLoads interpolate(const SurfaceLoads& a, const SurfaceLoads& b, double s);

/// Surface loads at time t from frames at increasing times (piecewise linear;
/// constant before the first and after the last frame). Throws
/// std::invalid_argument for sizes that differ or times not increasing.
SurfaceLoads loads_at(const std::vector<double>& frame_times, const std::vector<SurfaceLoads>& frames,
                      double t);

class LayerProblem {
 public:
  /// Takes the assembled system; factorises once (see TrapezoidalIntegrator).
  LayerProblem(LayerSystem system, TrapezoidalOptions time);

  /// Advances one step with the surface loads of t_{i+1}.
  void step(const SurfaceLoads& loads);

  const LayerSystem& system() const { return system_; }
  const TrapezoidalIntegrator& integrator() const { return *integrator_; }
  /// Continues from a checkpointed integrator state (TrapezoidalIntegrator::restore).
  void restore(const TrapezoidalState& s) { integrator_->restore(s); }
  double time() const { return integrator_->time(); }
  /// Force the layer exerts on its bone at the current step [N] (bone frame;
  /// minus the summed support reactions of the bone-side dofs). Under a
  /// compressive contact it points from the joint into the bone.
  Eigen::Vector3d force_on_bone() const;
  /// Articular-vertex index of each pressure dof fixed at the surface.
  const std::vector<int>& articular_p_dofs() const { return articular_p_; }

 private:
  LayerSystem system_;
  std::vector<int> fixed_u_, fixed_p_, articular_p_;
  std::vector<int> articular_slot_;  // per articular vertex: position in fixed_p_
  std::unique_ptr<TrapezoidalIntegrator> integrator_;
  StepInput input_;
};

}  // namespace arthrosim::biphasic
