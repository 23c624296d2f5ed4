// The thesis' small-memory-footprint method (SMF, chapter 3): the graph is
// cut into parts of at most `max_part` vertices (§3.1.1), each part is solved
// on its own and replaced, for the level above, by a tree of virtual
// measurements between its separators (§3.1.2, Eq. 3.10–3.11), the levels
// above are built the same way until one fits in a part, that top level is
// solved, and then, level by level down, every part's interior is solved
// again with its separators held (§3.1.3). No solve ever sees more than one
// part: the linear algebra is bounded by max_part whatever the graph.
//
// What the thesis leaves open, decided here (docs/slam.md):
//   - Gauge of a part while coarsening: its root is held at its current
//     pose (a vertex the file fixes if the part has one, else its first
//     separator, else its first vertex). The virtual measurements are
//     relative poses, the same whichever vertex is held.
//   - Vertices the file fixes are separators at every level, so they reach
//     the top and keep their poses there and on the way down.
//   - The virtual measurement of a tree path from separator a to separator s
//     is x̂_a⁻¹ x̂_s (Eq. 3.10: the compound of the optimised relative poses
//     along the path telescopes to it); its covariance (Eq. 3.11) is the
//     edges' covariances propagated along the path to first order, each
//     moved into a's frame by the adjoint of the path so far and the sum
//     then into s's: Σ* = Ad(z*⁻¹) (Σ_k Ad(P_k) Σ'_k Ad(P_k)ᵀ) Ad(z*⁻¹)ᵀ with
//     P_k = x̂_a⁻¹ x̂_k and Σ'_k an edge's covariance on the right of the
//     direction travelled.
//   - Stopping rule for levels: a level of at most max_part vertices is
//     the top. A level that does not shrink (as many separators as
//     vertices) is an error naming the level, not an endless loop.
//   - Warm starts: each part's solve starts from the poses the level holds
//     (the file's guess at the bottom, the parts' solutions above; on the
//     way down, the interior keeps its coarsening solution and only the
//     separators move), so each solve after the first is short.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory_resource>
#include <string>
#include <vector>

#include "trailnav/navigation/slam/arena.hpp"
#include "trailnav/navigation/slam/lm_solver.hpp"
#include "trailnav/navigation/slam/pose_graph.hpp"

namespace trailnav::slam {

inline constexpr int kSmfMaxLevels = 64;

struct SmfOptions {
  int max_part = 500;             // vertices of a part (the thesis: 500)
  std::size_t max_part_edges = 0; // edges a part's solve holds (0: 20 × max_part)
  int max_levels = kSmfMaxLevels - 1;  // levels above the bottom (at most kSmfMaxLevels − 1)
  LmOptions lm;                   // every part's and the top's solve
  // After each part's solve: the share of the work done, estimated (the
  // vertices solved over twice those of all levels, taken as 4/3 of the
  // bottom's until the levels are known), below 1 until the end.
  std::function<void(double fraction)> progress;
};

struct SmfLevel {
  std::size_t vertices = 0, edges = 0;
  int parts = 0;  // 1 at the top
};

struct SmfReport {
  bool ok = false;
  std::string error;
  double initial_chi2 = 0.0;
  double chi2 = 0.0;          // of the whole graph at the end
  int levels = 0;             // including the bottom (1: the graph fit in one part)
  std::array<SmfLevel, kSmfMaxLevels> level{};  // bottom first, `levels` of them (fixed: a solve allocates nothing)
  int part_solves = 0;
  int iterations = 0;          // LM steps over all solves
};

// Bytes of the hierarchy's arena for a capacity (what SmfSolver reserves).
std::size_t smf_hierarchy_bytes(GraphCapacity capacity, int pose_dim, int max_part);
// Bytes of the arena for one part's factorisation (at worst dense: its lower
// triangle, twice for CHOLMOD's workspace) and 16 MiB for the rest of a
// part's solve: what the caller hands SmfSolver.
std::size_t smf_part_arena_bytes(int pose_dim, int max_part);

template <class Pose>
class SmfSolver {
 public:
  // `capacity`: the largest graph to be solved; `arena` holds the parts'
  // factorisations (sized for one part). The hierarchy (the levels above the
  // bottom, their parts and the coarsening's scratch) lives in an arena of
  // its own, sized here from the capacity (smf_hierarchy_bytes): after
  // construction a solve takes no memory from the heap but METIS' own
  // workspace while it partitions a level.
  SmfSolver(GraphCapacity capacity, const SmfOptions& options, Arena& arena);
  SmfReport solve(PoseGraph<Pose>& graph);
  const Arena& hierarchy_arena() const noexcept { return hierarchy_arena_; }
  Arena& hierarchy_arena() noexcept { return hierarchy_arena_; }

 private:
  using Ints = std::pmr::vector<std::int32_t>;
  struct Level {
    explicit Level(std::pmr::memory_resource* r)
        : owned(r), below(r), part(r), separator(r), order(r), start(r), edge_order(r), edge_start(r) {}
    PoseGraph<Pose>* graph = nullptr;
    PoseGraph<Pose> owned;                 // levels above the bottom
    Ints below;                            // per vertex: its index in the level below
    Ints part;                             // per vertex: its part
    std::pmr::vector<std::uint8_t> separator;
    Ints order, start;                     // vertices by part
    Ints edge_order, edge_start;           // internal edges by part
    int parts = 0;
  };
  SmfReport run(PoseGraph<Pose>& graph);
  bool coarsen(Level& level, Level& above, SmfReport& report);
  // Solves part p of `level` with the vertices marked in held_ constant;
  // copies the solution back.
  bool solve_part(Level& level, int p, SmfReport& report);
  void virtual_edges(Level& level, int p, std::pmr::vector<GraphEdge<Pose>>& out);

  GraphCapacity capacity_;
  SmfOptions options_;
  LmSolver<Pose> part_solver_;
  PoseGraph<Pose> part_graph_;
  std::vector<std::int32_t> local_;      // level index -> part-local index (−1 none)
  std::vector<std::uint8_t> held_;        // per level vertex, for solve_part
  std::vector<std::uint8_t> part_held_;   // per part-local vertex
  Arena hierarchy_arena_;
  ArenaResource hierarchy_;
  std::vector<Level> levels_;             // reserved for max_levels + 1
  std::vector<Pose> moved_;               // per level vertex: how the level above moved a separator
  double work_done_ = 0.0, work_total_ = 1.0;  // vertices solved, for progress
};

}  // namespace trailnav::slam
