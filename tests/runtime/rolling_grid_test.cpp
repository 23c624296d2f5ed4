#include "trailnav/runtime/rolling_grid.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <utility>
#include <vector>

namespace trailnav {
namespace {

using Key = std::pair<std::int32_t, std::int32_t>;

TEST(RollingGrid, WorldToIndexFloorsNegativeCoordinates) {
  RollingGrid<int> grid(10, 10, 0.5);
  EXPECT_EQ(grid.world_to_index(0.1, 0.1), (CellIndex{0, 0}));
  EXPECT_EQ(grid.world_to_index(-0.1, -0.6), (CellIndex{-1, -2}));
  EXPECT_EQ(grid.world_to_index(2.5, 4.99), (CellIndex{5, 9}));
  const WorldPoint c = grid.cell_center({-1, 3});
  EXPECT_DOUBLE_EQ(c.x, -0.25);
  EXPECT_DOUBLE_EQ(c.y, 1.75);
}

TEST(RollingGrid, MoveToCentresTheRobotCell) {
  RollingGrid<int> grid(600, 600, 0.1);
  grid.move_to(12.34, -5.67);
  const CellIndex robot = grid.world_to_index(12.34, -5.67);
  EXPECT_EQ(robot.x - grid.origin().x, 300);
  EXPECT_EQ(robot.y - grid.origin().y, 300);
  EXPECT_NE(grid.find(12.34, -5.67), nullptr);
  EXPECT_EQ(grid.find(12.34 + 31.0, -5.67), nullptr);
}

TEST(RollingGrid, MoveClearsOnlyTheUncoveredStrips) {
  RollingGrid<int> grid(100, 80, 1.0, -1);
  grid.fill(7);
  EXPECT_EQ(grid.move_origin_to({3, 0}), 3u * 80u);
  EXPECT_EQ(grid.move_origin_to({3, -2}), 2u * 100u);
  EXPECT_EQ(grid.move_origin_to({2, -1}), 1u * 80u + 1u * 100u);
  EXPECT_EQ(grid.move_origin_to({2, -1}), 0u);
  EXPECT_EQ(grid.move_origin_to({500, 0}), 100u * 80u);  // jump: everything is new
}

// Property: after any sequence of moves, every cell that stayed inside the
// map keeps its value and every newly uncovered cell is cleared.
TEST(RollingGrid, PropertyCellsKeepTheirValuesAndNewCellsAreEmpty) {
  constexpr std::int32_t kSx = 37;  // odd, non-power-of-two sizes catch wrap errors
  constexpr std::int32_t kSy = 23;
  constexpr int kEmpty = -1;
  std::mt19937 rng(2024);
  for (int trial = 0; trial < 20; ++trial) {
    RollingGrid<int> grid(kSx, kSy, 0.25, kEmpty);
    std::map<Key, int> truth;  // world index -> value written
    int next_value = 0;
    for (int step = 0; step < 300; ++step) {
      // Write a few cells inside the map.
      std::uniform_int_distribution<std::int32_t> ux(0, kSx - 1);
      std::uniform_int_distribution<std::int32_t> uy(0, kSy - 1);
      for (int w = 0; w < 10; ++w) {
        const CellIndex c{grid.origin().x + ux(rng), grid.origin().y + uy(rng)};
        grid.at(c) = next_value;
        truth[{c.x, c.y}] = next_value++;
      }
      // Move: mostly small steps in any direction, sometimes a big jump.
      std::uniform_int_distribution<int> kind(0, 9);
      std::uniform_int_distribution<std::int32_t> small(-4, 4);
      std::uniform_int_distribution<std::int32_t> big(-60, 60);
      const bool jump = kind(rng) == 0;
      const CellIndex target{grid.origin().x + (jump ? big(rng) : small(rng)),
                             grid.origin().y + (jump ? big(rng) : small(rng))};
      grid.move_origin_to(target);
      // Forget the cells that left the map.
      for (auto it = truth.begin(); it != truth.end();) {
        it = grid.contains({it->first.first, it->first.second}) ? std::next(it) : truth.erase(it);
      }
      // Check every cell of the map.
      for (std::int32_t y = grid.origin().y; y < grid.origin().y + kSy; ++y) {
        for (std::int32_t x = grid.origin().x; x < grid.origin().x + kSx; ++x) {
          const auto found = truth.find({x, y});
          const int expected = found == truth.end() ? kEmpty : found->second;
          ASSERT_EQ(grid.at({x, y}), expected) << "trial " << trial << " step " << step << " cell " << x << "," << y;
        }
      }
    }
  }
}

TEST(RollingGrid, CopyToLinearisesFromTheOrigin) {
  RollingGrid<int> grid(5, 4, 1.0, 0);
  grid.move_origin_to({-7, 13});  // storage origin wraps in both axes
  for (std::int32_t y = 0; y < 4; ++y) {
    for (std::int32_t x = 0; x < 5; ++x) grid.at({-7 + x, 13 + y}) = 10 * y + x;
  }
  std::vector<int> out(20, -1);
  grid.copy_to(out);
  for (int i = 0; i < 20; ++i) EXPECT_EQ(out[static_cast<std::size_t>(i)], 10 * (i / 5) + i % 5);
}

TEST(RollingGrid, OffsetFromOriginNamesTheSameCellAsItsWorldIndex) {
  RollingGrid<int> grid(5, 4, 1.0, 0);
  for (const CellIndex origin : {CellIndex{0, 0}, CellIndex{-7, 13}, CellIndex{3, -2}, CellIndex{-11, -9}}) {
    grid.move_origin_to(origin);
    for (std::int32_t y = 0; y < 4; ++y) {
      for (std::int32_t x = 0; x < 5; ++x) {
        EXPECT_EQ(grid.offset_from_origin(x, y), grid.offset_of(grid.at({origin.x + x, origin.y + y})))
            << "origin " << origin.x << "," << origin.y << " cell " << x << "," << y;
      }
    }
  }
}

TEST(RollingGrid, WindowIterationIsClippedToTheMap) {
  RollingGrid<int> grid(10, 10, 1.0, 0);
  int visited = 0;
  grid.for_each_in_window({-5, -5}, {3, 2}, [&](CellIndex c, int& cell) {
    EXPECT_TRUE(grid.contains(c));
    cell = 1;
    ++visited;
  });
  EXPECT_EQ(visited, 3 * 2);
  EXPECT_EQ(grid.at({2, 1}), 1);
  EXPECT_EQ(grid.at({3, 1}), 0);
}

// The window walk steps the storage column instead of wrapping each cell;
// after the map has moved, every cell it hands over must still be the one
// at() names, across the storage's wrap-around.
TEST(RollingGrid, WindowIterationHandsOverTheCellOfEachIndexAfterMoves) {
  RollingGrid<int> grid(7, 5, 1.0, 0);
  for (const CellIndex origin : {CellIndex{0, 0}, CellIndex{4, 2}, CellIndex{-9, 13}, CellIndex{-3, -8}}) {
    grid.move_origin_to(origin);
    for (const auto& [lo, hi] : {std::pair{CellIndex{origin.x - 2, origin.y - 1}, CellIndex{origin.x + 9, origin.y + 7}},
                                 std::pair{CellIndex{origin.x + 3, origin.y + 1}, CellIndex{origin.x + 6, origin.y + 4}}}) {
      int visited = 0;
      grid.for_each_in_window(lo, hi, [&](CellIndex c, int& cell) {
        EXPECT_EQ(&cell, &grid.at(c)) << "origin " << origin.x << "," << origin.y << " cell " << c.x << "," << c.y;
        ++visited;
      });
      const int w = std::min(hi.x, origin.x + 7) - std::max(lo.x, origin.x);
      const int h = std::min(hi.y, origin.y + 5) - std::max(lo.y, origin.y);
      EXPECT_EQ(visited, w * h);
    }
  }
}

}  // namespace
}  // namespace trailnav
