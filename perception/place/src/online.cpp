#include "trailnav/perception/place/online.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace trailnav::perception::place {
namespace {

std::size_t checked_capacity(std::size_t capacity) {
  if (capacity == 0) throw std::invalid_argument("place: a database capacity of 0 images");
  return capacity;
}

// The filter is sized for the capacity; until the database is finished it
// is never stepped.
}  // namespace

OnlinePlace::OnlinePlace(const OnlineConfig& config)
    : config_(config),
      hog_(config.hog, config.width, config.height),
      capacity_(checked_capacity(config.capacity)),
      codes_(capacity_ * static_cast<std::size_t>(hog_.length())),
      norms_(capacity_),
      column_sum_(capacity_),
      descriptor_(static_cast<std::size_t>(hog_.length())),
      query_code_(static_cast<std::size_t>(hog_.length())),
      row_(capacity_),
      filter_(capacity_, config.transition) {}

bool OnlinePlace::add_database(std::span<const float> descriptor) noexcept {
  const auto len = static_cast<std::size_t>(hog_.length());
  if (count_ >= capacity_ || descriptor.size() != len) return false;
  norms_[count_] = encode_descriptor(descriptor, {codes_.data() + count_ * len, len});
  ++count_;
  return true;
}

bool OnlinePlace::add_database_code(std::span<const std::uint8_t> code, float norm) noexcept {
  const auto len = static_cast<std::size_t>(hog_.length());
  if (count_ >= capacity_ || code.size() != len) return false;
  std::copy(code.begin(), code.end(), codes_.begin() + static_cast<long>(count_ * len));
  norms_[count_] = norm;
  ++count_;
  return true;
}

void OnlinePlace::finish_database() noexcept {
  const auto len = static_cast<std::size_t>(hog_.length());
  // The priors: each image's mean similarity to the others (O(n_D²), once).
  std::fill(column_sum_.begin(), column_sum_.end(), 0.0);
  for (std::size_t j = 0; j < count_; ++j) {
    double sum = 0.0;
    for (std::size_t k = 0; k < count_; ++k) {
      if (k == j) continue;
      sum += static_cast<double>(cosine({codes_.data() + j * len, len}, norms_[j], {codes_.data() + k * len, len}, norms_[k]));
    }
    const double mean = count_ > 1 ? sum / static_cast<double>(count_ - 1) : 1.0;
    column_sum_[j] = mean * config_.prior_queries;
  }
  column_count_ = config_.prior_queries;
  filter_ = BayesFilter(std::max<std::size_t>(count_, 1), config_.transition);
}

std::span<const float> OnlinePlace::describe(std::span<const std::uint8_t> grey, int stride) noexcept {
  hog_.compute(grey, stride, descriptor_);
  return descriptor_;
}

PlaceEstimate OnlinePlace::step(std::span<const float> descriptor) noexcept {
  const auto len = static_cast<std::size_t>(hog_.length());
  if (count_ == 0 || descriptor.size() != len) return {};
  const float qn = encode_descriptor(descriptor, query_code_);
  column_count_ += 1.0;
  const double inv_count = 1.0 / column_count_;
  float lo = 0.0f, hi = 0.0f;
  for (std::size_t j = 0; j < count_; ++j) {
    const float s = cosine(query_code_, qn, {codes_.data() + j * len, len}, norms_[j]);
    column_sum_[j] += static_cast<double>(s);
    const double mean = column_sum_[j] * inv_count;
    const float v = mean > 0.0 ? static_cast<float>(static_cast<double>(s) / mean) : 0.0f;  // Eq. 5.3
    row_[j] = v;
    if (j == 0 || v < lo) lo = v;
    if (j == 0 || v > hi) hi = v;
  }
  const float range = hi - lo;
  for (std::size_t j = 0; j < count_; ++j) row_[j] = range > 0.0f ? (row_[j] - lo) / range : 1.0f;  // Eq. 5.4
  filter_.step({row_.data(), count_});
  const std::span<const double> bel = filter_.belief();
  std::size_t best = 0;
  for (std::size_t j = 1; j < count_; ++j)
    if (bel[j] > bel[best]) best = j;
  return {static_cast<int>(best), bel[best]};
}

}  // namespace trailnav::perception::place
