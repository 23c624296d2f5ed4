// The fixed-rate scheduler. One task table states, for every task, its name,
// kind (periodic at a rate, or event-driven), time budget, priority and CPU;
// the scheduler runs each task on its own thread (or periodic tasks of one
// rate on a thread they share, TaskSpec::thread) and measures it against that
// table: runs, overruns (more CPU time than the budget; a periodic run after a
// delay has a budget per period of input it drains), stalls (over budget
// by the clock while the task's own CPU time stayed within it: the thread
// lost its core mid-run to the kernel, the hypervisor or a higher priority),
// slips (start more than one period after the deadline), skipped periods, and
// execution-time (by the clock), CPU-time and wake-up-latency distributions,
// all readable at any time without locks.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "trailnav/runtime/clock.hpp"
#include "trailnav/runtime/histogram.hpp"
#include "trailnav/runtime/status.hpp"

namespace trailnav {

enum class TaskKind : std::uint8_t { periodic, event };

struct TaskSpec {
  std::string name;
  TaskKind kind = TaskKind::periodic;
  double rate_hz = 0.0;  // periodic tasks: runs per second
  Nanos budget = 0;      // CPU time allowed per run
  int priority = 0;      // 0: normal scheduling; 1..99: SCHED_FIFO priority
  int cpu = -1;          // CPU to pin the task's thread to; -1: any
  // Periodic tasks naming the same thread here share it (they must have the
  // same rate, priority and CPU): each period they run one after another, in
  // the order they were added, each measured on its own. One wake-up serves
  // them all (a wake-up costs 25-55 us of CPU on a virtual machine,
  // docs/performance.md). Empty: the task has a thread of its own, named
  // after it.
  std::string thread{};

  Nanos period() const noexcept {
    return kind == TaskKind::periodic && rate_hz > 0.0 ? static_cast<Nanos>(1e9 / rate_hz) : 0;
  }
};

// Checks one entry of the task table; the message names the task and the field.
Status validate_task_spec(const TaskSpec& spec, int cpu_count);
// Checks that `spec` may share a thread with `other` (TaskSpec::thread): ok
// when they name different threads or none, or agree on rate, priority and CPU.
Status validate_thread_sharing(const TaskSpec& spec, const TaskSpec& other);

struct TaskTick {
  std::uint64_t cycle = 0;  // 0 for the first run
  Nanos scheduled = 0;      // deadline (periodic) or signal time (event)
  Nanos started = 0;        // when the run began
};

class Task {
 public:
  virtual ~Task() = default;
  virtual void run(const TaskTick& tick) = 0;
  // Asked by the scheduler right after each run of a periodic task: for how
  // long the task can do without running (0: it runs next period, as always).
  // The scheduler then sleeps through the whole periods that fit in that
  // time, counted as rested, never past it: the deadlines stay on the
  // period's grid, and the next run drains those periods' input with one
  // allowance per period. A task whose input matters only at known moments
  // (the lidar's, where a revolution ends) saves the wake-ups in between,
  // which on a virtual machine cost 25-55 us of CPU each (docs/performance.md).
  virtual Nanos rest() noexcept { return 0; }
  // A descriptor whose readiness can end the task's sleep at once (-1:
  // none), for input that must be acted on without delay: the e-stop line's
  // edges, or the lidar packet that completes a revolution. Asked once, when
  // the scheduler starts.
  virtual int wake_fd() const noexcept { return -1; }
  // Asked after each run of a task with a wake_fd: whether the coming sleep
  // (a rest, or only to the next period) ends when that descriptor is
  // readable. A task that watches rests only where the clock can wait on
  // descriptors (Clock::wakes_on_descriptors): elsewhere, as on a simulated
  // clock, its rest is ignored and it runs every period. A run woken by its
  // descriptor starts at once, off the period's grid (its deadline is the
  // wake-up), and the grid goes on from there.
  virtual bool watching() noexcept { return true; }
};

// Wakes an event-driven task. Producers call signal(); several signals before
// the task runs coalesce into one run (the task drains its queues).
class TaskEvent {
 public:
  // Wait-free for the producer.
  void signal(Nanos when) noexcept {
    last_signal_.store(when, std::memory_order_relaxed);
    count_.fetch_add(1, std::memory_order_release);
    count_.notify_one();
  }
  Nanos last_signal() const noexcept { return last_signal_.load(std::memory_order_relaxed); }

  // Task side: blocks until a signal newer than `seen`; false once interrupted.
  bool wait(std::uint32_t& seen) noexcept;
  void interrupt() noexcept;
  void resume() noexcept { interrupted_.store(false, std::memory_order_release); }

 private:
  std::atomic<std::uint32_t> count_{0};
  std::atomic<Nanos> last_signal_{0};
  std::atomic<bool> interrupted_{false};
};

struct TaskStats {
  std::uint64_t runs = 0;
  std::uint64_t overruns = 0;  // runs that used more CPU time than the budget
  std::uint64_t stalls = 0;    // runs over budget by the clock only (the thread was kept off its core)
  std::uint64_t slips = 0;
  std::uint64_t skipped_periods = 0;
  std::uint64_t rested_periods = 0;  // slept through because the task asked to rest (Task::rest)
  DurationSummary execution;
  DurationSummary latency;  // start minus deadline (periodic) or minus signal (event)
  Nanos cpu_max = 0;        // most CPU time one run used
  DurationSummary cpu_per_period;  // CPU time of a run per period of input it drained (record_run)
};

// The bookkeeping for one task, separate from any thread so that it can be
// tested on its own. Single writer (the task's thread), lock-free readers.
class TaskAccounting {
 public:
  TaskAccounting(TaskKind kind, Nanos period, Nanos budget) noexcept
      : kind_(kind), period_(period), budget_(budget) {}

  // `cpu`: the CPU time the run used (by default all of its clock time).
  //
  // A periodic task drains what arrived since its last run, so a run that
  // starts k periods after the one before (the thread was delayed) has k
  // periods of input and k budgets: the allowance is budget x max(1, time
  // since the last start / period). Overruns and stalls are held against the
  // allowance; the CPU distribution is per period of input (cpu / k), the
  // figure a budget is chosen from. An event task's allowance is its budget.
  void record_run(Nanos scheduled, Nanos started, Nanos finished, Nanos cpu = -1) noexcept {
    const Nanos latency = started - scheduled;
    const Nanos execution = finished - started;
    if (cpu < 0) cpu = execution;
    double periods = 1.0;
    if (kind_ == TaskKind::periodic && period_ > 0) {
      const Nanos since = started - (last_started_ != kNever ? last_started_ : scheduled - period_);
      periods = std::max(1.0, static_cast<double>(since) / static_cast<double>(period_));
      last_started_ = started;
    }
    const auto allowance = static_cast<Nanos>(static_cast<double>(budget_) * periods);
    runs_.fetch_add(1, std::memory_order_relaxed);
    if (cpu > cpu_max_.load(std::memory_order_relaxed)) cpu_max_.store(cpu, std::memory_order_relaxed);
    if (cpu > allowance) {
      overruns_.fetch_add(1, std::memory_order_relaxed);
    } else if (execution > allowance) {
      stalls_.fetch_add(1, std::memory_order_relaxed);
    }
    if (kind_ == TaskKind::periodic && latency > period_) slips_.fetch_add(1, std::memory_order_relaxed);
    execution_.record(execution);
    latency_.record(latency);
    cpu_per_period_.record(static_cast<Nanos>(static_cast<double>(cpu) / periods));
  }
  void record_skipped(std::uint64_t periods) noexcept { skipped_.fetch_add(periods, std::memory_order_relaxed); }
  void record_rested(std::uint64_t periods) noexcept { rested_.fetch_add(periods, std::memory_order_relaxed); }

  TaskStats stats() const noexcept {
    TaskStats s;
    s.runs = runs_.load(std::memory_order_relaxed);
    s.overruns = overruns_.load(std::memory_order_relaxed);
    s.stalls = stalls_.load(std::memory_order_relaxed);
    s.cpu_max = cpu_max_.load(std::memory_order_relaxed);
    s.slips = slips_.load(std::memory_order_relaxed);
    s.skipped_periods = skipped_.load(std::memory_order_relaxed);
    s.rested_periods = rested_.load(std::memory_order_relaxed);
    s.execution = execution_.summary();
    s.latency = latency_.summary();
    s.cpu_per_period = cpu_per_period_.summary();
    return s;
  }

 private:
  TaskKind kind_;
  Nanos period_;
  Nanos budget_;
  std::atomic<std::uint64_t> runs_{0};
  std::atomic<std::uint64_t> overruns_{0};
  std::atomic<std::uint64_t> stalls_{0};
  std::atomic<Nanos> cpu_max_{0};  // single writer: load and store suffice
  std::atomic<std::uint64_t> slips_{0};
  std::atomic<std::uint64_t> skipped_{0};
  std::atomic<std::uint64_t> rested_{0};
  DurationHistogram execution_;
  DurationHistogram latency_;
  DurationHistogram cpu_per_period_;
  static constexpr Nanos kNever = INT64_MIN;
  Nanos last_started_ = kNever;  // the task's own thread only
};

// After a periodic run that ended at `finished`, the next deadline to sleep
// to: `scheduled + period`, moved on by whole periods while that deadline
// lies a full period or more in the past (the dropped periods are returned in
// `skipped`), so a late task catches up without a burst of runs.
Nanos next_periodic_deadline(Nanos scheduled, Nanos period, Nanos finished, std::uint64_t& skipped) noexcept;

// The deadline after a rest: `next` moved on by the whole periods that end
// no later than `finished + rest` (their count in `rested`); `next` itself
// when the rest is shorter than a period past it. Never past the rest's end.
Nanos rested_deadline(Nanos next, Nanos period, Nanos finished, Nanos rest, std::uint64_t& rested) noexcept;

enum class RealtimePolicy : std::uint8_t {
  off,          // normal scheduling, no memory locking
  best_effort,  // SCHED_FIFO and mlockall when permitted, one warning when not
  required,     // start() fails when either is not permitted
};

struct SchedulerOptions {
  RealtimePolicy realtime = RealtimePolicy::best_effort;
  bool lock_memory = true;
};

class Scheduler {
 public:
  Scheduler(Clock& clock, SchedulerOptions options);
  ~Scheduler();
  Scheduler(const Scheduler&) = delete;
  Scheduler& operator=(const Scheduler&) = delete;

  // Before start(). Event tasks need `event`; periodic tasks must not have one.
  // Tasks are indexed in the order added (for stats()); an error names the task.
  Status add(const TaskSpec& spec, Task& task, TaskEvent* event = nullptr);

  // Spawns one thread per task (or per shared thread), marks each as a
  // real-time thread for the allocation guard, and returns once every thread
  // is running.
  Status start();
  // Stops every task after its current run and joins the threads.
  void stop();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }

  std::size_t task_count() const noexcept { return entries_.size(); }
  const TaskSpec& spec(std::size_t index) const noexcept { return entries_[index]->spec; }
  TaskStats stats(std::size_t index) const noexcept { return entries_[index]->accounting.stats(); }
  // Whether SCHED_FIFO was granted to the tasks that asked for it.
  bool realtime_active() const noexcept { return realtime_active_; }
  bool memory_locked() const noexcept { return memory_locked_; }

 private:
  struct Entry {
    Entry(const TaskSpec& s, Task& t, TaskEvent* e)
        : spec(s), task(t), event(e), accounting(s.kind, s.period(), s.budget) {}
    TaskSpec spec;
    Task& task;
    TaskEvent* event;
    TaskAccounting accounting;
  };
  // A thread and the tasks it runs (one, or the periodic tasks sharing it).
  struct Thread {
    std::string name;
    std::vector<Entry*> entries;
    std::vector<int> wake_fds;  // the entries' Task::wake_fd, gathered at start
    std::thread thread;
  };

  void thread_main(Thread& thread) noexcept;
  void run_periodic(Thread& thread) noexcept;
  void run_event(Entry& entry) noexcept;
  void apply_thread_settings(const Thread& thread) noexcept;

  Clock& clock_;
  SchedulerOptions options_;
  std::vector<std::unique_ptr<Entry>> entries_;
  std::vector<std::unique_ptr<Thread>> threads_;  // made by start()
  std::atomic<bool> running_{false};
  std::atomic<int> threads_ready_{0};
  std::atomic<int> realtime_failures_{0};
  bool realtime_active_ = false;
  bool memory_locked_ = false;
};

}  // namespace trailnav
