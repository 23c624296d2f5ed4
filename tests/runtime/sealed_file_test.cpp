// trailnav's sealed files (runtime/sealed_file.hpp) and the atomic file
// under them: a file sealed and saved loads back byte for byte and opens
// with its version and a matching checksum; one changed byte fails the
// checksum; another magic, a file too short, a missing file and a directory
// are refused by name; a save into a missing directory says why and leaves
// nothing behind.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>

#include "trailnav/runtime/le_bytes.hpp"
#include "trailnav/runtime/sealed_file.hpp"

namespace trailnav {
namespace {

constexpr char kMagic[8] = {'T', 'N', 'T', 'E', 'S', 'T', '\0', '\0'};

TEST(SealedFile, RoundTripChecksumAndRefusals) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("sealed-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::vector<std::uint8_t> out = sealed::begin(kMagic, 7);
  le::put_u32(out, 0xDEADBEEFu);
  le::put_f64(out, 2.5);
  sealed::seal(out);
  ASSERT_EQ(out.size(), 8u + 4 + 4 + 8 + 4);
  const std::string path = (dir / "a.bin").string();
  ASSERT_EQ(sealed::save(path, out), "");
  std::vector<std::uint8_t> back;
  ASSERT_EQ(sealed::load(path, back), "");
  EXPECT_EQ(back, out);
  sealed::Opened o = sealed::open(back, kMagic, "test file");
  EXPECT_EQ(o.problem, "");
  EXPECT_EQ(o.version, 7u);
  EXPECT_TRUE(o.checksum_ok);
  ASSERT_EQ(o.body.size(), 12u);
  le::Reader in(o.body);
  std::uint32_t word = 0;
  double value = 0.0;
  ASSERT_TRUE(in.u32(word) && in.f64(value));
  EXPECT_EQ(word, 0xDEADBEEFu);
  EXPECT_EQ(value, 2.5);
  // One byte of the body changed: the version still reads, the checksum fails.
  back[13] ^= 0x10;
  o = sealed::open(back, kMagic, "test file");
  EXPECT_EQ(o.problem, "");
  EXPECT_FALSE(o.checksum_ok);
  back[0] = 'X';
  EXPECT_EQ(sealed::open(back, kMagic, "test file").problem, "not a trailnav test file (it does not begin with TNTEST)");
  const std::vector<std::uint8_t> short_file(out.begin(), out.begin() + 12);
  EXPECT_NE(sealed::open(short_file, kMagic, "test file").problem, "");
  EXPECT_NE(sealed::load((dir / "missing.bin").string(), back).find("missing.bin: cannot read (No such file"), std::string::npos);
  EXPECT_NE(sealed::load(dir.string(), back).find("cannot read"), std::string::npos);
  const std::string nowhere = (dir / "no" / "such" / "b.bin").string();
  EXPECT_NE(sealed::save(nowhere, out).find("b.bin: cannot write (No such file"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(dir / "no"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace trailnav
