#include "trailnav/runtime/config.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fstream>

#include "trailnav/runtime/runtime_config.hpp"

namespace trailnav {
namespace {

using ::testing::HasSubstr;

// Runs `read` on `text` and returns the error message it must produce.
template <typename F>
std::string error_of(const std::string& text, F&& read) {
  try {
    read(ConfigNode::parse(text, "robot.yaml"));
  } catch (const ConfigError& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected a configuration error for:\n" << text;
  return {};
}

constexpr const char* kGoodTable = R"(runtime:
  realtime: off
  lock_memory: false
  log_level: warn
tasks:
  - name: imu
    kind: periodic
    rate_hz: 200
    budget_ms: 0.5
    priority: 60
  - name: odometry
    kind: event
    budget_ms: 0.25
    cpu: 1
)";

TEST(Config, ReadsTheRuntimeSectionAndTaskTable) {
  const ConfigNode root = ConfigNode::parse(kGoodTable, "robot.yaml");
  const RuntimeSettings settings = parse_runtime_settings(root.map("runtime"));
  EXPECT_EQ(settings.scheduler.realtime, RealtimePolicy::off);
  EXPECT_FALSE(settings.scheduler.lock_memory);
  EXPECT_EQ(settings.log_level, log::Level::warn);
  const auto tasks = parse_task_table(root, "tasks", 2);
  root.reject_unknown_keys();
  ASSERT_EQ(tasks.size(), 2u);
  EXPECT_EQ(tasks[0].name, "imu");
  EXPECT_EQ(tasks[0].kind, TaskKind::periodic);
  EXPECT_DOUBLE_EQ(tasks[0].rate_hz, 200.0);
  EXPECT_EQ(tasks[0].budget, 500'000);
  EXPECT_EQ(tasks[0].priority, 60);
  EXPECT_EQ(tasks[0].cpu, -1);
  EXPECT_EQ(tasks[1].kind, TaskKind::event);
  EXPECT_EQ(tasks[1].cpu, 1);
  EXPECT_EQ(require_task(tasks, "odometry", root, "tasks").budget, 250'000);
}

TEST(Config, UnknownKeyNamesFileLineKeyAndTheAllowedKeys) {
  const std::string msg = error_of("runtime:\n  realtime: off\n  lock_memroy: true\n", [](const ConfigNode& root) {
    parse_runtime_settings(root.map("runtime"));
  });
  EXPECT_THAT(msg, HasSubstr("robot.yaml:3:"));
  EXPECT_THAT(msg, HasSubstr("'runtime.lock_memroy'"));
  EXPECT_THAT(msg, HasSubstr("unknown key"));
  EXPECT_THAT(msg, HasSubstr("lock_memory"));
}

// yaml-cpp keeps the first of two equal keys and says nothing: the loader
// refuses them, nested or at the top, so no setting is silently dropped.
TEST(Config, AKeyGivenTwiceIsAnError) {
  const std::string msg = error_of("obstacles:\n  ground: {height: 0.2}\n  model: PW\n  ground: {cut: false}\n",
                                   [](const ConfigNode&) {});
  EXPECT_THAT(msg, HasSubstr("robot.yaml:4:"));
  EXPECT_THAT(msg, HasSubstr("'obstacles.ground'"));
  EXPECT_THAT(msg, HasSubstr("given twice (first at line 2)"));
  EXPECT_THAT(error_of("runtime: {}\nruntime: {}\n", [](const ConfigNode&) {}), HasSubstr("given twice"));
  EXPECT_THAT(error_of("tasks:\n  - {name: a, name: b}\n", [](const ConfigNode&) {}), HasSubstr("'tasks[0].name'"));
}

TEST(Config, OutOfRangeValueSaysWhatIsAllowed) {
  const std::string msg = error_of(
      "tasks:\n  - name: imu\n    kind: periodic\n    rate_hz: 200\n    budget_ms: 0.5\n    priority: 140\n",
      [](const ConfigNode& root) { parse_task_table(root, "tasks", 2); });
  EXPECT_THAT(msg, HasSubstr("robot.yaml:6:"));
  EXPECT_THAT(msg, HasSubstr("'tasks[0].priority'"));
  EXPECT_THAT(msg, HasSubstr("[0, 99]"));
}

TEST(Config, WrongTypeIsAnErrorNotADefault) {
  const std::string msg = error_of("tasks:\n  - name: imu\n    kind: periodic\n    rate_hz: fast\n    budget_ms: 1\n",
                                   [](const ConfigNode& root) { parse_task_table(root, "tasks", 2); });
  EXPECT_THAT(msg, HasSubstr("robot.yaml:4:"));
  EXPECT_THAT(msg, HasSubstr("'fast' is not a number"));
}

TEST(Config, BadChoiceListsTheChoices) {
  const std::string msg = error_of("runtime:\n  realtime: maybe\n",
                                   [](const ConfigNode& root) { parse_runtime_settings(root.map("runtime")); });
  EXPECT_THAT(msg, HasSubstr("robot.yaml:2:"));
  EXPECT_THAT(msg, HasSubstr("off, best_effort, required"));
}

TEST(Config, MissingRequiredKeyIsNamed) {
  const std::string msg = error_of("tasks:\n  - name: imu\n    kind: periodic\n    budget_ms: 1\n",
                                   [](const ConfigNode& root) { parse_task_table(root, "tasks", 2); });
  EXPECT_THAT(msg, HasSubstr("robot.yaml:2:"));
  EXPECT_THAT(msg, HasSubstr("missing required key 'tasks[0].rate_hz'"));
}

TEST(Config, TableRulesPointAtTheEntry) {
  const std::string duplicate = error_of(
      "tasks:\n  - {name: a, kind: event, budget_ms: 1}\n  - {name: a, kind: event, budget_ms: 1}\n",
      [](const ConfigNode& root) { parse_task_table(root, "tasks", 2); });
  EXPECT_THAT(duplicate, HasSubstr("robot.yaml:3:"));
  EXPECT_THAT(duplicate, HasSubstr("used twice"));

  const std::string over_budget = error_of("tasks:\n  - {name: a, kind: periodic, rate_hz: 100, budget_ms: 20}\n",
                                           [](const ConfigNode& root) { parse_task_table(root, "tasks", 2); });
  EXPECT_THAT(over_budget, HasSubstr("budget exceeds the period"));

  const std::string event_rate = error_of("tasks:\n  - {name: a, kind: event, rate_hz: 5, budget_ms: 1}\n",
                                          [](const ConfigNode& root) { parse_task_table(root, "tasks", 2); });
  EXPECT_THAT(event_rate, HasSubstr("event-driven task has no rate"));
}

TEST(Config, SyntaxErrorsCarryTheLine) {
  const std::string msg = error_of("runtime:\n  realtime: off\n  bad: [1, 2\n", [](const ConfigNode&) {});
  EXPECT_THAT(msg, HasSubstr("robot.yaml:"));
  EXPECT_THAT(msg, HasSubstr("YAML syntax error"));
}

TEST(Config, MissingFileIsAClearError) {
  try {
    ConfigNode::load_file("/nonexistent/robot.yaml");
    FAIL() << "expected an error";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), HasSubstr("/nonexistent/robot.yaml"));
    EXPECT_THAT(e.what(), HasSubstr("cannot open"));
  }
}

TEST(Config, NumberListsCheckEveryElement) {
  const ConfigNode root = ConfigNode::parse("extrinsics:\n  xyz: [0.1, 0.2, 9.5]\n", "robot.yaml");
  const ConfigNode ext = root.map("extrinsics");
  try {
    ext.number_list("xyz", -5.0, 5.0);
    FAIL() << "expected an error";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), HasSubstr("'extrinsics.xyz[2]'"));
    EXPECT_THAT(e.what(), HasSubstr("out of range"));
  }
}

TEST(Config, BoardExampleParses) {
  const ConfigNode root = ConfigNode::load_file("board/demo/runtime-demo.yaml");
  const RuntimeSettings settings = parse_runtime_settings(root.map("runtime"));
  (void)settings;
  const auto tasks = parse_task_table(root, "tasks", 2);
  EXPECT_GE(tasks.size(), 3u);
}

}  // namespace
}  // namespace trailnav
