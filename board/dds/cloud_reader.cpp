#include "cloud_reader.hpp"

#include <algorithm>
#include <span>
#include <string_view>

#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::dds {

namespace {

constexpr std::size_t kMaxFields = 64;

velodyne::RangeImageShape shape_of(const CloudReaderOptions& o) noexcept {
  return {static_cast<int>(o.layout.elevation_deg.size()), o.layout.columns, std::clamp(o.layers, 1, 2)};
}

}  // namespace

CloudReader::CloudReader(const CloudReaderOptions& options, velodyne::RangeImageShape shape, std::size_t max_points)
    : options_(options),
      shape_(shape),
      max_points_(max_points),
      imager_(options.layout, shape.layers, options.image),
      cloud_(max_points),
      fields_(kMaxFields),
      revolutions_(std::max<std::size_t>(options.readers, 1), shape),
      name_(ros_topic(options.topic)) {}

CloudReader::Created CloudReader::create(const Domain& domain, const CloudReaderOptions& options) {
  Created result;
  if (options.layout.elevation_deg.empty() || options.layout.columns < 16) {
    result.error = "the point cloud input needs a lidar layout (rings and columns)";
    return result;
  }
  const velodyne::RangeImageShape shape = shape_of(options);
  const std::size_t max_points = options.max_points > 0 ? options.max_points
                                                        : static_cast<std::size_t>(shape.rings) *
                                                              static_cast<std::size_t>(shape.max_columns) *
                                                              static_cast<std::size_t>(shape.layers);
  if (max_points > cloud::kMaxPoints) {
    result.error = "max_points " + std::to_string(max_points) + " is more than a cloud holds (" +
                   std::to_string(cloud::kMaxPoints) + ")";
    return result;
  }
  std::unique_ptr<CloudReader> r(new CloudReader(options, shape, max_points));
  // A revolution every 0.1 s: reliable (a lost fragment of a large sample
  // is repaired, not the whole revolution lost), and only the newest kept
  // (a reader behind takes the latest, as the lidar driver's readers do).
  auto input = SampleReader::create(domain, sensor_msgs_msg_dds__PointCloud2__desc, options.topic, {true, 1});
  if (!input.reader) {
    result.error = input.error;
    return result;
  }
  r->input_ = std::move(input.reader);
  result.reader = std::move(r);
  return result;
}

CloudReader::~CloudReader() {
  stop();
  dds_sample_free(&sample_, &sensor_msgs_msg_dds__PointCloud2__desc, DDS_FREE_CONTENTS);
}

void CloudReader::start() {
  input_->start(&sample_, [this] { handle(sample_, host_now_ns()); });
}

void CloudReader::stop() {
  if (input_) input_->stop();
}

CloudReaderStats CloudReader::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

void CloudReader::handle(const sensor_msgs_msg_dds__PointCloud2_& m, std::int64_t receive_ns) noexcept {
  const std::uint64_t points = static_cast<std::uint64_t>(m.height) * m.width;
  Status st = Status::ok();
  if (m.fields._length > kMaxFields) {
    st = Status::error(name_ + ": " + std::to_string(m.fields._length) + " fields; at most " + std::to_string(kMaxFields));
  } else if (points > max_points_) {
    st = Status::error(name_ + ": " + std::to_string(points) + " points; the input takes at most " +
                       std::to_string(max_points_) + " (lidar.max_points)");
  } else {
    for (std::uint32_t k = 0; k < m.fields._length; ++k) {
      const sensor_msgs_msg_dds__PointField_& f = m.fields._buffer[k];
      fields_[k] = cloud::PointFieldView{f.name != nullptr ? std::string_view(f.name) : std::string_view(), f.offset,
                                         f.datatype, f.count};
    }
    cloud::PointCloud2View v;
    v.height = m.height;
    v.width = m.width;
    v.fields = std::span<const cloud::PointFieldView>(fields_.data(), m.fields._length);
    v.is_bigendian = m.is_bigendian;
    v.point_step = m.point_step;
    v.row_step = m.row_step;
    v.data = std::span<const std::uint8_t>(m.data._buffer, m.data._length);
    st = cloud::read_pointcloud2(v, name_, cloud_);
  }
  cloud::CloudImageStats image_stats;
  if (st) {
    const std::int64_t stamp =
        static_cast<std::int64_t>(m.header.stamp.sec) * 1'000'000'000 + static_cast<std::int64_t>(m.header.stamp.nanosec);
    velodyne::RangeImage& image = revolutions_.write_slot();
    imager_.fill(cloud_, image, image_stats, {}, stamp);
    image.completed_receive_ns = receive_ns;
    // The stamp is on the sender's CLOCK_REALTIME: to the reference (host) clock.
    image.clock_offset_ns = host_from_realtime(stamp) - stamp;
    revolutions_.publish();
    if (event_ != nullptr) event_->signal(event_clock_->now());
  }
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.messages;
  stats_.last_receive_ns = receive_ns;
  if (!st) {
    ++stats_.refused;
    stats_.last_error = st.message();
    return;
  }
  ++stats_.published;
  stats_.points += points;
  stats_.image += image_stats;
}

}  // namespace trailnav::dds
