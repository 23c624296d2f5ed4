// Benchmarks of the runtime's hot paths. Run: build/release/bin/trailnav_runtime_bench
#include <benchmark/benchmark.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "trailnav/runtime/clock.hpp"
#include "trailnav/runtime/fixed_vector.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/rolling_grid.hpp"
#include "trailnav/runtime/spsc_queue.hpp"

namespace trailnav {
namespace {

// One push and one pop on the same thread: the cost of the operations themselves.
// What the scheduler adds to every run of a task: two readings of the
// monotonic clock (vDSO) and two of the thread's CPU time (a system call).
void BM_ClockReadings(benchmark::State& state) {
  trailnav::MonotonicClock clock;
  const bool cpu = state.range(0) != 0;
  for (auto _ : state) benchmark::DoNotOptimize(cpu ? clock.thread_cpu_time() : clock.now());
  state.SetLabel(cpu ? "thread CPU time" : "monotonic");
}
BENCHMARK(BM_ClockReadings)->Arg(0)->Arg(1);

void BM_SpscQueuePushPop(benchmark::State& state) {
  auto q = std::make_unique<SpscQueue<std::uint64_t, 1024>>();
  std::uint64_t out = 0;
  std::uint64_t i = 0;
  for (auto _ : state) {
    q->try_push(i++);
    q->try_pop(out);
    benchmark::DoNotOptimize(out);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_SpscQueuePushPop);

// Items per second between a producer and a consumer thread.
void BM_SpscQueueThroughput(benchmark::State& state) {
  constexpr std::uint64_t kBatch = 1 << 20;
  auto q = std::make_unique<SpscQueue<std::uint64_t, 4096>>();
  for (auto _ : state) {
    std::thread producer([&] {
      for (std::uint64_t i = 0; i < kBatch;) {
        if (q->try_push(i)) ++i;
      }
    });
    std::uint64_t received = 0;
    std::uint64_t value = 0;
    while (received < kBatch) {
      if (q->try_pop(value)) ++received;
    }
    producer.join();
    benchmark::DoNotOptimize(value);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(kBatch));
}
BENCHMARK(BM_SpscQueueThroughput)->Unit(benchmark::kMillisecond)->UseRealTime();

struct GridSnapshot {
  explicit GridSnapshot(std::size_t n) : cells(n) { cells.resize(n); }
  CellIndex origin;
  FixedVector<std::int8_t> cells;
};

// Handing a 600 x 600 map from writer to reader: publish + try_read, no copy.
void BM_MailboxHandoff600x600(benchmark::State& state) {
  Mailbox<GridSnapshot> box(std::size_t{600 * 600});
  for (auto _ : state) {
    box.write_slot().origin.x += 1;
    box.publish();
    const GridSnapshot* s = box.try_read();
    benchmark::DoNotOptimize(s);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_MailboxHandoff600x600);

// The writer's full cost per snapshot: linearise the rolling grid into the
// mailbox slot, then publish.
void BM_MailboxSnapshotFromRollingGrid600x600(benchmark::State& state) {
  Mailbox<GridSnapshot> box(std::size_t{600 * 600});
  RollingGrid<std::int8_t> grid(600, 600, 0.1, -1);
  grid.move_to(123.4, -56.7);
  for (auto _ : state) {
    GridSnapshot& slot = box.write_slot();
    grid.copy_to(slot.cells.span());
    slot.origin = grid.origin();
    box.publish();
    benchmark::DoNotOptimize(box.try_read());
  }
  state.SetBytesProcessed(state.iterations() * 600 * 600);
}
BENCHMARK(BM_MailboxSnapshotFromRollingGrid600x600)->Unit(benchmark::kMicrosecond);

// A typical per-revolution move (robot at 1.2 m/s, 10 Hz, 0.1 m cells): one
// cell in x and one in y, on the default obstacle grid of 600 x 600 floats.
void BM_RollingGridMoveOneCell(benchmark::State& state) {
  RollingGrid<float> grid(600, 600, 0.1, 0.0f);
  CellIndex origin = grid.origin();
  for (auto _ : state) {
    origin.x += 1;
    origin.y += (origin.x & 1);
    benchmark::DoNotOptimize(grid.move_origin_to(origin));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_RollingGridMoveOneCell)->Unit(benchmark::kMicrosecond);

// Moves of N cells in both axes.
void BM_RollingGridMove(benchmark::State& state) {
  RollingGrid<float> grid(600, 600, 0.1, 0.0f);
  const auto step = static_cast<std::int32_t>(state.range(0));
  CellIndex origin = grid.origin();
  std::int64_t cleared = 0;
  for (auto _ : state) {
    origin.x += step;
    origin.y -= step;
    cleared += static_cast<std::int64_t>(grid.move_origin_to(origin));
  }
  state.counters["cells_cleared_per_move"] =
      benchmark::Counter(static_cast<double>(cleared) / static_cast<double>(state.iterations()));
}
BENCHMARK(BM_RollingGridMove)->Arg(1)->Arg(10)->Arg(100)->Arg(600)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace trailnav

BENCHMARK_MAIN();
