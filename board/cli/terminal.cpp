#include "terminal.hpp"

#include <unistd.h>

#include <algorithm>
#include <array>

#include "trailnav/runtime/alloc_guard.hpp"

namespace trailnav::cli {

ProgressBar::ProgressBar(std::string label, double total, std::string unit)
    : label_(std::move(label)), total_(total), unit_(std::move(unit)), interactive_(isatty(STDERR_FILENO) == 1) {}

void ProgressBar::update(double done) {
  const double fraction = total_ > 0.0 ? std::clamp(done / total_, 0.0, 1.0) : 1.0;
  if (interactive_) {
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(fraction * kWidth);
    std::fprintf(stderr, "\r%s [%.*s%*s] %5.1f%% %.1f/%.1f %s", label_.c_str(), filled,
                 "##############################", kWidth - filled, "", fraction * 100.0, done, total_, unit_.c_str());
    std::fflush(stderr);
    return;
  }
  const int decile = static_cast<int>(fraction * 10.0);
  if (decile != last_decile_) {
    last_decile_ = decile;
    std::fprintf(stderr, "%s: %3d%% (%.1f/%.1f %s)\n", label_.c_str(), decile * 10, done, total_, unit_.c_str());
  }
}

void ProgressBar::finish() {
  if (finished_) return;
  finished_ = true;
  update(total_);
  if (interactive_) std::fputc('\n', stderr);
}

namespace {
double us(Nanos n) { return nanos_to_micros(n); }
}  // namespace

void print_task_table(std::FILE* out, const Scheduler& scheduler) {
  std::fprintf(out, "%-14s %-8s %8s %9s %8s %8s %6s %6s %7s %7s  %-26s %-26s\n", "task", "kind", "rate_hz", "budget_us",
               "runs", "overruns", "stalls", "slips", "skipped", "rested", "exec_us p50/p99/max", "latency_us p50/p99/max");
  for (std::size_t i = 0; i < scheduler.task_count(); ++i) {
    const TaskSpec& spec = scheduler.spec(i);
    const TaskStats s = scheduler.stats(i);
    char exec[64];
    char latency[64];
    std::snprintf(exec, sizeof exec, "%.1f/%.1f/%.1f", us(s.execution.p50), us(s.execution.p99), us(s.execution.max));
    std::snprintf(latency, sizeof latency, "%.1f/%.1f/%.1f", us(s.latency.p50), us(s.latency.p99), us(s.latency.max));
    std::fprintf(out, "%-14s %-8s %8.1f %9.1f %8llu %8llu %6llu %6llu %7llu %7llu  %-26s %-26s\n", spec.name.c_str(),
                 spec.kind == TaskKind::periodic ? "periodic" : "event", spec.rate_hz, us(spec.budget),
                 static_cast<unsigned long long>(s.runs), static_cast<unsigned long long>(s.overruns),
                 static_cast<unsigned long long>(s.stalls), static_cast<unsigned long long>(s.slips), static_cast<unsigned long long>(s.skipped_periods),
                 static_cast<unsigned long long>(s.rested_periods), exec,
                 latency);
  }
}

std::uint64_t print_allocation_report(std::FILE* out) {
  std::array<alloc_guard::ThreadAllocations, alloc_guard::kMaxThreadNames> rows{};
  const std::size_t n = alloc_guard::report(rows);
  const std::uint64_t total = alloc_guard::total_allocations();
  std::fprintf(out, "heap operations on real-time threads after arm: %llu%s\n", static_cast<unsigned long long>(total),
               alloc_guard::hook_installed() ? "" : " (allocator hook not installed: not measured)");
  for (std::size_t i = 0; i < n; ++i) {
    std::fprintf(out, "  %-24s %llu\n", rows[i].name, static_cast<unsigned long long>(rows[i].allocations));
  }
  return total;
}

}  // namespace trailnav::cli
