// A pose graph (thesis §2.3.1): vertices are poses, edges relative
// measurements with their information matrices. Storage is reserved once
// for a capacity (vertices, edges) and never grows past it: adding beyond it
// is refused, so a graph's memory is known from the configuration.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory_resource>
#include <string>
#include <vector>

#include "trailnav/navigation/slam/poses.hpp"

namespace trailnav::slam {

template <class Pose>
struct GraphEdge {
  std::int32_t from = 0, to = 0;  // vertex indices (not file ids)
  Pose measurement;
  typename Pose::Matrix information = Pose::Matrix::Identity();
};

struct GraphCapacity {
  std::size_t vertices = 0;
  std::size_t edges = 0;
};

template <class Pose>
class PoseGraph {
 public:
  using Edge = GraphEdge<Pose>;
  static constexpr int kDim = Pose::kDim;

  PoseGraph() = default;
  explicit PoseGraph(GraphCapacity capacity) { reserve(capacity); }
  // Storage from `resource` (an arena, for SMF's levels).
  explicit PoseGraph(std::pmr::memory_resource* resource) : ids_(resource), poses_(resource), fixed_(resource), edges_(resource) {}
  void reserve(GraphCapacity capacity) {
    capacity_ = capacity;
    ids_.reserve(capacity.vertices);
    poses_.reserve(capacity.vertices);
    fixed_.reserve(capacity.vertices);
    edges_.reserve(capacity.edges);
  }
  GraphCapacity capacity() const noexcept { return capacity_; }

  // False when the capacity is reached.
  bool add_vertex(std::int64_t id, const Pose& pose, bool fixed = false) {
    if (poses_.size() >= capacity_.vertices) return false;
    ids_.push_back(id);
    poses_.push_back(pose);
    fixed_.push_back(fixed ? 1 : 0);
    return true;
  }
  bool add_edge(const Edge& e) {
    if (edges_.size() >= capacity_.edges) return false;
    edges_.push_back(e);
    return true;
  }
  void clear() noexcept {
    ids_.clear();
    poses_.clear();
    fixed_.clear();
    edges_.clear();
  }

  std::size_t vertex_count() const noexcept { return poses_.size(); }
  std::size_t edge_count() const noexcept { return edges_.size(); }
  std::int64_t id(std::size_t v) const noexcept { return ids_[v]; }
  const Pose& pose(std::size_t v) const noexcept { return poses_[v]; }
  Pose& pose(std::size_t v) noexcept { return poses_[v]; }
  bool fixed(std::size_t v) const noexcept { return fixed_[v] != 0; }
  void set_fixed(std::size_t v, bool f) noexcept { fixed_[v] = f ? 1 : 0; }
  bool any_fixed() const noexcept {
    for (std::uint8_t f : fixed_) {
      if (f != 0) return true;
    }
    return false;
  }
  const Edge& edge(std::size_t e) const noexcept { return edges_[e]; }
  Edge& edge(std::size_t e) noexcept { return edges_[e]; }
  const std::pmr::vector<Edge>& edges() const noexcept { return edges_; }
  const std::pmr::vector<Pose>& poses() const noexcept { return poses_; }
  std::pmr::vector<Pose>& poses() noexcept { return poses_; }

  // χ² = Σ e_ijᵀ Ω_ij e_ij over all edges (Eq. 2.3 without the ½, as g2o
  // reports it and as the thesis' Table 3.1 lists it).
  double chi2() const noexcept {
    double sum = 0.0;
    for (const Edge& e : edges_) {
      const typename Pose::Vector r = edge_error(e.measurement, poses_[static_cast<std::size_t>(e.from)],
                                                 poses_[static_cast<std::size_t>(e.to)]);
      sum += r.dot(e.information * r);
    }
    return sum;
  }

 private:
  GraphCapacity capacity_;
  std::pmr::vector<std::int64_t> ids_;
  std::pmr::vector<Pose> poses_;
  std::pmr::vector<std::uint8_t> fixed_;
  std::pmr::vector<Edge> edges_;
};

using PoseGraph2d = PoseGraph<Se2>;
using PoseGraph3d = PoseGraph<Se3>;

}  // namespace trailnav::slam
