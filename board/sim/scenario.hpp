// Simulator scenarios: a world (ground, terrain regions, trails, obstacles),
// the route the robot drives and its sensors, read from YAML (format in
// docs/simulator.md). Built-in scenarios live in board/sim/scenarios/.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace trailnav::sim {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;

// The terrain classes of thesis ch. 7 plus vegetation; the codes are the
// values of the terrain truth raster.
enum class TerrainClass : std::uint8_t { street = 0, dirt = 1, grass = 2, vegetation = 3, other = 4 };
inline constexpr int kTerrainClasses = 5;
const char* terrain_class_name(TerrainClass c) noexcept;
std::optional<TerrainClass> parse_terrain_class(std::string_view text) noexcept;

// Lidar remission of a material: a normal distribution on Velodyne's 0..255
// calibrated reflectivity scale, and the ground's unevenness.
struct Material {
  double remission_mean = 30.0;
  double remission_std = 8.0;
  double roughness = 0.01;  // m, standard deviation of small-scale height noise
};

// Stalks and leaves the lidar partly sees through: grass blades, bushes.
struct Medium {
  double height_min = 0.0;  // m above ground, per clump
  double height_max = 0.0;
  double density = 0.0;     // expected hits per metre of ray inside the medium
  double clump_size = 0.6;  // m, feature size of the height variation
  double cover = 1.0;       // fraction of the area covered (the rest bare)
  bool present() const noexcept { return height_max > 0.0 && density > 0.0 && cover > 0.0; }
};

struct Region {
  TerrainClass terrain = TerrainClass::grass;
  std::vector<Vec2> polygon;
  Medium medium;
};

// How a trail appears in OpenStreetMap.
struct TrailOsm {
  std::string highway = "track";
  std::string surface;
  std::string tracktype;
  std::string name;
  double offset_start = 0.0;  // m, perpendicular (left +) error at the trail's start
  double offset_end = 0.0;    // m, at its end; linear in between
  double wander = 0.5;        // m, amplitude of a smooth extra lateral error
  double spacing = 25.0;      // m, distance between mapped nodes (sparse polyline)
};

struct Trail {
  std::string name;
  TerrainClass terrain = TerrainClass::dirt;
  double width = 3.0;   // m
  double curb = 0.0;    // m, the trail lies this much below its surroundings (streets with curbs)
  std::vector<Vec2> points;  // control points; the centreline is a spline through them
  TrailOsm osm;
  Medium medium;  // e.g. mown grass on a meadow track; none by default
  int line = 0;
};

enum class ObstacleType : std::uint8_t { box, pole, wall, tree, bush, ditch };

struct Obstacle {
  ObstacleType type = ObstacleType::box;
  Vec2 center{0, 0};
  Vec3 size{1, 1, 1};      // box: length, width, height
  double yaw = 0.0;        // rad
  double radius = 0.1;     // pole, trunk, bush
  double height = 1.0;     // pole, tree (total), bush, wall
  double canopy_radius = 0.0;
  double canopy_base = 0.0;
  double thickness = 0.2;  // wall
  double depth = 0.3;      // ditch
  double width = 1.0;      // ditch
  double remission = 40.0;
  std::vector<Vec2> points;  // wall: from/to; ditch: polyline
  std::string name;
};

// An OpenStreetMap junction error: the mapped junction of trails `a` and `b`
// sits `shift` metres along `a` (in its point order) from the true one.
struct JunctionError {
  std::string a;
  std::string b;
  double shift = 0.0;
};

struct RouteLeg {
  std::string trail;
  bool reverse = false;
};

struct RobotSpec {
  double max_speed = 1.2;       // m/s
  double acceleration = 0.4;    // m/s^2
  double lateral_acceleration = 0.3;
  double wheelbase = 0.8;       // m, front to rear axle (for pitch)
  double track = 0.6;           // m, left to right wheel (for roll and wheel speeds)
  double lookahead = 2.0;       // m, pure-pursuit lookahead
  double start_offset = 0.0;    // m along the route where the robot starts
  Vec3 lidar_mount{0.2, 0.0, 1.1};   // m in the robot frame (x forward, y left, z up from the ground)
  Vec3 gps_antenna{0.0, 0.0, 1.3};
};

struct LidarSpec {
  std::string model = "VLP-16";
  std::string calibration;     // file; empty: the model's default in ../shared/data
  double rpm = 600.0;
  double range_noise = 0.02;   // m, standard deviation
  double dropout = 0.002;      // probability of no return on a hit
  double max_range = 100.0;
  double min_range = 0.9;
};

struct GpsSpec {
  double rate = 10.0;          // Hz
  double noise = 0.3;          // m, white noise per axis
  double bias_sigma = 3.0;     // m, stationary standard deviation of the wandering bias per axis
  double bias_time = 120.0;    // s, correlation time of the bias
  int baud = 115200;
};

struct ImuSpec {
  double rate = 100.0;
  double gyro_noise = 0.002;   // rad/s
  double gyro_bias = 0.003;    // rad/s, constant per axis (drawn from this sigma)
  double accel_noise = 0.02;   // m/s^2
  double accel_bias = 0.05;
  double yaw_error = 0.02;     // rad, orientation output's heading error (sigma)
  int baud = 921600;
};

struct WheelSpec {
  double rate = 50.0;
  double scale_left = 1.01;    // reported / true
  double scale_right = 0.985;
  double slip = 0.02;          // relative speed noise on loose ground (dirt, grass)
  double ticks_per_metre = 2000.0;
};

// Presses of the robot's emergency stop (GPIO line ESTOP in the recording).
struct EstopPress {
  double at = 0.0;    // s after the start
  double hold = 0.5;  // s held; the release bounces for a few milliseconds
};

struct WorldSpec {
  double xmin = -20, ymin = -20, xmax = 20, ymax = 20;  // m, east/north of the origin
  double resolution = 0.1;
  TerrainClass background = TerrainClass::grass;
  Medium background_medium;
  Vec2 slope{0.0, 0.0};        // rise per metre east and north
  double hill_amplitude = 0.0; // m
  double hill_wavelength = 40.0;
  double street_dirt = 0.1;    // fraction of street area covered with dirt (remission only)
};

struct Scenario {
  std::string name;
  std::string description;
  std::string source;  // file name or "(built-in ...)"
  std::string text;    // the YAML as read
  double origin_lat = 0.0;
  double origin_lon = 0.0;
  double origin_alt = 0.0;
  std::int64_t start_utc_ns = 0;
  double duration = 0.0;  // s; 0: until the route ends
  WorldSpec world;
  std::array<Material, kTerrainClasses> materials{};
  std::vector<Region> regions;
  std::vector<Trail> trails;
  std::vector<Obstacle> obstacles;
  std::vector<JunctionError> junction_errors;
  Vec2 osm_offset{0.0, 0.0};  // m, a translation of the whole map
  std::vector<RouteLeg> route;
  RobotSpec robot;
  LidarSpec lidar;
  GpsSpec gps;
  ImuSpec imu;
  WheelSpec wheels;
  std::vector<EstopPress> estop;

  const Trail* trail(std::string_view name) const noexcept;
};

struct ScenarioResult {
  std::optional<Scenario> scenario;
  std::string error;  // file:line: key: problem
};

// A built-in name ("urban", ...) or a YAML file path.
ScenarioResult load_scenario(const std::string& name_or_path);
ScenarioResult parse_scenario(const std::string& text, const std::string& source);
std::vector<std::string> builtin_scenario_names();

// "2026-06-21T10:00:00Z" -> ns since the epoch.
std::optional<std::int64_t> parse_utc(std::string_view text) noexcept;

}  // namespace trailnav::sim
