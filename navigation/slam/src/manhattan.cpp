#include "trailnav/navigation/slam/manhattan.hpp"

#include <array>
#include <cmath>
#include <random>
#include <vector>

namespace trailnav::slam {
namespace {

// Portable draws: the standard library's distributions may differ between
// implementations; these are the same everywhere.
struct Draw {
  std::mt19937_64 engine;
  double uniform() { return static_cast<double>(engine() >> 11) * 0x1.0p-53; }  // [0, 1)
  double gaussian() {  // Box–Muller
    const double u1 = 1.0 - uniform(), u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  }
};

constexpr int kVisitsKept = 6;  // the latest visits of a spot that closures may join

}  // namespace

ManhattanResult generate_manhattan(const ManhattanOptions& o, PoseGraph2d& out, PoseGraph2d* truth) {
  ManhattanResult r;
  if (o.nodes < 2) {
    r.error = "a world needs at least 2 poses";
    return r;
  }
  const int side = o.side > 0 ? o.side : static_cast<int>(std::ceil(std::sqrt(static_cast<double>(o.nodes)) / 3));
  if (side < 2) {
    r.error = "a world needs at least 2 streets a side";
    return r;
  }
  if (!(o.block > 0.0) || !(o.sigma_translation > 0.0) || !(o.sigma_rotation > 0.0) || o.closures_per_pose < 0 ||
      !(o.turn_probability >= 0.0 && o.turn_probability <= 1.0) ||
      !(o.closure_probability >= 0.0 && o.closure_probability <= 1.0)) {
    r.error = "block and noise must be positive, probabilities within 0..1";
    return r;
  }
  out.clear();
  if (truth != nullptr) truth->clear();
  Draw draw{std::mt19937_64(o.seed)};
  Se2::Matrix information = Se2::Matrix::Zero();
  information(0, 0) = information(1, 1) = 1.0 / (o.sigma_translation * o.sigma_translation);
  information(2, 2) = 1.0 / (o.sigma_rotation * o.sigma_rotation);
  auto noisy = [&](const Se2& z) {
    return z * Se2{o.sigma_translation * draw.gaussian(), o.sigma_translation * draw.gaussian(),
                   o.sigma_rotation * draw.gaussian()};
  };
  // Latest visits per crossing, a ring of kVisitsKept.
  std::vector<std::array<std::int32_t, kVisitsKept>> visits(static_cast<std::size_t>(side) * static_cast<std::size_t>(side));
  for (auto& v : visits) v.fill(-1);
  std::vector<Se2> true_pose;
  true_pose.reserve(o.nodes);
  static constexpr int dx[4] = {1, 0, -1, 0}, dy[4] = {0, 1, 0, -1};
  int x = 0, y = 0, heading = 0;
  Se2 guess;
  for (std::size_t i = 0; i < o.nodes; ++i) {
    if (i > 0) {
      // Turn at random, or because the street ends at the world's edge.
      if (draw.uniform() < o.turn_probability) heading = (heading + (draw.uniform() < 0.5 ? 1 : 3)) % 4;
      auto inside = [&](int h) {
        const int nx = x + dx[h], ny = y + dy[h];
        return nx >= 0 && ny >= 0 && nx < side && ny < side;
      };
      if (!inside(heading)) {
        const int left = (heading + 1) % 4, right = (heading + 3) % 4;
        const bool l = inside(left), rr = inside(right);
        heading = l && rr ? (draw.uniform() < 0.5 ? left : right) : l ? left : rr ? right : (heading + 2) % 4;
      }
      x += dx[heading];
      y += dy[heading];
    }
    const Se2 now{x * o.block, y * o.block, wrap_angle(heading * M_PI / 2.0)};
    true_pose.push_back(now);
    if (i > 0) {
      const Se2 z = noisy(true_pose[i - 1].inverse() * now);
      guess = guess * z;
      if (!out.add_edge({static_cast<std::int32_t>(i - 1), static_cast<std::int32_t>(i), z, information})) {
        r.error = "the graph's edge capacity is too small";
        return r;
      }
      if (truth != nullptr) truth->add_edge({static_cast<std::int32_t>(i - 1), static_cast<std::int32_t>(i), z, information});
    }
    if (!out.add_vertex(static_cast<std::int64_t>(i), guess, i == 0)) {
      r.error = "the graph's vertex capacity is too small";
      return r;
    }
    if (truth != nullptr) truth->add_vertex(static_cast<std::int64_t>(i), now, i == 0);
    // Closures to earlier visits of this crossing, the latest first.
    auto& seen = visits[static_cast<std::size_t>(y) * static_cast<std::size_t>(side) + static_cast<std::size_t>(x)];
    int made = 0;
    for (int k = 0; k < kVisitsKept && made < o.closures_per_pose; ++k) {
      const std::int32_t j = seen[static_cast<std::size_t>(k)];
      if (j < 0 || static_cast<std::size_t>(j) + 1 >= i) continue;
      if (draw.uniform() >= o.closure_probability) continue;
      const Se2 z = noisy(true_pose[static_cast<std::size_t>(j)].inverse() * now);
      if (!out.add_edge({j, static_cast<std::int32_t>(i), z, information})) {
        r.error = "the graph's edge capacity is too small";
        return r;
      }
      if (truth != nullptr) truth->add_edge({j, static_cast<std::int32_t>(i), z, information});
      ++made;
      ++r.closures;
    }
    for (int k = kVisitsKept - 1; k > 0; --k) seen[static_cast<std::size_t>(k)] = seen[static_cast<std::size_t>(k - 1)];
    seen[0] = static_cast<std::int32_t>(i);
  }
  r.ok = true;
  return r;
}

}  // namespace trailnav::slam
