#pragma once
// The knee of the shockwave model (seed section 2.2, Figures 1-2): the
// epiphyseal parts of femur and tibia (cortical shell of a stated thickness
// around a cancellous interior, cut at a distance from the joint line), the
// articular cartilage, the menisci, all in a box imitating the joint capsule
// (fibrous tissue inside, a shell outside), and the copper applicator on a
// face of the box. The patella is left out, as in the seed.
//
// Every lattice site of the box gets one tissue, by priority:
//   applicator > cortical / cancellous bone > cartilage > fibrocartilage
//   (menisci) > capsule shell > fibrous tissue.
//  - bone: inside the closed bone mesh (LineContainment); cortical where the
//    distance to the bone surface (CGAL closest point) is at most the
//    cortical thickness;
//  - cartilage: outside the bones, between the bone and the articular
//    surface: the ray from the nearest bone point through the site meets the
//    articular surface at or beyond the site;
//  - menisci: inside a closed meniscus mesh;
//  - capsule shell: within the shell thickness of the box faces.
// The applicator (20 x 20 mm, 1 mm by default) lies outside the box on one of
// its side faces, in contact; it takes max(1, round(thickness / h)) lattice
// layers (h the layer spacing) and its density is scaled so that its mass per
// area is that of the plate (the plate is acoustically thin: 0.2 us transit).
// The pulse acts on its outer layer.
//
// Frame: the model frame of the knee meshes (metres), Y superior.
#include <array>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "common/mesh.h"
#include "shockwave/model.h"

namespace arthrosim::shockwave {

/// Tissue ids of a knee model (index into Model::tissues).
enum KneeTissue : int {
  kCortical = 0,
  kCancellous = 1,
  kCartilage = 2,
  kFibrocartilage = 3,
  kFibrous = 4,
  kCapsuleShell = 5,
  kApplicator = 6,
  kKneeTissueCount = 7
};
/// "cortical", "cancellous", "cartilage", "fibrocartilage", "fibrous",
/// "capsule_shell", "applicator".
const char* knee_tissue_name(int tissue);

enum class BoneId { kFemur, kTibia };

struct CartilageSurface {
  std::string name;                ///< e.g. "femur", "tibia_medial"
  BoneId bone = BoneId::kFemur;
  common::TriangleMesh articular;  ///< articular surface (open patch) [m]
  /// Thickness per vertex [m] (for the thickness check; may be empty, then
  /// measured by casting from the vertices to the bone).
  Eigen::VectorXd thickness;
};

struct KneeMeshes {
  common::TriangleMesh femur;  ///< closed bone surface [m]
  common::TriangleMesh tibia;  ///< closed bone surface [m]
  std::vector<CartilageSurface> cartilage;
  /// Closed meniscus surfaces, with their names ("medial", "lateral").
  std::vector<std::pair<std::string, common::TriangleMesh>> menisci;
};

/// The faces of the capsule box the applicator can sit on, named in the model
/// frame (+-X anterior/posterior, +-Z).
enum class BoxFace { kMinusX, kPlusX, kMinusZ, kPlusZ };
/// "-x", "+x", "-z", "+z".
std::string to_string(BoxFace face);
BoxFace parse_box_face(const std::string& text, const std::string& source);

struct ApplicatorOptions {
  /// The box face it lies on; for the bundled right knee -z is medial.
  BoxFace face = BoxFace::kMinusZ;
  /// Centre of the plate [m], model frame; the coordinate along the face
  /// normal is ignored (the plate touches the face). NaN: the default
  /// placement, over the centroid of the meniscus named "medial" (or the
  /// box centre at the joint line without menisci), as in the seed's Fig. 2c.
  common::Vec3 centre = common::Vec3::Constant(std::numeric_limits<double>::quiet_NaN());
  double size = 20e-3;       ///< edge of the square plate [m]; range (0, 0.1]
  double thickness = 1e-3;   ///< [m]; range (0, 0.01]
};

struct KneeModelOptions {
  LatticeKind lattice = LatticeKind::kFcc;
  double diameter = 1e-3;             ///< automaton diameter d [m]; range [0.3e-3, 5e-3]
  /// Y of the joint line [m]; NaN: the mean height of the tibial articular
  /// surfaces (the midpoint of the bones' facing extremes without them).
  double joint_line = std::numeric_limits<double>::quiet_NaN();
  double femur_cut = 40e-3;           ///< femur kept up to this distance above the joint line [m]
  double tibia_cut = 40e-3;           ///< tibia kept down to this distance below it [m]
  double capsule_margin = 5e-3;       ///< fibrous tissue around the bones' extent [m]
  double shell_thickness = 2e-3;      ///< capsule shell [m]
  double cortical_thickness = 2e-3;   ///< cortical shell of the bones [m]
  ApplicatorOptions applicator;
  /// Tissue parameters, indexed by KneeTissue (default: Table 1, copper).
  std::vector<Tissue> tissues;
  PoreFluid fluid;
};

/// The default tissues (Table 1 and copper), indexed by KneeTissue.
std::vector<Tissue> default_knee_tissues();

struct KneeModelInfo {
  common::Vec3 box_lo = common::Vec3::Zero(), box_hi = common::Vec3::Zero();  ///< capsule box [m]
  double joint_line = 0.0;                       ///< [m]
  common::Vec3 applicator_centre = common::Vec3::Zero();  ///< centre of its inner face [m]
  common::Vec3 applicator_normal = common::Vec3::Zero();  ///< into the box
  int applicator_layers = 0;
  double applicator_density = 0.0;               ///< effective [kg/m^3]
  std::vector<std::int64_t> automata;            ///< per tissue
  double max_cartilage_thickness = 0.0;          ///< [m]
  double max_meniscus_height = 0.0;              ///< [m]
};

/// Builds the knee. InputError (naming `source`) when an automaton is larger
/// than a tissue's thickness (cortical or capsule shell, the thickest
/// cartilage, the highest meniscus), a tissue ends up with no automaton, the
/// applicator does not lie on the capsule box, or a tissue is invalid.
Model build_knee_model(const KneeMeshes& meshes, const KneeModelOptions& options, KneeModelInfo* info,
                       const std::string& source = "shockwave knee");

}  // namespace arthrosim::shockwave
