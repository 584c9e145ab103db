#pragma once
// The surface stage's physics terms by name (docs/architecture.md, "How to
// add a term"). A term is a ShellTerm (shell_model.h) plus one registration
// here: its effect name, a one-line description, an optional check of the
// surface (run before anything is built) and the builder that adds it to a
// surface's ShellModel. build_surface_model (surface_model.h) builds exactly
// the registered terms a scenario's effects list names, in the list's order;
// registering a term adds its name to the effect vocabulary (common/effects.h,
// stage surface), so scenes may list it and the ledger records it.
//
// The bundled terms are registered in surface_terms.cc (one line each); a
// term outside the library (a test) registers itself before the scene schema
// is first used:
//   const bool kToy = cartilage::register_surface_term({"toy_load", "...", {}, build});
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "cartilage/shell_model.h"

namespace arthrosim::cartilage {

struct SurfaceInput;
struct SurfaceParameters;

/// What a term's builder gets: the model to add to and the scenario's data.
struct SurfaceTermContext {
  ShellModel& model;
  const SurfaceInput& surface;
  const SurfaceParameters& parameters;
  const BoneMotion& bone;
  /// The generic loads' ramp: t / ramp_time_s, clamped to [0, 1].
  const std::function<double(double)>& ramp;
};

struct SurfaceTermInfo {
  std::string name;         ///< the effect name a scenario lists, e.g. "foundation_springs"
  std::string description;  ///< one line (docs/scenes.md's effects table)
  /// Optional: refuses a surface before any term is built (InputError).
  std::function<void(const SurfaceInput&)> check;
  /// Adds the term to ctx.model (ShellModel::add_term records it in the ledger).
  std::function<void(const SurfaceTermContext&)> build;
};

/// Registers a term and its effect name (common::register_effect, stage
/// surface). Returns true, so a translation unit can register at static
/// initialisation. A name registered twice is a std::logic_error.
bool register_surface_term(SurfaceTermInfo term);
/// The term called `name`, or nullptr (mesh_contact and imposed_kinematics
/// are effects of the surface stage but not terms of one surface).
const SurfaceTermInfo* find_surface_term(std::string_view name);
/// Every registered term, bundled ones first, in registration order.
const std::vector<SurfaceTermInfo>& surface_terms();

}  // namespace arthrosim::cartilage
