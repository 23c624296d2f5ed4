#include "trailnav/perception/obstacle_task.hpp"

#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::perception {

ObstacleTask::ObstacleTask(ObstaclePipeline& pipeline, Broadcast<velodyne::RangeImage>::Reader& revolutions, PoseQueue* poses,
                           Broadcast<TerrainClassMap>::Reader* terrain, Mailbox<ObstacleSnapshot>& out, std::size_t pose_history,
                           PoseWait pose_wait)
    : pipeline_(pipeline), revolutions_(revolutions), poses_(poses), terrain_(terrain), out_(out), track_(pose_history),
      pose_wait_(pose_wait) {}

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
  out.received_ns = 0;
  out.revolution = cloud.sequence;
  map.export_occupancy(out.occupancy);
}

void take_points(const ObstaclePipeline& pipeline, const TerrainClassMap* terrain, PointsSnapshot& out) noexcept {
  const RevolutionCloud& c = pipeline.cloud();
  const TerrainSource source = pipeline.terrain_source(terrain);
  out.time_ns = c.time_ns + c.clock_offset_ns;
  const double span = static_cast<double>(c.time_ns - c.start_ns) * 1e-9;
  const int columns = c.columns();
  std::size_t n = 0;
  for (int ring = 0; ring < c.rings(); ++ring) {
    for (int col = 0; col < columns; ++col) {
      const std::size_t k = c.index(ring, col);
      if (c.state[k] == PointState::none) continue;
      if (n == out.points.size()) break;
      const ObstaclePipeline::PointAnswer a = pipeline.answer(source, k);
      CloudPoint& p = out.points[n++];
      p.x = static_cast<float>(c.ref_x + static_cast<double>(c.x[k]));
      p.y = static_cast<float>(c.ref_y + static_cast<double>(c.y[k]));
      p.z = static_cast<float>(c.ref_z + static_cast<double>(c.z[k]));
      p.intensity = c.intensity[k];
      p.time = static_cast<float>(span * (col + 0.5) / columns);
      p.p_obstacle = a.smooth;
      p.ring = static_cast<std::uint16_t>(ring);
      p.obstacle = a.dirac ? 1 : 0;
      p.terrain = static_cast<std::uint8_t>(a.terrain);
    }
  }
  out.count = n;
}

namespace {

// A revolution that was not mapped, told to the aligned points' reader.
void hand_over_outcome(Mailbox<AlignedRevolution>* out, const velodyne::RangeImage& image,
                       AlignedRevolution::Outcome outcome) noexcept {
  if (out == nullptr) return;
  AlignedRevolution& a = out->write_slot();
  a.sequence = image.sequence;
  a.reference_end_ns = image.reference_end_ns();
  a.outcome = outcome;
  out->publish();
}

}  // namespace

void ObstacleTask::take_terrain() noexcept {
  if (terrain_ == nullptr) return;
  if (const TerrainClassMap* t = terrain_->try_read()) {
    terrain_map_ = t;
    ++counters_.terrain_maps;
  }
}

bool ObstacleTask::pose_ready(const velodyne::RangeImage& image) noexcept {
  // The pose thread must have reached the revolution's end (see PoseWait).
  if (poses_ == nullptr) return true;
  if (await_pose(track_, *poses_, image.reference_end_ns(), pose_wait_, counters_)) return true;
  hand_over_outcome(aligned_out_, image, AlignedRevolution::Outcome::pose_late);
  return false;
}

bool ObstacleTask::odometry_ready(const velodyne::RangeImage& image) noexcept {
  // A revolution mapped with a position the odometry could not measure
  // would put what it sees in the wrong cells, next to cells mapped before
  // from where the robot really was: no map then (the publisher sends the
  // last one stale), and a fresh one when the odometry knows again.
  if (track_.motion_known(image.reference_start_ns(), image.reference_end_ns())) return true;
  ++counters_.no_odometry;
  counters_.odometry_lost = true;
  hand_over_outcome(aligned_out_, image, AlignedRevolution::Outcome::no_odometry);
  return false;
}

void ObstacleTask::map_whole(const velodyne::RangeImage& image) noexcept {
  if (last_sequence_ != 0 && image.sequence > last_sequence_ + 1) counters_.skipped += image.sequence - last_sequence_ - 1;
  last_sequence_ = image.sequence;
  take_terrain();
  if (!pose_ready(image) || !odometry_ready(image)) return;
  if (counters_.odometry_lost) {
    pipeline_.forget_maps();
    ++counters_.map_resets;
    counters_.odometry_lost = false;
  }
  pipeline_.process(image, track_.size() > 0 ? &track_ : nullptr, terrain_map_);
  publish(image);
}

void ObstacleTask::publish(const velodyne::RangeImage& image) noexcept {
  ++counters_.revolutions;
  ObstacleSnapshot& snap = out_.write_slot();
  take_snapshot(pipeline_.map(), pipeline_.cloud(), snap);
  snap.terrain_sequence = terrain_map_ != nullptr ? terrain_map_->sequence : 0;
  snap.received_ns = image.completed_receive_ns;
  out_.publish();
  if (image.completed_receive_ns > 0) map_delay_.record(host_now_ns() - image.completed_receive_ns);
  if (points_out_ != nullptr && (last_points_ns_ == 0 || snap.time_ns - last_points_ns_ >= points_period_ns_ ||
                                 snap.time_ns < last_points_ns_)) {
    last_points_ns_ = snap.time_ns;
    take_points(pipeline_, terrain_map_, points_out_->write_slot());
    points_out_->publish();
    ++counters_.point_clouds;
  }
  if (notify_ != nullptr) notify_->notify();
  // Last: the hand-over trades the cloud's arrays away.
  if (aligned_out_ != nullptr) {
    AlignedRevolution& a = aligned_out_->write_slot();
    pipeline_.hand_over_aligned(a.cloud);
    a.sequence = image.sequence;
    a.reference_end_ns = image.reference_end_ns();
    a.outcome = AlignedRevolution::Outcome::aligned;
    aligned_out_->publish();
  }
  counters_.pipeline = pipeline_.counters();
}

int ObstacleTask::posed_columns(const velodyne::RangeImage& image, int final_columns) const noexcept {
  if (poses_ == nullptr || track_.size() == 0) return final_columns;
  // Whole blocks from the first not aligned yet, while their last column's
  // firing is within the lag of the newest pose.
  constexpr int kBlock = ObstaclePipeline::kBlockColumns;
  int usable = pipeline_.aligned_columns();
  while (usable < final_columns) {
    const int end = std::min(usable + kBlock, final_columns);
    const std::int64_t t = image.column_time_ns(end - 1);
    if (t != velodyne::RangeImage::kNoTime && track_.lag(t + image.clock_offset_ns) > pose_wait_.max_lag_ns) break;
    usable = end;
  }
  return usable;
}

bool ObstacleTask::follow_step() noexcept {
  if (followed_ == nullptr) {
    // A revolution published since that was not followed (the first one, or
    // one whose start this task missed): whole.
    if (const velodyne::RangeImage* image = revolutions_.try_read()) {
      if (image->sequence != last_sequence_) map_whole(*image);
    }
    followed_ = revolutions_.follow();
    begun_ = false;
    return followed_ != nullptr;
  }
  if (const velodyne::RangeImage* done = revolutions_.completed()) {
    // The revolution followed is complete: its last blocks, or the whole of
    // it if it was not begun.
    followed_ = nullptr;
    if (!begun_) {
      if (done->sequence != last_sequence_) map_whole(*done);
      return true;
    }
    if (last_sequence_ != 0 && done->sequence > last_sequence_ + 1) counters_.skipped += done->sequence - last_sequence_ - 1;
    last_sequence_ = done->sequence;
    if (!pose_ready(*done) || !odometry_ready(*done)) return true;
    pipeline_.finish(*done, track_.size() > 0 ? &track_ : nullptr);
    ++counters_.streamed;
    publish(*done);
    return true;
  }
  if (revolutions_.abandoned()) {
    if (begun_) ++counters_.abandoned;
    followed_ = nullptr;
    return true;
  }
  const std::uint64_t word = revolutions_.progress();
  if (word == 0) return false;  // nothing of it final yet
  const velodyne::RangeImage& image = *followed_;
  if (!begun_ || velodyne::progress_generation(word) != generation_) {
    if (begun_) ++counters_.abandoned;  // started anew in the same slot
    if (track_.lag(image.reference_start_ns()) > pose_wait_.max_lag_ns) return false;  // its first pose not yet here
    take_terrain();
    if (counters_.odometry_lost && track_.motion_known(image.reference_start_ns(), image.reference_start_ns())) {
      pipeline_.forget_maps();
      ++counters_.map_resets;
      counters_.odometry_lost = false;
    }
    pipeline_.begin(image, track_.size() > 0 ? &track_ : nullptr, terrain_map_);
    begun_ = true;
    generation_ = velodyne::progress_generation(word);
  }
  const int final_columns = velodyne::progress_columns(word);
  const int worked = pipeline_.advance(image, track_.size() > 0 ? &track_ : nullptr, posed_columns(image, final_columns));
  counters_.early_blocks += static_cast<std::uint64_t>(worked);
  return false;
}

void ObstacleTask::run(const TaskTick&) {
  ++counters_.runs;
  if (poses_ != nullptr) counters_.poses += track_.drain(*poses_);
  if (streaming_) {
    // A few steps at most: publish, follow the next, work on what it has.
    for (int step = 0; step < 4 && follow_step(); ++step) {
    }
    shared_.post(counters_);
    return;
  }
  take_terrain();
  const velodyne::RangeImage* image = revolutions_.try_read();
  if (image != nullptr && image->sequence != last_sequence_) map_whole(*image);
  shared_.post(counters_);
}

}  // namespace trailnav::perception
