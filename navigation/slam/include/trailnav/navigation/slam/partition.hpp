// Cuts a pose graph's vertices into connected parts of at most `max_part`
// (thesis §3.1.1: an edge cut; any partitioner that bounds the part size
// will do). trailnav uses METIS' multilevel k-way partitioning (Debian's
// libmetis) for k = ⌈n / (0.9 max_part)⌉ with contiguous parts asked for:
// its cuts are small (few separators, so the next level is small), it is
// deterministic for a fixed seed, and its memory is linear in the graph
// it cuts. The thesis chose Nibble because it is local and needs not hold
// the whole graph; trailnav holds each level anyway (§3.2's (2c+2)|V|), so
// the better cut wins. A part METIS returns larger than max_part (its
// balance tolerance is 3 %) or not connected is cut again: into its
// connected components, then along a breadth-first order into pieces of at
// most max_part.
#pragma once

#include "trailnav/navigation/slam/arena.hpp"

#include <cstdint>
#include <memory_resource>
#include <string>
#include <vector>

#include "trailnav/navigation/slam/pose_graph.hpp"

namespace trailnav::slam {


struct PartitionResult {
  bool ok = false;
  std::string error;
  int parts = 0;
};

// part[v] ∈ [0, parts) for every vertex. Self-loops and parallel edges are
// allowed in the graph. Scratch storage comes from `scratch`; METIS' own
// workspace (it calls malloc) from `workspace` when one is given and the
// build can redirect the heap (runtime/heap_redirect.hpp), else the heap.
template <class Pose>
PartitionResult partition_graph(const PoseGraph<Pose>& graph, int max_part, std::pmr::vector<std::int32_t>& part,
                                std::pmr::memory_resource* scratch = std::pmr::get_default_resource(),
                                Arena* workspace = nullptr);

}  // namespace trailnav::slam
