// Elastic-foundation contact: rigid sphere pressed into a thin layer on a
// rigid plane (linear law vs closed form, nonlinear law vs quadrature), mesh
// convergence rate, frame invariance, equal and opposite forces, the cached
// search giving the same answer as cold queries, bad input; the force of one
// casting surface split per compartment (two spheres on one plate).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "common/compartments.h"
#include "common/error.h"
#include "musculoskeletal/contact.h"

namespace msk = arthrosim::musculoskeletal;
using arthrosim::common::TriangleMesh;
using msk::Vec3;
constexpr double kPi = std::numbers::pi;

namespace {

// Square grid [-L, L]^2 at z = 0 with spacing s, normal +z (counter-clockwise
// seen from +z), shifted by an irrational offset so that no ray meets an edge
// of the sphere mesh exactly.
TriangleMesh plane_layer(double L, double s) {
  const int n = static_cast<int>(std::ceil(2 * L / s));
  const double off = 0.1234567 * s;
  TriangleMesh m;
  m.V.resize((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i)
      m.V.row(j * (n + 1) + i) << -L + i * s + off, -L + j * s + 0.7654321 * off, 0.0;
  m.F.resize(2 * n * n, 3);
  int t = 0;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
      m.F.row(t++) << a, b, c;
      m.F.row(t++) << a, c, d;
    }
  return m;
}

// Lower cap of the sphere of radius R centred at (0, 0, R - delta), covering
// |x|,|y| <= L (L < R), vertices exactly on the sphere, outward normals (-z).
TriangleMesh sphere_cap(double R, double delta, double L, double s) {
  const int n = static_cast<int>(std::ceil(2 * L / s));
  TriangleMesh m;
  m.V.resize((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = -L + 2 * L * i / n, y = -L + 2 * L * j / n;
      m.V.row(j * (n + 1) + i) << x, y, (R - delta) - std::sqrt(R * R - x * x - y * y);
    }
  m.F.resize(2 * n * n, 3);
  int t = 0;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
      m.F.row(t++) << a, c, b;  // clockwise from +z: normal points down, out of the sphere
      m.F.row(t++) << a, d, c;
    }
  return m;
}

struct SphereCase {
  double R = 0.02, delta = 0.001, h = 0.003;  // sphere radius, indentation, layer [m]
  double a() const { return std::sqrt(2 * R * delta - delta * delta); }
};

msk::ContactPair make_pair(const SphereCase& sc, double plane_spacing, msk::FoundationLaw law,
                           double sphere_spacing = 2e-4) {
  const double a = sc.a();
  msk::ContactSurface layer;  // casting: the deformable layer on the plane (body 0)
  layer.body = 0;
  layer.mesh = plane_layer(1.3 * a, plane_spacing);
  layer.thickness = Eigen::VectorXd::Constant(layer.mesh.num_triangles(), sc.h);
  msk::ContactSurface sphere;  // target: rigid sphere (body 1)
  sphere.body = 1;
  sphere.mesh = sphere_cap(sc.R, sc.delta, 1.2 * a, sphere_spacing);
  sphere.thickness = Eigen::VectorXd::Zero(sphere.mesh.num_triangles());
  msk::ElasticFoundationParameters mat;
  mat.law = law;
  return msk::ContactPair("sphere-on-layer", std::move(layer), std::move(sphere), mat);
}

msk::ContactResult evaluate(const msk::ContactPair& pair, const msk::Pose& X_WA = msk::Pose::Identity(),
                            const msk::Pose& X_WB = msk::Pose::Identity()) {
  msk::ContactPairData data;
  msk::evaluate_contact(pair, X_WA, X_WB, data);
  return data.result;
}

}  // namespace

TEST(ElasticFoundation, ModulusClosedForm) {
  msk::ElasticFoundationParameters p;  // E = 10 MPa, nu = 0.45
  EXPECT_NEAR(msk::foundation_modulus(p), 0.55 * 10e6 / (1.45 * 0.1), 1e-6);
}

TEST(ElasticFoundation, LinearSphereForceAndContactRadiusMatchClosedForm) {
  const SphereCase sc;
  const double spacing = 1e-4;  // 0.1 mm triangles, 1/62 of the contact radius
  auto pair = make_pair(sc, spacing, msk::FoundationLaw::kLinear);
  const auto r = evaluate(pair);
  const double K = pair.modulus();
  const double F = kPi * K * sc.delta * sc.delta * (3 * sc.R - sc.delta) / (3 * sc.h);
  // Force on the sphere pushes it up (+z), on the layer down.
  EXPECT_NEAR(r.force_on_target_W.z(), F, 2e-3 * F);  // measured error ~1e-4 at this spacing
  EXPECT_LT(std::hypot(r.force_on_target_W.x(), r.force_on_target_W.y()), 1e-3 * F);
  EXPECT_LT((r.force_on_target_W + r.force_on_casting_W).norm(), 1e-12 * F);
  EXPECT_LT((r.moment_on_target_W + r.moment_on_casting_W).norm(), 1e-12 * F);
  // Contact radius from the contact area (boundary cells of size s: |error| < s).
  EXPECT_NEAR(std::sqrt(r.contact_area / kPi), sc.a(), spacing);
  EXPECT_NEAR(r.max_pressure, K * sc.delta / sc.h, 1e-3 * K * sc.delta / sc.h);
  EXPECT_NEAR(r.mean_pressure, F / (kPi * sc.a() * sc.a()), 5e-3 * F / (kPi * sc.a() * sc.a()));
  EXPECT_LT(r.center_of_pressure_W.head<2>().norm(), spacing);
  // Small-indentation form F ~ pi K R delta^2 / h is within delta/(3R) = 1.7 %.
  EXPECT_NEAR(r.force_on_target_W.z(), kPi * K * sc.R * sc.delta * sc.delta / sc.h,
              sc.delta / (3 * sc.R) * 1.1 * F);
}

TEST(ElasticFoundation, NonlinearSphereForceMatchesQuadrature) {
  SphereCase sc;
  sc.delta = 0.002;  // d/h up to 2/3: strongly nonlinear
  auto pair = make_pair(sc, 1e-4, msk::FoundationLaw::kNonlinear);
  const auto r = evaluate(pair);
  const double K = pair.modulus();
  // F = int_0^a -K ln(1 - d(r)/h) 2 pi r dr, d(r) = sqrt(R^2 - r^2) - (R - delta);
  // composite Simpson with 20000 intervals (error ~1e-12 relative).
  const int N = 20000;
  const double a = sc.a();
  double sum = 0.0;
  for (int k = 0; k <= N; ++k) {
    const double rr = a * k / N;
    const double d = std::max(0.0, std::sqrt(sc.R * sc.R - rr * rr) - (sc.R - sc.delta));
    const double f = -K * std::log1p(-d / sc.h) * 2 * kPi * rr;
    sum += f * (k == 0 || k == N ? 1 : (k % 2 ? 4 : 2));
  }
  const double F = sum * (a / N) / 3;
  EXPECT_NEAR(r.force_on_target_W.z(), F, 2e-3 * F);  // same discretization error as linear
  EXPECT_NEAR(r.max_pressure, -K * std::log1p(-sc.delta / sc.h), 1e-3 * r.max_pressure);
}

TEST(ElasticFoundation, MeshConvergenceRateOfTheForceError) {
  const SphereCase sc;
  std::vector<double> s, err;
  for (double spacing : {8e-4, 4e-4, 2e-4, 1e-4}) {
    // Both meshes refined together (sphere spacing 0.77 x plane spacing, not
    // commensurate): the error combines the centroid quadrature on the layer
    // and the faceting of the sphere (flat triangles lie inside it, depth error
    // ~ s^2 / 8R), both O(s^2).
    auto pair = make_pair(sc, spacing, msk::FoundationLaw::kLinear, 0.77 * spacing);
    const double K = pair.modulus();
    const double F = kPi * K * sc.delta * sc.delta * (3 * sc.R - sc.delta) / (3 * sc.h);
    const double e = std::abs(evaluate(pair).force_on_target_W.z() - F) / F;
    s.push_back(std::log(spacing));
    err.push_back(std::log(e));
    std::printf("spacing %.1e m: relative force error %.3e\n", spacing, e);
  }
  // Least-squares slope of log(error) vs log(spacing).
  double ms = 0, me = 0;
  for (size_t i = 0; i < s.size(); ++i) ms += s[i] / s.size(), me += err[i] / s.size();
  double num = 0, den = 0;
  for (size_t i = 0; i < s.size(); ++i) num += (s[i] - ms) * (err[i] - me), den += (s[i] - ms) * (s[i] - ms);
  const double rate = num / den;
  std::printf("measured convergence rate %.2f\n", rate);
  RecordProperty("convergence_rate", std::to_string(rate));
  // Centroid quadrature of an integrand with a kink on the contact circle and
  // O(s^2) faceting: second order expected; 1.5 leaves room for the scatter of
  // the boundary cells.
  EXPECT_GT(rate, 1.5);
}

TEST(ElasticFoundation, SameBodyFrameForcesInArbitraryWorldPoses) {
  const SphereCase sc;
  auto pair = make_pair(sc, 2e-4, msk::FoundationLaw::kLinear);
  // Relative pose: sphere shifted slightly sideways and tilted (off-axis load).
  msk::Pose X_AB = msk::Pose::Identity();
  X_AB.linear() = Eigen::AngleAxisd(0.05, Vec3(1, 2, 0).normalized()).toRotationMatrix();
  X_AB.translation() = Vec3(3e-4, -2e-4, 1e-4);
  msk::ContactResult ref;
  std::mt19937_64 rng(20260422);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 5; ++trial) {
    msk::Pose X_WA = msk::Pose::Identity();
    if (trial > 0) {
      X_WA.linear() = Eigen::AngleAxisd(3.0 * u(rng), Vec3(u(rng), u(rng), u(rng)).normalized())
                          .toRotationMatrix();
      X_WA.translation() = Vec3(u(rng), u(rng), u(rng));
    }
    const auto r = evaluate(pair, X_WA, X_WA * X_AB);
    // Express in the casting body frame A: force, moment about A's origin, centre of pressure.
    const Eigen::Matrix3d R_AW = X_WA.linear().transpose();
    const Vec3 o = X_WA.translation();
    const Vec3 F_A = R_AW * r.force_on_target_W;
    const Vec3 M_A = R_AW * (r.moment_on_target_W - o.cross(r.force_on_target_W));
    const Vec3 cop_A = X_WA.inverse() * r.center_of_pressure_W;
    if (trial == 0) {
      ref = r;
      ASSERT_GT(r.num_contacting, 100);
      continue;
    }
    // Same triangles in contact, and forces equal to round-off of the pose
    // products (~1e-15 relative on O(1) m coordinates -> 1e-9 relative force).
    EXPECT_EQ(r.num_contacting, ref.num_contacting);
    EXPECT_LT((F_A - ref.force_on_target_W).norm(), 1e-8 * ref.force_on_target_W.norm());
    EXPECT_LT((M_A - ref.moment_on_target_W).norm(), 1e-8 * ref.force_on_target_W.norm());
    EXPECT_LT((cop_A - ref.center_of_pressure_W).norm(), 1e-9);
    EXPECT_LT((r.pressure - ref.pressure).lpNorm<Eigen::Infinity>(), 1e-8 * ref.max_pressure);
  }
}

TEST(ElasticFoundation, CachedSearchEqualsColdSearch) {
  const SphereCase sc;
  auto pair = make_pair(sc, 2e-4, msk::FoundationLaw::kLinear);
  msk::ContactPairData warm;
  msk::Pose X_WB = msk::Pose::Identity();
  for (int step = 0; step < 6; ++step) {
    X_WB.translation() = Vec3(1e-4 * step, -5e-5 * step, -4e-5 * step);
    msk::evaluate_contact(pair, msk::Pose::Identity(), X_WB, warm);
    msk::ContactPairData cold;
    msk::evaluate_contact(pair, msk::Pose::Identity(), X_WB, cold);
    // Bit-identical: same hit triangle and same arithmetic.
    EXPECT_EQ((warm.result.pressure - cold.result.pressure).lpNorm<Eigen::Infinity>(), 0.0);
    if (step > 0) { EXPECT_GT(warm.stats.guess_hits + warm.stats.skipped, 0); }
  }
}

TEST(ElasticFoundation, BadInputIsRejected) {
  const SphereCase sc;
  msk::ContactSurface a, b;
  a.body = 0;
  a.mesh = plane_layer(0.005, 1e-3);
  a.thickness = Eigen::VectorXd::Constant(a.mesh.num_triangles() - 1, 0.003);
  b.body = 1;
  b.mesh = sphere_cap(sc.R, sc.delta, 0.005, 1e-3);
  b.thickness = Eigen::VectorXd::Zero(b.mesh.num_triangles());
  EXPECT_THROW(msk::ContactPair("p", a, b, {}), arthrosim::common::InputError);
  a.thickness = Eigen::VectorXd::Constant(a.mesh.num_triangles(), -0.003);
  EXPECT_THROW(msk::ContactPair("p", a, b, {}), arthrosim::common::InputError);
  a.thickness = Eigen::VectorXd::Constant(a.mesh.num_triangles(), 0.003);
  msk::ElasticFoundationParameters bad;
  bad.poisson_ratio = 0.5;
  EXPECT_THROW(msk::ContactPair("p", a, b, bad), arthrosim::common::InputError);
  // Nonlinear law past the layer thickness stops with a message naming the pair.
  SphereCase deep;
  deep.delta = 0.0029;  // up to 2.9 mm of 3 mm: fine; push the sphere 0.2 mm further
  auto pair = make_pair(deep, 4e-4, msk::FoundationLaw::kNonlinear);
  msk::Pose X_WB = msk::Pose::Identity();
  X_WB.translation() = Vec3(0, 0, -2e-4);
  msk::ContactPairData d;
  msk::ElasticFoundationParameters mat;
  mat.law = msk::FoundationLaw::kNonlinear;
  mat.max_overlap_factor = 2.0;
  msk::ContactPair deep_pair("deep", pair.casting(), pair.target(), mat);
  try {
    msk::evaluate_contact(deep_pair, msk::Pose::Identity(), X_WB, d);
    FAIL() << "overlap beyond the thickness accepted";
  } catch (const arthrosim::common::NumericalError& e) {
    EXPECT_NE(std::string(e.what()).find("deep"), std::string::npos);
  }
}

namespace {

// Translates a mesh by (dx, 0, 0).
TriangleMesh shifted(TriangleMesh m, double dx) {
  m.V.col(0).array() += dx;
  return m;
}

// Two meshes as one (the second's indices offset).
TriangleMesh merged(const TriangleMesh& a, const TriangleMesh& b) {
  TriangleMesh m;
  m.V.resize(a.V.rows() + b.V.rows(), 3);
  m.V << a.V, b.V;
  m.F.resize(a.F.rows() + b.F.rows(), 3);
  m.F << a.F, (b.F.array() + static_cast<int>(a.V.rows())).matrix();
  return m;
}

// One plate (the casting surface, labelled by the shared medial/lateral rule
// with lateral = +x) under two rigid spheres: medial at x = -c pressed by
// delta_m, lateral at x = +c by delta_l; `which` = 0 both, 1 medial only,
// 2 lateral only.
msk::ContactPair two_indenters(double delta_m, double delta_l, int which) {
  const SphereCase med{0.02, delta_m, 0.003}, lat{0.02, delta_l, 0.003};
  const double a = std::max(med.a(), lat.a()), c = 1.4 * a, s = 1.5e-4;
  msk::ContactSurface plate;
  plate.body = 0;
  plate.mesh = plane_layer(2.8 * a, s);
  plate.thickness = Eigen::VectorXd::Constant(plate.mesh.num_triangles(), med.h);
  plate.lateral_M = Vec3::UnitX();
  const auto split = arthrosim::common::split_medial_lateral(plate.mesh, plate.lateral_M);
  plate.compartment = split.is_lateral;
  plate.compartment_rule = "test";
  const TriangleMesh m = shifted(sphere_cap(med.R, med.delta, 1.2 * med.a(), 2e-4), -c);
  const TriangleMesh l = shifted(sphere_cap(lat.R, lat.delta, 1.2 * lat.a(), 2e-4), +c);
  msk::ContactSurface spheres;
  spheres.body = 1;
  spheres.mesh = which == 0 ? merged(m, l) : which == 1 ? m : l;
  spheres.thickness = Eigen::VectorXd::Zero(spheres.mesh.num_triangles());
  return msk::ContactPair("two-spheres-on-plate", std::move(plate), std::move(spheres), {});
}

}  // namespace

// The split of one casting surface's force per compartment: each compartment
// carries what its own sphere alone produces (same rays, same pressures), the
// closed form within the mesh error, medial + lateral = total to round-off,
// the same in the casting frame for any common pose of the bodies.
TEST(ContactCompartments, TwoSpheresOnOnePlateSplitByTheirSides) {
  const double dm = 1e-3, dl = 0.6e-3;  // medial pressed deeper: F ~ delta^2 -> ratio ~2.8
  const auto both = two_indenters(dm, dl, 0), med = two_indenters(dm, dl, 1), lat = two_indenters(dm, dl, 2);
  const auto r = evaluate(both);
  const msk::CompartmentForces c = msk::casting_force_by_compartment(both, r);
  const Vec3 total = r.force_on_casting_W;  // identity poses: casting frame = world
  // Round-off: sums of a few thousand terms of similar size.
  EXPECT_LT((c.medial + c.lateral - total).norm(), 1e-12 * total.norm());
  // Each compartment against its sphere alone (the other sphere's rays miss
  // it): the same terms, so round-off again.
  const Vec3 f_m = evaluate(med).force_on_casting_W, f_l = evaluate(lat).force_on_casting_W;
  EXPECT_LT((c.medial - f_m).norm(), 1e-12 * f_m.norm());
  EXPECT_LT((c.lateral - f_l).norm(), 1e-12 * f_l.norm());
  // Closed form F = pi K delta^2 (3R - delta) / (3h) on the layer (pushed
  // down, -z): the 0.15 mm grid's error is < 0.5 % (measured ~1e-3 here).
  const double K = both.modulus();
  auto F = [&](double d) { return kPi * K * d * d * (3 * 0.02 - d) / (3 * 0.003); };
  EXPECT_NEAR(-c.medial.z(), F(dm), 5e-3 * F(dm));
  EXPECT_NEAR(-c.lateral.z(), F(dl), 5e-3 * F(dl));
  // Centres of pressure under the spheres (within a grid cell).
  const double cx = 1.4 * SphereCase{0.02, dm, 0.003}.a();
  EXPECT_LT((c.medial_cop - Vec3(-cx, 0, 0)).norm(), 1.5e-4);
  EXPECT_LT((c.lateral_cop - Vec3(cx, 0, 0)).norm(), 1.5e-4);
  EXPECT_GT(c.medial_area, c.lateral_area);
  // Both bodies moved by one pose: the split in the casting frame is the same.
  msk::Pose X = msk::Pose::Identity();
  X.linear() = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  X.translation() = Vec3(0.1, -0.2, 0.3);
  const auto rx = evaluate(both, X, X);
  const msk::CompartmentForces cxf = msk::casting_force_by_compartment(both, rx);
  EXPECT_LT((cxf.medial - c.medial).norm(), 1e-9 * c.medial.norm());
  EXPECT_LT((cxf.lateral - c.lateral).norm(), 1e-9 * c.lateral.norm());
}

TEST(ContactCompartments, WithoutLabelsOrWithTheWrongCountIsAnError) {
  auto pair = make_pair(SphereCase{}, 4e-4, msk::FoundationLaw::kLinear);
  const auto r = evaluate(pair);
  EXPECT_THROW(msk::casting_force_by_compartment(pair, r), arthrosim::common::InputError);
  msk::ContactSurface a = pair.casting(), b = pair.target();
  a.compartment.assign(3, 0);  // not one per triangle
  EXPECT_THROW(msk::ContactPair("bad", a, b, {}), arthrosim::common::InputError);
}
