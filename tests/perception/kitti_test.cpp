// Real HDL-64E geometry: the KITTI scans in ../shared/data/kitti/ become
// 64-ring range images, and the obstacle map built from them shows the cars
// and walls around the road without fake obstacles on the road.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "test_data.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/obstacle_pipeline.hpp"

namespace trailnav::perception {
namespace {

TEST(Kitti, RingsAreRecoveredFromTheFiringOrder) {
  for (const char* name : {"kitti/000000.bin", "kitti/000001.bin"}) {
    velodyne::RangeImage image(kitti_shape());
    std::vector<float> buffer;
    KittiStats stats;
    ASSERT_TRUE(load_kitti_scan(test::shared_data(name), buffer, image, &stats)) << name;
    EXPECT_GT(stats.points, 120000u);
    // About 7 % of the points share a column with an earlier point of their
    // laser (the lasers fire at slightly uneven azimuths) and are dropped, counted.
    EXPECT_GT(static_cast<double>(stats.placed), 0.9 * static_cast<double>(stats.points)) << stats.collisions;
    EXPECT_EQ(stats.placed + stats.collisions + stats.invalid, stats.points);
    // Row 0 is the lowest laser (about -24.8 degrees), row 63 the highest (+2).
    auto median_elevation = [&](int ring) {
      std::vector<double> el;
      for (int c = 0; c < image.columns(); ++c) {
        const auto& cell = image.at(0, ring, c);
        if (cell.valid()) el.push_back(static_cast<double>(std::atan2(cell.z, std::hypot(cell.x, cell.y))) * 180.0 / M_PI);
      }
      std::nth_element(el.begin(), el.begin() + static_cast<std::ptrdiff_t>(el.size() / 2), el.end());
      return el[el.size() / 2];
    };
    EXPECT_NEAR(median_elevation(0), -24.0, 1.0);
    EXPECT_NEAR(median_elevation(63), 2.5, 0.5);
    for (int r = 1; r < 64; ++r) EXPECT_LE(median_elevation(r - 1), median_elevation(r) + 1e-9) << r;
  }
}

TEST(Kitti, BrokenFilesAreRefusedWithAReason) {
  const std::string path = (std::filesystem::temp_directory_path() / "trailnav-kitti-bad.bin").string();
  std::FILE* f = std::fopen(path.c_str(), "wb");
  const char bytes[10] = {};
  std::fwrite(bytes, 1, sizeof bytes, f);
  std::fclose(f);
  velodyne::RangeImage image(kitti_shape());
  std::vector<float> buffer;
  const Status st = load_kitti_scan(path, buffer, image);
  EXPECT_FALSE(st);
  EXPECT_NE(st.message().find("16-byte points"), std::string::npos) << st.message();
  // Points in the wrong order (one sweep) are not an HDL-64E scan.
  std::vector<float> sweep;
  for (int i = 0; i < 1000; ++i) {
    const double a = 2.0 * M_PI * i / 1000.0;
    sweep.insert(sweep.end(), {static_cast<float>(5 * std::cos(a)), static_cast<float>(5 * std::sin(a)), -1.0f, 0.1f});
  }
  const Status st2 = kitti_to_range_image(sweep, "sweep", image);
  EXPECT_FALSE(st2);
  EXPECT_NE(st2.message().find("found 1 laser sweeps"), std::string::npos) << st2.message();
  std::filesystem::remove(path);
}

TEST(Kitti, MapShowsRealObstaclesAndAClearRoad) {
  ObstacleConfig config;
  config.fixed_class = TerrainClass::street;
  config.features.self_box = kKittiCarBox;  // as trailnav obstacles does for KITTI scans
  config.compare_models = true;
  auto made = ObstaclePipeline::create(config, kitti_shape());
  ASSERT_TRUE(made.pipeline) << made.error;
  velodyne::RangeImage image(kitti_shape());
  std::vector<float> buffer;
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, image));
  made.pipeline->process(image, nullptr, nullptr);
  for (FusionModel m : {FusionModel::pw, FusionModel::ps, FusionModel::pc}) {
    const ObstacleMap& map = *made.pipeline->map(m);
    const auto& g = map.grid();
    // The road ahead of the car (x 4..20 m, |y| <= 1.5 m) is observed and free.
    std::size_t road = 0, fake = 0;
    for (double x = 4.05; x < 20.0; x += 0.1) {
      for (double y = -1.45; y <= 1.5; y += 0.1) {
        const ObstacleCell& c = *g.find(x, y);
        if (map.state(c) == CellState::unknown) continue;
        ++road;
        if (map.state(c) == CellState::occupied) ++fake;
      }
    }
    EXPECT_GT(road, 1000u) << fusion_model_name(m);
    // (PW had three fake cells here: at (4.45, 0.95) a stray return 30 m
    // away and 11.5 m below the road was a ground point's cross-ring
    // neighbour (neighbour_reach drops it); at (4.55, -0.95) and (4.65, -0.85)
    // the car's own bonnet was (the self box drops it).)
    EXPECT_EQ(fake, 0u) << fusion_model_name(m);
    // Cars and walls: thousands of occupied cells in the rest of the map.
    std::size_t occupied = 0;
    for (std::int32_t y = 0; y < g.size_y(); ++y) {
      for (std::int32_t x = 0; x < g.size_x(); ++x) {
        occupied += map.state(g.at({g.origin().x + x, g.origin().y + y})) == CellState::occupied;
      }
    }
    EXPECT_GT(occupied, 3000u) << fusion_model_name(m);
  }
}

// The recording car's own body, roof rack and mirrors return points within a
// few metres of the sensor; without features.self_box they are obstacles
// drawn around the robot. With the KITTI car box they are dropped and counted,
// and no cell under the car is occupied.
TEST(Kitti, TheRecordingCarItselfIsNotAnObstacle) {
  std::vector<float> buffer;
  velodyne::RangeImage image(kitti_shape());
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, image));
  const auto occupied_under_car = [](const ObstacleMap& map) {
    std::size_t n = 0;
    for (double x = -2.75; x < 2.8; x += 0.1) {
      for (double y = -1.55; y < 1.6; y += 0.1) n += map.state(*map.grid().find(x, y)) == CellState::occupied;
    }
    return n;
  };
  ObstacleConfig plain;
  plain.fixed_class = TerrainClass::street;
  plain.model = FusionModel::pw;
  auto without = ObstaclePipeline::create(plain, kitti_shape());
  ASSERT_TRUE(without.pipeline) << without.error;
  without.pipeline->process(image, nullptr, nullptr);
  EXPECT_EQ(without.pipeline->counters().align.self_hits, 0u);
  EXPECT_GT(occupied_under_car(*without.pipeline->map(FusionModel::pw)), 3u);

  ObstacleConfig boxed = plain;
  boxed.features.self_box = kKittiCarBox;
  auto with = ObstaclePipeline::create(boxed, kitti_shape());
  ASSERT_TRUE(with.pipeline) << with.error;
  with.pipeline->process(image, nullptr, nullptr);
  EXPECT_GT(with.pipeline->counters().align.self_hits, 20u);
  EXPECT_LT(with.pipeline->counters().align.self_hits, 500u);  // the car, not the road around it
  EXPECT_EQ(occupied_under_car(*with.pipeline->map(FusionModel::pw)), 0u);
}

}  // namespace
}  // namespace trailnav::perception

namespace trailnav::perception {
namespace {

// The eight-wide (AVX2, where the CPU has it) and four-wide neighbour
// searches find the same neighbours as the portable one on real HDL-64E
// geometry: every point's state, stepHeight and sin(incline) bit for bit,
// with and without a full turn (the ring ends).
// The W-wide neighbour searches take a point to exist where its range is
// above 0: the aligner must write the two together, also for the returns it
// drops (out of range, the car itself).
TEST(Kitti, AlignedPointsExistExactlyWhereTheirRangeIsAboveZero) {
  velodyne::RangeImage image(kitti_shape());
  std::vector<float> buffer;
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, image));
  ObstacleConfig config;
  config.features.self_box = kKittiCarBox;
  config.features.max_range = 40.0f;
  RevolutionCloud cloud(CloudShape{image.rings(), image.shape().max_columns});
  CloudAligner aligner(config.mount, config.features);
  aligner.align(image, nullptr, cloud);
  EXPECT_GT(aligner.counters().out_of_range, 1'000u);
  EXPECT_GT(aligner.counters().self_hits, 10u);
  std::size_t points = 0, mismatched = 0;
  for (int i = 0; i < cloud.rings(); ++i) {
    for (int j = 0; j < cloud.columns(); ++j) {
      const std::size_t k = cloud.index(i, j);
      const bool exists = cloud.state[k] != PointState::none;
      if (exists) ++points;
      if (exists != (cloud.range[k] > 0.0f)) ++mismatched;
    }
  }
  EXPECT_GT(points, 50'000u);
  EXPECT_EQ(mismatched, 0u);
}

TEST(Kitti, EveryFeatureSearchAgreesBitForBit) {
  std::printf("four-wide search: %s, eight-wide (AVX2): %s\n", simd_features_available() ? "yes" : "no",
              wide_features_available() ? "yes" : "no");
  for (const char* name : {"kitti/000000.bin", "kitti/000001.bin"}) {
    velodyne::RangeImage image(kitti_shape());
    std::vector<float> buffer;
    ASSERT_TRUE(load_kitti_scan(test::shared_data(name), buffer, image)) << name;
    const ObstacleConfig config;
    for (const bool full_turn : {true, false}) {
      RevolutionCloud aligned(CloudShape{image.rings(), image.shape().max_columns});
      CloudAligner aligner(config.mount, config.features);
      aligner.align(image, nullptr, aligned);
      aligned.full_turn = full_turn;
      smooth_rings(aligned, config.features);
      RevolutionCloud portable = aligned;
      FeatureCounters portable_counts;
      compute_features(portable, config.features, portable_counts, FeatureKernel::portable);
      EXPECT_GT(portable_counts.measured, 50'000u);
      for (const FeatureKernel kernel : {FeatureKernel::fastest, FeatureKernel::four_wide}) {
        RevolutionCloud fast = aligned;
        FeatureCounters fast_counts;
        compute_features(fast, config.features, fast_counts, kernel);
        EXPECT_EQ(fast_counts.measured, portable_counts.measured);
        EXPECT_EQ(fast_counts.flat, portable_counts.flat);
        EXPECT_EQ(fast_counts.isolated, portable_counts.isolated);
        std::size_t differ = 0;
        for (std::size_t k = 0; k < fast.state.size(); ++k) {
          if (fast.state[k] != portable.state[k]) ++differ;
          if (fast.state[k] != PointState::measured) continue;
          if (std::memcmp(&fast.step_height[k], &portable.step_height[k], sizeof(float)) != 0 ||
              std::memcmp(&fast.sin_incline[k], &portable.sin_incline[k], sizeof(float)) != 0) {
            ++differ;
          }
        }
        EXPECT_EQ(differ, 0u) << name << (full_turn ? " full turn" : " open ring")
                              << (kernel == FeatureKernel::fastest ? " fastest" : " four-wide");
      }
    }
  }
}

}  // namespace
}  // namespace trailnav::perception
