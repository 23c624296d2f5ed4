// Traversability from positive and unlabelled examples (thesis chapter 6):
// the cell features on planes and on a real KITTI scan, the vocabulary, the
// χ² test against a worked example, Positive Naive Bayes and Elkan–Noto on
// word distributions whose truth is known, the terrain models, and the
// model file's round trip and its errors.
#include <gtest/gtest.h>

#include <zlib.h>

#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>
#include <vector>

#include "test_data.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/trav_config.hpp"
#include "trailnav/perception/trav_ground.hpp"
#include "trailnav/perception/trav_layer.hpp"
#include "trailnav/perception/trav_online.hpp"
#include "trailnav/perception/trav_recorder.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/perception/trav_learner.hpp"
#include "trailnav/perception/trav_model_file.hpp"
#include "trailnav/perception/trav_vocabulary.hpp"

namespace trailnav::perception::trav {
namespace {

// --- features ---

TEST(TravFeatures, APlaneGivesItsSlopeHeightRangeAndRemission) {
  // 40 points on a plane rising 20° towards +x, remission 40 and 60 alternately.
  const double slope = 20.0 * std::numbers::pi / 180.0;
  CellStats s;
  for (int i = 0; i < 40; ++i) {
    const float x = -0.09f + 0.18f * static_cast<float>(i % 8) / 7.0f;
    const float y = -0.09f + 0.18f * static_cast<float>(i / 8) / 4.0f;
    s.add(x, y, 1.5f + static_cast<float>(std::tan(slope)) * x, i % 2 == 0 ? 40.0f : 60.0f);
  }
  Feature f;
  ASSERT_TRUE(cell_feature(s, f));
  EXPECT_NEAR(f[Dim::slope], 20.0f, 0.5f);
  EXPECT_NEAR(static_cast<double>(f[Dim::max_dz]), 0.18 * std::tan(slope), 1e-4);
  EXPECT_NEAR(f[Dim::remission_mean], 50.0f, 1e-3f);
  EXPECT_NEAR(f[Dim::remission_var], 100.0f, 1e-2f);
  EXPECT_LT(f[Dim::roughness], 1e-6f);
  // From the terrain step's own feature of the same sums: the same bits.
  const FeatureVector terrain = compute_terrain_feature(s);
  Feature g;
  ASSERT_TRUE(cell_feature(s, g, &terrain));
  EXPECT_EQ(g.v, f.v);
}

TEST(TravFeatures, FewerThanFivePointsGiveNoFeature) {
  CellStats s;
  for (int i = 0; i < 4; ++i) s.add(0.01f * static_cast<float>(i), 0.0f, 0.0f, 10.0f);
  Feature f;
  EXPECT_FALSE(cell_feature(s, f));
  s.add(0.05f, 0.02f, 0.0f, 10.0f);
  EXPECT_TRUE(cell_feature(s, f));
}

// The features of a real HDL-64E scan (KITTI 000000, the car on a street
// between buildings and parked cars), the points put into 0.2 m cells in the
// sensor frame, 1.73 m above the road.
TEST(TravFeatures, OnARealKittiScanTheRoadIsFlatAndObstaclesAreTall) {
  // KITTI's format: x, y, z, remission (0..1) as little-endian floats.
  std::ifstream in(test::shared_data("kitti/000000.bin"), std::ios::binary);
  ASSERT_TRUE(in);
  std::vector<float> buffer;
  float v = 0.0f;
  while (in.read(reinterpret_cast<char*>(&v), sizeof v)) buffer.push_back(v);
  ASSERT_GT(buffer.size(), 400000u);
  constexpr int kCells = 200;  // 40 m x 40 m around the sensor
  constexpr float kRes = 0.2f;
  std::vector<CellStats> grid(kCells * kCells);
  for (std::size_t i = 0; i + 3 < buffer.size(); i += 4) {
    const float x = buffer[i], y = buffer[i + 1], z = buffer[i + 2], r = buffer[i + 3] * 255.0f;
    const int cx = static_cast<int>(std::floor(x / kRes)) + kCells / 2;
    const int cy = static_cast<int>(std::floor(y / kRes)) + kCells / 2;
    if (cx < 0 || cy < 0 || cx >= kCells || cy >= kCells) continue;
    const float ox = (static_cast<float>(cx - kCells / 2) + 0.5f) * kRes;
    const float oy = (static_cast<float>(cy - kCells / 2) + 0.5f) * kRes;
    grid[static_cast<std::size_t>(cy) * kCells + static_cast<std::size_t>(cx)].add(x - ox, y - oy, z + 1.73f, r);
  }
  const Vocabulary vocabulary{VocabularyConfig{}};
  int cells = 0, road = 0, road_flat = 0, tall = 0;
  std::vector<bool> used(vocabulary.size(), false);
  for (int cy = 0; cy < kCells; ++cy) {
    for (int cx = 0; cx < kCells; ++cx) {
      Feature f;
      if (!cell_feature(grid[static_cast<std::size_t>(cy) * kCells + static_cast<std::size_t>(cx)], f)) continue;
      ++cells;
      const std::uint32_t w = vocabulary.word(f);
      ASSERT_LT(w, vocabulary.size());
      used[w] = true;
      const float x = (static_cast<float>(cx - kCells / 2) + 0.5f) * kRes, y = (static_cast<float>(cy - kCells / 2) + 0.5f) * kRes;
      if (x > 4.0f && x < 12.0f && std::abs(y) < 1.5f) {  // the lane ahead of the car
        ++road;
        road_flat += (f[Dim::max_dz] < 0.08f && f[Dim::slope] < 10.0f) ? 1 : 0;
      }
      tall += f[Dim::max_dz] > 0.5f ? 1 : 0;
    }
  }
  EXPECT_GT(cells, 4000);
  ASSERT_GT(road, 100);
  EXPECT_GT(road_flat, road * 9 / 10) << road_flat << " of " << road;
  EXPECT_GT(tall, 200);  // building walls, parked cars
  int distinct = 0;
  for (bool u : used) distinct += u ? 1 : 0;
  EXPECT_GT(distinct, 100);
}

// --- vocabulary ---

TEST(TravVocabulary, FixedIncrementBinsOpenAtTheTopAndMixedRadixWords) {
  VocabularyConfig c;
  c.bins = {{{0.04f, 8}, {32.0f, 8}, {8.0f, 6}, {0.01f, 6}, {6.0f, 8}}};
  const Vocabulary v{c};
  EXPECT_EQ(v.size(), 8u * 8u * 6u * 6u * 8u);
  EXPECT_EQ(Vocabulary(VocabularyConfig{}).size(), 6u * 10u * 4u * 3u * 3u * 5u * 3u);  // the default
  VocabularyConfig thesis;
  thesis.set = FeatureSet::thesis;
  EXPECT_EQ(Vocabulary(thesis).size(), 6u * 10u * 4u * 3u * 3u);  // the thesis' five dimensions
  EXPECT_EQ(v.bin(Dim::max_dz, 0.0f), 0u);
  EXPECT_EQ(v.bin(Dim::max_dz, 0.039f), 0u);
  EXPECT_EQ(v.bin(Dim::max_dz, 0.041f), 1u);
  EXPECT_EQ(v.bin(Dim::max_dz, 5.0f), 7u);
  EXPECT_EQ(v.bin(Dim::max_dz, -1.0f), 0u);
  EXPECT_EQ(v.bin(Dim::max_dz, std::nanf("")), 0u);
  EXPECT_EQ(v.bin(Dim::remission_var, 15.9f * 15.9f), 1u);  // on the standard deviation: 15.9 / 8
  EXPECT_EQ(v.bin(Dim::roughness, 0.025f * 0.025f), 2u);   // on the RMS distance: 0.025 m / 0.01 m
  Feature f;
  f.v = {0.05f, 70.0f, 0.0f, 0.0f, 13.0f};  // bins 1, 2, 0, 0, 2
  EXPECT_EQ(v.word(f), (((1u * 8 + 2) * 6 + 0) * 6 + 0) * 8 + 2);
  VocabularyConfig no_re = c, no_rs = c;
  no_re.set = FeatureSet::no_remission;
  no_rs.set = FeatureSet::no_roughness_slope;
  EXPECT_EQ(Vocabulary(no_re).size(), 8u * 6u * 8u);
  EXPECT_EQ(Vocabulary(no_rs).size(), 8u * 8u * 6u);
  EXPECT_EQ(Vocabulary(no_re).word(f), (1u * 6 + 0) * 8 + 2);
}

// The ground reference's signed answer: above the ground the height, below
// it (a ditch) the depth; the default depth bins are 0.1 m wide, and the
// thesis' five dimensions use neither.
TEST(TravVocabulary, AboveTheGroundIsTheHeightBelowItTheDepth) {
  CellStats s;
  for (int i = 0; i < 8; ++i) s.add(0.05f * static_cast<float>(i), 0.0f, 0.0f, 40.0f);
  Feature up, down;
  ASSERT_TRUE(cell_feature(s, up, nullptr, 0.9f));
  ASSERT_TRUE(cell_feature(s, down, nullptr, -0.25f));
  EXPECT_FLOAT_EQ(up[Dim::height], 0.9f);
  EXPECT_FLOAT_EQ(up[Dim::depth], 0.0f);
  EXPECT_FLOAT_EQ(down[Dim::height], 0.0f);
  EXPECT_FLOAT_EQ(down[Dim::depth], 0.25f);
  const Vocabulary v{VocabularyConfig{}};
  EXPECT_EQ(v.bin(Dim::depth, 0.05f), 0u);
  EXPECT_EQ(v.bin(Dim::depth, 0.15f), 1u);
  EXPECT_EQ(v.bin(Dim::depth, 0.45f), 2u);
  Feature level = down;
  level.v[static_cast<std::size_t>(Dim::depth)] = 0.0f;
  EXPECT_NE(v.word(down), v.word(level));
  VocabularyConfig thesis;
  thesis.set = FeatureSet::thesis;
  EXPECT_EQ(Vocabulary(thesis).word(down), Vocabulary(thesis).word(level));
  EXPECT_EQ(dim_name(Dim::depth), "depth");
}

TEST(TravVocabulary, ABadBinningIsNamed) {
  VocabularyConfig c;
  EXPECT_EQ(check_vocabulary(c), "");
  c.bins[2].width = 0.0f;
  EXPECT_NE(check_vocabulary(c).find("remission_var"), std::string::npos);
  c = {};
  c.bins[4].bins = 0;
  EXPECT_NE(check_vocabulary(c).find("slope"), std::string::npos);
  c = {};
  for (auto& b : c.bins) b.bins = 64;
  EXPECT_NE(check_vocabulary(c).find("words"), std::string::npos);
}

// --- the χ² test ---

TEST(TravChiSquare, MatchesAWorkedExample) {
  // Rows (10, 20, 30) and (20, 20, 20): expected 15, 20, 25 in each row;
  // χ² = 2·25/15 + 2·25/25 = 5.333, 2 degrees of freedom, p = e^(−χ²/2).
  const std::vector<std::uint32_t> a{10, 20, 30, 0}, b{20, 20, 20, 0};
  const ChiSquare t = chi_square_homogeneity(a, b, 5.0);
  EXPECT_NEAR(t.statistic, 16.0 / 3.0, 1e-9);
  EXPECT_EQ(t.dof, 2);
  EXPECT_NEAR(t.p_value, std::exp(-8.0 / 3.0), 1e-9);
  // The same histogram scaled cannot be told apart.
  const std::vector<std::uint32_t> c{100, 200, 300, 0};
  EXPECT_NEAR(chi_square_homogeneity(a, c, 5.0).statistic, 0.0, 1e-9);
  EXPECT_NEAR(chi_square_homogeneity(a, c, 5.0).p_value, 1.0, 1e-9);
  // An empty histogram: nothing to test.
  EXPECT_EQ(chi_square_homogeneity(a, std::vector<std::uint32_t>(4, 0), 5.0).p_value, 1.0);
}

TEST(TravChiSquare, SparseWordsArePooled) {
  // Words 2..5 are expected fewer than 5 times: one pooled column.
  const std::vector<std::uint32_t> a{50, 50, 1, 2, 0, 1}, b{50, 50, 2, 1, 1, 0};
  const ChiSquare t = chi_square_homogeneity(a, b, 5.0);
  EXPECT_EQ(t.dof, 2);  // columns: word 0, word 1, the pool
  EXPECT_NEAR(t.statistic, 0.0, 1e-9);
  EXPECT_EQ(chi_square_homogeneity(a, b, 0.0).dof, 5);
}

// --- the learners on known distributions ---

// A vocabulary of `n` words (max |Δz| alone in n bins).
Vocabulary small_vocabulary(std::uint32_t n) {
  VocabularyConfig c;
  for (auto& b : c.bins) b = {1.0f, 1};
  c.bins[0] = {0.1f, n};
  return Vocabulary(c);
}

// Counts of `n` draws from `p` (exact expectations, rounded).
void add_expected(WordCounts& k, const std::vector<double>& p, double n, bool positive) {
  for (std::size_t w = 0; w < p.size(); ++w) {
    k.add(static_cast<std::uint32_t>(w), positive, static_cast<std::uint32_t>(std::lround(p[w] * n)));
  }
}

// Traversable ground uses words 0..4, the rest words 5..9, word 4 both.
const std::vector<double> kTrav{0.3, 0.3, 0.2, 0.1, 0.1, 0, 0, 0, 0, 0};
const std::vector<double> kNot{0, 0, 0, 0, 0.2, 0.2, 0.2, 0.2, 0.2, 0};  // word 9 never seen

TEST(TravLearners, RecoverTheClassesFromPositiveAndUnlabelledWords) {
  const Vocabulary v = small_vocabulary(10);
  TravModels models(v, LearnerConfig{});
  WordCounts map(v.size());
  add_expected(map, kTrav, 2000, true);  // the footprint's cells
  std::vector<double> mixed(10);
  for (std::size_t w = 0; w < 10; ++w) mixed[w] = 0.6 * kTrav[w] + 0.4 * kNot[w];
  add_expected(map, mixed, 10000, false);  // the rest: 60 % traversable
  const auto a = models.train(map);
  ASSERT_EQ(a.model, 0);
  EXPECT_TRUE(a.created);
  ASSERT_EQ(models.models(), 1u);
  // Elkan–Noto: a quarter of the traversable words were labelled, c = 0.25,
  // and the traversable share of the unlabelled is 60 %.
  EXPECT_NEAR(models.elkan_noto_c(0), 0.25, 0.01);
  EXPECT_NEAR(models.pnb_prior(0), 0.6, 0.02);
  EXPECT_NEAR(models.pos_prior(), (2000 + 6000) / 12000.0, 0.02);
  for (std::uint32_t w = 0; w < 4; ++w) {
    EXPECT_GT(models.pnb_log_ratio(0, w), 3.0f) << w;
    EXPECT_GT(models.pos_probability(0, w), 0.95) << w;
  }
  for (std::uint32_t w = 5; w < 9; ++w) {
    EXPECT_LT(models.pnb_log_ratio(0, w), -3.0f) << w;
    EXPECT_LT(models.pos_probability(0, w), 0.05) << w;
  }
  // Eq. 6.11: a word never seen is more likely untraversable.
  EXPECT_LT(models.pnb_log_ratio(0, 9), 0.0f);
  EXPECT_LT(models.probability(Method::pnb, std::vector<std::uint32_t>{9}), 0.5);
  EXPECT_LT(models.probability(Method::pos, std::vector<std::uint32_t>{9}), 0.5);
  // Cells: several features of one kind.
  for (Method m : {Method::pnb, Method::pos}) {
    EXPECT_GT(models.probability(m, std::vector<std::uint32_t>{0, 1, 2}), 0.99) << method_name(m);
    EXPECT_LT(models.probability(m, std::vector<std::uint32_t>{5, 6, 7}), 0.01) << method_name(m);
    EXPECT_NEAR(models.probability(m, {}), m == Method::pnb ? models.pnb_prior(0) : models.pos_prior(), 1e-6);
  }
}

TEST(TravLearners, PnbNegativeFrequenciesSumToOne) {
  // Eq. 6.9 with η of Eq. 6.10 is a distribution: Σ_f P(f|¬trav) = 1 when
  // some word is left over (C_N > 0), so exp(log P(f|trav) − llr) sums to 1.
  const Vocabulary v = small_vocabulary(10);
  TravModels models(v, LearnerConfig{.prior = 0.5});
  WordCounts map(v.size());
  add_expected(map, kTrav, 500, true);
  std::vector<double> mixed(10);
  for (std::size_t w = 0; w < 10; ++w) mixed[w] = 0.5 * kTrav[w] + 0.5 * kNot[w];
  add_expected(map, mixed, 4000, false);
  models.train(map);
  const double size = v.size(), np = 500, alpha_p = 1.0 / size;
  double sum_trav = 0.0, sum_not = 0.0;
  for (std::uint32_t w = 0; w < v.size(); ++w) {
    const double p_trav = (alpha_p + map.positive(w)) / (alpha_p * size + np);
    sum_trav += p_trav;
    sum_not += p_trav / std::exp(static_cast<double>(models.pnb_log_ratio(0, w)));
  }
  EXPECT_NEAR(sum_trav, 1.0, 1e-9);
  EXPECT_NEAR(sum_not, 1.0, 1e-4);
  EXPECT_DOUBLE_EQ(models.pnb_prior(0), 0.5);
}

TEST(TravLearners, ALocalMapWithoutPositivesIsNotLearnt) {
  const Vocabulary v = small_vocabulary(10);
  TravModels models(v, LearnerConfig{});
  WordCounts map(v.size());
  add_expected(map, kNot, 100, false);
  EXPECT_EQ(models.train(map).model, -1);
  EXPECT_EQ(models.models(), 0u);
  EXPECT_EQ(models.probability(Method::pnb, std::vector<std::uint32_t>{0}), 0.0);
}

// Positives drawn at random (fixed seed) from a distribution over the words.
WordCounts sampled_map(const Vocabulary& v, const std::vector<double>& positive, const std::vector<double>& unlabelled,
                       int n_positive, int n_unlabelled, std::uint32_t seed) {
  std::mt19937 rng(seed);
  WordCounts k(v.size());
  std::discrete_distribution<std::uint32_t> p(positive.begin(), positive.end()), u(unlabelled.begin(), unlabelled.end());
  for (int i = 0; i < n_positive; ++i) k.add(p(rng), true);
  for (int i = 0; i < n_unlabelled; ++i) k.add(u(rng), false);
  return k;
}

// Street words 0..3, grass 4..7, bushes 8..11.
const std::vector<double> kStreet{0.4, 0.3, 0.2, 0.1, 0, 0, 0, 0, 0, 0, 0, 0};
const std::vector<double> kGrass{0, 0, 0, 0, 0.25, 0.25, 0.25, 0.25, 0, 0, 0, 0};
std::vector<double> scene(double street, double grass, double bush) {
  std::vector<double> p(12);
  for (std::size_t w = 0; w < 4; ++w) p[w] = street * kStreet[w];
  for (std::size_t w = 4; w < 8; ++w) p[w] = grass * kGrass[w];
  for (std::size_t w = 8; w < 12; ++w) p[w] = bush * 0.25;
  return p;
}

TEST(TravTerrainModels, TheChiSquareTestSeparatesTheGroundDrivenOn) {
  const Vocabulary v = small_vocabulary(12);
  TravModels models(v, LearnerConfig{.max_models = 2});
  const auto street = [&](std::uint32_t seed) { return sampled_map(v, kStreet, scene(0.5, 0.3, 0.2), 300, 3000, seed); };
  const auto grass = [&](std::uint32_t seed) { return sampled_map(v, kGrass, scene(0.3, 0.5, 0.2), 300, 3000, seed); };
  auto a = models.train(street(1));
  EXPECT_EQ(a.model, 0);
  EXPECT_TRUE(a.created);
  a = models.train(street(2));  // the same ground: merged
  EXPECT_EQ(a.model, 0);
  EXPECT_FALSE(a.created);
  EXPECT_GE(a.test.p_value, 0.05);
  a = models.train(grass(3));  // other ground: a new model
  EXPECT_EQ(a.model, 1);
  EXPECT_TRUE(a.created);
  a = models.train(grass(4));
  EXPECT_EQ(a.model, 1);
  EXPECT_FALSE(a.created);
  // A third kind with no room left: forced into the closer model.
  std::vector<double> bush(12, 0.0);
  for (std::size_t w = 8; w < 12; ++w) bush[w] = 0.25;
  a = models.train(sampled_map(v, bush, scene(0.3, 0.3, 0.4), 300, 3000, 5));
  EXPECT_TRUE(a.forced);
  EXPECT_EQ(models.models(), 2u);
  EXPECT_LT(a.test.p_value, 0.05);
}

// Thesis §6.3.3: driving mostly on the street and a little on grass, one
// model cannot learn that grass is traversable; terrain models can.
TEST(TravTerrainModels, GrassDrivenBrieflyIsLearntOnlyWithTerrainModels) {
  const Vocabulary v = small_vocabulary(12);
  std::vector<WordCounts> maps;
  for (std::uint32_t s = 0; s < 6; ++s) maps.push_back(sampled_map(v, kStreet, scene(0.4, 0.4, 0.2), 300, 3000, 10 + s));
  maps.push_back(sampled_map(v, kGrass, scene(0.3, 0.5, 0.2), 300, 3000, 20));
  TravModels one(v, LearnerConfig{.max_models = 1}), several(v, LearnerConfig{});
  TravModels::Assignment grass;
  for (const WordCounts& m : maps) {
    one.train(m);
    grass = several.train(m);
  }
  EXPECT_EQ(one.models(), 1u);
  // The street maps may split too (the test rejects 5 % of equal ones), but
  // the grass map starts a model of its own.
  EXPECT_GE(several.models(), 2u);
  EXPECT_TRUE(grass.created);
  const std::vector<std::uint32_t> grass_cell{4, 5, 6}, bush_cell{8, 9, 10}, street_cell{0, 1, 2};
  for (Method m : {Method::pnb, Method::pos}) {
    EXPECT_GT(several.probability(m, grass_cell), 0.5) << method_name(m);
    EXPECT_GT(several.probability(m, grass_cell), one.probability(m, grass_cell)) << method_name(m);
    EXPECT_GT(several.probability(m, street_cell), 0.5) << method_name(m);
    EXPECT_LT(several.probability(m, bush_cell), 0.5) << method_name(m);
  }
}

// --- the model file ---

TravModelFile trained_file() {
  TravModelFile f;
  f.profile = "large";
  for (FeatureSet fs : {FeatureSet::no_remission, FeatureSet::no_roughness_slope}) {
    TravModelSet t;
    t.vocabulary.set = fs;
    t.learner.max_models = 4;
    const Vocabulary v(t.vocabulary);
    for (std::uint32_t m = 0; m < 2; ++m) {
      WordCounts k(v.size());
      for (std::uint32_t w = m; w < v.size(); w += 7) k.add(w, (w % 3) == 0, w + 1);
      t.models.push_back(k);
    }
    f.sets.push_back(std::move(t));
  }
  return f;
}

void recrc(std::vector<std::uint8_t>& b) {
  const auto crc = static_cast<std::uint32_t>(crc32(0L, b.data(), static_cast<uInt>(b.size() - 4)));
  for (int i = 0; i < 4; ++i) b[b.size() - 4 + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(crc >> (8 * i));
}

TEST(TravModelFile, RoundTripsEveryCountAndSetting) {
  const TravModelFile f = trained_file();
  const std::string path = (std::filesystem::temp_directory_path() / "trailnav-trav-model-test.tntrav").string();
  ASSERT_TRUE(save_trav_model(path, f));
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  const LoadedTravModel l = load_trav_model(path);
  std::filesystem::remove(path);
  ASSERT_TRUE(l.model) << l.error;
  EXPECT_EQ(l.model->profile, "large");
  ASSERT_EQ(l.model->sets.size(), 2u);
  ASSERT_NE(l.model->set(FeatureSet::no_remission), nullptr);
  ASSERT_NE(l.model->set(FeatureSet::no_roughness_slope), nullptr);
  EXPECT_EQ(l.model->set(FeatureSet::full), nullptr);
  for (std::size_t si = 0; si < 2; ++si) {
    const TravModelSet& a = f.sets[si];
    const TravModelSet& b = l.model->sets[si];
    EXPECT_EQ(b.vocabulary.set, a.vocabulary.set);
    EXPECT_EQ(b.learner.max_models, 4u);
    ASSERT_EQ(b.models.size(), 2u);
    for (std::size_t m = 0; m < 2; ++m) {
      for (std::uint32_t w = 0; w < Vocabulary(a.vocabulary).size(); ++w) {
        ASSERT_EQ(b.models[m].positive(w), a.models[m].positive(w));
        ASSERT_EQ(b.models[m].unlabelled(w), a.models[m].unlabelled(w));
      }
    }
    // The learner's tables from the loaded counts equal the originals'.
    TravModels ta(Vocabulary(a.vocabulary), a.learner), tb(Vocabulary(b.vocabulary), b.learner);
    ta.set_models(a.models);
    tb.set_models(b.models);
    for (std::uint32_t w = 0; w < Vocabulary(a.vocabulary).size(); ++w) ASSERT_EQ(ta.pos_log_ratio(w), tb.pos_log_ratio(w));
  }
  EXPECT_EQ(serialize_trav_model(*l.model), serialize_trav_model(f));
}

TEST(TravModelFile, BadBytesGetAClearError) {
  const std::vector<std::uint8_t> good = serialize_trav_model(trained_file());
  auto error = [](const std::vector<std::uint8_t>& b) {
    const LoadedTravModel l = parse_trav_model(b, "m.tntrav");
    EXPECT_FALSE(l.model);
    return l.error;
  };
  EXPECT_NE(error({'x', 'y'}).find("not a trailnav traversability model"), std::string::npos);
  auto b = good;
  b[8] = 9;  // version
  EXPECT_NE(error(b).find("version 9"), std::string::npos);
  b = good;
  b[good.size() / 2] ^= 0x40;
  EXPECT_NE(error(b).find("checksum"), std::string::npos);
  b.assign(good.begin(), good.end() - 10);
  EXPECT_NE(error(b).find("checksum"), std::string::npos);
  // Structural errors behind a valid checksum.
  b = good;
  b[16] = 'x';  // the profile's first letter... stays printable: fine
  recrc(b);
  EXPECT_TRUE(parse_trav_model(b, "m").model);
  b = good;
  b[12] = 200;  // profile length
  recrc(b);
  EXPECT_NE(error(b).find("longer than 64"), std::string::npos);
  // The first set's first model's first word beyond the vocabulary.
  const std::size_t header = 8 + 4 + 4 + 5 + 4 + 4 + kDims * 8 + 6 * 8 + 4 + 4;
  const std::size_t first_word = header + 8 + 8 + 4;
  b = good;
  b[first_word + 3] = 0x7f;
  recrc(b);
  EXPECT_NE(error(b).find("outside the vocabulary"), std::string::npos);
  b = good;
  b[first_word + 4] ^= 2;  // its positive count, 1 -> 3
  recrc(b);
  EXPECT_NE(error(b).find("do not add up"), std::string::npos);
  b = good;
  b[header - 4] = 99;  // 99 models
  recrc(b);
  EXPECT_NE(error(b).find("more than its max_models"), std::string::npos);
  b = good;
  b[8 + 4 + 4 + 5] = 5;  // five feature sets
  recrc(b);
  EXPECT_NE(error(b).find("1 to 4"), std::string::npos);
  b = good;
  b[8] = 1;  // a version 1 file: the thesis' five dimensions
  EXPECT_NE(error(b).find("train it again"), std::string::npos);
  b[8] = 2;  // a version 2 file: six dimensions, without the depth
  EXPECT_NE(error(b).find("without the depth"), std::string::npos);
  EXPECT_NE(error(b).find("train it again"), std::string::npos);
  EXPECT_NE(load_trav_model("/nonexistent/x.tntrav").error.find("cannot open"), std::string::npos);
}

}  // namespace
}  // namespace trailnav::perception::trav

// --- the local maps and the demonstration's labels ---

namespace trailnav::perception::trav {
namespace {

CellStats flat_cell(float remission) {
  CellStats s;
  for (int i = 0; i < 9; ++i) s.add(-0.08f + 0.02f * static_cast<float>(i), 0.03f * static_cast<float>(i % 3), 0.0f, remission);
  return s;
}

TEST(TravRecorder, TheFootprintsCellsArePositiveForOneLocalMap) {
  const Vocabulary v{VocabularyConfig{}};
  RecorderConfig rc;
  rc.footprint = {1.0, 0.7, 0.0};
  rc.local_map_distance = 10.0;
  TravRecorder rec(rc, v, 300, 300, 0.2);
  // Along +x from 0 to 10.4 m; a word on the path (y = 0) and one 2 m beside it, every metre.
  const CellStats path = flat_cell(50.0f), verge = flat_cell(20.0f);
  for (int k = 0; k <= 104; ++k) {
    const double x = 0.1 * k;
    rec.drive(x, 0.0, 0.0);
    if (k % 10 == 5) {
      rec.cell_sums({static_cast<std::int32_t>(std::floor(x / 0.2)), 0}, path, nullptr, x, 0.1);
      rec.cell_sums({static_cast<std::int32_t>(std::floor(x / 0.2)), 10}, verge, nullptr, x, 2.1);
    }
  }
  EXPECT_TRUE(rec.footprint({25, 1}));    // y 0.2..0.4 meets the 0.35 m half-width
  EXPECT_FALSE(rec.footprint({25, 2}));   // y 0.4..0.6 does not
  EXPECT_TRUE(rec.footprint({25, -2}));   // y -0.4..-0.2
  EXPECT_FALSE(rec.footprint({-4, 0}));   // 0.8 m behind the start
  EXPECT_TRUE(rec.local_map_complete());
  WordCounts counts(v.size());
  int cells = 0, positive_cells = 0;
  rec.finish_local_map(counts, [&](const TravRecorder::CellWords& c) {
    ++cells;
    positive_cells += c.positive ? 1 : 0;
    EXPECT_EQ(c.positive, c.cell.y == 0);
    EXPECT_EQ(c.words.size(), 1u);
  });
  EXPECT_EQ(cells, 20);  // x = 0.5, 1.5, ..., 9.5: ten on the path, ten beside it
  EXPECT_EQ(positive_cells, 10);
  Feature fp, fv;
  ASSERT_TRUE(cell_feature(path, fp));
  ASSERT_TRUE(cell_feature(verge, fv));
  EXPECT_EQ(counts.positive(v.word(fp)), 10u);
  EXPECT_EQ(counts.unlabelled(v.word(fv)), 10u);
  EXPECT_EQ(counts.total_positive(), 10u);
  EXPECT_EQ(counts.total_unlabelled(), 10u);
  // The next local map: the old marks no longer count.
  EXPECT_EQ(rec.local_map(), 2u);
  EXPECT_FALSE(rec.footprint({25, 0}));
  EXPECT_FALSE(rec.local_map_complete());
  rec.cell_sums({25, 0}, path, nullptr, 5.1, 0.1);
  rec.finish_local_map(counts);
  EXPECT_EQ(counts.total_positive(), 0u);
  EXPECT_EQ(counts.total_unlabelled(), 1u);
}

TEST(TravRecorder, FarCellsAndWordsBeyondItsCapacityAreCounted) {
  const Vocabulary v{VocabularyConfig{}};
  RecorderConfig rc;
  rc.max_range = 20.0;
  rc.max_words = 1000;
  TravRecorder rec(rc, v, 300, 300, 0.2);
  rec.drive(0.0, 0.0, 0.0);
  const CellStats s = flat_cell(30.0f);
  rec.cell_sums({110, 0}, s, nullptr, 22.1, 0.1);
  EXPECT_EQ(rec.counters().too_far, 1u);
  for (int i = 0; i < 1005; ++i) rec.cell_sums({i % 50, i / 50}, s, nullptr, 0.2 * (i % 50), 0.2 * (i / 50));
  EXPECT_EQ(rec.counters().words, 1000u);
  EXPECT_EQ(rec.counters().dropped, 5u);
  CellStats few;
  for (int i = 0; i < 4; ++i) few.add(0.01f * static_cast<float>(i), 0.0f, 0.0f, 1.0f);
  rec.cell_sums({1, 1}, few, nullptr, 0.3, 0.3);  // fewer than five points: no word
  EXPECT_EQ(rec.counters().words + rec.counters().dropped, 1005u);
  EXPECT_EQ(check_recorder(rc), "");
  rc.footprint.width = 0.0;
  EXPECT_NE(check_recorder(rc).find("footprint"), std::string::npos);
}

// Two real KITTI scans taking turns as the revolutions of a car driving
// 0.3 m a revolution along x, through a terrain mapper (no forest).
struct KittiDrive {
  std::array<velodyne::RangeImage, 2> scans{velodyne::RangeImage(kitti_shape()), velodyne::RangeImage(kitti_shape())};
  TerrainConfig config;
  std::unique_ptr<TerrainMapper> mapper;
  PoseTrack poses{64};
  KittiDrive() {
    std::vector<float> buffer;
    EXPECT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, scans[0]));
    EXPECT_TRUE(load_kitti_scan(test::shared_data("kitti/000001.bin"), buffer, scans[1]));
    MountParams mount;
    mount.translation = {0.0, 0.0, 1.73};
    auto made = TerrainMapper::create(config, mount, kitti_shape(), nullptr);
    EXPECT_TRUE(made.mapper) << made.error;
    mapper = std::move(made.mapper);
  }
  // Revolution n (1, 2, ...): its poses, then registration and, when due, a step. No allocation.
  void revolution(int n) noexcept {
    const std::int64_t t = std::int64_t{n} * 100'000'000;
    poses.push({t - 100'000'000, 0.3 * (n - 1), 0.0, 0.0, 0.0, 0.0, 0.0});
    poses.push({t, 0.3 * n, 0.0, 0.0, 0.0, 0.0, 0.0});
    velodyne::RangeImage& image = scans[static_cast<std::size_t>(n % 2)];
    image.sequence = static_cast<std::uint64_t>(n);
    image.start_ns = t - 100'000'000;
    image.end_ns = t;
    mapper->process(image, &poses);
  }
};

// Real KITTI revolutions through the terrain mapper into the recorder while
// the robot drives 0.3 m a revolution: words are recorded at the steps, the
// local map ends after d_M, its positives are the cells under the path, and
// after arming no heap operation happens (train included).
TEST(TravRecorder, RealRevolutionsThroughTheTerrainStepWithoutAllocating) {
  KittiDrive drive;
  ASSERT_TRUE(drive.mapper);
  const TerrainConfig& tc = drive.config;
  const Vocabulary v{VocabularyConfig{}};
  RecorderConfig rc;
  rc.local_map_distance = 2.0;  // 9 m driven: four local maps
  TravRecorder rec(rc, v, tc.map.size_x, tc.map.size_y, tc.map.resolution);
  drive.mapper->set_sums_sink(&rec);
  TravModels models(v, LearnerConfig{});
  WordCounts counts(v.size());

  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("terrain");
  ASSERT_TRUE(alloc_guard::arm());
  std::uint64_t trained = 0, positives = 0, unlabelled = 0;
  for (int n = 1; n <= 30; ++n) {
    rec.drive(0.3 * n, 0.0, 0.0);
    drive.revolution(n);
    if (rec.local_map_complete()) {
      rec.finish_local_map(counts);
      positives += counts.total_positive();
      unlabelled += counts.total_unlabelled();
      trained += models.train(counts).model >= 0 ? 1u : 0u;
    }
  }
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  EXPECT_GE(rec.counters().local_maps, 4u);
  EXPECT_GT(rec.counters().words, 10'000u);
  EXPECT_EQ(rec.counters().dropped, 0u);
  EXPECT_GT(positives, 20u);
  EXPECT_GT(unlabelled, 50u * positives);
  // A local map may go unlearnt: with 2 m local maps the path's cells can
  // lie in the lidar's blind circle around the car for the whole map and get
  // no word (the thesis' 20 m give every map positives).
  EXPECT_GE(trained, 3u);
  EXPECT_GE(models.models(), 1u);
}

}  // namespace
}  // namespace trailnav::perception::trav

// --- the layer on the robot ---

namespace trailnav::perception::trav {
namespace {

// A cell 1 m high (a box's side), remission 90.
CellStats tall_cell() {
  CellStats s;
  for (int i = 0; i < 12; ++i) s.add(0.02f * static_cast<float>(i % 4), 0.05f, 0.1f * static_cast<float>(i), 90.0f);
  return s;
}

struct TrainedLayer {
  Vocabulary vocabulary{VocabularyConfig{}};
  TravModels models{vocabulary, LearnerConfig{}};
  std::uint32_t ground = 0, wall = 0;
  TrainedLayer() {
    Feature f;
    EXPECT_TRUE(cell_feature(flat_cell(50.0f), f));
    ground = vocabulary.word(f);
    // The wall's height above the ground: its lowest point (0 m) above the
    // lowest around it (the ground cells', 0 m), as the layer's
    // GroundReference finds it.
    EXPECT_TRUE(cell_feature(tall_cell(), f, nullptr, 0.0f));
    wall = vocabulary.word(f);
    EXPECT_NE(ground, wall);
    WordCounts k(vocabulary.size());
    k.add(ground, true, 400);
    k.add(ground, false, 3000);
    k.add(wall, false, 1500);
    EXPECT_EQ(models.train(k).model, 0);
  }
};

TEST(TravLayer, CellsGiveTheLearnersAnswerForTheirWords) {
  TrainedLayer t;
  for (Method method : {Method::pnb, Method::pos}) {
    auto made = TravLayer::create(t.models, method, 20.0, 20.0, 300, 300, 0.2);
    ASSERT_TRUE(made.layer) << made.error;
    TravLayer& layer = *made.layer;
    layer.move_to(0.0, 0.0);
    const CellStats ground = flat_cell(50.0f), wall = tall_cell();
    for (int k = 0; k < 3; ++k) layer.cell_sums({5, 0}, ground, nullptr, 1.1, 0.1);
    layer.cell_sums({6, 0}, wall, nullptr, 1.3, 0.1);
    layer.cell_sums({6, 0}, wall, nullptr, 1.3, 0.1);
    const std::vector<std::uint32_t> g{t.ground, t.ground, t.ground}, w{t.wall, t.wall};
    EXPECT_NEAR(layer.probability(layer.grid().at({5, 0})), t.models.probability(method, g), 1e-5) << method_name(method);
    EXPECT_NEAR(layer.probability(layer.grid().at({6, 0})), t.models.probability(method, w), 1e-5) << method_name(method);
    EXPECT_GT(layer.probability(layer.grid().at({5, 0})), 0.9f);
    EXPECT_LT(layer.probability(layer.grid().at({6, 0})), 0.1f);
    EXPECT_LT(layer.probability(layer.grid().at({7, 0})), 0.0f);  // never observed
    std::vector<std::int8_t> costs(300 * 300);
    layer.export_costs(costs);
    const CellIndex o = layer.grid().origin();
    auto cost = [&](std::int32_t x, std::int32_t y) { return costs[static_cast<std::size_t>((y - o.y) * 300 + (x - o.x))]; };
    EXPECT_LE(cost(5, 0), 10);
    EXPECT_GE(cost(6, 0), 90);
    EXPECT_EQ(cost(7, 0), -1);
  }
}

TEST(TravLayer, ANewLocalMapStartsACellAfreshAndFarCellsAreLeftOut) {
  TrainedLayer t;
  auto made = TravLayer::create(t.models, Method::pnb, 5.0, 20.0, 300, 300, 0.2);
  ASSERT_TRUE(made.layer) << made.error;
  TravLayer& layer = *made.layer;
  layer.move_to(0.0, 0.0);
  layer.cell_sums({10, 0}, tall_cell(), nullptr, 2.1, 0.1);
  EXPECT_EQ(layer.grid().at({10, 0}).words, 1u);
  for (int k = 1; k <= 6; ++k) layer.move_to(static_cast<double>(k), 0.0);  // 6 m: the next local map
  EXPECT_EQ(layer.local_map(), 2u);
  EXPECT_LT(layer.probability(layer.grid().at({10, 0})), 0.5f);  // the old evidence stays until seen again
  layer.cell_sums({10, 0}, flat_cell(50.0f), nullptr, 2.1, 0.1);
  EXPECT_EQ(layer.grid().at({10, 0}).words, 1u);
  EXPECT_EQ(layer.counters().restarted, 1u);
  EXPECT_GT(layer.probability(layer.grid().at({10, 0})), 0.5f);
  layer.cell_sums({200, 0}, flat_cell(50.0f), nullptr, 40.1, 0.1);  // 34 m from the robot
  EXPECT_EQ(layer.counters().too_far, 1u);
}

TEST(TravLayer, WithoutTerrainModelsEveryCellIsUnknownAndTooManyAreRefused) {
  const Vocabulary v{VocabularyConfig{}};
  // A demonstration before its first local map: no model yet.
  TravModels none(v, LearnerConfig{});
  auto empty = TravLayer::create(none, Method::pnb, 20.0, 20.0, 10, 10, 0.2);
  ASSERT_TRUE(empty.layer) << empty.error;
  empty.layer->move_to(0.0, 0.0);
  empty.layer->cell_sums(empty.layer->grid().world_to_index(0.5, 0.5), flat_cell(50.0f), nullptr, 0.5, 0.5);
  EXPECT_EQ(empty.layer->counters().words, 1u);
  EXPECT_LT(empty.layer->probability(*empty.layer->grid().find(0.5, 0.5)), 0.0f);
  TravModels many(v, LearnerConfig{.max_models = 12});
  std::vector<WordCounts> counts;
  for (std::uint32_t m = 0; m < 9; ++m) {
    counts.emplace_back(v.size());
    counts.back().add(m, true, 10);
  }
  many.set_models(counts);
  EXPECT_NE(TravLayer::create(many, Method::pnb, 20.0, 20.0, 10, 10, 0.2).error.find("--max-models 8"), std::string::npos);
}

TEST(TravLayer, TheTerrainThreadsCallsTouchNoHeap) {
  TrainedLayer t;
  auto made = TravLayer::create(t.models, Method::pnb, 20.0, 20.0, 300, 300, 0.2);
  ASSERT_TRUE(made.layer);
  std::vector<std::int8_t> costs(300 * 300);
  const CellStats ground = flat_cell(50.0f);
  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("terrain");
  ASSERT_TRUE(alloc_guard::arm());
  for (int k = 0; k < 200; ++k) {
    made.layer->move_to(0.3 * k, 0.0);
    made.layer->cell_sums({k, 1}, ground, nullptr, 0.2 * k + 0.1, 0.3);
  }
  made.layer->export_costs(costs);
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  EXPECT_EQ(made.layer->counters().words, 200u);
}

}  // namespace
}  // namespace trailnav::perception::trav

// --- on real lidar data ---

namespace trailnav::perception::trav {
namespace {

// One KITTI scan's cells (0.2 m, 40 x 40 m around the car, sensor frame
// lifted 1.73 m to the road) and their words.
struct KittiCells {
  std::vector<std::pair<CellIndex, std::uint32_t>> words;
  std::vector<Feature> features;
};
KittiCells kitti_cells(const std::string& file, const Vocabulary& v) {
  std::ifstream in(test::shared_data("kitti/" + file), std::ios::binary);
  std::vector<float> b;
  float x = 0.0f;
  while (in.read(reinterpret_cast<char*>(&x), sizeof x)) b.push_back(x);
  constexpr int kCells = 200;
  constexpr float kRes = 0.2f;
  std::vector<CellStats> grid(kCells * kCells);
  for (std::size_t i = 0; i + 3 < b.size(); i += 4) {
    const int cx = static_cast<int>(std::floor(b[i] / kRes)) + kCells / 2;
    const int cy = static_cast<int>(std::floor(b[i + 1] / kRes)) + kCells / 2;
    if (cx < 0 || cy < 0 || cx >= kCells || cy >= kCells) continue;
    const float ox = (static_cast<float>(cx - kCells / 2) + 0.5f) * kRes, oy = (static_cast<float>(cy - kCells / 2) + 0.5f) * kRes;
    grid[static_cast<std::size_t>(cy) * kCells + static_cast<std::size_t>(cx)].add(b[i] - ox, b[i + 1] - oy, b[i + 2] + 1.73f,
                                                                                   b[i + 3] * 255.0f);
  }
  KittiCells out;
  for (int cy = 0; cy < kCells; ++cy) {
    for (int cx = 0; cx < kCells; ++cx) {
      Feature f;
      if (!cell_feature(grid[static_cast<std::size_t>(cy) * kCells + static_cast<std::size_t>(cx)], f)) continue;
      out.words.push_back({{cx - kCells / 2, cy - kCells / 2}, v.word(f)});
      out.features.push_back(f);
    }
  }
  return out;
}

// A demonstration on real data: the car of KITTI's scan 000000 drives the
// lane ahead of it (cells 4–12 m ahead, within 1 m of its axis: the
// positives; every other cell unlabelled). Both learners then classify the
// cells of the next scan, 000001: the road is called traversable and walls,
// cars and poles (max |Δz| > 0.5 m) are not. Figures in docs/traversability.md.
TEST(TravOnRealLidar, ALaneDrivenOnKittiTeachesTheRoadAndNotWhatStandsOnIt) {
  const Vocabulary v{VocabularyConfig{}};
  const KittiCells train = kitti_cells("000000.bin", v), test_scan = kitti_cells("000001.bin", v);
  ASSERT_GT(train.words.size(), 4000u);
  WordCounts counts(v.size());
  for (const auto& [c, w] : train.words) {
    const bool lane = c.x >= 20 && c.x < 60 && c.y >= -5 && c.y < 5;
    counts.add(w, lane);
  }
  EXPECT_GT(counts.total_positive(), 100u);
  TravModels models(v, LearnerConfig{});
  ASSERT_EQ(models.train(counts).model, 0);
  for (Method m : {Method::pnb, Method::pos}) {
    std::uint64_t road = 0, road_called = 0, tall = 0, tall_called = 0, all_called = 0;
    for (std::size_t i = 0; i < test_scan.words.size(); ++i) {
      const CellIndex c = test_scan.words[i].first;
      const std::vector<std::uint32_t> words{test_scan.words[i].second};
      const bool called = models.probability(m, words) > 0.5;
      all_called += called ? 1 : 0;
      const Feature& f = test_scan.features[i];
      if (c.x >= 20 && c.x < 60 && std::abs(c.y) < 8 && f[Dim::max_dz] < 0.08f) {  // the street ahead, flat cells
        ++road;
        road_called += called ? 1 : 0;
      }
      if (f[Dim::max_dz] > 0.5f) {
        ++tall;
        tall_called += called ? 1 : 0;
      }
    }
    std::printf("[ trav ] KITTI 000001, %s: flat street ahead called traversable %llu of %llu (%.3f), cells over 0.5 m "
                "%llu of %llu (%.3f), all cells %llu of %zu\n",
                std::string(method_name(m)).c_str(), static_cast<unsigned long long>(road_called),
                static_cast<unsigned long long>(road), static_cast<double>(road_called) / static_cast<double>(road),
                static_cast<unsigned long long>(tall_called), static_cast<unsigned long long>(tall),
                static_cast<double>(tall_called) / static_cast<double>(tall), static_cast<unsigned long long>(all_called),
                test_scan.words.size());
    ASSERT_GT(road, 200u);
    ASSERT_GT(tall, 200u);
    // POS is the more conservative (c, the largest g of the lane's words, from
    // one scan's lane): 0.39 of the street against PNB's 0.88.
    EXPECT_GT(static_cast<double>(road_called), (m == Method::pnb ? 0.8 : 0.3) * static_cast<double>(road)) << method_name(m);
    EXPECT_LT(static_cast<double>(tall_called), 0.05 * static_cast<double>(tall)) << method_name(m);
  }
}

}  // namespace
}  // namespace trailnav::perception::trav

// --- the demonstration mode on the robot ---

namespace trailnav::perception::trav {
namespace {

// trailnavd's two halves on real KITTI revolutions (driven 0.3 m a
// revolution along x): the terrain step hands its cells to TravOnline, whose
// recorder ends a local map every 6 m (the footprint's cells must have been
// seen in the local map they are driven in: KITTI's blind circle is 3-5 m); the trainer learns each, hands the
// models back (the layer takes them at the next step) and saves the file.
// From the first revolution on, neither half touches the heap — the save's
// serialisation and its write included. The class map then carries P(trav)
// on the cells the layer saw, and the file on disk holds the trainer's models.
TEST(TravDemonstration, RealRevolutionsTrainOnlineSaveAtomicallyAndFillTheClassMap) {
  KittiDrive drive;
  ASSERT_TRUE(drive.mapper);
  const TerrainConfig& tc = drive.config;
  const Vocabulary v{VocabularyConfig{}};
  const TravModels start(v, LearnerConfig{});  // a new demonstration: no model yet
  auto made = TravLayer::create(start, Method::pnb, 6.0, 20.0, tc.map.size_x, tc.map.size_y, tc.map.resolution);
  ASSERT_TRUE(made.layer) << made.error;
  RecorderConfig rc;
  rc.local_map_distance = 6.0;
  TravRecorder recorder(rc, v, tc.map.size_x, tc.map.size_y, tc.map.resolution);
  Mailbox<LocalMapWords> local_maps(v.size());
  Mailbox<TravModels> models(v, LearnerConfig{});
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("trav-demo-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "robot.tntrav").string();
  TravOnline online(*made.layer, &recorder, &local_maps, &models);
  TravTrainer trainer(start, "kitti-car", path, local_maps, models);
  drive.mapper->set_sums_sink(&online);
  constexpr int kRevolutions = 80;  // 24 m: four local maps of 6 m

  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("terrain");
  ASSERT_TRUE(alloc_guard::arm());
  for (int n = 1; n <= kRevolutions; ++n) {
    drive.revolution(n);
    while (trainer.poll()) {
    }
  }
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);

  const OnlineCounters& oc = online.counters();
  const TrainerCounters& tr = trainer.counters();
  EXPECT_EQ(oc.handed, 3u);  // 23.7 m driven: the fourth is under way
  EXPECT_EQ(tr.lost, 0u);
  EXPECT_EQ(tr.trained, 3u);
  EXPECT_EQ(tr.saves, tr.trained);
  EXPECT_EQ(tr.save_failures, 0u);
  EXPECT_GE(oc.model_updates, 1u);
  EXPECT_GE(made.layer->models().models(), 1u);
  // The class map carries the layer: cells with P(trav), the lane ahead
  // (within 1 m of the path, 2–8 m beyond the last pose) mostly traversable.
  const TerrainClassMap& map = drive.mapper->map();
  constexpr double kEnd = 0.3 * kRevolutions;  // the last pose's x
  std::uint64_t with_p = 0, called = 0, lane = 0, lane_called = 0;
  const auto& g = map.grid();
  for (std::int32_t y = 0; y < g.size_y(); ++y) {
    for (std::int32_t x = 0; x < g.size_x(); ++x) {
      const CellIndex i{g.origin().x + x, g.origin().y + y};
      const TerrainCell& c = g.at(i);
      if (c.traversable < 0.0f) continue;
      ++with_p;
      called += c.traversable > 0.5f ? 1u : 0u;
      const WorldPoint p = g.cell_center(i);
      if (p.x > kEnd + 2.0 && p.x < kEnd + 8.0 && std::abs(p.y) < 1.0) {
        ++lane;
        lane_called += c.traversable > 0.5f ? 1u : 0u;
      }
    }
  }
  EXPECT_GT(with_p, 1000u);
  ASSERT_GT(lane, 20u);
  std::printf("[ trav ] online: %llu cells with P(trav), %.3f of them called traversable; the lane ahead %.3f\n",
              static_cast<unsigned long long>(with_p), static_cast<double>(called) / static_cast<double>(with_p),
              static_cast<double>(lane_called) / static_cast<double>(lane));
  // The two scans alternate under a made-up motion, so the world is smeared:
  // the lane is not clean road everywhere. It is called traversable far more
  // often than the map's cells at large: 0.804 against 0.276 with the
  // ground reference's valleys and the depth (0.630 against 0.161 before
  // them: both shares rose).
  // What stands on the street is checked on unsmeared scans above
  // (TravOnRealLidar: no cell with 0.5 m of height called traversable).
  const double lane_share = static_cast<double>(lane_called) / static_cast<double>(lane);
  EXPECT_GT(lane_share, 0.6) << lane_called << " of " << lane;
  EXPECT_GT(lane_share, 2.5 * static_cast<double>(called) / static_cast<double>(with_p));
  // The file on disk: the trainer's models, under the profile's name, and
  // no temporary file left beside it.
  const LoadedTravModel loaded = load_trav_model(path);
  ASSERT_TRUE(loaded.model) << loaded.error;
  EXPECT_EQ(loaded.model->profile, "kitti-car");
  const TravModelSet* set = loaded.model->set(FeatureSet::full);
  ASSERT_NE(set, nullptr);
  ASSERT_EQ(set->models.size(), trainer.models().models());
  for (std::uint32_t m = 0; m < trainer.models().models(); ++m) {
    EXPECT_EQ(set->models[m].total_positive(), trainer.models().counts(m).total_positive());
    EXPECT_EQ(set->models[m].total_unlabelled(), trainer.models().counts(m).total_unlabelled());
  }
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  std::filesystem::remove_all(dir);
}

// TravOnline works out each cell's ground and word once, in the layer, and
// hands the word to the recorder: over real KITTI revolutions the recorder
// behind it records exactly what a recorder of its own, fed the same cells
// beside it, records — the same words, cell by cell, in the same order.
TEST(TravDemonstration, TheRecorderTakesTheLayersWordsAsItsOwnWouldBe) {
  KittiDrive drive;
  ASSERT_TRUE(drive.mapper);
  const TerrainConfig& tc = drive.config;
  TrainedLayer t;
  auto made = TravLayer::create(t.models, Method::pnb, 100.0, 20.0, tc.map.size_x, tc.map.size_y, tc.map.resolution);
  ASSERT_TRUE(made.layer) << made.error;
  RecorderConfig rc;
  rc.local_map_distance = 100.0;  // one local map throughout
  TravRecorder shared(rc, t.vocabulary, tc.map.size_x, tc.map.size_y, tc.map.resolution);
  TravRecorder own(rc, t.vocabulary, tc.map.size_x, tc.map.size_y, tc.map.resolution);
  Mailbox<LocalMapWords> local_maps(t.vocabulary.size());
  TravOnline online(*made.layer, &shared, &local_maps);
  ASSERT_TRUE(online.shares_words());  // the path under test, not two recorders each on their own
  struct Both final : CellSumsSink {
    TravOnline* online;
    TravRecorder* own;
    void cell_sums(CellIndex c, const CellStats& s, const FeatureVector* f, double x, double y) noexcept override {
      online->cell_sums(c, s, f, x, y);
      own->cell_sums(c, s, f, x, y);
    }
    void robot_pose(double x, double y, double yaw, std::int64_t ns) noexcept override {
      online->robot_pose(x, y, yaw, ns);
      own->drive(x, y, yaw);
    }
    void step_begins(double x, double y, std::int64_t ns, TerrainClassMap& map) noexcept override {
      online->step_begins(x, y, ns, map);
    }
  } both;
  both.online = &online;
  both.own = &own;
  drive.mapper->set_sums_sink(&both);
  for (int n = 1; n <= 40; ++n) drive.revolution(n);  // 12 m

  {
    VocabularyConfig other;
    other.bins[0].bins = 5;
    const Vocabulary v5(other);
    TravRecorder apart(rc, v5, tc.map.size_x, tc.map.size_y, tc.map.resolution);
    Mailbox<LocalMapWords> maps5(v5.size());
    EXPECT_FALSE(TravOnline(*made.layer, &apart, &maps5).shares_words());
  }
  ASSERT_GT(shared.counters().words, 10'000u);
  EXPECT_EQ(shared.counters().words, own.counters().words);
  EXPECT_EQ(shared.counters().too_far, own.counters().too_far);
  EXPECT_EQ(made.layer->counters().too_far, own.counters().too_far);
  EXPECT_EQ(made.layer->counters().words, shared.counters().words);
  std::vector<std::pair<CellIndex, std::vector<std::uint32_t>>> a, b;
  WordCounts ca(t.vocabulary.size()), cb(t.vocabulary.size());
  shared.finish_local_map(ca, [&](const TravRecorder::CellWords& c) {
    a.emplace_back(c.cell, std::vector<std::uint32_t>(c.words.begin(), c.words.end()));
  });
  own.finish_local_map(cb, [&](const TravRecorder::CellWords& c) {
    b.emplace_back(c.cell, std::vector<std::uint32_t>(c.words.begin(), c.words.end()));
  });
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t k = 0; k < a.size(); ++k) {
    ASSERT_EQ(a[k].first.x, b[k].first.x);
    ASSERT_EQ(a[k].first.y, b[k].first.y);
    ASSERT_EQ(a[k].second, b[k].second) << "cell " << a[k].first.x << "," << a[k].first.y;
  }
  EXPECT_EQ(ca.total_positive(), cb.total_positive());
  EXPECT_EQ(ca.total_unlabelled(), cb.total_unlabelled());
}

// A save that cannot happen (its directory is gone) is counted with its
// errno and leaves nothing behind; the models stay in memory for the next.
TEST(TravDemonstration, AFailedSaveIsCountedAndTheNextOneWrites) {
  TrainedLayer t;
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("trav-save-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  Mailbox<LocalMapWords> local_maps(t.vocabulary.size());
  Mailbox<TravModels> models(t.vocabulary, LearnerConfig{});
  TravTrainer trainer(t.models, "large", (dir / "m.tntrav").string(), local_maps, models);
  EXPECT_EQ(trainer.save(), ENOENT);
  EXPECT_EQ(trainer.counters().save_failures, 1u);
  EXPECT_EQ(trainer.counters().save_errno, ENOENT);
  std::filesystem::create_directories(dir);
  EXPECT_EQ(trainer.save(), 0);
  const LoadedTravModel loaded = load_trav_model((dir / "m.tntrav").string());
  ASSERT_TRUE(loaded.model) << loaded.error;
  EXPECT_EQ(loaded.model->set(FeatureSet::full)->models.size(), 1u);
  std::filesystem::remove_all(dir);
}

// The section of the robot config: its keys, a profile's footprint, and the
// start models (a missing file only in demonstration mode; a file learnt for
// another profile refused).
TEST(TravDemonstration, TheConfigSectionAndTheStartModels) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("trav-cfg-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string file = (dir / "robot.yaml").string();
  auto parse = [&](const std::string& text) {
    std::ofstream(file) << text;
    return parse_traversability_config(ConfigNode::load_file(file).map("traversability"));
  };
  TraversabilityConfig c = parse("traversability: {model: m.tntrav, method: pos, demonstration: {profile: small}}\n");
  EXPECT_EQ(c.model, (dir / "m.tntrav").string());
  EXPECT_EQ(c.method, Method::pos);
  EXPECT_TRUE(c.demonstration);
  EXPECT_DOUBLE_EQ(c.footprint.length, 0.6);
  StartModels s = load_start_models(c);
  ASSERT_TRUE(s.models) << s.error;
  EXPECT_TRUE(s.created);
  EXPECT_EQ(s.models->models(), 0u);
  try {
    parse("traversability: {model: m.tntrav, demonstration: {profile: rover}}\n");
    ADD_FAILURE() << "a profile without footprint was taken";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("footprint"), std::string::npos) << e.what();
  }
  c = parse("traversability: {model: m.tntrav}\n");
  EXPECT_NE(load_start_models(c).error.find("no such file"), std::string::npos);
  ASSERT_TRUE(save_trav_model(c.model, trained_file()));
  EXPECT_NE(load_start_models(c).error.find("no model of the feature set 'full'"), std::string::npos);
  TravModelFile full = trained_file();
  full.sets.front().vocabulary.set = FeatureSet::full;
  full.sets.front().models.assign(2, WordCounts(Vocabulary(full.sets.front().vocabulary).size()));
  full.sets.front().models[0].add(3, true, 40);
  full.sets.front().models[1].add(5, false, 40);
  ASSERT_TRUE(save_trav_model(c.model, full));
  s = load_start_models(c);
  ASSERT_TRUE(s.models) << s.error;
  EXPECT_FALSE(s.created);
  EXPECT_EQ(s.models->models(), 2u);
  EXPECT_EQ(s.other_sets, 1u);
  c = parse("traversability: {model: m.tntrav, demonstration: {profile: rover, footprint: {length_m: 2, width_m: 1}}}\n");
  EXPECT_NE(load_start_models(c).error.find("not 'rover'"), std::string::npos) << load_start_models(c).error;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace trailnav::perception::trav

// --- the height above the ground ---

namespace trailnav::perception::trav {
namespace {

CellStats level_cell(float z, int points = 8) {
  CellStats s;
  for (int i = 0; i < points; ++i) s.add(0.02f * static_cast<float>(i % 4), 0.03f * static_cast<float>(i / 4), z, 60.0f);
  return s;
}

// Undergrowth seen from afar (its leaves only, 1.2 m up) 2.5 m from ground
// the lidar saw stands 1.2 m above it; the same leaves 5 m away from any
// ground seen are 0 (the reference reaches 3 m); a cell whose lowest
// return is on the ground is at 0 whatever stands above it (a canopy); a
// block's lowest point is kept as the grid rolls with the robot, and
// forgotten once it has rolled out.
TEST(TravGround, TheLowestPointAboveTheLowestGroundWithinThreeMetres) {
  GroundReference g(60.0, 60.0);
  g.move_to(0.0, 0.0);
  EXPECT_FLOAT_EQ(g.height(10.1, 0.1, level_cell(0.3f)), 0.0f);  // nothing seen around it yet: its own block
  EXPECT_FLOAT_EQ(g.height(12.6, 0.1, level_cell(1.5f)), 1.2f);  // leaves 2.5 m from that ground
  EXPECT_FLOAT_EQ(g.height(15.6, 0.1, level_cell(1.5f)), 0.0f);  // 5.5 m away: only leaves within 3 m
  CellStats canopy = level_cell(0.3f);
  canopy.add(0.1f, 0.1f, 6.0f, 40.0f);  // a leaf 5.7 m above the ground in the same cell
  EXPECT_FLOAT_EQ(g.height(10.3, 0.3, canopy), 0.0f);
  g.move_to(20.0, 0.0);  // the ground's block at x = 10 m stays on the grid (33 m each way)
  EXPECT_FLOAT_EQ(g.height(12.6, 0.1, level_cell(1.5f)), 1.2f);
  g.move_to(60.0, 0.0);  // ... and is gone 50 m on
  EXPECT_FLOAT_EQ(g.height(32.6, 0.1, level_cell(1.5f)), 0.0f);
}

// A ditch 0.45 m deep along x = 3.5 m through ground at 0 m: the ground 2 m
// beside it is not raised above the ditch's bottom (its blocks are valleys,
// never the ground), a cell on the bottom gets its depth below the ground
// around (negative), a cell on its wall less; undergrowth's leaves beside the
// ground stay 1.2 m above it. The middle of a track three blocks wide
// between undergrowth is no valley (a ditch is one or two blocks wide): its
// cells are on the ground, and the leaves beside it stand above it.
TEST(TravGround, AValleyIsNeverTheGroundAndItsCellsGetTheirDepth) {
  GroundReference g(60.0, 60.0);
  g.move_to(0.0, 0.0);
  for (int j = 0; j < 9; ++j) {
    for (int i = 0; i < 9; ++i) {
      const float z = i == 3 ? -0.45f : 0.0f;
      g.height(i + 0.5, j + 0.5, level_cell(z));
    }
  }
  EXPECT_NEAR(g.height(5.3, 4.4, level_cell(0.0f)), 0.0f, 1e-6f);  // the track beside the ditch (was 0.45)
  EXPECT_NEAR(g.height(3.3, 4.4, level_cell(-0.45f)), -0.45f, 1e-6f);  // on its bottom
  EXPECT_NEAR(g.height(3.8, 4.4, level_cell(-0.2f)), -0.2f, 1e-6f);    // on its wall
  EXPECT_NEAR(g.height(8.7, 4.4, level_cell(1.2f)), 1.2f, 1e-6f);      // leaves beside the ground
  // Undergrowth at x 20-22 and 26-28, a track at x 23-25, level ground.
  for (int j = 0; j < 9; ++j) {
    for (int i = 20; i < 28; ++i) g.height(i + 0.5, j + 0.5, level_cell(i >= 23 && i < 26 ? 0.0f : 1.2f));
  }
  EXPECT_NEAR(g.height(22.5, 4.5, level_cell(1.2f)), 1.2f, 1e-6f);
  EXPECT_NEAR(g.height(26.5, 4.5, level_cell(1.2f)), 1.2f, 1e-6f);
  EXPECT_NEAR(g.height(24.5, 4.5, level_cell(0.0f)), 0.0f, 1e-6f);
}

}  // namespace
}  // namespace trailnav::perception::trav
