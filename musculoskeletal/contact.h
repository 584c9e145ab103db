#pragma once
// Elastic-foundation cartilage contact (Bei & Fregly 2004; Smith et al. 2016b;
// the contact of the lenhart2015 knee, seeds/002_3ffcc11eb7a447d9.txt).
//
// Two surfaces: the casting mesh (on body A; the smaller one, tibial or
// patellar cartilage) and the target mesh (on body B, femoral cartilage). For
// every casting triangle i with centre c_i, unit outward normal n_i (pointing
// towards the target) and area A_i, a ray from c_i along -n_i is intersected
// with the target mesh (in B's frame, so the AABB tree is built once). If the
// first hit lies at distance d_i <= d_max on a target triangle facing the
// caster (m . n_i < 0), the surfaces overlap by d_i and
//   linear     p_i = K d_i / h_i
//   nonlinear  p_i = -K ln(1 - d_i / h_i)        (requires d_i < h_i)
//   K = (1 - nu) E / ((1 + nu)(1 - 2 nu)),   h_i = t_A(i) + t_B(hit)
// (two layers of the same material in series: p = d / (h_1/K + h_2/K)).
// The caster receives f_i = -p_i A_i n_i at c_i, the target +p_i A_i n_i at
// the same point (equal and opposite, so the pair exerts no net wrench).
//
// Search acceleration (results are the same as a full tree query per triangle):
//  1. the last hit triangle of i and its edge neighbours are tried first with
//     an exact ray/triangle test (TriangleTree::hit_triangle);
//  2. for a triangle that had no hit, the distance D from the midpoint m0 of
//     its ray segment (c - L/2 n; L below) to the target surface is cached
//     (target frame); while |m - m0| + L/2 < D for the current midpoint m, the
//     whole segment lies inside the target-free ball of radius D about m0, so
//     the ray cannot hit and the query is skipped (rigorous; it also skips
//     triangles separated from the target by a gap, not only distant ones).
//  3. for a triangle whose last full query missed with a weak distance bound
//     (D - L/2 < mu, mu = 0.05 h_max: typically the ring around a contact
//     patch, where the target passes within L/2 of the ray's midpoint
//     sideways), the target triangles meeting the ray segment's bounding box
//     grown by mu were cached with the segment's end points; while both end
//     points stay within mu of the cached ones, the new segment lies in that
//     box, so only those triangles can be hit: they are tested with the same
//     exact ray/triangle test as the tree query (first hit, ties to the lower
//     index, as first_hit), which gives the tree query's result;
//  4. otherwise a full first_hit query (and on a miss a closest-point
//     refresh, and the box candidates of 3 when the bound is weak).
// Steps 2 and 3 work on the NEAR part of the segment, of length
// L = min(d_max, h_max) with h_max = d_max / max_overlap_factor the largest
// combined thickness (the whole segment for the bundled models). A longer
// search range (OpenSim-JAM's max_proximity, 20 mm over 6 mm of cartilage in
// lenhart2015) adds a FAR part [c + L dir, c + d_max dir] inside the casting
// body: the target triangles whose boxes meet it grown by M = h_max / 2 are
// cached (usually none) with its end points, and while both move less than M
// only they can be hit there; they are tested with the near part's
// candidates in steps 2 and 3 (the result is still the tree query's). With
// the whole long segment in one ball and one box instead, lenhart2015's
// stage 1 took 6.4 x the time (measured, docs/comak.md).
#include <Eigen/Geometry>
#include <memory>
#include <string>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::common {
class TriangleTree;
}

namespace arthrosim::musculoskeletal {

using common::Vec3;
using Pose = Eigen::Isometry3d;

enum class FoundationLaw { kLinear, kNonlinear };

struct ElasticFoundationParameters {
  /// Young's modulus E of the cartilage [Pa], > 0. lenhart2015: 10 MPa.
  double youngs_modulus = 10e6;
  /// Poisson ratio nu [-], 0 <= nu < 0.5. lenhart2015: 0.45.
  double poisson_ratio = 0.45;
  FoundationLaw law = FoundationLaw::kLinear;
  /// Rays are cast up to d_max = factor x (max casting thickness + max target
  /// thickness) [-], > 0. Deeper overlaps are not detected (they are beyond the
  /// layer thickness, where the foundation model has no meaning anyway).
  double max_overlap_factor = 1.0;
};

/// K = (1 - nu) E / ((1 + nu)(1 - 2 nu)) [Pa].
double foundation_modulus(const ElasticFoundationParameters& p);

/// One cartilage surface: mesh in its body's frame [m], thickness per triangle [m].
struct ContactSurface {
  int body = -1;
  common::TriangleMesh mesh;  ///< in the body frame [m]
  Eigen::VectorXd thickness;  ///< one entry per triangle, >= 0 (0 = rigid)
  // Provenance (set by the model loader; not used by the contact itself):
  std::string name;           ///< surface name in the model file
  std::string mesh_file;      ///< mesh file it was read from (empty: built in code)
  /// Pose of the mesh file's frame in the body frame (identity for
  /// frame="body", X_WB(0)^-1 for frame="reference"), so a replacement mesh
  /// in the file's frame (a prepared model) can be placed the same way.
  Pose X_BM = Pose::Identity();
  /// A tibial cartilage surface holding both plateaus: per triangle 1 lateral,
  /// 0 medial (the prepare stage's rule, common/compartments.h); empty when
  /// the surface is one compartment (or a patellar/femoral one). Set by the
  /// model loader (the model file's `split_lateral`, or the compartments of
  /// the prepared parts it was assembled from); only reported, never used by
  /// the contact itself (casting_force_by_compartment).
  std::vector<char> compartment;
  /// Medial-to-lateral direction in the mesh file's frame (the model file's
  /// `split_lateral`); zero when not declared. Kept so a replacement mesh (a
  /// prepared model) is split by the same rule.
  Vec3 lateral_M = Vec3::Zero();
  /// How `compartment` was made (written to the kinematics file).
  std::string compartment_rule;
};

/// Constant part of a contact pair (geometry precomputed, tree built once).
class ContactPair {
 public:
  /// Throws common::InputError (naming the pair) on empty meshes, thickness
  /// arrays of the wrong size, negative thickness or bad material values.
  ContactPair(std::string name, ContactSurface casting, ContactSurface target,
              ElasticFoundationParameters material);
  ~ContactPair();
  ContactPair(ContactPair&&) noexcept;
  ContactPair& operator=(ContactPair&&) noexcept;

  const std::string& name() const { return name_; }
  const ContactSurface& casting() const { return casting_; }
  const ContactSurface& target() const { return target_; }
  const ElasticFoundationParameters& material() const { return material_; }
  double modulus() const { return K_; }
  /// Longest ray: the largest possible combined thickness [m].
  double max_overlap() const { return d_max_; }

  // Precomputed geometry (casting: body-A frame; target: body-B frame).
  const common::Points3& casting_centres() const { return c_A_; }
  const common::Points3& casting_normals() const { return n_A_; }
  const Eigen::VectorXd& casting_areas() const { return area_A_; }
  const common::Points3& target_normals() const { return m_B_; }
  const common::Triangles& target_neighbours() const { return nbr_B_; }
  const common::TriangleTree& target_tree() const { return *tree_; }

 private:
  std::string name_;
  ContactSurface casting_, target_;
  ElasticFoundationParameters material_;
  double K_ = 0.0, d_max_ = 0.0;
  common::Points3 c_A_, n_A_, m_B_;
  Eigen::VectorXd area_A_;
  common::Triangles nbr_B_;
  std::unique_ptr<common::TriangleTree> tree_;
};

struct ContactResult {
  Vec3 force_on_target_W = Vec3::Zero();   ///< net force on the target body [N]
  Vec3 moment_on_target_W = Vec3::Zero();  ///< about the world origin [N m]
  Vec3 force_on_casting_W = Vec3::Zero();  ///< = -force_on_target_W
  Vec3 moment_on_casting_W = Vec3::Zero(); ///< about the world origin = -moment_on_target_W
  Vec3 center_of_pressure_W = Vec3::Zero();///< sum p A c / sum p A (zero if no contact)
  double contact_area = 0.0;               ///< sum of A_i with p_i > 0 [m^2]
  double max_pressure = 0.0;               ///< [Pa]
  double mean_pressure = 0.0;              ///< over the contact area [Pa]
  int num_contacting = 0;                  ///< triangles with p_i > 0
  Eigen::VectorXd pressure;                ///< per casting triangle [Pa]
  Eigen::VectorXd overlap;                 ///< per casting triangle [m]
};

/// The casting body's share of a pair's force per compartment of its
/// surface (ContactSurface::compartment), in the CASTING body's frame:
/// F_k = sum over the casting triangles i of compartment k of -p_i A_i n_i,
/// the same terms whose sum is force_on_casting_W (so medial + lateral equals
/// the total to round-off). cop_k = sum p_i A_i c_i / sum p_i A_i over those
/// triangles (casting body frame; zero without contact); area_k = sum A_i
/// with p_i > 0.
struct CompartmentForces {
  Vec3 medial = Vec3::Zero(), lateral = Vec3::Zero();
  Vec3 medial_cop = Vec3::Zero(), lateral_cop = Vec3::Zero();
  double medial_area = 0.0, lateral_area = 0.0;
};
/// InputError (naming the pair) when the casting surface has no compartment
/// labels or the result does not belong to the pair.
CompartmentForces casting_force_by_compartment(const ContactPair& pair, const ContactResult& result);

/// Search statistics of one evaluation.
struct ContactSearchStats {
  int guess_hits = 0;       ///< found via the cached triangle or its neighbours
  int skipped = 0;          ///< proven clear by the distance bound
  int tree_queries = 0;     ///< full ray queries
  int candidate_tests = 0;  ///< decided by the cached box candidates (step 3)
};

/// Workspace of one pair (cached guesses and results).
struct ContactPairData {
  std::vector<int> last_hit;           ///< per casting triangle, -1 none
  std::vector<double> clearance;       ///< cached distance D (NaN = unknown)
  common::Points3 clearance_centre_B;  ///< ray midpoint m0 of the cached distance
  /// Step 3: per casting triangle, whether box candidates are cached, the
  /// target triangles meeting the segment's box grown by mu, and the
  /// segment's end points (target frame) they were found for.
  std::vector<char> has_candidates;
  std::vector<std::vector<int>> candidates;
  common::Points3 candidate_start_B, candidate_end_B;
  /// Far part of a long segment (max_overlap_factor > 1, see the header):
  /// target triangles within M of it and its end points.
  std::vector<char> has_far;
  std::vector<std::vector<int>> far_candidates;
  common::Points3 far_start_B, far_end_B;
  ContactResult result;
  ContactSearchStats stats;
  /// Forget cached guesses (results are unchanged by this; only speed).
  void reset();
};

/// Evaluates the pair at body poses X_WA (casting body) and X_WB (target body).
/// Throws common::NumericalError naming the pair and triangle if the nonlinear
/// law is asked for an overlap >= the combined thickness.
void evaluate_contact(const ContactPair& pair, const Pose& X_WA, const Pose& X_WB,
                      ContactPairData& data);

}  // namespace arthrosim::musculoskeletal
