// Point clouds in over DDS (board/dds/cloud_reader.hpp): the real
// SemanticKITTI scan sent as a sensor_msgs/PointCloud2 through a real
// writer and reader on a loopback-only domain becomes the range image the
// offline tools make of the file, bit for bit, stamped with the message's
// time; a message that cannot be read is refused with its reason and
// counted, never published.
#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "cloud_reader.hpp"
#include "dds.hpp"
#include "test_data.hpp"
#include "trailnav/drivers/cloud/cloud_file.hpp"
#include "trailnav/drivers/cloud/cloud_image.hpp"
#include "trailnav/runtime/host_clock.hpp"

using namespace trailnav;

namespace {

// A PointCloud2 of x y z intensity (float32, 16 bytes a point) over `bytes`.
struct Message {
  std::vector<sensor_msgs_msg_dds__PointField_> fields;
  std::vector<std::string> names{"x", "y", "z", "intensity"};
  sensor_msgs_msg_dds__PointCloud2_ m{};
  explicit Message(std::vector<std::uint8_t>& bytes, std::uint8_t x_type = 7) {
    for (std::uint32_t k = 0; k < 4; ++k) {
      sensor_msgs_msg_dds__PointField_ f{};
      f.name = names[k].data();
      f.offset = 4 * k;
      f.datatype = k == 0 ? x_type : std::uint8_t{7};
      f.count = 1;
      fields.push_back(f);
    }
    m.header.stamp.sec = 1'700'000'000;
    m.header.stamp.nanosec = 250'000'000;
    m.header.frame_id = names[0].data();
    m.height = 1;
    m.width = static_cast<std::uint32_t>(bytes.size() / 16);
    m.fields._buffer = fields.data();
    m.fields._length = m.fields._maximum = static_cast<std::uint32_t>(fields.size());
    m.point_step = 16;
    m.row_step = 16 * m.width;
    m.data._buffer = bytes.data();
    m.data._length = m.data._maximum = static_cast<std::uint32_t>(bytes.size());
    m.is_dense = true;
  }
};

std::vector<std::uint8_t> scan_bytes(cloud::PointCloud& file) {
  cloud::CloudScratch scratch;
  const std::string path = test::shared_data("semantickitti/000000.bin");
  EXPECT_TRUE(cloud::load_cloud(path, file, scratch));
  return {scratch.bytes.begin(), scratch.bytes.begin() + static_cast<std::ptrdiff_t>(file.size * 16)};
}

dds::CloudReaderOptions kitti_options() {
  dds::CloudReaderOptions o;
  o.topic = "test/points_in";
  o.layout = *cloud::ring_layout_preset("HDL-64E");
  o.layout.columns = 2160;
  o.image = cloud::CloudImageOptions{255.0f, 0.1, cloud::RingSource::order};
  o.max_points = 130000;
  return o;
}

}  // namespace

TEST(CloudReader, AKittiScanSentAsPointCloud2IsTheFilesRangeImage) {
  host_clock_start();
  auto d = dds::Domain::create(95, dds::loopback_config());
  ASSERT_TRUE(d.domain) << d.error;
  auto made = dds::CloudReader::create(*d.domain, kitti_options());
  ASSERT_TRUE(made.reader) << made.error;
  dds::CloudReader& reader = *made.reader;
  reader.start();

  cloud::PointCloud file;
  std::vector<std::uint8_t> bytes = scan_bytes(file);
  Message msg(bytes);
  const dds_entity_t topic = dds_create_topic(d.domain->participant(), &sensor_msgs_msg_dds__PointCloud2__desc,
                                              "rt/test/points_in", nullptr, nullptr);
  ASSERT_GT(topic, 0);
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  const dds_entity_t writer = dds_create_writer(d.domain->participant(), topic, q, nullptr);
  dds_delete_qos(q);
  ASSERT_GT(writer, 0);
  // Until the reader has matched the writer (discovery), then one message.
  const velodyne::RangeImage* image = nullptr;
  bool sent = false;
  for (int k = 0; k < 500 && image == nullptr; ++k) {
    dds_publication_matched_status_t s{};
    dds_get_publication_matched_status(writer, &s);
    if (s.current_count > 0 && !sent) {
      ASSERT_EQ(dds_write(writer, &msg.m), 0);
      sent = true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    image = reader.revolutions(0).try_read();
  }
  ASSERT_NE(image, nullptr) << "no image in 10 s";
  const dds::CloudReaderStats st = reader.stats();
  EXPECT_EQ(st.published, 1u);
  EXPECT_EQ(st.refused, 0u);
  EXPECT_EQ(st.points, file.size);
  EXPECT_EQ(st.image.placed + st.image.second + st.image.collisions + st.image.invalid + st.image.bad_ring, file.size);
  EXPECT_EQ(st.image.sweeps, 64u);

  // The offline tools' image of the same file.
  const dds::CloudReaderOptions o = kitti_options();
  cloud::CloudImager imager(o.layout, 2, o.image);
  velodyne::RangeImage offline(imager.shape());
  cloud::CloudImageStats offline_stats;
  imager.fill(file, offline, offline_stats);
  EXPECT_EQ(image->points, offline.points);
  for (int layer = 0; layer < 2; ++layer) {
    for (int r = 0; r < offline.rings(); ++r) {
      ASSERT_EQ(std::memcmp(image->row(layer, r).data(), offline.row(layer, r).data(),
                            offline.row(layer, r).size_bytes()),
                0)
          << "layer " << layer << " row " << r;
    }
  }
  // Stamped with the message's time; the offset to the host clock taken.
  EXPECT_EQ(image->start_ns, 1'700'000'000'250'000'000LL);
  EXPECT_EQ(image->end_ns, 1'700'000'000'350'000'000LL);
  EXPECT_EQ(image->start_ns + image->clock_offset_ns, host_from_realtime(image->start_ns));
  EXPECT_GT(image->completed_receive_ns, 0);
  reader.stop();
  dds_delete(writer);
  dds_delete(topic);
}

TEST(CloudReader, UnreadableMessagesAreRefusedWithTheirReason) {
  host_clock_start();
  auto d = dds::Domain::create(94, dds::loopback_config());
  ASSERT_TRUE(d.domain) << d.error;
  dds::CloudReaderOptions o = kitti_options();
  o.max_points = 1000;
  auto made = dds::CloudReader::create(*d.domain, o);
  ASSERT_TRUE(made.reader) << made.error;
  dds::CloudReader& reader = *made.reader;
  std::vector<std::uint8_t> bytes(16 * 500, 0);
  // A datatype PointField does not have (handled as the thread would).
  Message bad(bytes, 9);
  reader.handle(bad.m, 1);
  dds::CloudReaderStats st = reader.stats();
  EXPECT_EQ(st.messages, 1u);
  EXPECT_EQ(st.refused, 1u);
  EXPECT_EQ(st.published, 0u);
  EXPECT_NE(st.last_error.find("rt/test/points_in: field 'x': datatype 9"), std::string::npos) << st.last_error;
  EXPECT_EQ(reader.revolutions(0).try_read(), nullptr);
  // More points than the input was sized for.
  std::vector<std::uint8_t> many(16 * 1001, 0);
  Message large(many);
  reader.handle(large.m, 2);
  st = reader.stats();
  EXPECT_EQ(st.refused, 2u);
  EXPECT_NE(st.last_error.find("1001 points; the input takes at most 1000"), std::string::npos) << st.last_error;
  // A good one after them is published, and the event signalled on the
  // clock it was given (the scheduler's: an event task's latency counts from it).
  TaskEvent event;
  MonotonicClock clock;
  reader.set_revolution_event(&event, clock);
  Message good(bytes);
  const Nanos before = clock.now();
  reader.handle(good.m, 3);
  const Nanos after = clock.now();
  EXPECT_GE(event.last_signal(), before);
  EXPECT_LE(event.last_signal(), after);
  st = reader.stats();
  EXPECT_EQ(st.published, 1u);
  EXPECT_EQ(st.image.invalid, 500u);  // every point at the origin
  EXPECT_NE(reader.revolutions(0).try_read(), nullptr);
  // A layout without rings is refused at creation.
  o.layout.elevation_deg.clear();
  EXPECT_FALSE(dds::CloudReader::create(*d.domain, o).reader);
}
