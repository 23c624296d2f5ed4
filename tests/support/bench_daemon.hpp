// trailnavd on a bench, for end-to-end tests: a simulated recording, a robot
// config on this test's own ports and DDS domain (every sensor and DDS on
// loopback), the daemon spawned as systemd would run it (stderr to a file),
// and the recording replayed into it in real time on a thread (lidar and
// GPIO over UDP, GPS and IMU through pseudo-terminals, CAN through its
// tunnel). Knows no DDS: tests subscribe with whichever DDS they test.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "replayer.hpp"

#include "sim_truth.hpp"

namespace trailnav::test {

struct BenchDaemonOptions {
  std::string scenario = "urban";
  std::uint64_t seed = 5;
  double seconds = 8.0;       // of simulated driving
  std::string tag = "bench";  // names the temporary folder
  bool realtime = false;      // SCHED_FIFO and mlockall where permitted
  // With navigation the daemon plans on the recording's world.osm to where
  // the drive ends, and the pose moves the obstacle and terrain maps.
  bool navigation = false;
  std::string extra_yaml;     // appended to the config (e.g. more dds keys go in `dds_yaml`)
  std::string dds_yaml;       // appended inside the dds section's braces, e.g. ", topics: {...}"
  std::vector<std::string> faults;  // injected by the replayer (trailnav replay --fault)
  std::uint64_t fault_seed = 1;
  // The GPS and IMU bytes as UDP datagrams on loopback (a serial device
  // server) instead of through pseudo-terminals: a pseudo-terminal's bytes
  // are moved by a kernel worker thread, which two CPU hogs in the test's own
  // session starved for seconds (docs/testing.md); the drivers' own tests and
  // the other daemon tests keep the pseudo-terminals.
  bool serial_over_udp = false;
  // The lidar the drive is simulated with and trailnavd configured for
  // (VLP-16, VLP-32C, HDL-32E, HDL-64E): the simulator's calibration (a real
  // file in ../shared/data) and the terrain model trained for it.
  std::string lidar = "VLP-16";
  // The task table of the lidar's preset (`tasks: {preset: auto}`, as the
  // shipped configs) instead of the tests' own generous one.
  bool preset_tasks = false;
  // The online mapping task (a `mapping` section, re-optimised every 2 s),
  // with more keys inside its braces (e.g. ", loops: {}").
  bool mapping = false;
  std::string mapping_yaml;
  // The pose moves the obstacle and terrain maps (as with navigation, without it).
  bool feed_pose = false;
  // A `traversability:` section (its flow mapping, e.g. "{model: /x.tntrav}");
  // with `demonstration: {...}` in it the task table gets the demonstration task.
  std::string traversability;
};

// A goal for orders: the vertex of the recording's world.osm farthest from
// where its drive starts that a route reaches from there. False when the
// recording has no map or truth.
struct FarGoal {
  double lat = 0.0, lon = 0.0;      // the vertex
  double easting = 0.0, northing = 0.0;
  double on_network_e = 0.0, on_network_n = 0.0;  // its projection onto the network (where routes end)
  double distance = 0.0;            // m from the drive's start
};
bool far_routable_goal(const std::string& recording, FarGoal& out, std::string& error);

class BenchDaemon {
 public:
  // Simulates, writes the config and spawns trailnavd (`daemon_binary`);
  // null with `error` when any of it fails.
  static std::unique_ptr<BenchDaemon> start(const std::string& daemon_binary, const BenchDaemonOptions& options,
                                            std::string& error);
  ~BenchDaemon();
  BenchDaemon(const BenchDaemon&) = delete;
  BenchDaemon& operator=(const BenchDaemon&) = delete;

  // Replays the recording on a thread after `delay_s` (the daemon opens its
  // links and DDS discovery settles meanwhile).
  void start_replay(double delay_s = 1.5);
  // Waits until the daemon is up: `arrived(wait_s)` takes what came on the
  // test's own subscriber to `diagnostics` (any DDS), waiting up to wait_s,
  // and says whether a health message was among it. The first one comes after
  // the real-time tasks have run and opened their links (the IMU's and GPS's
  // sockets are bound in their tasks' first runs): a drive replayed before
  // that loses its first datagrams, as a fixed delay did under a sanitizer
  // with another daemon starting on the other core. False when none came
  // within `timeout_s` or the daemon exited.
  bool wait_until_up(const std::function<bool(double wait_s)>& arrived, double timeout_s = 60.0) const;
  bool replaying() const noexcept { return replaying_.load(); }
  void join_replay();
  // What the replayer did (after join_replay()); its error when it could not start.
  const replay::ReplayReport& replay_report() const noexcept { return replay_report_; }
  const std::string& replay_error() const noexcept { return replay_error_; }
  // Host time (CLOCK_REALTIME ns) the replay started; 0 before.
  std::int64_t replay_start_ns() const noexcept { return replay_start_ns_.load(); }

  // SIGTERM, wait; the exit code (-1 when killed) and the daemon's stderr.
  int stop();
  const std::string& stderr_text() const noexcept { return stderr_text_; }
  long rss_kb() const;
  // The daemon's CPU time so far (user + system, all threads), s.
  double cpu_s() const;

  std::uint32_t domain() const noexcept { return domain_; }
  const std::string& recording() const noexcept { return recording_; }
  const std::filesystem::path& config_path() const noexcept { return config_; }
  // The simulated truth (loaded with navigation, mapping or traversability only).
  const eval::SimTruth& truth() const noexcept { return truth_; }
  pid_t pid() const noexcept { return pid_; }

 private:
  BenchDaemon() = default;

  BenchDaemonOptions options_;
  std::filesystem::path dir_, config_;
  std::string recording_;
  std::uint32_t domain_ = 0;
  int base_port_ = 0;
  int slot_fd_ = -1;  // the lock of its slot (domain and ports) among concurrent benches
  eval::SimTruth truth_;
  pid_t pid_ = 0;
  std::string stderr_path_, stderr_text_;
  std::atomic<bool> replaying_{false};
  std::atomic<std::int64_t> replay_start_ns_{0};
  std::thread player_;
  replay::ReplayReport replay_report_;
  std::string replay_error_;
};

}  // namespace trailnav::test
