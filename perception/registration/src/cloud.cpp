#include "trailnav/perception/registration/cloud.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <nanoflann.hpp>

namespace trailnav::perception::registration {

// --- voxel filter ---

VoxelFilter::VoxelFilter(std::size_t capacity) : capacity_(capacity) { keyed_.reserve(capacity); }

namespace {
// 21 bits per axis, offset so that ±1 048 576 voxels fit: ±262 km at 0.25 m.
constexpr std::int64_t kAxisOffset = 1 << 20;
constexpr std::int64_t kAxisMask = (1 << 21) - 1;
std::uint64_t voxel_key(const Point& p, float inverse) noexcept {
  auto axis = [&](float v) {
    const auto i = static_cast<std::int64_t>(std::floor(v * inverse)) + kAxisOffset;
    return static_cast<std::uint64_t>(std::clamp<std::int64_t>(i, 0, kAxisMask));
  };
  return axis(p.x()) << 42 | axis(p.y()) << 21 | axis(p.z());
}
}  // namespace

void VoxelFilter::filter(std::span<const Point> in, float voxel, Cloud& out) noexcept {
  out.points.clear();
  out.covariances.clear();
  keyed_.clear();
  const float inverse = 1.0f / voxel;
  counters_.points_in += in.size();
  for (std::size_t i = 0; i < in.size(); ++i) {
    const Point& p = in[i];
    if (!p.allFinite()) {
      ++counters_.non_finite;
      continue;
    }
    if (keyed_.size() == capacity_) {
      counters_.over_capacity += in.size() - i;
      break;
    }
    keyed_.push_back({voxel_key(p, inverse), static_cast<std::uint32_t>(i)});
  }
  // In place (std::sort takes no buffer), by voxel and then by input index,
  // so that each centroid is summed in the input's order: the same bits
  // every time.
  std::sort(keyed_.begin(), keyed_.end(), [](const Keyed& a, const Keyed& b) {
    return a.key != b.key ? a.key < b.key : a.index < b.index;
  });
  std::size_t k = 0;
  while (k < keyed_.size()) {
    const std::uint64_t key = keyed_[k].key;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    std::size_t n = 0;
    for (; k < keyed_.size() && keyed_[k].key == key; ++k, ++n) sum += in[keyed_[k].index].cast<double>();
    if (out.points.size() == out.points.capacity()) {  // the caller's capacity: never reallocate
      ++counters_.voxels_dropped;
      continue;
    }
    out.points.push_back((sum / static_cast<double>(n)).cast<float>());
    ++counters_.voxels;
  }
}

// --- k-d tree ---

namespace {
struct PointsAdaptor {
  const std::vector<Point>* points = nullptr;
  std::size_t kdtree_get_point_count() const { return points->size(); }
  float kdtree_get_pt(std::size_t i, std::size_t d) const { return (*points)[i][static_cast<Eigen::Index>(d)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};
using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PointsAdaptor>, PointsAdaptor, 3,
                                                 std::uint32_t>;
}  // namespace

struct KdTree::Impl {
  PointsAdaptor adaptor;
  std::unique_ptr<Tree> tree;
};

KdTree::KdTree() : impl_(std::make_unique<Impl>()) {}
KdTree::~KdTree() = default;

void KdTree::build(const std::vector<Point>& points) {
  impl_->adaptor.points = &points;
  impl_->tree = std::make_unique<Tree>(3, impl_->adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
}

std::size_t KdTree::size() const noexcept { return impl_->tree ? impl_->adaptor.points->size() : 0; }

std::size_t KdTree::nearest(const Point& q, std::span<std::uint32_t> indices, std::span<float> squared) const noexcept {
  if (!impl_->tree || indices.empty() || size() == 0) return 0;
  const std::size_t k = std::min({indices.size(), squared.size(), size()});
  nanoflann::KNNResultSet<float, std::uint32_t, std::size_t> result(k);
  result.init(indices.data(), squared.data());
  impl_->tree->findNeighbors(result, q.data(), nanoflann::SearchParams());
  return result.size();
}

bool KdTree::nearest(const Point& q, std::uint32_t& index, float& squared) const noexcept {
  return nearest(q, std::span<std::uint32_t>(&index, 1), std::span<float>(&squared, 1)) == 1;
}

namespace {
// nanoflann's result-set interface for one neighbour under a bound: the
// search visits only cells that may hold a point closer than worstDist().
struct NearestWithin {
  float best;
  std::uint32_t index;
  bool found;
  bool full() const noexcept { return true; }
  bool addPoint(float d, std::uint32_t i) noexcept {
    if (d < best) {
      best = d;
      index = i;
      found = true;
    }
    return true;
  }
  float worstDist() const noexcept { return best; }
};
}  // namespace

namespace {
// The same for two neighbours: the second's distance (or the bound) is what
// the search prunes against.
struct NearestTwoWithin {
  float d[2];
  std::uint32_t i[2];
  int count;
  bool full() const noexcept { return true; }
  bool addPoint(float dist, std::uint32_t index) noexcept {
    if (dist >= d[1]) return true;
    if (dist < d[0]) {
      d[1] = d[0];
      i[1] = i[0];
      d[0] = dist;
      i[0] = index;
    } else {
      d[1] = dist;
      i[1] = index;
    }
    count = count < 2 ? count + 1 : 2;
    return true;
  }
  float worstDist() const noexcept { return d[1]; }
};
}  // namespace

int KdTree::nearest_two_within(const Point& q, float bound, std::uint32_t index[2], float squared[2]) const noexcept {
  if (!impl_->tree || size() == 0) return 0;
  NearestTwoWithin result{{bound, bound}, {0, 0}, 0};
  impl_->tree->findNeighbors(result, q.data(), nanoflann::SearchParams());
  for (int k = 0; k < result.count; ++k) {
    index[k] = result.i[k];
    squared[k] = result.d[k];
  }
  return result.count;
}

bool KdTree::nearest_within(const Point& q, float bound, bool known, std::uint32_t& index, float& squared) const noexcept {
  if (!impl_->tree || size() == 0) return false;
  NearestWithin result{bound, index, known};
  impl_->tree->findNeighbors(result, q.data(), nanoflann::SearchParams());
  if (!result.found) return false;
  index = result.index;
  squared = result.best;
  return true;
}

// --- covariances ---

CovarianceEstimator::CovarianceEstimator(int k, float epsilon, bool planar, float max_thickness)
    : k_(std::max(k, 3)),
      epsilon_(epsilon),
      planar_(planar),
      max_thickness_(max_thickness),
      indices_(static_cast<std::size_t>(k_)),
      squared_(static_cast<std::size_t>(k_)) {}

void CovarianceEstimator::compute(Cloud& cloud, const KdTree& tree, std::vector<Point>& normals) noexcept {
  const std::size_t n = cloud.points.size();
  cloud.covariances.resize(n);  // no allocation when the caller reserved the capacity
  normals.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t found = tree.nearest(cloud.points[i], indices_, squared_);
    if (found < 3) {
      cloud.covariances[i] = Eigen::Matrix3f::Identity();
      normals[i] = Point::Zero();
      continue;
    }
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (std::size_t j = 0; j < found; ++j) mean += cloud.points[indices_[j]].cast<double>();
    mean /= static_cast<double>(found);
    Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
    for (std::size_t j = 0; j < found; ++j) {
      const Eigen::Vector3d d = cloud.points[indices_[j]].cast<double>() - mean;
      c += d * d.transpose();
    }
    c /= static_cast<double>(found);
    if (planar_) {
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es2;
      es2.computeDirect(c.topLeftCorner<2, 2>());
      const Eigen::Matrix2d v2 = es2.eigenvectors();
      const Eigen::Vector2d line(static_cast<double>(epsilon_), 1.0);
      Eigen::Matrix3f cov = Eigen::Matrix3f::Zero();
      cov.topLeftCorner<2, 2>() = (v2 * line.asDiagonal() * v2.transpose()).cast<float>();
      cov(2, 2) = 1.0f;
      const Point normal(static_cast<float>(v2(0, 0)), static_cast<float>(v2(1, 0)), 0.0f);
      // Eigenvalues ascending: across the line, then along it.
      const bool thin = max_thickness_ <= 0.0f ||
                        es2.eigenvalues()(0) <= static_cast<double>(max_thickness_ * max_thickness_) * es2.eigenvalues()(1);
      const bool ok = cov.allFinite() && normal.allFinite() && thin;
      cloud.covariances[i] = ok ? cov : Eigen::Matrix3f::Identity();
      normals[i] = ok ? normal : Point::Zero();
      continue;
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
    es.computeDirect(c);  // closed form for 3 x 3; eigenvalues ascending
    const Eigen::Matrix3d v = es.eigenvectors();
    const Eigen::Vector3d plane(static_cast<double>(epsilon_), 1.0, 1.0);
    const Eigen::Matrix3f cov = (v * plane.asDiagonal() * v.transpose()).cast<float>();
    const Point normal = v.col(0).cast<float>();
    // Across the plane against its narrower direction within it.
    const bool thin = max_thickness_ <= 0.0f ||
                      es.eigenvalues()(0) <= static_cast<double>(max_thickness_ * max_thickness_) * es.eigenvalues()(1);
    const bool ok = cov.allFinite() && normal.allFinite() && thin;  // degenerate neighbourhoods: no plane
    cloud.covariances[i] = ok ? cov : Eigen::Matrix3f::Identity();
    normals[i] = ok ? normal : Point::Zero();
  }
}

}  // namespace trailnav::perception::registration
