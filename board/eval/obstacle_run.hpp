// `trailnav obstacles` as a library: runs the obstacle pipeline over a
// recording, a pcap or KITTI scans, deterministically, writes map pictures,
// scores the maps against a simulated recording's truth and compares the
// fusion models with the KL divergence of §7.4.4.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "revolution_source.hpp"
#include "trailnav/perception/obstacle_config.hpp"
#include "trailnav/perception/obstacle_pipeline.hpp"
#include "trailnav/perception/random_forest.hpp"
#include "trailnav/perception/terrain_config.hpp"

namespace trailnav::eval {

// Where the terrain class of each cell comes from.
enum class TerrainMode : std::uint8_t {
  config,  // as configured: a fixed class, or adaptive (with no terrain map yet: the unknown class)
  truth,   // adaptive, from the simulated recording's true classes
  estimated,  // adaptive, from the terrain analysis (§7.2) run alongside on the same recording
};

// A face cell (MapScore::faces) that a scored map did not find: where the
// recall goes (`trailnav obstacles --misses`).
struct FaceMiss {
  perception::FusionModel model = perception::FusionModel::pc;
  double time_s = 0.0;                // of the snapshot, since the recording's start
  double robot_x = 0.0, robot_y = 0.0;
  double x = 0.0, y = 0.0;            // the cell's centre
  double distance = 0.0;              // m from the robot
  double side_seen_s = 0.0;           // when a lidar return first showed a side of the obstacle there
  std::string obstacle;               // its name, when it is a named obstacle
  float probability = 0.0f;           // the map's P(o) at the cell
  bool found_before = false;          // found at an earlier snapshot, lost since
};

// A scored snapshot whose map has a fake obstacle on the robot's next 4 m of
// true path (MapScore::blocked): the first such cell along the path
// (`trailnav obstacles --blocked`).
struct BlockedPath {
  perception::FusionModel model = perception::FusionModel::pw;
  double time_s = 0.0;                // of the snapshot, since the recording's start
  double robot_x = 0.0, robot_y = 0.0;
  double x = 0.0, y = 0.0;            // the fake obstacle cell's centre
  double ahead = 0.0;                 // m along the true path from the robot to where it blocks
  perception::TerrainClass truth_class = perception::TerrainClass::other;  // the cell's true terrain
  float probability = 0.0f;           // the map's P(o) at the cell
};

// One aligned point of a revolution inside ObstacleRunOptions::points_box,
// with what the pipeline made of it (`trailnav obstacles --points`): to see
// why a cell is, or is not, an obstacle.
struct PointRecord {
  double time_s = 0.0;            // end of its revolution: since a simulated recording's start (as FaceMiss),
                                  // else since the first revolution's end
  std::uint64_t revolution = 0;   // 1-based
  int ring = 0, column = 0;
  double x = 0.0, y = 0.0, z = 0.0;  // odometry frame (a simulated recording: the world), m
  float range = 0.0f;
  perception::PointState state = perception::PointState::none;
  float step_height = 0.0f;       // Eq. 7.5 (0 unless measured)
  float sin_incline = 0.0f;       // Eq. 7.6
  perception::TerrainClass terrain = perception::TerrainClass::other;  // the class its cell was fused with
  bool terrain_known = false;     // false: the unknown class (or a fixed class) was used
  bool dirac = false;             // Eq. 7.11 with that class's thresholds
  float smooth = 0.0f;            // Eq. 7.12 with that class's alpha and beta
};

// Why a point of a point-cloud file has the answer it has (`trailnav
// obstacles --labels-out`); codes 0, 1 and 9 answer, the others say why not.
enum class AnswerCode : std::uint8_t {
  evaluated = 0,      // its own features (Eqs. 7.5, 7.6) with its cell's terrain class
  cell_shared = 1,    // a second point of its range-image cell, within kSharedCellGap of the first: that one's answer
  no_return = 2,      // non-finite, or at the origin
  not_placed = 3,     // its ring is not the layout's, or a third point of its cell
  apart_in_cell = 4,  // a second point of its cell, farther than kSharedCellGap from the first
  out_of_range = 5,   // outside the obstacle detection's range limits
  vehicle = 6,        // inside the recording vehicle's box (features.self_box)
  dropped = 7,        // in alignment: its ring's azimuth column already taken, or too far from its firing
  isolated = 8,       // no neighbour to measure its features against
  // A second point of its cell farther than kSharedCellGap from the first, or a third,
  // answered by its height above the ground alone (obstacles.ground on).
  ground_only = 9,
};
inline constexpr int kAnswerCodes = 10;
inline constexpr float kSharedCellGap = 0.2f;  // m of range
std::string_view answer_code_name(AnswerCode c) noexcept;

struct ScanPointAnswer {
  std::int8_t obstacle = -1;  // 1 an obstacle, 0 not, -1 not evaluated (code says why)
  AnswerCode code = AnswerCode::no_return;
  float probability = 0.0f;   // P(obstacle) of the smooth model (Eq. 7.12); NaN when not evaluated
  float step_height = 0.0f;   // m, Eq. 7.5 (0 when flat or not evaluated)
  float sin_incline = 0.0f;   // Eq. 7.6
  float height = std::numeric_limits<float>::quiet_NaN();  // m above the ground (obstacles.ground), NaN: not known
};

// One point-cloud file's answers, every point in the file's order.
struct ScanAnswers {
  const std::string& file;
  const cloud::PointCloud& cloud;
  std::span<const ScanPointAnswer> answers;
};

// Each point of a point-cloud file: where the imager put it (`places`,
// CloudImager::fill), what alignment made of it (the pipeline must keep
// its fates: keep_point_fates()) and the answer of the point it became.
// `out` is sized once; nothing else is allocated.
void answer_scan_points(const cloud::PointCloud& cloud, std::span<const cloud::PointPlace> places,
                        const perception::ObstaclePipeline& pipeline, const perception::TerrainClassMap* classes,
                        std::vector<ScanPointAnswer>& out);

struct ObstacleRunOptions {
  std::vector<std::string> inputs;  // one recording directory or capture file, or point-cloud files
  CloudInputOptions cloud;          // how point-cloud files become range images
  perception::ObstacleConfig config;
  TerrainMode terrain = TerrainMode::config;
  // TerrainMode::estimated: the terrain analysis' settings and its model.
  perception::TerrainConfig terrain_config;
  const perception::RandomForest* terrain_forest = nullptr;
  std::string terrain_forest_name = "the terrain model";  // its file, for errors
  std::string calibration;   // empty: the recording's scenario or the model's default; "builtin": the model's built-in one
  std::string out_dir;       // empty: no files
  int png_every = 0;         // revolutions between map pictures (0: only the last)
  int score_every = 5;       // revolutions between scored snapshots
  double score_radius = 20.0;  // m around the robot
  int tolerance_cells = 1;     // an obstacle cell counts as found when an occupied cell is this close
  int max_revolutions = 0;     // 0: all
  std::function<void(double fraction)> progress;
  // Called with every revolution before it is processed (benchmarks keep copies).
  std::function<void(const velodyne::RangeImage&)> on_revolution;
  // Called after every revolution is processed (trailnavd's end-to-end test
  // compares the maps it publishes with these).
  std::function<void(const perception::ObstaclePipeline&)> on_processed;
  // Called for every face cell a scored map misses, at every scored snapshot.
  std::function<void(const FaceMiss&)> on_face_miss;
  // Called for every scored snapshot whose path a map blocks.
  std::function<void(const BlockedPath&)> on_blocked;
  // Every point whose x, y lie in [x_min, x_max] x [y_min, y_max] (odometry
  // frame) goes to on_point after its revolution is processed.
  std::optional<std::array<double, 4>> points_box;
  std::function<void(const PointRecord&)> on_point;
  // Point-cloud inputs: every file's per-point answers after it is processed.
  std::function<void(const ScanAnswers&)> on_scan_answers;
  // A simulated recording's true trajectory as the pose stream; false: no
  // pose stream (fixed orientation, the map stays where it started).
  bool truth_poses = true;
  // Point-cloud files go from their points straight into the pipeline
  // (ObstaclePipeline::align_scan) unless their terrain is estimated (the
  // terrain analysis reads range images) or on_revolution wants the
  // images; true: through a range image always, as recordings go (the same
  // answers: a test compares them).
  bool through_range_images = false;
};

// Scores of one map against the truth, summed over the scored snapshots.
struct ClassCells {
  std::uint64_t free = 0;  // observed free cells (not next to an obstacle)
  std::uint64_t fake = 0;  // of them, occupied
  double rate() const noexcept { return free ? static_cast<double>(fake) / static_cast<double>(free) : 0.0; }
};
struct FoundCells {
  std::uint64_t cells = 0;  // observed truth cells
  std::uint64_t found = 0;  // occupied within the tolerance
  double recall() const noexcept { return cells ? static_cast<double>(found) / static_cast<double>(cells) : 1.0; }
};
struct NamedObstacle {
  std::string name;
  std::uint64_t snapshots = 0;  // scored while it was within the radius
  std::uint64_t detected = 0;   // of them, with an occupied cell on it
  FoundCells faces;             // its outline cells with a side seen (as MapScore::faces)
};
struct MapScore {
  FoundCells obstacles;   // solid obstacles >= 10 cm: every observed cell of their footprint
  FoundCells outlines;    // of them, the cells on the footprint's outline, where the height steps
  FoundCells faces_hit;   // of those, the cells where any return from a side came from within 20 m (side_hits.u32)
  FoundCells faces;       // of those, the cells where a side return showed the face (side_sightings.u32)
  std::uint64_t faces_lost = 0;  // of the faces not found, those found at an earlier snapshot
  FoundCells negative;    // ditches
  FoundCells vegetation;  // bushes, undergrowth
  std::array<ClassCells, perception::kTerrainClasses> classes;
  std::uint64_t snapshots = 0;
  std::uint64_t blocked = 0;  // snapshots with a fake obstacle on the robot's next 4 m of path
  std::vector<NamedObstacle> named;
  ClassCells all_free() const noexcept;
};

struct KlSummary {
  std::uint64_t snapshots = 0;
  double mean_pw = 0.0;  // mean over snapshots of the mean per-cell KL(PC || PW), bits
  double mean_ps = 0.0;
  double max_pw = 0.0;
  double max_ps = 0.0;
};

struct ObstacleRunReport {
  std::string error;  // non-empty: nothing ran
  std::string input_kind;  // "recording", "kitti"
  std::string model_name;  // lidar
  // The recording vehicle's box the input brought (KITTI's car), used as
  // features.self_box because the config gave none.
  std::optional<std::array<float, 6>> source_self_box;
  bool scored = false;
  // The truth says which side returns show their face (side_sightings.u32
  // next to side_hits.u32; recordings simulated before do not): without it
  // no obstacle face counts as seen.
  bool side_sightings = false;
  std::uint64_t revolutions = 0;
  perception::PipelineCounters counters;
  std::array<std::optional<MapScore>, perception::kFusionModels> scores;
  std::optional<KlSummary> kl;
  double align_ms = 0.0;     // mean per revolution
  double features_ms = 0.0;
  double map_ms = 0.0;       // all maps kept
  double terrain_ms = 0.0;   // terrain analysis (estimated classes), mean per revolution
  std::uint64_t terrain_steps = 0;
  std::uint64_t malformed_packets = 0;
  cloud::CloudImageStats cloud_points;  // point-cloud inputs: where their points went, summed
  std::vector<std::string> files;  // written
};

ObstacleRunReport run_obstacles(const ObstacleRunOptions& options);

// Writes a map as PNG: unknown dark blue-grey, free white to occupied black
// by probability (occupied cells tinted blue), the robot as a red dot; north
// up; beside it the title, `notes`, the legend, a scale bar and north.
Status write_obstacle_png(const std::string& path, const perception::ObstacleMap& map, double robot_x, double robot_y,
                          const std::string& title = "obstacle map", const std::vector<std::string>& notes = {});

}  // namespace trailnav::eval
