// Velodyne decode throughput. Run: build/release/bin/trailnav_velodyne_bench
// (from the repository root, so ../shared/data is found).
#include <benchmark/benchmark.h>

#include <vector>

#include "trailnav/drivers/capture/capture_reader.hpp"
#include "trailnav/drivers/velodyne/decoder.hpp"

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
    const PacketInfo info = created.decoder->decode(packets[i], out);
    points += info.points;
    benchmark::DoNotOptimize(out.data());
    if (++i == packets.size()) i = 0;
  }
  state.SetItemsProcessed(points);  // items = points
  state.counters["packets_per_s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void BM_DecodeHdl32eRealCapture(benchmark::State& state) {
  static const auto packets = load_packets("../shared/data/velodyne/mrpt_sample_velodyne_hdl32.pcap");
  run(state, Model::hdl32e, *builtin_calibration(Model::hdl32e), packets);
}
BENCHMARK(BM_DecodeHdl32eRealCapture);

void BM_DecodeVlp16DualRealCapture(benchmark::State& state) {
  static const auto packets = load_packets("../shared/data/velodyne/nebula-vlp16/vlp16_dual_rewrapped.pcap");
  run(state, Model::vlp16, *builtin_calibration(Model::vlp16), packets);
}
BENCHMARK(BM_DecodeVlp16DualRealCapture);

// HDL-64E with a real calibration (two-point and intensity corrections on),
// every firing returning: the worst case per packet.
void BM_DecodeHdl64eFullPacket(benchmark::State& state) {
  CalibrationResult loaded = load_calibration("../shared/data/velodyne/calibration/ros_velodyne_64e_s2.1-sztaki.yaml");
  if (!loaded.calibration) {
    state.SkipWithError(loaded.error.c_str());
    return;
  }
  std::vector<std::uint8_t> packet(kDataPacketSize, 0);
  for (int b = 0; b < 12; ++b) {
    const std::size_t base = static_cast<std::size_t>(b) * 100;
    packet[base] = 0xFF;
    packet[base + 1] = b % 2 ? 0xDD : 0xEE;
    const int azimuth = 1000 + (b / 2) * 17;
    packet[base + 2] = static_cast<std::uint8_t>(azimuth & 0xFF);
    packet[base + 3] = static_cast<std::uint8_t>(azimuth >> 8);
    for (int k = 0; k < 32; ++k) {
      const int raw = 1000 + 131 * k + 700 * b;
      packet[base + 4 + static_cast<std::size_t>(k) * 3] = static_cast<std::uint8_t>(raw & 0xFF);
      packet[base + 5 + static_cast<std::size_t>(k) * 3] = static_cast<std::uint8_t>(raw >> 8);
      packet[base + 6 + static_cast<std::size_t>(k) * 3] = static_cast<std::uint8_t>(k * 5);
    }
  }
  run(state, Model::hdl64e, *loaded.calibration, {packet});
}
BENCHMARK(BM_DecodeHdl64eFullPacket);

}  // namespace
}  // namespace trailnav::velodyne

BENCHMARK_MAIN();
