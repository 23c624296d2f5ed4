#include "scan_reader.hpp"

#include <cmath>
#include <cstdio>

#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::dds {

namespace {

std::string number(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", v);
  return text;
}

}  // namespace

Status read_laser_scan(const sensor_msgs_msg_dds__LaserScan_& m, const LaserScanOptions& o, std::string_view what,
                       perception::registration::PlanarScan& out) noexcept {
  // What is wrong, named by the topic (the string built only for a refusal).
  auto refused = [what](const std::string& why) { return Status::error(std::string(what) + ": " + why); };
  const std::uint32_t n = m.ranges._length;
  if (n == 0 || m.ranges._buffer == nullptr) return refused("a scan without beams");
  if (n > o.max_beams || n > out.points.capacity()) {
    return refused(std::to_string(n) + " beams; the input takes at most " +
                   std::to_string(std::min(o.max_beams, out.points.capacity())) + " (station.max_points)");
  }
  if (!std::isfinite(m.angle_min) || !std::isfinite(m.angle_max) || !std::isfinite(m.angle_increment) ||
      m.angle_increment == 0.0f) {
    return refused("angle_min " + number(m.angle_min) + ", angle_max " + number(m.angle_max) + ", angle_increment " +
                   number(m.angle_increment) + ": the angles must be finite and the increment not zero");
  }
  // The last beam's angle as the message says it, and as its beams put it;
  // drivers differ by one beam (whether angle_max is the last beam's or one
  // past it), more is a message that does not describe its own beams.
  const double last = static_cast<double>(m.angle_min) + static_cast<double>(n - 1) * static_cast<double>(m.angle_increment);
  if (std::abs(last - static_cast<double>(m.angle_max)) > 1.01 * std::abs(static_cast<double>(m.angle_increment)) + 1e-6) {
    return refused(std::to_string(n) + " beams from angle_min " + number(m.angle_min) + " by " +
                   number(m.angle_increment) + " rad end at " + number(last) + ", but angle_max is " + number(m.angle_max));
  }
  if (!std::isfinite(m.range_min) || !std::isfinite(m.range_max) || m.range_min < 0.0f || m.range_max <= m.range_min) {
    return refused("range_min " + number(m.range_min) + ", range_max " + number(m.range_max) + ": not a range window");
  }
  const float far = o.max_range > 0.0f ? std::min(o.max_range, m.range_max) : m.range_max;
  const double c = std::cos(o.mount_yaw), s = std::sin(o.mount_yaw);
  out.points.clear();
  out.dropped = 0;
  for (std::uint32_t i = 0; i < n; ++i) {
    const float r = m.ranges._buffer[i];
    if (!std::isfinite(r) || r < m.range_min || r > far) continue;  // no return (ROS: outside the window)
    const double a = static_cast<double>(m.angle_min) + static_cast<double>(i) * static_cast<double>(m.angle_increment);
    const double lx = static_cast<double>(r) * std::cos(a), ly = static_cast<double>(r) * std::sin(a);
    out.points.emplace_back(static_cast<float>(o.mount_x + c * lx - s * ly), static_cast<float>(o.mount_y + s * lx + c * ly),
                            0.0f);
  }
  const std::int64_t stamp =
      static_cast<std::int64_t>(m.header.stamp.sec) * 1'000'000'000 + static_cast<std::int64_t>(m.header.stamp.nanosec);
  const double sweep = std::isfinite(m.time_increment) && m.time_increment > 0.0f
                           ? static_cast<double>(n - 1) * static_cast<double>(m.time_increment)
                           : 0.0;
  out.stamp_ns = host_from_realtime(stamp) + static_cast<std::int64_t>(sweep * 1e9);
  return Status::ok();
}

LaserScanReader::LaserScanReader(const LaserScanOptions& options, Mailbox<perception::registration::PlanarScan>& out)
    : options_(options), out_(out), name_(ros_topic(options.topic)) {}

LaserScanReader::Created LaserScanReader::create(const Domain& domain, const LaserScanOptions& options,
                                                 Mailbox<perception::registration::PlanarScan>& out) {
  Created result;
  std::unique_ptr<LaserScanReader> r(new LaserScanReader(options, out));
  // Sensor data: best effort is what laser drivers offer (SensorDataQoS),
  // and a best-effort reader matches reliable writers too; only the newest kept.
  auto input = SampleReader::create(domain, sensor_msgs_msg_dds__LaserScan__desc, options.topic, {false, 1});
  if (!input.reader) {
    result.error = input.error;
    return result;
  }
  r->input_ = std::move(input.reader);
  result.reader = std::move(r);
  return result;
}

LaserScanReader::~LaserScanReader() {
  stop();
  dds_sample_free(&sample_, &sensor_msgs_msg_dds__LaserScan__desc, DDS_FREE_CONTENTS);
}

void LaserScanReader::start() {
  input_->start(&sample_, [this] { handle(sample_, host_now_ns()); });
}

void LaserScanReader::stop() {
  if (input_) input_->stop();
}

LaserScanStats LaserScanReader::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

void LaserScanReader::handle(const sensor_msgs_msg_dds__LaserScan_& m, std::int64_t receive_ns) noexcept {
  perception::registration::PlanarScan& scan = out_.write_slot();
  const Status st = read_laser_scan(m, options_, name_, scan);
  if (st) {
    scan.sequence = ++sequence_;
    out_.publish();
  }
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.messages;
  stats_.last_receive_ns = receive_ns;
  if (!st) {
    ++stats_.refused;
    stats_.last_error = st.message();
    return;
  }
  ++stats_.handed;
  stats_.beams += m.ranges._length;
  stats_.returns += scan.points.size();
}

}  // namespace trailnav::dds
