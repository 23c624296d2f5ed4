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
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "trailnav/perception/place/bayes_filter.hpp"
#include "trailnav/perception/place/hog.hpp"
#include "trailnav/perception/place/similarity.hpp"

namespace trailnav::perception::place {

struct OnlineConfig {
  HogConfig hog{0};
  TransitionModel transition;
  int width = 0, height = 0;   // of the camera's grey frames
  std::size_t capacity = 0;    // database images at most
  double prior_queries = 10.0;
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

class OnlinePlace {
 public:
  // Throws std::invalid_argument for a frame no patch fits or a capacity of 0.
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
  // database). False when they do not.
  bool set_whitening(const Whitening& w);

  // The descriptor of a grey frame (width x height, `stride` bytes a row).
  std::span<const float> describe(std::span<const std::uint8_t> grey, int stride) noexcept;
  // One query: similarities, Eq. 5.3 with the running means (or the
  // whitening), Eq. 5.4, the filter's step. Returns the most likely database image.
  PlaceEstimate step(std::span<const float> descriptor) noexcept;
  std::span<const double> belief() const noexcept { return filter_.belief().first(count_); }
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
  Whitening whitening_;
  std::vector<float> projection_;  // rank
  BayesFilter filter_;
};

}  // namespace trailnav::perception::place
