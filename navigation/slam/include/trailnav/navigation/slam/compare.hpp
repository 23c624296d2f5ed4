// Per-edge reprojection error between two solutions of one graph (thesis
// Table 3.2): for every edge (i, j) of `a`, the relative pose x_i⁻¹ x_j in
// `a` against the same in `b`, and the length of the translation of the
// difference, in metres (and the angle of its rotation). Gauge-free: one
// rigid motion of either solution changes nothing. The graphs must have the
// same vertex ids (their order may differ).
#pragma once

#include <cstddef>
#include <string>

#include "trailnav/navigation/slam/pose_graph.hpp"

namespace trailnav::slam {

struct EdgeErrorStats {
  bool ok = false;
  std::string error;
  std::size_t edges = 0;
  double mean = 0.0, std = 0.0, max = 0.0;        // m
  double rotation_mean = 0.0, rotation_max = 0.0;  // rad
};

template <class Pose>
EdgeErrorStats compare_graphs(const PoseGraph<Pose>& a, const PoseGraph<Pose>& b);

}  // namespace trailnav::slam
