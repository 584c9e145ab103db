#pragma once
// foundation_damping: dampers matching the foundation springs, gated by the compression
// (ShellModel::add_foundation_damping documents the law).
#include <memory>

#include "cartilage/shell_model.h"
#include "cartilage/surface_terms.h"

namespace arthrosim::cartilage {
std::unique_ptr<ShellTerm> make_foundation_damping_term(const ShellModel& model, double c_N_s_m3, BoneMotion bone,
                                                        bool compressive_only, double gate_m);
/// Its registration (cartilage/surface_terms.cc lists it once).
SurfaceTermInfo foundation_damping_term();
}  // namespace arthrosim::cartilage
