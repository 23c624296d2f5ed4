#include "cloud_sender.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <thread>

namespace trailnav::dds {

CloudSender::Created CloudSender::create(const Domain& domain, const std::string& topic, const std::string& frame_id) {
  Created result;
  std::unique_ptr<CloudSender> s(new CloudSender());
  s->topic_ = ros_topic(topic);
  s->frame_ = frame_id;
  s->topic_entity_ =
      dds_create_topic(domain.participant(), &sensor_msgs_msg_dds__PointCloud2__desc, s->topic_.c_str(), nullptr, nullptr);
  if (s->topic_entity_ < 0) {
    result.error = "topic " + s->topic_ + ": " + dds_strretcode(s->topic_entity_);
    s->topic_entity_ = 0;
    return result;
  }
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 2);
  s->writer_ = dds_create_writer(domain.participant(), s->topic_entity_, q, nullptr);
  dds_delete_qos(q);
  if (s->writer_ < 0) {
    result.error = "writer on " + s->topic_ + ": " + dds_strretcode(s->writer_);
    s->writer_ = 0;
    return result;
  }
  result.sender = std::move(s);
  return result;
}

CloudSender::~CloudSender() {
  for (dds_entity_t e : {writer_, topic_entity_}) {
    if (e > 0) dds_delete(e);
  }
}

bool CloudSender::wait_for_reader(double timeout_s) const {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (;;) {
    dds_publication_matched_status_t m{};
    dds_get_publication_matched_status(writer_, &m);
    if (m.current_count > 0) return true;
    if (std::chrono::steady_clock::now() >= until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

Status CloudSender::send(const cloud::PointCloud& c, std::int64_t stamp_ns) {
  // The fields this cloud has.
  names_ = {"x", "y", "z", "intensity"};
  std::vector<std::uint8_t> types{7, 7, 7, 7};
  if (c.has_ring) names_.push_back("ring"), types.push_back(4);
  if (c.has_time) names_.push_back("time"), types.push_back(8);
  fields_.assign(names_.size(), sensor_msgs_msg_dds__PointField_{});
  std::uint32_t step = 0;
  for (std::size_t k = 0; k < names_.size(); ++k) {
    const std::uint32_t size = types[k] == 8 ? 8 : types[k] == 4 ? 2 : 4;
    step = (step + size - 1) / size * size;  // each aligned to its size, as PCL's point types are
    fields_[k].name = names_[k].data();
    fields_[k].offset = step;
    fields_[k].datatype = types[k];
    fields_[k].count = 1;
    step += size;
  }
  step = (step + 7) / 8 * 8;
  if (c.size > std::numeric_limits<std::uint32_t>::max() / step) return Status::error(topic_ + ": too many points");
  data_.assign(c.size * step, 0);
  double t0 = 0.0;
  if (c.has_time) {
    t0 = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < c.size; ++i) t0 = std::isfinite(c.time[i]) ? std::min(t0, c.time[i]) : t0;
    if (!std::isfinite(t0)) t0 = 0.0;
  }
  for (std::size_t i = 0; i < c.size; ++i) {
    std::uint8_t* p = data_.data() + i * step;
    std::memcpy(p + fields_[0].offset, &c.x[i], 4);
    std::memcpy(p + fields_[1].offset, &c.y[i], 4);
    std::memcpy(p + fields_[2].offset, &c.z[i], 4);
    std::memcpy(p + fields_[3].offset, &c.intensity[i], 4);
    std::size_t k = 4;
    if (c.has_ring) std::memcpy(p + fields_[k++].offset, &c.ring[i], 2);
    if (c.has_time) {
      const double t = c.time[i] - t0;
      std::memcpy(p + fields_[k].offset, &t, 8);
    }
  }
  sensor_msgs_msg_dds__PointCloud2_ m{};
  m.header.stamp.sec = static_cast<std::int32_t>(stamp_ns / 1'000'000'000);
  m.header.stamp.nanosec = static_cast<std::uint32_t>(stamp_ns % 1'000'000'000);
  m.header.frame_id = frame_.data();
  m.height = 1;
  m.width = static_cast<std::uint32_t>(c.size);
  m.fields._buffer = fields_.data();
  m.fields._length = m.fields._maximum = static_cast<std::uint32_t>(fields_.size());
  m.is_bigendian = false;
  m.point_step = step;
  m.row_step = step * m.width;
  m.data._buffer = data_.data();
  m.data._length = m.data._maximum = static_cast<std::uint32_t>(data_.size());
  m.is_dense = false;
  const dds_return_t r = dds_write(writer_, &m);
  if (r != DDS_RETCODE_OK) return Status::error(topic_ + ": " + dds_strretcode(r));
  return Status::ok();
}

}  // namespace trailnav::dds
