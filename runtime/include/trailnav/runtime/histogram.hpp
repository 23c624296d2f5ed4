// Log-linear histogram of durations with a single writer and lock-free
// readers. Values below 64 ns are exact; above, each power of two is split
// into 32 buckets, so a reported quantile is within about 3 % of the truth.
// Recording is a handful of relaxed atomic operations and never allocates.
#pragma once

#include <array>
#include <atomic>
#include <bit>
#include <cstdint>
#include <limits>

#include "trailnav/runtime/clock.hpp"

namespace trailnav {

struct DurationSummary {
  std::uint64_t count = 0;
  Nanos min = 0;
  Nanos p50 = 0;
  Nanos p99 = 0;
  Nanos max = 0;
  double mean = 0.0;
};

class DurationHistogram {
 public:
  static constexpr int kSubBits = 5;
  static constexpr int kLinearLimitBits = 6;  // values < 64 get their own bucket
  static constexpr int kMaxBits = 44;         // ~4.9 hours; larger values saturate
  static constexpr std::size_t kBuckets =
      (1u << kLinearLimitBits) + static_cast<std::size_t>(kMaxBits - kLinearLimitBits) * (1u << kSubBits);

  // Writer thread only.
  void record(Nanos value) noexcept {
    const std::uint64_t v = value < 0 ? 0 : static_cast<std::uint64_t>(value);
    buckets_[bucket_of(v)].fetch_add(1, std::memory_order_relaxed);
    count_.fetch_add(1, std::memory_order_relaxed);
    sum_.fetch_add(v, std::memory_order_relaxed);
    if (v < min_.load(std::memory_order_relaxed)) min_.store(v, std::memory_order_relaxed);
    if (v > max_.load(std::memory_order_relaxed)) max_.store(v, std::memory_order_relaxed);
  }

  // Any thread. While the writer is active the figures may mix two
  // consecutive states, never garbage.
  DurationSummary summary() const noexcept {
    DurationSummary s;
    s.count = count_.load(std::memory_order_relaxed);
    if (s.count == 0) return s;
    s.min = static_cast<Nanos>(min_.load(std::memory_order_relaxed));
    s.max = static_cast<Nanos>(max_.load(std::memory_order_relaxed));
    s.mean = static_cast<double>(sum_.load(std::memory_order_relaxed)) / static_cast<double>(s.count);
    s.p50 = clamp(quantile(0.50), s.min, s.max);
    s.p99 = clamp(quantile(0.99), s.min, s.max);
    return s;
  }

  // Value below which `q` of the samples lie (bucket upper bound).
  Nanos quantile(double q) const noexcept {
    std::uint64_t total = 0;
    for (const auto& b : buckets_) total += b.load(std::memory_order_relaxed);
    if (total == 0) return 0;
    const auto rank = static_cast<std::uint64_t>(q * static_cast<double>(total - 1)) + 1;
    std::uint64_t seen = 0;
    for (std::size_t i = 0; i < kBuckets; ++i) {
      seen += buckets_[i].load(std::memory_order_relaxed);
      if (seen >= rank) return static_cast<Nanos>(upper_bound_of(i));
    }
    return static_cast<Nanos>(upper_bound_of(kBuckets - 1));
  }

  void reset() noexcept {
    for (auto& b : buckets_) b.store(0, std::memory_order_relaxed);
    count_.store(0, std::memory_order_relaxed);
    sum_.store(0, std::memory_order_relaxed);
    min_.store(std::numeric_limits<std::uint64_t>::max(), std::memory_order_relaxed);
    max_.store(0, std::memory_order_relaxed);
  }

  static constexpr std::size_t bucket_of(std::uint64_t v) noexcept {
    if (v < (1u << kLinearLimitBits)) return static_cast<std::size_t>(v);
    const int exponent = static_cast<int>(std::bit_width(v)) - 1;  // >= kLinearLimitBits
    if (exponent >= kMaxBits) return kBuckets - 1;
    const auto sub = static_cast<std::size_t>((v >> (exponent - kSubBits)) & ((1u << kSubBits) - 1));
    return (1u << kLinearLimitBits) + static_cast<std::size_t>(exponent - kLinearLimitBits) * (1u << kSubBits) + sub;
  }

  // Largest value that lands in bucket i.
  static constexpr std::uint64_t upper_bound_of(std::size_t i) noexcept {
    if (i < (1u << kLinearLimitBits)) return i;
    const std::size_t rest = i - (1u << kLinearLimitBits);
    const int exponent = static_cast<int>(rest >> kSubBits) + kLinearLimitBits;
    const std::uint64_t sub = rest & ((1u << kSubBits) - 1);
    const std::uint64_t base = std::uint64_t{1} << exponent;
    const std::uint64_t width = std::uint64_t{1} << (exponent - kSubBits);
    return base + (sub + 1) * width - 1;
  }

 private:
  static Nanos clamp(Nanos v, Nanos lo, Nanos hi) noexcept { return v < lo ? lo : (v > hi ? hi : v); }

  std::array<std::atomic<std::uint64_t>, kBuckets> buckets_{};
  std::atomic<std::uint64_t> count_{0};
  std::atomic<std::uint64_t> sum_{0};
  std::atomic<std::uint64_t> min_{std::numeric_limits<std::uint64_t>::max()};
  std::atomic<std::uint64_t> max_{0};
};

}  // namespace trailnav
