// Synthetic Manhattan worlds for the memory experiment of thesis §3.3.1
// (Fig. 3.4: graphs of 20,000 to 500,000 poses; §3.3.2: 200,000 poses with
// about 3.2 edges a pose). No public pose graph is that large, so, as the
// thesis did, one is generated: a robot drives on the lines of a square
// grid of streets one step at a time, turning at random at crossings and at
// the world's edge; consecutive poses are joined by odometry, and a pose on
// a spot visited before is joined, each time with some probability, to
// earlier visits there (loop closures). Every measurement is the true
// relative pose with Gaussian noise and carries the information of that
// noise; the initial guess is dead reckoning on the noisy odometry (as in
// Olson's M3500). The same options and seed give the same graph, bit for
// bit, on any machine (own Gaussian sampler over a 64-bit Mersenne twister).
// Simulated truth: `truth` receives the noise-free poses.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "trailnav/navigation/slam/pose_graph.hpp"

namespace trailnav::slam {

struct ManhattanOptions {
  std::size_t nodes = 3500;
  std::uint64_t seed = 1;
  int side = 0;                  // streets per side of the square world (0: ⌈√(nodes) / 3⌉, about 9 visits a spot)
  double block = 1.0;            // m between crossings; one step per block
  double turn_probability = 0.3; // at a crossing
  double closure_probability = 0.8;  // per earlier visit of the same spot (the latest few only)
  int closures_per_pose = 3;     // at most
  double sigma_translation = 0.05;  // m, odometry and closures
  double sigma_rotation = 0.01;     // rad
};

struct ManhattanResult {
  bool ok = false;
  std::string error;
  std::size_t closures = 0;
};

// `out` (and `truth` when given) must be reserved for `nodes` vertices and
// enough edges (at most nodes × (1 + closures_per_pose)).
ManhattanResult generate_manhattan(const ManhattanOptions& options, PoseGraph2d& out, PoseGraph2d* truth = nullptr);

}  // namespace trailnav::slam
