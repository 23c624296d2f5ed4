// The local maps of thesis §6.1 and the demonstration's labels (§6.3): the
// terrain step hands over each cell's running sums (CellSumsSink), which
// become a feature and a word of the vocabulary; the robot's poses mark the
// cells its footprint crosses; once the robot has driven d_M (20 m) the
// local map ends: each word of a cell the footprint crossed during it is a
// positive example, every other word unlabelled, and the next local map
// begins. Everything is allocated at construction; after that nothing is.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string_view>
#include <span>
#include <vector>

#include "trailnav/perception/terrain_mapper.hpp"
#include "trailnav/perception/trav_ground.hpp"
#include "trailnav/perception/trav_learner.hpp"
#include "trailnav/runtime/rolling_grid.hpp"

namespace trailnav::perception::trav {

// The robot's footprint: a rectangle in the robot's frame (x forward), its
// centre `forward` metres ahead of the pose's point.
struct Footprint {
  double length = 1.0;
  double width = 0.7;
  double forward = 0.0;
};

// The built-in robot profiles' footprints: "large" (Viona's class, 1.2 x
// 0.8 m) and "small" (Obelix's class, 0.6 x 0.45 m); nothing for another name.
std::optional<Footprint> builtin_footprint(std::string_view profile) noexcept;

struct RecorderConfig {
  double local_map_distance = 20.0;  // d_M, m driven
  double max_range = 20.0;           // m: cells farther from the robot give no word (the thesis' 20 m)
  Footprint footprint;
  std::uint32_t max_words = 400000;  // words one local map holds; more are counted as dropped
};
std::string check_recorder(const RecorderConfig& c);  // "" if usable

struct RecorderCounters {
  std::uint64_t local_maps = 0;     // finished
  std::uint64_t words = 0;          // recorded
  std::uint64_t dropped = 0;        // beyond max_words
  std::uint64_t too_far = 0;        // cells beyond max_range
  std::uint64_t positive_words = 0;
  std::uint64_t footprint_cells = 0;  // marked (a cell once per local map)
};

class TravRecorder final : public CellSumsSink {
 public:
  // The grid's geometry is the terrain grid's (size in cells, resolution).
  TravRecorder(const RecorderConfig& config, const Vocabulary& vocabulary, std::int32_t size_x, std::int32_t size_y,
               double resolution);

  // A pose of the robot (odometry frame): marks the footprint's cells and
  // adds the distance from the previous pose to the local map's travel.
  void drive(double x, double y, double yaw) noexcept;
  void cell_sums(CellIndex cell, const CellStats& sums, const FeatureVector* feature, double x,
                 double y) noexcept override;
  // For a word made elsewhere over the same vocabulary and ground (the
  // layer's, TravOnline): whether the cell at (x, y) lies beyond max_range
  // (counted, as cell_sums() counts it), then the word recorded as
  // cell_sums() would have made it.
  bool too_far(double x, double y) noexcept;
  void record(CellIndex cell, std::uint32_t word) noexcept { store(cell, word); }

  bool local_map_complete() const noexcept { return travelled_ >= config_.local_map_distance; }
  double travelled() const noexcept { return travelled_; }
  std::uint32_t local_map() const noexcept { return local_map_; }  // 1 for the first

  // One cell of the finished local map, for evaluation: its words (in the
  // order recorded) and whether the footprint crossed it.
  struct CellWords {
    CellIndex cell;
    bool positive = false;
    std::span<const std::uint32_t> words;
  };
  // Ends the local map: its words counted by label into `counts` (cleared
  // first; over the same vocabulary), each cell given to `each_cell` if set,
  // then the next local map begins.
  void finish_local_map(WordCounts& counts, const std::function<void(const CellWords&)>& each_cell = {}) noexcept;

  const RecorderConfig& config() const noexcept { return config_; }
  const Vocabulary& vocabulary() const noexcept { return vocabulary_; }
  const RecorderCounters& counters() const noexcept { return counters_; }
  // Whether the footprint crossed the cell in the current local map.
  bool footprint(CellIndex cell) const noexcept;

 private:
  struct Entry {
    CellIndex cell;
    std::uint32_t word;
    std::uint32_t order;  // when recorded
  };
  void mark(double x, double y, double yaw) noexcept;
  void store(CellIndex cell, std::uint32_t word) noexcept;

  RecorderConfig config_;
  Vocabulary vocabulary_;
  RollingGrid<std::uint32_t> marks_;  // the local map in which the footprint last crossed the cell
  GroundReference ground_;
  std::vector<Entry> entries_;        // capacity max_words
  std::vector<std::uint32_t> words_;  // one cell's words, for each_cell
  std::size_t used_ = 0;
  std::uint32_t local_map_ = 1;
  double travelled_ = 0.0;
  bool have_pose_ = false;
  double last_x_ = 0.0, last_y_ = 0.0;
  RecorderCounters counters_;
};

}  // namespace trailnav::perception::trav
