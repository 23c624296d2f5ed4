#include "png.hpp"

#include <zlib.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <fstream>
#include <vector>

namespace trailnav::cli {
namespace {

void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  out.push_back(static_cast<std::uint8_t>(v >> 24));
  out.push_back(static_cast<std::uint8_t>(v >> 16));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
  out.push_back(static_cast<std::uint8_t>(v));
}

// A chunk is length, type, data and the CRC of type and data.
void put_chunk(std::vector<std::uint8_t>& out, const char type[4], const std::vector<std::uint8_t>& data) {
  put_u32(out, static_cast<std::uint32_t>(data.size()));
  const std::size_t type_at = out.size();
  out.insert(out.end(), type, type + 4);
  out.insert(out.end(), data.begin(), data.end());
  const uLong crc = crc32(0L, out.data() + type_at, static_cast<uInt>(4 + data.size()));
  put_u32(out, static_cast<std::uint32_t>(crc));
}

}  // namespace

Status write_png(const std::string& path, std::uint32_t width, std::uint32_t height, PngColor color,
                 std::span<const std::uint8_t> pixels) {
  const std::size_t channels = color == PngColor::rgb ? 3 : 1;
  const std::size_t row_bytes = width * channels;
  if (pixels.size() != row_bytes * height) return Status::error(path + ": pixel buffer does not match the image size");

  // Scanlines, each behind filter type 0 (none).
  std::vector<std::uint8_t> raw;
  raw.reserve((row_bytes + 1) * height);
  for (std::uint32_t y = 0; y < height; ++y) {
    raw.push_back(0);
    const auto row = pixels.subspan(y * row_bytes, row_bytes);
    raw.insert(raw.end(), row.begin(), row.end());
  }
  uLongf compressed_size = compressBound(static_cast<uLong>(raw.size()));
  std::vector<std::uint8_t> compressed(compressed_size);
  if (compress2(compressed.data(), &compressed_size, raw.data(), static_cast<uLong>(raw.size()), 6) != Z_OK) {
    return Status::error(path + ": zlib compression failed");
  }
  compressed.resize(compressed_size);

  std::vector<std::uint8_t> file = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<std::uint8_t> header;
  put_u32(header, width);
  put_u32(header, height);
  header.push_back(8);  // bits per channel
  header.push_back(static_cast<std::uint8_t>(color));
  header.push_back(0);  // deflate
  header.push_back(0);  // adaptive filtering
  header.push_back(0);  // no interlace
  put_chunk(file, "IHDR", header);
  put_chunk(file, "IDAT", compressed);
  put_chunk(file, "IEND", {});

  std::ofstream out(path, std::ios::binary);
  if (!out) return Status::error(path + ": cannot create file: " + std::strerror(errno));
  out.write(reinterpret_cast<const char*>(file.data()), static_cast<std::streamsize>(file.size()));
  if (!out) return Status::error(path + ": write failed");
  return Status::ok();
}

}  // namespace trailnav::cli

namespace trailnav::cli {
namespace {

std::uint32_t get_u32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | std::uint32_t{p[3]};
}

int paeth(int a, int b, int c) {
  const int p = a + b - c;
  const int pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  if (pa <= pb && pa <= pc) return a;
  return pb <= pc ? b : c;
}

}  // namespace

Status read_png_grey(const std::string& path, GreyImage& out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::error(path + ": cannot open: " + std::strerror(errno));
  const std::vector<std::uint8_t> file((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  static constexpr std::uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (file.size() < 8 || std::memcmp(file.data(), kSignature, 8) != 0) return Status::error(path + ": not a PNG file");
  std::vector<std::uint8_t> idat;
  bool header = false;
  std::size_t at = 8;
  while (at + 12 <= file.size()) {
    const std::uint32_t length = get_u32(file.data() + at);
    if (length > file.size() - at - 12) return Status::error(path + ": chunk at byte " + std::to_string(at) + " runs past the end");
    const std::string type(reinterpret_cast<const char*>(file.data() + at + 4), 4);
    const std::uint8_t* data = file.data() + at + 8;
    if (type == "IHDR") {
      if (length != 13) return Status::error(path + ": bad IHDR");
      out.width = get_u32(data);
      out.height = get_u32(data + 4);
      if (data[8] != 8 || data[9] != 0 || data[12] != 0) {
        return Status::error(path + ": only 8-bit greyscale, non-interlaced PNGs are read here (bit depth " +
                             std::to_string(data[8]) + ", colour type " + std::to_string(data[9]) + ")");
      }
      if (out.width == 0 || out.height == 0 || out.width > 100000 || out.height > 100000) {
        return Status::error(path + ": implausible size " + std::to_string(out.width) + " x " + std::to_string(out.height));
      }
      header = true;
    } else if (type == "IDAT") {
      idat.insert(idat.end(), data, data + length);
    } else if (type == "IEND") {
      break;
    }
    at += 12 + length;
  }
  if (!header) return Status::error(path + ": no IHDR chunk");
  const std::size_t w = out.width;
  std::vector<std::uint8_t> raw((w + 1) * out.height);
  uLongf raw_size = static_cast<uLongf>(raw.size());
  if (uncompress(raw.data(), &raw_size, idat.data(), static_cast<uLong>(idat.size())) != Z_OK || raw_size != raw.size()) {
    return Status::error(path + ": image data does not inflate to " + std::to_string(raw.size()) + " bytes");
  }
  out.pixels.assign(w * out.height, 0);
  for (std::size_t y = 0; y < out.height; ++y) {
    const std::uint8_t filter = raw[y * (w + 1)];
    const std::uint8_t* src = raw.data() + y * (w + 1) + 1;
    std::uint8_t* row = out.pixels.data() + y * w;
    const std::uint8_t* up = y > 0 ? row - w : nullptr;
    for (std::size_t x = 0; x < w; ++x) {
      const int a = x > 0 ? row[x - 1] : 0;
      const int b = up != nullptr ? up[x] : 0;
      const int c = x > 0 && up != nullptr ? up[x - 1] : 0;
      int v = src[x];
      switch (filter) {
        case 0: break;
        case 1: v += a; break;
        case 2: v += b; break;
        case 3: v += (a + b) / 2; break;
        case 4: v += paeth(a, b, c); break;
        default: return Status::error(path + ": row " + std::to_string(y) + " has unknown filter " + std::to_string(filter));
      }
      row[x] = static_cast<std::uint8_t>(v & 0xff);
    }
  }
  return Status::ok();
}

}  // namespace trailnav::cli
