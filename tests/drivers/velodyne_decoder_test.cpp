#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <random>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "test_data.hpp"
#include "trailnav/drivers/capture/capture_reader.hpp"
#include "trailnav/drivers/velodyne/decoder.hpp"
#include "trailnav/drivers/velodyne/revolution_cut.hpp"
#include "trailnav/runtime/alloc_guard.hpp"

namespace trailnav::velodyne {
namespace {

using test::shared_data;

struct DecodedPoint {
  int revolution;
  Point point;
};

struct Decoded {
  std::vector<DecodedPoint> points;
  std::vector<int> firings_per_revolution;  // points + firings without return
  std::uint64_t packets = 0;
  std::uint64_t malformed = 0;
  std::vector<PositionPacket> positions;
  std::vector<std::string> nmea;
  std::vector<std::uint32_t> data_timestamps;
  std::vector<std::uint16_t> first_azimuths;
};

PacketDecoder make_decoder(Model model, const Calibration& calibration, DecoderOptions options = {}) {
  auto created = PacketDecoder::create(model, calibration, options);
  EXPECT_TRUE(created.decoder.has_value()) << created.error;
  return std::move(*created.decoder);
}

Decoded decode_file(const std::string& path, const PacketDecoder& decoder) {
  Decoded out;
  auto opened = capture::open_capture(path);
  EXPECT_TRUE(opened.reader) << opened.error;
  if (!opened.reader) return out;
  std::vector<Point> buffer(kMaxPointsPerPacket);
  RevolutionCut cut(0.0);
  int revolution = 0;
  out.firings_per_revolution.push_back(0);
  while (auto d = opened.reader->next()) {
    if (d->destination_port == 8308 || d->payload.size() == kPositionPacketSize) {
      PositionPacket pos;
      if (decode_position_packet(d->payload, pos) == PositionError::none) {
        out.positions.push_back(pos);
        out.nmea.emplace_back(pos.nmea);
      }
      continue;
    }
    ++out.packets;
    const PacketInfo info = decoder.decode(d->payload, buffer);
    if (info.error != PacketError::none) {
      ++out.malformed;
      continue;
    }
    out.data_timestamps.push_back(info.timestamp_us);
    out.first_azimuths.push_back(info.first_azimuth);
    out.firings_per_revolution.back() += info.zero_returns;
    const int first_new = cut.first_new_sequence(info);
    for (int pass = 0; pass < 2; ++pass) {
      if (pass == 1) {
        if (first_new == info.sequences) break;
        ++revolution;
        out.firings_per_revolution.push_back(0);
      }
      for (int i = 0; i < info.points; ++i) {
        const Point& p = buffer[static_cast<std::size_t>(i)];
        if ((p.sequence < first_new) != (pass == 0)) continue;
        ++out.firings_per_revolution.back();
        out.points.push_back({revolution, p});
      }
    }
  }
  return out;
}

void expect_rings_ordered_by_elevation(const PacketDecoder& decoder) {
  const auto& lasers = decoder.calibration().lasers;
  std::vector<double> elevation_of_ring(lasers.size());
  for (std::size_t id = 0; id < lasers.size(); ++id) elevation_of_ring[decoder.rings()[id]] = lasers[id].vert_correction;
  EXPECT_TRUE(std::is_sorted(elevation_of_ring.begin(), elevation_of_ring.end()));
}

// In the data, too: the mean elevation of each ring's points rises with the ring.
void expect_point_rings_ordered(const Decoded& d, int rings) {
  std::vector<double> sum(static_cast<std::size_t>(rings), 0.0);
  std::vector<int> count(static_cast<std::size_t>(rings), 0);
  for (const DecodedPoint& p : d.points) {
    if (p.point.distance < 1.0f) continue;
    sum[p.point.ring] += std::asin(static_cast<double>(p.point.z / p.point.distance));
    ++count[p.point.ring];
  }
  for (int r = 1; r < rings; ++r) {
    if (count[static_cast<std::size_t>(r)] == 0 || count[static_cast<std::size_t>(r - 1)] == 0) continue;
    EXPECT_GT(sum[static_cast<std::size_t>(r)] / count[static_cast<std::size_t>(r)],
              sum[static_cast<std::size_t>(r - 1)] / count[static_cast<std::size_t>(r - 1)])
        << "ring " << r;
  }
}

// Every complete revolution of a single-return capture holds the firings one
// turn takes at the capture's own azimuth advance per packet (384 firings per
// packet). Firings without a return are counted per packet, so a revolution
// may be off by part of a packet: well inside the 1 % allowed.
void expect_complete_revolutions_have_expected_firings(const Decoded& d) {
  ASSERT_GE(d.firings_per_revolution.size(), 3u) << "need at least one complete revolution";
  // Mean azimuth advance per packet, from consecutive packets.
  double advance = 0.0;
  int n = 0;
  for (std::size_t i = 1; i < d.first_azimuths.size(); ++i) {
    int diff = d.first_azimuths[i] - d.first_azimuths[i - 1];
    if (diff < 0) diff += 36000;
    if (diff > 0 && diff < 3000) {
      advance += diff;
      ++n;
    }
  }
  ASSERT_GT(n, 0);
  advance /= n;
  constexpr double kFiringsPerPacket = kBlocksPerPacket * kReturnsPerBlock;
  const double expected = 36000.0 / advance * kFiringsPerPacket;
  for (std::size_t r = 1; r + 1 < d.firings_per_revolution.size(); ++r) {
    EXPECT_NEAR(d.firings_per_revolution[r], expected, expected * 0.01) << "revolution " << r;
  }
}

TEST(VelodyneDecoder, MrptHdl32eDecodesCleanly) {
  const PacketDecoder decoder = make_decoder(Model::hdl32e, *builtin_calibration(Model::hdl32e));
  const Decoded d = decode_file(shared_data("velodyne/mrpt_sample_velodyne_hdl32.pcap"), decoder);
  EXPECT_EQ(d.packets, 500u);
  EXPECT_EQ(d.malformed, 0u);
  expect_rings_ordered_by_elevation(decoder);
  expect_point_rings_ordered(d, 32);
  expect_complete_revolutions_have_expected_firings(d);
  const float max_range = std::max_element(d.points.begin(), d.points.end(), [](const auto& a, const auto& b) {
                            return a.point.distance < b.point.distance;
                          })->point.distance;
  EXPECT_GT(max_range, 60.0f);  // the README: ranges to 81 m
  EXPECT_LT(max_range, 130.0f);
}

TEST(VelodyneDecoder, MrptVlp16DecodesAndItsPositionPacketsCarryGprmc) {
  const PacketDecoder decoder = make_decoder(Model::vlp16, *builtin_calibration(Model::vlp16));
  const Decoded d = decode_file(shared_data("velodyne/mrpt_sample_velodyne_vlp16_gps.pcap"), decoder);
  EXPECT_EQ(d.packets, 293u);
  EXPECT_EQ(d.malformed, 0u);
  expect_rings_ordered_by_elevation(decoder);
  expect_complete_revolutions_have_expected_firings(d);
  ASSERT_EQ(d.positions.size(), 57u);
  EXPECT_EQ(d.nmea.front(), "$GPRMC,081802.00,A,3649.7478558,N,00224.4542928,W,0.034,212.5,210116,0.0,E,A*2E");
  EXPECT_EQ(d.positions.front().pps, PpsStatus::locked);
  // The position packets' clock is the data packets' clock.
  EXPECT_NEAR(static_cast<double>(d.positions.front().timestamp_us), static_cast<double>(d.data_timestamps.front()), 1e6);
}

TEST(VelodyneDecoder, EinrideRawRecordingDecodesCleanly) {
  const PacketDecoder decoder = make_decoder(Model::vlp16, *builtin_calibration(Model::vlp16));
  const Decoded d = decode_file(shared_data("velodyne/einride_vlp16_recording_raw1206.bin"), decoder);
  EXPECT_EQ(d.packets, 1000u);
  EXPECT_EQ(d.malformed, 0u);
  EXPECT_GE(d.firings_per_revolution.size(), 13u);  // ~13 revolutions
  expect_complete_revolutions_have_expected_firings(d);
}

TEST(VelodyneDecoder, RustLidarUtilsCaptureDecodesCleanly) {
  const PacketDecoder decoder = make_decoder(Model::vlp16, *builtin_calibration(Model::vlp16));
  const Decoded d = decode_file(shared_data("velodyne/rust-lidar-utils_velodyne_example_vlp16.pcap"), decoder);
  EXPECT_EQ(d.packets, 84u);
  EXPECT_EQ(d.malformed, 0u);
}

// --- the tier4/nebula reference cloud ---

struct ReferencePoint {
  float x, y, z;
  std::uint8_t intensity, return_type;
  std::uint16_t channel;
  float azimuth, elevation, distance;
  std::uint32_t time;
};

std::vector<ReferencePoint> load_nebula_pcd(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string marker = "DATA binary\n";
  const auto at = text.find(marker);
  EXPECT_NE(at, std::string::npos);
  EXPECT_NE(text.find("FIELDS x y z intensity return_type channel azimuth elevation distance time_stamp"), std::string::npos);
  std::vector<ReferencePoint> out;
  for (std::size_t o = at + marker.size(); o + 32 <= text.size(); o += 32) {
    ReferencePoint p{};
    const char* r = text.data() + o;
    std::memcpy(&p.x, r, 4);
    std::memcpy(&p.y, r + 4, 4);
    std::memcpy(&p.z, r + 8, 4);
    p.intensity = static_cast<std::uint8_t>(r[12]);
    p.return_type = static_cast<std::uint8_t>(r[13]);
    std::memcpy(&p.channel, r + 14, 2);
    std::memcpy(&p.azimuth, r + 16, 4);
    std::memcpy(&p.elevation, r + 20, 4);
    std::memcpy(&p.distance, r + 24, 4);
    std::memcpy(&p.time, r + 28, 4);
    out.push_back(p);
  }
  return out;
}

// Conventions matched: nebula's x/y/z frame is ROS velodyne_pointcloud's (x
// forward, y left), its `channel` is our ring, and it does not interpolate
// the azimuth of a packet's last firing group (LastGroupAzimuth::hold).
// One more convention of nebula's VLP-16 decoder has to be applied to our
// points for the comparison: in a dual-return packet it carries the azimuth
// of the *next* block over to the second block of each pair, so every return
// it takes from a pair's second block (our dual_strongest points) sits at the
// start azimuth of the next firing group, rounded to 0.01 degree and not
// interpolated (the last group keeps its own). Our decoder keeps each
// firing's true azimuth; the test moves those points to nebula's azimuth.
struct NebulaFrame {
  std::vector<Point> points;
  std::size_t moved = 0;
};

NebulaFrame decode_in_nebula_convention(const std::string& path, const PacketDecoder& decoder) {
  NebulaFrame out;
  auto opened = capture::open_capture(path);
  EXPECT_TRUE(opened.reader) << opened.error;
  std::vector<Point> buffer(kMaxPointsPerPacket);
  while (auto d = opened.reader->next()) {
    const PacketInfo info = decoder.decode(d->payload, buffer);
    if (info.error != PacketError::none) continue;
    const int sequences_per_group = 2;  // VLP-16: two firing sequences per block
    const int groups = info.sequences / sequences_per_group;
    for (int i = 0; i < info.points; ++i) {
      Point p = buffer[static_cast<std::size_t>(i)];
      if (p.kind == ReturnKind::dual_strongest) {
        const int group = p.sequence / sequences_per_group;
        const int next = group + 1 < groups ? group + 1 : group;
        const float start = info.sequence_azimuth[static_cast<std::size_t>(next * sequences_per_group)];
        const double a = std::fmod(std::round(static_cast<double>(start)), 36000.0) * std::numbers::pi / 18000.0;
        const double r = std::hypot(static_cast<double>(p.x), static_cast<double>(p.y));
        p.x = static_cast<float>(r * std::cos(a));
        p.y = static_cast<float>(-r * std::sin(a));
        p.azimuth = static_cast<float>(a);
        ++out.moved;
      }
      out.points.push_back(p);
    }
  }
  return out;
}

TEST(VelodyneDecoder, Vlp16DualReturnsReproduceTheNebulaReferenceCloud) {
  DecoderOptions options;
  options.last_group = LastGroupAzimuth::hold;
  const PacketDecoder decoder = make_decoder(Model::vlp16, *builtin_calibration(Model::vlp16), options);
  const Decoded d = decode_file(shared_data("velodyne/nebula-vlp16/vlp16_dual_rewrapped.pcap"), decoder);
  ASSERT_EQ(d.packets, 603u);
  ASSERT_EQ(d.malformed, 0u);
  const std::vector<ReferencePoint> reference = load_nebula_pcd(shared_data("velodyne/nebula-vlp16/1673400472138016708.pcd"));
  ASSERT_EQ(reference.size(), 14831u);
  const NebulaFrame ours = decode_in_nebula_convention(shared_data("velodyne/nebula-vlp16/vlp16_dual_rewrapped.pcap"), decoder);
  EXPECT_GT(ours.moved, 0u);

  // Our points by ring and 0.1-degree azimuth bucket.
  std::map<std::pair<int, int>, std::vector<const Point*>> index;
  auto bucket = [](float azimuth_rad) { return static_cast<int>(std::floor(azimuth_rad * 1800.0f / std::numbers::pi_v<float>)); };
  for (const Point& p : ours.points) index[{p.ring, bucket(p.azimuth)}].push_back(&p);

  constexpr std::uint8_t kNebulaIdentical = 6;  // both returns the same
  double max_error = 0.0;
  double sum_error = 0.0;
  double max_distinct_error = 0.0;
  int unmatched = 0;
  int distinct = 0;
  for (const ReferencePoint& r : reference) {
    double best = 1e9;
    const int b = bucket(r.azimuth);
    for (int nb = b - 2; nb <= b + 2; ++nb) {
      const auto it = index.find({r.channel, (nb + 3600) % 3600});
      if (it == index.end()) continue;
      for (const Point* q : it->second) {
        if (std::abs(q->distance - r.distance) > 0.0015f) continue;
        best = std::min(best, static_cast<double>(std::hypot(q->x - r.x, q->y - r.y, q->z - r.z)));
      }
    }
    if (best > 0.01) ++unmatched;
    if (r.return_type != kNebulaIdentical) {
      ++distinct;
      max_distinct_error = std::max(max_distinct_error, best);
    }
    max_error = std::max(max_error, best);
    sum_error += best;
  }
  const double mean_error = sum_error / static_cast<double>(reference.size());
  EXPECT_EQ(unmatched, 0) << "reference points without a decoded point within 1 cm";
  EXPECT_LE(max_error, 0.01);
  RecordProperty("max_error_m", std::to_string(max_error));
  RecordProperty("mean_error_m", std::to_string(mean_error));
  std::printf("nebula reference: %zu points (%d with distinct returns), all matched: max difference %.4f m, "
              "mean %.5f m (distinct returns: max %.4f m); %zu of our points moved to nebula's azimuth\n",
              reference.size(), distinct, max_error, mean_error, max_distinct_error, ours.moved);
}

TEST(VelodyneDecoder, DualReturnsAreMarkedAndIdenticalPairsKeptOnce) {
  const PacketDecoder all = make_decoder(Model::vlp16, *builtin_calibration(Model::vlp16));
  DecoderOptions strongest_only;
  strongest_only.selection = ReturnSelection::strongest;
  const PacketDecoder strongest = make_decoder(Model::vlp16, *builtin_calibration(Model::vlp16), strongest_only);
  const std::string path = shared_data("velodyne/nebula-vlp16/vlp16_dual_rewrapped.pcap");
  const Decoded d_all = decode_file(path, all);
  const Decoded d_strong = decode_file(path, strongest);
  std::map<ReturnKind, int> kinds;
  for (const DecodedPoint& p : d_all.points) ++kinds[p.point.kind];
  EXPECT_GT(kinds[ReturnKind::dual_both], 0);
  EXPECT_GT(kinds[ReturnKind::dual_last], 0);
  EXPECT_GT(kinds[ReturnKind::dual_strongest], 0);
  EXPECT_EQ(kinds[ReturnKind::strongest], 0);
  // Strongest only: one point per firing with a return.
  for (const DecodedPoint& p : d_strong.points) ASSERT_EQ(p.point.kind, ReturnKind::dual_strongest);
  // Identical pairs appear once in both; distinct last returns only in "all".
  EXPECT_EQ(d_all.points.size(), d_strong.points.size() + static_cast<std::size_t>(kinds[ReturnKind::dual_last]));
}

// --- bad bytes ---

std::vector<std::uint8_t> first_data_packet(const std::string& path) {
  auto opened = capture::open_capture(path);
  while (auto d = opened.reader->next()) {
    if (d->payload.size() == kDataPacketSize) return {d->payload.begin(), d->payload.end()};
  }
  return {};
}

TEST(VelodyneDecoder, BadPacketsAreRejectedWithTheirReason) {
  const PacketDecoder decoder = make_decoder(Model::vlp16, *builtin_calibration(Model::vlp16));
  std::vector<Point> out(kMaxPointsPerPacket);
  std::vector<std::uint8_t> good = first_data_packet(shared_data("velodyne/mrpt_sample_velodyne_vlp16_gps.pcap"));
  ASSERT_EQ(good.size(), kDataPacketSize);
  EXPECT_EQ(decoder.decode(good, out).error, PacketError::none);

  EXPECT_EQ(decoder.decode(std::span(good).first(1205), out).error, PacketError::wrong_size);
  std::vector<std::uint8_t> longer = good;
  longer.push_back(0);
  EXPECT_EQ(decoder.decode(longer, out).error, PacketError::wrong_size);

  std::vector<std::uint8_t> bad = good;
  bad[500] = 0xFF;  // block 5's flag
  bad[501] = 0xDD;  // a lower-block flag, legal only on an HDL-64E
  EXPECT_EQ(decoder.decode(bad, out).error, PacketError::bad_block_flag);

  bad = good;
  bad[302] = 0x40;  // block 3's azimuth = 0x9C40 = 40000
  bad[303] = 0x9C;
  EXPECT_EQ(decoder.decode(bad, out).error, PacketError::bad_azimuth);

  bad = good;
  bad[kReturnModeOffset] = 0x12;
  EXPECT_EQ(decoder.decode(bad, out).error, PacketError::unknown_return_mode);

  const std::vector<std::uint8_t> hdl32 = first_data_packet(shared_data("velodyne/mrpt_sample_velodyne_hdl32.pcap"));
  EXPECT_EQ(decoder.decode(hdl32, out).error, PacketError::model_mismatch);
  EXPECT_EQ(detect_model(hdl32), Model::hdl32e);
  EXPECT_EQ(detect_model(good), Model::vlp16);
}

TEST(VelodyneDecoder, RandomBytesNeverCrashOrProduceNonFinitePoints) {
  const PacketDecoder decoder = make_decoder(Model::vlp16, *builtin_calibration(Model::vlp16));
  std::vector<Point> out(kMaxPointsPerPacket);
  std::mt19937 rng(11);
  std::vector<std::uint8_t> good = first_data_packet(shared_data("velodyne/mrpt_sample_velodyne_vlp16_gps.pcap"));
  int accepted = 0;
  for (int i = 0; i < 20000; ++i) {
    std::vector<std::uint8_t> packet = good;
    if (i % 2 == 0) {
      for (auto& b : packet) b = static_cast<std::uint8_t>(rng());  // pure noise
    } else {
      for (int k = 0; k < 8; ++k) packet[rng() % packet.size()] = static_cast<std::uint8_t>(rng());  // mutations
    }
    const PacketInfo info = decoder.decode(packet, out);
    ASSERT_LE(info.points, kMaxPointsPerPacket);
    if (info.error != PacketError::none) continue;
    ++accepted;
    for (int k = 0; k < info.points; ++k) {
      const Point& p = out[static_cast<std::size_t>(k)];
      ASSERT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
      ASSERT_LT(p.ring, 16);
    }
  }
  EXPECT_GT(accepted, 0);  // mutated packets with intact structure still decode
}

// DecodeKernel::blocks (the default: a block's returns four at a time) and
// DecodeKernel::per_point must give the same bits for every point: every
// real capture, and random packets of every model with valid block flags,
// the HDL-64E under both real calibrations (two-point and intensity
// corrections on some lasers, not others).
void expect_same_bits(const PacketDecoder& decoder, std::span<const std::uint8_t> packet, int& points) {
  std::vector<Point> a(kMaxPointsPerPacket), b(kMaxPointsPerPacket);
  const PacketInfo blocks = decoder.decode(packet, a, DecodeKernel::blocks);
  const PacketInfo one_by_one = decoder.decode(packet, b, DecodeKernel::per_point);
  ASSERT_EQ(blocks.error, one_by_one.error);
  ASSERT_EQ(blocks.points, one_by_one.points);
  const auto bits = [](float f) { return std::bit_cast<std::uint32_t>(f); };
  for (int i = 0; i < blocks.points; ++i) {
    const Point& p = a[static_cast<std::size_t>(i)];
    const Point& q = b[static_cast<std::size_t>(i)];
    ASSERT_TRUE(bits(p.x) == bits(q.x) && bits(p.y) == bits(q.y) && bits(p.z) == bits(q.z) &&
                bits(p.distance) == bits(q.distance) && bits(p.azimuth) == bits(q.azimuth) &&
                bits(p.intensity) == bits(q.intensity) && bits(p.time) == bits(q.time) && p.ring == q.ring &&
                p.laser == q.laser && p.kind == q.kind && p.sequence == q.sequence)
        << "point " << i << " of laser " << int(p.laser) << ": " << p.x << " " << p.y << " " << p.z << " " << p.intensity
        << " against " << q.x << " " << q.y << " " << q.z << " " << q.intensity;
  }
  points += blocks.points;
}

TEST(VelodyneDecoder, BothKernelsGiveTheSameBitsForEveryPoint) {
  struct Capture {
    std::string file;
    Model model;
    DecoderOptions options;
  };
  DecoderOptions all_returns;
  all_returns.selection = ReturnSelection::all;
  const Capture captures[] = {
      {"velodyne/mrpt_sample_velodyne_hdl32.pcap", Model::hdl32e, {}},
      {"velodyne/mrpt_sample_velodyne_vlp16_gps.pcap", Model::vlp16, {}},
      {"velodyne/einride_vlp16_recording_raw1206.bin", Model::vlp16, {}},
      {"velodyne/rust-lidar-utils_velodyne_example_vlp16.pcap", Model::vlp16, {}},
      {"velodyne/nebula-vlp16/vlp16_dual_rewrapped.pcap", Model::vlp16, all_returns},
  };
  for (const Capture& c : captures) {
    SCOPED_TRACE(c.file);
    const PacketDecoder decoder = make_decoder(c.model, *builtin_calibration(c.model), c.options);
    auto opened = capture::open_capture(shared_data(c.file));
    ASSERT_TRUE(opened.reader) << opened.error;
    int points = 0;
    while (auto d = opened.reader->next()) {
      if (d->payload.size() == kDataPacketSize) expect_same_bits(decoder, d->payload, points);
    }
    EXPECT_GT(points, 10'000);
  }
  // Random packets, valid structure.
  std::mt19937 rng(5);
  const auto random_packet = [&](bool hdl64e) {
    std::vector<std::uint8_t> packet(kDataPacketSize);
    for (auto& byte : packet) byte = static_cast<std::uint8_t>(rng());
    for (int b = 0; b < kBlocksPerPacket; ++b) {
      std::uint8_t* block = packet.data() + static_cast<std::size_t>(b) * kBlockSize;
      block[0] = 0xFF;
      block[1] = hdl64e && b % 2 == 1 ? 0xDD : 0xEE;
      const auto azimuth = static_cast<std::uint16_t>(rng() % 36000);
      block[2] = static_cast<std::uint8_t>(azimuth & 0xFF);
      block[3] = static_cast<std::uint8_t>(azimuth >> 8);
    }
    return packet;
  };
  struct Sensor {
    Model model;
    std::string calibration;  // empty: built in
    std::uint8_t return_mode, product;
  };
  const Sensor sensors[] = {{Model::vlp16, "", 0x37, 0x22},
                            {Model::vlp32c, "", 0x38, 0x28},
                            {Model::hdl32e, "", 0x37, 0x21},
                            {Model::hdl64e, "velodyne/calibration/ros_velodyne_64e_s2.1-sztaki.yaml", 0, 0},
                            {Model::hdl64e, "velodyne/calibration/ros_velodyne_64e_utexas.yaml", 0, 0}};
  for (const Sensor& sensor : sensors) {
    SCOPED_TRACE(std::string(model_info(sensor.model).name) + " " + sensor.calibration);
    const Calibration calibration = sensor.calibration.empty()
                                        ? *builtin_calibration(sensor.model)
                                        : *load_calibration(shared_data(sensor.calibration)).calibration;
    const PacketDecoder decoder = make_decoder(sensor.model, calibration);
    int points = 0;
    for (int i = 0; i < 500; ++i) {
      std::vector<std::uint8_t> packet = random_packet(sensor.model == Model::hdl64e);
      if (sensor.model != Model::hdl64e) {
        packet[kReturnModeOffset] = sensor.return_mode;
        packet[kProductIdOffset] = sensor.product;
      }
      expect_same_bits(decoder, packet, points);
    }
    EXPECT_GT(points, 100'000);
  }
}

TEST(VelodyneDecoder, DecodingDoesNotTouchTheHeap) {
  const PacketDecoder decoder = make_decoder(Model::vlp16, *builtin_calibration(Model::vlp16));
  std::vector<Point> out(kMaxPointsPerPacket);
  const std::vector<std::uint8_t> packet = first_data_packet(shared_data("velodyne/mrpt_sample_velodyne_vlp16_gps.pcap"));
  ASSERT_TRUE(alloc_guard::hook_installed());
  alloc_guard::reset_counters();
  std::thread rt([&] {
    alloc_guard::mark_realtime_thread("velodyne-decode");
    alloc_guard::arm();
    for (int i = 0; i < 1000; ++i) {
      const PacketInfo info = decoder.decode(packet, out);
      if (info.error != PacketError::none) break;
    }
    alloc_guard::disarm();
    alloc_guard::unmark_current_thread();
  });
  rt.join();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
}

}  // namespace
}  // namespace trailnav::velodyne
