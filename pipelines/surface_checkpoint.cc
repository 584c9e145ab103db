#include "pipelines/surface_checkpoint.h"

#include <algorithm>
#include <exception>
#include <stdexcept>

#include "common/checkpoint.h"
#include "common/hdf5.h"
#include "common/output_file.h"

namespace arthrosim::pipelines {
namespace fs = std::filesystem;

namespace {

constexpr const char* kFormat = "arthrosim surface checkpoint";
constexpr std::int64_t kFormatVersion = 2;

void put(common::H5File& f, const std::string& name, const Eigen::VectorXd& v) {
  if (v.size() > 0) f.write(name, v);
}
Eigen::VectorXd get(const common::H5File& f, const std::string& name) {
  return f.exists(name) ? f.read_vector(name) : Eigen::VectorXd();
}
void put_long(common::H5File& f, const std::string& obj, const std::string& key, long v) {
  f.set_attribute(obj, key, static_cast<std::int64_t>(v));
}
long get_long(const common::H5File& f, const std::string& obj, const std::string& key) {
  return static_cast<long>(f.attribute_int(obj, key));
}

// One double (resp. int) column of the step records.
template <typename T, typename Get>
void put_column(common::H5File& f, const std::string& name, const std::vector<surface_output::StepRecord>& steps,
                Get get) {
  std::vector<T> v;
  for (const auto& s : steps) v.push_back(static_cast<T>(get(s)));
  f.write(name, v);
}

// Multipliers of every contact pair under `group` ("<group>/pair_<k>/a|b";
// an empty side is not written, so it reads back empty).
void put_multipliers(common::H5File& f, const std::string& group, const SurfaceCheckpoint::PairMultipliers& m) {
  f.create_group(group);
  put_long(f, group, "pairs", static_cast<long>(m.size()));
  for (std::size_t k = 0; k < m.size(); ++k) {
    const std::string g = group + "/pair_" + std::to_string(k);
    f.create_group(g);
    put(f, g + "/a", m[k][0]);
    put(f, g + "/b", m[k][1]);
  }
}
SurfaceCheckpoint::PairMultipliers get_multipliers(const common::H5File& f, const std::string& group) {
  SurfaceCheckpoint::PairMultipliers m(static_cast<std::size_t>(get_long(f, group, "pairs")));
  for (std::size_t k = 0; k < m.size(); ++k) {
    const std::string g = group + "/pair_" + std::to_string(k);
    m[k] = {get(f, g + "/a"), get(f, g + "/b")};
  }
  return m;
}

}  // namespace

void write_surface_checkpoint(const fs::path& path, const SurfaceCheckpoint& c, int sequence) {
  common::write_checkpoint(path, kFormat, kFormatVersion, c.identity, sequence, [&](common::H5File& f) {
    // The step loop.
    f.set_attribute("/", "t", c.t);
    put_long(f, "/", "k_out", c.k_out);
    put_long(f, "/", "penetration_warnings", c.penetration_warnings);
    put_long(f, "/", "unfaded_over", c.unfaded_over);
    put_long(f, "/", "rejections_logged", c.rejections_logged);
    put_long(f, "/", "last_iterations", c.last_iterations);
    put_long(f, "/", "last_rejections", c.last_rejections);
    f.set_attribute("/", "worst_ratio", c.worst_ratio);
    f.set_attribute("/", "worst_unfaded_ratio", c.worst_unfaded_ratio);
    f.set_attribute("/", "last_change", c.last_change);
    f.set_attribute("/", "final_residual_N", c.final_residual_N);
    f.set_attribute("/", "residual_tolerance_N", c.residual_tolerance_N);
    f.set_attribute("/", "max_penetration_m", c.max_penetration_m);
    put_long(f, "/", "contact_steps", c.contact_steps);
    put_long(f, "/", "active_contacts_sum", c.active_contacts_sum);
    // Frames and steps written.
    put_long(f, "/", "frames", static_cast<long>(c.frame_times.size()));
    put_long(f, "/", "steps", static_cast<long>(c.steps.size()));
    f.create_group("/frames");
    if (!c.frame_times.empty()) {
      f.write("/frames/time", c.frame_times);
      f.write("/frames/q", common::stack_rows(c.frame_q));
    }
    f.create_group("/steps");
    if (!c.steps.empty()) {
      using S = surface_output::StepRecord;
      put_column<double>(f, "/steps/time", c.steps, [](const S& s) { return s.time; });
      put_column<double>(f, "/steps/dt", c.steps, [](const S& s) { return s.dt; });
      put_column<int>(f, "/steps/newton_iterations", c.steps, [](const S& s) { return s.newton_iterations; });
      put_column<double>(f, "/steps/residual_N", c.steps, [](const S& s) { return s.residual_N; });
      put_column<double>(f, "/steps/residual_tolerance_N", c.steps, [](const S& s) { return s.residual_tolerance_N; });
      put_column<int>(f, "/steps/rejections", c.steps, [](const S& s) { return s.rejections; });
      put_column<double>(f, "/steps/wall_s", c.steps, [](const S& s) { return s.wall_s; });
      put_column<double>(f, "/steps/max_deflection_m", c.steps, [](const S& s) { return s.max_deflection_m; });
      put_column<double>(f, "/steps/change_m", c.steps, [](const S& s) { return s.change_m; });
      put_column<double>(f, "/steps/max_penetration_m", c.steps, [](const S& s) { return s.max_penetration_m; });
      put_column<double>(f, "/steps/penetration_ratio", c.steps, [](const S& s) { return s.penetration_ratio; });
      put_column<int>(f, "/steps/active_contacts", c.steps, [](const S& s) { return s.active_contacts; });
      put_column<double>(f, "/steps/max_rim_depth_m", c.steps, [](const S& s) { return s.max_rim_depth_m; });
      put_column<double>(f, "/steps/max_unfaded_penetration_m", c.steps,
                         [](const S& s) { return s.max_unfaded_penetration_m; });
      put_column<double>(f, "/steps/unfaded_penetration_ratio", c.steps,
                         [](const S& s) { return s.unfaded_penetration_ratio; });
      put_column<int>(f, "/steps/augmentations", c.steps, [](const S& s) { return s.augmentations; });
    }
    // Augmented Lagrangian contact.
    put_long(f, "/", "total_augmentations", c.total_augmentations);
    put_long(f, "/", "total_augmentation_iterations", c.total_augmentation_iterations);
    if (!c.multipliers.empty()) {
      put_multipliers(f, "/multipliers", c.multipliers);
      f.create_group("/frames/multipliers");
      for (std::size_t i = 0; i < c.frame_multipliers.size(); ++i)
        put_multipliers(f, "/frames/multipliers/" + std::to_string(i), c.frame_multipliers[i]);
    }
    // The integrator.
    const numerics::HhtState& h = c.hht;
    f.create_group("/hht");
    f.set_attribute("/hht", "t", h.t);
    f.set_attribute("/hht", "dt", h.dt);
    f.set_attribute("/hht", "h_prev", h.h_prev);
    put_long(f, "/hht", "successes_since_halving", h.successes_since_halving);
    put_long(f, "/hht", "steps", h.steps);
    put_long(f, "/hht", "rejected_steps", h.rejected_steps);
    f.set_attribute("/hht", "initial_assembly_s", h.initial_assembly_s);
    f.set_attribute("/hht", "total_s", h.total_s);
    put(f, "/hht/q", h.q);
    put(f, "/hht/v", h.v);
    put(f, "/hht/a", h.a);
    put(f, "/hht/F", h.F);
    put(f, "/hht/q_initial", h.q_initial);
    put(f, "/hht/dq_prev", h.dq_prev);
    if (!h.rejections.empty()) f.write("/hht/rejections", h.rejections);
    const numerics::NewtonStatistics& n = h.newton;
    f.create_group("/hht/newton");
    put_long(f, "/hht/newton", "iterations", n.iterations);
    put_long(f, "/hht/newton", "factorizations", n.factorizations);
    put_long(f, "/hht/newton", "symbolic_analyses", n.symbolic_analyses);
    put_long(f, "/hht/newton", "solver_switches", n.solver_switches);
    put_long(f, "/hht/newton", "pattern_changes", n.pattern_changes);
    put_long(f, "/hht/newton", "line_search_reductions", n.line_search_reductions);
    put_long(f, "/hht/newton", "roundoff_acceptances", n.roundoff_acceptances);
    f.set_attribute("/hht/newton", "assembly_s", n.assembly_s);
    f.set_attribute("/hht/newton", "factorization_s", n.factorization_s);
    f.set_attribute("/hht/newton", "solve_s", n.solve_s);
    f.set_attribute("/hht/newton", "linear_solver", n.linear_solver);
    // The factorisation modified Newton keeps (newton_reuse_factorization):
    // the matrix in compressed-column form and the tangent key.
    if (h.kept.valid) {
      const Eigen::SparseMatrix<double>& M = h.kept.matrix;
      f.create_group("/hht/newton/kept");
      put_long(f, "/hht/newton/kept", "rows", M.rows());
      put_long(f, "/hht/newton/kept", "cols", M.cols());
      f.set_attribute("/hht/newton/kept", "key", h.kept.key);
      f.write("/hht/newton/kept/outer",
              std::vector<int>(M.outerIndexPtr(), M.outerIndexPtr() + M.outerSize() + 1));
      f.write("/hht/newton/kept/inner", std::vector<int>(M.innerIndexPtr(), M.innerIndexPtr() + M.nonZeros()));
      f.write("/hht/newton/kept/values", std::vector<double>(M.valuePtr(), M.valuePtr() + M.nonZeros()));
    }
    // The coupled system.
    f.create_group("/system");
    put(f, "/system/pattern_q", c.pattern_q);
    put_long(f, "/system", "evaluations", c.system.evaluations);
    put_long(f, "/system", "tangent_evaluations", c.system.tangent_evaluations);
    put_long(f, "/system", "pattern_rebuilds", c.system.pattern_rebuilds);
    put_long(f, "/system", "max_active_contacts", c.system.max_active_contacts);
    f.set_attribute("/system", "contact_time_s", c.system.contact_time_s);
    f.set_attribute("/system", "models_time_s", c.system.models_time_s);
    f.set_attribute("/system", "copy_time_s", c.system.copy_time_s);
  });
}

std::optional<SurfaceCheckpoint> read_surface_checkpoint(const fs::path& path, std::string& why) {
  SurfaceCheckpoint c;
  const bool ok = common::read_checkpoint(path, kFormat, kFormatVersion, c.identity, why, [&](const common::H5File& f) {
    c.t = f.attribute_double("/", "t");
    c.k_out = static_cast<int>(get_long(f, "/", "k_out"));
    c.penetration_warnings = get_long(f, "/", "penetration_warnings");
    c.unfaded_over = get_long(f, "/", "unfaded_over");
    c.rejections_logged = get_long(f, "/", "rejections_logged");
    c.last_iterations = get_long(f, "/", "last_iterations");
    c.last_rejections = get_long(f, "/", "last_rejections");
    c.worst_ratio = f.attribute_double("/", "worst_ratio");
    c.worst_unfaded_ratio = f.attribute_double("/", "worst_unfaded_ratio");
    c.last_change = f.attribute_double("/", "last_change");
    c.final_residual_N = f.attribute_double("/", "final_residual_N");
    c.residual_tolerance_N = f.attribute_double("/", "residual_tolerance_N");
    c.max_penetration_m = f.attribute_double("/", "max_penetration_m");
    c.contact_steps = get_long(f, "/", "contact_steps");
    c.active_contacts_sum = get_long(f, "/", "active_contacts_sum");
    const long frames = get_long(f, "/", "frames"), steps = get_long(f, "/", "steps");
    if (frames > 0) {
      const Eigen::VectorXd t = f.read_vector("/frames/time");
      if (t.size() != frames)
        throw std::runtime_error("it holds " + std::to_string(t.size()) + " frame times for " + std::to_string(frames) +
                                 " frames");
      c.frame_times.assign(t.data(), t.data() + t.size());
      c.frame_q = common::unstack_rows(f.read_matrix("/frames/q"), frames, "/frames/q");
    }
    if (steps > 0) {
      auto d = [&](const char* name) {
        const Eigen::VectorXd v = f.read_vector(std::string("/steps/") + name);
        if (v.size() != steps) throw std::runtime_error(std::string("/steps/") + name + ": wrong length");
        return v;
      };
      auto i = [&](const char* name) {
        const Eigen::VectorXi v = f.read_vector_int(std::string("/steps/") + name);
        if (v.size() != steps) throw std::runtime_error(std::string("/steps/") + name + ": wrong length");
        return v;
      };
      const Eigen::VectorXd time = d("time"), dt = d("dt"), res = d("residual_N"), tol = d("residual_tolerance_N"),
                            wall = d("wall_s"), defl = d("max_deflection_m"), change = d("change_m"),
                            pen = d("max_penetration_m"), ratio = d("penetration_ratio"), rim = d("max_rim_depth_m"),
                            unf = d("max_unfaded_penetration_m"), unr = d("unfaded_penetration_ratio");
      const Eigen::VectorXi it = i("newton_iterations"), rej = i("rejections"), act = i("active_contacts"),
                            aug = i("augmentations");
      for (long k = 0; k < steps; ++k) {
        surface_output::StepRecord s;
        s.time = time[k];
        s.dt = dt[k];
        s.newton_iterations = it[k];
        s.residual_N = res[k];
        s.residual_tolerance_N = tol[k];
        s.rejections = rej[k];
        s.wall_s = wall[k];
        s.max_deflection_m = defl[k];
        s.change_m = change[k];
        s.max_penetration_m = pen[k];
        s.penetration_ratio = ratio[k];
        s.active_contacts = act[k];
        s.max_rim_depth_m = rim[k];
        s.max_unfaded_penetration_m = unf[k];
        s.unfaded_penetration_ratio = unr[k];
        s.augmentations = aug[k];
        c.steps.push_back(s);
      }
    }
    c.total_augmentations = get_long(f, "/", "total_augmentations");
    c.total_augmentation_iterations = get_long(f, "/", "total_augmentation_iterations");
    if (f.exists("/multipliers")) {
      c.multipliers = get_multipliers(f, "/multipliers");
      for (long k = 0; k < frames; ++k) {
        const std::string g = "/frames/multipliers/" + std::to_string(k);
        if (!f.exists(g)) throw std::runtime_error(g + ": missing (frames written: " + std::to_string(frames) + ")");
        c.frame_multipliers.push_back(get_multipliers(f, g));
      }
    }
    numerics::HhtState& h = c.hht;
    h.t = f.attribute_double("/hht", "t");
    h.dt = f.attribute_double("/hht", "dt");
    h.h_prev = f.attribute_double("/hht", "h_prev");
    h.successes_since_halving = static_cast<int>(get_long(f, "/hht", "successes_since_halving"));
    h.steps = get_long(f, "/hht", "steps");
    h.rejected_steps = get_long(f, "/hht", "rejected_steps");
    h.initial_assembly_s = f.attribute_double("/hht", "initial_assembly_s");
    h.total_s = f.attribute_double("/hht", "total_s");
    h.q = get(f, "/hht/q");
    h.v = get(f, "/hht/v");
    h.a = get(f, "/hht/a");
    h.F = get(f, "/hht/F");
    h.q_initial = get(f, "/hht/q_initial");
    h.dq_prev = get(f, "/hht/dq_prev");
    if (f.exists("/hht/rejections")) h.rejections = f.read_strings("/hht/rejections");
    numerics::NewtonStatistics& n = h.newton;
    n.iterations = get_long(f, "/hht/newton", "iterations");
    n.factorizations = get_long(f, "/hht/newton", "factorizations");
    n.symbolic_analyses = get_long(f, "/hht/newton", "symbolic_analyses");
    n.solver_switches = get_long(f, "/hht/newton", "solver_switches");
    n.pattern_changes = get_long(f, "/hht/newton", "pattern_changes");
    n.line_search_reductions = get_long(f, "/hht/newton", "line_search_reductions");
    n.roundoff_acceptances = get_long(f, "/hht/newton", "roundoff_acceptances");
    n.assembly_s = f.attribute_double("/hht/newton", "assembly_s");
    n.factorization_s = f.attribute_double("/hht/newton", "factorization_s");
    n.solve_s = f.attribute_double("/hht/newton", "solve_s");
    n.linear_solver = f.attribute_string("/hht/newton", "linear_solver");
    if (f.exists("/hht/newton/kept")) {
      const long rows = get_long(f, "/hht/newton/kept", "rows"), cols = get_long(f, "/hht/newton/kept", "cols");
      const Eigen::VectorXi outer = f.read_vector_int("/hht/newton/kept/outer");
      const Eigen::VectorXi inner = f.read_vector_int("/hht/newton/kept/inner");
      const Eigen::VectorXd values = f.read_vector("/hht/newton/kept/values");
      if (rows < 0 || cols < 0 || outer.size() != cols + 1 || inner.size() != values.size() || outer[0] != 0 ||
          outer[cols] != inner.size())
        throw std::runtime_error("/hht/newton/kept: a compressed-column matrix of " + std::to_string(rows) + " x " +
                                 std::to_string(cols) + " expected, found " + std::to_string(outer.size()) +
                                 " column starts and " + std::to_string(inner.size()) + " row indices for " +
                                 std::to_string(values.size()) + " values");
      for (long j = 0; j < cols; ++j)
        if (outer[j] > outer[j + 1]) throw std::runtime_error("/hht/newton/kept/outer: not ascending");
      for (Eigen::Index k = 0; k < inner.size(); ++k)
        if (inner[k] < 0 || inner[k] >= rows) throw std::runtime_error("/hht/newton/kept/inner: index out of range");
      Eigen::SparseMatrix<double>& M = h.kept.matrix;
      M.resize(rows, cols);
      M.resizeNonZeros(values.size());
      std::copy(outer.data(), outer.data() + outer.size(), M.outerIndexPtr());
      std::copy(inner.data(), inner.data() + inner.size(), M.innerIndexPtr());
      std::copy(values.data(), values.data() + values.size(), M.valuePtr());
      h.kept.key = f.attribute_double("/hht/newton/kept", "key");
      h.kept.valid = true;
    }
    c.pattern_q = get(f, "/system/pattern_q");
    c.system.evaluations = get_long(f, "/system", "evaluations");
    c.system.tangent_evaluations = get_long(f, "/system", "tangent_evaluations");
    c.system.pattern_rebuilds = get_long(f, "/system", "pattern_rebuilds");
    c.system.max_active_contacts = get_long(f, "/system", "max_active_contacts");
    c.system.contact_time_s = f.attribute_double("/system", "contact_time_s");
    c.system.models_time_s = f.attribute_double("/system", "models_time_s");
    c.system.copy_time_s = f.attribute_double("/system", "copy_time_s");
  });
  if (!ok) return std::nullopt;
  return c;
}

}  // namespace arthrosim::pipelines
