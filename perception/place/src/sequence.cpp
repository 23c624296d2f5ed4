#include "trailnav/perception/place/sequence.hpp"

#include <algorithm>

namespace trailnav::perception::place {

std::vector<Match> row_peaks(const Matrix& b, float p_min, int radius) {
  std::vector<Match> out;
  const Eigen::Index n = b.cols();
  const Eigen::Index r = std::max(radius, 0);
  for (Eigen::Index i = 0; i < b.rows(); ++i) {
    const float* row = b.row(i).data();
    for (Eigen::Index j = 0; j < n; ++j) {
      const float v = row[j];
      if (!(v >= p_min)) continue;
      bool peak = true;
      const Eigen::Index lo = std::max<Eigen::Index>(0, j - r);
      const Eigen::Index hi = std::min<Eigen::Index>(n - 1, j + r);
      for (Eigen::Index k = lo; k <= hi && peak; ++k) {
        if (k < j) peak = row[k] < v;       // the leftmost of equals
        else if (k > j) peak = row[k] <= v;
      }
      if (peak) out.push_back({static_cast<int>(i), static_cast<int>(j), v});
    }
  }
  return out;
}

std::vector<Match> sequence_filter(std::span<const Match> peaks, const SequenceConfig& config) {
  std::vector<Match> out;
  if (peaks.empty()) return out;
  const std::size_t n = peaks.size();
  // Where each query's peaks begin (peaks are sorted by query, then database).
  const int first_query = peaks.front().query;
  const int last_query = peaks.back().query;
  std::vector<std::size_t> begin(static_cast<std::size_t>(last_query - first_query) + 2, 0);
  for (std::size_t k = 0, q = 0; q < begin.size(); ++q) {
    while (k < n && peaks[k].query < first_query + static_cast<int>(q)) ++k;
    begin[q] = k;
  }
  const auto row_range = [&](int query) {
    const std::size_t q = static_cast<std::size_t>(query - first_query);
    return std::pair{begin[q], begin[q + 1]};
  };
  // Longest chain ending at each peak (rows ascending), then starting at each
  // (rows descending).
  std::vector<int> ending(n, 1), starting(n, 1);
  const auto relax = [&](std::vector<int>& length, std::size_t k, int other_query) {
    if (other_query < first_query || other_query > last_query) return;
    auto [lo, hi] = row_range(other_query);
    const int j = peaks[k].database;
    // The first peak of that row at column ≥ j - g_c.
    const Match* first = std::lower_bound(peaks.data() + lo, peaks.data() + hi, j - config.column_gap,
                                          [](const Match& m, int col) { return m.database < col; });
    for (const Match* m = first; m != peaks.data() + hi && m->database <= j + config.column_gap; ++m)
      length[k] = std::max(length[k], length[static_cast<std::size_t>(m - peaks.data())] + 1);
  };
  for (std::size_t k = 0; k < n; ++k)
    for (int gap = 1; gap <= config.row_gap; ++gap) relax(ending, k, peaks[k].query - gap);
  for (std::size_t k = n; k-- > 0;)
    for (int gap = 1; gap <= config.row_gap; ++gap) relax(starting, k, peaks[k].query + gap);
  for (std::size_t k = 0; k < n; ++k)
    if (ending[k] + starting[k] - 1 >= config.min_length) out.push_back(peaks[k]);
  return out;
}

}  // namespace trailnav::perception::place
