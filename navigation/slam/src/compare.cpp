#include "trailnav/navigation/slam/compare.hpp"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

namespace trailnav::slam {
namespace {

double translation(const Se2& d) { return std::hypot(d.x, d.y); }
double rotation(const Se2& d) { return std::abs(d.theta); }
double translation(const Se3& d) { return d.t.norm(); }
double rotation(const Se3& d) { return 2.0 * std::atan2(d.q.vec().norm(), std::abs(d.q.w())); }

}  // namespace

template <class Pose>
EdgeErrorStats compare_graphs(const PoseGraph<Pose>& a, const PoseGraph<Pose>& b) {
  EdgeErrorStats s;
  if (a.vertex_count() != b.vertex_count()) {
    s.error = "the graphs have " + std::to_string(a.vertex_count()) + " and " + std::to_string(b.vertex_count()) + " vertices";
    return s;
  }
  std::vector<std::pair<std::int64_t, std::size_t>> ids(b.vertex_count());
  for (std::size_t v = 0; v < b.vertex_count(); ++v) ids[v] = {b.id(v), v};
  std::sort(ids.begin(), ids.end());
  std::vector<std::size_t> in_b(a.vertex_count());
  for (std::size_t v = 0; v < a.vertex_count(); ++v) {
    const auto it = std::lower_bound(ids.begin(), ids.end(), std::make_pair(a.id(v), std::size_t{0}));
    if (it == ids.end() || it->first != a.id(v)) {
      s.error = "vertex " + std::to_string(a.id(v)) + " of the first graph is not in the second";
      return s;
    }
    in_b[v] = it->second;
  }
  double sum = 0.0, sum2 = 0.0, rsum = 0.0;
  for (const auto& e : a.edges()) {
    const auto i = static_cast<std::size_t>(e.from), j = static_cast<std::size_t>(e.to);
    const Pose ra = a.pose(i).inverse() * a.pose(j);
    const Pose rb = b.pose(in_b[i]).inverse() * b.pose(in_b[j]);
    const Pose d = rb.inverse() * ra;
    const double t = translation(d), r = rotation(d);
    sum += t;
    sum2 += t * t;
    rsum += r;
    s.max = std::max(s.max, t);
    s.rotation_max = std::max(s.rotation_max, r);
  }
  s.edges = a.edge_count();
  if (s.edges > 0) {
    const double n = static_cast<double>(s.edges);
    s.mean = sum / n;
    s.std = std::sqrt(std::max(0.0, sum2 / n - s.mean * s.mean));
    s.rotation_mean = rsum / n;
  }
  s.ok = true;
  return s;
}

template EdgeErrorStats compare_graphs(const PoseGraph<Se2>&, const PoseGraph<Se2>&);
template EdgeErrorStats compare_graphs(const PoseGraph<Se3>&, const PoseGraph<Se3>&);

}  // namespace trailnav::slam
