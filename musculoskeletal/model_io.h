#pragma once
// Loading the knee model from URDF with arthrosim extension elements
// (format: docs/model_format.md). The kinematic tree comes from urdfdom; the
// <arthrosim:...> elements (ligaments, muscles, wrap cylinders, cartilage
// surfaces, contact pairs, prescribed joints) are read with tinyxml2 so every
// error names file:line. Neither library appears in this header.
#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "musculoskeletal/model.h"

namespace arthrosim::musculoskeletal {

/// Loads a model file; relative mesh/thickness paths are relative to its folder.
Model load_model(const std::string& urdf_path);

/// Parses model text. `file_name` is used in messages, `base_dir` resolves
/// relative file names. Throws common::InputError("file:line: error: ...").
Model parse_model(const std::string& xml, const std::string& file_name,
                  const std::string& base_dir);

struct PreparedSurfacesReport {
  std::vector<std::string> lines;  ///< per replaced surface: "name: n -> m triangles (...)"
};

/// Replaces the cartilage surfaces of every contact pair by those of a
/// prepared model (docs/prepared_model.md: remeshed articular surface and
/// per-vertex thickness cast to the bone; a triangle gets the mean of its
/// vertices, as thickness_csv). A model surface is matched to the prepared
/// surface made from the mesh file of the same name; the prepared vertices
/// (model frame of the mesh files) are placed in the body frame exactly as
/// the model file places its own mesh (ContactSurface::X_BM). Materials and
/// pairs are kept. Throws InputError naming the file when a surface has no
/// prepared counterpart or the two lie more than 2 mm apart (centroids).
PreparedSurfacesReport use_prepared_surfaces(Model& model, const std::string& prepared_path);

/// A cartilage surface in the model frame of the mesh files [m] with one
/// thickness per vertex [m] (e.g. from pipelines/knee_generator.h).
struct SurfaceMesh {
  common::TriangleMesh mesh;
  Eigen::VectorXd vertex_thickness;
};

/// As use_prepared_surfaces, from meshes in memory keyed by the file name of
/// the model's mesh they replace ("femur_cartilage.stl"); `source` names them
/// in messages. Same placement, triangle thickness and 2 mm centroid check.
/// Used to time the fine generated knee (msk_bench, comak_bench) without
/// committing its meshes.
PreparedSurfacesReport use_contact_meshes(Model& model, const std::map<std::string, SurfaceMesh>& by_file,
                                          const std::string& source);

}  // namespace arthrosim::musculoskeletal
