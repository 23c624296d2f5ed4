#include "task_presets.hpp"

#include <algorithm>
#include <array>
#include <cstdio>

namespace trailnav::daemon {
namespace {

using K = TaskKind;

// Measured with toolchain/measure-task-presets.sh on 2026-12-02 (this 2-core
// VM; docs/performance.md "Task presets"): need = the largest CPU time of one
// run per period of input over three 60 s replays of `mixed-route`; budget =
// need x 1.5 rounded up to 0.1 ms, at most 90 % of the period. Where that cap
// bites (the lidar task of the 32- and 64-laser models, whose run completing
// a revolution clears the next one's range image) the budget is below the
// need and start-up says so. Priorities: the e-stop first, then the sensors by
// how little their kernel buffers hold against their rate, then pose,
// obstacles, navigation and terrain.
//   name, kind, rate [Hz], need [ms], budget [ms], priority
constexpr std::array<PresetRow, 9> kVlp16 = {{
    {"gpio", K::periodic, 200, 0.886, 1.4, 75},
    {"lidar", K::periodic, 1000, 0.886, 0.9, 70},
    {"imu", K::periodic, 400, 0.584, 0.9, 65},
    {"can", K::periodic, 200, 1.566, 2.4, 64},
    {"gps", K::periodic, 50, 0.513, 0.8, 60},
    {"pose", K::periodic, 100, 0.891, 1.4, 58},
    {"obstacles", K::event, 0, 4.668, 7.1, 50},
    {"navigation", K::periodic, 10, 0.992, 1.5, 45},
    {"terrain", K::periodic, 20, 10.623, 16.0, 40},
}};
constexpr std::array<PresetRow, 9> kVlp32c = {{
    {"gpio", K::periodic, 200, 0.947, 1.5, 75},
    {"lidar", K::periodic, 1000, 5.537, 0.9, 70},
    {"imu", K::periodic, 400, 0.824, 1.3, 65},
    {"can", K::periodic, 200, 0.967, 1.5, 64},
    {"gps", K::periodic, 50, 0.292, 0.5, 60},
    {"pose", K::periodic, 100, 2.806, 4.3, 58},
    {"obstacles", K::event, 0, 7.600, 11.4, 50},
    {"navigation", K::periodic, 10, 1.188, 1.8, 45},
    {"terrain", K::periodic, 20, 13.261, 19.9, 40},
}};
constexpr std::array<PresetRow, 9> kHdl32e = {{
    {"gpio", K::periodic, 200, 0.660, 1.0, 75},
    {"lidar", K::periodic, 1000, 2.180, 0.9, 70},
    {"imu", K::periodic, 400, 0.409, 0.7, 65},
    {"can", K::periodic, 200, 0.690, 1.1, 64},
    {"gps", K::periodic, 50, 4.783, 7.2, 60},
    {"pose", K::periodic, 100, 0.720, 1.1, 58},
    {"obstacles", K::event, 0, 5.947, 9.0, 50},
    {"navigation", K::periodic, 10, 0.914, 1.4, 45},
    {"terrain", K::periodic, 20, 11.118, 16.7, 40},
}};
constexpr std::array<PresetRow, 9> kHdl64e = {{
    {"gpio", K::periodic, 200, 0.688, 1.1, 75},
    {"lidar", K::periodic, 1000, 3.807, 0.9, 70},
    {"imu", K::periodic, 400, 1.586, 2.2, 65},
    {"can", K::periodic, 200, 0.618, 1.0, 64},
    {"gps", K::periodic, 50, 0.262, 0.4, 60},
    {"pose", K::periodic, 100, 2.108, 3.2, 58},
    {"obstacles", K::event, 0, 9.480, 14.3, 50},
    {"navigation", K::periodic, 10, 1.613, 2.5, 45},
    {"terrain", K::periodic, 20, 13.999, 21.0, 40},
}};

}  // namespace

std::span<const PresetRow> task_preset(velodyne::Model model) {
  switch (model) {
    case velodyne::Model::vlp16:
    case velodyne::Model::vlp16_hires: return kVlp16;
    case velodyne::Model::vlp32c: return kVlp32c;
    case velodyne::Model::hdl32e: return kHdl32e;
    case velodyne::Model::hdl64e: return kHdl64e;
  }
  return kVlp16;
}

std::vector<TaskSpec> preset_tasks(velodyne::Model model, std::span<const std::string_view> names) {
  std::vector<TaskSpec> out;
  for (const PresetRow& r : task_preset(model)) {
    if (std::find(names.begin(), names.end(), r.name) == names.end()) continue;
    TaskSpec t;
    t.name = std::string(r.name);
    t.kind = r.kind;
    t.rate_hz = r.kind == K::periodic ? r.rate_hz : 0.0;
    t.budget = static_cast<Nanos>(r.budget_ms * 1e6 + 0.5);
    t.priority = r.priority;
    out.push_back(t);
  }
  return out;
}

std::vector<std::string> budget_warnings(const std::vector<TaskSpec>& tasks, velodyne::Model model) {
  std::vector<std::string> out;
  const std::string_view lidar = velodyne::model_info(model).name;
  for (const TaskSpec& t : tasks) {
    for (const PresetRow& r : task_preset(model)) {
      if (r.name != t.name || static_cast<double>(t.budget) * 1e-6 >= r.need_ms) continue;
      // A need above 90 % of the period cannot be granted at this rate: the
      // rate is what to change, not the budget.
      const bool rate_bound = t.kind == TaskKind::periodic && t.rate_hz > 0.0 && r.need_ms > 0.9e3 / t.rate_hz;
      char line[400];
      std::snprintf(line, sizeof line,
                    "task '%s': its budget of %.3f ms is below the %.3f ms of CPU time one run needed with the %.*s "
                    "(docs/performance.md \"Task presets\"): expect overruns; %s",
                    t.name.c_str(), static_cast<double>(t.budget) * 1e-6, r.need_ms, static_cast<int>(lidar.size()),
                    lidar.data(),
                    rate_bound ? "at its rate a budget can be at most 90 % of the period: a lower rate_hz (tasks.change) "
                                 "gives each run more"
                               : "take 'tasks: {preset: auto}' or raise budget_ms");
      out.emplace_back(line);
    }
  }
  return out;
}

}  // namespace trailnav::daemon
