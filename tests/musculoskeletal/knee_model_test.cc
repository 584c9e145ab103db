// The bundled parametric knee model (data/models/knee_parametric/knee*.urdf):
// loads, has the lenhart2015 soft tissues (all 14 ligament groups with their
// bundle counts and stiffness per bundle, all 13 knee-crossing muscles with
// their F_max, as listed in /work/shared/references.md) and loads all three
// contact pairs at the reference pose. The passive settle of this model is
// tested in knee_settle_test.cc.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "common/error.h"
#include "common/hdf5.h"
#include "common/mesh.h"
#include "musculoskeletal/model_io.h"

namespace msk = arthrosim::musculoskeletal;

namespace {
std::string model_path(const char* name) {
  return std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/" + name;
}
}  // namespace

TEST(KneeModel, LoadsWithLenhartSoftTissues) {
  for (const char* f : {"knee.urdf", "knee_coarse.urdf"}) {
    const auto m = msk::load_model(model_path(f));
    EXPECT_EQ(m.free_coordinates.size(), 12u);
    EXPECT_EQ(m.prescribed_coordinates.size(), 4u);
    EXPECT_EQ(m.ligaments.size(), 14u);
    EXPECT_EQ(m.num_bundles(), 76);  // lenhart2015
    EXPECT_EQ(m.muscles.size(), 13u);
    ASSERT_EQ(m.contacts.size(), 3u);
    // lenhart2015: bundles x stiffness per bundle [N per unit strain], and the
    // Blankevoort transition strain 0.06 and OpenSim's damping 0.003 N s.
    const std::vector<std::tuple<const char*, size_t, double>> groups = {
        {"MCLs", 6, 500},  {"MCLd", 5, 500}, {"MCLpo", 5, 500}, {"ACLam", 6, 820}, {"ACLpl", 6, 820},
        {"PCLal", 5, 900}, {"PCLpm", 5, 300}, {"LCL", 4, 600},  {"PFL", 5, 440},   {"PCAP", 8, 500},
        {"PT", 6, 3000},   {"mPFL", 6, 150}, {"lPFL", 8, 150},  {"ITB", 1, 10000}};
    for (const auto& [name, n, k] : groups) {
      const int li = m.ligament_index(name);
      ASSERT_GE(li, 0) << name;
      ASSERT_EQ(m.ligaments[li].bundles.size(), n) << name;
      for (const auto& b : m.ligaments[li].bundles) {
        EXPECT_EQ(b.parameters.stiffness, k) << name;
        EXPECT_EQ(b.parameters.transition_strain, 0.06) << name;
        EXPECT_EQ(b.parameters.damping, 0.003) << name;
      }
    }
    const std::vector<std::pair<const char*, double>> fmax = {
        {"bflh", 705.2},    {"bfsh", 631.6},   {"gaslat", 606.4}, {"gasmed", 1308.0}, {"grac", 137.3},
        {"recfem", 848.8},  {"sart", 113.5},   {"semimem", 1162.7}, {"semiten", 301.9}, {"tfl", 155.0},
        {"vasint", 1024.2}, {"vaslat", 2255.4}, {"vasmed", 1443.7}};
    for (const auto& [name, f] : fmax) {
      const int mi = m.muscle_index(name);
      ASSERT_GE(mi, 0) << name;
      EXPECT_EQ(m.muscles[mi].max_isometric_force, f) << name;
    }
    // Quadriceps act on the patella (their last path point), not on the tibia.
    const int patella = m.tree.body_index("patella");
    for (const char* q : {"recfem", "vasmed", "vaslat", "vasint"})
      EXPECT_EQ(m.muscles[m.muscle_index(q)].path.points.back().body, patella) << q;
    // Contact material of lenhart2015: E = 10 MPa, nu = 0.45, linear law.
    for (const auto& c : m.contacts) {
      EXPECT_EQ(c.material().youngs_modulus, 10e6) << c.name();
      EXPECT_EQ(c.material().poisson_ratio, 0.45) << c.name();
      EXPECT_EQ(c.material().law, msk::FoundationLaw::kLinear) << c.name();
    }
    // Per-triangle thickness from the analytic per-vertex values: 1.5 .. 3.5 mm.
    for (const auto& c : m.contacts) {
      EXPECT_GE(c.casting().thickness.minCoeff(), 1.4e-3) << c.name();
      EXPECT_LE(c.casting().thickness.maxCoeff(), 3.6e-3) << c.name();
    }
    // At the reference pose the designed overlap (0.25 mm) loads every pair.
    auto d = msk::make_data(m);
    msk::evaluate_forces(m, d, Eigen::VectorXd::Zero(m.num_coordinates()), {}, {});
    for (size_t i = 0; i < m.contacts.size(); ++i) {
      const auto& r = d.contacts[i].result;
      std::printf("%s %s at q = 0: %d triangles, force %.1f N, area %.1f mm^2, p_max %.2f MPa\n", f,
                  m.contacts[i].name().c_str(), r.num_contacting, r.force_on_target_W.norm(),
                  r.contact_area * 1e6, r.max_pressure * 1e-6);
      EXPECT_GT(r.num_contacting, 0) << m.contacts[i].name();
    }
  }
}

// use_prepared_surfaces: a prepared file holding the model's own meshes (in
// the mesh files' frame, as arthrosim-prepare writes them) with a uniform
// 2 mm per-vertex thickness gives back the same body-frame meshes with that
// thickness; a prepared file without one of the surfaces, or with a surface
// moved by 5 mm, is rejected naming the file.
TEST(KneeModel, PreparedSurfacesReplaceTheContactMeshes) {
  namespace fs = std::filesystem;
  const auto m0 = msk::load_model(model_path("knee_coarse.urdf"));
  const fs::path dir = fs::path(ARTHROSIM_BINARY_DIR) / "test_scratch" / "knee_model";
  fs::create_directories(dir);
  // Writes a prepared file from the model's surfaces; `shift` moves the
  // named surface [m]; `skip` leaves one out.
  auto write_prepared = [&](const std::string& path, const std::string& skip,
                            const std::string& shifted, double shift) {
    arthrosim::common::H5File f(path, arthrosim::common::H5File::Mode::kTruncate);
    f.set_attribute("/", "schema", "arthrosim prepared model 1");  // the version the reader takes (common/file_check.h)
    std::vector<std::string> names;
    std::set<std::string> done;
    for (const auto& c : m0.contacts) {
      for (const auto* s : {&c.casting(), &c.target()}) {
        if (s->name == skip || !done.insert(s->name).second) continue;
        const std::string n = s->name.substr(0, s->name.find("_cartilage"));
        names.push_back(n);
        const std::string g = "/surfaces/" + n;
        f.create_group(g + "/triangles");
        f.set_attribute(g, "source_file", "/somewhere/else/" + fs::path(s->mesh_file).filename().string());
        Eigen::MatrixXd V(s->mesh.num_vertices(), 3);
        for (int i = 0; i < V.rows(); ++i)
          V.row(i) = (s->X_BM.inverse() * Eigen::Vector3d(s->mesh.V.row(i).transpose())).transpose();
        if (s->name == shifted) V.col(0).array() += shift;
        f.write(g + "/triangles/vertices", V);
        f.write(g + "/triangles/faces", Eigen::MatrixXi(s->mesh.F));
        f.write(g + "/triangles/thickness", Eigen::VectorXd::Constant(V.rows(), 2e-3));
      }
    }
    std::sort(names.begin(), names.end());
    f.write("/surfaces/names", names);
  };
  const std::string good = (dir / "prepared_good.h5").string();
  write_prepared(good, "", "", 0.0);
  auto m = msk::load_model(model_path("knee_coarse.urdf"));
  const auto rep = msk::use_prepared_surfaces(m, good);
  EXPECT_EQ(rep.lines.size(), 4u);
  ASSERT_EQ(m.contacts.size(), m0.contacts.size());
  for (size_t i = 0; i < m.contacts.size(); ++i) {
    const auto& a = m.contacts[i].casting();
    const auto& b = m0.contacts[i].casting();
    EXPECT_EQ(m.contacts[i].name(), m0.contacts[i].name());
    ASSERT_EQ(a.mesh.V.rows(), b.mesh.V.rows());
    // The round trip X_BM^-1 then X_BM: rounding only (1e-12 m).
    EXPECT_LE((a.mesh.V - b.mesh.V).cwiseAbs().maxCoeff(), 1e-12) << m.contacts[i].name();
    EXPECT_LE((a.thickness.array() - 2e-3).abs().maxCoeff(), 1e-15);
    EXPECT_EQ(m.contacts[i].material().youngs_modulus, m0.contacts[i].material().youngs_modulus);
  }
  auto message_of = [&](const std::string& path) {
    auto mm = msk::load_model(model_path("knee_coarse.urdf"));
    try {
      msk::use_prepared_surfaces(mm, path);
    } catch (const arthrosim::common::InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string missing = (dir / "prepared_missing.h5").string();
  write_prepared(missing, "patella_cartilage", "", 0.0);
  const std::string e1 = message_of(missing);
  EXPECT_NE(e1.find("prepared_missing.h5"), std::string::npos) << e1;
  EXPECT_NE(e1.find("patella_cartilage.stl"), std::string::npos) << e1;
  const std::string moved = (dir / "prepared_moved.h5").string();
  write_prepared(moved, "", "tibia_medial_cartilage", 5e-3);
  const std::string e2 = message_of(moved);
  EXPECT_NE(e2.find("prepared_moved.h5"), std::string::npos) << e2;
  EXPECT_NE(e2.find("5 mm"), std::string::npos) << e2;
  // A model surface whose mesh prepare split into compartments (two prepared
  // surfaces from one source file): the union replaces it. Here the femoral
  // cartilage's triangles are written as two parts split at x = 0, each with
  // its own vertices; the model gets all triangles back, same area. (Before,
  // only the part listed last was taken; here the centroid check refused it.)
  {
    const auto* femur = &m0.contacts[0].target();
    const std::string path = (dir / "prepared_split.h5").string();
    arthrosim::common::H5File f(path, arthrosim::common::H5File::Mode::kTruncate);
    f.set_attribute("/", "schema", "arthrosim prepared model 1");
    std::vector<std::string> names;
    std::set<std::string> done;
    for (const auto& c : m0.contacts)
      for (const auto* s : {&c.casting(), &c.target()}) {
        if (!done.insert(s->name).second) continue;
        std::vector<std::vector<int>> parts(1);
        if (s == femur) parts.assign(2, {});
        for (int t = 0; t < s->mesh.num_triangles(); ++t)
          parts[s == femur && s->mesh.V(s->mesh.F(t, 0), 0) > 0 ? 1 : 0].push_back(t);
        for (size_t p = 0; p < parts.size(); ++p) {
          const std::string n = s->name.substr(0, s->name.find("_cartilage")) + (parts.size() > 1 ? "_part" + std::to_string(p) : "");
          names.push_back(n);
          const std::string g = "/surfaces/" + n;
          arthrosim::common::TriangleMesh sub = arthrosim::common::submesh(s->mesh, parts[p]);
          for (int i = 0; i < sub.num_vertices(); ++i)
            sub.V.row(i) = (s->X_BM.inverse() * Eigen::Vector3d(sub.V.row(i).transpose())).transpose();
          f.create_group(g + "/triangles");
          f.set_attribute(g, "source_file", fs::path(s->mesh_file).filename().string());
          f.write(g + "/triangles/vertices", Eigen::MatrixXd(sub.V));
          f.write(g + "/triangles/faces", Eigen::MatrixXi(sub.F));
          f.write(g + "/triangles/thickness", Eigen::VectorXd::Constant(sub.num_vertices(), 2e-3));
        }
      }
    std::sort(names.begin(), names.end());
    f.write("/surfaces/names", names);
    f.flush();
    auto ms = msk::load_model(model_path("knee_coarse.urdf"));
    msk::use_prepared_surfaces(ms, path);
    const auto& a = ms.contacts[0].target();
    EXPECT_EQ(a.mesh.num_triangles(), femur->mesh.num_triangles());
    EXPECT_NEAR(arthrosim::common::surface_area(a.mesh), arthrosim::common::surface_area(femur->mesh), 1e-12);
  }
}
