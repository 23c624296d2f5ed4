#include "trailnav/runtime/sealed_file.hpp"

#include <zlib.h>

#include <cstring>

#include "trailnav/runtime/atomic_file.hpp"
#include "trailnav/runtime/le_bytes.hpp"

namespace trailnav::sealed {
namespace {

std::uint32_t crc_of(std::span<const std::uint8_t> bytes) {
  return static_cast<std::uint32_t>(crc32(0L, bytes.data(), static_cast<uInt>(bytes.size())));
}

}  // namespace

std::vector<std::uint8_t> begin(std::span<const char, 8> magic, std::uint32_t version) {
  std::vector<std::uint8_t> out(magic.begin(), magic.end());
  le::put_u32(out, version);
  return out;
}

void seal(std::vector<std::uint8_t>& out) { le::put_u32(out, crc_of(out)); }

Opened open(std::span<const std::uint8_t> bytes, std::span<const char, 8> magic, std::string_view kind) {
  Opened o;
  if (bytes.size() < magic.size() + 8 || std::memcmp(bytes.data(), magic.data(), magic.size()) != 0) {
    // The magic's printable part, for the message.
    const std::string name(magic.data(), strnlen(magic.data(), magic.size()));
    o.problem = "not a trailnav " + std::string(kind) + " (it does not begin with " + name + ")";
    return o;
  }
  const std::span<const std::uint8_t> sealed_part = bytes.first(bytes.size() - 4);
  std::uint32_t stored = 0;
  le::Reader(bytes.last(4)).u32(stored);
  le::Reader(sealed_part.subspan(magic.size())).u32(o.version);
  o.checksum_ok = crc_of(sealed_part) == stored;
  o.body = sealed_part.subspan(magic.size() + 4);
  return o;
}

std::string load(const std::string& path, std::vector<std::uint8_t>& bytes) {
  if (const int e = read_whole_file(path, bytes); e != 0) return path + ": cannot read (" + std::strerror(e) + ")";
  return "";
}

std::string save(const std::string& path, std::span<const std::uint8_t> bytes) {
  const AtomicFile file(path);
  if (const int e = file.write(bytes); e != 0) return path + ": cannot write (" + std::strerror(e) + ")";
  return "";
}

}  // namespace trailnav::sealed
