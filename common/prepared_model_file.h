#pragma once
// The prepared-model file, prepared.h5 (schema docs/prepared_model.md): the
// reader its consumers use (the surface stage's shells, the musculoskeletal
// stage's contact surfaces), and the writer of the part they read
// (PreparedModelWriter: identity, surfaces, quad surfaces, names), which
// pipelines::write_prepared_model (pipelines/prepare.h) and synthetic cases
// use. Every dataset path a consumer needs is here.
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::common {

class H5File;

class PreparedModelReader {
 public:
  /// Opens `path` (InputError naming it when it cannot be read).
  explicit PreparedModelReader(const std::string& path);
  ~PreparedModelReader();
  const std::string& path() const;

  /// The cartilage surfaces, in file order (/surfaces/names).
  std::vector<std::string> surface_names() const;
  /// The bone a surface lies on, e.g. "tibia".
  std::string bone(const std::string& surface) const;
  /// The cartilage mesh file a surface was prepared from.
  std::string source_file(const std::string& surface) const;
  /// "medial" or "lateral" for a part that prepare split from one mesh
  /// (common/compartments.h), else "" (also for files written before the
  /// attribute existed).
  std::string compartment(const std::string& surface) const;

  /// The repaired bone meshes (/bones/<name>), in file order.
  std::vector<std::string> bone_names() const;
  /// A bone's triangle mesh [m] (InputError naming the file when absent).
  TriangleMesh bone_mesh(const std::string& bone) const;
  /// The length unit prepare read the model's files in (root attribute
  /// input_unit, e.g. "mm"), or "" when the file does not record it.
  std::string input_unit() const;

  /// The all-quad articular surface of the shell stage.
  struct QuadSurface {
    QuadMesh mesh;             ///< nodes [m], quads
    Points3 normals;           ///< unit, per node, away from the bone
    std::vector<int> periphery;  ///< outline nodes, sorted
  };
  /// Checked: one normal per node, quad indices in range, finite values;
  /// InputError naming the file and dataset otherwise.
  QuadSurface quads(const std::string& surface) const;
  /// Cartilage thickness per quad node [m].
  Eigen::VectorXd quad_thickness(const std::string& surface) const;
  /// Dataset name of quad_thickness (for messages).
  static std::string quad_thickness_dataset(const std::string& surface);

  /// The remeshed triangle surface with its per-vertex thickness [m].
  struct TriangleSurface {
    TriangleMesh mesh;
    Eigen::VectorXd thickness;
    std::string group;  ///< its group in the file (messages)
  };
  /// Checked: one thickness per vertex, at least one triangle, indices in
  /// range, finite coordinates, finite thickness >= 0; InputError naming the
  /// file and dataset otherwise.
  TriangleSurface triangles(const std::string& surface) const;

 private:
  std::unique_ptr<H5File> f_;
};

/// Writes the part of a prepared model its readers use into an open file
/// (pipelines::write_prepared_model adds bones, triangles and statistics).
class PreparedModelWriter {
 public:
  explicit PreparedModelWriter(H5File& f) : f_(f) {}
  /// Root attributes: schema (the version PreparedModelReader accepts),
  /// model_folder, length_unit "m".
  void identity(const std::string& model_folder);
  /// Creates a surface's group with its bone attribute.
  void surface(const std::string& surface, const std::string& bone);
  /// A surface's all-quad mesh: nodes [m], quads, unit node normals, node
  /// thickness [m] and the sorted outline nodes.
  void quads(const std::string& surface, const QuadMesh& mesh, const Points3& normals, const Eigen::VectorXd& thickness,
             const std::vector<int>& periphery);
  /// /surfaces/names, in the order readers list them.
  void surface_names(const std::vector<std::string>& names);
  /// The group of a surface's quad mesh (for the writer's own extra datasets).
  static std::string quads_group(const std::string& surface);

 private:
  H5File& f_;
};

}  // namespace arthrosim::common
