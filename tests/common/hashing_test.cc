// SHA-256 against the FIPS 180-4 / NIST example vectors, incremental feeding
// across block boundaries, files and directory trees.
#include "common/hashing.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>

#include "common/error.h"

namespace arthrosim::common {
namespace {
namespace fs = std::filesystem;

TEST(Sha256, NistVectors) {
  // FIPS 180-4 examples (NIST CSRC "SHA256.pdf" and the short-message set).
  EXPECT_EQ(sha256_hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(sha256_hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(sha256_hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(sha256_hex("abcdefghbcdefghicdefghijdefghijkefghijklfghijklmghijklmnhijklmnoijklmnopjklmno"
                       "pqklmnopqrlmnopqrsmnopqrstnopqrstu"),
            "cf5b16a778af8380036ce59e7b0492370b249b11e8f07a51afac45037afee9d1");
  // One million 'a', fed in uneven pieces to cross block boundaries.
  Sha256 h;
  const std::string piece(997, 'a');
  std::size_t fed = 0;
  while (fed + piece.size() <= 1000000) {
    h.update(piece);
    fed += piece.size();
  }
  h.update(std::string(1000000 - fed, 'a'));
  EXPECT_EQ(h.hex_digest(), "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
  EXPECT_THROW(h.update("x"), std::logic_error);
}

TEST(Sha256, PaddingBoundaries) {
  // Lengths 55, 56 and 64 put the length field at the edge of a block; the
  // incremental and one-shot paths must agree byte for byte.
  for (std::size_t n : {0u, 1u, 55u, 56u, 57u, 63u, 64u, 65u, 119u, 120u, 128u}) {
    const std::string s(n, 'q');
    Sha256 h;
    for (char c : s) h.update(&c, 1);
    EXPECT_EQ(h.hex_digest(), sha256_hex(s)) << n;
  }
  EXPECT_NE(sha256_hex(std::string(55, 'q')), sha256_hex(std::string(56, 'q')));
}

TEST(Sha256, FilesAndTrees) {
  const fs::path dir = fs::temp_directory_path() / ("arthrosim_hash_test_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "sub");
  std::ofstream(dir / "a.txt") << "abc";
  std::ofstream(dir / "sub" / "b.txt") << "hello";
  std::ofstream(dir / ".hidden") << "ignored";
  EXPECT_EQ(sha256_file(dir / "a.txt"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(sha256_path(dir / "a.txt"), sha256_file(dir / "a.txt"));
  const std::string tree = sha256_path(dir);
  EXPECT_EQ(sha256_path(dir), tree);  // deterministic
  std::ofstream(dir / ".hidden") << "changed";  // hidden entries do not count
  EXPECT_EQ(sha256_path(dir), tree);
  std::ofstream(dir / "sub" / "b.txt") << "hellp";  // a content change
  const std::string edited = sha256_path(dir);
  EXPECT_NE(edited, tree);
  fs::rename(dir / "sub" / "b.txt", dir / "sub" / "c.txt");  // a rename
  EXPECT_NE(sha256_path(dir), edited);
  EXPECT_THROW(sha256_path(dir / "missing"), InputError);
  EXPECT_THROW(sha256_file(dir / "missing"), InputError);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace arthrosim::common
