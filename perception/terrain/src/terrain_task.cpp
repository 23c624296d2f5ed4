#include "trailnav/perception/terrain_task.hpp"

namespace trailnav::perception {

TerrainTask::TerrainTask(TerrainMapper& mapper, Broadcast<velodyne::RangeImage>::Reader& revolutions, PoseQueue* poses,
                         Broadcast<TerrainClassMap>& out, std::size_t pose_history, PoseWait pose_wait)
    : mapper_(mapper), revolutions_(&revolutions), poses_(poses), out_(out), track_(pose_history), pose_wait_(pose_wait) {}

TerrainTask::TerrainTask(TerrainMapper& mapper, Mailbox<AlignedRevolution>& aligned, Broadcast<TerrainClassMap>& out)
    : mapper_(mapper), aligned_(&aligned), poses_(nullptr), out_(out), track_(1) {}

void TerrainTask::took(std::uint64_t sequence, std::int64_t reference_end_ns) noexcept {
  if (last_sequence_ != 0 && sequence > last_sequence_ + 1) {
    if (counters_.skipped == 0) counters_.intact_until_ns = last_taken_end_ns_;
    counters_.skipped += sequence - last_sequence_ - 1;
  }
  last_sequence_ = sequence;
  last_taken_end_ns_ = reference_end_ns;
}

void TerrainTask::publish() noexcept {
  if (mapper_.map().sequence == 0) return;
  out_.write_slot().copy_from(mapper_.map());
  out_.publish();
  ++counters_.published;
  counters_.last_step_ns = mapper_.map().time_ns;
  if (notify_ != nullptr) notify_->notify();
}

void TerrainTask::run_aligned() noexcept {
  const AlignedRevolution* a = aligned_->try_read();
  if (a == nullptr || a->sequence == last_sequence_) return;
  took(a->sequence, a->reference_end_ns);
  switch (a->outcome) {
    case AlignedRevolution::Outcome::no_odometry:
      ++counters_.no_odometry;
      return;
    case AlignedRevolution::Outcome::pose_late:
      ++counters_.pose_late;
      counters_.pose_behind = true;
      return;
    case AlignedRevolution::Outcome::aligned: break;
  }
  counters_.pose_behind = false;
  ++counters_.revolutions;
  if (mapper_.process_aligned(a->cloud)) publish();
  counters_.mapper = mapper_.counters();
}

void TerrainTask::run(const TaskTick&) {
  ++counters_.runs;
  if (aligned_ != nullptr) {
    run_aligned();
    shared_.post(counters_);
    return;
  }
  if (poses_ != nullptr) counters_.poses += track_.drain(*poses_);
  const velodyne::RangeImage* image = revolutions_->try_read();
  if (image != nullptr && image->sequence != last_sequence_) {
    took(image->sequence, image->reference_end_ns());
    // The pose thread must have reached the revolution's end (see PoseWait).
    if (poses_ != nullptr) {
      if (!await_pose(track_, *poses_, image->reference_end_ns(), pose_wait_, counters_)) {
        shared_.post(counters_);
        return;
      }
    }
    if (!track_.motion_known(image->reference_start_ns(), image->reference_end_ns())) {
      // Features placed with a position the odometry could not measure
      // would land in the wrong cells (as for the obstacle map).
      ++counters_.no_odometry;
      shared_.post(counters_);
      return;
    }
    ++counters_.revolutions;
    if (mapper_.process(*image, track_.size() > 0 ? &track_ : nullptr)) publish();
    counters_.mapper = mapper_.counters();
  }
  shared_.post(counters_);
}

}  // namespace trailnav::perception
