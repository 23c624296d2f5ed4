// CARMEN log lines with 2D laser scans (`FLASER`), as the Freiburg building
// 079 log of ../shared/data/carmen: `FLASER n r_1 .. r_n x y θ odom_x odom_y
// odom_θ ipc_timestamp hostname logger_timestamp`. The beams span 180° from
// −90° (a SICK LMS: n = 180, 181, 360 or 361); a range at or beyond
// `max_range` is no return. The poses are the log's (here SLAM-corrected:
// the reference of the lidar odometry). Other lines are not scans.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

#include "trailnav/perception/registration/cloud.hpp"

namespace trailnav::perception::registration {

struct Pose2 {
  double x = 0.0, y = 0.0, theta = 0.0;
};

struct LaserScan2 {
  std::vector<float> ranges;  // metres, beam i at −90° + i·180°/(n − 1) (n − 1 steps) or 180°/n
  Pose2 pose;                 // the log's pose of the laser
  Pose2 odometry;             // the log's odometry fields
  double timestamp = 0.0;     // ipc timestamp, s
};

// Parses one line: "" on success; else what is wrong with it ("not FLASER"
// for other message types). At most `max_beams` ranges.
std::string parse_flaser(std::string_view line, LaserScan2& out, std::size_t max_beams = 1081);

// The scan's returns as points in the laser's frame (z = 0); ranges at or
// beyond `max_range` or below `min_range` are no return. Appends to `out`
// within its reserved capacity; returns how many returns found no room.
std::size_t scan_points(const LaserScan2& scan, float max_range, float min_range, std::vector<Point>& out) noexcept;

// A CARMEN log's scans (plain or gzip): the FLASER lines that parse, those
// numbered `from` to `to` among them (0 the first; `to` < 0: to the end).
// Lines of other messages are skipped; FLASER lines that do not parse are
// counted, the first with its line number and reason.
struct FlaserLog {
  std::vector<LaserScan2> scans;
  long refused = 0;
  std::string first_error;  // "line N: ..." of the first refused line
  std::string error;        // the file could not be opened: empty otherwise
};
FlaserLog read_flaser_log(const std::string& path, long from = 0, long to = -1);

// A planar pose as a 3D transform (z = 0, yaw θ), and a transform's planar
// part back (its translation's x and y, its yaw).
Eigen::Isometry3d to_isometry(const Pose2& p) noexcept;
Pose2 to_pose2(const Eigen::Isometry3d& t) noexcept;

}  // namespace trailnav::perception::registration
