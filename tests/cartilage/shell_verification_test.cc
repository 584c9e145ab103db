// Verification of the ANCF shell model against closed forms: patch tests on
// distorted meshes, cantilever convergence to beam theory (measured rate),
// thin-plate locking check, roll-up under an end moment, pressurised sphere,
// plate on the elastic foundation, beam on an elastic foundation (load
// spreading), Newton convergence order.
#include <gtest/gtest.h>

#include <Eigen/SparseLU>
#include <cmath>
#include <cstdio>

#include "numerics/hht_integrator.h"
#include "cartilage/shell_model.h"
#include "shell_test_meshes.h"

namespace arthrosim::cartilage {
namespace {

using testing::plate_mesh;

common::Points3 up(int n) {
  common::Points3 D(n, 3);
  D.rowwise() = Eigen::RowVector3d(0, 0, 1);
  return D;
}

std::vector<int> nodes_where(const common::QuadMesh& m, const std::function<bool(const Eigen::Vector3d&)>& pred) {
  std::vector<int> out;
  for (int i = 0; i < m.num_nodes(); ++i)
    if (pred(m.V.row(i).transpose())) out.push_back(i);
  return out;
}

numerics::IntegratorOptions static_options(double dt) {
  numerics::IntegratorOptions o;
  o.quasi_static = true;
  o.dt_s = dt;
  return o;
}

// ---------------------------------------------------------------------------
// Membrane patch test, finite strain: boundary positions follow a homogeneous
// deformation F (2% stretches + shear); interior nodes and all transverse
// gradients are free. The exact solution is r = F X, d = F e_z with the
// thickness stretch lambda3 that makes S33 = 0 (St. Venant-Kirchhoff):
// E33 = -lambda (E11 + E22)/(lambda + 2 mu). The element reproduces it
// exactly (compatible strains constant, ANS samples exact, EAS orthogonal to
// constant stress), so the only error is the Newton tolerance: 1e-8 relative.
TEST(ShellPatch, MembraneFiniteStrainDistortedMesh) {
  const double L = 1.0, t = 0.02, E = 1e6, nu = 0.3;
  common::QuadMesh mesh = plate_mesh(5, 4, L, 0.8 * L, 0.25);
  ShellMaterial mat;
  mat.youngs_modulus_Pa = E;
  mat.poisson_ratio = nu;
  ShellModel model(mesh, up(mesh.num_nodes()), Eigen::VectorXd::Constant(mesh.num_nodes(), t), mat);
  model.add_internal_forces();
  Eigen::Matrix2d F2;
  F2 << 1.02, 0.01, 0.005, 0.99;
  const Eigen::Matrix2d E2 = 0.5 * (F2.transpose() * F2 - Eigen::Matrix2d::Identity());
  const double lam = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu));
  const double E33 = -lam * E2.trace() / (lam + 2 * mu);
  const double lambda3 = std::sqrt(1 + 2 * E33);
  Eigen::Matrix3d F = Eigen::Matrix3d::Identity();
  F.topLeftCorner<2, 2>() = F2;
  F(2, 2) = lambda3;
  NodeConstraint c;
  c.name = "boundary_motion";
  c.nodes = model.boundary_nodes();
  c.mask = {true, true, true, false, false, false};
  c.value = [&](double s, int node, Eigen::Matrix<double, 6, 1>& q6) {
    const Eigen::Vector3d X = model.reference_position(node);
    q6.head<3>() = X + s * (F * X - X);
  };
  model.add_constraint(c);
  numerics::IntegratorOptions o = static_options(1.0);
  o.residual_rtol = 1e-13;
  numerics::HhtIntegrator solver(model, o);
  solver.initialize(0, model.reference_state());
  solver.advance_to(1.0);
  double err = 0, scale = 0;
  for (int i = 0; i < model.num_nodes(); ++i) {
    const Eigen::Vector3d X = model.reference_position(i);
    err = std::max(err, (solver.q().segment<3>(6 * i) - F * X).norm());
    err = std::max(err, 0.5 * t * (solver.q().segment<3>(6 * i + 3) - F * Eigen::Vector3d::UnitZ()).norm());
    scale = std::max(scale, (F * X - X).norm());
  }
  std::printf("membrane patch: max error %.3e m relative %.3e\n", err, err / scale);
  EXPECT_LT(err / scale, 1e-8);
  // Strain output (ShellElement::strain): at any point of any element the
  // local in-plane strain has the invariants of E2, E33 is the plane-stress
  // value and the transverse shears vanish. The local e1 axis differs per
  // distorted element, so invariants are compared (1e-10: Newton tolerance).
  for (int e = 0; e < model.num_elements(); ++e) {
    Eigen::Matrix3d frame;
    const auto E = model.element(e).strain(model.gather(e, solver.q()), 0.3, -0.6, 0.5, &frame);
    EXPECT_NEAR(E(0) + E(1), E2.trace(), 1e-10);
    EXPECT_NEAR(E(0) * E(1) - E(3) * E(3), E2.determinant(), 1e-10);
    EXPECT_NEAR(E(2), E33, 1e-10);
    EXPECT_NEAR(E(4), 0.0, 1e-10);
    EXPECT_NEAR(E(5), 0.0, 1e-10);
    EXPECT_NEAR(std::abs(frame.col(2).z()), 1.0, 1e-12);
  }
}

// Bending patch test (linear theory, tangent at the reference): boundary
// nodes take the exact constant-curvature field
//   w = (kx x^2 + ky y^2 + kxy x y)/2,  d - e_z = -(kx x + kxy y/2, ky y + kxy x/2, 0),
// interior nodes solve K_ff u_f = -K_fc u_c. Constant moments are reproduced
// exactly (ANS shear vanishes at the edge midpoints; the EAS thickness mode
// supplies E33 linear in z), so 1e-8 relative covers round-off only.
TEST(ShellPatch, BendingDistortedMesh) {
  const double L = 1.0, t = 0.01;
  common::QuadMesh mesh = plate_mesh(5, 4, L, 0.8 * L, 0.25);
  ShellMaterial mat;
  mat.youngs_modulus_Pa = 1e6;
  mat.poisson_ratio = 0.3;
  ShellModel model(mesh, up(mesh.num_nodes()), Eigen::VectorXd::Constant(mesh.num_nodes(), t), mat);
  model.add_internal_forces();
  const double kx = 1e-3, ky = -0.4e-3, kxy = 0.7e-3;
  const int n = model.num_dofs();
  Eigen::VectorXd u_exact = Eigen::VectorXd::Zero(n);
  for (int i = 0; i < model.num_nodes(); ++i) {
    const double x = mesh.V(i, 0), y = mesh.V(i, 1);
    u_exact(6 * i + 2) = 0.5 * (kx * x * x + ky * y * y + kxy * x * y);
    u_exact(6 * i + 3) = -(kx * x + 0.5 * kxy * y);
    u_exact(6 * i + 4) = -(ky * y + 0.5 * kxy * x);
  }
  Eigen::VectorXd F;
  Eigen::SparseMatrix<double> K;
  const Eigen::VectorXd q0 = model.reference_state();
  numerics::EvalRequest r;
  r.q = &q0;
  model.evaluate(r, F, nullptr, &K);
  std::vector<char> fixed(n, 0);
  for (int b : model.boundary_nodes())
    for (int j = 0; j < 6; ++j) fixed[6 * b + j] = 1;
  std::vector<int> free_idx, map(n, -1);
  for (int i = 0; i < n; ++i)
    if (!fixed[i]) {
      map[i] = static_cast<int>(free_idx.size());
      free_idx.push_back(i);
    }
  const int nf = static_cast<int>(free_idx.size());
  std::vector<Eigen::Triplet<double>> trip;
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(nf);
  for (int j = 0; j < K.outerSize(); ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(K, j); it; ++it) {
      if (map[it.row()] < 0) continue;
      if (map[j] >= 0)
        trip.emplace_back(map[it.row()], map[j], it.value());
      else
        rhs(map[it.row()]) -= it.value() * u_exact(j);
    }
  Eigen::SparseMatrix<double> Kff(nf, nf);
  Kff.setFromTriplets(trip.begin(), trip.end());
  Eigen::SparseLU<Eigen::SparseMatrix<double>> lu(Kff);
  ASSERT_EQ(lu.info(), Eigen::Success);
  const Eigen::VectorXd uf = lu.solve(rhs);
  double err = 0;
  for (int k = 0; k < nf; ++k) err = std::max(err, std::abs(uf(k) - u_exact(free_idx[k])));
  const double scale = u_exact.cwiseAbs().maxCoeff();
  std::printf("bending patch: max error %.3e relative %.3e\n", err, err / scale);
  EXPECT_LT(err / scale, 1e-8);
}

// ---------------------------------------------------------------------------
// Cantilever strip, clamped at x = 0 (all 6 coordinates of the root nodes),
// tip load P shared by the two tip nodes. Returns the mean tip deflection.
// If plane_strain, r_y and d_y are fixed everywhere (cylindrical bending: the
// plate rigidity D = E t^3 / (12 (1 - nu^2)) applies exactly).
double cantilever_tip(int nx, double L, double b, double t, double E, double nu, double P, bool plane_strain) {
  common::QuadMesh mesh = plate_mesh(nx, 1, L, b);
  ShellMaterial mat;
  mat.youngs_modulus_Pa = E;
  mat.poisson_ratio = nu;
  ShellModel model(mesh, up(mesh.num_nodes()), Eigen::VectorXd::Constant(mesh.num_nodes(), t), mat);
  model.add_internal_forces();
  model.fix_nodes("clamp", nodes_where(mesh, [](const Eigen::Vector3d& X) { return X.x() < 1e-12; }),
                  {true, true, true, true, true, true});
  if (plane_strain) {
    std::vector<int> all(mesh.num_nodes());
    for (int i = 0; i < mesh.num_nodes(); ++i) all[i] = i;
    model.fix_nodes("plane_strain", all, {false, true, false, false, true, false});
  }
  const std::vector<int> tip = nodes_where(mesh, [L](const Eigen::Vector3d& X) { return X.x() > L - 1e-12; });
  std::vector<std::pair<int, Eigen::Vector3d>> loads;
  for (int i : tip) loads.emplace_back(i, Eigen::Vector3d(0, 0, P / tip.size()));
  model.add_point_loads("tip_load", loads, [](double s) { return s; });
  numerics::HhtIntegrator solver(model, static_options(1.0));
  solver.initialize(0, model.reference_state());
  solver.advance_to(1.0);
  double w = 0;
  for (int i : tip) w += (solver.q()(6 * i + 2) - mesh.V(i, 2)) / tip.size();
  return w;
}

// Convergence to Timoshenko beam theory with nu = 0 (plate and beam theory
// then coincide; the continuum shell has constant transverse shear, shear
// factor 1): w = P L^3/(3 E I) + P L/(G b t). Load gives w/L ~ 1e-4, so the
// geometric nonlinearity changes w by ~1e-8 relative, far below the
// discretisation errors measured here.
TEST(ShellVerification, CantileverConvergesToBeamTheoryAtMeasuredRate) {
  const double L = 1.0, b = 0.1, t = 0.01, E = 1e7, nu = 0.0;
  const double I = b * t * t * t / 12, G = E / 2;
  const double w_ref_bending = 1e-4 * L;
  const double P = w_ref_bending * 3 * E * I / (L * L * L);
  const double w_ref = P * L * L * L / (3 * E * I) + P * L / (G * b * t);
  std::vector<double> errors;
  for (int nx : {2, 4, 8, 16}) {
    const double w = cantilever_tip(nx, L, b, t, E, nu, P, false);
    errors.push_back(std::abs(w - w_ref) / w_ref);
    std::printf("cantilever nx=%2d: w/w_ref = %.8f error %.3e\n", nx, w / w_ref, errors.back());
  }
  const double rate = std::log2(errors[errors.size() - 2] / errors.back());
  std::printf("cantilever convergence rate (last halving): %.3f\n", rate);
  // Bilinear displacement/gradient interpolation: O(h^2) tip error. Accept
  // [1.8, 2.3] (the measured value is printed above).
  EXPECT_GT(rate, 1.8);
  EXPECT_LT(rate, 2.3);
  EXPECT_LT(errors.back(), 5e-3);
}

// Very thin plate, t/L = 1e-3, nu = 0.3, cylindrical bending: within 2% of
// Kirchhoff w = P L^3/(3 D b) with 16 elements (a shear- or thickness-locked
// element would be stiffer by orders of magnitude: (L/t)^2 ~ 1e6).
TEST(ShellVerification, ThinPlateShowsNoLocking) {
  const double L = 1.0, b = 0.1, t = 1e-3, E = 400e6, nu = 0.3;
  const double D = E * t * t * t / (12 * (1 - nu * nu));
  const double P = 1e-4 * L * 3 * D * b / (L * L * L);
  const double w_ref = P * L * L * L / (3 * D * b);
  const double w = cantilever_tip(16, L, b, t, E, nu, P, true);
  std::printf("thin plate t/L=1e-3: w/w_Kirchhoff = %.6f\n", w / w_ref);
  EXPECT_NEAR(w / w_ref, 1.0, 0.02);
}

// Roll-up: cantilever (L = 12, b = 1, t = 0.1, E = 1.2e6, nu = 0; Sze et al.
// 2004 benchmark geometry) under the end moment M = 2 pi E I / L applied as a
// conservative director couple (the energy equivalent of a linear
// through-thickness end traction that follows the end fibre). Exact solution:
// a full circle of radius L / (2 pi): the tip returns to the root and the tip
// fibre turns by 2 pi. Returns the tip-fibre rotation / 2 pi; gap = largest
// tip-to-root distance.
double roll_up(int nx, double& gap, long& rejected) {
  const double L = 12, b = 1, t = 0.1, E = 1.2e6;
  const double I = b * t * t * t / 12, M = 2 * M_PI * E * I / L;
  common::QuadMesh mesh = plate_mesh(nx, 1, L, b);
  ShellMaterial mat;
  mat.youngs_modulus_Pa = E;
  mat.poisson_ratio = 0.0;
  ShellModel model(mesh, up(mesh.num_nodes()), Eigen::VectorXd::Constant(mesh.num_nodes(), t), mat);
  model.add_internal_forces();
  model.fix_nodes("clamp", nodes_where(mesh, [](const Eigen::Vector3d& X) { return X.x() < 1e-12; }),
                  {true, true, true, true, true, true});
  const std::vector<int> tip = nodes_where(mesh, [L](const Eigen::Vector3d& X) { return X.x() > L - 1e-9; });
  std::vector<std::pair<int, double>> moments;
  for (int i : tip) moments.emplace_back(i, M / tip.size());
  // Axis -y: positive M turns the fibre from +z towards -x (tip curls up).
  model.add_director_moments("end_moment", Eigen::Vector3d(0, -1, 0), moments, [](double s) { return s; });
  numerics::HhtIntegrator solver(model, static_options(1.0 / 20));
  solver.initialize(0, model.reference_state());
  solver.advance_to(1.0);
  const auto& st = solver.statistics();
  gap = 0;
  for (int i : tip) gap = std::max(gap, (solver.q().segment<3>(6 * i) - Eigen::Vector3d(0, mesh.V(i, 1), 0)).norm());
  const Eigen::Vector3d d_tip = solver.q().segment<3>(6 * tip[0] + 3);
  // Fibre angle theta with d = (-sin theta, 0, cos theta), unwrapped near 2 pi.
  double theta = std::atan2(-d_tip.x(), d_tip.z());
  if (theta < M_PI / 2) theta += 2 * M_PI;
  rejected = st.rejected_steps;
  std::printf("roll-up nx=%d: %ld steps, %ld rejected, %ld Newton iterations; tip rotation/2pi = %.5f, gap %.4f\n", nx,
              st.steps, st.rejected_steps, st.newton_iterations, theta / (2 * M_PI), gap);
  return theta / (2 * M_PI);
}

TEST(ShellVerification, EndMomentRollsCantileverIntoCircle) {
  double gap16, gap32;
  long rej16, rej32;
  const double e16 = std::abs(roll_up(16, gap16, rej16) - 1), e32 = std::abs(roll_up(32, gap32, rej32) - 1);
  const double rate = std::log2(e16 / e32);
  std::printf("roll-up: rotation error %.4f (16) %.4f (32), rate %.2f\n", e16, e32, rate);
  // At finite rotation per element the linearly interpolated fibre is
  // shorter than unit between nodes and the discrete curvature lags the
  // rotation: an O(h^2) error (measured ~3% at 16, < 1% at 32 elements).
  // Assert the O(h^2) rate and the 32-element accuracy: rotation within 1.5%,
  // tip back at the root within 3% of L.
  EXPECT_GT(rate, 1.6);
  EXPECT_LT(rate, 2.4);
  EXPECT_LT(e32, 0.015);
  EXPECT_LT(gap32, 0.03 * 12);
  EXPECT_EQ(rej16 + rej32, 0);
}

// Thin sphere (octant with symmetry conditions), R/t = 100, internal pressure
// on the mid-surface: membrane theory u = p R^2 (1 - nu)/(2 E t).
struct SphereResult {
  double mean, worst, within3;  // mean u/u_ref, max |u/u_ref - 1|, fraction within 3%
};
SphereResult pressurised_sphere(int n) {
  const double R = 1.0, t = 0.01, E = 1e9, nu = 0.3, p = 1e3;
  common::QuadMesh mesh = testing::sphere_octant(n, R);
  common::Points3 D(mesh.num_nodes(), 3);
  for (int i = 0; i < mesh.num_nodes(); ++i) D.row(i) = mesh.V.row(i).normalized();
  ShellMaterial mat;
  mat.youngs_modulus_Pa = E;
  mat.poisson_ratio = nu;
  ShellModel model(mesh, D, Eigen::VectorXd::Constant(mesh.num_nodes(), t), mat);
  model.add_internal_forces();
  model.add_pressure("pressure", 0.0, [p](double s) { return s * p; });
  for (int axis = 0; axis < 3; ++axis) {
    std::array<bool, 6> mask{};
    mask[axis] = mask[axis + 3] = true;  // symmetry plane: normal position and gradient components
    model.fix_nodes(std::string("symmetry_") + "xyz"[axis],
                    nodes_where(mesh, [axis](const Eigen::Vector3d& X) { return std::abs(X(axis)) < 1e-12; }), mask);
  }
  numerics::HhtIntegrator solver(model, static_options(1.0));
  solver.initialize(0, model.reference_state());
  solver.advance_to(1.0);
  const double u_ref = p * R * R * (1 - nu) / (2 * E * t);
  SphereResult res{0, 0, 0};
  for (int i = 0; i < model.num_nodes(); ++i) {
    const Eigen::Vector3d X = model.reference_position(i);
    const double u = (solver.q().segment<3>(6 * i) - X).dot(X.normalized()) / u_ref;
    res.mean += u / model.num_nodes();
    res.worst = std::max(res.worst, std::abs(u - 1));
    if (std::abs(u - 1) < 0.03) res.within3 += 1.0 / model.num_nodes();
  }
  std::printf("sphere %dx%d per face: u_mean/u_ref = %.5f, worst node error %.4f, %.1f%% of nodes within 3%% (%s)\n",
              n, n, res.mean, res.worst, 100 * res.within3, solver.statistics().linear_solver.c_str());
  return res;
}

// Bending/thickness corrections are O(t/R) = 1% and the faceted bilinear
// geometry adds O((h/R)^2) ~ 1% at 8 x 8: mean within 1%, 90% of the nodes
// within 3%. The worst node is the 3-valent cube corner, where three faces
// meet and the faceting is worst; its error must shrink with refinement
// (measured 0.30 -> 0.12 from 4x4 to 8x8).
TEST(ShellVerification, PressurisedSphereRadialDisplacement) {
  const SphereResult coarse = pressurised_sphere(4), fine = pressurised_sphere(8);
  EXPECT_NEAR(fine.mean, 1.0, 0.01);
  EXPECT_GT(fine.within3, 0.9);
  EXPECT_LT(fine.worst, 0.5 * coarse.worst);
}

// The symmetric approximation (CHOLMOD on (K + K^T)/2 of the follower-
// pressure tangent) converges to the same equilibrium as the exact tangent
// with UMFPACK: both are solved to residual_rtol 1e-10, so the states agree to
// ~1e-9 of the displacement.
TEST(ShellVerification, SymmetricApproximationReachesSameEquilibrium) {
  common::QuadMesh mesh = testing::spherical_patch(8, 0.04, 0.025);
  const common::Points3 D = quad_mesh_vertex_normals(mesh);
  auto solve = [&](numerics::LinearSolverChoice choice, numerics::IntegratorStatistics& st) {
    ShellModel model(mesh, D, Eigen::VectorXd::Constant(mesh.num_nodes(), 1e-3), ShellMaterial{});
    model.add_internal_forces();
    model.add_pressure("osmotic_pressure", -1.0, [](double s) { return 0.2e6 * s; });
    model.add_periphery_fixed();
    numerics::IntegratorOptions o = static_options(1.0);
    o.solver = choice;
    o.residual_rtol = 1e-10;
    o.max_newton_iterations = 40;
    numerics::HhtIntegrator solver(model, o);
    solver.initialize(0, model.reference_state());
    solver.advance_to(1.0);
    st = solver.statistics();
    return Eigen::VectorXd(solver.q() - model.reference_state());
  };
  numerics::IntegratorStatistics exact, sym;
  const Eigen::VectorXd u_exact = solve(numerics::LinearSolverChoice::kAuto, exact);
  const Eigen::VectorXd u_sym = solve(numerics::LinearSolverChoice::kCholmod, sym);
  std::printf("osmotic cap: %s %ld iterations, %s %ld iterations, max |dq| %.3e of max |q - q0| %.3e (positions and gradients)\n",
              exact.linear_solver.c_str(), exact.newton_iterations, sym.linear_solver.c_str(), sym.newton_iterations,
              (u_exact - u_sym).cwiseAbs().maxCoeff(), u_exact.cwiseAbs().maxCoeff());
  EXPECT_EQ(exact.linear_solver, "UMFPACK LU");
  EXPECT_EQ(sym.linear_solver, "CHOLMOD supernodal LLT");
  EXPECT_LT((u_exact - u_sym).cwiseAbs().maxCoeff(), 1e-8 * u_exact.cwiseAbs().maxCoeff());
}

// Plate on the compressive foundation, clamped along x = 0, uniform pressure
// on the outer face pushing towards the bone: far from the clamp the plate
// translates rigidly by p / k (nodal areas and the consistent pressure load
// are the same integrals). The clamp disturbance decays like
// exp(-beta x), beta = (k / (4 D))^(1/4) = 263 1/m for the seed's values, so
// at x >= 45 mm it is < 1e-5: tolerance 1e-4 relative.
TEST(ShellVerification, FoundationUniformPressureDeflectsByPOverK) {
  const double L = 0.06, W = 0.01, t = 1e-3, k = 7e8, p = 1e4;
  common::QuadMesh mesh = plate_mesh(48, 4, L, W);
  ShellMaterial mat;  // seed defaults: E = 400 MPa, nu = 0.3
  ShellModel model(mesh, up(mesh.num_nodes()), Eigen::VectorXd::Constant(mesh.num_nodes(), t), mat);
  model.add_internal_forces();
  model.add_foundation_springs(k);
  model.add_pressure("pressure", 1.0, [p](double s) { return -s * p; });
  model.fix_nodes("clamp", nodes_where(mesh, [](const Eigen::Vector3d& X) { return X.x() < 1e-12; }),
                  {true, true, true, true, true, true});
  numerics::HhtIntegrator solver(model, static_options(1.0));
  solver.initialize(0, model.reference_state());
  solver.advance_to(1.0);
  double worst = 0;
  int count = 0;
  for (int i = 0; i < model.num_nodes(); ++i) {
    if (mesh.V(i, 0) < 0.045) continue;
    const double w = solver.q()(6 * i + 2) - mesh.V(i, 2);
    worst = std::max(worst, std::abs(-w / (p / k) - 1.0));
    ++count;
  }
  const auto& st = solver.statistics();
  std::printf("foundation: %d far nodes, max |w/(p/k) - 1| = %.3e (%ld Newton iterations, %ld rejected; "
              "assembly %.3f s, factorisation %.3f s, solve %.3f s, %s)\n",
              count, worst, st.newton_iterations, st.rejected_steps, st.assembly_s, st.factorization_s, st.solve_s,
              st.linear_solver.c_str());
  EXPECT_GT(count, 0);
  EXPECT_LT(worst, 1e-4);
}

// Deflection under the load line of a free strip (nx x 1 quads, length L,
// width b, thickness t, nu of mat) on springs of modulus k acting in both
// directions, loaded by P across its width at mid-length. The springs act
// along the normal only: the in-plane rigid motions are held at the load
// line (x and y of one node, x of the other; zero there by symmetry and
// nu = 0).
double strip_on_foundation_deflection(int nx, double L, double b, double t, double k, const ShellMaterial& mat,
                                      double P, FoundationIntegration integration = FoundationIntegration::kNodal) {
  common::QuadMesh mesh = plate_mesh(nx, 1, L, b);
  ShellModel model(mesh, up(mesh.num_nodes()), Eigen::VectorXd::Constant(mesh.num_nodes(), t), mat);
  model.add_internal_forces();
  model.add_foundation_springs(k, BoneMotion::fixed(), /*compressive_only=*/false, integration);
  const int mid0 = nx / 2, mid1 = (nx + 1) + nx / 2;  // the two nodes across the width at x = L/2
  model.add_point_loads("line load", {{mid0, Eigen::Vector3d(0, 0, -P / 2)}, {mid1, Eigen::Vector3d(0, 0, -P / 2)}},
                        [](double s) { return s; });
  model.fix_nodes("in-plane", {mid0}, {true, true, false, false, false, false});
  model.fix_nodes("in-plane x", {mid1}, {true, false, false, false, false, false});
  numerics::HhtIntegrator solver(model, static_options(1.0));
  solver.initialize(0, model.reference_state());
  solver.advance_to(1.0);
  return -(solver.q()(6 * mid0 + 2) + solver.q()(6 * mid1 + 2)) / 2;
}

// A shell on its foundation spreads a load (Hetenyi's beam on an elastic
// foundation): a free strip of length L and width b, nu = 0 (beam theory and
// cylindrical bending coincide), on springs acting in both directions with
// modulus k, loaded by a line load P across its width at mid-length. The
// infinite-beam closed form is w0 = P lambda / (2 k b), lambda =
// (k b / (4 E I))^(1/4), I = b t^3 / 12: the load is carried over a length of
// about pi / lambda, not by the springs under it alone. This is what makes the
// surface stage (shells on a foundation) stiffer than the musculoskeletal
// stage's elastic foundation under the same overlap (docs/contact.md, "Stage 2
// against stage 1"). Transverse shear adds w0 lambda^2 t^2 E / (6 G) to first
// order (shear factor 1, as in the cantilever test above; 7.7e-4 relative
// here) and is in the reference. The free ends lie 5 / lambda from the load;
// their effect on w0 is of order exp(-5) x (deflection they would have) ~
// exp(-10) ~ 5e-5 relative. Discretisation: bilinear interpolation,
// O((lambda h)^2); measured 3.0e-2, 7.8e-3, 2.0e-3 at lambda h = 0.5, 0.25,
// 0.125 (rate 1.97): asserted rate in [1.8, 2.3], finest error < 0.5 %.
TEST(ShellVerification, BeamOnElasticFoundationSpreadsALineLoad) {
  const double t = 1e-3, b = 4e-3, E = 400e6, k = 7e5;  // k = 1e-3 x the seed's: lambda t = 0.048
  const double I = b * t * t * t / 12, G = E / 2;
  const double lambda = std::pow(k * b / (4 * E * I), 0.25);
  const double L = 10.0 / lambda;
  const double P = 1e-3;  // N: w0 ~ 8e-6 m = 8e-3 t, geometric nonlinearity negligible
  const double w_ref = P * lambda / (2 * k * b) * (1 + lambda * lambda * t * t * E / (6 * G));
  ShellMaterial mat;
  mat.youngs_modulus_Pa = E;
  mat.poisson_ratio = 0.0;
  std::vector<double> errors;
  for (int nx : {20, 40, 80}) {
    const double w0 = strip_on_foundation_deflection(nx, L, b, t, k, mat, P);
    errors.push_back(std::abs(w0 - w_ref) / w_ref);
    std::printf("beam on foundation nx=%d (lambda h = %.3f): w0/w_ref = %.6f, error %.3e\n", nx,
                lambda * L / nx, w0 / w_ref, errors.back());
  }
  const double rate = std::log2(errors[errors.size() - 2] / errors.back());
  std::printf("beam on foundation: convergence rate (last halving) %.3f\n", rate);
  EXPECT_GT(rate, 1.8);
  EXPECT_LT(rate, 2.3);
  EXPECT_LT(errors.back(), 5e-3);
}

// The same strip on the foundation the real subject's walks use: springs
// matched to the musculoskeletal stage's cartilage (K / h, K = 37.93 MPa from
// 10 MPa and nu = 0.45, h = 1.5 mm), about 36 x the seed's 0.7 N/mm^3. The
// bending length shrinks by 36^(1/4) = 2.4 (lambda t = 0.66): the seed's
// shell resolution (quads of 1.2-2 mm on the femur) puts lambda h near 1,
// where the bilinear interpolation cannot follow the deflection's decay and
// the strip carries a line load over too wide a band. Measured as the
// effective width W = P / (w0 k b) (the width of springs that would carry P
// at the load line's deflection): W falls monotonically under refinement at
// rate 2 to its limit (Richardson from the two finest meshes; the reference
// is the element's own limit, because at lambda t = 0.66 the first-order shear
// correction of the test above is itself 14 %). Printed: the excess over the
// limit at each lambda h, for the nodal springs (18 % at 1.2, 4.9 % at 0.6)
// and the element-consistent foundation (6.4 % and 1.6 %: about a third;
// docs/contact.md). Both converge to the same limit: the two integrate the
// same foundation. An independent check of these figures (to 4 digits): a Timoshenko beam
// of linear elements with one-point shear integration on lumped / consistent
// foundation springs (the strip's cylindrical bending) gives 1.1833 / 1.0642
// at lambda h = 1.2 and 1.0486 / 1.0164 at 0.6
// (scripts/foundation_beam_model.py).
TEST(ShellVerification, StiffFoundationSpreadingNeedsTheBendingLengthResolved) {
  const double t = 1e-3, b = 4e-3, E = 400e6, K = 10e6 * 0.55 / (1.45 * 0.1), k = K / 1.5e-3;
  const double I = b * t * t * t / 12;
  const double lambda = std::pow(k * b / (4 * E * I), 0.25);
  const double L = 12.0 / lambda;  // free ends 6 / lambda from the load: exp(-6) ~ 2.5e-3 of w0 there
  const double P = 1e-3;           // w0 ~ 9e-8 m: linear
  ShellMaterial mat;
  mat.youngs_modulus_Pa = E;
  mat.poisson_ratio = 0.0;
  const std::vector<int> nxs = {10, 20, 40, 80, 160};
  const size_t n = nxs.size();
  std::vector<double> W[2], W_limit(2);
  const char* names[2] = {"nodal", "consistent"};
  for (int m = 0; m < 2; ++m) {
    for (int nx : nxs) {
      const double w0 = strip_on_foundation_deflection(
          nx, L, b, t, k, mat, P, m == 0 ? FoundationIntegration::kNodal : FoundationIntegration::kConsistent);
      W[m].push_back(P / (w0 * k * b));
    }
    W_limit[m] = W[m][n - 1] + (W[m][n - 1] - W[m][n - 2]) / 3;
    for (size_t i = 0; i < n; ++i)
      std::printf("matched foundation, %s: lambda h = %.3f, effective width %.4f mm = %.4f x the limit %.4f mm\n",
                  names[m], lambda * L / nxs[i], W[m][i] * 1e3, W[m][i] / W_limit[m], W_limit[m] * 1e3);
    for (size_t i = 1; i < n; ++i) EXPECT_LT(W[m][i], W[m][i - 1]) << names[m] << ": coarser meshes spread wider";
    const double rate = std::log2((W[m][n - 3] - W[m][n - 2]) / (W[m][n - 2] - W[m][n - 1]));
    std::printf("matched foundation, %s: convergence rate %.3f\n", names[m], rate);
    EXPECT_GT(rate, 1.8) << names[m];  // bilinear interpolation: O((lambda h)^2)
    EXPECT_LT(rate, 2.3) << names[m];
    // Hetenyi without shear gives 2 / lambda; transverse shear softens the
    // strip and narrows the band (first order: / (1 + (lambda t)^2 E / (6 G)) = / 1.14).
    EXPECT_LT(W_limit[m], 2 / lambda);
    EXPECT_GT(W_limit[m], 0.8 * 2 / lambda);
  }
  // The same limit (Richardson's error at these meshes: ~1e-5 relative).
  EXPECT_NEAR(W_limit[1] / W_limit[0], 1.0, 1e-4);
  // The consistent foundation's excess is at most 0.4 x the nodal one at
  // every resolution (measured 0.33-0.35, as the beam model above).
  for (size_t i = 0; i < n - 1; ++i)
    EXPECT_LT(W[1][i] / W_limit[1] - 1, 0.4 * (W[0][i] / W_limit[0] - 1)) << "lambda h = " << lambda * L / nxs[i];
}

// Frame invariance: the same foundation/pressure/clamp problem posed in an
// arbitrary world pose (rotation + translation of mesh, directors and bone)
// gives the same displacement field rotated (1e-8 relative: Newton tolerance
// 1e-8 on both solves).
TEST(ShellVerification, ResultDoesNotDependOnWorldPose) {
  const common::QuadMesh base = plate_mesh(12, 3, 0.03, 0.0075, 0.2);
  std::vector<int> clamp;
  for (int i = 0; i < base.num_nodes(); ++i)
    if (base.V(i, 0) < 1e-12) clamp.push_back(i);
  auto solve = [&](const Eigen::Isometry3d& X) {
    common::QuadMesh mesh = base;
    common::Points3 D(mesh.num_nodes(), 3);
    for (int i = 0; i < mesh.num_nodes(); ++i) {
      mesh.V.row(i) = (X * Eigen::Vector3d(base.V.row(i).transpose())).transpose();
      D.row(i) = (X.linear() * Eigen::Vector3d::UnitZ()).transpose();
    }
    ShellModel model(mesh, D, Eigen::VectorXd::Constant(mesh.num_nodes(), 1e-3), ShellMaterial{});
    model.add_internal_forces();
    model.add_foundation_springs(7e8);
    model.add_pressure("pressure", 1.0, [](double s) { return -2e5 * s; });
    model.fix_nodes("clamp", clamp, {true, true, true, true, true, true});
    numerics::HhtIntegrator solver(model, static_options(1.0));
    solver.initialize(0, model.reference_state());
    solver.advance_to(1.0);
    Eigen::MatrixXd u(mesh.num_nodes(), 3);
    for (int i = 0; i < mesh.num_nodes(); ++i)
      u.row(i) = (X.linear().transpose() * (solver.q().segment<3>(6 * i) - model.reference_position(i))).transpose();
    return u;
  };
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  const Eigen::MatrixXd u0 = solve(X);
  X.linear() = Eigen::AngleAxisd(2.1, Eigen::Vector3d(0.3, -0.8, 0.5).normalized()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(0.4, -1.3, 2.2);
  const Eigen::MatrixXd u1 = solve(X);
  const double diff = (u0 - u1).cwiseAbs().maxCoeff(), scale = u0.cwiseAbs().maxCoeff();
  std::printf("frame invariance: max difference %.3e of max displacement %.3e\n", diff, scale);
  EXPECT_GT(scale, 0.0);
  EXPECT_LT(diff, 1e-8 * scale);
}

// Newton on one large load step (cantilever tip load to ~25% of L): the
// consistent tangent gives quadratic convergence; the measured order over the
// last iterates above round-off must be >= 1.8.
TEST(ShellVerification, NewtonConvergesQuadratically) {
  const double L = 1.0, b = 0.1, t = 0.01, E = 1e7;
  const double I = b * t * t * t / 12;
  const double P = 0.3 * 3 * E * I / (L * L);
  common::QuadMesh mesh = plate_mesh(8, 2, L, b);
  ShellMaterial mat;
  mat.youngs_modulus_Pa = E;
  ShellModel model(mesh, up(mesh.num_nodes()), Eigen::VectorXd::Constant(mesh.num_nodes(), t), mat);
  model.add_internal_forces();
  model.fix_nodes("clamp", nodes_where(mesh, [](const Eigen::Vector3d& X) { return X.x() < 1e-12; }),
                  {true, true, true, true, true, true});
  const std::vector<int> tip = nodes_where(mesh, [L](const Eigen::Vector3d& X) { return X.x() > L - 1e-12; });
  std::vector<std::pair<int, Eigen::Vector3d>> loads;
  for (int i : tip) loads.emplace_back(i, Eigen::Vector3d(0, 0, P / tip.size()));
  model.add_point_loads("tip_load", loads, [](double s) { return s; });
  numerics::IntegratorOptions o = static_options(1.0);
  o.residual_rtol = 1e-14;
  o.residual_atol_N = 1e-13;
  o.max_newton_iterations = 30;
  numerics::HhtIntegrator solver(model, o);
  solver.initialize(0, model.reference_state());
  solver.advance_to(1.0);
  ASSERT_EQ(solver.statistics().log.size(), 1u);
  const auto& r = solver.statistics().log[0].residual_norms;
  std::printf("Newton residuals:");
  for (double x : r) std::printf(" %.3e", x);
  std::printf("\n");
  // Orders p_k = log(r_{k+1}/r_k) / log(r_k/r_{k-1}) while r_{k+1} is above
  // the round-off floor (1e-10 of the first residual).
  double best = 0;
  for (size_t k = 1; k + 1 < r.size(); ++k) {
    if (r[k + 1] < 1e-10 * r[0]) break;
    const double order = std::log(r[k + 1] / r[k]) / std::log(r[k] / r[k - 1]);
    std::printf("  order at iterate %zu: %.3f\n", k + 1, order);
    best = std::max(best, order);
  }
  EXPECT_GE(best, 1.8);
  EXPECT_LE(r.size(), 12u);
  const double w = solver.q()(6 * tip[0] + 2);
  EXPECT_GT(w, 0.1 * L);  // really a large-deflection step
}

// A one-element shell (all four nodes' positions free, transverse gradients
// free, one edge clamped) released from a prescribed initial velocity: with
// alpha = 0 and no external work, the total energy (kinetic + strain) is
// conserved to Newton tolerance, checking mass matrix, inertia term and
// internal forces together in the dynamic path.
TEST(ShellHht, ElementEnergyConservedWithAlphaZero) {
  common::QuadMesh mesh;
  mesh.V.resize(4, 3);
  mesh.V << 0, 0, 0, 0.01, 0, 0, 0.01, 0.01, 0, 0, 0.01, 0;
  mesh.Q.resize(1, 4);
  mesh.Q << 0, 1, 2, 3;
  common::Points3 D(4, 3);
  D.rowwise() = Eigen::RowVector3d(0, 0, 1);
  ShellMaterial mat;  // seed defaults: 1 mm, 400 MPa, 0.3, 1000 kg/m^3
  ShellModel model(mesh, D, Eigen::VectorXd::Constant(4, 1e-3), mat);
  model.add_internal_forces();
  model.add_inertia();
  model.fix_nodes("clamp", {0, 3}, {true, true, true, true, true, true});
  numerics::IntegratorOptions o;
  o.alpha = 0.0;
  o.dt_s = 2e-6;
  o.residual_rtol = 1e-12;
  numerics::HhtIntegrator hht(model, o);
  Eigen::VectorXd v0 = Eigen::VectorXd::Zero(24);
  v0(6 * 1 + 2) = v0(6 * 2 + 2) = 0.5;  // tip moving at 0.5 m/s out of plane
  hht.initialize(0, model.reference_state(), v0);
  auto energy = [&]() {
    const Vector24 q = model.gather(0, hht.q()), v = model.gather(0, hht.v());
    return 0.5 * v.dot(model.element(0).mass() * v) + model.element(0).strain_energy(q);
  };
  const double E0 = energy();
  hht.advance_to(2e-4);
  std::printf("shell element alpha=0: energy ratio %.10f after %ld steps\n", energy() / E0, hht.statistics().steps);
  // Trapezoidal rule: exact energy conservation for linear systems; the
  // element is nonlinear with small (1e-3) strains, where the midpoint
  // energy error is O(h^2 * strain^2) ~ 1e-8; 1e-6 leaves margin.
  EXPECT_NEAR(energy() / E0, 1.0, 1e-6);
  EXPECT_EQ(model.built_terms(), (std::vector<std::string>{"internal_forces", "inertia", "clamp"}));
}

}  // namespace
}  // namespace arthrosim::cartilage
