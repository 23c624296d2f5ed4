#include "seqslam.hpp"

#include "trailnav/drivers/camera/frame.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace trailnav::eval {

std::vector<float> seqslam_prepare(std::span<const std::uint8_t> grey, int width, int height, const SeqSlamConfig& c) {
  // Down-sampled by area averages (drivers/camera's, as the camera reduces
  // its frames); a smaller image enlarged by its nearest pixels.
  std::vector<float> small(static_cast<std::size_t>(c.width * c.height), 0.0f);
  if (width >= c.width && height >= c.height) {
    std::vector<std::uint8_t> reduced(small.size());
    std::vector<std::uint32_t> sums(small.size()), counts(small.size());
    drivers::camera::area_counts(width, height, c.width, c.height, counts);
    drivers::camera::reduce_area(grey, width, height, reduced, c.width, c.height, sums, counts);
    for (std::size_t k = 0; k < small.size(); ++k) small[k] = reduced[k];
  } else {
    for (int sy = 0; sy < c.height; ++sy)
      for (int sx = 0; sx < c.width; ++sx)
        small[static_cast<std::size_t>(sy * c.width + sx)] =
            grey[static_cast<std::size_t>((sy * height / c.height) * width + sx * width / c.width)];
  }
  // Patch normalisation.
  for (int py = 0; py < c.height; py += c.patch)
    for (int px = 0; px < c.width; px += c.patch) {
      const int h = std::min(c.patch, c.height - py), w = std::min(c.patch, c.width - px);
      double sum = 0.0, sq = 0.0;
      for (int y = py; y < py + h; ++y)
        for (int x = px; x < px + w; ++x) {
          const double v = small[static_cast<std::size_t>(y * c.width + x)];
          sum += v;
          sq += v * v;
        }
      const double n = static_cast<double>(w * h);
      const double mean = sum / n;
      const double sd = std::sqrt(std::max(0.0, sq / n - mean * mean));
      for (int y = py; y < py + h; ++y)
        for (int x = px; x < px + w; ++x) {
          float& v = small[static_cast<std::size_t>(y * c.width + x)];
          v = sd > 1e-9 ? static_cast<float>((static_cast<double>(v) - mean) / sd) : 0.0f;
        }
    }
  return small;
}

std::vector<perception::place::Match> seqslam_matches(const std::vector<std::vector<float>>& database,
                                                      const std::vector<std::vector<float>>& queries,
                                                      const SeqSlamConfig& c) {
  const int n_d = static_cast<int>(database.size());
  const int n_q = static_cast<int>(queries.size());
  std::vector<perception::place::Match> out;
  if (n_d == 0 || n_q == 0) return out;
  // D (database x query), mean absolute differences.
  std::vector<float> d(static_cast<std::size_t>(n_d) * static_cast<std::size_t>(n_q));
  for (int j = 0; j < n_d; ++j)
    for (int i = 0; i < n_q; ++i) {
      const std::vector<float>& a = database[static_cast<std::size_t>(j)];
      const std::vector<float>& b = queries[static_cast<std::size_t>(i)];
      double s = 0.0;
      for (std::size_t k = 0; k < a.size(); ++k) s += static_cast<double>(std::fabs(a[k] - b[k]));
      d[static_cast<std::size_t>(j) * static_cast<std::size_t>(n_q) + static_cast<std::size_t>(i)] =
          static_cast<float>(s / static_cast<double>(a.size()));
    }
  // Local contrast enhancement over ±R database images, per query.
  std::vector<float> e(d.size());
  float lowest = std::numeric_limits<float>::max();
  for (int i = 0; i < n_q; ++i)
    for (int j = 0; j < n_d; ++j) {
      const int lo = std::max(0, j - c.window), hi = std::min(n_d - 1, j + c.window);
      double sum = 0.0, sq = 0.0;
      for (int k = lo; k <= hi; ++k) {
        const double v = d[static_cast<std::size_t>(k) * static_cast<std::size_t>(n_q) + static_cast<std::size_t>(i)];
        sum += v;
        sq += v * v;
      }
      const double n = static_cast<double>(hi - lo + 1);
      const double mean = sum / n;
      const double sd = std::sqrt(std::max(0.0, sq / n - mean * mean));
      const std::size_t at = static_cast<std::size_t>(j) * static_cast<std::size_t>(n_q) + static_cast<std::size_t>(i);
      e[at] = static_cast<float>(sd > 1e-12 ? (static_cast<double>(d[at]) - mean) / sd : 0.0);
      lowest = std::min(lowest, e[at]);
    }
  for (float& v : e) v -= lowest;
  std::vector<double> speeds;
  for (double v = c.v_min; v <= c.v_max + 1e-9; v += c.v_step) speeds.push_back(v);
  const int half = c.sequence / 2;
  std::vector<double> best_at(static_cast<std::size_t>(n_d));
  for (int t = half; t + (c.sequence - half) <= n_q; ++t) {
    const int first = t - half;  // the sequence's queries: first ... first + ds - 1, T among them
    std::fill(best_at.begin(), best_at.end(), std::numeric_limits<double>::infinity());
    for (int start = 0; start < n_d; ++start) {
      for (double v : speeds) {
        const int end = start + static_cast<int>(std::lround(v * (c.sequence - 1)));
        if (end >= n_d) continue;
        double score = 0.0;
        for (int k = 0; k < c.sequence; ++k) {
          const int j = start + static_cast<int>(std::lround(v * k));
          score += static_cast<double>(e[static_cast<std::size_t>(j) * static_cast<std::size_t>(n_q) + static_cast<std::size_t>(first + k)]);
        }
        const int at_t = start + static_cast<int>(std::lround(v * (t - first)));
        best_at[static_cast<std::size_t>(at_t)] = std::min(best_at[static_cast<std::size_t>(at_t)], score);
      }
    }
    int best = -1;
    for (int j = 0; j < n_d; ++j)
      if (std::isfinite(best_at[static_cast<std::size_t>(j)]) &&
          (best < 0 || best_at[static_cast<std::size_t>(j)] < best_at[static_cast<std::size_t>(best)]))
        best = j;
    if (best < 0) continue;
    double second = std::numeric_limits<double>::infinity();
    for (int j = 0; j < n_d; ++j)
      if (std::abs(j - best) > c.window) second = std::min(second, best_at[static_cast<std::size_t>(j)]);
    const double s1 = best_at[static_cast<std::size_t>(best)];
    const double confidence = std::isfinite(second) && second > 0.0 ? 1.0 - s1 / second : 0.0;
    out.push_back({t, best, static_cast<float>(confidence)});
  }
  return out;
}

}  // namespace trailnav::eval
