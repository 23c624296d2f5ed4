// A camera frame's bytes to the grey image place recognition describes: the
// V4L2 pixel formats trailnav takes (8-bit grey, YUYV 4:2:2 whose Y bytes are
// the grey image, and Motion-JPEG decoded by libturbojpeg straight to grey),
// then an area-average reduction to the descriptor's size. Buffers are
// sized at construction; convert() and reduce() allocate nothing. libjpeg
// takes its decoder's memory with malloc: each MJPEG frame is decoded by a
// decoder made for it and destroyed after it, inside a heap redirect
// (runtime/heap_redirect.hpp) served from an arena sized at construction
// (runtime/arena.hpp), which tjDestroy leaves empty again; builds whose malloc the sanitizers own have no
// redirect, and there the decoder uses the heap.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace trailnav {
class Arena;
}  // namespace trailnav

namespace trailnav::drivers::camera {

enum class PixelFormat : std::uint8_t { grey, yuyv, mjpeg };
const char* pixel_format_name(PixelFormat f) noexcept;
// "grey", "yuyv", "mjpeg"; false for another name.
bool parse_pixel_format(std::string_view name, PixelFormat& out) noexcept;
// The V4L2 fourcc (V4L2_PIX_FMT_GREY, _YUYV, _MJPEG).
std::uint32_t fourcc_of(PixelFormat f) noexcept;

class FrameConverter {
 public:
  // For frames of width x height in `format`, reduced to out_width x
  // out_height (equal: no reduction). Throws std::invalid_argument for
  // sizes below 1 or an output larger than the frame; std::runtime_error
  // when libturbojpeg cannot start.
  FrameConverter(PixelFormat format, int width, int height, int out_width, int out_height);
  ~FrameConverter();
  FrameConverter(const FrameConverter&) = delete;
  FrameConverter& operator=(const FrameConverter&) = delete;

  // One frame's bytes (`bytes_per_line` for the uncompressed formats, as
  // V4L2 reports it) to the reduced grey image. False, with error() set,
  // when the bytes are too few for the format or the JPEG does not decode
  // to this size.
  bool convert(std::span<const std::uint8_t> bytes, int bytes_per_line) noexcept;
  std::span<const std::uint8_t> grey() const noexcept { return out_; }
  int out_width() const noexcept { return out_width_; }
  int out_height() const noexcept { return out_height_; }
  const char* error() const noexcept { return error_; }
  // MJPEG frames that decoded with libjpeg's warnings (extraneous bytes,
  // a premature end: the rest of the picture filled in); they are published.
  std::uint64_t jpeg_warnings() const noexcept { return jpeg_warnings_; }
  // The most of the MJPEG decoder's block one frame used, and its size (bytes).
  std::size_t jpeg_memory_peak() const noexcept;
  std::size_t jpeg_memory_size() const noexcept;

 private:
  PixelFormat format_;
  int width_, height_, out_width_, out_height_;
  std::vector<std::uint8_t> full_;  // the frame in grey, before the reduction
  std::vector<std::uint32_t> sums_;
  std::vector<std::uint32_t> counts_;
  std::vector<std::uint8_t> out_;
  std::unique_ptr<Arena> arena_;  // MJPEG: the decoder's memory
  std::uint64_t jpeg_warnings_ = 0;
  bool decode_jpeg(std::span<const std::uint8_t> bytes) noexcept;
  char error_[160] = {};
};

// Area average of a grey image (w x h, w >= ow, h >= oh) onto (ow x oh):
// each output pixel the mean of the input pixels whose centres fall in it
// (rounded). How many fall in each depends on the sizes alone: area_counts()
// once, then reduce_area() per image with `sums` as scratch (ow x oh each).
void area_counts(int w, int h, int ow, int oh, std::span<std::uint32_t> counts) noexcept;
void reduce_area(std::span<const std::uint8_t> in, int w, int h, std::span<std::uint8_t> out, int ow, int oh,
                 std::span<std::uint32_t> sums, std::span<const std::uint32_t> counts) noexcept;

}  // namespace trailnav::drivers::camera
