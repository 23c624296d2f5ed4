#include "trailnav/navigation/slam/partition.hpp"

#include <metis.h>

#include <algorithm>
#include <cmath>
#include <optional>

#include "trailnav/navigation/slam/arena.hpp"
#include "trailnav/runtime/heap_redirect.hpp"

namespace trailnav::slam {
namespace {

// METIS takes its workspace with malloc: inside partition_graph the calling
// thread's malloc is served from the caller's arena (runtime/heap_redirect).

struct Adjacency {
  explicit Adjacency(std::pmr::memory_resource* r) : start(r), neighbours(r) {}
  std::pmr::vector<idx_t> start, neighbours;
};

template <class Pose>
void adjacency(const PoseGraph<Pose>& g, Adjacency& a, std::pmr::memory_resource* scratch) {
  const std::size_t n = g.vertex_count();
  std::pmr::vector<std::uint64_t> pairs(scratch);
  pairs.reserve(2 * g.edge_count());
  for (const auto& e : g.edges()) {
    if (e.from == e.to) continue;
    pairs.push_back(static_cast<std::uint64_t>(e.from) << 32 | static_cast<std::uint32_t>(e.to));
    pairs.push_back(static_cast<std::uint64_t>(e.to) << 32 | static_cast<std::uint32_t>(e.from));
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  a.start.assign(n + 1, 0);
  a.neighbours.resize(pairs.size());
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    ++a.start[static_cast<std::size_t>(pairs[k] >> 32) + 1];
    a.neighbours[k] = static_cast<idx_t>(pairs[k] & 0xffffffffu);
  }
  for (std::size_t v = 0; v < n; ++v) a.start[v + 1] += a.start[v];
}

}  // namespace

template <class Pose>
PartitionResult partition_graph(const PoseGraph<Pose>& graph, int max_part, std::pmr::vector<std::int32_t>& part,
                                std::pmr::memory_resource* scratch, Arena* workspace) {
  PartitionResult r;
  const std::size_t n = graph.vertex_count();
  part.assign(n, 0);
  if (max_part < 2) {
    r.error = "a part must hold at least 2 vertices";
    return r;
  }
  Adjacency a(scratch);
  adjacency(graph, a, scratch);
  idx_t nparts = static_cast<idx_t>(std::ceil(static_cast<double>(n) / (0.9 * max_part)));
  if (nparts > 1) {
    idx_t nv = static_cast<idx_t>(n), ncon = 1, cut = 0;
    idx_t options[METIS_NOPTIONS];
    METIS_SetDefaultOptions(options);
    options[METIS_OPTION_SEED] = 1;
    options[METIS_OPTION_CONTIG] = 1;
    options[METIS_OPTION_NUMBERING] = 0;
    std::pmr::vector<idx_t> out(n, scratch);
    std::optional<heap_redirect::ArenaRedirect> redirect;
    std::optional<heap_redirect::Scope> scope;
    if (workspace != nullptr) {
      redirect.emplace(*workspace);
      scope.emplace(*redirect);
    }
    int status = METIS_PartGraphKway(&nv, &ncon, a.start.data(), a.neighbours.data(), nullptr, nullptr, nullptr, &nparts,
                                     nullptr, nullptr, options, &cut, out.data());
    if (status != METIS_OK) {
      // Contiguous parts need a connected graph: try again without.
      options[METIS_OPTION_CONTIG] = 0;
      status = METIS_PartGraphKway(&nv, &ncon, a.start.data(), a.neighbours.data(), nullptr, nullptr, nullptr, &nparts,
                                   nullptr, nullptr, options, &cut, out.data());
    }
    scope.reset();
    if (status != METIS_OK) {
      r.error = "METIS could not partition the graph (status " + std::to_string(status) + ")";
      return r;
    }
    for (std::size_t v = 0; v < n; ++v) part[v] = static_cast<std::int32_t>(out[v]);
  }
  // Each part's connected components in breadth-first order, cut into pieces
  // of at most max_part; a piece (a stretch of that order) may fall apart, so
  // a second pass takes the pieces' components: the final parts.
  std::pmr::vector<std::int32_t> final_part(scratch), queue(scratch);
  queue.reserve(n);
  std::int32_t next = 0;
  auto components = [&](int limit) {
    final_part.assign(n, -1);
    next = 0;
    for (std::size_t seed = 0; seed < n; ++seed) {
      if (final_part[seed] >= 0) continue;
      const std::int32_t p = part[seed];
      queue.clear();
      queue.push_back(static_cast<std::int32_t>(seed));
      final_part[seed] = next;
      std::size_t head = 0;
      int in_piece = 1;
      while (head < queue.size()) {
        const auto v = static_cast<std::size_t>(queue[head++]);
        for (idx_t k = a.start[v]; k < a.start[v + 1]; ++k) {
          const auto w = static_cast<std::size_t>(a.neighbours[static_cast<std::size_t>(k)]);
          if (final_part[w] >= 0 || part[w] != p) continue;
          if (in_piece == limit) {
            ++next;
            in_piece = 0;
          }
          final_part[w] = next;
          ++in_piece;
          queue.push_back(static_cast<std::int32_t>(w));
        }
      }
      ++next;
    }
    part.assign(final_part.begin(), final_part.end());
  };
  components(max_part);
  components(max_part + 1);  // the pieces are at most max_part: components only
  r.parts = next;
  r.ok = true;
  return r;
}

template PartitionResult partition_graph(const PoseGraph<Se2>&, int, std::pmr::vector<std::int32_t>&, std::pmr::memory_resource*, Arena*);
template PartitionResult partition_graph(const PoseGraph<Se3>&, int, std::pmr::vector<std::int32_t>&, std::pmr::memory_resource*, Arena*);

}  // namespace trailnav::slam
