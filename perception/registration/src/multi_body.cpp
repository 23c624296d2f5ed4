#include "trailnav/perception/registration/multi_body.hpp"

#include <algorithm>
#include <limits>

#include "gicp_terms.hpp"

namespace trailnav::perception::registration {

MultiBodyGicp::MultiBodyGicp(const GicpConfig& config, std::size_t capacity, std::size_t max_bodies)
    : config_(config), max_bodies_(max_bodies), h_(max_bodies), b_(max_bodies) {
  pairs_.reserve(capacity);
}

int MultiBodyGicp::align(const Cloud& query, std::span<const Target* const> bodies,
                         std::span<const Eigen::Isometry3d> initial, std::span<BodyResult> out) noexcept {
  const std::size_t nb = std::min({bodies.size(), initial.size(), out.size(), max_bodies_});
  const std::size_t n = std::min(query.size(), pairs_.capacity());
  for (std::size_t k = 0; k < nb; ++k) {
    out[k] = BodyResult{};
    out[k].transform = initial[k];
  }
  for (std::size_t k = 0; k < nb; ++k) {
    if (!detail::usable(config_, query, n, *bodies[k])) return 0;
  }
  const bool to_plane = config_.metric == Metric::point_to_plane;
  const float gate2 = config_.max_correspondence_distance * config_.max_correspondence_distance;
  int iterations = 0;
  for (int it = 0; it < config_.max_iterations; ++it) {
    // Eq. 4.2: each query point to the nearest reference point of any body,
    // each body under its own transform.
    pairs_.clear();
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d q = query.points[i].cast<double>();
      float best = std::numeric_limits<float>::infinity();
      std::uint32_t best_j = 0, best_body = 0;
      for (std::size_t k = 0; k < nb; ++k) {
        std::uint32_t j = 0;
        float d2 = 0.0f;
        if (!bodies[k]->tree.nearest((out[k].transform * q).cast<float>(), j, d2) || d2 > gate2 || d2 >= best) continue;
        if (to_plane && bodies[k]->normals[j].isZero()) continue;
        best = d2;
        best_j = j;
        best_body = static_cast<std::uint32_t>(k);
      }
      if (best <= gate2) pairs_.push_back({static_cast<std::uint32_t>(i), best_j, best_body, best});
    }
    // Eq. 4.1 / 4.4: with Dirac weights the normal equations are block
    // diagonal, one 6 × 6 block per body.
    for (std::size_t k = 0; k < nb; ++k) {
      h_[k].setZero();
      b_[k].setZero();
      out[k].correspondences = 0;
      out[k].fitness = 0.0;
      out[k].error = 0.0;
    }
    for (const Pair& p : pairs_) {
      BodyResult& r = out[p.body];
      r.error += detail::accumulate(config_, query, p.query, *bodies[p.body], p.target, r.transform.linear(),
                                    r.transform.translation(), h_[p.body], b_[p.body]);
      r.fitness += static_cast<double>(p.squared);
      ++r.correspondences;
    }
    bool all_converged = true, any_observed = false;
    for (std::size_t k = 0; k < nb; ++k) {
      BodyResult& r = out[k];
      r.observed = r.correspondences >= 6;
      if (r.correspondences > 0) r.fitness /= static_cast<double>(r.correspondences);
      if (!r.observed) {
        r.converged = false;
        continue;  // out of view: keeps its transform
      }
      any_observed = true;
      bool converged = false;
      if (!detail::step(config_, h_[k], b_[k], r.transform, converged)) {
        r.converged = false;
        continue;
      }
      r.converged = converged;
      all_converged = all_converged && converged;
    }
    if (!any_observed) break;  // nothing in view: no step was made
    iterations = it + 1;
    if (all_converged) break;
  }
  for (std::size_t k = 0; k < nb; ++k) {
    if (out[k].observed) out[k].covariance = detail::covariance_of(h_[k]);
  }
  return iterations;
}

}  // namespace trailnav::perception::registration
