#include "pipelines/biphasic_checkpoint.h"

#include <stdexcept>

#include "common/checkpoint.h"
#include "common/hdf5.h"

namespace arthrosim::pipelines {
namespace fs = std::filesystem;

namespace {

constexpr const char* kFormat = "arthrosim biphasic checkpoint";
constexpr std::int64_t kFormatVersion = 1;

std::string layer_group(size_t l) { return "/layers/" + std::to_string(l); }

}  // namespace

void write_biphasic_checkpoint(const fs::path& path, const BiphasicCheckpoint& c, int sequence) {
  common::write_checkpoint(path, kFormat, kFormatVersion, c.identity, sequence, [&](common::H5File& f) {
    f.set_attribute("/", "steps_done", static_cast<std::int64_t>(c.steps_done));
    f.set_attribute("/", "layers", static_cast<std::int64_t>(c.layers.size()));
    f.create_group("/layers");
    for (size_t l = 0; l < c.layers.size(); ++l) {
      const std::string g = layer_group(l);
      const biphasic::TrapezoidalState& s = c.layers[l];
      f.create_group(g);
      f.set_attribute(g, "time", s.time);
      f.set_attribute(g, "steps", static_cast<std::int64_t>(s.steps));
      f.set_attribute(g, "solves", static_cast<std::int64_t>(s.solves));
      f.set_attribute(g, "solve_s", s.solve_s);
      f.set_attribute(g, "step_s", s.step_s);
      f.set_attribute(g, "max_relative_residual", s.max_relative_residual);
      f.write(g + "/u", s.u);
      f.write(g + "/v", s.v);
      f.write(g + "/p", s.p);
      f.write(g + "/last_F_t", s.last_F_t);
      f.write(g + "/last_F_Q", s.last_F_Q);
      if (c.steps_done > 0) {
        f.write(g + "/u_history", common::stack_rows(c.u_history[l]));
        f.write(g + "/p_history", common::stack_rows(c.p_history[l]));
      }
    }
  });
}

std::optional<BiphasicCheckpoint> read_biphasic_checkpoint(const fs::path& path, std::string& why) {
  BiphasicCheckpoint c;
  const bool ok = common::read_checkpoint(path, kFormat, kFormatVersion, c.identity, why, [&](const common::H5File& f) {
    c.steps_done = static_cast<int>(f.attribute_int("/", "steps_done"));
    const std::int64_t layers = f.attribute_int("/", "layers");
    for (std::int64_t l = 0; l < layers; ++l) {
      const std::string g = layer_group(static_cast<size_t>(l));
      biphasic::TrapezoidalState s;
      s.time = f.attribute_double(g, "time");
      s.steps = static_cast<int>(f.attribute_int(g, "steps"));
      s.solves = static_cast<int>(f.attribute_int(g, "solves"));
      s.solve_s = f.attribute_double(g, "solve_s");
      s.step_s = f.attribute_double(g, "step_s");
      s.max_relative_residual = f.attribute_double(g, "max_relative_residual");
      s.u = f.read_vector(g + "/u");
      s.v = f.read_vector(g + "/v");
      s.p = f.read_vector(g + "/p");
      s.last_F_t = f.read_vector(g + "/last_F_t");
      s.last_F_Q = f.read_vector(g + "/last_F_Q");
      if (s.steps != c.steps_done)
        throw std::runtime_error(g + ": " + std::to_string(s.steps) + " steps, expected " + std::to_string(c.steps_done));
      c.layers.push_back(std::move(s));
      c.u_history.push_back(c.steps_done > 0 ? common::unstack_rows(f.read_matrix(g + "/u_history"), c.steps_done, g + "/u_history")
                                             : std::vector<Eigen::VectorXd>());
      c.p_history.push_back(c.steps_done > 0 ? common::unstack_rows(f.read_matrix(g + "/p_history"), c.steps_done, g + "/p_history")
                                             : std::vector<Eigen::VectorXd>());
    }
  });
  if (!ok) return std::nullopt;
  return c;
}

}  // namespace arthrosim::pipelines
