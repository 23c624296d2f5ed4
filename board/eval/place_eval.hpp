// `trailnav place-eval`: the thesis' chapter 5 measured on two image
// sequences, a database (an earlier run) and queries (a later one in another
// season), against ground truth (docs/place.md).
//
// Methods (the report's `method`):
//   raw             each query's best cosine match (the thesis' Raw_BM),
//                   thresholded on its similarity;
//   filter          each query's most likely place in B (Eq. 5.9) over
//                   S̃ = Eq. 5.4(Eq. 5.3(S)), thresholded on its belief;
//   filter+seq      the local peaks of B above p_min kept only in sequences
//                   (§5.3), p_min swept;
//   zca+filter, zca+filter+seq   with S̃ = Eq. 5.4(ZCA(S)) (§5.4);
//   seqslam         SeqSLAM from its paper (seqslam.hpp);
//   online          the robot's causal filter (perception/place/online.hpp):
//                   queries one at a time, ZCA learnt from the database
//                   against itself (as place-map stores it), each query's
//                   most likely place in the forward belief;
//   online+lag      the same, the answer for each query given `online_lag`
//                   queries later from the fixed-lag smoothed belief;
//   online+lag+seq  those of online+lag that pass the online sequence test.
//                   (The last `online_lag` queries get no lagged answer.)
// Each gives a precision-recall curve over its threshold and its best F1.
//
// Cases (`case`): `connected`, the query sequence as recorded; and
// `scattered-1` ... `scattered-3`, built from it as the thesis' Seq 1, 2, 5
// are shaped: the queries cut into chunks of 20-150 images, replayed in a
// shuffled order with some chunks twice (revisits, jumps back and forth,
// loops), and a stretch of the database left out so that some queries have
// no place (docs/place.md gives each case's seed and shape).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "seqslam.hpp"
#include "trailnav/perception/place/bayes_filter.hpp"
#include "trailnav/perception/place/evaluation.hpp"
#include "trailnav/perception/place/hog.hpp"

namespace trailnav::eval {

struct PlaceEvalOptions {
  std::string database;      // a directory of PNG frames
  std::string query;         // the same
  std::string ground_truth;  // "" none, "same-index", or a CSV file `query,reference[,tolerance]` (1-based)
  int tolerance = -1;        // frames; -1: the CSV's third column, else 5 (the thesis: fewer than six)
  int subsample = 1;         // every n-th image of each directory, from the first
  int max_images = 0;        // per sequence after subsampling, 0: all
  std::string case_name = "connected";
  perception::place::HogConfig hog{0};  // patch 0: auto_patch()
  bool compact = true;  // descriptors as bytes (similarity.hpp)
  perception::place::TransitionModel transition;
  perception::place::SequenceConfig sequence;
  int peak_radius = 50;  // a peak is the largest belief within ±this many database images
  double zca_epsilon = 0.1;  // relative to Σ's mean eigenvalue
  bool zca_after_columns = false;
  bool zca_from_database = false;  // Σ from the database against itself, not from the queries (what a robot has)  // Eq. 5.3, then ZCA, then Eq. 5.4 (the other order, measured)
  bool seqslam = true;
  SeqSlamConfig seqslam_config;
  bool online = true;
  int online_lag = 10;
  perception::place::SequenceConfig online_sequence{10, 5, 5};
  int online_zca_rank = 200;       // as place-map
  double online_zca_epsilon = 0.3;
  std::function<void(const std::string& stage, double fraction)> progress;
};

struct PlaceMethod {
  std::string method;
  perception::place::PrCurve curve;
  std::vector<perception::place::Match> matches;  // at the best F1
};

struct PlaceEvalReport {
  std::string error;
  std::size_t database_images = 0, query_images = 0, positives = 0;
  int width = 0, height = 0, descriptor_length = 0, patch = 0;
  std::size_t descriptor_bytes = 0;  // per image as stored
  std::vector<int> query_order;      // the case's queries as indices into the query directory's images
  perception::place::GroundTruth truth;
  std::vector<PlaceMethod> methods;
  double seconds_descriptors = 0.0, seconds_similarity = 0.0, seconds_zca = 0.0, seconds_filters = 0.0,
         seconds_seqslam = 0.0, seconds_online = 0.0;
};

PlaceEvalReport run_place_eval(const PlaceEvalOptions& options);

// The scattered cases' query order and the database images left out, from
// a connected sequence of n images (the case's number picks the seed and
// the shape); empty for "connected" or an unknown name.
struct ScatteredCase {
  std::vector<int> query_order;
  int database_gap_begin = 0, database_gap_end = 0;  // left out: [begin, end)
};
bool scattered_case(const std::string& name, int images, ScatteredCase& out);

}  // namespace trailnav::eval
