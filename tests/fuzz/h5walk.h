#pragma once
// Reads everything in an HDF5 file through common::H5File the way the stage
// readers do: every group listed, every attribute read with each getter,
// every dataset read according to its type and rank (hdf5_fuzz.cc,
// hdf5_raw_fuzz.cc).
#include <string>

#include "common/error.h"
#include "common/hdf5.h"

namespace arthrosim::fuzz {

using arthrosim::common::H5File;
using arthrosim::common::H5Type;

inline void read_attributes(const H5File& f, const std::string& object) {
  for (const std::string& key : f.attribute_names(object)) {
    // Each getter checks the type itself; mismatches are InputErrors.
    try { (void)f.attribute_string(object, key); } catch (const arthrosim::common::InputError&) {}
    try { (void)f.attribute_double(object, key); } catch (const arthrosim::common::InputError&) {}
    try { (void)f.attribute_int(object, key); } catch (const arthrosim::common::InputError&) {}
  }
}

// Every getter on every dataset: those that do not fit its type or rank
// must say so with an InputError.
inline void read_dataset(const H5File& f, const std::string& name) {
  (void)f.dims(name);
  (void)f.extent(name);
  (void)f.type(name);
  auto attempt = [](auto&& read) {
    try {
      read();
    } catch (const arthrosim::common::InputError&) {
    }
  };
  attempt([&] { (void)f.read_vector(name); });
  attempt([&] { (void)f.read_matrix(name); });
  attempt([&] { (void)f.read_matrix(name, 3); });
  attempt([&] { (void)f.read_tensor3(name); });
  attempt([&] { (void)f.read_vector_int(name); });
  attempt([&] { (void)f.read_matrix_int(name); });
  attempt([&] { (void)f.read_matrix_int(name, 3); });
  attempt([&] { (void)f.read_tensor3_int(name); });
  attempt([&] { (void)f.read_strings(name); });
}

// Depth-first over the groups. Hard links can make cycles (a group holding
// its parent), so the walk goes at most 4 groups deep and visits at most
// `budget` members in all.
inline void walk(const H5File& f, const std::string& group, int* budget, int depth = 0) {
  if (depth > 4) return;
  read_attributes(f, group);
  for (const std::string& child : f.list(group)) {
    if (--*budget < 0) return;
    const std::string path = (group == "/" ? "/" : group + "/") + child;
    try {
      if (f.is_group(path)) {
        walk(f, path, budget, depth + 1);
      } else if (f.is_dataset(path)) {
        read_attributes(f, path);
        read_dataset(f, path);
      }
    } catch (const arthrosim::common::InputError&) {
      // One bad member does not stop the walk.
    }
  }
}

}  // namespace arthrosim::fuzz
