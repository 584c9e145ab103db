#include "biphasic/layer_system.h"

#include <array>
#include <cmath>
#include <sstream>
#include <vector>

#include "biphasic/hex_basis.h"
#include "common/error.h"

namespace arthrosim::biphasic {
namespace {

using Triplets = std::vector<Eigen::Triplet<double>>;
using Sparse = Eigen::SparseMatrix<double>;

// Sums triplets into a sparse matrix in chunks, so the triplet list of a large
// layer never holds all element entries at once.
class ChunkedAssembler {
 public:
  ChunkedAssembler(int rows, int cols) : sum_(rows, cols) {}
  void add(int i, int j, double v) {
    triplets_.emplace_back(i, j, v);
    if (triplets_.size() >= kChunk) flush();
  }
  Sparse finish() {
    flush();
    sum_.makeCompressed();
    return std::move(sum_);
  }

 private:
  static constexpr size_t kChunk = 4'000'000;
  void flush() {
    if (triplets_.empty()) return;
    Sparse part(sum_.rows(), sum_.cols());
    part.setFromTriplets(triplets_.begin(), triplets_.end());
    sum_ = sum_.nonZeros() == 0 ? part : Sparse(sum_ + part);
    triplets_.clear();
  }
  Sparse sum_;
  Triplets triplets_;
};

struct Geometry {
  double det = 0.0;
  Eigen::Matrix3d inverse;  // dxi/dx
};

Geometry geometry_at(const Eigen::Matrix<double, 8, 3>& X, const Eigen::MatrixXd& dM,
                     const LayerMesh& mesh, int element) {
  const Eigen::Matrix3d J = X.transpose() * dM;  // J(i, r) = dx_i / dxi_r
  Geometry g;
  g.det = J.determinant();
  if (!(g.det > 0.0) || !std::isfinite(g.det)) {
    std::ostringstream s;
    s << "layer '" << mesh.name << "': element " << element
      << ": expected a positive volume Jacobian at a quadrature point, found " << g.det;
    throw common::InputError(s.str());
  }
  // dN/dx = dN/dxi * dxi/dx; rows of dN are nodes: grad = dN * J^{-1}.
  g.inverse = J.inverse();
  return g;
}

}  // namespace

const char* to_string(ElementPair pair) {
  return pair == ElementPair::kTaylorHood ? "taylor_hood_q2q1" : "equal_order_q1q1";
}

LayerSystem assemble_layer(LayerMesh mesh, const Material& material, ElementPair pair) {
  const int layers = mesh.layers;
  return assemble_layer(std::move(mesh), std::vector<Material>(layers, material), pair);
}

LayerSystem assemble_layer(LayerMesh mesh, const std::vector<Material>& layer_materials,
                           ElementPair pair) {
  if (static_cast<int>(layer_materials.size()) != mesh.layers) {
    throw common::InputError("layer '" + mesh.name + "': expected one material per element layer (" +
                             std::to_string(mesh.layers) + "), found " +
                             std::to_string(layer_materials.size()));
  }
  for (const Material& material : layer_materials) validate(material, "layer '" + mesh.name + "'");
  LayerSystem sys;
  sys.mesh = std::move(mesh);
  sys.materials = layer_materials;
  sys.pair = pair;
  const LayerMesh& m = sys.mesh;
  const int order = sys.u_order();
  const int nn = hex_nodes(order);
  const int nu = sys.num_u_dofs();
  const int np = sys.num_p_dofs();

  const QuadratureRule rule = hex_rule(order == 2 ? 3 : 2);
  // Reference bases at the quadrature points (the same for every element).
  std::vector<Eigen::VectorXd> Mq(rule.points.size()), Nq(rule.points.size());
  std::vector<Eigen::MatrixXd> dMq(rule.points.size()), dNq(rule.points.size());
  for (size_t g = 0; g < rule.points.size(); ++g) {
    hex_basis(1, rule.points[g], &Mq[g], &dMq[g]);
    hex_basis(order, rule.points[g], &Nq[g], &dNq[g]);
  }

  ChunkedAssembler Kasm(nu, nu), Aasm(nu, np), Basm(np, np);
  Eigen::MatrixXd Ke(3 * nn, 3 * nn), Ae(3 * nn, 8);
  Eigen::Matrix<double, 8, 8> Be;
  std::vector<int> udof(3 * nn);
  std::array<int, 8> pdof{};
  for (int el = 0; el < m.num_elements(); ++el) {
    const Eigen::Matrix<double, 8, 3> X = element_corners(m, el);
    const Material& material = sys.element_material(el);
    const double lambda = material.lame_lambda();
    const double mu = material.shear_modulus();
    const double k = material.permeability_m4_per_Ns;
    Ke.setZero();
    Ae.setZero();
    Be.setZero();
    for (size_t g = 0; g < rule.points.size(); ++g) {
      const Geometry geo = geometry_at(X, dMq[g], m, el);
      const double w = rule.weights[g] * geo.det;
      const Eigen::MatrixXd G = dNq[g] * geo.inverse;   // nn x 3 physical gradients
      const Eigen::MatrixXd Gm = dMq[g] * geo.inverse;  // 8 x 3
      const Eigen::MatrixXd GG = G * G.transpose();
      for (int a = 0; a < nn; ++a) {
        for (int b = 0; b < nn; ++b) {
          const double dot = GG(a, b);
          for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j) {
              double v = lambda * G(a, i) * G(b, j) + mu * G(a, j) * G(b, i);
              if (i == j) v += mu * dot;
              Ke(3 * a + i, 3 * b + j) += w * v;
            }
          }
        }
        for (int c = 0; c < 8; ++c)
          for (int i = 0; i < 3; ++i) Ae(3 * a + i, c) += w * G(a, i) * Mq[g][c];
      }
      Be.noalias() += (w * k) * (Gm * Gm.transpose());
    }
    for (int a = 0; a < nn; ++a)
      for (int i = 0; i < 3; ++i) udof[3 * a + i] = 3 * sys.u_node(el, a) + i;
    for (int c = 0; c < 8; ++c) pdof[c] = m.hex_q1(el, c);
    for (int r = 0; r < 3 * nn; ++r) {
      for (int s = 0; s < 3 * nn; ++s) Kasm.add(udof[r], udof[s], Ke(r, s));
      for (int c = 0; c < 8; ++c) Aasm.add(udof[r], pdof[c], Ae(r, c));
    }
    for (int c = 0; c < 8; ++c)
      for (int d = 0; d < 8; ++d) Basm.add(pdof[c], pdof[d], Be(c, d));
  }
  sys.K = Kasm.finish();
  sys.A = Aasm.finish();
  sys.B = Basm.finish();

  // Surface load operator on the articular faces (element layer N - 1, xi_3 = +1).
  const int nv = m.num_vertices();
  ChunkedAssembler Sasm(nu, 3 * nv);
  const QuadratureRule face = quad_rule(3);
  static constexpr int kLocal[4] = {0, 1, 3, 2};  // quad corner -> bilinear basis index
  Eigen::VectorXd Mf, Nf;
  Eigen::MatrixXd dMf, dNf;
  const int m1 = order + 1;
  for (int q = 0; q < m.num_quads(); ++q) {
    const int el = m.element(q, m.layers - 1);
    Eigen::Matrix<double, 4, 3> Xf;
    for (int c = 0; c < 4; ++c) Xf.row(kLocal[c]) = m.surface.V.row(m.surface.Q(q, c));
    Eigen::MatrixXd Se = Eigen::MatrixXd::Zero(m1 * m1, 4);
    for (size_t g = 0; g < face.points.size(); ++g) {
      quad_basis(1, face.points[g][0], face.points[g][1], &Mf, &dMf);
      quad_basis(order, face.points[g][0], face.points[g][1], &Nf, &dNf);
      const Eigen::Vector3d t1 = Xf.transpose() * dMf.col(0);
      const Eigen::Vector3d t2 = Xf.transpose() * dMf.col(1);
      const double w = face.weights[g] * t1.cross(t2).norm();
      Se.noalias() += w * Nf * Mf.transpose();
    }
    for (int j = 0; j < m1; ++j) {
      for (int i = 0; i < m1; ++i) {
        const int a_local = ((m1 - 1) * m1 + j) * m1 + i;  // top face of the element
        const int node = sys.u_node(el, a_local);
        for (int c = 0; c < 4; ++c) {
          const double v = Se(j * m1 + i, kLocal[c]);
          const int vert = m.surface.Q(q, c);
          for (int d = 0; d < 3; ++d) Sasm.add(3 * node + d, 3 * vert + d, v);
        }
      }
    }
  }
  sys.surface_load = Sasm.finish();
  return sys;
}

PointFields evaluate_point(const LayerSystem& sys, int element, const Eigen::Vector3d& xi,
                           const Eigen::VectorXd& u, const Eigen::VectorXd& p) {
  const LayerMesh& m = sys.mesh;
  const int order = sys.u_order();
  const int nn = hex_nodes(order);
  Eigen::VectorXd M, N;
  Eigen::MatrixXd dM, dN;
  hex_basis(1, xi, &M, &dM);
  hex_basis(order, xi, &N, &dN);
  const Eigen::Matrix<double, 8, 3> X = element_corners(m, element);
  const Geometry geo = geometry_at(X, dM, m, element);
  const Eigen::MatrixXd G = dN * geo.inverse;
  const Eigen::MatrixXd Gm = dM * geo.inverse;
  Eigen::Matrix3d grad_u = Eigen::Matrix3d::Zero();  // (i, j) = d u_i / d x_j
  for (int a = 0; a < nn; ++a) {
    const int node = sys.u_node(element, a);
    grad_u += u.segment<3>(3 * node) * G.row(a);
  }
  PointFields f;
  f.strain = 0.5 * (grad_u + grad_u.transpose());
  const Material& material = sys.element_material(element);
  const double lambda = material.lame_lambda();
  const double mu = material.shear_modulus();
  f.effective_stress = lambda * f.strain.trace() * Eigen::Matrix3d::Identity() + 2.0 * mu * f.strain;
  Eigen::Vector3d grad_p = Eigen::Vector3d::Zero();
  f.pressure = 0.0;
  for (int c = 0; c < 8; ++c) {
    const double pc = p[m.hex_q1(element, c)];
    f.pressure += M[c] * pc;
    grad_p += pc * Gm.row(c).transpose();
  }
  f.total_stress = f.effective_stress - f.pressure * Eigen::Matrix3d::Identity();
  f.flux = -material.permeability_m4_per_Ns * grad_p;
  return f;
}

}  // namespace arthrosim::biphasic
