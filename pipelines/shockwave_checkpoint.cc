#include "pipelines/shockwave_checkpoint.h"

#include <stdexcept>

#include "common/checkpoint.h"
#include "common/hdf5.h"

namespace arthrosim::pipelines {
namespace fs = std::filesystem;

namespace {

constexpr const char* kFormat = "arthrosim shockwave checkpoint";
constexpr std::int64_t kFormatVersion = 1;

// The scalar attributes of a finished run, in the order of this table.
struct RunNumber {
  const char* name;
  double ShockwaveRunResult::*field;
};
const RunNumber kRunNumbers[] = {
    {"efd_j_per_m2", &ShockwaveRunResult::efd_j_per_m2},
    {"peak_pressure_pa", &ShockwaveRunResult::peak_pressure_pa},
    {"wall_s", &ShockwaveRunResult::wall_s},
    {"cpu_s", &ShockwaveRunResult::cpu_s},
    {"energy_residual", &ShockwaveRunResult::energy_residual},
    {"force_n", &ShockwaveRunResult::force_n},
    {"displacement_m", &ShockwaveRunResult::displacement_m},
    {"stiffness_n_per_m", &ShockwaveRunResult::stiffness_n_per_m},
    {"bar_speed", &ShockwaveRunResult::bar_speed},
    {"bar_drained_speed", &ShockwaveRunResult::bar_drained_speed},
    {"bar_undrained_speed", &ShockwaveRunResult::bar_undrained_speed},
};

// Frame scalars, the columns of /current/frames/scalars.
constexpr int kFrameScalars = 8;
void frame_scalars(const ShockwaveFrame& f, double* row) {
  const double v[kFrameScalars] = {f.time, f.applied_pressure, f.kinetic, f.potential,
                                   f.work, f.dissipation, f.compression_force, f.compression_displacement};
  for (int k = 0; k < kFrameScalars; ++k) row[k] = v[k];
}
void set_frame_scalars(ShockwaveFrame& f, const double* row) {
  f.time = row[0];
  f.applied_pressure = row[1];
  f.kinetic = row[2];
  f.potential = row[3];
  f.work = row[4];
  f.dissipation = row[5];
  f.compression_force = row[6];
  f.compression_displacement = row[7];
}

// One per-frame field as an (F, N) matrix; nothing when the frames have none.
void write_field(common::H5File& f, const std::string& name, const std::vector<ShockwaveFrame>& frames,
                 std::vector<double> ShockwaveFrame::*field) {
  if (frames.empty() || (frames.front().*field).empty()) return;
  const Eigen::Index n = static_cast<Eigen::Index>((frames.front().*field).size());
  Eigen::MatrixXd M(static_cast<Eigen::Index>(frames.size()), n);
  for (size_t k = 0; k < frames.size(); ++k) {
    if (static_cast<Eigen::Index>((frames[k].*field).size()) != n)
      throw std::logic_error("shockwave checkpoint: frames of different sizes in " + name);
    M.row(static_cast<Eigen::Index>(k)) = Eigen::Map<const Eigen::RowVectorXd>((frames[k].*field).data(), n);
  }
  f.write(name, M);
}
void read_field(const common::H5File& f, const std::string& name, std::vector<ShockwaveFrame>& frames,
                std::vector<double> ShockwaveFrame::*field) {
  if (!f.exists(name)) return;
  const Eigen::MatrixXd M = f.read_matrix(name);
  if (M.rows() != static_cast<Eigen::Index>(frames.size()))
    throw std::runtime_error(name + ": expected " + std::to_string(frames.size()) + " rows, found " +
                             std::to_string(M.rows()));
  for (size_t k = 0; k < frames.size(); ++k) {
    const Eigen::RowVectorXd r = M.row(static_cast<Eigen::Index>(k));
    frames[k].*field = std::vector<double>(r.data(), r.data() + r.size());
  }
}

std::vector<double> to_std(const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); }

}  // namespace

void write_shockwave_checkpoint(const fs::path& path, const ShockwaveCheckpoint& c, int sequence) {
  common::write_checkpoint(path, kFormat, kFormatVersion, c.identity, sequence, [&](common::H5File& f) {
    f.set_attribute("/", "runs_finished", static_cast<std::int64_t>(c.finished.size()));
    f.create_group("/finished");
    for (size_t r = 0; r < c.finished.size(); ++r) {
      const ShockwaveRunResult& rr = c.finished[r].result;
      const std::string g = "/finished/" + std::to_string(r);
      f.create_group(g);
      f.set_attribute(g, "label", rr.label);
      f.set_attribute(g, "file", rr.file.string());
      f.set_attribute(g, "file_sha256", c.finished[r].file_sha256);
      f.set_attribute(g, "steps", static_cast<std::int64_t>(rr.steps));
      f.set_attribute(g, "frames", static_cast<std::int64_t>(rr.frames));
      for (const RunNumber& x : kRunNumbers) f.set_attribute(g, x.name, rr.*(x.field));
      Eigen::MatrixXd volumes(static_cast<Eigen::Index>(rr.volumes.size()), 5);
      for (size_t t = 0; t < rr.volumes.size(); ++t) {
        const shockwave::RegenerationVolumes& v = rr.volumes[t];
        volumes.row(static_cast<Eigen::Index>(t)) << v.tissue, v.compressive, v.distortional, v.pore, v.all;
      }
      Eigen::MatrixXd peaks(static_cast<Eigen::Index>(rr.max_peaks.size()), 3);
      for (size_t t = 0; t < rr.max_peaks.size(); ++t)
        peaks.row(static_cast<Eigen::Index>(t)) << rr.max_peaks[t][0], rr.max_peaks[t][1], rr.max_peaks[t][2];
      f.write(g + "/volumes", volumes);
      f.write(g + "/max_peaks", peaks);
      f.write(g + "/all_at_once_m3", rr.all_at_once_m3);
    }
    if (!c.current) return;
    const ShockwaveRunProgress& p = *c.current;
    f.create_group("/current");
    f.set_attribute("/current", "run", static_cast<std::int64_t>(p.run));
    f.set_attribute("/current", "peak_pressure_pa", p.peak_pressure_pa);
    f.create_group("/current/simulation");
    const std::string s = "/current/simulation";
    f.set_attribute(s, "steps", static_cast<std::int64_t>(p.sim.steps));
    f.set_attribute(s, "buffer", static_cast<std::int64_t>(p.sim.buffer));
    f.set_attribute(s, "kinetic", p.sim.kinetic);
    f.set_attribute(s, "work", p.sim.work);
    f.set_attribute(s, "dissipation", p.sim.dissipation);
    f.set_attribute(s, "damping", p.sim.damping);
    std::vector<std::string> names;
    for (const auto& [name, array] : p.sim.arrays) {
      names.push_back(name);
      f.write(s + "/" + name, array);
    }
    f.write(s + "/arrays", names);
    f.create_group("/current/frames");
    f.set_attribute("/current/frames", "count", static_cast<std::int64_t>(p.frames.size()));
    if (!p.frames.empty()) {
      Eigen::MatrixXd scalars(static_cast<Eigen::Index>(p.frames.size()), kFrameScalars);
      for (size_t k = 0; k < p.frames.size(); ++k) {
        double row[kFrameScalars];
        frame_scalars(p.frames[k], row);
        for (int j = 0; j < kFrameScalars; ++j) scalars(static_cast<Eigen::Index>(k), j) = row[j];
      }
      f.write("/current/frames/scalars", scalars);
      write_field(f, "/current/frames/all_at_once_m3", p.frames, &ShockwaveFrame::all_at_once_m3);
      write_field(f, "/current/frames/pressure", p.frames, &ShockwaveFrame::pressure);
      write_field(f, "/current/frames/distortional_strain", p.frames, &ShockwaveFrame::distortional_strain);
      write_field(f, "/current/frames/pore_pressure", p.frames, &ShockwaveFrame::pore_pressure);
    }
    f.set_attribute("/current", "bar_steps", static_cast<std::int64_t>(p.bar_p1.size()));
    if (!p.bar_p1.empty()) {
      f.write("/current/bar_p1", p.bar_p1);
      f.write("/current/bar_p2", p.bar_p2);
    }
  });
}

std::optional<ShockwaveCheckpoint> read_shockwave_checkpoint(const fs::path& path, std::string& why) {
  ShockwaveCheckpoint c;
  const bool ok = common::read_checkpoint(path, kFormat, kFormatVersion, c.identity, why, [&](const common::H5File& f) {
    const std::int64_t finished = f.attribute_int("/", "runs_finished");
    for (std::int64_t r = 0; r < finished; ++r) {
      const std::string g = "/finished/" + std::to_string(r);
      ShockwaveFinishedRun fr;
      ShockwaveRunResult& rr = fr.result;
      rr.label = f.attribute_string(g, "label");
      rr.file = f.attribute_string(g, "file");
      fr.file_sha256 = f.attribute_string(g, "file_sha256");
      rr.steps = f.attribute_int(g, "steps");
      rr.frames = static_cast<int>(f.attribute_int(g, "frames"));
      for (const RunNumber& x : kRunNumbers) rr.*(x.field) = f.attribute_double(g, x.name);
      const Eigen::MatrixXd volumes = f.read_matrix(g + "/volumes", 5);
      for (Eigen::Index t = 0; t < volumes.rows(); ++t)
        rr.volumes.push_back({volumes(t, 0), volumes(t, 1), volumes(t, 2), volumes(t, 3), volumes(t, 4)});
      const Eigen::MatrixXd peaks = f.read_matrix(g + "/max_peaks", 3);
      for (Eigen::Index t = 0; t < peaks.rows(); ++t) rr.max_peaks.push_back({peaks(t, 0), peaks(t, 1), peaks(t, 2)});
      rr.all_at_once_m3 = to_std(f.read_vector(g + "/all_at_once_m3"));
      if (rr.max_peaks.size() != rr.volumes.size() || rr.all_at_once_m3.size() != rr.volumes.size())
        throw std::runtime_error(g + ": tissue counts of volumes, peaks and at-once volumes differ");
      c.finished.push_back(std::move(fr));
    }
    if (!f.exists("/current")) return;
    ShockwaveRunProgress p;
    p.run = static_cast<int>(f.attribute_int("/current", "run"));
    if (p.run != finished)
      throw std::runtime_error("/current: run " + std::to_string(p.run) + " after " + std::to_string(finished) +
                               " finished runs");
    p.peak_pressure_pa = f.attribute_double("/current", "peak_pressure_pa");
    const std::string s = "/current/simulation";
    p.sim.steps = f.attribute_int(s, "steps");
    p.sim.buffer = static_cast<int>(f.attribute_int(s, "buffer"));
    p.sim.kinetic = f.attribute_double(s, "kinetic");
    p.sim.work = f.attribute_double(s, "work");
    p.sim.dissipation = f.attribute_double(s, "dissipation");
    p.sim.damping = f.attribute_double(s, "damping");
    for (const std::string& name : f.read_strings(s + "/arrays"))
      p.sim.arrays.emplace_back(name, to_std(f.read_vector(s + "/" + name)));
    const std::int64_t frames = f.attribute_int("/current/frames", "count");
    p.frames.resize(static_cast<size_t>(frames));
    if (frames > 0) {
      const Eigen::MatrixXd scalars = f.read_matrix("/current/frames/scalars", kFrameScalars);
      if (scalars.rows() != frames)
        throw std::runtime_error("/current/frames/scalars: expected " + std::to_string(frames) + " rows, found " +
                                 std::to_string(scalars.rows()));
      for (std::int64_t k = 0; k < frames; ++k) {
        const Eigen::RowVectorXd r = scalars.row(static_cast<Eigen::Index>(k));
        set_frame_scalars(p.frames[static_cast<size_t>(k)], r.data());
      }
      read_field(f, "/current/frames/all_at_once_m3", p.frames, &ShockwaveFrame::all_at_once_m3);
      read_field(f, "/current/frames/pressure", p.frames, &ShockwaveFrame::pressure);
      read_field(f, "/current/frames/distortional_strain", p.frames, &ShockwaveFrame::distortional_strain);
      read_field(f, "/current/frames/pore_pressure", p.frames, &ShockwaveFrame::pore_pressure);
    }
    const std::int64_t bar_steps = f.attribute_int("/current", "bar_steps");
    if (bar_steps > 0) {
      p.bar_p1 = to_std(f.read_vector("/current/bar_p1"));
      p.bar_p2 = to_std(f.read_vector("/current/bar_p2"));
      if (static_cast<std::int64_t>(p.bar_p1.size()) != bar_steps ||
          static_cast<std::int64_t>(p.bar_p2.size()) != bar_steps)
        throw std::runtime_error("/current/bar_p1, bar_p2: expected " + std::to_string(bar_steps) + " values");
    }
    c.current = std::move(p);
  });
  if (!ok) return std::nullopt;
  return c;
}

}  // namespace arthrosim::pipelines
