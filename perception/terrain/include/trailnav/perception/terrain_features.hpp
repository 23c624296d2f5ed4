// The terrain feature of a grid cell: the five dimensions of thesis §7.2.1,
// from running sums of the points registered in the cell, so a cell never
// stores its points, and a sixth, the spread of remission over the cells
// around it (TerrainMapper computes it; kAreaRadius).
//
// Sums are kept relative to the first point of the cell (shifted data), which
// keeps float sums of squares accurate however many points arrive.
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

namespace trailnav::perception {

inline constexpr int kTerrainFeatures = 6;

enum class TerrainFeature : std::uint8_t {
  max_remission = 0,   // 0..255
  mean_remission = 1,  // 0..255
  std_remission = 2,   // 0..255
  roughness = 3,       // m^2: smallest eigenvalue of the points' covariance
  slope = 4,           // degrees: angle between that eigenvector (the surface normal) and gravity
  // 0..255: standard deviation of remission over the points of the
  // (2 kAreaRadius + 1)^2 cells around the cell registered since the last
  // step. A single cell's few points and 0.2 m of ground cannot tell whether
  // the ground's reflectivity varies finely (paving, gravel) or evenly (dirt);
  // a metre of ground can.
  area_std_remission = 5,
};
inline constexpr int kAreaRadius = 2;  // cells each way: 5 x 5 cells, 1 m at the default 0.2 m
std::string_view terrain_feature_name(TerrainFeature f) noexcept;

using FeatureVector = std::array<float, kTerrainFeatures>;

struct CellStats {
  std::uint32_t n = 0;
  float x0 = 0.0f, y0 = 0.0f, z0 = 0.0f, r0 = 0.0f;  // the first point (x, y from the cell centre)
  float max_r = 0.0f;
  float sr = 0.0f, srr = 0.0f;                        // remission sums, shifted by r0
  float sx = 0.0f, sy = 0.0f, sz = 0.0f;              // coordinate sums, shifted by the first point
  float sxx = 0.0f, sxy = 0.0f, sxz = 0.0f, syy = 0.0f, syz = 0.0f, szz = 0.0f;
  float min_dz = 0.0f, max_dz = 0.0f;                 // z's extremes from z0 (the traversability's max |Δz|)

  // x, y relative to the cell's centre; z in the odometry frame; r the remission.
  void add(float x, float y, float z, float r) noexcept {
    if (n == 0) {
      x0 = x;
      y0 = y;
      z0 = z;
      r0 = r;
      max_r = r;
    }
    ++n;
    const float dx = x - x0, dy = y - y0, dz = z - z0, dr = r - r0;
    max_r = r > max_r ? r : max_r;
    sr += dr;
    srr += dr * dr;
    sx += dx;
    sy += dy;
    sz += dz;
    sxx += dx * dx;
    sxy += dx * dy;
    sxz += dx * dz;
    syy += dy * dy;
    syz += dy * dz;
    szz += dz * dz;
    min_dz = dz < min_dz ? dz : min_dz;
    max_dz = dz > max_dz ? dz : max_dz;
  }
};

static_assert(sizeof(CellStats) == 76, "docs/terrain.md gives the cell's size");

// The feature of a cell with at least three points; its area_std_remission is
// the cell's own std_remission (the mapper replaces it with the area's).
FeatureVector compute_terrain_feature(const CellStats& s) noexcept;
// The same for four cells at once (four-wide vectors); the same results.
void compute_terrain_features(const std::array<const CellStats*, 4>& cells, std::array<FeatureVector, 4>& out) noexcept;

}  // namespace trailnav::perception
