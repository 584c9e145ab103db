#pragma once
// Linear biphasic material (Mow et al. 1980): an isotropic linear elastic
// solid matrix (aggregate modulus H_A = lambda + 2 mu, drained Poisson's ratio
// nu_s) saturated by an inviscid fluid, with constant isotropic permeability
// k (Darcy: relative fluid flux w = -k grad p). Both phases intrinsically
// incompressible. SI units.
#include <string>

namespace arthrosim::biphasic {

struct Material {
  /// Aggregate (confined compression) modulus H_A [Pa]; > 0. Human tibial
  /// cartilage 0.48-1.58 MPa (docs/biphasic.md, parameters).
  double aggregate_modulus_Pa = 0.0;
  /// Drained Poisson's ratio of the solid matrix [-]; in [0, 0.5).
  double poisson_ratio = 0.0;
  /// Permeability k [m^4 / (N s)]; > 0. Human tibial cartilage 1.7-5.4e-15.
  double permeability_m4_per_Ns = 0.0;

  /// Lame's first parameter lambda = H_A nu / (1 - nu) [Pa].
  double lame_lambda() const { return aggregate_modulus_Pa * poisson_ratio / (1.0 - poisson_ratio); }
  /// Shear modulus mu = H_A (1 - 2 nu) / (2 (1 - nu)) [Pa].
  double shear_modulus() const {
    return aggregate_modulus_Pa * (1.0 - 2.0 * poisson_ratio) / (2.0 * (1.0 - poisson_ratio));
  }
  /// Young's modulus E_s = 2 mu (1 + nu) [Pa].
  double youngs_modulus() const { return 2.0 * shear_modulus() * (1.0 + poisson_ratio); }
};

/// Throws common::InputError "<where>: expected ..., found ..." for
/// H_A <= 0, nu outside [0, 0.5), k <= 0, or a non-finite value.
void validate(const Material& material, const std::string& where);

}  // namespace arthrosim::biphasic
