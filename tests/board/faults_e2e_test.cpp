// trailnavd under injected faults (issue 36): the `mixed-route` drive replayed
// into the daemon with one fault at a time (board/replay/faults.hpp, as
// `trailnav replay --fault` does it), and for each:
//   - the daemon keeps running and exits cleanly when stopped;
//   - health names the fault (the stream's status goes stale or counts it)
//     within the stale time, plus a margin for a loaded machine;
//   - no unseen cell is ever reported free: every free cell of every map is
//     one the simulated lidar had a return in by then (truth/returns.u32,
//     simulated truth), through the odometry and true poses of the map's
//     instant;
//   - maps resume when the data does, the pose recovers after a GPS outage;
//   - the counters health reports match what the replayer injected.
// The margins: health is published every 0.5 s and read here as it arrives;
// on two loaded cores a status was seen up to about a second after the fact,
// so each "within" gets the stale time plus 2 s.
#include <gtest/gtest.h>

#include <signal.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "bench_daemon.hpp"
#include "dds.hpp"
#include "diagnostic_msgs.h"
#include "geometry_msgs.h"
#include "nav_msgs.h"
#include "sim_truth.hpp"
#include "subscriber.hpp"
#include "tf2_msgs.h"
#include "trailnav/runtime/clock.hpp"

using namespace trailnav;

namespace {

constexpr double kStaleAfter = 0.5;   // dds.stale_after_s of the bench config (the default)
constexpr double kMargin = 2.0;       // s: health's period and a loaded machine (see the top)
constexpr double kGpsFixTimeout = 2.0;  // gps.fix_timeout_s (the default)

struct Health {
  double t = 0.0;  // s after the replay's start (host clock), when it arrived
  std::string name;
  int level = 0;
  std::string message;
  std::map<std::string, std::string> values;
  double number(const std::string& key) const {
    const auto it = values.find(key);
    return it == values.end() ? std::nan("") : std::atof(it->second.c_str());
  }
  bool flag(const std::string& key) const {
    const auto it = values.find(key);
    return it != values.end() && it->second == "true";
  }
};

struct FaultRun {
  replay::ReplayReport report;
  std::string replay_error;
  int exit_code = -1;
  bool alive_throughout = true;
  std::string stderr_text;
  std::vector<Health> health;
  std::vector<double> fresh_maps;  // s after the replay's start (their stamps)
  std::vector<double> stale_maps;  // s: resent maps (the lidar silent), when received
  struct Utm {
    double t;          // s after the replay's start, the pose's stamp
    double de, dn;     // UTM pose minus the true position (world frame + the origin's UTM)
  };
  std::vector<Utm> utm;
  // Free cells against the simulated lidar's returns.
  std::size_t maps_checked = 0, free_cells = 0, unseen_free = 0;
  std::size_t maps_without_tf = 0;  // fresh maps with no odom -> base_link at their stamp
  double worst_unseen_s = 0.0;  // how far ahead of the first return the worst one was

  const replay::FaultCounters& counters(const std::string& stream) const {
    static const replay::FaultCounters none;
    for (const auto& c : report.faults) {
      if (c.stream == stream) return c;
    }
    return none;
  }
  // The newest health of `name` at or before t (null: none).
  const Health* at(const std::string& name, double t) const {
    const Health* best = nullptr;
    for (const Health& h : health) {
      if (h.name == name && h.t <= t) best = &h;
    }
    return best;
  }
  const Health* last(const std::string& name) const { return at(name, 1e9); }
  // The first health of `name` from `from` on for which `pred` holds.
  template <class Pred>
  const Health* first(const std::string& name, double from, Pred pred) const {
    for (const Health& h : health) {
      if (h.name == name && h.t >= from && pred(h)) return &h;
    }
    return nullptr;
  }
  std::size_t fresh_between(double a, double b) const {
    return static_cast<std::size_t>(std::count_if(fresh_maps.begin(), fresh_maps.end(), [&](double t) { return t >= a && t < b; }));
  }
  // Revolutions the obstacle thread says it did not map, all through the
  // run: replaced before it saw them (it was too slow: sanitizers, a loaded
  // machine) or left out because the pose thread was behind them. How many
  // maps come in a window depends on the machine; these plus the maps made
  // do not. (Not those left out for want of odometry: the tests that cut
  // it check that maps come back after it does.)
  std::size_t maps_left_out() const {
    const Health* h = last("trailnavd: obstacles");
    if (h == nullptr) return 0;
    auto n = [&](const char* key) {
      const double v = h->number(key);
      return std::isnan(v) ? std::size_t{0} : static_cast<std::size_t>(v);
    };
    return n("skipped") + n("pose_late");
  }
  // Maps the daemon made in [a, b) by its own count: the obstacle task's
  // `revolutions` in the health received by b minus that received by a
  // (health comes once a second). A subscriber starved by a loaded machine
  // misses maps (the writer keeps only the newest for a reader that has not
  // acknowledged the one before); this count cannot.
  std::size_t made_between(double a, double b) const {
    const auto revolutions = [&](double t) {
      const Health* h = at("trailnavd: obstacles", t);
      const double v = h == nullptr ? 0.0 : h->number("revolutions");
      return std::isnan(v) ? 0.0 : v;
    };
    return static_cast<std::size_t>(std::max(0.0, revolutions(b) - revolutions(a)));
  }
  // Maps made in [a, b) (received, or counted by the daemon where it made
  // more than a starved subscriber received), and those the daemon counted
  // as left out.
  std::size_t accounted_between(double a, double b) const {
    return std::max(fresh_between(a, b), made_between(a, b)) + maps_left_out();
  }
};

std::int64_t stamp_ns(const builtin_interfaces_msg_dds__Time_& s) {
  return static_cast<std::int64_t>(s.sec) * 1'000'000'000 + static_cast<std::int64_t>(s.nanosec);
}

// The simulated lidar's first return per 0.2 m cell (ms after the start;
// max when never), and the earliest one within a radius of a point: a map's
// free cell must have one within the distance its position may be off by.
struct SeenRaster {
  double x0 = 0.0, y0 = 0.0, cell = 0.2;
  int w = 0, h = 0;
  std::vector<std::uint32_t> first_ms;
  std::uint32_t within(double x, double y, double r) const {
    std::uint32_t best = std::numeric_limits<std::uint32_t>::max();
    const int i0 = static_cast<int>(std::floor((x - r - x0) / cell)), i1 = static_cast<int>(std::floor((x + r - x0) / cell));
    const int j0 = static_cast<int>(std::floor((y - r - y0) / cell)), j1 = static_cast<int>(std::floor((y + r - y0) / cell));
    for (int j = std::max(j0, 0); j <= std::min(j1, h - 1); ++j) {
      for (int i = std::max(i0, 0); i <= std::min(i1, w - 1); ++i) {
        best = std::min(best, first_ms[static_cast<std::size_t>(j) * static_cast<std::size_t>(w) + static_cast<std::size_t>(i)]);
      }
    }
    return best;
  }
};

SeenRaster seen_raster(const eval::SimTruth& truth) {
  SeenRaster s;
  const eval::TruthRaster& r = truth.terrain;
  const int k = std::max(1, static_cast<int>(std::lround(s.cell / r.resolution)));
  s.cell = r.resolution * k;
  s.x0 = r.x0 - 0.5 * r.resolution;
  s.y0 = r.y0 - 0.5 * r.resolution;
  s.w = (r.width + k - 1) / k;
  s.h = (r.height + k - 1) / k;
  s.first_ms.assign(static_cast<std::size_t>(s.w) * static_cast<std::size_t>(s.h), std::numeric_limits<std::uint32_t>::max());
  for (int y = 0; y < r.height; ++y) {
    for (int x = 0; x < r.width; ++x) {
      const std::uint32_t v = truth.returns[static_cast<std::size_t>(y) * static_cast<std::size_t>(r.width) + static_cast<std::size_t>(x)];
      if (v == 0) continue;
      std::uint32_t& c = s.first_ms[static_cast<std::size_t>(y / k) * static_cast<std::size_t>(s.w) + static_cast<std::size_t>(x / k)];
      c = std::min(c, v - 1);
    }
  }
  return s;
}

// `seconds` of the mixed-route drive replayed into trailnavd with `faults`.
FaultRun run_with_faults(const std::vector<std::string>& faults, double seconds = 18.0, const std::string& tag = "faults") {
  FaultRun out;
  test::BenchDaemonOptions bo;
  bo.scenario = "mixed-route";
  bo.seconds = seconds;
  bo.tag = tag;
  bo.navigation = true;
  bo.faults = faults;
  // The faults are injected into the streams, not into the kernel's
  // pseudo-terminal path: GPS and IMU bytes come as UDP datagrams (a serial
  // device server), which a loaded machine does not hold up for seconds as it
  // does a pseudo-terminal's kernel worker (docs/testing.md). The daemon's
  // handling of a starved serial IMU is tested in the pose's own tests.
  bo.serial_over_udp = true;
  std::string error;
  auto bench = test::BenchDaemon::start(TRAILNAVD_BINARY, bo, error);
  EXPECT_TRUE(bench) << error;
  if (!bench) return out;
  const eval::SimTruth& truth = bench->truth();
  EXPECT_FALSE(truth.returns.empty()) << "the recording has no truth/returns.u32";
  const SeenRaster seen = truth.returns.empty() ? SeenRaster{} : seen_raster(truth);
  sim::Polyline no_trail;
  eval::TrailCheck to_world(truth, no_trail, 0);

  auto domain = dds::Domain::create(bench->domain(), dds::loopback_config());
  EXPECT_TRUE(domain.domain) << domain.error;
  if (!domain.domain) return out;
  // 10 s of maps: beside two hogs in its session this process lost its core
  // for seconds, and a reader keeping 32 lost 24 of 159 maps it then counted
  // as never made.
  auto maps = dds::Subscriber::create(*domain.domain, "trailnav/obstacle_map", &nav_msgs_msg_dds__OccupancyGrid__desc, 0, false, 100);
  // The odometry poses come from odom -> base_link on tf: the pose-rate ones
  // and each map's own at its stamp (the pose topic is a sample of the poses
  // at pose_rate_hz and need not hold a map's).
  // Deep enough for 20 s of transforms (about 40 a second): this process may
  // lose its core for a second on a loaded machine, and every map's own must
  // still be there when it takes them.
  auto poses = dds::Subscriber::create(*domain.domain, "tf", &tf2_msgs_msg_dds__TFMessage__desc, 0, false, 1000);
  auto utm = dds::Subscriber::create(*domain.domain, "trailnav/utm_pose", &geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc, 0);
  auto health = dds::Subscriber::create(*domain.domain, "diagnostics", &diagnostic_msgs_msg_dds__DiagnosticArray__desc, 0);
  EXPECT_TRUE(maps.subscriber && poses.subscriber && utm.subscriber && health.subscriber);
  if (!(maps.subscriber && poses.subscriber && utm.subscriber && health.subscriber)) return out;

  // The drive starts once the daemon is up (its first health; see
  // BenchDaemon::wait_until_up), then 0.5 s for discovery to settle.
  EXPECT_TRUE(bench->wait_until_up([&](double wait_s) {
    bool up = false;
    health.subscriber->take(wait_s, [&](const dds::ReceivedSample&) { up = true; });
    return up;
  })) << "no health from trailnavd within 60 s of its start";
  bench->start_replay(0.5);
  std::map<std::int64_t, bool> map_stamps;
  struct Pending {
    std::int64_t stamp;
    double ox, oy, res;
    std::uint32_t w, h;
    std::vector<std::int8_t> data;
  };
  std::vector<Pending> pending;  // checked once the poses around them have arrived
  std::map<std::int64_t, std::array<double, 3>> odometry;  // odom -> base_link: x, y, yaw
  struct UtmRaw {
    std::int64_t stamp;
    double e, n;
  };
  std::vector<UtmRaw> utm_raw;
  auto since_start = [&](std::int64_t host_ns) {
    const std::int64_t start = bench->replay_start_ns();
    return start == 0 ? -1e9 : static_cast<double>(host_ns - start) * 1e-9;
  };
  auto take_all = [&](double wait) {
    poses.subscriber->take(wait, [&](const dds::ReceivedSample& r) {
      const auto& m = *static_cast<const tf2_msgs_msg_dds__TFMessage_*>(r.sample);
      for (std::uint32_t i = 0; i < m.transforms._length; ++i) {
        const auto& t = m.transforms._buffer[i];
        if (std::strcmp(t.header.frame_id, "odom") != 0 || std::strcmp(t.child_frame_id, "base_link") != 0) continue;
        const auto& q = t.transform.rotation;
        odometry[stamp_ns(t.header.stamp)] = {t.transform.translation.x, t.transform.translation.y,
                                              std::atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))};
      }
    });
    maps.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& g = *static_cast<const nav_msgs_msg_dds__OccupancyGrid_*>(r.sample);
      const std::int64_t stamp = stamp_ns(g.header.stamp);
      if (map_stamps.count(stamp) != 0) {
        out.stale_maps.push_back(since_start(r.receive_ns));
        return;
      }
      map_stamps[stamp] = true;
      out.fresh_maps.push_back(since_start(stamp));
      pending.push_back({stamp, g.info.origin.position.x, g.info.origin.position.y, g.info.resolution, g.info.width,
                         g.info.height, std::vector<std::int8_t>(g.data._buffer, g.data._buffer + g.data._length)});
    });
    utm.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& p = *static_cast<const geometry_msgs_msg_dds__PoseWithCovarianceStamped_*>(r.sample);
      utm_raw.push_back({stamp_ns(p.header.stamp), p.pose.pose.position.x, p.pose.pose.position.y});
    });
    health.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& a = *static_cast<const diagnostic_msgs_msg_dds__DiagnosticArray_*>(r.sample);
      for (std::uint32_t i = 0; i < a.status._length; ++i) {
        const auto& s = a.status._buffer[i];
        Health h;
        h.t = since_start(r.receive_ns);
        h.name = s.name;
        h.level = s.level;
        h.message = s.message;
        for (std::uint32_t k = 0; k < s.values._length; ++k) h.values[s.values._buffer[k].key] = s.values._buffer[k].value;
        out.health.push_back(std::move(h));
      }
    });
  };
  while (bench->replaying()) {
    take_all(0.05);
    if (::kill(bench->pid(), 0) != 0) out.alive_throughout = false;
  }
  // Health and the last maps of the drive.
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  while (std::chrono::steady_clock::now() < until) take_all(0.05);
  if (::kill(bench->pid(), 0) != 0) out.alive_throughout = false;
  bench->join_replay();
  out.report = bench->replay_report();
  out.replay_error = bench->replay_error();
  out.exit_code = bench->stop();
  out.stderr_text = bench->stderr_text();

  // The checks through the truth need the offset of the daemon's clock from
  // the recording's.
  const std::int64_t offset = bench->replay_start_ns() - truth.trajectory.front().utc_ns;
  to_world.set_offset(offset);
  to_world.set_past_end_tolerance(out.report.send_error.max + eval::kDaemonStallTolerance_ns);
  for (const auto& [stamp, xyyaw] : odometry) to_world.add_odometry_pose(stamp, xyyaw[0], xyyaw[1], xyyaw[2]);
  for (const Pending& m : pending) {
    if (odometry.count(m.stamp) == 0) ++out.maps_without_tf;
    double ax = 0, ay = 0, bx = 0, by = 0, cx = 0, cy = 0;
    if (!to_world.to_world(m.stamp, 0.0, 0.0, ax, ay) || !to_world.to_world(m.stamp, 1.0, 0.0, bx, by) ||
        !to_world.to_world(m.stamp, 0.0, 1.0, cx, cy)) {
      continue;
    }
    ++out.maps_checked;
    const std::size_t unseen_before = out.unseen_free;
    const double t_ms = static_cast<double>(m.stamp - bench->replay_start_ns()) * 1e-6;
    const double mx = m.ox + 0.5 * m.w * m.res, my = m.oy + 0.5 * m.h * m.res;  // the robot, at the map's centre
    for (std::uint32_t j = 0; j < m.h; ++j) {
      for (std::uint32_t i = 0; i < m.w; ++i) {
        const std::int8_t v = m.data[static_cast<std::size_t>(j) * m.w + i];
        if (v < 0 || v >= 50) continue;
        ++out.free_cells;
        const double x = m.ox + (i + 0.5) * m.res, y = m.oy + (j + 0.5) * m.res;
        const double wx = ax + (bx - ax) * x + (cx - ax) * y, wy = ay + (by - ay) * x + (cy - ay) * y;
        // How far the cell may be off: its own 0.1 m and the odometry-to-truth
        // mapping's error (a few centimetres), plus the yaw error of that
        // mapping and the ring spacing's sampling at the cell's distance
        // from the robot (the map's centre): 3 % of it.
        const double d = std::hypot(x - mx, y - my);
        std::uint32_t first = seen.within(wx, wy, 0.2);  // most cells: a return right there
        if (static_cast<double>(first) > t_ms + 200.0) first = seen.within(wx, wy, 0.4 + 0.03 * d);
        // A revolution is stamped at its end; allow its 0.1 s and the
        // replay's sending jitter.
        if (static_cast<double>(first) > t_ms + 200.0) {
          ++out.unseen_free;
          if (first != std::numeric_limits<std::uint32_t>::max()) {
            out.worst_unseen_s = std::max(out.worst_unseen_s, (static_cast<double>(first) - t_ms) * 1e-3);
          } else {
            out.worst_unseen_s = std::numeric_limits<double>::infinity();
          }
          if (out.unseen_free <= 5) {
            std::printf("[ faults ] unseen free cell: map %.2f s, odom (%.2f, %.2f), %.1f m from the robot, world (%.2f, %.2f), "
                        "value %d, first return within %.2f m %s (%.2f s)\n",
                        t_ms * 1e-3, x, y, d, wx, wy, v, 0.4 + 0.03 * d,
                        first == std::numeric_limits<std::uint32_t>::max() ? "never" : "later",
                        (static_cast<double>(first) - t_ms) * 1e-3);
          }
        }
      }
    }
    if (std::getenv("TRAILNAV_FAULTS_DUMP") != nullptr) {
      std::printf("[ dump ] map %.2f s: %zu unseen free cells; odometry origin in the world (%.3f, %.3f) yaw %.3f deg\n",
                  t_ms * 1e-3, out.unseen_free - unseen_before, ax, ay, std::atan2(by - ay, bx - ax) * 180.0 / M_PI);
    }
  }
  // The UTM pose against the truth: world frame + the UTM of its origin, which
  // is the first pose's difference before any fault (taken as the median of
  // the first second).
  for (const UtmRaw& u : utm_raw) {
    eval::TruthAt p;
    if (!eval::truth_at(truth.trajectory, u.stamp - offset, p)) continue;
    out.utm.push_back({since_start(u.stamp), u.e - p.x, u.n - p.y});
  }
  std::printf("[ faults ]");
  for (const auto& f : faults) std::printf(" %s", f.c_str());
  std::printf("\n[ faults ] %zu fresh maps, %zu resent stale; %zu maps checked, %zu free cells, %zu unseen; exit %d\n",
              out.fresh_maps.size(), out.stale_maps.size(), out.maps_checked, out.free_cells, out.unseen_free, out.exit_code);
  std::printf("[ faults ] replay sent late: p50 %.2f ms, p99 %.2f ms, max %.2f ms; %llu events over 1 ms late\n",
              static_cast<double>(out.report.send_error.p50) * 1e-6, static_cast<double>(out.report.send_error.p99) * 1e-6,
              static_cast<double>(out.report.send_error.max) * 1e-6, static_cast<unsigned long long>(out.report.late_over_1ms));
  if (std::getenv("TRAILNAV_FAULTS_DUMP") != nullptr) {
    std::map<std::string, const Health*> last;
    for (const Health& h : out.health) last[h.name] = &h;
    for (const auto& [name, h] : last) {
      std::printf("[ dump ] %s:", name.c_str());
      for (const auto& [k, v] : h->values) std::printf(" %s=%s", k.c_str(), v.c_str());
      std::printf("\n");
    }
  }
  for (const char* task : {"trailnavd: obstacles", "trailnavd: terrain"}) {
    if (const Health* h = out.last(task)) {
      std::printf("[ faults ] %s: revolutions %s, pose_waits %s, pose_late %s, pose_wait_max_ms %s\n", task,
                  h->values.count("revolutions") ? h->values.at("revolutions").c_str() : "-",
                  h->values.count("pose_waits") ? h->values.at("pose_waits").c_str() : "-",
                  h->values.count("pose_late") ? h->values.at("pose_late").c_str() : "-",
                  h->values.count("pose_wait_max_ms") ? h->values.at("pose_wait_max_ms").c_str() : "-");
    }
  }
  for (const auto& c : out.report.faults) {
    if (std::getenv("TRAILNAV_FAULTS_DUMP") == nullptr && c.events == c.sent && c.lost + c.silenced + c.reordered + c.duplicated + c.truncated + c.corrupted + c.shifted + c.stepped + c.injected == 0) {
      continue;
    }
    std::printf("[ faults ] %-14s events %llu sent %llu lost %llu silenced %llu reordered %llu duplicated %llu truncated %llu "
                "corrupted %llu shifted %llu stepped %llu injected %llu\n",
                c.stream.c_str(), static_cast<unsigned long long>(c.events), static_cast<unsigned long long>(c.sent),
                static_cast<unsigned long long>(c.lost), static_cast<unsigned long long>(c.silenced),
                static_cast<unsigned long long>(c.reordered), static_cast<unsigned long long>(c.duplicated),
                static_cast<unsigned long long>(c.truncated), static_cast<unsigned long long>(c.corrupted),
                static_cast<unsigned long long>(c.shifted), static_cast<unsigned long long>(c.stepped),
                static_cast<unsigned long long>(c.injected));
  }
  return out;
}

// What every fault run must show.
void expect_survived(const FaultRun& r) {
  EXPECT_EQ(r.replay_error, "");
  EXPECT_TRUE(r.alive_throughout);
  EXPECT_EQ(r.exit_code, 0) << r.stderr_text;
  EXPECT_GT(r.maps_checked, 50u);
  EXPECT_EQ(r.maps_without_tf, 0u) << "each map moving with the pose comes with its own transform";
  EXPECT_GT(r.free_cells, 10'000u);
  EXPECT_EQ(r.unseen_free, 0u) << "free cells the lidar had not seen (the worst " << r.worst_unseen_s << " s early)";
  EXPECT_NE(r.stderr_text.find(", 0 real-time allocations"), std::string::npos) << r.stderr_text;
}

std::uint64_t count(const Health* h, const std::string& key) {
  return h == nullptr ? 0 : static_cast<std::uint64_t>(h->number(key));
}

// Every lidar datagram the replayer sent arrived, or the kernel says it
// dropped it; and maps came all through the drive after `from` s.
void expect_lidar_datagrams_counted(const FaultRun& r, double from, double to, std::size_t maps) {
  const Health* lidar = r.last("trailnavd: lidar");
  ASSERT_NE(lidar, nullptr);
  EXPECT_EQ(count(lidar, "packets") + count(lidar, "kernel_drops"), r.counters("lidar").sent);
  EXPECT_GT(r.accounted_between(from, to), maps);
}

}  // namespace

// Without a fault: the checks themselves hold (the baseline of the others).
TEST(TrailnavdFaults, NoFaultIsTheBaseline) {
  const FaultRun r = run_with_faults({}, 14.0, "faults-none");
  expect_survived(r);
  const Health* lidar = r.last("trailnavd: lidar");
  ASSERT_NE(lidar, nullptr);
  EXPECT_EQ(count(lidar, "lost_packets"), 0u);
  EXPECT_EQ(count(lidar, "malformed"), 0u);
  // The last map is resent stale only after the drive has ended, or while
  // revolutions were left out for a reason the daemon counted (a loaded
  // machine: the pose thread behind, the obstacle thread too slow).
  const auto during = static_cast<std::size_t>(
      std::count_if(r.stale_maps.begin(), r.stale_maps.end(), [](double t) { return t <= 13.9; }));
  EXPECT_LE(during, r.maps_left_out());
}

TEST(TrailnavdFaults, LidarPacketLossInBursts) {
  const FaultRun r = run_with_faults({"lidar:loss=0.02,burst=10@4+8"}, 16.0, "faults-loss");
  expect_survived(r);
  const auto& c = r.counters("lidar");
  ASSERT_GT(c.lost, 500u);
  const Health* lidar = r.last("trailnavd: lidar");
  ASSERT_NE(lidar, nullptr);
  // Every datagram sent arrived (or the kernel says it dropped it).
  EXPECT_EQ(count(lidar, "packets") + count(lidar, "kernel_drops"), c.sent);
  // The driver tells lost packets from the gaps in the sensor's timestamps:
  // every burst is seen, to the packet, except where bursts touch a
  // revolution's cut (an estimate then within a packet or two per burst).
  const double lost = static_cast<double>(count(lidar, "lost_packets"));
  EXPECT_NEAR(lost, static_cast<double>(c.lost), 0.05 * static_cast<double>(c.lost) + 5.0);
  // Maps on through the loss and after it.
  EXPECT_GT(r.accounted_between(5.0, 11.0), 40u);
  EXPECT_GT(r.accounted_between(13.0, 15.5), 15u);
}

TEST(TrailnavdFaults, LidarPacketsReordered) {
  const FaultRun r = run_with_faults({"lidar:reorder=0.02,depth=3@4"}, 14.0, "faults-reorder");
  expect_survived(r);
  const auto& c = r.counters("lidar");
  ASSERT_GT(c.reordered, 100u);
  expect_lidar_datagrams_counted(r, 5.0, 13.0, 60);
}

TEST(TrailnavdFaults, LidarPacketsDuplicated) {
  const FaultRun r = run_with_faults({"lidar:duplicate=0.05@4"}, 14.0, "faults-duplicate");
  expect_survived(r);
  const auto& c = r.counters("lidar");
  ASSERT_GT(c.duplicated, 250u);  // 5 % of the ~7,500 data packets after 4 s
  EXPECT_EQ(c.sent, c.events + c.duplicated);
  expect_lidar_datagrams_counted(r, 5.0, 13.0, 60);
}

TEST(TrailnavdFaults, LidarPacketsTruncated) {
  const FaultRun r = run_with_faults({"lidar:truncate=0.01@4"}, 14.0, "faults-truncate");
  expect_survived(r);
  const auto& c = r.counters("lidar");
  ASSERT_GT(c.truncated, 50u);
  const Health* lidar = r.last("trailnavd: lidar");
  ASSERT_NE(lidar, nullptr);
  // Every cut datagram is refused as the wrong size, and counted.
  EXPECT_EQ(count(lidar, "malformed"), c.truncated);
  EXPECT_GT(r.accounted_between(5.0, 13.0), 60u);
}

TEST(TrailnavdFaults, LidarSilenceMakesTheMapStaleAndMapsResume) {
  const FaultRun r = run_with_faults({"lidar:silence=4@6"}, 16.0, "faults-silence");
  expect_survived(r);
  const auto& c = r.counters("lidar");
  ASSERT_GT(c.silenced, 1000u);
  // Health says so within the stale time.
  const Health* stale = r.first("trailnavd: lidar", 6.0, [](const Health& h) { return h.flag("stale"); });
  ASSERT_NE(stale, nullptr);
  EXPECT_LE(stale->t, 6.0 + kStaleAfter + kMargin);
  EXPECT_NE(stale->message.find("silent for"), std::string::npos) << stale->message;
  // The last map is resent stale meanwhile, and no fresh map is made.
  EXPECT_GT(r.stale_maps.size(), 3u);
  EXPECT_EQ(r.fresh_between(6.3, 9.9), 0u);
  // Maps and health come back with the data.
  EXPECT_GT(r.accounted_between(10.0, 15.5), 30u);
  EXPECT_GT(r.fresh_between(10.0, 15.5), 5u);
  const Health* back = r.first("trailnavd: lidar", 10.0, [](const Health& h) { return !h.flag("stale"); });
  ASSERT_NE(back, nullptr);
  EXPECT_LE(back->t, 10.0 + kMargin);
  // The revolution the silence cut is dropped, not joined to the first
  // after it (points seconds apart in one revolution).
  EXPECT_EQ(count(r.last("trailnavd: lidar"), "discontinuities"), 1u);
}

TEST(TrailnavdFaults, LidarClockStepsForward) {
  const FaultRun r = run_with_faults({"lidar:clock-step=2.5@6", "lidar-position:clock-step=2.5@6"}, 14.0, "faults-step-fwd");
  expect_survived(r);
  ASSERT_GT(r.counters("lidar").stepped, 1000u);
  const Health* before = r.at("trailnavd: lidar", 5.5);
  const Health* after = r.last("trailnavd: lidar");
  ASSERT_NE(before, nullptr);
  ASSERT_NE(after, nullptr);
  // Health names the step: the clock relation re-anchored (docs/dds.md, "One clock").
  EXPECT_GT(count(after, "clock_steps"), count(before, "clock_steps"));
  EXPECT_EQ(count(after, "discontinuities"), 1u);
  const Health* named = r.first("trailnavd: lidar", 6.0, [&](const Health& h) { return count(&h, "clock_steps") > count(before, "clock_steps"); });
  ASSERT_NE(named, nullptr);
  EXPECT_LE(named->t, 6.0 + kStaleAfter + kMargin);
  EXPECT_GT(r.accounted_between(7.0, 13.0), 40u);
}

TEST(TrailnavdFaults, LidarClockStepsBack) {
  const FaultRun r = run_with_faults({"lidar:clock-step=-2.5@6", "lidar-position:clock-step=-2.5@6"}, 14.0, "faults-step-back");
  expect_survived(r);
  const Health* before = r.at("trailnavd: lidar", 5.5);
  const Health* after = r.last("trailnavd: lidar");
  ASSERT_NE(before, nullptr);
  ASSERT_NE(after, nullptr);
  EXPECT_GT(count(after, "clock_steps"), count(before, "clock_steps"));
  EXPECT_GT(r.accounted_between(7.0, 13.0), 40u);
}

TEST(TrailnavdFaults, GpsCorruptedSentencesAreRejectedAndCounted) {
  const FaultRun r = run_with_faults({"gps:corrupt=0.05@3"}, 14.0, "faults-corrupt");
  expect_survived(r);
  const auto& c = r.counters("gps");
  ASSERT_GT(c.corrupted, 10u);
  const Health* gps = r.at("trailnavd: gps", 13.5);  // before the drive ends (and the GPS goes quiet)
  ASSERT_NE(gps, nullptr);
  // Each corrupted read breaks the one sentence it touches (a read may hold
  // the end of one and the start of the next: never more than two).
  const Health* end = r.last("trailnavd: gps");
  EXPECT_GE(count(end, "rejected"), c.corrupted);
  EXPECT_LE(count(end, "rejected"), 2 * c.corrupted);
  EXPECT_FALSE(gps->flag("stale"));
}

TEST(TrailnavdFaults, GpsOutageThenAJumpOf50Metres) {
  const FaultRun r = run_with_faults({"gps:outage=5,jump=50@5"}, 18.0, "faults-gps");
  expect_survived(r);
  const auto& c = r.counters("gps");
  ASSERT_GT(c.silenced, 100u);
  ASSERT_GT(c.shifted, 50u);
  // Health: no fix within the fix timeout.
  const Health* lost = r.first("trailnavd: gps", 5.0, [](const Health& h) { return h.message != "fix"; });
  ASSERT_NE(lost, nullptr);
  EXPECT_LE(lost->t, 5.0 + kGpsFixTimeout + kMargin);
  // The pose keeps going on odometry meanwhile, and after the GPS returns it
  // follows the receiver again: it re-anchors on the agreeing fixes 50 m to
  // the north and counts a jump.
  const Health* jumped = r.first("trailnavd: pose", 10.0, [](const Health& h) { return h.number("gps_jumps") >= 1.0; });
  ASSERT_NE(jumped, nullptr);
  EXPECT_LE(jumped->t, 10.0 + 2.0 + kMargin);
  std::vector<double> de0, dn0, de1, dn1;
  for (const auto& u : r.utm) {
    if (u.t > 2.0 && u.t < 5.0) {
      de0.push_back(u.de);
      dn0.push_back(u.dn);
    }
    if (u.t > 14.0) {
      de1.push_back(u.de);
      dn1.push_back(u.dn);
    }
  }
  ASSERT_GT(de0.size(), 10u);
  ASSERT_GT(de1.size(), 10u);
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  // The UTM pose minus the true position: 50 m further north, no further east.
  std::printf("[ faults ] UTM pose minus truth: before the outage east %.2f north %.2f m, after it east %.2f north %.2f m\n",
              median(de0), median(dn0), median(de1), median(dn1));
  // The simulated receiver's own error wanders by a metre or two (and the
  // alignment re-anchors on five fixes): 3 m either way.
  EXPECT_NEAR(median(dn1) - median(dn0), 50.0, 3.0);
  EXPECT_NEAR(median(de1) - median(de0), 0.0, 3.0);
  const Health* pose = r.last("trailnavd: pose");
  ASSERT_NE(pose, nullptr);
  EXPECT_TRUE(pose->flag("utm_valid"));
}

TEST(TrailnavdFaults, CanBusOffAndRestart) {
  const FaultRun r = run_with_faults({"wheels:bus-off=3@6"}, 14.0, "faults-busoff");
  expect_survived(r);
  const auto& c = r.counters("wheels");
  ASSERT_EQ(c.injected, 2u);
  ASSERT_GT(c.silenced, 100u);
  const Health* off = r.first("trailnavd: can", 6.0, [](const Health& h) { return h.number("bus_off") >= 1.0; });
  ASSERT_NE(off, nullptr);
  EXPECT_LE(off->t, 6.0 + kStaleAfter + kMargin);
  EXPECT_NE(off->level, 0);  // not OK while the bus is off
  const Health* can = r.last("trailnavd: can");
  ASSERT_NE(can, nullptr);
  EXPECT_EQ(count(can, "bus_off"), 1u);
  EXPECT_EQ(count(can, "restarted"), 1u);
  EXPECT_EQ(count(can, "error_frames"), 2u);
  EXPECT_EQ(count(can, "frames"), c.sent);  // error frames are frames too
  // Frames again after the restart: health back to OK.
  const Health* back = r.first("trailnavd: can", 9.0, [](const Health& h) { return h.level == 0; });
  ASSERT_NE(back, nullptr);
  EXPECT_LE(back->t, 9.0 + kMargin);
  // Without wheel speeds the odometry does not know how far the robot went:
  // the obstacle map is not made then (sent stale), and is started afresh
  // when the speeds return.
  const Health* lost = r.first("trailnavd: obstacles", 6.0, [](const Health& h) { return h.level == 2; });
  ASSERT_NE(lost, nullptr);
  EXPECT_LE(lost->t, 6.0 + 0.25 + kMargin);  // the odometry's wheel timeout
  EXPECT_NE(lost->message.find("odometry lost"), std::string::npos) << lost->message;
  EXPECT_GT(r.stale_maps.size(), 1u);
  EXPECT_EQ(r.fresh_between(6.6, 9.0), 0u);
  EXPECT_GT(r.accounted_between(9.5, 13.5), 25u);
  EXPECT_GT(r.fresh_between(9.5, 13.5), 5u);
  EXPECT_EQ(count(r.last("trailnavd: obstacles"), "map_resets"), 1u);
}
