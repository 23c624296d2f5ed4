#include "trailnav/runtime/scheduler.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/log.hpp"

namespace trailnav {

Status validate_task_spec(const TaskSpec& spec, int cpu_count) {
  const std::string who = "task '" + spec.name + "': ";
  if (spec.name.empty()) return Status::error("task without a name: every task needs a unique name");
  if (spec.name.size() > 15) return Status::error(who + "name is longer than 15 characters (thread names are limited to 15)");
  if (spec.kind == TaskKind::periodic && !(spec.rate_hz > 0.0 && spec.rate_hz <= 10'000.0)) {
    return Status::error(who + "rate_hz must be in (0, 10000] for a periodic task");
  }
  if (spec.kind == TaskKind::event && spec.rate_hz != 0.0) {
    return Status::error(who + "an event-driven task has no rate_hz; it runs when its data arrives");
  }
  if (spec.budget <= 0) return Status::error(who + "budget must be positive");
  if (spec.kind == TaskKind::periodic && spec.budget > spec.period()) {
    return Status::error(who + "budget exceeds the period (1/rate_hz); the task could never keep its rate");
  }
  if (spec.priority < 0 || spec.priority > 99) return Status::error(who + "priority must be in [0, 99] (0: normal scheduling)");
  if (spec.cpu < -1 || spec.cpu >= cpu_count) {
    return Status::error(who + "cpu must be -1 (any) or in [0, " + std::to_string(cpu_count - 1) + "]");
  }
  if (spec.thread.size() > 15) {
    return Status::error(who + "thread name is longer than 15 characters (thread names are limited to 15)");
  }
  if (!spec.thread.empty() && spec.kind == TaskKind::event) {
    return Status::error(who + "an event-driven task runs on a thread of its own: only periodic tasks share a thread");
  }
  return Status::ok();
}

Status validate_thread_sharing(const TaskSpec& spec, const TaskSpec& other) {
  if (spec.thread.empty() || other.thread != spec.thread) return Status::ok();
  if (other.rate_hz == spec.rate_hz && other.priority == spec.priority && other.cpu == spec.cpu) return Status::ok();
  char text[320];
  std::snprintf(text, sizeof text,
                "task '%s': thread '%s' runs task '%s' at %g Hz, priority %d, cpu %d; a task sharing it needs the same "
                "(this one: %g Hz, priority %d, cpu %d)",
                spec.name.c_str(), spec.thread.c_str(), other.name.c_str(), other.rate_hz, other.priority, other.cpu,
                spec.rate_hz, spec.priority, spec.cpu);
  return Status::error(text);
}

namespace {

// `next` moved on by whole periods while it lies a full period or more
// before `until` (their count in `moved`): the deadline grid arithmetic of
// both functions below.
Nanos advance_whole_periods(Nanos next, Nanos period, Nanos until, std::uint64_t& moved) noexcept {
  moved = 0;
  if (until - next >= period) {
    moved = static_cast<std::uint64_t>((until - next) / period);
    next += static_cast<Nanos>(moved) * period;
  }
  return next;
}

}  // namespace

Nanos next_periodic_deadline(Nanos scheduled, Nanos period, Nanos finished, std::uint64_t& skipped) noexcept {
  return advance_whole_periods(scheduled + period, period, finished, skipped);
}

Nanos rested_deadline(Nanos next, Nanos period, Nanos finished, Nanos rest, std::uint64_t& rested) noexcept {
  rested = 0;
  if (rest <= 0 || period <= 0) return next;
  return advance_whole_periods(next, period, finished + rest, rested);
}

bool TaskEvent::wait(std::uint32_t& seen) noexcept {
  for (;;) {
    if (interrupted_.load(std::memory_order_acquire)) return false;
    const std::uint32_t current = count_.load(std::memory_order_acquire);
    if (current != seen) {
      seen = current;
      return true;
    }
    count_.wait(current, std::memory_order_acquire);
  }
}

void TaskEvent::interrupt() noexcept {
  interrupted_.store(true, std::memory_order_release);
  count_.fetch_add(1, std::memory_order_release);
  count_.notify_all();
}

Scheduler::Scheduler(Clock& clock, SchedulerOptions options) : clock_(clock), options_(options) {}

Scheduler::~Scheduler() { stop(); }

Status Scheduler::add(const TaskSpec& spec, Task& task, TaskEvent* event) {
  if (running()) return Status::error("task '" + spec.name + "': tasks must be added before start()");
  const int cpus = static_cast<int>(std::thread::hardware_concurrency());
  if (Status s = validate_task_spec(spec, cpus > 0 ? cpus : 1); !s) return s;
  for (const auto& e : entries_) {
    if (e->spec.name == spec.name) return Status::error("task '" + spec.name + "': name used twice in the task table");
  }
  if (spec.kind == TaskKind::event && event == nullptr) {
    return Status::error("task '" + spec.name + "': an event-driven task needs the event that wakes it");
  }
  if (spec.kind == TaskKind::periodic && event != nullptr) {
    return Status::error("task '" + spec.name + "': a periodic task is woken by its rate, not by an event");
  }
  for (const auto& e : entries_) {
    if (Status s = validate_thread_sharing(spec, e->spec); !s) return s;
  }
  entries_.push_back(std::make_unique<Entry>(spec, task, event));
  return Status::ok();
}

Status Scheduler::start() {
  if (running()) return Status::error("scheduler already running");
  memory_locked_ = false;
  if (options_.realtime != RealtimePolicy::off && options_.lock_memory) {
    if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
      memory_locked_ = true;
    } else {
      const int err = errno;
      if (options_.realtime == RealtimePolicy::required) {
        return Status::error(std::string("mlockall failed: ") + std::strerror(err) +
                             " (grant CAP_IPC_LOCK or raise RLIMIT_MEMLOCK, or set realtime: best_effort)");
      }
      TN_LOG_WARN("memory not locked (mlockall: %s); page faults may delay real-time tasks. "
                  "Grant CAP_IPC_LOCK or raise RLIMIT_MEMLOCK.", std::strerror(err));
    }
  }

  clock_.resume_sleepers();
  for (auto& e : entries_) {
    if (e->event != nullptr) e->event->resume();
  }
  // The threads: one per task, but one for all the tasks naming a thread.
  threads_.clear();
  for (auto& e : entries_) {
    Thread* shared = nullptr;
    for (auto& t : threads_) {
      if (!e->spec.thread.empty() && t->entries.front()->spec.thread == e->spec.thread) shared = t.get();
    }
    if (shared == nullptr) {
      threads_.push_back(std::make_unique<Thread>());
      shared = threads_.back().get();
      shared->name = e->spec.thread.empty() ? e->spec.name : e->spec.thread;
    }
    shared->entries.push_back(e.get());
    if (const int fd = e->task.wake_fd(); fd >= 0) shared->wake_fds.push_back(fd);
  }
  threads_ready_.store(0, std::memory_order_release);
  realtime_failures_.store(0, std::memory_order_release);
  running_.store(true, std::memory_order_release);
  for (auto& t : threads_) {
    Thread& thread = *t;
    thread.thread = std::thread([this, &thread] { thread_main(thread); });
  }
  while (threads_ready_.load(std::memory_order_acquire) < static_cast<int>(threads_.size())) {
    std::this_thread::yield();
  }

  bool any_asked = false;
  for (const auto& e : entries_) any_asked = any_asked || e->spec.priority > 0;
  const int failures = realtime_failures_.load(std::memory_order_acquire);
  realtime_active_ = any_asked && options_.realtime != RealtimePolicy::off && failures == 0;
  if (failures > 0) {
    if (options_.realtime == RealtimePolicy::required) {
      stop();
      return Status::error("SCHED_FIFO not permitted for " + std::to_string(failures) +
                           " task(s) (grant CAP_SYS_NICE or raise RLIMIT_RTPRIO, or set realtime: best_effort)");
    }
    TN_LOG_WARN("SCHED_FIFO not permitted for %d task(s); they run with normal priority and may be "
                "delayed by other processes. Grant CAP_SYS_NICE or raise RLIMIT_RTPRIO.", failures);
  }
  return Status::ok();
}

void Scheduler::stop() {
  if (!running_.exchange(false, std::memory_order_acq_rel)) return;
  clock_.interrupt_sleepers();
  for (auto& e : entries_) {
    if (e->event != nullptr) e->event->interrupt();
  }
  for (auto& t : threads_) {
    if (t->thread.joinable()) t->thread.join();
  }
  if (memory_locked_) munlockall();  // memory_locked() keeps reporting what the run had
}

void Scheduler::apply_thread_settings(const Thread& thread) noexcept {
  const TaskSpec& spec = thread.entries.front()->spec;  // the tasks sharing a thread share these
  pthread_setname_np(pthread_self(), thread.name.c_str());
  if (spec.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(static_cast<unsigned>(spec.cpu), &set);
    if (pthread_setaffinity_np(pthread_self(), sizeof set, &set) != 0) {
      TN_LOG_WARN("thread '%s': could not pin to CPU %d", thread.name.c_str(), spec.cpu);
    }
  }
  if (options_.realtime != RealtimePolicy::off && spec.priority > 0) {
    sched_param param{};
    param.sched_priority = spec.priority;
    if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &param) != 0) {
      realtime_failures_.fetch_add(static_cast<int>(thread.entries.size()), std::memory_order_acq_rel);
    }
  }
}

void Scheduler::thread_main(Thread& thread) noexcept {
  apply_thread_settings(thread);
  alloc_guard::mark_realtime_thread(thread.name.c_str());
  threads_ready_.fetch_add(1, std::memory_order_acq_rel);
  if (thread.entries.front()->spec.kind == TaskKind::periodic) {
    run_periodic(thread);
  } else {
    run_event(*thread.entries.front());
  }
  alloc_guard::unmark_current_thread();
}

void Scheduler::run_periodic(Thread& thread) noexcept {
  const Nanos period = thread.entries.front()->spec.period();
  // Rests end early when a descriptor of the thread's tasks is ready, where
  // the clock can wait on descriptors; elsewhere such tasks do not rest.
  const bool watch_fds = !thread.wake_fds.empty() && clock_.wakes_on_descriptors();
  Nanos deadline = clock_.now() + period;
  std::uint64_t cycle = 0;
  bool watching = false;     // this sleep may be ended by a descriptor
  Nanos rest_from = 0;       // the deadline the rest skipped from
  std::uint64_t planned = 0; // the periods that rest skips
  while (running_.load(std::memory_order_acquire)) {
    if (watching) {
      const Clock::Wake wake = clock_.sleep_until_readable(deadline, thread.wake_fds);
      if (wake == Clock::Wake::interrupted) break;
      std::uint64_t rested = planned;
      if (wake == Clock::Wake::readable) {
        // Run now: the periods rested are those that passed.
        const Nanos woke = clock_.now();
        rested = woke > rest_from ? static_cast<std::uint64_t>((woke - rest_from) / period) : 0;
        deadline = std::min(deadline, woke);
      }
      for (Entry* e : thread.entries) {
        if (rested > 0) e->accounting.record_rested(rested);
      }
    } else if (!clock_.sleep_until(deadline)) {
      break;
    }
    if (!running_.load(std::memory_order_acquire)) break;
    // The tasks of a shared thread one after another, each measured on its
    // own (its latency includes the runs before it in this period).
    Nanos finished = 0;
    Nanos rest = -1;
    bool watch = false;
    for (Entry* e : thread.entries) {
      const Nanos started = clock_.now();
      const Nanos cpu_start = clock_.thread_cpu_time();
      e->task.run(TaskTick{cycle, deadline, started});
      const Nanos cpu = clock_.thread_cpu_time() - cpu_start;
      finished = clock_.now();
      e->accounting.record_run(deadline, started, finished, cpu);
      const bool wants = e->task.wake_fd() >= 0 && e->task.watching();
      watch = watch || wants;
      // A shared thread rests only as long as every task on it can.
      const Nanos r = wants && !watch_fds ? 0 : e->task.rest();
      rest = rest < 0 ? r : std::min(rest, r);
    }
    std::uint64_t skipped = 0;
    const Nanos next = next_periodic_deadline(deadline, period, finished, skipped);
    std::uint64_t rested = 0;
    deadline = rested_deadline(next, period, finished, rest, rested);
    watching = watch_fds && watch;
    rest_from = next;
    planned = rested;
    for (Entry* e : thread.entries) {
      if (skipped > 0) e->accounting.record_skipped(skipped);
      if (rested > 0 && !watching) e->accounting.record_rested(rested);
    }
    ++cycle;
  }
}

void Scheduler::run_event(Entry& entry) noexcept {
  std::uint32_t seen = 0;
  std::uint64_t cycle = 0;
  while (running_.load(std::memory_order_acquire)) {
    if (!entry.event->wait(seen)) break;
    if (!running_.load(std::memory_order_acquire)) break;
    const Nanos signalled = entry.event->last_signal();
    const Nanos started = clock_.now();
    const Nanos cpu_start = clock_.thread_cpu_time();
    entry.task.run(TaskTick{cycle, signalled, started});
    const Nanos cpu = clock_.thread_cpu_time() - cpu_start;
    const Nanos finished = clock_.now();
    entry.accounting.record_run(signalled, started, finished, cpu);
    ++cycle;
  }
}

}  // namespace trailnav
