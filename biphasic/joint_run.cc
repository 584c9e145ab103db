#include "biphasic/joint_run.h"

#include <cmath>
#include <exception>
#include <set>
#include <sstream>

#include "common/error.h"
#include "common/spatial.h"

namespace arthrosim::biphasic {

const char* to_string(Region region) {
  switch (region) {
    case Region::kCentral: return "central";
    case Region::kAnterior: return "anterior";
    case Region::kPosterior: return "posterior";
    case Region::kMedial: return "medial";
    case Region::kLateral: return "lateral";
  }
  return "?";
}

JointRun::JointRun(std::vector<JointLayer> layers, std::vector<JointPair> pairs, JointOptions options)
    : layers_(std::move(layers)), pairs_(std::move(pairs)), options_(options) {
  std::set<std::string> names;
  for (const JointLayer& l : layers_) {
    if (!names.insert(l.name).second) throw common::InputError("biphasic: layer '" + l.name + "' given twice");
  }
  for (const JointPair& p : pairs_) {
    for (const std::string& n : {p.a, p.b}) {
      if (!names.count(n)) {
        throw common::InputError("biphasic: contact pair " + p.a + " / " + p.b + ": no layer named '" + n + "'");
      }
    }
    if (p.a == p.b) throw common::InputError("biphasic: contact pair of layer '" + p.a + "' with itself");
  }
  // Layers are independent: built (extrusion, assembly, factorisation) in
  // parallel, each by one thread, so the result does not depend on the
  // thread count.
  const int nl = static_cast<int>(layers_.size());
  problems_.resize(nl);
  regions_.resize(nl);
  node_areas_.resize(nl);
  untangled_.resize(nl);
  std::vector<std::exception_ptr> errors(nl);
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < nl; ++i) {
    try {
      build_layer(i);
    } catch (...) {
      errors[i] = std::current_exception();
    }
  }
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
}

void JointRun::build_layer(int i) {
  JointLayer& l = layers_[i];
  common::QuadMesh surface = l.surface;
  surface.name = l.name;
  untangled_[i] = untangle_normals(surface, &l.normals, l.thickness);
  LayerMesh mesh = extrude_layer(surface, l.normals, l.thickness, options_.element_layers,
                                 graded_levels(options_.element_layers, options_.grading));
  problems_[i] = std::make_unique<LayerProblem>(assemble_layer(std::move(mesh), l.material, options_.pair),
                                                options_.time);
  const LayerMesh& m = problems_[i]->system().mesh;
  const Eigen::VectorXd area = articular_node_areas(m);
  node_areas_[i] = area;
  // Regions from the area centroid and the half extents along the axes.
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int v = 0; v < m.num_vertices(); ++v) c += area[v] * m.surface.V.row(v).transpose();
  c /= area.sum();
  double ant_min = 0, ant_max = 0, lat_min = 0, lat_max = 0;
  for (int v = 0; v < m.num_vertices(); ++v) {
    const Eigen::Vector3d d = m.surface.V.row(v).transpose() - c;
    ant_min = std::min(ant_min, d.dot(options_.anterior_B));
    ant_max = std::max(ant_max, d.dot(options_.anterior_B));
    lat_min = std::min(lat_min, d.dot(options_.lateral_B));
    lat_max = std::max(lat_max, d.dot(options_.lateral_B));
  }
  std::vector<Region> r(m.num_vertices());
  for (int v = 0; v < m.num_vertices(); ++v) {
    const Eigen::Vector3d d = m.surface.V.row(v).transpose() - c;
    const double a = d.dot(options_.anterior_B), s = d.dot(options_.lateral_B);
    const double an = a / (a >= 0 ? std::max(ant_max, 1e-12) : std::max(-ant_min, 1e-12));
    const double sn = s / (s >= 0 ? std::max(lat_max, 1e-12) : std::max(-lat_min, 1e-12));
    if (std::abs(an) <= options_.central_fraction && std::abs(sn) <= options_.central_fraction) {
      r[v] = Region::kCentral;
    } else if (std::abs(an) >= std::abs(sn)) {
      r[v] = an > 0 ? Region::kAnterior : Region::kPosterior;
    } else {
      r[v] = sn > 0 ? Region::kLateral : Region::kMedial;
    }
  }
  regions_[i] = std::move(r);
}

int JointRun::layer_index(const std::string& name) const {
  for (size_t i = 0; i < layers_.size(); ++i)
    if (layers_[i].name == name) return static_cast<int>(i);
  return -1;
}

namespace {

std::string frame_label(const JointFrame& f) {
  std::ostringstream s;
  s << "frame at t = " << f.time_s << " s";
  return s.str();
}

const Eigen::Isometry3d& pose(const JointFrame& frame, const std::string& bone) {
  auto it = frame.X_WB.find(bone);
  if (it == frame.X_WB.end()) {
    throw common::InputError("biphasic: " + frame_label(frame) + ": expected a pose of bone '" + bone +
                             "', found none");
  }
  return it->second;
}

}  // namespace

std::vector<std::vector<char>> contact_vertices(const std::vector<JointLayer>& layers,
                                                const std::vector<JointPair>& pairs,
                                                const std::vector<JointFrame>& frames) {
  auto index = [&](const std::string& name) {
    for (size_t i = 0; i < layers.size(); ++i)
      if (layers[i].name == name) return static_cast<int>(i);
    throw common::InputError("biphasic: contact pair names no layer '" + name + "'");
  };
  std::vector<std::vector<char>> out;
  for (const JointLayer& l : layers) {
    common::QuadMesh s = l.surface;
    s.name = l.name;
    validate_surface_data(s, l.normals, l.thickness);
    validate(l.material, "layer '" + l.name + "'");
    out.emplace_back(l.surface.num_nodes(), 0);
  }
  for (const JointFrame& frame : frames) {
    std::vector<PlacedSurface> placed;
    std::vector<std::unique_ptr<common::TriangleTree>> trees;
    for (const JointLayer& l : layers) {
      common::QuadMesh s = l.surface;
      s.name = l.name;
      placed.push_back(place_surface(s, l.normals, l.thickness, l.material.aggregate_modulus_Pa, pose(frame, l.bone)));
      trees.push_back(std::make_unique<common::TriangleTree>(placed.back().triangles));
    }
    for (const JointPair& p : pairs) {
      const int a = index(p.a), b = index(p.b);
      // The force only scales the conditions; 1 N finds the same contact set.
      const ContactConditions ca = penetration_conditions(placed[a], placed[b], *trees[b], 1.0);
      const ContactConditions cb = penetration_conditions(placed[b], placed[a], *trees[a], 1.0);
      for (size_t v = 0; v < ca.in_contact.size(); ++v) out[a][v] |= ca.in_contact[v];
      for (size_t v = 0; v < cb.in_contact.size(); ++v) out[b][v] |= cb.in_contact[v];
    }
  }
  return out;
}

JointLayer crop_layer(const JointLayer& layer, const std::vector<char>& seed, double margin_m,
                      std::vector<int>* kept) {
  const int nv = layer.surface.num_nodes();
  std::vector<Eigen::Vector3d> seeds;
  for (int v = 0; v < nv; ++v)
    if (seed[v]) seeds.push_back(layer.surface.V.row(v).transpose());
  std::vector<char> near(nv, 0);
  const double m2 = margin_m * margin_m;
  for (int v = 0; v < nv; ++v) {
    const Eigen::Vector3d x = layer.surface.V.row(v).transpose();
    for (const Eigen::Vector3d& s : seeds) {
      if ((x - s).squaredNorm() <= m2) {
        near[v] = 1;
        break;
      }
    }
  }
  std::vector<int> quads;
  std::vector<int> new_index(nv, -1);
  std::vector<int> old_index;
  for (int q = 0; q < layer.surface.num_quads(); ++q) {
    bool keep = false;
    for (int k = 0; k < 4; ++k) keep = keep || near[layer.surface.Q(q, k)];
    if (!keep) continue;
    quads.push_back(q);
    for (int k = 0; k < 4; ++k) {
      const int v = layer.surface.Q(q, k);
      if (new_index[v] < 0) {
        new_index[v] = static_cast<int>(old_index.size());
        old_index.push_back(v);
      }
    }
  }
  JointLayer out = layer;
  const int n = static_cast<int>(old_index.size());
  out.surface.V.resize(n, 3);
  out.normals.resize(n, 3);
  out.thickness.resize(n);
  for (int i = 0; i < n; ++i) {
    out.surface.V.row(i) = layer.surface.V.row(old_index[i]);
    out.normals.row(i) = layer.normals.row(old_index[i]);
    out.thickness[i] = layer.thickness[old_index[i]];
  }
  out.surface.Q.resize(static_cast<int>(quads.size()), 4);
  for (size_t i = 0; i < quads.size(); ++i)
    for (int k = 0; k < 4; ++k) out.surface.Q(static_cast<int>(i), k) = new_index[layer.surface.Q(quads[i], k)];
  if (kept) *kept = old_index;
  return out;
}

std::vector<PairFrame> JointRun::contact(const JointFrame& frame) const {
  std::vector<PlacedSurface> placed;
  std::vector<std::unique_ptr<common::TriangleTree>> trees;
  for (size_t i = 0; i < layers_.size(); ++i) {
    placed.push_back(place_surface(problems_[i]->system().mesh, layers_[i].material.aggregate_modulus_Pa,
                                   pose(frame, layers_[i].bone)));
    trees.push_back(std::make_unique<common::TriangleTree>(placed.back().triangles));
  }
  std::vector<PairFrame> out;
  for (const JointPair& p : pairs_) {
    auto it = frame.force_N.find(p.compartment);
    if (it == frame.force_N.end()) {
      throw common::InputError("biphasic: " + frame_label(frame) + ": expected the contact force of compartment '" +
                               p.compartment + "', found none");
    }
    const int a = layer_index(p.a), b = layer_index(p.b);
    PairFrame pf;
    pf.a = penetration_conditions(placed[a], placed[b], *trees[b], it->second);
    pf.b = penetration_conditions(placed[b], placed[a], *trees[a], it->second);
    out.push_back(std::move(pf));
  }
  return out;
}

std::vector<SurfaceLoads> JointRun::layer_loads(const JointFrame& frame,
                                                const std::vector<PairFrame>& conditions) const {
  std::vector<SurfaceLoads> out;
  for (size_t i = 0; i < layers_.size(); ++i) {
    const Eigen::Isometry3d& X = pose(frame, layers_[i].bone);
    const PlacedSurface placed =
        place_surface(problems_[i]->system().mesh, layers_[i].material.aggregate_modulus_Pa, X);
    std::vector<const ContactConditions*> mine;
    for (size_t k = 0; k < pairs_.size(); ++k) {
      if (pairs_[k].a == layers_[i].name) mine.push_back(&conditions[k].a);
      if (pairs_[k].b == layers_[i].name) mine.push_back(&conditions[k].b);
    }
    out.push_back(surface_loads(placed, mine, X.linear().transpose()));
  }
  return out;
}

LayerStep JointRun::evaluate(int layer, const SurfaceLoads& loads, const Eigen::VectorXd& u,
                             const Eigen::VectorXd& p) const {
  const LayerProblem& lp = *problems_[layer];
  const LayerSystem& sys = lp.system();
  const LayerMesh& m = sys.mesh;
  LayerStep s;
  s.fields = nodal_fields(sys, u, p);
  s.loads = loads;
  const Eigen::VectorXd& area = node_areas_[layer];
  double fluid = 0.0, total = 0.0;
  for (int v = 0; v < m.num_vertices(); ++v) {
    const double t = loads.traction.segment<3>(3 * v).norm();
    if (t <= 0.0) continue;
    s.contact_area_m2 += area[v];
    fluid += area[v] * loads.pressure[v];
    total += area[v] * t;
    const double sigma1 = s.fields.max_principal[m.q1_node(v, m.layers)];
    if (s.max_tensile_vertex < 0 || sigma1 > s.max_tensile_Pa) {
      s.max_tensile_Pa = sigma1;
      s.max_tensile_vertex = v;
    }
  }
  s.fluid_load_support = total > 0.0 ? fluid / total : 0.0;
  if (s.max_tensile_vertex >= 0) s.max_tensile_region = regions_[layer][s.max_tensile_vertex];
  for (int v = 0; v < m.num_vertices(); ++v) {
    const double tau = s.fields.max_shear[m.q1_node(v, 0)];
    if (s.max_shear_vertex < 0 || tau > s.max_shear_Pa) {
      s.max_shear_Pa = tau;
      s.max_shear_vertex = v;
    }
  }
  s.max_shear_region = regions_[layer][s.max_shear_vertex];
  return s;
}

int JointRun::run(const std::vector<double>& frame_times, const std::vector<std::vector<SurfaceLoads>>& frame_loads,
                  const std::function<void(int, double, const std::vector<LayerStep>&)>& on_step, int first_step) {
  if (frame_times.size() < 2 || frame_loads.size() != frame_times.size()) {
    throw common::InputError("biphasic: expected at least two frames with loads, found " +
                             std::to_string(frame_times.size()) + " times and " +
                             std::to_string(frame_loads.size()) + " load sets");
  }
  const size_t nl = layers_.size();
  std::vector<std::vector<SurfaceLoads>> per_layer(nl);
  for (const auto& f : frame_loads) {
    if (f.size() != nl) throw std::invalid_argument("biphasic: frame loads for a different number of layers");
    for (size_t i = 0; i < nl; ++i) per_layer[i].push_back(f[i]);
  }
  const double dt = options_.time.time_step_s;
  const double t0 = frame_times.front();
  const int steps = static_cast<int>(std::floor((frame_times.back() - t0) / dt + 1e-9));
  std::vector<LayerStep> results(nl);
  std::vector<std::exception_ptr> errors(nl);
  for (int i = std::max(first_step, 1); i <= steps; ++i) {
    const double t = t0 + i * dt;
    // Layers are independent: one thread per layer (deterministic).
#pragma omp parallel for schedule(dynamic, 1)
    for (int l = 0; l < static_cast<int>(nl); ++l) {
      try {
        const SurfaceLoads loads = loads_at(frame_times, per_layer[l], t);
        problems_[l]->step(loads);
        results[l] = evaluate(l, loads, problems_[l]->integrator().u(), problems_[l]->integrator().p());
      } catch (...) {
        errors[l] = std::current_exception();
      }
    }
    for (const std::exception_ptr& e : errors)
      if (e) std::rethrow_exception(e);
    if (on_step) on_step(i, t, results);
  }
  return steps;
}

void JointRun::restore(const std::vector<TrapezoidalState>& states) {
  if (states.size() != problems_.size())
    throw std::invalid_argument("biphasic: " + std::to_string(states.size()) + " layer states for " +
                                std::to_string(problems_.size()) + " layers");
  for (size_t l = 0; l < problems_.size(); ++l) problems_[l]->restore(states[l]);
}

std::vector<LayerStep> JointRun::results_at(const std::vector<double>& frame_times,
                                            const std::vector<std::vector<SurfaceLoads>>& frame_loads, double t,
                                            const std::vector<Eigen::VectorXd>& u,
                                            const std::vector<Eigen::VectorXd>& p) const {
  const size_t nl = layers_.size();
  if (u.size() != nl || p.size() != nl)
    throw std::invalid_argument("biphasic: a step's fields for " + std::to_string(u.size()) + " layers, expected " +
                                std::to_string(nl));
  std::vector<LayerStep> results(nl);
  for (size_t l = 0; l < nl; ++l) {
    std::vector<SurfaceLoads> mine;
    for (const auto& f : frame_loads) mine.push_back(f[l]);
    results[l] = evaluate(static_cast<int>(l), loads_at(frame_times, mine, t), u[l], p[l]);
  }
  return results;
}

}  // namespace arthrosim::biphasic
