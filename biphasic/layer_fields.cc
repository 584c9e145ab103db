#include "biphasic/layer_fields.h"

#include <Eigen/Eigenvalues>

namespace arthrosim::biphasic {

Eigen::Matrix<double, 1, 6> to_voigt(const Eigen::Matrix3d& s) {
  Eigen::Matrix<double, 1, 6> v;
  v << s(0, 0), s(1, 1), s(2, 2), s(0, 1), s(1, 2), s(0, 2);
  return v;
}

Eigen::Matrix3d from_voigt(const Eigen::Matrix<double, 1, 6>& v) {
  Eigen::Matrix3d s;
  s << v[0], v[3], v[5], v[3], v[1], v[4], v[5], v[4], v[2];
  return s;
}

Eigen::Vector3d principal_values(const Eigen::Matrix<double, 1, 6>& s) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(from_voigt(s), Eigen::EigenvaluesOnly);
  return eig.eigenvalues();
}

NodalFields nodal_fields(const LayerSystem& sys, const Eigen::VectorXd& u, const Eigen::VectorXd& p) {
  const LayerMesh& m = sys.mesh;
  const int n = m.num_q1_nodes();
  NodalFields f;
  f.displacement.resize(n, 3);
  f.pressure = p;
  f.effective_stress = Eigen::Matrix<double, Eigen::Dynamic, 6>::Zero(n, 6);
  f.total_stress = Eigen::Matrix<double, Eigen::Dynamic, 6>::Zero(n, 6);
  f.flux = common::Points3::Zero(n, 3);
  Eigen::VectorXd count = Eigen::VectorXd::Zero(n);
  // Corner c of an element: reference point (+-1, +-1, +-1) in hex_basis order.
  for (int el = 0; el < m.num_elements(); ++el) {
    for (int c = 0; c < 8; ++c) {
      const Eigen::Vector3d xi(c & 1 ? 1.0 : -1.0, c & 2 ? 1.0 : -1.0, c & 4 ? 1.0 : -1.0);
      const PointFields pf = evaluate_point(sys, el, xi, u, p);
      const int node = m.hex_q1(el, c);
      f.effective_stress.row(node) += to_voigt(pf.effective_stress);
      f.total_stress.row(node) += to_voigt(pf.total_stress);
      f.flux.row(node) += pf.flux.transpose();
      count[node] += 1.0;
    }
  }
  for (int node = 0; node < n; ++node) {
    f.effective_stress.row(node) /= count[node];
    f.total_stress.row(node) /= count[node];
    f.flux.row(node) /= count[node];
  }
  // Displacement of the corner nodes (they are displacement nodes too).
  for (int v = 0; v < m.num_vertices(); ++v) {
    for (int L = 0; L <= m.layers; ++L) {
      const int u_node = sys.pair == ElementPair::kTaylorHood ? m.q2_node(m.vertex_entity(v), 2 * L) : m.q1_node(v, L);
      f.displacement.row(m.q1_node(v, L)) = u.segment<3>(3 * u_node).transpose();
    }
  }
  f.max_principal.resize(n);
  f.max_shear.resize(n);
  for (int node = 0; node < n; ++node) {
    const Eigen::Vector3d s = principal_values(f.effective_stress.row(node));
    f.max_principal[node] = s[2];
    f.max_shear[node] = 0.5 * (s[2] - s[0]);
  }
  return f;
}

}  // namespace arthrosim::biphasic
