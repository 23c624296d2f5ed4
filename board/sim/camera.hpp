// A simulated camera (issue 41), good enough to exercise the place task end
// to end: grey frames rendered by casting one ray per pixel into the world
// the lidar sees (world.hpp), shaded by what it hits, in one of two
// "seasons" whose looks differ as much as Nordland's summer and winter do.
// Simulated, not photographic: no lens distortion, blur, rolling shutter or
// auto exposure; recordings say so in their description.
//
// Summer: a sky brighter at the horizon with clouds (value noise), the
// terrain classes' own brightness and textures (world-fixed noise at two
// scales, so a place looks the same each time it is seen), lit by a sun 40°
// high with shadows cast (a second ray per ground pixel towards the sun),
// leafy canopies, objects by their remission and their angle to the view,
// haze over 150 m. Winter: an overcast sky, snow on every class but streets
// (slush), snow on the grass medium, leafless canopies (the sky through bare
// branches), no shadows, diffuse light, fog over 50 m.
//
// Pinhole camera: x forward, y left, z up in its mount, pitched down by
// `pitch_deg`; the image's rows run top to bottom.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "motion.hpp"
#include "scenario.hpp"
#include "world.hpp"

namespace trailnav::sim {

enum class Season : std::uint8_t { summer, winter };
const char* season_name(Season s) noexcept;

struct CameraSpec {
  double rate = 10.0;      // Hz
  int width = 128;         // pixels rendered
  int height = 64;
  double hfov_deg = 100.0;
  double pitch_deg = 8.0;  // down from level
  Vec3 mount{0.3, 0.0, 1.2};  // m in the robot frame
  double max_range = 150.0;   // m; beyond: sky
  double noise = 0.01;        // sensor noise, a fraction of full scale
};

class CameraRenderer {
 public:
  CameraRenderer(const World& world, const CameraSpec& spec, Season season, std::uint64_t seed);
  // Frame `index` seen from pose `p` into `out` (width x height bytes).
  void render(const PoseSample& p, std::uint64_t index, std::span<std::uint8_t> out) const noexcept;
  std::uint64_t rays() const noexcept { return rays_; }

 private:
  double sky(const Vec3& dir) const noexcept;
  double shade(const Vec3& origin, const Vec3& dir, std::uint64_t key) const noexcept;
  const World& world_;
  CameraSpec spec_;
  Season season_;
  std::uint64_t seed_;
  Vec3 sun_;
  mutable std::uint64_t rays_ = 0;
};

}  // namespace trailnav::sim
