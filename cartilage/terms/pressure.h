#pragma once
// pressure: a follower pressure on one face of the shell (ShellModel::add_pressure); the scene effect `pressure` is the
// generic load on the mid-surface.
#include <memory>

#include "cartilage/shell_model.h"
#include "cartilage/surface_terms.h"

namespace arthrosim::cartilage {
std::unique_ptr<ShellTerm> make_pressure_term(const ShellModel& model, std::string name, double face_zeta,
                                              std::function<double(double)> p_Pa);
/// Its registration (cartilage/surface_terms.cc lists it once).
SurfaceTermInfo pressure_term();
}  // namespace arthrosim::cartilage
