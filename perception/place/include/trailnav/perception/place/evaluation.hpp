// Scoring place matches against ground truth (thesis §5.5): a match (i, j)
// is a true positive when query i has a database place r in the ground truth
// and |j - r| ≤ its tolerance. Precision: true matches over all matches.
// Recall: queries with at least one true match over the queries that have a
// place in the database (a query seen nowhere in the database can only be
// a false positive). F1 = 2 P R / (P + R) (Eq. 5.15, β = 1).
#pragma once

#include <span>
#include <vector>

#include "trailnav/perception/place/sequence.hpp"

namespace trailnav::perception::place {

struct GroundTruth {
  std::vector<int> reference;  // per query: its database index, -1 for none
  std::vector<int> tolerance;  // per query
  bool correct(const Match& m) const noexcept {
    if (m.query < 0 || static_cast<std::size_t>(m.query) >= reference.size()) return false;
    const int r = reference[static_cast<std::size_t>(m.query)];
    const int d = m.database - r;
    return r >= 0 && (d < 0 ? -d : d) <= tolerance[static_cast<std::size_t>(m.query)];
  }
  std::size_t positives() const noexcept;  // queries with a place
};

struct PrPoint {
  double threshold = 0.0;
  double precision = 0.0;
  double recall = 0.0;
  double f1 = 0.0;
  std::size_t matches = 0;
  std::size_t true_matches = 0;
};

struct PrCurve {
  std::vector<PrPoint> points;  // by threshold, descending
  PrPoint best;                 // of the largest F1
};

// One set of matches scored.
PrPoint score(std::span<const Match> matches, const GroundTruth& truth, double threshold = 0.0);

// Every match whose score is at least t, for t over the matches' scores
// (descending; at most `max_points` points kept evenly, the best always).
PrCurve sweep(std::vector<Match> matches, const GroundTruth& truth, std::size_t max_points = 400);

// The curve of points scored one threshold at a time (thresholds descending).
PrCurve curve_of(std::vector<PrPoint> points);

}  // namespace trailnav::perception::place
