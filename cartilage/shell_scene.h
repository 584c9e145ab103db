#pragma once
// Named node sets, masked constraints and loads of the generic quad-mesh
// scene (issue 34; scene keys node_sets, constraints, loads, documented in
// docs/scenes.md and docs/shell_element.md section 2). Each definition is one
// text item "NAME: ..." so that any number of them fit in a scene list:
//
//   node_sets:   "NAME: box XMIN YMIN ZMIN XMAX YMAX ZMAX"   (mm, closed box)
//                "NAME: plane NX NY NZ D [TOL]"              (|n.x - D| <= TOL, n normalised; D, TOL mm; TOL 1e-3)
//                "NAME: nodes I J K ..."                       (0-based node indices, as in the output)
//                "NAME: all"
//                "NAME: group G"                               (nodes of the faces after an OBJ 'g' line naming G)
//                "NAME: vtk_point_field F V"                   (nodes whose VTK point field F equals V)
//                "NAME: vtk_cell_field F V"                    (nodes of the quads whose VTK cell field F equals V)
//   constraints: "SET: C C ... [= V V ...]" with C in ux uy uz dx dy dz (u = ux uy uz, d = dx dy dz, all = both):
//                the masked coordinates of the set's nodes (positions and
//                director components, global frame) are prescribed at their
//                reference value plus V (mm for u, dimensionless for d; 0 if
//                no values), reached linearly at the ramp time, or following
//                history H when the item ends with "history H".
//   loads:       "SET: force FX FY FZ"            total force [N], equal shares per node
//                "SET: force_per_node FX FY FZ"   [N] on every node of the set
//                "SET: traction TX TY TZ"         fixed-direction force per unit reference area [MPa]
//                                                 on the quads whose four nodes are in SET
//                "SET: gravity GX GY GZ"          body force rho g per unit volume [m/s^2], same quads
//                "SET: body_force FX FY FZ"       body force per unit volume [N/mm^3], same quads
//                each optionally followed by "history H" (default: the ramp
//                0 at t = 0 to 1 at end_time_s, constant after).
//   histories:   "H: ramp T"                      factor t / T, 1 after T [s]
//                "H: table T0 F0 T1 F1 ..."       (time [s], factor) pairs, times >= 0 strictly
//                                                 increasing; linear in between, F0 before T0,
//                                                 the last factor after the last time
//
// Distributed loads are lumped consistently: node a of a quad gets
// f integral(N_a dA) over the bilinear reference mid-surface (2 x 2 Gauss),
// and no director part (a load uniform through the thickness has none:
// integral of zeta over the thickness is zero).
#include <Eigen/Core>
#include <array>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "common/mesh.h"
#include "common/mesh_io.h"

namespace arthrosim::cartilage {

struct NodeSetDefinition {
  std::string name;
  enum class Kind { kBox, kPlane, kNodes, kAll, kGroup, kPointField, kCellField } kind = Kind::kAll;
  std::vector<double> numbers;  ///< box: 6 (SI); plane: unit normal (3), offset D and tolerance [m]
  std::vector<int> nodes;       ///< kNodes
  std::string group;            ///< kGroup; the field's name for kPointField, kCellField
  double field_value = 0;       ///< kPointField, kCellField: the value selected (exact equality)
};

/// Face groups of a mesh file (OBJ 'g' lines): group name -> quad indices.
using FaceGroups = common::FaceGroups;

/// A time history: a piecewise linear factor of time (scene key histories).
struct HistoryDefinition {
  std::string name;
  std::vector<double> time_s;  ///< strictly increasing, >= 0, at least one
  std::vector<double> factor;  ///< same size
  /// The factor at t: linear between points, constant outside them.
  double at(double t) const;
};

struct ConstraintDefinition {
  std::string set;
  std::string history;         ///< "" = the default ramp
  std::array<bool, 6> mask{};  ///< r_x, r_y, r_z, d_x, d_y, d_z
  Eigen::Matrix<double, 6, 1> value = Eigen::Matrix<double, 6, 1>::Zero();  ///< SI (m; 1)
  bool prescribed() const { return !value.isZero(0.0); }
};

struct LoadDefinition {
  std::string set;
  std::string history;  ///< "" = the default ramp
  enum class Kind { kForce, kForcePerNode, kTraction, kGravity, kBodyForce } kind = Kind::kForce;
  Eigen::Vector3d vector = Eigen::Vector3d::Zero();  ///< SI: N, N, Pa, m/s^2, N/m^3
};

/// Parsers of one item; std::invalid_argument with what is wrong otherwise.
NodeSetDefinition parse_node_set(const std::string& text);
ConstraintDefinition parse_constraint(const std::string& text);
LoadDefinition parse_load(const std::string& text);
HistoryDefinition parse_history(const std::string& text);

/// The nodes of `mesh` in the set (sorted, unique); an index out of range or
/// an unknown group throws std::invalid_argument.
std::vector<int> select_nodes(const NodeSetDefinition& set, const common::QuadMesh& mesh,
                              const FaceGroups& groups = {}, const std::vector<common::VtkField>& fields = {});

/// Consistent nodal forces of a fixed-direction force per unit area f [Pa]
/// on the quads whose four nodes are all in `nodes` (sorted): node a gets
/// f integral(N_a dA) over the bilinear reference quad. Result: per node
/// (N x 3) [N].
Eigen::MatrixXd consistent_area_loads(const common::QuadMesh& mesh, const std::vector<int>& nodes,
                                      const Eigen::Vector3d& f_Pa);

}  // namespace arthrosim::cartilage
