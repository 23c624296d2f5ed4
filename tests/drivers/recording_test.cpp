#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "test_data.hpp"
#include "trailnav/drivers/recording/recording.hpp"

namespace trailnav::recording {
namespace {

namespace fs = std::filesystem;

fs::path temp_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("trailnav-test-" + name + "-" + std::to_string(getpid()));
  fs::remove_all(dir);
  return dir;
}

TEST(Recording, EveryLineOfTheRealCandumpLogRoundTrips) {
  std::ifstream in(test::shared_data("can/gpsd_nmea2000_garmin_boat_candump.log"));
  ASSERT_TRUE(in);
  std::string line, interface, error;
  int frames = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    CanFrame frame;
    ASSERT_TRUE(parse_candump_line(line, frame, interface, error)) << line << ": " << error;
    EXPECT_EQ(interface, "can0");
    EXPECT_NE(frame.id & kCanEffFlag, 0u) << "NMEA 2000 uses extended ids";
    EXPECT_EQ(format_candump_line(frame, interface), line);
    ++frames;
  }
  EXPECT_EQ(frames, 10495);
}

TEST(Recording, CandumpVariantsAndErrors) {
  CanFrame f;
  std::string interface, error;
  ASSERT_TRUE(parse_candump_line("(1436509052.249713) vcan0 1D0#0011223344556677", f, interface, error)) << error;
  EXPECT_EQ(f.id, 0x1D0u);
  EXPECT_EQ(f.length, 8);
  EXPECT_EQ(f.data[7], 0x77);
  EXPECT_EQ(f.time_ns, 1436509052249713000);
  ASSERT_TRUE(parse_candump_line("(1.5) can1 123#R", f, interface, error)) << error;
  EXPECT_EQ(f.id, 0x123u | kCanRtrFlag);
  EXPECT_EQ(f.time_ns, 1'500'000'000);
  ASSERT_TRUE(parse_candump_line("(2.000001) can0 12345678##1" + std::string(24, 'A'), f, interface, error)) << error;
  EXPECT_TRUE(f.fd);
  EXPECT_EQ(f.length, 12);
  EXPECT_EQ(f.id, 0x12345678u | kCanEffFlag);
  EXPECT_EQ(format_candump_line(f, interface), "(2.000001) can0 12345678##1" + std::string(24, 'A'));

  EXPECT_FALSE(parse_candump_line("1436509052.249713 can0 123#00", f, interface, error));
  EXPECT_FALSE(parse_candump_line("(1.0) can0 1234#00", f, interface, error));
  EXPECT_NE(error.find("3 (standard) or 8"), std::string::npos) << error;
  EXPECT_FALSE(parse_candump_line("(1.0) can0 800#00", f, interface, error));
  EXPECT_FALSE(parse_candump_line("(1.0) can0 123#001", f, interface, error));
  EXPECT_FALSE(parse_candump_line("(1.0) can0 123#001122334455667788", f, interface, error));
  EXPECT_NE(error.find("more than 8"), std::string::npos) << error;
  EXPECT_FALSE(parse_candump_line("(1.0) can0 123##1" + std::string(22, '0'), f, interface, error));
  EXPECT_FALSE(parse_candump_line("(1.0) can0", f, interface, error));
}

TEST(Recording, SerialLinesRoundTrip) {
  const std::vector<std::uint8_t> bytes = {'$', 'G', 'P', 0x00, 0xFF, '\r', '\n'};
  const std::string line = format_serial_line(1'700'000'000'123'456'000, bytes);
  EXPECT_EQ(line, "(1700000000.123456) 24475000FF0D0A");
  std::int64_t t = 0;
  std::vector<std::uint8_t> back;
  std::string error;
  ASSERT_TRUE(parse_serial_line(line, t, back, error)) << error;
  EXPECT_EQ(t, 1'700'000'000'123'456'000);
  EXPECT_EQ(back, bytes);
  EXPECT_FALSE(parse_serial_line("(1.0) ", t, back, error));
  EXPECT_FALSE(parse_serial_line("(1.0) 2G", t, back, error));
}

TEST(Recording, WrittenRecordingsReadBackInTimeOrder) {
  const fs::path dir = temp_dir("roundtrip");
  {
    auto created = RecordingWriter::create(dir.string(), "unit test");
    ASSERT_TRUE(created.writer) << created.error;
    RecordingWriter& w = *created.writer;
    const int lidar = w.add_udp_stream("lidar", 2368);
    const int wheels = w.add_can_stream("wheels", "can0");
    const int gps = w.add_serial_stream("gps", 9600);
    const std::vector<std::uint8_t> packet(1206, 0x5A);
    const std::vector<std::uint8_t> nmea = {'$', 'G', 'P', 'G', 'G', 'A'};
    for (int i = 0; i < 10; ++i) {
      const std::int64_t t = 1'000'000'000'000 + i * 1'000'000;
      ASSERT_TRUE(w.write_udp(lidar, t, packet));
      CanFrame f;
      f.time_ns = t + 300'000;
      f.id = 0x1D0;
      f.length = 2;
      f.data[0] = static_cast<std::uint8_t>(i);
      ASSERT_TRUE(w.write_can(wheels, f));
      ASSERT_TRUE(w.write_serial(gps, t + 600'000, nmea));
    }
    EXPECT_FALSE(w.write_can(lidar, CanFrame{}));
    ASSERT_TRUE(w.close());
  }
  auto opened = RecordingReader::open(dir.string());
  ASSERT_TRUE(opened.reader) << opened.error;
  RecordingReader& r = *opened.reader;
  ASSERT_EQ(r.streams().size(), 3u);
  EXPECT_EQ(r.streams()[2].baud, 9600);
  std::int64_t previous = 0;
  int counts[3] = {0, 0, 0};
  while (auto e = r.next()) {
    EXPECT_GE(e->time_ns, previous);
    previous = e->time_ns;
    ++counts[e->stream];
    if (e->kind == StreamKind::udp) {
      EXPECT_EQ(e->payload.size(), 1206u);
      EXPECT_EQ(e->payload[100], 0x5A);
    } else if (e->kind == StreamKind::can) {
      EXPECT_EQ(e->can->id, 0x1D0u);
      EXPECT_EQ(e->can->data[0], counts[1] - 1);
    } else {
      EXPECT_EQ(e->payload.size(), 6u);
    }
  }
  EXPECT_EQ(counts[0], 10);
  EXPECT_EQ(counts[1], 10);
  EXPECT_EQ(counts[2], 10);
  EXPECT_EQ(r.counters().bad_lines, 0u);
  fs::remove_all(dir);
}

TEST(Recording, ManifestErrorsNameFileLineAndKey) {
  const fs::path dir = temp_dir("manifest");
  fs::create_directories(dir);
  std::ofstream(dir / "udp.pcap") << "";
  std::ofstream(dir / kManifestName) << "format: trailnav-recording\nversion: 1\nstreams:\n"
                                        "  - name: lidar\n    kind: udp\n    file: udp.pcap\n    port: 99999\n";
  auto r = load_manifest((dir / kManifestName).string());
  EXPECT_FALSE(r.manifest);
  EXPECT_NE(r.error.find(":7"), std::string::npos) << r.error;
  EXPECT_NE(r.error.find("port"), std::string::npos) << r.error;

  std::ofstream(dir / kManifestName) << "format: trailnav-recording\nversion: 1\nstreams:\n"
                                        "  - name: gps\n    kind: serial\n    file: serial/missing.log\n";
  r = load_manifest((dir / kManifestName).string());
  EXPECT_NE(r.error.find("does not exist"), std::string::npos) << r.error;

  std::ofstream(dir / kManifestName) << "format: trailnav-recording\nversion: 1\nstreams:\n"
                                        "  - name: x\n    kind: radio\n    file: udp.pcap\n";
  r = load_manifest((dir / kManifestName).string());
  EXPECT_NE(r.error.find("radio"), std::string::npos) << r.error;
  EXPECT_FALSE(RecordingReader::open((dir / "nothing").string()).reader);
  fs::remove_all(dir);
}

TEST(Recording, BareCapturesBecomeStreamsByPort) {
  auto opened = RecordingReader::open(test::shared_data("velodyne/mrpt_sample_velodyne_vlp16_gps.pcap"));
  ASSERT_TRUE(opened.reader) << opened.error;
  ASSERT_EQ(opened.reader->streams().size(), 2u);
  EXPECT_EQ(opened.reader->streams()[0].name, "lidar");
  EXPECT_EQ(opened.reader->streams()[1].name, "lidar-position");
  int data = 0, position = 0;
  while (auto e = opened.reader->next()) (e->stream == 0 ? data : position)++;
  EXPECT_EQ(data, 293);
  EXPECT_EQ(position, 57);

  // A raw file has no capture times: they come from the packets' own clock.
  auto raw = RecordingReader::open(test::shared_data("velodyne/einride_vlp16_recording_raw1206.bin"));
  ASSERT_TRUE(raw.reader) << raw.error;
  std::int64_t first = -1, last = 0;
  int n = 0;
  while (auto e = raw.reader->next()) {
    if (first < 0) first = e->time_ns;
    EXPECT_GE(e->time_ns, last);
    last = e->time_ns;
    ++n;
  }
  EXPECT_EQ(n, 1000);
  EXPECT_NEAR(static_cast<double>(last - first) * 1e-9, 1000 * 1.327e-3, 0.01);
}

}  // namespace
}  // namespace trailnav::recording
