#include "trailnav/navigation/navigator/navigation_task.hpp"

namespace trailnav::nav {

NavigationTask::NavigationTask(Navigator& navigator, Mailbox<pose::PoseSnapshot>& poses,
                               Broadcast<perception::TerrainClassMap>::Reader* terrain, Mailbox<NavigationSnapshot>& out)
    : navigator_(navigator), poses_(poses), terrain_(terrain), out_(out) {}

void NavigationTask::run(const TaskTick&) {
  ++local_.runs;
  bool ordered = false;
  if (commands_ != nullptr) {
    NavCommand c;
    while (commands_->try_pop(c)) {
      ++local_.commands;
      ordered = true;
      if (c.kind == NavCommand::Kind::cancel) {
        navigator_.cancel();
      } else {
        navigator_.set_goal(c.goal);
      }
      if (answers_ != nullptr) {
        navigator_.report(answer_);
        if (!answers_->try_push(answer_)) ++local_.answers_dropped;
      }
    }
  }
  const pose::PoseSnapshot* pose = poses_.try_read();
  const perception::TerrainClassMap* map = terrain_ != nullptr ? terrain_->try_read() : nullptr;
  if (pose != nullptr) ++local_.poses;
  if (map != nullptr) ++local_.terrain_maps;
  // Nothing new, or no pose yet (the subgoals need both frames of one instant).
  if (!ordered && ((pose == nullptr && map == nullptr) || poses_.last_read_sequence() == 0)) {
    shared_.post(local_);
    return;
  }
  if (poses_.last_read_sequence() != 0) {
    const pose::PoseSnapshot& p = poses_.last_read();
    navigator_.step(p.local, p.utm, map);
  }
  NavigationSnapshot& slot = out_.write_slot();
  navigator_.snapshot(slot);
  if (slot.active_revision != last_active_revision_ || slot.path_revision != last_path_revision_ ||
      slot.state != last_state_ || slot.goal_revision != last_goal_revision_) {
    last_active_revision_ = slot.active_revision;
    last_path_revision_ = slot.path_revision;
    last_state_ = slot.state;
    last_goal_revision_ = slot.goal_revision;
    out_.publish();
    ++local_.published;
    if (notify_ != nullptr) notify_->notify();
  }
  local_.state = slot.state;
  local_.subgoals = slot.subgoals;
  local_.active = slot.active;
  local_.route_length = slot.route_length;
  local_.progress = slot.progress;
  local_.cross_track = slot.cross_track;
  local_.navigator = slot.counters;
  local_.message = slot.message;
  local_.refusal = slot.report.refusal;
  local_.remaining = slot.report.remaining;
  shared_.post(local_);
}

}  // namespace trailnav::nav
