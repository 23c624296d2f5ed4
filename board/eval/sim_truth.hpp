// The ground truth a simulated recording carries in its truth/ directory
// (docs/simulator.md): the scenario, the trajectory and the rasters, read
// back for scoring. Also a terrain-class map filled from the true classes,
// which stands in for the terrain thread until one is configured.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "roads.hpp"
#include "scenario.hpp"
#include "trailnav/perception/pose_track.hpp"
#include "trailnav/perception/terrain_class_map.hpp"

namespace trailnav::eval {

struct TruthRaster {
  int width = 0;
  int height = 0;
  double resolution = 0.05;
  double x0 = 0.0;  // world x, y of pixel (0, 0)'s centre (south-west corner)
  double y0 = 0.0;
  std::vector<std::uint8_t> data;  // row 0 = south

  // The pixel nearest a world point; `outside` beyond the raster.
  std::uint8_t at(double x, double y, std::uint8_t outside = 255) const noexcept;
};

struct TruthPose {
  std::int64_t utc_ns = 0;
  double x = 0, y = 0, z = 0, roll = 0, pitch = 0, yaw = 0;
  double arc = 0;  // m along the route
  double lat = std::numeric_limits<double>::quiet_NaN();  // degrees (NaN in recordings made before the column)
  double lon = std::numeric_limits<double>::quiet_NaN();
};

struct SimTruth {
  std::string dir;
  sim::Scenario scenario;
  TruthRaster terrain;    // sim::TerrainClass codes
  TruthRaster obstacles;  // sim::ObstacleTruth codes
  // Per obstacle pixel (same layout): ms after the scenario's start + 1 of the
  // first lidar return from a solid obstacle there; 0 never. Empty for
  // recordings made before the simulator wrote sightings.u32.
  std::vector<std::uint32_t> sightings;
  // The same for returns from an obstacle's side (a vertical face), not its
  // top, within 20 m (side_hits.u32), and for those of them that show the
  // face (side_sightings.u32: not clipping the top edge, not grazing; see
  // board/sim/truth.hpp); empty for older recordings.
  std::vector<std::uint32_t> side_hits;
  std::vector<std::uint32_t> side_sightings;
  // Per pixel: ms after the start + 1 of the first lidar return of any kind
  // there (returns.u32): a map may call a cell free only after this. Empty
  // for recordings made before the simulator wrote it.
  std::vector<std::uint32_t> returns;
  std::vector<TruthPose> trajectory;
};

struct SimTruthResult {
  std::optional<SimTruth> truth;
  std::string error;
};

// `dir`: a recording's truth/ directory.
SimTruthResult load_sim_truth(const std::string& dir);

// The route the robot drove (truth/route.csv: the true centrelines of the
// route's legs, world frame); an error when missing or shorter than two points.
std::string load_true_route(const std::string& dir, sim::Polyline& out);

// How far past a recording's end the daemon's stamps may lie beyond the
// replayer's own lateness: its threads stalled for up to 3.1 s under
// ThreadSanitizer on a busy 2-core machine (CI, December 2026).
inline constexpr std::int64_t kDaemonStallTolerance_ns = 5'000'000'000;

// Checks points a subscriber receives in trailnavd's odometry frame against
// the simulated trail. The odometry frame drifts away from the simulator's
// world, so each point goes through the robot's odometry pose and its true
// pose at the same instant: world = T_true(t) T_odom(t)^-1 p. Odometry poses
// come from the pose topic; `offset_ns` maps trailnavd's clock to the
// recording's (the replay's start in wall time minus the recording's start).
class TrailCheck {
 public:
  TrailCheck(const SimTruth& truth, const sim::Polyline& trail, std::int64_t offset_ns)
      : truth_(truth), trail_(trail), offset_ns_(offset_ns) {}
  void set_offset(std::int64_t offset_ns) noexcept { offset_ns_ = offset_ns; }
  // A recording has no data after its end, so an odometry pose stamped past
  // the trajectory's end is of data at or before it, stamped late: a sensor
  // whose clock relation was re-anchored on late arrivals (the replayer sent
  // late, or the daemon's threads stalled for seconds, as under a sanitizer)
  // stamps late until the next window. Such a stamp, up to `late_ns` past the
  // end, is taken as the robot at the end; beyond it, no true pose (NaN).
  void set_past_end_tolerance(std::int64_t late_ns) noexcept { late_ns_ = std::max<std::int64_t>(0, late_ns); }
  void add_odometry_pose(std::int64_t t_ns, double x, double y, double yaw);
  // Distance of (x, y), stamped t_ns (trailnavd's clock), to the trail's
  // centre; NaN without an odometry pose within 0.2 s or a true pose then.
  double distance(std::int64_t t_ns, double x, double y) const;
  // (x, y) of the odometry frame at t_ns in the simulator's world frame;
  // false as for distance().
  bool to_world(std::int64_t t_ns, double x, double y, double& wx, double& wy) const;
  std::int64_t offset_ns() const noexcept { return offset_ns_; }

 private:
  struct Sample {
    std::int64_t t;
    double x, y, yaw;
  };
  const SimTruth& truth_;
  const sim::Polyline& trail_;
  std::int64_t offset_ns_;
  std::int64_t late_ns_ = 0;
  std::vector<Sample> odometry_;
};

// The true pose at UTC time t, interpolated; false outside the trajectory.
struct TruthAt {
  double x = 0, y = 0, yaw = 0, arc = 0, lat = 0, lon = 0;
};
bool truth_at(const std::vector<TruthPose>& trajectory, std::int64_t t, TruthAt& out);

// Positions in a UTM frame named as trailnavd names it (`utm_32N`), stamped
// on trailnavd's clock, against the true trajectory at their stamps
// (`offset_ns`: trailnavd's clock minus the recording's): per position, it
// minus the truth, east and north; NaN for a position without a true pose
// at its time. A frame that is not a UTM one gives none.
struct StampedPosition {
  std::int64_t t = 0;
  double east = 0.0, north = 0.0;
};
std::vector<std::array<double, 2>> utm_errors(const std::vector<TruthPose>& trajectory, const std::string& frame,
                                              const std::vector<StampedPosition>& positions, std::int64_t offset_ns);

// Errors split into the offset common to all (their mean: with GPS-tied
// positions, the receiver's bias, which nothing tied to GPS can see) and
// what is left of each; NaN errors are left out.
struct CommonOffset {
  double east = 0.0, north = 0.0;  // the mean error
  double absolute_mean = 0.0;      // mean |error|
  double mean = 0.0, max = 0.0;    // of |error − offset|
  std::size_t count = 0;           // errors that are numbers
};
CommonOffset split_common_offset(const std::vector<std::array<double, 2>>& errors);

// The true trajectory as the obstacle pipeline's pose history (UTC times).
void fill_pose_track(const SimTruth& truth, perception::PoseTrack& track);

// Fills the cells of `map` that are not known yet (after it moved) with the
// true class distribution: the classes of the truth pixels in a window of
// `window` m around the cell, mixed with `epsilon` of a uniform one. A cell
// holding part of a solid obstacle is `other`, one holding undergrowth
// `vegetation`, as a terrain classifier sees them.
void fill_truth_terrain(const SimTruth& truth, perception::TerrainClassMap& map, double window = 0.2,
                        float epsilon = 0.05f);

}  // namespace trailnav::eval
