#pragma once
// Loading the knee model from URDF with arthrosim extension elements
// (format: docs/model_format.md). The kinematic tree comes from urdfdom; the
// <arthrosim:...> elements (ligaments, muscles, wrap cylinders, cartilage
// surfaces, contact pairs, prescribed joints) are read with tinyxml2 so every
// error names file:line. Neither library appears in this header.
#include <string>

#include "musculoskeletal/model.h"

namespace arthrosim::musculoskeletal {

/// Loads a model file; relative mesh/thickness paths are relative to its folder.
Model load_model(const std::string& urdf_path);

/// Parses model text. `file_name` is used in messages, `base_dir` resolves
/// relative file names. Throws common::InputError("file:line: error: ...").
Model parse_model(const std::string& xml, const std::string& file_name,
                  const std::string& base_dir);

}  // namespace arthrosim::musculoskeletal
