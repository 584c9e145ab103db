#pragma once
// The penetration method (seed 000, section IV, eqs 17-26): boundary
// conditions for two biphasic layers in contact, from the overlap of their
// undeformed articular surfaces placed by the measured bone poses.
//
// For each articular node x of layer A (unit normal n pointing into the joint
// space, thickness h_A, aggregate modulus H_A) a ray from x along -n finds the
// articular surface of layer B inside A (penetration g = distance, the
// normal component of the total penetration vector g n; eq 20). With the
// thickness h_B of B interpolated at the hit point:
//   eta   = 1 / (1 + H_A h_B / (H_B h_A))                              (24)
//   g_A   = eta g,  eps_nn = g_A / h_A                             (21, 23)
//   sigma_E_nn   = H_A eps_nn              (elastic normal stress, 19 + 23)
//   sigma_Tot_nn = gamma_A eps_nn                                      (25)
//   |F| = gamma_A | int_Gc eps_nn n dG |                               (26)
//   p = sigma_Tot_nn - sigma_E_nn                                       (17)
// Stresses here are COMPRESSIVE POSITIVE magnitudes (the seed's eq 17 in
// tension-positive form reads p = sigma_E_nn - sigma_Tot_nn with both
// negative). The integral of (26) uses the articular node areas
// int M_v dG (so the traction the FE applies integrates to |F| exactly).
// gamma_A follows from the magnitude |F| of the measured contact force of the
// compartment; the direction of the resulting force is that of the overlap.
//
// The layer then gets, on its contact nodes, the total traction
// t = -sigma_Tot_nn n and the pressure p (eq 17); outside the contact area
// its articular surface is free-draining (p = 0, no traction): the seed does
// not state this, it is the natural choice of an exposed surface bathed in
// synovial fluid (FEBio's sliding-biphasic contact does the same).
//
// A compartment whose measured force is zero gets no contact conditions even
// where the layers overlap (ContactConditions::unloaded_overlap).
//
// Units SI; positions of both layers in one common frame (the world).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "biphasic/layer_mesh.h"
#include "common/mesh.h"
#include "common/spatial.h"

namespace arthrosim::biphasic {

/// One layer's articular surface placed in the common frame for a frame.
struct PlacedSurface {
  std::string name;
  common::Points3 nodes;      ///< articular vertices in the common frame [m]
  common::Points3 normals;    ///< unit normals in the common frame
  Eigen::VectorXd thickness;  ///< [m]
  Eigen::VectorXd node_area;  ///< int M_v dG [m^2] (pose independent)
  common::TriangleMesh triangles;  ///< the quads split into triangles (same vertex indices)
  double aggregate_modulus_Pa = 0.0;
};

/// The surface of `mesh` moved by the pose X_WB of its bone (the mesh is in
/// the bone frame B).
PlacedSurface place_surface(const LayerMesh& mesh, double aggregate_modulus_Pa,
                            const Eigen::Isometry3d& X_WB);
/// The same from the surface data alone (unit normals, thickness per node).
PlacedSurface place_surface(const common::QuadMesh& surface, const common::Points3& normals,
                            const Eigen::VectorXd& thickness, double aggregate_modulus_Pa,
                            const Eigen::Isometry3d& X_WB);

/// Boundary conditions of one layer ("self") from its contact with one other
/// layer. Per-node arrays have one entry per articular vertex of self (zero
/// outside the contact area).
struct ContactConditions {
  std::string self, other;
  std::vector<char> in_contact;   ///< 1 where the ray from the node hit the other surface within reach
  Eigen::VectorXd g_total;        ///< total normal penetration g [m]
  Eigen::VectorXd other_thickness;  ///< h_B at the hit point [m]
  Eigen::VectorXd eta;            ///< split parameter (eq 24) [-]
  Eigen::VectorXd strain;         ///< eps_nn = eta g / h_A [-]
  Eigen::VectorXd sigma_E;        ///< H_A eps_nn [Pa], compressive positive
  Eigen::VectorXd sigma_total;    ///< gamma eps_nn [Pa], compressive positive
  Eigen::VectorXd pressure;       ///< sigma_total - sigma_E [Pa]
  double gamma = 0.0;             ///< [Pa] (0 when skipped)
  Eigen::Vector3d strain_integral = Eigen::Vector3d::Zero();  ///< int eps_nn n dG [m^2]
  double force_magnitude = 0.0;   ///< |F| the tractions were scaled to [N]
  double contact_area = 0.0;      ///< sum of the node areas in contact [m^2]
  int contact_nodes = 0;
  /// Nodes whose overlap exceeds both thicknesses (g > h_A + h_B): bone
  /// against bone, the method's assumption fails there (counted, not hidden).
  int nodes_beyond_thickness = 0;
  /// Nodes with p < 0 (gamma < H_A: the measured force is smaller than the
  /// elastic force of the overlap; the method then asks for fluid tension).
  int nodes_negative_pressure = 0;
  /// True when |F| > 0 but the surfaces do not overlap: no contact conditions
  /// are applied for this frame (a reported skip, never a division by zero).
  bool skipped_no_overlap = false;
  /// True when |F| = 0 but the surfaces overlap (stage 1 measured no load
  /// where this geometry overlaps): eq 26 would give gamma = 0 and eq 17 a
  /// fluid TENSION p = -sigma_E on an unloaded surface, so no contact
  /// conditions are applied (free-draining, no traction); the overlap's area
  /// is kept in unloaded_overlap_area. A reported skip.
  bool unloaded_overlap = false;
  double unloaded_overlap_area = 0.0;  ///< [m^2]
};

/// Rays from every node of `self` along -n, up to h_self + max h_other, hit
/// the back side of `other` (its normal points away from the joint space of
/// self, i.e. along the ray). `force_magnitude` [N] >= 0.
ContactConditions penetration_conditions(const PlacedSurface& self, const PlacedSurface& other,
                                         const common::TriangleTree& other_tree,
                                         double force_magnitude);

/// Surface loads of one layer at one frame: the nodal total traction
/// (3 per articular vertex, in the LAYER's (bone) frame) and the nodal
/// pressure of every articular vertex (0 outside contact).
struct SurfaceLoads {
  Eigen::VectorXd traction;  ///< 3 nv [Pa]
  Eigen::VectorXd pressure;  ///< nv [Pa]
};

/// Combines the conditions of every contact pair of one layer (a node in
/// contact with two layers takes the pair with the larger penetration).
/// `R_BW` rotates common-frame vectors into the layer's bone frame.
SurfaceLoads surface_loads(const PlacedSurface& self, const std::vector<const ContactConditions*>& pairs,
                           const Eigen::Matrix3d& R_BW);

}  // namespace arthrosim::biphasic
