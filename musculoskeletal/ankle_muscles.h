#pragma once
// Uniarticular ankle muscles for COMAK's optional ankle equilibrium
// (ComakOptions::ankle_equilibrium, comak.h): a lumped soleus (plantarflexor)
// and a tibialis anterior (dorsiflexor) added to a knee model that has only
// the 13 knee-crossing muscles. Without them the ankle row could be balanced
// by the gastrocnemii alone, and only in plantarflexion: the dorsiflexion
// demand after heel strike would make it infeasible.
//
// Both are straight via-point paths (tibia -> calcaneus), so their moment
// arms come from the geometry like every other muscle's (r = -dl/dq) and they
// act on the knee coordinates not at all: origin and insertion ride on the
// tibia and the calcaneus, which move rigidly together when only knee
// coordinates change, so their generalized force there is zero to rounding.
//
// Parameters (OpenSim gait2392, after Delp et al. 1990; the soleus F_max is
// also Arnold et al. 2010's and lenhart2015's):
//   soleus             F_max 3549 N; origin tibia (-0.0024, -0.1533, 0.0071),
//                      insertion calcaneus (0, 0.031, -0.0053) m;
//   tibialis anterior  F_max  905 N; origin tibia (0.0179, -0.1624, 0.0115),
//                      via tibia (0.0329, -0.3951, -0.0177) (the extensor
//                      retinaculum), insertion calcaneus (0.1166, 0.0178,
//                      -0.0305) m;
// gait2392 frames: tibia origin at the knee, ankle 0.43 m below it; the
// calcaneus frame sits at (-0.04877, -0.04195, 0.00792) m from the ankle
// (subtalar joint location in the talus). Points are taken relative to the
// ankle and scaled by s = (the model's knee-to-ankle distance) / 0.43 m;
// the subtalar and the ankle's obliquity are ignored (the model's ankle is a
// hinge about the tibia's Z). Moment arms at the bundled model's neutral
// ankle (s = 0.944): soleus 4.4 cm plantarflexion, tibialis anterior 4.3 cm
// dorsiflexion (ankle_muscles_test prints them). The tibia frame must be X
// anterior, Y proximal, Z lateral (right leg), as docs/knee_geometry.md says.
#include <string>
#include <vector>

#include "musculoskeletal/model.h"

namespace arthrosim::musculoskeletal {

struct AnkleMuscleOptions {
  double soleus_max_force = 3549.0;   ///< [N] (gait2392 / Arnold 2010)
  double tibant_max_force = 905.0;    ///< [N] (gait2392)
  /// Knee-to-ankle distance of the source model [m] (gait2392: 0.43).
  double source_shank_length = 0.43;
};

/// Appends "soleus" and "tibant" to model.muscles. Throws InputError if the
/// model has no revolute 'ankle_flexion' joint from the tibia, or already has
/// a muscle of either name. Returns the names added.
std::vector<std::string> add_ankle_muscles(Model& model, const AnkleMuscleOptions& options = {});

}  // namespace arthrosim::musculoskeletal
