// The scene keys of ComakOptions (comak.h).
#include "musculoskeletal/comak.h"

namespace arthrosim::musculoskeletal {

void ComakOptions::declare(common::OptionVisitor& v) {
  using common::Unit;
  // 1e-4, not Ipopt's 1e-8: the faceted contact makes the scaled dual
  // infeasibility stall at 1e-3..1e-2, so a tighter tol only ends at Ipopt's
  // acceptable level after many more iterations (docs/comak.md).
  v.number("ipopt_tolerance", ipopt_tolerance, Unit::kNone, {1e-14, 1e-2},
           "Ipopt's convergence tolerance (its option 'tol', scaled NLP) per frame; 1e-4 because the faceted contact "
           "stalls the scaled dual infeasibility at 1e-3..1e-2 (docs/comak.md)");
  v.integer("ipopt_acceptable_iterations", acceptable_iterations, {1, 1e6},
            "consecutive iterates at Ipopt's acceptable level (acceptable_tol 1e-2) that end a solve as 'acceptable'; "
            "more keeps iterating towards ipopt_tolerance (docs/comak.md)");
  v.integer("ipopt_max_iterations", max_iterations, {1, 1e6},
            "Ipopt iteration limit per attempt of a frame (the last retry gets twice as many)");
  v.number("activation_min", activation_min, Unit::kNone, {0, 1}, "lower bound of every muscle activation");
  v.flag("reserve_actuators", reserve_actuators, "add heavily weighted reserve actuators on the secondary coordinates");
  v.flag("ankle_equilibrium", ankle_equilibrium,
         "add the ankle moment balance (gastrocnemii plus soleus and tibialis anterior stand-ins; a model with its own "
         "leg: its own ankle muscles and foot) as a constraint (docs/comak.md)");
  v.flag("hip_equilibrium", hip_equilibrium,
         "add the leg's moment balance about the hip's three axes (a model with its own leg and its hip muscles, e.g. "
         "arthrosim import-osim --muscles leg) (docs/comak.md)");
  v.flag("coordinate_damping", coordinate_damping,
         "the model's coordinate dampers act on the secondary coordinates' speed from the previous frame "
         "(OpenSim-JAM's SpringGeneralizedForce; docs/comak.md)");
  v.flag("body_inertia", body_inertia,
         "add the weight and d'Alembert forces of the tibia and patella bodies (URDF inertials, moving with the model; "
         "the shank's terms leave the external load) (docs/comak.md)");
  v.flag("second_start", second_start,
         "also solve every converged frame from the passive settle at its flexion and keep the lower objective (the "
         "problem has local optima; a warm start carries the previous frame's branch; docs/comak.md)");
}

}  // namespace arthrosim::musculoskeletal
