// The terrain evaluation behind `trailnav terrain-eval` (thesis Table 7.2) on
// a simulated recording of `meadow-block` with the shipped model: grass is
// recognised, the integrated map (Eq. 7.15) beats single features, and the
// per-cell matrix counts each labelled cell once.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include <unistd.h>

#include "simulator.hpp"
#include "terrain_run.hpp"
#include "trailnav/perception/random_forest.hpp"

namespace trailnav::eval {
namespace {

namespace fs = std::filesystem;
using perception::TerrainClass;

TEST(TerrainEval, MeadowGrassIsRecognisedAndEachCellCountsOnceInTheLastMatrix) {
  const std::string dir = (fs::temp_directory_path() / ("trailnav-terrain-eval-" + std::to_string(::getpid()))).string();
  fs::remove_all(dir);
  sim::SimOptions s;
  s.scenario = "meadow-block";
  s.seed = 3;
  s.duration = 12.0;
  s.out = dir;
  const sim::SimReport sr = sim::run_simulation(s);
  ASSERT_TRUE(sr.error.empty()) << sr.error;
  auto model = perception::RandomForest::load("board/models/terrain-sim.tnrf");
  ASSERT_TRUE(model.forest) << model.error;

  TerrainRunOptions o;
  o.input = dir;
  o.forest = &*model.forest;
  const TerrainRunReport r = run_terrain(o);
  fs::remove_all(dir);
  ASSERT_TRUE(r.error.empty()) << r.error;
  const int grass = static_cast<int>(TerrainClass::grass);
  ASSERT_GT(r.integrated.row_total(grass), 1000u);
  std::printf("grass recall: integrated %.3f, single features %.3f, last per cell %.3f (%llu cells, %llu observations)\n",
              r.integrated.recall(grass), r.single.recall(grass), r.last.recall(grass),
              static_cast<unsigned long long>(r.last.total()), static_cast<unsigned long long>(r.integrated.total()));
  EXPECT_GE(r.integrated.recall(grass), 0.91);  // the thesis' Table 7.2
  EXPECT_GT(r.integrated.recall(grass), r.single.recall(grass));
  EXPECT_GE(r.last.recall(grass), 0.91);
  // Cells are observed at several steps; the last matrix has each once.
  EXPECT_GT(r.last.total(), 1000u);
  EXPECT_LT(2 * r.last.total(), r.integrated.total());
}

}  // namespace
}  // namespace trailnav::eval
