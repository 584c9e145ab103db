#pragma once
// Tissues of the shockwave model: the poroelastic parameters of the seed's
// Table 1 (seeds/001_8413b035bc6d0ea6.txt; Eremina & Smolin 2021, Materials
// 14:7678), the copper applicator, the pore fluid, and the Biot constants
// derived from them (Appendix A, eq. A9-A10).
//
// Units: SI (kg/m^3, Pa, m^2, Pa s).
//
// Conventions (docs/shockwave.md, "Tissues"):
//  - `density` is the density of the matrix material (Table 1, "density of the
//    matrix"). A saturated automaton of porosity phi carries the mass
//    (1 - phi) rho + phi rho_f per unit volume, with or without the pore
//    fluid's pressure being modelled (the fluid is there either way). For the
//    Table-1 tissues this gives 960 (cartilage), 980 (fibrocartilage), 1000
//    (fibrous tissue, capsule shell), 910 (cancellous), 1816 kg/m^3 (cortical).
//  - Biot coefficient a = 1 - K/K_s (A9). K = K_s (a = 0, the capsule shell of
//    Table 1) means the skeleton carries all load and the pore pressure has no
//    mechanical effect: the tissue is treated as single-phase (no pore
//    pressure, no filtration through it). K > K_s is an input error.
//  - Biot modulus M, 1/M = phi/K_f + (a - phi)/K_s (low-frequency Biot /
//    Gassmann); a tissue with a > 0 and 1/M <= 0 is an input error.
//  - Undrained bulk modulus K_u = K + a^2 M (Gassmann).
#include <string>
#include <vector>

namespace arthrosim::shockwave {

/// Interstitial (pore) fluid.
struct PoreFluid {
  /// Bulk modulus K_f [Pa]; saline, seed section 2.2 (Cowin & Doty 2007).
  double bulk_modulus = 2.4e9;
  /// Reference density rho_0 [kg/m^3] at the reference pressure P_0 = 0 (gauge).
  double density = 1000.0;
  /// Dynamic viscosity eta [Pa s]: water at 37 C, 0.69 mPa s (Kestin, Sokolov &
  /// Wakeham 1978, J Phys Chem Ref Data 7:941); 0.9 % saline differs by ~2 %.
  /// Range 1e-4 .. 1.
  double viscosity = 0.69e-3;
};

struct Tissue {
  std::string name;
  /// Density of the matrix material rho [kg/m^3]. Range (0, 3e4).
  double density = 0.0;
  /// Drained shear modulus G of the skeleton [Pa]. > 0.
  double shear_modulus = 0.0;
  /// Drained bulk modulus K of the skeleton [Pa]. > 0.
  double bulk_modulus = 0.0;
  /// Bulk modulus K_s of the solid the skeleton is made of [Pa]; >= K.
  double solid_bulk_modulus = 0.0;
  /// Porosity phi in (0, 1); 0 for a non-porous solid (the applicator).
  double porosity = 0.0;
  /// Intrinsic permeability k [m^2] (Table 1); >= 0. If 0 and
  /// channel_diameter > 0, k = phi d_ch^2 (A12).
  double permeability = 0.0;
  /// Filtration channel diameter d_ch [m] for A12 (used only when
  /// permeability is 0).
  double channel_diameter = 0.0;
  /// A non-porous solid (the applicator): porosity must be 0. Every other
  /// tissue must have a porosity in (0, 1).
  bool solid = false;
};

/// Table 1 of the seed (elastic and poroelastic parameters).
Tissue cortical_bone();
Tissue cancellous_bone();
Tissue cartilage();
Tissue fibrocartilage();
Tissue fibrous_tissue();
Tissue capsule_shell();
/// The copper applicator (seed section 2.2): rho 8950 kg/m^3, K 115 GPa,
/// G 41.6 GPa (He et al. 2020, Mater Des 196:109171); no pores.
Tissue copper();

/// Constants derived from a tissue and the pore fluid.
struct TissueConstants {
  bool porous = false;         ///< phi > 0
  bool poroelastic = false;    ///< porous and a > 0: carries a pore pressure
  double a = 0.0;              ///< Biot coefficient 1 - K/K_s (0 if not poroelastic)
  double biot_modulus = 0.0;   ///< M [Pa] (0 if not poroelastic)
  double undrained_bulk = 0.0; ///< K + a^2 M [Pa] (= K if not poroelastic)
  double permeability = 0.0;   ///< k [m^2] (Table value or phi d_ch^2)
  double total_density = 0.0;  ///< (1 - phi) rho + phi rho_f [kg/m^3]
  /// P-wave speeds sqrt((K + 4G/3)/rho_t), sqrt((K_u + 4G/3)/rho_t) [m/s].
  double drained_p_speed = 0.0;
  double undrained_p_speed = 0.0;
  double shear_speed = 0.0;    ///< sqrt(G/rho_t) [m/s]
};

/// Checks the tissue (InputError naming `source` and the tissue on any value
/// out of range: K <= 0, G <= 0, porosity outside (0, 1) for a tissue,
/// K > K_s, 1/M <= 0, ...) and derives its constants. Tissues must be
/// porous (phi in (0, 1)) unless `solid` (phi = 0).
TissueConstants derive(const Tissue& tissue, const PoreFluid& fluid, const std::string& source);

}  // namespace arthrosim::shockwave
