// Point sets for registration (thesis §2.5, chapter 4): points with the
// covariance that models each one's uncertainty, a voxel filter and a k-d
// tree over them. Everything is sized by a capacity given at construction;
// filtering, covariances and searches never touch the heap afterwards. Only
// building a tree allocates (nanoflann's node pool): a target is indexed
// when it is set up, not in a real-time loop.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace trailnav::perception::registration {

using Point = Eigen::Vector3f;

// A point set with one covariance per point (filled by
// compute_covariances(); empty covariances mean "not computed").
struct Cloud {
  std::vector<Point> points;
  std::vector<Eigen::Matrix3f> covariances;
  std::size_t size() const noexcept { return points.size(); }
};

// Voxel downsampling: the centroid of the points in each cube of `voxel`
// metres, in the order of their voxels' keys (deterministic, whatever the
// input order). Non-finite points are dropped and counted.
class VoxelFilter {
 public:
  explicit VoxelFilter(std::size_t capacity);

  struct Counters {
    std::uint64_t points_in = 0;
    std::uint64_t non_finite = 0;
    std::uint64_t over_capacity = 0;  // input points beyond the capacity, dropped
    std::uint64_t voxels = 0;
    std::uint64_t voxels_dropped = 0;  // beyond the output's reserved capacity (it is never reallocated)
  };
  // Replaces `out.points` (cleared; its reserved capacity must hold the
  // voxels — at most the input's size — or the rest are dropped and counted)
  // and leaves `out.covariances` empty.
  void filter(std::span<const Point> in, float voxel, Cloud& out) noexcept;
  const Counters& counters() const noexcept { return counters_; }

 private:
  struct Keyed {
    std::uint64_t key;
    std::uint32_t index;
  };
  std::vector<Keyed> keyed_;
  std::size_t capacity_;
  Counters counters_;
};

// A k-d tree over a cloud's points (nanoflann, L2). The cloud must outlive
// the tree and not change while it is used.
class KdTree {
 public:
  KdTree();
  ~KdTree();
  KdTree(const KdTree&) = delete;
  KdTree& operator=(const KdTree&) = delete;

  void build(const std::vector<Point>& points);  // allocates (nanoflann's node pool)
  std::size_t size() const noexcept;
  // The k nearest points of `q` (k at most `indices.size()`), nearest first;
  // returns how many were found.
  std::size_t nearest(const Point& q, std::span<std::uint32_t> indices, std::span<float> squared) const noexcept;
  // The nearest point, or false for an empty tree.
  bool nearest(const Point& q, std::uint32_t& index, float& squared) const noexcept;
  // The nearest point closer than `bound` (a squared distance): when the
  // caller already knows a point at that distance (`index` holds it and
  // `known` is true) or does not care beyond it, the search prunes every
  // branch farther away. Returns whether a point was found (or known);
  // `index` and `squared` are then the nearest.
  bool nearest_within(const Point& q, float bound, bool known, std::uint32_t& index, float& squared) const noexcept;
  // The two nearest points closer than `bound` (squared), nearest first;
  // returns how many (0 to 2).
  int nearest_two_within(const Point& q, float bound, std::uint32_t index[2], float squared[2]) const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// GICP's covariances (Segal et al., the thesis' Σ of Eq. 2.8): from the k
// nearest neighbours of each point, the sample covariance's eigenvectors
// with the eigenvalues replaced by (ε, 1, 1) — a plane with its normal along
// the smallest — so that plane-to-plane distances follow. The normal of
// point i is that eigenvector (for point-to-plane). A point with fewer than
// three neighbours gets the identity (no plane) and a zero normal.
class CovarianceEstimator {
 public:
  // `planar`: points of a 2D scan (z = 0): the covariance of their x and y
  // only, a line with its normal in the plane, and variance 1 along z (the
  // 2D registration leaves z, roll and pitch at their initial values).
  // `max_thickness` (0: off): a neighbourhood whose spread across its
  // plane (line) is more than this share of its spread along it — a corner,
  // an edge, a post seen as a blob — has no usable plane: its point gets
  // the identity covariance and a zero normal, so point-to-plane
  // associations skip it (a corner's fitted normal points diagonally and
  // pulls the registration off by millimetres).
  explicit CovarianceEstimator(int k = 20, float epsilon = 1e-3f, bool planar = false, float max_thickness = 0.0f);
  // Fills cloud.covariances and `normals` (unit, same order), resized to the
  // points' count: no heap when the caller reserved that capacity.
  void compute(Cloud& cloud, const KdTree& tree, std::vector<Point>& normals) noexcept;
  int k() const noexcept { return k_; }

 private:
  int k_;
  float epsilon_;
  bool planar_;
  float max_thickness_;
  std::vector<std::uint32_t> indices_;
  std::vector<float> squared_;
};

}  // namespace trailnav::perception::registration
