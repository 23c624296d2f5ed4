// Parameters of the obstacle detection, with the thesis' defaults (§7.1,
// Table 7.1, §7.4), and their YAML form (docs/obstacles.md).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "trailnav/perception/terrain_class_map.hpp"
#include "trailnav/runtime/config.hpp"

namespace trailnav::perception {

// How the terrain class enters the obstacle probability (§7.4.4).
enum class FusionModel : std::uint8_t {
  pw,  // Dirac thresholds (Eq. 7.11) of the most likely class (Eq. 7.17)
  ps,  // smooth model (Eq. 7.12) of the most likely class (Eq. 7.17)
  pc,  // smooth model summed over the class distribution (Eq. 7.16)
};
inline constexpr int kFusionModels = 3;
std::string_view fusion_model_name(FusionModel m) noexcept;  // "PW", "PS", "PC"
std::optional<FusionModel> parse_fusion_model(std::string_view name) noexcept;  // case-insensitive

// The longest top hold (an hour): as long as the map keeps the cell.
inline constexpr float kTopHoldForever = 3600.0f;

// P(o | g, t) for one terrain class.
struct ClassParams {
  float max_step_height = 0.05f;  // m (Dirac)
  float max_incline_deg = 20.5f;  // degrees (Dirac)
  float alpha = 25.0f;            // 1/m (smooth)
  float beta = 1.2f;              // (smooth)
  // PW: how long free points at an obstacle's height (see MapParams) leave a
  // cell of this class occupied after its last obstacle point, in seconds;
  // unset: map.dirac_top_hold. `other` (solid objects) holds for the hour of
  // kTopHoldForever; the rest as the thesis' hold.
  std::optional<float> top_hold_s;
};

// Table 7.1; vegetation, which the table lacks, is treated like other.
std::array<ClassParams, kTerrainClasses> default_class_params() noexcept;

struct FeatureParams {
  int ring_neighbours = 5;         // K: search along the ring, each way
  int cross_neighbours = 2;        // L: search across rings, each way
  float min_distance = 0.05f;      // x, m: a neighbour must be farther than this
  int smoothing_half_window = 5;   // points averaged each way along the ring (0: no smoothing)
  float smoothing_max_jump = 0.15f;  // m: a range jump this large between ring neighbours ends a window
  float min_range = 1.0f;          // m: nearer returns are ignored (the robot itself)
  float max_range = 40.0f;         // m: farther returns are ignored (the map reaches 30 m each way)
  // A neighbour farther from a point than this times the point's range is
  // on another surface (behind it, or a stray return far below the road) and
  // counts as missing in the search.
  float neighbour_reach = 1.0f;
  // Returns inside this box of the sensor frame (x, y, z from and to, m) are
  // the robot itself (its body, mirrors, racks) and ignored. Empty: none.
  std::optional<std::array<float, 6>> self_box;
};

// The height above the ground (ground_height.hpp, docs/obstacles.md).
struct GroundParams {
  bool enabled = false;
  float cell = 0.5f;       // m
  float radius = 2.0f;     // m (L1)
  float max_slope = 0.2f;  // rise per metre the ground may have
  float height = 0.2f;     // m: a point this far above the ground stands on it
  bool raise = true;       // such a point's step becomes its height (off: only cut)
  bool cut = true;         // a step is cut to the point's height above the ground (off: only raise)
};

struct MapParams {
  int size = 600;               // cells per side
  double resolution = 0.1;      // m
  float prior = 0.5f;           // P_c(o)
  float measurement_min = 0.4f;  // P(o | g) is clamped to [min, max] before Eq. 7.10
  float measurement_max = 0.97f;
  float logit_min = -4.0f;      // the cell's log-odds are clamped to [min, max]
  float logit_max = 4.0f;
  float dirac_hold_s = 2.0f;    // PW: an observed obstacle keeps its cell occupied this long
  // PW: once dirac_hold is over, a free point clears the cell at once only if
  // it lies more than dirac_clear_depth below the cell's highest obstacle
  // point (ground where the obstacle stood); a free point at the obstacle's
  // height (a box's flat top, or grass tops) clears it only dirac_top_hold
  // after the last obstacle point (a class's own top_hold first). With
  // dirac_top_hold <= dirac_hold (the default) every free point clears after
  // the hold, as in the thesis.
  float dirac_clear_depth = 0.1f;
  float dirac_top_hold_s = 2.0f;
  float occupied = 0.5f;        // P above this is an obstacle (PNGs, scores, planners' 0-100)
};

// Sensor pose on the robot and the orientation to assume without a pose stream.
struct MountParams {
  std::array<double, 3> translation{0.0, 0.0, 0.0};  // m, sensor origin in the robot frame
  std::array<double, 3> rotation_deg{0.0, 0.0, 0.0};  // roll, pitch, yaw of the sensor on the robot
  double fixed_roll_deg = 0.0;   // robot orientation when no pose stream is configured
  double fixed_pitch_deg = 0.0;
};

struct ObstacleConfig {
  FeatureParams features;
  GroundParams ground;  // the height above the ground (ground_height.hpp); off unless configured
  std::array<ClassParams, kTerrainClasses> classes = default_class_params();
  MapParams map;
  MountParams mount;
  // PW by default: what the thesis' robot drove with (§7.4.3), and the one
  // that finds a box standing in grass (docs/obstacles.md, "Which model").
  FusionModel model = FusionModel::pw;
  // Terrain source: adaptive (a terrain-class map) or one fixed class for all
  // cells (the basic approach of §7.1.3).
  std::optional<TerrainClass> fixed_class;
  TerrainClass unknown_class = TerrainClass::other;  // for cells the terrain map does not know
  bool compare_models = false;  // also keep PW, PS and PC maps side by side (KL, §7.4.4)
  // trailnavd: work on each revolution while it arrives, so that only its last
  // blocks are left when it is complete (ObstacleTask::set_streaming); the
  // maps are the same bits either way. False: each revolution once complete.
  bool streaming = true;
};

// Reads the `obstacles:` mapping; ConfigError (file, line, key) on bad values.
ObstacleConfig parse_obstacle_config(const ConfigNode& node);

struct ObstacleConfigResult {
  std::optional<ObstacleConfig> config;
  std::string error;
};
// A YAML file whose top level has an `obstacles:` mapping.
ObstacleConfigResult load_obstacle_config(const std::string& path);
// Checks the values against each other (window sizes, capacities).
std::string check_obstacle_config(const ObstacleConfig& config);

}  // namespace trailnav::perception
