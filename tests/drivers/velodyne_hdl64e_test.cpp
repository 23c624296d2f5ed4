// No HDL-64E packet capture is public: these tests encode packets from real
// HDL-64E calibrations and check that they decode back to the points a
// double-precision evaluation of the calibration model gives, upper and
// lower laser blocks included.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "test_data.hpp"
#include "trailnav/drivers/velodyne/decoder.hpp"

namespace trailnav::velodyne {
namespace {

struct Expected {
  double x, y, z, intensity;
  int laser;
};

// The calibration model in double precision: distance correction, two-point
// correction, vertical and horizontal offsets, then the ROS frame (x forward,
// y left); intensity with the focal correction (focal distance in cm).
Expected model_point(const LaserCorrection& c, double azimuth_hundredths, std::uint16_t raw, std::uint8_t raw_intensity) {
  const double a = azimuth_hundredths * std::numbers::pi / 18000.0 - c.rot_correction;
  const double sa = std::sin(a);
  const double ca = std::cos(a);
  const double cv = std::cos(c.vert_correction);
  const double sv = std::sin(c.vert_correction);
  const double d = raw * 0.002 + c.dist_correction;
  double dx = d;
  double dy = d;
  if (c.two_pt_correction) {
    const double xy = d * cv - c.vert_offset_correction * sv;
    const double xx = std::abs(xy * sa - c.horiz_offset_correction * ca);
    const double yy = std::abs(xy * ca + c.horiz_offset_correction * sa);
    dx = d + (c.dist_correction - c.dist_correction_x) * (xx - 2.4) / (25.04 - 2.4) + c.dist_correction_x - c.dist_correction;
    dy = d + (c.dist_correction - c.dist_correction_y) * (yy - 1.93) / (25.04 - 1.93) + c.dist_correction_y - c.dist_correction;
  }
  const double xy_x = dx * cv - c.vert_offset_correction * sv;
  const double xy_y = dy * cv - c.vert_offset_correction * sv;
  Expected e{};
  e.x = xy_y * ca + c.horiz_offset_correction * sa;
  e.y = -(xy_x * sa - c.horiz_offset_correction * ca);
  e.z = dy * sv + c.vert_offset_correction * cv;
  const double focal = 256.0 * std::pow(1.0 - c.focal_distance * 100.0 / 13100.0, 2);
  double intensity = raw_intensity + c.focal_slope * std::abs(focal - 256.0 * std::pow(1.0 - raw / 65535.0, 2));
  e.intensity = std::clamp(intensity, static_cast<double>(c.min_intensity), static_cast<double>(c.max_intensity));
  return e;
}

void put16(std::vector<std::uint8_t>& p, std::size_t at, std::uint16_t v) {
  p[at] = static_cast<std::uint8_t>(v & 0xFF);
  p[at + 1] = static_cast<std::uint8_t>(v >> 8);
}

void round_trip(const std::string& calibration_file) {
  CalibrationResult loaded = load_calibration(test::shared_data("velodyne/calibration/" + calibration_file));
  ASSERT_TRUE(loaded.calibration) << loaded.error;
  const Calibration& cal = *loaded.calibration;
  auto created = PacketDecoder::create(Model::hdl64e, cal);
  ASSERT_TRUE(created.decoder) << created.error;
  const PacketDecoder& decoder = *created.decoder;

  constexpr int kGap = 17;  // azimuth advance per upper/lower pair, hundredths of a degree
  std::vector<Point> out(kMaxPointsPerPacket);
  double max_error = 0.0;
  int checked = 0;
  for (int start : {0, 9000, 35950}) {  // includes a packet across the 0/360 wrap
    std::vector<std::uint8_t> packet(kDataPacketSize, 0);
    std::vector<Expected> expected;
    for (int block = 0; block < 12; ++block) {
      const int pair = block / 2;
      const bool lower = block % 2 == 1;
      const std::size_t base = static_cast<std::size_t>(block) * 100;
      put16(packet, base, lower ? kLowerBlockFlag : kUpperBlockFlag);
      const int azimuth = (start + pair * kGap) % 36000;
      put16(packet, base + 2, static_cast<std::uint16_t>(azimuth));
      for (int k = 0; k < 32; ++k) {
        const auto raw = static_cast<std::uint16_t>(800 + 97 * k + 1300 * pair + (lower ? 20000 : 0));  // 1.6 m .. 64 m
        const auto intensity = static_cast<std::uint8_t>((k * 7 + block * 13) % 256);
        put16(packet, base + 4 + static_cast<std::size_t>(k) * 3, raw);
        packet[base + 6 + static_cast<std::size_t>(k) * 3] = intensity;
        const int laser = (lower ? 32 : 0) + k;
        // Firing k of a pair comes 1.5 us after firing k-1; a pair spans 48 us.
        const double firing_azimuth = azimuth + kGap * (k * 1.5 / 48.0);
        expected.push_back(model_point(cal.lasers[static_cast<std::size_t>(laser)], firing_azimuth, raw, intensity));
        expected.back().laser = laser;
      }
    }
    put16(packet, kTimestampOffset, 0x1234);
    const PacketInfo info = decoder.decode(packet, out);
    ASSERT_EQ(info.error, PacketError::none);
    ASSERT_EQ(info.points, 384);
    for (int i = 0; i < info.points; ++i) {
      const Point& p = out[static_cast<std::size_t>(i)];
      const Expected& e = expected[static_cast<std::size_t>(i)];
      ASSERT_EQ(p.laser, e.laser);
      const double error =
          std::hypot(static_cast<double>(p.x) - e.x, static_cast<double>(p.y) - e.y, static_cast<double>(p.z) - e.z);
      max_error = std::max(max_error, error);
      EXPECT_LT(error, 0.002) << "laser " << e.laser << " at start azimuth " << start;
      EXPECT_NEAR(p.intensity, e.intensity, 0.01) << "laser " << e.laser;
      ++checked;
    }
  }
  EXPECT_EQ(checked, 3 * 384);
  std::printf("%s: %d points, max difference %.6f m\n", calibration_file.c_str(), checked, max_error);
}

TEST(VelodyneHdl64e, PacketsEncodedFromTheSztakiCalibrationDecodeBack) { round_trip("ros_velodyne_64e_s2.1-sztaki.yaml"); }
TEST(VelodyneHdl64e, PacketsEncodedFromTheUtexasCalibrationDecodeBack) { round_trip("ros_velodyne_64e_utexas.yaml"); }

TEST(VelodyneHdl64e, LowerBlocksAreTheLasers32To63AndRingsFollowElevation) {
  CalibrationResult loaded = load_calibration(test::shared_data("velodyne/calibration/ros_velodyne_64e_s2.1-sztaki.yaml"));
  ASSERT_TRUE(loaded.calibration);
  auto created = PacketDecoder::create(Model::hdl64e, *loaded.calibration);
  ASSERT_TRUE(created.decoder);
  std::vector<std::uint8_t> packet(kDataPacketSize, 0);
  for (int block = 0; block < 12; ++block) {
    put16(packet, static_cast<std::size_t>(block) * 100, block % 2 ? kLowerBlockFlag : kUpperBlockFlag);
    put16(packet, static_cast<std::size_t>(block) * 100 + 4, 5000);  // only return slot 0 fires
  }
  EXPECT_EQ(detect_model(packet), Model::hdl64e);
  std::vector<Point> out(kMaxPointsPerPacket);
  const PacketInfo info = created.decoder->decode(packet, out);
  ASSERT_EQ(info.points, 12);
  for (int i = 0; i < 12; ++i) EXPECT_EQ(out[static_cast<std::size_t>(i)].laser, i % 2 ? 32 : 0);
  EXPECT_LT(out[1].ring, out[0].ring);  // laser 32 (lower block) points lower than laser 0
  EXPECT_EQ(info.zero_returns, 12 * 31);
}

TEST(VelodyneHdl64e, DualModeIsRefusedWithAClearError) {
  CalibrationResult loaded = load_calibration(test::shared_data("velodyne/calibration/ros_velodyne_64e_utexas.yaml"));
  ASSERT_TRUE(loaded.calibration);
  DecoderOptions options;
  options.hdl64e_mode = ReturnMode::dual;
  auto created = PacketDecoder::create(Model::hdl64e, *loaded.calibration, options);
  EXPECT_FALSE(created.decoder);
  EXPECT_NE(created.error.find("dual-return mode is not supported for the HDL-64E"), std::string::npos);
}

}  // namespace
}  // namespace trailnav::velodyne
