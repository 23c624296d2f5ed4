// The box of the thesis' simulated floor (board/sim/station_world.hpp) taught
// as trailnavd would be given it: 16 scans on the arc before it, their poses
// first guessed by noisy odometry and refined by the joint registration, the
// box marked by its polygon. For the station tests. Simulated truth.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "random.hpp"
#include "station_world.hpp"
#include "trailnav/perception/registration/station.hpp"

namespace trailnav::test {

// Every segment of the floor with its objects where they were taught.
inline std::vector<sim::station::Segment> taught_floor(const sim::station::World& world) {
  std::vector<sim::station::Pose2> taught;
  for (const sim::station::ObjectShape& o : world.objects) taught.push_back(o.pose);
  std::vector<sim::station::Segment> seg = world.walls;
  const auto os = sim::station::object_segments(world, taught);
  seg.insert(seg.end(), os.begin(), os.end());
  return seg;
}

// `drive_key` draws the teach-in's odometry noise, `noise_key` its scans'.
inline perception::registration::BuiltStation teach_simulated_box(const sim::station::World& world,
                                                                  const std::string& name, std::uint64_t drive_key,
                                                                  std::uint64_t noise_key,
                                                                  const perception::registration::StationConfig& config) {
  namespace reg = perception::registration;
  namespace st = sim::station;
  const st::ObjectShape& box = world.objects[0];
  const std::vector<st::Segment> seg = taught_floor(world);
  const st::Drive teach = st::teach_drive(box, 16, drive_key);
  std::vector<reg::StationScan> scans(teach.truth.size());
  st::Pose2 guess = teach.truth.front();
  for (std::size_t i = 0; i < scans.size(); ++i) {
    if (i > 0) guess = st::compose(guess, teach.odometry[i]);
    scans[i].points = st::cast(seg, teach.truth[i], {}, sim::hash(noise_key, i));
    scans[i].pose = st::to_isometry(guess);
  }
  reg::teach(scans, config);
  const reg::StationObject marked{name, {box.mark.begin(), box.mark.end()}};
  return reg::build_station(scans, std::span<const reg::StationObject>(&marked, 1), config);
}

}  // namespace trailnav::test
