#include "shockwave/tissue.h"

#include <cmath>
#include <sstream>

#include "common/error.h"

namespace arthrosim::shockwave {

namespace {

Tissue make(const char* name, double rho, double G_GPa, double K_GPa, double Ks_GPa, double phi, double k) {
  Tissue t;
  t.name = name;
  t.density = rho;
  t.shear_modulus = G_GPa * 1e9;
  t.bulk_modulus = K_GPa * 1e9;
  t.solid_bulk_modulus = Ks_GPa * 1e9;
  t.porosity = phi;
  t.permeability = k;
  return t;
}

std::string num(double v) {
  std::ostringstream s;
  s.precision(6);
  s << v;
  return s.str();
}

}  // namespace

// Table 1 of the seed: rho [kg/m^3], G, K, K_s [GPa], porosity, k [m^2].
Tissue cortical_bone() { return make("cortical", 1850, 5.55, 14, 17, 0.04, 3.6e-15); }
Tissue cancellous_bone() { return make("cancellous", 700, 1.3, 3.3, 15, 0.7, 1.0e-11); }
Tissue cartilage() { return make("cartilage", 800, 0.0043, 0.00416, 3.4, 0.8, 4.8e-18); }
Tissue fibrocartilage() { return make("fibrocartilage", 900, 0.130, 0.283, 2.3, 0.8, 9.5e-19); }
Tissue fibrous_tissue() { return make("fibrous", 1000, 0.00043, 0.00416, 2.3, 0.9, 7.5e-19); }
Tissue capsule_shell() { return make("capsule_shell", 1000, 1.2, 2.3, 2.3, 0.9, 1.0e-11); }
Tissue copper() {
  Tissue t = make("applicator", 8950, 41.6, 115, 115, 0.0, 0.0);
  t.solid = true;
  return t;
}

TissueConstants derive(const Tissue& t, const PoreFluid& fluid, const std::string& source) {
  auto fail = [&](const std::string& what, double found) {
    throw common::InputError(source, 0, "tissue '" + t.name + "': expected " + what + ", found " + num(found));
  };
  if (!(t.density > 0.0 && t.density < 3e4)) fail("density in (0, 30000) kg/m^3", t.density);
  if (!(t.bulk_modulus > 0.0 && std::isfinite(t.bulk_modulus))) fail("bulk modulus K > 0 Pa", t.bulk_modulus);
  if (!(t.shear_modulus > 0.0 && std::isfinite(t.shear_modulus))) fail("shear modulus G > 0 Pa", t.shear_modulus);
  if (!t.solid) {
    if (!(t.porosity > 0.0 && t.porosity < 1.0)) fail("porosity in (0, 1)", t.porosity);
  } else if (t.porosity != 0.0) {
    fail("porosity 0 for a solid (non-porous) material", t.porosity);
  }
  if (!(t.permeability >= 0.0 && std::isfinite(t.permeability))) fail("permeability >= 0 m^2", t.permeability);
  if (!(t.channel_diameter >= 0.0 && std::isfinite(t.channel_diameter)))
    fail("channel diameter >= 0 m", t.channel_diameter);
  if (!(fluid.bulk_modulus > 0.0)) throw common::InputError(source, 0, "pore fluid: expected K_f > 0, found " + num(fluid.bulk_modulus));
  if (!(fluid.density > 0.0)) throw common::InputError(source, 0, "pore fluid: expected density > 0, found " + num(fluid.density));
  if (!(fluid.viscosity > 0.0)) throw common::InputError(source, 0, "pore fluid: expected viscosity > 0, found " + num(fluid.viscosity));

  TissueConstants c;
  c.porous = t.porosity > 0.0;
  c.total_density = (1.0 - t.porosity) * t.density + t.porosity * fluid.density;
  c.permeability = t.permeability > 0.0 ? t.permeability : t.porosity * t.channel_diameter * t.channel_diameter;
  if (c.porous) {
    if (!(t.solid_bulk_modulus > 0.0)) fail("solid bulk modulus K_s > 0 Pa", t.solid_bulk_modulus);
    if (t.bulk_modulus > t.solid_bulk_modulus)
      throw common::InputError(source, 0, "tissue '" + t.name + "': expected K <= K_s (Biot coefficient a = 1 - K/K_s >= 0), found K = " +
                                              num(t.bulk_modulus) + " Pa > K_s = " + num(t.solid_bulk_modulus) + " Pa");
    const double a = 1.0 - t.bulk_modulus / t.solid_bulk_modulus;
    if (a > 0.0) {
      // 1/M = phi/K_f + (a - phi)/K_s (eq. A10 with the pore volume of Biot's model).
      const double inv_m = t.porosity / fluid.bulk_modulus + (a - t.porosity) / t.solid_bulk_modulus;
      if (!(inv_m > 0.0))
        throw common::InputError(source, 0, "tissue '" + t.name + "': expected a positive Biot modulus (1/M = phi/K_f + (a - phi)/K_s > 0), found 1/M = " +
                                                num(inv_m) + " 1/Pa (a = " + num(a) + ", phi = " + num(t.porosity) + ")");
      c.poroelastic = true;
      c.a = a;
      c.biot_modulus = 1.0 / inv_m;
    }
  }
  c.undrained_bulk = t.bulk_modulus + c.a * c.a * c.biot_modulus;
  const double g43 = 4.0 * t.shear_modulus / 3.0;
  c.drained_p_speed = std::sqrt((t.bulk_modulus + g43) / c.total_density);
  c.undrained_p_speed = std::sqrt((c.undrained_bulk + g43) / c.total_density);
  c.shear_speed = std::sqrt(t.shear_modulus / c.total_density);
  return c;
}

}  // namespace arthrosim::shockwave
