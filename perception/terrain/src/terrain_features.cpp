#include "trailnav/perception/terrain_features.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace trailnav::perception {

std::string_view terrain_feature_name(TerrainFeature f) noexcept {
  switch (f) {
    case TerrainFeature::max_remission: return "max remission";
    case TerrainFeature::mean_remission: return "mean remission";
    case TerrainFeature::std_remission: return "std remission";
    case TerrainFeature::roughness: return "roughness";
    case TerrainFeature::slope: return "slope";
  }
  return "?";
}

FeatureVector compute_terrain_feature(const CellStats& s) noexcept {
  const float inv = 1.0f / static_cast<float>(s.n);
  const float mr = s.sr * inv;
  const float var_r = std::max(0.0f, s.srr * inv - mr * mr);
  const float mx = s.sx * inv, my = s.sy * inv, mz = s.sz * inv;
  Eigen::Matrix3f c;
  c(0, 0) = s.sxx * inv - mx * mx;
  c(0, 1) = c(1, 0) = s.sxy * inv - mx * my;
  c(0, 2) = c(2, 0) = s.sxz * inv - mx * mz;
  c(1, 1) = s.syy * inv - my * my;
  c(1, 2) = c(2, 1) = s.syz * inv - my * mz;
  c(2, 2) = s.szz * inv - mz * mz;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3f> eig;
  eig.computeDirect(c);
  // Eigenvalues come in increasing order: the first is the roughness, its
  // eigenvector the surface normal. Points along one line (a single lidar
  // ring crossing the cell) leave the normal undetermined in the plane
  // across the line; the surface then is taken to contain the line and the
  // horizontal across it, so the slope is the line's own rise.
  const Eigen::Vector3f lambda = eig.eigenvalues();
  const float roughness = std::max(0.0f, lambda(0));
  constexpr float kDeg = 57.29577951308232f;
  float slope_rad = 0.0f;
  if (lambda(1) < 0.05f * lambda(2)) {
    slope_rad = std::asin(std::min(1.0f, std::abs(eig.eigenvectors()(2, 2))));
  } else {
    slope_rad = std::acos(std::min(1.0f, std::abs(eig.eigenvectors()(2, 0))));
  }
  FeatureVector f;
  f[static_cast<int>(TerrainFeature::max_remission)] = s.max_r;
  f[static_cast<int>(TerrainFeature::mean_remission)] = s.r0 + mr;
  f[static_cast<int>(TerrainFeature::std_remission)] = std::sqrt(var_r);
  f[static_cast<int>(TerrainFeature::roughness)] = roughness;
  f[static_cast<int>(TerrainFeature::slope)] = slope_rad * kDeg;
  return f;
}

}  // namespace trailnav::perception
