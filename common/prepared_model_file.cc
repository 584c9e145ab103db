#include "common/prepared_model_file.h"

#include "common/error.h"
#include "common/file_check.h"
#include "common/hdf5.h"

namespace arthrosim::common {

namespace {
std::string group(const std::string& surface) { return "/surfaces/" + surface; }
constexpr const char* kNames = "/surfaces/names";
}  // namespace

PreparedModelReader::PreparedModelReader(const std::string& path)
    : f_(std::make_unique<H5File>(path, H5File::Mode::kRead)) {
  require_file_format(*f_, path, StageFile::kPreparedModel);  // kind and schema version
}
PreparedModelReader::~PreparedModelReader() = default;
const std::string& PreparedModelReader::path() const { return f_->path(); }

std::vector<std::string> PreparedModelReader::surface_names() const { return f_->read_strings(kNames); }

std::string PreparedModelReader::bone(const std::string& surface) const {
  return f_->attribute_string(group(surface), "bone");
}

std::string PreparedModelReader::source_file(const std::string& surface) const {
  return f_->attribute_string(group(surface), "source_file");
}

std::string PreparedModelReader::compartment(const std::string& surface) const {
  const std::string g = group(surface);
  return f_->has_attribute(g, "compartment") ? f_->attribute_string(g, "compartment") : std::string();
}

std::vector<std::string> PreparedModelReader::bone_names() const {
  return f_->is_group("/bones") ? f_->list("/bones") : std::vector<std::string>{};
}

TriangleMesh PreparedModelReader::bone_mesh(const std::string& bone) const {
  const std::string g = "/bones/" + bone;
  if (!f_->is_group(g)) throw InputError(path(), 0, "expected the bone " + g + ", found none");
  TriangleMesh m;
  m.V = f_->read_matrix(g + "/vertices", 3);
  m.F = f_->read_matrix_int(g + "/faces", 3);
  m.name = bone;
  return m;
}

std::string PreparedModelReader::input_unit() const {
  return f_->has_attribute("/", "input_unit") ? f_->attribute_string("/", "input_unit") : std::string();
}

PreparedModelReader::QuadSurface PreparedModelReader::quads(const std::string& name) const {
  const H5File& f = *f_;
  const std::string g = PreparedModelWriter::quads_group(name) + "/";
  QuadSurface s;
  s.mesh.name = name;
  s.mesh.V = f.read_matrix(g + "nodes", 3);
  const Eigen::MatrixXi Q = f.read_matrix_int(g + "quads", 4);
  s.mesh.Q = Q;
  s.normals = f.read_matrix(g + "normals", 3);
  const Eigen::VectorXi P = f.read_vector_int(g + "periphery");
  s.periphery.assign(P.data(), P.data() + P.size());
  const int N = static_cast<int>(s.mesh.V.rows());
  if (s.normals.rows() != N)
    throw InputError(f.path() + ": error: dataset " + g + "normals: expected " + std::to_string(N) +
                     " rows (one per node), found " + std::to_string(s.normals.rows()));
  if (Q.size() > 0 && (Q.minCoeff() < 0 || Q.maxCoeff() >= N))
    throw InputError(f.path() + ": error: dataset " + g + "quads: node index out of range [0, " + std::to_string(N) +
                     ")");
  if (!s.mesh.V.allFinite() || !s.normals.allFinite())
    throw InputError(f.path() + ": error: dataset " + g + "nodes or " + g + "normals holds NaN/Inf");
  return s;
}

std::string PreparedModelReader::quad_thickness_dataset(const std::string& surface) {
  return PreparedModelWriter::quads_group(surface) + "/thickness";
}

Eigen::VectorXd PreparedModelReader::quad_thickness(const std::string& surface) const {
  return f_->read_vector(quad_thickness_dataset(surface));
}

PreparedModelReader::TriangleSurface PreparedModelReader::triangles(const std::string& surface) const {
  TriangleSurface s;
  s.group = group(surface) + "/triangles/";
  s.mesh.V = f_->read_matrix(s.group + "vertices", 3);
  s.mesh.F = f_->read_matrix_int(s.group + "faces", 3);
  s.thickness = f_->read_vector(s.group + "thickness");
  const std::string& g = s.group;
  const Eigen::MatrixXd& V = s.mesh.V;
  const Eigen::MatrixXi& F = s.mesh.F;
  const Eigen::VectorXd& t = s.thickness;
  if (t.size() != V.rows() || F.rows() == 0)
    throw InputError(path(), 0, g + ": expected one thickness per vertex and triangles, found " +
                                    std::to_string(t.size()) + " values for " + std::to_string(V.rows()) +
                                    " vertices");
  // Nothing outside the file's own arrays, no NaN/Inf (a damaged or foreign file).
  for (int r = 0; r < F.rows(); ++r)
    for (int k = 0; k < 3; ++k)
      if (F(r, k) < 0 || F(r, k) >= V.rows())
        throw InputError(path(), 0, g + "faces: expected vertex indices in [0, " + std::to_string(V.rows()) +
                                        "), found " + std::to_string(F(r, k)) + " in triangle " +
                                        std::to_string(r));
  if (!V.allFinite()) throw InputError(path(), 0, g + "vertices: expected finite coordinates, found NaN or Inf");
  if (!t.allFinite() || (t.array() < 0).any())
    throw InputError(path(), 0,
                     g + "thickness: expected finite values >= 0, found NaN, Inf or a negative value");
  return s;
}

// ---------------------------------------------------------------------------
// Writer
// ---------------------------------------------------------------------------
std::string PreparedModelWriter::quads_group(const std::string& surface) { return group(surface) + "/quads"; }

void PreparedModelWriter::identity(const std::string& model_folder) {
  f_.set_attribute("/", "schema", "arthrosim prepared model 1");
  f_.set_attribute("/", "model_folder", model_folder);
  f_.set_attribute("/", "length_unit", "m");
}

void PreparedModelWriter::surface(const std::string& surface, const std::string& bone) {
  f_.create_group(group(surface));
  f_.set_attribute(group(surface), "bone", bone);
}

void PreparedModelWriter::quads(const std::string& surface, const QuadMesh& mesh, const Points3& normals,
                                const Eigen::VectorXd& thickness, const std::vector<int>& periphery) {
  const std::string q = quads_group(surface);
  f_.write(q + "/nodes", mesh.V);
  f_.write(q + "/quads", mesh.Q);
  f_.write(q + "/normals", normals);
  f_.write(q + "/thickness", thickness);
  f_.write(q + "/periphery",
           Eigen::VectorXi(Eigen::Map<const Eigen::VectorXi>(periphery.data(), static_cast<Eigen::Index>(periphery.size()))));
}

void PreparedModelWriter::surface_names(const std::vector<std::string>& names) { f_.write(kNames, names); }

}  // namespace arthrosim::common
