// The geometric features of thesis §7.1.2 on hand-built rings: a step of
// known height gives that stepHeight, a ramp gives its incline, noise below
// x gives nothing; smoothing keeps edges; missing points are skipped.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "trailnav/perception/cloud.hpp"
#include "trailnav/perception/obstacle_models.hpp"

namespace trailnav::perception {
namespace {

constexpr int kRings = 8;
constexpr int kColumns = 360;

// Ring i lies on a circle of radius 3 + 0.5 i around the sensor; height(r, azimuth).
template <typename Height>
RevolutionCloud make_cloud(Height height) {
  RevolutionCloud c(CloudShape{kRings, kColumns});
  c.reset(kColumns);
  c.full_turn = true;
  for (int i = 0; i < kRings; ++i) {
    const double r = 3.0 + 0.5 * i;
    for (int j = 0; j < kColumns; ++j) {
      const double a = 2.0 * std::numbers::pi * j / kColumns;
      const std::size_t k = c.index(i, j);
      c.x[k] = static_cast<float>(r * std::cos(a));
      c.y[k] = static_cast<float>(r * std::sin(a));
      c.z[k] = static_cast<float>(height(r, a, i, j));
      c.range[k] = static_cast<float>(r);
      c.state[k] = PointState::valid;
    }
  }
  return c;
}

FeatureParams no_smoothing() {
  FeatureParams p;
  p.smoothing_half_window = 0;
  return p;
}

TEST(Features, StepOfKnownHeightGivesThatStepHeight) {
  // A 0.3 m step between rings 3 and 4 (radius 4.5 m to 5.0 m).
  RevolutionCloud c = make_cloud([](double, double, int i, int) { return i >= 4 ? 0.3 : 0.0; });
  FeatureCounters counters;
  compute_features(c, no_smoothing(), counters);
  const float expected_sin = static_cast<float>(0.3 / std::hypot(0.5, 0.3));
  for (int j = 0; j < kColumns; ++j) {
    for (int i : {3, 4}) {
      const std::size_t k = c.index(i, j);
      ASSERT_EQ(c.state[k], PointState::measured);
      EXPECT_NEAR(c.step_height[k], 0.3f, 1e-5f) << "ring " << i << " column " << j;
      EXPECT_NEAR(c.sin_incline[k], expected_sin, 1e-5f);
    }
    // Away from the step: flat ground, no step.
    EXPECT_NEAR(c.step_height[c.index(0, j)], 0.0f, 1e-5f);
    EXPECT_NEAR(c.step_height[c.index(7, j)], 0.0f, 1e-5f);
  }
  EXPECT_EQ(counters.measured, static_cast<std::uint64_t>(kRings * kColumns));
  // Street thresholds see the step as an obstacle, grass thresholds do not.
  ObstacleModels models(default_class_params(), MapParams{});
  const std::size_t k = c.index(3, 10);
  EXPECT_TRUE(models.dirac(static_cast<int>(TerrainClass::street), c.step_height[k], c.sin_incline[k]));
  EXPECT_FALSE(models.dirac(static_cast<int>(TerrainClass::grass), c.step_height[k], c.sin_incline[k]));
}

TEST(Features, RampGivesItsIncline) {
  const double slope = 10.0 * std::numbers::pi / 180.0;
  RevolutionCloud c = make_cloud([&](double r, double, int, int) { return std::tan(slope) * (r - 3.0); });
  FeatureCounters counters;
  compute_features(c, no_smoothing(), counters);
  for (int i = 0; i < kRings; ++i) {
    for (int j = 0; j < kColumns; j += 7) {
      const std::size_t k = c.index(i, j);
      EXPECT_NEAR(std::asin(c.sin_incline[k]), slope, 1e-4) << "ring " << i;
      EXPECT_NEAR(c.step_height[k], 0.5 * std::tan(slope), 1e-4);
    }
  }
}

TEST(Features, NoiseBelowXGivesNothing) {
  // Flat ground with height noise of up to +-2 cm: every step stays below
  // the street threshold, so no point is an obstacle.
  RevolutionCloud c = make_cloud([](double, double, int i, int j) {
    const unsigned h = static_cast<unsigned>(i * 7919 + j * 104729) * 2654435761u;
    return 0.02 * ((h >> 8) / static_cast<double>(1u << 24) * 2.0 - 1.0);
  });
  FeatureCounters counters;
  compute_features(c, no_smoothing(), counters);
  ObstacleModels models(default_class_params(), MapParams{});
  for (std::size_t k = 0; k < c.state.size(); ++k) {
    ASSERT_LE(c.step_height[k], 0.04f + 1e-6f);
    EXPECT_FALSE(models.dirac(static_cast<int>(TerrainClass::street), c.step_height[k], c.sin_incline[k]));
  }
}

TEST(Features, NeighboursAllWithinXAreFlat) {
  // Points 1 cm apart along the ring and across rings, with 1 cm bumps: no
  // neighbour within K and L is farther than x, so nothing is measured.
  RevolutionCloud c(CloudShape{3, 64});
  c.reset(64);
  c.full_turn = false;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 64; ++j) {
      const std::size_t k = c.index(i, j);
      c.x[k] = 0.01f * static_cast<float>(j);
      c.y[k] = 0.01f * static_cast<float>(i);
      c.z[k] = (i + j) % 2 ? 0.01f : 0.0f;
      c.range[k] = 5.0f;
      c.state[k] = PointState::valid;
    }
  }
  FeatureParams p = no_smoothing();
  p.ring_neighbours = 3;
  FeatureCounters counters;
  compute_features(c, p, counters);
  EXPECT_EQ(counters.flat, 3u * 64u);
  EXPECT_EQ(counters.measured, 0u);
  for (std::size_t k = 0; k < 3 * 64; ++k) EXPECT_EQ(c.step_height[k], 0.0f);
}

TEST(Features, MissingPointsAreSkippedAndLonePointsIsolated) {
  RevolutionCloud c = make_cloud([](double, double, int i, int) { return i >= 4 ? 0.3 : 0.0; });
  // Ring 4 loses column 100: ring 3's point there finds ring 5 instead.
  c.remove(c.index(4, 100));
  // A lone point: everything around (3, 200) within K and L missing.
  for (int i = 0; i < kRings; ++i) {
    for (int j = 190; j <= 210; ++j) {
      if (!(i == 3 && j == 200)) c.remove(c.index(i, j));
    }
  }
  FeatureCounters counters;
  compute_features(c, no_smoothing(), counters);
  EXPECT_EQ(c.state[c.index(3, 100)], PointState::measured);
  EXPECT_NEAR(c.step_height[c.index(3, 100)], 0.3f, 1e-5f);
  EXPECT_NEAR(c.sin_incline[c.index(3, 100)], 0.3 / std::hypot(1.0, 0.3), 1e-5);
  EXPECT_EQ(c.state[c.index(3, 200)], PointState::isolated);
  EXPECT_EQ(c.state[c.index(4, 100)], PointState::none);
  EXPECT_EQ(counters.isolated, 1u);
}

// A stray return 30 m away and 11 m below flat ground (as in KITTI scan
// 000000, ring 4) sits in the range image between ground points. It is
// farther from them than they are from the sensor (neighbour_reach 1): not on
// their surface, so they skip it and stay flat, in every search kernel.
TEST(Features, AStrayReturnFarBelowIsNoNeighbour) {
  for (FeatureKernel kernel : {FeatureKernel::portable, FeatureKernel::four_wide, FeatureKernel::fastest}) {
    for (float reach : {1.0f, 1000.0f}) {
      RevolutionCloud c = make_cloud([](double, double, int, int) { return 0.0; });
      const std::size_t stray = c.index(2, 100);
      c.x[stray] *= 30.0f / 4.0f;
      c.y[stray] *= 30.0f / 4.0f;
      c.z[stray] = -11.0f;
      c.range[stray] = 32.0f;
      FeatureParams params = no_smoothing();
      params.neighbour_reach = reach;
      FeatureCounters counters;
      compute_features(c, params, counters, kernel);
      float worst = 0.0f;
      for (int i = 0; i < kRings; ++i) {
        for (int j = 0; j < kColumns; ++j) {
          if (c.index(i, j) != stray) worst = std::max(worst, c.step_height[c.index(i, j)]);
        }
      }
      if (reach == 1.0f) {
        EXPECT_EQ(worst, 0.0f) << "kernel " << static_cast<int>(kernel);
        EXPECT_EQ(c.state[c.index(2, 99)], PointState::measured);  // found the point beyond the stray
      } else {
        EXPECT_NEAR(worst, 11.0f, 1e-3f) << "without the reach the stray is a neighbour";
      }
    }
  }
}

TEST(Smoothing, AveragesNoiseAndKeepsEdges) {
  // Ring 0 alternates +-2 cm around 0; at column 180 the range jumps by 2 m
  // (an object's edge) and the height by 0.5 m.
  RevolutionCloud c(CloudShape{1, kColumns});
  c.reset(kColumns);
  for (int j = 0; j < kColumns; ++j) {
    const std::size_t k = c.index(0, j);
    const bool far = j >= 180;
    c.aligned_x[k] = 0.03f * static_cast<float>(j);
    c.aligned_y[k] = 0.0f;
    c.aligned_z[k] = (far ? 0.5f : 0.0f) + (j % 2 ? 0.02f : -0.02f);
    c.range[k] = far ? 7.0f : 5.0f;
    c.state[k] = PointState::valid;
  }
  FeatureParams p;
  p.smoothing_half_window = 5;
  smooth_rings(c, p);
  for (int j = 10; j < 170; ++j) EXPECT_NEAR(c.z[c.index(0, j)], 0.0f, 0.02f / 11 + 1e-6f) << j;
  for (int j = 190; j < 350; ++j) EXPECT_NEAR(c.z[c.index(0, j)], 0.5f, 0.02f / 11 + 1e-6f) << j;
  // The points next to the edge average only their own side.
  EXPECT_LT(c.z[c.index(0, 179)], 0.03f);
  EXPECT_GT(c.z[c.index(0, 180)], 0.47f);
  // x stays centred: a symmetric window on an evenly spaced ring.
  EXPECT_NEAR(c.x[c.index(0, 100)], 3.0f, 1e-4f);
}

TEST(Models, TablesMatchTheFormula) {
  const auto classes = default_class_params();
  ObstacleModels models(classes, MapParams{});
  double worst = 0.0;
  for (int t = 0; t < kTerrainClasses; ++t) {
    for (float h = 0.0f; h < 2.0f; h += 0.0037f) {
      for (float s = 0.0f; s <= 1.0f; s += 0.013f) {
        const float exact = ObstacleModels::smooth_exact(classes[static_cast<std::size_t>(t)], h, s);
        worst = std::max(worst, static_cast<double>(std::abs(models.smooth(t, h, s) - exact)));
      }
    }
  }
  EXPECT_LT(worst, 0.01);
  // Eq. 7.12 at the thesis' street parameters: a 0.3 m vertical step.
  EXPECT_NEAR(ObstacleModels::smooth_exact(classes[0], 0.3f, 1.0f),
              (1.0 - std::exp(-7.5)) * std::sqrt(1.0 - std::exp(-1.2)), 1e-6);
}

}  // namespace
}  // namespace trailnav::perception
