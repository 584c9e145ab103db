#include "biphasic/penetration.h"

#include <cmath>
#include <sstream>

#include "common/error.h"
#include "common/finite.h"

namespace arthrosim::biphasic {

PlacedSurface place_surface(const LayerMesh& mesh, double aggregate_modulus_Pa,
                            const Eigen::Isometry3d& X_WB) {
  common::QuadMesh surface = mesh.surface;
  surface.name = mesh.name;
  return place_surface(surface, mesh.normals, mesh.thickness, aggregate_modulus_Pa, X_WB);
}

PlacedSurface place_surface(const common::QuadMesh& surface, const common::Points3& normals,
                            const Eigen::VectorXd& thickness, double aggregate_modulus_Pa,
                            const Eigen::Isometry3d& X_WB) {
  PlacedSurface s;
  s.name = surface.name;
  const int nv = surface.num_nodes();
  s.nodes.resize(nv, 3);
  s.normals.resize(nv, 3);
  const Eigen::Matrix3d R = X_WB.linear();
  for (int v = 0; v < nv; ++v) {
    s.nodes.row(v) = (X_WB * Eigen::Vector3d(surface.V.row(v).transpose())).transpose();
    s.normals.row(v) = (R * Eigen::Vector3d(normals.row(v).transpose()).normalized()).transpose();
  }
  s.thickness = thickness;
  s.node_area = surface_node_areas(surface);
  s.triangles = common::triangulate(surface);
  s.triangles.V = s.nodes;
  s.triangles.name = surface.name;
  s.aggregate_modulus_Pa = aggregate_modulus_Pa;
  return s;
}

ContactConditions penetration_conditions(const PlacedSurface& self, const PlacedSurface& other,
                                         const common::TriangleTree& other_tree,
                                         double force_magnitude) {
  if (!std::isfinite(force_magnitude) || force_magnitude < 0.0) {
    std::ostringstream s;
    s << "penetration " << self.name << " / " << other.name
      << ": contact force magnitude: expected a finite value >= 0 N, found " << force_magnitude;
    throw common::InputError(s.str());
  }
  const int nv = static_cast<int>(self.nodes.rows());
  ContactConditions c;
  c.self = self.name;
  c.other = other.name;
  c.in_contact.assign(nv, 0);
  c.g_total = Eigen::VectorXd::Zero(nv);
  c.other_thickness = Eigen::VectorXd::Zero(nv);
  c.eta = Eigen::VectorXd::Zero(nv);
  c.strain = Eigen::VectorXd::Zero(nv);
  c.sigma_E = Eigen::VectorXd::Zero(nv);
  c.sigma_total = Eigen::VectorXd::Zero(nv);
  c.pressure = Eigen::VectorXd::Zero(nv);
  c.force_magnitude = force_magnitude;
  const double H_A = self.aggregate_modulus_Pa;
  const double H_B = other.aggregate_modulus_Pa;
  const double h_other_max = other.thickness.maxCoeff();

  for (int v = 0; v < nv; ++v) {
    const Eigen::Vector3d x = self.nodes.row(v).transpose();
    const Eigen::Vector3d n = self.normals.row(v).transpose();
    const double h_A = self.thickness[v];
    const auto hit = other_tree.first_hit(x, -n, h_A + h_other_max, common::HitSide::kBack);
    if (!hit) continue;
    const auto tri = other.triangles.F.row(hit->triangle);
    const double h_B = hit->barycentric[0] * other.thickness[tri[0]] +
                       hit->barycentric[1] * other.thickness[tri[1]] +
                       hit->barycentric[2] * other.thickness[tri[2]];
    const double g = hit->distance;
    if (g > h_A + h_B) ++c.nodes_beyond_thickness;
    const double eta = 1.0 / (1.0 + H_A * h_B / (H_B * h_A));
    c.in_contact[v] = 1;
    c.g_total[v] = g;
    c.other_thickness[v] = h_B;
    c.eta[v] = eta;
    c.strain[v] = eta * g / h_A;
    c.sigma_E[v] = H_A * c.strain[v];
    c.strain_integral += self.node_area[v] * c.strain[v] * n;
    c.contact_area += self.node_area[v];
    ++c.contact_nodes;
  }
  const double denom = c.strain_integral.norm();
  const bool unloaded = force_magnitude == 0.0 && c.contact_nodes > 0 && denom > 0.0;
  if (c.contact_nodes == 0 || !(denom > 0.0) || unloaded) {
    // No overlap: nothing to apply. With a force that is a reported skip.
    // No force: nothing to apply either (gamma = 0 would prescribe a fluid
    // tension -sigma_E on an unloaded surface); reported when they overlap.
    c.skipped_no_overlap = force_magnitude > 0.0;
    c.unloaded_overlap = unloaded;
    c.unloaded_overlap_area = unloaded ? c.contact_area : 0.0;
    c.in_contact.assign(nv, 0);
    c.g_total.setZero();
    c.eta.setZero();
    c.strain.setZero();
    c.sigma_E.setZero();
    c.contact_area = 0.0;
    c.contact_nodes = 0;
    return c;
  }
  c.gamma = force_magnitude / denom;
  for (int v = 0; v < nv; ++v) {
    if (!c.in_contact[v]) continue;
    c.sigma_total[v] = c.gamma * c.strain[v];
    c.pressure[v] = c.sigma_total[v] - c.sigma_E[v];
    if (c.pressure[v] < 0.0) ++c.nodes_negative_pressure;
  }
  const std::string where = "penetration " + self.name + " / " + other.name;
  common::check_finite(c.pressure, where + ": pressure");
  common::check_finite(c.sigma_total, where + ": total normal stress");
  return c;
}

SurfaceLoads surface_loads(const PlacedSurface& self, const std::vector<const ContactConditions*>& pairs,
                           const Eigen::Matrix3d& R_BW) {
  const int nv = static_cast<int>(self.nodes.rows());
  SurfaceLoads loads;
  loads.traction = Eigen::VectorXd::Zero(3 * nv);
  loads.pressure = Eigen::VectorXd::Zero(nv);
  for (int v = 0; v < nv; ++v) {
    const ContactConditions* best = nullptr;
    for (const ContactConditions* c : pairs) {
      if (c->in_contact[v] && (!best || c->g_total[v] > best->g_total[v])) best = c;
    }
    if (!best) continue;
    const Eigen::Vector3d n_W = self.normals.row(v).transpose();
    loads.traction.segment<3>(3 * v) = R_BW * (-best->sigma_total[v] * n_W);
    loads.pressure[v] = best->pressure[v];
  }
  return loads;
}

}  // namespace arthrosim::biphasic
