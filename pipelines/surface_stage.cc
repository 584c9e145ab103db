#include "pipelines/surface_stage.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>

#include "cartilage/coupled_system.h"
#include "numerics/hht_integrator.h"
#include "cartilage/surface_model.h"
#include "common/effects.h"
#include "common/error.h"
#include "common/file_check.h"
#include "common/finite.h"
#include "common/hdf5.h"
#include "common/log.h"
#include "common/metadata.h"
#include "common/output_file.h"
#include "common/progress.h"
#include "common/scene.h"
#include "common/xdmf.h"
#include "pipelines/stages.h"

namespace arthrosim::pipelines {
namespace {

using numerics::HhtIntegrator;
using cartilage::ShellModel;
using common::H5File;

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// Reads one cartilage surface of the prepared model (docs/prepared_model.md).
cartilage::SurfaceInput read_prepared_surface(const H5File& f, const std::string& name) {
  const std::string g = "/surfaces/" + name + "/quads/";
  cartilage::SurfaceInput s;
  s.name = name;
  s.mesh.name = name;
  s.mesh.V = f.read_matrix(g + "nodes", 3);
  const Eigen::MatrixXi Q = f.read_matrix_int(g + "quads", 4);
  s.mesh.Q = Q;
  s.normals = f.read_matrix(g + "normals", 3);
  const Eigen::VectorXi P = f.read_vector_int(g + "periphery");
  s.periphery.assign(P.data(), P.data() + P.size());
  const int N = static_cast<int>(s.mesh.V.rows());
  if (s.normals.rows() != N)
    throw common::InputError(f.path() + ": error: dataset " + g + "normals: expected " + std::to_string(N) +
                             " rows (one per node), found " + std::to_string(s.normals.rows()));
  if (Q.size() > 0 && (Q.minCoeff() < 0 || Q.maxCoeff() >= N))
    throw common::InputError(f.path() + ": error: dataset " + g + "quads: node index out of range [0, " +
                             std::to_string(N) + ")");
  if (!s.mesh.V.allFinite() || !s.normals.allFinite())
    throw common::InputError(f.path() + ": error: dataset " + g + "nodes or " + g + "normals holds NaN/Inf");
  return s;
}

/// Quad OBJ reader for the generic case: 'v x y z' (millimetres) and 4-node
/// 'f' lines (index forms i, i/j, i/j/k, i//k; negative = relative); comments,
/// vn/vt/vp/g/o/s/usemtl/mtllib/l lines are skipped. Anything else, or a face
/// that is not a quad, is an InputError with file:line.
common::QuadMesh read_quad_obj(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw common::InputError(path + ": error: cannot open the mesh file");
  std::vector<Eigen::Vector3d> V;
  std::vector<Eigen::Vector4i> Q;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream ls(line);
    std::string kw;
    if (!(ls >> kw)) continue;
    if (kw == "v") {
      Eigen::Vector3d p;
      if (!(ls >> p.x() >> p.y() >> p.z()) || !p.allFinite())
        throw common::InputError(path, line_no, "expected 'v x y z' with three finite numbers");
      V.push_back(p * 1e-3);
    } else if (kw == "f") {
      std::vector<int> idx;
      std::string tok;
      while (ls >> tok) {
        const std::string head = tok.substr(0, tok.find('/'));
        std::size_t used = 0;
        int k = 0;
        try {
          k = std::stoi(head, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used != head.size() || head.empty() || k == 0)
          throw common::InputError(path, line_no, "expected a vertex index, found '" + tok + "'");
        const int i = k > 0 ? k - 1 : static_cast<int>(V.size()) + k;
        if (i < 0 || i >= static_cast<int>(V.size()))
          throw common::InputError(path, line_no,
                                   "vertex index " + head + " out of range (" + std::to_string(V.size()) +
                                       " vertices so far)");
        idx.push_back(i);
      }
      if (idx.size() != 4)
        throw common::InputError(path, line_no,
                                 "expected a quad (4 vertices), found a face with " + std::to_string(idx.size()));
      Q.emplace_back(idx[0], idx[1], idx[2], idx[3]);
    } else if (kw == "vn" || kw == "vt" || kw == "vp" || kw == "g" || kw == "o" || kw == "s" || kw == "usemtl" ||
               kw == "mtllib" || kw == "l") {
      continue;
    } else {
      throw common::InputError(path, line_no, "unknown OBJ keyword '" + kw + "'");
    }
  }
  if (Q.empty()) throw common::InputError(path + ": error: no quad faces");
  common::QuadMesh m;
  m.V.resize(static_cast<Eigen::Index>(V.size()), 3);
  for (size_t i = 0; i < V.size(); ++i) m.V.row(static_cast<Eigen::Index>(i)) = V[i].transpose();
  m.Q.resize(static_cast<Eigen::Index>(Q.size()), 4);
  for (size_t i = 0; i < Q.size(); ++i) m.Q.row(static_cast<Eigen::Index>(i)) = Q[i].transpose();
  return m;
}

/// Legacy VTK ASCII polydata quad reader for the generic case: POINTS
/// (coordinates in mm) and POLYGONS whose cells all have 4 nodes; header
/// lines, other sections (VERTICES, LINES, POINT_DATA, CELL_DATA, ...) end
/// the geometry part and are ignored. Errors name file:line.
common::QuadMesh read_quad_vtk(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw common::InputError(path + ": error: cannot open the mesh file");
  // Tokens with their line numbers.
  std::vector<std::pair<std::string, int>> tok;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (line_no <= 2) continue;  // "# vtk DataFile Version x" and the title
    std::istringstream ls(line);
    std::string w;
    while (ls >> w) tok.emplace_back(w, line_no);
  }
  size_t k = 0;
  auto next = [&](const char* what) -> const std::pair<std::string, int>& {
    if (k >= tok.size()) throw common::InputError(path, line_no, std::string("unexpected end of file, expected ") + what);
    return tok[k++];
  };
  auto number = [&](const char* what) {
    const auto& t = next(what);
    try {
      size_t used = 0;
      const double x = std::stod(t.first, &used);
      if (used == t.first.size() && std::isfinite(x)) return x;
    } catch (const std::exception&) {
    }
    throw common::InputError(path, t.second, std::string("expected ") + what + ", found '" + t.first + "'");
  };
  common::QuadMesh m;
  bool have_points = false, have_polys = false;
  while (k < tok.size()) {
    const auto& t = next("a keyword");
    if (t.first == "ASCII" || t.first == "DATASET" || t.first == "POLYDATA") continue;
    if (t.first == "BINARY") throw common::InputError(path, t.second, "expected ASCII, found BINARY");
    if (t.first == "POINTS") {
      const int n = static_cast<int>(number("the number of points"));
      next("the point type");
      m.V.resize(n, 3);
      for (int i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) m.V(i, c) = number("a coordinate") * 1e-3;
      have_points = true;
    } else if (t.first == "POLYGONS") {
      const int n = static_cast<int>(number("the number of polygons"));
      number("the list size");
      m.Q.resize(n, 4);
      for (int i = 0; i < n; ++i) {
        const int line_of_cell = k < tok.size() ? tok[k].second : line_no;
        const int nv = static_cast<int>(number("a polygon size"));
        if (nv != 4)
          throw common::InputError(path, line_of_cell, "expected a quad (4 nodes), found a polygon with " + std::to_string(nv));
        for (int c = 0; c < 4; ++c) {
          const double x = number("a node index");
          if (x < 0 || x >= static_cast<double>(m.V.rows()) || x != std::floor(x))
            throw common::InputError(path, line_of_cell, "node index " + std::to_string(x) + " out of range [0, " +
                                                             std::to_string(m.V.rows()) + ")");
          m.Q(i, c) = static_cast<int>(x);
        }
      }
      have_polys = true;
    } else {
      break;  // VERTICES, LINES, POINT_DATA, ...: not geometry of the shell
    }
  }
  if (!have_points || !have_polys || m.Q.rows() == 0)
    throw common::InputError(path + ": error: expected POINTS and a non-empty POLYGONS section of quads");
  return m;
}

/// Nodes inside the box [xmin, ymin, zmin, xmax, ymax, zmax] (SI), sorted.
std::vector<int> nodes_in_box(const common::QuadMesh& m, const std::vector<double>& box) {
  std::vector<int> out;
  for (int i = 0; i < m.num_nodes(); ++i) {
    bool in = true;
    for (int k = 0; k < 3; ++k) in = in && m.V(i, k) >= box[k] && m.V(i, k) <= box[k + 3];
    if (in) out.push_back(i);
  }
  return out;
}

struct SurfaceRun {
  cartilage::SurfaceInput input;
  std::unique_ptr<ShellModel> model;
  cartilage::BoneMotion bone = cartilage::BoneMotion::fixed();
  std::string bone_name;  // "" for generic meshes
  Eigen::Isometry3d X_WB0 = Eigen::Isometry3d::Identity();  // bone pose at t = 0
  cartilage::NodeBasis basis;
  std::vector<H5File::Appender> frame_out;  // displacement, deflection, E, e1, e1_dir, e2 [, contact_pressure]
  SurfaceSummary summary;
};

/// Seating ramp in front of imposed kinematics: for t < T the bone sits at
/// its first pose moved by -(1 - S(t/T)) offset_B (bone frame), S the
/// smoothstep 3 s^2 - 2 s^3 (zero velocity at both ends: no impulsive start
/// of the shells); afterwards it follows `base` delayed by T. A bone without
/// offset is only delayed.
cartilage::BoneMotion seated(const cartilage::BoneMotion& base, double T, const Eigen::Vector3d& offset_B) {
  if (!(T > 0)) return base;
  cartilage::BoneMotion m;
  m.at_rest = false;
  const Eigen::Isometry3d X0 = base.pose(0.0);
  m.pose = [base, T, offset_B, X0](double t) {
    if (t >= T) return base.pose(t - T);
    const double s = std::max(t, 0.0) / T;
    Eigen::Isometry3d X = X0;
    X.translation() += X0.linear() * (-(1 - s * s * (3 - 2 * s)) * offset_B);
    return X;
  };
  m.spatial_velocity = [base, T, offset_B, X0](double t) {
    if (t >= T) return base.spatial_velocity(t - T);
    const double s = std::max(t, 0.0) / T;
    Eigen::Matrix<double, 6, 1> V = Eigen::Matrix<double, 6, 1>::Zero();
    V.tail<3>() = X0.linear() * offset_B * (6 * s * (1 - s) / T);
    return V;
  };
  return m;
}

}  // namespace

void SurfaceScenarioOptions::declare_shared(common::OptionVisitor& v) {
  using common::Unit;
  v.text_list("surfaces", surfaces, "", "cartilage surfaces of the prepared model simulated as shells");
  v.number("end_time_s", end_time_s, Unit::kSecond, {0, 1e4},
           "simulated time; may be left out only by a scenario with imposed_kinematics, which then runs for the "
           "kinematics file's duration");
  v.number("output_interval_ms", output_interval_s, Unit::kMillisecond, {0, 1e6}, "time between written frames");
  integrator.declare(v);
  v.flag("steady_state", steady_state,
         "solve directly for the steady state at end_time_s (static equilibrium: every listed term is built, "
         "velocities and accelerations are zero there) instead of time stepping");
  v.number("steady_state_change_mm", steady_state_change_m, Unit::kMillimetre, {0, 1e3},
           "time-stepping runs: end once the largest weighted coordinate change over one step (positions, and "
           "transverse gradients x h/2) is at most this, after the pressure ramp; 0: run to end_time_s. The output "
           "records where and why it stopped (docs/surface_output.md)");
  physics.declare(v);
  v.text_list("osmotic_surfaces", osmotic_surfaces, "",
              "osmotic_pressure: the surfaces that carry it (each one of `surfaces`); empty: every simulated surface "
              "(the seed's run pressurised the femoral cartilage)");
  v.flag("foundation_from_thickness", foundation_from_thickness,
         "foundation_springs stiffness per node k_i = K / h_i (h_i: the prepared cartilage thickness, K from "
         "matched_youngs_modulus_mpa and matched_poisson_ratio), matching the musculoskeletal stage's "
         "elastic-foundation contact, instead of foundation_stiffness_n_per_mm3");
  v.number("matched_youngs_modulus_mpa", matched_youngs_modulus_Pa, Unit::kMegapascal, {1e-6, 1e6},
           "E of the elastic-foundation layer used by foundation_from_thickness (the bundled knee's contact: 10 MPa)");
  v.number("matched_poisson_ratio", matched_poisson_ratio, Unit::kNone, {0, 0.499},
           "nu of the elastic-foundation layer used by foundation_from_thickness (bundled knee: 0.45)");
  v.choice("periphery_normal", periphery_normal,
           {{"clamped", PeripheryNormal::kClamped}, {"foundation", PeripheryNormal::kFoundation}},
           "periphery_fixed: clamped = boundary nodes move with the bone in all six coordinates (seed 002); "
           "foundation = tied to the bone in their tangent plane only, resting on the foundation along the normal "
           "(for contact zones that reach the rim, as in stage 1's elastic foundation)");
  v.number("periphery_tie_stiffness_n_per_mm3", periphery_tie_N_m3, Unit::kNewtonPerCubicMillimetre, {1e-3, 1e9},
           "periphery_normal: foundation: stiffness per unit area of the tangential tie");
  v.text_list("contact_pairs", contact_pairs, "",
              "surface pairs in mesh contact, each 'a:b' (both must be simulated); force output is on b (the tibia: "
              "/contact/tibiofemoral/...)");
  contact.declare(v);
  v.number("penetration_limit", penetration_limit, Unit::kNone, {0, 1e6},
           "the seed's accuracy rule: largest interpenetration / largest deflection allowed per step");
  v.choice("penetration_action", stop_on_penetration, {{"warn", false}, {"stop", true}},
           "when a step breaks penetration_limit: warn (counted, reported) or stop the run");
  v.choice("predictor", predictor, {{"rigid", Predictor::kRigid}, {"extrapolated", Predictor::kExtrapolated}},
           "imposed_kinematics: Newton start of a step: the surfaces carried rigidly by their bones (rigid), plus the "
           "bone-relative deformation change of the step before, extrapolated linearly in time (extrapolated)");
  v.number("seating_time_s", seating_time_s, Unit::kSecond, {0, 10},
           "imposed kinematics start with a seating ramp of this duration: bones other than the femur move from "
           "seating_offset_mm away along their own -Y axis to their first pose (the seed's run began with a 0.02 s "
           "seating)");
  v.number("seating_offset_mm", seating_offset_m, Unit::kMillimetre, {0, 100},
           "initial separation of the seating ramp; must exceed the first frame's overlap");
}

void SurfaceScenarioOptions::declare_instance(common::OptionVisitor& v) {
  using common::Unit;
  v.text("description", description, "", "free text for reports");
  v.path("mesh", mesh,
         "quad mesh (OBJ with 'v' and 4-node 'f' lines, or legacy ASCII VTK polydata with quad POLYGONS; coordinates "
         "in mm) simulated instead of the prepared model's surfaces; shell directors on the side of the quad normals");
  v.number_list("fixed_box_mm", fixed_box_m, Unit::kMillimetre, {6, 6},
                "[xmin, ymin, zmin, xmax, ymax, zmax]: nodes of `mesh` in this box are clamped (all six coordinates; "
                "effect fixed_nodes)");
  v.number_list("load_box_mm", load_box_m, Unit::kMillimetre, {6, 6},
                "box of the nodes of `mesh` that share point_load_n equally (effect point_loads)");
  v.number_list("point_load_n", point_load_N, Unit::kNone, {3, 3},
                "[fx, fy, fz] total force [N] on the nodes in load_box_mm, ramped linearly from 0 at t = 0 to its value "
                "at end_time_s (effect point_loads)");
  v.number("pressure_mpa", pressure_Pa, Unit::kMegapascal, {-1e3, 1e3},
           "pressure on the mid-surface of `mesh`, positive along the directors, ramped like point_load_n (effect "
           "pressure)");
  v.number_list("displaced_box_mm", displaced_box_m, Unit::kMillimetre, {6, 6},
                "box of the nodes of `mesh` whose positions are prescribed (effect prescribed_displacement)");
  v.number_list("displacement_mm", displacement_m, Unit::kMillimetre, {3, 3},
                "[ux, uy, uz] displacement of the nodes in displaced_box_mm, ramped like point_load_n");
  v.effect_list("effects", effects, "surface", "surface effects to simulate in this scenario").required();
}

StageDescriptor surface_stage_descriptor() {
  StageDescriptor d;
  d.name = "surface";
  d.executable = "arthrosim-surface";
  d.summary = "ANCF shells on foundations, osmotic pressure, mesh contact, HHT; one run per scenario";
  d.block = block_schema_with_instances<SurfaceScenarioOptions>(
      "surface", "options and scenarios of the deformable-surface stage", "scenarios",
      "the scenarios to run, each with its own effects", "scenario");
  d.outputs = {"surface"};
  for (const common::EffectInfo& e : common::known_effects())
    if (e.stage == common::EffectStage::kSurface)
      d.effects.push_back({std::string(e.name), "surface", std::string(e.description)});
  d.check = [](const common::Scene& scene) {
    // Without imposed kinematics nothing sets the run's duration.
    for (const common::BlockInstance& sc : scene.instances("surface")) {
      if (!sc.wants("imposed_kinematics") && !sc.options.has("end_time_s"))
        throw common::InputError(scene.file.string(), sc.line, sc.column,
                                 "scenario '" + sc.name +
                                     "' does not use imposed_kinematics, so it needs 'end_time_s' (in the scenario or "
                                     "the surface block)");
    }
  };
  return d;
}

SurfaceStageResult run_surface_stage(const SurfaceStageOptions& options) {
  const double t_start = now_s();
  const common::Scene scene = load_scene(options.scene);
  const std::vector<common::BlockInstance>& scenarios = scene.instances("surface");
  const common::BlockInstance* sc = nullptr;
  if (!options.scenario.empty()) {
    sc = &scene.require_instance("surface", options.scenario);
  } else {
    if (scenarios.size() != 1)
      throw common::InputError(options.scene + ": error: the scene has " + std::to_string(scenarios.size()) +
                               " scenarios; choose one with --scenario");
    sc = &scenarios.front();
  }
  const common::OptionBlock& o = sc->options;  // where each value was written (messages)
  const SurfaceScenarioOptions opt = common::read_options<SurfaceScenarioOptions>(o);

  // ---- parameters (SI from the scene) ------------------------------------
  cartilage::SurfaceParameters par = opt.physics;
  par.osmotic_ramp_s = 0;  // set below (osmotic_ramp_s, or the seating ramp)
  if (opt.periphery_normal == SurfaceScenarioOptions::PeripheryNormal::kFoundation)
    par.periphery_tie_N_m3 = opt.periphery_tie_N_m3;
  // ---- kinematics (imposed_kinematics) -------------------------------------
  const bool moving = sc->wants("imposed_kinematics");
  std::unique_ptr<H5File> kin;
  std::vector<double> kin_times;
  std::string partial_input;  // "" or the PARTIAL INPUT line (--allow-partial)
  if (moving) {
    if (options.kinematics.empty())
      throw common::InputError(scene.file.string(), sc->line,
                               "scenario '" + sc->name + "' lists imposed_kinematics: give --kinematics");
    kin = std::make_unique<H5File>(options.kinematics, H5File::Mode::kRead);
    partial_input = common::require_usable_file(*kin, options.kinematics, common::StageFile::kKinematics,
                                                options.allow_partial);
    const Eigen::VectorXd t = kin->read_vector("/time");
    kin_times.assign(t.data(), t.data() + t.size());
    if (kin_times.empty()) throw common::InputError(options.kinematics + ": error: dataset /time has no frame");
  } else if (!options.kinematics.empty()) {
    common::log_warn("--kinematics " + options.kinematics + " is not used: scenario '" + sc->name +
                     "' does not list imposed_kinematics");
  }
  auto bone_motion = [&](const std::string& bone) {
    const std::string ds = "/bodies/" + bone + "/X_W";
    const common::Tensor3d X = kin->read_tensor3(ds);
    if (X.dims[0] != static_cast<std::int64_t>(kin_times.size()) || X.dims[1] != 4 || X.dims[2] != 4)
      throw common::InputError(options.kinematics + ": error: dataset " + ds + ": expected dims (" +
                               std::to_string(kin_times.size()) + ", 4, 4), found (" + std::to_string(X.dims[0]) +
                               ", " + std::to_string(X.dims[1]) + ", " + std::to_string(X.dims[2]) + ")");
    std::vector<Eigen::Isometry3d> poses(kin_times.size());
    for (std::int64_t k = 0; k < X.dims[0]; ++k) {
      Eigen::Matrix4d M;
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) M(i, j) = X(k, i, j);
      common::check_finite(M, options.kinematics + ": dataset " + ds + ", frame " + std::to_string(k));
      if ((M.topLeftCorner<3, 3>().transpose() * M.topLeftCorner<3, 3>() - Eigen::Matrix3d::Identity()).norm() > 1e-6)
        throw common::InputError(options.kinematics + ": error: dataset " + ds + ", frame " + std::to_string(k) +
                                 ": expected a rotation in the top-left 3 x 3 block");
      poses[k].matrix() = M;
    }
    return cartilage::interpolated_bone_motion(kin_times, std::move(poses), options.kinematics + ": " + ds);
  };

  if (!opt.end_time_s && !moving)
    throw common::InputError(scene.file.string(), sc->line,
                             "scenario '" + sc->name + "' needs end_time_s (it has no imposed_kinematics)");
  const double end_time = opt.end_time_s ? *opt.end_time_s : kin_times.back() - kin_times.front();
  if (!(end_time > 0))
    throw common::InputError(scene.file.string(), sc->line, "scenario '" + sc->name + "': nothing to simulate (end time 0)");
  const double dt = opt.integrator.dt_s;
  const bool steady = opt.steady_state;
  const bool quasi_static = steady || !sc->wants("inertia");
  if (steady && !(end_time > 0))
    throw common::InputError(scene.file.string(), sc->line, "steady_state needs end_time_s > 0");
  double interval = opt.output_interval_s;
  if (steady) interval = end_time;
  if (interval < dt) interval = dt;

  numerics::IntegratorOptions iopt = opt.integrator;
  iopt.same_tolerances();
  iopt.quasi_static = quasi_static;
  iopt.dt_s = steady ? end_time : dt;
  // Opt-in keys of the dynamic path (docs/scenes.md; all off by default).
  // osmotic_ramp_s: without imposed kinematics the osmotic pressure rises
  // over this time, by the same smoothstep the seating ramp uses with
  // imposed kinematics (SurfaceParameters::osmotic_ramp_s, set below from
  // seating_time_s when bones move).
  const double osmotic_ramp = opt.physics.osmotic_ramp_s;
  if (osmotic_ramp > 0) {
    if (moving)
      throw common::InputError(scene.file.string(), o.value("osmotic_ramp_s").line,
                               "scenario '" + sc->name + "': osmotic_ramp_s is for scenarios without "
                               "imposed_kinematics (with them the pressure rises over seating_time_s)");
    if (osmotic_ramp > end_time)
      throw common::InputError(scene.file.string(), o.value("osmotic_ramp_s").line,
                               "scenario '" + sc->name + "': osmotic_ramp_s (" + std::to_string(osmotic_ramp) +
                                   " s) exceeds end_time_s (" + std::to_string(end_time) +
                                   " s): the pressure would never reach osmotic_pressure_mpa");
    par.osmotic_ramp_s = osmotic_ramp;
  }
  // steady_state_change_mm: a time-stepping run ends once the largest
  // weighted coordinate change over one step is at most this (m here).
  const double stop_change = opt.steady_state_change_m;
  if (stop_change > 0 && steady)
    throw common::InputError(scene.file.string(), o.value("steady_state_change_mm").line,
                             "scenario '" + sc->name + "': steady_state_change_mm stops a time-stepping run; "
                             "it has no meaning with steady_state: true");

  // ---- models -------------------------------------------------------------
  common::EffectLedger ledger("surface:" + sc->name);
  std::vector<SurfaceRun> runs;
  const bool generic = !opt.mesh.empty();
  const bool contact = sc->wants("mesh_contact");
  for (const char* e : {"fixed_nodes", "point_loads", "pressure", "prescribed_displacement"}) {
    if (sc->wants(e) && !generic)
      throw common::InputError(scene.file.string(), sc->line,
                               "scenario '" + sc->name + "': effect '" + e + "' needs a generic `mesh`");
  }
  if (contact && generic)
    throw common::InputError(scene.file.string(), sc->line,
                             "scenario '" + sc->name + "': mesh_contact needs the prepared model's surfaces, not a generic `mesh`");
  auto require = [&](const char* key, const char* effect) {
    if (sc->wants(effect) && !o.has(key))
      throw common::InputError(scene.file.string(), sc->line,
                               "scenario '" + sc->name + "': effect '" + effect + "' needs `" + key + "`");
  };
  require("fixed_box_mm", "fixed_nodes");
  require("load_box_mm", "point_loads");
  require("point_load_n", "point_loads");
  require("pressure_mpa", "pressure");
  require("displaced_box_mm", "prescribed_displacement");
  require("displacement_mm", "prescribed_displacement");
  if (generic) {
    SurfaceRun r;
    const std::string mesh_file = opt.mesh.string();
    std::string ext = opt.mesh.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (ext != ".obj" && ext != ".vtk")
      throw common::InputError(scene.file.string(), o.value("mesh").line,
                               "mesh '" + mesh_file + "': expected an .obj or .vtk quad mesh");
    r.input.mesh = ext == ".vtk" ? read_quad_vtk(mesh_file) : read_quad_obj(mesh_file);
    r.input.name = opt.mesh.stem().string();
    r.input.mesh.name = r.input.name;
    r.input.normals = cartilage::quad_mesh_vertex_normals(r.input.mesh);
    cartilage::GenericLoads& g = r.input.generic;
    g.ramp_time_s = end_time > 0 ? end_time : 1.0;
    if (!opt.fixed_box_m.empty()) g.fixed_nodes = nodes_in_box(r.input.mesh, opt.fixed_box_m);
    if (!opt.load_box_m.empty()) g.load_nodes = nodes_in_box(r.input.mesh, opt.load_box_m);
    if (!opt.point_load_N.empty()) {
      const auto& f = opt.point_load_N;
      g.total_force_N = Eigen::Vector3d(f[0], f[1], f[2]);
    }
    if (opt.pressure_Pa) g.pressure_Pa = *opt.pressure_Pa;
    if (!opt.displaced_box_m.empty()) g.displaced_nodes = nodes_in_box(r.input.mesh, opt.displaced_box_m);
    if (!opt.displacement_m.empty()) {
      const auto& u = opt.displacement_m;
      g.displacement_m = Eigen::Vector3d(u[0], u[1], u[2]);
    }
    r.model = cartilage::build_surface_model(r.input, par, sc->effects, cartilage::BoneMotion::fixed(), &ledger);
    r.basis = cartilage::node_strain_basis(*r.model);
    r.summary.name = r.input.name;
    r.summary.nodes = r.model->num_nodes();
    r.summary.elements = r.model->num_elements();
    runs.push_back(std::move(r));
  }
  if (!generic && options.prepared.empty())
    throw common::InputError(options.scene + ": error: scenario '" + sc->name +
                             "' simulates the prepared model's surfaces: give --prepared");
  std::unique_ptr<H5File> prepared_file;
  std::vector<std::string> names;
  if (!generic) {
    prepared_file = std::make_unique<H5File>(options.prepared, H5File::Mode::kRead);
    common::require_file_format(*prepared_file, options.prepared, common::StageFile::kPreparedModel);
    names = prepared_file->read_strings("/surfaces/names");
  }
  const std::vector<std::string> surface_names = generic ? std::vector<std::string>{} : opt.surfaces;
  // Contact pairs: "a:b", both simulated.
  std::vector<std::pair<int, int>> pair_index;
  std::vector<std::string> pair_names;
  if (contact) {
    for (const std::string& pr : opt.contact_pairs) {
      const auto colon = pr.find(':');
      const std::string a = pr.substr(0, colon), b = colon == std::string::npos ? "" : pr.substr(colon + 1);
      const auto ia = std::find(surface_names.begin(), surface_names.end(), a);
      const auto ib = std::find(surface_names.begin(), surface_names.end(), b);
      if (colon == std::string::npos || ia == surface_names.end() || ib == surface_names.end() || ia == ib)
        throw common::InputError(scene.file.string(), o.value("contact_pairs").line,
                                 "contact pair '" + pr + "': expected 'a:b' with two different surfaces of this "
                                 "scenario's `surfaces`");
      pair_index.emplace_back(static_cast<int>(ia - surface_names.begin()), static_cast<int>(ib - surface_names.begin()));
      pair_names.push_back(pr);
    }
    if (pair_index.empty())
      throw common::InputError(scene.file.string(), sc->line,
                               "scenario '" + sc->name + "' lists mesh_contact but contact_pairs is empty");
  }
  // osmotic_surfaces: which surfaces carry osmotic_pressure (empty: all).
  std::vector<std::string> osmotic_surfaces;
  if (!generic && sc->wants("osmotic_pressure")) {
    osmotic_surfaces = opt.osmotic_surfaces;
    for (const std::string& s : osmotic_surfaces)
      if (std::find(surface_names.begin(), surface_names.end(), s) == surface_names.end())
        throw common::InputError(scene.file.string(), o.value("osmotic_surfaces").line,
                                 "osmotic surface '" + s + "' is not one of this scenario's `surfaces`");
  }
  const double seating = moving ? opt.seating_time_s : 0.0;
  // With imposed kinematics the pressure rises during the seating ramp (a
  // step load on the resting shells would start a dynamic inflation).
  if (moving) par.osmotic_ramp_s = seating;
  const double seat_offset = opt.seating_offset_m;
  for (const std::string& name : surface_names) {
    const H5File& prepared = *prepared_file;
    if (std::find(names.begin(), names.end(), name) == names.end()) {
      std::string have;
      for (const auto& n : names) have += (have.empty() ? "" : ", ") + n;
      throw common::InputError(scene.file.string(), o.value("surfaces").line,
                               "surface '" + name + "' is not in the prepared model " + options.prepared +
                                   " (it has: " + have + ")");
    }
    SurfaceRun r;
    r.input = read_prepared_surface(prepared, name);
    r.bone_name = prepared.attribute_string("/surfaces/" + name, "bone");
    if (moving) {
      // Prepared coordinates are bone-frame coordinates (the model frame at
      // q = 0, docs/kinematics_file.md); the shell's reference is the surface
      // placed by the bone's pose at t = 0 (after the seating offset).
      const Eigen::Vector3d offset = r.bone_name == "femur" ? Eigen::Vector3d::Zero()
                                                            : Eigen::Vector3d(0, seat_offset, 0);
      r.bone = seated(bone_motion(r.bone_name), seating, offset);
      r.X_WB0 = r.bone.pose(0.0);
      r.input.mesh.V = ((r.input.mesh.V * r.X_WB0.linear().transpose()).rowwise() + r.X_WB0.translation().transpose()).eval();
      r.input.normals = (r.input.normals * r.X_WB0.linear().transpose()).eval();
    }
    cartilage::SurfaceParameters p = par;
    if (opt.foundation_from_thickness && sc->wants("foundation_springs")) {
      const Eigen::VectorXd h = prepared.read_vector("/surfaces/" + name + "/quads/thickness");
      p.foundation_stiffness_per_node_N_m3 = cartilage::matched_foundation_stiffness(
          h, opt.matched_youngs_modulus_Pa, opt.matched_poisson_ratio,
          options.prepared + ": dataset /surfaces/" + name + "/quads/thickness");
    }
    std::vector<std::string> effects = sc->effects;
    if (!osmotic_surfaces.empty() &&
        std::find(osmotic_surfaces.begin(), osmotic_surfaces.end(), name) == osmotic_surfaces.end())
      effects.erase(std::remove(effects.begin(), effects.end(), "osmotic_pressure"), effects.end());
    r.model = cartilage::build_surface_model(r.input, p, effects, r.bone, &ledger);
    if (moving) r.model->set_motion_predictor(r.bone);
    r.basis = cartilage::node_strain_basis(*r.model);
    r.summary.name = name;
    r.summary.nodes = r.model->num_nodes();
    r.summary.elements = r.model->num_elements();
    runs.push_back(std::move(r));
  }
  const double total_time = end_time + seating;
  // One system of all surfaces (side by side, exactly the separate models
  // when there is no contact), coupled by the contact pairs.
  std::vector<ShellModel*> model_ptrs;
  std::vector<std::string> model_names;
  for (SurfaceRun& r : runs) {
    model_ptrs.push_back(r.model.get());
    model_names.push_back(r.summary.name);
  }
  cartilage::CoupledShellSystem system(model_ptrs, model_names);
  system.attach_ledger(&ledger);
  const cartilage::ContactOptions& copt = opt.contact;
  if (copt.faded_vertex_weights && copt.rim_vertices)
    throw common::InputError(options.scene + ": error: scenario '" + sc->name +
                             "': contact_rim_vertices applies to contact_vertex_weights: tributary only (faded "
                             "weights give rim nodes their own, reduced weight)");
  for (size_t k = 0; k < pair_index.size(); ++k)
    system.add_contact(pair_names[k], pair_index[k].first, pair_index[k].second, copt);
  ledger.require_only(sc->effects);
  common::log_info(ledger.to_text());

  // ---- output file: static part -------------------------------------------
  // Written as <out>.partial and renamed over <out> once completed: a
  // previous complete output stays until then (common/output_file.h).
  common::AtomicOutput atomic(options.out);
  H5File out(atomic.temp().string(), H5File::Mode::kTruncate);
  {
    std::vector<const char*> argv;
    for (const auto& a : options.argv) argv.push_back(a.c_str());
    common::write_metadata(out, common::collect_run_metadata("arthrosim-surface", static_cast<int>(argv.size()),
                                                             argv.data(), options.scene, o.canonical_text()));
  }
  out.set_attribute("/", "schema", "arthrosim surface output 2");
  out.set_attribute("/", "scenario", sc->name);
  out.set_attribute("/", "prepared_model", generic ? std::string() : options.prepared);
  out.set_attribute("/", "mesh", generic ? opt.mesh.string() : std::string());
  out.set_attribute("/", "mode", steady ? "steady_state" : (quasi_static ? "quasi_static" : "hht"));
  out.set_attribute("/", "status", "running");
  if (!partial_input.empty()) out.set_attribute("/", "partial_input", partial_input);
  out.set_attribute("/", "seating_time_s", seating);
  common::write_effect_ledger(out, ledger);
  const auto n_frames_expected = static_cast<std::int64_t>(std::floor(total_time / interval + 1e-9)) + 1 +
                                 (std::fmod(total_time, interval) > 1e-12 * interval ? 1 : 0);
  const auto n_steps_expected = static_cast<std::int64_t>(std::ceil(total_time / (steady ? total_time : dt) - 1e-9));
  H5File::Appender time_out = out.appender("/time", {}, {n_frames_expected, 0});
  std::unique_ptr<H5File::Appender> trial_time_out;
  if (moving) trial_time_out = std::make_unique<H5File::Appender>(out.appender("/trial_time", {}, {n_frames_expected, 0}));
  for (SurfaceRun& r : runs) {
    const std::string g = "/surfaces/" + r.summary.name + "/";
    const std::int64_t N = r.model->num_nodes();
    out.write(g + "nodes", r.input.mesh.V);
    out.write(g + "quads", Eigen::MatrixXi(r.input.mesh.Q));
    out.write(g + "normals", Eigen::MatrixXd(r.basis.n));
    out.write(g + "basis_a1", Eigen::MatrixXd(r.basis.a1));
    out.write(g + "basis_a2", Eigen::MatrixXd(r.basis.a2));
    if (!r.bone_name.empty()) out.set_attribute("/surfaces/" + r.summary.name, "bone", r.bone_name);
    std::vector<int> fixed(r.model->constrained().size() / 6);
    for (size_t i = 0; i < fixed.size(); ++i) fixed[i] = r.model->constrained()[6 * i] ? 1 : 0;
    out.write(g + "fixed", fixed);
    const common::H5AppendOptions fo{n_frames_expected, 0};
    r.frame_out.push_back(out.appender(g + "displacement", {N, 3}, fo));
    r.frame_out.push_back(out.appender(g + "deflection", {N}, fo));
    r.frame_out.push_back(out.appender(g + "strain/E", {N, 3}, fo));
    r.frame_out.push_back(out.appender(g + "strain/e1", {N}, fo));
    r.frame_out.push_back(out.appender(g + "strain/e1_dir", {N, 3}, fo));
    r.frame_out.push_back(out.appender(g + "strain/e2", {N}, fo));
    if (contact) r.frame_out.push_back(out.appender(g + "contact_pressure", {N}, fo));
  }
  const common::H5AppendOptions so{n_steps_expected, 0};
  std::vector<H5File::Appender> solver_out;  // per step
  for (const char* name : {"time", "dt"}) solver_out.push_back(out.appender(std::string("/solver/") + name, {}, so));
  solver_out.push_back(out.appender_int("/solver/newton_iterations", {}, so));
  solver_out.push_back(out.appender("/solver/residual_N", {}, so));
  solver_out.push_back(out.appender("/solver/residual_tolerance_N", {}, so));
  solver_out.push_back(out.appender_int("/solver/rejections", {}, so));
  solver_out.push_back(out.appender("/solver/wall_s", {}, so));
  solver_out.push_back(out.appender("/solver/max_deflection_m", {}, so));
  // steady_state_change_mm: the largest weighted coordinate change per step.
  std::unique_ptr<H5File::Appender> change_out;
  if (stop_change > 0) change_out = std::make_unique<H5File::Appender>(out.appender("/solver/change_m", {}, so));
  if (contact) {
    solver_out.push_back(out.appender("/solver/max_penetration_m", {}, so));
    solver_out.push_back(out.appender("/solver/penetration_ratio", {}, so));
    solver_out.push_back(out.appender_int("/solver/active_contacts", {}, so));
    solver_out.push_back(out.appender("/solver/max_rim_depth_m", {}, so));
    solver_out.push_back(out.appender("/solver/max_unfaded_penetration_m", {}, so));
    solver_out.push_back(out.appender("/solver/unfaded_penetration_ratio", {}, so));
  }
  // Tibiofemoral contact force per frame (on the second surface of each
  // pair, in its bone's frame; pairs named medial/lateral are the
  // compartments), as in the kinematics file.
  std::vector<H5File::Appender> contact_out;
  if (contact) {
    contact_out.push_back(out.appender("/contact/tibiofemoral/force", {3}, {n_frames_expected, 0}));
    contact_out.push_back(out.appender("/contact/tibiofemoral/medial_force", {3}, {n_frames_expected, 0}));
    contact_out.push_back(out.appender("/contact/tibiofemoral/lateral_force", {3}, {n_frames_expected, 0}));
    contact_out.push_back(out.appender("/contact/tibiofemoral/area", {}, {n_frames_expected, 0}));
    contact_out.push_back(out.appender("/contact/tibiofemoral/max_penetration", {}, {n_frames_expected, 0}));
    out.write("/contact/pairs", pair_names);
  }
  out.flush();

  std::vector<double> times;
  const std::string xdmf_path = std::filesystem::path(options.out).replace_extension(".xdmf").string();
  auto write_sidecar = [&]() {
    common::XdmfSeries series;
    series.times = times;
    for (const SurfaceRun& r : runs) {
      const std::string g = "/surfaces/" + r.summary.name + "/";
      common::XdmfSurface s;
      s.name = r.summary.name;
      s.geometry_dataset = g + "nodes";
      s.topology_dataset = g + "quads";
      s.cell_type = common::XdmfCellType::kQuadrilateral;
      s.fields = {{"displacement", g + "displacement"}, {"deflection", g + "deflection"},
                  {"E", g + "strain/E"},                {"e1", g + "strain/e1"},
                  {"e1_dir", g + "strain/e1_dir"},      {"e2", g + "strain/e2"}};
      if (contact) s.fields.push_back({"contact_pressure", g + "contact_pressure"});
      series.surfaces.push_back(std::move(s));
    }
    common::write_xdmf(xdmf_path, out, series);
  };
  // Bone-relative rigid motion of surface r at time t.
  auto rigid = [&](const SurfaceRun& r, double t) { return Eigen::Isometry3d(r.bone.pose(t) * r.X_WB0.inverse()); };
  auto max_abs_deflection = [&](const Eigen::VectorXd& qs, double t) {
    double m = 0;
    for (int k = 0; k < static_cast<int>(runs.size()); ++k)
      m = std::max(m, cartilage::nodal_deflection(*runs[k].model, system.segment(k, qs), rigid(runs[k], t))
                          .cwiseAbs()
                          .maxCoeff());
    return m;
  };
  long penetration_warnings = 0;
  double worst_ratio = 0;
  // The same rule on the unfaded contacts only (reported, not enforced):
  // separates the penalty's own interpenetration from the rims' faded zone.
  long unfaded_over = 0;
  double worst_unfaded_ratio = 0;
  // One frame: every surface's fields, the contact forces, then /time (so
  // /time counts complete frames).
  // Contact state of every pair at q (computed once per step; the frame
  // written after that step reuses it).
  auto contact_reports = [&](const Eigen::VectorXd& qs) {
    std::vector<cartilage::ContactPairReport> reps;
    for (int k = 0; k < system.num_contacts(); ++k) reps.push_back(system.contact_report(k, qs));
    return reps;
  };
  auto write_frame = [&](const Eigen::VectorXd& qs, double t, const std::vector<cartilage::ContactPairReport>& reps) {
    std::vector<Eigen::VectorXd> pressure(runs.size());
    for (size_t k = 0; k < runs.size(); ++k) pressure[k] = Eigen::VectorXd::Zero(runs[k].model->num_nodes());
    Eigen::Vector3d total = Eigen::Vector3d::Zero(), medial = total, lateral = total;
    double area = 0, max_pen = 0;
    for (int k = 0; k < system.num_contacts(); ++k) {
      const cartilage::ContactPairReport& rep = reps[k];
      const int a = pair_index[k].first, b = pair_index[k].second;
      pressure[a] += rep.pressure_a;
      pressure[b] += rep.pressure_b;
      const Eigen::Vector3d f_B = runs[b].bone.pose(t).linear().transpose() * rep.total_force_b;
      total += f_B;
      if (pair_names[k].find("medial") != std::string::npos) medial += f_B;
      if (pair_names[k].find("lateral") != std::string::npos) lateral += f_B;
      area += rep.contact_area_m2;
      max_pen = std::max(max_pen, rep.counts.max_penetration_m);
    }
    for (size_t k = 0; k < runs.size(); ++k) {
      SurfaceRun& r = runs[k];
      const Eigen::VectorXd q = system.segment(static_cast<int>(k), qs);
      const Eigen::Isometry3d T = rigid(r, t);
      const Eigen::MatrixXd u = cartilage::nodal_displacement(*r.model, q, T);
      const Eigen::VectorXd w = cartilage::nodal_deflection(*r.model, q, T);
      const cartilage::NodalStrains st = cartilage::nodal_strains(*r.model, r.basis, q);
      common::check_finite(u, "surface " + r.summary.name + ": displacement at t = " + std::to_string(t));
      common::check_finite(st.E, "surface " + r.summary.name + ": strain at t = " + std::to_string(t));
      r.frame_out[0].append(u);
      r.frame_out[1].append(w);
      r.frame_out[2].append(st.E);
      r.frame_out[3].append(st.e1);
      r.frame_out[4].append(st.e1_dir);
      r.frame_out[5].append(st.e2);
      if (contact) r.frame_out[6].append(pressure[k]);
      Eigen::Index imax = 0;
      w.cwiseAbs().maxCoeff(&imax);
      if (std::abs(w(imax)) >= std::abs(r.summary.max_deflection_m)) {
        r.summary.max_deflection_m = w(imax);
        r.summary.max_deflection_time_s = t;
      }
      r.summary.e1_min = std::min(r.summary.e1_min, st.e1.minCoeff());
      r.summary.e1_max = std::max(r.summary.e1_max, st.e1.maxCoeff());
      r.summary.e2_min = std::min(r.summary.e2_min, st.e2.minCoeff());
    }
    if (contact) {
      contact_out[0].append(total);
      contact_out[1].append(medial);
      contact_out[2].append(lateral);
      contact_out[3].append(area);
      contact_out[4].append(max_pen);
    }
    time_out.append(t);
    if (trial_time_out) trial_time_out->append(t - seating + kin_times.front());
    times.push_back(t);
    write_sidecar();
  };

  // ---- integrate ----------------------------------------------------------
  if (contact) iopt.line_search_halvings = 8;  // Newton globalisation for penalty contact
  if (iopt.reuse_factorization && contact)
    throw common::InputError(scene.file.string(), o.value("newton_reuse_factorization").line,
                             "scenario '" + sc->name + "': newton_reuse_factorization cannot be combined with "
                             "mesh_contact (its Newton line search needs a fresh tangent)");
  // Imposed kinematics: each step starts from the surfaces carried by their
  // bones (rigid predictor), so Newton only finds the deformation change.
  if (moving)
    iopt.predictor = opt.predictor == SurfaceScenarioOptions::Predictor::kExtrapolated ? numerics::IntegratorOptions::Predictor::kSystemExtrapolated
                                                           : numerics::IntegratorOptions::Predictor::kSystem;
  Eigen::VectorXd q0(system.num_dofs());
  for (int k = 0; k < system.num_models(); ++k)
    q0.segment(system.offset(k), runs[k].model->num_dofs()) = runs[k].model->reference_state();
  // The surfaces must start apart (or the first frame's overlap is applied
  // as an impact): the seating offset has to exceed the initial overlap.
  std::vector<cartilage::ContactPairReport> reports = contact_reports(q0);
  for (int k = 0; k < system.num_contacts(); ++k)
    if (reports[k].counts.vertex_face + reports[k].counts.edge_edge > 0)
      throw common::InputError(scene.file.string(), sc->line,
                               "scenario '" + sc->name + "': contact pair " + pair_names[k] + " overlaps by " +
                                   std::to_string(reports[k].counts.max_penetration_m * 1e3) +
                                   " mm at t = 0; increase seating_offset_mm (now " +
                                   std::to_string(seat_offset * 1e3) + " mm)");
  // Rejections are reported as they happen: one output step may hold many
  // halved sub-steps, and the run must not look idle meanwhile.
  long rejections_logged = 0;
  iopt.on_rejection = [&](const std::string& rejection) {
    common::log_warn("surface " + sc->name + ": step rejected and halved (" + std::to_string(++rejections_logged) +
                     " so far): " + rejection);
  };
  numerics::HhtIntegrator integrator(system, iopt);
  integrator.initialize(0.0, q0);
  common::log_info("scenario " + sc->name + ": " +
                   (steady ? std::string("steady state (static equilibrium at t = ") + std::to_string(end_time) + " s)"
                           : (quasi_static ? "quasi-static" : "HHT alpha " + std::to_string(iopt.alpha)) +
                                 std::string(", dt ") + std::to_string(dt) + " s to " + std::to_string(total_time) +
                                 " s" + (seating > 0 ? " (" + std::to_string(seating) + " s seating first)" : "") +
                                 (osmotic_ramp > 0 ? ", osmotic pressure ramped over " + std::to_string(osmotic_ramp) +
                                                         " s"
                                                   : std::string()) +
                                 (stop_change > 0 ? ", stopping at the steady state (change per step <= " +
                                                        std::to_string(stop_change * 1e3) + " mm)"
                                                  : std::string())));
  write_frame(integrator.q(), 0.0, reports);
  common::ProgressOptions popt;
  if (!options.progress) popt.mode = common::ProgressOptions::Mode::kOff;
  common::Progress progress("surface " + sc->name, std::max<std::int64_t>(n_steps_expected, 1), popt);
  const double step = steady ? total_time : dt;
  const double limit = opt.penetration_limit;
  const bool stop_on_penetration = opt.stop_on_penetration;
  double t = 0;
  int k_out = 1;
  // steady_state_change_mm: each step is taken by advance_to_steady_state
  // over that one step (same halving rules as advance_to), which returns
  // whether the step's weighted change was at most stop_change. The stop is
  // not accepted before the pressure ramp (or seating) has ended: at the
  // start of a smoothstep ramp the load barely changes.
  bool stopped_steady = false;
  double last_change = std::numeric_limits<double>::quiet_NaN();
  long last_iterations = 0, last_rejections = 0;
  SurfaceStageResult res;
  try {
    while (t < total_time * (1 - 1e-12)) {
      const double t_out = std::min(k_out * interval, total_time);
      while (t < t_out * (1 - 1e-12)) {
        const double t_next = std::min(t + step, t_out);
        const double w0 = now_s();
        bool at_steady = false;
        if (stop_change > 0) {
          at_steady = integrator.advance_to_steady_state(stop_change, t_next, &last_change) &&
                      t_next >= par.osmotic_ramp_s;
        } else {
          integrator.advance_to(t_next);
        }
        const double wall = now_s() - w0;
        const numerics::IntegratorStatistics& s = integrator.statistics();
        const numerics::StepRecord& rec = s.log.back();
        const double r0 = rec.residual_norms.front(), rl = rec.residual_norms.back();
        if (common::log_level() >= common::LogLevel::kDebug) {  // --verbose: the step's Newton history
          std::ostringstream m;
          m << "step to t = " << t_next << " s (dt " << rec.dt << " s, " << wall << " s):  residuals [N]";
          for (double x : rec.residual_norms) m << " " << x;
          m << "  increments [m]";
          for (double x : rec.increment_norms) m << " " << x;
          common::log_debug(m.str());
        }
        res.final_residual_N = rl;
        res.residual_tolerance_N = std::max(iopt.residual_rtol * r0, iopt.residual_atol_N);
        const double max_def = max_abs_deflection(integrator.q(), t_next);
        solver_out[0].append(t_next);
        solver_out[1].append(rec.dt);
        solver_out[2].append(static_cast<int>(s.newton_iterations - last_iterations));
        solver_out[3].append(rl);
        solver_out[4].append(res.residual_tolerance_N);
        solver_out[5].append(static_cast<int>(s.rejected_steps - last_rejections));
        solver_out[6].append(wall);
        solver_out[7].append(max_def);
        if (change_out) change_out->append(last_change);
        if (contact) {
          reports = contact_reports(integrator.q());
          double pen = 0, rim_depth = 0, unfaded = 0;
          long active = 0;
          for (const cartilage::ContactPairReport& rep : reports) {
            pen = std::max(pen, rep.counts.max_penetration_m);
            rim_depth = std::max(rim_depth, rep.counts.max_rim_depth_m);
            unfaded = std::max(unfaded, rep.counts.max_unfaded_penetration_m);
            active += rep.counts.vertex_face + rep.counts.edge_edge;
          }
          auto ratio_of = [&](double p) {
            return max_def > 0 ? p / max_def : (p > 0 ? std::numeric_limits<double>::infinity() : 0.0);
          };
          const double ratio = ratio_of(pen), unfaded_ratio = ratio_of(unfaded);
          solver_out[8].append(pen);
          solver_out[9].append(ratio);
          solver_out[10].append(static_cast<int>(active));
          solver_out[11].append(rim_depth);
          solver_out[12].append(unfaded);
          solver_out[13].append(unfaded_ratio);
          if (active > 0 && unfaded_ratio > limit) {
            ++unfaded_over;
            worst_unfaded_ratio = std::max(worst_unfaded_ratio, unfaded_ratio);
          }
          res.max_penetration_m = std::max(res.max_penetration_m, pen);
          res.contact_steps += active > 0 ? 1 : 0;
          res.active_contacts_sum += active;
          // The seed's accuracy rule, enforced: interpenetration below
          // penetration_limit x the largest deflection (checked while in contact).
          if (active > 0 && ratio > limit) {
            ++penetration_warnings;
            if (ratio > worst_ratio) worst_ratio = ratio;
            std::ostringstream m;
            m << "t = " << t_next << " s: max interpenetration " << pen * 1e3 << " mm is " << ratio
              << " of the max deflection " << max_def * 1e3 << " mm (limit " << limit << ")";
            if (stop_on_penetration)
              throw common::NumericalError("surface " + sc->name + ": accuracy rule broken: " + m.str() +
                                           "; raise contact_stiffness_n_per_mm3 or set penetration_action: warn");
            if (penetration_warnings <= 5 || penetration_warnings % 1000 == 0)
              common::log_warn("surface " + sc->name + ": " + m.str() + " (warning " +
                               std::to_string(penetration_warnings) + ")");
          }
        }
        last_iterations = s.newton_iterations;
        last_rejections = s.rejected_steps;
        t = t_next;
        progress.step();
        if (at_steady) {
          stopped_steady = true;
          break;
        }
      }
      write_frame(integrator.q(), t, reports);  // at a stop: the steady state is the last frame
      ++k_out;
      if (stopped_steady) break;
    }
  } catch (const std::exception& e) {
    out.set_attribute("/", "status", std::string("failed: ") + e.what());
    out.flush();
    throw;
  }
  progress.finish();

  // ---- statistics -----------------------------------------------------------
  res.scenario = sc->name;
  res.frames = static_cast<int>(times.size());
  for (SurfaceRun& r : runs) {
    for (auto& a : r.frame_out) a.close();
    const std::string g = "/surfaces/" + r.summary.name;
    out.set_attribute(g, "max_deflection_m", r.summary.max_deflection_m);
    out.set_attribute(g, "max_deflection_time_s", r.summary.max_deflection_time_s);
    out.set_attribute(g, "e1_min", r.summary.e1_min);
    out.set_attribute(g, "e1_max", r.summary.e1_max);
    out.set_attribute(g, "e2_min", r.summary.e2_min);
    r.summary.final_residual_N = res.final_residual_N;
    r.summary.residual_tolerance_N = res.residual_tolerance_N;
    out.set_attribute(g, "final_residual_N", res.final_residual_N);
    out.set_attribute(g, "residual_tolerance_N", res.residual_tolerance_N);
    res.surfaces.push_back(r.summary);
  }
  for (auto& a : solver_out) a.close();
  if (change_out) change_out->close();
  if (stop_change > 0) {
    res.steady_state_stop = true;
    res.steady_state_reached = stopped_steady;
    res.stop_time_s = t;
    res.last_change_m = last_change;
    out.set_attribute("/solver", "steady_state_change_tol_m", stop_change);
    out.set_attribute("/solver", "stop_reason", stopped_steady ? "steady_state" : "end_time");
    out.set_attribute("/solver", "stop_time_s", t);
    out.set_attribute("/solver", "last_change_m", last_change);
    std::ostringstream m;
    m << "scenario " << sc->name << ": ";
    if (stopped_steady) {
      m << "steady state reached at t = " << t << " s after " << integrator.statistics().steps
        << " steps: largest weighted change over the last step " << last_change * 1e3 << " mm <= "
        << stop_change * 1e3 << " mm";
      common::log_info(m.str());
    } else {
      m << "end_time_s = " << t << " s reached before the steady state (a whole step of time_step_s after the "
        << "pressure ramp with a largest weighted change <= " << stop_change * 1e3
        << " mm, steady_state_change_mm); the last step's change was " << last_change * 1e3 << " mm";
      common::log_warn(m.str());
    }
  }
  if (osmotic_ramp > 0) out.set_attribute("/", "osmotic_ramp_s", osmotic_ramp);
  for (auto& a : contact_out) a.close();
  const numerics::IntegratorStatistics& s = integrator.statistics();
  const cartilage::CoupledSystemStatistics& cs = system.statistics();
  out.set_attribute("/solver", "steps", static_cast<std::int64_t>(s.steps));
  out.set_attribute("/solver", "newton_iterations", static_cast<std::int64_t>(s.newton_iterations));
  out.set_attribute("/solver", "rejected_steps", static_cast<std::int64_t>(s.rejected_steps));
  out.set_attribute("/solver", "factorizations", static_cast<std::int64_t>(s.factorizations));
  out.set_attribute("/solver", "symbolic_analyses", static_cast<std::int64_t>(s.symbolic_analyses));
  out.set_attribute("/solver", "solver_switches", static_cast<std::int64_t>(s.solver_switches));
  out.set_attribute("/solver", "pattern_changes", static_cast<std::int64_t>(s.pattern_changes));
  out.set_attribute("/solver", "line_search_reductions", static_cast<std::int64_t>(s.line_search_reductions));
  out.set_attribute("/solver", "linear_solver", s.linear_solver);
  out.set_attribute("/solver", "assembly_s", s.assembly_s);
  out.set_attribute("/solver", "contact_s", cs.contact_time_s);
  // Where the assembly time goes (wall): element loops, summing element
  // results into the surface matrices, the surfaces' evaluations as a whole
  // (all their terms), and copying between the surfaces and the system.
  double elements_s = 0, element_scatter_s = 0;
  for (const ShellModel* m : model_ptrs) {
    elements_s += m->statistics().element_time_s;
    element_scatter_s += m->statistics().scatter_time_s;
  }
  const long evaluations = cs.evaluations, tangent_evaluations = cs.tangent_evaluations;
  out.set_attribute("/solver", "evaluations", static_cast<std::int64_t>(evaluations));
  out.set_attribute("/solver", "tangent_evaluations", static_cast<std::int64_t>(tangent_evaluations));
  out.set_attribute("/solver", "elements_s", elements_s);
  out.set_attribute("/solver", "element_scatter_s", element_scatter_s);
  out.set_attribute("/solver", "surfaces_s", cs.models_time_s);
  out.set_attribute("/solver", "coupling_copy_s", cs.copy_time_s);
  out.set_attribute("/solver", "factorization_s", s.factorization_s);
  out.set_attribute("/solver", "solve_s", s.solve_s);
  out.set_attribute("/solver", "total_s", s.total_s);
  std::string rej;
  for (const auto& x : s.rejections) rej += x + "\n";
  out.set_attribute("/solver", "rejections", rej);
  if (contact) {
    out.set_attribute("/solver", "penetration_warnings", static_cast<std::int64_t>(penetration_warnings));
    out.set_attribute("/solver", "worst_penetration_ratio", worst_ratio);
    out.set_attribute("/solver", "unfaded_penetration_warnings", static_cast<std::int64_t>(unfaded_over));
    out.set_attribute("/solver", "worst_unfaded_penetration_ratio", worst_unfaded_ratio);
    out.set_attribute("/solver", "penetration_limit", limit);
    out.set_attribute("/solver", "max_penetration_m", res.max_penetration_m);
  }
  res.steps = s.steps;
  res.newton_iterations = s.newton_iterations;
  res.rejected_steps = s.rejected_steps;
  res.factorizations = s.factorizations;
  res.assembly_s = s.assembly_s;
  res.contact_s = cs.contact_time_s;
  res.elements_s = elements_s;
  res.evaluations = evaluations;
  res.tangent_evaluations = tangent_evaluations;
  res.element_scatter_s = element_scatter_s;
  res.surfaces_s = cs.models_time_s;
  res.coupling_copy_s = cs.copy_time_s;
  res.factorization_s = s.factorization_s;
  res.solve_s = s.solve_s;
  res.pattern_changes = s.pattern_changes;
  res.penetration_warnings = penetration_warnings;
  res.worst_penetration_ratio = worst_ratio;
  res.unfaded_penetration_warnings = unfaded_over;
  res.worst_unfaded_penetration_ratio = worst_unfaded_ratio;
  time_out.close();
  if (trial_time_out) trial_time_out->close();
  res.wall_s = now_s() - t_start;
  out.set_attribute("/solver", "wall_s", res.wall_s);
  out.set_attribute("/", "status", "completed");
  out.flush();
  write_sidecar();
  atomic.commit();
  res.status = SurfaceStageStatus::kCompleted;
  return res;
}

}  // namespace arthrosim::pipelines
