#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <numbers>
#include <thread>
#include <vector>

#include "collecting_sink.hpp"
#include "test_data.hpp"
#include "trailnav/drivers/capture/capture_reader.hpp"
#include "trailnav/drivers/velodyne/range_image.hpp"
#include "trailnav/drivers/velodyne/revolution_cut.hpp"
#include "trailnav/drivers/velodyne/sensor_clock.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "vlp16_packets.hpp"

namespace trailnav::velodyne {
namespace {

using test::shared_data;

using test::CollectingSink;

struct Packet {
  std::vector<std::uint8_t> bytes;
  std::int64_t host_ns;
};

std::vector<Packet> data_packets(const std::string& path) {
  std::vector<Packet> out;
  auto opened = capture::open_capture(path);
  EXPECT_TRUE(opened.reader) << opened.error;
  if (!opened.reader) return out;
  while (auto d = opened.reader->next()) {
    if (d->payload.size() != kDataPacketSize) continue;
    out.push_back({{d->payload.begin(), d->payload.end()}, d->time_ns});
  }
  return out;
}

PacketDecoder decoder_for(Model model, const std::string& calibration_file = "", DecoderOptions options = {}) {
  Calibration cal;
  if (calibration_file.empty()) {
    cal = *builtin_calibration(model);
  } else {
    auto loaded = load_calibration(shared_data("velodyne/calibration/" + calibration_file));
    EXPECT_TRUE(loaded.calibration) << loaded.error;
    cal = *loaded.calibration;
  }
  auto created = PacketDecoder::create(model, cal, options);
  EXPECT_TRUE(created.decoder) << created.error;
  return std::move(*created.decoder);
}

RevolutionAssembler assembler_for(const PacketDecoder& decoder, AssemblerOptions options = {}) {
  auto created = RevolutionAssembler::create(decoder, options);
  EXPECT_TRUE(created.assembler) << created.error;
  return std::move(*created.assembler);
}

std::vector<RangeImage> assemble(const PacketDecoder& decoder, const std::vector<Packet>& packets,
                                 AssemblerOptions options = {}, AssemblerCounters* counters = nullptr) {
  RevolutionAssembler assembler = assembler_for(decoder, options);
  CollectingSink sink(assembler.shape());
  SensorClock clock;
  for (const Packet& p : packets) {
    const std::uint32_t ts = read_u32(p.bytes.data() + kTimestampOffset);
    // Raw files have no capture time: take the packet clock as the host's.
    const std::int64_t host_ns = p.host_ns != 0 ? p.host_ns : static_cast<std::int64_t>(ts) * 1000;
    assembler.add_packet(p.bytes, clock.resolve(ts, host_ns), sink);
  }
  if (counters != nullptr) *counters = assembler.counters();
  return std::move(sink.images);
}

// Points per revolution, straight from the decoder and the cut, for comparison.
std::vector<int> points_per_revolution(const PacketDecoder& decoder, const std::vector<Packet>& packets) {
  std::vector<Point> buffer(kMaxPointsPerPacket);
  RevolutionCut cut(0.0);
  std::vector<int> counts{0};
  for (const Packet& p : packets) {
    const PacketInfo info = decoder.decode(p.bytes, buffer);
    const int first_new = cut.first_new_sequence(info);
    const bool crosses = first_new < info.sequences;
    if (crosses) counts.push_back(0);
    for (int i = 0; i < info.points; ++i) {
      const bool before_cut = buffer[static_cast<std::size_t>(i)].sequence < first_new;
      ++counts[counts.size() - (crosses && before_cut ? 2 : 1)];
    }
  }
  return counts;
}

void expect_clean_revolutions(const PacketDecoder& decoder, const std::vector<Packet>& packets, int expected_revolutions) {
  AssemblerCounters counters;
  const auto images = assemble(decoder, packets, {}, &counters);
  ASSERT_EQ(static_cast<int>(images.size()), expected_revolutions);
  EXPECT_EQ(counters.malformed, 0u);
  EXPECT_EQ(counters.lost_packets, 0u);
  EXPECT_EQ(counters.out_of_order, 0u);
  EXPECT_EQ(counters.partial_revolutions, 1u);
  const std::vector<int> reference = points_per_revolution(decoder, packets);
  for (std::size_t i = 0; i < images.size(); ++i) {
    const RangeImage& image = images[i];
    SCOPED_TRACE("revolution " + std::to_string(i + 1));
    EXPECT_EQ(image.sequence, i + 1);
    EXPECT_EQ(image.missing_columns, 0);
    EXPECT_EQ(image.lost_packets, 0u);
    // One column per firing at the measured rate.
    const double firings = decoder.model().sequences_per_block * 1e6 / decoder.model().group_period_us * 60.0 / image.rpm;
    EXPECT_NEAR(image.columns(), firings, firings * 0.06);
    // Same points as the point-wise cut, less the few firings that found their column taken.
    // Every point is in its image, less the firings whose column was taken.
    EXPECT_NEAR(image.points, reference[i + 1], static_cast<int>(image.collisions + 1) * decoder.model().lasers);
    EXPECT_LT(image.collisions, static_cast<std::uint32_t>(image.columns() / 100 + 2));
    // Time runs with the columns, within one revolution.
    EXPECT_GT(image.end_ns, image.start_ns);
    EXPECT_LT(image.end_ns - image.start_ns, static_cast<std::int64_t>(60e9 / image.rpm * 1.01));
  }
}

TEST(RangeImage, RealCapturesAssembleIntoCompleteRevolutions) {
  {
    SCOPED_TRACE("MRPT HDL-32E");
    const PacketDecoder d = decoder_for(Model::hdl32e, "ros_velodyne_32db.yaml");
    expect_clean_revolutions(d, data_packets(shared_data("velodyne/mrpt_sample_velodyne_hdl32.pcap")), 2);
  }
  {
    SCOPED_TRACE("einride VLP-16 raw");
    const PacketDecoder d = decoder_for(Model::vlp16);
    expect_clean_revolutions(d, data_packets(shared_data("velodyne/einride_vlp16_recording_raw1206.bin")), 12);
  }
  {
    SCOPED_TRACE("MRPT VLP-16");
    const PacketDecoder d = decoder_for(Model::vlp16);
    expect_clean_revolutions(d, data_packets(shared_data("velodyne/mrpt_sample_velodyne_vlp16_gps.pcap")), 3);
  }
}

// The assembler clears each column of the image it fills right before its
// first points land there, and the columns no firing reached at the
// revolution's end, not the whole image at its start: whatever a slot held
// before (a reader's old revolution), the revolution that leaves it is the
// same, cell for cell. Real captures, one and two layers, with packets lost.
class JunkSink final : public RevolutionSink {
 public:
  explicit JunkSink(RangeImageShape shape) : work_(shape) {}
  RangeImage& next_image() noexcept override {
    // A full image of a wrong revolution in every cell of the capacity.
    work_.begin(work_.shape().max_columns);
    RangeCell junk;
    junk.x = junk.y = junk.z = 9.0f;
    junk.distance = 7.0f;
    junk.azimuth = 1.0f;
    junk.time = 0.5f;
    junk.intensity = 99.0f;
    junk.kind = ReturnKind::dual_last;
    for (int layer = 0; layer < work_.layers(); ++layer) {
      for (int ring = 0; ring < work_.rings(); ++ring) {
        for (int c = 0; c < work_.shape().max_columns; ++c) work_.at(layer, ring, c) = junk;
      }
    }
    return work_;
  }
  void complete(RangeImage& image) noexcept override { images.push_back(image); }
  std::vector<RangeImage> images;

 private:
  RangeImage work_;
};

void expect_same_cells_from_a_junk_filled_image(const PacketDecoder& d, const std::vector<Packet>& packets,
                                                AssemblerOptions options = {}) {
  const std::vector<RangeImage> clean = assemble(d, packets, options);
  RevolutionAssembler assembler = assembler_for(d, options);
  JunkSink sink(assembler.shape());
  SensorClock clock;
  for (const Packet& p : packets) {
    const std::uint32_t ts = read_u32(p.bytes.data() + kTimestampOffset);
    assembler.add_packet(p.bytes, clock.resolve(ts, p.host_ns != 0 ? p.host_ns : static_cast<std::int64_t>(ts) * 1000), sink);
  }
  ASSERT_EQ(sink.images.size(), clean.size());
  ASSERT_GE(clean.size(), 3u);
  for (std::size_t i = 0; i < clean.size(); ++i) {
    const RangeImage& a = clean[i];
    const RangeImage& b = sink.images[i];
    ASSERT_EQ(a.columns(), b.columns());
    EXPECT_EQ(a.points, b.points);
    std::size_t differ = 0;
    for (int layer = 0; layer < a.layers(); ++layer) {
      for (int ring = 0; ring < a.rings(); ++ring) {
        for (int c = 0; c < a.columns(); ++c) {
          differ += std::memcmp(&a.at(layer, ring, c), &b.at(layer, ring, c), sizeof(RangeCell)) != 0 ? 1u : 0u;
        }
      }
    }
    EXPECT_EQ(differ, 0u) << "revolution " << i + 1;
  }
}

TEST(RangeImage, AnImageIsTheSameWhateverItsSlotHeldBefore) {
  std::vector<Packet> vlp16 = data_packets(shared_data("velodyne/einride_vlp16_recording_raw1206.bin"));
  expect_same_cells_from_a_junk_filled_image(decoder_for(Model::vlp16), vlp16);
  // Lost packets: their columns stay missing and empty, also the last ones
  // before a cut (the columns after a revolution's last firing).
  const PacketDecoder d = decoder_for(Model::vlp16);
  std::vector<Point> buffer(kMaxPointsPerPacket);
  RevolutionCut cut(0.0);
  std::vector<std::size_t> crossings;
  for (std::size_t k = 0; k < vlp16.size(); ++k) {
    const PacketInfo info = d.decode(vlp16[k].bytes, buffer);
    if (cut.first_new_sequence(info) < info.sequences) crossings.push_back(k);
  }
  ASSERT_GE(crossings.size(), 6u);
  vlp16.erase(vlp16.begin() + static_cast<std::ptrdiff_t>(crossings[4]) - 3,
              vlp16.begin() + static_cast<std::ptrdiff_t>(crossings[4]));
  vlp16.erase(vlp16.begin() + 330, vlp16.begin() + 333);
  expect_same_cells_from_a_junk_filled_image(d, vlp16);
  DecoderOptions all;
  all.selection = ReturnSelection::all;
  AssemblerOptions dual;
  dual.dual_returns = true;
  expect_same_cells_from_a_junk_filled_image(decoder_for(Model::vlp16, "", all),
                                             data_packets(shared_data("velodyne/nebula-vlp16/vlp16_dual_rewrapped.pcap")), dual);
}

TEST(RangeImage, DualReturnsFillTwoLayers) {
  DecoderOptions options;
  options.selection = ReturnSelection::all;
  const PacketDecoder d = decoder_for(Model::vlp16, "", options);
  AssemblerOptions assembler;
  assembler.dual_returns = true;
  AssemblerCounters counters;
  const auto images =
      assemble(d, data_packets(shared_data("velodyne/nebula-vlp16/vlp16_dual_rewrapped.pcap")), assembler, &counters);
  ASSERT_FALSE(images.empty());
  EXPECT_EQ(counters.lost_packets, 0u);
  for (const RangeImage& image : images) {
    ASSERT_EQ(image.layers(), 2);
    EXPECT_EQ(image.missing_columns, 0);
    int strongest = 0, last = 0, both = 0;
    for (int ring = 0; ring < image.rings(); ++ring) {
      for (int c = 0; c < image.columns(); ++c) {
        const RangeCell& s = image.at(0, ring, c);
        const RangeCell& l = image.at(1, ring, c);
        if (s.valid() && s.kind == ReturnKind::dual_both) {
          ++both;
          EXPECT_EQ(l.kind, ReturnKind::dual_both);
          EXPECT_EQ(l.distance, s.distance);
        }
        if (s.valid() && s.kind == ReturnKind::dual_strongest) ++strongest;
        if (l.valid() && l.kind == ReturnKind::dual_last) ++last;
        if (s.valid()) {
          EXPECT_NE(s.kind, ReturnKind::dual_last);
        }
      }
    }
    EXPECT_GT(both, 0);
    EXPECT_GT(strongest + last, 0);
  }
  // With one layer, the same packets give exactly layer 0: the strongest returns.
  const auto single = assemble(d, data_packets(shared_data("velodyne/nebula-vlp16/vlp16_dual_rewrapped.pcap")));
  ASSERT_EQ(single.size(), images.size());
  for (std::size_t i = 0; i < images.size(); ++i) {
    int layer0 = 0;
    for (int ring = 0; ring < images[i].rings(); ++ring) {
      for (const RangeCell& c : images[i].row(0, ring)) layer0 += c.valid() ? 1 : 0;
    }
    EXPECT_EQ(single[i].points, layer0);
    EXPECT_EQ(single[i].at(0, 5, 100).distance, images[i].at(0, 5, 100).distance);
  }
}

TEST(RangeImage, LostPacketsLeaveMissingColumnsAndAreCounted) {
  const PacketDecoder d = decoder_for(Model::vlp16);
  std::vector<Packet> packets = data_packets(shared_data("velodyne/einride_vlp16_recording_raw1206.bin"));
  const auto clean = assemble(d, packets);
  // Drop three packets with returns (part of this indoor scan returns
  // nothing) in the fifth revolution.
  std::vector<Point> buffer(kMaxPointsPerPacket);
  std::size_t drop = 320;
  for (;; ++drop) {
    int returns = 0;
    for (std::size_t k = drop; k < drop + 3; ++k) returns += d.decode(packets[k].bytes, buffer).points;
    if (returns > 600) break;
  }
  ASSERT_LT(drop, 380u);
  packets.erase(packets.begin() + static_cast<std::ptrdiff_t>(drop), packets.begin() + static_cast<std::ptrdiff_t>(drop) + 3);
  AssemblerCounters counters;
  const auto images = assemble(d, packets, {}, &counters);
  ASSERT_EQ(images.size(), clean.size());
  EXPECT_EQ(counters.lost_packets, 3u);
  int damaged = 0;
  for (std::size_t i = 0; i < images.size(); ++i) {
    const RangeImage& image = images[i];
    if (image.lost_packets == 0) {
      EXPECT_EQ(image.missing_columns, 0) << "revolution " << i + 1;
      continue;
    }
    ++damaged;
    EXPECT_EQ(image.lost_packets, 3u);
    // 3 packets of 24 firings each: their columns are missing, give or take one at each edge.
    EXPECT_NEAR(image.missing_columns, 72, 2);
    int run = 0, runs = 0;
    for (int c = 0; c < image.columns(); ++c) {
      if (image.column_state(c) == ColumnState::missing) {
        if (run++ == 0) ++runs;
        for (int ring = 0; ring < image.rings(); ++ring) EXPECT_FALSE(image.at(0, ring, c).valid());
      } else {
        run = 0;
      }
    }
    EXPECT_EQ(runs, 1) << "one contiguous gap";
    EXPECT_LT(image.points, clean[i].points - 600) << "revolution " << i + 1;
  }
  EXPECT_EQ(damaged, 1);
}

TEST(RangeImage, OutOfOrderPacketsAreDroppedAndCounted) {
  const PacketDecoder d = decoder_for(Model::vlp16);
  std::vector<Packet> packets = data_packets(shared_data("velodyne/einride_vlp16_recording_raw1206.bin"));
  std::swap(packets[400], packets[401]);
  AssemblerCounters counters;
  const auto images = assemble(d, packets, {}, &counters);
  EXPECT_EQ(counters.out_of_order, 1u);
  EXPECT_EQ(counters.lost_packets, 1u);  // seen as lost when its successor came first
  EXPECT_EQ(images.size(), 12u);
}

// A real capture with a gap: the sensor silent for 2 s (its packets
// dropped), and in a second run its clock stepped 3 s back halfway. Either way
// the revolution in progress is dropped, never joined across the jump (its
// points would be placed with poses seconds apart): every revolution handed
// on spans one turn's time, and the jump is counted.
TEST(RangeImage, ClockJumpsEndTheRevolutionInProgress) {
  const PacketDecoder d = decoder_for(Model::vlp16);
  const std::vector<Packet> packets = data_packets(shared_data("velodyne/einride_vlp16_recording_raw1206.bin"));
  ASSERT_GT(packets.size(), 800u);
  const auto clean = assemble(d, packets);
  auto stamp = [](Packet& p, std::int64_t shift_us) {
    std::uint32_t us = 0;
    for (int k = 0; k < 4; ++k) us |= static_cast<std::uint32_t>(p.bytes[static_cast<std::size_t>(1200 + k)]) << (8 * k);
    std::int64_t v = (static_cast<std::int64_t>(us) + shift_us) % 3'600'000'000;
    if (v < 0) v += 3'600'000'000;
    for (int k = 0; k < 4; ++k) p.bytes[static_cast<std::size_t>(1200 + k)] = static_cast<std::uint8_t>(v >> (8 * k));
  };
  for (const std::int64_t shift : {2'000'000LL, -3'000'000LL}) {
    std::vector<Packet> jumped = packets;
    for (std::size_t k = 410; k < jumped.size(); ++k) {
      stamp(jumped[k], shift);  // raw file: the host's time follows the packet clock here
    }
    AssemblerCounters counters;
    const auto images = assemble(d, jumped, {}, &counters);
    EXPECT_EQ(counters.discontinuities, 1u) << shift;
    EXPECT_EQ(counters.out_of_order, 0u) << shift;
    // One revolution fewer than the clean capture: the one the jump cut.
    EXPECT_EQ(images.size(), clean.size() - 1) << shift;
    for (const RangeImage& image : images) {
      EXPECT_LT(image.end_ns - image.start_ns, 120'000'000) << shift;  // one turn at 600 rpm, not seconds
    }
  }
}

TEST(RangeImage, CutIsExactAtAnyAzimuth) {
  const PacketDecoder d = decoder_for(Model::vlp16);
  const auto packets = data_packets(shared_data("velodyne/einride_vlp16_recording_raw1206.bin"));
  for (double cut_deg : {0.0, 90.0, 181.3, 359.9}) {
    AssemblerOptions options;
    options.cut_azimuth_rad = cut_deg * std::numbers::pi / 180.0;
    const auto images = assemble(d, packets, options);
    ASSERT_GE(images.size(), 11u) << cut_deg;
    for (const RangeImage& image : images) {
      const double width = 2.0 * std::numbers::pi / image.columns();
      float previous_time = -1.0f;
      for (int c = 0; c < image.columns(); ++c) {
        float column_time = -1.0f;
        for (int ring = 0; ring < image.rings(); ++ring) {
          const RangeCell& cell = image.at(0, ring, c);
          if (!cell.valid()) continue;
          // The VLP-16 has no rotation corrections: a cell's own azimuth is its
          // column's, within the bin (and one bin for a moved collision).
          double diff = std::remainder(static_cast<double>(cell.azimuth) - image.column_azimuth(c), 2.0 * std::numbers::pi);
          EXPECT_LE(std::abs(diff), 1.6 * width) << "cut " << cut_deg << " column " << c;
          column_time = std::max(column_time, cell.time);
        }
        if (column_time >= 0.0f) {
          EXPECT_GT(column_time, previous_time) << "cut " << cut_deg << " column " << c;
          previous_time = column_time;
        }
      }
      EXPECT_GE(previous_time, 0.095f);
      EXPECT_LE(previous_time, 0.105f);
    }
  }
}

TEST(RangeImage, FollowsAChangeOfRotationRate) {
  const PacketDecoder d = decoder_for(Model::vlp16);
  RevolutionAssembler assembler = assembler_for(d);
  EXPECT_EQ(assembler.columns(), 1808);  // 18084 firings/s at 10 Hz
  EXPECT_EQ(assembler.shape().max_columns, 3617);
  CollectingSink sink(assembler.shape());
  test::Vlp16Stream stream(600.0, 10.0);
  auto feed = [&](int packets) {
    for (int i = 0; i < packets; ++i) {
      const auto bytes = stream.next();
      assembler.add_packet(bytes, static_cast<std::int64_t>(stream.time_us() * 1000.0), sink);
    }
  };
  feed(76 * 4);  // four turns at 600 rpm
  stream.set_rpm(300.0);
  feed(151 * 5);  // five turns at 300 rpm
  ASSERT_GE(sink.images.size(), 7u);
  EXPECT_GE(assembler.counters().rpm_changes, 1u);  // the turn that slowed down measures in between
  EXPECT_LE(assembler.counters().rpm_changes, 2u);
  EXPECT_EQ(assembler.counters().lost_packets, 0u);
  const RangeImage& fast = sink.images[1];
  EXPECT_NEAR(fast.rpm, 600.0, 3.0);
  EXPECT_EQ(fast.columns(), 1808);
  const RangeImage& slow = sink.images.back();
  EXPECT_NEAR(slow.rpm, 300.0, 1.5);
  EXPECT_EQ(slow.columns(), 3617);
  int steady = 0;
  for (const RangeImage& image : sink.images) {
    EXPECT_EQ(image.missing_columns, 0) << image.sequence;
    if (std::abs(image.rpm - 600.0 * 1808 / image.columns()) < 5.0) {
      ++steady;
      // Steady rate: every firing has its own column, so every cell is filled.
      EXPECT_EQ(image.points, image.columns() * 16) << image.sequence;
      EXPECT_LE(image.collisions, 1u);
    }
  }
  EXPECT_GE(steady, 5) << "revolutions at a steady rate, at both speeds";
}

TEST(RangeImage, RevolutionsArePublishedThroughAMailboxWithoutAllocating) {
  const PacketDecoder d = decoder_for(Model::vlp16);
  const auto packets = data_packets(shared_data("velodyne/einride_vlp16_recording_raw1206.bin"));
  RevolutionAssembler assembler = assembler_for(d);
  Mailbox<RangeImage> mailbox(assembler.shape());
  MailboxRevolutionSink sink(mailbox);
  std::atomic<bool> done{false};
  std::vector<std::uint64_t> seen;
  std::vector<int> points;
  seen.reserve(64);
  points.reserve(64);
  std::thread reader([&] {
    for (;;) {
      const bool finished = done.load(std::memory_order_acquire);
      if (const RangeImage* image = mailbox.try_read()) {
        seen.push_back(image->sequence);
        points.push_back(image->points);
      }
      if (finished) break;
      std::this_thread::yield();
    }
  });
  ASSERT_TRUE(alloc_guard::hook_installed());
  alloc_guard::reset_counters();
  std::thread writer([&] {
    alloc_guard::mark_realtime_thread("assembler");
    alloc_guard::arm();
    for (const Packet& p : packets) {
      assembler.add_packet(p.bytes, static_cast<std::int64_t>(read_u32(p.bytes.data() + kTimestampOffset)) * 1000, sink);
      std::this_thread::sleep_for(std::chrono::microseconds(50));
    }
    alloc_guard::disarm();
    alloc_guard::unmark_current_thread();
  });
  writer.join();
  done.store(true, std::memory_order_release);
  reader.join();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u) << "add_packet allocated";
  ASSERT_FALSE(seen.empty());
  EXPECT_EQ(seen.back(), 12u);
  EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
  for (int n : points) EXPECT_GT(n, 10000);
}

TEST(RangeImage, BadOptionsAreRefused) {
  const PacketDecoder d = decoder_for(Model::vlp16);
  AssemblerOptions o;
  o.min_rpm = 10.0;
  EXPECT_NE(RevolutionAssembler::create(d, o).error.find("min_rpm"), std::string::npos);
  o = {};
  o.rpm = 200.0;
  EXPECT_NE(RevolutionAssembler::create(d, o).error.find("rpm 200"), std::string::npos);
  o = {};
  o.cut_azimuth_rad = 7.0;
  EXPECT_FALSE(RevolutionAssembler::create(d, o).assembler);
}

}  // namespace
}  // namespace trailnav::velodyne
