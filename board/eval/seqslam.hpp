// SeqSLAM (Milford and Wyeth, ICRA 2012), the thesis' comparison (its
// OpenSeqSLAM), written here from the paper for the side-by-side of
// `trailnav place-eval` (docs/place.md); not part of the robot's pipeline.
//
// Images down-sampled (64 x 32 by default, area averages) and normalised
// patch by patch (8 x 8 pixels: zero mean, unit deviation); the difference
// matrix D of mean absolute pixel differences; local contrast enhancement of
// each query's column over a window of ±R database images (D - mean) / std;
// then for every query T and database start, straight trajectories through
// the ds queries centred on T at speeds v_min ... v_max (database images per
// query), scored by the sum of the enhanced differences they pass; the
// query's match is the database image the best trajectory passes at T, its
// confidence the ratio of the best score to the best outside ±R of it
// (Milford and Wyeth's uniqueness test; 1 - best / second here, larger is
// better). OpenSeqSLAM's defaults: ds = 10, R = 10, v 0.8-1.2 in steps of
// 0.1. The enhanced matrix is shifted to be non-negative before the sums
// (the paper's ratio assumes positive scores; where OpenSeqSLAM shifts is
// not stated there).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "trailnav/perception/place/sequence.hpp"

namespace trailnav::eval {

struct SeqSlamConfig {
  int width = 64, height = 32;  // after down-sampling
  int patch = 8;                // patch normalisation
  int window = 10;              // R: contrast enhancement and uniqueness
  int sequence = 10;            // ds
  double v_min = 0.8, v_max = 1.2, v_step = 0.1;
};

// One image prepared: down-sampled to width x height and patch-normalised.
std::vector<float> seqslam_prepare(std::span<const std::uint8_t> grey, int width, int height, const SeqSlamConfig& config);

// The best match of each query (queries whose sequence does not fit are left
// out), with its confidence as the score.
std::vector<perception::place::Match> seqslam_matches(const std::vector<std::vector<float>>& database,
                                                      const std::vector<std::vector<float>>& queries,
                                                      const SeqSlamConfig& config);

}  // namespace trailnav::eval
