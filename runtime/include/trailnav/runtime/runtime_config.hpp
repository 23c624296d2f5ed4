// The runtime's own configuration: scheduling policy, logging, and the task
// table. Each robot config (and the demo's) embeds these sections.
//
//   runtime:
//     realtime: best_effort        # off | best_effort | required
//     lock_memory: true
//     log_level: info              # debug | info | warn | error
//     log_sink: auto               # auto | stderr | journal
//   tasks:
//     - {name: imu, kind: periodic, rate_hz: 200, budget_ms: 0.5, priority: 60, cpu: -1}
//     - {name: odometry, kind: event, budget_ms: 0.5, priority: 55}
#pragma once

#include <string_view>
#include <vector>

#include "trailnav/runtime/config.hpp"
#include "trailnav/runtime/log.hpp"
#include "trailnav/runtime/scheduler.hpp"

namespace trailnav {

struct RuntimeSettings {
  SchedulerOptions scheduler;
  log::Level log_level = log::Level::info;
  log::Sink log_sink = log::Sink::automatic;
};

// Reads the `runtime` section (all keys optional, defaults as above).
RuntimeSettings parse_runtime_settings(const ConfigNode& section);

// Reads a task table (a list under `key`); checks every entry and that names
// are unique, with errors that point at the entry's line.
std::vector<TaskSpec> parse_task_table(const ConfigNode& parent, std::string_view key, int cpu_count);

// Changes to a given table (a preset): an optional list under `key` whose
// entries name a task of `table` and give any of rate_hz (periodic tasks),
// budget_ms, priority and cpu; the changed entry is checked as a whole one.
void change_task_table(const ConfigNode& parent, std::string_view key, int cpu_count, std::vector<TaskSpec>& table);

// Finds a task by name in a parsed table; fails naming the task when the
// table lacks one the program needs.
const TaskSpec& require_task(const std::vector<TaskSpec>& table, std::string_view name, const ConfigNode& parent,
                             std::string_view key);

}  // namespace trailnav
