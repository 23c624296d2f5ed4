// Terrain analysis (thesis §7.2): the features from running sums and the area
// around a cell, the random forest's file format and its checks, training (separable data is
// learnt; the same seed gives the same bytes), the Bayes update of Eq. 7.15
// with frozen and re-opened cells, and the features of a real KITTI scan.
#include <gtest/gtest.h>

#include <zlib.h>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <numbers>
#include <random>

#include "test_data.hpp"
#include "trailnav/perception/forest_training.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/obstacle_pipeline.hpp"
#include "trailnav/perception/random_forest.hpp"
#include "trailnav/perception/terrain_mapper.hpp"

namespace trailnav::perception {
namespace {

namespace fs = std::filesystem;

constexpr int kMaxR = static_cast<int>(TerrainFeature::max_remission);
constexpr int kMeanR = static_cast<int>(TerrainFeature::mean_remission);
constexpr int kStdR = static_cast<int>(TerrainFeature::std_remission);
constexpr int kRough = static_cast<int>(TerrainFeature::roughness);
constexpr int kSlope = static_cast<int>(TerrainFeature::slope);

TEST(TerrainFeatures, FlatCellHasNoRoughnessNoSlopeAndItsRemission) {
  CellStats s;
  for (int i = 0; i < 10; ++i) {
    for (int j = 0; j < 10; ++j) s.add(-0.1f + 0.02f * static_cast<float>(i), -0.1f + 0.02f * static_cast<float>(j), 312.5f, i % 2 ? 30.0f : 40.0f);
  }
  const FeatureVector f = compute_terrain_feature(s);
  EXPECT_FLOAT_EQ(f[kMaxR], 40.0f);
  EXPECT_NEAR(f[kMeanR], 35.0f, 1e-4);
  EXPECT_NEAR(f[kStdR], 5.0f, 1e-3);
  EXPECT_NEAR(f[kRough], 0.0f, 1e-9);
  EXPECT_NEAR(f[kSlope], 0.0f, 0.05);
}

TEST(TerrainFeatures, TiltedPlaneGivesItsSlopeAndNoiseGivesRoughness) {
  for (double deg : {10.0, 25.0, 45.0}) {
    CellStats s;
    const double t = std::tan(deg * std::numbers::pi / 180.0);
    for (int i = 0; i < 8; ++i) {
      for (int j = 0; j < 8; ++j) {
        const double x = -0.1 + 0.025 * i, y = -0.1 + 0.025 * j;
        s.add(static_cast<float>(x), static_cast<float>(y), static_cast<float>(100.0 + t * (0.6 * x + 0.8 * y)), 20.0f);
      }
    }
    EXPECT_NEAR(compute_terrain_feature(s)[kSlope], deg, 0.05) << deg;
  }
  // Height noise of sigma 2 cm: the smallest eigenvalue is sigma^2.
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(0.0f, 0.02f);
  std::uniform_real_distribution<float> pos(-0.1f, 0.1f);
  CellStats s;
  for (int i = 0; i < 4000; ++i) s.add(pos(rng), pos(rng), 5.0f + noise(rng), 10.0f);
  EXPECT_NEAR(compute_terrain_feature(s)[kRough], 0.0004f, 0.00003f);
}

TEST(TerrainFeatures, PointsAlongOneRingTakeTheLinesRise) {
  // A single scan line crossing the cell, rising 1 in 5: the plane across it
  // is undetermined, the slope is the line's own.
  CellStats s;
  for (int i = 0; i < 20; ++i) {
    const float x = -0.1f + 0.01f * static_cast<float>(i);
    s.add(x, 0.001f * static_cast<float>(i % 2), 0.2f * x, 25.0f);
  }
  EXPECT_NEAR(compute_terrain_feature(s)[kSlope], std::atan(0.2) * 180.0 / std::numbers::pi, 0.3);
}

// The closed-form eigen solution against Eigen's solver on thousands of
// cells: flat, tilted, noisy, along one line, bushy; roughness and slope
// agree wherever the normal is determined.
TEST(TerrainFeatures, ClosedFormAgreesWithAnIterativeEigenSolver) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  int compared = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    CellStats s;
    const int kind = trial % 4;
    const float tx = 2.0f * u(rng), ty = 2.0f * u(rng);
    const float noise = kind == 3 ? 0.1f : 0.02f * (0.5f + 0.5f * u(rng)) * (0.5f + 0.5f * u(rng));
    for (int i = 0; i < 25; ++i) {
      float x = 0.1f * u(rng), y = 0.1f * u(rng);
      if (kind == 2) y = 0.002f * u(rng);  // one ring crossing the cell
      s.add(x, y, 3.0f + tx * x + ty * y + noise * u(rng), 30.0f);
    }
    // The same covariance as the feature's, in double.
    const double inv = 1.0 / s.n;
    auto mean = [&](float sum) { return static_cast<double>(sum) * inv; };
    const double mx = mean(s.sx), my = mean(s.sy), mz = mean(s.sz);
    const double xy = mean(s.sxy) - mx * my, xz = mean(s.sxz) - mx * mz, yz = mean(s.syz) - my * mz;
    Eigen::Matrix3d c;
    c << mean(s.sxx) - mx * mx, xy, xz, xy, mean(s.syy) - my * my, yz, xz, yz, mean(s.szz) - mz * mz;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(c);
    const Eigen::Vector3d l = eig.eigenvalues();
    const FeatureVector f = compute_terrain_feature(s);
    EXPECT_NEAR(static_cast<double>(f[kRough]), l(0), 2e-4 * l(2) + 1e-9) << trial;
    // Near the line rule's border, or with the two smaller eigenvalues nearly
    // equal, the normal is not determined: nothing to compare.
    const bool line = l(1) < 0.05 * l(2);
    if (std::abs(l(1) / l(2) - 0.05) < 0.005 || (!line && l(1) - l(0) < 0.05 * l(2))) continue;
    const double slope = line ? std::asin(std::min(1.0, std::abs(eig.eigenvectors()(2, 2))))
                              : std::acos(std::min(1.0, std::abs(eig.eigenvectors()(2, 0))));
    EXPECT_NEAR(static_cast<double>(f[kSlope]), slope * 180.0 / std::numbers::pi, 0.2) << trial;
    ++compared;
  }
  EXPECT_GT(compared, 3000);
  // Four cells at once, each in its lane: the same as one at a time.
  std::array<CellStats, 4> four;
  for (std::size_t l = 0; l < 4; ++l) {
    for (int i = 0; i < 15 + static_cast<int>(l); ++i) {
      const float x = 0.1f * u(rng), y = l == 2 ? 0.0f : 0.1f * u(rng);
      four[l].add(x, y, 0.3f * static_cast<float>(l) * x + 0.01f * u(rng), 20.0f + 10.0f * u(rng));
    }
  }
  std::array<FeatureVector, 4> together;
  compute_terrain_features({&four[0], &four[1], &four[2], &four[3]}, together);
  for (std::size_t l = 0; l < 4; ++l) EXPECT_EQ(together[l], compute_terrain_feature(four[l])) << l;
  // All points at one spot: no roughness, no slope, and no NaN.
  CellStats same;
  for (int i = 0; i < 20; ++i) same.add(0.01f, -0.02f, 4.0f, 12.0f);
  const FeatureVector f = compute_terrain_feature(same);
  EXPECT_EQ(f[kRough], 0.0f);
  EXPECT_EQ(f[kSlope], 0.0f);
}

// One stump of a tree: f[0] <= 0.5 ? leaf 0 : leaf 1.
RandomForest stump(ClassDistribution left, ClassDistribution right) {
  std::vector<ForestNode> nodes(3);
  nodes[0] = {0, 0, 0.5f, 2};
  nodes[1] = {-1, 0, 0.0f, 0};
  nodes[2] = {-1, 0, 0.0f, 1};
  std::vector<float> leaves(left.begin(), left.end());
  leaves.insert(leaves.end(), right.begin(), right.end());
  auto made = RandomForest::from_parts({0}, std::move(nodes), std::move(leaves));
  EXPECT_TRUE(made.forest) << made.error;
  return std::move(*made.forest);
}

TEST(RandomForest, PredictsTheMeanOfItsTreesAndRejectsBrokenParts) {
  const RandomForest f = stump({1, 0, 0, 0, 0}, {0, 0, 1, 0, 0});
  ClassDistribution p;
  f.predict({0.2f, 0, 0, 0, 0}, p);
  EXPECT_EQ(p[0], 1.0f);
  f.predict({0.7f, 0, 0, 0, 0}, p);
  EXPECT_EQ(p[2], 1.0f);

  auto broken = [](std::vector<ForestNode> nodes, std::vector<float> leaves) {
    return RandomForest::from_parts({0}, std::move(nodes), std::move(leaves)).error;
  };
  const std::vector<float> two_leaves = {1, 0, 0, 0, 0, 0, 1, 0, 0, 0};
  EXPECT_NE(broken({{7, 0, 0.5f, 2}, {-1, 0, 0, 0}, {-1, 0, 0, 1}}, two_leaves).find("feature 7 out of range"), std::string::npos);
  EXPECT_NE(broken({{0, 0, 0.5f, 0}, {-1, 0, 0, 0}, {-1, 0, 0, 1}}, two_leaves).find("child index"), std::string::npos);
  EXPECT_NE(broken({{0, 0, 0.5f, 2}, {-1, 0, 0, 0}, {-1, 0, 0, 5}}, two_leaves).find("leaf row 5"), std::string::npos);
  EXPECT_NE(broken({{0, 0, NAN, 2}, {-1, 0, 0, 0}, {-1, 0, 0, 1}}, two_leaves).find("not a number"), std::string::npos);
  EXPECT_NE(broken({{0, 0, 0.5f, 2}, {-1, 0, 0, 0}, {-1, 0, 0, 1}}, {1, 0, 0, 0, 0, 0.5f, 0, 0, 0, 0}).find("sum to 1"),
            std::string::npos);
  EXPECT_NE(broken({{0, 0, 0.5f, 2}, {-1, 0, 0, 0}, {-1, 0, 0, 1}, {-1, 0, 0, 1}}, two_leaves).find("no path reaches"),
            std::string::npos);
}

std::vector<std::uint8_t> file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
void write_bytes(const std::string& path, const std::vector<std::uint8_t>& b) {
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

TEST(RandomForest, ModelFileRoundTripsAndEveryCorruptionIsNamed) {
  const fs::path dir = fs::temp_directory_path() / ("trailnav-forest-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string path = (dir / "m.tnrf").string();
  const RandomForest f = stump({0.7f, 0.3f, 0, 0, 0}, {0, 0, 0.25f, 0.75f, 0});
  ASSERT_TRUE(f.save(path));
  auto back = RandomForest::load(path);
  ASSERT_TRUE(back.forest) << back.error;
  ClassDistribution a, b;
  for (float x : {0.1f, 0.5f, 0.9f}) {
    f.predict({x, 0, 0, 0, 0}, a);
    back.forest->predict({x, 0, 0, 0, 0}, b);
    EXPECT_EQ(a, b);
  }
  const auto good = file_bytes(path);
  // The shipped model, loaded and saved again, is the same bytes: the nodes
  // kept only in their walking form come back exactly.
  {
    auto shipped = RandomForest::load("board/models/terrain-sim.tnrf");
    ASSERT_TRUE(shipped.forest) << shipped.error;
    const std::string again = (dir / "again.tnrf").string();
    ASSERT_TRUE(shipped.forest->save(again));
    EXPECT_EQ(file_bytes(again), file_bytes("board/models/terrain-sim.tnrf"));
  }
  auto expect_error = [&](std::vector<std::uint8_t> bytes, const std::string& words) {
    write_bytes(path, bytes);
    const auto r = RandomForest::load(path);
    EXPECT_FALSE(r.forest);
    EXPECT_NE(r.error.find(words), std::string::npos) << r.error;
    EXPECT_EQ(r.error.rfind(path, 0), 0u) << r.error;  // names the file
  };
  auto flipped = good;
  flipped[40] ^= 0x10;
  expect_error(flipped, "checksum mismatch");
  expect_error(std::vector<std::uint8_t>(good.begin(), good.end() - 7), "truncated or corrupt");
  auto magic = good;
  magic[0] = 'X';
  expect_error(magic, "not a trailnav terrain model");
  auto version = good;
  version[8] = 9;
  expect_error(version, "version 9");
  expect_error({}, "not a trailnav terrain model");
  EXPECT_NE(RandomForest::load((dir / "missing.tnrf").string()).error.find("cannot open"), std::string::npos);
  fs::remove_all(dir);
}

// A model says which lidar's remissions it learnt; the tools refuse a model
// for another lidar. Files of the five-feature versions are refused by name.
TEST(RandomForest, ModelFileNamesItsLidarAndAnotherLidarIsRefused) {
  const fs::path dir = fs::temp_directory_path() / ("trailnav-forest-lidar-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string path = (dir / "m.tnrf").string();
  RandomForest f = stump({0.7f, 0.3f, 0, 0, 0}, {0, 0, 0.25f, 0.75f, 0});
  EXPECT_EQ(f.lidar(), "");
  EXPECT_EQ(check_forest_lidar(f, "HDL-64E", path), "");  // says nothing: any lidar
  EXPECT_NE(f.set_lidar("VLP 16").find("without spaces"), std::string::npos);
  EXPECT_NE(f.set_lidar("A-LIDAR-NAME-TOO-LONG").find("at most 15"), std::string::npos);
  EXPECT_EQ(f.lidar(), "");
  ASSERT_EQ(f.set_lidar("HDL-64E"), "");
  ASSERT_TRUE(f.save(path));
  const auto saved = file_bytes(path);
  auto back = RandomForest::load(path);
  ASSERT_TRUE(back.forest) << back.error;
  EXPECT_EQ(back.forest->lidar(), "HDL-64E");
  EXPECT_EQ(check_forest_lidar(*back.forest, "hdl-64e", path), "");
  const std::string e = check_forest_lidar(*back.forest, "VLP-16", path);
  EXPECT_EQ(e.rfind(path, 0), 0u) << e;
  EXPECT_NE(e.find("trained on HDL-64E returns, this lidar is VLP-16"), std::string::npos) << e;

  // A version 1 or 2 file holds a forest of the five per-cell features:
  // refused, saying what to do.
  for (const std::uint8_t old_version : {std::uint8_t{1}, std::uint8_t{2}}) {
    auto old = saved;
    old[8] = old_version;
    old[12] = 5;
    write_bytes(path, old);
    const std::string why = RandomForest::load(path).error;
    EXPECT_EQ(why.rfind(path + ": model format version " + std::to_string(old_version), 0), 0u) << why;
    EXPECT_NE(why.find("five per-cell features"), std::string::npos) << why;
    EXPECT_NE(why.find("trailnav terrain-train"), std::string::npos) << why;
  }

  // Text after the field's terminating NUL is corruption, named.
  auto bad = saved;
  bad[32 + 10] = 'x';
  const auto bad_crc = static_cast<std::uint32_t>(crc32(0L, bad.data(), static_cast<uInt>(bad.size() - 4)));
  for (std::size_t i = 0; i < 4; ++i) bad[bad.size() - 4 + i] = static_cast<std::uint8_t>(bad_crc >> (8 * i));
  write_bytes(path, bad);
  EXPECT_NE(RandomForest::load(path).error.find("malformed lidar field"), std::string::npos);

  // The shipped model is for the simulator's default lidar.
  auto shipped = RandomForest::load("board/models/terrain-sim.tnrf");
  ASSERT_TRUE(shipped.forest) << shipped.error;
  EXPECT_EQ(shipped.forest->lidar(), "VLP-16");
  fs::remove_all(dir);
}

// A model says the cells whose features it learnt (map resolution,
// min_points, the range of returns); the tools refuse a config that makes
// other cells, naming both, and take the model's when run without one.
// Version 3 files, which do not say, still load.
TEST(RandomForest, ModelFileSaysItsCellsAndAConfigOfOtherCellsIsRefused) {
  const fs::path dir = fs::temp_directory_path() / ("trailnav-forest-cells-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string path = (dir / "m.tnrf").string();
  RandomForest f = stump({0.7f, 0.3f, 0, 0, 0}, {0, 0, 0.25f, 0.75f, 0});
  TerrainConfig config;  // 0.2 m cells, 15 points, 1 to 30 m
  EXPECT_FALSE(f.feature_settings().said());
  EXPECT_EQ(check_forest_settings(f, config, path), "");  // says nothing: any cells
  EXPECT_NE(f.set_feature_settings({0.2f, 2, 1.0f, 30.0f}).find("min_points 2"), std::string::npos);
  EXPECT_NE(f.set_feature_settings({0.2f, 10, 20.0f, 15.0f}).find("above min_range"), std::string::npos);
  EXPECT_NE(f.set_feature_settings({5.0f, 10, 1.0f, 15.0f}).find("map resolution"), std::string::npos);
  EXPECT_FALSE(f.feature_settings().said());
  TerrainConfig hdl = config;
  hdl.min_points = 10;
  hdl.max_range = 15.0f;
  ASSERT_EQ(f.set_feature_settings(feature_settings_of(hdl)), "");
  ASSERT_TRUE(f.save(path));
  const auto saved = file_bytes(path);
  auto back = RandomForest::load(path);
  ASSERT_TRUE(back.forest) << back.error;
  EXPECT_TRUE(back.forest->feature_settings() == feature_settings_of(hdl));
  EXPECT_EQ(check_forest_settings(*back.forest, hdl, path), "");
  const std::string e = check_forest_settings(*back.forest, config, path);
  EXPECT_EQ(e.rfind(path, 0), 0u) << e;
  EXPECT_NE(e.find("learnt the features of cells of 0.2 m with at least 10 points, returns from 1 to 15 m"),
            std::string::npos) << e;
  EXPECT_NE(e.find("this config makes cells of 0.2 m with at least 15 points, returns from 1 to 30 m"), std::string::npos)
      << e;
  TerrainConfig adopted;
  adopt_forest_settings(*back.forest, adopted);
  EXPECT_EQ(check_forest_settings(*back.forest, adopted, path), "");
  EXPECT_EQ(adopted.min_points, 10);
  EXPECT_EQ(adopted.max_range, 15.0f);

  auto with_crc = [](std::vector<std::uint8_t> b) {
    const auto crc = static_cast<std::uint32_t>(crc32(0L, b.data(), static_cast<uInt>(b.size() - 4)));
    for (std::size_t i = 0; i < 4; ++i) b[b.size() - 4 + i] = static_cast<std::uint8_t>(crc >> (8 * i));
    return b;
  };
  // Settings out of range in an intact file: named.
  auto bad = saved;
  bad[48 + 4] = 1;  // min_points 1
  write_bytes(path, with_crc(bad));
  EXPECT_NE(RandomForest::load(path).error.find("feature settings: min_points 1"), std::string::npos)
      << RandomForest::load(path).error;
  // A version 3 file: the same without the 16 bytes of settings.
  auto v3 = saved;
  v3[8] = 3;
  v3.erase(v3.begin() + 48, v3.begin() + 64);
  write_bytes(path, with_crc(v3));
  auto old = RandomForest::load(path);
  ASSERT_TRUE(old.forest) << old.error;
  EXPECT_FALSE(old.forest->feature_settings().said());
  EXPECT_EQ(old.forest->lidar(), "");
  EXPECT_EQ(check_forest_settings(*old.forest, config, path), "");

  // The shipped HDL-64E model learnt cells of its robot config's settings.
  auto shipped = RandomForest::load("board/models/terrain-sim-hdl64e.tnrf");
  ASSERT_TRUE(shipped.forest) << shipped.error;
  const ConfigNode root = ConfigNode::load_file("board/robots/bench-hdl64e.yaml");
  EXPECT_EQ(check_forest_settings(*shipped.forest, parse_terrain_config(root.map("terrain")),
                                  "board/models/terrain-sim-hdl64e.tnrf"),
            "");
  EXPECT_EQ(shipped.forest->feature_settings().min_points, 10u);
  fs::remove_all(dir);
}

LabelledFeatures separable(int n, std::uint32_t seed) {
  // Street: bright and flat; grass: dark and rough; other: steep. Noise in
  // the remaining features.
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  LabelledFeatures d;
  for (int i = 0; i < n; ++i) {
    const int c = i % 3;
    FeatureVector f{u(rng) * 60.0f, 0.0f, u(rng) * 10.0f, 0.0f, u(rng) * 5.0f, u(rng) * 10.0f};
    if (c == 0) f[kMeanR] = 40.0f + u(rng) * 10.0f, f[kRough] = u(rng) * 1e-4f;
    if (c == 1) f[kMeanR] = 15.0f + u(rng) * 10.0f, f[kRough] = 1e-3f + u(rng) * 1e-3f;
    if (c == 2) f[kMeanR] = 15.0f + u(rng) * 35.0f, f[kSlope] = 50.0f + u(rng) * 40.0f;
    d.add(f, c == 0 ? TerrainClass::street : c == 1 ? TerrainClass::grass : TerrainClass::other);
  }
  return d;
}

TEST(ForestTraining, LearnsSeparableClassesAndIsReproducible) {
  const LabelledFeatures d = separable(3000, 7);
  ForestParams p;  // the thesis' defaults
  EXPECT_EQ(p.trees, 6);
  EXPECT_EQ(p.features_per_split, 2);
  EXPECT_EQ(p.min_samples_split, 100);
  p.threads = 2;
  const TrainedForest a = train_forest(d, p);
  ASSERT_TRUE(a.forest) << a.error;
  EXPECT_GT(a.out_of_bag.accuracy(), 0.99);
  const LabelledFeatures test = separable(600, 8);
  ConfusionMatrix m;
  for (std::size_t i = 0; i < test.size(); ++i) {
    ClassDistribution q;
    a.forest->predict(test.features[i], q);
    m.add(test.labels[i], static_cast<int>(std::max_element(q.begin(), q.end()) - q.begin()));
  }
  EXPECT_GT(m.accuracy(), 0.99) << format_confusion(m);
  // One thread or two, the same seed grows the same forest.
  p.threads = 1;
  const TrainedForest b = train_forest(d, p);
  ASSERT_TRUE(b.forest);
  ASSERT_EQ(a.forest->nodes(), b.forest->nodes());
  EXPECT_EQ(std::memcmp(a.forest->node_table().data(), b.forest->node_table().data(), a.forest->nodes() * sizeof(ForestNode)), 0);
  p.seed = 2;
  const TrainedForest c = train_forest(d, p);
  ASSERT_TRUE(c.forest);
  EXPECT_FALSE(c.forest->nodes() == a.forest->nodes() &&
               std::memcmp(a.forest->node_table().data(), c.forest->node_table().data(), a.forest->nodes() * sizeof(ForestNode)) == 0);
  // Bad input is refused with a reason.
  EXPECT_NE(train_forest(LabelledFeatures{}, p).error, "");
  p.features_per_split = 9;
  EXPECT_NE(train_forest(d, p).error.find("features per split"), std::string::npos);
}

// A mapper over a tiny grid whose cells are fed directly; the forest is a
// single leaf saying `likelihood` whatever the feature.
struct FixedMapper {
  explicit FixedMapper(ClassDistribution likelihood, TerrainConfig config = small_config()) {
    std::vector<ForestNode> nodes(1);
    nodes[0] = {-1, 0, 0.0f, 0};
    forest = std::move(*RandomForest::from_parts({0}, nodes, std::vector<float>(likelihood.begin(), likelihood.end())).forest);
    auto made = TerrainMapper::create(config, MountParams{}, {4, 64, 1}, &*forest);
    EXPECT_TRUE(made.mapper) << made.error;
    mapper = std::move(made.mapper);
    mapper->step(0);  // opens the first interval
  }
  static TerrainConfig small_config() {
    TerrainConfig c;
    c.map = {20, 20, 0.2};
    c.max_range = 2.5f;
    c.step_distance = 0.5;
    c.min_points = 5;
    c.reopen_after = 10.0;
    return c;
  }
  void feed(double x, double y, int points) {
    TerrainWorkCell& w = mapper->work().at(mapper->work().world_to_index(x, y));
    for (int i = 0; i < points; ++i) w.stats.add(0.01f * static_cast<float>(i % 7), 0.013f * static_cast<float>(i % 5), 0.0f, 30.0f);
  }
  const TerrainCell& cell(double x, double y) { return *mapper->map().grid().find(x, y); }
  std::optional<RandomForest> forest;
  std::unique_ptr<TerrainMapper> mapper;
};

TEST(TerrainMapper, BayesUpdateFreezesAfterTenConfidentObservationsAndReopens) {
  FixedMapper m({0.6f, 0.1f, 0.1f, 0.1f, 0.1f});
  m.feed(0.3, 0.3, 4);  // below minPoints: no feature yet, the points wait
  m.mapper->step(1'000'000'000);
  EXPECT_FALSE(m.cell(0.3, 0.3).known);
  m.feed(0.3, 0.3, 1);
  m.mapper->step(2'000'000'000);
  ASSERT_TRUE(m.cell(0.3, 0.3).known);
  EXPECT_NEAR(m.cell(0.3, 0.3).p[0], 0.6f, 1e-6);  // uniform prior: the first posterior is P(t | f)
  // Eq. 7.15: after n observations P(street) = 0.6^n / (0.6^n + 4 * 0.1^n),
  // with every class kept at least at min_probability.
  std::array<double, kTerrainClasses> ref{0.6, 0.1, 0.1, 0.1, 0.1};
  const double lik[] = {0.6, 0.1, 0.1, 0.1, 0.1};
  for (int n = 2; n <= 11; ++n) {
    m.feed(0.3, 0.3, 5);
    m.mapper->step(std::int64_t{n + 1} * 1'000'000'000);
    double sum = 0.0;
    for (int t = 0; t < kTerrainClasses; ++t) sum += ref[static_cast<std::size_t>(t)] *= lik[t];
    for (double& v : ref) v = std::max(v / sum, 1e-4);
    sum = 0.0;
    for (double v : ref) sum += v;
    EXPECT_NEAR(m.cell(0.3, 0.3).p[0], ref[0] / sum, 1e-5) << n;
    if (n <= 4) {
      EXPECT_NEAR(ref[0] / sum, std::pow(0.6, n) / (std::pow(0.6, n) + 4.0 * std::pow(0.1, n)), 1e-6);
    }
  }
  EXPECT_EQ(m.mapper->counters().frozen, 1u);  // more than ten observations, above 0.9
  EXPECT_EQ(m.mapper->counters().features, 11u);
  // Frozen: further features leave it alone ...
  m.feed(0.3, 0.3, 5);
  m.mapper->step(13'000'000'000);
  EXPECT_EQ(m.mapper->counters().features, 11u);
  EXPECT_EQ(m.mapper->counters().frozen_skipped, 1u);
  // ... until reopen_after (10 s) has passed.
  m.feed(0.3, 0.3, 5);
  m.mapper->step(23'000'000'000);
  EXPECT_EQ(m.mapper->counters().reopened, 1u);
  EXPECT_EQ(m.mapper->counters().features, 12u);
  EXPECT_EQ(m.cell(0.3, 0.3).best, TerrainClass::street);
  // A cell nobody saw is unknown, not classified.
  EXPECT_FALSE(m.cell(2.5, 2.5).known);
}

// The sixth feature: the spread of remission over all points of the 5 x 5
// cells around a cell at this step, those with too few points for a feature
// of their own included; a cell farther away does not count, and a cell
// alone has its own spread.
TEST(TerrainMapper, AreaRemissionSpreadPoolsThePointsOfTheCellsAround) {
  struct Collect : TerrainObserver {
    std::vector<std::pair<CellIndex, FeatureVector>> seen;
    void observe(const TerrainObservation& o) override { seen.emplace_back(o.cell, o.feature); }
  } collect;
  FixedMapper m({0.6f, 0.1f, 0.1f, 0.1f, 0.1f});
  m.mapper->set_observer(&collect);
  const CellIndex o = m.mapper->work().origin();  // 20 x 20 cells
  const CellIndex centre{o.x + 6, o.y + 6};
  std::vector<double> area;  // every remission the centre's area holds
  std::map<std::pair<int, int>, std::vector<double>> by_cell;  // every remission, per cell
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int dy = -3; dy <= 3; ++dy) {
    for (int dx = -3; dx <= 3; ++dx) {
      const CellIndex i{centre.x + dx, centre.y + dy};
      const int points = (dx + dy) % 2 == 0 ? 8 : 3;  // some cells below min_points (5)
      // Far cells (3 away) are bright, so counting them would show.
      const float base = std::abs(dx) == 3 || std::abs(dy) == 3 ? 200.0f : 20.0f + 4.0f * static_cast<float>(dx + 2 * dy);
      TerrainWorkCell& w = m.mapper->work().at(i);
      for (int k = 0; k < points; ++k) {
        const float r = base + 10.0f * u(rng);
        w.stats.add(0.02f * static_cast<float>(k % 3), 0.03f * static_cast<float>(k % 2), 0.001f * static_cast<float>(k), r);
        if (std::abs(dx) <= 2 && std::abs(dy) <= 2) area.push_back(r);
        by_cell[{i.x, i.y}].push_back(r);
      }
    }
  }
  // And a lone cell with nobody around, in the corner of the window.
  const CellIndex lone{o.x + 19, o.y + 19};  // the window's corner: its area is clipped
  ASSERT_TRUE(m.mapper->work().contains(lone));
  for (int k = 0; k < 6; ++k) m.mapper->work().at(lone).stats.add(0.01f * static_cast<float>(k), 0.0f, 0.0f, 30.0f + 2.0f * static_cast<float>(k));
  m.mapper->step(1'000'000'000);
  double mean = 0.0, var = 0.0;
  for (double r : area) mean += r;
  mean /= static_cast<double>(area.size());
  for (double r : area) var += (r - mean) * (r - mean);
  const double expected = std::sqrt(var / static_cast<double>(area.size()));
  constexpr int kArea = static_cast<int>(TerrainFeature::area_std_remission);
  constexpr int kOwn = static_cast<int>(TerrainFeature::std_remission);
  bool saw_centre = false, saw_lone = false;
  for (const auto& [i, f] : collect.seen) {
    if (i.x == centre.x && i.y == centre.y) {
      saw_centre = true;
      EXPECT_NEAR(f[kArea], expected, 1e-3 * expected);
      EXPECT_GT(f[kArea], 3.0f * f[kOwn]);  // the area's gradient, which one cell does not see
    }
    if (i.x == lone.x && i.y == lone.y) {
      saw_lone = true;
      EXPECT_NEAR(f[kArea], f[kOwn], 1e-4f);
      EXPECT_NEAR(f[kOwn], std::sqrt(35.0f / 3.0f), 1e-3f);  // 30, 32, ..., 40
    }
  }
  EXPECT_TRUE(saw_centre);
  EXPECT_TRUE(saw_lone);
  // Every cell that got a feature, at the block's edges too, against the
  // spread of every point within two cells of it.
  std::size_t checked = 0;
  for (const auto& [i, f] : collect.seen) {
    if (i.x == lone.x && i.y == lone.y) continue;
    std::vector<double> around;
    for (int dy = -kAreaRadius; dy <= kAreaRadius; ++dy) {
      for (int dx = -kAreaRadius; dx <= kAreaRadius; ++dx) {
        const auto it = by_cell.find({i.x + dx, i.y + dy});
        if (it != by_cell.end()) around.insert(around.end(), it->second.begin(), it->second.end());
      }
    }
    double around_mean = 0.0, v = 0.0;
    for (double r : around) around_mean += r;
    around_mean /= static_cast<double>(around.size());
    for (double r : around) v += (r - around_mean) * (r - around_mean);
    const double want = std::sqrt(v / static_cast<double>(around.size()));
    EXPECT_NEAR(f[kArea], want, 1e-3 * want + 1e-3) << "cell " << i.x - o.x << "," << i.y - o.y;
    ++checked;
  }
  EXPECT_GE(checked, 20u);  // the cells of 8 points in the 7 x 7 block
}

TEST(TerrainMapper, ProbabilitiesStayAboveTheFloorSoEvidenceCanTurnACell) {
  TerrainConfig c = FixedMapper::small_config();
  c.freeze_observations = 60000;
  FixedMapper m({0.0f, 0.0f, 1.0f, 0.0f, 0.0f}, c);  // the forest is certain: grass
  for (int n = 1; n <= 30; ++n) {
    m.feed(0.5, 0.5, 5);
    m.mapper->step(std::int64_t{n} * 1'000'000'000);
  }
  const TerrainCell& cell = m.cell(0.5, 0.5);
  EXPECT_EQ(cell.best, TerrainClass::grass);
  for (float p : cell.p) EXPECT_GE(p, c.min_probability * 0.99f);
}

TEST(TerrainMapper, RealKittiRoadCellsAreFlatAndSmooth) {
  velodyne::RangeImage image(kitti_shape());
  std::vector<float> buffer;
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, image));
  TerrainConfig config;
  config.max_step_interval = 0.0;
  MountParams mount;
  mount.translation = {0.0, 0.0, 1.73};  // KITTI's Velodyne above the road
  auto made = TerrainMapper::create(config, mount, image.shape(), nullptr);
  ASSERT_TRUE(made.mapper) << made.error;
  struct Collect final : TerrainObserver {
    void observe(const TerrainObservation& o) override {
      // The lane ahead of the car: 4 to 12 m forward, within 1.5 m of the centre line.
      if (o.x > 4.0 && o.x < 12.0 && std::abs(o.y) < 1.5) road.push_back(o.feature);
      ++cells;
    }
    std::vector<FeatureVector> road;
    int cells = 0;
  } collect;
  made.mapper->set_observer(&collect);
  made.mapper->process(image, nullptr);  // opens the interval
  made.mapper->step(1);                  // computes the features
  EXPECT_GT(collect.cells, 1000);
  ASSERT_GT(collect.road.size(), 20u);
  // Asphalt: smooth to a few millimetres, and level; over a 0.2 m cell the
  // lidar's noise tilts a fitted plane by a few degrees at most.
  std::vector<float> slopes;
  int smooth = 0;
  for (const FeatureVector& f : collect.road) {
    smooth += f[kRough] < 1e-4f ? 1 : 0;
    slopes.push_back(f[kSlope]);
    EXPECT_LT(f[kSlope], 15.0f);
  }
  EXPECT_GE(smooth, static_cast<int>(0.95 * static_cast<double>(collect.road.size())));
  std::nth_element(slopes.begin(), slopes.begin() + static_cast<std::ptrdiff_t>(slopes.size() / 2), slopes.end());
  EXPECT_LT(slopes[slopes.size() / 2], 6.0f);
}

// trailnavd's terrain thread registers the points the obstacle thread
// aligned (RevolutionCloud::hand_over_aligned()) instead of aligning each
// revolution again. On real KITTI revolutions (the robot driving 0.3 m a
// revolution, so steps run), with a self box and the terrain's own 30 m
// inside the obstacles' 40 m: the class map, the registered points and the
// work grid are those of a mapper aligning for itself with the obstacle
// config's alignment, bit for bit; and the pipeline that handed its arrays
// away maps exactly as one that never did.
TEST(TerrainMapper, TheObstacleThreadsAlignedPointsGiveTheSameMapBitForBit) {
  std::array<velodyne::RangeImage, 2> scans{velodyne::RangeImage(kitti_shape()), velodyne::RangeImage(kitti_shape())};
  std::vector<float> buffer;
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, scans[0]));
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000001.bin"), buffer, scans[1]));
  auto model = RandomForest::load("board/models/terrain-sim.tnrf");
  ASSERT_TRUE(model.forest) << model.error;
  ObstacleConfig oc;
  oc.mount.translation = {0.0, 0.0, 1.73};
  oc.features.self_box = std::array<float, 6>{-2.5f, 2.5f, -1.0f, 1.0f, -2.0f, 0.2f};
  TerrainConfig tc;
  auto own = TerrainMapper::create(tc, oc.mount, kitti_shape(), &*model.forest, oc.features);
  auto shared = TerrainMapper::create(tc, oc.mount, kitti_shape(), &*model.forest, oc.features);
  ASSERT_TRUE(own.mapper && shared.mapper) << own.error;
  auto handing = ObstaclePipeline::create(oc, kitti_shape());
  auto keeping = ObstaclePipeline::create(oc, kitti_shape());
  ASSERT_TRUE(handing.pipeline && keeping.pipeline) << handing.error;
  AlignedRevolution slot(CloudShape{kitti_shape().rings, kitti_shape().max_columns});

  PoseTrack poses(64);
  std::uint64_t steps = 0;
  const std::size_t cells = static_cast<std::size_t>(tc.map.size_x) * static_cast<std::size_t>(tc.map.size_y);
  std::vector<std::uint8_t> a(2 * cells), b(2 * cells);
  const auto map_cells = static_cast<std::size_t>(oc.map.size) * static_cast<std::size_t>(oc.map.size);
  std::vector<std::int8_t> ga(map_cells), gb(map_cells);
  for (int n = 1; n <= 12; ++n) {
    const std::int64_t t = std::int64_t{n} * 100'000'000;
    poses.push({t - 100'000'000, 0.3 * (n - 1), 0.02 * (n - 1), 0.0, 0.0, 0.0, 0.01 * (n - 1)});
    poses.push({t, 0.3 * n, 0.02 * n, 0.0, 0.0, 0.0, 0.01 * n});
    velodyne::RangeImage& image = scans[static_cast<std::size_t>(n % 2)];
    image.sequence = static_cast<std::uint64_t>(n);
    image.start_ns = t - 100'000'000;
    image.end_ns = t;
    const bool stepped = own.mapper->process(image, &poses);
    handing.pipeline->process(image, &poses, nullptr);
    keeping.pipeline->process(image, &poses, nullptr);
    handing.pipeline->hand_over_aligned(slot.cloud);
    EXPECT_EQ(shared.mapper->process_aligned(slot.cloud), stepped) << "revolution " << n;
    steps += stepped ? 1 : 0;
    own.mapper->map().export_classes(std::span(a).first(cells), std::span(a).subspan(cells));
    shared.mapper->map().export_classes(std::span(b).first(cells), std::span(b).subspan(cells));
    ASSERT_TRUE(a == b) << "class maps differ after revolution " << n;
    handing.pipeline->map().export_occupancy(ga);
    keeping.pipeline->map().export_occupancy(gb);
    ASSERT_TRUE(ga == gb) << "obstacle maps differ after revolution " << n;
  }
  const TerrainCounters ca = own.mapper->counters(), cb = shared.mapper->counters();
  EXPECT_GE(steps, 5u);
  EXPECT_GT(ca.known_cells, 1000u);
  EXPECT_EQ(cb.known_cells, ca.known_cells);
  EXPECT_EQ(cb.points, ca.points);
  EXPECT_EQ(cb.features, ca.features);
  EXPECT_GT(cb.points, 12u * 50'000u);
  // The points between the terrain's 30 m and the obstacles' 40 m were aligned, and left out here.
  EXPECT_GT(cb.out_of_range, 12u * 1'000u);
  EXPECT_EQ(cb.out_of_range, ca.out_of_range);
  EXPECT_GT(ca.align.self_hits, 0u);
  auto& wa = own.mapper->work();
  const auto& wb = shared.mapper->work();
  ASSERT_EQ(wa.origin().x, wb.origin().x);
  ASSERT_EQ(wa.origin().y, wb.origin().y);
  std::size_t compared = 0, differ = 0;
  wa.for_each_in_window(wa.origin(), {wa.origin().x + wa.size_x(), wa.origin().y + wa.size_y()},
                        [&](CellIndex i, const TerrainWorkCell& w) {
                          differ += std::memcmp(&wb.at(i).stats, &w.stats, sizeof w.stats) != 0 ? 1u : 0u;
                          ++compared;
                        });
  EXPECT_EQ(differ, 0u);
  EXPECT_EQ(compared, cells);
}

TEST(TerrainMapper, ATerrainRangeBeyondTheAlignedPointsIsAnError) {
  TerrainConfig tc;
  FeatureParams alignment;
  alignment.max_range = 25.0f;
  const auto made = TerrainMapper::create(tc, MountParams{}, kitti_shape(), nullptr, alignment);
  EXPECT_FALSE(made.mapper);
  EXPECT_NE(made.error.find("1..30 m reaches outside the 1..25 m of obstacles.features"), std::string::npos) << made.error;
  tc.max_range = 25.0f;
  tc.min_range = 0.5f;
  EXPECT_NE(check_terrain_alignment(tc, alignment).find("0.5..25 m"), std::string::npos);
  tc.min_range = 2.0f;
  EXPECT_EQ(check_terrain_alignment(tc, alignment), "");
}

TEST(TerrainCost, ExpectedClassCostOfACellAndUnknownCells) {
  const TerrainConfig c;  // §8.1.2: street 0.1, dirt 0.2, grass 0.4, vegetation 0.8, other 1.0
  TerrainCell cell;
  EXPECT_FLOAT_EQ(terrain_cost(cell, c.cost, 0.7f), 0.7f);  // not classified yet
  cell.set({0.0f, 0.0f, 1.0f, 0.0f, 0.0f});
  EXPECT_FLOAT_EQ(terrain_cost(cell, c.cost, c.unknown_cost), 0.4f);
  cell.set({0.5f, 0.0f, 0.5f, 0.0f, 0.0f});
  EXPECT_FLOAT_EQ(terrain_cost(cell, c.cost, c.unknown_cost), 0.25f);
}

TEST(TerrainConfig, DefaultsAreTheThesisAndMistakesNameFileAndLine) {
  const TerrainConfig d;
  EXPECT_EQ(d.map.size_x, 300);
  EXPECT_DOUBLE_EQ(d.map.resolution, 0.2);
  EXPECT_DOUBLE_EQ(d.step_distance, 0.5);
  EXPECT_EQ(d.freeze_observations, 10);
  EXPECT_FLOAT_EQ(d.freeze_probability, 0.9f);
  EXPECT_FLOAT_EQ(d.cost[static_cast<int>(TerrainClass::grass)], 0.4f);
  const ConfigNode ok = ConfigNode::parse("terrain:\n  model: m.tnrf\n  cost: {grass: 0.5}\n", "/etc/robot.yaml");
  const TerrainConfig c = parse_terrain_config(ok.map("terrain"));
  EXPECT_EQ(c.model, "/etc/m.tnrf");
  EXPECT_FLOAT_EQ(c.cost[static_cast<int>(TerrainClass::grass)], 0.5f);
  try {
    const ConfigNode bad = ConfigNode::parse("terrain:\n  min_points: 1\n", "robot.yaml");
    (void)parse_terrain_config(bad.map("terrain"));
    FAIL() << "accepted min_points 1";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("robot.yaml:2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("min_points"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace trailnav::perception
