// The parts of a GICP Gauss–Newton iteration that the single-body and the
// multi-body solvers share (gicp.hpp, multi_body.hpp): one association's
// term of the normal equations and the update of a transform.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "trailnav/perception/registration/gicp.hpp"

namespace trailnav::perception::registration::detail {

// [v]×: the cross product with v as a matrix.
inline Eigen::Matrix3d skew(const Eigen::Vector3d& v) noexcept {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

// The longest step of one iteration (see step()).
inline constexpr double kMaxStepRotation = 0.2;     // rad
inline constexpr double kMaxStepTranslation = 0.5;  // m

// Adds source point i's association with target point j to H and b (Eq. 2.10
// linearised for d = s − T(a), J = [[x]×, −I]); returns its weighted
// Mahalanobis term.
double accumulate(const GicpConfig& config, const Cloud& source, std::size_t i, const Target& target, std::size_t j,
                  const Eigen::Matrix3d& rot, const Eigen::Vector3d& tr, Eigen::Matrix<double, 6, 6>& h,
                  Eigen::Matrix<double, 6, 1>& b) noexcept;

// Solves H δ = −b (slightly damped) and applies T ← exp(δ)·T. Returns false
// when the step is not finite; `converged` when it is below the thresholds.
bool step(const GicpConfig& config, const Eigen::Matrix<double, 6, 6>& h, const Eigen::Matrix<double, 6, 1>& b,
          Eigen::Isometry3d& transform, bool& converged) noexcept;

// H⁻¹ when H is invertible, else the identity.
Eigen::Matrix<double, 6, 6> covariance_of(const Eigen::Matrix<double, 6, 6>& h) noexcept;

// Whether the metric's inputs are there for these clouds.
bool usable(const GicpConfig& config, const Cloud& source, std::size_t n, const Target& target) noexcept;

}  // namespace trailnav::perception::registration::detail
