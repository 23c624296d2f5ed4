// The terrain evaluation behind `trailnav terrain-eval` (thesis Table 7.2) on
// a simulated recording of `meadow-block` with the shipped model: grass is
// recognised, the integrated map (Eq. 7.15) beats single features, and the
// per-cell matrix counts each labelled cell once.
#include <gtest/gtest.h>

#include <cstdio>
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

// The labelled-cell CSV of `terrain-train` and `--save-features`: what is
// saved loads back the same, and bad files stop with file and line.
TEST(TerrainEval, LabelledCellsCsvRoundTripsAndBadLinesAreNamed) {
  const fs::path dir = fs::temp_directory_path() / ("trailnav-labelled-csv-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string path = (dir / "cells.csv").string();
  perception::LabelledFeatures saved;
  saved.add({41.0f, 33.25f, 3.8f, 1.2e-5f, 1.3f, 6.5f}, TerrainClass::street);
  saved.add({60.0f, 40.5f, 9.75f, 3e-4f, 4.0f, 13.0f}, TerrainClass::other);
  ASSERT_TRUE(save_labelled_csv(path, saved));
  perception::LabelledFeatures back;
  ASSERT_EQ(load_labelled_csv(path, back), "");
  EXPECT_EQ(back.features, saved.features);
  EXPECT_EQ(back.labels, saved.labels);

  const auto error_of = [&](const std::string& text) {
    {
      std::FILE* f = std::fopen(path.c_str(), "w");
      std::fputs(text.c_str(), f);
      std::fclose(f);
    }
    perception::LabelledFeatures out;
    return load_labelled_csv(path, out);
  };
  const std::string header = "max_remission,mean_remission,std_remission,roughness,slope,area_std_remission,class\n";
  EXPECT_EQ(error_of("# labelled by hand\n" + header + "41,33,3.8,1e-5,1.3,6,grass\n"), "");
  // A file of the five-feature format says what it lacks.
  std::string e = error_of("max_remission,mean_remission,std_remission,roughness,slope,class\n41,33,3.8,1e-5,1.3,grass\n");
  EXPECT_EQ(e.rfind(path + ":1: five features per line", 0), 0u) << e;
  e = error_of(header + "41,33,3.8,1e-5,1.3,grass\n");
  EXPECT_EQ(e, path + ":2: 'grass' is not a number (area std remission)");
  e = error_of(header + "41,33,3.8,1e-5,1.3,6,gras\n");
  EXPECT_EQ(e.rfind(path + ":2: unknown class 'gras'", 0), 0u) << e;
  e = error_of(header + "41,33,3.8,1e-5,1.3,6\n");
  EXPECT_EQ(e, path + ":2: expected 7 fields");
  fs::remove_all(dir);
}

}  // namespace
}  // namespace trailnav::eval
