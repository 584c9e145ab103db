#include "musculoskeletal/ankle_muscles.h"

#include "common/error.h"

namespace arthrosim::musculoskeletal {

std::vector<std::string> add_ankle_muscles(Model& model, const AnkleMuscleOptions& o) {
  const int ankle = model.tree.coordinate_index("ankle_flexion");
  const int tibia = model.tree.body_index("tibia");
  const Joint* joint = nullptr;
  for (const Joint& j : model.tree.joints)
    if (ankle >= 0 && j.coordinate == ankle) joint = &j;
  if (!joint || joint->type != JointType::kRevolute || joint->parent != tibia)
    throw common::InputError(model.source + ": error: the ankle muscles need a revolute joint "
                             "'ankle_flexion' whose parent is the body 'tibia'");
  for (const char* n : {"soleus", "tibant"})
    if (model.muscle_index(n) >= 0)
      throw common::InputError(model.source + ": error: the model already has a muscle '" +
                               std::string(n) + "'; the ankle stand-ins would duplicate it");
  if (!(o.soleus_max_force > 0) || !(o.tibant_max_force > 0) || !(o.source_shank_length > 0))
    throw common::InputError("ankle muscles: forces and source shank length must be > 0");
  const int foot = joint->child;
  const Vec3 c_T = joint->X_PJ.translation();  // ankle centre in the tibia frame
  const double shank = -c_T.y();
  if (!(shank > 0))
    throw common::InputError(model.source + ": error: the ankle joint must lie below the knee "
                             "(negative Y in the tibia frame)");
  const double s = shank / o.source_shank_length;
  const Vec3 ankle_src(0.0, -o.source_shank_length, 0.0);
  const Vec3 subtalar(-0.04877, -0.04195, 0.00792);  // calcaneus frame from the ankle (gait2392)
  auto on_tibia = [&](const Vec3& p_src) {
    return PathPoint{tibia, c_T + s * (p_src - ankle_src)};
  };
  auto on_foot = [&](const Vec3& p_calcn) {
    // Child frame = joint frame at q = 0 for a revolute joint.
    const Vec3 p_T = c_T + s * (p_calcn + subtalar);
    return PathPoint{foot, joint->X_PJ.inverse() * p_T};
  };
  Muscle soleus;
  soleus.name = "soleus";
  soleus.max_isometric_force = o.soleus_max_force;
  soleus.path.points = {on_tibia(Vec3(-0.0024, -0.1533, 0.0071)), on_foot(Vec3(0.0, 0.031, -0.0053))};
  Muscle tibant;
  tibant.name = "tibant";
  tibant.max_isometric_force = o.tibant_max_force;
  tibant.path.points = {on_tibia(Vec3(0.0179, -0.1624, 0.0115)),
                        on_tibia(Vec3(0.0329, -0.3951, -0.0177)),
                        on_foot(Vec3(0.1166, 0.0178, -0.0305))};
  model.muscles.push_back(soleus);
  model.muscles.push_back(tibant);
  return {"soleus", "tibant"};
}

}  // namespace arthrosim::musculoskeletal
