// Terminal output for the command-line tools: a progress bar for long work
// and a task-statistics table. Not for real-time threads.
#pragma once

#include <cstdio>
#include <string>

#include "trailnav/runtime/scheduler.hpp"

namespace trailnav::cli {

// A one-line progress bar on stderr, redrawn in place on a terminal and
// printed every 10 % otherwise (logs and CI).
class ProgressBar {
 public:
  ProgressBar(std::string label, double total, std::string unit);
  void update(double done);
  void finish();

 private:
  std::string label_;
  double total_;
  std::string unit_;
  bool interactive_;
  int last_decile_ = -1;
  bool finished_ = false;
};

// Prints one row per task: kind, rate, budget, runs, overruns, slips,
// skipped periods, execution and wake-up latency p50/p99/max in microseconds.
void print_task_table(std::FILE* out, const Scheduler& scheduler);

// Prints the allocation guard's report; returns the number of heap operations
// counted on real-time threads since arm().
std::uint64_t print_allocation_report(std::FILE* out);

}  // namespace trailnav::cli
