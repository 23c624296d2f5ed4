// Images from files for the offline tools (`trailnav place-eval`): PNG in
// any of its colour types and depths, read through libpng's simplified API
// and turned grey (colour by libpng's luminance of the sRGB values; a grey
// image stored as RGB, as the Nordland frames are, keeps its values).
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace trailnav::drivers::camera {

struct GreyImage {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;  // row-major, width bytes a row
};

struct ImageRead {
  GreyImage image;
  std::string error;  // empty when read; else what was wrong, naming the file
  bool ok() const noexcept { return error.empty(); }
};

// One image file. Refuses what is not a PNG, is truncated or corrupt, or
// larger than max_pixels (a bound on memory: 64 M pixels by default).
ImageRead read_grey_image(const std::string& path, std::uint64_t max_pixels = 64ULL << 20);

// A grey image (width x height bytes, row-major) as an 8-bit grey PNG.
// "" or the error, naming the file.
std::string write_grey_png(const std::string& path, std::span<const std::uint8_t> grey, int width, int height);

struct ImageList {
  std::vector<std::string> paths;  // sorted by file name
  std::string error;
};

// The PNG files of a directory (by their .png extension, any case), sorted
// by name: a sequence recorded frame by frame with zero-padded numbers.
ImageList list_images(const std::string& directory);

}  // namespace trailnav::drivers::camera
