#include "trailnav/perception/place/hog.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace trailnav::perception::place {

int auto_patch(int width, int height) noexcept {
  int patch = 32;
  while (patch > 4 && (width / patch) * (height / patch) < 8) patch /= 2;
  return patch;
}

Hog::Hog(const HogConfig& config, int width, int height) : config_(config), width_(width), height_(height) {
  if (config_.patch == 0) config_.patch = auto_patch(width, height);
  if (config_.patch < 2 || config.cells < 1 || config.bins < 2 || config_.patch % config.cells != 0)
    throw std::invalid_argument("HOG: the patch (" + std::to_string(config_.patch) +
                                " pixels) must be a whole number of cells (" + std::to_string(config.cells) +
                                " a side) and have at least 2 orientation bins");
  if (!(config.clip > 0.0f)) throw std::invalid_argument("HOG: the L2-Hys clip must be positive");
  patches_x_ = width / config_.patch;
  patches_y_ = height / config_.patch;
  if (patches_x_ < 1 || patches_y_ < 1)
    throw std::invalid_argument("HOG: a " + std::to_string(width) + " x " + std::to_string(height) +
                                " image holds no whole patch of " + std::to_string(config_.patch) + " pixels");
  length_ = patches_x_ * patches_y_ * config.cells * config.cells * config.bins;
  const std::size_t pixels = static_cast<std::size_t>(patches_x_ * config_.patch) * static_cast<std::size_t>(patches_y_ * config_.patch);
  magnitude_.resize(pixels);
  bin_.resize(pixels);
}

void Hog::compute(std::span<const std::uint8_t> grey, int stride, std::span<float> out) noexcept {
  const int w = patches_x_ * config_.patch;
  const int h = patches_y_ * config_.patch;
  const int bins = config_.bins;
  const float to_bin = static_cast<float>(bins) / std::numbers::pi_v<float>;
  // Gradients by central differences over the whole image (a patch's border
  // pixels see their neighbours in the next patch; the image's border is
  // replicated).
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* row = grey.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(stride);
    const std::uint8_t* up = grey.data() + static_cast<std::size_t>(y > 0 ? y - 1 : 0) * static_cast<std::size_t>(stride);
    const std::uint8_t* down =
        grey.data() + static_cast<std::size_t>(y + 1 < height_ ? y + 1 : height_ - 1) * static_cast<std::size_t>(stride);
    for (int x = 0; x < w; ++x) {
      const int left = x > 0 ? x - 1 : 0;
      const int right = x + 1 < width_ ? x + 1 : width_ - 1;
      const float gx = static_cast<float>(row[right]) - static_cast<float>(row[left]);
      const float gy = static_cast<float>(down[x]) - static_cast<float>(up[x]);
      float angle = std::atan2(gy, gx);  // (-π, π]
      if (angle < 0.0f) angle += std::numbers::pi_v<float>;
      const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
      magnitude_[i] = std::sqrt(gx * gx + gy * gy);
      // Bin centres at (k + 0.5) x 180° / bins.
      bin_[i] = angle * to_bin - 0.5f;
    }
  }
  std::fill(out.begin(), out.end(), 0.0f);
  const int cell = config_.patch / config_.cells;
  const int per_patch = config_.cells * config_.cells * bins;
  double total = 0.0;
  for (int py = 0; py < patches_y_; ++py) {
    for (int px = 0; px < patches_x_; ++px) {
      float* hist = out.data() + static_cast<std::size_t>(py * patches_x_ + px) * static_cast<std::size_t>(per_patch);
      for (int y = 0; y < config_.patch; ++y) {
        const int iy = py * config_.patch + y;
        const int cy = y / cell;
        for (int x = 0; x < config_.patch; ++x) {
          const int ix = px * config_.patch + x;
          const std::size_t i = static_cast<std::size_t>(iy) * static_cast<std::size_t>(w) + static_cast<std::size_t>(ix);
          const float m = magnitude_[i];
          if (m == 0.0f) continue;
          const float t = bin_[i];
          const float lower = std::floor(t);
          const float frac = t - lower;
          int b0 = static_cast<int>(lower);
          if (b0 < 0) b0 += bins;
          int b1 = b0 + 1;
          if (b1 >= bins) b1 -= bins;
          if (b0 >= bins) b0 -= bins;
          float* c = hist + static_cast<std::size_t>((cy * config_.cells + x / cell) * bins);
          c[b0] += m * (1.0f - frac);
          c[b1] += m * frac;
        }
      }
      // L2-Hys per patch.
      double sum = 0.0;
      for (int k = 0; k < per_patch; ++k) sum += static_cast<double>(hist[k]) * static_cast<double>(hist[k]);
      if (sum == 0.0) continue;
      float inv = static_cast<float>(1.0 / std::sqrt(sum));
      sum = 0.0;
      for (int k = 0; k < per_patch; ++k) {
        hist[k] = std::min(hist[k] * inv, config_.clip);
        sum += static_cast<double>(hist[k]) * static_cast<double>(hist[k]);
      }
      inv = static_cast<float>(1.0 / std::sqrt(sum));
      for (int k = 0; k < per_patch; ++k) hist[k] *= inv;
      total += 1.0;  // each normalised patch has unit length
    }
  }
  // f / |f|: every patch with gradients has unit length, so |f|² is their count.
  if (total > 0.0) {
    const float inv = static_cast<float>(1.0 / std::sqrt(total));
    for (float& v : out) v *= inv;
  }
}

}  // namespace trailnav::perception::place
