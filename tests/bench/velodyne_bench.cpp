// Velodyne decode throughput. Run: build/release/bin/trailnav_velodyne_bench
// (from the repository root, so ../shared/data is found).
#include <benchmark/benchmark.h>

#include <vector>

#include "trailnav/drivers/capture/capture_reader.hpp"
#include "trailnav/drivers/velodyne/decoder.hpp"
#include "trailnav/drivers/velodyne/range_image.hpp"

namespace trailnav::velodyne {
namespace {

std::vector<std::vector<std::uint8_t>> load_packets(const std::string& path) {
  std::vector<std::vector<std::uint8_t>> packets;
  auto opened = capture::open_capture(path);
  if (!opened.reader) return packets;
  while (auto d = opened.reader->next()) {
    if (d->payload.size() == kDataPacketSize) packets.emplace_back(d->payload.begin(), d->payload.end());
  }
  return packets;
}

// One HDL-64E packet: 6 upper/lower block pairs starting at `azimuth`
// (hundredths of a degree), `pair_step` apart, every firing returning.
std::vector<std::uint8_t> hdl64e_packet(double azimuth, double pair_step, std::uint32_t stamp) {
  std::vector<std::uint8_t> packet(kDataPacketSize, 0);
  for (int b = 0; b < 12; ++b) {
    const std::size_t base = static_cast<std::size_t>(b) * 100;
    packet[base] = 0xFF;
    packet[base + 1] = b % 2 ? 0xDD : 0xEE;
    const int a = static_cast<int>(azimuth + (b / 2) * pair_step) % 36000;
    packet[base + 2] = static_cast<std::uint8_t>(a & 0xFF);
    packet[base + 3] = static_cast<std::uint8_t>(a >> 8);
    for (int k = 0; k < 32; ++k) {
      const int raw = 1000 + 131 * k + 700 * b;
      packet[base + 4 + static_cast<std::size_t>(k) * 3] = static_cast<std::uint8_t>(raw & 0xFF);
      packet[base + 5 + static_cast<std::size_t>(k) * 3] = static_cast<std::uint8_t>(raw >> 8);
      packet[base + 6 + static_cast<std::size_t>(k) * 3] = static_cast<std::uint8_t>(k * 5);
    }
  }
  for (std::size_t i = 0; i < 4; ++i) packet[kTimestampOffset + i] = static_cast<std::uint8_t>(stamp >> (8 * i));
  return packet;
}

void run(benchmark::State& state, Model model, const Calibration& calibration, const std::vector<std::vector<std::uint8_t>>& packets) {
  auto created = PacketDecoder::create(model, calibration);
  if (!created.decoder || packets.empty()) {
    state.SkipWithError("decoder or data missing (run from the repository root)");
    return;
  }
  std::vector<Point> out(kMaxPointsPerPacket);
  std::size_t i = 0;
  std::int64_t points = 0;
  for (auto _ : state) {
    const PacketInfo info = created.decoder->decode(packets[i], out, static_cast<DecodeKernel>(state.range(0)));
    points += info.points;
    benchmark::DoNotOptimize(out.data());
    if (++i == packets.size()) i = 0;
  }
  state.SetItemsProcessed(points);  // items = points
  state.SetLabel(state.range(0) == 0 ? "blocks" : "per point");
  state.counters["packets_per_s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void BM_DecodeHdl32eRealCapture(benchmark::State& state) {
  static const auto packets = load_packets("../shared/data/velodyne/mrpt_sample_velodyne_hdl32.pcap");
  run(state, Model::hdl32e, *builtin_calibration(Model::hdl32e), packets);
}
BENCHMARK(BM_DecodeHdl32eRealCapture)->Arg(0)->Arg(1);  // DecodeKernel: blocks, per point

void BM_DecodeVlp16DualRealCapture(benchmark::State& state) {
  static const auto packets = load_packets("../shared/data/velodyne/nebula-vlp16/vlp16_dual_rewrapped.pcap");
  run(state, Model::vlp16, *builtin_calibration(Model::vlp16), packets);
}
BENCHMARK(BM_DecodeVlp16DualRealCapture)->Arg(0)->Arg(1);  // DecodeKernel: blocks, per point

// HDL-64E with a real calibration (two-point and intensity corrections on),
// every firing returning: the worst case per packet.
void BM_DecodeHdl64eFullPacket(benchmark::State& state) {
  CalibrationResult loaded = load_calibration("../shared/data/velodyne/calibration/ros_velodyne_64e_s2.1-sztaki.yaml");
  if (!loaded.calibration) {
    state.SkipWithError(loaded.error.c_str());
    return;
  }
  const std::vector<std::uint8_t> packet = hdl64e_packet(1000.0, 17.0, 0);
  run(state, Model::hdl64e, *loaded.calibration, {packet});
}
BENCHMARK(BM_DecodeHdl64eFullPacket)->Arg(0)->Arg(1);  // DecodeKernel: blocks, per point

// Decode plus revolution assembly into the range image, the driver's whole
// per-packet work. Items are points.
class NullSink final : public RevolutionSink {
 public:
  explicit NullSink(RangeImageShape shape) : image_(shape) {}
  RangeImage& next_image() noexcept override { return image_; }
  void complete(RangeImage& image) noexcept override { benchmark::DoNotOptimize(image.points); }

 private:
  RangeImage image_;
};

void assemble(benchmark::State& state, Model model, const Calibration& calibration,
              std::vector<std::vector<std::uint8_t>> packets, double packet_us) {
  auto created = PacketDecoder::create(model, calibration);
  if (!created.decoder || packets.empty()) {
    state.SkipWithError("decoder or data missing (run from the repository root)");
    return;
  }
  auto assembler = std::move(*RevolutionAssembler::create(*created.decoder, {}).assembler);
  NullSink sink(assembler.shape());
  std::vector<Point> out(kMaxPointsPerPacket);
  std::int64_t points = 0;
  for (const auto& p : packets) points += created.decoder->decode(p, out).points;
  std::size_t i = 0;
  std::int64_t t = 0;
  std::int64_t done = 0;
  for (auto _ : state) {
    // The packet clock runs on across loops over the packets.
    const auto stamp = static_cast<std::uint32_t>((t / 1000) % kMicrosPerHour);
    for (std::size_t b = 0; b < 4; ++b) packets[i][kTimestampOffset + b] = static_cast<std::uint8_t>(stamp >> (8 * b));
    assembler.add_packet(packets[i], t, sink);
    t += static_cast<std::int64_t>(packet_us * 1000.0);
    if (++i == packets.size()) {
      i = 0;
      done += points;
    }
  }
  state.SetItemsProcessed(done + points * static_cast<std::int64_t>(i) / static_cast<std::int64_t>(packets.size()));
  state.counters["revolutions"] = static_cast<double>(assembler.counters().revolutions);
  state.counters["lost"] = static_cast<double>(assembler.counters().lost_packets);
  state.counters["out_of_order"] = static_cast<double>(assembler.counters().out_of_order);
}

void BM_AssembleVlp16RealCapture(benchmark::State& state) {
  static const auto packets = load_packets("../shared/data/velodyne/einride_vlp16_recording_raw1206.bin");
  assemble(state, Model::vlp16, *builtin_calibration(Model::vlp16), packets, 1327.0);
}
BENCHMARK(BM_AssembleVlp16RealCapture);

// HDL-64E at about 600 rpm: 6 upper/lower pairs a packet, 347 packets a turn
// (so the packets loop seamlessly), every firing returning; a real calibration.
void BM_AssembleHdl64eFullRevolutions(benchmark::State& state) {
  CalibrationResult loaded = load_calibration("../shared/data/velodyne/calibration/ros_velodyne_64e_s2.1-sztaki.yaml");
  if (!loaded.calibration) {
    state.SkipWithError(loaded.error.c_str());
    return;
  }
  std::vector<std::vector<std::uint8_t>> packets;
  double azimuth = 0.0;
  std::uint32_t stamp = 0;
  for (int n = 0; n < 347 * 3; ++n) {  // three turns
    packets.push_back(hdl64e_packet(azimuth, 36000.0 / 347.0 / 6.0, stamp));
    azimuth += 36000.0 / 347.0;
    if (azimuth >= 36000.0) azimuth -= 36000.0;
    stamp += 288;
  }
  assemble(state, Model::hdl64e, *loaded.calibration, packets, 288.0);
}
BENCHMARK(BM_AssembleHdl64eFullRevolutions);

}  // namespace
}  // namespace trailnav::velodyne

BENCHMARK_MAIN();
