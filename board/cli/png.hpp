// Writes 8-bit grey or RGB images as PNG (zlib from Debian), for maps a
// person can look at. Not for real-time threads.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "trailnav/runtime/status.hpp"

namespace trailnav::cli {

enum class PngColor : std::uint8_t { grey = 0, rgb = 2 };

// `pixels` holds `height` rows of `width` pixels, top row first (1 byte per
// pixel for grey, 3 for RGB).
Status write_png(const std::string& path, std::uint32_t width, std::uint32_t height, PngColor color,
                 std::span<const std::uint8_t> pixels);

}  // namespace trailnav::cli

namespace trailnav::cli {

// Reads an 8-bit greyscale PNG (any filter, no interlace) such as the
// simulator's truth rasters; rows top first.
struct GreyImage {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::vector<std::uint8_t> pixels;
};
Status read_png_grey(const std::string& path, GreyImage& out);

}  // namespace trailnav::cli
