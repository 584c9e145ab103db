#include "common/scene.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>

#include "common/effects.h"
#include "common/error.h"

namespace arthrosim::common {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// ---------------------------------------------------------------------------
// The schema: the one place that says which keys exist. Defaults of the
// surface stage are the seed's (seeds/002_3ffcc11eb7a447d9.txt and
// shared/references.md: shell 1 mm, E = 400 MPa, nu = 0.3, 1000 kg/m^3,
// HHT alpha = -0.2, dt = 1e-4 s, output every 5 ms, osmotic pressure 0.2 MPa,
// foundation k = 0.7 N/mm^3 and c = 7e6 N s/mm^3 as the seed's text gives).
// COMAK defaults follow issue 4 (activation lower bound 0.01, 6 Hz low-pass)
// and are the same values as musculoskeletal::ComakOptions (ipopt_tolerance
// 1e-4, 300 iterations per attempt; a test in tests/musculoskeletal/
// comak_test.cc keeps them equal); CPD defaults are Myronenko & Song (2010).
// ---------------------------------------------------------------------------
using T = OptionType;
using U = Unit;

const std::vector<OptionSpec>& schema_table() {
  static const std::vector<OptionSpec> kSchema = {
      // --- top level ---------------------------------------------------------
      {"scene", "description", T::kText, U::kNone, "", false, 0, 0, "", false,
       "free text shown when the scene runs"},
      {"scene", "model", T::kPath, U::kNone, "", true, 0, 0, "", false,
       "the knee model: a folder of bone and cartilage surface meshes, or a URDF file"},
      {"scene", "trial", T::kPath, U::kNone, "", false, 0, 0, "", false,
       "walking trial (folder or file) for the musculoskeletal stage; needed when that stage "
       "runs"},
      {"scene", "trial.start_s", T::kNumber, U::kSecond, "", false, -1e6, 1e6, "", false,
       "first time of the trial that the musculoskeletal stage solves (the whole trial is still "
       "filtered and differentiated); absent: the trial's first time"},
      {"scene", "trial.end_s", T::kNumber, U::kSecond, "", false, -1e6, 1e6, "", false,
       "last time of the trial that the musculoskeletal stage solves; absent: the trial's last time"},
      {"scene", "outputs", T::kOutputList, U::kNone, "", true, 0, 0, "", false,
       "what to produce: prepared_model, kinematics, surface (every scenario), report; the "
       "stages these need run, nothing else"},
      {"scene", "prepare", T::kBlock, U::kNone, "", false, 0, 0, "", false,
       "options of the prepare stage"},
      {"scene", "comak", T::kBlock, U::kNone, "", false, 0, 0, "", false,
       "effects and options of the musculoskeletal (COMAK) stage"},
      {"scene", "surface", T::kBlock, U::kNone, "", false, 0, 0, "", false,
       "options and scenarios of the deformable-surface stage"},
      {"scene", "post", T::kBlock, U::kNone, "", false, 0, 0, "", false,
       "options of the post stage"},
      // --- prepare -------------------------------------------------------------
      {"prepare", "edge_length_mm", T::kNumber, U::kMillimetre, "3", false, 0.2, 20, "", false,
       "target edge length of the remeshed cartilage surfaces"},
      {"prepare", "surface_edge_length_mm", T::kTextList, U::kNone, "[]", false, 0, 0, "", false,
       "per-surface target edge lengths in place of edge_length_mm, items 'name=mm' (e.g. [femur=3.7])"},
      {"prepare", "mesh_unit", T::kText, U::kNone, "mm", false, 0, 0, "mm|cm|m", false,
       "length unit of the model's mesh files (STL carries none)"},
      {"prepare", "max_cast_distance_mm", T::kNumber, U::kMillimetre, "10", false, 1, 50, "", false,
       "longest ray cast from cartilage to bone when measuring thickness"},
      {"prepare", "remesh_iterations", T::kInteger, U::kNone, "5", false, 1, 20, "", false,
       "isotropic remeshing iterations"},
      // --- comak ---------------------------------------------------------------
      {"comak", "effects", T::kEffectList, U::kNone, "", true, 0, 0, "", false,
       "musculoskeletal effects to simulate"},
      // 1e-4, not Ipopt's 1e-8: the faceted contact makes the scaled dual
      // infeasibility stall at 1e-3..1e-2, so a tighter tol only ends at
      // Ipopt's acceptable level after many more iterations (docs/comak.md).
      {"comak", "ipopt_tolerance", T::kNumber, U::kNone, "1e-4", false, 1e-14, 1e-2, "", false,
       "Ipopt's convergence tolerance (its option 'tol', scaled NLP) per frame; 1e-4 because the "
       "faceted contact stalls the scaled dual infeasibility at 1e-3..1e-2 (docs/comak.md)"},
      {"comak", "ipopt_acceptable_iterations", T::kInteger, U::kNone, "5", false, 1, 1e6, "", false,
       "consecutive iterates at Ipopt's acceptable level (acceptable_tol 1e-2) that end a solve as "
       "'acceptable'; more keeps iterating towards ipopt_tolerance (docs/comak.md)"},
      {"comak", "ipopt_max_iterations", T::kInteger, U::kNone, "300", false, 1, 1e6, "", false,
       "Ipopt iteration limit per attempt of a frame (the last retry gets twice as many)"},
      {"comak", "activation_min", T::kNumber, U::kNone, "0.01", false, 0, 1, "", false,
       "lower bound of every muscle activation"},
      {"comak", "reserve_actuators", T::kFlag, U::kNone, "false", false, 0, 0, "", false,
       "add heavily weighted reserve actuators on the secondary coordinates"},
      {"comak", "ankle_equilibrium", T::kFlag, U::kNone, "false", false, 0, 0, "", false,
       "add the ankle moment balance (gastrocnemii plus soleus and tibialis anterior stand-ins) "
       "as a constraint (docs/comak.md)"},
      {"comak", "hip_equilibrium", T::kFlag, U::kNone, "false", false, 0, 0, "", false,
       "add the leg's moment balance about the hip's three axes (a model with its own leg and its "
       "hip muscles, e.g. arthrosim import-osim --muscles leg) (docs/comak.md)"},
      {"comak", "coordinate_damping", T::kFlag, U::kNone, "true", false, 0, 0, "", false,
       "the model's coordinate dampers act on the secondary coordinates' speed from the previous "
       "frame (OpenSim-JAM's SpringGeneralizedForce; docs/comak.md)"},
      {"comak", "body_inertia", T::kFlag, U::kNone, "false", false, 0, 0, "", false,
       "add the weight and d'Alembert forces of the tibia and patella bodies (URDF inertials, "
       "moving with the model; the shank's terms leave the external load) (docs/comak.md)"},
      {"comak", "second_start", T::kFlag, U::kNone, "true", false, 0, 0, "", false,
       "also solve every converged frame from the passive settle at its flexion and keep the lower "
       "objective (the problem has local optima; a warm start carries the previous frame's branch; "
       "docs/comak.md)"},
      {"comak", "lowpass_cutoff_hz", T::kNumber, U::kHertz, "6", false, 0.1, 1000, "", false,
       "low-pass filter of trial kinematics and ground reactions"},
      // --- surface (defaults for every scenario; "overridable" ones may be set
      // per scenario) --------------------------------------------------------
      {"surface", "scenarios", T::kScenarios, U::kNone, "", true, 0, 0, "", false,
       "the scenarios to run, each with its own effects"},
      {"surface", "surfaces", T::kTextList, U::kNone, "[femur, tibia_medial, tibia_lateral]", false,
       0, 0, "", true, "cartilage surfaces of the prepared model simulated as shells"},
      {"surface", "time_step_s", T::kNumber, U::kSecond, "1e-4", false, 1e-8, 1, "", true,
       "HHT time step"},
      {"surface", "end_time_s", T::kNumber, U::kSecond, "", false, 0, 1e4, "", true,
       "simulated time; may be left out only by a scenario with imposed_kinematics, which "
       "then runs for the kinematics file's duration"},
      {"surface", "output_interval_ms", T::kNumber, U::kMillisecond, "5", false, 0, 1e6, "", true,
       "time between written frames"},
      {"surface", "hht_alpha", T::kNumber, U::kNone, "-0.2", false, -1.0 / 3.0, 0, "", true,
       "HHT numerical damping parameter (0 = trapezoidal rule)"},
      {"surface", "shell_thickness_mm", T::kNumber, U::kMillimetre, "1", false, 0.01, 20, "", true,
       "thickness of the superficial-layer shells"},
      {"surface", "youngs_modulus_mpa", T::kNumber, U::kMegapascal, "400", false, 1e-3, 1e6, "",
       true, "Young's modulus of the shells"},
      {"surface", "poisson_ratio", T::kNumber, U::kNone, "0.3", false, 0, 0.499, "", true,
       "Poisson's ratio of the shells"},
      {"surface", "density_kg_per_m3", T::kNumber, U::kKilogramPerCubicMetre, "1000", false, 1, 1e5,
       "", true, "density of the shells (used by inertia)"},
      {"surface", "foundation_stiffness_n_per_mm3", T::kNumber, U::kNewtonPerCubicMillimetre,
       "0.7", false, 0, 1e6, "", true,
       "foundation spring stiffness per unit area and unit compression (foundation_springs)"},
      {"surface", "foundation_damping_n_s_per_mm3", T::kNumber,
       U::kNewtonSecondPerCubicMillimetre, "7e6", false, 0, 1e12, "", true,
       "foundation damping per unit area and unit compression rate (foundation_damping)"},
      {"surface", "osmotic_surfaces", T::kTextList, U::kNone, "[]", false, 0, 0, "", true,
       "osmotic_pressure: the surfaces that carry it (each one of `surfaces`); empty: every simulated "
       "surface (the seed's run pressurised the femoral cartilage)"},
      {"surface", "osmotic_pressure_mpa", T::kNumber, U::kMegapascal, "0.2", false, 0, 100, "",
       true, "pressure on the internal face of the shells (osmotic_pressure)"},
      {"surface", "steady_state", T::kFlag, U::kNone, "false", false, 0, 0, "", true,
       "solve directly for the steady state at end_time_s (static equilibrium: every listed "
       "term is built, velocities and accelerations are zero there) instead of time stepping"},
      {"surface", "linear_solver", T::kText, U::kNone, "auto", false, 0, 0, "auto|cholmod|umfpack",
       true,
       "sparse solver of the Newton steps: auto (CHOLMOD when every tangent is symmetric, else "
       "UMFPACK), cholmod (on the symmetric part (K + K^T)/2), umfpack"},
      // Opt-in keys of the dynamic path (pipelines/surface_stage.cc; all off
      // by default, so existing scenes run unchanged).
      {"surface", "osmotic_ramp_s", T::kNumber, U::kSecond, "0", false, 0, 1e4, "", true,
       "without imposed_kinematics: the osmotic pressure rises from 0 over this time by the smoothstep "
       "3 s^2 - 2 s^3 of the seating ramp (0: full pressure from t = 0; with imposed_kinematics the "
       "pressure rises over seating_time_s instead); at most end_time_s"},
      {"surface", "steady_state_change_mm", T::kNumber, U::kMillimetre, "0", false, 0, 1e3, "", true,
       "time-stepping runs: end once the largest weighted coordinate change over one step (positions, "
       "and transverse gradients x h/2) is at most this, after the pressure ramp; 0: run to end_time_s. "
       "The output records where and why it stopped (docs/surface_output.md)"},
      {"surface", "newton_reuse_factorization", T::kFlag, U::kNone, "false", false, 0, 0, "", true,
       "modified Newton: keep the last factorisation across iterations and steps of the same size while "
       "the residual falls by 4x per iteration (else refactorise); not with mesh_contact"},
      // Deformable mesh contact (effect mesh_contact; cartilage/mesh_contact.h,
      // docs/contact.md) and the seating of imposed kinematics.
      {"surface", "contact_pairs", T::kTextList, U::kNone, "[femur:tibia_medial, femur:tibia_lateral]",
       false, 0, 0, "", true,
       "surface pairs in mesh contact, each 'a:b' (both must be simulated); force output is on b "
       "(the tibia: /contact/tibiofemoral/...)"},
      {"surface", "contact_stiffness_n_per_mm3", T::kNumber, U::kNewtonPerCubicMillimetre, "20", false,
       1e-6, 1e9, "", true,
       "penalty pressure per unit interpenetration; the seed's accuracy rule (penetration below a tenth "
       "of the deflection) needs about ten times the foundation stiffness or more"},
      {"surface", "contact_damping_n_s_per_mm3", T::kNumber, U::kNewtonSecondPerCubicMillimetre, "0",
       false, 0, 1e12, "", true, "penalty damping per unit interpenetration rate (0: none, symmetric tangent)"},
      {"surface", "contact_max_depth_mm", T::kNumber, U::kMillimetre, "1", false, 1e-3, 100, "", true,
       "deeper overlaps are not contacts (the far side of a surface)"},
      {"surface", "contact_smoothing_mm", T::kNumber, U::kMillimetre, "0.001", false, 1e-9, 1, "", true,
       "width of the quadratic toe of the penalty law (continuous tangent at first touch)"},
      {"surface", "contact_edge_edge", T::kFlag, U::kNone, "false", false, 0, 0, "", true,
       "also evaluate edge-edge pairs (sharp features); the vertex test with edge and corner features "
       "covers smooth surfaces"},
      {"surface", "contact_rim", T::kText, U::kNone, "fade_inside", false, 0, 0, "fade_inside|rim_contacts", true,
       "how contact ends at a surface's rim: fade_inside weights contacts on the faces next to a rim by a node "
       "weight interpolated from 0 on the rim to 1 inside (continuous, never sideways); rim_contacts is the "
       "earlier treatment (a vertex beyond a rim keeps its distance to it, faded by angle; docs/contact.md)"},
      {"surface", "contact_rim_max_depth_mm", T::kNumber, U::kMillimetre, "0.5", false, 0, 100, "", true,
       "contact_rim: rim_contacts: cut-off depth of rim contacts (a vertex beside the other surface's rim), "
       "faded over its last quarter; 0: contact_max_depth_mm"},
      {"surface", "contact_rim_vertices", T::kFlag, U::kNone, "false", false, 0, 0, "", true,
       "nodes on a surface's rim may be penetrating vertices; by default they only carry their triangles, "
       "as stage 1 samples the casting surface at triangle centres, never at its rim (docs/contact.md)"},
      {"surface", "contact_vertex_weights", T::kText, U::kNone, "tributary", false, 0, 0, "tributary|faded", true,
       "a node's weight as the penetrating vertex of a contact: tributary = a third of its triangles' areas "
       "(rim nodes per contact_rim_vertices); faded = the integral of the rim fade times its shape function over "
       "its triangles, so each surface samples itself with the fade the other surface's vertices see, and rim nodes "
       "carry a reduced weight (fade_inside only, not with contact_rim_vertices; docs/contact.md, \"Rims\")"},
      {"surface", "predictor", T::kText, U::kNone, "extrapolated", false, 0, 0, "rigid|extrapolated", true,
       "imposed_kinematics: Newton start of a step: the surfaces carried rigidly by their bones (rigid), "
       "plus the bone-relative deformation change of the step before, extrapolated linearly in time"},
      {"surface", "periphery_normal", T::kText, U::kNone, "clamped", false, 0, 0, "clamped|foundation", true,
       "periphery_fixed: clamped = boundary nodes move with the bone in all six coordinates (seed 002); "
       "foundation = tied to the bone in their tangent plane only, resting on the foundation along the "
       "normal (for contact zones that reach the rim, as in stage 1's elastic foundation)"},
      {"surface", "periphery_tie_stiffness_n_per_mm3", T::kNumber, U::kNewtonPerCubicMillimetre, "1000", false,
       1e-3, 1e9, "", true, "periphery_normal: foundation: stiffness per unit area of the tangential tie"},
      {"surface", "penetration_limit", T::kNumber, U::kNone, "0.1", false, 0, 1e6, "", true,
       "the seed's accuracy rule: largest interpenetration / largest deflection allowed per step"},
      {"surface", "penetration_action", T::kText, U::kNone, "warn", false, 0, 0, "warn|stop", true,
       "when a step breaks penetration_limit: warn (counted, reported) or stop the run"},
      {"surface", "seating_time_s", T::kNumber, U::kSecond, "0.02", false, 0, 10, "", true,
       "imposed kinematics start with a seating ramp of this duration: bones other than the femur "
       "move from seating_offset_mm away along their own -Y axis to their first pose (the seed's "
       "run began with a 0.02 s seating)"},
      {"surface", "seating_offset_mm", T::kNumber, U::kMillimetre, "1", false, 0, 100, "", true,
       "initial separation of the seating ramp; must exceed the first frame's overlap"},
      {"surface", "foundation_from_thickness", T::kFlag, U::kNone, "false", false, 0, 0, "", true,
       "foundation_springs stiffness per node k_i = K / h_i (h_i: the prepared cartilage thickness, "
       "K from matched_youngs_modulus_mpa and matched_poisson_ratio), matching the musculoskeletal "
       "stage's elastic-foundation contact, instead of foundation_stiffness_n_per_mm3"},
      {"surface", "matched_youngs_modulus_mpa", T::kNumber, U::kMegapascal, "10", false, 1e-6, 1e6, "", true,
       "E of the elastic-foundation layer used by foundation_from_thickness (the bundled knee's "
       "contact: 10 MPa)"},
      {"surface", "matched_poisson_ratio", T::kNumber, U::kNone, "0.45", false, 0, 0.499, "", true,
       "nu of the elastic-foundation layer used by foundation_from_thickness (bundled knee: 0.45)"},
      {"surface", "max_newton_iterations", T::kNumber, U::kNone, "15", false, 1, 1000, "", true,
       "Newton iterations per step attempt before the step is halved"},
      {"surface", "newton_tolerance", T::kNumber, U::kNone, "1e-8", false, 1e-14, 1e-2, "", true,
       "relative tolerance of a step's Newton iteration on the residual and on the increment "
       "(docs/shell_element.md)"},
      {"surface", "newton_residual_floor_n", T::kNumber, U::kNone, "1e-10", false, 0, 1e6, "", true,
       "absolute residual [N] below which a step's residual test passes whatever its first "
       "residual (contact: force jumps at facet kinks leave residuals of order 0.01 N)"},
      {"surface", "newton_increment_floor_mm", T::kNumber, U::kMillimetre, "1e-11", false, 0, 1, "", true,
       "absolute Newton increment below which a step's increment test passes"},
      // --- one scenario --------------------------------------------------------
      {"scenario", "description", T::kText, U::kNone, "", false, 0, 0, "", false,
       "free text for reports"},
      // Generic case (docs/surface_output.md): any quad mesh with node sets
      // chosen by boxes, so standard shell problems can be checked.
      {"scenario", "mesh", T::kPath, U::kNone, "", false, 0, 0, "", false,
       "quad mesh (OBJ with 'v' and 4-node 'f' lines, or legacy ASCII VTK polydata with quad "
       "POLYGONS; coordinates in mm) simulated instead of the "
       "prepared model's surfaces; shell directors on the side of the quad normals"},
      {"scenario", "fixed_box_mm", T::kNumberList, U::kMillimetre, "", false, 6, 6, "", false,
       "[xmin, ymin, zmin, xmax, ymax, zmax]: nodes of `mesh` in this box are clamped (all six "
       "coordinates; effect fixed_nodes)"},
      {"scenario", "load_box_mm", T::kNumberList, U::kMillimetre, "", false, 6, 6, "", false,
       "box of the nodes of `mesh` that share point_load_n equally (effect point_loads)"},
      {"scenario", "point_load_n", T::kNumberList, U::kNone, "", false, 3, 3, "", false,
       "[fx, fy, fz] total force [N] on the nodes in load_box_mm, ramped linearly from 0 at t = 0 "
       "to its value at end_time_s (effect point_loads)"},
      {"scenario", "pressure_mpa", T::kNumber, U::kMegapascal, "", false, -1e3, 1e3, "", false,
       "pressure on the mid-surface of `mesh`, positive along the directors, ramped like "
       "point_load_n (effect pressure)"},
      {"scenario", "displaced_box_mm", T::kNumberList, U::kMillimetre, "", false, 6, 6, "", false,
       "box of the nodes of `mesh` whose positions are prescribed (effect prescribed_displacement)"},
      {"scenario", "displacement_mm", T::kNumberList, U::kMillimetre, "", false, 3, 3, "", false,
       "[ux, uy, uz] displacement of the nodes in displaced_box_mm, ramped like point_load_n"},
      {"scenario", "effects", T::kEffectList, U::kNone, "", true, 0, 0, "", false,
       "surface effects to simulate in this scenario"},
      // --- post ----------------------------------------------------------------
      {"post", "splitline_map", T::kPath, U::kNone, "", false, 0, 0, "", false,
       "split-line map (SVG or CSV) to compare the averaged strain directions with"},
      {"post", "angle_threshold_deg", T::kNumber, U::kDegree, "20", false, 0, 90, "", false,
       "report the fraction of samples whose model-map angle is below this"},
      {"post", "cpd_outlier_weight", T::kNumber, U::kNone, "0.1", false, 0, 0.99, "", false,
       "Coherent Point Drift outlier weight w"},
      {"post", "cpd_beta", T::kNumber, U::kNone, "2", false, 1e-6, 1e6, "", false,
       "Coherent Point Drift kernel width beta (normalised units)"},
      {"post", "cpd_lambda", T::kNumber, U::kNone, "3", false, 1e-9, 1e9, "", false,
       "Coherent Point Drift regularisation lambda"},
      {"post", "cpd_nonrigid", T::kFlag, U::kNone, "true", false, 0, 0, "", false,
       "register the map non-rigidly after the affine fit (false: affine only)"},
      {"post", "outline_points", T::kInteger, U::kNone, "200", false, 8, 5000, "", false,
       "both outlines are resampled to this many points for registration"},
      {"post", "average_radius_mm", T::kNumber, U::kMillimetre, "0", false, 0, 100, "", false,
       "radius of the spatial averaging of model directions at each map sample; 0 = the "
       "registered map's resolution (at least 1.5 model node spacings)"},
      {"post", "view_surface", T::kText, U::kNone, "femur", false, 0, 0, "", false,
       "surface of the surface-output files that is projected and compared with the map"},
      {"post", "view_direction_x", T::kNumber, U::kNone, "0", false, -1e6, 1e6, "", false,
       "x component of the viewing direction (model frame; default (0, 1, 0): distal view of the femur, looking superiorly)"},
      {"post", "view_direction_y", T::kNumber, U::kNone, "1", false, -1e6, 1e6, "", false,
       "y component of the viewing direction (model frame; default (0, 1, 0): distal view of the femur, looking superiorly)"},
      {"post", "view_direction_z", T::kNumber, U::kNone, "0", false, -1e6, 1e6, "", false,
       "z component of the viewing direction (model frame; default (0, 1, 0): distal view of the femur, looking superiorly)"},
      {"post", "view_up_x", T::kNumber, U::kNone, "1", false, -1e6, 1e6, "", false,
       "x component of the direction shown upwards in the view (default (1, 0, 0): anterior up)"},
      {"post", "view_up_y", T::kNumber, U::kNone, "0", false, -1e6, 1e6, "", false,
       "y component of the direction shown upwards in the view (default (1, 0, 0): anterior up)"},
      {"post", "view_up_z", T::kNumber, U::kNone, "0", false, -1e6, 1e6, "", false,
       "z component of the direction shown upwards in the view (default (1, 0, 0): anterior up)"},
  };
  return kSchema;
}

// ---------------------------------------------------------------------------
// Small helpers
// ---------------------------------------------------------------------------
struct Where {
  std::string file;
  int line;
  int column;
};

Where where(const std::string& file, const YAML::Mark& m) {
  // yaml-cpp marks are 0-based; editors count from 1.
  return {file, m.line + 1, m.column + 1};
}

[[noreturn]] void fail(const Where& w, const std::string& message) {
  throw InputError(w.file, w.line, w.column, message);
}

std::string describe(const YAML::Node& node) {
  switch (node.Type()) {
    case YAML::NodeType::Null:
      return "nothing";
    case YAML::NodeType::Sequence:
      return "a list";
    case YAML::NodeType::Map:
      return "a block of keys";
    case YAML::NodeType::Scalar:
      return "'" + node.Scalar() + "'";
    default:
      return "an undefined value";
  }
}

std::string shortest(double v) {
  char buf[64];
  auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, end);
}

// Levenshtein distance, for "did you mean" hints on typos.
std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] != b[j - 1])});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string hint(std::string_view word, const std::vector<std::string_view>& candidates) {
  std::string_view best;
  std::size_t best_d = 4;  // suggest only close matches
  for (std::string_view c : candidates) {
    const std::size_t d = edit_distance(word, c);
    if (d < best_d) {
      best_d = d;
      best = c;
    }
  }
  return best.empty() ? std::string() : " (did you mean '" + std::string(best) + "'?)";
}

std::string join(const std::vector<std::string_view>& words) {
  std::string s;
  for (std::string_view w : words) s += (s.empty() ? "" : ", ") + std::string(w);
  return s;
}

std::string join(const std::vector<std::string>& words) {
  std::string s;
  for (const std::string& w : words) s += (s.empty() ? "" : ", ") + w;
  return s;
}

std::string_view type_word(OptionType t) {
  switch (t) {
    case T::kNumber:
      return "a number";
    case T::kInteger:
      return "a whole number";
    case T::kFlag:
      return "true or false";
    case T::kText:
      return "text";
    case T::kPath:
      return "a path";
    case T::kTextList:
    case T::kOutputList:
      return "a list like [a, b]";
    case T::kNumberList:
      return "a list of numbers like [1, 2.5]";
    case T::kEffectList:
      return "a list of effects like [a, b]";
    case T::kBlock:
    case T::kScenarios:
      return "a block of keys";
  }
  return "a value";
}

// Keys allowed in `block`, for messages. A scenario also takes the surface
// keys marked overridable.
std::vector<const OptionSpec*> block_specs(std::string_view block) {
  std::vector<const OptionSpec*> out;
  for (const OptionSpec& s : schema_table()) {
    if (s.block == block) out.push_back(&s);
    if (block == "scenario" && s.block == "surface" && s.overridable) out.push_back(&s);
  }
  return out;
}

const OptionSpec* spec_in(std::string_view block, std::string_view key) {
  for (const OptionSpec* s : block_specs(block)) {
    if (s->key == key) return s;
  }
  return nullptr;
}

std::filesystem::path repository_of(const std::filesystem::path& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  for (fs::path p = dir; !p.empty(); p = p.parent_path()) {
    if (fs::exists(p / ".git", ec)) return p;
    if (p == p.parent_path()) break;
  }
  return {};
}

// ---------------------------------------------------------------------------
// The parser
// ---------------------------------------------------------------------------
class Parser {
 public:
  Parser(std::string file_label, std::filesystem::path scene_dir)
      : file_(std::move(file_label)), dir_(std::move(scene_dir)) {}

  Where at(const YAML::Node& n) const { return where(file_, n.Mark()); }

  // Checks that `node` is a map whose keys all belong to `block`, that no key
  // repeats and that required keys are present. Returns (key node, value
  // node) pairs in file order.
  std::vector<std::pair<YAML::Node, YAML::Node>> entries(const YAML::Node& node,
                                                         std::string_view block,
                                                         const std::string& block_label) {
    if (!node.IsMap()) {
      fail(at(node), "expected a block of keys for '" + block_label + "', found " +
                         describe(node));
    }
    std::vector<std::pair<YAML::Node, YAML::Node>> out;
    std::map<std::string, int> seen;
    std::vector<std::string_view> allowed;
    for (const OptionSpec* s : block_specs(block)) allowed.push_back(s->key);
    const YAML::const_iterator last = node.end();
    for (YAML::const_iterator it = node.begin(); it != last; ++it) {
      const YAML::Node key = it->first;
      const YAML::Node val = it->second;
      if (!key.IsScalar()) fail(at(key), "expected a key name, found " + describe(key));
      const std::string& k = key.Scalar();
      if (spec_in(block, k) == nullptr) {
        std::string msg = "unknown key '" + k + "' in '" + block_label + "'" + hint(k, allowed);
        msg += "; allowed keys: " + join(allowed);
        if (block == "scenario") {
          msg += " (stage-wide keys go in the 'surface' block; these may be overridden per "
                 "scenario)";
        }
        fail(at(key), msg);
      }
      if (auto s = seen.find(k); s != seen.end()) {
        fail(at(key), "key '" + k + "' given twice in '" + block_label + "' (first on line " +
                          std::to_string(s->second) + ")");
      }
      seen[k] = at(key).line;
      out.emplace_back(key, val);
    }
    for (const OptionSpec* s : block_specs(block)) {
      if (s->required && s->block == block && !seen.count(std::string(s->key))) {
        fail(at(node), "missing required key '" + std::string(s->key) + "' in '" + block_label +
                           "' (" + std::string(s->doc) + ")");
      }
    }
    return out;
  }

  std::string scalar(const YAML::Node& value, const OptionSpec& spec) {
    if (!value.IsScalar()) {
      fail(at(value), "'" + std::string(spec.key) + "': expected " +
                          std::string(type_word(spec.type)) + ", found " + describe(value));
    }
    return value.Scalar();
  }

  double parse_number(const std::string& text, const YAML::Node& value, const OptionSpec& spec) {
    const char* begin = text.c_str();
    char* end = nullptr;
    const double v = std::strtod(begin, &end);
    if (text.empty() || end != begin + text.size() || text.find_first_of("xXpP") !=
                                                          std::string::npos) {
      fail(at(value), "'" + std::string(spec.key) + "': expected a number, found '" + text + "'");
    }
    if (!std::isfinite(v)) {
      fail(at(value),
           "'" + std::string(spec.key) + "': expected a finite number, found '" + text + "'");
    }
    return v;
  }

  void check_range(double v, const std::string& text, const YAML::Node& value,
                   const OptionSpec& spec) {
    if (v < spec.min || v > spec.max) {
      fail(at(value), "'" + std::string(spec.key) + "': expected a value in [" +
                          shortest(spec.min) + ", " + shortest(spec.max) + "]" +
                          std::string(unit_suffix(spec.unit).empty() ? "" : " ") +
                          std::string(unit_suffix(spec.unit).empty()
                                          ? ""
                                          : unit_suffix(spec.unit).substr(1)) +
                          ", found " + text);
    }
  }

  std::vector<std::string> word_list(const YAML::Node& value, const OptionSpec& spec) {
    if (!value.IsSequence()) {
      fail(at(value), "'" + std::string(spec.key) + "': expected a list like [a, b], found " +
                          describe(value));
    }
    std::vector<std::string> out;
    for (const YAML::Node& item : value) {
      if (!item.IsScalar()) {
        fail(at(item), "'" + std::string(spec.key) + "': expected a word in the list, found " +
                           describe(item));
      }
      if (std::find(out.begin(), out.end(), item.Scalar()) != out.end()) {
        fail(at(item), "'" + std::string(spec.key) + "': '" + item.Scalar() + "' listed twice");
      }
      out.push_back(item.Scalar());
    }
    return out;
  }

  std::filesystem::path resolve(const std::string& written, const YAML::Node& value,
                                const OptionSpec& spec) {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::path p(written);
    std::vector<fs::path> tried;
    if (p.is_absolute()) {
      tried.push_back(p);
    } else {
      tried.push_back(dir_ / p);
      const fs::path repo = repository_of(dir_);
      if (!repo.empty()) tried.push_back(repo / p);
    }
    for (const fs::path& c : tried) {
      if (fs::exists(c, ec)) return fs::weakly_canonical(c, ec).lexically_normal();
    }
    std::string where_list;
    for (const fs::path& c : tried) {
      where_list += (where_list.empty() ? "" : ", ") + c.lexically_normal().string();
    }
    fail(at(value), "'" + std::string(spec.key) + "': expected an existing file or folder, found '" +
                        written + "' (looked for " + where_list + ")");
  }

  // Parses one value against its spec (not for kBlock / kScenarios).
  OptionValue value(const YAML::Node& key, const YAML::Node& value, const OptionSpec& spec) {
    OptionValue v;
    v.spec = &spec;
    v.given = true;
    const Where w = at(key);
    v.line = w.line;
    v.column = w.column;
    fill(v, value, spec);
    return v;
  }

  void fill(OptionValue& v, const YAML::Node& value, const OptionSpec& spec) {
    const std::string key(spec.key);
    switch (spec.type) {
      case T::kNumber: {
        const std::string text = scalar(value, spec);
        const double x = parse_number(text, value, spec);
        check_range(x, text, value, spec);
        v.number_as_written = x;
        v.number_si = x * unit_to_si(spec.unit);
        v.canonical = shortest(x);
        break;
      }
      case T::kInteger: {
        const std::string text = scalar(value, spec);
        const char* begin = text.c_str();
        char* end = nullptr;
        errno = 0;
        const long long x = std::strtoll(begin, &end, 10);
        if (text.empty() || end != begin + text.size() || errno == ERANGE) {
          fail(at(value), "'" + key + "': expected a whole number, found '" + text + "'");
        }
        check_range(double(x), text, value, spec);
        v.integer = x;
        v.canonical = std::to_string(x);
        break;
      }
      case T::kFlag: {
        const std::string text = scalar(value, spec);
        if (text == "true" || text == "yes" || text == "on") {
          v.flag = true;
        } else if (text == "false" || text == "no" || text == "off") {
          v.flag = false;
        } else {
          fail(at(value), "'" + key + "': expected true or false, found '" + text + "'");
        }
        v.canonical = v.flag ? "true" : "false";
        break;
      }
      case T::kText: {
        const std::string text = scalar(value, spec);
        if (!spec.choices.empty()) {
          std::vector<std::string_view> choices;
          std::string_view rest = spec.choices;
          while (!rest.empty()) {
            const auto bar = rest.find('|');
            choices.push_back(rest.substr(0, bar));
            rest = bar == std::string_view::npos ? std::string_view() : rest.substr(bar + 1);
          }
          if (std::find(choices.begin(), choices.end(), text) == choices.end()) {
            fail(at(value), "'" + key + "': expected one of " + join(choices) + ", found '" +
                                text + "'" + hint(text, choices));
          }
        }
        v.text = text;
        v.canonical = text;
        break;
      }
      case T::kPath: {
        const std::string text = scalar(value, spec);
        if (text.empty()) fail(at(value), "'" + key + "': expected a path, found nothing");
        v.text = text;
        v.path = resolve(text, value, spec);
        v.canonical = text;
        break;
      }
      case T::kTextList:
        v.list = word_list(value, spec);
        v.canonical = "[" + join(v.list) + "]";
        break;
      case T::kNumberList: {
        if (!value.IsSequence()) {
          fail(at(value), "'" + key + "': expected a list of numbers like [1, 2.5], found " + describe(value));
        }
        std::vector<std::string> words;
        for (const YAML::Node& item : value) {
          if (!item.IsScalar()) {
            fail(at(item), "'" + key + "': expected a number in the list, found " + describe(item));
          }
          const double x = parse_number(item.Scalar(), item, spec);
          v.numbers_as_written.push_back(x);
          v.numbers_si.push_back(x * unit_to_si(spec.unit));
          words.push_back(shortest(x));
        }
        const auto n = static_cast<double>(v.numbers_si.size());
        if (n < spec.min || n > spec.max) {
          fail(at(value), "'" + key + "': expected " +
                              (spec.min == spec.max ? shortest(spec.min) : shortest(spec.min) + " to " + shortest(spec.max)) +
                              " numbers, found " + shortest(n));
        }
        v.canonical = "[" + join(words) + "]";
        break;
      }
      case T::kOutputList: {
        v.list = word_list(value, spec);
        std::size_t i = 0;
        for (const YAML::Node& item : value) {
          if (!parse_output(item.Scalar())) {
            std::vector<std::string_view> names;
            for (Output o : {Output::kPreparedModel, Output::kKinematics, Output::kSurface,
                             Output::kReport}) {
              names.push_back(to_string(o));
            }
            fail(at(item), "'outputs': unknown output '" + item.Scalar() + "'" +
                               hint(item.Scalar(), names) + "; known outputs: " + join(names));
          }
          ++i;
        }
        if (v.list.empty()) fail(at(value), "'outputs': expected at least one output, found []");
        v.canonical = "[" + join(v.list) + "]";
        break;
      }
      case T::kEffectList: {
        const EffectStage stage = spec.block == "comak" ? EffectStage::kMusculoskeletal
                                                        : EffectStage::kSurface;
        v.list = word_list(value, spec);
        std::vector<std::string_view> names;
        for (const EffectInfo& e : known_effects()) {
          if (e.stage == stage) names.push_back(e.name);
        }
        for (const YAML::Node& item : value) {
          const EffectInfo* e = find_effect(item.Scalar());
          if (e == nullptr) {
            fail(at(item), "unknown effect '" + item.Scalar() + "'" + hint(item.Scalar(), names) +
                               "; the " + std::string(to_string(stage)) +
                               " stage knows: " + effect_names(stage));
          }
          if (e->stage != stage) {
            fail(at(item), "effect '" + item.Scalar() + "' belongs to the " +
                               std::string(to_string(e->stage)) + " stage, not the " +
                               std::string(to_string(stage)) + " stage; this list takes: " +
                               effect_names(stage));
          }
        }
        v.canonical = "[" + join(v.list) + "]";
        break;
      }
      case T::kBlock:
      case T::kScenarios:
        throw std::logic_error("Parser::fill called for a block");
    }
  }

  // Parses a flat option block (no nested blocks except scenarios, handled by
  // the caller) into `out`, then fills defaults.
  void options(const YAML::Node& node, std::string_view block, const std::string& label,
               OptionBlock& out, YAML::Node* scenarios = nullptr) {
    for (auto& [key, val] : entries(node, block, label)) {
      const OptionSpec& spec = *spec_in(block, key.Scalar());
      if (spec.type == T::kScenarios) {
        if (scenarios) *scenarios = val;
        continue;
      }
      out.set(key.Scalar(), value(key, val, spec));
    }
  }

  void defaults(std::string_view block, OptionBlock& out) {
    for (const OptionSpec* s : block_specs(block)) {
      if (s->block != block && block != "scenario") continue;
      if (s->type == T::kBlock || s->type == T::kScenarios) continue;
      if (out.has(s->key) || s->default_value.empty()) continue;
      OptionValue v;
      v.spec = s;
      v.given = false;
      // Defaults are parsed by the same code as user text, so they obey the
      // same types and ranges (a bad default fails every scene, loudly).
      YAML::Node node;
      try {
        node = YAML::Load(std::string(s->default_value));
      } catch (const YAML::Exception& e) {
        throw std::logic_error("schema default of " + std::string(s->block) + "." +
                               std::string(s->key) + " is not valid YAML");
      }
      fill(v, node, *s);
      out.set(std::string(s->key), v);
    }
  }

  const std::string& file() const { return file_; }

 private:
  std::string file_;
  std::filesystem::path dir_;
};

bool valid_scenario_name(const std::string& name) {
  if (name.empty()) return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_';
  });
}

}  // namespace

// ---------------------------------------------------------------------------
// Units
// ---------------------------------------------------------------------------
std::string_view unit_suffix(Unit unit) {
  switch (unit) {
    case U::kNone:
      return "";
    case U::kMillimetre:
      return "_mm";
    case U::kDegree:
      return "_deg";
    case U::kSecond:
      return "_s";
    case U::kMillisecond:
      return "_ms";
    case U::kMegapascal:
      return "_mpa";
    case U::kHertz:
      return "_hz";
    case U::kKilogramPerCubicMetre:
      return "_kg_per_m3";
    case U::kNewtonPerCubicMillimetre:
      return "_n_per_mm3";
    case U::kNewtonSecondPerCubicMillimetre:
      return "_n_s_per_mm3";
  }
  return "";
}

double unit_to_si(Unit unit) {
  switch (unit) {
    case U::kMillimetre:
    case U::kMillisecond:
      return 1e-3;
    case U::kDegree:
      return std::numbers::pi / 180.0;
    case U::kMegapascal:
      return 1e6;
    // 1 N/mm^3 = 1 N / (1e-3 m)^3 = 1e9 N/m^3; likewise N s/mm^3.
    case U::kNewtonPerCubicMillimetre:
    case U::kNewtonSecondPerCubicMillimetre:
      return 1e9;
    case U::kNone:
    case U::kSecond:
    case U::kHertz:
    case U::kKilogramPerCubicMetre:
      return 1.0;
  }
  return 1.0;
}

std::string_view si_unit_name(Unit unit) {
  switch (unit) {
    case U::kNone:
      return "";
    case U::kMillimetre:
      return "m";
    case U::kDegree:
      return "rad";
    case U::kSecond:
    case U::kMillisecond:
      return "s";
    case U::kMegapascal:
      return "Pa";
    case U::kHertz:
      return "1/s";
    case U::kKilogramPerCubicMetre:
      return "kg/m^3";
    case U::kNewtonPerCubicMillimetre:
      return "N/m^3";
    case U::kNewtonSecondPerCubicMillimetre:
      return "N s/m^3";
  }
  return "";
}

const std::vector<OptionSpec>& option_schema() { return schema_table(); }

const OptionSpec* find_option(std::string_view block, std::string_view key) {
  for (const OptionSpec& s : schema_table()) {
    if (s.block == block && s.key == key) return &s;
  }
  return nullptr;
}

std::string_view to_string(Output output) {
  switch (output) {
    case Output::kPreparedModel:
      return "prepared_model";
    case Output::kKinematics:
      return "kinematics";
    case Output::kSurface:
      return "surface";
    case Output::kReport:
      return "report";
  }
  return "";
}

std::optional<Output> parse_output(std::string_view word) {
  for (Output o : {Output::kPreparedModel, Output::kKinematics, Output::kSurface,
                   Output::kReport}) {
    if (to_string(o) == word) return o;
  }
  return std::nullopt;
}

// ---------------------------------------------------------------------------
// OptionBlock
// ---------------------------------------------------------------------------
const OptionValue& OptionBlock::value(std::string_view key) const {
  auto it = values_.find(key);
  if (it == values_.end()) {
    throw std::logic_error("option block '" + name_ + "' has no value for '" + std::string(key) +
                           "' (not in the schema, or no default and not given; check has())");
  }
  return it->second;
}

const OptionValue& OptionBlock::checked(std::string_view key, OptionType type) const {
  const OptionValue& v = value(key);
  if (v.spec->type != type) {
    throw std::logic_error("option '" + name_ + "." + std::string(key) +
                           "' read with the wrong type (the schema says " +
                           std::string(type_word(v.spec->type)) + ")");
  }
  return v;
}

double OptionBlock::si(std::string_view key) const { return checked(key, T::kNumber).number_si; }
double OptionBlock::as_written(std::string_view key) const {
  return checked(key, T::kNumber).number_as_written;
}
std::int64_t OptionBlock::integer(std::string_view key) const {
  return checked(key, T::kInteger).integer;
}
bool OptionBlock::flag(std::string_view key) const { return checked(key, T::kFlag).flag; }
const std::string& OptionBlock::text(std::string_view key) const {
  return checked(key, T::kText).text;
}
const std::filesystem::path& OptionBlock::path(std::string_view key) const {
  return checked(key, T::kPath).path;
}
const std::vector<double>& OptionBlock::numbers_si(std::string_view key) const {
  return checked(key, T::kNumberList).numbers_si;
}
const std::vector<std::string>& OptionBlock::list(std::string_view key) const {
  const OptionValue& v = value(key);
  if (v.spec->type != T::kTextList && v.spec->type != T::kEffectList &&
      v.spec->type != T::kOutputList) {
    throw std::logic_error("option '" + name_ + "." + std::string(key) +
                           "' read as a list but is " + std::string(type_word(v.spec->type)));
  }
  return v.list;
}
bool OptionBlock::has(std::string_view key) const { return values_.find(key) != values_.end(); }
bool OptionBlock::given(std::string_view key) const {
  auto it = values_.find(key);
  return it != values_.end() && it->second.given;
}

std::vector<std::pair<std::string, std::string>> OptionBlock::canonical() const {
  std::vector<std::pair<std::string, std::string>> out;
  for (const auto& [key, v] : values_) out.emplace_back(name_ + "." + key, v.canonical);
  return out;  // std::map: already sorted by key
}

std::string OptionBlock::canonical_text() const {
  std::string s;
  for (const auto& [k, v] : canonical()) s += k + " = " + v + "\n";
  return s;
}

void OptionBlock::set(const std::string& key, OptionValue value) {
  values_[key] = std::move(value);
}

// ---------------------------------------------------------------------------
// Scene
// ---------------------------------------------------------------------------
bool Scenario::wants(std::string_view effect) const {
  return std::find(effects.begin(), effects.end(), effect) != effects.end();
}

bool Scene::wants(Output output) const {
  return std::find(outputs.begin(), outputs.end(), output) != outputs.end();
}

const Scenario* Scene::scenario(std::string_view name) const {
  for (const Scenario& s : scenarios) {
    if (s.name == name) return &s;
  }
  return nullptr;
}

const Scenario& Scene::require_scenario(std::string_view name) const {
  if (const Scenario* s = scenario(name)) return *s;
  std::string have;
  for (const Scenario& s : scenarios) have += (have.empty() ? "" : ", ") + s.name;
  throw InputError(file.string(), 0,
                   "expected a scenario named '" + std::string(name) + "' under surface.scenarios, "
                   "found " + (have.empty() ? std::string("none") : have));
}

std::vector<std::string> Scene::musculoskeletal_effects() const {
  if (!comak) return {};
  return comak->list("effects");
}

Scene parse_scene(const std::string& text, const std::filesystem::path& file) {
  namespace fs = std::filesystem;
  const std::string label = file.string();
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw InputError(label, e.mark.line + 1, e.mark.column + 1,
                     "not valid YAML: " + e.msg);
  }
  Parser p(label, fs::absolute(file).parent_path());
  if (!root.IsMap()) {
    throw InputError(label, root.IsNull() ? 1 : root.Mark().line + 1,
                     root.IsNull() ? 0 : root.Mark().column + 1,
                     "expected a scene (a block of keys: model, outputs, ...), found " +
                         describe(root));
  }

  Scene scene;
  scene.file = fs::absolute(file).lexically_normal();
  scene.top = OptionBlock("scene");
  scene.prepare = OptionBlock("prepare");
  scene.post = OptionBlock("post");

  // Blocks as found (a default-constructed YAML::Node is a defined null, so
  // presence is tracked separately).
  YAML::Node prepare_node, comak_node, surface_node, post_node;
  bool has_prepare = false, has_comak = false, has_surface = false, has_post = false;
  YAML::Node outputs_node;
  for (auto& [key, val] : p.entries(root, "scene", "the scene")) {
    const std::string& k = key.Scalar();
    const OptionSpec& spec = *spec_in("scene", k);
    if (spec.type == T::kBlock) {
      if (k == "prepare") prepare_node = val, has_prepare = true;
      if (k == "comak") comak_node = val, has_comak = true;
      if (k == "surface") surface_node = val, has_surface = true;
      if (k == "post") post_node = val, has_post = true;
      continue;
    }
    if (k == "outputs") outputs_node = val;
    scene.top.set(k, p.value(key, val, spec));
  }
  if (scene.top.has("description")) scene.description = scene.top.text("description");
  scene.model = scene.top.path("model");
  if (scene.top.has("trial")) scene.trial = scene.top.path("trial");
  for (const std::string& o : scene.top.list("outputs")) scene.outputs.push_back(*parse_output(o));

  if (has_prepare) p.options(prepare_node, "prepare", "prepare", scene.prepare);
  p.defaults("prepare", scene.prepare);

  if (has_comak) {
    scene.comak = OptionBlock("comak");
    p.options(comak_node, "comak", "comak", *scene.comak);
    p.defaults("comak", *scene.comak);
  }

  if (has_surface) {
    scene.surface = OptionBlock("surface");
    YAML::Node scenarios_node;  // set: 'scenarios' is a required key of the block
    p.options(surface_node, "surface", "surface", *scene.surface, &scenarios_node);
    p.defaults("surface", *scene.surface);
    if (!scenarios_node.IsMap() || scenarios_node.size() == 0) {
      fail(p.at(scenarios_node),
           "'scenarios': expected a block of named scenarios (e.g. osmotic:, gait:), found " +
               describe(scenarios_node));
    }
    const YAML::const_iterator last = scenarios_node.end();
    for (YAML::const_iterator it = scenarios_node.begin(); it != last; ++it) {
      const std::string name = it->first.Scalar();
      if (!valid_scenario_name(name)) {
        fail(p.at(it->first), "expected a scenario name of lowercase letters, digits and '_', "
                              "found '" + name + "'");
      }
      if (scene.scenario(name) != nullptr) {
        fail(p.at(it->first), "scenario '" + name + "' given twice");
      }
      Scenario sc;
      sc.name = name;
      sc.line = p.at(it->first).line;
      sc.options = OptionBlock("surface." + name);
      p.options(it->second, "scenario", "surface.scenarios." + name, sc.options);
      // Inherit every surface option the scenario does not set itself.
      for (const auto& [k, v] : scene.surface->values()) {
        if (!sc.options.has(k)) sc.options.set(k, v);
      }
      sc.effects = sc.options.list("effects");
      if (!sc.wants("imposed_kinematics") && !sc.options.has("end_time_s")) {
        fail(p.at(it->first), "scenario '" + name +
                                  "' does not use imposed_kinematics, so it needs 'end_time_s' "
                                  "(in the scenario or the surface block)");
      }
      scene.scenarios.push_back(std::move(sc));
    }
  }

  if (has_post) p.options(post_node, "post", "post", scene.post);
  p.defaults("post", scene.post);

  // --- consistency: what the outputs need must be in the scene --------------
  const Where outputs_at = p.at(outputs_node);
  const bool wants_surface = scene.wants(Output::kSurface) || scene.wants(Output::kReport);
  if (wants_surface && scene.scenarios.empty()) {
    fail(outputs_at, "output '" +
                         std::string(scene.wants(Output::kSurface) ? "surface" : "report") +
                         "' needs a 'surface' block with at least one scenario");
  }
  const Scenario* moving = nullptr;
  if (wants_surface) {
    for (const Scenario& s : scene.scenarios) {
      if (s.wants("imposed_kinematics") && moving == nullptr) moving = &s;
    }
  }
  const bool needs_comak = scene.wants(Output::kKinematics) || moving != nullptr;
  if (needs_comak) {
    const std::string why = moving ? "scenario '" + moving->name + "' uses imposed_kinematics"
                                   : "output 'kinematics' is requested";
    const Where w = moving ? Where{label, moving->line, 1} : outputs_at;
    if (!scene.comak) {
      fail(w, why + ", which needs the musculoskeletal stage: add a 'comak' block with its "
                    "effects");
    }
    if (!scene.trial) fail(w, why + ", which needs a walking trial: add 'trial: PATH'");
  }
  return scene;
}

Scene load_scene(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError(file.string(), 0, "cannot open the scene file");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_scene(ss.str(), file);
}

std::string schema_markdown() {
  std::ostringstream s;
  std::string_view current;
  for (const OptionSpec& o : schema_table()) {
    if (o.block != current) {
      current = o.block;
      s << "\n### " << (current == "scene" ? "top level" : current) << "\n\n";
      if (current == "scenario") {
        s << "A scenario also accepts every `surface` key marked *per scenario*.\n\n";
      }
      s << "| key | type | default | range / choices | meaning |\n|---|---|---|---|---|\n";
    }
    std::string range;
    if (o.type == T::kNumber || o.type == T::kInteger) {
      range = "[" + shortest(o.min) + ", " + shortest(o.max) + "]";
    } else if (o.type == T::kNumberList) {
      range = o.min == o.max ? shortest(o.min) + " numbers" : shortest(o.min) + " to " + shortest(o.max) + " numbers";
    } else if (!o.choices.empty()) {
      range = std::string(o.choices);
    }
    std::string type(type_word(o.type));
    if (!unit_suffix(o.unit).empty()) {
      type += " (" + std::string(unit_suffix(o.unit).substr(1)) + " -> " +
              std::string(si_unit_name(o.unit)) + ")";
    }
    std::string def = o.default_value.empty() ? (o.required ? "required" : "none")
                                              : "`" + std::string(o.default_value) + "`";
    std::string doc(o.doc);
    if (o.overridable) doc += " *(per scenario)*";
    for (char& c : range) {
      if (c == '|') c = '/';
    }
    s << "| `" << o.key << "` | " << type << " | " << def << " | " << range << " | " << doc
      << " |\n";
  }
  return s.str();
}

}  // namespace arthrosim::common
