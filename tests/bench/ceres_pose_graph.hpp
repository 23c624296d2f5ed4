// The peer for the pose-graph side-by-side: the same g2o graph solved by
// Ceres Solver (Debian's libceres-dev) in its pose-graph formulation — one
// parameter block per pose (SE(2): x, y, θ; SE(3): position and an Eigen
// quaternion on Ceres' quaternion manifold), one automatically
// differentiated residual per edge, r = √Ω e with e the same error as
// trailnav's (Eq. 2.1 in g2o's convention), so Ceres' cost ½Σ|r|² is half
// the χ² trailnav reports. Levenberg–Marquardt on a sparse normal Cholesky
// (SuiteSparse), one thread, function tolerance as trailnav's. The gauge
// as trailnav's: FIX vertices constant, else the first. Our own code; only
// the library is Ceres.
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Cholesky>

#include <memory>
#include <vector>

#include "trailnav/navigation/slam/g2o_io.hpp"

namespace trailnav::bench {

struct CeresOutcome {
  double initial_chi2 = 0.0, chi2 = 0.0;
  int iterations = 0;
  bool converged = false;
  std::string message;
};

struct Se2Residual {
  Se2Residual(const slam::Se2& measured, const Eigen::Matrix3d& sqrt_information) : z(measured), s(sqrt_information) {}
  template <class T>
  bool operator()(const T* a, const T* b, T* r) const {
    using std::cos;
    using std::sin;
    // x_a⁻¹ x_b
    const T ca = cos(a[2]), sa = sin(a[2]);
    const T dx = b[0] - a[0], dy = b[1] - a[1];
    const T lx = ca * dx + sa * dy, ly = -sa * dx + ca * dy;
    // z⁻¹ (x_a⁻¹ x_b)
    const double cz = std::cos(z.theta), sz = std::sin(z.theta);
    const T ex = cz * (lx - z.x) + sz * (ly - z.y);
    const T ey = -sz * (lx - z.x) + cz * (ly - z.y);
    T et = b[2] - a[2] - z.theta;
    // wrap to (−π, π]
    const T two_pi = T(2.0 * M_PI);
    et = et - two_pi * ceres::floor((et + T(M_PI)) / two_pi);
    for (int i = 0; i < 3; ++i) r[i] = T(s(i, 0)) * ex + T(s(i, 1)) * ey + T(s(i, 2)) * et;
    return true;
  }
  slam::Se2 z;
  Eigen::Matrix3d s;
};

struct Se3Residual {
  Se3Residual(const slam::Se3& measured, const Eigen::Matrix<double, 6, 6>& sqrt_information)
      : z(measured), s(sqrt_information) {}
  template <class T>
  bool operator()(const T* pa, const T* qa, const T* pb, const T* qb, T* r) const {
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> ta(pa), tb(pb);
    Eigen::Map<const Eigen::Quaternion<T>> ra(qa), rb(qb);
    const Eigen::Quaternion<T> ra_inv = ra.conjugate();
    const Eigen::Matrix<T, 3, 1> t_ab = ra_inv * (tb - ta);
    const Eigen::Quaternion<T> q_ab = ra_inv * rb;
    const Eigen::Quaternion<T> zq_inv = z.q.conjugate().template cast<T>();
    const Eigen::Matrix<T, 3, 1> e_t = zq_inv * (t_ab - z.t.template cast<T>());
    Eigen::Quaternion<T> e_q = zq_inv * q_ab;
    Eigen::Matrix<T, 6, 1> e;
    e.template head<3>() = e_t;
    const T sign = e_q.w() < T(0) ? T(-1) : T(1);
    e.template tail<3>() = sign * e_q.vec();
    Eigen::Map<Eigen::Matrix<T, 6, 1>> out(r);
    out = s.template cast<T>() * e;
    return true;
  }
  slam::Se3 z;
  Eigen::Matrix<double, 6, 6> s;
};

template <int N>
Eigen::Matrix<double, N, N> square_root(const Eigen::Matrix<double, N, N>& information) {
  return Eigen::LLT<Eigen::Matrix<double, N, N>>(information).matrixL().transpose();  // LᵀL = Ω
}

inline ceres::Solver::Options ceres_options(int max_iterations, double tolerance) {
  ceres::Solver::Options o;
  o.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  o.sparse_linear_algebra_library_type = ceres::SUITE_SPARSE;
  o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  o.max_num_iterations = max_iterations;
  o.function_tolerance = tolerance;
  o.num_threads = 1;
  o.minimizer_progress_to_stdout = false;
  o.logging_type = ceres::SILENT;
  return o;
}

// Solves `g` in place (its poses take Ceres' solution).
inline CeresOutcome solve_with_ceres(slam::G2oGraph& g, int max_iterations = 500, double tolerance = 1e-6) {
  CeresOutcome out;
  ceres::Problem::Options po;
  po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  ceres::EigenQuaternionManifold quaternion;
  std::vector<double> x;  // SE(2): 3 per pose; SE(3): 3 + 4 per pose
  const std::size_t n = g.vertex_count();
  const bool spatial = g.kind == slam::GraphKind::spatial;
  x.resize(n * (spatial ? 7u : 3u));
  bool any_fixed = false;
  for (std::size_t v = 0; v < n; ++v) {
    if (spatial) {
      const auto& p = g.spatial.pose(v);
      double* b = x.data() + 7 * v;
      b[0] = p.t.x(), b[1] = p.t.y(), b[2] = p.t.z();
      b[3] = p.q.x(), b[4] = p.q.y(), b[5] = p.q.z(), b[6] = p.q.w();  // Eigen's order
      any_fixed = any_fixed || g.spatial.fixed(v);
    } else {
      const auto& p = g.planar.pose(v);
      double* b = x.data() + 3 * v;
      b[0] = p.x, b[1] = p.y, b[2] = p.theta;
      any_fixed = any_fixed || g.planar.fixed(v);
    }
  }
  if (spatial) {
    for (const auto& e : g.spatial.edges()) {
      auto* cost = new ceres::AutoDiffCostFunction<Se3Residual, 6, 3, 4, 3, 4>(new Se3Residual(e.measurement, square_root<6>(e.information)));
      double* a = x.data() + 7 * static_cast<std::size_t>(e.from);
      double* b = x.data() + 7 * static_cast<std::size_t>(e.to);
      problem.AddResidualBlock(cost, nullptr, a, a + 3, b, b + 3);
      problem.SetManifold(a + 3, &quaternion);
      problem.SetManifold(b + 3, &quaternion);
    }
  } else {
    for (const auto& e : g.planar.edges()) {
      auto* cost = new ceres::AutoDiffCostFunction<Se2Residual, 3, 3, 3>(new Se2Residual(e.measurement, square_root<3>(e.information)));
      problem.AddResidualBlock(cost, nullptr, x.data() + 3 * static_cast<std::size_t>(e.from), x.data() + 3 * static_cast<std::size_t>(e.to));
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    const bool fixed = spatial ? g.spatial.fixed(v) : g.planar.fixed(v);
    if (!(fixed || (!any_fixed && v == 0))) continue;
    double* b = x.data() + (spatial ? 7 : 3) * v;
    if (!problem.HasParameterBlock(b)) continue;
    problem.SetParameterBlockConstant(b);
    if (spatial) problem.SetParameterBlockConstant(b + 3);
  }
  ceres::Solver::Summary summary;
  ceres::Solve(ceres_options(max_iterations, tolerance), &problem, &summary);
  out.initial_chi2 = 2.0 * summary.initial_cost;
  out.chi2 = 2.0 * summary.final_cost;
  out.iterations = static_cast<int>(summary.iterations.size()) - 1;
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  out.message = summary.message;
  for (std::size_t v = 0; v < n; ++v) {
    if (spatial) {
      const double* b = x.data() + 7 * v;
      g.spatial.pose(v).t = Eigen::Vector3d(b[0], b[1], b[2]);
      g.spatial.pose(v).q = Eigen::Quaterniond(b[6], b[3], b[4], b[5]).normalized();
    } else {
      const double* b = x.data() + 3 * v;
      g.planar.pose(v) = slam::Se2{b[0], b[1], slam::wrap_angle(b[2])};
    }
  }
  return out;
}

}  // namespace trailnav::bench
