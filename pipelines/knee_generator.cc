// Parametric right knee (see knee_generator.h for the frame and construction,
// docs/knee_geometry.md for the dimensions and their literature sources).
#include "pipelines/knee_generator.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <unordered_map>

#include "common/error.h"
#include "common/mesh_io.h"
#include "common/remesh.h"
#include "common/spatial.h"

namespace arthrosim::pipelines {

using common::Points3;
using common::TriangleMesh;
using common::Triangles;
using common::Vec3;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double mm(double v) { return v * 1e-3; }
constexpr double deg(double v) { return v * kPi / 180.0; }

// Polynomial smooth minimum (Quilez): equals min(a, b) when |a - b| >= k and
// blends the two surfaces with a fillet of size ~k otherwise; C1.
double smin(double a, double b, double k) {
  const double h = std::clamp(0.5 + 0.5 * (b - a) / k, 0.0, 1.0);
  return b + (a - b) * h - k * h * (1.0 - h);
}
double smax(double a, double b, double k) { return -smin(-a, -b, k); }
// C1 ramp 0 -> 1 on u in [0, 1].
double smoothstep(double u) {
  u = std::clamp(u, 0.0, 1.0);
  return u * u * (3.0 - 2.0 * u);
}

// Ellipsoid pseudo-distance: (normalised radius - 1) * smallest semi-axis.
double ellipsoid(const Vec3& p, const Vec3& c, const Vec3& semi) {
  const Vec3 q = (p - c).cwiseQuotient(semi);
  return (q.norm() - 1.0) * semi.minCoeff();
}
// Capsule (segment a-b, radius r): exact signed distance.
double capsule(const Vec3& p, const Vec3& a, const Vec3& b, double r) {
  const Vec3 ab = b - a;
  const double t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
  return (p - (a + t * ab)).norm() - r;
}

// ---------------------------------------------------------------------------
// Dimensions [m]. Adult female values; see docs/knee_geometry.md for sources.
struct Condyle {
  double centre_z;        // ML position of the condyle centre on the flexion axis
  double radius;          // sagittal radius of the posterior and distal arc
  double anterior_radius; // sagittal radius reached anteriorly (trochlear facet)
};
struct Dimensions {
  Condyle medial{mm(-21.0), mm(21.0), mm(32.0)};
  Condyle lateral{mm(21.0), mm(20.0), mm(33.5)};
  double condyle_tube_radial = mm(11.0);  // radial semi-axis of the condyle section
  double condyle_half_width = mm(13.0);   // ML semi-axis of the condyle section
  Vec3 metaphysis_centre{mm(2.0), mm(12.0), 0.0};
  Vec3 metaphysis_semi{mm(20.0), mm(32.0), mm(37.5)};  // epicondylar width 75 mm
  double shaft_x = mm(12.0);
  double femur_shaft_radius = mm(13.0);
  double femur_shaft_top = mm(85.0);
  double groove_depth_x = mm(28.0);        // groove bottom at y = groove_peak_y
  double groove_peak_y = mm(10.0);
  double groove_sagittal_radius = mm(30.0);
  double groove_half_width = mm(14.0);
  double notch_half_width = mm(8.0);
  double notch_roof_y = mm(0.0);
  double notch_front_x = mm(8.0);

  // Tibia.
  double plateau_semi_ap = mm(22.5);   // AP 45 mm
  double plateau_semi_ml = mm(35.0);   // ML 70 mm
  double plateau_centre_x = 0.0;
  double medial_bowl_radius = mm(45.0);    // concave
  double lateral_dome_radius = mm(150.0);  // slightly convex
  double tibia_taper_end_y = mm(-86.0);    // outline scale reaches taper_min here
  double tibia_taper_start_y = mm(-34.0);
  double tibia_taper_min = 0.36;
  double tibia_body_bottom_y = mm(-90.0);
  double tibia_shaft_radius = mm(11.5);
  double tibia_shaft_top = mm(-60.0);
  double tibia_shaft_bottom = mm(-115.0);
  double spine_height = mm(7.0);
  double spine_z = mm(5.0);
  Vec3 tuberosity_centre{mm(19.0), mm(-44.0), mm(4.0)};
  Vec3 tuberosity_semi{mm(5.0), mm(10.0), mm(8.0)};

  // Patella (bone, without cartilage): ML 40, SI 35, AP 18 mm.
  double patella_y = mm(20.0);
  double patella_z = 0.0;
  Vec3 patella_semi{mm(12.5), mm(17.5), mm(20.0)};
  double patella_bone_thickness = mm(18.0);

  // Cartilage.
  double rim_thickness = mm(1.5);
  double condyle_distal_thickness = mm(2.8);
  double condyle_posterior_thickness = mm(2.2);
  double trochlea_thickness = mm(2.5);
  double tibia_centre_thickness = mm(3.0);
  double patella_facet_thickness = mm(3.0);
  double patella_ridge_thickness = mm(3.5);
  double tibia_medial_semi_ap = mm(17.0), tibia_medial_semi_ml = mm(10.5);
  double tibia_lateral_semi_ap = mm(15.0), tibia_lateral_semi_ml = mm(10.5);
  double patella_cart_semi_si = mm(14.0), patella_cart_semi_ml = mm(13.0);

  // Menisci (docs/knee_geometry.md): C-rings around the compartment centres.
  // Outer outline an ellipse (semi-axes AP, ML) cut open between the horns;
  // length 40 / 33 mm, overall width 27 mm (Fox, Bedi & Rodeo 2012 report
  // medial 40.5-45.5 x 27 mm, lateral 32.4-35.7 x 26.6-29.3 mm; the length is
  // held to the 45 mm plateau), body width (rim) 9 / 10 mm, distance between
  // the horns 24 / 11 mm (Murlimanju et al. 2012: 24.1 and 11.3 mm), wedge
  // cross-section from 1 mm at the inner free edge to 6 mm at the periphery.
  struct Meniscus {
    double semi_ap, semi_ml, rim, horn_gap;
  };
  Meniscus medial_meniscus{mm(20.0), mm(15.0), mm(9.0), mm(24.0)};
  Meniscus lateral_meniscus{mm(16.5), mm(14.0), mm(10.0), mm(11.0)};
  double meniscus_peripheral_height = mm(6.0);
  double meniscus_inner_height = mm(1.0);
  double meniscus_femur_clearance = mm(0.2);

  // Limb (Winter 2009 segment proportions of stature, 1.65 m subject).
  double stature = 1.65;
  double thigh_fraction = 0.245;
  double leg_fraction = 0.246;
};

// Bisection for the zero of f between a (f < 0 inside) and b (f > 0).
Vec3 bisect(const std::function<double(const Vec3&)>& f, Vec3 a, Vec3 b) {
  for (int it = 0; it < 60; ++it) {
    const Vec3 m = 0.5 * (a + b);
    if (f(m) < 0.0) a = m; else b = m;
  }
  return 0.5 * (a + b);
}

// First crossing of f = 0 along origin + s * dir, s in (0, length], marching
// by `step` then bisecting. Returns false if there is no sign change.
bool march_to_surface(const std::function<double(const Vec3&)>& f, const Vec3& origin,
                      const Vec3& dir, double length, double step, Vec3* out) {
  const bool inside0 = f(origin) < 0.0;
  Vec3 prev = origin;
  for (double s = step; s <= length + 1e-12; s += step) {
    const Vec3 cur = origin + s * dir;
    const bool inside = f(cur) < 0.0;
    if (inside != inside0) {
      *out = inside0 ? bisect(f, prev, cur) : bisect(f, cur, prev);
      return true;
    }
    prev = cur;
  }
  return false;
}

}  // namespace

// ---------------------------------------------------------------------------
struct ParametricKnee::Impl {
  Dimensions d;
  double overlap = mm(0.25);
  // Tibial plateau reference heights (bone surface at the plateau centres),
  // solved so the cartilage surfaces overlap by `overlap` at the centres.
  double medial_plateau_y = mm(-26.5);
  double lateral_plateau_y = mm(-25.5);
  // Table of the patella's posterior (articular) bone surface x = B(y, z).
  double table_y0 = 0, table_z0 = 0, table_h = mm(0.25);
  int table_ny = 0, table_nz = 0;
  std::vector<double> back;      // B(y, z)
  // Meniscus tables (built on first use): per meniscus, on a grid over its
  // footprint, the lower face height (tibial articular surface) and the
  // highest admissible upper face (below the femoral articular surface).
  struct MeniscusTable {
    double x0 = 0, z0 = 0, h = mm(0.5);
    int nx = 0, nz = 0;
    std::vector<double> low, limit;
    double at(const std::vector<double>& v, double x, double z) const {
      const double fx = std::clamp((x - x0) / h, 0.0, nx - 1.000001);
      const double fz = std::clamp((z - z0) / h, 0.0, nz - 1.000001);
      const int ix = static_cast<int>(fx), iz = static_cast<int>(fz);
      const double tx = fx - ix, tz = fz - iz;
      auto g = [&](int i, int k) { return v[static_cast<size_t>(i) * nz + k]; };
      return (1 - tx) * ((1 - tz) * g(ix, iz) + tz * g(ix, iz + 1)) + tx * ((1 - tz) * g(ix + 1, iz) + tz * g(ix + 1, iz + 1));
    }
  };
  mutable std::once_flag meniscus_once;
  mutable MeniscusTable meniscus_table[2];
  double patella_centre_x = 0.0;  // ellipsoid centre
  double patella_back_x0 = 0.0;   // B at the patella centre

  // --- femur ---------------------------------------------------------------
  double condyle(const Vec3& p, const Condyle& c) const {
    const double rho = std::hypot(p.x(), p.y());
    const double phi = std::atan2(p.y(), p.x());
    // Sagittal J-curve: radius c.radius posteriorly and distally, growing to
    // c.anterior_radius on the anterior (trochlear) side, back to c.radius
    // superiorly where the condyle merges into the metaphysis.
    double bump = 0.0;
    // (The growth starts 30 deg anterior of the distal point so the distal
    // point stays the lowest one: tibial contact at the plateau centres.)
    if (phi >= deg(-60.0) && phi < deg(-10.0)) bump = smoothstep((phi - deg(-60.0)) / deg(50.0));
    else if (phi >= deg(-10.0) && phi < deg(40.0)) bump = 1.0;
    else if (phi >= deg(40.0) && phi < deg(100.0)) bump = 1.0 - smoothstep((phi - deg(40.0)) / deg(60.0));
    const double r = c.radius + (c.anterior_radius - c.radius) * bump;
    const double rho0 = r - d.condyle_tube_radial;
    // Elliptic section in (rho, z); on the inner side the radial semi-axis
    // reaches past the axis so the condyle is a solid disc (C1 at rho0).
    const double a = rho >= rho0 ? d.condyle_tube_radial : rho0 + mm(3.0);
    const double u = (rho - rho0) / a;
    const double v = (p.z() - c.centre_z) / d.condyle_half_width;
    return (std::sqrt(u * u + v * v) - 1.0) * std::min(d.condyle_tube_radial, d.condyle_half_width);
  }
  double groove_front(double y, double z) const {
    const double dy = y - d.groove_peak_y;
    const double zr = z / mm(12.0);
    return d.groove_depth_x - dy * dy / (2.0 * d.groove_sagittal_radius) + mm(3.0) * zr * zr;
  }
  double femur(const Vec3& p) const {
    double f = smin(condyle(p, d.medial), condyle(p, d.lateral), mm(3.0));
    f = smin(f, ellipsoid(p, d.metaphysis_centre, d.metaphysis_semi), mm(3.0));
    double block = smax(p.x() - groove_front(p.y(), p.z()), std::abs(p.z()) - d.groove_half_width, mm(3.0));
    block = smax(block, smax(p.y() - mm(38.0), -(p.y() + mm(12.0)), mm(3.0)), mm(3.0));
    block = smax(block, mm(5.0) - p.x(), mm(3.0));
    f = smin(f, block, mm(7.0));
    f = smin(f, capsule(p, Vec3(d.shaft_x, mm(20.0), 0.0), Vec3(d.shaft_x, d.femur_shaft_top, 0.0),
                        d.femur_shaft_radius),
             mm(10.0));
    double slot = smax(std::abs(p.z()) - d.notch_half_width, p.y() - d.notch_roof_y, mm(2.0));
    slot = smax(slot, p.x() - d.notch_front_x, mm(2.0));
    return smax(f, -slot, mm(1.5));
  }

  // --- tibia ---------------------------------------------------------------
  double plateau_height(double x, double z) const {
    const double dxm = x - d.plateau_centre_x, dzm = z - d.medial.centre_z;
    const double dzl = z - d.lateral.centre_z;
    const double hm = medial_plateau_y + (dxm * dxm + dzm * dzm) / (2.0 * d.medial_bowl_radius);
    const double hl = lateral_plateau_y - (dxm * dxm + dzl * dzl) / (2.0 * d.lateral_dome_radius);
    const double w = 1.0 / (1.0 + std::exp(-z / mm(3.0)));
    double h = (1.0 - w) * hm + w * hl;
    // Intercondylar eminence: medial and lateral tubercles.
    for (double sz : {-1.0, 1.0}) {
      const double ex = (x - mm(2.0)) / mm(6.0), ez = (z - sz * d.spine_z) / mm(3.0);
      h += d.spine_height * std::exp(-0.5 * (ex * ex + ez * ez));
    }
    return h;
  }
  double tibia(const Vec3& p) const {
    const double s = d.tibia_taper_min + (1.0 - d.tibia_taper_min) *
        smoothstep((p.y() - d.tibia_taper_end_y) / (d.tibia_taper_start_y - d.tibia_taper_end_y));
    const double a = d.plateau_semi_ap * s, b = d.plateau_semi_ml * s;
    const double q = std::pow(std::abs(p.x() - d.plateau_centre_x) / a, 3.0) + std::pow(std::abs(p.z()) / b, 3.0);
    const double outline = (std::cbrt(q) - 1.0) * std::min(a, b);
    double f = smax(p.y() - plateau_height(p.x(), p.z()), outline, mm(3.0));
    f = smax(f, d.tibia_body_bottom_y - p.y(), mm(3.0));
    f = smin(f, capsule(p, Vec3(0.0, d.tibia_shaft_top, 0.0), Vec3(0.0, d.tibia_shaft_bottom, 0.0),
                        d.tibia_shaft_radius),
             mm(8.0));
    return smin(f, ellipsoid(p, d.tuberosity_centre, d.tuberosity_semi), mm(4.0));
  }

  // --- patella -------------------------------------------------------------
  double back_at(double y, double z) const {
    const double fy = std::clamp((y - table_y0) / table_h, 0.0, table_ny - 1.000001);
    const double fz = std::clamp((z - table_z0) / table_h, 0.0, table_nz - 1.000001);
    const int iy = static_cast<int>(fy), iz = static_cast<int>(fz);
    const double ty = fy - iy, tz = fz - iz;
    auto at = [&](int j, int k) { return back[static_cast<size_t>(j) * table_nz + k]; };
    return (1 - ty) * ((1 - tz) * at(iy, iz) + tz * at(iy, iz + 1)) +
           ty * ((1 - tz) * at(iy + 1, iz) + tz * at(iy + 1, iz + 1));
  }
  double patella(const Vec3& p) const {
    const Vec3 c(patella_centre_x, d.patella_y, d.patella_z);
    return smax(ellipsoid(p, c, d.patella_semi), back_at(p.y(), p.z()) - p.x(), mm(2.0));
  }

  // --- menisci ---------------------------------------------------------------
  const Dimensions::Meniscus& meniscus_dims(KneeMeniscus w) const {
    return w == KneeMeniscus::kMedial ? d.medial_meniscus : d.lateral_meniscus;
  }
  double meniscus_centre_z(KneeMeniscus w) const {
    return w == KneeMeniscus::kMedial ? d.medial.centre_z : d.lateral.centre_z;
  }
  void meniscus_box(KneeMeniscus w, Vec3* lo, Vec3* hi) const {
    const auto& md = meniscus_dims(w);
    const double zc = meniscus_centre_z(w);
    const double yc = plateau_height(d.plateau_centre_x, zc);
    *lo = Vec3(d.plateau_centre_x - md.semi_ap - mm(3.0), yc - mm(8.0), zc - md.semi_ml - mm(3.0));
    *hi = Vec3(d.plateau_centre_x + md.semi_ap + mm(3.0), yc + mm(14.0), zc + md.semi_ml + mm(3.0));
  }
  void build_meniscus_tables() const {
    for (KneeMeniscus w : {KneeMeniscus::kMedial, KneeMeniscus::kLateral}) {
      MeniscusTable& t = meniscus_table[w == KneeMeniscus::kMedial ? 0 : 1];
      Vec3 lo, hi;
      meniscus_box(w, &lo, &hi);
      t.x0 = lo.x();
      t.z0 = lo.z();
      t.nx = static_cast<int>(std::ceil((hi.x() - lo.x()) / t.h)) + 1;
      t.nz = static_cast<int>(std::ceil((hi.z() - lo.z()) / t.h)) + 1;
      t.low.assign(static_cast<size_t>(t.nx) * t.nz, 0.0);
      t.limit.assign(t.low.size(), 1e9);
      const KneeCartilage tc = w == KneeMeniscus::kMedial ? KneeCartilage::kTibiaMedial : KneeCartilage::kTibiaLateral;
      for (int i = 0; i < t.nx; ++i)
        for (int k = 0; k < t.nz; ++k) {
          const double x = t.x0 + i * t.h, z = t.z0 + k * t.h;
          const size_t idx = static_cast<size_t>(i) * t.nz + k;
          // Lower face: the tibial bone surface plus the tibial cartilage
          // (faded to 0 over the last 1 mm inside its outline).
          const Vec3 q(x, plateau_height(x, z), z);
          const Vec3 n = gradient(KneeBone::kTibia, q).normalized();
          const double r = region(tc, q, n);
          const double tcart = r > 0.0 ? thickness(tc, q, n) * smoothstep(r / mm(1.0)) : 0.0;
          t.low[idx] = q.y() + tcart;
          // Upper limit: the lowest femoral bone point above (x, z), found by
          // marching down from the flexion axis height, minus the femoral
          // cartilage there (vertical extent t / |n_y|) and a clearance.
          double y = mm(0.0);
          const double step = mm(0.25);
          double lowest_inside = 1e9;
          bool prev_inside = femur(Vec3(x, y, z)) < 0.0;
          for (; y > t.low[idx]; y -= step) {
            const bool inside = femur(Vec3(x, y - step, z)) < 0.0;
            if (prev_inside && !inside) {
              const Vec3 b = bisect([&](const Vec3& p) { return femur(p); }, Vec3(x, y, z), Vec3(x, y - step, z));
              lowest_inside = b.y();
            }
            prev_inside = inside;
          }
          if (lowest_inside < 1e8) {
            const Vec3 b(x, lowest_inside, z);
            const Vec3 nf = gradient(KneeBone::kFemur, b).normalized();
            const double tf = region(KneeCartilage::kFemur, b, nf) > 0.0 ? thickness(KneeCartilage::kFemur, b, nf) : 0.0;
            t.limit[idx] = lowest_inside - tf / std::max(std::abs(nf.y()), 0.3) - d.meniscus_femur_clearance;
          }
        }
    }
  }
  double meniscus(KneeMeniscus w, const Vec3& p) const {
    std::call_once(meniscus_once, [this] { build_meniscus_tables(); });
    const MeniscusTable& t = meniscus_table[w == KneeMeniscus::kMedial ? 0 : 1];
    const auto& md = meniscus_dims(w);
    const double zc = meniscus_centre_z(w);
    const double dx = p.x() - d.plateau_centre_x, dz = p.z() - zc;
    const double ai = md.semi_ap - md.rim, bi = md.semi_ml - md.rim;
    const double ro = std::sqrt(std::pow(dx / md.semi_ap, 2) + std::pow(dz / md.semi_ml, 2));
    const double ri = std::sqrt(std::pow(dx / ai, 2) + std::pow(dz / bi, 2));
    double f = std::max((ro - 1.0) * md.semi_ml, (1.0 - ri) * bi);
    // The C opens towards the intercondylar area (+z for the medial, -z for
    // the lateral meniscus) between the horns.
    const double toward = w == KneeMeniscus::kMedial ? dz : -dz;
    f = std::max(f, std::min(0.5 * md.horn_gap - std::abs(dx), toward));
    // Wedge: radial position s from the inner (0) to the outer (1) outline.
    double s = 0.0;
    if (ri > 1e-9 && ro > 1e-9) s = (1.0 - 1.0 / ri) / (1.0 / ro - 1.0 / ri);
    s = std::clamp(s, 0.0, 1.0);
    const double low = t.at(t.low, p.x(), p.z());
    const double top = std::min(low + d.meniscus_inner_height + (d.meniscus_peripheral_height - d.meniscus_inner_height) * s,
                                t.at(t.limit, p.x(), p.z()));
    return std::max(f, std::max(low - p.y(), p.y() - top));
  }

  double implicit(KneeBone b, const Vec3& p) const {
    switch (b) {
      case KneeBone::kFemur: return femur(p);
      case KneeBone::kTibia: return tibia(p);
      case KneeBone::kPatella: return patella(p);
    }
    return 0.0;
  }
  Vec3 gradient(KneeBone b, const Vec3& p) const {
    const double h = mm(0.01);
    Vec3 g;
    for (int i = 0; i < 3; ++i) {
      Vec3 e = Vec3::Zero();
      e[i] = h;
      g[i] = (implicit(b, p + e) - implicit(b, p - e)) / (2.0 * h);
    }
    return g;
  }

  // --- cartilage regions (positive inside, ~mm scale distances) -----------
  double condyle_region(const Condyle& c, const Vec3& p) const {
    const double phi = std::atan2(p.y(), p.x());
    // Unwrapped angle: posterior-superior (phi = 130 deg) -> -230 deg, through
    // posterior (-180), distal (-90), anterior (0) to +35 deg (trochlear facet).
    const double theta = phi > deg(90.0) ? phi - 2.0 * kPi : phi;
    const double rho = std::hypot(p.x(), p.y());
    const double arc = std::min(theta - deg(-230.0), deg(35.0) - theta) * c.radius;
    const double side = mm(10.0) - std::abs(p.z() - c.centre_z);
    const double radial = (rho - (c.radius - mm(5.0))) * 2.0;
    return smin(smin(arc, side, mm(3.0)), radial, mm(2.0));
  }
  double groove_region(const Vec3& p, const Vec3& n) const {
    double r = smin(p.x() - mm(10.0), mm(12.0) - std::abs(p.z()), mm(3.0));
    r = smin(r, smin(p.y() + mm(10.0), mm(36.0) - p.y(), mm(3.0)), mm(3.0));
    return smin(r, (n.x() - 0.3) * mm(30.0), mm(2.0));
  }
  double tibia_region(bool medial, const Vec3& p, const Vec3& n) const {
    const double zc = medial ? d.medial.centre_z : d.lateral.centre_z;
    const double a = medial ? d.tibia_medial_semi_ap : d.tibia_lateral_semi_ap;
    const double b = medial ? d.tibia_medial_semi_ml : d.tibia_lateral_semi_ml;
    const double ex = (p.x() - d.plateau_centre_x) / a, ez = (p.z() - zc) / b;
    const double ellipse = b * (1.0 - std::sqrt(ex * ex + ez * ez));
    return smin(ellipse, (n.y() - 0.6) * mm(30.0), mm(2.0));
  }
  double patella_footprint(double y, double z) const {
    const double ey = (y - d.patella_y) / d.patella_cart_semi_si;
    const double ez = (z - d.patella_z) / d.patella_cart_semi_ml;
    return d.patella_cart_semi_ml * (1.0 - std::sqrt(ey * ey + ez * ez));
  }
  double region(KneeCartilage c, const Vec3& p, const Vec3& n) const {
    switch (c) {
      case KneeCartilage::kFemur:
        return std::max({condyle_region(d.medial, p), condyle_region(d.lateral, p), groove_region(p, n)});
      case KneeCartilage::kTibiaMedial: return tibia_region(true, p, n);
      case KneeCartilage::kTibiaLateral: return tibia_region(false, p, n);
      case KneeCartilage::kPatella:
        return smin(patella_footprint(p.y(), p.z()), (-n.x() - 0.2) * mm(30.0), mm(2.0));
    }
    return -1.0;
  }
  // Thickness: rim value on the outline, rising over `ramp` to a local peak.
  double ramp(double peak, double r, double width) const {
    return d.rim_thickness + (peak - d.rim_thickness) * smoothstep(r / width);
  }
  double thickness(KneeCartilage c, const Vec3& p, const Vec3& n) const {
    switch (c) {
      case KneeCartilage::kFemur: {
        // Excess over the rim value from each sub-region (condyles, groove),
        // combined by the weighted mean sum(e^5) / sum(e^4): smooth, equal to
        // the only non-zero excess where the regions do not overlap, and never
        // above the largest one.
        double num = 0.0, den = 0.0;
        for (const Condyle* cd : {&d.medial, &d.lateral}) {
          // Thickest distally (load bearing in stance), thinner posteriorly.
          const double distal = std::max(0.0, -p.y() / std::max(std::hypot(p.x(), p.y()), mm(1.0)));
          const double peak = d.condyle_posterior_thickness +
                              (d.condyle_distal_thickness - d.condyle_posterior_thickness) * distal * distal;
          const double e = ramp(peak, condyle_region(*cd, p), mm(8.0)) - d.rim_thickness;
          num += std::pow(e, 5);
          den += std::pow(e, 4);
        }
        const double e = ramp(d.trochlea_thickness, groove_region(p, n), mm(8.0)) - d.rim_thickness;
        num += std::pow(e, 5);
        den += std::pow(e, 4);
        return d.rim_thickness + (den > 0.0 ? num / den : 0.0);
      }
      case KneeCartilage::kTibiaMedial:
      case KneeCartilage::kTibiaLateral:
        return ramp(d.tibia_centre_thickness, region(c, p, n), mm(8.0));
      case KneeCartilage::kPatella: {
        const double ez = (p.z() - d.patella_z) / mm(4.0);
        const double peak = d.patella_facet_thickness +
                            (d.patella_ridge_thickness - d.patella_facet_thickness) * std::exp(-0.5 * ez * ez);
        return ramp(peak, region(c, p, n), mm(10.0));
      }
    }
    return 0.0;
  }

  // Femoral surface point below (0, *, z) and its cartilage thickness.
  Vec3 femur_distal_point(double z) const {
    Vec3 q;
    auto f = [&](const Vec3& x) { return femur(x); };
    if (!march_to_surface(f, Vec3(0, 0, z), Vec3(0, -1, 0), mm(60.0), mm(0.5), &q))
      throw std::logic_error("knee generator: no distal femoral surface");
    return q;
  }

  void solve_tibia() {
    // Target: tibial cartilage top at each plateau centre = femoral cartilage
    // bottom + overlap. The femoral surface is found numerically (blends).
    auto target = [&](const Condyle& c) {
      const Vec3 q = femur_distal_point(c.centre_z);
      const Vec3 n = gradient(KneeBone::kFemur, q).normalized();
      const double tf = thickness(KneeCartilage::kFemur, q, n);
      return q.y() - tf - d.tibia_centre_thickness + overlap;
    };
    const double ym = target(d.medial), yl = target(d.lateral);
    medial_plateau_y = ym;
    lateral_plateau_y = yl;
    // The medial/lateral blend and the tubercles' tails shift H slightly at the
    // centres: fixed-point correction (H is affine in the two reference heights).
    for (int it = 0; it < 4; ++it) {
      medial_plateau_y += ym - plateau_height(d.plateau_centre_x, d.medial.centre_z);
      lateral_plateau_y += yl - plateau_height(d.plateau_centre_x, d.lateral.centre_z);
    }
  }

  void build_patella_table() {
    // Patella back B(y, z) = femoral front x_F(y, z) + (t_F + t_P) * sec(slope)
    // - overlap + gap(y, z): conforms to the trochlea (offset along the
    // normal: the vertical distance between parallel surfaces a normal distance
    // t apart is t * sqrt(1 + |grad x_F|^2)), with a quadratic gap that opens
    // away from the centre so first contact is at the ridge centre.
    const double half_y = d.patella_semi.y() + mm(4.0), half_z = d.patella_semi.z() + mm(4.0);
    table_y0 = d.patella_y - half_y;
    table_z0 = d.patella_z - half_z;
    table_ny = static_cast<int>(std::ceil(2 * half_y / table_h)) + 1;
    table_nz = static_cast<int>(std::ceil(2 * half_z / table_h)) + 1;
    std::vector<double> front(static_cast<size_t>(table_ny) * table_nz);
    std::vector<char> valid(front.size(), 0);
    auto f = [&](const Vec3& x) { return femur(x); };
    for (int j = 0; j < table_ny; ++j)
      for (int k = 0; k < table_nz; ++k) {
        const double y = table_y0 + j * table_h, z = table_z0 + k * table_h;
        // Most anterior femoral surface point: march backwards from the front.
        Vec3 q;
        const size_t idx = static_cast<size_t>(j) * table_nz + k;
        if (march_to_surface(f, Vec3(mm(60.0), y, z), Vec3(-1, 0, 0), mm(90.0), mm(0.5), &q)) {
          front[idx] = q.x();
          valid[idx] = 1;
        }
      }
    // Cells where the femur is absent (outside the patella's outline): use
    // the lowest valid value (the patella's ellipsoid decides there anyway).
    double lowest = 1e9;
    for (size_t i = 0; i < front.size(); ++i) if (valid[i]) lowest = std::min(lowest, front[i]);
    for (size_t i = 0; i < front.size(); ++i) if (!valid[i]) front[i] = lowest;
    // Gaussian smoothing (sigma 1.5 mm) of the femoral front: the blends
    // between groove and condyles leave creases whose mirror image would give
    // the patella concave folds tighter than its cartilage thickness. The
    // quadratic gap below (about 2 mm at the facet creases) covers the small
    // shift this makes.
    {
      const double sigma = mm(1.0);
      const int rad = static_cast<int>(std::ceil(3 * sigma / table_h));
      std::vector<double> w(2 * rad + 1);
      double wsum = 0;
      for (int i = -rad; i <= rad; ++i) wsum += w[i + rad] = std::exp(-0.5 * std::pow(i * table_h / sigma, 2));
      for (double& x : w) x /= wsum;
      std::vector<double> tmp(front.size());
      for (int j = 0; j < table_ny; ++j)
        for (int k = 0; k < table_nz; ++k) {
          double acc = 0;
          for (int i = -rad; i <= rad; ++i) acc += w[i + rad] * front[static_cast<size_t>(j) * table_nz + std::clamp(k + i, 0, table_nz - 1)];
          tmp[static_cast<size_t>(j) * table_nz + k] = acc;
        }
      for (int j = 0; j < table_ny; ++j)
        for (int k = 0; k < table_nz; ++k) {
          double acc = 0;
          for (int i = -rad; i <= rad; ++i) acc += w[i + rad] * tmp[static_cast<size_t>(std::clamp(j + i, 0, table_ny - 1)) * table_nz + k];
          front[static_cast<size_t>(j) * table_nz + k] = acc;
        }
    }
    auto fr = [&](int j, int k) {
      j = std::clamp(j, 0, table_ny - 1);
      k = std::clamp(k, 0, table_nz - 1);
      return front[static_cast<size_t>(j) * table_nz + k];
    };
    back.assign(front.size(), 0.0);
    const int s = 2;  // slope stencil: +-0.5 mm
    for (int j = 0; j < table_ny; ++j)
      for (int k = 0; k < table_nz; ++k) {
        const double y = table_y0 + j * table_h, z = table_z0 + k * table_h;
        const double xf = fr(j, k);
        const double gy = (fr(j + s, k) - fr(j - s, k)) / (2 * s * table_h);
        const double gz = (fr(j, k + s) - fr(j, k - s)) / (2 * s * table_h);
        const Vec3 q(xf, y, z);
        const Vec3 nf = gradient(KneeBone::kFemur, q).normalized();
        // Outside their outlines both thickness fields return the rim value
        // (1.5 mm): the patella keeps that clearance instead of bulging
        // towards the femur where there is no cartilage (no step at the rim).
        const double tf = thickness(KneeCartilage::kFemur, q, nf);
        const double tp = thickness(KneeCartilage::kPatella, Vec3(xf, y, z), Vec3(-1.0, 0.0, 0.0));
        const double dz = (z - d.patella_z) / mm(1.0), dy = (y - d.patella_y) / mm(1.0);
        const double gap = mm(0.015 * dz * dz + 0.004 * dy * dy);
        back[static_cast<size_t>(j) * table_nz + k] =
            xf + (tf + tp) * std::sqrt(1.0 + gy * gy + gz * gz) - overlap + gap;
      }
    patella_back_x0 = back_at(d.patella_y, d.patella_z);
    // Bone AP thickness measured from the ridge; ellipsoid's back lies behind B.
    patella_centre_x = patella_back_x0 + d.patella_bone_thickness - d.patella_semi.x();
  }
};

// ---------------------------------------------------------------------------
std::string bone_file_stem(KneeBone bone) {
  switch (bone) {
    case KneeBone::kFemur: return "femur_bone";
    case KneeBone::kTibia: return "tibia_bone";
    case KneeBone::kPatella: return "patella_bone";
  }
  return "";
}
std::string cartilage_file_stem(KneeCartilage c) {
  switch (c) {
    case KneeCartilage::kFemur: return "femur_cartilage";
    case KneeCartilage::kTibiaMedial: return "tibia_medial_cartilage";
    case KneeCartilage::kTibiaLateral: return "tibia_lateral_cartilage";
    case KneeCartilage::kPatella: return "patella_cartilage";
  }
  return "";
}
std::string meniscus_file_stem(KneeMeniscus m) {
  return m == KneeMeniscus::kMedial ? "medial_meniscus" : "lateral_meniscus";
}
KneeBone cartilage_bone(KneeCartilage c) {
  switch (c) {
    case KneeCartilage::kFemur: return KneeBone::kFemur;
    case KneeCartilage::kTibiaMedial:
    case KneeCartilage::kTibiaLateral: return KneeBone::kTibia;
    case KneeCartilage::kPatella: return KneeBone::kPatella;
  }
  return KneeBone::kFemur;
}

const TriangleMesh& KneeGeometry::bone(KneeBone b) const {
  switch (b) {
    case KneeBone::kFemur: return femur_bone;
    case KneeBone::kTibia: return tibia_bone;
    case KneeBone::kPatella: return patella_bone;
  }
  return femur_bone;
}
const TriangleMesh& KneeGeometry::meniscus(KneeMeniscus m) const {
  return m == KneeMeniscus::kMedial ? medial_meniscus : lateral_meniscus;
}
const KneeCartilagePatch& KneeGeometry::patch(KneeCartilage c) const {
  for (const auto& p : cartilage)
    if (p.which == c) return p;
  throw std::logic_error("KneeGeometry: missing cartilage " + cartilage_file_stem(c));
}

ParametricKnee::ParametricKnee(double contact_overlap) : impl_(new Impl) {
  if (!(contact_overlap >= 0.0 && contact_overlap <= mm(0.5)))
    throw common::InputError("knee generator", 0,
                             "expected contact overlap in [0, 0.5] mm, found " +
                                 std::to_string(contact_overlap * 1e3) + " mm");
  impl_->overlap = contact_overlap;
  impl_->solve_tibia();
  impl_->build_patella_table();
}
ParametricKnee::~ParametricKnee() { delete impl_; }

double ParametricKnee::implicit(KneeBone bone, const Vec3& p) const { return impl_->implicit(bone, p); }
Vec3 ParametricKnee::normal(KneeBone bone, const Vec3& p) const {
  return impl_->gradient(bone, p).normalized();
}
double ParametricKnee::meniscus_implicit(KneeMeniscus m, const Vec3& p) const { return impl_->meniscus(m, p); }
void ParametricKnee::meniscus_bounds(KneeMeniscus m, Vec3* lo, Vec3* hi) const { impl_->meniscus_box(m, lo, hi); }
double ParametricKnee::region(KneeCartilage c, const Vec3& p, const Vec3& n) const {
  return impl_->region(c, p, n);
}
double ParametricKnee::thickness(KneeCartilage c, const Vec3& p, const Vec3& n) const {
  return impl_->thickness(c, p, n);
}

void ParametricKnee::bounds(KneeBone bone, Vec3* lo, Vec3* hi) const {
  const Dimensions& d = impl_->d;
  switch (bone) {
    case KneeBone::kFemur:
      *lo = Vec3(mm(-30.0), mm(-30.0), mm(-42.0));
      *hi = Vec3(mm(40.0), d.femur_shaft_top + d.femur_shaft_radius + mm(3.0), mm(42.0));
      break;
    case KneeBone::kTibia:
      *lo = Vec3(mm(-28.0), d.tibia_shaft_bottom - d.tibia_shaft_radius - mm(3.0), mm(-40.0));
      *hi = Vec3(mm(30.0), mm(-10.0), mm(40.0));
      break;
    case KneeBone::kPatella: {
      const Vec3 c(impl_->patella_centre_x, d.patella_y, d.patella_z);
      *lo = c - d.patella_semi - Vec3::Constant(mm(3.0));
      *hi = c + d.patella_semi + Vec3::Constant(mm(3.0));
      lo->x() = impl_->patella_back_x0 - mm(10.0);
      break;
    }
  }
}

std::vector<KneeLandmark> ParametricKnee::landmarks() const {
  const Impl& m = *impl_;
  const Dimensions& d = m.d;
  std::vector<KneeLandmark> out;
  auto surface = [&](KneeBone b, const Vec3& from, const Vec3& dir) {
    Vec3 q;
    auto f = [&](const Vec3& x) { return m.implicit(b, x); };
    if (!march_to_surface(f, from, dir.normalized(), mm(100.0), mm(0.25), &q))
      throw std::logic_error("knee generator: landmark ray missed the surface");
    return q;
  };
  const Vec3 X(1, 0, 0), Y(0, 1, 0), Z(0, 0, 1);
  auto add = [&](const std::string& body, const std::string& name, const Vec3& p, const std::string& note) {
    out.push_back({body, name, p, note});
  };
  // Femur.
  add("femur", "flexion_axis_midpoint", Vec3::Zero(), "model origin (knee joint centre)");
  for (const auto* c : {&d.medial, &d.lateral}) {
    const std::string side = c == &d.medial ? "medial" : "lateral";
    const Vec3 centre(0, 0, c->centre_z);
    add("femur", side + "_condyle_centre", centre, "centre of the posterior condylar arc, on the flexion axis");
    add("femur", side + "_condyle_distal", surface(KneeBone::kFemur, centre, -Y), "most distal bone point of the condyle");
    add("femur", side + "_condyle_posterior", surface(KneeBone::kFemur, centre, -X), "most posterior bone point of the condyle");
    const double sz = c == &d.medial ? -1.0 : 1.0;
    add("femur", side + "_epicondyle",
        surface(KneeBone::kFemur, Vec3(d.metaphysis_centre.x(), d.metaphysis_centre.y(), 0), sz * Z),
        "most " + side + " bone point at the epicondylar level");
  }
  add("femur", "trochlear_groove", surface(KneeBone::kFemur, Vec3(0, d.patella_y, d.patella_z), X),
      "groove bottom (bone) at the level of the patella centre");
  add("femur", "intercondylar_notch_roof", surface(KneeBone::kFemur, Vec3(mm(-6.0), mm(-40.0), 0), Y),
      "bone point of the notch roof, 6 mm posterior of the flexion axis");
  add("femur", "shaft_axis_proximal", Vec3(d.shaft_x, d.femur_shaft_top, 0), "on the femoral shaft axis at the top of the meshed shaft");
  // Tibia.
  for (bool medial : {true, false}) {
    const std::string side = medial ? "medial" : "lateral";
    const double zc = medial ? d.medial.centre_z : d.lateral.centre_z;
    add("tibia", side + "_plateau_centre", Vec3(d.plateau_centre_x, m.plateau_height(d.plateau_centre_x, zc), zc),
        "bone surface at the plateau centre (cartilage adds 3 mm)");
    const double sz = medial ? -1.0 : 1.0;
    add("tibia", side + "_intercondylar_tubercle",
        Vec3(mm(2.0), m.plateau_height(mm(2.0), sz * d.spine_z), sz * d.spine_z), "tip of the tibial spine");
  }
  add("tibia", "tuberosity", surface(KneeBone::kTibia, Vec3(0, d.tuberosity_centre.y(), d.tuberosity_centre.z()), X),
      "most anterior bone point of the tibial tuberosity");
  add("tibia", "plateau_anterior_rim", surface(KneeBone::kTibia, Vec3(0, m.plateau_height(0, 0) - mm(12.0), 0), X),
      "anterior bone point 12 mm below the eminence, midline");
  add("tibia", "plateau_posterior_rim", surface(KneeBone::kTibia, Vec3(0, m.plateau_height(0, 0) - mm(12.0), 0), -X),
      "posterior bone point 12 mm below the eminence, midline");
  add("tibia", "fibular_head", Vec3(mm(-16.0), mm(-42.0), mm(36.0)),
      "approximate fibular head centre (posterolateral); the fibula is not meshed");
  add("tibia", "shaft_axis_distal", Vec3(0, d.tibia_shaft_bottom, 0), "on the tibial shaft axis at the bottom of the meshed shaft");
  // Patella.
  const Vec3 pc(m.patella_centre_x, d.patella_y, d.patella_z);
  const Vec3 ridge = surface(KneeBone::kPatella, pc, -X);
  const Vec3 front = surface(KneeBone::kPatella, pc, X);
  const Vec3 mid = 0.5 * (ridge + front);
  add("patella", "centre", mid, "midpoint between the articular ridge and the anterior surface");
  add("patella", "articular_ridge", ridge, "bone point of the median ridge at the centre");
  add("patella", "anterior", front, "anterior bone point at the centre");
  add("patella", "apex", surface(KneeBone::kPatella, mid, -Y), "inferior pole (patellar tendon origin)");
  add("patella", "base", surface(KneeBone::kPatella, mid, Y), "superior pole (quadriceps tendon insertion)");
  add("patella", "medial_border", surface(KneeBone::kPatella, mid, -Z), "most medial bone point");
  add("patella", "lateral_border", surface(KneeBone::kPatella, mid, Z), "most lateral bone point");
  // Limb: mechanical axis along Y, neutral alignment.
  add("limb", "hip_centre", Vec3(0, d.thigh_fraction * d.stature, 0),
      "on the mechanical axis, thigh length 0.245 x stature (Winter 2009)");
  add("limb", "ankle_centre", Vec3(0, -d.leg_fraction * d.stature, 0),
      "on the mechanical axis, leg length 0.246 x stature (Winter 2009)");
  return out;
}

// ---------------------------------------------------------------------------
TriangleMesh contour_implicit(const std::function<double(const Vec3&)>& f, const Vec3& lo,
                              const Vec3& hi, double h, const std::string& name) {
  const Eigen::Vector3i n = ((hi - lo) / h).array().ceil().cast<int>() + 1;
  const int64_t nx = n.x(), ny = n.y(), nz = n.z();
  std::vector<double> val(static_cast<size_t>(nx * ny * nz));
  auto node = [&](int64_t i, int64_t j, int64_t k) { return i + nx * (j + ny * k); };
  auto pos = [&](int64_t id) {
    const int64_t i = id % nx, j = (id / nx) % ny, k = id / (nx * ny);
    return Vec3(lo.x() + i * h, lo.y() + j * h, lo.z() + k * h);
  };
  const double tiny = 1e-9 * h;
#pragma omp parallel for schedule(static)
  for (int64_t k = 0; k < nz; ++k)
    for (int64_t j = 0; j < ny; ++j)
      for (int64_t i = 0; i < nx; ++i) {
        double v = f(Vec3(lo.x() + i * h, lo.y() + j * h, lo.z() + k * h));
        if (!std::isfinite(v))
          throw std::logic_error("contour_implicit: non-finite implicit value in " + name);
        if (v == 0.0) v = tiny;  // no vertex exactly on a grid node
        val[static_cast<size_t>(node(i, j, k))] = v;
      }
  std::unordered_map<uint64_t, int> edge_vertex;
  std::vector<Vec3> verts;
  std::vector<std::array<int, 3>> tris;
  auto vertex_on = [&](int64_t a, int64_t b) {
    if (a > b) std::swap(a, b);
    const uint64_t key = (static_cast<uint64_t>(a) << 32) | static_cast<uint64_t>(b - a);
    auto it = edge_vertex.find(key);
    if (it != edge_vertex.end()) return it->second;
    const double fa = val[a], fb = val[b];
    const double t = std::clamp(fa / (fa - fb), 0.01, 0.99);
    verts.push_back((1 - t) * pos(a) + t * pos(b));
    const int id = static_cast<int>(verts.size()) - 1;
    edge_vertex.emplace(key, id);
    return id;
  };
  // Kuhn split: 6 tetrahedra around the diagonal corner 0 -> corner 7
  // (corner c = i + 2 j + 4 k); conforming between neighbouring cubes.
  static const int kTets[6][4] = {{0, 1, 3, 7}, {0, 3, 2, 7}, {0, 2, 6, 7},
                                  {0, 6, 4, 7}, {0, 4, 5, 7}, {0, 5, 1, 7}};
  auto emit = [&](int a, int b, int c, const Vec3& dir) {
    const Vec3 nrm = (verts[b] - verts[a]).cross(verts[c] - verts[a]);
    if (nrm.dot(dir) < 0) std::swap(b, c);
    tris.push_back({a, b, c});
  };
  for (int64_t k = 0; k + 1 < nz; ++k)
    for (int64_t j = 0; j + 1 < ny; ++j)
      for (int64_t i = 0; i + 1 < nx; ++i) {
        int64_t corner[8];
        bool any_in = false, any_out = false;
        for (int c = 0; c < 8; ++c) {
          corner[c] = node(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
          (val[corner[c]] < 0 ? any_in : any_out) = true;
        }
        if (!any_in || !any_out) continue;
        for (const auto& tet : kTets) {
          int64_t in[4], out[4];
          int nin = 0, nout = 0;
          for (int c : tet) (val[corner[c]] < 0 ? in[nin++] : out[nout++]) = corner[c];
          if (nin == 0 || nout == 0) continue;
          Vec3 cin = Vec3::Zero(), cout = Vec3::Zero();
          for (int q = 0; q < nin; ++q) cin += pos(in[q]);
          for (int q = 0; q < nout; ++q) cout += pos(out[q]);
          const Vec3 dir = cout / nout - cin / nin;  // towards f > 0
          if (nin == 1 || nout == 1) {
            const int64_t apex = nin == 1 ? in[0] : out[0];
            const int64_t* others = nin == 1 ? out : in;
            emit(vertex_on(apex, others[0]), vertex_on(apex, others[1]), vertex_on(apex, others[2]), dir);
          } else {
            const int a = vertex_on(in[0], out[0]), b = vertex_on(in[0], out[1]);
            const int c = vertex_on(in[1], out[1]), e = vertex_on(in[1], out[0]);
            // a, b, c, e go round the quad (in0out0, in0out1, in1out1, in1out0).
            emit(a, b, c, dir);
            emit(a, c, e, dir);
          }
        }
      }
  const int nv = static_cast<int>(verts.size());
  TriangleMesh mesh;
  mesh.name = name;
  mesh.V.resize(nv, 3);
  for (int v = 0; v < nv; ++v) mesh.V.row(v) = verts[v].transpose();
  mesh.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (size_t t = 0; t < tris.size(); ++t) mesh.F.row(t) << tris[t][0], tris[t][1], tris[t][2];
  return mesh;
}

namespace {
// Newton projection of the vertices onto f = 0 (step limited to `max_step`).
void project_onto_implicit(const std::function<double(const Vec3&)>& f, double max_step, TriangleMesh* mesh) {
  const int nv = mesh->num_vertices();
#pragma omp parallel for schedule(static)
  for (int v = 0; v < nv; ++v) {
    Vec3 p = mesh->vertex(v);
    for (int it = 0; it < 3; ++it) {
      const double fv = f(p);
      Vec3 g;
      const double e = 1e-5 * max_step / 1e-3;
      for (int a = 0; a < 3; ++a) {
        Vec3 d = Vec3::Zero();
        d[a] = e;
        g[a] = (f(p + d) - f(p - d)) / (2 * e);
      }
      const double g2 = g.squaredNorm();
      if (g2 < 1e-12) break;
      Vec3 step = -fv / g2 * g;
      if (step.norm() > max_step) step *= max_step / step.norm();
      p += step;
    }
    mesh->V.row(v) = p.transpose();
  }
}
}  // namespace

TriangleMesh clip_by_vertex_field(const TriangleMesh& mesh, const Eigen::VectorXd& r_in,
                                  double snap_fraction, const std::string& name) {
  const int nv = mesh.num_vertices();
  Points3 V = mesh.V;
  Eigen::VectorXd r = r_in;
  // Snap: a vertex whose nearest cut point (over its sign-changing edges) is
  // within snap_fraction of that edge moves onto the cut and gets r = 0.
  std::vector<double> best(nv, 2.0);
  std::vector<Vec3> target(nv);
  for (int t = 0; t < mesh.num_triangles(); ++t)
    for (int e = 0; e < 3; ++e) {
      const int a = mesh.F(t, e), b = mesh.F(t, (e + 1) % 3);
      if ((r[a] > 0) == (r[b] > 0)) continue;
      const double s = r[a] / (r[a] - r[b]);  // cut at a + s (b - a)
      const Vec3 cut = (1 - s) * mesh.vertex(a) + s * mesh.vertex(b);
      if (s < best[a]) { best[a] = s; target[a] = cut; }
      if (1 - s < best[b]) { best[b] = 1 - s; target[b] = cut; }
    }
  for (int v = 0; v < nv; ++v)
    if (best[v] < snap_fraction) {
      V.row(v) = target[v].transpose();
      r[v] = 0.0;
    }
  // Clip every triangle to r >= 0 (Sutherland-Hodgman; cut points shared
  // through an edge map so the patch is conforming).
  std::vector<Vec3> verts;
  std::vector<int> old_to_new(nv, -1);
  std::unordered_map<uint64_t, int> cut_vertex;
  auto keep = [&](int v) {
    if (old_to_new[v] < 0) {
      old_to_new[v] = static_cast<int>(verts.size());
      verts.push_back(V.row(v).transpose());
    }
    return old_to_new[v];
  };
  auto cut = [&](int a, int b) {
    const uint64_t key = (static_cast<uint64_t>(std::min(a, b)) << 32) | static_cast<uint32_t>(std::max(a, b));
    auto it = cut_vertex.find(key);
    if (it != cut_vertex.end()) return it->second;
    const double s = r[a] / (r[a] - r[b]);
    verts.push_back(((1 - s) * V.row(a) + s * V.row(b)).transpose());
    const int id = static_cast<int>(verts.size()) - 1;
    cut_vertex.emplace(key, id);
    return id;
  };
  std::vector<std::array<int, 3>> tris;
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    int poly[4];
    int np = 0;
    for (int e = 0; e < 3; ++e) {
      const int a = mesh.F(t, e), b = mesh.F(t, (e + 1) % 3);
      if (r[a] >= 0) poly[np++] = keep(a);
      if ((r[a] > 0 && r[b] < 0) || (r[a] < 0 && r[b] > 0)) poly[np++] = cut(a, b);
    }
    for (int q = 1; q + 1 < np; ++q) tris.push_back({poly[0], poly[q], poly[q + 1]});
  }
  // Drop zero-area pieces (three snapped vertices on one line, etc.).
  TriangleMesh out;
  out.name = name;
  std::vector<std::array<int, 3>> good;
  for (const auto& tr : tris) {
    const Vec3 n = (verts[tr[1]] - verts[tr[0]]).cross(verts[tr[2]] - verts[tr[0]]);
    const double l2 = std::max({(verts[tr[1]] - verts[tr[0]]).squaredNorm(),
                                (verts[tr[2]] - verts[tr[1]]).squaredNorm(),
                                (verts[tr[0]] - verts[tr[2]]).squaredNorm()});
    if (n.norm() > 1e-6 * l2) good.push_back(tr);
  }
  // Compact (vertices in order of first use).
  std::vector<int> remap(verts.size(), -1);
  std::vector<Vec3> used;
  for (auto& tr : good)
    for (int& v : tr) {
      if (remap[v] < 0) { remap[v] = static_cast<int>(used.size()); used.push_back(verts[v]); }
      v = remap[v];
    }
  out.V.resize(static_cast<Eigen::Index>(used.size()), 3);
  for (size_t v = 0; v < used.size(); ++v) out.V.row(v) = used[v].transpose();
  out.F.resize(static_cast<Eigen::Index>(good.size()), 3);
  for (size_t t = 0; t < good.size(); ++t) out.F.row(t) << good[t][0], good[t][1], good[t][2];
  return out;
}

namespace {

// Renumbers vertices in order of first use by F (what an STL reader that
// welds identical corners reproduces); returns old index per new index.
std::vector<int> renumber_by_first_use(TriangleMesh* mesh) {
  std::vector<int> remap(mesh->num_vertices(), -1), order;
  for (int t = 0; t < mesh->num_triangles(); ++t)
    for (int e = 0; e < 3; ++e) {
      int& v = mesh->F(t, e);
      if (remap[v] < 0) { remap[v] = static_cast<int>(order.size()); order.push_back(v); }
      v = remap[v];
    }
  Points3 V(static_cast<Eigen::Index>(order.size()), 3);
  for (size_t i = 0; i < order.size(); ++i) V.row(i) = mesh->V.row(order[i]);
  mesh->V = V;
  return order;
}

// The edge-connected component with the largest area (a region function can
// leave specks where it grazes zero at a patch's far edge; they are dropped).
TriangleMesh largest_component(const TriangleMesh& mesh) {
  const common::MeshTopology topo = common::build_topology(mesh);
  const Eigen::VectorXd area = common::triangle_areas(mesh);
  std::vector<int> comp(mesh.num_triangles(), -1);
  std::vector<double> comp_area;
  for (int seed = 0; seed < mesh.num_triangles(); ++seed) {
    if (comp[seed] >= 0) continue;
    const int id = static_cast<int>(comp_area.size());
    comp_area.push_back(0.0);
    std::vector<int> stack{seed};
    comp[seed] = id;
    while (!stack.empty()) {
      const int t = stack.back();
      stack.pop_back();
      comp_area[id] += area[t];
      for (int k = 0; k < 3; ++k) {
        const int nb = topo.triangle_neighbours(t, k);
        if (nb >= 0 && comp[nb] < 0) { comp[nb] = id; stack.push_back(nb); }
      }
    }
  }
  const int best = static_cast<int>(std::max_element(comp_area.begin(), comp_area.end()) - comp_area.begin());
  TriangleMesh out;
  out.name = mesh.name;
  std::vector<int> remap(mesh.num_vertices(), -1);
  std::vector<int> used;
  std::vector<std::array<int, 3>> tris;
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    if (comp[t] != best) continue;
    std::array<int, 3> tr;
    for (int k = 0; k < 3; ++k) {
      int& m = remap[mesh.F(t, k)];
      if (m < 0) { m = static_cast<int>(used.size()); used.push_back(mesh.F(t, k)); }
      tr[k] = m;
    }
    tris.push_back(tr);
  }
  out.V.resize(static_cast<Eigen::Index>(used.size()), 3);
  for (size_t i = 0; i < used.size(); ++i) out.V.row(i) = mesh.V.row(used[i]);
  out.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (size_t t = 0; t < tris.size(); ++t) out.F.row(t) << tris[t][0], tris[t][1], tris[t][2];
  return out;
}

}  // namespace

KneeGeneratorOptions fine_knee_options() {
  KneeGeneratorOptions o;
  o.edge_length = 0.74e-3;
  o.cartilage_edge_length[KneeCartilage::kTibiaMedial] = 0.57e-3;
  o.cartilage_edge_length[KneeCartilage::kTibiaLateral] = 0.57e-3;
  return o;
}

KneeGeometry ParametricKnee::generate(const KneeGeneratorOptions& options) const {
  if (!(options.edge_length >= mm(0.5) && options.edge_length <= mm(6.0)))
    throw common::InputError("knee generator", 0,
                             "expected edge length in [0.5, 6] mm, found " +
                                 std::to_string(options.edge_length * 1e3) + " mm");
  const double h = options.grid_spacing > 0 ? options.grid_spacing
                                            : std::clamp(options.edge_length / 2.5, mm(0.4), mm(1.0));
  if (!(h >= mm(0.2) && h <= mm(2.0)))
    throw common::InputError("knee generator", 0,
                             "expected grid spacing in [0.2, 2] mm, found " + std::to_string(h * 1e3) + " mm");
  if (options.remesh_iterations < 1 || options.remesh_iterations > 20)
    throw common::InputError("knee generator", 0, "expected remesh iterations in [1, 20], found " +
                                                      std::to_string(options.remesh_iterations));
  for (const auto& [c, e] : options.cartilage_edge_length)
    if (!(e >= mm(0.5) && e <= mm(6.0)))
      throw common::InputError("knee generator", 0,
                               "expected the edge length of " + cartilage_file_stem(c) +
                                   " in [0.5, 6] mm, found " + std::to_string(e * 1e3) + " mm");
  const Impl* m = impl_;
  const ParametricKnee& shape = *this;

  common::RemeshOptions ro;
  ro.target_edge_length = options.edge_length;
  ro.iterations = options.remesh_iterations;

  KneeGeometry g;
  g.contact_overlap = m->overlap;
  for (KneeBone b : {KneeBone::kFemur, KneeBone::kTibia, KneeBone::kPatella}) {
    Vec3 lo, hi;
    shape.bounds(b, &lo, &hi);
    TriangleMesh raw = contour_implicit([&](const Vec3& p) { return m->implicit(b, p); }, lo, hi, h,
                                        bone_file_stem(b));
    // Remesh the contour (its vertices are linear interpolants on grid edges),
    // then put the remeshed vertices exactly on f = 0. Projecting before the
    // remesh could fold the contour's tiny triangles into degenerate ones.
    TriangleMesh bone = common::isotropic_remesh(raw, ro);
    project_onto_implicit([&](const Vec3& p) { return m->implicit(b, p); }, 0.25 * h, &bone);
    bone.name = bone_file_stem(b);
    renumber_by_first_use(&bone);
    switch (b) {
      case KneeBone::kFemur: g.femur_bone = std::move(bone); break;
      case KneeBone::kTibia: g.tibia_bone = std::move(bone); break;
      case KneeBone::kPatella: g.patella_bone = std::move(bone); break;
    }
  }
  for (KneeCartilage c : {KneeCartilage::kFemur, KneeCartilage::kTibiaMedial, KneeCartilage::kTibiaLateral,
                          KneeCartilage::kPatella}) {
    const KneeBone b = cartilage_bone(c);
    const TriangleMesh& bone = g.bone(b);
    Eigen::VectorXd r(bone.num_vertices());
    for (int v = 0; v < bone.num_vertices(); ++v) {
      const Vec3 p = bone.vertex(v);
      r[v] = m->region(c, p, m->gradient(b, p).normalized());
    }
    TriangleMesh cut = largest_component(clip_by_vertex_field(bone, r, 0.3, cartilage_file_stem(c)));
    common::RemeshOptions rc = ro;
    const auto own = options.cartilage_edge_length.find(c);
    if (own != options.cartilage_edge_length.end()) rc.target_edge_length = own->second;
    TriangleMesh base = common::isotropic_remesh(cut, rc);
    if (rc.target_edge_length < ro.target_edge_length)
      project_onto_implicit([&](const Vec3& p) { return m->implicit(b, p); }, 0.25 * h, &base);
    KneeCartilagePatch patch;
    patch.which = c;
    patch.mesh = base;
    patch.mesh.name = cartilage_file_stem(c);
    patch.thickness.resize(base.num_vertices());
    patch.bone_points = base.V;
    for (int v = 0; v < base.num_vertices(); ++v) {
      const Vec3 p = base.vertex(v);
      const Vec3 n = m->gradient(b, p).normalized();
      const double t = m->thickness(c, p, n);
      patch.thickness[v] = t;
      patch.mesh.V.row(v) = (p + t * n).transpose();
    }
    const std::vector<int> order = renumber_by_first_use(&patch.mesh);
    Eigen::VectorXd th(order.size());
    Points3 bp(static_cast<Eigen::Index>(order.size()), 3);
    for (size_t i = 0; i < order.size(); ++i) {
      th[i] = patch.thickness[order[i]];
      bp.row(i) = patch.bone_points.row(order[i]);
    }
    patch.thickness = th;
    patch.bone_points = bp;
    g.cartilage.push_back(std::move(patch));
  }
  for (KneeMeniscus w : {KneeMeniscus::kMedial, KneeMeniscus::kLateral}) {
    Vec3 lo, hi;
    m->meniscus_box(w, &lo, &hi);
    auto f = [&](const Vec3& p) { return m->meniscus(w, p); };
    // A finer grid than the bones' resolves the 1 mm inner edge.
    TriangleMesh raw = contour_implicit(f, lo, hi, std::min(h, mm(0.5)), meniscus_file_stem(w));
    TriangleMesh men = largest_component(common::isotropic_remesh(raw, ro));
    project_onto_implicit(f, 0.25 * h, &men);
    men.name = meniscus_file_stem(w);
    renumber_by_first_use(&men);
    (w == KneeMeniscus::kMedial ? g.medial_meniscus : g.lateral_meniscus) = std::move(men);
  }
  g.landmarks = shape.landmarks();
  return g;
}

SurfaceOverlap surface_overlap(const TriangleMesh& a, const TriangleMesh& b, double search_depth) {
  const common::TriangleTree tree(b);
  const Points3 na = common::vertex_normals(a);
  const Points3 nb = common::triangle_normals(b);
  SurfaceOverlap out;
  for (int v = 0; v < a.num_vertices(); ++v) {
    const Vec3 dir = -na.row(v).transpose();
    const auto hit = tree.first_hit(a.vertex(v), dir, search_depth);
    if (!hit || nb.row(hit->triangle).dot(dir) <= 0.0) continue;
    ++out.penetrating_vertices;
    if (hit->distance > out.max_depth) {
      out.max_depth = hit->distance;
      out.at = a.vertex(v);
    }
  }
  return out;
}

// ---------------------------------------------------------------------------
void write_knee_geometry(const KneeGeometry& g, const KneeGeneratorOptions& options, const std::string& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw common::InputError(dir, 0, "cannot create the output directory: " + ec.message());
  for (KneeBone b : {KneeBone::kFemur, KneeBone::kTibia, KneeBone::kPatella})
    common::write_stl(g.bone(b), (fs::path(dir) / (bone_file_stem(b) + ".stl")).string());
  for (const auto& patch : g.cartilage) {
    const std::string stem = cartilage_file_stem(patch.which);
    const std::string stl = (fs::path(dir) / (stem + ".stl")).string();
    common::write_stl(patch.mesh, stl);
    const std::string csv = (fs::path(dir) / (stem + "_thickness.csv")).string();
    std::ofstream out(csv);
    if (!out) throw common::InputError(csv, 0, "cannot open for writing");
    out << "# analytic cartilage thickness per vertex of " << stem
        << ".stl (vertices in order of first use by the triangles)\n";
    out << "x_mm,y_mm,z_mm,thickness_mm\n";
    char line[160];
    for (int v = 0; v < patch.mesh.num_vertices(); ++v) {
      // Coordinates as the STL stores them (float millimetres).
      const float x = static_cast<float>(patch.mesh.V(v, 0) / 1e-3);
      const float y = static_cast<float>(patch.mesh.V(v, 1) / 1e-3);
      const float z = static_cast<float>(patch.mesh.V(v, 2) / 1e-3);
      std::snprintf(line, sizeof line, "%.9g,%.9g,%.9g,%.9f\n", x, y, z, patch.thickness[v] * 1e3);
      out << line;
    }
    if (!out) throw common::InputError(csv, 0, "write failed");
  }
  for (KneeMeniscus w : {KneeMeniscus::kMedial, KneeMeniscus::kLateral})
    if (g.meniscus(w).num_triangles() > 0)
      common::write_stl(g.meniscus(w), (fs::path(dir) / (meniscus_file_stem(w) + ".stl")).string());
  const std::string yaml = (fs::path(dir) / "landmarks.yaml").string();
  std::ofstream y(yaml);
  if (!y) throw common::InputError(yaml, 0, "cannot open for writing");
  y << "# Landmarks of the parametric right knee (arthrosim-make-knee), full extension.\n"
       "# Model frame = femur frame: origin at the midpoint of the flexion axis through the\n"
       "# posterior condyle centres, X anterior, Y superior, Z right (lateral). Metres.\n"
       "# See docs/knee_geometry.md.\n";
  char buf[256];
  std::snprintf(buf, sizeof buf, "generator:\n  edge_length_mm: %.6g\n  contact_overlap_mm: %.6g\n",
                options.edge_length * 1e3, g.contact_overlap * 1e3);
  y << buf << "units: m\nframe: femur_at_extension\nside: right\nlandmarks:\n";
  std::string body;
  for (const auto& l : g.landmarks) {
    if (l.body != body) {
      body = l.body;
      y << "  " << body << ":\n";
    }
    std::snprintf(buf, sizeof buf, "    %s: [%.7f, %.7f, %.7f]  # %s\n", l.name.c_str(), l.p_F.x(), l.p_F.y(),
                  l.p_F.z(), l.note.c_str());
    y << buf;
  }
  if (!y) throw common::InputError(yaml, 0, "write failed");
}

Eigen::VectorXd read_thickness_csv(const std::string& path, const TriangleMesh& mesh) {
  std::ifstream in(path);
  if (!in) throw common::InputError(path, 0, "cannot open the thickness file");
  std::string line;
  int lineno = 0, row = 0;
  Eigen::VectorXd t(mesh.num_vertices());
  bool header = false;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    if (!header) {
      if (line.rfind("x_mm,y_mm,z_mm,thickness_mm", 0) != 0)
        throw common::InputError(path, lineno, "expected header 'x_mm,y_mm,z_mm,thickness_mm', found '" + line + "'");
      header = true;
      continue;
    }
    double x, y, z, th;
    char c1, c2, c3;
    std::istringstream ss(line);
    if (!(ss >> x >> c1 >> y >> c2 >> z >> c3 >> th) || c1 != ',' || c2 != ',' || c3 != ',')
      throw common::InputError(path, lineno, "expected 4 comma-separated numbers, found '" + line + "'");
    if (row >= mesh.num_vertices())
      throw common::InputError(path, lineno, "more rows than the " + std::to_string(mesh.num_vertices()) +
                                                 " vertices of " + mesh.name);
    const Vec3 p(x * 1e-3, y * 1e-3, z * 1e-3);
    if ((p - mesh.vertex(row)).norm() > 1e-6)
      throw common::InputError(path, lineno, "row position does not match vertex " + std::to_string(row) + " of " +
                                                 mesh.name);
    if (!std::isfinite(th) || th <= 0)
      throw common::InputError(path, lineno, "expected a positive thickness, found '" + line + "'");
    t[row++] = th * 1e-3;
  }
  if (row != mesh.num_vertices())
    throw common::InputError(path, lineno, "expected " + std::to_string(mesh.num_vertices()) + " rows, found " +
                                               std::to_string(row));
  return t;
}

}  // namespace arthrosim::pipelines
