#include "trailnav/perception/registration/gicp.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/LU>

namespace trailnav::perception::registration {

const char* check_gicp_config(const GicpConfig& c) noexcept {
  if (c.max_iterations < 1 || c.max_iterations > 1000) return "max_iterations: 1 to 1000";
  if (!(c.max_correspondence_distance > 0.0f) || !std::isfinite(c.max_correspondence_distance)) {
    return "max_correspondence_distance: a positive number of metres";
  }
  if (!(c.rotation_epsilon > 0.0) || !(c.translation_epsilon > 0.0)) return "rotation_epsilon, translation_epsilon: positive";
  if (!(c.huber_delta >= 0.0) || !std::isfinite(c.huber_delta)) return "huber_delta: 0 (off) or positive";
  return "";
}

Gicp::Gicp(const GicpConfig& config, std::size_t capacity) : config_(config) { pairs_.reserve(capacity); }

namespace {
Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}
}  // namespace

GicpResult Gicp::align(const Cloud& source, const Target& target, const Eigen::Isometry3d& initial) noexcept {
  GicpResult r;
  r.transform = initial;
  const bool plane = config_.metric == Metric::plane_to_plane;
  const bool to_plane = config_.metric == Metric::point_to_plane;
  const std::size_t n = std::min(source.size(), pairs_.capacity());
  if (target.tree.size() == 0 || n == 0) return r;
  if (plane && (source.covariances.size() < n || target.cloud.covariances.size() < target.cloud.size())) return r;
  if (to_plane && target.normals.size() < target.cloud.size()) return r;
  const float gate2 = config_.max_correspondence_distance * config_.max_correspondence_distance;

  Eigen::Matrix<double, 6, 6> h = Eigen::Matrix<double, 6, 6>::Identity();
  for (int it = 0; it < config_.max_iterations; ++it) {
    const Eigen::Matrix3d rot = r.transform.linear();
    const Eigen::Vector3d tr = r.transform.translation();
    // Eq. 2.11: each source point's nearest target point under T.
    pairs_.clear();
    double squared_sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d x = rot * source.points[i].cast<double>() + tr;
      std::uint32_t j = 0;
      float d2 = 0.0f;
      if (!target.tree.nearest(x.cast<float>(), j, d2) || d2 > gate2) continue;
      if (to_plane && target.normals[j].isZero()) continue;
      pairs_.push_back({static_cast<std::uint32_t>(i), j});
      squared_sum += static_cast<double>(d2);
    }
    r.correspondences = pairs_.size();
    if (pairs_.size() < 6) {
      r.converged = false;
      return r;
    }
    r.fitness = squared_sum / static_cast<double>(pairs_.size());
    // Eq. 2.10 linearised: H δ = −b with J = [−[x]×, I] for d = s − T(a).
    h.setZero();
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    double error = 0.0;
    for (const Pair& p : pairs_) {
      const Eigen::Vector3d a = source.points[p.source].cast<double>();
      const Eigen::Vector3d x = rot * a + tr;
      const Eigen::Vector3d d = target.cloud.points[p.target].cast<double>() - x;
      Eigen::Matrix3d m;
      if (plane) {
        // (Σ^S + R Σ^A Rᵀ)⁻¹ (Eq. 2.8).
        const Eigen::Matrix3d c =
            target.cloud.covariances[p.target].cast<double>() + rot * source.covariances[p.source].cast<double>() * rot.transpose();
        m = c.inverse();
      } else if (to_plane) {
        const Eigen::Vector3d nrm = target.normals[p.target].cast<double>();
        m = nrm * nrm.transpose();
      } else {
        m = Eigen::Matrix3d::Identity();
      }
      const double q = d.dot(m * d);
      double w = 1.0;
      if (config_.huber_delta > 0.0) {
        const double s = std::sqrt(q);
        if (s > config_.huber_delta) w = config_.huber_delta / s;
      }
      error += w * q;
      // d = s − x(δ): ∂d/∂δ = −∂x/∂δ = −[−[x]×, I] = [[x]×, −I].
      Eigen::Matrix<double, 3, 6> j;
      j.leftCols<3>() = skew(x);
      j.rightCols<3>() = -Eigen::Matrix3d::Identity();
      const Eigen::Matrix<double, 6, 3> jtm = j.transpose() * (w * m);
      h.noalias() += jtm * j;
      b.noalias() += jtm * d;
    }
    r.error = error;
    // Gauss–Newton step; a tiny damping keeps a degenerate direction (a
    // corridor, a plane) from blowing up.
    Eigen::Matrix<double, 6, 6> hd = h;
    hd.diagonal().array() += 1e-9 * std::max(1.0, h.diagonal().maxCoeff());
    const Eigen::Matrix<double, 6, 1> delta = -hd.ldlt().solve(b);
    if (!delta.allFinite()) return r;
    const Eigen::Vector3d omega = delta.head<3>();
    const double angle = omega.norm();
    Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
    if (angle > 0.0) step.linear() = Eigen::AngleAxisd(angle, omega / angle).toRotationMatrix();
    step.translation() = delta.tail<3>();
    r.transform = step * r.transform;
    r.transform.linear() = Eigen::Quaterniond(r.transform.linear()).normalized().toRotationMatrix();
    r.iterations = it + 1;
    if (angle < config_.rotation_epsilon && delta.tail<3>().norm() < config_.translation_epsilon) {
      r.converged = true;
      break;
    }
  }
  const Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(h);
  if (lu.isInvertible()) r.covariance = lu.inverse();
  return r;
}

void prepare_target(Target& target, CovarianceEstimator& covariances) {
  target.tree.build(target.cloud.points);
  covariances.compute(target.cloud, target.tree, target.normals);
}

void prepare_source(Cloud& source, CovarianceEstimator& covariances, KdTree& scratch, std::vector<Point>& normals_scratch) {
  scratch.build(source.points);
  covariances.compute(source, scratch, normals_scratch);
}

}  // namespace trailnav::perception::registration
