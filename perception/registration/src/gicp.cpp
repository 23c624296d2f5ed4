#include "trailnav/perception/registration/gicp.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include "gicp_terms.hpp"
#include "trailnav/perception/registration/multi_body.hpp"

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

namespace detail {

bool usable(const GicpConfig& config, const Cloud& source, std::size_t n, const Target& target) noexcept {
  if (target.tree.size() == 0 || n == 0) return false;
  if (config.metric == Metric::plane_to_plane) {
    return source.covariances.size() >= n && target.cloud.covariances.size() >= target.cloud.size();
  }
  if (config.metric == Metric::point_to_plane) return target.normals.size() >= target.cloud.size();
  return true;
}

double accumulate(const GicpConfig& config, const Cloud& source, std::size_t i, const Target& target, std::size_t j,
                  const Eigen::Matrix3d& rot, const Eigen::Vector3d& tr, Eigen::Matrix<double, 6, 6>& h,
                  Eigen::Matrix<double, 6, 1>& b) noexcept {
  const Eigen::Vector3d x = rot * source.points[i].cast<double>() + tr;
  const Eigen::Vector3d d = target.cloud.points[j].cast<double>() - x;
  Eigen::Matrix3d m = Eigen::Matrix3d::Identity();  // point to point
  switch (config.metric) {
    case Metric::plane_to_plane: {
      // (Σ^S + R Σ^A Rᵀ)⁻¹ (Eq. 2.8).
      const Eigen::Matrix3d c =
          target.cloud.covariances[j].cast<double>() + rot * source.covariances[i].cast<double>() * rot.transpose();
      m = c.inverse();
      break;
    }
    case Metric::point_to_plane: {
      const Eigen::Vector3d nrm = target.normals[j].cast<double>();
      m = nrm * nrm.transpose();
      break;
    }
    case Metric::point_to_point: break;
  }
  const double q = d.dot(m * d);
  double w = 1.0;
  if (config.huber_delta > 0.0) {
    const double s = std::sqrt(q);
    if (s > config.huber_delta) w = config.huber_delta / s;
  }
  // d = s − x(δ): ∂d/∂δ = −∂x/∂δ = −[−[x]×, I] = J = [S, −I], S = [x]×.
  // With W = w M: JᵀWJ = [[−S W S, S W], [−W S, W]], JᵀWd = [−S W d, −W d]
  // (Sᵀ = −S), by 3 × 3 blocks.
  const Eigen::Matrix3d wm = w * m;
  const Eigen::Matrix3d sk = skew(x);
  const Eigen::Matrix3d ws = wm * sk;
  const Eigen::Matrix3d sw = sk * wm;
  h.topLeftCorner<3, 3>().noalias() -= sk * ws;
  h.topRightCorner<3, 3>() += sw;
  h.bottomLeftCorner<3, 3>() -= ws;
  h.bottomRightCorner<3, 3>() += wm;
  const Eigen::Vector3d wd = wm * d;
  b.head<3>().noalias() -= sk * wd;
  b.tail<3>() -= wd;
  return w * q;
}

bool step(const GicpConfig& config, const Eigen::Matrix<double, 6, 6>& h, const Eigen::Matrix<double, 6, 1>& b,
          Eigen::Isometry3d& transform, bool& converged) noexcept {
  // A tiny damping keeps a degenerate direction (a corridor, a plane) from
  // blowing up.
  Eigen::Matrix<double, 6, 6> hd = h;
  hd.diagonal().array() += 1e-9 * std::max(1.0, h.diagonal().maxCoeff());
  Eigen::Matrix<double, 6, 1> delta = -hd.ldlt().solve(b);
  if (!delta.allFinite()) return false;
  // A step longer than kMaxStepRotation or kMaxStepTranslation is shortened
  // (a trust region): along a direction the points hardly constrain — a
  // corridor's axis — Gauss–Newton's step can be metres long.
  const double scale = std::max({1.0, delta.head<3>().norm() / kMaxStepRotation, delta.tail<3>().norm() / kMaxStepTranslation});
  delta /= scale;
  const Eigen::Vector3d omega = delta.head<3>();
  const double angle = omega.norm();
  Eigen::Isometry3d s = Eigen::Isometry3d::Identity();
  if (angle > 0.0) s.linear() = Eigen::AngleAxisd(angle, omega / angle).toRotationMatrix();
  s.translation() = delta.tail<3>();
  transform = s * transform;
  transform.linear() = Eigen::Quaterniond(transform.linear()).normalized().toRotationMatrix();
  converged = angle < config.rotation_epsilon && delta.tail<3>().norm() < config.translation_epsilon;
  return true;
}

Eigen::Matrix<double, 6, 6> covariance_of(const Eigen::Matrix<double, 6, 6>& h) noexcept {
  const Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(h);
  return lu.isInvertible() ? Eigen::Matrix<double, 6, 6>(lu.inverse()) : Eigen::Matrix<double, 6, 6>::Identity();
}

}  // namespace detail

Gicp::Gicp(const GicpConfig& config, std::size_t capacity)
    : config_(config), solver_(std::make_unique<MultiBodyGicp>(config, capacity, 1)) {}
Gicp::~Gicp() = default;

GicpResult Gicp::align(const Cloud& source, const Target& target, const Eigen::Isometry3d& initial) noexcept {
  const Target* bodies[] = {&target};
  BodyResult out[1];
  GicpResult r;
  r.iterations = solver_->align(source, bodies, std::span<const Eigen::Isometry3d>(&initial, 1), out);
  r.transform = out[0].transform;
  r.covariance = out[0].covariance;
  r.converged = out[0].converged;
  r.correspondences = out[0].correspondences;
  r.fitness = out[0].fitness;
  r.error = out[0].error;
  r.information = out[0].information;
  return r;
}

std::array<double, 9> planar_pose_covariance(const Eigen::Matrix<double, 6, 6>& h, const Eigen::Vector3d& t, double error,
                                             std::size_t n) noexcept {
  constexpr int idx[3] = {2, 3, 4};  // ω_z, v_x, v_y
  Eigen::Matrix3d hs;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) hs(i, j) = h(idx[i], idx[j]);
  }
  std::array<double, 9> a{};
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(hs);
  if (!lu.isInvertible() || n <= 3) {
    a[0] = a[4] = a[8] = -1.0;
    return a;
  }
  Eigen::Matrix3d jac;
  jac << -t.y(), 1.0, 0.0, t.x(), 0.0, 1.0, 1.0, 0.0, 0.0;
  const double variance = error / static_cast<double>(n - 3);
  const Eigen::Matrix3d out = variance * (jac * lu.inverse() * jac.transpose());
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) a[static_cast<std::size_t>(3 * i + j)] = out(i, j);
  }
  return a;
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
