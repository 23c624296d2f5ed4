#include "task_presets.hpp"

#include <algorithm>
#include <array>
#include <cstdio>

namespace trailnav::daemon {
namespace {

using K = TaskKind;

// The tasks, the same for every lidar: rate and priority. Priorities: the
// e-stop first, then the sensors by how little their kernel buffers hold
// against their rate, then pose, obstacles, navigation and terrain.
// Rates: every wake-up costs CPU (25-55 us on the test VM, docs/performance.md),
// so a driver reads as often as its data is used, not as often as it comes.
// The IMU (400 Hz samples) and the CAN odometry are read at the pose's 100 Hz:
// their readings keep their own times (the IMU's sample counter, the kernel's
// CAN timestamps), the serial and CAN buffers hold far more than 10 ms, and the
// IMU's clock relation takes the least delayed sample of each read, whose age
// is bounded by the sample interval, not by the read interval.
//
// The IMU, CAN and GPS readers and the pose estimator share one thread,
// `sensors`, at the pose's 100 Hz and the IMU's priority: each period the
// readers drain their buffers and the pose then takes what they read, fresh,
// for one wake-up instead of four (the GPS is read at 100 Hz there, not 50:
// a read of an empty port costs less than a wake-up of its own). The e-stop
// (gpio) keeps a thread of its own and the top priority.
struct Task {
  std::string_view name;
  TaskKind kind;
  double rate_hz;  // periodic tasks
  int priority;
  std::string_view thread = {};
};
constexpr std::array<Task, 14> kTasks = {{
    {"gpio", K::periodic, 200, 75},
    {"lidar", K::periodic, 1000, 70},
    {"imu", K::periodic, 100, 65, "sensors"},
    {"can", K::periodic, 100, 65, "sensors"},
    {"gps", K::periodic, 100, 65, "sensors"},
    {"pose", K::periodic, 100, 65, "sensors"},
    {"obstacles", K::event, 0, 50},
    {"navigation", K::periodic, 10, 45},
    {"terrain", K::periodic, 20, 40},
    // Normal scheduling (priority 0), below every real-time thread: the
    // map's solves take what CPU is left (docs/slam.md "Online mapping").
    {"mapping", K::periodic, 2, 0},
    // Normal scheduling too: the demonstration's training (a local map every
    // d_M = 20 m driven) and the model file's save.
    {"demonstration", K::periodic, 1, 0},
    // Normal scheduling, one thread: the camera's frames (at most 30 a
    // second drained at each run), then the place filter's step on the newest.
    {"camera", K::periodic, 30, 0, "place"},
    {"place", K::periodic, 30, 0, "place"},
    // Normal scheduling, a thread of its own: the station's scan-to-model
    // registration and its multi-body fix (tens of milliseconds) on the
    // newest planar scan, ten times a second.
    {"station", K::periodic, 10, 0},
}};

// The budget a need gets: need x 1.5 rounded up to 0.1 ms, at least
// kInterferenceMs, at most 90 % of the period. The floor: the kernel's
// interrupt work and, on a virtual machine, the hypervisor's stalls are
// charged to whichever thread is on the core, so a run whose own work is
// 10-30 us can be charged a millisecond (on the test VM the largest run of
// each small task in a minute is 0.1-1.2 ms, its p99 under 0.15 ms:
// docs/performance.md "Task presets"); a budget below that would count the
// machine's interference as the task's overrun. Where the cap bites (the
// lidar task at 1 kHz: 0.9 ms) the floor is the cap.
constexpr double kInterferenceMs = 1.0;
constexpr double budget_for(double need_ms, TaskKind kind, double rate_hz) {
  const double tenths = need_ms * 15.0;
  auto whole = static_cast<long long>(tenths);
  if (static_cast<double>(whole) < tenths) ++whole;
  double budget = static_cast<double>(whole) / 10.0;
  if (budget < kInterferenceMs) budget = kInterferenceMs;
  const double cap = kind == K::periodic ? 0.9e3 / rate_hz : budget;
  return budget < cap ? budget : cap;
}

// One model's table from its measured needs, in kTasks' order.
constexpr std::array<PresetRow, 14> rows(const std::array<double, 14>& need_ms) {
  std::array<PresetRow, 14> out{};
  for (std::size_t i = 0; i < kTasks.size(); ++i) {
    const Task& t = kTasks[i];
    out[i] = {t.name, t.kind, t.rate_hz, need_ms[i], budget_for(need_ms[i], t.kind, t.rate_hz), t.priority, t.thread};
  }
  return out;
}

// The needs, measured with toolchain/measure-task-presets.sh --runs 4 on
// 2026-12-03 at dd9ef44 (this 2-core VM; docs/performance.md "Task presets"):
// the largest CPU time of one run per period of input over four 60 s replays
// of `mixed-route`, the sensors sharing their thread, the obstacle thread
// streaming, the GPIO task at rest between edges. A periodic task's run
// longer than 90 % of its period is the VM's stall, listed there, not a need.
// The mapping task's need does not depend on the lidar: the SMF re-solve of
// a full map (5,000 keyframes, the config's default capacity, with their GPS
// bias vertices: 9,843 vertices), measured with `taskset -c 0
// build/release/bin/trailnav_slam_bench --benchmark_filter=OnlineMap` on
// 2026-12-04 (docs/slam.md "Online mapping"): 136 ms. A larger
// mapping.max_keyframes needs a larger budget (tasks.change).
constexpr double kMappingNeedMs = 136.0;
// The demonstration task's: one local map trained in and the model saved.
// `taskset -c 0 build/release/bin/trailnav_terrain_bench --benchmark_filter=TravTrainLocalMap`
// on 2026-12-04 (|V| = 10,800): 0.79 ms of CPU with eight terrain models
// (1.24 ms of wall time, the fsync waiting on the disk); the largest CPU time
// of one run in trailnavd's demonstration test (tests/board/trav_daemon_test.cpp)
// was 1.53 ms (docs/traversability.md "On the robot").
constexpr double kDemonstrationNeedMs = 1.53;
// The camera's and the place task's, the same for every lidar. The camera:
// a 640 x 480 frame to 64 x 32, YUYV 0.62 ms and MJPEG 0.87 ms (`taskset -c 1
// build/release/bin/trailnav_place_bench`, BM_CameraFrame, 2026-12-05). The
// place task: the largest CPU time of one run in trailnavd with a database of
// 10,000 images, its whitening (rank 200), the lag of 10 frames and the
// sequence test, 600 frames at 10 Hz
// (`TRAILNAV_LONG_TESTS=1 build/release/bin/trailnav_place_daemon_tests
// --gtest_filter='*WholeSummer*'`, 2026-12-05): 7.37 ms (p99 2.95 ms; one
// step alone in the benchmark 2.09 ms: in the daemon each step reads about 14 MB
// of codes, whitening and the lag's ring next to the other threads, and the
// largest runs are the VM's stalls). A larger database needs a larger budget
// (tasks.change).
// The station task's: one scan added to the local model and the multi-body
// fix of the model against the surroundings and an object, the box of the
// thesis' simulated floor. Alone (`taskset -c 1 build/release/bin/trailnav_registration_bench
// --benchmark_filter='BM_Station(Visit|TaskRun)'`, 2026-12-05): a run standing
// at the box 8.8-9.0 ms (BM_StationTaskRun); the fix after driving in, its first
// iterations from further off, 17.8-20.5 ms (BM_StationVisit/1 less /0, two runs) and the
// scan's registration 1.4 ms. In trailnavd, the largest CPU time of one run
// over four runs of `build/release/bin/trailnav_station_daemon_tests
// --gtest_filter='*OverDds*'` (30 scans each, next to the DDS threads on this
// 2-core VM): 30.2-45.05 ms. A station with more objects or more points
// needs a larger budget (tasks.change).
constexpr double kStationNeedMs = 45.05;
constexpr double kCameraNeedMs = 0.87;
constexpr double kPlaceNeedMs = 7.37;
//                                          gpio   lidar  imu    can    gps    pose   obstacles navigation terrain mapping demonstration camera place station
constexpr std::array<PresetRow, 14> kVlp16 = rows({0.036, 0.386, 0.225, 0.242, 0.229, 0.266, 10.488, 0.687, 7.400, kMappingNeedMs, kDemonstrationNeedMs, kCameraNeedMs, kPlaceNeedMs, kStationNeedMs});
constexpr std::array<PresetRow, 14> kVlp32c = rows({0.037, 0.384, 0.527, 1.245, 0.586, 0.923, 11.216, 2.106, 10.544, kMappingNeedMs, kDemonstrationNeedMs, kCameraNeedMs, kPlaceNeedMs, kStationNeedMs});
constexpr std::array<PresetRow, 14> kHdl32e = rows({0.027, 0.354, 0.639, 0.335, 0.325, 0.359, 16.391, 0.590, 7.831, kMappingNeedMs, kDemonstrationNeedMs, kCameraNeedMs, kPlaceNeedMs, kStationNeedMs});
constexpr std::array<PresetRow, 14> kHdl64e = rows({0.097, 0.541, 0.486, 1.011, 0.332, 0.588, 5.785, 0.795, 12.778, kMappingNeedMs, kDemonstrationNeedMs, kCameraNeedMs, kPlaceNeedMs, kStationNeedMs});

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
    t.thread = std::string(r.thread);
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
