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
  auto w = Writer::create(domain, sensor_msgs_msg_dds__PointCloud2__desc, topic, EndpointQos{true, 2, Durability::volatile_});
  if (!w.writer) {
    result.error = w.error;
    return result;
  }
  std::unique_ptr<CloudSender> s(new CloudSender());
  s->frame_ = frame_id;
  s->writer_ = std::move(w.writer);
  result.sender = std::move(s);
  return result;
}

bool CloudSender::wait_for_reader(double timeout_s) const {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (;;) {
    dds_publication_matched_status_t m{};
    dds_get_publication_matched_status(writer_->handle(), &m);
    if (m.current_count > 0) return true;
    if (std::chrono::steady_clock::now() >= until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

bool CloudSender::wait_for_acks(double timeout_s) const {
  return dds_wait_for_acks(writer_->handle(), static_cast<dds_duration_t>(timeout_s * 1e9)) == DDS_RETCODE_OK;
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
  if (c.size > std::numeric_limits<std::uint32_t>::max() / step) return Status::error(topic() + ": too many points");
  data_.assign(c.size * step, 0);
  const double t0 = cloud::first_time(c);
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
  // (The stamp is the header's; the source timestamp is the time of writing.)
  if (!writer_->write(&m)) return Status::error(topic() + ": the write failed");
  return Status::ok();
}

}  // namespace trailnav::dds
