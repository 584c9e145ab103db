#pragma once
// Importing an OpenSim 4.x model with OpenSim-JAM components (lenhart2015 and
// its kind) into arthrosim's model format (URDF + <arthrosim:...> elements,
// docs/model_format.md; method and mapping: docs/import.md).
//
// What is imported. The knee joint's parent body (the femur body that
// carries the femoral cartilage, femur_distal_r) becomes the root; the tree
// keeps every body below it (tibia, patella, talus, foot) and the chain
// above it up to the ground (femur, pelvis, ground), so the lab pose of every
// body follows from the model's own joints. The chain's joints are reversed
// (inverse transforms, negated axes), so the coordinates keep their OpenSim
// names, values and signs. Other bodies (the other leg, trunk, arms) are not
// imported; their masses count in the subject mass.
//  - Bodies: mass, centre of mass, inertia (about the COM, body axes),
//    PhysicalOffsetFrames (joint and body frames) composed into the joints.
//  - Joints: CustomJoint (SpatialTransform: rotation1..3 applied in order
//    about their axes, then the translations, as Simbody's FunctionBased
//    mobilizer does: X_FM = [R1 R2 R3 | sum t_i b_i]), WeldJoint, PinJoint,
//    SliderJoint. Each becomes a chain of URDF joints (one per coordinate,
//    joint name = coordinate name) with massless links between them. A
//    TransformAxis function must be Constant, LinearFunction with slope +-1
//    (MultiplierFunction of them folded in) of at most one coordinate; a
//    spline or a coupled coordinate stops the import naming the element and
//    line.
//  - The knee joint's and the patellofemoral joint's coordinates are free
//    (the knee flexion primary, the other 11 secondary), all others are
//    prescribed (<arthrosim:prescribed>); roles (<arthrosim:role>) tell
//    COMAK which coordinate is the knee flexion, hip and ankle angle and
//    which body is the femur, tibia and patella.
//  - Blankevoort1991Ligament (all properties, OpenSim-JAM's defaults for
//    those absent), grouped by name without trailing digits (MCLd1..5 ->
//    MCLd); muscles (any <...Muscle> with max_isometric_force,
//    optimal_fiber_length, tendon_slack_length, pennation_angle_at_optimal)
//    crossing the knee or the patellofemoral joint, or every muscle on the
//    imported bodies (muscles = leg); GeometryPath points (PathPoint,
//    ConditionalPathPoint, MovingPathPoint) and PathWraps with their wrap
//    objects (WrapCylinder, WrapEllipsoid, WrapSphere, WrapTorus) in the
//    elements of musculoskeletal/path.h's wrapping.
//  - Smith2018ArticularContactForce and its Smith2018ContactMesh pair:
//    meshes kept in their body frames and units (copied to DIR/Geometry),
//    elastic modulus, Poisson's ratio, uniform thickness, linear/nonlinear
//    law, max_proximity (as max_overlap_factor).
//  - SpringGeneralizedForce on an imported coordinate
//    (<arthrosim:coordinate_spring>).
// Everything else is listed in the import report (DIR/import_report.md) with
// its element, name and line and why it was not imported; an element the
// importer would need but cannot represent throws common::InputError
// "model.osim:LINE: error: ...". Nothing is dropped silently.
#include <map>
#include <string>
#include <vector>

namespace arthrosim::musculoskeletal {

enum class ImportMuscles {
  kKnee,  ///< muscles whose path spans the knee or the patellofemoral joint
  kLeg,   ///< every muscle whose path lies on imported bodies
};

struct OsimImportOptions {
  std::string knee_joint = "knee_r";             ///< tibiofemoral joint (its parent is the root)
  std::string patellofemoral_joint = "pf_r";     ///< its coordinates are free too ("" = none)
  /// The knee joint's primary coordinate; empty = the coordinate of its
  /// rotation1 axis.
  std::string knee_flexion;
  ImportMuscles muscles = ImportMuscles::kKnee;
  /// Extra folders searched for mesh files (after <model dir>/Geometry and
  /// the model's folder).
  std::vector<std::string> geometry_dirs;
  /// Leave the wrap objects and PathWraps out (each one is listed in the
  /// report as omitted on request).
  bool without_wrapping = false;
  /// File name of the model written into the output folder; empty = the
  /// OpenSim model's name + ".urdf".
  std::string urdf_name;
};

struct OsimImportSummary {
  std::string urdf_path;    ///< written model file
  std::string report_path;  ///< DIR/import_report.md
  std::string model_name;
  double subject_mass_kg = 0.0;  ///< all bodies of the source model
  int bodies = 0;                ///< imported OpenSim bodies (incl. ground)
  int links = 0;                 ///< URDF links (bodies + massless chain links)
  int coordinates = 0, free_coordinates = 0;
  int muscles = 0, ligament_bundles = 0, ligament_groups = 0;
  int contacts = 0, surfaces = 0, coordinate_springs = 0;
  std::map<std::string, int> wrap_objects;  ///< by kind ("WrapCylinder", ...)
  int path_wraps = 0;                       ///< PathWraps of imported paths
  int not_imported = 0;                     ///< report entries not imported
  std::vector<std::string> copied_meshes;   ///< file names in DIR/Geometry
};

/// Converts `osim_path` into DIR (created if missing): DIR/<name>.urdf,
/// DIR/Geometry/<meshes>, DIR/import_report.md. Throws common::InputError
/// naming the .osim file and line on anything it cannot represent.
OsimImportSummary import_osim(const std::string& osim_path, const std::string& out_dir,
                              const OsimImportOptions& options = {});

}  // namespace arthrosim::musculoskeletal
