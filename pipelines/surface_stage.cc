#include "pipelines/surface_stage.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

#include "cartilage/coupled_system.h"
#include "numerics/hht_integrator.h"
#include "common/checkpoint.h"
#include "pipelines/surface_checkpoint.h"
#include "cartilage/surface_model.h"
#include "common/effects.h"
#include "common/error.h"
#include "common/file_check.h"
#include "common/finite.h"
#include "common/hdf5.h"
#include "common/log.h"
#include "common/metadata.h"
#include "common/prepared_model_file.h"
#include "common/progress.h"
#include "common/scene.h"
#include "musculoskeletal/kinematics_file.h"
#include "pipelines/stages.h"
#include "pipelines/surface_output.h"
#include "pipelines/study.h"

namespace arthrosim::pipelines {
namespace {

using numerics::HhtIntegrator;
using cartilage::ShellModel;
using common::H5File;

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// One cartilage surface of the prepared model (docs/prepared_model.md).
cartilage::SurfaceInput read_prepared_surface(const common::PreparedModelReader& prepared, const std::string& name) {
  common::PreparedModelReader::QuadSurface q = prepared.quads(name);
  cartilage::SurfaceInput s;
  s.name = name;
  s.mesh = std::move(q.mesh);
  s.normals = std::move(q.normals);
  s.periphery = std::move(q.periphery);
  return s;
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
  v.flag("linear", integrator.linear,
         "steady_state only: linear (small-displacement) analysis, one solve with the tangent of the reference "
         "configuration and no geometric update (for linear benchmarks); strains are still evaluated as "
         "Green-Lagrange strains of the solution");
  v.number("steady_state_change_mm", steady_state_change_m, Unit::kMillimetre, {0, 1e3},
           "time-stepping runs: end once the largest weighted coordinate change over one step (positions, and "
           "transverse gradients x h/2) is at most this, after the pressure ramp; 0: run to end_time_s. The output "
           "records where and why it stopped (docs/surface_output.md)");
  v.number("checkpoint_interval_s", checkpoint_interval_s, Unit::kSecond, {0, 86400},
           "wall time between checkpoints <out>.checkpoint (0: after every step); a rerun of the same command "
           "continues from the last one (docs/surface_output.md, \"Checkpoints\")");
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
  v.text_list("node_sets", node_sets, "",
              "named node sets of `mesh`, each 'NAME: box XMIN YMIN ZMIN XMAX YMAX ZMAX' (mm), 'NAME: plane NX NY NZ D "
              "[TOL]' (nodes with |n.x - D| <= TOL, n normalised, D and TOL in mm, TOL 0.001 by default), 'NAME: nodes "
              "I J ...' (0-based indices), 'NAME: all', 'NAME: group G' (the nodes of the faces after an OBJ 'g' line "
              "naming G), 'NAME: vtk_point_field F V' (the nodes whose scalar point field F of a .vtk mesh equals V) or "
              "'NAME: vtk_cell_field F V' (the nodes of the quads whose scalar cell field F equals V)");
  v.text_list("constraints", constraints, "",
              "constraints on node sets, each 'SET: C C ... [= V V ...]' with C one of ux uy uz dx dy dz (global "
              "position and director components; u = ux uy uz, d = dx dy dz, all = both): the components are held at "
              "their reference value (effect fixed_nodes) or moved by V (mm for u, dimensionless for d), ramped like "
              "point_load_n or following 'history H' at the end (effect prescribed_displacement); 'SET: C C ... frame F' reads "
              "the components in a local frame instead (no values; F = 'normal NX NY NZ': first axis n, e.g. an oblique "
              "symmetry plane 'ux dx frame normal ...'; 'rotation AX AY AZ DEG': the global axes rotated by DEG about A; "
              "'cylindrical PX PY PZ AX AY AZ': radial, circumferential, axial about the axis through P [mm] along A); "
              "the reactions are written per constraint (docs/surface_output.md)");
  v.text_list("loads", loads, "",
              "loads on node sets (effect point_loads, ramped like point_load_n), each 'SET: force FX FY FZ' (total "
              "[N], equal shares), 'SET: force_per_node FX FY FZ' [N], 'SET: traction TX TY TZ' (fixed direction, "
              "MPa, on the quads with all four nodes in SET, consistent nodal forces) or 'SET: gravity GX GY GZ' "
              "(m/s^2: body force density_kg_per_m3 x g per unit volume on those quads) or 'SET: body_force FX FY FZ' "
              "(N/mm^3, per unit volume, on those quads); each may end with 'history H' (a name of `histories`; "
              "without one it ramps like point_load_n)");
  v.text_list("histories", histories, "",
              "time histories of loads and prescribed constraint values (items ending 'history H'), each 'H: ramp T' "
              "(factor t / T, 1 after T; T in s, > 0) or 'H: table T0 F0 T1 F1 ...' ((time [s] >= 0, strictly "
              "increasing; dimensionless factor) pairs, linear in between, the first factor before T0 and the last "
              "after the last time); the factor multiplies the load or the prescribed value");
  v.effect_list("effects", effects, "surface", "surface effects to simulate in this scenario").required();
}

StageDescriptor surface_stage_descriptor() {
  StageDescriptor d;
  d.name = "surface";
  d.takes_allow_partial = true;
  d.executable = "arthrosim-surface";
  d.summary = "ANCF shells on foundations, osmotic pressure, mesh contact, HHT; one run per scenario";
  d.block = block_schema_with_instances<SurfaceScenarioOptions>(
      "surface", "options and scenarios of the deformable-surface stage", "scenarios",
      "the scenarios to run, each with its own effects", "scenario");
  d.outputs = {"surface"};
  for (const common::EffectInfo& e : common::known_effects())
    if (e.stage == common::EffectStage::kSurface)
      d.effects.push_back({std::string(e.name), "surface", std::string(e.description)});
  d.no_runs = "a 'surface' block with at least one scenario";
  d.runs = [](const common::Scene& scene, const std::filesystem::path& out) {
    std::vector<StageStep> runs;
    const std::filesystem::path prepared = out / "prepared.h5", kinematics = out / "kinematics.h5";
    for (const common::BlockInstance& sc : scene.instances("surface")) {
      StageStep s;
      s.name = "surface." + sc.name;
      s.executable = "arthrosim-surface";
      s.provides = {"surface"};
      s.origin = "scenario '" + sc.name + "'";
      s.line = sc.line;
      s.column = sc.column;
      s.inputs.emplace_back("prepared.h5", prepared);
      s.arguments = {"--prepared", prepared.string()};
      if (sc.wants("imposed_kinematics")) {
        s.inputs.emplace_back("kinematics.h5", kinematics);
        s.input_reasons["kinematics.h5"] = "uses imposed_kinematics";
        s.arguments.insert(s.arguments.end(), {"--kinematics", kinematics.string()});
      }
      s.options = sc.options.canonical();
      s.effects = sc.effects;
      add_path_inputs(sc.options, s);
      const std::filesystem::path file = out / ("surface_" + sc.name + ".h5");
      s.outputs = {file};
      s.arguments.insert(s.arguments.end(),
                         {"--scene", scene.file.string(), "--scenario", sc.name, "--out", file.string()});
      runs.push_back(std::move(s));
    }
    return runs;
  };
  d.check = [](const common::Scene& scene) {
    // Without imposed kinematics nothing sets the run's duration.
    for (const common::BlockInstance& sc : scene.instances("surface")) {
      if (!sc.wants("imposed_kinematics") && !sc.options.has("end_time_s"))
        throw common::InputError(scene.file.string(), sc.line, sc.column,
                                 "scenario '" + sc.name +
                                     "' does not use imposed_kinematics, so it needs 'end_time_s' (in the scenario or "
                                     "the surface block)");
      surface_from_scene(scene, sc.name);  // every other rule between its keys
    }
  };
  d.key_outputs = [](const std::string& run, const std::filesystem::path& dir, const std::filesystem::path& ref) {
    const std::string file = "surface_" + run.substr(run.find('.') + 1) + ".h5";
    return study::surface_metrics(dir / file, ref / file);
  };
  return d;
}

SurfaceScenarioConfig surface_from_scene(const common::Scene& scene, const std::string& scenario) {
  const std::vector<common::BlockInstance>& scenarios = scene.instances("surface");
  const common::BlockInstance* sc = nullptr;
  if (!scenario.empty()) {
    sc = &scene.require_instance("surface", scenario);
  } else {
    if (scenarios.size() != 1)
      throw common::InputError(scene.file.string() + ": error: the scene has " + std::to_string(scenarios.size()) +
                               " scenarios; choose one with --scenario");
    sc = &scenarios.front();
  }
  const common::OptionBlock& o = sc->options;  // where each value was written (messages)
  const std::string file = scene.file.string();
  SurfaceScenarioConfig c;
  c.scene_file = scene.file;
  c.name = sc->name;
  c.line = sc->line;
  c.effects = sc->effects;
  c.options = common::read_options<SurfaceScenarioOptions>(o);
  c.canonical_options = o.canonical_text();
  c.surfaces_line = o.value("surfaces").line;
  const SurfaceScenarioOptions& opt = c.options;
  auto wants = [&](const char* e) { return sc->wants(e); };
  c.moving = wants("imposed_kinematics");
  c.generic = !opt.mesh.empty();
  c.contact = wants("mesh_contact");
  c.steady = opt.steady_state;
  c.quasi_static = c.steady || !wants("inertia");

  if (const std::string bad = opt.physics.check_material(); !bad.empty()) {
    int line = sc->line;
    for (const char* k : {"shell_thickness_mm", "youngs_modulus_mpa", "poisson_ratio"})
      if (bad.rfind(k, 0) == 0 && o.has(k)) line = o.value(k).line;
    throw common::InputError(file, line, "scenario '" + sc->name + "': " + bad);
  }
  if (!opt.end_time_s && !c.moving)
    throw common::InputError(file, sc->line, "scenario '" + sc->name + "' needs end_time_s (it has no imposed_kinematics)");
  if (opt.end_time_s && !(*opt.end_time_s > 0))
    throw common::InputError(file, sc->line, "scenario '" + sc->name + "': nothing to simulate (end time 0)");
  // osmotic_ramp_s: without imposed kinematics the osmotic pressure rises
  // over this time, by the same smoothstep the seating ramp uses with
  // imposed kinematics (SurfaceParameters::osmotic_ramp_s, set from
  // seating_time_s when bones move).
  const double osmotic_ramp = opt.physics.osmotic_ramp_s;
  if (osmotic_ramp > 0) {
    if (c.moving)
      throw common::InputError(file, o.value("osmotic_ramp_s").line,
                               "scenario '" + sc->name + "': osmotic_ramp_s is for scenarios without "
                               "imposed_kinematics (with them the pressure rises over seating_time_s)");
    if (osmotic_ramp > *opt.end_time_s)
      throw common::InputError(file, o.value("osmotic_ramp_s").line,
                               "scenario '" + sc->name + "': osmotic_ramp_s (" + std::to_string(osmotic_ramp) +
                                   " s) exceeds end_time_s (" + std::to_string(*opt.end_time_s) +
                                   " s): the pressure would never reach osmotic_pressure_mpa");
  }
  if (opt.integrator.linear && !c.steady)
    throw common::InputError(file, o.value("linear").line,
                             "scenario '" + sc->name + "': linear: true is a steady-state analysis (one solve at "
                             "end_time_s); add steady_state: true");
  if (opt.integrator.linear && c.contact)
    throw common::InputError(file, o.value("linear").line,
                             "scenario '" + sc->name + "': linear: true cannot be combined with mesh_contact");
  if (opt.steady_state_change_m > 0 && c.steady)
    throw common::InputError(file, o.value("steady_state_change_mm").line,
                             "scenario '" + sc->name + "': steady_state_change_mm stops a time-stepping run; "
                             "it has no meaning with steady_state: true");
  for (const char* e : {"fixed_nodes", "point_loads", "pressure", "prescribed_displacement"}) {
    if (wants(e) && !c.generic)
      throw common::InputError(file, sc->line, "scenario '" + sc->name + "': effect '" + e + "' needs a generic `mesh`");
  }
  if (c.contact && c.generic)
    throw common::InputError(file, sc->line,
                             "scenario '" + sc->name +
                                 "': mesh_contact needs the prepared model's surfaces, not a generic `mesh`");
  auto require = [&](const char* key, const char* effect) {
    if (wants(effect) && !o.has(key))
      throw common::InputError(file, sc->line,
                               "scenario '" + sc->name + "': effect '" + effect + "' needs `" + key + "`");
  };
  // Named sets, constraints and loads (generic mesh only).
  for (const auto& [key, items] : {std::pair<const char*, const std::vector<std::string>*>{"node_sets", &opt.node_sets},
                                    {"constraints", &opt.constraints},
                                    {"loads", &opt.loads},
                                    {"histories", &opt.histories}})
    if (!items->empty() && !c.generic)
      throw common::InputError(file, o.value(key).line, "scenario '" + sc->name + "': `" + key + "` needs a generic `mesh`");
  auto parse_list = [&](const char* key, const std::vector<std::string>& items, auto parse, auto& out) {
    for (const std::string& item : items) {
      try {
        out.push_back(parse(item));
      } catch (const std::invalid_argument& e) {
        throw common::InputError(file, o.value(key).line, "scenario '" + sc->name + "': " + key + ": " + e.what());
      }
    }
  };
  parse_list("node_sets", opt.node_sets, cartilage::parse_node_set, c.node_sets);
  parse_list("constraints", opt.constraints, cartilage::parse_constraint, c.constraints);
  parse_list("loads", opt.loads, cartilage::parse_load, c.loads);
  parse_list("histories", opt.histories, cartilage::parse_history, c.histories);
  for (std::size_t i = 0; i < c.histories.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (c.histories[i].name == c.histories[j].name)
        throw common::InputError(file, o.value("histories").line,
                                 "scenario '" + sc->name + "': history '" + c.histories[i].name + "' defined twice");
  auto known_history = [&](const std::string& name, const char* key) {
    if (name.empty()) return;
    for (const auto& h : c.histories)
      if (h.name == name) return;
    std::string have;
    for (const auto& h : c.histories) have += (have.empty() ? "" : ", ") + h.name;
    throw common::InputError(file, o.value(key).line,
                             "scenario '" + sc->name + "': " + key + ": unknown history '" + name + "' (histories: " +
                                 (have.empty() ? "none" : have) + ")");
  };
  for (const auto& d : c.constraints) known_history(d.history, "constraints");
  for (const auto& d : c.loads) known_history(d.history, "loads");
  for (std::size_t i = 0; i < c.node_sets.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (c.node_sets[i].name == c.node_sets[j].name)
        throw common::InputError(file, o.value("node_sets").line,
                                 "scenario '" + sc->name + "': node set '" + c.node_sets[i].name + "' defined twice");
  auto known_set = [&](const std::string& name, const char* key) {
    for (const auto& d : c.node_sets)
      if (d.name == name) return;
    std::string have;
    for (const auto& d : c.node_sets) have += (have.empty() ? "" : ", ") + d.name;
    throw common::InputError(file, o.value(key).line,
                             "scenario '" + sc->name + "': " + key + ": unknown node set '" + name + "' (node_sets: " +
                                 (have.empty() ? "none" : have) + ")");
  };
  bool fixed_sets = false, prescribed_sets = false;
  for (const auto& d : c.constraints) {
    known_set(d.set, "constraints");
    (d.prescribed() ? prescribed_sets : fixed_sets) = true;
    if (d.frame != cartilage::ConstraintDefinition::Frame::kGlobal && c.contact)
      throw common::InputError(file, o.value("constraints").line,
                               "scenario '" + sc->name + "': local-frame constraints cannot be combined with mesh_contact "
                               "(the contact tangent is added outside the surface's constraint projection)");
  }
  for (const auto& d : c.loads) known_set(d.set, "loads");
  // Every constraint and load must be built by a listed effect.
  if (fixed_sets && !wants("fixed_nodes"))
    throw common::InputError(file, o.value("constraints").line,
                             "scenario '" + sc->name + "': constraints without values need effect fixed_nodes");
  if (prescribed_sets && !wants("prescribed_displacement"))
    throw common::InputError(file, o.value("constraints").line,
                             "scenario '" + sc->name + "': constraints with values need effect prescribed_displacement");
  if (!c.loads.empty() && !wants("point_loads"))
    throw common::InputError(file, o.value("loads").line, "scenario '" + sc->name + "': loads need effect point_loads");
  if (!fixed_sets) require("fixed_box_mm", "fixed_nodes");
  if (c.loads.empty()) {
    require("load_box_mm", "point_loads");
    require("point_load_n", "point_loads");
  }
  require("pressure_mpa", "pressure");
  if (!prescribed_sets) {
    require("displaced_box_mm", "prescribed_displacement");
    require("displacement_mm", "prescribed_displacement");
  }
  if (c.generic) {
    std::string ext = opt.mesh.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return std::tolower(ch); });
    if (ext != ".obj" && ext != ".vtk")
      throw common::InputError(file, o.value("mesh").line,
                               "mesh '" + opt.mesh.string() + "': expected an .obj or .vtk quad mesh");
  } else {
    c.surfaces = opt.surfaces;
  }
  // Contact pairs: "a:b", both simulated.
  if (c.contact) {
    for (const std::string& pr : opt.contact_pairs) {
      const auto colon = pr.find(':');
      const std::string a = pr.substr(0, colon), b = colon == std::string::npos ? "" : pr.substr(colon + 1);
      const auto ia = std::find(c.surfaces.begin(), c.surfaces.end(), a);
      const auto ib = std::find(c.surfaces.begin(), c.surfaces.end(), b);
      if (colon == std::string::npos || ia == c.surfaces.end() || ib == c.surfaces.end() || ia == ib)
        throw common::InputError(file, o.value("contact_pairs").line,
                                 "contact pair '" + pr + "': expected 'a:b' with two different surfaces of this "
                                 "scenario's `surfaces`");
      c.contact_pairs.emplace_back(static_cast<int>(ia - c.surfaces.begin()), static_cast<int>(ib - c.surfaces.begin()));
      c.contact_pair_names.push_back(pr);
    }
    if (c.contact_pairs.empty())
      throw common::InputError(file, sc->line, "scenario '" + sc->name + "' lists mesh_contact but contact_pairs is empty");
  }
  // osmotic_surfaces: which surfaces carry osmotic_pressure (empty: all).
  if (!c.generic && wants("osmotic_pressure")) {
    for (const std::string& name : opt.osmotic_surfaces)
      if (std::find(c.surfaces.begin(), c.surfaces.end(), name) == c.surfaces.end())
        throw common::InputError(file, o.value("osmotic_surfaces").line,
                                 "osmotic surface '" + name + "' is not one of this scenario's `surfaces`");
  }
  if (opt.contact.faded_vertex_weights && opt.contact.rim_vertices)
    throw common::InputError(file + ": error: scenario '" + sc->name +
                             "': contact_rim_vertices applies to contact_vertex_weights: tributary only (faded "
                             "weights give rim nodes their own, reduced weight)");
  if (c.contact && opt.contact.augmentations > 0 && opt.steady_state_change_m > 0)
    throw common::InputError(file, o.value("contact_augmentations").line,
                             "scenario '" + sc->name + "': contact_augmentations cannot be combined with "
                             "steady_state_change_mm (the augmented step is solved again from its start)");
  if (opt.integrator.reuse_factorization && c.contact)
    throw common::InputError(file, o.value("newton_reuse_factorization").line,
                             "scenario '" + sc->name + "': newton_reuse_factorization cannot be combined with "
                             "mesh_contact (its Newton line search needs a fresh tangent)");
  return c;
}

namespace {

// ---------------------------------------------------------------------------
// build: the shell models of one scenario, their coupled system and the
// integrator's options, from the scenario and its input files.
// ---------------------------------------------------------------------------
struct SurfaceBuild {
  const SurfaceScenarioConfig* config = nullptr;
  std::vector<double> kin_times;  // imposed kinematics: the kinematics file's frame times
  std::string partial_input;      // "" or the PARTIAL INPUT line (--allow-partial, common/file_check.h)
  double end_time = 0, seating = 0, total_time = 0, dt = 0, interval = 0;
  cartilage::SurfaceParameters par;
  common::EffectLedger ledger;
  std::vector<SurfaceRun> runs;
  std::unique_ptr<cartilage::CoupledShellSystem> system;
  numerics::IntegratorOptions iopt;
};

std::unique_ptr<SurfaceBuild> build_surface_stage(const SurfaceScenarioConfig& c, const SurfaceStageOptions& options) {
  auto b = std::make_unique<SurfaceBuild>();
  b->config = &c;
  const SurfaceScenarioOptions& opt = c.options;
  const std::string file = c.scene_file.string();
  b->par = opt.physics;
  b->par.osmotic_ramp_s = 0;  // below: osmotic_ramp_s, or the seating ramp
  if (opt.periphery_normal == SurfaceScenarioOptions::PeripheryNormal::kFoundation)
    b->par.periphery_tie_N_m3 = opt.periphery_tie_N_m3;
  cartilage::SurfaceParameters& par = b->par;
  // ---- kinematics (imposed_kinematics) -------------------------------------
  std::unique_ptr<musculoskeletal::KinematicsFileReader> kin;
  if (c.moving) {
    if (options.kinematics.empty())
      throw common::InputError(file, c.line, "scenario '" + c.name + "' lists imposed_kinematics: give --kinematics");
    kin = std::make_unique<musculoskeletal::KinematicsFileReader>(options.kinematics);
    b->partial_input = kin->require_complete(options.allow_partial);  // kind, version, completeness
    const Eigen::VectorXd t = kin->time();
    b->kin_times.assign(t.data(), t.data() + t.size());
    if (b->kin_times.empty()) throw common::InputError(options.kinematics + ": error: dataset /time has no frame");
  } else if (!options.kinematics.empty()) {
    common::log_warn("--kinematics " + options.kinematics + " is not used: scenario '" + c.name +
                     "' does not list imposed_kinematics");
  }
  const std::vector<double>& kin_times = b->kin_times;
  auto bone_motion = [&](const std::string& bone) {
    return cartilage::interpolated_bone_motion(
        kin_times, kin->body_poses(bone),
        options.kinematics + ": " + musculoskeletal::KinematicsFileReader::body_poses_dataset(bone));
  };

  const double end_time = opt.end_time_s ? *opt.end_time_s : kin_times.back() - kin_times.front();
  if (!(end_time > 0))
    throw common::InputError(file, c.line, "scenario '" + c.name + "': nothing to simulate (end time 0)");
  b->end_time = end_time;
  b->dt = opt.integrator.dt_s;
  double interval = opt.output_interval_s;
  if (c.steady) interval = end_time;
  if (interval < b->dt) interval = b->dt;
  b->interval = interval;

  b->iopt = opt.integrator;
  numerics::IntegratorOptions& iopt = b->iopt;
  iopt.same_tolerances();
  iopt.quasi_static = c.quasi_static;
  iopt.dt_s = c.steady ? end_time : b->dt;
  if (opt.physics.osmotic_ramp_s > 0) par.osmotic_ramp_s = opt.physics.osmotic_ramp_s;

  // ---- models -------------------------------------------------------------
  b->ledger = common::EffectLedger("surface:" + c.name);
  common::EffectLedger& ledger = b->ledger;
  std::vector<SurfaceRun>& runs = b->runs;
  if (c.generic) {
    SurfaceRun r;
    const std::string mesh_file = opt.mesh.string();
    std::string ext = opt.mesh.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return std::tolower(ch); });
    common::Points3 given_normals;
    cartilage::FaceGroups groups;         // OBJ 'g' groups (node sets "NAME: group G")
    std::vector<common::VtkField> fields;  // VTK fields (node sets "NAME: vtk_point_field F V", ...)
    r.input.mesh = ext == ".vtk" ? common::read_quad_vtk(mesh_file, {}, &fields)
                                 : common::read_quad_obj(mesh_file, {}, &given_normals, &groups);
    r.input.name = opt.mesh.stem().string();
    r.input.mesh.name = r.input.name;
    // Directors: the OBJ's vertex normals when given, else area-weighted quad normals.
    r.input.normals = given_normals.rows() > 0 ? given_normals : cartilage::quad_mesh_vertex_normals(r.input.mesh);
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
    // Named sets, their constraints and loads.
    std::map<std::string, std::vector<int>> sets;
    for (const cartilage::NodeSetDefinition& d : c.node_sets) {
      try {
        sets[d.name] = cartilage::select_nodes(d, r.input.mesh, groups, fields);
      } catch (const std::invalid_argument& e) {
        throw common::InputError(file, c.line, "scenario '" + c.name + "': " + e.what());
      }
      if (sets[d.name].empty())
        throw common::InputError(file, c.line,
                                 "scenario '" + c.name + "': node set '" + d.name + "' holds no node of " + mesh_file);
    }
    for (const cartilage::ConstraintDefinition& d : c.constraints) g.constraints.push_back({d, sets.at(d.set)});
    for (const cartilage::HistoryDefinition& h : c.histories) g.histories[h.name] = h;
    for (const cartilage::LoadDefinition& d : c.loads) {
      const std::vector<int>& nodes = sets.at(d.set);
      Eigen::MatrixXd f;
      using K = cartilage::LoadDefinition::Kind;
      if (d.kind == K::kForce || d.kind == K::kForcePerNode) {
        const double share = d.kind == K::kForce ? 1.0 / static_cast<double>(nodes.size()) : 1.0;
        for (int n : nodes) (d.history.empty() ? g.set_loads_N : g.history_loads_N[d.history]).emplace_back(n, share * d.vector);
        continue;
      }
      const Eigen::Vector3d per_area =
          d.kind == K::kTraction     ? d.vector
          : d.kind == K::kBodyForce ? Eigen::Vector3d(par.shell_thickness_m * d.vector)
                                    : Eigen::Vector3d(par.material.density_kg_m3 * par.shell_thickness_m * d.vector);
      f = cartilage::consistent_area_loads(r.input.mesh, nodes, per_area);
      if (f.isZero(0.0))
        throw common::InputError(file, c.line,
                                 "scenario '" + c.name + "': load on node set '" + d.set +
                                     "': no quad has all four nodes in the set");
      for (int n = 0; n < f.rows(); ++n)
        if (!f.row(n).isZero(0.0))
          (d.history.empty() ? g.set_loads_N : g.history_loads_N[d.history]).emplace_back(n, f.row(n).transpose());
    }
    r.model = cartilage::build_surface_model(r.input, par, c.effects, cartilage::BoneMotion::fixed(), &ledger);
    r.basis = cartilage::node_strain_basis(*r.model);
    r.summary.name = r.input.name;
    r.summary.nodes = r.model->num_nodes();
    r.summary.elements = r.model->num_elements();
    runs.push_back(std::move(r));
  }
  if (!c.generic && options.prepared.empty())
    throw common::InputError(options.scene + ": error: scenario '" + c.name +
                             "' simulates the prepared model's surfaces: give --prepared");
  std::unique_ptr<common::PreparedModelReader> prepared_file;
  std::vector<std::string> names;
  if (!c.generic) {
    prepared_file = std::make_unique<common::PreparedModelReader>(options.prepared);
    names = prepared_file->surface_names();
  }
  const std::vector<std::string>& osmotic_surfaces =
      !c.generic && std::find(c.effects.begin(), c.effects.end(), "osmotic_pressure") != c.effects.end()
          ? opt.osmotic_surfaces
          : std::vector<std::string>{};
  b->seating = c.moving ? opt.seating_time_s : 0.0;
  // With imposed kinematics the pressure rises during the seating ramp (a
  // step load on the resting shells would start a dynamic inflation).
  if (c.moving) par.osmotic_ramp_s = b->seating;
  const double seat_offset = opt.seating_offset_m;
  for (const std::string& name : c.surfaces) {
    const common::PreparedModelReader& prepared = *prepared_file;
    if (std::find(names.begin(), names.end(), name) == names.end()) {
      std::string have;
      for (const auto& n : names) have += (have.empty() ? "" : ", ") + n;
      throw common::InputError(file, c.surfaces_line,
                               "surface '" + name + "' is not in the prepared model " + options.prepared +
                                   " (it has: " + have + ")");
    }
    SurfaceRun r;
    r.input = read_prepared_surface(prepared, name);
    r.bone_name = prepared.bone(name);
    if (c.moving) {
      // Prepared coordinates are bone-frame coordinates (the model frame at
      // q = 0, docs/kinematics_file.md); the shell's reference is the surface
      // placed by the bone's pose at t = 0 (after the seating offset).
      const Eigen::Vector3d offset = r.bone_name == "femur" ? Eigen::Vector3d::Zero()
                                                            : Eigen::Vector3d(0, seat_offset, 0);
      r.bone = seated(bone_motion(r.bone_name), b->seating, offset);
      r.X_WB0 = r.bone.pose(0.0);
      r.input.mesh.V = ((r.input.mesh.V * r.X_WB0.linear().transpose()).rowwise() + r.X_WB0.translation().transpose()).eval();
      r.input.normals = (r.input.normals * r.X_WB0.linear().transpose()).eval();
    }
    cartilage::SurfaceParameters p = par;
    if (opt.foundation_from_thickness && std::find(c.effects.begin(), c.effects.end(), "foundation_springs") != c.effects.end()) {
      const Eigen::VectorXd h = prepared.quad_thickness(name);
      p.foundation_stiffness_per_node_N_m3 = cartilage::matched_foundation_stiffness(
          h, opt.matched_youngs_modulus_Pa, opt.matched_poisson_ratio,
          options.prepared + ": dataset " + common::PreparedModelReader::quad_thickness_dataset(name));
    }
    std::vector<std::string> effects = c.effects;
    if (!osmotic_surfaces.empty() &&
        std::find(osmotic_surfaces.begin(), osmotic_surfaces.end(), name) == osmotic_surfaces.end())
      effects.erase(std::remove(effects.begin(), effects.end(), "osmotic_pressure"), effects.end());
    r.model = cartilage::build_surface_model(r.input, p, effects, r.bone, &ledger);
    if (c.moving) r.model->set_motion_predictor(r.bone);
    r.basis = cartilage::node_strain_basis(*r.model);
    r.summary.name = name;
    r.summary.nodes = r.model->num_nodes();
    r.summary.elements = r.model->num_elements();
    runs.push_back(std::move(r));
  }
  b->total_time = end_time + b->seating;
  // One system of all surfaces (side by side, exactly the separate models
  // when there is no contact), coupled by the contact pairs.
  std::vector<ShellModel*> model_ptrs;
  std::vector<std::string> model_names;
  for (SurfaceRun& r : runs) {
    model_ptrs.push_back(r.model.get());
    model_names.push_back(r.summary.name);
  }
  b->system = std::make_unique<cartilage::CoupledShellSystem>(model_ptrs, model_names);
  b->system->attach_ledger(&ledger);
  for (size_t k = 0; k < c.contact_pairs.size(); ++k)
    b->system->add_contact(c.contact_pair_names[k], c.contact_pairs[k].first, c.contact_pairs[k].second, opt.contact);
  ledger.require_only(c.effects);
  common::log_info(ledger.to_text());

  if (c.contact) iopt.line_search_halvings = 8;  // Newton globalisation for penalty contact
  // Imposed kinematics: each step starts from the surfaces carried by their
  // bones (rigid predictor), so Newton only finds the deformation change.
  if (c.moving)
    iopt.predictor = opt.predictor == SurfaceScenarioOptions::Predictor::kExtrapolated
                         ? numerics::IntegratorOptions::Predictor::kSystemExtrapolated
                         : numerics::IntegratorOptions::Predictor::kSystem;
  return b;
}

}  // namespace

// ---------------------------------------------------------------------------
// run: integrate and record.
// ---------------------------------------------------------------------------
SurfaceStageResult run_surface_stage(const SurfaceStageOptions& options) {
  const double t_start = now_s();
  const common::Scene scene = load_scene(options.scene);
  const SurfaceScenarioConfig config = surface_from_scene(scene, options.scenario);
  std::unique_ptr<SurfaceBuild> built = build_surface_stage(config, options);
  SurfaceBuild& b = *built;
  const SurfaceScenarioConfig& c = config;
  const SurfaceScenarioOptions& opt = c.options;
  std::vector<SurfaceRun>& runs = b.runs;
  cartilage::CoupledShellSystem& system = *b.system;
  numerics::IntegratorOptions& iopt = b.iopt;
  const bool contact = c.contact, moving = c.moving, steady = c.steady;
  const double end_time = b.end_time, seating = b.seating, total_time = b.total_time, dt = b.dt, interval = b.interval;
  const double osmotic_ramp = opt.physics.osmotic_ramp_s, stop_change = opt.steady_state_change_m;
  const std::string file = c.scene_file.string();

  // ---- output file: static part -------------------------------------------
  surface_output::Layout layout;
  layout.scenario = c.name;
  layout.prepared_model = c.generic ? std::string() : options.prepared;
  layout.mesh = c.generic ? opt.mesh.string() : std::string();
  layout.mode = steady ? "steady_state" : (c.quasi_static ? "quasi_static" : "hht");
  layout.seating_time_s = seating;
  layout.frames_expected = static_cast<std::int64_t>(std::floor(total_time / interval + 1e-9)) + 1 +
                           (std::fmod(total_time, interval) > 1e-12 * interval ? 1 : 0);
  layout.steps_expected = static_cast<std::int64_t>(std::ceil(total_time / (steady ? total_time : dt) - 1e-9));
  layout.contact = contact;
  layout.trial_time = moving;
  layout.change = stop_change > 0;
  const int max_augmentations = contact ? opt.contact.augmentations : 0;
  layout.augmentations = max_augmentations > 0;
  layout.contact_pairs = c.contact_pair_names;
  layout.partial_input = b.partial_input;
  std::vector<const char*> argv;
  for (const auto& a : options.argv) argv.push_back(a.c_str());
  surface_output::Writer out(options.out,
                             common::collect_run_metadata("arthrosim-surface", static_cast<int>(argv.size()),
                                                          argv.data(), options.scene, c.canonical_options),
                             layout, b.ledger);
  for (SurfaceRun& r : runs) {
    surface_output::SurfaceGeometry g;
    g.name = r.summary.name;
    g.bone = r.bone_name;
    g.nodes = r.input.mesh.V;
    g.quads = r.input.mesh.Q;
    g.normals = r.basis.n;
    g.basis_a1 = r.basis.a1;
    g.basis_a2 = r.basis.a2;
    g.fixed.resize(r.model->constrained().size() / 6);
    for (size_t i = 0; i < g.fixed.size(); ++i) g.fixed[i] = r.model->constrained()[6 * i] ? 1 : 0;
    out.add_surface(g);
  }
  out.flush();

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
  // Contact state of every pair at q (computed once per step; the frame
  // written after that step reuses it).
  auto contact_reports = [&](const Eigen::VectorXd& qs) {
    std::vector<cartilage::ContactPairReport> reps;
    for (int k = 0; k < system.num_contacts(); ++k) reps.push_back(system.contact_report(k, qs));
    return reps;
  };
  int frames_written = 0;
  // One frame: every surface's fields, the contact forces, then /time (so
  // /time counts complete frames).
  // Reactions of the generic mesh's constraints, per frame: R = F (internal
  // minus applied forces, zero velocity) summed over the set's constrained
  // position coordinates not already counted by an earlier constraint
  // (docs/surface_output.md).
  std::vector<std::vector<std::vector<Eigen::Vector3d>>> reactions(runs.size());
  auto record_reactions = [&](size_t k, const Eigen::VectorXd& q, double t) {
    SurfaceRun& r = runs[k];
    const auto& cons = r.input.generic.constraints;
    if (cons.empty()) return;
    reactions[k].resize(cons.size());
    Eigen::VectorXd F;
    numerics::EvalRequest req;
    req.t = t;
    if (iopt.linear) {
      // linear: true solves the equations linearised at the reference state
      // (constraints applied at t): the reactions are those of the same
      // linear problem, F = F(q0) + K(q0) (q - q0).
      Eigen::VectorXd q0 = r.model->reference_state();
      r.model->apply_constraints(t, q0);
      Eigen::SparseMatrix<double> K;
      req.q = &q0;
      r.model->evaluate_unprojected(req, F, &K);
      F += K * (q - q0);
    } else {
      req.q = &q;
      r.model->evaluate_unprojected(req, F, nullptr);
    }
    // A coordinate held by several constraints counts for the first of them.
    std::vector<char> claimed(static_cast<size_t>(F.size()), 0);
    // With local frames: per node the directions already counted
    // (orthonormal); a constraint counts F's part along its own held
    // position directions orthogonal to those.
    const bool frames = r.model->has_local_frames();
    std::map<int, std::vector<Eigen::Vector3d>> counted;
    for (size_t i = 0; i < cons.size(); ++i) {
      Eigen::Vector3d R = Eigen::Vector3d::Zero();
      if (frames) {
        for (int n : cons[i].nodes) {
          const Eigen::Matrix3d L = cons[i].definition.local_frame(r.model->reference_position(n));
          const Eigen::Vector3d f = F.segment<3>(6 * n);
          for (int j = 0; j < 3; ++j) {
            if (!cons[i].definition.mask[static_cast<size_t>(j)]) continue;
            Eigen::Vector3d a = L.col(j);
            for (const Eigen::Vector3d& b : counted[n]) a -= b.dot(a) * b;
            if (a.norm() < 1e-8) continue;
            a.normalize();
            counted[n].push_back(a);
            R += a.dot(f) * a;
          }
        }
        reactions[k][i].push_back(R);
        continue;
      }
      for (int n : cons[i].nodes)
        for (int j = 0; j < 3; ++j) {
          const size_t dof = static_cast<size_t>(6 * n + j);
          if (!cons[i].definition.mask[static_cast<size_t>(j)] || claimed[dof]) continue;
          claimed[dof] = 1;
          R(j) += F(static_cast<Eigen::Index>(dof));
        }
      reactions[k][i].push_back(R);
    }
  };
  auto write_frame = [&](const Eigen::VectorXd& qs, double t, const std::vector<cartilage::ContactPairReport>& reps) {
    std::vector<Eigen::VectorXd> pressure(runs.size());
    for (size_t k = 0; k < runs.size(); ++k) pressure[k] = Eigen::VectorXd::Zero(runs[k].model->num_nodes());
    surface_output::ContactFrame cf;
    for (int k = 0; k < system.num_contacts(); ++k) {
      const cartilage::ContactPairReport& rep = reps[k];
      const int a = c.contact_pairs[k].first, bb = c.contact_pairs[k].second;
      pressure[a] += rep.pressure_a;
      pressure[bb] += rep.pressure_b;
      const Eigen::Vector3d f_B = runs[bb].bone.pose(t).linear().transpose() * rep.total_force_b;
      cf.force += f_B;
      if (c.contact_pair_names[k].find("medial") != std::string::npos) cf.medial_force += f_B;
      if (c.contact_pair_names[k].find("lateral") != std::string::npos) cf.lateral_force += f_B;
      cf.area += rep.contact_area_m2;
      cf.max_penetration = std::max(cf.max_penetration, rep.counts.max_penetration_m);
    }
    std::vector<surface_output::SurfaceFrame> frames(runs.size());
    for (size_t k = 0; k < runs.size(); ++k) {
      SurfaceRun& r = runs[k];
      surface_output::SurfaceFrame& fr = frames[k];
      const Eigen::VectorXd q = system.segment(static_cast<int>(k), qs);
      const Eigen::Isometry3d T = rigid(r, t);
      fr.displacement = cartilage::nodal_displacement(*r.model, q, T);
      fr.deflection = cartilage::nodal_deflection(*r.model, q, T);
      const cartilage::NodalStrains st = cartilage::nodal_strains(*r.model, r.basis, q);
      record_reactions(k, q, t);
      common::check_finite(fr.displacement, "surface " + r.summary.name + ": displacement at t = " + std::to_string(t));
      common::check_finite(st.E, "surface " + r.summary.name + ": strain at t = " + std::to_string(t));
      fr.E = st.E;
      fr.e1 = st.e1;
      fr.e1_dir = st.e1_dir;
      fr.e2 = st.e2;
      if (contact) fr.contact_pressure = pressure[k];
      const Eigen::VectorXd& w = fr.deflection;
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
    out.append_frame(t, moving ? t - seating + b.kin_times.front() : 0.0, frames, contact ? &cf : nullptr);
    ++frames_written;
  };

  // ---- integrate ----------------------------------------------------------
  Eigen::VectorXd q0(system.num_dofs());
  for (int k = 0; k < system.num_models(); ++k)
    q0.segment(system.offset(k), runs[k].model->num_dofs()) = runs[k].model->reference_state();
  // The surfaces must start apart (or the first frame's overlap is applied
  // as an impact): the seating offset has to exceed the initial overlap.
  std::vector<cartilage::ContactPairReport> reports = contact_reports(q0);
  for (int k = 0; k < system.num_contacts(); ++k)
    if (reports[k].counts.vertex_face + reports[k].counts.edge_edge > 0)
      throw common::InputError(file, c.line,
                               "scenario '" + c.name + "': contact pair " + c.contact_pair_names[k] + " overlaps by " +
                                   std::to_string(reports[k].counts.max_penetration_m * 1e3) +
                                   " mm at t = 0; increase seating_offset_mm (now " +
                                   std::to_string(opt.seating_offset_m * 1e3) + " mm)");
  // Rejections are reported as they happen: one output step may hold many
  // halved sub-steps, and the run must not look idle meanwhile.
  long rejections_logged = 0;
  iopt.on_rejection = [&](const std::string& rejection) {
    common::log_warn("surface " + c.name + ": step rejected and halved (" + std::to_string(++rejections_logged) +
                     " so far): " + rejection);
  };
  HhtIntegrator integrator(system, iopt);
  integrator.initialize(0.0, q0);
  common::log_info("scenario " + c.name + ": " +
                   (steady ? std::string("steady state (static equilibrium at t = ") + std::to_string(end_time) + " s)"
                           : (c.quasi_static ? "quasi-static" : "HHT alpha " + std::to_string(iopt.alpha)) +
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
  common::Progress progress("surface " + c.name, std::max<std::int64_t>(layout.steps_expected, 1), popt);
  const double step = steady ? total_time : dt;
  const double limit = opt.penetration_limit;
  const bool stop_on_penetration = opt.stop_on_penetration;
  double t = 0;
  int k_out = 1;
  // ---- checkpoint and resume (pipelines/surface_checkpoint.h) -----------------
  // Tied to this run's identity (program, command line, options, the bytes
  // of the scene, prepared model, kinematics and mesh, the runner's key).
  const std::filesystem::path checkpoint_path = common::checkpoint_name(options.out);
  SurfaceCheckpoint checkpoint;
  checkpoint.identity = common::run_identity(
      options.argv, c.canonical_options,
      {{options.scene, "--scene"}, {options.prepared, "--prepared"}, {options.kinematics, "--kinematics"},
       {opt.mesh, "mesh"}});
  // A steady-state solve has no step boundary.
  const bool checkpoints = !steady;
  // contact_augmentations: every pair's multipliers (saved with each
  // checkpoint and each frame: a frame's contact pressures depend on them).
  auto current_multipliers = [&] {
    SurfaceCheckpoint::PairMultipliers m;
    for (int k = 0; k < system.num_contacts(); ++k) m.push_back(system.contact_multipliers(k));
    return m;
  };
  // (A checkpoint's pair counts are checked before it is used.)
  auto set_multipliers = [&](const SurfaceCheckpoint::PairMultipliers& m) {
    for (int k = 0; k < system.num_contacts(); ++k) system.set_contact_multipliers(k, m[k]);
  };
  common::CheckpointClock checkpoint_clock(opt.checkpoint_interval_s);
  int checkpoints_written = 0;
  if (checkpoints && std::filesystem::exists(checkpoint_path)) {
    std::string why;
    std::optional<SurfaceCheckpoint> found = read_surface_checkpoint(checkpoint_path, why);
    if (found && found->identity != checkpoint.identity)
      why = "it belongs to another run (inputs, options, command line or build differ)";
    else if (found) {
      // contact_augmentations: the multipliers of every pair, now and per frame.
      const std::size_t pairs = max_augmentations > 0 ? static_cast<std::size_t>(system.num_contacts()) : 0;
      bool match = found->multipliers.size() == pairs &&
                   found->frame_multipliers.size() == (pairs > 0 ? found->frame_times.size() : 0);
      for (const SurfaceCheckpoint::PairMultipliers& m : found->frame_multipliers) match = match && m.size() == pairs;
      if (!match) why = "its contact multipliers do not match the scenario's contact pairs";
    }
    if (found && why.empty()) {
      checkpoint = std::move(*found);
      common::log_info("resuming from the checkpoint " + checkpoint_path.string() + ": t = " +
                       std::to_string(checkpoint.t) + " s, steps done: " + std::to_string(checkpoint.steps.size()) +
                       ", frames written: " + std::to_string(checkpoint.frame_times.size() + 1) + " (taken from it)");
      // What the run wrote before, written again: frames from their coordinates.
      const bool augmented = max_augmentations > 0;
      for (std::size_t i = 0; i < checkpoint.frame_times.size(); ++i) {
        if (augmented) set_multipliers(checkpoint.frame_multipliers[i]);
        write_frame(checkpoint.frame_q[i], checkpoint.frame_times[i],
                    contact ? contact_reports(checkpoint.frame_q[i]) : reports);
      }
      if (augmented) set_multipliers(checkpoint.multipliers);
      for (const surface_output::StepRecord& sr : checkpoint.steps) {
        out.append_step(sr);
        progress.step();
      }
      system.restore(checkpoint.pattern_q, checkpoint.system);
      integrator.restore(checkpoint.hht);
      t = checkpoint.t;
      k_out = checkpoint.k_out;
      penetration_warnings = checkpoint.penetration_warnings;
      unfaded_over = checkpoint.unfaded_over;
      worst_ratio = checkpoint.worst_ratio;
      worst_unfaded_ratio = checkpoint.worst_unfaded_ratio;
      rejections_logged = checkpoint.rejections_logged;
      if (contact) reports = contact_reports(integrator.q());
    } else {
      common::log_warn("not resuming from " + checkpoint_path.string() + ": " + why + "; starting over");
      std::filesystem::remove(checkpoint_path);
      const auto identity = checkpoint.identity;
      checkpoint = SurfaceCheckpoint();  // every other member as a fresh run has it
      checkpoint.identity = identity;
    }
  }
  // steady_state_change_mm: each step is taken by advance_to_steady_state
  // over that one step (same halving rules as advance_to), which returns
  // whether the step's weighted change was at most stop_change. The stop is
  // not accepted before the pressure ramp (or seating) has ended: at the
  // start of a smoothstep ramp the load barely changes.
  bool stopped_steady = false;
  long total_augmentations = 0, total_augmentation_iterations = 0;  // contact_augmentations
  double last_change = std::numeric_limits<double>::quiet_NaN();
  long last_iterations = 0, last_rejections = 0;
  SurfaceStageResult res;
  if (!checkpoint.steps.empty()) {  // resumed
    total_augmentations = checkpoint.total_augmentations;
    total_augmentation_iterations = checkpoint.total_augmentation_iterations;
    last_change = checkpoint.last_change;
    last_iterations = checkpoint.last_iterations;
    last_rejections = checkpoint.last_rejections;
    res.final_residual_N = checkpoint.final_residual_N;
    res.residual_tolerance_N = checkpoint.residual_tolerance_N;
    res.max_penetration_m = checkpoint.max_penetration_m;
    res.contact_steps = checkpoint.contact_steps;
    res.active_contacts_sum = checkpoint.active_contacts_sum;
  }
  try {
    while (t < total_time * (1 - 1e-12)) {
      const double t_out = std::min(k_out * interval, total_time);
      while (t < t_out * (1 - 1e-12)) {
        const double t_next = std::min(t + step, t_out);
        const double w0 = now_s();
        bool at_steady = false;
        int step_augmentations = 0;
        long augmentation_iterations = 0;
        bool reports_current = false;  // `reports` already hold the accepted q's contacts
        if (stop_change > 0) {
          at_steady = integrator.advance_to_steady_state(stop_change, t_next, &last_change) &&
                      t_next >= b.par.osmotic_ramp_s;
        } else if (max_augmentations == 0) {
          integrator.advance_to(t_next);
        } else {
          // Augmented Lagrangian (Uzawa, docs/contact.md): solve the step;
          // while its max penetration exceeds contact_augment_tolerance x its
          // max deflection, set each vertex's multiplier to its contact
          // pressure and solve the step again from its start. The multipliers
          // stay for the next step (warm start).
          const numerics::HhtState start = integrator.state();
          const long iterations0 = integrator.statistics().newton_iterations;
          integrator.advance_to(t_next);
          for (;;) {
            const Eigen::VectorXd& qa = integrator.q();
            reports = contact_reports(qa);
            reports_current = true;
            double pen = 0;
            for (const cartilage::ContactPairReport& rep : reports) pen = std::max(pen, rep.counts.max_penetration_m);
            const double def = max_abs_deflection(qa, t_next);
            if (!(pen > opt.contact.augment_tolerance * def) || step_augmentations == max_augmentations) break;
            for (int k = 0; k < system.num_contacts(); ++k)
              system.set_contact_multipliers(k, system.updated_contact_multipliers(k, qa));
            // restore() rewinds the counters too: keep this attempt's work.
            augmentation_iterations += integrator.statistics().newton_iterations - iterations0;
            reports_current = false;
            integrator.restore(start);
            integrator.advance_to(t_next);
            ++step_augmentations;
          }
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
        surface_output::StepRecord sr;
        sr.time = t_next;
        sr.dt = rec.dt;
        sr.newton_iterations = static_cast<int>(s.newton_iterations - last_iterations + augmentation_iterations);
        sr.augmentations = step_augmentations;
        total_augmentations += step_augmentations;
        total_augmentation_iterations += augmentation_iterations;
        sr.residual_N = rl;
        sr.residual_tolerance_N = res.residual_tolerance_N;
        sr.rejections = static_cast<int>(s.rejected_steps - last_rejections);
        sr.wall_s = wall;
        sr.max_deflection_m = max_def;
        sr.change_m = last_change;
        if (contact) {
          if (!reports_current) reports = contact_reports(integrator.q());
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
          sr.max_penetration_m = pen;
          sr.penetration_ratio = ratio;
          sr.active_contacts = static_cast<int>(active);
          sr.max_rim_depth_m = rim_depth;
          sr.max_unfaded_penetration_m = unfaded;
          sr.unfaded_penetration_ratio = unfaded_ratio;
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
            if (stop_on_penetration) {
              out.append_step(sr);
              throw common::NumericalError("surface " + c.name + ": accuracy rule broken: " + m.str() +
                                           "; raise contact_stiffness_n_per_mm3 or set penetration_action: warn");
            }
            if (penetration_warnings <= 5 || penetration_warnings % 1000 == 0)
              common::log_warn("surface " + c.name + ": " + m.str() + " (warning " +
                               std::to_string(penetration_warnings) + ")");
          }
        }
        out.append_step(sr);
        if (checkpoints) checkpoint.steps.push_back(sr);
        last_iterations = s.newton_iterations;
        last_rejections = s.rejected_steps;
        t = t_next;
        progress.step();
        if (at_steady) {
          stopped_steady = true;
          break;
        }
        if (checkpoints && t < total_time * (1 - 1e-12) && checkpoint_clock.due()) {
          SurfaceCheckpoint& k = checkpoint;
          k.t = t;
          k.k_out = k_out;
          k.penetration_warnings = penetration_warnings;
          k.unfaded_over = unfaded_over;
          k.rejections_logged = rejections_logged;
          k.last_iterations = last_iterations;
          k.last_rejections = last_rejections;
          k.worst_ratio = worst_ratio;
          k.worst_unfaded_ratio = worst_unfaded_ratio;
          k.last_change = last_change;
          k.final_residual_N = res.final_residual_N;
          k.residual_tolerance_N = res.residual_tolerance_N;
          k.max_penetration_m = res.max_penetration_m;
          k.contact_steps = res.contact_steps;
          k.active_contacts_sum = res.active_contacts_sum;
          k.hht = integrator.state();
          k.pattern_q = system.pattern_coordinates();
          if (max_augmentations > 0) k.multipliers = current_multipliers();
          k.total_augmentations = total_augmentations;
          k.total_augmentation_iterations = total_augmentation_iterations;
          k.system = system.statistics();
          write_surface_checkpoint(checkpoint_path, k, ++checkpoints_written);
          checkpoint_clock.mark();
          common::log_debug("checkpoint " + checkpoint_path.string() + " at t = " + std::to_string(t) + " s: " +
                            std::to_string(std::filesystem::file_size(checkpoint_path)) + " bytes");
        }
      }
      write_frame(integrator.q(), t, reports);  // at a stop: the steady state is the last frame
      if (checkpoints) {
        checkpoint.frame_times.push_back(t);
        checkpoint.frame_q.push_back(integrator.q());
        if (max_augmentations > 0) checkpoint.frame_multipliers.push_back(current_multipliers());
      }
      ++k_out;
      if (stopped_steady) break;
    }
  } catch (const std::exception& e) {
    out.fail(e.what());
    throw;
  }
  progress.finish();

  // ---- statistics -----------------------------------------------------------
  res.scenario = c.name;
  res.frames = frames_written;
  for (SurfaceRun& r : runs) {
    r.summary.final_residual_N = res.final_residual_N;
    r.summary.residual_tolerance_N = res.residual_tolerance_N;
    surface_output::SurfaceSummaryAttributes a;
    a.max_deflection_m = r.summary.max_deflection_m;
    a.max_deflection_time_s = r.summary.max_deflection_time_s;
    a.e1_min = r.summary.e1_min;
    a.e1_max = r.summary.e1_max;
    a.e2_min = r.summary.e2_min;
    a.final_residual_N = res.final_residual_N;
    a.residual_tolerance_N = res.residual_tolerance_N;
    out.set_surface_summary(r.summary.name, a);
    res.surfaces.push_back(r.summary);
  }
  if (stop_change > 0) {
    res.steady_state_stop = true;
    res.steady_state_reached = stopped_steady;
    res.stop_time_s = t;
    res.last_change_m = last_change;
    out.set_solver_attribute("steady_state_change_tol_m", stop_change);
    out.set_solver_attribute("stop_reason", std::string(stopped_steady ? "steady_state" : "end_time"));
    out.set_solver_attribute("stop_time_s", t);
    out.set_solver_attribute("last_change_m", last_change);
    std::ostringstream m;
    m << "scenario " << c.name << ": ";
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
  if (osmotic_ramp > 0) out.set_root_attribute("osmotic_ramp_s", osmotic_ramp);
  const numerics::IntegratorStatistics& s = integrator.statistics();
  const cartilage::CoupledSystemStatistics& cs = system.statistics();
  out.set_solver_attribute("steps", static_cast<std::int64_t>(s.steps));
  out.set_solver_attribute("newton_iterations",
                           static_cast<std::int64_t>(s.newton_iterations + total_augmentation_iterations));
  if (max_augmentations > 0) {
    out.set_solver_attribute("contact_augmentations", static_cast<std::int64_t>(total_augmentations));
    out.set_solver_attribute("augmentation_newton_iterations",
                             static_cast<std::int64_t>(total_augmentation_iterations));
  }
  out.set_solver_attribute("rejected_steps", static_cast<std::int64_t>(s.rejected_steps));
  out.set_solver_attribute("factorizations", static_cast<std::int64_t>(s.factorizations));
  out.set_solver_attribute("symbolic_analyses", static_cast<std::int64_t>(s.symbolic_analyses));
  out.set_solver_attribute("solver_switches", static_cast<std::int64_t>(s.solver_switches));
  out.set_solver_attribute("pattern_changes", static_cast<std::int64_t>(s.pattern_changes));
  out.set_solver_attribute("line_search_reductions", static_cast<std::int64_t>(s.line_search_reductions));
  out.set_solver_attribute("linear_solver", s.linear_solver);
  out.set_solver_attribute("assembly_s", s.assembly_s);
  out.set_solver_attribute("contact_s", cs.contact_time_s);
  // Where the assembly time goes (wall): element loops, summing element
  // results into the surface matrices, the surfaces' evaluations as a whole
  // (all their terms), and copying between the surfaces and the system.
  double elements_s = 0, element_scatter_s = 0;
  for (const SurfaceRun& r : runs) {
    elements_s += r.model->statistics().element_time_s;
    element_scatter_s += r.model->statistics().scatter_time_s;
  }
  const long evaluations = cs.evaluations, tangent_evaluations = cs.tangent_evaluations;
  out.set_solver_attribute("evaluations", static_cast<std::int64_t>(evaluations));
  out.set_solver_attribute("tangent_evaluations", static_cast<std::int64_t>(tangent_evaluations));
  out.set_solver_attribute("elements_s", elements_s);
  out.set_solver_attribute("element_scatter_s", element_scatter_s);
  out.set_solver_attribute("surfaces_s", cs.models_time_s);
  out.set_solver_attribute("coupling_copy_s", cs.copy_time_s);
  out.set_solver_attribute("factorization_s", s.factorization_s);
  out.set_solver_attribute("solve_s", s.solve_s);
  out.set_solver_attribute("total_s", s.total_s);
  std::string rej;
  for (const auto& x : s.rejections) rej += x + "\n";
  out.set_solver_attribute("rejections", rej);
  if (contact) {
    out.set_solver_attribute("penetration_warnings", static_cast<std::int64_t>(penetration_warnings));
    out.set_solver_attribute("worst_penetration_ratio", worst_ratio);
    out.set_solver_attribute("unfaded_penetration_warnings", static_cast<std::int64_t>(unfaded_over));
    out.set_solver_attribute("worst_unfaded_penetration_ratio", worst_unfaded_ratio);
    out.set_solver_attribute("penetration_limit", limit);
    out.set_solver_attribute("max_penetration_m", res.max_penetration_m);
  }
  res.steps = s.steps;
  res.newton_iterations = s.newton_iterations + total_augmentation_iterations;
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
  for (size_t k = 0; k < runs.size(); ++k) {
    const auto& cons = runs[k].input.generic.constraints;
    for (size_t i = 0; i < reactions[k].size(); ++i) {
      Eigen::MatrixXd R(static_cast<Eigen::Index>(reactions[k][i].size()), 3);
      for (Eigen::Index f = 0; f < R.rows(); ++f) R.row(f) = reactions[k][i][static_cast<size_t>(f)].transpose();
      std::string comps;
      static const char* names[6] = {"ux", "uy", "uz", "dx", "dy", "dz"};
      for (int j = 0; j < 6; ++j)
        if (cons[i].definition.mask[static_cast<size_t>(j)]) comps += (comps.empty() ? "" : " ") + std::string(names[j]);
      out.set_reactions(runs[k].summary.name, std::to_string(i) + "_" + cons[i].definition.set, cons[i].definition.set,
                        comps, R);
    }
  }
  res.wall_s = now_s() - t_start;
  out.set_solver_attribute("wall_s", res.wall_s);
  out.complete();
  std::filesystem::remove(checkpoint_path);
  res.checkpoints = checkpoints_written;
  res.status = SurfaceStageStatus::kCompleted;
  return res;
}

}  // namespace arthrosim::pipelines
