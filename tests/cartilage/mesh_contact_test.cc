// Deformable mesh-to-mesh contact (cartilage/mesh_contact.h,
// cartilage/coupled_system.h): gap derivatives and the Newton tangent against
// finite differences, a rigid sphere pressed into a shell on its foundation
// against the elastic-foundation closed form, two shells on foundations
// sharing load as springs in series, edge-edge detection where no vertex
// penetrates, and the uncoupled system being exactly its models.
#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "cartilage/coupled_system.h"
#include "numerics/hht_integrator.h"
#include "cartilage/mesh_contact.h"
#include "cartilage/shell_model.h"
#include "cartilage/surface_model.h"
#include "common/effects.h"
#include "common/error.h"
#include "contact_test_helpers.h"
#include "musculoskeletal/contact.h"
#include "shell_test_meshes.h"
#include "tangent_fd.h"

namespace msk = arthrosim::musculoskeletal;

namespace arthrosim::cartilage {
namespace {

using Vec12 = Eigen::Matrix<double, 12, 1>;

common::QuadMesh shifted(common::QuadMesh m, const Eigen::Vector3d& d) {
  m.V.rowwise() += d.transpose();
  return m;
}

// The node positions of model m of a coupled system at its coordinates q.
common::Points3 node_positions(const CoupledShellSystem& sys, int m, const Eigen::VectorXd& q) {
  const Eigen::VectorXd qm = sys.segment(m, q);
  common::Points3 x(qm.size() / 6, 3);
  for (int i = 0; i < x.rows(); ++i) x.row(i) = qm.segment<3>(6 * i).transpose();
  return x;
}

std::unique_ptr<ShellModel> make_model(const common::QuadMesh& mesh, double E, double t) {
  ShellMaterial mat;
  mat.youngs_modulus_Pa = E;
  mat.poisson_ratio = 0.3;
  auto m = std::make_unique<ShellModel>(mesh, quad_mesh_vertex_normals(mesh),
                                        Eigen::VectorXd::Constant(mesh.num_nodes(), t), mat);
  m->add_internal_forces();
  return m;
}

// ---------------------------------------------------------------------------
// The gradient dg/dx = w_k n is exact and the AD Hessian matches finite
// differences of it. Points are generic (no symmetry); step 1e-7 m on a
// 1e-3 m geometry: central-difference truncation ~(1e-4)^2 and round-off
// ~1e-16/1e-7 relative, so 1e-6 relative is a safe bound.
TEST(MeshContact, GapGradientAndHessianMatchFiniteDifferences) {
  const std::array<Eigen::Vector3d, 4> vf = {Eigen::Vector3d(0.3e-3, 0.25e-3, -0.1e-3),
                                             Eigen::Vector3d(0.0, 0.0, 0.02e-3), Eigen::Vector3d(1.1e-3, 0.1e-3, 0.0),
                                             Eigen::Vector3d(0.2e-3, 0.9e-3, 0.07e-3)};
  const std::array<Eigen::Vector3d, 4> ee = {Eigen::Vector3d(-0.5e-3, 0.1e-3, 0.05e-3),
                                             Eigen::Vector3d(0.6e-3, -0.05e-3, 0.0),
                                             Eigen::Vector3d(0.05e-3, -0.7e-3, 0.11e-3),
                                             Eigen::Vector3d(-0.1e-3, 0.8e-3, 0.09e-3)};
  const char* names[6] = {"vertex-face", "edge-edge", "vertex-edge", "vertex-vertex", "vertex-edge in front",
                          "vertex-vertex in front"};
  // The last two: sign = -1, a vertex in front of the feature (augmented
  // contacts at positive gaps), g = +|x0 - c| = minus the behind value.
  for (int kind = 0; kind < 6; ++kind) {
    const ContactKind k = static_cast<ContactKind>(kind < 4 ? kind : kind - 2);
    const double sign = kind < 4 ? 1.0 : -1.0;
    const auto& x = kind == 1 ? ee : vf;
    Vec12 G;
    Eigen::Matrix<double, 12, 12> H;
    const double g = contact_gap(k, x, sign, &G, &H);
    if (kind >= 4) { EXPECT_EQ(g, -contact_gap(k, x, 1.0, nullptr, nullptr)); }
    EXPECT_TRUE(std::isfinite(g));
    const double h = 1e-7;
    double errG = 0, errH = 0;
    for (int j = 0; j < 12; ++j) {
      auto xp = x, xm = x;
      xp[j / 3](j % 3) += h;
      xm[j / 3](j % 3) -= h;
      Vec12 Gp, Gm;
      const double gp = contact_gap(k, xp, sign, &Gp, nullptr);
      const double gm = contact_gap(k, xm, sign, &Gm, nullptr);
      errG = std::max(errG, std::abs((gp - gm) / (2 * h) - G(j)));
      errH = std::max(errH, ((Gp - Gm) / (2 * h) - H.col(j)).cwiseAbs().maxCoeff());
    }
    std::printf("%s: |G - G_fd| %.2e (|G| %.2f), |H - H_fd| %.2e (|H| %.3e)\n", names[kind], errG, G.cwiseAbs().maxCoeff(), errH, H.cwiseAbs().maxCoeff());
    EXPECT_LT(errG, 1e-6 * G.cwiseAbs().maxCoeff());
    EXPECT_LT(errH, 1e-6 * H.cwiseAbs().maxCoeff());
    EXPECT_LT((H - H.transpose()).cwiseAbs().maxCoeff(), 1e-9 * H.cwiseAbs().maxCoeff());
  }
}

/// max |K - K_fd| / max |K| of the system's tangent (wrt = 0: dF/dq, 1: dF/dv)
/// at t = 0; steps 1e-10 m on positions, 1e-7 on transverse gradients.
double system_fd_error(CoupledShellSystem& sys, const Eigen::VectorXd& q, const Eigen::VectorXd& v, int wrt,
                       double* Kmax = nullptr) {
  return testing::tangent_fd_error(sys, 0.0, q, v, wrt, 1e-10, 1e-7, Kmax);
}

// A curved (spherical) patch facing down pressed into a plate: many
// vertex-face contacts in both passes with non-zero Hessian terms; the
// contact stiffness dominates the soft shells' so the check sees it.
// Tolerance 1e-5 of max|K|: positions step 1e-10 m against penetrations of
// 3e-4 m keeps the active set fixed; truncation (h/L)^2 ~ 1e-14, round-off
// ~ eps |F| / h ~ 1e-6 |K| at worst.
TEST(MeshContact, NewtonTangentMatchesFiniteDifferences) {
  for (int damped = 0; damped < 2; ++damped) {
    const common::QuadMesh plate = shifted(testing::plate_mesh(5, 5, 6e-3, 6e-3, 0.15), {-3e-3, -3e-3, 0});
    const common::QuadMesh cap = testing::flipped(testing::spherical_patch(6, 5e-3, 6e-3), -0.3e-3);
    auto A = make_model(plate, 1e6, 0.3e-3), B = make_model(cap, 1e6, 0.3e-3);
    CoupledShellSystem sys({A.get(), B.get()}, {"plate", "cap"});
    ContactOptions o;
    o.rim_vertices = true;  // rim nodes may be penetrating vertices in this set-up
    o.stiffness_N_m3 = 5e10;
    o.damping_N_s_m3 = damped ? 2e8 : 0.0;
    sys.add_contact("plate-cap", 0, 1, o);
    Eigen::VectorXd q(sys.num_dofs());
    q.head(A->num_dofs()) = A->reference_state();
    q.tail(B->num_dofs()) = B->reference_state();
    Eigen::VectorXd v = Eigen::VectorXd::Zero(sys.num_dofs());
    for (int i = 0; i < v.size(); ++i) v(i) = 1e-3 * std::sin(0.7 * i);  // gap rates of both signs
    const ContactPairReport rep = sys.contact_report(0, q, damped ? &v : nullptr);
    std::printf("damped %d: %ld vertex-face, %ld edge-edge, max penetration %.3e m, force %.4f N\n", damped,
                rep.counts.vertex_face, rep.counts.edge_edge, rep.counts.max_penetration_m, rep.total_force_a.z());
    ASSERT_GT(rep.counts.vertex_face, 10);
    double kmax = 0;
    const double e = system_fd_error(sys, q, v, 0, &kmax);
    std::printf("  dF/dq relative error %.2e (max |K| %.3e)\n", e, kmax);
    EXPECT_LT(e, 1e-5);
    EXPECT_FALSE(sys.tangent_symmetric());  // boundary fades and damping are not symmetric
    if (damped) {
      const double ev = system_fd_error(sys, q, v, 1);
      std::printf("  dF/dv relative error %.2e\n", ev);
      EXPECT_LT(ev, 1e-6);
    }
    // Equal and opposite: contact forces on both surfaces sum to zero (1e-12 N
    // of round-off on forces of about 1 N).
    EXPECT_LT((rep.total_force_a + rep.total_force_b).norm(), 1e-12 + 1e-10 * rep.total_force_a.norm());
  }
}

// The depth fade near max_depth: the cap of NewtonTangentMatchesFiniteDifferences
// penetrates up to 0.3 mm; with max_depth 0.36 mm the deepest contacts lie in
// the fade zone (0.27-0.36 mm), where the pressure falls with depth. The
// tangent still matches central differences (tolerance as there), and the
// total force is below the unfaded one.
TEST(MeshContact, DepthFadeTangentMatchesFiniteDifferences) {
  const common::QuadMesh plate = shifted(testing::plate_mesh(5, 5, 6e-3, 6e-3, 0.15), {-3e-3, -3e-3, 0});
  const common::QuadMesh cap = testing::flipped(testing::spherical_patch(6, 5e-3, 6e-3), -0.3e-3);
  double force[2] = {0, 0};
  for (int faded = 0; faded < 2; ++faded) {
    auto A = make_model(plate, 1e6, 0.3e-3), B = make_model(cap, 1e6, 0.3e-3);
    CoupledShellSystem sys({A.get(), B.get()}, {"plate", "cap"});
    ContactOptions o;
    o.rim_vertices = true;  // rim nodes may be penetrating vertices in this set-up
    o.stiffness_N_m3 = 5e10;
    o.max_depth_m = faded ? 0.36e-3 : 1e-3;
    sys.add_contact("plate-cap", 0, 1, o);
    Eigen::VectorXd q(sys.num_dofs());
    q << A->reference_state(), B->reference_state();
    const ContactPairReport rep = sys.contact_report(0, q, nullptr);
    force[faded] = rep.total_force_a.norm();
    int in_zone = 0;
    for (const ContactPoint& c : sys.contact(0).detect(plate.V, cap.V, nullptr, nullptr, false))
      if (-c.gap > 0.75 * o.max_depth_m) ++in_zone;
    const double e = system_fd_error(sys, q, Eigen::VectorXd::Zero(sys.num_dofs()), 0);
    std::printf("max_depth %.2f mm: %d contacts in the fade zone, force %.4f N, tangent relative error %.2e\n",
                o.max_depth_m * 1e3, in_zone, force[faded], e);
    if (faded) { EXPECT_GT(in_zone, 0); }
    EXPECT_LT(e, 1e-5);
  }
  EXPECT_LT(force[1], force[0]);
}

// A small flat plate (distorted mesh) pressed 30 um into a larger one, its
// rim inside the larger plate, slid in-plane across it in steps of 10 um.
// RimTreatment::kFadeInside: contacts with the faces next to the small
// plate's rim are faded (0 < phi < 1), their tangent (the fade's gradient
// included) matches finite differences (tolerance as above), the force
// stays normal to the flat plates (no sideways component beyond round-off),
// and the total force changes smoothly as vertices cross the rim row: the
// largest change per 10 um step must stay below 2 % of the force (measured
// 0.48 %; a vertex crossing a rim with a force jump changes it by its whole
// share: 17 % with the earlier rim contacts, kRimContacts, which on the same
// configuration also push sideways, up to 0.57 of the normal force).
TEST(MeshContact, RimFadeInsideIsContinuousAndNeverSideways) {
  const common::QuadMesh big = shifted(testing::plate_mesh(12, 12, 10e-3, 10e-3), {-5e-3, -5e-3, 0});
  const common::QuadMesh small0 =
      testing::flipped(shifted(testing::plate_mesh(6, 6, 4e-3, 4e-3, 0.2), {-2e-3, -2e-3, 0}), -30e-6);
  for (RimTreatment rim : {RimTreatment::kFadeInside, RimTreatment::kRimContacts}) {
    ContactOptions o;
    o.rim_vertices = true;  // rim nodes may be penetrating vertices in this set-up
    o.rim_max_depth_m = 0;  // rim contacts cut off at max_depth_m
    o.stiffness_N_m3 = 5e10;
    o.rim = rim;
    const bool fade = rim == RimTreatment::kFadeInside;
    double worst_jump = 0, F0 = 0, sideways = 0, last = 0;
    int faded = 0;
    for (int s = 0; s <= 100; ++s) {
      const common::QuadMesh small = shifted(small0, {10e-6 * s, 4e-6 * s, 0});
      MeshContact mc("big-small", ContactSurface(big), ContactSurface(small), o);
      Eigen::Vector3d F = Eigen::Vector3d::Zero();
      for (const ContactPoint& c : mc.detect(big.V, small.V, nullptr, nullptr, false)) {
        F += c.area * c.fade * c.pressure * c.G.segment<3>(0);
        if (s == 0 && c.fade_edge >= 0 && c.fade > 0 && c.fade < 1) ++faded;
      }
      sideways = std::max(sideways, F.head<2>().norm() / std::abs(F.z()));
      if (s == 0) F0 = std::abs(F.z());
      if (s > 0) worst_jump = std::max(worst_jump, std::abs(std::abs(F.z()) - last) / F0);
      last = std::abs(F.z());
    }
    std::printf("%s: %d faded contacts, force on the big plate's vertices %.5f N, largest change per 10 um %.2e "
                "of it, sideways/normal up to %.2e\n",
                fade ? "fade inside" : "rim contacts", faded, F0, worst_jump, sideways);
    if (fade) {
      EXPECT_GT(faded, 3);
      EXPECT_LT(worst_jump, 0.02);
      EXPECT_LT(sideways, 1e-12);
      // Tangent at a generic offset: in the start position vertices of the
      // two regular grids lie exactly above each other, where the closest
      // feature of a flat surface is a vertex (a tie of face, edge and corner)
      // and the corner's distance Hessian is not that of the face around it.
      auto A = make_model(big, 1e6, 0.3e-3), B = make_model(shifted(small0, {0.37e-3, 0.21e-3, 0}), 1e6, 0.3e-3);
      CoupledShellSystem sys({A.get(), B.get()}, {"big", "small"});
      sys.add_contact("big-small", 0, 1, o);
      Eigen::VectorXd q(sys.num_dofs());
      q << A->reference_state(), B->reference_state();
      const double e = system_fd_error(sys, q, Eigen::VectorXd::Zero(sys.num_dofs()), 0);
      std::printf("  fade-inside tangent relative error %.2e\n", e);
      EXPECT_LT(e, 1e-5);
    } else {
      EXPECT_GT(sideways, 1e-3);  // the defect kFadeInside removes
    }
  }
}

// The counts behind the seed's accuracy rule: a small plate tilted about
// its y axis and pressed into a larger one, so that its deepest row is its
// rim, where kFadeInside fades the contacts. max_penetration_m is the
// deepest of all active contacts (a faded one here), max_unfaded_
// penetration_m the deepest unfaded one, max_rim_depth_m the deepest faded
// one; each is checked against the contact list itself, and the tilt must
// make the rim the deepest (otherwise the case would not tell them apart).
// The small plate's rim nodes are not penetrating vertices, as in the
// walking scenes (contact_rim_vertices false).
TEST(MeshContact, PenetrationCountsSeparateFadedRimContacts) {
  const common::QuadMesh big = shifted(testing::plate_mesh(12, 12, 10e-3, 10e-3), {-5e-3, -5e-3, 0});
  common::QuadMesh small =
      testing::flipped(shifted(testing::plate_mesh(6, 6, 4e-3, 4e-3, 0.2), {-2e-3, -2e-3, 0}), 10e-6);
  // Tilt: z falls by 20 um per mm of x, so the plate's -x rim is 80 um
  // deeper than its +x rim; part of it stays above the big plate.
  for (int i = 0; i < small.V.rows(); ++i) small.V(i, 2) += 20e-3 * small.V(i, 0);
  ContactOptions o;
  o.stiffness_N_m3 = 5e10;
  o.rim_vertices = false;  // the surface stage's default: rim nodes do not penetrate
  MeshContact mc("big-small", ContactSurface(big), ContactSurface(small), o);
  ContactCounts n;
  const auto active = mc.detect(big.V, small.V, nullptr, nullptr, false, &n);
  double deepest = 0, unfaded = 0, faded = 0;
  for (const ContactPoint& c : active) {
    deepest = std::max(deepest, -c.gap);
    double& m = c.fade_edge >= 0 ? faded : unfaded;
    m = std::max(m, -c.gap);
  }
  std::printf("%zu contacts: deepest %.2f um, unfaded %.2f um, faded %.2f um\n", active.size(), deepest * 1e6,
              unfaded * 1e6, faded * 1e6);
  ASSERT_GT(unfaded, 0.0);
  ASSERT_GT(faded, unfaded);  // the tilt puts the rim row deepest
  EXPECT_EQ(n.max_penetration_m, deepest);
  EXPECT_EQ(n.max_unfaded_penetration_m, unfaded);
  EXPECT_EQ(n.max_rim_depth_m, faded);
  EXPECT_LT(n.max_unfaded_penetration_m, n.max_penetration_m);
}

// The earlier rim treatment (RimTreatment::kRimContacts): a cap narrower
// than its contact zone, plate vertices beside the cap's rim are behind the
// plane of its boundary triangles and keep their distance to the rim as gap,
// faded by how squarely they lie behind it. The fade's gradient is part of
// the tangent: checked against finite differences (tolerance as above).
TEST(MeshContact, BoundaryFadeTangentMatchesFiniteDifferences) {
  const common::QuadMesh plate = shifted(testing::plate_mesh(8, 8, 5e-3, 5e-3, 0.15), {-2.5e-3, -2.5e-3, 0});
  const common::QuadMesh cap = testing::flipped(testing::spherical_patch(5, 3e-3, 6e-3), -0.3e-3);
  ContactOptions o;
  o.rim_vertices = true;  // rim nodes may be penetrating vertices in this set-up
  o.rim_max_depth_m = 0;  // rim contacts cut off at max_depth_m
  o.stiffness_N_m3 = 5e10;
  o.rim = RimTreatment::kRimContacts;
  MeshContact mc("plate-cap", ContactSurface(plate), ContactSurface(cap), o);
  const auto active = mc.detect(plate.V, cap.V, nullptr, nullptr, false);
  int faded = 0;
  for (const ContactPoint& c : active)
    if (c.fade_edge >= 0) {
      ++faded;
      EXPECT_GT(c.fade, 0.0);
      EXPECT_LE(c.fade, 1.0);
    }
  std::printf("rim: %zu contacts, %d faded beyond the cap's open boundary\n", active.size(), faded);
  ASSERT_GT(faded, 3);
  auto A = make_model(plate, 1e6, 0.3e-3), B = make_model(cap, 1e6, 0.3e-3);
  CoupledShellSystem sys({A.get(), B.get()}, {"plate", "cap"});
  sys.add_contact("plate-cap", 0, 1, o);
  Eigen::VectorXd q(sys.num_dofs());
  q << A->reference_state(), B->reference_state();
  const double e = system_fd_error(sys, q, Eigen::VectorXd::Zero(sys.num_dofs()), 0);
  std::printf("  rim tangent relative error %.2e\n", e);
  EXPECT_LT(e, 1e-5);
  // A rim cut-off just above the deepest rim contact puts it in the depth
  // fade: still consistent, and the faded rim force is smaller.
  double deepest = 0;
  for (const ContactPoint& c : active)
    if (c.fade_edge >= 0) deepest = std::max(deepest, -c.gap);
  ContactOptions o2 = o;
  o2.rim_max_depth_m = 1.1 * deepest;
  CoupledShellSystem sys2({A.get(), B.get()}, {"plate", "cap"});
  sys2.add_contact("plate-cap", 0, 1, o2);
  const double e2 = system_fd_error(sys2, q, Eigen::VectorXd::Zero(sys2.num_dofs()), 0);
  const double f1 = sys.contact_report(0, q).total_force_a.norm(), f2 = sys2.contact_report(0, q).total_force_a.norm();
  std::printf("  rim cut-off %.3e m: tangent relative error %.2e, force %.5f N (was %.5f N)\n", o2.rim_max_depth_m, e2,
              f2, f1);
  EXPECT_LT(e2, 1e-5);
  EXPECT_LT(f2, f1);
}

// Two tents whose ridges cross: the ridges' edges interpenetrate by delta but
// every vertex is either outside the other surface or deeper than
// max_depth, so only the edge-edge test can see the contact. Its gap is the
// line distance -delta with the normal of the lower (second) surface.
TEST(MeshContact, EdgeEdgeCatchesCrossingRidges) {
  const double L = 4e-3, h = 4e-3, delta = 0.2e-3;
  common::QuadMesh a;  // ridge along x at z = h, sides down to z = 0 at y = -L, +L; normals up
  a.V.resize(6, 3);
  a.V << -L, -L, 0, L, -L, 0, L, 0, h, -L, 0, h, L, L, 0, -L, L, 0;
  a.Q.resize(2, 4);
  a.Q << 0, 1, 2, 3, 3, 2, 4, 5;
  common::QuadMesh b;  // ridge along y at z = h - delta, sides up to 2h - delta at x = -L, +L; normals down
  b.V.resize(6, 3);
  const double z0 = h - delta, z1 = 2 * h - delta;
  b.V << -L, -L, z1, -L, L, z1, 0, L, z0, 0, -L, z0, L, L, z1, L, -L, z1;
  b.Q.resize(2, 4);
  b.Q << 0, 1, 2, 3, 3, 2, 4, 5;
  ContactOptions o;
  o.rim_vertices = true;  // rim nodes may be penetrating vertices in this set-up
  o.stiffness_N_m3 = 1e10;
  o.max_depth_m = 1e-3;
  o.edge_edge = true;
  MeshContact mc("ridges", ContactSurface(a), ContactSurface(b), o);
  ContactCounts counts;
  const auto active = mc.detect(a.V, b.V, nullptr, nullptr, true, &counts);
  std::printf("ridges: %ld vertex-face, %ld edge-edge\n", counts.vertex_face, counts.edge_edge);
  EXPECT_EQ(counts.vertex_face, 0);
  ASSERT_GE(counts.edge_edge, 1);
  bool ridge = false;
  for (const ContactPoint& c : active) {
    EXPECT_EQ(c.kind, ContactKind::kEdgeEdge);
    EXPECT_LT(c.gap, 0.0);
    EXPECT_GT(c.gap, -o.max_depth_m);
    if (std::abs(c.gap + delta) < 1e-12) {
      ridge = true;
      EXPECT_NEAR(c.normal.z(), -1.0, 1e-12);
      EXPECT_NEAR(c.point.norm(), std::hypot(0.0, z0), 1e-9);  // on the second ridge, at (0, 0, h - delta)
    }
  }
  EXPECT_TRUE(ridge);
  // With edge-edge off the same configuration has no contact at all.
  ContactOptions off = o;
  off.edge_edge = false;
  MeshContact mc_off("ridges", ContactSurface(a), ContactSurface(b), off);
  EXPECT_TRUE(mc_off.detect(a.V, b.V, nullptr, nullptr, false).empty());
  // Tangent with the edge-edge contact against finite differences.
  auto A = make_model(a, 1e6, 0.3e-3), B = make_model(b, 1e6, 0.3e-3);
  CoupledShellSystem sys({A.get(), B.get()}, {"a", "b"});
  sys.add_contact("ridges", 0, 1, o);
  Eigen::VectorXd q(sys.num_dofs());
  q << A->reference_state(), B->reference_state();
  const double e = system_fd_error(sys, q, Eigen::VectorXd::Zero(sys.num_dofs()), 0);
  std::printf("edge-edge tangent relative error %.2e\n", e);
  EXPECT_LT(e, 1e-5);
}

// A system without contact is exactly its models side by side.
TEST(MeshContact, UncoupledSystemIsItsModels) {
  const common::QuadMesh m1 = testing::spherical_patch(3, 0.01, 0.02);
  const common::QuadMesh m2 = shifted(testing::plate_mesh(2, 3, 0.01, 0.01), {0, 0, 0.05});
  auto A = make_model(m1, 400e6, 1e-3), B = make_model(m2, 400e6, 1e-3);
  A->add_foundation_springs(7e8);
  B->add_pressure("pressure", 0.0, [](double) { return 1e5; });
  CoupledShellSystem sys({A.get(), B.get()}, {"a", "b"});
  Eigen::VectorXd q(sys.num_dofs());
  q << A->reference_state(), B->reference_state();
  for (int i = 0; i < q.size(); ++i) q(i) += 1e-5 * std::cos(1.3 * i);
  numerics::EvalRequest r;
  r.q = &q;
  Eigen::VectorXd F;
  Eigen::SparseMatrix<double> K;
  sys.evaluate(r, F, nullptr, &K);
  Eigen::VectorXd qa = sys.segment(0, q), qb = sys.segment(1, q), Fa, Fb;
  Eigen::SparseMatrix<double> Ka, Kb;
  numerics::EvalRequest ra = r, rb = r;
  ra.q = &qa;
  rb.q = &qb;
  A->evaluate(ra, Fa, nullptr, &Ka);
  B->evaluate(rb, Fb, nullptr, &Kb);
  EXPECT_EQ(F.head(Fa.size()), Fa);
  EXPECT_EQ(F.tail(Fb.size()), Fb);
  const Eigen::MatrixXd Kd(K);
  EXPECT_EQ(Kd.topLeftCorner(Fa.size(), Fa.size()), Eigen::MatrixXd(Ka));
  EXPECT_EQ(Kd.bottomRightCorner(Fb.size(), Fb.size()), Eigen::MatrixXd(Kb));
  EXPECT_EQ(Kd.topRightCorner(Fa.size(), Fb.size()).cwiseAbs().maxCoeff(), 0.0);
}

/// In-plane position coordinates of every node fixed (the foundation acts
/// along the normal only, so in-plane rigid motions would be free).
void fix_in_plane(ShellModel& m) {
  std::vector<int> all(m.num_nodes());
  for (int i = 0; i < m.num_nodes(); ++i) all[i] = i;
  m.fix_nodes("in_plane", all, {true, true, false, false, false, false});
}

/// Solves the quasi-static contact problem in `steps` load steps to t = 1.
void solve_quasi_static(CoupledShellSystem& sys, int steps, Eigen::VectorXd& q, numerics::IntegratorStatistics* stats = nullptr) {
  numerics::IntegratorOptions opt;
  opt.quasi_static = true;
  opt.dt_s = 1.0 / steps;
  opt.max_newton_iterations = 25;
  opt.line_search_halvings = 8;
  opt.residual_rtol = 1e-9;
  opt.residual_atol_N = 1e-8;
  numerics::HhtIntegrator hht(sys, opt);
  hht.initialize(0.0, q);
  try {
    hht.advance_to(1.0);
  } catch (const std::exception& e) {
    for (const auto& r : hht.statistics().rejections) std::printf("  rejected: %s\n", r.c_str());
    throw;
  }
  q = hht.q();
  if (stats) *stats = hht.statistics();
}

// Rigid sphere (radius R, every node prescribed, moving down by d over the
// load steps) pressed into a shell on a foundation of modulus k, the shell
// reduced to its normal displacements on a negligible membrane (see below),
// so that the surface follows the sphere and the pressure is the
// foundation's in series with the penalty:
//   F = k_eff V_cap,  k_eff = 1/(1/k + 1/k_c),  V_cap = pi d^2 (3R - d)/3.
// Error sources are the faceted sphere, the nodal quadrature of the pressure
// and the residual bending; they fall with refinement (checked), and the
// finest mesh must be within 2 %.
TEST(MeshContact, RigidSphereOnFoundationMatchesClosedForm) {
  const double R = 12e-3, d = 0.25e-3, k = 7e8, kc = 7e10, W = 12e-3;
  const double keff = 1.0 / (1.0 / k + 1.0 / kc);
  const double F_exact = keff * M_PI * d * d * (3 * R - d) / 3.0;
  double prev_err = 1e30;
  const int sizes[3] = {12, 24, 40};
  for (int level = 0; level < 3; ++level) {
    const int n = sizes[level];
    const common::QuadMesh plate = shifted(testing::plate_mesh(n, n, W, W), {-W / 2, -W / 2, 0});
    // Sphere bottom starts 0.02 mm above the plate and ends d below it.
    const double lift = 0.02e-3;
    const common::QuadMesh sphere = testing::flipped(testing::spherical_patch(n, 9e-3, R), lift);
    auto P = make_model(plate, 1e3, 0.2e-3), S = make_model(sphere, 1e6, 0.2e-3);
    P->add_foundation_springs(k, BoneMotion::fixed(), /*compressive_only=*/false);
    // Only the normal position is free: a bed of foundation springs (acting
    // both ways, so that a Newton iterate overshooting upwards still meets
    // the spring) under a membrane so soft (E = 1 kPa) that its shear
    // coupling length sqrt(G t / k) = 10 um is negligible -- the
    // elastic-foundation model.
    std::vector<int> all(P->num_nodes());
    for (int i = 0; i < P->num_nodes(); ++i) all[i] = i;
    P->fix_nodes("bed_of_springs", all, {true, true, false, true, true, true});
    NodeConstraint c;
    c.name = "rigid_motion";
    for (int i = 0; i < S->num_nodes(); ++i) c.nodes.push_back(i);
    c.mask.fill(true);
    const Eigen::VectorXd s0 = S->reference_state();
    c.value = [s0, lift, d](double t, int node, Eigen::Matrix<double, 6, 1>& q6) {
      q6 = s0.segment<6>(6 * node);
      q6(2) -= t * (lift + d);
    };
    S->add_constraint(std::move(c));
    CoupledShellSystem sys({P.get(), S.get()}, {"plate", "sphere"});
    ContactOptions o;
    o.rim_vertices = true;  // rim nodes may be penetrating vertices in this set-up
    o.stiffness_N_m3 = kc;
    sys.add_contact("plate-sphere", 0, 1, o);
    Eigen::VectorXd q(sys.num_dofs());
    q << P->reference_state(), S->reference_state();
    numerics::IntegratorStatistics st;
    solve_quasi_static(sys, 4, q, &st);
    const ContactPairReport rep = sys.contact_report(0, q);
    const double F = -rep.total_force_a.z();  // the sphere pushes the plate down
    const double err = std::abs(F / F_exact - 1);
    std::printf("sphere n=%d: F = %.5f N, closed form %.5f N, error %.3e; %ld vf, %ld ee; max pen %.3e m; "
                "newton %ld, pattern changes %ld, %s, %.2f s (assembly %.2f, factorisation %.2f, solve %.2f)\n",
                n, F, F_exact, err, rep.counts.vertex_face, rep.counts.edge_edge, rep.counts.max_penetration_m,
                st.newton_iterations, st.pattern_changes, st.linear_solver.c_str(), st.total_s, st.assembly_s,
                st.factorization_s, st.solve_s);
    EXPECT_LT(err, prev_err);
    prev_err = err;
    if (level == 2) { EXPECT_LT(err, 0.02); }
    // The penetration is about the penalty's share of the overlap,
    // d k / (k + k_c), plus half the toe width; node-to-surface forces vary
    // from node to node around p A_i, so allow a factor 2.
    if (level == 2) { EXPECT_LT(rep.counts.max_penetration_m, 2 * (d * k / (k + kc) + 0.5 * o.smoothing_m)); }
  }
}

// Two flat shells on foundations k1 (bone at rest) and k2 (bone moving down
// by d), non-matching meshes, pressed together: the uniform interior state
// is springs in series, p = (d - s0)/(1/k1 + 1/k2 + 1/k_c), with deflections
// p/k1 and p/k2. Checked near the centre, more than 10 bending lengths
// (D/k)^(1/4) = 0.63 mm from the top plate's edge, so edge effects are far
// below the 1 % tolerance (which covers the Newton tolerance and round-off
// many times over).
TEST(MeshContact, TwoShellsShareLoadAsSpringsInSeries) {
  const double k1 = 7e8, k2 = 2.1e9, kc = 7e10, d = 0.3e-3, s0 = 0.05e-3;
  const common::QuadMesh lower = shifted(testing::plate_mesh(14, 14, 20e-3, 20e-3), {-10e-3, -10e-3, 0});
  const common::QuadMesh upper =
      testing::flipped(shifted(testing::plate_mesh(11, 11, 14e-3, 14e-3, 0.1), {-7.3e-3, -6.9e-3, 0}), s0);
  auto A = make_model(lower, 10e6, 0.5e-3), B = make_model(upper, 10e6, 0.5e-3);
  A->add_foundation_springs(k1);
  const BoneMotion down = testing::translating_bone(Eigen::Vector3d(0, 0, -d));
  B->add_foundation_springs(k2, down);
  fix_in_plane(*A);
  fix_in_plane(*B);
  CoupledShellSystem sys({A.get(), B.get()}, {"lower", "upper"});
  ContactOptions o;
  o.rim_vertices = true;  // rim nodes may be penetrating vertices in this set-up
  o.stiffness_N_m3 = kc;
  sys.add_contact("lower-upper", 0, 1, o);
  Eigen::VectorXd q(sys.num_dofs());
  q << A->reference_state(), B->reference_state();
  solve_quasi_static(sys, 3, q);
  // The penalty's quadratic toe adds delta/2 to the penetration.
  const double p = (d - s0 - 0.5 * o.smoothing_m) / (1 / k1 + 1 / k2 + 1 / kc);
  // Area-weighted mean deflections of the nodes within 3 mm of the centre: with
  // non-matching meshes the node-to-surface forces fluctuate from node to
  // node around p A_i (the barycentric spreading of the other mesh's
  // vertices), but their local mean is p (force balance).
  auto mean_deflection = [&](int m, double bone_dz, double sign) {
    return testing::mean_normal_deflection(sys.model(m), sys.segment(m, q), Eigen::Vector3d::Zero(),
                                           Eigen::Vector3d::UnitZ(), 3e-3, Eigen::Vector3d(0, 0, bone_dz), sign);
  };
  const double wa = mean_deflection(0, 0.0, -1.0);  // lower surface pushed down
  const double wb = mean_deflection(1, -d, 1.0);    // upper surface pushed up relative to its bone
  std::printf("series: w1 %.5e (exact %.5e), w2 %.5e (exact %.5e) m\n", wa, p / k1, wb, p / k2);
  EXPECT_NEAR(wa, p / k1, 0.01 * p / k1);
  EXPECT_NEAR(wb, p / k2, 0.01 * p / k2);
}

// Augmented Lagrangian (Uzawa) on the springs-in-series set-up: the exact
// non-penetrating state has the pressure p* = (d - s0)/(1/k1 + 1/k2). A soft
// penalty k_c = 5e9 N/m^3 alone gives p0 = (d - s0 - delta/2)/(1/k1 + 1/k2 +
// 1/k_c), 9.5 % low. Each augmentation sets a vertex's multiplier to its
// pressure; on the linear branch p = lambda + k_c pen, so the interior
// penetration contracts by r = k_eq/(k_eq + k_c) = 0.095 per augmentation
// (k_eq = 1/(1/k1 + 1/k2)) and the multipliers converge to p*. Checked in
// the interior (within 3 mm of the centre, as the series test): the mean
// penetration falls by at most 2 r per augmentation over the first two
// (non-matching meshes make the node forces fluctuate around the mean, the
// factor 2 covers it; by the third the mean penetration, 1e-4 of the
// overlap, is at the level of those fluctuations), and after three
// augmentations the deflections match p* within 1 % (the series test's
// tolerance; the penalty alone is 9.5 % off, so the check can fail), the
// area-weighted mean multiplier within 3 % (see below), the penetration
// below 1e-3 of the overlap.
TEST(MeshContact, AugmentedLagrangianConvergesToNonPenetratingClosedForm) {
  const double k1 = 7e8, k2 = 2.1e9, kc = 5e9, d = 0.3e-3, s0 = 0.05e-3;
  const double keq = 1 / (1 / k1 + 1 / k2), p_exact = keq * (d - s0), r = keq / (keq + kc);
  const common::QuadMesh lower = shifted(testing::plate_mesh(14, 14, 20e-3, 20e-3), {-10e-3, -10e-3, 0});
  const common::QuadMesh upper =
      testing::flipped(shifted(testing::plate_mesh(11, 11, 14e-3, 14e-3, 0.1), {-7.3e-3, -6.9e-3, 0}), s0);
  auto A = make_model(lower, 10e6, 0.5e-3), B = make_model(upper, 10e6, 0.5e-3);
  A->add_foundation_springs(k1);
  B->add_foundation_springs(k2, testing::translating_bone(Eigen::Vector3d(0, 0, -d)));
  fix_in_plane(*A);
  fix_in_plane(*B);
  CoupledShellSystem sys({A.get(), B.get()}, {"lower", "upper"});
  ContactOptions o;
  o.rim_vertices = true;
  o.stiffness_N_m3 = kc;
  sys.add_contact("lower-upper", 0, 1, o);
  Eigen::VectorXd q0(sys.num_dofs());
  q0 << A->reference_state(), B->reference_state();
  auto points = [&](int m, const Eigen::VectorXd& q) { return node_positions(sys, m, q); };
  double prev_pen = 0;
  for (int n = 0; n <= 3; ++n) {
    Eigen::VectorXd q = q0;
    solve_quasi_static(sys, 3, q);
    const common::Points3 xa = points(0, q), xb = points(1, q);
    // Interior contacts: mean penetration and, through the update, the mean multiplier.
    const auto lambda = sys.updated_contact_multipliers(0, q);
    double pen = 0, lam = 0, area = 0;
    int count = 0;
    for (const ContactPoint& c : sys.contact(0).detect(xa, xb, nullptr, nullptr, false)) {
      if (c.point.head<2>().norm() > 3e-3) continue;
      pen += -c.gap;
      lam += c.area * lambda[c.side[0]](c.node[0]);  // area-weighted: the force balance
      area += c.area;
      ++count;
    }
    ASSERT_GT(count, 20);
    pen /= count;
    lam /= area;
    const double wa = testing::mean_normal_deflection(sys.model(0), sys.segment(0, q), Eigen::Vector3d::Zero(),
                                                      Eigen::Vector3d::UnitZ(), 3e-3, Eigen::Vector3d::Zero(), -1.0);
    std::printf("augmentations %d: mean interior penetration %.4e m, mean multiplier %.6e Pa (p* %.6e), "
                "w1 %.6e (p*/k1 %.6e) m\n", n, pen, lam, p_exact, wa, p_exact / k1);
    if (n == 0) {
      const double p0 = (d - s0 - 0.5 * o.smoothing_m) / (1 / k1 + 1 / k2 + 1 / kc);
      EXPECT_NEAR(wa, p0 / k1, 0.01 * p0 / k1);
      EXPECT_GT(std::abs(wa / (p_exact / k1) - 1), 0.05);  // the penalty alone is far off
    } else if (n < 3) {
      EXPECT_LT(pen, 2 * r * prev_pen);
    }
    if (n == 3) {
      EXPECT_NEAR(wa, p_exact / k1, 0.01 * p_exact / k1);
      // The per-vertex pressures on non-matching meshes scatter around the
      // local mean (each samples the other mesh's barycentric spreading); the
      // same disc mean is 1.5 % above the penalty's own closed form p0 at n = 0.
      // 3 % still separates p* from the penalty's 9.5 % deficit.
      EXPECT_NEAR(lam, p_exact, 0.03 * p_exact);
      EXPECT_LT(pen, 1e-3 * (d - s0));
    }
    prev_pen = pen;
    sys.set_contact_multipliers(0, lambda);
  }
}

// The two stages model the same cartilage: a flat layer pair of thicknesses
// h1, h2 (E, nu) under a uniform overlap delta. Stage 1's elastic
// foundation (msk::ContactPair, rays from the lower layer's triangle centres)
// gives p = K delta / (h1 + h2) at every interior triangle, K from
// msk::foundation_modulus. Stage 2 with the matched foundation
// (cartilage::matched_foundation_stiffness, k_i = K / h_i: the surface
// stage's foundation_from_thickness) and augmented contact removes the
// penetration, and its springs in series carry the same p: deflections
// p / k1 and p / k2 within 1 % (the series test's tolerance) and the
// area-weighted mean multiplier within 3 % (the augmented test's tolerance:
// per-vertex pressures of non-matching meshes scatter around the mean).
// The penalty alone (no update) is 4 % low with k_c = 300 N/mm^3, so the
// check can fail. Both stages take E and nu as given; the same K is asserted
// to round-off. On curved, finite patches the stages differ by the shells'
// load spreading and by sampling (docs/contact.md, "Stage 2 against stage 1").
TEST(MeshContact, MatchedFoundationsCarryTheMusculoskeletalStagesPressure) {
  const double E = 10e6, nu = 0.45, h1 = 1e-3, h2 = 2e-3, d = 0.3e-3, s0 = 0.05e-3, overlap = d - s0;
  msk::ElasticFoundationParameters mat;
  mat.youngs_modulus = E;
  mat.poisson_ratio = nu;
  const double K = msk::foundation_modulus(mat);
  const Eigen::VectorXd k1v = matched_foundation_stiffness(Eigen::VectorXd::Constant(1, h1), E, nu, "h1");
  const Eigen::VectorXd k2v = matched_foundation_stiffness(Eigen::VectorXd::Constant(1, h2), E, nu, "h2");
  EXPECT_NEAR(k1v(0) * h1, K, 1e-12 * K);
  EXPECT_NEAR(k2v(0) * h2, K, 1e-12 * K);
  const double k1 = k1v(0), k2 = k2v(0), kc = 3e11;  // 300 N/mm^3, the lenhart2015 scenes' penalty
  const double p1 = K * overlap / (h1 + h2);

  const common::QuadMesh lower = shifted(testing::plate_mesh(14, 14, 20e-3, 20e-3), {-10e-3, -10e-3, 0});
  const common::QuadMesh upper =
      testing::flipped(shifted(testing::plate_mesh(11, 11, 14e-3, 14e-3, 0.1), {-7.3e-3, -6.9e-3, 0}), s0);
  // Stage 1: the lower layer casts (normal +z), the upper layer is the
  // target, placed where stage 2's upper bone ends (moved down by d).
  {
    msk::ContactSurface cast, target;
    cast.body = 0;
    cast.mesh = common::triangulate(lower);
    cast.thickness = Eigen::VectorXd::Constant(cast.mesh.num_triangles(), h1);
    target.body = 1;
    target.mesh = common::triangulate(upper);
    target.mesh.V.col(2).array() -= d;
    target.thickness = Eigen::VectorXd::Constant(target.mesh.num_triangles(), h2);
    const msk::ContactPair pair("layers", std::move(cast), std::move(target), mat);
    msk::ContactPairData data;
    msk::evaluate_contact(pair, msk::Pose::Identity(), msk::Pose::Identity(), data);
    int interior = 0;
    for (int i = 0; i < pair.casting().mesh.num_triangles(); ++i) {
      if (pair.casting_centres().row(i).head<2>().norm() > 3e-3) continue;
      EXPECT_NEAR(data.result.pressure(i), p1, 1e-9 * p1);
      ++interior;
    }
    ASSERT_GT(interior, 20);
  }
  // Stage 2: shells on the matched foundations, augmented contact.
  auto A = make_model(lower, 10e6, 0.5e-3), B = make_model(upper, 10e6, 0.5e-3);
  A->add_foundation_springs(Eigen::VectorXd::Constant(A->num_nodes(), k1), BoneMotion::fixed());
  B->add_foundation_springs(Eigen::VectorXd::Constant(B->num_nodes(), k2),
                            testing::translating_bone(Eigen::Vector3d(0, 0, -d)));
  fix_in_plane(*A);
  fix_in_plane(*B);
  CoupledShellSystem sys({A.get(), B.get()}, {"lower", "upper"});
  ContactOptions o;
  o.rim_vertices = true;
  o.stiffness_N_m3 = kc;
  sys.add_contact("lower-upper", 0, 1, o);
  Eigen::VectorXd q0(sys.num_dofs());
  q0 << A->reference_state(), B->reference_state();
  auto points = [&](int m, const Eigen::VectorXd& q) { return node_positions(sys, m, q); };
  for (int n = 0; n <= 2; ++n) {
    Eigen::VectorXd q = q0;
    solve_quasi_static(sys, 2, q);
    const auto lambda = sys.updated_contact_multipliers(0, q);
    double lam = 0, area = 0;
    for (const ContactPoint& c : sys.contact(0).detect(points(0, q), points(1, q), nullptr, nullptr, false)) {
      if (c.point.head<2>().norm() > 3e-3) continue;
      lam += c.area * lambda[c.side[0]](c.node[0]);
      area += c.area;
    }
    lam /= area;
    const double w1 = testing::mean_normal_deflection(sys.model(0), sys.segment(0, q), Eigen::Vector3d::Zero(),
                                                      Eigen::Vector3d::UnitZ(), 3e-3, Eigen::Vector3d::Zero(), -1.0);
    std::printf("updates %d: w1 %.6e m (stage 1: p1/k1 %.6e), mean multiplier %.6e Pa (stage 1: p1 %.6e)\n", n, w1,
                p1 / k1, lam, p1);
    if (n == 0) { EXPECT_GT(std::abs(w1 / (p1 / k1) - 1), 0.02); }  // the penalty alone is off
    if (n == 2) {
      EXPECT_NEAR(w1, p1 / k1, 0.01 * p1 / k1);
      EXPECT_NEAR(lam, p1, 0.03 * p1);
    }
    sys.set_contact_multipliers(0, lambda);
  }
}

// An augmented vertex contact at g = 0 over a crease: a plate's centre node
// rests 0.1 um above the crease line of a lower surface folded by +-10
// degrees, a valley (concave seen from the plate: the closest face changes
// at the line) and a ridge (convex: the closest point lies on the edge, whose
// normal (p - c)/|p - c| turns through the whole kink within a few gaps),
// with a multiplier of 20 MPa on every plate node, and the plate slides
// across the line in 2 um steps. The node's force (the multiplier's, not
// vanishing at g = 0) then turns by the fold. Measured with the blend
// switched off (kCreaseBlend = 0): the largest change in one step is 27.4 %
// (valley) and 34.7 % (ridge) of the node's force (the Newton stall of the
// real subject's augmented walk, docs/contact.md). With the blend
// (half-width 5 % of the smaller triangle height) 0.87 % and 0.95 % (2 %
// asserted). Tangent inside the band against central differences as in
// AugmentedTangentMatchesFiniteDifferences (measured 8.7e-9, 3.5e-9).
TEST(MeshContact, AugmentedContactTurnsContinuouslyAcrossACrease) {
  for (const double fold : {1.0, -1.0}) {  // valley (concave seen from the plate), ridge (convex)
  SCOPED_TRACE(fold > 0 ? "valley" : "ridge");
  const double slope = fold * std::tan(10.0 * M_PI / 180.0), kc = 3e11, lam = 2e7;
  common::QuadMesh lower = shifted(testing::plate_mesh(6, 6, 6e-3, 6e-3), {-3e-3, -3e-3, 0});
  for (int i = 0; i < lower.V.rows(); ++i) lower.V(i, 2) = slope * std::abs(lower.V(i, 0));
  // 0.1 um above the valley line (g > 0, in contact through the offset of
  // about 17 um), the sample points off the line by 0.37 um (no vertex
  // exactly on an edge of the other surface).
  const common::QuadMesh upper = testing::flipped(shifted(testing::plate_mesh(2, 2, 2e-3, 2e-3), {-1e-3, -1.1e-3, 0}), 0.1e-6);
  auto A = make_model(lower, 1e6, 0.3e-3), B = make_model(upper, 1e6, 0.3e-3);
  CoupledShellSystem sys({A.get(), B.get()}, {"valley", "plate"});
  ContactOptions o;
  o.rim_vertices = true;
  o.stiffness_N_m3 = kc;
  sys.add_contact("valley-plate", 0, 1, o);
  sys.set_contact_multipliers(0, {Eigen::VectorXd::Zero(A->num_nodes()), Eigen::VectorXd::Constant(B->num_nodes(), lam)});
  const int centre = 4;  // the plate's middle node
  Eigen::VectorXd q(sys.num_dofs());
  q << A->reference_state(), B->reference_state();
  const int ob = A->num_dofs();
  double worst = 0, fmax = 0, fx_first = 0, fx_last = 0;
  Eigen::Vector3d prev = Eigen::Vector3d::Zero();
  const int n = 100;
  for (int s = 0; s <= n; ++s) {
    const double dx = -100.37e-6 + 2e-6 * s;
    Eigen::VectorXd qs = q;
    for (int i = 0; i < B->num_nodes(); ++i) qs(ob + 6 * i) += dx;
    const ContactPairReport rep = sys.contact_report(0, qs);
    const Eigen::Vector3d f = rep.force_b.row(centre).transpose();
    if (s > 0) worst = std::max(worst, (f - prev).norm());
    fmax = std::max(fmax, f.norm());
    if (s == 0) fx_first = f.x();
    fx_last = f.x();
    prev = f;
  }
  std::printf("%s: centre node force %.4f N (max), x-force %.4f -> %.4f N, largest change per 2 um step %.3e N "
              "(%.3f %% of the force)\n", fold > 0 ? "valley" : "ridge", fmax, fx_first, fx_last, worst, 100 * worst / fmax);
  // The force turned from one face's normal to the other's (x-component sign change) ...
  EXPECT_LT(fx_first * fx_last, 0.0);
  // ... and continuously.
  EXPECT_LT(worst, 0.02 * fmax);
  // Tangent with the centre node inside the band (1 um from the valley line).
  Eigen::VectorXd qb = q;
  for (int i = 0; i < B->num_nodes(); ++i) qb(ob + 6 * i) += 1.37e-6;
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(sys.num_dofs());
  const double err = system_fd_error(sys, qb, zero, 0);
  std::printf("%s: tangent relative error %.2e\n", fold > 0 ? "valley" : "ridge", err);
  EXPECT_LT(err, 1e-5);
  }
}

// With multipliers set (nonzero offsets, some contacts at positive gaps),
// the tangent still matches central differences (tolerance as in
// NewtonTangentMatchesFiniteDifferences); zero multipliers give exactly
// the penalty's forces.
TEST(MeshContact, AugmentedTangentMatchesFiniteDifferences) {
  const common::QuadMesh plate = shifted(testing::plate_mesh(5, 5, 6e-3, 6e-3, 0.15), {-3e-3, -3e-3, 0});
  const common::QuadMesh cap = testing::flipped(testing::spherical_patch(6, 5e-3, 6e-3), -0.3e-3);
  auto A = make_model(plate, 1e6, 0.3e-3), B = make_model(cap, 1e6, 0.3e-3);
  CoupledShellSystem sys({A.get(), B.get()}, {"plate", "cap"});
  ContactOptions o;
  o.rim_vertices = true;
  o.stiffness_N_m3 = 5e10;
  sys.add_contact("plate-cap", 0, 1, o);
  Eigen::VectorXd q(sys.num_dofs());
  q.head(A->num_dofs()) = A->reference_state();
  q.tail(B->num_dofs()) = B->reference_state();
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(sys.num_dofs());
  const ContactPairReport before = sys.contact_report(0, q);
  sys.set_contact_multipliers(0, {Eigen::VectorXd::Zero(A->num_nodes()), Eigen::VectorXd::Zero(B->num_nodes())});
  const ContactPairReport zeros = sys.contact_report(0, q);
  EXPECT_EQ(before.force_a, zeros.force_a);
  EXPECT_EQ(before.force_b, zeros.force_b);
  // Multipliers of 1.5 x the penalty pressures: offsets beyond the current
  // penetration, so contacts at positive gaps too.
  auto lambda = sys.updated_contact_multipliers(0, q);
  for (auto& l : lambda) l *= 1.5;
  sys.set_contact_multipliers(0, lambda);
  const ContactPairReport rep = sys.contact_report(0, q);
  std::printf("augmented: %ld vertex contacts (penalty %ld), force %.4f N (penalty %.4f N)\n", rep.counts.vertex_face,
              before.counts.vertex_face, rep.total_force_a.z(), before.total_force_a.z());
  EXPECT_GT(std::abs(rep.total_force_a.z()), 1.2 * std::abs(before.total_force_a.z()));
  const double e = system_fd_error(sys, q, zero, 0);
  std::printf("  augmented tangent relative error %.2e\n", e);
  EXPECT_LT(e, 1e-5);
  EXPECT_THROW(sys.set_contact_multipliers(0, {Eigen::VectorXd::Zero(3), Eigen::VectorXd()}), common::InputError);
}

// Same contact, one and two threads: bit-identical contact forces.
TEST(MeshContact, DeterministicAcrossThreadCounts) {
  const common::QuadMesh plate = shifted(testing::plate_mesh(30, 30, 12e-3, 12e-3, 0.2), {-6e-3, -6e-3, 0});
  const common::QuadMesh cap = testing::flipped(testing::spherical_patch(30, 10e-3, 10e-3), -0.2e-3);
  ContactOptions o;
  o.rim_vertices = true;  // rim nodes may be penetrating vertices in this set-up
  MeshContact mc("c", ContactSurface(plate), ContactSurface(cap), o);
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto r1 = mc.detect(plate.V, cap.V, nullptr, nullptr, true);
  omp_set_num_threads(2);
  const auto r2 = mc.detect(plate.V, cap.V, nullptr, nullptr, true);
  omp_set_num_threads(saved);
  ASSERT_EQ(r1.size(), r2.size());
  ASSERT_GT(r1.size(), 100u);
  for (size_t k = 0; k < r1.size(); ++k) {
    EXPECT_EQ(r1[k].node, r2[k].node);
    EXPECT_EQ(r1[k].gap, r2[k].gap);
    EXPECT_EQ(r1[k].G, r2[k].G);
    EXPECT_EQ(r1[k].H, r2[k].H);
  }
}

// A small plate pushed 0.1 mm into a larger one: every one of its nodes
// penetrates. With rim_vertices its 16 rim nodes are
// penetrating vertices too; without, rim nodes of both plates only carry
// their triangles: no active contact has a rim vertex, the small plate's 9
// interior nodes still do, the large plate's vertices still meet the small
// plate's rim triangles, and the tangent stays consistent (FD, tolerance as
// in NewtonTangentMatchesFiniteDifferences).
TEST(MeshContact, RimNodesCanBeExcludedAsPenetratingVertices) {
  const common::QuadMesh big = shifted(testing::plate_mesh(6, 6, 6e-3, 6e-3, 0.1), {-3e-3, -3e-3, 0});
  const common::QuadMesh small =
      shifted(testing::flipped(testing::plate_mesh(4, 4, 3e-3, 3e-3), -0.1e-3), {-1.5e-3, -1.5e-3, 0});
  int rim_vertex[2] = {0, 0}, small_vertices[2] = {0, 0};
  for (int excluded = 0; excluded < 2; ++excluded) {
    auto A = make_model(big, 1e6, 0.3e-3), B = make_model(small, 1e6, 0.3e-3);
    B->add_periphery_fixed();
    CoupledShellSystem sys({A.get(), B.get()}, {"big", "small"});
    ContactOptions o;
    o.stiffness_N_m3 = 5e10;
    o.rim_vertices = excluded == 0;
    sys.add_contact("big-small", 0, 1, o);
    Eigen::VectorXd q(sys.num_dofs());
    q << A->reference_state(), B->reference_state();
    const auto active = sys.contact(0).detect(big.V, small.V, nullptr, nullptr, false);
    int rim_faces = 0;
    for (const ContactPoint& c : active) {
      const ContactSurface& sv = sys.contact(0).surface(c.side[0]);
      if (sv.boundary_vertex[c.node[0]]) ++rim_vertex[excluded];
      if (c.side[0] == 1) {
        ++small_vertices[excluded];
      } else {
        for (int k = 1; k < 4; ++k)
          if (c.kind == ContactKind::kVertexFace && B->constrained()[6 * c.node[k]]) {
            ++rim_faces;
            break;
          }
      }
    }
    std::printf("rim_vertices %d: %zu contacts, %d with the small plate's vertex, %d with a rim vertex, "
                "%d big-plate vertices on rim triangles\n",
                excluded == 0, active.size(), small_vertices[excluded], rim_vertex[excluded], rim_faces);
    EXPECT_GT(rim_faces, 0);
    const double e = system_fd_error(sys, q, Eigen::VectorXd::Zero(sys.num_dofs()), 0);
    std::printf("  tangent relative error %.2e\n", e);
    EXPECT_LT(e, 1e-5);
  }
  EXPECT_EQ(rim_vertex[0], 16);  // the 4 x 4 plate's 16 rim nodes (the large plate's rim is outside)
  EXPECT_EQ(rim_vertex[1], 0);
  EXPECT_EQ(small_vertices[1], small_vertices[0] - 16);  // the 9 interior nodes remain
}

// Faded vertex weights (ContactOptions::faded_vertex_weights) against an
// independent quadrature of their definition, the integral of s(r) N_i over
// each triangle (s the rim fade, r the interpolation of 0 on rim nodes and 1
// elsewhere, N_i the linear shape function): the midpoint rule on 160^2
// sub-triangles per triangle, whose error for these smooth cubics is of
// order (1/160)^2 ~ 4e-5 of a triangle's area, so 2e-4 of it is asked. The
// plate is skewed so that its triangles differ. Interior nodes away from
// the rim keep their tributary area; rim nodes get a weight (they support
// the rim) but less than theirs; the total is the faded area.
TEST(MeshContact, FadedVertexWeightsAreTheFadeIntegrals) {
  common::QuadMesh plate = testing::plate_mesh(5, 4, 5e-3, 4e-3);
  for (int i = 0; i < plate.V.rows(); ++i) plate.V(i, 0) += 0.3 * plate.V(i, 1) + 1e-4 * std::sin(7.0 * i);
  const ContactSurface s(plate);
  const Eigen::VectorXd w = faded_vertex_weights(s);
  Eigen::VectorXd ref = Eigen::VectorXd::Zero(s.num_nodes);
  const int n = 160;
  for (int t = 0; t < s.F.rows(); ++t) {
    const double A = s.triangle_area(t);
    double rho[3];
    for (int k = 0; k < 3; ++k) rho[k] = s.boundary_vertex[s.F(t, k)] ? 0.0 : 1.0;
    // Sub-triangles of the barycentric grid: centroids of the n^2 cells.
    for (int a = 0; a < n; ++a)
      for (int b = 0; a + b < n; ++b)
        for (int up = 0; up < 2; ++up) {
          if (up == 1 && a + b + 1 >= n) continue;
          const double l0 = (a + (up ? 2.0 : 1.0) / 3) / n, l1 = (b + (up ? 2.0 : 1.0) / 3) / n;
          const double lam[3] = {l0, l1, 1 - l0 - l1};
          const double r = lam[0] * rho[0] + lam[1] * rho[1] + lam[2] * rho[2];
          const double fade = r * r * (3 - 2 * r);
          for (int k = 0; k < 3; ++k) ref(s.F(t, k)) += fade * lam[k] * A / (double(n) * n);
        }
  }
  double max_tri = s.triangle_area.maxCoeff(), faded_area = 0;
  for (int i = 0; i < s.num_nodes; ++i) EXPECT_NEAR(w(i), ref(i), 2e-4 * max_tri) << "node " << i;
  for (int i = 0; i < s.num_nodes; ++i) {
    faded_area += ref(i);
    bool next_to_rim = s.boundary_vertex[i];
    for (int t : s.vertex_triangles[i])
      for (int k = 0; k < 3; ++k) next_to_rim = next_to_rim || s.boundary_vertex[s.F(t, k)];
    if (!next_to_rim) { EXPECT_NEAR(w(i), s.vertex_area(i), 1e-12 * max_tri) << "interior node " << i; }
    if (s.boundary_vertex[i]) { EXPECT_LT(w(i), s.vertex_area(i)) << "rim node " << i; }
  }
  // Every rim node but the corners has a rim-row triangle with an interior node.
  int supported_rim = 0;
  for (int i = 0; i < s.num_nodes; ++i) supported_rim += s.boundary_vertex[i] && w(i) > 0;
  EXPECT_GE(supported_rim, 2 * (5 + 4) - 4);
  EXPECT_NEAR(w.sum(), faded_area, 2e-4 * max_tri);
  EXPECT_LT(w.sum(), s.vertex_area.sum());
}

TEST(MeshContact, RejectsBadOptions) {
  const common::QuadMesh plate = testing::plate_mesh(2, 2, 1e-3, 1e-3);
  ContactOptions o;
  o.rim_max_depth_m = 0;  // rim contacts cut off at max_depth_m
  o.stiffness_N_m3 = -1;
  EXPECT_THROW(MeshContact("c", ContactSurface(plate), ContactSurface(plate), o), common::InputError);
  o = ContactOptions();
  o.max_depth_m = 0;
  EXPECT_THROW(MeshContact("c", ContactSurface(plate), ContactSurface(plate), o), common::InputError);
  o = ContactOptions();
  o.damping_N_s_m3 = std::nan("");
  EXPECT_THROW(MeshContact("c", ContactSurface(plate), ContactSurface(plate), o), common::InputError);
  o = ContactOptions();
  o.faded_vertex_weights = true;  // the weights are those of fade_inside's fade
  o.rim = RimTreatment::kRimContacts;
  EXPECT_THROW(MeshContact("c", ContactSurface(plate), ContactSurface(plate), o), common::InputError);
}

}  // namespace
}  // namespace arthrosim::cartilage
