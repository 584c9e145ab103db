#include "cartilage/surface_model.h"

#include "cartilage/surface_terms.h"

#include <algorithm>
#include <Eigen/Geometry>
#include <cmath>
#include <functional>
#include <memory>

#include "common/effects.h"
#include "common/error.h"

namespace arthrosim::cartilage {

void SurfaceParameters::declare(common::OptionVisitor& v) {
  using common::Unit;
  // Limits of physics, not of cartilage (a generic scene may be a metal
  // shell): thickness and E positive, nu in (-1, 0.5); the open ends are
  // checked by check_material().
  v.number("shell_thickness_mm", shell_thickness_m, Unit::kMillimetre, {0, 1e6},
           "thickness of the shells (> 0)");
  v.number("youngs_modulus_mpa", material.youngs_modulus_Pa, Unit::kMegapascal, {0, 1e12},
           "Young's modulus of the shells (> 0)");
  v.number("poisson_ratio", material.poisson_ratio, Unit::kNone, {-1, 0.5},
           "Poisson's ratio of the shells, in the open interval (-1, 0.5)");
  v.number("density_kg_per_m3", material.density_kg_m3, Unit::kKilogramPerCubicMetre, {1, 1e5},
           "density of the shells (used by inertia)");
  v.number("foundation_stiffness_n_per_mm3", foundation_stiffness_N_m3, Unit::kNewtonPerCubicMillimetre, {0, 1e6},
           "foundation spring stiffness per unit area and unit compression (foundation_springs)");
  v.choice("foundation_integration", foundation_integration,
           {{"nodal", FoundationIntegration::kNodal}, {"consistent", FoundationIntegration::kConsistent}},
           "foundation_springs: springs at the nodes with their nodal areas (nodal, the seed's) or the foundation "
           "integrated over each element at its Gauss points (consistent): on a foundation stiff enough that the "
           "shells' bending length spans 1-2 elements, nodal springs spread a load wider (docs/contact.md)");
  v.number("foundation_damping_n_s_per_mm3", foundation_damping_N_s_m3, Unit::kNewtonSecondPerCubicMillimetre,
           {0, 1e12}, "foundation damping per unit area and unit compression rate (foundation_damping)");
  v.number("osmotic_pressure_mpa", osmotic_pressure_Pa, Unit::kMegapascal, {0, 100},
           "pressure on the internal face of the shells (osmotic_pressure)");
  v.number("osmotic_ramp_s", osmotic_ramp_s, Unit::kSecond, {0, 1e4},
           "without imposed_kinematics: the osmotic pressure rises from 0 over this time by the smoothstep "
           "3 s^2 - 2 s^3 of the seating ramp (0: full pressure from t = 0; with imposed_kinematics the pressure rises "
           "over seating_time_s instead); at most end_time_s");
}

std::string SurfaceParameters::check_material() const {
  if (!(shell_thickness_m > 0)) return "shell_thickness_mm must be > 0";
  if (!(material.youngs_modulus_Pa > 0)) return "youngs_modulus_mpa must be > 0";
  const double nu = material.poisson_ratio;
  if (!(nu > -1 && nu < 0.5))
    return "poisson_ratio must lie in the open interval (-1, 0.5) (positive definite isotropic elasticity), found " +
           std::to_string(nu);
  return {};
}

std::unique_ptr<ShellModel> build_surface_model(const SurfaceInput& surface, const SurfaceParameters& parameters,
                                                const std::vector<std::string>& effects, const BoneMotion& bone,
                                                common::EffectLedger* ledger) {
  // Check the whole list first, so that an unsupported effect stops the run
  // before anything is built or recorded. mesh_contact (two surfaces) and
  // imposed_kinematics (the bone motion) are the stage's, not a term's.
  for (const std::string& e : effects) {
    if (find_surface_term(e) || e == "imposed_kinematics" || e == "mesh_contact") continue;
    if (!common::find_effect(e)) throw common::InputError("surface " + surface.name + ": unknown effect '" + e + "'");
    std::string names;
    for (const SurfaceTermInfo& t : surface_terms()) names += t.name + ", ";
    throw common::InputError("surface " + surface.name + ": effect '" + e +
                             "' is requested but the surface stage of this build cannot simulate it (it "
                             "simulates " + names + "imposed_kinematics and mesh_contact); remove it from the "
                             "scenario");
  }
  for (const std::string& e : effects) {
    const SurfaceTermInfo* t = find_surface_term(e);
    if (t && t->check) t->check(surface);
  }
  const GenericLoads& g = surface.generic;
  const bool moving = std::find(effects.begin(), effects.end(), "imposed_kinematics") != effects.end();
  if (moving && bone.at_rest)
    throw common::InputError("surface " + surface.name +
                             ": imposed_kinematics is requested but the bone is at rest (no kinematics given)");
  if (!(g.ramp_time_s > 0)) throw common::InputError("surface " + surface.name + ": load ramp time must be > 0");
  if (!(parameters.shell_thickness_m > 0))
    throw common::InputError("surface " + surface.name + ": shell thickness must be > 0");
  if (surface.normals.rows() != surface.mesh.num_nodes())
    throw common::InputError("surface " + surface.name + ": " + std::to_string(surface.normals.rows()) +
                             " normals for " + std::to_string(surface.mesh.num_nodes()) + " nodes");
  common::QuadMesh mesh = surface.mesh;
  mesh.name = surface.name;
  auto model = std::make_unique<ShellModel>(
      mesh, surface.normals, Eigen::VectorXd::Constant(mesh.num_nodes(), parameters.shell_thickness_m),
      parameters.material);
  model->attach_ledger(ledger);
  const double T = g.ramp_time_s;
  const std::function<double(double)> ramp = [T](double t) { return std::clamp(t / T, 0.0, 1.0); };
  model->add_internal_forces();
  if (moving && ledger) ledger->record("imposed_kinematics", 1, surface.name);
  // Order of construction follows the scenario's list; the terms are
  // independent (their sum is the residual).
  const SurfaceTermContext context{*model, surface, parameters, bone, ramp};
  for (const std::string& e : effects) {
    if (const SurfaceTermInfo* t = find_surface_term(e)) t->build(context);
  }
  return model;
}

BoneMotion interpolated_bone_motion(std::vector<double> times, std::vector<Eigen::Isometry3d> poses,
                                    const std::string& source) {
  if (times.empty() || times.size() != poses.size())
    throw common::InputError(source + ": error: " + std::to_string(times.size()) + " times for " +
                             std::to_string(poses.size()) + " poses (expected the same number, at least 1)");
  for (size_t i = 1; i < times.size(); ++i)
    if (!(times[i] > times[i - 1]))
      throw common::InputError(source + ": error: times must increase strictly, found " +
                               std::to_string(times[i - 1]) + " then " + std::to_string(times[i]) + " at frame " +
                               std::to_string(i));
  struct Track {
    std::vector<double> t;
    std::vector<Eigen::Isometry3d> X;
    // Interval [i, i+1] holding absolute time s and the fraction within it;
    // i = -1 before the first sample, i = n-1 after the last (held poses).
    int interval(double s, double& f) const {
      const int n = static_cast<int>(t.size());
      if (n == 1 || s <= t.front()) { f = 0; return s <= t.front() ? -1 : n - 1; }
      if (s >= t.back()) { f = 0; return n - 1; }
      const int i = static_cast<int>(std::upper_bound(t.begin(), t.end(), s) - t.begin()) - 1;
      f = (s - t[i]) / (t[i + 1] - t[i]);
      return i;
    }
  };
  auto track = std::make_shared<Track>(Track{std::move(times), std::move(poses)});
  const double t0 = track->t.front();
  BoneMotion m;
  m.at_rest = false;
  m.pose = [track, t0](double t) {
    double f = 0;
    const int i = track->interval(t0 + t, f);
    if (i < 0) return track->X.front();
    if (i >= static_cast<int>(track->t.size()) - 1) return track->X.back();
    const Eigen::Isometry3d& A = track->X[i];
    const Eigen::Isometry3d& B = track->X[i + 1];
    const Eigen::AngleAxisd rel(B.linear() * A.linear().transpose());
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = Eigen::AngleAxisd(f * rel.angle(), rel.axis()).toRotationMatrix() * A.linear();
    X.translation() = (1 - f) * A.translation() + f * B.translation();
    return X;
  };
  m.spatial_velocity = [track, t0](double t) {
    Eigen::Matrix<double, 6, 1> V = Eigen::Matrix<double, 6, 1>::Zero();
    double f = 0;
    const int i = track->interval(t0 + t, f);
    if (i < 0 || i >= static_cast<int>(track->t.size()) - 1) return V;
    const double dt = track->t[i + 1] - track->t[i];
    const Eigen::AngleAxisd rel(track->X[i + 1].linear() * track->X[i].linear().transpose());
    V.head<3>() = rel.angle() / dt * rel.axis();
    V.tail<3>() = (track->X[i + 1].translation() - track->X[i].translation()) / dt;
    return V;
  };
  return m;
}

NodeBasis node_strain_basis(const ShellModel& model) {
  const int N = model.num_nodes();
  NodeBasis b;
  b.a1.resize(N, 3);
  b.a2.resize(N, 3);
  b.n.resize(N, 3);
  for (int i = 0; i < N; ++i) {
    const Eigen::Vector3d n = model.reference_director(i).normalized();
    Eigen::Vector3d axis = Eigen::Vector3d::UnitX();
    if (std::abs(axis.dot(n)) > 0.9) axis = Eigen::Vector3d::UnitY();
    const Eigen::Vector3d a1 = (axis - axis.dot(n) * n).normalized();
    b.a1.row(i) = a1.transpose();
    b.a2.row(i) = n.cross(a1).transpose();
    b.n.row(i) = n.transpose();
  }
  return b;
}

NodalStrains nodal_strains(const ShellModel& model, const NodeBasis& basis, const Eigen::VectorXd& q) {
  const int N = model.num_nodes();
  const int M = model.num_elements();
  Eigen::MatrixXd sum = Eigen::MatrixXd::Zero(N, 3);
  Eigen::VectorXi count = Eigen::VectorXi::Zero(N);
  // Corner natural coordinates, counter-clockwise (ShellElement node order).
  static const std::vector<double> kXi = {-1, 1, 1, -1};
  static const std::vector<double> kEta = {-1, -1, 1, 1};
  std::vector<Eigen::Matrix<double, 4, 3>> per_element(M);
#pragma omp parallel for schedule(static)
  for (int e = 0; e < M; ++e) {
    const Vector24 qe = model.gather(e, q);
    std::vector<Eigen::Matrix3d> frames;
    const Eigen::Matrix<double, 6, Eigen::Dynamic> corner = model.element(e).strains(qe, kXi, kEta, 0.0, &frames);
    for (int k = 0; k < 4; ++k) {
      const Eigen::Matrix3d& frame = frames[k];
      const Eigen::Matrix<double, 6, 1> s = corner.col(k);
      Eigen::Matrix2d El;
      El << s(0), s(3), s(3), s(1);
      const Eigen::Matrix<double, 3, 2> P = frame.leftCols<2>();
      const Eigen::Matrix3d W = P * El * P.transpose();  // world components
      const int node = model.quads()(e, k);
      const Eigen::Vector3d a1 = basis.a1.row(node).transpose(), a2 = basis.a2.row(node).transpose();
      per_element[e].row(k) << a1.dot(W * a1), a2.dot(W * a2), a1.dot(W * a2);
    }
  }
  // Serial, fixed-order sum: deterministic whatever the thread count.
  for (int e = 0; e < M; ++e)
    for (int k = 0; k < 4; ++k) {
      const int node = model.quads()(e, k);
      sum.row(node) += per_element[e].row(k);
      ++count(node);
    }
  NodalStrains out;
  out.E.resize(N, 3);
  out.e1.resize(N);
  out.e2.resize(N);
  out.e1_dir.resize(N, 3);
  for (int i = 0; i < N; ++i) {
    const Eigen::RowVector3d E = count(i) > 0 ? Eigen::RowVector3d(sum.row(i) / count(i)) : Eigen::RowVector3d::Zero();
    out.E.row(i) = E;
    // Principal values of [[a, c], [c, b]]: m +- sqrt(((a - b)/2)^2 + c^2),
    // first direction at angle theta = atan2(2c, a - b)/2 from a1.
    const double a = E(0), b = E(1), c = E(2);
    const double m = 0.5 * (a + b), r = std::hypot(0.5 * (a - b), c);
    out.e1(i) = m + r;
    out.e2(i) = m - r;
    const double theta = 0.5 * std::atan2(2 * c, a - b);
    Eigen::Vector3d d = std::cos(theta) * basis.a1.row(i).transpose() + std::sin(theta) * basis.a2.row(i).transpose();
    if (d.dot(basis.a1.row(i).transpose()) < 0) d = -d;
    out.e1_dir.row(i) = d.normalized().transpose();
  }
  return out;
}

Eigen::VectorXd nodal_deflection(const ShellModel& model, const Eigen::VectorXd& q) {
  Eigen::VectorXd w(model.num_nodes());
  for (int i = 0; i < model.num_nodes(); ++i)
    w(i) = (q.segment<3>(6 * i) - model.reference_position(i)).dot(model.reference_director(i).normalized());
  return w;
}

Eigen::VectorXd matched_foundation_stiffness(const Eigen::VectorXd& thickness_m, double E, double nu,
                                             const std::string& where) {
  if (!(E > 0) || !(nu >= 0 && nu < 0.5))
    throw common::InputError(where + ": matched foundation needs E > 0 and 0 <= nu < 0.5, found E = " +
                             std::to_string(E) + " Pa, nu = " + std::to_string(nu));
  const double K = (1 - nu) * E / ((1 + nu) * (1 - 2 * nu));
  Eigen::VectorXd k(thickness_m.size());
  for (Eigen::Index i = 0; i < thickness_m.size(); ++i) {
    if (!(thickness_m(i) > 0) || !std::isfinite(thickness_m(i)))
      throw common::InputError(where + ": node " + std::to_string(i) + ": expected a cartilage thickness > 0, found " +
                               std::to_string(thickness_m(i)) + " m");
    k(i) = K / thickness_m(i);
  }
  return k;
}

Eigen::MatrixXd nodal_displacement(const ShellModel& model, const Eigen::VectorXd& q, const Eigen::Isometry3d& T) {
  Eigen::MatrixXd u(model.num_nodes(), 3);
  for (int i = 0; i < model.num_nodes(); ++i)
    u.row(i) = (q.segment<3>(6 * i) - T * model.reference_position(i)).transpose();
  return u;
}

Eigen::VectorXd nodal_deflection(const ShellModel& model, const Eigen::VectorXd& q, const Eigen::Isometry3d& T) {
  Eigen::VectorXd w(model.num_nodes());
  for (int i = 0; i < model.num_nodes(); ++i)
    w(i) = (q.segment<3>(6 * i) - T * model.reference_position(i))
               .dot(T.linear() * model.reference_director(i).normalized());
  return w;
}

Eigen::MatrixXd nodal_displacement(const ShellModel& model, const Eigen::VectorXd& q) {
  Eigen::MatrixXd u(model.num_nodes(), 3);
  for (int i = 0; i < model.num_nodes(); ++i) u.row(i) = (q.segment<3>(6 * i) - model.reference_position(i)).transpose();
  return u;
}

}  // namespace arthrosim::cartilage
