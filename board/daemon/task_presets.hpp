// Task tables per lidar model: the rates, priorities and budgets trailnavd's
// tasks need with a VLP-16, VLP-32C, HDL-32E or HDL-64E on the robot PC.
//
// A budget is the CPU time one run of a task may use per period of input it
// drains (runtime/include/trailnav/runtime/scheduler.hpp; an overrun above
// it). Each preset row carries the CPU time its task was measured to need:
// the largest CPU time of one run per period of input over 60 s replays of
// the `mixed-route` drive with that lidar into trailnavd on the reference
// machine (a 2-core VM, docs/performance.md "Task presets" gives the runs and
// the command). The budget is derived from it: need x 1.5 (a margin for
// another machine and for the kernel's interrupt work billed to whichever
// thread it interrupts), rounded up to 0.1 ms, at most 90 % of the period.
//
// A config takes a preset with
//
//   tasks:
//     preset: auto          # the lidar's model; or VLP-16, VLP-32C, HDL-32E, HDL-64E
//     change:               # optional: rows changed from the preset's, by name
//       - {name: lidar, cpu: 1}
//
// or writes the whole table out as a list (docs/trailnavd.md); either way a
// budget below what the lidar needs is warned about at start-up.
#pragma once

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "trailnav/drivers/velodyne/model.hpp"
#include "trailnav/runtime/scheduler.hpp"

namespace trailnav::daemon {

struct PresetRow {
  std::string_view name;
  TaskKind kind;
  double rate_hz;    // periodic tasks
  double need_ms;    // the largest CPU time of one run per period of input, measured with this lidar
  double budget_ms;  // what the table grants: derived from need_ms (above)
  int priority;      // SCHED_FIFO
  std::string_view thread;  // shared with the other rows naming it (TaskSpec::thread); empty: its own
};

// The model's table (a VLP-16-HiRes sends a VLP-16's packets: its table).
std::span<const PresetRow> task_preset(velodyne::Model model);

// The preset's rows for the tasks named, in the preset's order.
std::vector<TaskSpec> preset_tasks(velodyne::Model model, std::span<const std::string_view> names);

// One line per task whose budget is below what the preset measured it to
// need with this lidar (empty when every budget suffices).
std::vector<std::string> budget_warnings(const std::vector<TaskSpec>& tasks, velodyne::Model model);

}  // namespace trailnav::daemon
