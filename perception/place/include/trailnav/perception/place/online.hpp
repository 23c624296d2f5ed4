// Place recognition one query at a time, for the robot (issue 41): a
// database of compact descriptors loaded at start-up, then per camera frame
// its HOG descriptor, its cosine similarities to every database image, the
// normalisations of Eq. 5.3 and 5.4 and one step of the forward filter
// (Eq. 5.6). Everything is sized at construction; describe(), step() and
// most_likely() allocate nothing.
//
// Eq. 5.3 divides by each database image's mean similarity over all
// queries, which a robot cannot know before it has driven: here the mean over
// the queries so far, started from `prior_queries` pseudo-queries at the
// database image's mean similarity to the database's other images (what it
// resembles in general), so that the first frames are normalised too.
//
// The fixed lag (§5.2 and §5.3 on a robot): the offline Eq. 5.9 combines the
// forward belief with a backward pass from the sequence's end, which a robot
// never reaches. Here the answer for frame t - L is given at frame t: its
// forward belief combined, as Eq. 5.9, with a backward pass over the L + 1
// likelihood rows t, t-1, ..., t-L started from a uniform belief at t (the
// last L + 1 rows are kept in a ring). The sequence test of §5.3 then asks
// whether that answer lies on a chain of peaks (|Δrow| ≤ g_r, |Δcolumn| ≤
// g_c): the longest chain ending at it through the smoothed peaks of earlier
// frames (kept with their chain lengths, g_r frames back), plus the longest
// starting at it through the forward beliefs' peaks of the L frames after
// it, at least l_s long. A row's peaks: its `peaks_per_row` largest beliefs
// at or above the uniform 1/n_D, each the largest within ±peak_radius of
// the ones already taken (the offline row_peaks takes every local peak;
// bounded here so a step's cost is).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "trailnav/perception/place/bayes_filter.hpp"
#include "trailnav/perception/place/hog.hpp"
#include "trailnav/perception/place/sequence.hpp"
#include "trailnav/perception/place/similarity.hpp"

namespace trailnav::perception::place {

struct OnlineConfig {
  HogConfig hog{0};
  TransitionModel transition;
  int width = 0, height = 0;   // of the camera's grey frames
  std::size_t capacity = 0;    // database images at most
  double prior_queries = 10.0;
  // The fixed lag (frames) of the smoothed answer, and the online sequence
  // test (min_length 0: none; the answer is then always `in_sequence`).
  int lag = 0;
  SequenceConfig sequence{0, 5, 5};
  int peak_radius = 50;
  int peaks_per_row = 4;
};

// ZCA whitening learnt from the database against itself (docs/place.md "ZCA
// for the robot"), kept to its `rank` largest directions: a query's raw
// similarities s become (s - mean) W with W ≈ base I + U diag(gains) Uᵀ,
// base = ε^-1/2, gains = (λ + ε)^-1/2 - ε^-1/2. It takes Eq. 5.3's place.
struct Whitening {
  int rank = 0;  // 0: none
  float epsilon_relative = 0.0f;
  float base = 0.0f;
  std::vector<float> mean;        // n_D
  std::vector<float> gains;       // rank
  std::vector<float> directions;  // n_D x rank, row-major
};

// From a database's codes (count x length bytes) and their lengths: the
// self-similarity matrix's column means and the `rank` largest
// eigen-directions of its covariance (by a full solve up to
// `full_solve_up_to` images, else by randomised subspace iteration); ε = epsilon_relative
// x the covariance's mean eigenvalue. Offline (place-map): allocates.
Whitening learn_whitening(std::span<const std::uint8_t> codes, std::span<const float> norms, int length, int rank,
                          double epsilon_relative, int full_solve_up_to = 3000);

struct PlaceEstimate {
  int index = -1;        // database image, -1 before a database
  double probability = 0.0;
};

// The answer for an earlier frame: the smoothed belief's most likely image.
struct LaggedEstimate {
  bool valid = false;         // false until lag + 1 frames were stepped
  std::uint64_t step = 0;     // which step it answers (0: the first frame after finish_database())
  int index = -1;             // database image
  double probability = 0.0;   // its smoothed belief
  int chain = 0;              // the longest chain of peaks through it (0: it was no peak)
  bool in_sequence = false;   // chain >= sequence.min_length
};

class OnlinePlace {
 public:
  // Throws std::invalid_argument for a frame no patch fits, a capacity of 0,
  // a negative lag or gap, or peaks_per_row outside 1..16.
  explicit OnlinePlace(const OnlineConfig& config);

  int descriptor_length() const noexcept { return hog_.length(); }
  std::size_t size() const noexcept { return count_; }
  std::size_t capacity() const noexcept { return capacity_; }
  // Bytes the database holds per image (the code and its length).
  std::size_t bytes_per_image() const noexcept { return static_cast<std::size_t>(hog_.length()) + sizeof(float); }

  // Set-up: the database in its recorded order. False when full or the
  // descriptor's length is not this one's. Then finish_database() once (it
  // computes the priors of Eq. 5.3 and starts the filter).
  bool add_database(std::span<const float> descriptor) noexcept;
  // The same from a stored code (database.hpp) and its length.
  bool add_database_code(std::span<const std::uint8_t> code, float norm) noexcept;
  void finish_database() noexcept;

  // ZCA instead of Eq. 5.3 (after finish_database(); sizes must match the
  // database). False when they do not. The directions are kept as bytes
  // (each direction scaled by its largest value), a quarter of the memory.
  bool set_whitening(const Whitening& w);

  // The descriptor of a grey frame (width x height, `stride` bytes a row).
  std::span<const float> describe(std::span<const std::uint8_t> grey, int stride) noexcept;
  // One query: similarities, Eq. 5.3 with the running means (or the
  // whitening), Eq. 5.4, the filter's step. Returns the most likely database image.
  PlaceEstimate step(std::span<const float> descriptor) noexcept;
  // The same from the query's raw cosine similarities to every database
  // image (n_D values; an evaluation that has computed them already).
  PlaceEstimate step_similarities(std::span<const float> similarities) noexcept;
  std::span<const double> belief() const noexcept { return filter_.belief().first(count_); }
  // After each step: the answer for the frame `lag` steps back, and its
  // smoothed belief (n_D values; the forward belief when the lag is 0).
  const LaggedEstimate& lagged() const noexcept { return lagged_; }
  std::span<const double> lagged_belief() const noexcept { return {smoothed_.data(), count_}; }
  int lag() const noexcept { return config_.lag; }
  std::uint64_t steps() const noexcept { return steps_; }
  // The last query's similarities after Eq. 5.3 and 5.4 (the likelihood).
  std::span<const float> likelihood() const noexcept { return {row_.data(), count_}; }

 private:
  OnlineConfig config_;
  Hog hog_;
  std::size_t capacity_;
  std::size_t count_ = 0;
  std::vector<std::uint8_t> codes_;   // capacity x length
  std::vector<float> norms_;
  std::vector<double> column_sum_;    // Σ similarities per database image (prior included)
  double column_count_ = 0.0;
  std::vector<float> descriptor_;
  std::vector<std::uint8_t> query_code_;
  std::vector<float> row_;
  Whitening whitening_;               // its directions kept as bytes below
  std::vector<std::int8_t> directions_q_;  // n_D x rank
  std::vector<float> direction_scale_;     // rank
  std::vector<float> projection_;  // rank
  BayesFilter filter_;

  // The fixed lag: likelihood rows and forward beliefs of the last lag + 1
  // steps (slot = step % (lag + 1)), the backward pass, the smoothed belief.
  struct Peak {
    int column = 0;
    int length = 0;  // the longest chain ending (history) or starting (look-ahead) here
  };
  PlaceEstimate advance() noexcept;  // row_ holds the raw similarities
  void smooth_and_test() noexcept;
  int find_peaks(std::span<const double> belief, Peak* out) const noexcept;
  std::size_t slots_ = 1;
  std::uint64_t steps_ = 0;
  std::vector<float> rows_;       // slots x capacity
  std::vector<double> forward_;   // slots x capacity
  BayesFilter backward_;
  std::vector<double> smoothed_;  // capacity
  // Peaks: the forward beliefs' of the look-ahead (per slot) and the
  // smoothed beliefs' of the last g_r + 1 answered steps (with their
  // chain lengths), peaks_per_row each.
  std::vector<Peak> ahead_;    // slots x peaks_per_row
  std::vector<int> ahead_count_;
  std::vector<Peak> history_;  // (g_r + 1) x peaks_per_row
  std::vector<int> history_count_;
  LaggedEstimate lagged_;
};

}  // namespace trailnav::perception::place
