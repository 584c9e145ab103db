#pragma once
// Volume mesh of a cartilage layer: an articular quad surface extruded along
// its node normals, through the per-node thickness, down to the bone, in
// `layers` element layers of equal parametric height.
//
// Geometry. Surface node v at x_v with unit normal n_v (pointing away from the
// bone, into the joint space) and thickness h_v > 0 lies on the bone at
// x_v - h_v n_v. Level s in [0, 1] of the layer (0 bone, 1 articular surface)
// is at x_v - (1 - s) h_v n_v; corner level L is at s_L (equal steps L / N by
// default). Each element is the trilinear hexahedron
// spanned by its 8 corners (subparametric for the quadratic field: the
// displacement nodes sit where the trilinear map puts them).
//
// Nodes. Two node sets share the geometry:
//  - pressure / corner nodes (Q1): surface vertex v at corner level L = 0..N,
//    index v * (N + 1) + L;
//  - displacement nodes (Q2): surface entity e (vertices, then unique edges,
//    then quads) at level l = 0..2N, index e * (2N + 1) + l; a vertex entity
//    is at the vertex, an edge entity at the edge midpoint, a quad entity at
//    the quad's parametric centre.
// Element (q, L) (surface quad q, element layer L = 0 at the bone) has index
// q * N + L. Its local node order is that of hex_basis.h with the first two
// reference coordinates those of the surface quad (corner 0 at (-1, -1),
// corner 1 at (1, -1), corner 2 at (1, 1), corner 3 at (-1, 1)) and the third
// running from the bone (-1) to the articular side (+1); with a quad that is
// counter-clockwise seen from the joint space the element is right-handed.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::biphasic {

struct LayerMesh {
  std::string name;                 ///< label for messages
  int layers = 0;                   ///< element layers through the thickness (N)
  common::QuadMesh surface;         ///< articular surface (as given)
  common::Points3 normals;          ///< unit node normals of the surface (away from bone)
  Eigen::VectorXd thickness;        ///< per surface node [m]
  std::vector<double> levels;       ///< corner level fractions s_L, L = 0..N (0 bone, 1 surface)
  Eigen::Matrix<int, Eigen::Dynamic, 2> edges;       ///< unique surface edges (a < b)
  Eigen::Matrix<int, Eigen::Dynamic, 4> quad_edges;  ///< per quad: edges of sides 01, 12, 23, 30

  common::Points3 q1_nodes;  ///< pressure / corner nodes [m]
  common::Points3 q2_nodes;  ///< displacement nodes [m]
  Eigen::Matrix<int, Eigen::Dynamic, 8> hex_q1;   ///< per element, corner nodes (hex_basis order)
  Eigen::Matrix<int, Eigen::Dynamic, 27> hex_q2;  ///< per element, displacement nodes

  std::vector<int> periphery_vertices;  ///< surface vertices on the outline (sorted)
  std::vector<int> periphery_edges;     ///< surface edges on the outline (sorted)

  int num_vertices() const { return static_cast<int>(surface.V.rows()); }
  int num_quads() const { return static_cast<int>(surface.Q.rows()); }
  int num_edges() const { return static_cast<int>(edges.rows()); }
  int num_elements() const { return num_quads() * layers; }
  int num_q1_nodes() const { return static_cast<int>(q1_nodes.rows()); }
  int num_q2_nodes() const { return static_cast<int>(q2_nodes.rows()); }

  /// Corner node of surface vertex v at corner level L (0 bone .. N articular).
  int q1_node(int v, int L) const { return v * (layers + 1) + L; }
  /// Displacement node of surface entity e at level l (0 bone .. 2N articular).
  int q2_node(int entity, int l) const { return entity * (2 * layers + 1) + l; }
  int vertex_entity(int v) const { return v; }
  int edge_entity(int e) const { return num_vertices() + e; }
  int quad_entity(int q) const { return num_vertices() + num_edges() + q; }
  int element(int q, int L) const { return q * layers + L; }

  /// Node sets (sorted). order 1: corner nodes, order 2: displacement nodes.
  std::vector<int> bone_nodes(int order) const;       ///< on the bone (level 0)
  std::vector<int> articular_nodes(int order) const;  ///< on the articular surface
  std::vector<int> periphery_nodes(int order) const;  ///< on the side faces (outline x all levels)
  /// Articular node of surface vertex v (order 1 or 2).
  int articular_node(int order, int v) const {
    return order == 1 ? q1_node(v, layers) : q2_node(vertex_entity(v), 2 * layers);
  }
  /// Bone-side node of surface vertex v.
  int bone_node(int order, int v) const {
    return order == 1 ? q1_node(v, 0) : q2_node(vertex_entity(v), 0);
  }
};

/// Checks the surface data extrude_layer needs (same errors as it): at least
/// one quad, indices in range, finite coordinates, a non-zero finite normal
/// and a finite thickness > 0 at every node.
void validate_surface_data(const common::QuadMesh& surface, const common::Points3& normals,
                           const Eigen::VectorXd& thickness);

/// Builds the layer mesh. `normals` (one row per surface node) are normalised
/// here; `thickness` [m] per surface node. Throws common::InputError naming
/// `surface.name` and the node / quad for: layers < 1, a non-finite or
/// non-positive thickness, a zero or non-finite normal, a quad index out of
/// range, or an element whose trilinear Jacobian is not positive at a corner
/// (thickness too large for the surface curvature, inverted quad).
/// `level_fractions` (optional, N + 1 values from 0 at the bone to 1 at the
/// articular surface, strictly increasing) places the corner levels; empty
/// means equal heights. Displacement mid-levels sit half way between.
LayerMesh extrude_layer(const common::QuadMesh& surface, const common::Points3& normals,
                        const Eigen::VectorXd& thickness, int layers,
                        const std::vector<double>& level_fractions = {});

/// Extrusion directions that do not turn an element inside out. Where a
/// quad's one-layer element would have a non-positive corner Jacobian (the
/// bone-side face folds: adjacent normals diverge strongly over a short edge
/// compared with the thickness, typically at a sharp outline), the normals
/// of that quad's vertices are replaced by the normalised average of the
/// normals of the quads around them; repeated up to `max_rounds` times.
/// Returns the vertices whose normal changed (sorted); throws
/// common::InputError naming the quads still inverted after that.
std::vector<int> untangle_normals(const common::QuadMesh& surface, common::Points3* normals,
                                  const Eigen::VectorXd& thickness, int max_rounds = 20);

/// Corner positions (8 x 3, hex_basis order) of element `element`.
Eigen::Matrix<double, 8, 3> element_corners(const LayerMesh& mesh, int element);

/// Corner level fractions of `layers` element layers whose heights grow
/// geometrically by `ratio` from the articular surface to the bone (ratio 1:
/// equal heights; ratio > 1: the element at the surface is the thinnest).
std::vector<double> graded_levels(int layers, double ratio);

/// Area-weighted integrals of the bilinear surface basis: a[v] = integral over
/// the articular surface of the bilinear hat function of vertex v [m^2]
/// (2 x 2 Gauss rule per quad: exact for planar quads). Sum = surface area.
Eigen::VectorXd articular_node_areas(const LayerMesh& mesh);
/// The same for any quad surface.
Eigen::VectorXd surface_node_areas(const common::QuadMesh& surface);

/// Volume of the layer [m^3] (Gauss 2 x 2 x 2 on each trilinear element, exact).
double layer_volume(const LayerMesh& mesh);

}  // namespace arthrosim::biphasic
