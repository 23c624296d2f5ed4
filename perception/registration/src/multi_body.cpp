#include "trailnav/perception/registration/multi_body.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "gicp_terms.hpp"

namespace trailnav::perception::registration {

namespace {
// A squared distance as the k-d tree's search sums it (nanoflann's
// L2_Simple_Adaptor), so a partner kept or bounded by it compares equal to
// the one a search finds.
float tree_distance(const Eigen::Vector3f& q, const Point& p) noexcept {
  float d = 0.0f;
  for (int c = 0; c < 3; ++c) {
    const float diff = q[c] - p[c];
    d += diff * diff;
  }
  return d;
}
}  // namespace

MultiBodyGicp::MultiBodyGicp(const GicpConfig& config, std::size_t capacity, std::size_t max_bodies)
    : config_(config),
      max_bodies_(max_bodies),
      h_(max_bodies),
      b_(max_bodies),
      previous_body_(capacity, kNone),
      previous_target_(capacity, 0),
      searched_(capacity) {
  pairs_.reserve(capacity);
}

void MultiBodyGicp::associate_one(const Cloud& query, const Target& body, const Eigen::Isometry3d& transform,
                                  std::size_t n, bool to_plane, float gate2, float gate_bound) noexcept {
  // Float distances are exact to about 1e-5 m at 100 m; the certificate
  // keeps a margin ten times that, so a near tie is always searched.
  constexpr float kMargin = 1e-4f;
  const float gate = std::sqrt(gate2);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f q = (transform * query.points[i].cast<double>()).cast<float>();
    Searched& s = searched_[i];
    std::uint32_t j = 0;
    float d2 = 0.0f;
    bool have = false;
    if (previous_body_[i] != kNone) {
      const float moved = (q - s.at).norm();
      if (s.nearest + 2.0f * moved + kMargin < s.second) {
        // Still the nearest: every other point lies at least second − moved
        // away, this one at most nearest + moved.
        j = previous_target_[i];
        d2 = tree_distance(q, body.cloud.points[j]);
        have = true;
        ++kept_;
      }
    }
    if (!have) {
      std::uint32_t idx[2];
      float sq[2];
      const int found = body.tree.nearest_two_within(q, gate_bound, idx, sq);
      ++searches_;
      if (found == 0) {
        previous_body_[i] = kNone;
        continue;
      }
      j = idx[0];
      d2 = sq[0];
      s = {q, std::sqrt(d2), found == 2 ? std::sqrt(sq[1]) : gate};
      previous_body_[i] = 0;
      previous_target_[i] = j;
    }
    // The nearest point, as a search of the whole tree finds it: within the
    // gate, and with a normal for point-to-plane.
    if (d2 > gate2) continue;
    if (to_plane && body.normals[j].isZero()) continue;
    pairs_.push_back({static_cast<std::uint32_t>(i), j, 0, d2});
  }
}

void MultiBodyGicp::associate_everywhere(const Cloud& query, std::span<const Target* const> bodies,
                                         std::span<BodyResult> out, std::size_t nb, std::size_t n, bool to_plane,
                                         float gate2) noexcept {
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d q = query.points[i].cast<double>();
    float best = std::numeric_limits<float>::infinity();
    std::uint32_t best_j = 0, best_body = 0;
    for (std::size_t k = 0; k < nb; ++k) {
      std::uint32_t j = 0;
      float d2 = 0.0f;
      ++searches_;
      if (!bodies[k]->tree.nearest((out[k].transform * q).cast<float>(), j, d2) || d2 > gate2 || d2 >= best) continue;
      if (to_plane && bodies[k]->normals[j].isZero()) continue;
      best = d2;
      best_j = j;
      best_body = static_cast<std::uint32_t>(k);
    }
    if (best <= gate2) pairs_.push_back({static_cast<std::uint32_t>(i), best_j, best_body, best});
  }
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
  // Searches find points strictly closer than their bound; the gate admits its own distance.
  const float gate_bound = std::nextafter(gate2, std::numeric_limits<float>::infinity());
  std::fill(previous_body_.begin(), previous_body_.begin() + static_cast<std::ptrdiff_t>(n), kNone);
  int iterations = 0;
  for (int it = 0; it < config_.max_iterations; ++it) {
    // Eq. 4.2: each query point to the nearest reference point of any body,
    // each body under its own transform. Each body's search is bounded by
    // the gate and by the best partner so far in the bodies before it, and
    // the body of the last iteration's partner also by that partner's
    // distance now (it is a point of that body: the nearest can only be
    // closer). The same partners as unbounded searches, but the tree skips
    // what cannot be closer; after the first iterations, most of it.
    pairs_.clear();
    if (search_every_point_) {
      associate_everywhere(query, bodies, out, nb, n, to_plane, gate2);
    } else if (nb == 1) {
      associate_one(query, *bodies[0], out[0].transform, n, to_plane, gate2, gate_bound);
    }
    for (std::size_t i = 0; i < n && nb > 1 && !search_every_point_; ++i) {
      const Eigen::Vector3d q = query.points[i].cast<double>();
      const std::uint32_t was_body = previous_body_[i];
      float best = gate_bound;
      std::uint32_t best_j = 0, best_body = 0;
      bool found = false;
      for (std::size_t k = 0; k < nb; ++k) {
        const Eigen::Vector3f qk = (out[k].transform * q).cast<float>();
        std::uint32_t j = 0;
        float d2 = 0.0f;
        float bound = best;
        bool known = false;
        if (was_body == k) {
          j = previous_target_[i];
          const float d_was = tree_distance(qk, bodies[k]->cloud.points[j]);
          if (d_was < bound) {
            // Strictly closer than the bodies before (which win ties): a candidate.
            bound = std::nextafter(d_was, std::numeric_limits<float>::infinity());
            known = true;
          }
        }
        ++searches_;
        if (!bodies[k]->tree.nearest_within(qk, bound, known, j, d2)) continue;
        if (to_plane && bodies[k]->normals[j].isZero()) continue;
        best = d2;
        best_j = j;
        best_body = static_cast<std::uint32_t>(k);
        found = true;
      }
      previous_body_[i] = found ? best_body : kNone;
      previous_target_[i] = best_j;
      if (found) pairs_.push_back({static_cast<std::uint32_t>(i), best_j, best_body, best});
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
    if (!out[k].observed) continue;
    out[k].covariance = detail::covariance_of(h_[k]);
    out[k].information = h_[k];
  }
  return iterations;
}

}  // namespace trailnav::perception::registration
