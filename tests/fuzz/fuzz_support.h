#pragma once
// Shared by the libFuzzer targets of tests/fuzz (docs/testing.md).
//
// The contract every reader is fuzzed against: on any input it returns or
// throws common::InputError (a clear "file:line: error: ..." message). Any
// other exception escaping a reader is a defect, reported here by abort() so
// that libFuzzer records the input; crashes, sanitizer reports, leaks,
// timeouts and out-of-memory are caught by libFuzzer itself.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <string>
#include <typeinfo>

#include "common/error.h"

namespace arthrosim::fuzz {

template <class F>
int run_reader(F&& read) {
  // ARTHROSIM_FUZZ_VERBOSE=1 prints each input's outcome (to check that a
  // corpus entry is read to its end: run the target on it).
  static const bool verbose = std::getenv("ARTHROSIM_FUZZ_VERBOSE") != nullptr;
  try {
    read();
    if (verbose) std::fprintf(stderr, "fuzz: read without error\n");
  } catch (const common::InputError& e) {
    // The expected outcome for bad input.
    if (verbose) std::fprintf(stderr, "fuzz: InputError: %s\n", e.what());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz: a reader threw %s (not common::InputError): %s\n", typeid(e).name(), e.what());
    std::abort();
  }
  return 0;
}

inline std::string as_string(const std::uint8_t* data, std::size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

/// A folder of this process's own under $TMPDIR (or /tmp) for readers that
/// take a path; removed at exit.
inline const std::filesystem::path& scratch_dir() {
  static const std::filesystem::path dir = [] {
    const char* base = std::getenv("TMPDIR");
    std::string tmpl = std::string(base && *base ? base : "/tmp") + "/arthrosim-fuzz-XXXXXX";
    if (!mkdtemp(tmpl.data())) {
      std::perror("fuzz: mkdtemp");
      std::abort();
    }
    static const std::string keep = tmpl;
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(keep, ec);
    });
    return std::filesystem::path(tmpl);
  }();
  return dir;
}

inline void write_file(const std::filesystem::path& path, const std::string& content) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(content.data(), static_cast<std::streamsize>(content.size()));
  if (!out) {
    std::fprintf(stderr, "fuzz: cannot write %s\n", path.c_str());
    std::abort();
  }
}

}  // namespace arthrosim::fuzz
