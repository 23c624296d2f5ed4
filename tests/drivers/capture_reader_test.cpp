#include "trailnav/drivers/capture/capture_reader.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

#include "test_data.hpp"

namespace trailnav::capture {
namespace {

TEST(CaptureReader, ReadsUdpFromARealPcap) {
  auto opened = open_capture(test::shared_data("velodyne/mrpt_sample_velodyne_vlp16_gps.pcap"));
  ASSERT_TRUE(opened.reader) << opened.error;
  int data = 0;
  int position = 0;
  std::int64_t previous = 0;
  while (auto d = opened.reader->next()) {
    if (d->destination_port == 2368 && d->payload.size() == 1206) ++data;
    if (d->destination_port == 8308 && d->payload.size() == 512) ++position;
    EXPECT_GE(d->time_ns, previous);
    previous = d->time_ns;
  }
  EXPECT_EQ(data, 293);
  EXPECT_EQ(position, 57);
  EXPECT_EQ(opened.reader->counters().frames, 350u);
  EXPECT_EQ(opened.reader->counters().truncated, 0u);
  EXPECT_EQ(opened.reader->position(), opened.reader->size() - 24);  // all but the file header
}

TEST(CaptureReader, ReadsRawBackToBackPayloads) {
  auto opened = open_capture(test::shared_data("velodyne/einride_vlp16_recording_raw1206.bin"));
  ASSERT_TRUE(opened.reader) << opened.error;
  int n = 0;
  while (auto d = opened.reader->next()) {
    ASSERT_EQ(d->payload.size(), 1206u);
    EXPECT_EQ(d->payload[0], 0xFF);
    EXPECT_EQ(d->payload[1], 0xEE);
    ++n;
  }
  EXPECT_EQ(n, 1000);
}

TEST(CaptureReader, TruncatedFramesAreCountedNotDelivered) {
  // A pcap with one Ethernet/IPv4/UDP frame whose UDP length claims more
  // bytes than were captured.
  const std::string path = ::testing::TempDir() + "/truncated.pcap";
  {
    std::ofstream f(path, std::ios::binary);
    const unsigned char header[24] = {0xd4, 0xc3, 0xb2, 0xa1, 2, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xff, 0xff, 0, 0, 1, 0, 0, 0};
    f.write(reinterpret_cast<const char*>(header), 24);
    unsigned char frame[14 + 20 + 8 + 4] = {};
    frame[12] = 0x08;            // IPv4
    frame[14] = 0x45;            // version 4, 20-byte header
    frame[14 + 9] = 17;          // UDP
    frame[34 + 2] = 0x09;        // destination port 2368
    frame[34 + 3] = 0x40;
    frame[34 + 4] = 0x04;        // UDP length 1214: more than the 12 bytes present
    frame[34 + 5] = 0xBE;
    const unsigned int record[4] = {1, 0, sizeof frame, sizeof frame};
    f.write(reinterpret_cast<const char*>(record), 16);
    f.write(reinterpret_cast<const char*>(frame), sizeof frame);
  }
  auto opened = open_capture(path);
  ASSERT_TRUE(opened.reader) << opened.error;
  EXPECT_FALSE(opened.reader->next().has_value());
  EXPECT_EQ(opened.reader->counters().frames, 1u);
  EXPECT_EQ(opened.reader->counters().truncated, 1u);
  std::remove(path.c_str());
}

TEST(CaptureReader, RejectsFilesThatAreNeitherPcapNorRaw) {
  const auto opened = open_capture(test::shared_data("README.md"));
  EXPECT_FALSE(opened.reader);
  EXPECT_NE(opened.error.find("neither a pcap/pcapng file nor raw 1206-byte"), std::string::npos) << opened.error;
}

}  // namespace
}  // namespace trailnav::capture
