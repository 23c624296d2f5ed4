#include "trailnav/drivers/camera/frame.hpp"

#include <linux/videodev2.h>
#include <turbojpeg.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <memory>
#include <stdexcept>

#include "trailnav/runtime/arena.hpp"
#include "trailnav/runtime/heap_redirect.hpp"

namespace trailnav::drivers::camera {

const char* pixel_format_name(PixelFormat f) noexcept {
  switch (f) {
    case PixelFormat::grey: return "grey";
    case PixelFormat::yuyv: return "yuyv";
    case PixelFormat::mjpeg: return "mjpeg";
  }
  return "?";
}

bool parse_pixel_format(std::string_view name, PixelFormat& out) noexcept {
  if (name == "grey") out = PixelFormat::grey;
  else if (name == "yuyv") out = PixelFormat::yuyv;
  else if (name == "mjpeg") out = PixelFormat::mjpeg;
  else return false;
  return true;
}

std::uint32_t fourcc_of(PixelFormat f) noexcept {
  switch (f) {
    case PixelFormat::grey: return V4L2_PIX_FMT_GREY;
    case PixelFormat::yuyv: return V4L2_PIX_FMT_YUYV;
    case PixelFormat::mjpeg: return V4L2_PIX_FMT_MJPEG;
  }
  return 0;
}

FrameConverter::FrameConverter(PixelFormat format, int width, int height, int out_width, int out_height)
    : format_(format), width_(width), height_(height), out_width_(out_width), out_height_(out_height) {
  if (width < 1 || height < 1 || out_width < 1 || out_height < 1 || out_width > width || out_height > height)
    throw std::invalid_argument("camera: frames of " + std::to_string(width) + " x " + std::to_string(height) +
                                " cannot be reduced to " + std::to_string(out_width) + " x " + std::to_string(out_height));
  const auto pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  full_.resize(pixels);
  const auto out = static_cast<std::size_t>(out_width) * static_cast<std::size_t>(out_height);
  sums_.resize(out);
  counts_.resize(out);
  area_counts(width, height, out_width, out_height, counts_);
  out_.resize(out);
  if (format == PixelFormat::mjpeg) {
    tjhandle probe = tjInitDecompress();
    if (probe == nullptr) throw std::runtime_error(std::string("camera: libturbojpeg: ") + tjGetErrorStr2(nullptr));
    tjDestroy(probe);
    // libjpeg-turbo decoding one frame to grey holds its structures (tens of
    // kilobytes), a row group of each component and, for a progressive
    // JPEG, the whole frame's coefficients (2 bytes a sample, the chroma at
    // most as many again): 4 bytes a pixel and 1 MB cover every subsampling.
    arena_ = std::make_unique<Arena>((std::size_t{1} << 20) + 4 * pixels);
  }
}

FrameConverter::~FrameConverter() = default;

std::size_t FrameConverter::jpeg_memory_peak() const noexcept { return arena_ ? arena_->high_water() : 0; }
std::size_t FrameConverter::jpeg_memory_size() const noexcept { return arena_ ? arena_->capacity() : 0; }

bool FrameConverter::decode_jpeg(std::span<const std::uint8_t> bytes) noexcept {
  // Everything libjpeg takes while the scope lives comes from the arena and
  // is given back by tjDestroy before the scope ends.
  heap_redirect::ArenaRedirect redirect(*arena_);
  const heap_redirect::Scope scope(redirect);
  tjhandle jpeg = tjInitDecompress();
  if (jpeg == nullptr) {
    std::snprintf(error_, sizeof error_, "libturbojpeg could not start a decoder in its %zu bytes", arena_->capacity());
    return false;
  }
  bool ok = true;
  int jw = 0, jh = 0, sub = 0, space = 0;
  auto* data = const_cast<unsigned char*>(bytes.data());  // libturbojpeg 2.1 takes a non-const pointer, reads only
  const auto size = static_cast<unsigned long>(bytes.size());
  if (bytes.size() < 4 || tjDecompressHeader3(jpeg, data, size, &jw, &jh, &sub, &space) != 0) {
    std::snprintf(error_, sizeof error_, "an MJPEG frame of %zu bytes has no readable JPEG header (%s)", bytes.size(),
                  tjGetErrorStr2(jpeg));
    ok = false;
  } else if (jw != width_ || jh != height_) {
    std::snprintf(error_, sizeof error_, "an MJPEG frame of %d x %d pixels where %d x %d were set", jw, jh, width_, height_);
    ok = false;
  } else if (tjDecompress2(jpeg, data, size, full_.data(), width_, width_, height_, TJPF_GRAY, TJFLAG_FASTDCT) != 0) {
    if (tjGetErrorCode(jpeg) == TJERR_FATAL) {
      std::snprintf(error_, sizeof error_, "an MJPEG frame of %zu bytes does not decode (%s)", bytes.size(),
                    tjGetErrorStr2(jpeg));
      ok = false;
    } else {
      ++jpeg_warnings_;
    }
  }
  tjDestroy(jpeg);
  return ok;
}

void area_counts(int w, int h, int ow, int oh, std::span<std::uint32_t> counts) noexcept {
  std::fill(counts.begin(), counts.end(), 0u);
  for (int y = 0; y < h; ++y) {
    const auto oy = static_cast<std::size_t>(std::min(oh - 1, y * oh / h));
    for (int x = 0; x < w; ++x)
      ++counts[oy * static_cast<std::size_t>(ow) + static_cast<std::size_t>(std::min(ow - 1, x * ow / w))];
  }
}

void reduce_area(std::span<const std::uint8_t> in, int w, int h, std::span<std::uint8_t> out, int ow, int oh,
                 std::span<std::uint32_t> sums, std::span<const std::uint32_t> counts) noexcept {
  std::fill(sums.begin(), sums.end(), 0u);
  for (int y = 0; y < h; ++y) {
    const auto oy = static_cast<std::size_t>(std::min(oh - 1, y * oh / h));
    const std::uint8_t* row = in.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
    for (int x = 0; x < w; ++x)
      sums[oy * static_cast<std::size_t>(ow) + static_cast<std::size_t>(std::min(ow - 1, x * ow / w))] += row[x];
  }
  for (std::size_t k = 0; k < out.size(); ++k)
    out[k] = static_cast<std::uint8_t>(counts[k] > 0 ? (sums[k] + counts[k] / 2) / counts[k] : 0u);
}

bool FrameConverter::convert(std::span<const std::uint8_t> bytes, int bytes_per_line) noexcept {
  error_[0] = '\0';
  const auto w = static_cast<std::size_t>(width_);
  const auto h = static_cast<std::size_t>(height_);
  switch (format_) {
    case PixelFormat::grey:
    case PixelFormat::yuyv: {
      const std::size_t per_pixel = format_ == PixelFormat::grey ? 1 : 2;
      const std::size_t line = bytes_per_line > 0 ? static_cast<std::size_t>(bytes_per_line) : w * per_pixel;
      if (line < w * per_pixel || bytes.size() < line * (h - 1) + w * per_pixel) {
        std::snprintf(error_, sizeof error_, "a %s frame of %zu bytes is short of %d x %d pixels (%zu bytes a line)",
                      pixel_format_name(format_), bytes.size(), width_, height_, line);
        return false;
      }
      for (std::size_t y = 0; y < h; ++y) {
        const std::uint8_t* src = bytes.data() + y * line;
        std::uint8_t* dst = full_.data() + y * w;
        if (per_pixel == 1) {
          std::memcpy(dst, src, w);
        } else {
          for (std::size_t x = 0; x < w; ++x) dst[x] = src[2 * x];  // Y0 U Y1 V: the Ys are the grey image
        }
      }
      break;
    }
    case PixelFormat::mjpeg:
      if (!decode_jpeg(bytes)) return false;
      break;
  }
  if (out_width_ == width_ && out_height_ == height_) {
    std::memcpy(out_.data(), full_.data(), out_.size());
  } else {
    reduce_area(full_, width_, height_, out_, out_width_, out_height_, sums_, counts_);
  }
  return true;
}

}  // namespace trailnav::drivers::camera
