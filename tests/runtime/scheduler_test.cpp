#include "trailnav/runtime/scheduler.hpp"

#include <gtest/gtest.h>
#include <fcntl.h>
#include <pthread.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

namespace trailnav {
namespace {

constexpr Nanos kMs = kNanosPerMilli;

// --- the accounting on its own ---

TEST(TaskAccounting, OverrunIsNotASlip) {
  TaskAccounting acc(TaskKind::periodic, 10 * kMs, 2 * kMs);
  acc.record_run(0, 1 * kMs, 4 * kMs);  // on time, 3 ms of work against 2 ms
  const TaskStats s = acc.stats();
  EXPECT_EQ(s.runs, 1u);
  EXPECT_EQ(s.overruns, 1u);
  EXPECT_EQ(s.slips, 0u);
}

TEST(TaskAccounting, SlipIsNotAnOverrun) {
  TaskAccounting acc(TaskKind::periodic, 10 * kMs, 2 * kMs);
  acc.record_run(0, 15 * kMs, 16 * kMs);  // 15 ms late, 1 ms of work
  const TaskStats s = acc.stats();
  EXPECT_EQ(s.overruns, 0u);
  EXPECT_EQ(s.slips, 1u);
}

TEST(TaskAccounting, LateButWithinOnePeriodIsNeither) {
  TaskAccounting acc(TaskKind::periodic, 10 * kMs, 2 * kMs);
  acc.record_run(0, 10 * kMs, 12 * kMs);  // exactly one period late, exactly on budget
  const TaskStats s = acc.stats();
  EXPECT_EQ(s.overruns, 0u);
  EXPECT_EQ(s.slips, 0u);
  EXPECT_EQ(s.latency.max, 10 * kMs);
  EXPECT_EQ(s.execution.max, 2 * kMs);
}

TEST(TaskAccounting, AThreadKeptOffItsCoreStallsButDoesNotOverrun) {
  TaskAccounting acc(TaskKind::periodic, 10 * kMs, 2 * kMs);
  acc.record_run(0, 1 * kMs, 4 * kMs, kMs / 10);  // 3 ms by the clock, 0.1 ms of CPU time
  acc.record_run(0, 1 * kMs, 4 * kMs, 3 * kMs);   // 3 ms of CPU time: an overrun
  acc.record_run(0, 1 * kMs, 2 * kMs, kMs);       // within budget both ways
  const TaskStats s = acc.stats();
  EXPECT_EQ(s.runs, 3u);
  EXPECT_EQ(s.overruns, 1u);
  EXPECT_EQ(s.stalls, 1u);
  EXPECT_EQ(s.execution.max, 3 * kMs);  // the distribution stays by the clock
  EXPECT_EQ(s.cpu_max, 3 * kMs);
}

TEST(TaskAccounting, ARunAfterADelayHasABudgetPerPeriodOfInput) {
  TaskAccounting acc(TaskKind::periodic, 10 * kMs, 2 * kMs);
  acc.record_run(10 * kMs, 10 * kMs, 11 * kMs, kMs);  // on time: 1 ms per period
  // Started 30 ms after the run before: three periods of input, 6 ms allowed.
  acc.record_run(20 * kMs, 40 * kMs, 45 * kMs, 5 * kMs);
  TaskStats s = acc.stats();
  EXPECT_EQ(s.overruns, 0u);
  EXPECT_EQ(s.stalls, 0u);
  EXPECT_EQ(s.slips, 1u);
  EXPECT_EQ(s.cpu_max, 5 * kMs);                       // the most one run used
  EXPECT_NEAR(static_cast<double>(s.cpu_per_period.max), 5.0 / 3.0 * kMs, 0.05 * kMs);  // per period of input
  // Back on the grid, one period after: one budget again.
  acc.record_run(50 * kMs, 50 * kMs, 53 * kMs, 3 * kMs);
  s = acc.stats();
  EXPECT_EQ(s.overruns, 1u);
  // An event task's allowance is its budget, however long since its last run.
  TaskAccounting ev(TaskKind::event, 0, 2 * kMs);
  ev.record_run(0, 0, kMs, kMs);
  ev.record_run(100 * kMs, 100 * kMs, 103 * kMs, 3 * kMs);
  EXPECT_EQ(ev.stats().overruns, 1u);
}

TEST(TaskAccounting, EventTasksNeverSlip) {
  TaskAccounting acc(TaskKind::event, 0, 2 * kMs);
  acc.record_run(0, 500 * kMs, 501 * kMs);
  EXPECT_EQ(acc.stats().slips, 0u);
  EXPECT_EQ(acc.stats().latency.max, 500 * kMs);
}

TEST(NextPeriodicDeadline, KeepsTheGridWhenOnTime) {
  std::uint64_t skipped = 99;
  EXPECT_EQ(next_periodic_deadline(0, 10 * kMs, 5 * kMs, skipped), 10 * kMs);
  EXPECT_EQ(skipped, 0u);
  // The next deadline has passed, but by less than a period: run at once.
  EXPECT_EQ(next_periodic_deadline(0, 10 * kMs, 19 * kMs, skipped), 10 * kMs);
  EXPECT_EQ(skipped, 0u);
}

TEST(NextPeriodicDeadline, DropsWholePeriodsThatAreLongGone) {
  std::uint64_t skipped = 0;
  EXPECT_EQ(next_periodic_deadline(0, 10 * kMs, 25 * kMs, skipped), 20 * kMs);
  EXPECT_EQ(skipped, 1u);
  EXPECT_EQ(next_periodic_deadline(100 * kMs, 10 * kMs, 147 * kMs, skipped), 140 * kMs);
  EXPECT_EQ(skipped, 3u);
}

TEST(RestedDeadline, SleepsThroughWholePeriodsNeverPastTheRest) {
  std::uint64_t rested = 99;
  // No rest, or one shorter than a period past the next deadline: unchanged.
  EXPECT_EQ(rested_deadline(10 * kMs, 10 * kMs, 1 * kMs, 0, rested), 10 * kMs);
  EXPECT_EQ(rested, 0u);
  EXPECT_EQ(rested_deadline(10 * kMs, 10 * kMs, 1 * kMs, 18 * kMs, rested), 10 * kMs);  // until 19 ms
  EXPECT_EQ(rested, 0u);
  // Until 20 ms: the 10 ms deadline is slept through, 20 ms is the next.
  EXPECT_EQ(rested_deadline(10 * kMs, 10 * kMs, 1 * kMs, 19 * kMs, rested), 20 * kMs);
  EXPECT_EQ(rested, 1u);
  // Until 47 ms: 10, 20 and 30 rested, 40 ms is the last deadline before it.
  EXPECT_EQ(rested_deadline(10 * kMs, 10 * kMs, 1 * kMs, 46 * kMs, rested), 40 * kMs);
  EXPECT_EQ(rested, 3u);
  EXPECT_EQ(rested_deadline(10 * kMs, 10 * kMs, 1 * kMs, -5 * kMs, rested), 10 * kMs);  // negative: none
  EXPECT_EQ(rested, 0u);
}

// --- task table validation ---

TEST(TaskSpec, ValidationNamesTheTaskAndTheField) {
  TaskSpec spec{"obstacles", TaskKind::periodic, 10.0, 200 * kMs, 50, -1};
  Status s = validate_task_spec(spec, 2);
  ASSERT_FALSE(s);
  EXPECT_NE(s.message().find("obstacles"), std::string::npos);
  EXPECT_NE(s.message().find("budget exceeds the period"), std::string::npos);

  spec.budget = 5 * kMs;
  spec.priority = 120;
  s = validate_task_spec(spec, 2);
  ASSERT_FALSE(s);
  EXPECT_NE(s.message().find("priority"), std::string::npos);

  spec.priority = 10;
  spec.cpu = 2;
  EXPECT_FALSE(validate_task_spec(spec, 2));
  spec.cpu = 1;
  EXPECT_TRUE(validate_task_spec(spec, 2));
}

class CountingTask final : public Task {
 public:
  void run(const TaskTick&) override { runs.fetch_add(1); }
  std::atomic<int> runs{0};
};

TEST(Scheduler, RejectsBadTableEntries) {
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  CountingTask task;
  TaskEvent event;
  EXPECT_TRUE(scheduler.add({"a", TaskKind::periodic, 100.0, kMs, 0, -1}, task));
  EXPECT_FALSE(scheduler.add({"a", TaskKind::periodic, 100.0, kMs, 0, -1}, task));  // duplicate
  EXPECT_FALSE(scheduler.add({"b", TaskKind::event, 0.0, kMs, 0, -1}, task));       // no event
  EXPECT_FALSE(scheduler.add({"c", TaskKind::periodic, 100.0, kMs, 0, -1}, task, &event));
  EXPECT_TRUE(scheduler.add({"d", TaskKind::event, 0.0, kMs, 0, -1}, task, &event));
  EXPECT_EQ(scheduler.task_count(), 2u);
}

// --- the scheduler driven by a simulated clock: exact accounting ---

// Each run "works" for a scripted time by advancing the simulated clock.
class ScriptedTask final : public Task {
 public:
  explicit ScriptedTask(SimulatedClock& clock) : clock_(clock) {}
  void run(const TaskTick& tick) override {
    const Nanos work = tick.cycle < work_.size() ? work_[tick.cycle] : 1 * kMs;
    clock_.advance_by(work);
  }
  std::array<Nanos, 16> work_{1 * kMs, 3 * kMs, 1 * kMs, 1 * kMs, 1 * kMs, 1 * kMs, 1 * kMs, 1 * kMs,
                              1 * kMs, 1 * kMs, 1 * kMs, 1 * kMs, 1 * kMs, 1 * kMs, 1 * kMs, 1 * kMs};

 private:
  SimulatedClock& clock_;
};

// Waits until the task has run `runs` times and is asleep again.
void wait_for(const Scheduler& scheduler, const SimulatedClock& clock, std::uint64_t runs) {
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (scheduler.stats(0).runs < runs || clock.sleepers() == 0) {
    ASSERT_LT(std::chrono::steady_clock::now(), give_up) << "task did not reach " << runs << " runs";
    std::this_thread::yield();
  }
}

TEST(Scheduler, CountsOverrunsSlipsAndSkipsExactlyOnSimulatedTime) {
  SimulatedClock clock(0);
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  ScriptedTask task(clock);
  ASSERT_TRUE(scheduler.add({"scripted", TaskKind::periodic, 100.0, 2 * kMs, 0, -1}, task));
  ASSERT_TRUE(scheduler.start());
  wait_for(scheduler, clock, 0);

  for (int k = 1; k <= 5; ++k) {  // cycles 0..4 on time; cycle 1 works 3 ms: one overrun
    clock.advance_to(k * 10 * kMs);
    wait_for(scheduler, clock, static_cast<std::uint64_t>(k));
  }
  // Cycle 5 (deadline 60 ms) starts at 75 ms: a slip. It ends at 76 ms; the
  // 70 ms deadline has passed by less than a period, so cycle 6 runs at once.
  clock.advance_to(75 * kMs);
  wait_for(scheduler, clock, 7);
  clock.advance_to(80 * kMs);
  wait_for(scheduler, clock, 8);
  // Cycle 8 (deadline 90 ms) starts at 125 ms: a slip; it ends at 126 ms, so
  // the 100 and 110 ms deadlines are dropped and cycle 9 runs at once for 120 ms.
  clock.advance_to(125 * kMs);
  wait_for(scheduler, clock, 10);
  scheduler.stop();

  const TaskStats s = scheduler.stats(0);
  EXPECT_EQ(s.runs, 10u);
  EXPECT_EQ(s.overruns, 1u);
  EXPECT_EQ(s.slips, 2u);
  EXPECT_EQ(s.skipped_periods, 2u);
  EXPECT_EQ(s.execution.max, 3 * kMs);
  EXPECT_EQ(s.execution.min, 1 * kMs);
  EXPECT_EQ(s.latency.min, 0);
  EXPECT_EQ(s.latency.max, 35 * kMs);
}

// A task that asks to rest for a scripted time after each run.
class RestingTask final : public Task {
 public:
  explicit RestingTask(SimulatedClock& clock) : clock_(clock) {}
  void run(const TaskTick& tick) override {
    clock_.advance_by(kMs);
    started.push_back(tick.started);  // test thread reads after stop()
    next_rest = tick.cycle < rests.size() ? rests[tick.cycle] : 0;
  }
  Nanos rest() noexcept override { return next_rest; }
  std::array<Nanos, 4> rests{35 * kMs, 0, 9 * kMs, 19 * kMs};
  std::vector<Nanos> started;
  Nanos next_rest = 0;

 private:
  SimulatedClock& clock_;
};

TEST(Scheduler, ARestingTaskSleepsThroughWholePeriodsAndRunsOnTheGrid) {
  SimulatedClock clock(0);
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  RestingTask task(clock);
  task.started.reserve(16);
  ASSERT_TRUE(scheduler.add({"resting", TaskKind::periodic, 100.0, 2 * kMs, 0, -1}, task));
  ASSERT_TRUE(scheduler.start());
  wait_for(scheduler, clock, 0);
  clock.advance_to(10 * kMs);
  wait_for(scheduler, clock, 1);
  // Cycle 0 ends at 11 ms and rests 35 ms, until 46 ms: the 20 and 30 ms
  // deadlines are slept through (the run at 40 ms is still within the rest,
  // but the one after it would not be), so the next run is at 40 ms.
  clock.advance_to(30 * kMs);
  ASSERT_EQ(scheduler.stats(0).runs, 1u);
  clock.advance_to(40 * kMs);
  wait_for(scheduler, clock, 2);
  // Cycle 1 asks for no rest: 50 ms. Cycle 2 (50 ms) rests 9 ms, until
  // 60 ms, which is the next deadline anyway: nothing rested.
  clock.advance_to(50 * kMs);
  wait_for(scheduler, clock, 3);
  clock.advance_to(60 * kMs);
  wait_for(scheduler, clock, 4);
  // Cycle 3 (60 ms) rests 19 ms, until 80 ms: 70 rested, 80 ms next.
  clock.advance_to(70 * kMs);
  ASSERT_EQ(scheduler.stats(0).runs, 4u);
  clock.advance_to(80 * kMs);
  wait_for(scheduler, clock, 5);
  scheduler.stop();

  const TaskStats s = scheduler.stats(0);
  EXPECT_EQ(s.runs, 5u);
  EXPECT_EQ(s.rested_periods, 3u);
  EXPECT_EQ(s.skipped_periods, 0u);
  EXPECT_EQ(s.slips, 0u);
  EXPECT_EQ(s.overruns, 0u);  // 1 ms of CPU against 2 ms per period of input
  ASSERT_EQ(task.started.size(), 5u);
  EXPECT_EQ(task.started[0], 10 * kMs);
  EXPECT_EQ(task.started[1], 40 * kMs);
  EXPECT_EQ(task.started[2], 50 * kMs);
  EXPECT_EQ(task.started[3], 60 * kMs);
  EXPECT_EQ(task.started[4], 80 * kMs);
}

// A task that rests long and gives a pipe's read end as its wake-up
// descriptor: each run drains the pipe and notes when it started.
class DescriptorTask final : public Task {
 public:
  DescriptorTask(int fd, Nanos rest, bool watch = true) : fd_(fd), rest_(rest), watch_(watch) { started.reserve(64); }
  void run(const TaskTick& tick) override {
    char buffer[16];
    while (read(fd_, buffer, sizeof buffer) > 0) ++drained;
    started.push_back(tick.started);  // the test thread reads after stop()
    scheduled.push_back(tick.scheduled);
    runs.fetch_add(1, std::memory_order_release);
  }
  Nanos rest() noexcept override { return rest_; }
  int wake_fd() const noexcept override { return fd_; }
  bool watching() noexcept override { return watch_; }
  std::vector<Nanos> started, scheduled;
  int drained = 0;
  std::atomic<int> runs{0};

 private:
  int fd_;
  Nanos rest_;
  bool watch_;
};

struct Pipe {
  Pipe() {
    EXPECT_EQ(pipe2(fds, O_NONBLOCK | O_CLOEXEC), 0);
  }
  ~Pipe() {
    close(fds[0]);
    close(fds[1]);
  }
  int fds[2] = {-1, -1};
};

TEST(Scheduler, ARestIsEndedAtOnceByTheTasksDescriptor) {
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  Pipe p;
  // 100 Hz, resting 20 s after each run: only the pipe can wake it in time.
  DescriptorTask task(p.fds[0], 20'000 * kMs);
  ASSERT_TRUE(scheduler.add({"watching", TaskKind::periodic, 100.0, 5 * kMs, 0, -1}, task));
  ASSERT_TRUE(scheduler.start());
  for (int k = 0; k < 2000 && task.runs.load(std::memory_order_acquire) < 1; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_EQ(task.runs.load(std::memory_order_acquire), 1);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(task.runs.load(std::memory_order_acquire), 1);  // resting
  Nanos written = 0;
  for (int wake = 0; wake < 2; ++wake) {
    written = clock.now();
    ASSERT_EQ(write(p.fds[1], "x", 1), 1);
    // Woken by the byte, not by the end of the 20 s rest.
    for (int k = 0; k < 10'000 && task.runs.load(std::memory_order_acquire) < 2 + wake; ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    ASSERT_EQ(task.runs.load(std::memory_order_acquire), 2 + wake);
  }
  scheduler.stop();
  ASSERT_EQ(task.started.size(), 3u);
  EXPECT_EQ(task.drained, 2);
  // The woken run starts at its wake-up, off the 10 ms grid: its deadline is
  // when the descriptor woke the thread, after the byte was written.
  EXPECT_GE(task.scheduled[2], written);
  EXPECT_LE(task.scheduled[2], task.started[2]);
  EXPECT_LT(task.started[2] - written, 10'000 * kMs);
  const TaskStats s = scheduler.stats(0);
  EXPECT_EQ(s.runs, 3u);
  // The periods that passed while it rested, counted when it woke: at least
  // the 50 ms waited before the first byte, far fewer than 2 x 20 s.
  EXPECT_GE(s.rested_periods, 4u);
  EXPECT_LT(s.rested_periods, 1000u);
  // A period is skipped only when a run ends a whole period after its
  // deadline: the thread kept off its core (a busy machine, once seen). Not
  // more than the latencies and run times that really happened account for.
  const auto late_periods = static_cast<std::uint64_t>((s.latency.max + s.execution.max) / (10 * kMs));
  EXPECT_LE(s.skipped_periods, s.runs * late_periods)
      << "latency max " << s.latency.max << " ns, run max " << s.execution.max << " ns";
}

// Without a rest, a watching task's sleep to its next period ends when the
// descriptor is readable (the lidar task near a revolution's end); a task
// that does not watch sleeps its whole period whatever the descriptor says.
TEST(Scheduler, AWatchingTasksSleepToTheNextPeriodEndsAtTheDescriptor) {
  for (const bool watch : {true, false}) {
    MonotonicClock clock;
    Scheduler scheduler(clock, {RealtimePolicy::off, false});
    Pipe p;
    DescriptorTask task(p.fds[0], 0, watch);
    ASSERT_TRUE(scheduler.add({"watching", TaskKind::periodic, 0.5, 50 * kMs, 0, -1}, task));  // 2 s period
    ASSERT_TRUE(scheduler.start());
    for (int k = 0; k < 5000 && task.runs.load(std::memory_order_acquire) < 1; ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    ASSERT_EQ(task.runs.load(std::memory_order_acquire), 1);
    const Nanos written = clock.now();
    ASSERT_EQ(write(p.fds[1], "x", 1), 1);
    for (int k = 0; k < 10'000 && task.runs.load(std::memory_order_acquire) < 2; ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    scheduler.stop();
    ASSERT_GE(task.started.size(), 2u) << "watch " << watch;
    if (watch) {
      // Woken by the byte: at least a little after it was written, and
      // (a run never comes early) before the period would have ended.
      EXPECT_GE(task.scheduled[1], written);
      EXPECT_LT(task.scheduled[1], task.scheduled[0] + 2000 * kMs);
    } else {
      // On the grid: a whole period after the first run's deadline.
      EXPECT_EQ(task.scheduled[1], task.scheduled[0] + 2000 * kMs);
      EXPECT_GE(task.started[1], task.scheduled[0] + 2000 * kMs);
    }
    EXPECT_EQ(scheduler.stats(0).rested_periods, 0u);
  }
}

TEST(Scheduler, OnAClockThatCannotWaitOnDescriptorsATaskWithOneDoesNotRest) {
  SimulatedClock clock(0);
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  Pipe p;
  DescriptorTask task(p.fds[0], 35 * kMs);
  ASSERT_TRUE(scheduler.add({"watching", TaskKind::periodic, 100.0, 5 * kMs, 0, -1}, task));
  ASSERT_TRUE(scheduler.start());
  wait_for(scheduler, clock, 0);
  for (int k = 1; k <= 5; ++k) {
    clock.advance_to(k * 10 * kMs);
    wait_for(scheduler, clock, static_cast<std::uint64_t>(k));
  }
  scheduler.stop();
  const TaskStats s = scheduler.stats(0);
  EXPECT_EQ(s.runs, 5u);  // every period: a simulated clock never sees the pipe
  EXPECT_EQ(s.rested_periods, 0u);
  ASSERT_EQ(task.started.size(), 5u);
  EXPECT_EQ(task.started[4], 50 * kMs);
}

// Two tasks naming one thread: each period they run one after another on
// that thread (in the order added), each with its own figures; one sleeper
// waits for both; the thread rests only as long as both tasks can.
class SharingTask final : public Task {
 public:
  SharingTask(SimulatedClock& clock, Nanos work, char tag, std::string& log) : clock_(clock), work_(work), tag_(tag), log_(log) {}
  void run(const TaskTick& tick) override {
    clock_.advance_by(work_);
    log_.push_back(tag_);
    threads.push_back(std::this_thread::get_id());
    char name[16] = {};
    pthread_getname_np(pthread_self(), name, sizeof name);
    thread_name = name;
    deadlines.push_back(tick.scheduled);
  }
  Nanos rest() noexcept override { return rest_for.load(); }
  std::vector<std::thread::id> threads;
  std::vector<Nanos> deadlines;
  std::string thread_name;
  std::atomic<Nanos> rest_for{0};

 private:
  SimulatedClock& clock_;
  Nanos work_;
  char tag_;
  std::string& log_;
};

TEST(Scheduler, PeriodicTasksSharingAThreadRunInTurnOnItEachMeasuredOnItsOwn) {
  SimulatedClock clock(0);
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  std::string log;
  log.reserve(64);
  SharingTask a(clock, kMs, 'a', log), b(clock, 2 * kMs, 'b', log);
  for (SharingTask* t : {&a, &b}) {
    t->threads.reserve(16);
    t->deadlines.reserve(16);
    t->thread_name.reserve(16);
  }
  a.rest_for = 35 * kMs;  // b does not rest: neither does the thread
  TaskSpec sa{"a", TaskKind::periodic, 100.0, 2 * kMs, 0, -1, "pair"};
  TaskSpec sb{"b", TaskKind::periodic, 100.0, kMs, 0, -1, "pair"};
  ASSERT_TRUE(scheduler.add(sa, a));
  ASSERT_TRUE(scheduler.add(sb, b));
  ASSERT_TRUE(scheduler.start());
  wait_for(scheduler, clock, 0);
  EXPECT_EQ(clock.sleepers(), 1u);  // one thread for both
  clock.advance_to(10 * kMs);
  wait_for(scheduler, clock, 1);
  clock.advance_to(20 * kMs);
  wait_for(scheduler, clock, 2);
  b.rest_for = 35 * kMs;  // read after b's next run: now both can rest
  clock.advance_to(30 * kMs);
  wait_for(scheduler, clock, 3);
  // Cycle 2 ran at 30 ms and ended at 33 ms; resting until 68 ms sleeps
  // through 40 and 50 ms (the run at 60 ms is still within the rest).
  clock.advance_to(50 * kMs);
  ASSERT_EQ(scheduler.stats(0).runs, 3u);
  clock.advance_to(60 * kMs);
  wait_for(scheduler, clock, 4);
  scheduler.stop();

  EXPECT_EQ(log, "abababab");
  ASSERT_EQ(a.threads.size(), 4u);
  ASSERT_EQ(b.threads.size(), 4u);
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(a.threads[i], b.threads[i]);
    EXPECT_EQ(a.deadlines[i], b.deadlines[i]);  // one period, one deadline
  }
  EXPECT_EQ(a.thread_name, "pair");
  const TaskStats ta = scheduler.stats(0), tb = scheduler.stats(1);
  EXPECT_EQ(ta.runs, 4u);
  EXPECT_EQ(tb.runs, 4u);
  EXPECT_EQ(ta.execution.max, kMs);
  EXPECT_EQ(tb.execution.max, 2 * kMs);
  EXPECT_EQ(ta.latency.max, 0);
  EXPECT_EQ(tb.latency.max, kMs);  // b starts when a is done
  EXPECT_EQ(ta.overruns, 0u);
  // 2 ms of work against b's own 1 ms, but the run after the rest drains
  // three periods of input: an allowance of 3 ms.
  EXPECT_EQ(tb.overruns, 3u);
  // 40 and 50 ms, then 70 and 80 ms after the last run (it rested too).
  EXPECT_EQ(ta.rested_periods, 4u);
  EXPECT_EQ(tb.rested_periods, 4u);
}

TEST(Scheduler, OnlyPeriodicTasksOfOneRatePriorityAndCpuShareAThread) {
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  CountingTask task;
  TaskEvent event;
  ASSERT_TRUE(scheduler.add({"imu", TaskKind::periodic, 100.0, kMs, 65, -1, "sensors"}, task));
  Status s = scheduler.add({"can", TaskKind::periodic, 200.0, kMs, 65, -1, "sensors"}, task);
  EXPECT_EQ(s.message(),
            "task 'can': thread 'sensors' runs task 'imu' at 100 Hz, priority 65, cpu -1; a task sharing it needs the "
            "same (this one: 200 Hz, priority 65, cpu -1)");
  EXPECT_FALSE(scheduler.add({"gps", TaskKind::periodic, 100.0, kMs, 60, -1, "sensors"}, task));
  EXPECT_TRUE(scheduler.add({"pose", TaskKind::periodic, 100.0, kMs, 65, -1, "sensors"}, task));
  EXPECT_TRUE(scheduler.add({"other", TaskKind::periodic, 200.0, kMs, 0, -1, "other-thread"}, task));
  s = scheduler.add({"obstacles", TaskKind::event, 0.0, kMs, 0, -1, "sensors"}, task, &event);
  EXPECT_NE(s.message().find("an event-driven task runs on a thread of its own"), std::string::npos) << s.message();
  s = scheduler.add({"x", TaskKind::periodic, 100.0, kMs, 0, -1, "a-very-long-thread-name"}, task);
  EXPECT_NE(s.message().find("thread name is longer than 15"), std::string::npos) << s.message();
}

// --- the scheduler on the real clock ---

TEST(Scheduler, RunsPeriodicTasksAtTheirRateAndEventTasksOnSignal) {
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  CountingTask periodic;
  CountingTask on_event;
  TaskEvent event;
  ASSERT_TRUE(scheduler.add({"periodic", TaskKind::periodic, 200.0, 2 * kMs, 0, -1}, periodic));
  ASSERT_TRUE(scheduler.add({"on-event", TaskKind::event, 0.0, 2 * kMs, 0, -1}, on_event, &event));
  const Nanos started = clock.now();
  ASSERT_TRUE(scheduler.start());
  for (int i = 0; i < 20; ++i) {
    event.signal(clock.now());
    std::this_thread::sleep_for(std::chrono::milliseconds(15));
  }
  scheduler.stop();
  const Nanos elapsed = clock.now() - started;
  // About 300 ms at 200 Hz is 60 runs; allow for a loaded CI machine below,
  // and never more than one run per 5 ms period of the time it really ran
  // (sleeps overshoot under load, so that is more than 300 ms).
  EXPECT_GE(periodic.runs.load(), 30);
  EXPECT_LE(periodic.runs.load(), static_cast<int>(elapsed / (5 * kMs)) + 2);
  // Signals 15 ms apart each wake the task once (coalescing allowed under load).
  EXPECT_GE(on_event.runs.load(), 10);
  EXPECT_LE(on_event.runs.load(), 20);
  EXPECT_EQ(scheduler.stats(1).runs, static_cast<std::uint64_t>(on_event.runs.load()));
}

TEST(Scheduler, StopsPromptlyEvenForSlowTasks) {
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  CountingTask slow;
  CountingTask waiting;
  TaskEvent never;
  ASSERT_TRUE(scheduler.add({"slow", TaskKind::periodic, 0.2, kMs, 0, -1}, slow));
  ASSERT_TRUE(scheduler.add({"waiting", TaskKind::event, 0.0, kMs, 0, -1}, waiting, &never));
  ASSERT_TRUE(scheduler.start());
  const auto t0 = std::chrono::steady_clock::now();
  scheduler.stop();
  const auto elapsed = std::chrono::steady_clock::now() - t0;
  EXPECT_LT(elapsed, std::chrono::milliseconds(500));
  EXPECT_EQ(slow.runs.load(), 0);
  EXPECT_EQ(waiting.runs.load(), 0);
}

// A task that waits 5 ms inside its run uses almost no CPU time: over its
// 1 ms budget by the clock, a stall; one that computes until it has used
// 5 ms of CPU time overruns.
class WaitingTask final : public Task {
 public:
  explicit WaitingTask(bool spin) : spin_(spin) {}
  void run(const TaskTick&) override {
    if (spin_) {
      MonotonicClock clock;
      const Nanos end = clock.thread_cpu_time() + 5 * kMs;
      while (clock.thread_cpu_time() < end) {
      }
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    runs.fetch_add(1);
  }
  std::atomic<int> runs{0};

 private:
  bool spin_;
};

TEST(Scheduler, BudgetsAreCpuTimeAndTimeOffTheCoreIsAStall) {
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  WaitingTask sleeper(false);
  WaitingTask spinner(true);
  ASSERT_TRUE(scheduler.add({"sleeper", TaskKind::periodic, 50.0, kMs, 0, -1}, sleeper));
  ASSERT_TRUE(scheduler.add({"spinner", TaskKind::periodic, 50.0, kMs, 0, -1}, spinner));
  ASSERT_TRUE(scheduler.start());
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while ((sleeper.runs.load() < 3 || spinner.runs.load() < 3) && std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  scheduler.stop();
  const TaskStats slept = scheduler.stats(0);
  const TaskStats spun = scheduler.stats(1);
  ASSERT_GE(slept.runs, 3u);
  ASSERT_GE(spun.runs, 3u);
  EXPECT_EQ(slept.overruns, 0u);
  EXPECT_EQ(slept.stalls, slept.runs);
  EXPECT_EQ(spun.overruns, spun.runs);
  EXPECT_EQ(spun.stalls, 0u);
}

TEST(Scheduler, CanBeRestarted) {
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  CountingTask task;
  ASSERT_TRUE(scheduler.add({"restart", TaskKind::periodic, 500.0, kMs, 0, -1}, task));
  for (int round = 0; round < 2; ++round) {
    ASSERT_TRUE(scheduler.start());
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    scheduler.stop();
  }
  EXPECT_GE(task.runs.load(), 10);
}

}  // namespace
}  // namespace trailnav
