// Path evaluation cost per wrap type (musculoskeletal/path.h, wrap.h): one
// evaluate_path call (length, contact points, force applications) of a
// femur-to-tibia path over a wrap surface fixed on the femur, at knee
// flexion angles sweeping 0.05..0.35 rad over 256 precomputed poses (each call
// at a new pose, as in COMAK's Ipopt and finite-difference evaluations; no
// state is kept between calls). Counters: fraction of calls wrapped and mean
// Newton iterations (ellipsoid: coarse N = 8 and fine 2N = 16 chords).
// Run: build/bench/wrap_bench [--benchmark_repetitions=5 --benchmark_report_aggregates_only=true]
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "musculoskeletal/kinematics.h"
#include "musculoskeletal/path.h"

namespace msk = arthrosim::musculoskeletal;
using msk::Vec3;

namespace {

struct Scene {
  msk::KinematicTree tree;
  std::vector<std::vector<msk::Pose>> poses;
  std::vector<Eigen::VectorXd> qs;
};

// Femur root; tibia on a revolute joint about z at the origin.
const Scene& scene() {
  static const Scene s = [] {
    Scene sc;
    sc.tree.add_root("femur", 0.0);
    msk::Joint j;
    j.name = "knee";
    j.type = msk::JointType::kRevolute;
    j.parent = 0;
    j.axis_J = Vec3::UnitZ();
    sc.tree.add_body("tibia", 0.0, j);
    for (int i = 0; i < 256; ++i) {
      Eigen::VectorXd q(1);
      q[0] = 0.05 + 0.3 * i / 255.0;
      msk::KinematicsData d;
      msk::forward_kinematics(sc.tree, q, d);
      sc.poses.push_back(d.X_WB);
      sc.qs.push_back(q);
    }
    return sc;
  }();
  return s;
}

msk::Path base_path() {
  msk::Path p;
  p.points = {{0, Vec3(0.004, 0.15, 0.003)}, {1, Vec3(0.002, -0.15, -0.004)}};
  return p;
}

msk::PathWrap on_femur(msk::WrapSurface s, const Vec3& origin, const Eigen::Matrix3d& R = Eigen::Matrix3d::Identity()) {
  s.body = 0;
  s.X_BS.linear() = R;
  s.X_BS.translation() = origin;
  return msk::PathWrap{s};
}

void run(benchmark::State& state, const msk::Path& path) {
  const Scene& sc = scene();
  size_t i = 0;
  int wrapped = 0, calls = 0;
  for (auto _ : state) {
    const msk::PathState st = msk::evaluate_path(path, sc.poses[i], sc.qs[i]);
    benchmark::DoNotOptimize(st.length);
    wrapped += st.wrapped;
    ++calls;
    i = (i + 1) % sc.poses.size();
  }
  state.counters["wrapped_fraction"] = calls ? double(wrapped) / calls : 0.0;
}

void BM_Straight(benchmark::State& state) { run(state, base_path()); }

void BM_Cylinder(benchmark::State& state) {
  msk::Path p = base_path();
  msk::WrapSurface c;
  c.name = "cyl";
  c.radius = 0.025;
  p.wraps = {on_femur(c, Vec3(0.012, 0.0, 0.0))};
  run(state, p);
}

void BM_CylinderQuadrantFinite(benchmark::State& state) {
  msk::Path p = base_path();
  msk::WrapSurface c;
  c.name = "cyl";
  c.radius = 0.025;
  c.length = 0.18;
  c.quadrant = msk::WrapQuadrant::kNegX;
  p.wraps = {on_femur(c, Vec3(0.012, 0.0, 0.0))};
  run(state, p);
}

void BM_Sphere(benchmark::State& state) {
  msk::Path p = base_path();
  msk::WrapSurface s;
  s.name = "sph";
  s.shape = msk::WrapShape::kSphere;
  s.radius = 0.025;
  p.wraps = {on_femur(s, Vec3(0.012, 0.0, 0.0))};
  run(state, p);
}

// lenhart2015's Gastroc_at_Condyles_r semi-axes, long axis along the knee axis.
void BM_Ellipsoid(benchmark::State& state) {
  msk::Path p = base_path();
  msk::WrapSurface e;
  e.name = "gastroc";
  e.shape = msk::WrapShape::kEllipsoid;
  e.semi_axes = Vec3(0.0277566, 0.0231305, 0.138783);
  e.ellipsoid_chords = static_cast<int>(state.range(0));
  p.wraps = {on_femur(e, Vec3(0.012, 0.0, 0.0),
                      Eigen::AngleAxisd(0.3, Vec3(1, 1, 0).normalized()).toRotationMatrix())};
  run(state, p);
}

void BM_Torus(benchmark::State& state) {
  msk::Path p = base_path();
  msk::WrapSurface t;
  t.name = "ring";
  t.shape = msk::WrapShape::kTorus;
  t.radius = 0.012;
  t.ring_radius = 0.032;
  // Axis along y (the path), 0.1 m from the femur point: the path crosses
  // the torus plane 3..10 mm inside the tube (inner equator 0.02 m).
  Eigen::Matrix3d R;
  R.col(0) = Vec3::UnitX();
  R.col(1) = -Vec3::UnitZ();
  R.col(2) = Vec3::UnitY();
  p.wraps = {on_femur(t, Vec3(0.035, 0.1, 0.0), R)};
  run(state, p);
}

// Two wraps on one segment (a sphere then a cylinder): Gauss-Seidel refinement.
void BM_SphereThenCylinder(benchmark::State& state) {
  msk::Path p = base_path();
  msk::WrapSurface s;
  s.name = "sph";
  s.shape = msk::WrapShape::kSphere;
  s.radius = 0.02;
  msk::WrapSurface c;
  c.name = "cyl";
  c.radius = 0.02;
  p.wraps = {on_femur(s, Vec3(0.015, 0.06, 0.0)), on_femur(c, Vec3(0.012, -0.04, 0.0))};
  run(state, p);
}

}  // namespace

BENCHMARK(BM_Straight);
BENCHMARK(BM_Cylinder);
BENCHMARK(BM_CylinderQuadrantFinite);
BENCHMARK(BM_Sphere);
BENCHMARK(BM_Ellipsoid)->Arg(8)->Arg(4)->Arg(16);
BENCHMARK(BM_Torus);
BENCHMARK(BM_SphereThenCylinder);

BENCHMARK_MAIN();
