#include "pipelines/comak_checkpoint.h"

#include <exception>
#include <stdexcept>

#include "common/checkpoint.h"
#include "common/hdf5.h"
#include "common/output_file.h"

namespace arthrosim::pipelines {
namespace fs = std::filesystem;
namespace msk = musculoskeletal;

namespace {

constexpr const char* kFormat = "arthrosim comak checkpoint";
constexpr std::int64_t kFormatVersion = 1;

// A vector that may be empty (HDF5 datasets are written only when not).
void put(common::H5File& f, const std::string& name, const Eigen::VectorXd& v) {
  if (v.size() > 0) f.write(name, v);
}
Eigen::VectorXd get(const common::H5File& f, const std::string& name) {
  return f.exists(name) ? f.read_vector(name) : Eigen::VectorXd();
}

// Vectors of any sizes as one flat dataset and their sizes.
void put_series(common::H5File& f, const std::string& name, const std::vector<const Eigen::VectorXd*>& rows) {
  std::vector<double> flat;
  std::vector<int> sizes;
  for (const Eigen::VectorXd* r : rows) {
    flat.insert(flat.end(), r->data(), r->data() + r->size());
    sizes.push_back(static_cast<int>(r->size()));
  }
  f.create_group(name);
  if (!flat.empty()) f.write(name + "/values", flat);
  f.write(name + "/sizes", sizes);
}
std::vector<Eigen::VectorXd> get_series(const common::H5File& f, const std::string& name) {
  const Eigen::VectorXi sizes = f.read_vector_int(name + "/sizes");
  const Eigen::VectorXd flat = get(f, name + "/values");
  std::vector<Eigen::VectorXd> rows;
  Eigen::Index at = 0;
  for (Eigen::Index i = 0; i < sizes.size(); ++i) {
    if (sizes[i] < 0 || at + sizes[i] > flat.size()) throw std::runtime_error(name + ": sizes exceed the values");
    rows.push_back(flat.segment(at, sizes[i]));
    at += sizes[i];
  }
  return rows;
}

}  // namespace

void write_comak_checkpoint(const fs::path& path, const ComakCheckpoint& c, int sequence) {
  common::write_checkpoint(path, kFormat, kFormatVersion, c.identity, sequence, [&](common::H5File& f) {
    const msk::ComakRunState& s = c.state;
    f.set_attribute("/", "frames_total", c.frames_total);
    f.set_attribute("/", "frames_done", static_cast<std::int64_t>(s.frames_done));
    // The run state.
    f.create_group("/state");
    put(f, "/state/q", s.q);
    put(f, "/state/a", s.a);
    put(f, "/state/q_prev", s.q_prev);
    f.set_attribute("/state", "t_prev", s.t_prev);
    f.set_attribute("/state", "have_warm", static_cast<std::int64_t>(s.have_warm ? 1 : 0));
    f.create_group("/state/warm");
    put(f, "/state/warm/lambda", s.warm.lambda);
    put(f, "/state/warm/z_lower", s.warm.z_lower);
    put(f, "/state/warm/z_upper", s.warm.z_upper);
    // The summary so far.
    const msk::ComakRunSummary& m = s.summary;
    f.create_group("/summary");
    f.set_attribute("/summary", "frames", static_cast<std::int64_t>(m.frames));
    f.set_attribute("/summary", "converged", static_cast<std::int64_t>(m.converged));
    f.set_attribute("/summary", "failed", static_cast<std::int64_t>(m.failed));
    f.set_attribute("/summary", "total_iterations", static_cast<std::int64_t>(m.total_iterations));
    f.set_attribute("/summary", "wall_time", m.wall_time);
    if (!m.failed_frames.empty())
      f.write("/summary/failed_frames", std::vector<int>(m.failed_frames.begin(), m.failed_frames.end()));
    f.create_group("/settle");
    f.set_attribute("/settle", "status", static_cast<std::int64_t>(m.first_settle.status));
    f.set_attribute("/settle", "iterations", static_cast<std::int64_t>(m.first_settle.iterations));
    f.set_attribute("/settle", "max_force_residual", m.first_settle.max_force_residual);
    f.set_attribute("/settle", "max_moment_residual", m.first_settle.max_moment_residual);
    f.set_attribute("/settle", "message", m.first_settle.message);
    put(f, "/settle/q", m.first_settle.q);
    if (!m.first_settle.history.empty()) f.write("/settle/history", m.first_settle.history);
    // The frames done.
    f.create_group("/frames");
    std::vector<const Eigen::VectorXd*> q, act, res, qp;
    std::vector<double> dtp, obj, fres, mres, wall;
    std::vector<int> status, ipopt, iters, attempts;
    std::vector<std::string> names, messages;
    for (const ComakFrameRecord& r : c.frames) {
      q.push_back(&r.result.q);
      act.push_back(&r.result.activations);
      res.push_back(&r.result.reserves);
      qp.push_back(&r.q_previous);
      dtp.push_back(r.dt_previous);
      obj.push_back(r.result.objective);
      fres.push_back(r.result.max_force_residual);
      mres.push_back(r.result.max_moment_residual);
      wall.push_back(r.result.wall_time);
      status.push_back(static_cast<int>(r.result.status));
      ipopt.push_back(r.result.ipopt_status);
      iters.push_back(r.result.iterations);
      attempts.push_back(r.result.attempts);
      names.push_back(r.result.ipopt_status_name);
      messages.push_back(r.result.message);
    }
    put_series(f, "/frames/q", q);
    put_series(f, "/frames/activations", act);
    put_series(f, "/frames/reserves", res);
    put_series(f, "/frames/q_previous", qp);
    f.write("/frames/dt_previous", dtp);
    f.write("/frames/objective", obj);
    f.write("/frames/max_force_residual", fres);
    f.write("/frames/max_moment_residual", mres);
    f.write("/frames/wall_time", wall);
    f.write("/frames/status", status);
    f.write("/frames/ipopt_status", ipopt);
    f.write("/frames/iterations", iters);
    f.write("/frames/attempts", attempts);
    f.write("/frames/ipopt_status_name", names);
    f.write("/frames/message", messages);
  });
}

std::optional<ComakCheckpoint> read_comak_checkpoint(const fs::path& path, std::string& why) {
  ComakCheckpoint c;
  const bool ok = common::read_checkpoint(path, kFormat, kFormatVersion, c.identity, why, [&](const common::H5File& f) {
    c.frames_total = f.attribute_int("/", "frames_total");
    msk::ComakRunState& s = c.state;
    s.frames_done = static_cast<int>(f.attribute_int("/", "frames_done"));
    s.q = get(f, "/state/q");
    s.a = get(f, "/state/a");
    s.q_prev = get(f, "/state/q_prev");
    s.t_prev = f.attribute_double("/state", "t_prev");
    s.have_warm = f.attribute_int("/state", "have_warm") != 0;
    s.warm.lambda = get(f, "/state/warm/lambda");
    s.warm.z_lower = get(f, "/state/warm/z_lower");
    s.warm.z_upper = get(f, "/state/warm/z_upper");
    msk::ComakRunSummary& m = s.summary;
    m.frames = static_cast<int>(f.attribute_int("/summary", "frames"));
    m.converged = static_cast<int>(f.attribute_int("/summary", "converged"));
    m.failed = static_cast<int>(f.attribute_int("/summary", "failed"));
    m.total_iterations = static_cast<int>(f.attribute_int("/summary", "total_iterations"));
    m.wall_time = f.attribute_double("/summary", "wall_time");
    if (f.exists("/summary/failed_frames")) {
      const Eigen::VectorXi ff = f.read_vector_int("/summary/failed_frames");
      m.failed_frames.assign(ff.data(), ff.data() + ff.size());
    }
    m.first_settle.status = static_cast<msk::SettleStatus>(f.attribute_int("/settle", "status"));
    m.first_settle.iterations = static_cast<int>(f.attribute_int("/settle", "iterations"));
    m.first_settle.max_force_residual = f.attribute_double("/settle", "max_force_residual");
    m.first_settle.max_moment_residual = f.attribute_double("/settle", "max_moment_residual");
    m.first_settle.message = f.attribute_string("/settle", "message");
    m.first_settle.q = get(f, "/settle/q");
    if (f.exists("/settle/history")) {
      const Eigen::VectorXd h = f.read_vector("/settle/history");
      m.first_settle.history.assign(h.data(), h.data() + h.size());
    }
    const auto q = get_series(f, "/frames/q"), act = get_series(f, "/frames/activations"),
               res = get_series(f, "/frames/reserves"), qp = get_series(f, "/frames/q_previous");
    const Eigen::VectorXd dtp = f.read_vector("/frames/dt_previous"), obj = f.read_vector("/frames/objective"),
                          fres = f.read_vector("/frames/max_force_residual"),
                          mres = f.read_vector("/frames/max_moment_residual"), wall = f.read_vector("/frames/wall_time");
    const Eigen::VectorXi status = f.read_vector_int("/frames/status"), ipopt = f.read_vector_int("/frames/ipopt_status"),
                          iters = f.read_vector_int("/frames/iterations"),
                          attempts = f.read_vector_int("/frames/attempts");
    const std::vector<std::string> names = f.read_strings("/frames/ipopt_status_name"),
                                   messages = f.read_strings("/frames/message");
    const std::size_t n = static_cast<std::size_t>(s.frames_done);
    for (std::size_t size : {q.size(), act.size(), res.size(), qp.size(), static_cast<std::size_t>(dtp.size()),
                             static_cast<std::size_t>(obj.size()), static_cast<std::size_t>(wall.size()),
                             static_cast<std::size_t>(status.size()), names.size(), messages.size()})
      if (size != n) {
        throw std::runtime_error("it holds " + std::to_string(size) + " records for " + std::to_string(n) + " frames done");
      }
    if (s.frames_done < 1 || s.frames_done > c.frames_total || m.frames != s.frames_done) {
      throw std::runtime_error("inconsistent frame counts (" + std::to_string(s.frames_done) + " done of " +
            std::to_string(c.frames_total) + ")");
    }
    for (std::size_t i = 0; i < n; ++i) {
      ComakFrameRecord r;
      const Eigen::Index k = static_cast<Eigen::Index>(i);
      r.result.q = q[i];
      r.result.activations = act[i];
      r.result.reserves = res[i];
      r.q_previous = qp[i];
      r.dt_previous = dtp[k];
      r.result.objective = obj[k];
      r.result.max_force_residual = fres[k];
      r.result.max_moment_residual = mres[k];
      r.result.wall_time = wall[k];
      r.result.status = static_cast<msk::ComakFrameStatus>(status[k]);
      r.result.ipopt_status = ipopt[k];
      r.result.iterations = iters[k];
      r.result.attempts = attempts[k];
      r.result.ipopt_status_name = names[i];
      r.result.message = messages[i];
      c.frames.push_back(std::move(r));
    }
  });
  if (!ok) return std::nullopt;
  return c;
}

}  // namespace arthrosim::pipelines
