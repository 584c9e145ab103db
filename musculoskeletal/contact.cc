#include "musculoskeletal/contact.h"

#include <cmath>
#include <limits>
#include <map>
#include <sstream>
#include <utility>

#include "common/error.h"
#include "common/spatial.h"

namespace arthrosim::musculoskeletal {

double foundation_modulus(const ElasticFoundationParameters& p) {
  const double E = p.youngs_modulus, nu = p.poisson_ratio;
  return (1.0 - nu) * E / ((1.0 + nu) * (1.0 - 2.0 * nu));
}

namespace {

void check_surface(const std::string& pair, const char* role, const ContactSurface& s) {
  auto fail = [&](const std::string& what) {
    throw common::InputError("contact pair '" + pair + "' " + role + " surface: " + what);
  };
  if (s.mesh.num_triangles() == 0) fail("expected a mesh with triangles, found none");
  if (s.body < 0) fail("expected a body index >= 0, found " + std::to_string(s.body));
  if (s.thickness.size() != s.mesh.num_triangles())
    fail("expected " + std::to_string(s.mesh.num_triangles()) + " thickness values (one per "
         "triangle), found " + std::to_string(s.thickness.size()));
  for (int i = 0; i < s.thickness.size(); ++i)
    if (!(s.thickness[i] >= 0.0) || !std::isfinite(s.thickness[i])) {
      std::ostringstream m;
      m << "expected thickness >= 0 m, found " << s.thickness[i] << " at triangle " << i;
      fail(m.str());
    }
  if (!s.compartment.empty() && static_cast<int>(s.compartment.size()) != s.mesh.num_triangles())
    fail("expected " + std::to_string(s.mesh.num_triangles()) + " compartment labels (one per triangle), found " +
         std::to_string(s.compartment.size()));
  for (int i = 0; i < s.mesh.num_triangles(); ++i)
    for (int k = 0; k < 3; ++k)
      if (s.mesh.F(i, k) < 0 || s.mesh.F(i, k) >= s.mesh.num_vertices())
        fail("triangle " + std::to_string(i) + " has a vertex index out of range");
}

// Edge neighbours (neighbour k across the edge opposite vertex k, -1 if none).
common::Triangles neighbours(const common::TriangleMesh& m) {
  common::Triangles N = common::Triangles::Constant(m.num_triangles(), 3, -1);
  std::map<std::pair<int, int>, std::pair<int, int>> first;  // edge -> (tri, k)
  for (int t = 0; t < m.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      int a = m.F(t, (k + 1) % 3), b = m.F(t, (k + 2) % 3);
      if (a > b) std::swap(a, b);
      auto [it, inserted] = first.try_emplace({a, b}, t, k);
      if (!inserted) {
        N(t, k) = it->second.first;
        N(it->second.first, it->second.second) = t;
      }
    }
  return N;
}

}  // namespace

ContactPair::ContactPair(std::string name, ContactSurface casting, ContactSurface target,
                         ElasticFoundationParameters material)
    : name_(std::move(name)),
      casting_(std::move(casting)),
      target_(std::move(target)),
      material_(material) {
  check_surface(name_, "casting", casting_);
  check_surface(name_, "target", target_);
  const double E = material_.youngs_modulus, nu = material_.poisson_ratio;
  if (!(E > 0.0) || !std::isfinite(E))
    throw common::InputError("contact pair '" + name_ + "': expected Young's modulus > 0 Pa, found " +
                             std::to_string(E));
  if (!(nu >= 0.0 && nu < 0.5))
    throw common::InputError("contact pair '" + name_ +
                             "': expected 0 <= Poisson ratio < 0.5, found " + std::to_string(nu));
  if (!(material_.max_overlap_factor > 0.0))
    throw common::InputError("contact pair '" + name_ + "': expected max_overlap_factor > 0");
  K_ = foundation_modulus(material_);
  d_max_ = material_.max_overlap_factor *
           (casting_.thickness.maxCoeff() + target_.thickness.maxCoeff());
  if (!(d_max_ > 0.0))
    throw common::InputError("contact pair '" + name_ +
                             "': expected a positive combined thickness, found both surfaces rigid");

  const auto& M = casting_.mesh;
  const int n = M.num_triangles();
  c_A_.resize(n, 3);
  n_A_.resize(n, 3);
  area_A_.resize(n);
  for (int i = 0; i < n; ++i) {
    const Vec3 a = M.vertex(M.F(i, 0)), b = M.vertex(M.F(i, 1)), c = M.vertex(M.F(i, 2));
    const Vec3 cr = (b - a).cross(c - a);
    const double len = cr.norm();
    c_A_.row(i) = ((a + b + c) / 3.0).transpose();
    area_A_[i] = 0.5 * len;
    n_A_.row(i) = (len > 0 ? Vec3(cr / len) : Vec3::Zero()).transpose();
  }
  const auto& T = target_.mesh;
  m_B_.resize(T.num_triangles(), 3);
  for (int i = 0; i < T.num_triangles(); ++i) {
    const Vec3 a = T.vertex(T.F(i, 0)), b = T.vertex(T.F(i, 1)), c = T.vertex(T.F(i, 2));
    const Vec3 cr = (b - a).cross(c - a);
    const double len = cr.norm();
    m_B_.row(i) = (len > 0 ? Vec3(cr / len) : Vec3::Zero()).transpose();
  }
  nbr_B_ = neighbours(T);
  tree_ = std::make_unique<common::TriangleTree>(T);
}

ContactPair::~ContactPair() = default;
ContactPair::ContactPair(ContactPair&&) noexcept = default;
ContactPair& ContactPair::operator=(ContactPair&&) noexcept = default;

void ContactPairData::reset() {
  last_hit.clear();
  clearance.clear();
  has_candidates.clear();
  candidates.clear();
  has_far.clear();
  far_candidates.clear();
}

void evaluate_contact(const ContactPair& pair, const Pose& X_WA, const Pose& X_WB,
                      ContactPairData& data) {
  const int n = pair.casting().mesh.num_triangles();
  if (static_cast<int>(data.last_hit.size()) != n) {
    data.last_hit.assign(n, -1);
    data.clearance.assign(n, std::numeric_limits<double>::quiet_NaN());
    data.clearance_centre_B.setZero(n, 3);
    data.has_candidates.assign(n, 0);
    data.candidates.assign(n, {});
    data.has_far.assign(n, 0);
    data.far_candidates.assign(n, {});
    data.far_start_B.setZero(n, 3);
    data.far_end_B.setZero(n, 3);
    data.candidate_start_B.setZero(n, 3);
    data.candidate_end_B.setZero(n, 3);
  }
  ContactResult& r = data.result;
  r = ContactResult();
  r.pressure.setZero(n);
  r.overlap.setZero(n);
  data.stats = ContactSearchStats();

  const Pose X_BA = X_WB.inverse() * X_WA;
  const Eigen::Matrix3d R_BA = X_BA.linear();
  const common::TriangleTree& tree = pair.target_tree();
  const auto& m_B = pair.target_normals();
  const auto& nbr = pair.target_neighbours();
  const auto& tB = pair.target().thickness;
  const auto& tA = pair.casting().thickness;
  const double d_max = pair.max_overlap(), K = pair.modulus();
  const bool nonlinear = pair.material().law == FoundationLaw::kNonlinear;
  // Box margin of step 3 (see header): 5 % of the largest combined
  // thickness, not of d_max, so a long search range (OpenSim-JAM's
  // max_proximity 20 mm over 6 mm of cartilage) does not widen the ring of
  // near misses and their boxes (measured on lenhart2015: 1,500 instead of
  // 220 boxes of 49 instead of 9 triangles per evaluation; docs/comak.md).
  const double mu = 0.05 * d_max / pair.material().max_overlap_factor;

  // Accumulated in the target frame B, then rotated to the world.
  Vec3 F_B = Vec3::Zero(), M_B = Vec3::Zero(), cop_B = Vec3::Zero();
  double sum_pA = 0.0;

  // The segment [c, c + d_max dir] in two parts: the near part (length
  // L = min(d_max, h_max), h_max the largest combined thickness) searched as
  // described in the header, and, when the search range is longer than the
  // layers (max_overlap_factor > 1), the far part [c + L dir, c + d_max dir],
  // which lies inside the casting body: its target triangles within M of it
  // are cached (usually none) and stay the only possible hits there while its
  // end points move less than M.
  const double h_max = d_max / pair.material().max_overlap_factor;
  const double L = std::min(d_max, h_max);
  const bool far = d_max > L;
  const double M = 0.5 * h_max;  // far part's box margin

  for (int i = 0; i < n; ++i) {
    const Vec3 c = X_BA * Vec3(pair.casting_centres().row(i).transpose());
    const Vec3 nn = R_BA * Vec3(pair.casting_normals().row(i).transpose());
    const Vec3 dir = -nn;
    std::optional<common::RayHit> hit;
    auto accept = [&](const std::optional<common::RayHit>& h) {
      return h && Vec3(m_B.row(h->triangle).transpose()).dot(nn) < 0.0;
    };
    // First hit among a list of candidate triangles (ascending: ties keep
    // the lower index, as first_hit).
    auto first_among = [&](const std::vector<int>& list, std::optional<common::RayHit>& first) {
      for (int t : list) {
        auto h = tree.hit_triangle(t, c, dir, d_max);
        if (h && (!first || h->distance < first->distance)) first = h;
      }
    };
    const Vec3 near_end = c + L * dir, end = c + d_max * dir;
    // The far part's cached candidates still cover it.
    const bool far_valid = !far || (data.has_far[i] &&
                                    (near_end - Vec3(data.far_start_B.row(i).transpose())).norm() < M &&
                                    (end - Vec3(data.far_end_B.row(i).transpose())).norm() < M);
    // 1. cached triangle and its neighbours.
    const int g = data.last_hit[i];
    if (g >= 0) {
      auto h = tree.hit_triangle(g, c, dir, d_max);
      if (accept(h)) hit = h;
      for (int k = 0; k < 3 && !hit; ++k) {
        const int gn = nbr(g, k);
        if (gn < 0) continue;
        auto h2 = tree.hit_triangle(gn, c, dir, d_max);
        if (accept(h2)) hit = h2;
      }
      if (hit) ++data.stats.guess_hits;
    }
    if (!hit) {
      // 2. distance bound from a cached clearance (near part), and no hit
      // among the far part's candidates.
      const Vec3 mid = c + 0.5 * L * dir;  // midpoint of the near part
      const double D = data.clearance[i];
      if (std::isfinite(D) && far_valid &&
          (mid - Vec3(data.clearance_centre_B.row(i).transpose())).norm() + 0.5 * L < D) {
        std::optional<common::RayHit> first;
        if (far) first_among(data.far_candidates[i], first);
        if (!accept(first)) {
          ++data.stats.skipped;
          data.last_hit[i] = -1;
          continue;
        }
        hit = first;
      }
    }
    if (!hit) {
      // 3. cached box candidates (the near part stayed inside their box).
      if (data.has_candidates[i] && far_valid &&
          (c - Vec3(data.candidate_start_B.row(i).transpose())).norm() < mu &&
          (near_end - Vec3(data.candidate_end_B.row(i).transpose())).norm() < mu) {
        ++data.stats.candidate_tests;
        std::optional<common::RayHit> first;
        first_among(data.candidates[i], first);
        if (far) first_among(data.far_candidates[i], first);
        if (accept(first)) {
          hit = first;
        } else {
          data.last_hit[i] = -1;
          continue;
        }
      } else {
        // 4. full query.
        ++data.stats.tree_queries;
        auto h = tree.first_hit(c, dir, d_max);
        if (far && !far_valid) {
          const Vec3 lo = near_end.cwiseMin(end) - Vec3::Constant(M);
          const Vec3 hi = near_end.cwiseMax(end) + Vec3::Constant(M);
          data.far_candidates[i] = tree.triangles_in_box(lo, hi);
          data.far_start_B.row(i) = near_end.transpose();
          data.far_end_B.row(i) = end.transpose();
          data.has_far[i] = 1;
        }
        if (accept(h)) {
          hit = h;
        } else {
          data.last_hit[i] = -1;
          const Vec3 mid = c + 0.5 * L * dir;
          const double D = tree.closest_point(mid).distance;
          data.clearance[i] = D;
          data.clearance_centre_B.row(i) = mid.transpose();
          if (D - 0.5 * L < mu) {
            // Weak distance bound: cache the box candidates (step 3).
            const Vec3 lo = c.cwiseMin(near_end) - Vec3::Constant(mu);
            const Vec3 hi = c.cwiseMax(near_end) + Vec3::Constant(mu);
            data.candidates[i] = tree.triangles_in_box(lo, hi);
            data.candidate_start_B.row(i) = c.transpose();
            data.candidate_end_B.row(i) = near_end.transpose();
            data.has_candidates[i] = 1;
          }
          continue;
        }
      }
    }
    data.last_hit[i] = hit->triangle;
    data.clearance[i] = std::numeric_limits<double>::quiet_NaN();
    const double d = hit->distance;
    const double h = tA[i] + tB[hit->triangle];
    double p;
    if (nonlinear) {
      if (!(d < h)) {
        std::ostringstream s;
        s << "contact pair '" << pair.name() << "': casting triangle " << i << " overlaps by "
          << d << " m, not less than the combined thickness " << h
          << " m (the nonlinear elastic-foundation law is singular there)";
        throw common::NumericalError(s.str());
      }
      p = -K * std::log1p(-d / h);
    } else {
      if (!(h > 0.0)) {
        std::ostringstream s;
        s << "contact pair '" << pair.name() << "': zero combined thickness at casting triangle "
          << i;
        throw common::NumericalError(s.str());
      }
      p = K * d / h;
    }
    if (!(p > 0.0)) continue;
    const double A = pair.casting_areas()[i];
    r.pressure[i] = p;
    r.overlap[i] = d;
    const Vec3 f_target = p * A * nn;  // on the target, +p A n at c
    F_B += f_target;
    M_B += c.cross(f_target);
    cop_B += p * A * c;
    sum_pA += p * A;
    r.contact_area += A;
    r.max_pressure = std::max(r.max_pressure, p);
    ++r.num_contacting;
  }
  const Eigen::Matrix3d R_WB = X_WB.linear();
  const Vec3 o_WB = X_WB.translation();
  r.force_on_target_W = R_WB * F_B;
  // Moment about the world origin: M_W = R M_B + o x F_W.
  r.moment_on_target_W = R_WB * M_B + o_WB.cross(r.force_on_target_W);
  r.force_on_casting_W = -r.force_on_target_W;
  r.moment_on_casting_W = -r.moment_on_target_W;
  if (sum_pA > 0.0) {
    r.center_of_pressure_W = X_WB * Vec3(cop_B / sum_pA);
    r.mean_pressure = sum_pA / r.contact_area;
  }
  if (!std::isfinite(r.force_on_target_W.sum()) || !std::isfinite(r.moment_on_target_W.sum()))
    throw common::NumericalError("contact pair '" + pair.name() + "': non-finite force");
}

CompartmentForces casting_force_by_compartment(const ContactPair& pair, const ContactResult& result) {
  const std::vector<char>& label = pair.casting().compartment;
  const int n = pair.casting().mesh.num_triangles();
  if (label.empty())
    throw common::InputError("contact pair '" + pair.name() +
                             "': expected compartment labels on the casting surface, found none");
  if (result.pressure.size() != n)
    throw common::InputError("contact pair '" + pair.name() + "': expected a result with " + std::to_string(n) +
                             " casting-triangle pressures, found " + std::to_string(result.pressure.size()));
  CompartmentForces r;
  double w[2] = {0.0, 0.0};
  for (int i = 0; i < n; ++i) {
    const double p = result.pressure[i];
    if (!(p > 0.0)) continue;
    const double pA = p * pair.casting_areas()[i];
    const Vec3 c = pair.casting_centres().row(i).transpose();
    const Vec3 f = -pA * Vec3(pair.casting_normals().row(i).transpose());
    const bool lat = label[static_cast<std::size_t>(i)] != 0;
    (lat ? r.lateral : r.medial) += f;
    (lat ? r.lateral_cop : r.medial_cop) += pA * c;
    (lat ? r.lateral_area : r.medial_area) += pair.casting_areas()[i];
    w[lat ? 1 : 0] += pA;
  }
  if (w[0] > 0) r.medial_cop /= w[0];
  if (w[1] > 0) r.lateral_cop /= w[1];
  return r;
}

}  // namespace arthrosim::musculoskeletal
