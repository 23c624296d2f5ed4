// `trailnav place-map RECORDING --out DB`: a place database (perception/place/
// database.hpp) from a recording's camera frames and the poses the robot had
// when it took them: a simulated recording's true trajectory (simulated
// truth, said so), or a CSV of poses (`time,x,y,yaw[,lat,lon]`, time in
// seconds since the epoch, x and y in metres, yaw in radians) from whatever
// localised that drive. Frames are reduced to the descriptor's size as the
// camera driver reduces them, described, and kept every `every_m` metres
// driven (0: every frame).
#pragma once

#include <functional>
#include <string>

#include "trailnav/perception/place/database.hpp"

namespace trailnav::eval {

struct PlaceMapOptions {
  std::string recording;
  std::string camera;   // the image stream; "" for the recording's only one
  std::string poses;    // CSV; "" for the simulated truth
  int width = 64, height = 32;  // the descriptor's frames (camera.out_width x out_height)
  perception::place::HogConfig hog{0};
  double every_m = 0.0;
  // ZCA for the robot, learnt from the database against itself (docs/place.md):
  // its largest directions kept (0: none, Eq. 5.3 online instead) and ε.
  int zca_rank = 200;
  double zca_epsilon = 0.3;
  std::function<void(double)> progress;
};

struct PlaceMapReport {
  std::string error;
  perception::place::PlaceDatabase database;
  std::size_t frames = 0;          // image events read
  std::size_t without_pose = 0;    // outside the poses' time span: left out
  std::size_t too_close = 0;       // within every_m of the last kept: left out
  std::string pose_source;         // "simulated truth" or the CSV
  double path_m = 0.0;             // along the kept frames
};

PlaceMapReport make_place_map(const PlaceMapOptions& options);

}  // namespace trailnav::eval
