#include "shockwave/model.h"

#include <algorithm>
#include <exception>
#include <stdexcept>

#include "common/error.h"

namespace arthrosim::shockwave {

std::int64_t Model::bonds() const {
  std::int64_t sum = 0;
  for (std::uint8_t c : neighbour_count) sum += c;
  return sum / 2;
}

std::vector<std::int64_t> Model::tissue_counts() const {
  std::vector<std::int64_t> c(tissues.size(), 0);
  for (std::uint8_t t : tissue) ++c[t];
  return c;
}

common::Vec3 Model::period() const {
  common::Vec3 p = common::Vec3::Zero();
  for (int a = 0; a < 3; ++a)
    if (grid.periodic[a]) p[a] = grid.count[a] * lattice.spacing;
  return p;
}

Model build_model(const Lattice& lattice, const GridSpec& grid, std::vector<Tissue> tissues, const PoreFluid& fluid,
                  const std::function<int(int, int, int, const common::Vec3&)>& classify, const std::string& source) {
  if (tissues.empty() || tissues.size() > 255)
    throw common::InputError(source, 0, "expected 1 to 255 tissues, found " + std::to_string(tissues.size()));
  for (int a = 0; a < 3; ++a) {
    if (grid.count[a] < 1)
      throw common::InputError(source, 0, "expected at least one grid point per axis, found " +
                                              std::to_string(grid.count[a]) + " on axis " + std::to_string(a));
    if (grid.periodic[a] && grid.count[a] < 3)
      throw common::InputError(source, 0, "expected at least 3 grid points on a periodic axis, found " +
                                              std::to_string(grid.count[a]));
    if (grid.periodic[a] && lattice.kind == LatticeKind::kFcc && grid.count[a] % 2 != 0)
      throw common::InputError(source, 0, "expected an even grid count on a periodic FCC axis, found " +
                                              std::to_string(grid.count[a]));
  }
  Model m;
  m.lattice = lattice;
  m.grid = grid;
  m.fluid = fluid;
  m.tissues = std::move(tissues);
  for (const Tissue& t : m.tissues) m.constants.push_back(derive(t, fluid, source));

  const int ni = grid.count[0], nj = grid.count[1], nk = grid.count[2];
  const std::int64_t cells = static_cast<std::int64_t>(ni) * nj * nk;
  std::vector<std::int32_t> index(static_cast<size_t>(cells), -1);
  std::vector<std::int16_t> label(static_cast<size_t>(cells), -1);
  const double h = lattice.spacing;
  const int ntissues = static_cast<int>(m.tissues.size());
  std::string bad;
  std::exception_ptr error;
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < nk; ++k)
    for (int j = 0; j < nj; ++j)
      for (int i = 0; i < ni; ++i) {
        if (!lattice.is_site(i, j, k)) continue;
        const common::Vec3 p = grid.origin + h * common::Vec3(i, j, k);
        int t = -1;
        try {
          t = classify(i, j, k, p);
        } catch (...) {
#pragma omp critical
          if (!error) error = std::current_exception();
          continue;
        }
        if (t < -1 || t >= ntissues) {
#pragma omp critical
          bad = "classifier returned tissue " + std::to_string(t);
          continue;
        }
        label[static_cast<size_t>(i + static_cast<std::int64_t>(ni) * (j + static_cast<std::int64_t>(nj) * k))] =
            static_cast<std::int16_t>(t);
      }
  if (error) std::rethrow_exception(error);
  if (!bad.empty()) throw std::logic_error("build_model: " + bad);
  // Automata in grid order (k slowest, i fastest): neighbours are close in memory.
  std::int32_t n = 0;
  for (std::int64_t c = 0; c < cells; ++c)
    if (label[static_cast<size_t>(c)] >= 0) index[static_cast<size_t>(c)] = n++;
  m.x.resize(n);
  m.y.resize(n);
  m.z.resize(n);
  m.tissue.resize(n);
  m.cell.resize(n);
  for (std::int64_t c = 0; c < cells; ++c) {
    const std::int32_t a = index[static_cast<size_t>(c)];
    if (a < 0) continue;
    const int i = static_cast<int>(c % ni), j = static_cast<int>((c / ni) % nj), k = static_cast<int>(c / (static_cast<std::int64_t>(ni) * nj));
    const common::Vec3 p = grid.origin + h * common::Vec3(i, j, k);
    m.x[a] = p.x();
    m.y[a] = p.y();
    m.z[a] = p.z();
    m.tissue[a] = static_cast<std::uint8_t>(label[static_cast<size_t>(c)]);
    m.cell[a] = {i, j, k};
  }
  const int K = lattice.directions;
  m.neighbours.assign(static_cast<size_t>(K) * n, -1);
  m.neighbour_count.assign(n, 0);
#pragma omp parallel for schedule(static)
  for (std::int32_t a = 0; a < n; ++a) {
    const auto [i, j, k] = m.cell[a];
    int count = 0;
    for (int s = 0; s < K; ++s) {
      std::array<int, 3> q{i + lattice.offsets[s][0], j + lattice.offsets[s][1], k + lattice.offsets[s][2]};
      bool inside = true;
      for (int ax = 0; ax < 3; ++ax) {
        if (q[ax] >= 0 && q[ax] < grid.count[ax]) continue;
        if (grid.periodic[ax]) q[ax] = (q[ax] + grid.count[ax]) % grid.count[ax];
        else inside = false;
      }
      if (!inside) continue;
      const std::int32_t b = index[static_cast<size_t>(q[0] + static_cast<std::int64_t>(ni) * (q[1] + static_cast<std::int64_t>(nj) * q[2]))];
      if (b < 0) continue;
      m.neighbours[static_cast<size_t>(s) * n + a] = b;
      ++count;
    }
    m.neighbour_count[a] = static_cast<std::uint8_t>(count);
  }
  return m;
}

std::vector<int> layer(const Model& model, int axis, int index) {
  std::vector<int> out;
  for (int a = 0; a < model.size(); ++a)
    if (model.cell[a][axis] == index) out.push_back(a);
  return out;
}

}  // namespace arthrosim::shockwave
