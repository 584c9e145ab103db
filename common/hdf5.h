#pragma once
// HDF5 files for every arthrosim input and output (see docs/file_formats.md).
//
// Conventions (the same for every stage):
//  - Arrays are stored exactly as the caller sees them: an Eigen matrix with r
//    rows and c columns becomes an HDF5 dataset of dims (r, c) in HDF5's C
//    (row-major) order, whatever Eigen's storage order; a compile-time vector
//    (VectorXd, RowVectorXd, VectorXi...) becomes a rank-1 dataset.
//  - doubles are stored as 64-bit IEEE little endian, ints as 32-bit signed
//    little endian, strings as variable-length UTF-8.
//  - Dataset names are absolute or relative to the root ("a/b" == "/a/b");
//    intermediate groups are created automatically; writing a dataset that
//    exists replaces it.
//  - No timestamps are stored (object time tracking is off), so writing the
//    same data twice gives bit-identical datasets.
//  - Errors: a missing dataset or a shape/type mismatch throws InputError
//    "<file>: error: dataset /a/b ..., expected ..., found ..."; a failing HDF5
//    library call throws InputError with HDF5's own innermost message. HDF5's
//    automatic error printing is switched off.
//
// Thread safety: the Debian HDF5 build is not thread-safe. Use an H5File (and
// any H5File at all) from one thread at a time; never from inside an OpenMP
// parallel region.
//
// The HDF5 C API is an implementation detail (pimpl): this header includes
// only Eigen and the standard library.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

namespace arthrosim::common {

/// A rank-3 array, row-major (the last index varies fastest), as stored.
template <typename T>
struct Tensor3 {
  std::array<std::int64_t, 3> dims{0, 0, 0};
  std::vector<T> data;  ///< size dims[0]*dims[1]*dims[2], row-major

  T& operator()(std::int64_t i, std::int64_t j, std::int64_t k) {
    return data[static_cast<size_t>((i * dims[1] + j) * dims[2] + k)];
  }
  const T& operator()(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return data[static_cast<size_t>((i * dims[1] + j) * dims[2] + k)];
  }
};
using Tensor3d = Tensor3<double>;
using Tensor3i = Tensor3<int>;

/// Element type of a dataset, as reported by H5File::type().
enum class H5Type { kDouble, kInt, kString, kOther };

/// Options of H5File::appender.
struct H5AppendOptions {
  /// Frames expected in total (>= 0). Space for them is allocated at once, so
  /// no append before that count changes the file structure (crash safety,
  /// see H5File::Appender). 0 = unknown: start with one chunk and double.
  std::int64_t expected_frames = 0;
  /// Chunk size along the frame axis (>= 0). 0 = automatic: chunks of at most
  /// 64 KiB (one frame if a frame is larger), at most 4096 frames.
  std::int64_t frames_per_chunk = 0;
};

class H5File {
 public:
  enum class Mode {
    kRead,       ///< existing file, read only
    kReadWrite,  ///< existing file, or a new one if it does not exist
    kTruncate,   ///< new empty file (replaces an existing one)
  };

  /// Opens or creates `path`. Throws InputError when the file cannot be
  /// opened (missing, not HDF5, no permission).
  H5File(const std::string& path, Mode mode);
  ~H5File();
  H5File(H5File&&) noexcept;
  H5File& operator=(H5File&&) noexcept;
  H5File(const H5File&) = delete;
  H5File& operator=(const H5File&) = delete;

  const std::string& path() const;
  bool writable() const;

  // ---- structure -------------------------------------------------------
  /// True if a group or dataset of that name exists (every intermediate group
  /// is checked; no error for a missing parent).
  bool exists(const std::string& name) const;
  bool is_dataset(const std::string& name) const;
  bool is_group(const std::string& name) const;
  /// Names (not full paths) of the members of a group, sorted by name.
  /// Throws InputError if `group` is not a group.
  std::vector<std::string> list(const std::string& group = "/") const;
  /// Readable dims of a dataset (empty for a scalar dataset): for a dataset
  /// written by an Appender the first dimension is the number of complete
  /// frames. Throws if missing.
  std::vector<std::int64_t> dims(const std::string& name) const;
  /// Allocated extent of a dataset as HDF5 stores it; differs from dims()
  /// only for an appended dataset whose Appender is still open or was killed
  /// (capacity allocated ahead). Needed by writers of references into the
  /// file (XDMF).
  std::vector<std::int64_t> extent(const std::string& name) const;
  /// Element type of a dataset. Throws if missing.
  H5Type type(const std::string& name) const;
  /// Creates a group (and its parents) if it does not exist yet.
  void create_group(const std::string& name);
  /// Removes a dataset or group (the link; HDF5 does not shrink the file).
  void remove(const std::string& name);

  // ---- writing ---------------------------------------------------------
  /// Writes any Eigen matrix or vector of double or int. Compile-time vectors
  /// become rank-1 datasets, everything else rank 2 (rows x cols).
  template <typename Derived>
  void write(const std::string& name, const Eigen::DenseBase<Derived>& m);
  void write(const std::string& name, const std::vector<std::string>& strings);
  void write(const std::string& name, const std::vector<double>& values);
  void write(const std::string& name, const std::vector<int>& values);
  /// Rank-3 dataset of dims {d0, d1, d2}; `row_major` has d0*d1*d2 values.
  void write_tensor3(const std::string& name, const std::array<std::int64_t, 3>& dims,
                     const std::vector<double>& row_major);
  void write_tensor3(const std::string& name, const std::array<std::int64_t, 3>& dims,
                     const std::vector<int>& row_major);
  void write_tensor3(const std::string& name, const Tensor3d& t) { write_tensor3(name, t.dims, t.data); }
  void write_tensor3(const std::string& name, const Tensor3i& t) { write_tensor3(name, t.dims, t.data); }

  // ---- reading (each throws InputError naming file and dataset when the
  // dataset is missing or its rank/type differs from what is asked for) ----
  Eigen::MatrixXd read_matrix(const std::string& name) const;     ///< rank 2, double
  Eigen::VectorXd read_vector(const std::string& name) const;     ///< rank 1, double
  Eigen::MatrixXi read_matrix_int(const std::string& name) const; ///< rank 2, int
  Eigen::VectorXi read_vector_int(const std::string& name) const; ///< rank 1, int
  std::vector<std::string> read_strings(const std::string& name) const;  ///< rank 1, string
  Tensor3d read_tensor3(const std::string& name) const;           ///< rank 3, double
  Tensor3i read_tensor3_int(const std::string& name) const;       ///< rank 3, int
  /// Matrix with a required number of columns (e.g. 3 for points): throws
  /// "expected dims (*, 3), found (n, m)" otherwise.
  Eigen::MatrixXd read_matrix(const std::string& name, std::int64_t required_cols) const;
  Eigen::MatrixXi read_matrix_int(const std::string& name, std::int64_t required_cols) const;

  // ---- attributes (on "/" , a group or a dataset) ------------------------
  void set_attribute(const std::string& object, const std::string& key, const std::string& value);
  void set_attribute(const std::string& object, const std::string& key, const char* value) {
    set_attribute(object, key, std::string(value));
  }
  void set_attribute(const std::string& object, const std::string& key, double value);
  void set_attribute(const std::string& object, const std::string& key, std::int64_t value);
  void set_attribute(const std::string& object, const std::string& key, int value) {
    set_attribute(object, key, static_cast<std::int64_t>(value));
  }
  bool has_attribute(const std::string& object, const std::string& key) const;
  /// Attribute names of an object, sorted.
  std::vector<std::string> attribute_names(const std::string& object) const;
  /// Getters throw InputError naming file, object and key if missing or of
  /// another type (an integer attribute may be read as double).
  std::string attribute_string(const std::string& object, const std::string& key) const;
  double attribute_double(const std::string& object, const std::string& key) const;
  std::int64_t attribute_int(const std::string& object, const std::string& key) const;

  /// Writes every buffered change to the file (H5Fflush).
  void flush();

  // ---- frame-by-frame appending ------------------------------------------
  /// Appends frames to a dataset whose first dimension is unlimited:
  /// dims (n_frames, frame_dims...). Frame rank is 0 (a scalar per frame),
  /// 1 or 2, so the dataset rank is at most 3.
  ///
  /// Crash safety. Every append() writes one frame and flushes the file, so
  /// a process killed at any moment leaves every frame whose append()
  /// returned readable (through the OS page cache: a killed process, not a
  /// power loss; there is no fsync). How: HDF5 1.10 does not write its
  /// metadata in a crash-consistent order (measured: killing a writer inside
  /// H5Fflush sometimes left a zero-filled last frame, a lost chunk-index
  /// entry, or an end-of-file address below a chunk), so the dataset's space
  /// is allocated ahead (capacity, options.expected_frames) and a steady-state
  /// append changes no file structure: it writes raw data into allocated
  /// chunks, flushes, then bumps the int64 attribute
  /// "arthrosim_frames_complete" and flushes again. Readers (H5File::dims and
  /// every read_*) see only the first arthrosim_frames_complete frames.
  /// When the capacity is exceeded it doubles (the only appends that change
  /// the file structure; not crash-safe; log2(n) of them), so pass the
  /// expected frame count when known. close() (or the destructor) shrinks the
  /// dataset to the frames written, so after a normal end other tools (h5py,
  /// ParaView) see exactly n_frames; after a kill they see the capacity, with
  /// unspecified values (zeros in practice) in the frames beyond the counter.
  ///
  /// If the dataset already exists with the same element type and frame
  /// dims, appending continues after its last complete frame; otherwise
  /// creation of a conflicting dataset throws InputError.
  class Appender {
   public:
    Appender(Appender&&) noexcept;
    Appender& operator=(Appender&&) noexcept;
    /// Calls close(), ignoring errors (call close() to see them).
    ~Appender();
    /// Shrinks the dataset to the frames appended and flushes. Idempotent;
    /// append() after close() throws.
    void close();

    /// One frame: a scalar (frame rank 0), a vector of size d1 (rank 1), or
    /// a matrix d1 x d2 (rank 2). Throws InputError on a size mismatch.
    template <typename Derived>
    void append(const Eigen::DenseBase<Derived>& frame);
    void append(double value);
    void append(int value);
    std::int64_t num_frames() const;
    const std::vector<std::int64_t>& frame_dims() const;

   private:
    friend class H5File;
    struct Impl;
    explicit Appender(std::unique_ptr<Impl> impl);
    // `rows` x `cols` is the shape the caller passed (checked against the
    // frame dims); `data` is row-major.
    void append_raw(const void* data, std::int64_t rows, std::int64_t cols, bool is_double);
    std::unique_ptr<Impl> impl_;
  };

  /// Appender of double (resp. int) frames of dims `frame_dims` (size 0..2).
  Appender appender(const std::string& name, const std::vector<std::int64_t>& frame_dims,
                    const H5AppendOptions& options = {});
  Appender appender_int(const std::string& name, const std::vector<std::int64_t>& frame_dims,
                        const H5AppendOptions& options = {});

 private:
  void write_raw(const std::string& name, const std::vector<std::int64_t>& dims,
                 const void* data, bool is_double);
  Appender make_appender(const std::string& name, const std::vector<std::int64_t>& frame_dims,
                         const H5AppendOptions& options, bool is_double);
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// ---- template definitions ------------------------------------------------

namespace detail {
template <typename Derived>
constexpr bool kIsVector =
    Derived::ColsAtCompileTime == 1 || Derived::RowsAtCompileTime == 1;
template <typename Scalar>
constexpr bool kIsSupportedScalar = std::is_same_v<Scalar, double> || std::is_same_v<Scalar, int>;
}  // namespace detail

template <typename Derived>
void H5File::write(const std::string& name, const Eigen::DenseBase<Derived>& m) {
  using Scalar = typename Derived::Scalar;
  static_assert(detail::kIsSupportedScalar<Scalar>, "H5File::write: double or int only");
  // Copy into row-major order: HDF5 stores C order and we store what the
  // caller sees (rows x cols) regardless of Eigen's storage order.
  Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rm = m;
  std::vector<std::int64_t> dims;
  if constexpr (detail::kIsVector<Derived>) {
    dims = {static_cast<std::int64_t>(rm.size())};
  } else {
    dims = {static_cast<std::int64_t>(rm.rows()), static_cast<std::int64_t>(rm.cols())};
  }
  write_raw(name, dims, rm.data(), std::is_same_v<Scalar, double>);
}

template <typename Derived>
void H5File::Appender::append(const Eigen::DenseBase<Derived>& frame) {
  using Scalar = typename Derived::Scalar;
  static_assert(detail::kIsSupportedScalar<Scalar>, "Appender::append: double or int only");
  Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rm = frame;
  append_raw(rm.data(), static_cast<std::int64_t>(rm.rows()), static_cast<std::int64_t>(rm.cols()),
             std::is_same_v<Scalar, double>);
}

}  // namespace arthrosim::common
