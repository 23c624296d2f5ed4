// Counter-based randomness for the simulator: every random quantity is a pure
// function of (seed, stream, index), so a run is reproducible bit for bit no
// matter in which order things are computed.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>

namespace trailnav::sim {

// The splitmix64 finaliser: a bijective 64-bit mix with good avalanche.
constexpr std::uint64_t mix64(std::uint64_t x) noexcept {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

constexpr std::uint64_t hash(std::uint64_t a, std::uint64_t b) noexcept { return mix64(a ^ mix64(b)); }
constexpr std::uint64_t hash(std::uint64_t a, std::uint64_t b, std::uint64_t c) noexcept {
  return mix64(a ^ mix64(b ^ mix64(c)));
}

// Uniform in [0, 1) from the top 53 bits.
constexpr double unit(std::uint64_t h) noexcept { return static_cast<double>(h >> 11) * 0x1.0p-53; }

// Standard normal by Box-Muller from two hashes of one key.
inline double gaussian(std::uint64_t h) noexcept {
  const double u1 = 1.0 - unit(h);  // (0, 1]
  const double u2 = unit(mix64(h + 0x632BE59BD9B4E019ull));
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

// A sequential generator for the places where draws come in order (sensor
// noise, bias random walks): key = (seed, stream), one draw per call.
class Rng {
 public:
  Rng(std::uint64_t seed, std::uint64_t stream) noexcept : key_(hash(seed, stream)) {}
  double uniform() noexcept { return unit(hash(key_, counter_++)); }
  double normal() noexcept { return gaussian(hash(key_, counter_++)); }

 private:
  std::uint64_t key_;
  std::uint64_t counter_ = 0;
};

// Smooth 2-D value noise in [-1, 1] with feature size `scale` metres: hashed
// lattice values blended with a quintic fade.
inline double value_noise(std::uint64_t key, double x, double y, double scale) noexcept {
  const double u = x / scale;
  const double v = y / scale;
  const double fu = std::floor(u);
  const double fv = std::floor(v);
  const auto iu = static_cast<std::int64_t>(fu);
  const auto iv = static_cast<std::int64_t>(fv);
  auto lattice = [&](std::int64_t i, std::int64_t j) {
    return 2.0 * unit(hash(key, static_cast<std::uint64_t>(i), static_cast<std::uint64_t>(j))) - 1.0;
  };
  auto fade = [](double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); };
  const double a = fade(u - fu);
  const double b = fade(v - fv);
  const double v00 = lattice(iu, iv);
  const double v10 = lattice(iu + 1, iv);
  const double v01 = lattice(iu, iv + 1);
  const double v11 = lattice(iu + 1, iv + 1);
  return (v00 * (1 - a) + v10 * a) * (1 - b) + (v01 * (1 - a) + v11 * a) * b;
}

// Two octaves of value noise, still in about [-1, 1].
inline double fractal_noise(std::uint64_t key, double x, double y, double scale) noexcept {
  return 0.7 * value_noise(key, x, y, scale) + 0.3 * value_noise(mix64(key), x, y, scale * 0.37);
}

}  // namespace trailnav::sim
