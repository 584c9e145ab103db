#pragma once
// foundation_springs: compressive-only springs from every node to its anchor on the bone
// (ShellModel::add_foundation_springs documents the law).
#include <memory>

#include "cartilage/shell_model.h"
#include "cartilage/surface_terms.h"

namespace arthrosim::cartilage {
std::unique_ptr<ShellTerm> make_foundation_springs_term(const ShellModel& model, Eigen::VectorXd k_per_node_N_m3,
                                                        BoneMotion bone, bool compressive_only,
                                                        FoundationIntegration integration);
/// Its registration (cartilage/surface_terms.cc lists it once).
SurfaceTermInfo foundation_springs_term();
}  // namespace arthrosim::cartilage
