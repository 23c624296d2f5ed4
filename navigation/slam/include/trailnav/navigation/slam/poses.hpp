// Poses and relative measurements of a pose graph (thesis §2.3.1), in the
// plane (SE(2)) and in space (SE(3)), with the error of an edge and its
// Jacobians as the solvers need them. Pure, header-only, no allocation.
//
// An edge (i, j) with measurement z_ij and information Ω_ij has the error of
// Eq. 2.1, e_ij = z_ij ⊖ (x_i ⊖ x_j): the measured transform's inverse times
// the estimated one, x_i⁻¹ x_j, as a vector (g2o's convention, so that χ² =
// Σ e_ijᵀ Ω_ij e_ij of a file is the same number g2o reports for it):
//   SE(2): (Δx, Δy, Δθ) of z⁻¹ x_i⁻¹ x_j, the angle wrapped to (−π, π];
//   SE(3): (Δt, q_v) of z⁻¹ x_i⁻¹ x_j, q_v the vector part of its unit
//          quaternion taken with q_w ≥ 0.
//
// Increments (what the solver adds to a pose each step):
//   SE(2): global, x ⊞ δ = (x + δx, y + δy, θ + δθ), as g2o's VertexSE2;
//   SE(3): on the right, x ⊞ δ = x · Δ(δ), Δ(δ) = (Exp(δ_φ), δ_ρ), δ = (δ_ρ, δ_φ).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>

namespace trailnav::slam {

inline double wrap_angle(double a) noexcept {
  a = std::fmod(a + M_PI, 2.0 * M_PI);
  if (a <= 0.0) a += 2.0 * M_PI;
  return a - M_PI;
}

struct Se2 {
  double x = 0.0, y = 0.0, theta = 0.0;  // m, m, rad

  static constexpr int kDim = 3;
  using Vector = Eigen::Matrix<double, 3, 1>;
  using Matrix = Eigen::Matrix<double, 3, 3>;

  Se2 operator*(const Se2& b) const noexcept {
    const double c = std::cos(theta), s = std::sin(theta);
    return {x + c * b.x - s * b.y, y + s * b.x + c * b.y, wrap_angle(theta + b.theta)};
  }
  Se2 inverse() const noexcept {
    const double c = std::cos(theta), s = std::sin(theta);
    return {-(c * x + s * y), s * x - c * y, wrap_angle(-theta)};
  }
  Vector vector() const noexcept { return {x, y, theta}; }
  static Se2 from_vector(const Vector& v) noexcept { return {v[0], v[1], wrap_angle(v[2])}; }
  Se2 plus(const Vector& d) const noexcept { return {x + d[0], y + d[1], wrap_angle(theta + d[2])}; }
};

struct Se3 {
  Eigen::Vector3d t = Eigen::Vector3d::Zero();              // m
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();    // unit

  static constexpr int kDim = 6;
  using Vector = Eigen::Matrix<double, 6, 1>;
  using Matrix = Eigen::Matrix<double, 6, 6>;

  Se3 operator*(const Se3& b) const noexcept {
    Se3 r;
    r.t = t + q * b.t;
    r.q = (q * b.q).normalized();
    return r;
  }
  Se3 inverse() const noexcept {
    Se3 r;
    r.q = q.conjugate();
    r.t = -(r.q * t);
    return r;
  }
  // (t, q_v) with q_w ≥ 0: the error vector of an edge.
  Vector vector() const noexcept {
    Vector v;
    v.head<3>() = t;
    const double sign = q.w() < 0.0 ? -1.0 : 1.0;
    v.tail<3>() = sign * q.vec();
    return v;
  }
  Se3 plus(const Vector& d) const noexcept {
    Se3 r;
    r.t = t + q * d.head<3>();
    const double angle = d.tail<3>().norm();
    const Eigen::Quaterniond dq = angle < 1e-12
                                      ? Eigen::Quaterniond(1.0, 0.5 * d[3], 0.5 * d[4], 0.5 * d[5]).normalized()
                                      : Eigen::Quaterniond(Eigen::AngleAxisd(angle, d.tail<3>() / angle));
    r.q = (q * dq).normalized();
    return r;
  }
};

inline Eigen::Matrix3d skew(const Eigen::Vector3d& v) noexcept {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

// The error of Eq. 2.1 and its Jacobians with respect to the increments of
// x_i (ji) and x_j (jj), at the current poses.
template <class Pose>
struct EdgeLinearisation {
  typename Pose::Vector error;
  typename Pose::Matrix ji, jj;
};

inline typename Se2::Vector edge_error(const Se2& z, const Se2& xi, const Se2& xj) noexcept {
  return (z.inverse() * (xi.inverse() * xj)).vector();
}

inline typename Se3::Vector edge_error(const Se3& z, const Se3& xi, const Se3& xj) noexcept {
  return (z.inverse() * (xi.inverse() * xj)).vector();
}

// SE(2): e_t = R_zᵀ (R_iᵀ (t_j − t_i) − t_z), e_θ = θ_j − θ_i − θ_z; with the
// global increments, ∂e_t/∂t_i = −R_zᵀR_iᵀ, ∂e_t/∂θ_i = R_zᵀ (∂R_iᵀ/∂θ)(t_j − t_i),
// ∂e_t/∂t_j = R_zᵀR_iᵀ, ∂e_θ/∂θ_i = −1, ∂e_θ/∂θ_j = 1.
inline void linearise(const Se2& z, const Se2& xi, const Se2& xj, EdgeLinearisation<Se2>& out) noexcept {
  out.error = edge_error(z, xi, xj);
  const double ci = std::cos(xi.theta), si = std::sin(xi.theta);
  const double cz = std::cos(z.theta), sz = std::sin(z.theta);
  Eigen::Matrix2d rit, rzt, drit;
  rit << ci, si, -si, ci;
  rzt << cz, sz, -sz, cz;
  drit << -si, ci, -ci, -si;
  const Eigen::Vector2d dt(xj.x - xi.x, xj.y - xi.y);
  const Eigen::Matrix2d a = rzt * rit;
  out.ji.setZero();
  out.jj.setZero();
  out.ji.topLeftCorner<2, 2>() = -a;
  out.ji.topRightCorner<2, 1>() = rzt * drit * dt;
  out.ji(2, 2) = -1.0;
  out.jj.topLeftCorner<2, 2>() = a;
  out.jj(2, 2) = 1.0;
}

// SE(3), increments on the right: with E = z⁻¹ x_i⁻¹ x_j and B = x_i⁻¹ x_j,
// E·Δ(δ_j) moves the error by J_r(E) δ_j, J_r(E) = diag(R_E, ½(q_w I + [q_v]×))
// (sign of q taken with the error's), and z⁻¹ Δ(δ_i)⁻¹ B = E·Δ(−Ad(B⁻¹) δ_i),
// Ad(T) = [[R, [t]×R], [0, R]]: so J_i = −J_r(E) Ad(B⁻¹), J_j = J_r(E).
inline void linearise(const Se3& z, const Se3& xi, const Se3& xj, EdgeLinearisation<Se3>& out) noexcept {
  const Se3 b = xi.inverse() * xj;
  const Se3 e = z.inverse() * b;
  out.error = e.vector();
  const double sign = e.q.w() < 0.0 ? -1.0 : 1.0;
  Se3::Matrix jr = Se3::Matrix::Zero();
  jr.topLeftCorner<3, 3>() = e.q.toRotationMatrix();
  jr.bottomRightCorner<3, 3>() = 0.5 * sign * (e.q.w() * Eigen::Matrix3d::Identity() + skew(e.q.vec()));
  const Se3 binv = b.inverse();
  const Eigen::Matrix3d r = binv.q.toRotationMatrix();
  Se3::Matrix ad = Se3::Matrix::Zero();
  ad.topLeftCorner<3, 3>() = r;
  ad.topRightCorner<3, 3>() = skew(binv.t) * r;
  ad.bottomRightCorner<3, 3>() = r;
  out.jj = jr;
  out.ji = -jr * ad;
}

}  // namespace trailnav::slam
