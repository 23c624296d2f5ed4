// Fuzzes the Velodyne data path: packet decoding for every model, position
// packets with their NMEA time, the sensor clock, and revolution assembly.
// The input is a sequence of packets: consecutive 1206-byte pieces (the rest
// as a packet of the wrong size). Invariants are checked, not just crashes.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <bit>
#include <cstdlib>
#include <memory>
#include <vector>

#include "check.hpp"

#include "trailnav/drivers/velodyne/range_image.hpp"
#include "trailnav/drivers/velodyne/sensor_clock.hpp"

using namespace trailnav::velodyne;

namespace {


class CheckingSink final : public RevolutionSink {
 public:
  explicit CheckingSink(RangeImageShape shape) : image_(shape) {}
  RangeImage& next_image() noexcept override { return image_; }
  void complete(RangeImage& image) noexcept override {
    check(image.columns() >= 1 && image.columns() <= image.shape().max_columns);
    check(image.missing_columns >= 0 && image.missing_columns <= image.columns());
    for (int layer = 0; layer < image.layers(); ++layer) {
      for (int ring = 0; ring < image.rings(); ++ring) {
        for (const RangeCell& c : image.row(layer, ring)) {
          if (!c.valid()) continue;
          check(std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.z) && std::isfinite(c.time));
        }
      }
    }
  }

 private:
  RangeImage image_;
};

bool same_bits(const Point& a, const Point& b) {
  const auto bits = [](float f) { return std::bit_cast<std::uint32_t>(f); };
  return bits(a.x) == bits(b.x) && bits(a.y) == bits(b.y) && bits(a.z) == bits(b.z) &&
         bits(a.distance) == bits(b.distance) && bits(a.azimuth) == bits(b.azimuth) &&
         bits(a.intensity) == bits(b.intensity) && bits(a.time) == bits(b.time) && a.ring == b.ring &&
         a.laser == b.laser && a.kind == b.kind && a.sequence == b.sequence;
}

// A synthetic HDL-64E calibration with every correction in use.
Calibration hdl64e_calibration() {
  Calibration c;
  for (int i = 0; i < 64; ++i) {
    LaserCorrection l;
    l.laser_id = i;
    l.vert_correction = (-24.0 + i * 0.45) * 3.14159265 / 180.0;
    l.rot_correction = ((i % 8) - 4) * 0.01;
    l.dist_correction = 1.2 + 0.01 * i;
    l.dist_correction_x = 1.25;
    l.dist_correction_y = 1.22;
    l.vert_offset_correction = 0.2;
    l.horiz_offset_correction = i % 2 == 0 ? 0.026 : -0.026;
    l.two_pt_correction = true;
    l.focal_distance = 8.0;
    l.focal_slope = 1.1;
    l.min_intensity = 5;
    l.max_intensity = 240;
    c.lasers.push_back(l);
  }
  c.source = "fuzzer";
  return c;
}

// Decoders and images are built once (they are large); the assemblers and
// clocks, which carry state, afresh for every input.
struct Model_ {
  PacketDecoder decoder;
  AssemblerOptions options;
  std::unique_ptr<CheckingSink> sink;
};

std::vector<Model_>& models() {
  static std::vector<Model_> all = [] {
    std::vector<Model_> out;
    for (Model m : {Model::vlp16, Model::vlp32c, Model::hdl32e, Model::hdl64e}) {
      const Calibration cal = m == Model::hdl64e ? hdl64e_calibration() : *builtin_calibration(m);
      auto decoder = PacketDecoder::create(m, cal, DecoderOptions{});
      check(decoder.decoder.has_value());
      AssemblerOptions options;
      options.dual_returns = m != Model::hdl64e;
      options.min_rpm = 600.0;
      out.push_back({std::move(*decoder.decoder), options, nullptr});
    }
    for (Model_& m : out) {
      auto assembler = RevolutionAssembler::create(m.decoder, m.options);
      check(assembler.assembler.has_value());
      m.sink = std::make_unique<CheckingSink>(assembler.assembler->shape());
    }
    return out;
  }();
  return all;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static std::vector<Point> points(kMaxPointsPerPacket);
  static std::vector<Point> reference(kMaxPointsPerPacket);
  std::vector<Model_>& all = models();
  std::vector<RevolutionAssembler> assemblers;
  std::vector<SensorClock> clocks(all.size());
  for (Model_& m : all) assemblers.push_back(std::move(*RevolutionAssembler::create(m.decoder, m.options).assembler));
  std::int64_t host = 1'700'000'000'000'000'000;
  std::size_t offset = 0;
  while (offset < size) {
    const std::size_t n = std::min(kDataPacketSize, size - offset);
    const std::span<const std::uint8_t> packet(data + offset, n);
    offset += n;
    host += 1'327'000;
    (void)detect_model(packet);
    for (std::size_t k = 0; k < all.size(); ++k) {
      const PacketDecoder& decoder = all[k].decoder;
      const PacketInfo info = decoder.decode(packet, points);
      check(info.points >= 0 && info.points <= kMaxPointsPerPacket);
      // Both ways of computing the points give the same bits.
      const PacketInfo one_by_one = decoder.decode(packet, reference, DecodeKernel::per_point);
      check(one_by_one.error == info.error && one_by_one.points == info.points);
      for (int i = 0; i < info.points; ++i) {
        check(same_bits(points[static_cast<std::size_t>(i)], reference[static_cast<std::size_t>(i)]));
      }
      for (int i = 0; i < info.points; ++i) {
        const Point& q = points[static_cast<std::size_t>(i)];
        check(std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z));
        check(q.ring < decoder.model().lasers);
        check(q.azimuth >= 0.0f && q.azimuth < 6.2832f);
        check(q.sequence < info.sequences);
      }
      const std::uint32_t stamp = n == kDataPacketSize ? read_u32(packet.data() + kTimestampOffset) : 0;
      assemblers[k].add_packet(packet, clocks[k].resolve(stamp, host), *all[k].sink);
    }
    // The same bytes as a position packet, when long enough.
    if (n >= kPositionPacketSize) {
      PositionPacket pos;
      if (decode_position_packet(packet.subspan(0, kPositionPacketSize), pos) == PositionError::none) {
        check(pos.nmea.size() <= kPositionPacketSize - 206);
        (void)rmc_utc_ns(pos.nmea);
        for (SensorClock& c : clocks) c.on_position_packet(pos);
      }
    }
  }
  (void)rmc_utc_ns(std::string_view(reinterpret_cast<const char*>(data), size));
  return 0;
}
