// `trailnav echo <topic>`: subscribes to one of trailnavd's topics (or any ROS 2
// topic of a type trailnav knows) and prints what arrives: a summary per
// sample, then rate, sizes and latency. Maps can be saved as PNG.
#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "commands.hpp"
#include "dds.hpp"
#include "diagnostic_msgs.h"
#include "geometry_msgs.h"
#include "nav_msgs.h"
#include "geographic_msgs.h"
#include "sensor_msgs.h"
#include "std_msgs.h"
#include "tf2_msgs.h"
#include "trailnav_msgs.h"
#include "map_png.hpp"
#include "trailnav/runtime/histogram.hpp"
#include "subscriber.hpp"

namespace trailnav::cli {
namespace {

namespace fs = std::filesystem;

volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

struct EchoOptions {
  std::string topic;
  std::string png_dir;
  int count = 0;
  double timeout = 10.0;
  unsigned domain = 0;
  std::string cyclone_config;
  bool quiet = false;
  bool digest = false;
};

// FNV-1a, 64 bits: a fingerprint of a map's cells to compare what two
// subscribers (or two DDS implementations) received.
std::uint64_t fnv1a(const void* data, std::size_t n) noexcept {
  std::uint64_t h = 14695981039346656037ull;
  const auto* p = static_cast<const std::uint8_t*>(data);
  for (std::size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

double stamp_s(const builtin_interfaces_msg_dds__Time_& t) { return t.sec + 1e-9 * t.nanosec; }

void print_sample(const dds::ReceivedSample& r, std::uint64_t n, double latency_ms, bool digest) {
  char head[96];
  std::snprintf(head, sizeof head, "#%llu %7.1f kB %7.2f ms", static_cast<unsigned long long>(n),
                static_cast<double>(r.wire_bytes) / 1000.0, latency_ms);
  if (r.type == &nav_msgs_msg_dds__OccupancyGrid__desc) {
    const auto& g = *static_cast<const nav_msgs_msg_dds__OccupancyGrid_*>(r.sample);
    std::uint64_t occ = 0, fr = 0, unk = 0;
    for (std::uint32_t i = 0; i < g.data._length; ++i) {
      const std::int8_t v = g.data._buffer[i];
      if (v < 0) {
        ++unk;
      } else if (v > 50) {
        ++occ;
      } else {
        ++fr;
      }
    }
    std::printf("%s  stamp %.3f  %ux%u @ %.3f m, origin (%.2f, %.2f) in %s: %llu occupied, %llu free, %llu unknown\n",
                head, stamp_s(g.header.stamp), g.info.width, g.info.height, static_cast<double>(g.info.resolution),
                g.info.origin.position.x, g.info.origin.position.y, g.header.frame_id, static_cast<unsigned long long>(occ),
                static_cast<unsigned long long>(fr), static_cast<unsigned long long>(unk));
    if (digest) {
      std::printf("    digest stamp %d.%09u cells %016llx\n", g.header.stamp.sec, g.header.stamp.nanosec,
                  static_cast<unsigned long long>(fnv1a(g.data._buffer, g.data._length)));
    }
  } else if (r.type == &geometry_msgs_msg_dds__PoseStamped__desc) {
    const auto& p = *static_cast<const geometry_msgs_msg_dds__PoseStamped_*>(r.sample);
    const auto& q = p.pose.orientation;
    const double yaw = std::atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z));
    std::printf("%s  stamp %.3f  %s x %.3f y %.3f z %.3f m, yaw %.1f deg\n", head, stamp_s(p.header.stamp),
                p.header.frame_id, p.pose.position.x, p.pose.position.y, p.pose.position.z, yaw * 180.0 / M_PI);
  } else if (r.type == &geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc) {
    const auto& p = *static_cast<const geometry_msgs_msg_dds__PoseWithCovarianceStamped_*>(r.sample);
    std::printf("%s  stamp %.3f  %s easting %.2f northing %.2f m, sigma %.2f / %.2f m\n", head, stamp_s(p.header.stamp),
                p.header.frame_id, p.pose.pose.position.x, p.pose.pose.position.y, std::sqrt(p.pose.covariance[0]),
                std::sqrt(p.pose.covariance[7]));
  } else if (r.type == &sensor_msgs_msg_dds__NavSatFix__desc) {
    const auto& f = *static_cast<const sensor_msgs_msg_dds__NavSatFix_*>(r.sample);
    std::printf("%s  stamp %.3f  lat %.7f lon %.7f alt %.2f m\n", head, stamp_s(f.header.stamp), f.latitude,
                f.longitude, f.altitude);
  } else if (r.type == &diagnostic_msgs_msg_dds__DiagnosticArray__desc) {
    const auto& a = *static_cast<const diagnostic_msgs_msg_dds__DiagnosticArray_*>(r.sample);
    static const char* const kLevels[] = {"OK", "WARN", "ERROR", "STALE"};
    std::printf("%s  stamp %.3f  %u statuses\n", head, stamp_s(a.header.stamp), a.status._length);
    for (std::uint32_t i = 0; i < a.status._length; ++i) {
      const auto& s = a.status._buffer[i];
      std::printf("    %-5s %s: %s", s.level < 4 ? kLevels[s.level] : "?", s.name, s.message);
      for (std::uint32_t k = 0; k < s.values._length; ++k) std::printf("  %s=%s", s.values._buffer[k].key, s.values._buffer[k].value);
      std::printf("\n");
    }
  } else if (r.type == &nav_msgs_msg_dds__Path__desc) {
    const auto& p = *static_cast<const nav_msgs_msg_dds__Path_*>(r.sample);
    std::printf("%s  stamp %.3f  %s, %u poses", head, stamp_s(p.header.stamp), p.header.frame_id, p.poses._length);
    if (p.poses._length > 0) {
      const auto& a = p.poses._buffer[0].pose.position;
      const auto& b = p.poses._buffer[p.poses._length - 1].pose.position;
      std::printf(" from (%.2f, %.2f) to (%.2f, %.2f)", a.x, a.y, b.x, b.y);
    }
    std::printf("\n");
  } else if (r.type == &tf2_msgs_msg_dds__TFMessage__desc) {
    const auto& m = *static_cast<const tf2_msgs_msg_dds__TFMessage_*>(r.sample);
    std::printf("%s  %u transforms\n", head, m.transforms._length);
    for (std::uint32_t i = 0; i < m.transforms._length; ++i) {
      const auto& t = m.transforms._buffer[i];
      const auto& q = t.transform.rotation;
      const double yaw = std::atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z));
      std::printf("    stamp %.3f  %s -> %s: x %.3f y %.3f z %.3f m, yaw %.2f deg\n", stamp_s(t.header.stamp),
                  t.header.frame_id, t.child_frame_id, t.transform.translation.x, t.transform.translation.y,
                  t.transform.translation.z, yaw * 180.0 / M_PI);
    }
  } else if (r.type == &nav_msgs_msg_dds__Odometry__desc) {
    const auto& o = *static_cast<const nav_msgs_msg_dds__Odometry_*>(r.sample);
    const auto& q = o.pose.pose.orientation;
    const double yaw = std::atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z));
    std::printf("%s  stamp %.3f  %s -> %s x %.3f y %.3f m, yaw %.1f deg, speed %.2f m/s, yaw rate %.3f rad/s, sigma %.2f m\n",
                head, stamp_s(o.header.stamp), o.header.frame_id, o.child_frame_id, o.pose.pose.position.x,
                o.pose.pose.position.y, yaw * 180.0 / M_PI, o.twist.twist.linear.x, o.twist.twist.angular.z,
                std::sqrt(o.pose.covariance[0]));
  } else if (r.type == &trailnav_msgs_msg_dds__NavigationStatus__desc) {
    const auto& s = *static_cast<const trailnav_msgs_msg_dds__NavigationStatus_*>(r.sample);
    std::printf("%s  stamp %.3f  %s", head, stamp_s(s.header.stamp), s.state_name);
    if (s.has_goal) {
      std::printf(", goal %.7f %.7f (%s %.1f %.1f), %.1f of %.1f m to go, subgoal %u of %u", s.goal.latitude, s.goal.longitude,
                  s.header.frame_id, s.goal_easting, s.goal_northing, s.distance_remaining, s.route_length, s.active_subgoal,
                  s.subgoals);
    }
    std::printf("; goals %llu (refused %llu), cancels %llu, plans %llu%s%s\n", static_cast<unsigned long long>(s.goals_received),
                static_cast<unsigned long long>(s.goals_refused), static_cast<unsigned long long>(s.cancels),
                static_cast<unsigned long long>(s.plans), s.message[0] != '\0' ? "\n    " : "", s.message);
  } else if (r.type == &trailnav_msgs_msg_dds__PlaceMatch__desc) {
    const auto& m = *static_cast<const trailnav_msgs_msg_dds__PlaceMatch_*>(r.sample);
    std::printf("%s  stamp %.3f  %s: camera frame %u is database image %u (taken %.3f), probability %.3f (peak %.4f), "
                "step %llu, %u frames back, chain %u%s\n",
                head, stamp_s(m.header.stamp), m.header.frame_id, m.frame_sequence, m.database_index,
                stamp_s(m.database_stamp), m.probability, m.peak, static_cast<unsigned long long>(m.steps), m.lag_frames,
                m.chain_length, m.in_sequence ? " (in sequence)" : " (not in a sequence)");
  } else if (r.type == &trailnav_msgs_msg_dds__StationFix__desc) {
    const auto& f = *static_cast<const trailnav_msgs_msg_dds__StationFix_*>(r.sample);
    std::printf("%s  stamp %.3f  %s '%s' fix %llu (visit %llu, %u local points): robot x %.3f y %.3f m, yaw %.2f deg%s\n", head,
                stamp_s(f.header.stamp), f.header.frame_id, f.station, static_cast<unsigned long long>(f.fix_number),
                static_cast<unsigned long long>(f.visit), f.local_points, f.robot_x, f.robot_y, f.robot_yaw * 180.0 / M_PI,
                f.surroundings_observed ? "" : " (surroundings not observed)");
    for (std::uint32_t k = 0; k < f.objects._length; ++k) {
      const auto& o = f.objects._buffer[k];
      std::printf("    %s (%s): centre moved %.1f mm, turned %.2f deg, %u associations%s\n", o.name, o.frame_id,
                  o.centre_moved * 1e3, o.turned * 180.0 / M_PI, o.correspondences, o.observed ? "" : " (not observed)");
    }
  } else if (r.type == &sensor_msgs_msg_dds__LaserScan__desc) {
    const auto& l = *static_cast<const sensor_msgs_msg_dds__LaserScan_*>(r.sample);
    std::printf("%s  stamp %.3f  %s: %u beams from %.1f to %.1f deg, ranges %.2f-%.2f m\n", head, stamp_s(l.header.stamp),
                l.header.frame_id, l.ranges._length, static_cast<double>(l.angle_min) * 180.0 / M_PI,
                static_cast<double>(l.angle_max) * 180.0 / M_PI, static_cast<double>(l.range_min),
                static_cast<double>(l.range_max));
  } else if (r.type == &geographic_msgs_msg_dds__GeoPoseStamped__desc) {
    const auto& g = *static_cast<const geographic_msgs_msg_dds__GeoPoseStamped_*>(r.sample);
    std::printf("%s  stamp %.3f  lat %.7f lon %.7f alt %.2f m\n", head, stamp_s(g.header.stamp), g.pose.position.latitude,
                g.pose.position.longitude, g.pose.position.altitude);
  } else if (r.type == &sensor_msgs_msg_dds__PointCloud2__desc) {
    const auto& c = *static_cast<const sensor_msgs_msg_dds__PointCloud2_*>(r.sample);
    std::printf("%s  stamp %.3f  %s, %u x %u points of %u bytes, fields", head, stamp_s(c.header.stamp), c.header.frame_id,
                c.width, c.height, c.point_step);
    for (std::uint32_t f = 0; f < c.fields._length; ++f) std::printf(" %s", c.fields._buffer[f].name);
    // trailnav's own clouds: how many points the Dirac model called obstacles.
    std::int32_t obstacle_at = -1;
    for (std::uint32_t f = 0; f < c.fields._length; ++f) {
      if (std::strcmp(c.fields._buffer[f].name, "obstacle") == 0 && c.fields._buffer[f].datatype == 2) {
        obstacle_at = static_cast<std::int32_t>(c.fields._buffer[f].offset);
      }
    }
    if (obstacle_at >= 0 && c.point_step > 0 && static_cast<std::uint32_t>(obstacle_at) < c.point_step) {
      std::uint64_t obstacles = 0;
      for (std::uint32_t i = 0; i + c.point_step <= c.data._length; i += c.point_step) obstacles += c.data._buffer[i + static_cast<std::uint32_t>(obstacle_at)] != 0;
      std::printf("; %llu obstacle points", static_cast<unsigned long long>(obstacles));
    }
    std::printf("\n");
  } else if (r.type == &std_msgs_msg_dds__Empty__desc) {
    std::printf("%s  (empty)\n", head);
  } else if (r.type == &trailnav_msgs_msg_dds__TerrainClassMap__desc) {
    const auto& t = *static_cast<const trailnav_msgs_msg_dds__TerrainClassMap_*>(r.sample);
    std::uint64_t counts[6] = {};
    for (std::uint32_t i = 0; i < t.class_id._length; ++i) ++counts[std::min<std::uint8_t>(t.class_id._buffer[i], 5)];
    std::printf("%s  stamp %.3f  %ux%u @ %.3f m:", head, stamp_s(t.header.stamp), t.info.width, t.info.height,
                static_cast<double>(t.info.resolution));
    for (std::uint32_t c = 0; c < t.class_names._length && c < 5; ++c) {
      std::printf(" %s %llu", t.class_names._buffer[c], static_cast<unsigned long long>(counts[c]));
    }
    std::printf(" unknown %llu\n", static_cast<unsigned long long>(counts[5]));
  }
}

int run_echo(const EchoOptions& o) {
  const dds::ConfigText config = dds::cyclone_config_or_loopback(o.cyclone_config);
  if (!config.error.empty()) {
    std::fprintf(stderr, "trailnav echo: %s\n", config.error.c_str());
    return 2;
  }
  const std::string& xml = config.xml;
  if (!o.png_dir.empty()) {
    std::error_code ec;
    fs::create_directories(o.png_dir, ec);
    if (ec) {
      std::fprintf(stderr, "trailnav echo: cannot create %s: %s\n", o.png_dir.c_str(), ec.message().c_str());
      return 1;
    }
  }
  auto domain = dds::Domain::create(o.domain, xml);
  if (!domain.domain) {
    std::fprintf(stderr, "trailnav echo: %s\n", domain.error.c_str());
    return 1;
  }
  auto sub = dds::Subscriber::create(*domain.domain, o.topic, nullptr, o.timeout);
  if (!sub.subscriber) {
    std::fprintf(stderr, "trailnav echo: %s\n", sub.error.c_str());
    return 1;
  }
  std::fprintf(stderr, "trailnav echo: %s (%s), DDS domain %u\n", sub.subscriber->topic().c_str(),
               sub.subscriber->type().m_typename, o.domain);
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);

  std::uint64_t n = 0, bytes = 0, pngs = 0;
  DurationHistogram latencies;  // ns, within 3 %
  std::int64_t first_ns = 0, last_ns = 0;
  double silent = 0.0;
  std::string base = o.topic;
  std::replace(base.begin(), base.end(), '/', '_');
  while (!g_stop && (o.count == 0 || n < static_cast<std::uint64_t>(o.count))) {
    const int got = sub.subscriber->take(0.2, [&](const dds::ReceivedSample& r) {
      if (o.count > 0 && n >= static_cast<std::uint64_t>(o.count)) return;
      ++n;
      bytes += r.wire_bytes;
      if (first_ns == 0) first_ns = r.receive_ns;
      last_ns = r.receive_ns;
      const double latency_ms = static_cast<double>(r.receive_ns - r.source_ns) * 1e-6;
      latencies.record(r.receive_ns - r.source_ns);
      if (!o.quiet) print_sample(r, n, latency_ms, o.digest);
      if (!o.png_dir.empty()) {
        char name[64];
        std::snprintf(name, sizeof name, "-%06llu.png", static_cast<unsigned long long>(n));
        const std::string path = (fs::path(o.png_dir) / (base + name)).string();
        Status st;
        if (r.type == &nav_msgs_msg_dds__OccupancyGrid__desc) {
          const auto& grid = *static_cast<const nav_msgs_msg_dds__OccupancyGrid_*>(r.sample);
          if (o.topic.find("traversability") != std::string::npos) {
            st = write_cost_png(path, grid, o.topic, "100 (1 - P(trav)) of the learnt layer", "0: traversable",
                                "100: not traversable");
          } else if (o.topic.find("terrain_cost") != std::string::npos) {
            st = write_cost_png(path, grid, o.topic, "the expected class cost x 100");
          } else {
            st = write_occupancy_png(path, grid, o.topic);
          }
          ++pngs;
        } else if (r.type == &trailnav_msgs_msg_dds__TerrainClassMap__desc) {
          st = write_terrain_png(path, *static_cast<const trailnav_msgs_msg_dds__TerrainClassMap_*>(r.sample), o.topic);
          ++pngs;
        }
        if (!st) std::fprintf(stderr, "trailnav echo: %s\n", st.message().c_str());
      }
    });
    silent = got > 0 ? 0.0 : silent + 0.2;
    if (silent >= o.timeout) {
      std::fprintf(stderr, "trailnav echo: nothing for %.0f s, stopping\n", o.timeout);
      break;
    }
  }
  const DurationSummary lat = latencies.summary();
  const auto ms = [](Nanos v) { return nanos_to_seconds(v) * 1e3; };
  const double span = static_cast<double>(last_ns - first_ns) * 1e-9;
  std::printf("%s: %llu samples, %.2f Hz, mean %.1f kB; latency (source time to here) p50 %.2f ms, p99 %.2f ms, max %.2f ms",
              sub.subscriber->topic().c_str(), static_cast<unsigned long long>(n), n > 1 && span > 0 ? static_cast<double>(n - 1) / span : 0.0,
              n ? static_cast<double>(bytes) / static_cast<double>(n) / 1000.0 : 0.0, ms(lat.p50), ms(lat.p99), ms(lat.max));
  if (pngs > 0) std::printf("; %llu PNGs in %s", static_cast<unsigned long long>(pngs), o.png_dir.c_str());
  std::printf("\n");
  return n > 0 ? 0 : 1;
}

}  // namespace

void add_echo_command(CLI::App& app) {
  auto o = std::make_shared<EchoOptions>();
  auto* cmd = app.add_subcommand("echo",
                                 "Print what arrives on a trailnavd topic (DDS, ROS 2 naming): one line per sample with "
                                 "its size and latency, then rate and latency percentiles; save maps as PNG.\n"
                                 "Topics: trailnav/obstacle_map, trailnav/terrain_map, trailnav/terrain_cost, trailnav/traversability, trailnav/pose, "
                                 "trailnav/utm_pose, trailnav/fix, trailnav/subgoal, trailnav/subgoal_path, "
                                 "trailnav/navigation_status, tf, tf_static, odom, diagnostics, and when configured "
                                 "trailnav/obstacle_map_coarse, trailnav/points, trailnav/place_match, trailnav/place_pose, "
                                 "trailnav/station and trailnav/station/<body>; and the order topics "
                                 "trailnav/goal, trailnav/geo_goal, trailnav/cancel (docs/dds.md). Exit 1 when nothing arrived.");
  cmd->add_option("topic", o->topic, "Topic name without the rt/ prefix, e.g. trailnav/obstacle_map")->required();
  cmd->add_option("--png", o->png_dir, "Save every map (obstacle map, terrain map, cost layers) as DIR/<topic>-<n>.png");
  cmd->add_option("--count", o->count, "Stop after this many samples (0: until Ctrl-C or silence)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--timeout", o->timeout, "Seconds to wait for a writer, and of silence before stopping")
      ->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--domain", o->domain, "DDS domain id")->capture_default_str()->check(CLI::Range(0, 232));
  cmd->add_option("--cyclone-config", o->cyclone_config,
                  "Cyclone DDS XML configuration (default: loopback only: interface lo, no multicast)");
  cmd->add_flag("--quiet", o->quiet, "Only the summary at the end");
  cmd->add_flag("--digest", o->digest,
                "Occupancy grids: also print the stamp and an FNV-1a 64 fingerprint of the cells (to compare subscribers)");
  cmd->callback([o] {
    const int rc = run_echo(*o);
    if (rc != 0) std::exit(rc);
  });
}

}  // namespace trailnav::cli
