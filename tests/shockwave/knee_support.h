#pragma once
// Loads a bundled parametric knee folder into the shockwave model's meshes.
#include <filesystem>
#include <string>

#include "common/mesh_io.h"
#include "pipelines/knee_generator.h"
#include "shockwave/knee_model.h"

namespace arthrosim::shockwave::testing {

inline KneeMeshes load_bundled_knee(const std::string& resolution) {
  const std::string dir = std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/" + resolution + "/";
  KneeMeshes k;
  k.femur = common::read_stl(dir + "femur_bone.stl");
  k.tibia = common::read_stl(dir + "tibia_bone.stl");
  using pipelines::KneeCartilage;
  for (KneeCartilage c : {KneeCartilage::kFemur, KneeCartilage::kTibiaMedial, KneeCartilage::kTibiaLateral}) {
    CartilageSurface s;
    const std::string stem = pipelines::cartilage_file_stem(c);
    s.name = stem;
    s.bone = c == KneeCartilage::kFemur ? BoneId::kFemur : BoneId::kTibia;
    s.articular = common::read_stl(dir + stem + ".stl");
    s.thickness = pipelines::read_thickness_csv(dir + stem + "_thickness.csv", s.articular);
    k.cartilage.push_back(s);
  }
  for (pipelines::KneeMeniscus w : {pipelines::KneeMeniscus::kMedial, pipelines::KneeMeniscus::kLateral})
    k.menisci.emplace_back(w == pipelines::KneeMeniscus::kMedial ? "medial" : "lateral",
                           common::read_stl(dir + pipelines::meniscus_file_stem(w) + ".stl"));
  return k;
}

}  // namespace arthrosim::shockwave::testing
