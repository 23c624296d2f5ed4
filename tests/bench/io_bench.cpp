// UDP reception and replay timing on loopback. Run from the repository root:
// build/release/bin/trailnav_io_bench
#include <benchmark/benchmark.h>

#include <atomic>
#include <thread>
#include <vector>

#include "replayer.hpp"
#include "trailnav/drivers/udp/udp_receiver.hpp"
#include "trailnav/drivers/udp/udp_sender.hpp"

namespace trailnav {
namespace {

// Datagrams of 1206 bytes from a sender thread through recvmmsg; items are datagrams.
void BM_UdpReceiveLoopback(benchmark::State& state) {
  udp::ReceiverOptions options;
  options.bind = {0x7F000001u, 0};
  options.batch = static_cast<int>(state.range(0));
  options.receive_buffer_bytes = 8 << 20;
  auto receiver = std::move(udp::UdpReceiver::open(options).receiver);
  auto sender = std::move(udp::UdpSender::open(receiver->local(), 8 << 20).sender);
  std::atomic<bool> stop{false};
  std::thread producer([&] {
    const std::vector<std::uint8_t> payload(1206, 1);
    while (!stop.load(std::memory_order_relaxed)) sender->send(payload);
  });
  std::int64_t received = 0;
  for (auto _ : state) received += static_cast<std::int64_t>(receiver->receive(10).size());
  stop.store(true);
  producer.join();
  state.SetItemsProcessed(received);
  state.counters["kernel_drops"] = static_cast<double>(receiver->counters().kernel_drops);
  state.counters["per_call"] = static_cast<double>(received) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_UdpReceiveLoopback)->Arg(1)->Arg(16)->Arg(64);

// The replayer's timing: a real capture at its recorded rate into a draining
// receiver; counters are the send-time error (actual minus scheduled), in us.
void BM_ReplayTiming(benchmark::State& state, const char* capture) {
  udp::ReceiverOptions options;
  options.bind = {0x7F000001u, 0};
  auto receiver = std::move(udp::UdpReceiver::open(options).receiver);
  std::atomic<bool> stop{false};
  std::thread drain([&] {
    while (!stop.load()) receiver->receive(5);
  });
  replay::ReplayReport report;
  for (auto _ : state) {
    replay::ReplayOptions o;
    o.udp_targets["lidar"] = receiver->local();
    o.loops = 3;
    auto created = replay::Replayer::create(capture, o);
    if (!created.replayer) {
      state.SkipWithError(created.error.c_str());
      break;
    }
    report = created.replayer->run();
  }
  stop.store(true);
  drain.join();
  state.counters["p50_us"] = static_cast<double>(report.send_error.p50) / 1e3;
  state.counters["p99_us"] = static_cast<double>(report.send_error.p99) / 1e3;
  state.counters["max_us"] = static_cast<double>(report.send_error.max) / 1e3;
  state.counters["sends"] = static_cast<double>(report.send_error.count);
}
BENCHMARK_CAPTURE(BM_ReplayTiming, hdl32e, "../shared/data/velodyne/mrpt_sample_velodyne_hdl32.pcap")
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReplayTiming, vlp16_raw, "../shared/data/velodyne/einride_vlp16_recording_raw1206.bin")
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace trailnav

BENCHMARK_MAIN();
