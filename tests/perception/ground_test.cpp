// The height above the ground (ground_height.hpp): what it does to a
// point's step on made-up clouds whose answer is known, and on the real
// KITTI scans under the allocation guard and in the streaming pipeline.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "test_data.hpp"
#include "trailnav/perception/ground_height.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/obstacle_pipeline.hpp"
#include "trailnav/runtime/alloc_guard.hpp"

namespace trailnav::perception {
namespace {

// A cloud of points given one by one (ring 0, one column each), all
// measured with the step given.
struct Points {
  explicit Points(int n) : cloud(CloudShape{1, n}) { cloud.reset(n); }
  void add(float x, float y, float z, float step, float sin_incline = 0.0f) {
    const auto k = static_cast<std::size_t>(next++);
    cloud.x[k] = x;
    cloud.y[k] = y;
    cloud.z[k] = z;
    cloud.range[k] = std::hypot(x, y, z);
    cloud.step_height[k] = step;
    cloud.sin_incline[k] = sin_incline;
    cloud.state[k] = PointState::measured;
  }
  RevolutionCloud cloud;
  int next = 0;
};

// Flat ground at z = -1.7 (points every 0.25 m from 5 to 12 m ahead), a
// 4 cm curb from x = 7.2 on, whose top edge the features saw as a 12 cm step
// (its neighbour a road point in front), and a pole standing on the curb's
// side at x = 10 (a point each 0.3 m up to 1.5 m; their neighbours on the
// pole itself: steps 5 cm, incline flat).
TEST(Ground, APoleStandsOnTheGroundAndACurbIsCutToItsHeight) {
  Points p(1024);
  for (float x = 5.0f; x <= 12.0f; x += 0.25f) {
    for (float y = -1.0f; y <= 1.0f; y += 0.1f) p.add(x, y, -1.7f + (x >= 7.2f ? 0.04f : 0.0f), 0.0f);
  }
  const int curb = p.next;
  p.add(7.25f, 0.1f, -1.66f, 0.12f, 0.9f);
  const int pole = p.next;
  for (int k = 1; k <= 5; ++k) p.add(10.0f, 0.1f, -1.7f + 0.3f * static_cast<float>(k), 0.05f, 0.1f);
  GroundGrid g(GroundParams{true, 0.5f, 2.0f, 0.2f, 0.2f}, 40.0f, p.cloud.x.size());
  g.build(p.cloud);
  EXPECT_NEAR(g.ground_at(6.0f, 0.0f), -1.7f, 1e-6f);
  EXPECT_NEAR(g.ground_at(7.25f, 0.1f), -1.7f, 1e-6f);  // the cell [7.0, 7.5) holds road points
  EXPECT_NEAR(g.ground_at(10.0f, 0.0f), -1.66f, 1e-6f);
  std::vector<float> height(p.cloud.x.size());
  g.apply(p.cloud, height);
  // The pole: 0.3 m and up above the ground, so a step that high, vertical.
  for (int k = 0; k < 5; ++k) {
    const auto i = static_cast<std::size_t>(pole + k);
    EXPECT_NEAR(height[i], 0.3f * static_cast<float>(k + 1) - 0.04f, 1e-5f) << k;
    EXPECT_NEAR(p.cloud.step_height[i], 0.3f * static_cast<float>(k + 1) - 0.04f, 1e-5f) << k;
    EXPECT_EQ(p.cloud.sin_incline[i], 1.0f);
  }
  // The curb's edge stands 4 cm above its own cell's ground: its step is 4 cm now.
  EXPECT_NEAR(p.cloud.step_height[static_cast<std::size_t>(curb)], 0.04f, 1e-5f);
  EXPECT_EQ(g.counters().raised, 5u);   // the pole's points, 0.26 m and up
  EXPECT_EQ(g.counters().lowered, 1u);  // the curb's edge
}

// One stray return 3 m below the ground in a cell (as KITTI has) is not
// the ground: the second lowest point of a cell is.
TEST(Ground, AStrayReturnBelowTheGroundIsNotTheGround) {
  Points p(64);
  for (float x = 5.0f; x < 7.0f; x += 0.25f) p.add(x, 0.2f, -1.7f, 0.0f);
  p.add(6.1f, 0.2f, -4.7f, 0.0f);
  GroundGrid g(GroundParams{true}, 40.0f, p.cloud.x.size());
  g.build(p.cloud);
  EXPECT_NEAR(g.ground_at(6.1f, 0.2f), -1.7f, 1e-6f);
}

// A 10 % ramp (6 degrees) is ground: no point on it stands 0.2 m above the
// ground the slope allowance (0.2 per metre) gives.
TEST(Ground, ARampWithinTheSlopeIsGround) {
  Points p(2048);
  for (float x = 2.0f; x < 20.0f; x += 0.2f) {
    for (float y = -2.0f; y <= 2.0f; y += 0.4f) p.add(x, y, -1.7f + 0.1f * x, 0.02f, 0.1f);
  }
  GroundGrid g(GroundParams{true}, 40.0f, p.cloud.x.size());
  g.build(p.cloud);
  std::vector<float> height(p.cloud.x.size());
  g.apply(p.cloud, height);
  EXPECT_EQ(g.counters().raised, 0u);
  float highest = 0.0f;
  for (int k = 0; k < p.next; ++k) highest = std::max(highest, height[static_cast<std::size_t>(k)]);
  EXPECT_LT(highest, 0.2f);
}

// Points with no ground cell near (beyond the grid) keep their features.
TEST(Ground, PointsBeyondTheGridKeepTheirFeatures) {
  Points p(8);
  p.add(300.0f, 0.0f, 5.0f, 0.3f, 0.7f);
  GroundGrid g(GroundParams{true}, 40.0f, p.cloud.x.size());
  g.build(p.cloud);
  std::vector<float> height(p.cloud.x.size());
  g.apply(p.cloud, height);
  EXPECT_TRUE(std::isnan(height[0]));
  EXPECT_EQ(p.cloud.step_height[0], 0.3f);
  EXPECT_EQ(g.counters().no_ground, 1u);
}

// On the real scans, in the streaming pipeline: the maps the same bits
// whatever steps the revolution arrived in, and no allocation once made.
TEST(Ground, RealScansStreamedGiveTheSameMapsWithoutTheHeap) {
  ObstacleConfig config;
  config.ground.enabled = true;
  config.features.self_box = kKittiCarBox;
  velodyne::RangeImage image(kitti_shape());
  std::vector<float> buffer;
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, image));
  auto whole = ObstaclePipeline::create(config, kitti_shape());
  auto steps = ObstaclePipeline::create(config, kitti_shape());
  ASSERT_TRUE(whole.pipeline && steps.pipeline);
  // First touch of the pages; each pipeline takes the scan twice.
  whole.pipeline->process(image, nullptr, nullptr);
  steps.pipeline->process(image, nullptr, nullptr);
  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("obstacles");
  ASSERT_TRUE(alloc_guard::arm());
  whole.pipeline->process(image, nullptr, nullptr);
  steps.pipeline->begin(image, nullptr, nullptr);
  for (int c = 100; c < image.columns(); c += 100) steps.pipeline->advance(image, nullptr, c);
  steps.pipeline->finish(image, nullptr);
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  const GroundCounters& gc = whole.pipeline->counters().ground;
  EXPECT_GT(gc.raised, 5000u);   // walls, trees, cars, poles
  EXPECT_GT(gc.lowered, 1000u);  // curbs, rough ground
  const auto& a = whole.pipeline->map().grid();
  const auto& b = steps.pipeline->map().grid();
  std::size_t differ = 0;
  for (std::int32_t y = 0; y < a.size_y(); ++y) {
    for (std::int32_t x = 0; x < a.size_x(); ++x) {
      const CellIndex c{a.origin().x + x, a.origin().y + y};
      differ += std::memcmp(&a.at(c).logit, &b.at(c).logit, sizeof(float)) != 0 ? 1u : 0u;  // (unknown: NaN)
    }
  }
  EXPECT_EQ(differ, 0u);
}

TEST(Ground, TheConfigSectionIsReadAndChecked) {
  auto parse = [](const std::string& text) { return parse_obstacle_config(ConfigNode::parse(text, "test.yaml")); };
  const ObstacleConfig c = parse("ground: {cell: 0.4, radius: 1.6, max_slope: 0.3, height: 0.25}\n");
  EXPECT_TRUE(c.ground.enabled);  // a ground section turns it on unless it says otherwise
  EXPECT_FLOAT_EQ(c.ground.cell, 0.4f);
  EXPECT_FLOAT_EQ(c.ground.radius, 1.6f);
  EXPECT_FLOAT_EQ(c.ground.max_slope, 0.3f);
  EXPECT_FLOAT_EQ(c.ground.height, 0.25f);
  EXPECT_FALSE(parse("ground: {enabled: false}\n").ground.enabled);
  EXPECT_FALSE(ObstacleConfig{}.ground.enabled);
  EXPECT_THROW(parse("ground: {radius: 0.2}\n"), ConfigError);
  EXPECT_THROW(parse("ground: {hieght: 0.2}\n"), ConfigError);
}

}  // namespace
}  // namespace trailnav::perception
