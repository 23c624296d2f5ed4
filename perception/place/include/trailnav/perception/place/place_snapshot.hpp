// The place task's answer (place_task.hpp), on its own so that the pose
// thread, which may take it as a measurement (navigation/pose), needs no
// camera headers.
#pragma once

#include <cstdint>

namespace trailnav::perception::place {

struct PlaceSnapshot {
  std::int64_t stamp_ns = 0;         // the camera frame's (host time)
  std::uint32_t frame_sequence = 0;  // the camera's
  std::uint64_t number = 0;          // steps so far
  int index = -1;                    // database image
  double probability = 0.0;          // belief within ±window of it
  double peak = 0.0;                 // belief of the image itself
  std::int64_t database_stamp_ns = 0;
  double x = 0.0, y = 0.0, yaw = 0.0;  // the database's frame
  double lat = 0.0, lon = 0.0;         // the same as latitude and longitude (the window's weighted mean); NaN when the database has none
  double cov_xx = 0.0, cov_xy = 0.0, cov_yy = 0.0, var_yaw = 0.0;
  int lag = 0;               // frames this answer trails the newest
  int chain = 0;             // the longest chain of matches through it
  bool in_sequence = false;  // chain >= the online sequence test's l_s
};

}  // namespace trailnav::perception::place
