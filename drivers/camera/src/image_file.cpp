#include "trailnav/drivers/camera/image_file.hpp"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <filesystem>
#include <system_error>

#include <png.h>

namespace trailnav::drivers::camera {

ImageRead read_grey_image(const std::string& path, std::uint64_t max_pixels) {
  ImageRead out;
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (png_image_begin_read_from_file(&image, path.c_str()) == 0) {
    out.error = path + ": not a readable PNG (" + image.message + ")";
    png_image_free(&image);
    return out;
  }
  if (image.width == 0 || image.height == 0 ||
      static_cast<std::uint64_t>(image.width) * image.height > max_pixels) {
    out.error = path + ": " + std::to_string(image.width) + " x " + std::to_string(image.height) +
                " pixels, outside 1 to " + std::to_string(max_pixels) + " pixels";
    png_image_free(&image);
    return out;
  }
  image.format = PNG_FORMAT_GRAY;
  out.image.width = static_cast<int>(image.width);
  out.image.height = static_cast<int>(image.height);
  out.image.pixels.resize(PNG_IMAGE_SIZE(image));
  if (png_image_finish_read(&image, nullptr, out.image.pixels.data(), 0, nullptr) == 0) {
    out.error = path + ": corrupt or truncated PNG (" + image.message + ")";
    out.image = {};
    png_image_free(&image);
    return out;
  }
  png_image_free(&image);
  return out;
}

std::string write_grey_png(const std::string& path, std::span<const std::uint8_t> grey, int width, int height) {
  if (width < 1 || height < 1 || grey.size() < static_cast<std::size_t>(width) * static_cast<std::size_t>(height))
    return path + ": " + std::to_string(grey.size()) + " bytes are no " + std::to_string(width) + " x " +
           std::to_string(height) + " grey image";
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(width);
  image.height = static_cast<png_uint_32>(height);
  image.format = PNG_FORMAT_GRAY;
  if (png_image_write_to_file(&image, path.c_str(), 0, grey.data(), width, nullptr) == 0) {
    std::string e = path + ": cannot write the PNG (" + image.message + ")";
    png_image_free(&image);
    return e;
  }
  return "";
}

ImageList list_images(const std::string& directory) {
  namespace fs = std::filesystem;
  ImageList out;
  std::error_code ec;
  if (!fs::is_directory(directory, ec)) {
    out.error = directory + ": not a directory of images";
    return out;
  }
  for (fs::directory_iterator it(directory, ec), end; !ec && it != end; it.increment(ec)) {
    if (!it->is_regular_file(ec)) continue;
    std::string ext = it->path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (ext == ".png") out.paths.push_back(it->path().string());
  }
  if (ec) {
    out.error = directory + ": " + ec.message();
    out.paths.clear();
    return out;
  }
  std::sort(out.paths.begin(), out.paths.end());
  if (out.paths.empty()) out.error = directory + ": holds no .png files";
  return out;
}

}  // namespace trailnav::drivers::camera
