#pragma once
// Content hashing for stage reuse (pipelines/runner.h) and anything else that
// must recognise "the same bytes" across runs and machines.
//
// SHA-256 (FIPS 180-4) written from the standard's description. It is used
// instead of std::hash because std::hash is neither specified nor stable
// across library versions, and instead of FNV-1a because a 64-bit
// non-cryptographic hash makes accidental collisions between large files
// (meshes, HDF5 outputs) plausible enough to matter for a cache key.
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

namespace arthrosim::common {

/// Incremental SHA-256. Feed bytes with update(), then call hex_digest() once
/// (the object is finished afterwards; update() after finishing throws
/// std::logic_error).
class Sha256 {
 public:
  Sha256();
  void update(const void* data, std::size_t size);
  void update(std::string_view text) { update(text.data(), text.size()); }
  /// 32-byte digest. Finishes the hash.
  std::array<std::uint8_t, 32> digest();
  /// 64 lowercase hex characters. Finishes the hash.
  std::string hex_digest();

 private:
  void compress(const std::uint8_t* block);
  std::array<std::uint32_t, 8> h_;
  std::array<std::uint8_t, 64> buffer_{};
  std::size_t buffered_ = 0;
  std::uint64_t total_bytes_ = 0;
  bool finished_ = false;
};

/// SHA-256 of a string, as 64 hex characters.
std::string sha256_hex(std::string_view text);

/// SHA-256 of a file's bytes, as 64 hex characters. Throws InputError naming
/// the file when it cannot be read.
std::string sha256_file(const std::filesystem::path& file);

/// SHA-256 of a file, or of a directory tree: for a directory, every regular
/// file below it in lexicographic order of its relative path (generic form),
/// hashing "relative path NUL file-hash NUL" per file, so renaming, adding or
/// removing a file changes the result as much as editing one does. Hidden
/// entries (names starting with '.') are skipped. Throws InputError when the
/// path does not exist.
///
/// Bounded: a directory holding more than `limits.max_files` files or more
/// than `limits.max_bytes` bytes in them is refused (InputError naming the
/// folder, what it holds so far and the limit) before any byte is hashed, and
/// the walk stops at the first file past a limit, so `model: /usr` fails in
/// well under a second instead of hashing gigabytes. A cheaper stamp (sizes
/// and modification times) is deliberately not used beyond the limit: it
/// misses edits that keep the size and time (copies with -p, checkouts,
/// restored backups), which is the stale reuse the stamp exists to prevent;
/// a folder that large is almost always the wrong folder (the bundled model
/// and trial folders hold < 50 files and < 10 MB).
struct HashLimits {
  std::size_t max_files = 10000;
  std::uintmax_t max_bytes = std::uintmax_t(2) << 30;  // 2 GiB
};
std::string sha256_path(const std::filesystem::path& path, const HashLimits& limits = {});

}  // namespace arthrosim::common
