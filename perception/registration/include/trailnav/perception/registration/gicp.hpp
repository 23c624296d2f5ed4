// Generalized ICP (thesis §2.5, Eq. 2.7–2.11; Segal et al.): the rigid
// transform T that maximises the likelihood of the differences
// d_i = s_i − T(a_i) of associated points, each Gaussian with covariance
// Σ_i^S + R Σ_i^A Rᵀ (Eq. 2.8), i.e. minimises Σ_i d_iᵀ (Σ_i^S + R Σ_i^A
// Rᵀ)⁻¹ d_i (Eq. 2.10), alternating with the association of each source
// point to its nearest target point under the current T (Eq. 2.11).
//
// The metric is a choice of covariances (thesis §4.1.1): plane-to-plane
// (both sets' plane covariances), point-to-plane (the target's normal only:
// the weight n nᵀ, as the thesis' implementation), point-to-point (I).
//
// Our choices where the thesis leaves them open (docs/registration.md):
// - Gauss–Newton on SE(3) with a left perturbation T ← exp(δ)·T, δ = (ω, v):
//   ∂(R a + t)/∂(ω, v) = [−[Ra+t]×, I]. The weights are held fixed within an
//   iteration (R of the previous one), as GICP does.
// - Convergence: the update's rotation below `rotation_epsilon` (rad) and its
//   translation below `translation_epsilon` (m), or `max_iterations`.
// - Outliers: an association farther than `max_correspondence_distance` is
//   dropped; a robust Huber weight on the Mahalanobis distance beyond
//   `huber_delta` (0: none).
// - The result's covariance: the inverse of the final Gauss–Newton normal
//   matrix H = Σ Jᵀ M J (M the inverse covariance in m⁻²), in (ω, v) order.
//
// Preallocated: the association buffer holds `capacity` source points; a
// registration never touches the heap.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "trailnav/perception/registration/cloud.hpp"

namespace trailnav::perception::registration {

enum class Metric : std::uint8_t { plane_to_plane, point_to_plane, point_to_point };

struct GicpConfig {
  Metric metric = Metric::plane_to_plane;
  int max_iterations = 40;
  float max_correspondence_distance = 1.0f;  // m
  double rotation_epsilon = 2e-5;             // rad
  double translation_epsilon = 5e-5;          // m
  double huber_delta = 0.0;                   // Mahalanobis units; 0: plain least squares
};
// "" if usable, else what is wrong.
const char* check_gicp_config(const GicpConfig& c) noexcept;

struct GicpResult {
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();  // source -> target
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();  // (ω, v)
  int iterations = 0;
  bool converged = false;
  std::size_t correspondences = 0;  // in the last iteration
  double fitness = 0.0;             // mean squared Euclidean distance of the last associations, m²
  double error = 0.0;               // the objective (Eq. 2.10) at the last associations
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();  // the final normal matrix H, (ω, v)
};

// A planar registration's covariance in (x, y, yaw), row-major 3 × 3, of a
// result T = (t, R) with normal matrix H (GicpResult::information), objective
// E at n associations. H is the information of the left perturbation
// δ = (ω, v), T ← exp(δ)·T; a planar problem's is singular out of the plane,
// so the in-plane block for s = (ω_z, v_x, v_y) is inverted on its own (the
// covariance given the plane). To first order the position moves by
// ω × t + v and the heading by ω_z:
//   [x, y, yaw] = J s,  J = [[−t_y, 1, 0], [t_x, 0, 1], [1, 0, 0]],
// and Σ = σ̂² J H_ss⁻¹ Jᵀ. H weighs each residual as if the sensor's error
// were 1 m (point-to-plane: M = n nᵀ), so it is scaled by the residuals' a
// posteriori variance σ̂² = E / (n − 3). A block that cannot be inverted, or
// n ≤ 3, gives −1 on the diagonal: unknown.
std::array<double, 9> planar_pose_covariance(const Eigen::Matrix<double, 6, 6>& information, const Eigen::Vector3d& t,
                                             double error, std::size_t n) noexcept;

// One target: its points, covariances (and normals for point-to-plane) and
// its tree, built once.
struct Target {
  Cloud cloud;
  std::vector<Point> normals;
  KdTree tree;
};

class MultiBodyGicp;

// The single-body case of MultiBodyGicp (multi_body.hpp): one solver loop.
class Gicp {
 public:
  Gicp(const GicpConfig& config, std::size_t capacity);
  ~Gicp();
  Gicp(const Gicp&) = delete;
  Gicp& operator=(const Gicp&) = delete;

  const GicpConfig& config() const noexcept { return config_; }
  // Registers `source` (its covariances computed unless the metric is point
  // to point or point to plane) onto `target` from `initial`. At most
  // `capacity` source points are used (the first ones).
  GicpResult align(const Cloud& source, const Target& target,
                   const Eigen::Isometry3d& initial = Eigen::Isometry3d::Identity()) noexcept;

 private:
  GicpConfig config_;
  std::unique_ptr<MultiBodyGicp> solver_;
};

// The target's covariances, normals and tree from its points (allocates:
// the tree; set-up, not a real-time path).
void prepare_target(Target& target, CovarianceEstimator& covariances);
// A source's covariances, with a tree built over it in `scratch` (allocates).
void prepare_source(Cloud& source, CovarianceEstimator& covariances, KdTree& scratch,
                    std::vector<Point>& normals_scratch);

}  // namespace trailnav::perception::registration
