#include "shockwave/criteria.h"

#include "shockwave/reduce.h"

namespace arthrosim::shockwave {

RegenerationVolumes regeneration_volumes(const Model& m, int tissue, const std::vector<double>& P,
                                         const std::vector<double>& eps, const std::vector<double>& pore,
                                         const RegenerationCriteria& c) {
  const double V = m.lattice.cell_volume;
  auto count = [&](auto pred) {
    return V * deterministic_sum(m.size(), [&](std::int64_t i) { return (m.tissue[i] == tissue && pred(i)) ? 1.0 : 0.0; });
  };
  auto comp = [&](std::int64_t i) { return P[i] > c.compressive_min; };
  auto dist = [&](std::int64_t i) { return eps[i] >= c.distortional_min && eps[i] <= c.distortional_max; };
  auto fl = [&](std::int64_t i) { return pore[i] >= c.pore_min && pore[i] <= c.pore_max; };
  RegenerationVolumes v;
  v.tissue = count([](std::int64_t) { return true; });
  v.compressive = count(comp);
  v.distortional = count(dist);
  v.pore = count(fl);
  v.all = count([&](std::int64_t i) { return comp(i) && dist(i) && fl(i); });
  return v;
}

}  // namespace arthrosim::shockwave
