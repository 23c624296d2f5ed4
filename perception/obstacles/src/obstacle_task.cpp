#include "trailnav/perception/obstacle_task.hpp"

namespace trailnav::perception {

ObstacleTask::ObstacleTask(ObstaclePipeline& pipeline, Broadcast<velodyne::RangeImage>::Reader& revolutions, PoseQueue* poses,
                           Broadcast<TerrainClassMap>::Reader* terrain, Mailbox<ObstacleSnapshot>& out, std::size_t pose_history)
    : pipeline_(pipeline), revolutions_(revolutions), poses_(poses), terrain_(terrain), out_(out), track_(pose_history) {}

void take_snapshot(const ObstacleMap& map, const RevolutionCloud& cloud, ObstacleSnapshot& out) noexcept {
  const auto& g = map.grid();
  out.resolution = g.resolution();
  out.origin_x = g.origin().x * g.resolution();
  out.origin_y = g.origin().y * g.resolution();
  out.robot_x = cloud.robot_x;
  out.robot_y = cloud.robot_y;
  out.robot_yaw = cloud.robot_yaw;
  out.robot_z = cloud.robot_z;
  out.robot_roll = cloud.robot_roll;
  out.robot_pitch = cloud.robot_pitch;
  out.time_ns = cloud.time_ns + cloud.clock_offset_ns;
  out.sensor_time_ns = cloud.time_ns;
  out.received_ns = 0;
  out.revolution = cloud.sequence;
  map.export_occupancy(out.occupancy);
}

void ObstacleTask::run(const TaskTick&) {
  ++counters_.runs;
  if (poses_ != nullptr) counters_.poses += track_.drain(*poses_);
  if (terrain_ != nullptr) {
    if (const TerrainClassMap* t = terrain_->try_read()) {
      terrain_map_ = t;
      ++counters_.terrain_maps;
    }
  }
  const velodyne::RangeImage* image = revolutions_.try_read();
  if (image == nullptr || image->sequence == last_sequence_) {
    shared_.post(counters_);
    return;
  }
  if (last_sequence_ != 0 && image->sequence > last_sequence_ + 1) counters_.skipped += image->sequence - last_sequence_ - 1;
  last_sequence_ = image->sequence;
  pipeline_.process(*image, track_.size() > 0 ? &track_ : nullptr, terrain_map_);
  ++counters_.revolutions;
  ObstacleSnapshot& snap = out_.write_slot();
  take_snapshot(pipeline_.map(), pipeline_.cloud(), snap);
  snap.terrain_sequence = terrain_map_ != nullptr ? terrain_map_->sequence : 0;
  snap.received_ns = image->completed_receive_ns;
  out_.publish();
  if (notify_ != nullptr) notify_->notify();
  counters_.pipeline = pipeline_.counters();
  shared_.post(counters_);
}

}  // namespace trailnav::perception
