// HDF5 layer over the HDF5 C API (1.10). See hdf5.h for the conventions.
//
// Notes on choices:
//  - Default (earliest) file format: readable by every HDF5 >= 1.8 and by
//    ParaView, and the superblock carries no "file open for writing" flag, so a
//    file left behind by a killed process opens without h5clear.
//  - Object time tracking off on every group and dataset (determinism).
//  - Appended datasets are chunked with an unlimited first dimension; every
//    append() ends with H5Fflush so that the file on disk (through the OS page
//    cache) is consistent after each frame. We do not use SWMR: in HDF5 1.10 it
//    forbids creating new objects once started, and a killed writer needs no
//    concurrent reader here.
#include "common/hdf5.h"

#include <hdf5.h>

#include <algorithm>
#include <filesystem>
#include <limits>
#include <mutex>
#include <sstream>

#include "common/error.h"

namespace arthrosim::common {
namespace {

void init_hdf5() {
  static std::once_flag once;
  std::call_once(once, [] {
    H5open();
    // We convert failures into exceptions with HDF5's message; the library
    // must not print its error stack to stderr on its own.
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  });
}

// Innermost message of HDF5's current error stack (then cleared).
herr_t walk_error(unsigned /*n*/, const H5E_error2_t* err, void* data) {
  auto* out = static_cast<std::string*>(data);
  if (err->desc != nullptr && err->desc[0] != '\0') *out = err->desc;  // keep the last = innermost
  return 0;
}
std::string hdf5_message() {
  std::string msg;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, walk_error, &msg);
  H5Eclear2(H5E_DEFAULT);
  return msg.empty() ? std::string("HDF5 library error") : msg;
}

// Owning hid_t with the matching close function.
class Hid {
 public:
  Hid() = default;
  Hid(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Hid() { reset(); }
  Hid(Hid&& o) noexcept : id_(o.id_), close_(o.close_) { o.id_ = H5I_INVALID_HID; }
  Hid& operator=(Hid&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = o.id_;
      close_ = o.close_;
      o.id_ = H5I_INVALID_HID;
    }
    return *this;
  }
  Hid(const Hid&) = delete;
  Hid& operator=(const Hid&) = delete;
  void reset() {
    if (id_ >= 0 && close_ != nullptr) close_(id_);
    id_ = H5I_INVALID_HID;
  }
  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }

 private:
  hid_t id_ = H5I_INVALID_HID;
  herr_t (*close_)(hid_t) = nullptr;
};

// "a/b//c/" -> "/a/b/c"; "" -> "/".
std::string normalize(const std::string& name) {
  std::string out = "/";
  for (char c : name) {
    if (c == '/' && out.back() == '/') continue;
    out += c;
  }
  if (out.size() > 1 && out.back() == '/') out.pop_back();
  return out;
}

std::string parent_of(const std::string& norm) {
  const size_t pos = norm.rfind('/');
  return pos == 0 ? std::string("/") : norm.substr(0, pos);
}

std::string dims_text(const std::vector<std::int64_t>& dims) {
  std::ostringstream s;
  s << "(";
  for (size_t i = 0; i < dims.size(); ++i) s << (i ? ", " : "") << dims[i];
  s << ")";
  return s.str();
}

const char* type_name(H5Type t) {
  switch (t) {
    case H5Type::kDouble: return "floating-point";
    case H5Type::kInt: return "integer";
    case H5Type::kString: return "string";
    default: return "unsupported-type";
  }
}

H5Type classify(hid_t type) {
  switch (H5Tget_class(type)) {
    case H5T_FLOAT: return H5Type::kDouble;
    case H5T_INTEGER: return H5Type::kInt;
    case H5T_STRING: return H5Type::kString;
    default: return H5Type::kOther;
  }
}

Hid make_ocpl(hid_t cls) {
  Hid p(H5Pcreate(cls), H5Pclose);
  H5Pset_obj_track_times(p.get(), 0);  // no timestamps: bit-identical files
  return p;
}

Hid string_type() {
  Hid t(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(t.get(), H5T_VARIABLE);
  H5Tset_cset(t.get(), H5T_CSET_UTF8);
  return t;
}

herr_t collect_link(hid_t, const char* name, const H5L_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->push_back(name);
  return 0;
}
herr_t collect_attr(hid_t, const char* name, const H5A_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->push_back(name);
  return 0;
}

// Frame counter of appendable datasets. A kill in the middle of H5Fflush can
// leave the new extent on disk without the newest chunk (its frame then reads
// as zeros), because HDF5 writes metadata entries in no guaranteed order.
// So an appended dataset carries this int64 attribute, the number of frames
// known to be complete, updated only after the frame's flush returned, and
// every reader here uses min(extent, counter) frames.
constexpr const char* kFramesAttribute = "arthrosim_frames_complete";

bool create_frames_attribute(hid_t dset, std::int64_t value) {
  Hid space(H5Screate(H5S_SCALAR), H5Sclose);
  Hid a(H5Acreate2(dset, kFramesAttribute, H5T_STD_I64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  return a.valid() && H5Awrite(a.get(), H5T_NATIVE_INT64, &value) >= 0;
}

// Frames readable in a dataset whose first dimension is `extent`.
std::int64_t committed_frames(hid_t dset, std::int64_t extent) {
  if (H5Aexists(dset, kFramesAttribute) <= 0) {
    H5Eclear2(H5E_DEFAULT);
    return extent;
  }
  Hid a(H5Aopen(dset, kFramesAttribute, H5P_DEFAULT), H5Aclose);
  std::int64_t v = extent;
  if (!a.valid() || H5Aread(a.get(), H5T_NATIVE_INT64, &v) < 0) {
    H5Eclear2(H5E_DEFAULT);
    return extent;
  }
  return std::clamp<std::int64_t>(v, 0, extent);
}

// Reads a string-typed dataset or attribute (variable or fixed length) of
// `n` elements. `read` performs the H5Dread/H5Aread with the given memory type.
template <typename ReadFn>
std::vector<std::string> read_string_data(hid_t file_type, size_t n, ReadFn read) {
  std::vector<std::string> out(n);
  if (n == 0) return out;
  if (H5Tis_variable_str(file_type) > 0) {
    Hid mem = string_type();
    std::vector<char*> ptrs(n, nullptr);
    if (read(mem.get(), ptrs.data()) < 0) return {};
    for (size_t i = 0; i < n; ++i) out[i] = ptrs[i] ? std::string(ptrs[i]) : std::string();
    hsize_t dim = n;
    Hid space(H5Screate_simple(1, &dim, nullptr), H5Sclose);
    H5Dvlen_reclaim(mem.get(), space.get(), H5P_DEFAULT, ptrs.data());
  } else {
    const size_t len = H5Tget_size(file_type);
    Hid mem(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_size(mem.get(), len);
    // NULLPAD in memory: a NULLTERM memory type would drop the last character
    // of a full-length NULLPAD string (h5py's fixed-length bytes).
    H5Tset_strpad(mem.get(), H5T_STR_NULLPAD);
    std::vector<char> buf(n * len);
    if (read(mem.get(), buf.data()) < 0) return {};
    for (size_t i = 0; i < n; ++i) {
      const char* p = buf.data() + i * len;
      size_t l = 0;
      while (l < len && p[l] != '\0') ++l;
      out[i].assign(p, l);
    }
  }
  return out;
}

}  // namespace

// ===========================================================================
struct H5File::Impl {
  std::string path;
  bool writable = false;
  Hid file;

  [[noreturn]] void fail(const std::string& message) const { throw InputError(path, 0, message); }
  [[noreturn]] void fail_hdf5(const std::string& what) const {
    throw InputError(path, 0, what + ": " + hdf5_message());
  }
  void require_writable(const std::string& name) const {
    if (!writable) fail("cannot write " + name + ": file is open read-only");
  }

  bool link_exists(const std::string& norm) const {
    if (norm == "/") return true;
    // H5Lexists fails when an intermediate group is missing: check each level.
    size_t pos = 1;
    while (true) {
      const size_t next = norm.find('/', pos);
      const std::string prefix = norm.substr(0, next);
      const htri_t e = H5Lexists(file.get(), prefix.c_str(), H5P_DEFAULT);
      if (e <= 0) {
        H5Eclear2(H5E_DEFAULT);
        return false;
      }
      if (next == std::string::npos) return true;
      // The prefix must be a group to contain more.
      Hid obj(H5Oopen(file.get(), prefix.c_str(), H5P_DEFAULT), H5Oclose);
      if (!obj.valid() || H5Iget_type(obj.get()) != H5I_GROUP) {
        H5Eclear2(H5E_DEFAULT);
        return false;
      }
      pos = next + 1;
    }
  }

  H5I_type_t object_type(const std::string& norm) const {
    if (!link_exists(norm)) return H5I_BADID;
    Hid obj(H5Oopen(file.get(), norm.c_str(), H5P_DEFAULT), H5Oclose);
    if (!obj.valid()) {
      H5Eclear2(H5E_DEFAULT);
      return H5I_BADID;
    }
    return H5Iget_type(obj.get());
  }

  void ensure_group(const std::string& norm) {
    if (norm == "/") return;
    const H5I_type_t t = object_type(norm);
    if (t == H5I_GROUP) return;
    if (t != H5I_BADID) fail("cannot create group " + norm + ": a dataset of that name exists");
    ensure_group(parent_of(norm));
    Hid gcpl = make_ocpl(H5P_GROUP_CREATE);
    Hid g(H5Gcreate2(file.get(), norm.c_str(), H5P_DEFAULT, gcpl.get(), H5P_DEFAULT), H5Gclose);
    if (!g.valid()) fail_hdf5("cannot create group " + norm);
  }

  Hid open_dataset(const std::string& norm) const {
    const H5I_type_t t = object_type(norm);
    if (t == H5I_BADID) fail("dataset " + norm + " not found");
    if (t != H5I_DATASET) fail("dataset " + norm + " not found (" + norm + " is a group)");
    Hid d(H5Dopen2(file.get(), norm.c_str(), H5P_DEFAULT), H5Dclose);
    if (!d.valid()) fail_hdf5("cannot open dataset " + norm);
    return d;
  }

  // Full extent of a dataset.
  static std::vector<std::int64_t> extent_of(hid_t dset) {
    Hid space(H5Dget_space(dset), H5Sclose);
    const int rank = H5Sget_simple_extent_ndims(space.get());
    std::vector<hsize_t> d(std::max(rank, 0));
    if (rank > 0) H5Sget_simple_extent_dims(space.get(), d.data(), nullptr);
    return std::vector<std::int64_t>(d.begin(), d.end());
  }
  // Readable dims: the extent, with the first dimension limited to the
  // committed frames of an appended dataset.
  static std::vector<std::int64_t> dims_of(hid_t dset) {
    std::vector<std::int64_t> d = extent_of(dset);
    if (!d.empty()) d[0] = committed_frames(dset, d[0]);
    return d;
  }

  static H5Type type_of(hid_t dset) {
    Hid t(H5Dget_type(dset), H5Tclose);
    return classify(t.get());
  }

  // Opens a dataset and checks its rank and element type.
  Hid open_checked(const std::string& norm, int rank, H5Type type, std::vector<std::int64_t>* dims) const {
    Hid d = open_dataset(norm);
    *dims = dims_of(d.get());
    const H5Type found = type_of(d.get());
    if (static_cast<int>(dims->size()) != rank || found != type) {
      std::ostringstream s;
      s << "dataset " << norm << ": expected a rank-" << rank << " " << type_name(type)
        << " array, found " << type_name(found) << " dims " << dims_text(*dims);
      fail(s.str());
    }
    return d;
  }

  // Elements of the readable dims, refused (InputError) when the file does
  // not store them: HDF5 reads never-written parts of a dataset as fill
  // values, so a small file can declare dims of 10^12 elements, and reading
  // them would allocate terabytes. An uncompressed dataset must store at
  // least `min_bytes_per_element` bytes per element; a compressed one (any
  // filter) at least 1/1100 of that (deflate's best ratio is about 1:1032).
  size_t stored_elements(hid_t dset, const std::string& norm, const std::vector<std::int64_t>& dims,
                         size_t min_bytes_per_element) const {
    size_t n = 1;
    bool overflow = false;
    for (auto v : dims) overflow = overflow || v < 0 || __builtin_mul_overflow(n, static_cast<size_t>(v), &n);
    if (n == 0 && !overflow) {
      // An empty dataset stores nothing, but its other dimensions still size
      // what the callers build and loop over (a 0 x 2^35 matrix): the stages
      // index with int, so a dimension beyond that range is refused too.
      for (auto v : dims) {
        if (v > std::numeric_limits<std::int32_t>::max()) {
          std::ostringstream s;
          s << "dataset " << norm << ": dims " << dims_text(dims) << " have a dimension over "
            << std::numeric_limits<std::int32_t>::max() << ", the largest the readers index";
          fail(s.str());
        }
      }
      return 0;
    }
    size_t needed = 0;
    overflow = overflow || __builtin_mul_overflow(n, min_bytes_per_element, &needed);
    Hid plist(H5Dget_create_plist(dset), H5Pclose);
    const double ratio = plist.valid() && H5Pget_nfilters(plist.get()) > 0 ? 1100.0 : 1.0;
    const double stored = static_cast<double>(H5Dget_storage_size(dset));
    if (overflow || static_cast<double>(needed) > stored * ratio) {
      std::ostringstream s;
      s << "dataset " << norm << ": dims " << dims_text(dims) << " need "
        << (overflow ? std::string("more than 2^64") : std::to_string(needed)) << " bytes, but the file stores "
        << static_cast<std::uint64_t>(stored) << (ratio > 1 ? " compressed" : "")
        << " (a truncated or never written dataset)";
      fail(s.str());
    }
    return n;
  }

  template <typename T>
  std::vector<T> read_numeric(const std::string& name, int rank, std::vector<std::int64_t>* dims) const {
    const std::string norm = normalize(name);
    constexpr bool is_double = std::is_same_v<T, double>;
    Hid d = open_checked(norm, rank, is_double ? H5Type::kDouble : H5Type::kInt, dims);
    Hid ftype(H5Dget_type(d.get()), H5Tclose);
    const size_t n = stored_elements(d.get(), norm, *dims, std::max<size_t>(1, H5Tget_size(ftype.get())));
    std::vector<T> buf(n);
    if (n == 0) return buf;
    // Select the readable frames only (see kFramesAttribute).
    std::vector<hsize_t> count(dims->begin(), dims->end()), start(dims->size(), 0);
    Hid fspace(H5Dget_space(d.get()), H5Sclose);
    Hid mspace(H5Screate_simple(rank, count.data(), nullptr), H5Sclose);
    H5Sselect_hyperslab(fspace.get(), H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr);
    if (H5Dread(d.get(), is_double ? H5T_NATIVE_DOUBLE : H5T_NATIVE_INT, mspace.get(), fspace.get(),
                H5P_DEFAULT, buf.data()) < 0) {
      fail_hdf5("cannot read dataset " + norm);
    }
    return buf;
  }

  Hid open_object(const std::string& object) const {
    const std::string norm = normalize(object);
    if (!link_exists(norm)) fail("object " + norm + " not found (for attributes)");
    Hid o(H5Oopen(file.get(), norm.c_str(), H5P_DEFAULT), H5Oclose);
    if (!o.valid()) fail_hdf5("cannot open object " + norm);
    return o;
  }

  Hid open_attribute(const std::string& object, const std::string& key) const {
    Hid o = open_object(object);
    const htri_t e = H5Aexists(o.get(), key.c_str());
    if (e <= 0) {
      H5Eclear2(H5E_DEFAULT);
      fail("attribute '" + key + "' of " + normalize(object) + " not found");
    }
    Hid a(H5Aopen(o.get(), key.c_str(), H5P_DEFAULT), H5Aclose);
    if (!a.valid()) fail_hdf5("cannot open attribute '" + key + "' of " + normalize(object));
    return a;
  }

  // Creates (replacing) a scalar attribute of file type `ftype`, writes `buf`
  // in memory type `mtype`.
  void write_attribute(const std::string& object, const std::string& key, hid_t ftype, hid_t mtype,
                       const void* buf) {
    require_writable("attribute " + key);
    Hid o = open_object(object);
    if (H5Aexists(o.get(), key.c_str()) > 0) H5Adelete(o.get(), key.c_str());
    H5Eclear2(H5E_DEFAULT);
    Hid space(H5Screate(H5S_SCALAR), H5Sclose);
    Hid a(H5Acreate2(o.get(), key.c_str(), ftype, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
    if (!a.valid() || H5Awrite(a.get(), mtype, buf) < 0) {
      fail_hdf5("cannot write attribute '" + key + "' of " + normalize(object));
    }
  }
};

H5File::H5File(const std::string& path, Mode mode) : impl_(std::make_unique<Impl>()) {
  init_hdf5();
  impl_->path = path;
  Hid fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
  // Use file locking where the file system supports it, but do not fail on
  // file systems that do not (some network mounts).
  H5Pset_file_locking(fapl.get(), 1, 1);
  hid_t f = H5I_INVALID_HID;
  switch (mode) {
    case Mode::kRead:
      if (!std::filesystem::exists(path)) impl_->fail("cannot open HDF5 file: no such file");
      f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, fapl.get());
      if (f < 0) impl_->fail_hdf5("cannot open HDF5 file for reading");
      break;
    case Mode::kReadWrite:
      if (std::filesystem::exists(path)) {
        f = H5Fopen(path.c_str(), H5F_ACC_RDWR, fapl.get());
        if (f < 0) impl_->fail_hdf5("cannot open HDF5 file for writing");
      } else {
        f = H5Fcreate(path.c_str(), H5F_ACC_EXCL, H5P_DEFAULT, fapl.get());
        if (f < 0) impl_->fail_hdf5("cannot create HDF5 file");
      }
      impl_->writable = true;
      break;
    case Mode::kTruncate:
      f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.get());
      if (f < 0) impl_->fail_hdf5("cannot create HDF5 file");
      impl_->writable = true;
      break;
  }
  impl_->file = Hid(f, H5Fclose);
}

H5File::~H5File() = default;
H5File::H5File(H5File&&) noexcept = default;
H5File& H5File::operator=(H5File&&) noexcept = default;

const std::string& H5File::path() const { return impl_->path; }
bool H5File::writable() const { return impl_->writable; }

bool H5File::exists(const std::string& name) const { return impl_->link_exists(normalize(name)); }
bool H5File::is_dataset(const std::string& name) const {
  return impl_->object_type(normalize(name)) == H5I_DATASET;
}
bool H5File::is_group(const std::string& name) const {
  return impl_->object_type(normalize(name)) == H5I_GROUP;
}

std::vector<std::string> H5File::list(const std::string& group) const {
  const std::string norm = normalize(group);
  if (impl_->object_type(norm) != H5I_GROUP) impl_->fail("group " + norm + " not found");
  Hid g(H5Gopen2(impl_->file.get(), norm.c_str(), H5P_DEFAULT), H5Gclose);
  std::vector<std::string> names;
  hsize_t idx = 0;
  if (H5Literate(g.get(), H5_INDEX_NAME, H5_ITER_INC, &idx, collect_link, &names) < 0) {
    impl_->fail_hdf5("cannot list group " + norm);
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::vector<std::int64_t> H5File::dims(const std::string& name) const {
  Hid d = impl_->open_dataset(normalize(name));
  return Impl::dims_of(d.get());
}

std::vector<std::int64_t> H5File::extent(const std::string& name) const {
  Hid d = impl_->open_dataset(normalize(name));
  return Impl::extent_of(d.get());
}

H5Type H5File::type(const std::string& name) const {
  Hid d = impl_->open_dataset(normalize(name));
  return Impl::type_of(d.get());
}

void H5File::create_group(const std::string& name) {
  impl_->require_writable(normalize(name));
  impl_->ensure_group(normalize(name));
}

void H5File::remove(const std::string& name) {
  const std::string norm = normalize(name);
  impl_->require_writable(norm);
  if (norm == "/") impl_->fail("cannot remove the root group");
  if (!impl_->link_exists(norm)) impl_->fail("cannot remove " + norm + ": not found");
  if (H5Ldelete(impl_->file.get(), norm.c_str(), H5P_DEFAULT) < 0) impl_->fail_hdf5("cannot remove " + norm);
}

void H5File::write_raw(const std::string& name, const std::vector<std::int64_t>& dims, const void* data,
                       bool is_double) {
  const std::string norm = normalize(name);
  impl_->require_writable(norm);
  if (norm == "/") impl_->fail("cannot write a dataset named /");
  const hid_t ftype = is_double ? H5T_IEEE_F64LE : H5T_STD_I32LE;
  const hid_t mtype = is_double ? H5T_NATIVE_DOUBLE : H5T_NATIVE_INT;
  size_t n = 1;
  for (auto v : dims) n *= static_cast<size_t>(v);

  Hid dset;
  const H5I_type_t existing = impl_->object_type(norm);
  if (existing == H5I_GROUP) impl_->fail("cannot write dataset " + norm + ": a group of that name exists");
  if (existing == H5I_DATASET) {
    // Same type, dims and contiguous layout: overwrite in place (no file
    // growth). Otherwise unlink and recreate.
    Hid d(H5Dopen2(impl_->file.get(), norm.c_str(), H5P_DEFAULT), H5Dclose);
    Hid plist(H5Dget_create_plist(d.get()), H5Pclose);
    Hid t(H5Dget_type(d.get()), H5Tclose);
    const bool same = Impl::extent_of(d.get()) == dims && H5Pget_layout(plist.get()) == H5D_CONTIGUOUS &&
                      H5Tequal(t.get(), ftype) > 0;
    if (same) {
      dset = std::move(d);
    } else {
      d.reset();
      if (H5Ldelete(impl_->file.get(), norm.c_str(), H5P_DEFAULT) < 0) {
        impl_->fail_hdf5("cannot replace dataset " + norm);
      }
    }
  }
  if (!dset.valid()) {
    impl_->ensure_group(parent_of(norm));
    std::vector<hsize_t> hd(dims.begin(), dims.end());
    Hid space(H5Screate_simple(static_cast<int>(hd.size()), hd.data(), nullptr), H5Sclose);
    Hid dcpl = make_ocpl(H5P_DATASET_CREATE);
    dset = Hid(H5Dcreate2(impl_->file.get(), norm.c_str(), ftype, space.get(), H5P_DEFAULT, dcpl.get(),
                          H5P_DEFAULT),
               H5Dclose);
    if (!dset.valid()) impl_->fail_hdf5("cannot create dataset " + norm);
  }
  if (n > 0 && H5Dwrite(dset.get(), mtype, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0) {
    impl_->fail_hdf5("cannot write dataset " + norm);
  }
}

void H5File::write(const std::string& name, const std::vector<std::string>& strings) {
  const std::string norm = normalize(name);
  impl_->require_writable(norm);
  if (impl_->object_type(norm) == H5I_GROUP) {
    impl_->fail("cannot write dataset " + norm + ": a group of that name exists");
  }
  if (impl_->link_exists(norm)) H5Ldelete(impl_->file.get(), norm.c_str(), H5P_DEFAULT);
  impl_->ensure_group(parent_of(norm));
  Hid type = string_type();
  hsize_t dim = strings.size();
  Hid space(H5Screate_simple(1, &dim, nullptr), H5Sclose);
  Hid dcpl = make_ocpl(H5P_DATASET_CREATE);
  Hid d(H5Dcreate2(impl_->file.get(), norm.c_str(), type.get(), space.get(), H5P_DEFAULT, dcpl.get(),
                   H5P_DEFAULT),
        H5Dclose);
  if (!d.valid()) impl_->fail_hdf5("cannot create dataset " + norm);
  std::vector<const char*> ptrs(strings.size());
  for (size_t i = 0; i < strings.size(); ++i) ptrs[i] = strings[i].c_str();
  if (!ptrs.empty() && H5Dwrite(d.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, ptrs.data()) < 0) {
    impl_->fail_hdf5("cannot write dataset " + norm);
  }
}

void H5File::write(const std::string& name, const std::vector<double>& values) {
  write_raw(name, {static_cast<std::int64_t>(values.size())}, values.data(), true);
}
void H5File::write(const std::string& name, const std::vector<int>& values) {
  write_raw(name, {static_cast<std::int64_t>(values.size())}, values.data(), false);
}

namespace {
template <typename T>
void check_tensor_size(const H5File& f, const std::string& name, const std::array<std::int64_t, 3>& dims,
                       const std::vector<T>& data) {
  for (auto d : dims) {
    if (d < 0) throw InputError(f.path(), 0, "dataset " + normalize(name) + ": negative dimension");
  }
  const auto n = dims[0] * dims[1] * dims[2];
  if (static_cast<std::int64_t>(data.size()) != n) {
    std::ostringstream s;
    s << "dataset " << normalize(name) << ": expected " << n << " values for dims "
      << dims_text({dims[0], dims[1], dims[2]}) << ", found " << data.size();
    throw InputError(f.path(), 0, s.str());
  }
}
}  // namespace

void H5File::write_tensor3(const std::string& name, const std::array<std::int64_t, 3>& dims,
                           const std::vector<double>& row_major) {
  check_tensor_size(*this, name, dims, row_major);
  write_raw(name, {dims[0], dims[1], dims[2]}, row_major.data(), true);
}
void H5File::write_tensor3(const std::string& name, const std::array<std::int64_t, 3>& dims,
                           const std::vector<int>& row_major) {
  check_tensor_size(*this, name, dims, row_major);
  write_raw(name, {dims[0], dims[1], dims[2]}, row_major.data(), false);
}

Eigen::MatrixXd H5File::read_matrix(const std::string& name) const {
  std::vector<std::int64_t> d;
  auto buf = impl_->read_numeric<double>(name, 2, &d);
  if (buf.empty()) return Eigen::MatrixXd(d[0], d[1]);
  return Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(buf.data(), d[0], d[1]);
}
Eigen::VectorXd H5File::read_vector(const std::string& name) const {
  std::vector<std::int64_t> d;
  auto buf = impl_->read_numeric<double>(name, 1, &d);
  return Eigen::Map<Eigen::VectorXd>(buf.data(), d[0]);
}
Eigen::MatrixXi H5File::read_matrix_int(const std::string& name) const {
  std::vector<std::int64_t> d;
  auto buf = impl_->read_numeric<int>(name, 2, &d);
  if (buf.empty()) return Eigen::MatrixXi(d[0], d[1]);
  return Eigen::Map<Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(buf.data(), d[0], d[1]);
}
Eigen::VectorXi H5File::read_vector_int(const std::string& name) const {
  std::vector<std::int64_t> d;
  auto buf = impl_->read_numeric<int>(name, 1, &d);
  return Eigen::Map<Eigen::VectorXi>(buf.data(), d[0]);
}
Tensor3d H5File::read_tensor3(const std::string& name) const {
  Tensor3d t;
  std::vector<std::int64_t> d;
  t.data = impl_->read_numeric<double>(name, 3, &d);
  t.dims = {d[0], d[1], d[2]};
  return t;
}
Tensor3i H5File::read_tensor3_int(const std::string& name) const {
  Tensor3i t;
  std::vector<std::int64_t> d;
  t.data = impl_->read_numeric<int>(name, 3, &d);
  t.dims = {d[0], d[1], d[2]};
  return t;
}

namespace {
template <typename M>
void check_cols(const H5File& f, const std::string& name, const M& m, std::int64_t cols) {
  if (m.cols() != cols) {
    std::ostringstream s;
    s << "dataset " << normalize(name) << ": expected dims (*, " << cols << "), found ("
      << m.rows() << ", " << m.cols() << ")";
    throw InputError(f.path(), 0, s.str());
  }
}
}  // namespace

Eigen::MatrixXd H5File::read_matrix(const std::string& name, std::int64_t required_cols) const {
  Eigen::MatrixXd m = read_matrix(name);
  check_cols(*this, name, m, required_cols);
  return m;
}
Eigen::MatrixXi H5File::read_matrix_int(const std::string& name, std::int64_t required_cols) const {
  Eigen::MatrixXi m = read_matrix_int(name);
  check_cols(*this, name, m, required_cols);
  return m;
}

std::vector<std::string> H5File::read_strings(const std::string& name) const {
  const std::string norm = normalize(name);
  std::vector<std::int64_t> d;
  Hid dset = impl_->open_checked(norm, 1, H5Type::kString, &d);
  Hid ftype(H5Dget_type(dset.get()), H5Tclose);
  // A variable-length string is stored as a global-heap reference (16 bytes);
  // 8 per element is a safe lower bound for both kinds.
  const size_t bytes = H5Tis_variable_str(ftype.get()) > 0 ? 8 : std::max<size_t>(1, H5Tget_size(ftype.get()));
  const size_t n = impl_->stored_elements(dset.get(), norm, d, bytes);
  bool failed = false;
  auto out = read_string_data(ftype.get(), n, [&](hid_t mem, void* buf) {
    const herr_t r = H5Dread(dset.get(), mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf);
    failed = r < 0;
    return r;
  });
  if (failed) impl_->fail_hdf5("cannot read dataset " + norm);
  return out;
}

// ---- attributes -------------------------------------------------------------
void H5File::set_attribute(const std::string& object, const std::string& key, const std::string& value) {
  Hid type = string_type();
  const char* p = value.c_str();
  impl_->write_attribute(object, key, type.get(), type.get(), &p);
}
void H5File::set_attribute(const std::string& object, const std::string& key, double value) {
  impl_->write_attribute(object, key, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &value);
}
void H5File::set_attribute(const std::string& object, const std::string& key, std::int64_t value) {
  impl_->write_attribute(object, key, H5T_STD_I64LE, H5T_NATIVE_INT64, &value);
}

bool H5File::has_attribute(const std::string& object, const std::string& key) const {
  if (!impl_->link_exists(normalize(object))) return false;
  Hid o = impl_->open_object(object);
  const htri_t e = H5Aexists(o.get(), key.c_str());
  H5Eclear2(H5E_DEFAULT);
  return e > 0;
}

std::vector<std::string> H5File::attribute_names(const std::string& object) const {
  Hid o = impl_->open_object(object);
  std::vector<std::string> names;
  hsize_t idx = 0;
  if (H5Aiterate2(o.get(), H5_INDEX_NAME, H5_ITER_INC, &idx, collect_attr, &names) < 0) {
    impl_->fail_hdf5("cannot list attributes of " + normalize(object));
  }
  std::sort(names.begin(), names.end());
  return names;
}

namespace {
std::string attr_mismatch(const std::string& object, const std::string& key, const char* expected, H5Type found) {
  return "attribute '" + key + "' of " + normalize(object) + ": expected " + expected + ", found " +
         type_name(found);
}
}  // namespace

std::string H5File::attribute_string(const std::string& object, const std::string& key) const {
  Hid a = impl_->open_attribute(object, key);
  Hid t(H5Aget_type(a.get()), H5Tclose);
  if (classify(t.get()) != H5Type::kString) impl_->fail(attr_mismatch(object, key, "a string", classify(t.get())));
  Hid space(H5Aget_space(a.get()), H5Sclose);
  const hssize_t n = H5Sget_simple_extent_npoints(space.get());
  if (n != 1) impl_->fail("attribute '" + key + "' of " + normalize(object) + ": expected one string, found " + std::to_string(n));
  bool failed = false;
  auto out = read_string_data(t.get(), 1, [&](hid_t mem, void* buf) {
    const herr_t r = H5Aread(a.get(), mem, buf);
    failed = r < 0;
    return r;
  });
  if (failed) impl_->fail_hdf5("cannot read attribute '" + key + "' of " + normalize(object));
  return out[0];
}

double H5File::attribute_double(const std::string& object, const std::string& key) const {
  Hid a = impl_->open_attribute(object, key);
  Hid t(H5Aget_type(a.get()), H5Tclose);
  const H5Type c = classify(t.get());
  if (c != H5Type::kDouble && c != H5Type::kInt) impl_->fail(attr_mismatch(object, key, "a number", c));
  Hid space(H5Aget_space(a.get()), H5Sclose);
  if (H5Sget_simple_extent_npoints(space.get()) != 1) {
    impl_->fail("attribute '" + key + "' of " + normalize(object) + ": expected a scalar");
  }
  double v = 0.0;
  if (H5Aread(a.get(), H5T_NATIVE_DOUBLE, &v) < 0) impl_->fail_hdf5("cannot read attribute '" + key + "'");
  return v;
}

std::int64_t H5File::attribute_int(const std::string& object, const std::string& key) const {
  Hid a = impl_->open_attribute(object, key);
  Hid t(H5Aget_type(a.get()), H5Tclose);
  const H5Type c = classify(t.get());
  if (c != H5Type::kInt) impl_->fail(attr_mismatch(object, key, "an integer", c));
  Hid space(H5Aget_space(a.get()), H5Sclose);
  if (H5Sget_simple_extent_npoints(space.get()) != 1) {
    impl_->fail("attribute '" + key + "' of " + normalize(object) + ": expected a scalar");
  }
  std::int64_t v = 0;
  if (H5Aread(a.get(), H5T_NATIVE_INT64, &v) < 0) impl_->fail_hdf5("cannot read attribute '" + key + "'");
  return v;
}

void H5File::flush() {
  if (H5Fflush(impl_->file.get(), H5F_SCOPE_LOCAL) < 0) impl_->fail_hdf5("cannot flush");
}

// ---- appending ----------------------------------------------------------------
struct H5File::Appender::Impl {
  std::string path;  // file path, for messages
  std::string name;
  Hid dset;
  Hid committed;  // the kFramesAttribute attribute of dset
  std::vector<std::int64_t> frame_dims;
  bool is_double = true;
  bool closed = false;
  std::int64_t n_frames = 0;  // complete frames (== the counter on disk)
  std::int64_t capacity = 0;  // current extent along the frame axis
  std::int64_t chunk_frames = 1;

  [[noreturn]] void fail(const std::string& m) const { throw InputError(path, 0, "dataset " + name + ": " + m); }

  void set_extent(std::int64_t frames) {
    std::vector<hsize_t> extent{static_cast<hsize_t>(frames)};
    for (auto d : frame_dims) extent.push_back(static_cast<hsize_t>(d));
    if (H5Dset_extent(dset.get(), extent.data()) < 0) fail("cannot resize: " + hdf5_message());
    capacity = frames;
  }
  void flush() {
    if (H5Fflush(dset.get(), H5F_SCOPE_LOCAL) < 0) fail("cannot flush: " + hdf5_message());
  }
};

H5File::Appender::Appender(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
H5File::Appender::Appender(Appender&&) noexcept = default;
H5File::Appender& H5File::Appender::operator=(Appender&& o) noexcept {
  if (this != &o) {
    if (impl_) {
      try {
        close();
      } catch (...) {
      }
    }
    impl_ = std::move(o.impl_);
  }
  return *this;
}
H5File::Appender::~Appender() {
  if (!impl_) return;
  try {
    close();
  } catch (...) {
    // Destructors must not throw; the frames written stay readable through
    // the frame counter even if the shrink failed.
  }
}

void H5File::Appender::close() {
  Impl& a = *impl_;
  if (a.closed) return;
  a.closed = true;
  if (a.capacity != a.n_frames) {
    a.set_extent(a.n_frames);
    a.flush();
  }
  a.committed.reset();
  a.dset.reset();
}

std::int64_t H5File::Appender::num_frames() const { return impl_->n_frames; }
const std::vector<std::int64_t>& H5File::Appender::frame_dims() const { return impl_->frame_dims; }

void H5File::Appender::append(double value) { append_raw(&value, 1, 1, true); }
void H5File::Appender::append(int value) { append_raw(&value, 1, 1, false); }

void H5File::Appender::append_raw(const void* data, std::int64_t rows, std::int64_t cols, bool is_double) {
  Impl& a = *impl_;
  const auto& fd = a.frame_dims;
  if (a.closed) a.fail("append after close()");
  if (is_double != a.is_double) {
    a.fail(std::string("appending a frame of ") + (is_double ? "double" : "int") + " values to a dataset of " +
           (a.is_double ? "double" : "int"));
  }
  bool ok = false;
  if (fd.empty()) {
    ok = rows * cols == 1;
  } else if (fd.size() == 1) {
    ok = (rows == 1 || cols == 1) && rows * cols == fd[0];
  } else {
    ok = rows == fd[0] && cols == fd[1];
  }
  if (!ok) {
    std::ostringstream s;
    s << "frame " << a.n_frames << ": expected frame dims " << dims_text(fd) << ", found (" << rows << ", "
      << cols << ")";
    a.fail(s.str());
  }
  if (a.n_frames >= a.capacity) {
    // Growth: the one kind of append that changes the file structure (chunk
    // index, extent). Doubling keeps it to log2(n) appends. Flushed on its
    // own, before the frame, so the frame's own flush below is structural-
    // change free.
    const std::int64_t grown = std::max(2 * a.capacity, a.chunk_frames);
    a.set_extent((grown + a.chunk_frames - 1) / a.chunk_frames * a.chunk_frames);
    a.flush();
  }
  if (rows * cols > 0) {
    std::vector<hsize_t> start(fd.size() + 1, 0), count{1};
    for (auto d : fd) count.push_back(static_cast<hsize_t>(d));
    start[0] = static_cast<hsize_t>(a.n_frames);
    Hid fspace(H5Dget_space(a.dset.get()), H5Sclose);
    H5Sselect_hyperslab(fspace.get(), H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr);
    Hid mspace(H5Screate_simple(static_cast<int>(count.size()), count.data(), nullptr), H5Sclose);
    if (H5Dwrite(a.dset.get(), is_double ? H5T_NATIVE_DOUBLE : H5T_NATIVE_INT, mspace.get(), fspace.get(),
                 H5P_DEFAULT, data) < 0) {
      a.fail("cannot write frame " + std::to_string(a.n_frames) + ": " + hdf5_message());
    }
  }
  // Two-phase commit (see kFramesAttribute): the first flush puts the frame's
  // raw data into its already allocated chunk; only then does the counter
  // move, in a second flush that rewrites the object header in place.
  a.flush();
  const std::int64_t committed = a.n_frames + 1;
  if (H5Awrite(a.committed.get(), H5T_NATIVE_INT64, &committed) < 0) {
    a.fail("cannot update frame counter: " + hdf5_message());
  }
  a.flush();
  a.n_frames = committed;
}

H5File::Appender H5File::make_appender(const std::string& name, const std::vector<std::int64_t>& frame_dims,
                                       const H5AppendOptions& options, bool is_double) {
  const std::string norm = normalize(name);
  impl_->require_writable(norm);
  const auto fail = [&](const std::string& m) { impl_->fail("dataset " + norm + ": " + m); };
  if (frame_dims.size() > 2) fail("frame rank " + std::to_string(frame_dims.size()) + " > 2 is not supported");
  for (auto d : frame_dims) {
    if (d < 0) fail("negative frame dimension");
  }
  if (options.frames_per_chunk < 0 || options.expected_frames < 0) {
    fail("negative frames_per_chunk or expected_frames");
  }
  auto a = std::make_unique<Appender::Impl>();
  a->path = impl_->path;
  a->name = norm;
  a->frame_dims = frame_dims;
  a->is_double = is_double;
  const int rank = static_cast<int>(frame_dims.size()) + 1;

  const H5I_type_t existing = impl_->object_type(norm);
  if (existing == H5I_GROUP) fail("a group of that name exists");
  if (existing == H5I_DATASET) {
    // Continue an existing appendable dataset of the same kind.
    Hid d(H5Dopen2(impl_->file.get(), norm.c_str(), H5P_DEFAULT), H5Dclose);
    Hid space(H5Dget_space(d.get()), H5Sclose);
    std::vector<hsize_t> cur(std::max(H5Sget_simple_extent_ndims(space.get()), 0));
    std::vector<hsize_t> max(cur.size());
    if (!cur.empty()) H5Sget_simple_extent_dims(space.get(), cur.data(), max.data());
    std::vector<std::int64_t> found(cur.begin(), cur.end());
    const H5Type t = Impl::type_of(d.get());
    bool ok = static_cast<int>(cur.size()) == rank && max[0] == H5S_UNLIMITED &&
              t == (is_double ? H5Type::kDouble : H5Type::kInt);
    for (size_t i = 0; ok && i < frame_dims.size(); ++i) ok = found[i + 1] == frame_dims[i];
    if (!ok) {
      std::vector<std::int64_t> want{-1};
      want.insert(want.end(), frame_dims.begin(), frame_dims.end());
      std::string w = dims_text(want);
      w.replace(1, 2, "unlimited");
      fail(std::string("cannot append: expected an appendable ") + (is_double ? "floating-point" : "integer") +
           " dataset of dims " + w + ", found " + type_name(t) + " dims " + dims_text(found) +
           (cur.empty() || max[0] == H5S_UNLIMITED ? "" : " (fixed size)"));
    }
    Hid plist(H5Dget_create_plist(d.get()), H5Pclose);
    std::vector<hsize_t> chunk(rank, 1);
    H5Pget_chunk(plist.get(), rank, chunk.data());
    a->chunk_frames = static_cast<std::int64_t>(std::max<hsize_t>(chunk[0], 1));
    a->n_frames = committed_frames(d.get(), found[0]);
    a->capacity = found[0];
    if (H5Aexists(d.get(), kFramesAttribute) <= 0) {
      H5Eclear2(H5E_DEFAULT);
      create_frames_attribute(d.get(), a->n_frames);
    }
    a->committed = Hid(H5Aopen(d.get(), kFramesAttribute, H5P_DEFAULT), H5Aclose);
    if (!a->committed.valid()) impl_->fail_hdf5("cannot open frame counter of " + norm);
    a->dset = std::move(d);
    if (options.expected_frames > a->capacity) a->set_extent(options.expected_frames);
    a->flush();
    return Appender(std::move(a));
  }

  impl_->ensure_group(parent_of(norm));
  std::int64_t frames_per_chunk = options.frames_per_chunk;
  std::vector<hsize_t> dims0{0}, maxdims{H5S_UNLIMITED}, chunk{0};
  std::int64_t frame_values = 1;
  for (auto d : frame_dims) {
    dims0.push_back(static_cast<hsize_t>(d));
    maxdims.push_back(static_cast<hsize_t>(d));
    chunk.push_back(static_cast<hsize_t>(std::max<std::int64_t>(d, 1)));  // chunk dims must be > 0
    frame_values *= std::max<std::int64_t>(d, 1);
  }
  if (frames_per_chunk == 0) {
    // Every flush rewrites the chunk holding the newest frame, so chunks stay
    // small: at most 64 KiB (or one frame when a frame is larger).
    const std::int64_t frame_bytes = frame_values * (is_double ? 8 : 4);
    frames_per_chunk = std::clamp<std::int64_t>(65536 / frame_bytes, 1, 4096);
  }
  chunk[0] = static_cast<hsize_t>(frames_per_chunk);
  a->chunk_frames = frames_per_chunk;
  Hid space(H5Screate_simple(rank, dims0.data(), maxdims.data()), H5Sclose);
  Hid dcpl = make_ocpl(H5P_DATASET_CREATE);
  H5Pset_chunk(dcpl.get(), rank, chunk.data());
  // Chunks are allocated when the extent grows, not at first write: a
  // steady-state append then changes no chunk index. They are not filled
  // (writing fill values would cost as much I/O as the data): frames beyond
  // the counter are unspecified, in practice zeros of a fresh file region.
  H5Pset_alloc_time(dcpl.get(), H5D_ALLOC_TIME_EARLY);
  H5Pset_fill_time(dcpl.get(), H5D_FILL_TIME_NEVER);
  a->dset = Hid(H5Dcreate2(impl_->file.get(), norm.c_str(), is_double ? H5T_IEEE_F64LE : H5T_STD_I32LE,
                           space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT),
                H5Dclose);
  if (!a->dset.valid()) impl_->fail_hdf5("cannot create dataset " + norm);
  if (!create_frames_attribute(a->dset.get(), 0)) impl_->fail_hdf5("cannot create frame counter of " + norm);
  a->committed = Hid(H5Aopen(a->dset.get(), kFramesAttribute, H5P_DEFAULT), H5Aclose);
  if (options.expected_frames > 0) a->set_extent(options.expected_frames);
  // Make the empty dataset and its allocated space durable before the first frame.
  a->flush();
  return Appender(std::move(a));
}

H5File::Appender H5File::appender(const std::string& name, const std::vector<std::int64_t>& frame_dims,
                                  const H5AppendOptions& options) {
  return make_appender(name, frame_dims, options, true);
}
H5File::Appender H5File::appender_int(const std::string& name, const std::vector<std::int64_t>& frame_dims,
                                      const H5AppendOptions& options) {
  return make_appender(name, frame_dims, options, false);
}

}  // namespace arthrosim::common
