#include "commands.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>

#include "messages.hpp"

namespace trailnav::dds {

namespace {

void copy_frame(const char* frame, std::array<char, 48>& out) noexcept {
  out.fill('\0');
  if (frame == nullptr) return;
  std::strncpy(out.data(), frame, out.size() - 1);
}

}  // namespace

nav::NavCommand goal_from_pose(const geometry_msgs_msg_dds__PoseStamped_& s, const CommandReaderOptions& o) noexcept {
  nav::NavCommand c;
  c.kind = nav::NavCommand::Kind::goal;
  c.goal.a = s.pose.position.x;
  c.goal.b = s.pose.position.y;
  copy_frame(s.header.frame_id, c.goal.frame_id);
  const std::string_view frame = s.header.frame_id != nullptr ? std::string_view(s.header.frame_id) : std::string_view();
  char utm[16], map[64];
  utm_frame_name(o.zone, o.north, utm);
  map_frame_name(o.map_frame, o.zone, o.north, map);
  if (frame == o.odom_frame) {
    c.goal.frame = nav::GoalFrame::odom;
  } else if (frame == utm || frame == map) {
    c.goal.frame = nav::GoalFrame::utm;
  } else {
    c.goal.frame = nav::GoalFrame::unknown;
  }
  return c;
}

nav::NavCommand goal_from_geo_pose(const geographic_msgs_msg_dds__GeoPoseStamped_& s) noexcept {
  nav::NavCommand c;
  c.kind = nav::NavCommand::Kind::goal;
  c.goal.frame = nav::GoalFrame::geographic;
  c.goal.a = s.pose.position.latitude;
  c.goal.b = s.pose.position.longitude;
  copy_frame(s.header.frame_id, c.goal.frame_id);
  return c;
}

CommandReader::Created CommandReader::create(const Domain& domain, const CommandReaderOptions& options,
                                             nav::NavCommandQueue& queue) {
  Created result;
  std::unique_ptr<CommandReader> r(new CommandReader(options, queue));
  dds_qos_t* q = dds_create_qos();
  // Every order counts: reliable, and room for a burst of them.
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 16);
  auto make = [&](const dds_topic_descriptor_t& type, const std::string& name, dds_entity_t& topic, dds_entity_t& reader) {
    if (!result.error.empty()) return;
    const std::string full = ros_topic(name);
    topic = dds_create_topic(domain.participant(), &type, full.c_str(), nullptr, nullptr);
    if (topic < 0) {
      result.error = "topic " + full + ": " + dds_strretcode(topic);
      topic = 0;
      return;
    }
    reader = dds_create_reader(domain.participant(), topic, q, nullptr);
    if (reader < 0) {
      result.error = "reader on " + full + ": " + dds_strretcode(reader);
      reader = 0;
    }
  };
  make(geometry_msgs_msg_dds__PoseStamped__desc, options.topics.goal, r->goal_topic_, r->goal_reader_);
  make(geographic_msgs_msg_dds__GeoPoseStamped__desc, options.topics.geo_goal, r->geo_topic_, r->geo_reader_);
  make(std_msgs_msg_dds__Empty__desc, options.topics.cancel, r->cancel_topic_, r->cancel_reader_);
  dds_delete_qos(q);
  if (!result.error.empty()) return result;
  r->waitset_ = dds_create_waitset(domain.participant());
  for (dds_entity_t reader : {r->goal_reader_, r->geo_reader_, r->cancel_reader_}) {
    dds_set_status_mask(reader, DDS_DATA_AVAILABLE_STATUS);
    dds_waitset_attach(r->waitset_, reader, reader);
  }
  result.reader = std::move(r);
  return result;
}

CommandReader::~CommandReader() {
  stop();
  dds_sample_free(&goal_sample_, &geometry_msgs_msg_dds__PoseStamped__desc, DDS_FREE_CONTENTS);
  dds_sample_free(&geo_sample_, &geographic_msgs_msg_dds__GeoPoseStamped__desc, DDS_FREE_CONTENTS);
  for (dds_entity_t e : {waitset_, goal_reader_, geo_reader_, cancel_reader_, goal_topic_, geo_topic_, cancel_topic_}) {
    if (e > 0) dds_delete(e);
  }
}

void CommandReader::start() {
  if (running_.exchange(true)) return;
  thread_ = std::thread([this] { loop(); });
}

void CommandReader::stop() {
  if (!running_.exchange(false)) return;
  if (waitset_ > 0) dds_waitset_set_trigger(waitset_, true);
  if (thread_.joinable()) thread_.join();
}

CommandReaderStats CommandReader::stats() const noexcept {
  CommandReaderStats s;
  s.goals = goals_.load(std::memory_order_relaxed);
  s.geo_goals = geo_goals_.load(std::memory_order_relaxed);
  s.cancels = cancels_.load(std::memory_order_relaxed);
  s.queue_full = queue_full_.load(std::memory_order_relaxed);
  return s;
}

void CommandReader::push(const nav::NavCommand& command) noexcept {
  if (!queue_.try_push(command)) queue_full_.fetch_add(1, std::memory_order_relaxed);
}

void CommandReader::take_all() noexcept {
  dds_sample_info_t info;
  void* one[1];
  // Samples in the order of the topics; an order within a topic is kept.
  one[0] = &goal_sample_;
  while (dds_take(goal_reader_, one, &info, 1, 1) == 1) {
    if (!info.valid_data) continue;
    goals_.fetch_add(1, std::memory_order_relaxed);
    push(goal_from_pose(goal_sample_, options_));
  }
  one[0] = &geo_sample_;
  while (dds_take(geo_reader_, one, &info, 1, 1) == 1) {
    if (!info.valid_data) continue;
    geo_goals_.fetch_add(1, std::memory_order_relaxed);
    push(goal_from_geo_pose(geo_sample_));
  }
  one[0] = &cancel_sample_;
  while (dds_take(cancel_reader_, one, &info, 1, 1) == 1) {
    if (!info.valid_data) continue;
    cancels_.fetch_add(1, std::memory_order_relaxed);
    nav::NavCommand c;
    c.kind = nav::NavCommand::Kind::cancel;
    push(c);
  }
}

void CommandReader::loop() noexcept {
  while (running_.load(std::memory_order_acquire)) {
    dds_attach_t triggered[3];
    dds_waitset_wait(waitset_, triggered, 3, DDS_MSECS(200));
    if (!running_.load(std::memory_order_acquire)) break;
    take_all();
  }
}

}  // namespace trailnav::dds
