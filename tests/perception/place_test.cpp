// Place recognition's pure core (perception/place, thesis chapter 5): HOG,
// the compact descriptors, the O(n_D) prediction against the dense
// transition of Eq. 5.7, the forward-backward belief, ZCA, peaks, the
// sequence filter and the scores; on real Nordland frames where it matters.
#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <random>

#include <Eigen/Eigenvalues>

#include "test_data.hpp"
#include "trailnav/drivers/camera/image_file.hpp"
#include "trailnav/perception/place/bayes_filter.hpp"
#include "trailnav/perception/place/evaluation.hpp"
#include "trailnav/perception/place/hog.hpp"
#include "trailnav/perception/place/online.hpp"
#include "trailnav/perception/place/sequence.hpp"
#include "trailnav/perception/place/similarity.hpp"
#include "trailnav/runtime/alloc_guard.hpp"

namespace trailnav::perception::place {
namespace {

namespace camera = drivers::camera;

std::string nordland(const std::string& season, int frame) {
  char name[64];
  std::snprintf(name, sizeof name, "nordland/%s/images-%05d.png", season.c_str(), frame);
  return test::shared_data(name);
}

double norm(const std::vector<float>& v) {
  double s = 0.0;
  for (float x : v) s += static_cast<double>(x) * static_cast<double>(x);
  return std::sqrt(s);
}

TEST(Hog, TheThesisPatchIs128ValuesAndSmallImagesGetSmallerPatches) {
  EXPECT_EQ(auto_patch(1024, 768), 32);
  EXPECT_EQ(auto_patch(64, 32), 16);
  EXPECT_EQ(auto_patch(16, 16), 4);
  Hog thesis(HogConfig{}, 1024, 768);
  EXPECT_EQ(thesis.length(), 98'304);  // §5.4's dimension: 32 x 24 patches of 128
  Hog small(HogConfig{0}, 64, 32);
  EXPECT_EQ(small.config().patch, 16);
  EXPECT_EQ(small.length(), 8 * 128);
  EXPECT_THROW(Hog(HogConfig{32}, 20, 20), std::invalid_argument);
  EXPECT_THROW(Hog(HogConfig{30, 4}, 64, 64), std::invalid_argument);
}

TEST(Hog, AnEdgeVotesForItsOrientationAndTheDescriptorHasUnitLength) {
  // A vertical edge (dark left, bright right): horizontal gradients, angle 0,
  // which bins 0 and 7 (centres at ±11.25°) share equally.
  const int w = 32, h = 32;
  std::vector<std::uint8_t> image(static_cast<std::size_t>(w * h));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) image[static_cast<std::size_t>(y * w + x)] = x < 16 ? 20 : 200;
  Hog hog(HogConfig{32, 4, 8}, w, h);
  std::vector<float> f(static_cast<std::size_t>(hog.length()));
  hog.compute(image, w, f);
  EXPECT_NEAR(norm(f), 1.0, 1e-5);
  double bin0 = 0, bin7 = 0, rest = 0;
  for (std::size_t k = 0; k < f.size(); ++k) {
    const std::size_t b = k % 8;
    (b == 0 ? bin0 : b == 7 ? bin7 : rest) += static_cast<double>(f[k]);
  }
  EXPECT_GT(bin0, 0.5);
  EXPECT_NEAR(bin0, bin7, 1e-5);
  EXPECT_EQ(rest, 0.0);
  // The reversed edge is the same descriptor (unsigned orientations).
  for (auto& p : image) p = static_cast<std::uint8_t>(220 - p);
  std::vector<float> g(f.size());
  hog.compute(image, w, g);
  for (std::size_t k = 0; k < f.size(); ++k) EXPECT_FLOAT_EQ(f[k], g[k]);
  // A flat image has no gradients: all zero, not NaN.
  std::fill(image.begin(), image.end(), 90);
  hog.compute(image, w, g);
  for (float v : g) EXPECT_EQ(v, 0.0f);
}

TEST(Hog, RealNordlandFramesWithoutTheHeapAndTheirCompactCosines) {
  camera::ImageRead a = camera::read_grey_image(nordland("summer", 5000));
  camera::ImageRead b = camera::read_grey_image(nordland("winter", 5000));
  camera::ImageRead c = camera::read_grey_image(nordland("winter", 15000));
  ASSERT_TRUE(a.ok()) << a.error;
  ASSERT_TRUE(b.ok() && c.ok());
  ASSERT_EQ(a.image.width, 64);
  ASSERT_EQ(a.image.height, 32);
  Hog hog(HogConfig{0}, 64, 32);
  std::vector<float> fa(static_cast<std::size_t>(hog.length())), fb(fa.size()), fc(fa.size());
  hog.compute(a.image.pixels, 64, fa);  // first touch
  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("place");
  ASSERT_TRUE(alloc_guard::arm());
  hog.compute(a.image.pixels, 64, fa);
  hog.compute(b.image.pixels, 64, fb);
  hog.compute(c.image.pixels, 64, fc);
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  const auto dot = [](const std::vector<float>& x, const std::vector<float>& y) {
    return std::inner_product(x.begin(), x.end(), y.begin(), 0.0);
  };
  EXPECT_NEAR(norm(fa), 1.0, 1e-5);
  // The same place across seasons is more alike than another place.
  EXPECT_GT(dot(fa, fb), dot(fa, fc));
  CompactDescriptors packed;
  packed.add(fa);
  packed.add(fb);
  packed.add(fc);
  EXPECT_EQ(packed.codes.size(), 3u * fa.size());
  EXPECT_NEAR(cosine(packed.code(0), packed.norms[0], packed.code(1), packed.norms[1]), dot(fa, fb), 0.01);
  EXPECT_NEAR(cosine(packed.code(0), packed.norms[0], packed.code(2), packed.norms[2]), dot(fa, fc), 0.01);
  EXPECT_NEAR(cosine(packed.code(0), packed.norms[0], packed.code(0), packed.norms[0]), 1.0, 1e-6);
}

// The dense transition of Eq. 5.7 for a small database, as the thesis
// writes it, each row x' (the source) scaled by the sum of a row that lies
// inside the database (the bands' mass past the ends is lost).
std::vector<double> dense_prediction(const std::vector<double>& belief, const TransitionModel& m, bool reversed) {
  const int n = static_cast<int>(belief.size());
  std::vector<double> out(belief.size(), 0.0);
  for (int src = 0; src < n; ++src) {
    std::vector<double> row(belief.size());
    const double sum = n + (m.c_f - 1.0) * (m.f - 1) + (m.c_s - 1.0) + (m.c_b - 1.0) * (m.b - 1);
    for (int x = 0; x < n; ++x) {
      const int d = reversed ? src - x : x - src;
      const double w = (d > 0 && d < m.f) ? m.c_f : d == 0 ? m.c_s : (d < 0 && d > -m.b) ? m.c_b : 1.0;
      row[static_cast<std::size_t>(x)] = w;
    }
    for (int x = 0; x < n; ++x) out[static_cast<std::size_t>(x)] += belief[static_cast<std::size_t>(src)] * row[static_cast<std::size_t>(x)] / sum;
  }
  return out;
}

TEST(BayesFilter, ThePrefixSumPredictionIsTheDenseTransitionOfEq5_7) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (bool reversed : {false, true}) {
    for (int n : {1, 2, 4, 9, 40}) {
      TransitionModel m;
      BayesFilter filter(static_cast<std::size_t>(n), m, reversed);
      std::vector<float> likelihood(static_cast<std::size_t>(n));
      for (float& l : likelihood) l = static_cast<float>(u(rng));
      filter.update(likelihood);  // a belief that is not uniform
      std::vector<double> before(filter.belief().begin(), filter.belief().end());
      filter.predict();
      const std::vector<double> want = dense_prediction(before, m, reversed);
      double total = 0.0;
      for (int i = 0; i < n; ++i) {
        EXPECT_NEAR(filter.belief()[static_cast<std::size_t>(i)], want[static_cast<std::size_t>(i)], 1e-12) << n << " " << i;
        total += filter.belief()[static_cast<std::size_t>(i)];
      }
      EXPECT_LE(total, 1.0 + 1e-12);  // only what passes the ends is lost
      if (n == 40) {
        EXPECT_GT(total, 0.9);
      }
    }
  }
  EXPECT_THROW(BayesFilter(0, TransitionModel{}), std::invalid_argument);
  EXPECT_THROW(BayesFilter(5, TransitionModel{0}), std::invalid_argument);
}

TEST(BayesFilter, AStepAllocatesNothingAndAFlatLikelihoodKeepsThePrediction) {
  BayesFilter filter(10'000, TransitionModel{});
  std::vector<float> likelihood(10'000, 0.5f);
  likelihood[1234] = 1.0f;
  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("place");
  ASSERT_TRUE(alloc_guard::arm());
  for (int k = 0; k < 5; ++k) filter.step(likelihood);
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  const auto bel = filter.belief();
  EXPECT_EQ(std::max_element(bel.begin(), bel.end()) - bel.begin(), 1234);
  std::vector<float> zero(10'000, 0.0f);
  filter.step(zero);
  double total = 0.0;
  for (double v : filter.belief()) total += v;
  EXPECT_NEAR(total, 1.0, 1e-9);
}

TEST(BayesFilter, ForwardBackwardFollowsAPathThroughNoise) {
  // Queries 0..59 walk the database at one image a query from 100, with a
  // jump back to 30 at query 30; the likelihood is noise, and 1 on the path.
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> noise(0.0f, 0.6f);
  Matrix l(60, 300);
  std::vector<int> truth;
  for (int i = 0; i < 60; ++i) {
    const int place = i < 30 ? 100 + i : 30 + (i - 30);
    truth.push_back(place);
    for (int j = 0; j < 300; ++j) l(i, j) = noise(rng);
    l(i, place) = 1.0f;
  }
  const Matrix b = forward_backward(l, TransitionModel{});
  int right = 0;
  for (int i = 0; i < 60; ++i) {
    Eigen::Index j = 0;
    b.row(i).maxCoeff(&j);
    right += std::abs(static_cast<int>(j) - truth[static_cast<std::size_t>(i)]) <= 1 ? 1 : 0;
    EXPECT_NEAR(b.row(i).sum(), 1.0f, 1e-4f);
  }
  EXPECT_GE(right, 58);
  // The forward pass alone lags at the jump: it needs queries to move its mass.
  const Matrix f = forward_pass(l, TransitionModel{});
  Eigen::Index at_jump = 0;
  f.row(30).maxCoeff(&at_jump);
  Eigen::Index smoothed = 0;
  b.row(30).maxCoeff(&smoothed);
  EXPECT_GT(at_jump, 100);  // still on the first stretch
  EXPECT_EQ(smoothed, 30);
}

// The online filter's fixed lag: the answer for step t - L is Eq. 5.9 over
// the window (the forward belief of all the steps so far, the backward pass
// over the last L + 1 rows from a uniform belief), which is what the offline
// forward_backward gives when the sequence ends at t; and the sequence test
// refuses the steps just after a jump until the chain through them is l_s
// long again. Nothing is allocated per step.
TEST(OnlinePlace, TheFixedLagIsEq5_9OverItsWindowAndTheSequenceTestWaitsOutAJump) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> noise(0.0f, 0.6f);
  OnlineConfig config;
  config.width = 64;
  config.height = 32;
  config.capacity = 300;
  config.lag = 5;
  config.sequence = {8, 5, 5};
  OnlinePlace online(config);
  std::vector<float> d(static_cast<std::size_t>(online.descriptor_length()));
  for (int j = 0; j < 300; ++j) {
    for (float& v : d) v = noise(rng);
    ASSERT_TRUE(online.add_database(d));
  }
  online.finish_database();
  // Queries 0..59 walk the database from 100 at one image a query, then
  // jump back to 30 at query 30; raw similarities are noise, 1 on the path.
  constexpr int kQueries = 60;
  std::vector<std::vector<float>> raw(kQueries, std::vector<float>(300));
  std::vector<int> truth;
  for (int i = 0; i < kQueries; ++i) {
    const int place = i < 30 ? 100 + i : 30 + (i - 30);
    truth.push_back(place);
    for (float& v : raw[static_cast<std::size_t>(i)]) v = noise(rng);
    raw[static_cast<std::size_t>(i)][static_cast<std::size_t>(place)] = 1.0f;
  }
  Matrix likelihood(kQueries, 300);
  std::vector<LaggedEstimate> answers;
  std::vector<std::vector<double>> smoothed;
  answers.reserve(kQueries);
  smoothed.reserve(kQueries);
  for (int i = 0; i < kQueries; ++i) {
    const bool guarded = i == 20;  // one step under the guard (the first ones fill the ring)
    if (guarded) {
      alloc_guard::set_fatal(false);
      alloc_guard::mark_realtime_thread("place");
      ASSERT_TRUE(alloc_guard::arm());
    }
    online.step_similarities(raw[static_cast<std::size_t>(i)]);
    if (guarded) {
      alloc_guard::disarm();
      alloc_guard::unmark_current_thread();
      EXPECT_EQ(alloc_guard::total_allocations(), 0u);
    }
    for (int j = 0; j < 300; ++j) likelihood(i, j) = online.likelihood()[static_cast<std::size_t>(j)];
    answers.push_back(online.lagged());
    smoothed.emplace_back(online.lagged_belief().begin(), online.lagged_belief().end());
  }
  for (int i = 0; i < 5; ++i) EXPECT_FALSE(answers[static_cast<std::size_t>(i)].valid) << i;
  for (int t : {5, 17, 31, 34, 59}) {
    const LaggedEstimate& e = answers[static_cast<std::size_t>(t)];
    ASSERT_TRUE(e.valid);
    EXPECT_EQ(e.step, static_cast<std::uint64_t>(t - 5));
    const Matrix b = forward_backward(likelihood.topRows(t + 1), TransitionModel{});
    for (int j = 0; j < 300; ++j)
      EXPECT_NEAR(smoothed[static_cast<std::size_t>(t)][static_cast<std::size_t>(j)], b(t - 5, j), 1e-5) << t << "," << j;
  }
  int right = 0;
  for (int t = 5; t < kQueries; ++t) {
    const LaggedEstimate& e = answers[static_cast<std::size_t>(t)];
    right += std::abs(e.index - truth[e.step]) <= 1 ? 1 : 0;
  }
  EXPECT_GE(right, 53);  // of 55
  // The sequence test: on the first stretch long chains; at the jump (step
  // 30) the chain is 1 + the look-ahead's, whose forward beliefs reach the
  // new stretch only after two frames (measured: 4, 6, 7 at steps 30-32,
  // then 8, 10, 11 ...).
  EXPECT_TRUE(answers[25].in_sequence) << answers[25].chain;
  EXPECT_EQ(answers[35].step, 30u);
  EXPECT_FALSE(answers[35].in_sequence) << answers[35].chain;
  EXPECT_EQ(answers[35].index, 30);  // the smoothed answer is already right
  EXPECT_FALSE(answers[37].in_sequence) << answers[37].chain;
  EXPECT_TRUE(answers[38].in_sequence) << answers[38].chain;
  EXPECT_EQ(answers[38].index, 33);
  EXPECT_TRUE(answers[59].in_sequence);
  EXPECT_GE(answers[59].chain, 25);
  // Lag 0: the answer is the forward belief's, for the step just taken.
  config.lag = 0;
  OnlinePlace causal(config);
  for (int j = 0; j < 300; ++j) causal.add_database(std::vector<float>(d.size(), 0.1f + 0.001f * static_cast<float>(j)));
  causal.finish_database();
  const PlaceEstimate e = causal.step_similarities(raw[3]);
  EXPECT_TRUE(causal.lagged().valid);
  EXPECT_EQ(causal.lagged().step, 0u);
  EXPECT_EQ(causal.lagged().index, e.index);
  EXPECT_DOUBLE_EQ(causal.lagged().probability, e.probability);
  config.peaks_per_row = 0;
  EXPECT_THROW(OnlinePlace{config}, std::invalid_argument);
  config.peaks_per_row = 4;
  config.lag = -1;
  EXPECT_THROW(OnlinePlace{config}, std::invalid_argument);
}

TEST(Similarity, TheTwoNormalisationsOfEq5_3And5_4) {
  Matrix s(3, 2);
  s << 0.2f, 0.8f, 0.4f, 0.4f, 0.6f, 0.3f;
  normalise_columns(s);  // column means 0.4 and 0.5
  EXPECT_FLOAT_EQ(s(0, 0), 0.5f);
  EXPECT_FLOAT_EQ(s(0, 1), 1.6f);
  stretch_rows(s);
  EXPECT_FLOAT_EQ(s(0, 0), 0.0f);
  EXPECT_FLOAT_EQ(s(0, 1), 1.0f);
  EXPECT_FLOAT_EQ(s(1, 0), 1.0f);  // 1.0 against 0.8
  EXPECT_FLOAT_EQ(s(1, 1), 0.0f);
}

TEST(Similarity, ZcaWhitensAndBothPathsAgree) {
  std::mt19937 rng(3);
  std::normal_distribution<float> g(0.0f, 1.0f);
  // Correlated columns: many rows (n_Q > n_D, the covariance path).
  Matrix s(400, 6);
  for (int i = 0; i < 400; ++i) {
    const float common = g(rng);
    for (int j = 0; j < 6; ++j) s(i, j) = common * 0.9f + 0.3f * g(rng) + static_cast<float>(j);
  }
  const Matrix w = zca_whiten(s, 1e-9);
  const Eigen::MatrixXd c = w.cast<double>().transpose() * w.cast<double>() / 400.0;
  for (int a = 0; a < 6; ++a)
    for (int b = 0; b < 6; ++b) EXPECT_NEAR(c(a, b), a == b ? 1.0 : 0.0, 1e-3) << a << "," << b;
  // The Gram path (n_Q ≤ n_D) against Eq. 5.14 written out.
  Matrix t(5, 12);
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 12; ++j) t(i, j) = g(rng);
  const Matrix gram = zca_whiten(t, 0.1);
  Eigen::MatrixXd centred = t.cast<double>();
  centred.rowwise() -= centred.colwise().mean();
  const Eigen::MatrixXd sigma = centred.transpose() * centred / 5.0;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(sigma);
  const double epsilon = 0.1 * eig.eigenvalues().sum() / 5.0;  // the mean over the rank min(n_Q, n_D)
  const Eigen::MatrixXd direct = centred * eig.eigenvectors() *
                                 (eig.eigenvalues().array().max(0.0) + epsilon).rsqrt().matrix().asDiagonal() *
                                 eig.eigenvectors().transpose();
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 12; ++j) EXPECT_NEAR(gram(i, j), direct(i, j), 1e-4);
}

// The whitening learnt from a database's codes (real Nordland frames): the
// randomised subspace iteration finds the full solve's largest directions
// and gains; a whitened row is what Eq. 5.14 gives with those directions.
TEST(Whitening, TheRandomisedSolveFindsTheFullSolvesLargestDirections) {
  Hog hog(HogConfig{0}, 64, 32);
  std::vector<float> f(static_cast<std::size_t>(hog.length()));
  CompactDescriptors db;
  for (int k = 0; k < 300; ++k) {
    const camera::ImageRead r = camera::read_grey_image(nordland("summer", 10 * (k + 1)));
    ASSERT_TRUE(r.ok()) << r.error;
    hog.compute(r.image.pixels, 64, f);
    db.add(f);
  }
  const Whitening full = learn_whitening(db.codes, db.norms, db.length, 20, 0.3);
  const Whitening fast = learn_whitening(db.codes, db.norms, db.length, 20, 0.3, 100);  // forced
  ASSERT_EQ(full.rank, 20);
  ASSERT_EQ(fast.rank, 20);
  EXPECT_FLOAT_EQ(full.base, fast.base);
  for (std::size_t j = 0; j < 300; ++j) EXPECT_FLOAT_EQ(full.mean[j], fast.mean[j]);
  for (int c = 0; c < 5; ++c) {  // the leading ones, where the iteration has converged
    EXPECT_NEAR(full.gains[static_cast<std::size_t>(c)], fast.gains[static_cast<std::size_t>(c)],
                1e-3f * std::abs(full.gains[static_cast<std::size_t>(c)]));
    double dot = 0.0;
    for (std::size_t j = 0; j < 300; ++j)
      dot += static_cast<double>(full.directions[j * 20 + static_cast<std::size_t>(c)]) *
             static_cast<double>(fast.directions[j * 20 + static_cast<std::size_t>(c)]);
    EXPECT_GT(std::abs(dot), 0.999) << c;  // unit vectors, up to their sign
  }
  // Gains shrink the largest directions (λ + ε > ε): negative, largest first in size.
  EXPECT_LT(full.gains[0], full.gains[19]);
  EXPECT_LT(full.gains[19], 0.0f);
  EXPECT_EQ(learn_whitening(db.codes, db.norms, db.length, 0, 0.3).rank, 0);
  EXPECT_EQ(learn_whitening(std::span(db.codes).first(2048), std::span(db.norms).first(2), db.length, 50, 0.3).rank, 1);
}

TEST(Sequence, PeaksAndTheLongestChainsThroughThem) {
  Matrix b = Matrix::Zero(3, 8);
  b.row(0) << 0.1f, 0.5f, 0.5f, 0.1f, 0.0f, 0.3f, 0.2f, 0.0f;
  b.row(1) << 0.9f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f;
  const std::vector<Match> p = row_peaks(b, 0.2f, 1);
  ASSERT_EQ(p.size(), 3u);  // row 0: column 1 (the leftmost of equals) and 5; row 1: 0; row 2 below p_min
  EXPECT_EQ(p[0], (Match{0, 1, 0.5f}));
  EXPECT_EQ(p[1], (Match{0, 5, 0.3f}));
  EXPECT_EQ(p[2], (Match{1, 0, 0.9f}));

  // A chain of 6 with a row gap of 2 and column steps up to 3; a stray match;
  // a chain of 4.
  std::vector<Match> peaks;
  for (int k = 0; k < 6; ++k) peaks.push_back({k * 2, 100 + 3 * k, 1.0f});
  peaks.push_back({5, 400, 1.0f});
  for (int k = 0; k < 4; ++k) peaks.push_back({20 + k, 10 + k, 1.0f});
  std::sort(peaks.begin(), peaks.end(), [](const Match& a, const Match& b2) {
    return a.query != b2.query ? a.query < b2.query : a.database < b2.database;
  });
  SequenceConfig config{6, 2, 3};
  std::vector<Match> kept = sequence_filter(peaks, config);
  ASSERT_EQ(kept.size(), 6u);
  for (const Match& m : kept) EXPECT_LT(m.database, 120);
  config.min_length = 4;
  EXPECT_EQ(sequence_filter(peaks, config).size(), 10u);
  config.row_gap = 1;  // the first chain breaks into single matches
  EXPECT_EQ(sequence_filter(peaks, config).size(), 4u);
  config = {6, 2, 2};  // its column steps of 3 too
  EXPECT_TRUE(sequence_filter(peaks, config).empty());
  EXPECT_TRUE(sequence_filter({}, config).empty());
}

TEST(Evaluation, PrecisionRecallAndTheBestF1) {
  GroundTruth truth;
  truth.reference = {10, 20, 30, -1};
  truth.tolerance = {2, 2, 2, 2};
  EXPECT_EQ(truth.positives(), 3u);
  std::vector<Match> matches = {{0, 11, 0.9f}, {1, 25, 0.8f}, {2, 30, 0.7f}, {3, 5, 0.6f}, {0, 9, 0.5f}};
  const PrPoint all = score(matches, truth);
  EXPECT_EQ(all.matches, 5u);
  EXPECT_EQ(all.true_matches, 3u);
  EXPECT_DOUBLE_EQ(all.precision, 0.6);
  EXPECT_DOUBLE_EQ(all.recall, 2.0 / 3.0);  // queries 0 and 2 found; 0 twice counts once
  const PrCurve c = sweep(matches, truth);
  ASSERT_EQ(c.points.size(), 5u);
  EXPECT_DOUBLE_EQ(c.points[0].precision, 1.0);
  EXPECT_DOUBLE_EQ(c.points[0].recall, 1.0 / 3.0);
  // Best: the first three (P 2/3, R 2/3) against the first one (P 1, R 1/3).
  EXPECT_FLOAT_EQ(static_cast<float>(c.best.threshold), 0.7f);
  EXPECT_NEAR(c.best.f1, 2.0 / 3.0, 1e-12);
}

TEST(ImageFile, NordlandFramesAreGreyAndBadFilesAreRefusedByName) {
  // Frames 1-17 of each season are copies of one frame (the data's README).
  const camera::ImageRead a = camera::read_grey_image(nordland("winter", 10));
  const camera::ImageRead b = camera::read_grey_image(nordland("winter", 170));
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a.image.pixels, b.image.pixels);
  EXPECT_EQ(a.image.pixels.size(), 64u * 32u);
  const camera::ImageList list = camera::list_images(test::shared_data("nordland/summer"));
  ASSERT_TRUE(list.error.empty()) << list.error;
  ASSERT_EQ(list.paths.size(), 2400u);
  EXPECT_NE(list.paths.front().find("images-00010.png"), std::string::npos);
  EXPECT_NE(list.paths.back().find("images-24000.png"), std::string::npos);

  const camera::ImageRead text = camera::read_grey_image(test::shared_data("README.md"));
  EXPECT_FALSE(text.ok());
  EXPECT_NE(text.error.find("README.md"), std::string::npos);
  EXPECT_FALSE(camera::read_grey_image("/nonexistent/frame.png").ok());
  EXPECT_FALSE(camera::list_images("/nonexistent").error.empty());
  EXPECT_FALSE(camera::list_images(test::shared_data("kitti")).error.empty());  // no PNG there
  // A PNG cut short.
  FILE* in = std::fopen(nordland("summer", 5000).c_str(), "rb");
  ASSERT_NE(in, nullptr);
  std::vector<unsigned char> bytes(100000);
  bytes.resize(std::fread(bytes.data(), 1, bytes.size(), in));
  std::fclose(in);
  const std::string cut = ::testing::TempDir() + "/cut.png";
  FILE* out = std::fopen(cut.c_str(), "wb");
  ASSERT_NE(out, nullptr);
  std::fwrite(bytes.data(), 1, bytes.size() / 2, out);
  std::fclose(out);
  const camera::ImageRead truncated = camera::read_grey_image(cut);
  EXPECT_FALSE(truncated.ok());
  EXPECT_NE(truncated.error.find("cut.png"), std::string::npos);
  // And a limit on size.
  EXPECT_FALSE(camera::read_grey_image(nordland("summer", 5000), 1000).ok());
}

}  // namespace
}  // namespace trailnav::perception::place
