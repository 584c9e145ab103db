#pragma once
// A joint simulated by the penetration method: several cartilage layers (each
// on a rigid bone), contact pairs between them, and a sequence of measured
// frames (bone poses and the contact force of each compartment).
//
// Model (constant): the layers' volume meshes and matrices, one factorised
// LayerProblem per layer. Run:
//  1. preprocessing, per frame: place every layer's articular surface by its
//     bone pose, compute the penetration conditions of every pair in both
//     directions (penetration.h) and each layer's surface loads (traction in
//     its bone frame, surface pressure);
//  2. time stepping with a constant dt from the first to the last frame time:
//     each layer's loads are interpolated linearly between frames; one solve
//     per layer per step. The layers do not interact once the conditions are
//     set (that is the method: two independent linear problems per pair), so
//     they are stepped independently.
//  3. per step: the layer's nodal fields and the indicators of the issue
//     (contact area, fluid load support, maximum tensile stress on the
//     contact surface, maximum shear stress at the cartilage-bone interface,
//     with their regions).
// The state starts undeformed at the first frame time; the first frame's
// loads act as a step load from rest.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "biphasic/layer_fields.h"
#include "biphasic/layer_problem.h"
#include "biphasic/penetration.h"
#include "common/mesh.h"

namespace arthrosim::biphasic {

/// One cartilage layer as given (bone frame, SI).
struct JointLayer {
  std::string name;           ///< "femur", "tibia_medial", ...
  std::string bone;           ///< the bone it sits on: key into JointFrame::X_WB
  common::QuadMesh surface;   ///< articular quads, counter-clockwise seen from the joint space
  common::Points3 normals;    ///< per node, pointing away from the bone
  Eigen::VectorXd thickness;  ///< per node [m]
  Material material;
};

/// Two layers in contact and the compartment whose force loads them.
struct JointPair {
  std::string a, b;         ///< layer names
  std::string compartment;  ///< key into JointFrame::force_N, e.g. "medial"
};

/// One measured frame.
struct JointFrame {
  double time_s = 0.0;
  std::map<std::string, Eigen::Isometry3d> X_WB;  ///< pose of each bone in the world
  std::map<std::string, double> force_N;          ///< |F| of each compartment [N]
};

struct JointOptions {
  int element_layers = 4;
  /// Height ratio of successive element layers from the articular surface to
  /// the bone (1: equal; > 1: thinner at the surface). graded_levels().
  double grading = 1.0;
  ElementPair pair = ElementPair::kTaylorHood;
  TrapezoidalOptions time;  ///< dt and omega
  /// Regions: a node is central when its offset from the layer's area centroid
  /// is within this fraction of the layer's half extent along both the
  /// anterior and the lateral axis; otherwise anterior/posterior or
  /// lateral/medial by the larger normalised offset.
  double central_fraction = 1.0 / 3.0;
  Eigen::Vector3d anterior_B = Eigen::Vector3d::UnitX();  ///< in every bone frame
  Eigen::Vector3d lateral_B = Eigen::Vector3d::UnitZ();   ///< in every bone frame (right knee)
};

enum class Region { kCentral = 0, kAnterior = 1, kPosterior = 2, kMedial = 3, kLateral = 4 };
const char* to_string(Region region);

/// The penetration conditions of one pair at one frame, both directions.
struct PairFrame {
  ContactConditions a;  ///< conditions of layer a (from b)
  ContactConditions b;  ///< conditions of layer b (from a)
};

/// What one layer reports at one step.
struct LayerStep {
  NodalFields fields;
  SurfaceLoads loads;          ///< the interpolated loads applied at this step
  double contact_area_m2 = 0;  ///< area of the articular vertices with a prescribed contact traction
  /// Share of the contact force carried by the fluid: int p dG / int sigma_Tot dG
  /// over the contact area (0 when there is no contact).
  double fluid_load_support = 0.0;
  double max_tensile_Pa = 0.0;  ///< largest first principal sigma_E on the contact area
  int max_tensile_vertex = -1;  ///< articular vertex (-1: no contact)
  Region max_tensile_region = Region::kCentral;
  double max_shear_Pa = 0.0;    ///< largest (s1 - s3)/2 at the cartilage-bone interface
  int max_shear_vertex = -1;    ///< surface vertex whose bone-side node it is
  Region max_shear_region = Region::kCentral;
};

/// Vertices of each layer that are in contact in at least one frame, from the
/// full surfaces (preprocessing only, no finite elements). Checks as
/// JointRun::contact.
std::vector<std::vector<char>> contact_vertices(const std::vector<JointLayer>& layers,
                                                const std::vector<JointPair>& pairs,
                                                const std::vector<JointFrame>& frames);

/// The layer restricted to the quads with a vertex within `margin_m` of a
/// `seed` vertex (Euclidean distance in the bone frame), vertices renumbered;
/// `kept` (if given) receives the original index of each kept vertex. With no
/// seed vertex the result has no quads. The cut faces are free-draining and
/// traction-free like the layer's outline: far from every contact their
/// loads are zero, so the margin only needs to cover the decay of the
/// solution (docs/biphasic.md, "Cropping").
JointLayer crop_layer(const JointLayer& layer, const std::vector<char>& seed, double margin_m,
                      std::vector<int>* kept = nullptr);

class JointRun {
 public:
  /// Builds every layer (extrusion, assembly, one factorisation each) and
  /// checks the pairs name existing layers (InputError otherwise).
  JointRun(std::vector<JointLayer> layers, std::vector<JointPair> pairs, JointOptions options);

  const std::vector<JointLayer>& layers() const { return layers_; }
  const std::vector<JointPair>& pairs() const { return pairs_; }
  const LayerProblem& problem(int layer) const { return *problems_[layer]; }
  int layer_index(const std::string& name) const;  ///< -1 if none
  /// Surface vertices of a layer whose extrusion direction was smoothed so
  /// that no element folds (untangle_normals).
  const std::vector<int>& untangled(int layer) const { return untangled_[layer]; }
  /// Region of each articular vertex of a layer.
  const std::vector<Region>& regions(int layer) const { return regions_[layer]; }
  const JointOptions& options() const { return options_; }

  /// Preprocessing of one frame: the conditions of every pair (order of pairs()).
  /// Throws InputError naming the frame for a missing bone pose or force.
  std::vector<PairFrame> contact(const JointFrame& frame) const;
  /// Each layer's surface loads from the conditions of one frame.
  std::vector<SurfaceLoads> layer_loads(const JointFrame& frame, const std::vector<PairFrame>& conditions) const;

  /// Steps from the first to the last frame time (frames' times increasing;
  /// their loads from layer_loads). After each step `on_step(step, time,
  /// per-layer results)` is called in step order. Returns the number of
  /// steps.
  /// `first_step` > 1 continues a run whose layers were restored
  /// (LayerProblem::restore) to the state after step first_step - 1.
  int run(const std::vector<double>& frame_times, const std::vector<std::vector<SurfaceLoads>>& frame_loads,
          const std::function<void(int, double, const std::vector<LayerStep>&)>& on_step, int first_step = 1);
  /// Continues from a checkpoint: restores each layer's integrator state.
  void restore(const std::vector<TrapezoidalState>& states);
  /// What run() reported at step `step` (time t) of a run whose layers had the
  /// displacements u[l] and pressures p[l] after it: the results of a step
  /// already done, evaluated again (a resumed run rewrites its output).
  std::vector<LayerStep> results_at(const std::vector<double>& frame_times,
                                    const std::vector<std::vector<SurfaceLoads>>& frame_loads, double t,
                                    const std::vector<Eigen::VectorXd>& u, const std::vector<Eigen::VectorXd>& p) const;

 private:
  LayerStep evaluate(int layer, const SurfaceLoads& loads, const Eigen::VectorXd& u, const Eigen::VectorXd& p) const;
  void build_layer(int layer);

  std::vector<JointLayer> layers_;
  std::vector<JointPair> pairs_;
  JointOptions options_;
  std::vector<std::unique_ptr<LayerProblem>> problems_;
  std::vector<std::vector<Region>> regions_;
  std::vector<Eigen::VectorXd> node_areas_;
  std::vector<std::vector<int>> untangled_;
};

}  // namespace arthrosim::biphasic
