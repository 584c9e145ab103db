#pragma once
// Mesh generators shared by the cartilage shell tests and the benchmark.
#include <Eigen/Core>
#include <cmath>

#include "common/mesh.h"

namespace arthrosim::cartilage::testing {

/// nx x ny quads on [0, L] x [0, W] in the plane z = 0 (counter-clockwise
/// about +z). Node (i, j) has index j (nx+1) + i. If distortion > 0 the
/// interior nodes are moved by a fixed, deterministic pattern of relative
/// size `distortion` of the element size (no randomness).
inline common::QuadMesh plate_mesh(int nx, int ny, double L, double W, double distortion = 0.0) {
  common::QuadMesh m;
  m.V.resize((nx + 1) * (ny + 1), 3);
  const double hx = L / nx, hy = W / ny;
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) {
      double x = i * hx, y = j * hy;
      if (distortion > 0 && i > 0 && i < nx && j > 0 && j < ny) {
        x += distortion * hx * std::sin(1.7 * i + 2.3 * j);
        y += distortion * hy * std::cos(2.9 * i - 1.1 * j);
      }
      m.V.row(j * (nx + 1) + i) << x, y, 0.0;
    }
  m.Q.resize(nx * ny, 4);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i;
      m.Q.row(j * nx + i) << a, a + 1, a + nx + 2, a + nx + 1;
    }
  m.name = "plate";
  return m;
}

/// Spherical cap / curved patch: the plate mesh [-L/2, L/2]^2 mapped onto a
/// sphere of radius R about (0, 0, -R) (so the cap top is at the origin and
/// the outward normal is +z there).
inline common::QuadMesh spherical_patch(int n, double L, double R) {
  common::QuadMesh m = plate_mesh(n, n, L, L);
  for (int i = 0; i < m.V.rows(); ++i) {
    const double x = m.V(i, 0) - L / 2, y = m.V(i, 1) - L / 2;
    Eigen::Vector3d p(x, y, R);
    p = R * p.normalized();
    m.V.row(i) << p.x(), p.y(), p.z() - R;
  }
  m.name = "spherical patch";
  return m;
}

/// One octant (x, y, z >= 0) of a sphere of radius R, meshed by projecting the
/// three faces x=1, y=1, z=1 of the unit cube corner (n x n quads each,
/// counter-clockwise seen from outside). Nodes on the cube edges are shared.
inline common::QuadMesh sphere_octant(int n, double R) {
  // Nodes of the three faces indexed on a global grid of cube-surface points.
  std::vector<Eigen::Vector3d> pts;
  auto key = [n](int a, int b, int c) { return (a * (n + 1) + b) * (n + 1) + c; };
  std::vector<int> id((n + 1) * (n + 1) * (n + 1), -1);
  auto node = [&](int a, int b, int c) {
    int& k = id[key(a, b, c)];
    if (k < 0) {
      k = static_cast<int>(pts.size());
      // Equi-angular spacing on each face for better element quality.
      auto u = [n](int s) { return std::tan(0.25 * M_PI * s / n); };
      Eigen::Vector3d p(u(a), u(b), u(c));
      pts.push_back(R * p.normalized());
    }
    return k;
  };
  std::vector<Eigen::Vector4i> quads;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      // face x = 1 (a = n): (y, z) grid, ccw seen from +x: y then z.
      quads.emplace_back(node(n, i, j), node(n, i + 1, j), node(n, i + 1, j + 1), node(n, i, j + 1));
      // face y = 1: (z, x) grid, ccw seen from +y.
      quads.emplace_back(node(j, n, i), node(j, n, i + 1), node(j + 1, n, i + 1), node(j + 1, n, i));
      // face z = 1: (x, y) grid, ccw seen from +z.
      quads.emplace_back(node(i, j, n), node(i + 1, j, n), node(i + 1, j + 1, n), node(i, j + 1, n));
    }
  common::QuadMesh m;
  m.V.resize(static_cast<int>(pts.size()), 3);
  for (size_t i = 0; i < pts.size(); ++i) m.V.row(i) = pts[i].transpose();
  m.Q.resize(static_cast<int>(quads.size()), 4);
  for (size_t e = 0; e < quads.size(); ++e) m.Q.row(e) = quads[e].transpose();
  m.name = "sphere octant";
  return m;
}


/// The mesh mirrored in z (z -> z0 - z) with its orientation reversed, so that
/// its normals point the other way (a surface facing down onto another).
inline common::QuadMesh flipped(common::QuadMesh m, double z0) {
  for (int i = 0; i < m.V.rows(); ++i) m.V(i, 2) = z0 - m.V(i, 2);
  for (int e = 0; e < m.Q.rows(); ++e) {
    const Eigen::Vector4i q = m.Q.row(e);
    m.Q.row(e) << q(0), q(3), q(2), q(1);
  }
  return m;
}

}  // namespace arthrosim::cartilage::testing
