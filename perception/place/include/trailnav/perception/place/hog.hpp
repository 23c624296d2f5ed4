// The whole-image descriptor of the thesis' §5.1.1: the image cut into
// square patches (32 x 32 pixels in the thesis), a histogram-of-oriented-
// gradients descriptor h per patch, all of them stacked into one vector f and
// f scaled to unit length, so that the cosine similarity of Eq. 5.1 is a dot
// product.
//
// What the thesis leaves open, decided here (docs/place.md measures it):
// - |h| = 128: the thesis' 98,304 dimensions for 32 x 24 patches of a
//   1024 x 768 image are 128 per patch, which is 4 x 4 cells of 8 orientation
//   bins. So a patch is `cells` x `cells` cells (default 4) and each cell a
//   histogram of `bins` (default 8) orientations;
// - orientations unsigned (0-180°, a dark-to-light edge the same as a
//   light-to-dark one: snow against summer grass reverses contrasts), each
//   gradient's magnitude shared linearly between its two nearest bins;
//   gradients by central differences, the border replicated;
// - each patch normalised on its own as Dalal and Triggs' L2-Hys (unit
//   length, values clipped at 0.2, unit length again), so that a bright
//   patch (sky, snow) does not outweigh the rest; a patch without gradients
//   stays zero.
//
// Not for images larger than the descriptor was made for: the buffers are
// sized at construction; compute() allocates nothing.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace trailnav::perception::place {

struct HogConfig {
  int patch = 32;          // pixels, square; the thesis' 32 (0: auto_patch())
  int cells = 4;           // cells per patch side
  int bins = 8;            // orientations over 180°
  float clip = 0.2f;       // L2-Hys
};

// The patch for an image: the thesis' 32 pixels, halved while fewer than 8
// whole patches fit (down to 4), so that a small image (Nordland's 64 x 32
// frames: 16) is still described region by region; docs/place.md measures
// 8, 16 and 32 on Nordland.
int auto_patch(int width, int height) noexcept;

class Hog {
 public:
  // For grey images of width x height (a patch of 0 is auto_patch()'s); patches that do not fit whole (the
  // right and bottom remainder) are left out. Throws std::invalid_argument
  // when not one patch fits or the patch is not a whole number of cells.
  Hog(const HogConfig& config, int width, int height);

  int width() const noexcept { return width_; }
  int height() const noexcept { return height_; }
  int patches_x() const noexcept { return patches_x_; }
  int patches_y() const noexcept { return patches_y_; }
  // |f| = patches x cells² x bins.
  int length() const noexcept { return length_; }
  const HogConfig& config() const noexcept { return config_; }

  // f of a grey image (row-major, `stride` bytes a row) into `out`
  // (length() values, unit length; all zero for an image without gradients).
  void compute(std::span<const std::uint8_t> grey, int stride, std::span<float> out) noexcept;

 private:
  HogConfig config_;
  int width_, height_;
  int patches_x_, patches_y_;
  int length_;
  std::vector<float> magnitude_;   // per pixel of the covered area
  std::vector<float> bin_;         // per pixel: continuous bin position
};

}  // namespace trailnav::perception::place
