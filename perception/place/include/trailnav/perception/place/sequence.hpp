// The sequence filter of the thesis' §5.3: matches are the local peaks of
// the belief matrix B above p_min, kept only where they form sequences.
//
// A peak: B(i, j) ≥ p_min and the largest of row i within ±radius columns
// (of equal values the leftmost), so that a neighbourhood of high belief is
// one match and a row may hold several (a database that passes a place
// twice).
//
// A sequence (Eq. 5.10): matches (i_1, j_1) ... (i_n, j_n) with
// 0 < i_{k+1} - i_k ≤ g_r and |j_{k+1} - j_k| ≤ g_c, n ≥ l_s. The thesis keeps
// "the union of the sequences"; here a match is kept when the longest chain
// of matches through it (longest ending there + longest starting there - 1,
// by dynamic programming over the rows) is at least l_s, which is that union.
#pragma once

#include <span>
#include <vector>

#include "trailnav/perception/place/similarity.hpp"

namespace trailnav::perception::place {

struct Match {
  int query = 0;
  int database = 0;
  float score = 0.0f;
  friend bool operator==(const Match&, const Match&) = default;
};

struct SequenceConfig {
  int min_length = 20;  // l_s (the thesis: 16-47, set per data set)
  int row_gap = 5;      // g_r
  int column_gap = 5;   // g_c
};

// The local peaks of every row of `b` at or above p_min, by row then column.
std::vector<Match> row_peaks(const Matrix& b, float p_min, int radius);

// The matches of `peaks` (sorted by query, then database) that lie on a
// sequence, in the same order.
std::vector<Match> sequence_filter(std::span<const Match> peaks, const SequenceConfig& config);

}  // namespace trailnav::perception::place
