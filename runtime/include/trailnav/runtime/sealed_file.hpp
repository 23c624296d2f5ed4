// trailnav's own binary files (the place database, the station file): an
// 8-byte magic, a little-endian u32 version, the body, and zlib's CRC-32 of
// everything before it. One way to seal them, open them, load and save them,
// so each format's reader says only what is its own (its versions, its
// fields). Allocates; not for real-time threads.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace trailnav::sealed {

// A new file's first bytes: the magic and the version.
std::vector<std::uint8_t> begin(std::span<const char, 8> magic, std::uint32_t version);
// Appends the CRC of everything in `out`.
void seal(std::vector<std::uint8_t>& out);

struct Opened {
  std::string problem;                  // "" when the magic is there and the file long enough
  std::uint32_t version = 0;
  bool checksum_ok = false;             // said apart: a reader names an unknown version first
  std::span<const std::uint8_t> body;   // after the version, before the CRC
};
// `kind` names the format in the problem: "not a trailnav <kind> (it does
// not begin with <magic>)".
Opened open(std::span<const std::uint8_t> bytes, std::span<const char, 8> magic, std::string_view kind);

// "" or "PATH: cannot read (reason)".
std::string load(const std::string& path, std::vector<std::uint8_t>& bytes);
// "" or "PATH: cannot write (reason)"; the file is replaced whole (AtomicFile).
std::string save(const std::string& path, std::span<const std::uint8_t> bytes);

}  // namespace trailnav::sealed
