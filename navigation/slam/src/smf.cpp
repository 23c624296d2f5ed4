#include "trailnav/navigation/slam/smf.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <algorithm>
#include <new>
#include <numeric>

#include "trailnav/navigation/slam/partition.hpp"

namespace trailnav::slam {
namespace {

// Ad(T) for increments δ = (ρ, φ) on the right: T·Exp(δ)·T⁻¹ = Exp(Ad(T) δ).
Se2::Matrix adjoint(const Se2& t) {
  const double c = std::cos(t.theta), s = std::sin(t.theta);
  Se2::Matrix a;
  a << c, -s, t.y, s, c, -t.x, 0.0, 0.0, 1.0;
  return a;
}

Se3::Matrix adjoint(const Se3& t) {
  const Eigen::Matrix3d r = t.q.toRotationMatrix();
  Se3::Matrix a = Se3::Matrix::Zero();
  a.topLeftCorner<3, 3>() = r;
  a.topRightCorner<3, 3>() = skew(t.t) * r;
  a.bottomRightCorner<3, 3>() = r;
  return a;
}

// An edge's covariance in its error's coordinates to the tangent of the
// right increment and back. SE(2): the same to first order. SE(3): the
// error's rotation part is the quaternion's vector part, half the angle.
Se2::Matrix to_tangent(const Se2::Matrix& s) { return s; }
Se2::Matrix from_tangent(const Se2::Matrix& s) { return s; }
Se3::Matrix to_tangent(const Se3::Matrix& s) {
  Se3::Vector d;
  d << 1, 1, 1, 2, 2, 2;
  return d.asDiagonal() * s * d.asDiagonal();
}
Se3::Matrix from_tangent(const Se3::Matrix& s) {
  Se3::Vector d;
  d << 1, 1, 1, 0.5, 0.5, 0.5;
  return d.asDiagonal() * s * d.asDiagonal();
}

template <class M>
M symmetric_inverse(const M& m) {
  M inv = m.ldlt().solve(M::Identity());
  return 0.5 * (inv + inv.transpose());
}

// Counting sort of items into buckets: order holds items bucket by bucket,
// start[b] .. start[b+1] bucket b's.
void bucket(const std::pmr::vector<std::int32_t>& key, int buckets, std::pmr::vector<std::int32_t>& order,
            std::pmr::vector<std::int32_t>& start) {
  start.assign(static_cast<std::size_t>(buckets) + 1, 0);
  for (std::int32_t k : key) {
    if (k >= 0) ++start[static_cast<std::size_t>(k) + 1];
  }
  for (std::size_t b = 0; b < static_cast<std::size_t>(buckets); ++b) start[b + 1] += start[b];
  order.assign(static_cast<std::size_t>(start.back()), 0);
  std::pmr::vector<std::int32_t> fill(start.begin(), start.end() - 1, order.get_allocator().resource());
  for (std::size_t i = 0; i < key.size(); ++i) {
    if (key[i] >= 0) order[static_cast<std::size_t>(fill[static_cast<std::size_t>(key[i])]++)] = static_cast<std::int32_t>(i);
  }
}

}  // namespace

std::size_t smf_hierarchy_bytes(GraphCapacity capacity, int pose_dim, int max_part) {
  // What one solve can hold at once, with the thesis' bound that the levels
  // above the bottom hold at most as many vertices as the bottom (Eq. 3.12)
  // and at most its edges plus one virtual edge per vertex:
  //   bottom level: parts, separator flags, orders (4 + 1 + 4 + 4 bytes a
  //     vertex, 4 + 4 an edge: its part and its order);
  //   levels above: the same, plus their graphs (id, pose, fixed flag; edges)
  //     and each vertex's index below;
  //   the coarsening's scratch for the largest level: the partitioner's
  //     adjacency (16 + 8 bytes an edge, 12 a vertex), the next level's index
  //     of each vertex, the virtual edges (at most one a vertex);
  //   one part's tree walk (edges, weights, order: 20 bytes an edge; per
  //     vertex a covariance and 16 bytes).
  // Then a quarter on top for the arena's block headers and fragmentation,
  // and 1 MiB.
  const double v = static_cast<double>(capacity.vertices), e = static_cast<double>(capacity.edges);
  const double pose = pose_dim == 3 ? sizeof(Se2) : sizeof(Se3);
  const double edge = pose_dim == 3 ? sizeof(GraphEdge<Se2>) : sizeof(GraphEdge<Se3>);
  const double d2 = 8.0 * pose_dim * pose_dim;
  const double bottom = v * 13.0 + e * 8.0;
  const double above = v * (13.0 + 4.0 + 8.0 + pose + 1.0) + (e + v) * (8.0 + edge);
  const double scratch = (e + v) * 24.0 + v * 12.0 + v * 4.0 + v * edge;
  const double part = 20.0 * 20.0 * max_part + max_part * (d2 + 16.0);
  return static_cast<std::size_t>(1.25 * (bottom + above + scratch + part) + 1048576.0);
}

std::size_t smf_part_arena_bytes(int pose_dim, int max_part) {
  const double n = static_cast<double>(pose_dim) * max_part;
  return static_cast<std::size_t>(8.0 * n * n + 16.0 * 1048576.0);
}

template <class Pose>
SmfSolver<Pose>::SmfSolver(GraphCapacity capacity, const SmfOptions& options, Arena& arena)
    : capacity_(capacity),
      options_(options),
      part_solver_({static_cast<std::size_t>(options.max_part),
                    options.max_part_edges != 0 ? options.max_part_edges : 20u * static_cast<std::size_t>(options.max_part)},
                   arena, Factorisation::simplicial),
      part_graph_({static_cast<std::size_t>(options.max_part),
                   options.max_part_edges != 0 ? options.max_part_edges : 20u * static_cast<std::size_t>(options.max_part)}),
      hierarchy_arena_(smf_hierarchy_bytes(capacity, Pose::kDim, options.max_part)),
      hierarchy_(hierarchy_arena_) {
  if (options_.max_part_edges == 0) options_.max_part_edges = 20u * static_cast<std::size_t>(options.max_part);
  local_.assign(capacity.vertices, -1);
  held_.assign(capacity.vertices, 0);
  part_held_.reserve(static_cast<std::size_t>(options.max_part));
  options_.max_levels = std::clamp(options_.max_levels, 1, kSmfMaxLevels - 1);
  levels_.reserve(static_cast<std::size_t>(options_.max_levels) + 1);
  moved_.reserve(capacity.vertices);
}

template <class Pose>
bool SmfSolver<Pose>::solve_part(Level& level, int p, SmfReport& report) {
  PoseGraph<Pose>& g = *level.graph;
  part_graph_.clear();
  part_held_.clear();
  const auto ps = static_cast<std::size_t>(p);
  for (std::int32_t i = level.start[ps]; i < level.start[ps + 1]; ++i) {
    const auto v = static_cast<std::size_t>(level.order[static_cast<std::size_t>(i)]);
    local_[v] = static_cast<std::int32_t>(part_graph_.vertex_count());
    part_graph_.add_vertex(static_cast<std::int64_t>(v), g.pose(v), g.fixed(v));
    part_held_.push_back(held_[v]);
  }
  for (std::int32_t i = level.edge_start[ps]; i < level.edge_start[ps + 1]; ++i) {
    GraphEdge<Pose> e = g.edge(static_cast<std::size_t>(level.edge_order[static_cast<std::size_t>(i)]));
    e.from = local_[static_cast<std::size_t>(e.from)];
    e.to = local_[static_cast<std::size_t>(e.to)];
    if (!part_graph_.add_edge(e)) {
      report.error = "a part has more than " + std::to_string(options_.max_part_edges) +
                     " edges (max_part_edges): raise it or lower max_part";
      return false;
    }
  }
  const LmReport r = part_solver_.solve(part_graph_, options_.lm, part_held_);
  if (!r.ok) {
    report.error = "a part's solve failed: " + r.error;
    return false;
  }
  ++report.part_solves;
  report.iterations += r.iterations;
  work_done_ += static_cast<double>(part_graph_.vertex_count());
  if (options_.progress) options_.progress(std::min(0.99, work_done_ / work_total_));
  for (std::size_t k = 0; k < part_graph_.vertex_count(); ++k) {
    const auto v = static_cast<std::size_t>(part_graph_.id(k));
    g.pose(v) = part_graph_.pose(k);
    local_[v] = -1;
  }
  return true;
}

// The maximum spanning tree of the part's solved subgraph on det(Ω), and
// from its root a depth-first walk: each separator gets one virtual edge
// from its nearest separator ancestor (Fig. 3.2), Eq. 3.10–3.11.
template <class Pose>
void SmfSolver<Pose>::virtual_edges(Level& level, int p, std::pmr::vector<GraphEdge<Pose>>& out) {
  std::pmr::memory_resource* r = &hierarchy_;
  using Matrix = typename Pose::Matrix;
  const PoseGraph<Pose>& g = *level.graph;
  const auto ps = static_cast<std::size_t>(p);
  const std::int32_t first = level.start[ps];
  const auto m = static_cast<std::size_t>(level.start[ps + 1] - first);
  for (std::size_t k = 0; k < m; ++k) local_[static_cast<std::size_t>(level.order[static_cast<std::size_t>(first) + k])] = static_cast<std::int32_t>(k);
  auto vertex = [&](std::size_t k) { return static_cast<std::size_t>(level.order[static_cast<std::size_t>(first) + k]); };
  // Kruskal on det(Ω), largest first (ties: the earlier edge).
  Ints edges(level.edge_order.begin() + level.edge_start[ps], level.edge_order.begin() + level.edge_start[ps + 1], r);
  std::pmr::vector<double> weight(edges.size(), r);
  for (std::size_t i = 0; i < edges.size(); ++i) weight[i] = g.edge(static_cast<std::size_t>(edges[i])).information.determinant();
  std::pmr::vector<std::size_t> by_weight(edges.size(), r);
  std::iota(by_weight.begin(), by_weight.end(), 0u);
  // The order of a stable sort (ties: the earlier edge), without its heap buffer.
  std::sort(by_weight.begin(), by_weight.end(),
            [&](std::size_t a, std::size_t b) { return weight[a] > weight[b] || (weight[a] == weight[b] && a < b); });
  Ints root_of(m, r);
  std::iota(root_of.begin(), root_of.end(), 0);
  auto find = [&](std::int32_t x) {
    while (root_of[static_cast<std::size_t>(x)] != x) {
      root_of[static_cast<std::size_t>(x)] = root_of[static_cast<std::size_t>(root_of[static_cast<std::size_t>(x)])];
      x = root_of[static_cast<std::size_t>(x)];
    }
    return x;
  };
  Ints tree_start(m + 1, 0, r), tree(r);  // adjacency: (neighbour, level edge) pairs
  Ints chosen(r);
  chosen.reserve(m);
  for (std::size_t i : by_weight) {
    const auto& e = g.edge(static_cast<std::size_t>(edges[i]));
    const std::int32_t a = find(local_[static_cast<std::size_t>(e.from)]), b = find(local_[static_cast<std::size_t>(e.to)]);
    if (a == b) continue;
    root_of[static_cast<std::size_t>(a)] = b;
    chosen.push_back(edges[i]);
  }
  for (std::int32_t ei : chosen) {
    const auto& e = g.edge(static_cast<std::size_t>(ei));
    ++tree_start[static_cast<std::size_t>(local_[static_cast<std::size_t>(e.from)]) + 1];
    ++tree_start[static_cast<std::size_t>(local_[static_cast<std::size_t>(e.to)]) + 1];
  }
  for (std::size_t k = 0; k < m; ++k) tree_start[k + 1] += tree_start[k];
  tree.assign(2 * static_cast<std::size_t>(tree_start[m]), 0);
  {
    Ints fill(tree_start.begin(), tree_start.end() - 1, r);
    for (std::int32_t ei : chosen) {
      const auto& e = g.edge(static_cast<std::size_t>(ei));
      const auto a = static_cast<std::size_t>(local_[static_cast<std::size_t>(e.from)]);
      const auto b = static_cast<std::size_t>(local_[static_cast<std::size_t>(e.to)]);
      tree[2 * static_cast<std::size_t>(fill[a])] = static_cast<std::int32_t>(b);
      tree[2 * static_cast<std::size_t>(fill[a]++) + 1] = ei;
      tree[2 * static_cast<std::size_t>(fill[b])] = static_cast<std::int32_t>(a);
      tree[2 * static_cast<std::size_t>(fill[b]++) + 1] = ei;
    }
  }
  // The root: a fixed vertex, else the first separator.
  std::size_t root = m;
  for (std::size_t k = 0; k < m && root == m; ++k) {
    if (g.fixed(vertex(k))) root = k;
  }
  for (std::size_t k = 0; k < m && root == m; ++k) {
    if (level.separator[vertex(k)] != 0) root = k;
  }
  Ints ancestor(m, -1, r);
  std::pmr::vector<Matrix> sigma(m, Matrix::Zero(), r);  // Σ_L from the ancestor separator
  std::pmr::vector<std::uint8_t> seen(m, 0, r);
  Ints stack(r);
  stack.reserve(m);
  stack.push_back(static_cast<std::int32_t>(root));
  seen[root] = 1;
  ancestor[root] = static_cast<std::int32_t>(root);
  while (!stack.empty()) {
    const auto u = static_cast<std::size_t>(stack.back());
    stack.pop_back();
    const bool u_sep = level.separator[vertex(u)] != 0;
    const std::size_t a = u_sep ? u : static_cast<std::size_t>(ancestor[u]);
    const Matrix base = u_sep ? Matrix::Zero() : sigma[u];
    const Pose& xa = g.pose(vertex(a));
    const Pose& xu = g.pose(vertex(u));
    for (std::int32_t k = tree_start[u]; k < tree_start[u + 1]; ++k) {
      const auto w = static_cast<std::size_t>(tree[2 * static_cast<std::size_t>(k)]);
      if (seen[w] != 0) continue;
      seen[w] = 1;
      const auto& e = g.edge(static_cast<std::size_t>(tree[2 * static_cast<std::size_t>(k) + 1]));
      const Pose& xw = g.pose(vertex(w));
      const Matrix covariance = symmetric_inverse(e.information);
      Matrix step = to_tangent(covariance);  // on the right of from⁻¹·to
      if (static_cast<std::size_t>(local_[static_cast<std::size_t>(e.from)]) != u) {
        const Matrix ad = adjoint(xw.inverse() * xu);  // travelled against the edge: (T·Exp(δ))⁻¹ = T⁻¹·Exp(−Ad(T)δ)
        step = ad * step * ad.transpose();
      }
      const Matrix ap = adjoint(xa.inverse() * xw);
      sigma[w] = base + ap * step * ap.transpose();
      ancestor[w] = static_cast<std::int32_t>(a);
      if (level.separator[vertex(w)] != 0) {
        GraphEdge<Pose> v;
        v.from = static_cast<std::int32_t>(vertex(a));
        v.to = static_cast<std::int32_t>(vertex(w));
        v.measurement = xa.inverse() * xw;
        const Matrix back = adjoint(v.measurement.inverse());
        const Matrix moved = back * sigma[w] * back.transpose();
        v.information = symmetric_inverse(from_tangent(moved));
        out.push_back(v);
      }
      stack.push_back(static_cast<std::int32_t>(w));
    }
  }
  for (std::size_t k = 0; k < m; ++k) local_[vertex(k)] = -1;
}

template <class Pose>
bool SmfSolver<Pose>::coarsen(Level& level, Level& above, SmfReport& report) {
  PoseGraph<Pose>& g = *level.graph;
  const std::size_t n = g.vertex_count();
  const PartitionResult pr = partition_graph(g, options_.max_part, level.part, &hierarchy_, &hierarchy_arena_);
  if (!pr.ok) {
    report.error = pr.error;
    return false;
  }
  level.parts = pr.parts;
  level.separator.assign(n, 0);
  Ints edge_part(g.edge_count(), -1, &hierarchy_);
  for (std::size_t k = 0; k < g.edge_count(); ++k) {
    const auto& e = g.edge(k);
    const auto a = static_cast<std::size_t>(e.from), b = static_cast<std::size_t>(e.to);
    if (level.part[a] != level.part[b]) {
      level.separator[a] = 1;
      level.separator[b] = 1;
    } else {
      edge_part[k] = level.part[a];
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    if (g.fixed(v)) level.separator[v] = 1;
  }
  bucket(level.part, level.parts, level.order, level.start);
  bucket(edge_part, level.parts, level.edge_order, level.edge_start);

  std::pmr::vector<GraphEdge<Pose>> virtuals(&hierarchy_);
  virtuals.reserve(n);
  for (int p = 0; p < level.parts; ++p) {
    // Coarsening: the part alone, its root held (Sec. 3.1.2: "we optimize
    // the subgraph without considering the separator edges").
    const auto ps = static_cast<std::size_t>(p);
    std::size_t root = n;
    for (std::int32_t i = level.start[ps]; i < level.start[ps + 1] && root == n; ++i) {
      if (g.fixed(static_cast<std::size_t>(level.order[static_cast<std::size_t>(i)]))) root = static_cast<std::size_t>(level.order[static_cast<std::size_t>(i)]);
    }
    bool any_separator = false;
    for (std::int32_t i = level.start[ps]; i < level.start[ps + 1]; ++i) {
      const auto v = static_cast<std::size_t>(level.order[static_cast<std::size_t>(i)]);
      if (level.separator[v] != 0) {
        any_separator = true;
        if (root == n) root = v;
      }
    }
    if (root == n) root = static_cast<std::size_t>(level.order[static_cast<std::size_t>(level.start[ps])]);
    held_[root] = 1;
    const bool ok = solve_part(level, p, report);
    held_[root] = 0;
    if (!ok) return false;
    if (any_separator) virtual_edges(level, p, virtuals);
  }
  // The level above: the separators, the cut edges and the virtual ones.
  std::size_t separators = 0;
  for (std::uint8_t s : level.separator) separators += s;
  above.owned.reserve({separators, g.edge_count() + separators});
  above.owned.clear();
  above.graph = &above.owned;
  above.below.clear();
  Ints up(n, -1, &hierarchy_);
  for (std::size_t v = 0; v < n; ++v) {
    if (level.separator[v] == 0) continue;
    up[v] = static_cast<std::int32_t>(above.owned.vertex_count());
    above.owned.add_vertex(g.id(v), g.pose(v), g.fixed(v));
    above.below.push_back(static_cast<std::int32_t>(v));
  }
  for (std::size_t k = 0; k < g.edge_count(); ++k) {
    if (edge_part[k] >= 0) continue;
    GraphEdge<Pose> e = g.edge(k);
    e.from = up[static_cast<std::size_t>(e.from)];
    e.to = up[static_cast<std::size_t>(e.to)];
    above.owned.add_edge(e);
  }
  for (GraphEdge<Pose> e : virtuals) {
    e.from = up[static_cast<std::size_t>(e.from)];
    e.to = up[static_cast<std::size_t>(e.to)];
    above.owned.add_edge(e);
  }
  return true;
}

template <class Pose>
SmfReport SmfSolver<Pose>::solve(PoseGraph<Pose>& graph) {
  SmfReport report;
  try {
    report = run(graph);
  } catch (const std::bad_alloc&) {
    report = SmfReport{};
    report.error = "the hierarchy needs more than its arena of " + std::to_string(hierarchy_arena_.capacity() >> 20) +
                   " MiB (sized for " + std::to_string(capacity_.vertices) + " vertices and " +
                   std::to_string(capacity_.edges) + " edges; its levels did not halve)";
  }
  levels_.clear();  // back into the arena
  return report;
}

template <class Pose>
SmfReport SmfSolver<Pose>::run(PoseGraph<Pose>& graph) {
  SmfReport report;
  report.initial_chi2 = graph.chi2();
  if (graph.vertex_count() > capacity_.vertices || graph.edge_count() > capacity_.edges) {
    report.error = "the graph (" + std::to_string(graph.vertex_count()) + " vertices, " + std::to_string(graph.edge_count()) +
                   " edges) exceeds the solver's capacity (" + std::to_string(capacity_.vertices) + ", " +
                   std::to_string(capacity_.edges) + ")";
    return report;
  }
  levels_.clear();
  levels_.emplace_back(&hierarchy_);
  levels_[0].graph = &graph;
  work_done_ = 0.0;
  work_total_ = 2.0 * 4.0 / 3.0 * static_cast<double>(std::max<std::size_t>(graph.vertex_count(), 1));
  // Leaves to root.
  while (levels_.back().graph->vertex_count() > static_cast<std::size_t>(options_.max_part)) {
    if (static_cast<int>(levels_.size()) > options_.max_levels) {
      report.error = "more than " + std::to_string(options_.max_levels) + " levels";
      return report;
    }
    levels_.emplace_back(&hierarchy_);
    Level& level = levels_[levels_.size() - 2];
    Level& above = levels_.back();
    if (!coarsen(level, above, report)) return report;
    report.level[static_cast<std::size_t>(report.levels++)] = {level.graph->vertex_count(), level.graph->edge_count(), level.parts};
    if (above.graph->vertex_count() >= level.graph->vertex_count()) {
      report.error = "level " + std::to_string(levels_.size() - 2) + " does not shrink: " +
                     std::to_string(above.graph->vertex_count()) + " of its " + std::to_string(level.graph->vertex_count()) +
                     " vertices are separators (parts of " + std::to_string(options_.max_part) + " are too small for this graph)";
      return report;
    }
  }
  // The top: one part.
  Level& top = levels_.back();
  const std::size_t tn = top.graph->vertex_count();
  top.parts = 1;
  top.part.assign(tn, 0);
  top.separator.assign(tn, 0);
  bucket(top.part, 1, top.order, top.start);
  Ints all(top.graph->edge_count(), 0, &hierarchy_);
  bucket(all, 1, top.edge_order, top.edge_start);
  if (!solve_part(top, 0, report)) return report;
  report.level[static_cast<std::size_t>(report.levels++)] = {tn, top.graph->edge_count(), 1};
  // Root to leaves: each level's separators take their poses from above,
  // then every part is solved with its separators held.
  for (std::size_t l = levels_.size() - 1; l-- > 0;) {
    Level& level = levels_[l];
    const Level& above = levels_[l + 1];
    // Warm start: each part's interior is first moved rigidly with its
    // first separator (from where the part's own solve left it to where the
    // level above put it), so its solve starts aligned with the separators.
    moved_.assign(level.graph->vertex_count(), Pose{});
    for (std::size_t k = 0; k < above.below.size(); ++k) {
      const auto v = static_cast<std::size_t>(above.below[k]);
      moved_[v] = above.graph->pose(k) * level.graph->pose(v).inverse();
      level.graph->pose(v) = above.graph->pose(k);
    }
    for (int p = 0; p < level.parts; ++p) {
      const auto ps = static_cast<std::size_t>(p);
      std::size_t anchor = level.separator.size();
      for (std::int32_t i = level.start[ps]; i < level.start[ps + 1] && anchor == level.separator.size(); ++i) {
        const auto v = static_cast<std::size_t>(level.order[static_cast<std::size_t>(i)]);
        if (level.separator[v] != 0) anchor = v;
      }
      if (anchor == level.separator.size()) continue;
      for (std::int32_t i = level.start[ps]; i < level.start[ps + 1]; ++i) {
        const auto v = static_cast<std::size_t>(level.order[static_cast<std::size_t>(i)]);
        if (level.separator[v] == 0) level.graph->pose(v) = moved_[anchor] * level.graph->pose(v);
      }
    }
    for (std::size_t v = 0; v < level.separator.size(); ++v) held_[v] = level.separator[v];
    bool ok = true;
    for (int p = 0; p < level.parts && ok; ++p) ok = solve_part(level, p, report);
    for (std::size_t v = 0; v < level.separator.size(); ++v) held_[v] = 0;
    if (!ok) return report;
  }
  report.levels = static_cast<int>(levels_.size());
  report.chi2 = graph.chi2();
  report.ok = true;
  return report;
}

template class SmfSolver<Se2>;
template class SmfSolver<Se3>;

}  // namespace trailnav::slam
