// trailnavd: the trailnav service. Reads one robot config, starts the drivers,
// the pose, obstacle and publisher threads, tells systemd it is ready and
// keeps its watchdog fed while every periodic task makes progress; SIGTERM
// or SIGINT stops it cleanly (exit 0). Exit 2: the configuration is wrong;
// exit 1: something named in it could not be opened or started.
#include <CLI/CLI.hpp>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>

#include <systemd/sd-daemon.h>

#include "daemon.hpp"
#include "robot_config.hpp"
#include "trailnav/runtime/host_clock.hpp"
#include "trailnav/runtime/log.hpp"

using namespace trailnav;

int main(int argc, char** argv) {
  // Host time starts here: steps of the system clock from now on are taken
  // out of every stamp (runtime/host_clock.hpp).
  trailnav::host_clock_start();
  CLI::App app{
      "trailnavd: the trailnav service. Runs the sensor drivers, the pose, the obstacle map and their\n"
      "publisher on the real-time scheduler, as one robot config says, and publishes ROS 2-compatible\n"
      "topics over Cyclone DDS (docs/trailnavd.md, docs/dds.md). Stops on SIGTERM or SIGINT.\n"
      "Exit status: 0 stopped cleanly, 1 could not start, 2 bad configuration.",
      "trailnavd"};
  std::string config_path;
  bool check = false;
  double duration = 0.0;
  app.add_option("-c,--config", config_path,
                 "The robot config (YAML): sensors, ports, calibrations, extrinsics, obstacle map, task table and DDS. "
                 "Examples: board/robots/bench.yaml (loopback bench), board/robots/robot-example.yaml")
      ->required();
  app.add_flag("--check", check, "Validate the config and every file it names, then exit (0: valid)");
  app.add_option("--duration", duration, "Stop by itself after this many seconds (0: run until signalled)")
      ->check(CLI::Range(0.0, 1e9));
  app.set_version_flag("--version", std::string("trailnavd ") + TRAILNAV_VERSION);
  CLI11_PARSE(app, argc, argv);

  auto loaded = daemon::load_robot_config(config_path);
  if (!loaded.config) {
    std::fprintf(stderr, "trailnavd: configuration error: %s\n", loaded.error.c_str());
    return 2;
  }
  const daemon::RobotConfig& config = *loaded.config;
  if (check) {
    // The road network is loaded and the goal placed on it, as at start-up.
    const auto nav = daemon::Daemon::check_navigation(config);
    if (!nav.error.empty()) {
      std::fprintf(stderr, "trailnavd: configuration error: %s\n", nav.error.c_str());
      return 2;
    }
    if (!nav.summary.empty()) std::printf("trailnavd: %s\n", nav.summary.c_str());
    for (const std::string& w : config.warnings) std::printf("trailnavd: warning: %s\n", w.c_str());
    std::printf("trailnavd: %s is valid (%zu tasks%s%s)\n", config_path.c_str(), config.tasks.size(),
                config.task_preset.empty() ? "" : ", task preset ", config.task_preset.c_str());
    return 0;
  }

  // Signals are taken by this thread alone (sigtimedwait): block them before
  // any other thread (Cyclone's, the tasks') exists, so all inherit the mask.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  log::set_min_level(config.runtime.log_level);
  log::start(config.runtime.log_sink);
  for (const std::string& w : config.warnings) TN_LOG_WARN("trailnavd: %s", w.c_str());
  auto created = daemon::Daemon::create(config);
  if (!created.daemon) {
    TN_LOG_ERROR("trailnavd: cannot start: %s", created.error.c_str());
    log::stop();
    std::fprintf(stderr, "trailnavd: cannot start: %s\n", created.error.c_str());
    return 1;
  }
  daemon::Daemon& d = *created.daemon;
  if (Status st = d.start(); !st) {
    TN_LOG_ERROR("trailnavd: cannot start: %s", st.message().c_str());
    log::stop();
    std::fprintf(stderr, "trailnavd: cannot start: %s\n", st.message().c_str());
    return 1;
  }
  TN_LOG_INFO("trailnavd: running %s (%zu tasks, DDS domain %u)", config_path.c_str(), config.tasks.size(),
              config.dds.domain);
  sd_notify(0, "READY=1\nSTATUS=running");

  std::uint64_t watchdog_us = 0;
  const bool watchdog = sd_watchdog_enabled(0, &watchdog_us) > 0 && watchdog_us > 0;
  // Wake at half the watchdog interval (or every second) to check progress.
  const double tick_s = watchdog ? std::min(1.0, static_cast<double>(watchdog_us) * 0.5e-6) : 1.0;
  timespec start{};
  clock_gettime(CLOCK_MONOTONIC, &start);
  int stopped_by = 0;
  while (stopped_by == 0) {
    timespec wait{};
    wait.tv_sec = static_cast<time_t>(tick_s);
    wait.tv_nsec = static_cast<long>((tick_s - static_cast<double>(wait.tv_sec)) * 1e9);
    const int sig = sigtimedwait(&stop_signals, nullptr, &wait);
    if (sig > 0) {
      stopped_by = sig;
      break;
    }
    const bool alive = d.alive();
    const std::string status = "STATUS=" + d.status_line();
    if (alive && watchdog) {
      sd_notify(0, ("WATCHDOG=1\n" + status).c_str());
    } else {
      sd_notify(0, status.c_str());
    }
    if (!alive) TN_LOG_WARN("trailnavd: a periodic task made no progress: withholding the watchdog");
    if (duration > 0.0) {
      timespec now{};
      clock_gettime(CLOCK_MONOTONIC, &now);
      if (static_cast<double>(now.tv_sec - start.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec - start.tv_nsec) >= duration) {
        break;
      }
    }
  }
  sd_notify(0, "STOPPING=1");
  TN_LOG_INFO("trailnavd: stopping (%s)", stopped_by == SIGTERM ? "SIGTERM" : stopped_by == SIGINT ? "SIGINT" : "duration");
  d.stop();
  TN_LOG_INFO("trailnavd: %s", d.status_line().c_str());
  std::fprintf(stderr, "trailnavd: stopped: %s\n%s", d.status_line().c_str(), d.task_report().c_str());
  log::stop();
  return 0;
}
