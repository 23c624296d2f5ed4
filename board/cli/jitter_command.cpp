// `trailnav jitter`: how punctually this machine wakes a periodic task. A
// task runs at the given rate on the scheduler while other threads burn CPU;
// the wake-up latency (start minus absolute deadline) is reported as
// p50/p99/max. Run it on the robot PC before trusting its timing.
#include <atomic>
#include <cstdio>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "terminal.hpp"
#include "trailnav/runtime/log.hpp"
#include "trailnav/runtime/scheduler.hpp"

namespace trailnav::cli {
namespace {

struct JitterOptions {
  double rate_hz = 100.0;
  double duration_s = 10.0;
  int load_threads = 1;
  int priority = 0;
  int cpu = -1;
};

class TickTask final : public Task {
 public:
  void run(const TaskTick& tick) override { last_cycle.store(tick.cycle, std::memory_order_relaxed); }
  std::atomic<std::uint64_t> last_cycle{0};
};

int run_jitter(const JitterOptions& o) {
  MonotonicClock clock;
  SchedulerOptions options;
  options.realtime = o.priority > 0 ? RealtimePolicy::best_effort : RealtimePolicy::off;
  options.lock_memory = o.priority > 0;
  Scheduler scheduler(clock, options);
  TickTask task;
  const auto period = static_cast<Nanos>(1e9 / o.rate_hz);
  if (Status s = scheduler.add({"jitter", TaskKind::periodic, o.rate_hz, period / 2, o.priority, o.cpu}, task); !s) {
    std::fprintf(stderr, "trailnav jitter: %s\n", s.message().c_str());
    return 2;
  }

  std::atomic<bool> burning{true};
  std::vector<std::thread> burners;
  for (int i = 0; i < o.load_threads; ++i) {
    burners.emplace_back([&burning] {
      volatile std::uint64_t x = 0;
      while (burning.load(std::memory_order_relaxed)) x = x + 1;
    });
  }
  std::printf("trailnav jitter: %.0f Hz task for %.1f s, %d CPU-burning thread(s), priority %d%s\n", o.rate_hz,
              o.duration_s, o.load_threads, o.priority, o.priority > 0 ? " (SCHED_FIFO if permitted)" : " (normal scheduling)");
  if (Status s = scheduler.start(); !s) {
    std::fprintf(stderr, "trailnav jitter: %s\n", s.message().c_str());
    burning = false;
    for (auto& t : burners) t.join();
    return 1;
  }
  ProgressBar progress("jitter", o.duration_s, "s");
  const Nanos start = clock.now();
  for (;;) {
    const double elapsed = nanos_to_seconds(clock.now() - start);
    if (elapsed >= o.duration_s) break;
    progress.update(elapsed);
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  progress.finish();
  scheduler.stop();
  burning = false;
  for (auto& t : burners) t.join();

  const TaskStats s = scheduler.stats(0);
  std::printf("wake-up latency (us): p50 %.1f  p99 %.1f  max %.1f  (runs %llu, slips %llu, skipped %llu)\n",
              nanos_to_micros(s.latency.p50), nanos_to_micros(s.latency.p99), nanos_to_micros(s.latency.max),
              static_cast<unsigned long long>(s.runs), static_cast<unsigned long long>(s.slips),
              static_cast<unsigned long long>(s.skipped_periods));
  std::printf("scheduling: %s\n", scheduler.realtime_active() ? "SCHED_FIFO" : "normal");
  return 0;
}

}  // namespace

void add_jitter_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "jitter",
      "Measure how punctually a periodic task wakes (latency = start - absolute deadline) while other threads burn\n"
      "CPU; prints p50/p99/max in microseconds. Use --priority 1..99 to ask for SCHED_FIFO.");
  static JitterOptions o;
  cmd->add_option("--rate", o.rate_hz, "Task rate in Hz")->check(CLI::Range(1.0, 10000.0))->capture_default_str();
  cmd->add_option("--duration", o.duration_s, "Seconds to measure")->check(CLI::Range(0.5, 3600.0))->capture_default_str();
  cmd->add_option("--load-threads", o.load_threads, "Threads that burn CPU meanwhile")->check(CLI::Range(0, 64))->capture_default_str();
  cmd->add_option("--priority", o.priority, "SCHED_FIFO priority (0: normal scheduling)")->check(CLI::Range(0, 99))->capture_default_str();
  cmd->add_option("--cpu", o.cpu, "Pin the task to this CPU (-1: any)")->capture_default_str();
  cmd->callback([] {
    const int code = run_jitter(o);
    if (code != 0) throw CLI::RuntimeError(code);
  });
}

}  // namespace trailnav::cli
