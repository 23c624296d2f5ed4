#include "trailnav/perception/place/evaluation.hpp"

#include <algorithm>

namespace trailnav::perception::place {

std::size_t GroundTruth::positives() const noexcept {
  std::size_t n = 0;
  for (int r : reference) n += r >= 0 ? 1 : 0;
  return n;
}

namespace {

PrPoint point(double threshold, std::size_t matches, std::size_t true_matches, std::size_t found, std::size_t positives) {
  PrPoint p;
  p.threshold = threshold;
  p.matches = matches;
  p.true_matches = true_matches;
  p.precision = matches > 0 ? static_cast<double>(true_matches) / static_cast<double>(matches) : 1.0;
  p.recall = positives > 0 ? static_cast<double>(found) / static_cast<double>(positives) : 0.0;
  p.f1 = p.precision + p.recall > 0.0 ? 2.0 * p.precision * p.recall / (p.precision + p.recall) : 0.0;
  return p;
}

}  // namespace

PrPoint score(std::span<const Match> matches, const GroundTruth& truth, double threshold) {
  std::vector<char> found(truth.reference.size(), 0);
  std::size_t true_matches = 0, queries = 0;
  for (const Match& m : matches) {
    if (!truth.correct(m)) continue;
    ++true_matches;
    char& f = found[static_cast<std::size_t>(m.query)];
    if (f == 0) ++queries;
    f = 1;
  }
  return point(threshold, matches.size(), true_matches, queries, truth.positives());
}

PrCurve curve_of(std::vector<PrPoint> points) {
  PrCurve c;
  c.points = std::move(points);
  for (const PrPoint& p : c.points)
    if (p.matches > 0 && p.f1 > c.best.f1) c.best = p;
  return c;
}

PrCurve sweep(std::vector<Match> matches, const GroundTruth& truth, std::size_t max_points) {
  std::stable_sort(matches.begin(), matches.end(), [](const Match& a, const Match& b) { return a.score > b.score; });
  std::vector<char> found(truth.reference.size(), 0);
  const std::size_t positives = truth.positives();
  std::vector<PrPoint> all;
  std::size_t true_matches = 0, queries = 0;
  for (std::size_t k = 0; k < matches.size(); ++k) {
    const Match& m = matches[k];
    if (truth.correct(m)) {
      ++true_matches;
      char& f = found[static_cast<std::size_t>(m.query)];
      if (f == 0) ++queries;
      f = 1;
    }
    // A point where the next score differs (all matches of equal score in or out together).
    if (k + 1 == matches.size() || matches[k + 1].score != m.score)
      all.push_back(point(m.score, k + 1, true_matches, queries, positives));
  }
  PrCurve c = curve_of(all);
  if (max_points >= 2 && all.size() > max_points) {
    std::vector<PrPoint> kept;
    const double step = static_cast<double>(all.size() - 1) / static_cast<double>(max_points - 1);
    for (std::size_t i = 0; i < max_points; ++i) kept.push_back(all[static_cast<std::size_t>(static_cast<double>(i) * step + 0.5)]);
    c.points = std::move(kept);
  }
  return c;
}

}  // namespace trailnav::perception::place
