// The static-allocation contract: once the runtime is armed, real-time
// threads never touch the heap. This test runs a scheduler with a producer,
// an event-driven consumer and two rolling-grid tasks that hand snapshots to
// a reader through the runtime's primitives, and logs from them, for
// thousands of cycles after arm() — and finds zero heap operations.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cmath>
#include <thread>

#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/fixed_vector.hpp"
#include "trailnav/runtime/log.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/rolling_grid.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/spsc_queue.hpp"
#include "../support/no_allocations.hpp"

namespace trailnav {
namespace {

struct Sample {
  Nanos time = 0;
  double x = 0.0;
  double y = 0.0;
};

struct Pose {
  double x = 0.0;
  double y = 0.0;
};

struct GridSnapshot {
  explicit GridSnapshot(std::size_t cell_count) : cells(cell_count) { cells.resize(cell_count); }
  CellIndex origin;
  std::uint64_t cycle = 0;
  FixedVector<std::uint8_t> cells;
};

// 1 kHz: a robot moving on a circle, one sample per run, into a queue.
class Producer final : public Task {
 public:
  Producer(SpscQueue<Sample, 256>& queue, TaskEvent& event) : queue_(queue), event_(event) {}
  void run(const TaskTick& tick) override {
    const double t = static_cast<double>(tick.cycle) * 1e-3;
    if (!queue_.try_push(Sample{tick.started, 20.0 * std::cos(0.1 * t), 20.0 * std::sin(0.1 * t)})) ++dropped;
    event_.signal(tick.started);
  }
  std::uint64_t dropped = 0;

 private:
  SpscQueue<Sample, 256>& queue_;
  TaskEvent& event_;
};

// Event-driven: drains the queue, keeps a batch in a fixed vector, publishes
// the latest pose.
class Consumer final : public Task {
 public:
  Consumer(SpscQueue<Sample, 256>& queue, Mailbox<Pose>& poses) : queue_(queue), poses_(poses) {}
  void run(const TaskTick&) override {
    batch_.clear();
    Sample s;
    while (queue_.try_pop(s)) {
      if (!batch_.try_push_back(s)) break;
    }
    if (batch_.empty()) return;
    poses_.write_slot() = Pose{batch_.back().x, batch_.back().y};
    poses_.publish();
    consumed += batch_.size();
  }
  std::uint64_t consumed = 0;

 private:
  SpscQueue<Sample, 256>& queue_;
  Mailbox<Pose>& poses_;
  InlineVector<Sample, 256> batch_;
};

// Periodic: moves a rolling grid with the pose, marks the cells around the
// robot, and hands a linearised copy to the reader every few cycles.
template <typename Cell>
class GridTask final : public Task {
 public:
  GridTask(Mailbox<Pose>& poses, Mailbox<GridSnapshot>* out, std::int32_t size, double resolution)
      : poses_(poses), out_(out), grid_(size, size, resolution, Cell{}) {}
  void run(const TaskTick& tick) override {
    if (const Pose* p = poses_.try_read()) pose_ = *p;
    grid_.move_to(pose_.x, pose_.y);
    const CellIndex c = grid_.world_to_index(pose_.x, pose_.y);
    grid_.for_each_in_window({c.x - 5, c.y - 5}, {c.x + 6, c.y + 6}, [](CellIndex, Cell& cell) { cell = Cell{1}; });
    if (out_ != nullptr && tick.cycle % 10 == 0) {
      GridSnapshot& snap = out_->write_slot();
      if constexpr (std::is_same_v<Cell, std::uint8_t>) grid_.copy_to(snap.cells.span());
      snap.origin = grid_.origin();
      snap.cycle = tick.cycle;
      out_->publish();
    }
    if (tick.cycle % 200 == 0) TN_LOG_DEBUG("grid cycle %llu at %.2f %.2f", static_cast<unsigned long long>(tick.cycle), pose_.x, pose_.y);
  }

 private:
  Mailbox<Pose>& poses_;
  Mailbox<GridSnapshot>* out_;
  RollingGrid<Cell> grid_;
  Pose pose_;
};

TEST(ZeroAllocation, ArmedSchedulerWithRollingGridsRunsThousandsOfCyclesWithoutTouchingTheHeap) {
  ASSERT_TRUE(alloc_guard::hook_installed());
  alloc_guard::set_fatal(false);  // count and report rather than abort, so the test names the thread
  alloc_guard::reset_counters();
  log::set_min_level(log::Level::debug);
  log::start(log::Sink::stderr_only);

  // Start-up: everything is allocated here.
  MonotonicClock clock;
  auto queue = std::make_unique<SpscQueue<Sample, 256>>();
  TaskEvent samples_ready;
  Mailbox<Pose> poses;
  Mailbox<Pose> poses_for_terrain;
  Mailbox<GridSnapshot> obstacle_snapshots(std::size_t{600 * 600});
  Producer producer(*queue, samples_ready);
  Consumer consumer(*queue, poses);
  GridTask<std::uint8_t> obstacles(poses, &obstacle_snapshots, 600, 0.1);
  GridTask<float> terrain(poses_for_terrain, nullptr, 300, 0.2);

  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  ASSERT_TRUE(scheduler.add({"producer", TaskKind::periodic, 1000.0, kNanosPerMilli / 2, 0, -1}, producer));
  ASSERT_TRUE(scheduler.add({"consumer", TaskKind::event, 0.0, kNanosPerMilli / 2, 0, -1}, consumer, &samples_ready));
  ASSERT_TRUE(scheduler.add({"obstacles", TaskKind::periodic, 500.0, 2 * kNanosPerMilli, 0, -1}, obstacles));
  ASSERT_TRUE(scheduler.add({"terrain", TaskKind::periodic, 200.0, 5 * kNanosPerMilli, 0, -1}, terrain));
  ASSERT_TRUE(scheduler.start());
  ASSERT_TRUE(alloc_guard::arm());

  // The reader (a publisher in the daemon) is not real-time.
  std::uint64_t snapshots = 0;
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (scheduler.stats(0).runs < 3000 || scheduler.stats(2).runs < 1000 || scheduler.stats(3).runs < 500) {
    if (const GridSnapshot* snap = obstacle_snapshots.try_read()) {
      ++snapshots;
      EXPECT_EQ(snap->cells.size(), 600u * 600u);
    }
    if (std::chrono::steady_clock::now() > give_up) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  scheduler.stop();
  alloc_guard::disarm();
  log::stop();
  log::set_min_level(log::Level::info);

  EXPECT_GE(scheduler.stats(0).runs, 3000u);
  EXPECT_GE(scheduler.stats(2).runs, 1000u);
  EXPECT_GE(scheduler.stats(3).runs, 500u);
  EXPECT_GT(consumer.consumed, 2500u);
  EXPECT_GT(snapshots, 10u);

  test::expect_no_realtime_allocations();
}

}  // namespace
}  // namespace trailnav
