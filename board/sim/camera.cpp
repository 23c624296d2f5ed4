#include "camera.hpp"

#include <algorithm>
#include <cmath>

#include "random.hpp"

namespace trailnav::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Brightness (0..1) and texture of each terrain class, per season: a mean,
// and the amplitudes of world-fixed value noise at a fine and a coarse
// scale (m). Winter: snow on everything but streets.
struct Look {
  double mean, fine, fine_scale, coarse, coarse_scale;
};
constexpr Look kSummer[kTerrainClasses] = {
    {0.30, 0.03, 0.4, 0.05, 6.0},   // street: asphalt, patched
    {0.47, 0.10, 0.5, 0.10, 3.0},   // dirt: ruts and puddles
    {0.33, 0.10, 0.25, 0.10, 4.0},  // grass: blades and patches
    {0.22, 0.14, 0.5, 0.08, 2.0},   // vegetation: shrubs
    {0.42, 0.08, 1.0, 0.08, 5.0},   // other: gravel, rock
};
constexpr Look kWinter[kTerrainClasses] = {
    {0.44, 0.08, 0.5, 0.06, 4.0},   // street: slush and tyre tracks
    {0.86, 0.02, 1.0, 0.04, 6.0},   // snow
    {0.88, 0.02, 1.0, 0.04, 6.0},
    {0.62, 0.18, 0.5, 0.06, 2.0},   // shrubs poking out
    {0.84, 0.03, 1.0, 0.05, 6.0},
};

double textured(const Look& l, std::uint64_t key, double x, double y) noexcept {
  return l.mean + l.fine * value_noise(key, x, y, l.fine_scale) + l.coarse * fractal_noise(mix64(key), x, y, l.coarse_scale);
}

}  // namespace

const char* season_name(Season s) noexcept { return s == Season::summer ? "summer" : "winter"; }

CameraRenderer::CameraRenderer(const World& world, const CameraSpec& spec, Season season, std::uint64_t seed)
    : world_(world), spec_(spec), season_(season), seed_(seed) {
  // The sun 40° high in the south-west (x east, y north).
  const double elevation = 40.0 * kPi / 180.0, azimuth = 225.0 * kPi / 180.0;
  sun_ = Vec3(std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
}

double CameraRenderer::sky(const Vec3& dir) const noexcept {
  const double up = std::max(0.0, dir.z());
  if (season_ == Season::winter) return 0.80 - 0.06 * up;  // overcast
  double v = 0.78 - 0.28 * up;
  if (dir.z() > 0.03) {
    // Clouds on a plane 500 m up, fixed to the world.
    const double x = dir.x() / dir.z() * 500.0, y = dir.y() / dir.z() * 500.0;
    v += 0.3 * std::max(0.0, fractal_noise(hash(seed_, 0xC10D), x, y, 400.0));
  }
  return v;
}

double CameraRenderer::shade(const Vec3& origin, const Vec3& dir, std::uint64_t key) const noexcept {
  const bool winter = season_ == Season::winter;
  const Hit h = world_.cast(origin, dir, 0.05, spec_.max_range, key);
  ++rays_;
  if (!h.hit) return sky(dir);
  // Leafless in winter: the sky through bare branches.
  if (winter && h.kind == HitKind::canopy) return 0.65 * sky(dir) + 0.35 * 0.25;
  const Vec3 at = origin + dir * h.distance;
  const auto cls = static_cast<std::size_t>(h.terrain);
  const std::uint64_t tex = hash(seed_, 0x7E8, cls);
  double albedo = 0.0, light = 1.0;
  const auto sunlit = [&](const Vec3& normal) {
    if (winter) return 0.72 + 0.2 * normal.z();
    const double facing = std::max(0.0, normal.dot(sun_));
    if (facing <= 0.0) return 0.35;
    // A shadow ray towards the sun, near pixels only (far shadows are a
    // pixel's fraction at this resolution).
    if (h.distance < 60.0) {
      ++rays_;
      const Hit s = world_.cast(at + normal * 0.05, sun_, 0.0, 40.0, hash(key, 0x5AD));
      if (s.hit) return 0.35;
    }
    return 0.35 + 0.75 * facing;
  };
  switch (h.kind) {
    case HitKind::ground: {
      albedo = textured((winter ? kWinter : kSummer)[cls], tex, at.x(), at.y());
      light = sunlit(world_.normal(at.x(), at.y()));
      break;
    }
    case HitKind::medium:  // grass blades, or snow on them
      albedo = winter ? 0.84 + 0.03 * value_noise(tex, at.x(), at.y(), 1.0) : 0.27 + 0.09 * value_noise(tex, at.x(), at.y(), 0.3);
      light = sunlit(Vec3::UnitZ());
      break;
    case HitKind::object:
      albedo = 0.12 + 0.5 * std::clamp(h.reflectivity, 0.0, 255.0) / 255.0;
      light = winter ? 0.5 + 0.3 * h.cos_incidence : 0.3 + 0.7 * h.cos_incidence;
      break;
    case HitKind::canopy:  // leaves (winter's returned above)
      albedo = 0.15 + 0.07 * value_noise(hash(seed_, 0x1EAF), at.x() + at.z(), at.y(), 0.4);
      light = 0.75;
      break;
  }
  const double haze = std::exp(-h.distance / (winter ? 50.0 : 150.0));
  const double horizon = winter ? 0.80 : 0.78;
  return albedo * light * haze + horizon * (1.0 - haze);
}

void CameraRenderer::render(const PoseSample& p, std::uint64_t index, std::span<std::uint8_t> out) const noexcept {
  const int w = spec_.width, h = spec_.height;
  const Eigen::Matrix3d body = rotation(p.roll, p.pitch, p.yaw);
  const Eigen::Matrix3d r = body * Eigen::AngleAxisd(spec_.pitch_deg * kPi / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Vec3 origin = p.p + body * spec_.mount;
  const double f = 0.5 * w / std::tan(0.5 * spec_.hfov_deg * kPi / 180.0);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const Vec3 d = (r * Vec3(f, -(u + 0.5 - 0.5 * w), -(v + 0.5 - 0.5 * h))).normalized();
      const std::uint64_t key = hash(seed_, index, static_cast<std::uint64_t>(v * w + u));
      const double value = shade(origin, d, key) + spec_.noise * gaussian(hash(key, 0x901));
      out[static_cast<std::size_t>(v * w + u)] = static_cast<std::uint8_t>(std::clamp(std::lround(255.0 * value), 0L, 255L));
    }
  }
}

}  // namespace trailnav::sim
