#pragma once
// Small deterministic meshes shared by the common-library geometry tests.
#include <array>
#include <cmath>
#include <map>
#include <random>
#include <utility>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::common::testing {

/// Icosahedron subdivided `levels` times (each triangle into 4, midpoints
/// pushed to the sphere): 20 * 4^levels outward-oriented triangles, closed.
inline TriangleMesh icosphere(int levels, double radius) {
  const double p = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Vec3> v = {{-1, p, 0}, {1, p, 0},  {-1, -p, 0}, {1, -p, 0}, {0, -1, p},  {0, 1, p},
                         {0, -1, -p}, {0, 1, -p}, {p, 0, -1},  {p, 0, 1},  {-p, 0, -1}, {-p, 0, 1}};
  for (auto& x : v) x.normalize();
  std::vector<std::array<int, 3>> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                       {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                       {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                       {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      const auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      mid[key] = static_cast<int>(v.size()) - 1;
      return static_cast<int>(v.size()) - 1;
    };
    std::vector<std::array<int, 3>> g;
    for (const auto& t : f) {
      const int ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]), ca = midpoint(t[2], t[0]);
      g.push_back({t[0], ab, ca});
      g.push_back({t[1], bc, ab});
      g.push_back({t[2], ca, bc});
      g.push_back({ab, bc, ca});
    }
    f = std::move(g);
  }
  TriangleMesh m;
  m.V.resize(static_cast<int>(v.size()), 3);
  for (size_t i = 0; i < v.size(); ++i) m.V.row(static_cast<int>(i)) = radius * v[i].transpose();
  m.F.resize(static_cast<int>(f.size()), 3);
  for (size_t i = 0; i < f.size(); ++i) m.F.row(static_cast<int>(i)) << f[i][0], f[i][1], f[i][2];
  m.name = "icosphere";
  return m;
}

/// Icosphere with every vertex radius scaled by 1 + amplitude * U(-1, 1)
/// (std::mt19937_64 with the given seed).
inline TriangleMesh perturbed_sphere(int levels, double radius, double amplitude, unsigned seed) {
  TriangleMesh m = icosphere(levels, radius);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < m.num_vertices(); ++i) m.V.row(i) *= 1.0 + amplitude * u(rng);
  m.name = "perturbed_sphere";
  return m;
}

/// Open, gently curved patch over [0, lx] x [0, ly] with nx x ny quads split
/// into triangles, z = bump * sin(pi x / lx) sin(pi y / ly); normals +z.
inline TriangleMesh curved_patch(int nx, int ny, double lx, double ly, double bump) {
  TriangleMesh m;
  m.V.resize((nx + 1) * (ny + 1), 3);
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      const double x = lx * i / nx, y = ly * j / ny;
      m.V.row(j * (nx + 1) + i) << x, y, bump * std::sin(M_PI * x / lx) * std::sin(M_PI * y / ly);
    }
  }
  m.F.resize(2 * nx * ny, 3);
  int t = 0;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i, b = a + 1, c = a + nx + 2, d = a + nx + 1;
      m.F.row(t++) << a, b, c;
      m.F.row(t++) << a, c, d;
    }
  }
  m.name = "curved_patch";
  return m;
}

}  // namespace arthrosim::common::testing
