#include "trailnav/runtime/runtime_config.hpp"

#include <algorithm>
#include <string>

namespace trailnav {

RuntimeSettings parse_runtime_settings(const ConfigNode& section) {
  RuntimeSettings settings;
  const std::string realtime = section.choice("realtime", {"off", "best_effort", "required"}, "best_effort");
  settings.scheduler.realtime = realtime == "off"        ? RealtimePolicy::off
                                : realtime == "required" ? RealtimePolicy::required
                                                         : RealtimePolicy::best_effort;
  settings.scheduler.lock_memory = section.boolean("lock_memory", true);
  const std::string level = section.choice("log_level", {"debug", "info", "warn", "error"}, "info");
  log::parse_level(level.c_str(), settings.log_level);
  const std::string sink = section.choice("log_sink", {"auto", "stderr", "journal"}, "auto");
  settings.log_sink = sink == "stderr" ? log::Sink::stderr_only : sink == "journal" ? log::Sink::journal : log::Sink::automatic;
  section.reject_unknown_keys();
  return settings;
}

std::vector<TaskSpec> parse_task_table(const ConfigNode& parent, std::string_view key, int cpu_count) {
  std::vector<TaskSpec> table;
  for (const ConfigNode& entry : parent.map_list(key)) {
    TaskSpec spec;
    spec.name = entry.string("name");
    spec.kind = entry.choice("kind", {"periodic", "event"}) == "event" ? TaskKind::event : TaskKind::periodic;
    if (spec.kind == TaskKind::periodic) {
      spec.rate_hz = entry.number("rate_hz", 0.001, 10'000.0);
    } else if (entry.has("rate_hz")) {
      entry.fail("rate_hz", "an event-driven task has no rate; remove rate_hz or make the task periodic");
    }
    spec.budget = static_cast<Nanos>(entry.number("budget_ms", 0.001, 60'000.0) * 1e6);
    spec.priority = static_cast<int>(entry.integer("priority", 0, 99, 0));
    spec.cpu = static_cast<int>(entry.integer("cpu", -1, cpu_count - 1, -1));
    spec.thread = entry.string("thread", "");
    entry.reject_unknown_keys();
    if (Status s = validate_task_spec(spec, cpu_count); !s) entry.fail("", s.message());
    for (const TaskSpec& other : table) {
      if (other.name == spec.name) entry.fail("name", "task name '" + spec.name + "' is used twice");
      if (Status s = validate_thread_sharing(spec, other); !s) entry.fail("thread", s.message());
    }
    table.push_back(spec);
  }
  return table;
}

void change_task_table(const ConfigNode& parent, std::string_view key, int cpu_count, std::vector<TaskSpec>& table) {
  std::vector<std::string> changed;
  for (const ConfigNode& entry : parent.optional_map_list(key)) {
    const std::string name = entry.string("name");
    const auto it = std::find_if(table.begin(), table.end(), [&](const TaskSpec& t) { return t.name == name; });
    if (it == table.end()) {
      std::string names;
      for (const TaskSpec& t : table) names += (names.empty() ? "" : ", ") + t.name;
      entry.fail("name", "the table has no task '" + name + "' to change (it has " + names + ")");
    }
    if (std::find(changed.begin(), changed.end(), name) != changed.end()) {
      entry.fail("name", "task '" + name + "' is changed twice");
    }
    changed.push_back(name);
    TaskSpec spec = *it;
    if (spec.kind == TaskKind::periodic) {
      spec.rate_hz = entry.number("rate_hz", 0.001, 10'000.0, spec.rate_hz);
    } else if (entry.has("rate_hz")) {
      entry.fail("rate_hz", "task '" + name + "' is event-driven: it has no rate");
    }
    if (entry.has("budget_ms")) spec.budget = static_cast<Nanos>(entry.number("budget_ms", 0.001, 60'000.0) * 1e6);
    spec.priority = static_cast<int>(entry.integer("priority", 0, 99, spec.priority));
    spec.cpu = static_cast<int>(entry.integer("cpu", -1, cpu_count - 1, spec.cpu));
    spec.thread = entry.string("thread", spec.thread);
    entry.reject_unknown_keys();
    if (Status s = validate_task_spec(spec, cpu_count); !s) entry.fail("", s.message());
    for (const TaskSpec& other : table) {
      if (other.name == spec.name) continue;
      if (Status s = validate_thread_sharing(spec, other); !s) entry.fail("", s.message());
    }
    *it = spec;
  }
}

const TaskSpec& require_task(const std::vector<TaskSpec>& table, std::string_view name, const ConfigNode& parent,
                             std::string_view key) {
  for (const TaskSpec& spec : table) {
    if (spec.name == name) return spec;
  }
  parent.fail(key, "the task table has no task named '" + std::string(name) + "', which this program needs");
}

}  // namespace trailnav
