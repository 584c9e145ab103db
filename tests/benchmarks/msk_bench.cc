// Musculoskeletal model timings (issue 3):
//  - one full evaluation (kinematics, 76 ligament bundles, 13 muscles, the
//    three contact pairs) and one with dQ/dq over the 12 knee coordinates, on
//    the bundled medium model (data/models/knee_parametric/knee.urdf);
//  - contact of the tibiofemoral (medial + lateral) and patellofemoral pairs
//    on a fine parametric knee generated here (edge 0.74 mm: ~30,000 femoral
//    cartilage triangles; tibial cartilage at 0.57 mm: ~8,600 triangles, the
//    counts of lenhart2015's MR-derived meshes; patella at 0.74 mm; the
//    printed counters give the actual numbers):
//    cold (no cached guesses), warm at a fixed pose, and warm while the tibia
//    and patella move by 1 um per call (the finite-difference pattern);
//  - the full evaluation and the one with dQ/dq on the medium model with its
//    cartilage replaced by that fine knee's (use_contact_meshes).
// Run: build/bench/msk_bench
#include <benchmark/benchmark.h>

#include <map>
#include <memory>

#include "musculoskeletal/contact.h"
#include "musculoskeletal/model_io.h"
#include "pipelines/knee_generator.h"

namespace msk = arthrosim::musculoskeletal;
namespace pl = arthrosim::pipelines;

namespace {

const msk::Model& medium_model() {
  static const msk::Model m =
      msk::load_model(std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/knee.urdf");
  return m;
}

Eigen::VectorXd loaded_pose(const msk::Model& m) {
  // 30 deg of flexion with the patella following; light contact everywhere.
  Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_coordinates());
  q[m.tree.coordinate_index("knee_flexion")] = 0.5236;
  q[m.tree.coordinate_index("pf_flexion")] = 0.33;
  return q;
}

// One full force evaluation (all forces, TF and PF contact) at the loaded pose.
void run_evaluate(benchmark::State& state, const msk::Model& m) {
  auto d = msk::make_data(m);
  const Eigen::VectorXd q = loaded_pose(m);
  const Eigen::VectorXd a = Eigen::VectorXd::Constant(m.muscles.size(), 0.02);
  msk::evaluate_forces(m, d, q, {}, a);
  for (auto _ : state) {
    msk::evaluate_forces(m, d, q, {}, a);
    benchmark::DoNotOptimize(d.Q.data());
  }
  int n = 0;
  for (const auto& c : d.contacts) n += c.result.num_contacting;
  state.counters["contacting_triangles"] = n;
}

// One evaluation of dQ/dq over the free coordinates at the loaded pose.
void run_jacobian(benchmark::State& state, const msk::Model& m) {
  auto d = msk::make_data(m);
  const Eigen::VectorXd q = loaded_pose(m);
  const Eigen::VectorXd a = Eigen::VectorXd::Constant(m.muscles.size(), 0.02);
  msk::evaluate_forces(m, d, q, {}, a);
  for (auto _ : state) {
    msk::evaluate_jacobian(m, d, q, {}, a, {}, m.free_coordinates);
    benchmark::DoNotOptimize(d.dQ_dq.data());
  }
}

void BM_ModelEvaluate_Medium(benchmark::State& state) { run_evaluate(state, medium_model()); }
BENCHMARK(BM_ModelEvaluate_Medium)->Unit(benchmark::kMillisecond);

void BM_ModelJacobian_Medium(benchmark::State& state) { run_jacobian(state, medium_model()); }
BENCHMARK(BM_ModelJacobian_Medium)->Unit(benchmark::kMillisecond);

struct FinePairs {
  std::vector<msk::ContactPair> pairs;
  int femur_triangles = 0, tibia_triangles = 0, patella_triangles = 0;
};

msk::ContactSurface surface(const pl::KneeCartilagePatch& p, int body) {
  msk::ContactSurface s;
  s.body = body;
  s.mesh = p.mesh;
  s.thickness.resize(p.mesh.num_triangles());
  for (int i = 0; i < p.mesh.num_triangles(); ++i)
    s.thickness[i] = (p.thickness[p.mesh.F(i, 0)] + p.thickness[p.mesh.F(i, 1)] +
                      p.thickness[p.mesh.F(i, 2)]) / 3.0;
  return s;
}

const FinePairs& fine_pairs() {
  static const FinePairs fp = [] {
    pl::ParametricKnee knee;
    const auto g = knee.generate(pl::fine_knee_options());
    FinePairs f;
    const auto& fem = g.patch(pl::KneeCartilage::kFemur);
    msk::ElasticFoundationParameters mat;  // 10 MPa, 0.45, linear (lenhart2015)
    // Bodies: 0 femur, 1 tibia, 2 patella.
    f.pairs.emplace_back("tf_medial", surface(g.patch(pl::KneeCartilage::kTibiaMedial), 1),
                         surface(fem, 0), mat);
    f.pairs.emplace_back("tf_lateral", surface(g.patch(pl::KneeCartilage::kTibiaLateral), 1),
                         surface(fem, 0), mat);
    f.pairs.emplace_back("pf", surface(g.patch(pl::KneeCartilage::kPatella), 2), surface(fem, 0), mat);
    f.femur_triangles = fem.mesh.num_triangles();
    f.tibia_triangles = g.patch(pl::KneeCartilage::kTibiaMedial).mesh.num_triangles() +
                        g.patch(pl::KneeCartilage::kTibiaLateral).mesh.num_triangles();
    f.patella_triangles = g.patch(pl::KneeCartilage::kPatella).mesh.num_triangles();
    return f;
  }();
  return fp;
}

// The medium model with the fine generated cartilage (same generator, same
// frame as its own meshes).
const msk::Model& fine_model() {
  static msk::Model m = [] {
    msk::Model x =
        msk::load_model(std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/knee.urdf");
    const auto g = pl::ParametricKnee().generate(pl::fine_knee_options());
    std::map<std::string, msk::SurfaceMesh> by_file;
    for (const auto& p : g.cartilage)
      by_file[pl::cartilage_file_stem(p.which) + ".stl"] = {p.mesh, p.thickness};
    msk::use_contact_meshes(x, by_file, "fine generated knee");
    return x;
  }();
  return m;
}

void BM_ModelEvaluate_Fine(benchmark::State& state) { run_evaluate(state, fine_model()); }
BENCHMARK(BM_ModelEvaluate_Fine)->Unit(benchmark::kMillisecond);

void BM_ModelJacobian_Fine(benchmark::State& state) { run_jacobian(state, fine_model()); }
BENCHMARK(BM_ModelJacobian_Fine)->Unit(benchmark::kMillisecond);

// mode 0: cold (caches reset every call); 1: warm, fixed pose; 2: warm, moving 1 um per call.
void BM_ContactBothPairs_Fine(benchmark::State& state) {
  const auto& f = fine_pairs();
  const int mode = static_cast<int>(state.range(0));
  std::vector<msk::ContactPairData> data(f.pairs.size());
  msk::Pose X_WF = msk::Pose::Identity(), X_WT = msk::Pose::Identity(), X_WP = msk::Pose::Identity();
  X_WT.translation().y() = 0.3e-3;  // tibia 0.3 mm into the femur (on top of the designed 0.25 mm)
  X_WP.translation().x() = -0.3e-3;
  auto run = [&] {
    msk::evaluate_contact(f.pairs[0], X_WT, X_WF, data[0]);
    msk::evaluate_contact(f.pairs[1], X_WT, X_WF, data[1]);
    msk::evaluate_contact(f.pairs[2], X_WP, X_WF, data[2]);
  };
  run();
  long it = 0;
  for (auto _ : state) {
    if (mode == 0)
      for (auto& d : data) d.reset();
    if (mode == 2) {
      const double s = (it++ % 2 ? 1e-6 : -1e-6);
      X_WT.translation().x() += s;
      X_WP.translation().y() += s;
    }
    run();
    benchmark::DoNotOptimize(data[0].result.force_on_target_W.data());
  }
  state.counters["femur_tris"] = f.femur_triangles;
  state.counters["tibia_tris"] = f.tibia_triangles;
  state.counters["patella_tris"] = f.patella_triangles;
  int n = 0, q = 0;
  for (const auto& d : data) n += d.result.num_contacting, q += d.stats.tree_queries;
  state.counters["contacting"] = n;
  state.counters["tree_queries_last"] = q;
  state.counters["TF_force_N"] =
      (data[0].result.force_on_target_W + data[1].result.force_on_target_W).norm();
  state.counters["PF_force_N"] = data[2].result.force_on_target_W.norm();
}
BENCHMARK(BM_ContactBothPairs_Fine)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
