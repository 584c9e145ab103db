#pragma once
// Parametric right knee at full extension: bones (closed surfaces) and
// articular cartilage (open patches with an analytically known thickness),
// plus anatomical landmarks. Used as the bundled model
// (data/models/knee_parametric/<resolution>/) and by tests and benchmarks.
//
// Model frame F (all meshes and landmarks): the femur frame at full extension.
//   origin: midpoint of the flexion axis through the centres of the posterior
//           femoral condyles (the circles fitted to their posterior arcs),
//   X: anterior, Y: superior (along the mechanical axis), Z: to the right,
//   i.e. lateral for this right knee (medial is -Z).
// Units: metres inside (files: STL in millimetres, landmarks.yaml in metres).
//
// Construction (docs/knee_geometry.md has the dimensions and their sources):
//   1. each bone is an implicit function f(p) (negative inside, roughly a
//      signed distance in metres) assembled from primitives with smooth
//      unions (polynomial smooth minimum);
//   2. f is sampled on a regular grid and contoured by marching tetrahedra
//      (Kuhn split of every cube: watertight, manifold, no ambiguous cases);
//   3. CGAL isotropic remeshing (common/remesh.h) to the target edge length,
//      then every vertex is projected onto f = 0 by Newton steps;
//   4. a cartilage patch is the part of its bone mesh where a smooth region
//      function r(p) >= 0 (clipped along r = 0, vertices close to the cut
//      snapped onto it), remeshed with its outline kept, and every vertex p
//      moved to p + t(p) n(p): n = grad f / |grad f| (analytic bone normal),
//      t = thickness field (1.5 mm on the outline, up to 2.8-3.5 mm in the
//      load-bearing centres). The thickness at every cartilage vertex is
//      therefore known exactly.
// The tibia and patella are designed against the femur (its surface is found
// numerically, not assumed) so that opposing cartilage surfaces overlap by a
// small designed amount at extension (contact_overlap, default 0.25 mm).
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/mesh.h"

namespace arthrosim::pipelines {

/// The three bones of the model.
enum class KneeBone { kFemur, kTibia, kPatella };
/// The two menisci: wedge-shaped C-rings of fibrocartilage on the tibial
/// plateau (dimensions and sources in docs/knee_geometry.md).
enum class KneeMeniscus { kMedial, kLateral };
/// The four cartilage patches of the model.
enum class KneeCartilage { kFemur, kTibiaMedial, kTibiaLateral, kPatella };

/// File stem of a bone ("femur_bone", "tibia_bone", "patella_bone").
std::string bone_file_stem(KneeBone bone);
/// File stem of a cartilage ("femur_cartilage", "tibia_medial_cartilage",
/// "tibia_lateral_cartilage", "patella_cartilage").
std::string cartilage_file_stem(KneeCartilage cartilage);
/// The bone a cartilage lies on.
KneeBone cartilage_bone(KneeCartilage cartilage);
/// File stem of a meniscus ("medial_meniscus", "lateral_meniscus"). A model
/// folder names a meniscus `<name>_meniscus.{stl,obj,ply}` (closed surface).
std::string meniscus_file_stem(KneeMeniscus meniscus);

struct KneeGeneratorOptions {
  /// Target edge length of every output mesh [m]. Range 0.5e-3 .. 6e-3
  /// (bundled: coarse 3e-3, medium 2e-3; fine 1e-3 is made on demand).
  double edge_length = 2e-3;
  /// Spacing of the implicit-function sampling grid [m]; 0 selects
  /// clamp(edge_length / 2.5, 0.4 mm, 1.0 mm). Range 0.2e-3 .. 2e-3.
  double grid_spacing = 0.0;
  /// Isotropic remeshing iterations. Range 1 .. 20.
  int remesh_iterations = 5;
  /// Per-cartilage target edge length [m] replacing edge_length for that
  /// patch only (same range), e.g. finer tibial than femoral triangles as in
  /// MR-derived meshes. A patch remeshed finer than its bone gets its base
  /// vertices projected back onto the bone's implicit surface (so the new
  /// vertices do not sit on the bone mesh's chords). Empty: all edge_length.
  std::map<KneeCartilage, double> cartilage_edge_length;
};

/// The fine resolution of the issue-3/4 benchmarks (about the triangle
/// counts of lenhart2015's MR-derived meshes: femoral cartilage ~30,000,
/// tibial ~8,600): edge 0.74 mm, tibial cartilage 0.57 mm. Generated on
/// demand (msk_bench, comak_bench), never committed.
KneeGeneratorOptions fine_knee_options();

struct KneeLandmark {
  std::string body;  ///< "femur", "tibia", "patella" or "limb"
  std::string name;  ///< e.g. "medial_condyle_centre"
  common::Vec3 p_F;  ///< position in the model frame [m]
  std::string note;  ///< how it is defined (written as a comment)
};

struct KneeCartilagePatch {
  KneeCartilage which = KneeCartilage::kFemur;
  /// Articular surface [m]; triangle normals point out of the cartilage
  /// (towards the joint space). Vertices are numbered in order of first use
  /// by F, so a binary STL round trip with vertex welding keeps the order.
  common::TriangleMesh mesh;
  /// Analytic cartilage thickness at every vertex [m] (distance from the
  /// bone along the bone normal).
  Eigen::VectorXd thickness;
  /// For every vertex, the bone surface point it was offset from [m].
  common::Points3 bone_points;
};

struct KneeGeometry {
  common::TriangleMesh femur_bone;    ///< closed, outward oriented [m]
  common::TriangleMesh tibia_bone;    ///< closed, outward oriented [m]
  common::TriangleMesh patella_bone;  ///< closed, outward oriented [m]
  std::vector<KneeCartilagePatch> cartilage;  ///< femur, tibia medial, tibia lateral, patella
  common::TriangleMesh medial_meniscus;   ///< closed, outward oriented [m]
  common::TriangleMesh lateral_meniscus;  ///< closed, outward oriented [m]
  std::vector<KneeLandmark> landmarks;
  double contact_overlap = 0.0;  ///< designed overlap the shape was fitted with [m]

  const common::TriangleMesh& bone(KneeBone b) const;
  const KneeCartilagePatch& patch(KneeCartilage c) const;
  const common::TriangleMesh& meniscus(KneeMeniscus m) const;
};

/// The analytic shape: bone implicit functions, cartilage region and thickness
/// fields. Construction tabulates the femoral surface the patella and tibia are
/// fitted to (a fraction of a second).
class ParametricKnee {
 public:
  /// contact_overlap: designed overlap of opposing cartilage surfaces at their
  /// first contact point (femoral condyle vs tibial plateau centre, trochlea
  /// vs patellar ridge) [m]. Range 0 .. 0.5e-3.
  explicit ParametricKnee(double contact_overlap = 0.25e-3);
  ~ParametricKnee();
  ParametricKnee(const ParametricKnee&) = delete;
  ParametricKnee& operator=(const ParametricKnee&) = delete;

  /// Implicit function of a bone at p [m]: negative inside, zero on the
  /// surface, roughly the signed distance [m] near the surface.
  double implicit(KneeBone bone, const common::Vec3& p_F) const;
  /// Outward unit normal of the implicit surface at p (normalised gradient).
  common::Vec3 normal(KneeBone bone, const common::Vec3& p_F) const;
  /// Cartilage region function at a bone surface point p with outward normal
  /// n [m]: positive inside the articular area, zero on its outline.
  double region(KneeCartilage cartilage, const common::Vec3& p_F, const common::Vec3& n_F) const;
  /// Cartilage thickness [m] at a bone surface point (1.5 mm on and outside
  /// the outline, at most 3.5 mm).
  double thickness(KneeCartilage cartilage, const common::Vec3& p_F, const common::Vec3& n_F) const;
  /// Axis-aligned box [m] enclosing a bone, with a margin of a few mm.
  void bounds(KneeBone bone, common::Vec3* lo, common::Vec3* hi) const;
  /// Implicit function of a meniscus (negative inside, roughly the signed
  /// distance near the surface) [m]. Its lower face follows the tibial
  /// articular surface (cartilage where there is cartilage, bone elsewhere),
  /// its upper face rises linearly from the thin inner edge to the peripheral
  /// height and stays clear of the femoral articular surface above.
  double meniscus_implicit(KneeMeniscus meniscus, const common::Vec3& p_F) const;
  /// Axis-aligned box [m] enclosing a meniscus, with a margin of a few mm.
  void meniscus_bounds(KneeMeniscus meniscus, common::Vec3* lo, common::Vec3* hi) const;
  /// Landmarks (femur, tibia, patella, limb) in the model frame.
  std::vector<KneeLandmark> landmarks() const;

  /// Meshes everything (deterministic: same options, identical output).
  KneeGeometry generate(const KneeGeneratorOptions& options) const;

  struct Impl;

 private:
  Impl* impl_;
};

/// Contours an implicit function sampled on a grid by marching tetrahedra
/// (each cube split into 6 tetrahedra around its main diagonal; vertices by
/// linear interpolation along grid edges, kept 1% of an edge away from grid
/// nodes so no triangle is degenerate). The result is closed, manifold and oriented with
/// normals towards f > 0 provided the zero set does not reach the box.
/// Exposed for tests (a sphere has a closed form).
common::TriangleMesh contour_implicit(const std::function<double(const common::Vec3&)>& f,
                                      const common::Vec3& lo, const common::Vec3& hi,
                                      double spacing, const std::string& name);

/// The part of `mesh` where the per-vertex values r >= 0 (linear along
/// edges), cut along r = 0. Vertices whose cut point lies within
/// snap_fraction of an edge length are moved onto the cut instead (no
/// slivers). Orientation is kept; unused vertices are dropped.
common::TriangleMesh clip_by_vertex_field(const common::TriangleMesh& mesh,
                                          const Eigen::VectorXd& r, double snap_fraction,
                                          const std::string& name);

/// Overlap of two articular surfaces facing each other.
struct SurfaceOverlap {
  double max_depth = 0.0;       ///< largest penetration of a vertex of `a` past `b` [m] (0 if none)
  int penetrating_vertices = 0; ///< vertices of `a` past `b`
  common::Vec3 at = common::Vec3::Zero();  ///< the deepest vertex of `a` [m]
};
/// For every vertex v of `a` a ray is cast from v along -n_a(v) (into a's
/// cartilage) up to `search_depth`; if it first meets a triangle of `b` whose
/// normal points along the ray, v lies past b's articular surface by the hit
/// distance (the elastic-foundation overlap depth measured from a).
SurfaceOverlap surface_overlap(const common::TriangleMesh& a, const common::TriangleMesh& b,
                               double search_depth = 3e-3);

/// Writes a generated model to `dir` (created if missing): one binary STL per
/// surface in millimetres (file stems above; the menisci as
/// medial_meniscus.stl and lateral_meniscus.stl), <cartilage>_thickness.csv
/// (one row per vertex of the STL after welding: x_mm,y_mm,z_mm,thickness_mm)
/// and landmarks.yaml (metres, model frame).
void write_knee_geometry(const KneeGeometry& geometry, const KneeGeneratorOptions& options,
                         const std::string& dir);

/// Reads a <cartilage>_thickness.csv written by write_knee_geometry and checks
/// that its rows match the vertices of `mesh` (read from the STL with welding)
/// to 1e-6 m; returns the thickness per vertex [m]. InputError (file:line)
/// on any mismatch or malformed line.
Eigen::VectorXd read_thickness_csv(const std::string& path, const common::TriangleMesh& mesh);

}  // namespace arthrosim::pipelines
