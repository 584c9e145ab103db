#pragma once
// "h5spec": the input language of the structure-aware HDF5 fuzz targets
// (hdf5_fuzz.cc, prepared_fuzz.cc). A fuzz input is a sequence of records,
// each building one object of a *well-formed* HDF5 file with the HDF5 C API;
// the target then reads that file with arthrosim's readers. The readers are
// thus fuzzed with hostile content (types, ranks, dims, values, names, links)
// rather than with corrupt bytes, which exercise libhdf5's own parser and hit
// its known defects first (docs/testing.md; target hdf5_raw does that).
//
// Records (all integers unsigned bytes; missing bytes read as 0):
//   op % 5 == 0  group      parent name
//   op % 5 == 1  dataset    parent name type rank dims[rank] layout values
//   op % 5 == 2  attribute  parent(unused) object name type rank dims[rank] values
//   op % 5 == 3  soft link  parent name target(text)
//   op % 5 == 4  hard link  parent name object
//   parent/object: index (mod count) into the groups / all objects made so far
//   (group 0 = "/"); name: length byte (mod 32) then that many bytes, each
//   kept if [A-Za-z0-9_] else mapped to a letter; text: length byte (mod 64)
//   then raw bytes; type % 11: 0 f64le 1 f64be 2 f32le 3 i32le 4 i64le 5 u8
//   6 i16be 7 u32le 8 variable-length UTF-8 string 9 fixed string (one more
//   byte: size % 16 + 1) 10 compound {f64 a; i32 b}; rank % 4 (0 = scalar);
//   dims % 9 each, except 0xF0..0xFF = 2^(20 + b % 16) (then no values are
//   written: a sparse dataset of fill values); layout % 3: contiguous, chunked (first dim unlimited),
//   compact; values: strings as text, other types as the element bytes in
//   the file's byte order.
// A record the library refuses (e.g. a duplicate name) is skipped.
#include <hdf5.h>

#include <cstdint>
#include <string>
#include <vector>

namespace arthrosim::fuzz {

class H5Spec {
 public:
  H5Spec(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}

  /// Writes the file; returns false if HDF5 could not create it at all.
  bool write(const std::string& path) {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    if (file < 0) return false;
    groups_ = {"/"};
    objects_ = {"/"};
    while (pos_ < size_) record(file);
    H5Fclose(file);
    return true;
  }

 private:
  std::uint8_t byte() { return pos_ < size_ ? data_[pos_++] : 0; }

  std::string name() {
    const int n = byte() % 32;
    std::string s;
    for (int i = 0; i < n; ++i) {
      const unsigned char c = byte();
      const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
      s += ok ? static_cast<char>(c) : static_cast<char>('a' + c % 26);
    }
    return s.empty() ? std::string("x") : s;
  }

  std::string text() {
    const int n = byte() % 64;
    std::string s;
    for (int i = 0; i < n; ++i) s += static_cast<char>(byte());
    return s;
  }

  static std::string join(const std::string& parent, const std::string& child) {
    return parent == "/" ? "/" + child : parent + "/" + child;
  }

  // A file type and the number of bytes per element (0 = variable-length string).
  hid_t make_type(std::uint8_t code, std::size_t* elem) {
    switch (code % 11) {
      case 0: *elem = 8; return H5Tcopy(H5T_IEEE_F64LE);
      case 1: *elem = 8; return H5Tcopy(H5T_IEEE_F64BE);
      case 2: *elem = 4; return H5Tcopy(H5T_IEEE_F32LE);
      case 3: *elem = 4; return H5Tcopy(H5T_STD_I32LE);
      case 4: *elem = 8; return H5Tcopy(H5T_STD_I64LE);
      case 5: *elem = 1; return H5Tcopy(H5T_STD_U8LE);
      case 6: *elem = 2; return H5Tcopy(H5T_STD_I16BE);
      case 7: *elem = 4; return H5Tcopy(H5T_STD_U32LE);
      case 8: {
        *elem = 0;
        const hid_t t = H5Tcopy(H5T_C_S1);
        H5Tset_size(t, H5T_VARIABLE);
        H5Tset_cset(t, H5T_CSET_UTF8);
        return t;
      }
      case 9: {
        const std::uint8_t b = byte();
        *elem = b % 16 + 1;
        const hid_t t = H5Tcopy(H5T_C_S1);
        H5Tset_size(t, *elem);
        H5Tset_strpad(t, (b & 0x80) ? H5T_STR_NULLTERM : H5T_STR_NULLPAD);
        return t;
      }
      default: {
        *elem = 12;
        const hid_t t = H5Tcreate(H5T_COMPOUND, 12);
        H5Tinsert(t, "a", 0, H5T_IEEE_F64LE);
        H5Tinsert(t, "b", 8, H5T_STD_I32LE);
        return t;
      }
    }
  }

  // Reads rank and dims; returns the dataspace and the element count.
  hid_t make_space(std::vector<hsize_t>* dims, std::size_t* count) {
    const int rank = byte() % 4;
    dims->assign(rank, 0);
    *count = 1;
    for (int i = 0; i < rank; ++i) {
      const std::uint8_t b = byte();
      // 0xF0..0xFF: a huge dimension, 2^(20 + b % 16) (a sparse dataset: its
      // values are not written, it reads as fill values).
      (*dims)[i] = b >= 0xF0 ? hsize_t{1} << (20 + b % 16) : b % 9;
      *count *= (*dims)[i];
    }
    return rank == 0 ? H5Screate(H5S_SCALAR) : H5Screate_simple(rank, dims->data(), nullptr);
  }

  // Element data in file representation; for variable-length strings the
  // strings themselves (pointers into `strings`).
  // More elements than this are not written (a sparse dataset).
  static constexpr std::size_t kMaxWritten = 4096;

  void values(std::size_t count, std::size_t elem, std::vector<std::uint8_t>* raw,
              std::vector<std::string>* strings, std::vector<const char*>* ptrs) {
    if (count > kMaxWritten) return;
    if (elem == 0) {
      strings->clear();
      for (std::size_t i = 0; i < count; ++i) strings->push_back(text());
      ptrs->clear();
      for (const auto& s : *strings) ptrs->push_back(s.c_str());
    } else {
      raw->resize(count * elem);
      for (auto& b : *raw) b = byte();
    }
  }

  void record(hid_t file) {
    const int op = byte() % 5;
    if (op == 4 && objects_.empty()) return;
    const std::string& parent = groups_[byte() % groups_.size()];
    if (op == 2) {
      attribute(file, objects_[byte() % objects_.size()]);
      return;
    }
    const std::string path = join(parent, name());
    if (op == 0) {
      const hid_t g = H5Gcreate2(file, path.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
      if (g >= 0) {
        groups_.push_back(path);
        objects_.push_back(path);
        H5Gclose(g);
      }
    } else if (op == 1) {
      dataset(file, path);
    } else if (op == 3) {
      const std::string target = text();
      H5Lcreate_soft(target.c_str(), file, path.c_str(), H5P_DEFAULT, H5P_DEFAULT);
    } else {
      const std::string& target = objects_[byte() % objects_.size()];
      H5Lcreate_hard(file, target.c_str(), file, path.c_str(), H5P_DEFAULT, H5P_DEFAULT);
    }
  }

  void dataset(hid_t file, const std::string& path) {
    std::size_t elem = 0, count = 0;
    const hid_t type = make_type(byte(), &elem);
    std::vector<hsize_t> dims;
    hid_t space = make_space(&dims, &count);
    const int layout = byte() % 3;
    const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
    if (layout == 1 && !dims.empty()) {
      std::vector<hsize_t> chunk(dims.size()), maxdims(dims);
      for (std::size_t i = 0; i < dims.size(); ++i) chunk[i] = dims[i] > 0 ? dims[i] : 1;
      maxdims[0] = H5S_UNLIMITED;
      H5Sclose(space);
      space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), maxdims.data());
      H5Pset_chunk(dcpl, static_cast<int>(chunk.size()), chunk.data());
    } else if (layout == 2) {
      H5Pset_layout(dcpl, H5D_COMPACT);
    }
    std::vector<std::uint8_t> raw;
    std::vector<std::string> strings;
    std::vector<const char*> ptrs;
    values(count, elem, &raw, &strings, &ptrs);
    const hid_t d = H5Dcreate2(file, path.c_str(), type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
    if (d >= 0) {
      if (count > 0 && count <= kMaxWritten)
        H5Dwrite(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, elem == 0 ? static_cast<const void*>(ptrs.data()) : raw.data());
      objects_.push_back(path);
      H5Dclose(d);
    }
    H5Pclose(dcpl);
    H5Sclose(space);
    H5Tclose(type);
  }

  void attribute(hid_t file, const std::string& object) {
    const std::string key = name();
    std::size_t elem = 0, count = 0;
    const hid_t type = make_type(byte(), &elem);
    std::vector<hsize_t> dims;
    const hid_t space = make_space(&dims, &count);
    std::vector<std::uint8_t> raw;
    std::vector<std::string> strings;
    std::vector<const char*> ptrs;
    values(count, elem, &raw, &strings, &ptrs);
    const hid_t o = H5Oopen(file, object.c_str(), H5P_DEFAULT);
    if (o >= 0) {
      const hid_t a = H5Acreate2(o, key.c_str(), type, space, H5P_DEFAULT, H5P_DEFAULT);
      if (a >= 0) {
        if (count > 0 && count <= kMaxWritten)
          H5Awrite(a, type, elem == 0 ? static_cast<const void*>(ptrs.data()) : raw.data());
        H5Aclose(a);
      }
      H5Oclose(o);
    }
    H5Sclose(space);
    H5Tclose(type);
  }

  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
  std::vector<std::string> groups_;
  std::vector<std::string> objects_;
};

}  // namespace arthrosim::fuzz
