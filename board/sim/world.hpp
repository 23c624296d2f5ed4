// The simulated world: a ground height field with terrain classes and
// remission, a see-through medium (grass blades, bushes) on top of it, and
// solid or leafy primitives (boxes, walls, poles, trunks, canopies), with a
// ray caster fast enough for an HDL-64E in real time on one core.
//
// The height field is sampled every `resolution` metres; between samples it
// is bilinear. Blocks of 16 x 16 samples carry their highest point, so a ray
// skips whole blocks it passes above.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "roads.hpp"
#include "scenario.hpp"

namespace trailnav::sim {

enum class HitKind : std::uint8_t { ground, medium, object, canopy };

struct Hit {
  bool hit = false;
  double distance = 0.0;      // m along the ray
  double reflectivity = 0.0;  // 0..255, before the incidence angle
  double cos_incidence = 1.0;
  TerrainClass terrain = TerrainClass::other;
  HitKind kind = HitKind::ground;
  bool through_medium = false;  // the ray passed through grass or leaves before the hit
  bool side = false;            // a solid primitive's side (a vertical face), not its top
  double below_top = 0.0;       // a side's hit: m below the primitive's top
};

// Codes of the obstacle truth raster.
enum class ObstacleTruth : std::uint8_t { free = 0, obstacle = 1, negative = 2, vegetation = 3 };

// Where several codes meet in one cell, the higher rank wins: solid
// obstacles over negative ones over vegetation over free.
constexpr int truth_rank(std::uint8_t code) noexcept {
  constexpr int kRank[] = {0, 3, 2, 1};
  return code < 4 ? kRank[code] : 0;
}

class World {
 public:
  static std::unique_ptr<World> build(const Scenario& scenario, const RoadNetwork& roads, std::uint64_t seed);
  ~World();

  // Ground height (bilinear), terrain class and upward normal at a world point.
  double ground(double x, double y) const noexcept;
  TerrainClass terrain(double x, double y) const noexcept;
  Vec3 normal(double x, double y) const noexcept;

  // The first thing the ray origin + t * dir (dir a unit vector) meets for t
  // in [min_range, max_range]. `ray_key` seeds the draws for partial hits in
  // grass and leaves, so the same key gives the same answer.
  Hit cast(const Vec3& origin, const Vec3& dir, double min_range, double max_range, std::uint64_t ray_key) const noexcept;

  // Truth rasters, one byte per sample, row 0 at the south edge.
  int width() const noexcept { return nx_; }
  int height() const noexcept { return ny_; }
  double resolution() const noexcept { return res_; }
  double x0() const noexcept { return x0_; }
  double y0() const noexcept { return y0_; }
  const std::vector<std::uint8_t>& terrain_raster() const noexcept { return cls_; }
  const std::vector<std::uint8_t>& obstacle_raster() const noexcept { return truth_; }
  // The raster pixel nearest a world point; -1 outside.
  std::ptrdiff_t pixel(double x, double y) const noexcept {
    const auto i = static_cast<long>(std::lround((x - x0_) * inv_res_));
    const auto j = static_cast<long>(std::lround((y - y0_) * inv_res_));
    if (i < 0 || j < 0 || i >= nx_ || j >= ny_) return -1;
    return static_cast<std::ptrdiff_t>(j) * nx_ + i;
  }

 private:
  World() = default;
  struct Primitive;
  struct SampleRange {
    int i0, i1, j0, j1;  // inclusive
  };
  // The samples inside a world box, clipped to the grid.
  SampleRange samples_within(double xlo, double ylo, double xhi, double yhi) const noexcept;
  void build_primitives(const Scenario& s);
  void build_blocks();
  void build_truth();
  bool intersect(const Primitive& p, const Vec3& o, const Vec3& d, double t_lo, double t_hi, std::uint64_t ray_key,
                 Hit& hit) const noexcept;
  std::size_t index(int i, int j) const noexcept {
    return static_cast<std::size_t>(j) * static_cast<std::size_t>(nx_) + static_cast<std::size_t>(i);
  }

  int nx_ = 0;
  int ny_ = 0;
  double res_ = 0.1;
  double inv_res_ = 10.0;
  double x0_ = 0.0;
  double y0_ = 0.0;
  std::vector<float> h_;         // ground height
  std::vector<float> med_;       // medium height above ground (0: none)
  std::vector<float> dens_;      // medium density, hits per metre
  std::vector<std::uint8_t> refl_;
  std::vector<std::uint8_t> cls_;
  std::vector<float> ditch_;     // depth of a ditch dug here (truth)
  std::vector<std::uint8_t> truth_;
  std::array<Material, kTerrainClasses> materials_{};
  std::uint64_t seed_ = 0;

  static constexpr int kBlock = 16;
  int bx_ = 0;
  int by_ = 0;
  std::vector<float> block_max_;
  std::vector<std::uint32_t> block_first_;  // CSR: primitives overlapping each block
  std::vector<std::uint32_t> block_items_;
  std::vector<Primitive> primitives_;
  double z_top_ = 0.0;
};

}  // namespace trailnav::sim
