// The terrain analysis over recordings, offline and deterministically: the
// features of every cell at every step with the simulated truth's class
// (training data for `trailnav terrain-train`), and the cell-wise confusion
// matrices of the integrated class map (Eq. 7.15) and of single features
// (`trailnav terrain-eval`, as the thesis' Table 7.2). Also the labelled-cell
// CSV format users label their own data in (docs/terrain.md).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "sim_truth.hpp"
#include "trailnav/perception/forest_training.hpp"
#include "trailnav/perception/obstacle_config.hpp"
#include "trailnav/perception/terrain_config.hpp"
#include "trailnav/perception/terrain_mapper.hpp"

namespace trailnav::eval {

// The true class of a terrain cell (centre x, y; side `res`), or none when
// the cell is mixed (only obvious cells are labelled, as in the thesis): all
// of its truth pixels of one class, `other` if a solid object covers at least
// half of it, `vegetation` if undergrowth does; a cell partly covered is mixed.
std::optional<perception::TerrainClass> truth_cell_class(const SimTruth& truth, double x, double y, double res);

struct TerrainRunOptions {
  std::string input;               // one recording with truth/
  perception::TerrainConfig config;
  perception::MountParams mount;   // translation zero: the simulated scenario's
  const perception::RandomForest* forest = nullptr;  // null: features only
  std::string forest_name = "the terrain model";      // its file, for errors
  std::string calibration;
  bool collect_samples = false;    // keep (feature, true class) of every labelled observation
  std::function<void(double)> progress;
  // Called after every revolution (the obstacle run with estimated classes uses the map).
  std::function<void(const perception::TerrainMapper&, bool stepped)> on_revolution;
  // Optional: the mapper's sums sink (a traversability layer); it must outlive the run.
  perception::CellSumsSink* sums_sink = nullptr;
};

struct TerrainRunReport {
  std::string error;
  std::string lidar;  // the recording's lidar model ("VLP-16", ...)
  std::uint64_t revolutions = 0;
  perception::TerrainCounters counters;
  perception::LabelledFeatures samples;
  perception::ConfusionMatrix integrated;  // the map's best class per observed, labelled cell and step
  perception::ConfusionMatrix single;      // the forest's best class for that step's feature alone
  perception::ConfusionMatrix last;        // each labelled cell once: the map's best class at its last observation
  std::uint64_t unlabelled = 0;            // observations of mixed cells (not scored)
  double align_ms = 0.0;     // mean per revolution
  double register_ms = 0.0;  // mean per revolution
  double step_ms = 0.0;      // mean per step, with the scoring of its cells
};

TerrainRunReport run_terrain(const TerrainRunOptions& options);

// Labelled cells as CSV: a header line, then per cell the six features and a
// class name (docs/terrain.md). Appends to `out`; errors name file and line.
std::string load_labelled_csv(const std::string& path, perception::LabelledFeatures& out);
Status save_labelled_csv(const std::string& path, const perception::LabelledFeatures& data);

}  // namespace trailnav::eval
