#pragma once
// Regeneration criteria of the seed (section 1 and 3.3, after Prendergast,
// Huiskes & Soballe 1997, Giori et al. 1995, Simon et al. 2011, Wang & Yang
// 2018): compressive stress above 0.15 MPa (chondrogenesis), distortional
// strain between 0.05 % and 1.1 % (differentiation), pore fluid pressure
// between 20 kPa and 2 MPa (cell migration), and all three together.
//
// "Volume" (the seed defines none): the summed volume V of the automata of a
// tissue whose PEAK value over the run lies in the criterion's range (peaks
// per automaton: the largest hydrostatic pressure P = -sigma_mean, the
// largest distortional strain, the largest pore pressure); "all three": the
// automata whose three peaks all lie in range. V is the automaton's cell
// volume (d^3 SC, d^3/sqrt(2) FCC), the volume each automaton stands for.
// Also available: the same counts on the instantaneous fields (the volume
// where the criteria hold at one time).
#include <vector>

#include "shockwave/model.h"

namespace arthrosim::shockwave {

struct RegenerationCriteria {
  double compressive_min = 0.15e6;   ///< hydrostatic pressure P > this [Pa]
  double distortional_min = 0.05e-2; ///< distortional strain in [min, max] [-]
  double distortional_max = 1.1e-2;
  double pore_min = 20e3;            ///< pore pressure in [min, max] [Pa]
  double pore_max = 2e6;
};

struct RegenerationVolumes {
  double tissue = 0.0;        ///< volume of the tissue [m^3]
  double compressive = 0.0;   ///< [m^3]
  double distortional = 0.0;  ///< [m^3]
  double pore = 0.0;          ///< [m^3]
  double all = 0.0;           ///< all three [m^3]
};

/// Volumes of automata of `tissue` meeting the criteria, for per-automaton
/// values (peaks or instantaneous) of pressure, distortional strain and pore
/// pressure.
RegenerationVolumes regeneration_volumes(const Model& model, int tissue, const std::vector<double>& pressure,
                                         const std::vector<double>& distortional_strain,
                                         const std::vector<double>& pore_pressure,
                                         const RegenerationCriteria& criteria = {});

}  // namespace arthrosim::shockwave
