// `trailnav station eval --sim [--runs N] [--seed S] [--report json]`:
// localisation relative to objects that move (thesis chapter 4) on the
// thesis' simulated floor (board/eval/station_eval.hpp): per object and
// move set, the translation and rotation error of the robot's pose
// relative to the object (mean, std, max) for the multi-body registration
// and for one GICP over the whole reference. docs/registration.md.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>

#include "commands.hpp"
#include "dds.hpp"
#include "sensor_msgs.h"
#include "figure.hpp"
#include "station_eval.hpp"
#include "terminal.hpp"
#include "trailnav/perception/registration/carmen.hpp"
#include "trailnav/perception/registration/station.hpp"
#include "trailnav/perception/registration/station_file.hpp"
#include "trailnav/runtime/config.hpp"

namespace trailnav::cli {
namespace {

struct Options {
  bool sim = false;
  std::string carmen;
  int places = 6;
  std::string report;
  int runs = 10;
  std::uint64_t seed = 1;
  int local_scans = 10;
  int teach_scans = 16;
  std::string metric = "point-to-plane";
  float voxel = 0.0f;  // 0: the default
  int neighbours = 0;
  int teach_rounds = 0;
  double gate = 0.0;
  double fine_gate = 0.0;
  double noise = 1.0;
  bool teach_truth = false;
  bool teach_graph = false;
  bool quiet = false;
  std::string png_dir;
};

void stats_json(const char* name, const eval::ErrorStats& s, const char* tail) {
  std::printf("\"%s\": {\"mean\": %.4f, \"std\": %.4f, \"max\": %.4f}%s", name, s.mean, s.std, s.max, tail);
}

// One picture per object: 5 m x 5 m around it at 1 cm a pixel.
int write_png(const std::string& dir, const eval::StationObjectResult& ob, bool simulated, const char* who) {
  constexpr int kSize = 500;
  constexpr double kRes = 0.01;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(kSize) * kSize * 3, 255);
  const double x0 = ob.centre.x() - 0.5 * kSize * kRes, y0 = ob.centre.y() - 0.5 * kSize * kRes;
  auto plot = [&](const std::vector<Eigen::Vector2f>& pts, Rgb c, int dot) {
    for (const Eigen::Vector2f& p : pts) {
      const int px = static_cast<int>(std::floor((static_cast<double>(p.x()) - x0) / kRes));
      const int py = kSize - 1 - static_cast<int>(std::floor((static_cast<double>(p.y()) - y0) / kRes));
      for (int dy = 0; dy < dot; ++dy) {
        for (int dx = 0; dx < dot; ++dx) {
          const int x = px + dx - dot / 2, y = py + dy - dot / 2;
          if (x < 0 || y < 0 || x >= kSize || y >= kSize) continue;
          std::uint8_t* q = &rgb[(static_cast<std::size_t>(y) * kSize + static_cast<std::size_t>(x)) * 3];
          q[0] = c.r;
          q[1] = c.g;
          q[2] = c.b;
        }
      }
    }
  };
  const Rgb grey{150, 150, 150}, blue{40, 90, 220}, orange{240, 140, 20}, green{20, 160, 60};
  plot(ob.taught_surroundings, grey, 2);
  plot(ob.taught_object, blue, 2);
  plot(ob.last_visit, orange, 3);
  plot(ob.object_moved, green, 2);
  MapFigure f;
  f.title = "station: " + ob.name;
  f.notes.push_back(simulated ? "the thesis' simulated floor (simulated truth)" : "constructed from a real log");
  if (!ob.where.empty()) {
    for (const std::string& l : wrap_text(ob.where, 34)) f.notes.push_back(l);
  }
  char line[128];
  std::snprintf(line, sizeof line, "last visit (set %zu): %.1f mm, %.2f deg off", ob.sets.size(), ob.last_error_mm,
                ob.last_error_deg);
  f.notes.push_back(line);
  f.notes.push_back("5 m x 5 m around the object");
  f.legend = {{grey, "taught surroundings"},
              {blue, "taught object"},
              {orange, "last visit, placed by the surroundings"},
              {green, "taught object moved as estimated"}};
  f.metres_per_pixel = kRes;
  f.north_up = false;
  std::string name = ob.name;
  for (char& c : name) c = c == ' ' ? '-' : c;
  const std::string path = dir + "/station-" + name + ".png";
  if (const Status st = write_map_figure(path, rgb, kSize, kSize, f); !st.is_ok()) {
    std::fprintf(stderr, "%s: cannot write %s: %s\n", who, path.c_str(), st.message().c_str());
    return 1;
  }
  return 0;
}

int run(const Options& o) {
  const char* who = "trailnav station eval";
  if (o.sim == !o.carmen.empty()) {
    std::fprintf(stderr, "%s: give either --sim (the thesis' simulated floor) or --carmen LOG (cases constructed from a "
                 "real CARMEN log)\n", who);
    return 2;
  }
  if (o.report != "" && o.report != "json") {
    std::fprintf(stderr, "%s: --report takes json, not '%s'\n", who, o.report.c_str());
    return 2;
  }
  eval::StationEvalOptions opt;
  opt.runs = o.runs;
  opt.seed = o.seed;
  opt.teach_scans = o.teach_scans;
  opt.station.local_scans = o.local_scans;
  opt.visit_scans = o.local_scans;
  opt.noise = o.noise;
  opt.teach_truth = o.teach_truth;
  opt.station.teach_graph = o.teach_graph;
  if (o.voxel > 0.0f) opt.station.voxel = o.voxel;
  if (o.neighbours > 0) opt.station.neighbours = o.neighbours;
  if (o.teach_rounds > 0) opt.station.teach_rounds = o.teach_rounds;
  if (o.gate > 0.0) opt.station.gicp.max_correspondence_distance = static_cast<float>(o.gate);
  if (o.fine_gate > 0.0) opt.station.fine_gate = static_cast<float>(o.fine_gate);
  if (o.metric == "point-to-plane") {
    opt.station.gicp.metric = perception::registration::Metric::point_to_plane;
  } else if (o.metric == "plane-to-plane") {
    opt.station.gicp.metric = perception::registration::Metric::plane_to_plane;
  } else {
    std::fprintf(stderr, "%s: --metric takes point-to-plane or plane-to-plane, not '%s'\n", who, o.metric.c_str());
    return 2;
  }
  std::unique_ptr<ProgressBar> bar;
  if (!o.quiet) {
    bar = std::make_unique<ProgressBar>("station visits", 1.0, "");
    opt.progress = [&](double f) { bar->update(f); };
  }
  eval::StationEvalResult r;
  if (o.sim) {
    r = eval::evaluate_station_sim(opt);
  } else {
    eval::StationCarmenOptions c;
    c.log = o.carmen;
    c.runs = o.runs;
    c.seed = o.seed;
    c.places = o.places;
    c.teach_scans = o.teach_scans;
    c.visit_scans = o.local_scans;
    c.station = opt.station;
    c.progress = opt.progress;
    r = eval::evaluate_station_carmen(c);
  }
  if (bar) bar->finish();
  if (!r.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, r.error.c_str());
    return 1;
  }
  if (!o.png_dir.empty()) {
    for (const eval::StationObjectResult& ob : r.objects) {
      if (write_png(o.png_dir, ob, o.sim, who) != 0) return 1;
    }
  }
  if (o.report == "json") {
    std::printf("{\"truth\": \"%s\", \"runs\": %d, \"seed\": %llu, \"objects\": [",
                o.sim ? "simulated" : "constructed from a real log (applied motions)", o.runs,
                static_cast<unsigned long long>(o.seed));
    for (std::size_t k = 0; k < r.objects.size(); ++k) {
      const eval::StationObjectResult& ob = r.objects[k];
      std::printf("%s{\"name\": \"%s\", \"where\": \"%s\", \"teach_rounds\": %d, \"teach_converged\": %s, \"teach_largest_correction_m\": %.4f, "
                  "\"teach_error_mm\": %.3f, \"teach_error_deg\": %.4f, \"object_points\": %zu, \"surroundings_points\": %zu, \"sets\": [",
                  k ? ", " : "", ob.name.c_str(), ob.where.c_str(), ob.teach_rounds, ob.teach_converged ? "true" : "false",
                  ob.teach_largest_correction, ob.teach_error_mm, ob.teach_error_deg, ob.object_points,
                  ob.surroundings_points);
      for (std::size_t s = 0; s < ob.sets.size(); ++s) {
        const eval::StationSetResult& x = ob.sets[s];
        std::printf("%s{\"set\": %d, \"moved_m\": %.3f, \"turned_deg\": %.1f, \"runs\": %d, \"unobserved\": %d, ", s ? ", " : "",
                    x.set, x.translation, x.rotation * 180.0 / 3.14159265358979323846, x.runs, x.unobserved);
        stats_json("translation_mm", x.translation_mm, ", ");
        stats_json("rotation_deg", x.rotation_deg, ", ");
        std::printf("\"single_body\": {");
        stats_json("translation_mm", x.single_translation_mm, ", ");
        stats_json("rotation_deg", x.single_rotation_deg, "}}");
      }
      std::printf("]}");
    }
    std::printf("], \"places_changed\": %d}\n", r.places_changed);
    return 0;
  }
  if (o.sim) {
    std::printf("station localisation on the thesis' simulated floor (simulated truth), %d runs per object and set, seed %llu\n",
                o.runs, static_cast<unsigned long long>(o.seed));
    std::printf("error of the object's pose in the robot frame: translation (at its centre) mm and rotation deg, mean / std / max\n\n");
  } else {
    std::printf("station localisation on cases constructed from %s (real scans, applied motions), %d runs per place and set\n",
                o.carmen.c_str(), o.runs);
    std::printf("error of the object's estimated motion: translation (at its centre) mm and rotation deg, mean / std / max\n");
    std::printf("(%d place(s) left out: their object had moved between the two passes by itself)\n\n", r.places_changed);
  }
  std::printf("%-8s %-3s %-14s | %-24s %-24s | %-24s\n", "object", "set", "moved", "multi-body translation",
              "multi-body rotation", "one body (transl., rot.)");
  for (const eval::StationObjectResult& ob : r.objects) {
    if (!ob.where.empty()) std::printf("%s: %s\n", ob.name.c_str(), ob.where.c_str());
    for (const eval::StationSetResult& x : ob.sets) {
      char moved[32];
      std::snprintf(moved, sizeof moved, "%.2f m %4.1f deg", x.translation, x.rotation * 180.0 / 3.14159265358979323846);
      std::printf("%-8s %-3d %-14s | %6.2f %6.2f %6.2f mm     %6.3f %6.3f %6.3f deg  | %7.1f mm %6.2f deg%s\n", ob.name.c_str(),
                  x.set, moved, x.translation_mm.mean, x.translation_mm.std, x.translation_mm.max, x.rotation_deg.mean,
                  x.rotation_deg.std, x.rotation_deg.max, x.single_translation_mm.mean, x.single_rotation_deg.mean,
                  x.unobserved > 0 ? "  (object unobserved in some runs)" : "");
    }
    std::printf("%-8s teach-in: %d rounds%s, poses corrected by up to %.1f mm", ob.name.c_str(), ob.teach_rounds,
                ob.teach_converged ? "" : " (not converged)", 1000.0 * ob.teach_largest_correction);
    if (ob.teach_error_mm >= 0.0) {
      std::printf(", then %.2f mm and %.3f deg from the truth at most", ob.teach_error_mm, ob.teach_error_deg);
    }
    std::printf("; %zu object points, %zu of the surroundings\n", ob.object_points, ob.surroundings_points);
  }
  return 0;
}

namespace reg = perception::registration;

struct TeachOptions {
  std::string log;
  long from = 0, to = -1;
  std::string objects;
  std::string out;
  std::string png;
  std::string name = "station";
  float max_range = 20.0f;
};

// The objects a user marked (station frame, metres):
//   objects:
//     - name: table
//       polygon: [[x, y], [x, y], [x, y], ...]
//     - name: box
//       box: {centre: [x, y], size: [length, width], heading_deg: 0}
std::vector<reg::StationObject> read_objects(const std::string& path) {
  const ConfigNode root = ConfigNode::load_file(path);
  std::vector<reg::StationObject> out;
  for (const ConfigNode& o : root.map_list("objects")) {
    reg::StationObject obj;
    obj.name = o.string("name");
    if (obj.name.empty() || obj.name.size() > reg::kStationMaxName || obj.name == "surroundings") {
      throw ConfigError(o.file(), o.line(), o.path() + ".name", "a name of 1 to 64 characters other than 'surroundings'");
    }
    if (o.has("polygon") == o.has("box")) {
      throw ConfigError(o.file(), o.line(), o.path(), "give either polygon (corners [x, y]) or box (centre, size, heading_deg)");
    }
    if (o.has("polygon")) {
      for (const std::vector<double>& c : o.number_rows("polygon", 2, -1e5, 1e5)) obj.polygon.emplace_back(c[0], c[1]);
      if (obj.polygon.size() < 3 || obj.polygon.size() > reg::kStationMaxCorners) {
        throw ConfigError(o.file(), o.line(), o.path() + ".polygon", "3 to 1024 corners");
      }
    } else {
      const ConfigNode b = o.map("box");
      const std::vector<double> c = b.number_list("centre", -1e5, 1e5);
      const std::vector<double> size = b.number_list("size", 0.01, 100.0);
      if (c.size() != 2 || size.size() != 2) throw ConfigError(b.file(), b.line(), b.path(), "centre: [x, y], size: [length, width]");
      const double h = b.number("heading_deg", -360.0, 360.0, 0.0) * 3.14159265358979323846 / 180.0;
      const double ch = std::cos(h), sh = std::sin(h);
      for (const auto& [u, v] : {std::pair{-1.0, -1.0}, std::pair{1.0, -1.0}, std::pair{1.0, 1.0}, std::pair{-1.0, 1.0}}) {
        const double x = 0.5 * size[0] * u, y = 0.5 * size[1] * v;
        obj.polygon.emplace_back(c[0] + ch * x - sh * y, c[1] + sh * x + ch * y);
      }
      b.reject_unknown_keys();
    }
    o.reject_unknown_keys();
    out.push_back(std::move(obj));
  }
  root.reject_unknown_keys();
  return out;
}

// A located visit drawn over the station: its scans placed by the
// surroundings' transform and each object moved as estimated.
struct Overlay {
  std::vector<reg::Point> visit;                 // station frame
  std::vector<std::vector<reg::Point>> moved;    // per body (0 empty)
};

int write_station_png(const std::string& path, const reg::Station& s, const std::string& title, const std::string& note,
                      const char* who, const Overlay* overlay = nullptr) {
  Eigen::Vector2f lo(1e9f, 1e9f), hi(-1e9f, -1e9f);
  for (const reg::Target& b : s.bodies) {
    for (const reg::Point& p : b.cloud.points) {
      lo = lo.cwiseMin(p.head<2>());
      hi = hi.cwiseMax(p.head<2>());
    }
  }
  for (const auto& poly : s.polygons) {
    for (const Eigen::Vector2d& c : poly) {
      lo = lo.cwiseMin(c.cast<float>());
      hi = hi.cwiseMax(c.cast<float>());
    }
  }
  lo -= Eigen::Vector2f(0.2f, 0.2f);
  hi += Eigen::Vector2f(0.2f, 0.2f);
  const double extent = static_cast<double>(std::max(hi.x() - lo.x(), hi.y() - lo.y()));
  const double res = std::max(0.01, extent / 800.0);
  const int w = std::max(1, static_cast<int>(std::ceil(static_cast<double>(hi.x() - lo.x()) / res)));
  const int h = std::max(1, static_cast<int>(std::ceil(static_cast<double>(hi.y() - lo.y()) / res)));
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 3, 255);
  auto set = [&](double x, double y, Rgb c) {
    const int px = static_cast<int>(std::floor((x - static_cast<double>(lo.x())) / res));
    const int py = h - 1 - static_cast<int>(std::floor((y - static_cast<double>(lo.y())) / res));
    if (px < 0 || py < 0 || px >= w || py >= h) return;
    std::uint8_t* q = &rgb[(static_cast<std::size_t>(py) * static_cast<std::size_t>(w) + static_cast<std::size_t>(px)) * 3];
    q[0] = c.r;
    q[1] = c.g;
    q[2] = c.b;
  };
  const Rgb palette[] = {{40, 90, 220}, {220, 60, 40}, {20, 160, 60}, {200, 120, 0}, {140, 60, 180}, {0, 150, 160}};
  MapFigure f;
  f.title = title;
  f.notes.push_back(note);
  f.notes.push_back("station frame; objects outlined as marked");
  for (std::size_t k = 0; k < s.bodies.size(); ++k) {
    const Rgb c = k == 0 ? Rgb{150, 150, 150} : palette[(k - 1) % std::size(palette)];
    for (const reg::Point& p : s.bodies[k].cloud.points) set(static_cast<double>(p.x()), static_cast<double>(p.y()), c);
    if (k > 0) {
      const auto& poly = s.polygons[k];
      for (std::size_t i = 0; i < poly.size(); ++i) {
        const Eigen::Vector2d a = poly[i], b = poly[(i + 1) % poly.size()];
        const int steps = std::max(1, static_cast<int>((b - a).norm() / (0.5 * res)));
        for (int t = 0; t <= steps; ++t) {
          const Eigen::Vector2d q = a + (b - a) * (static_cast<double>(t) / steps);
          set(q.x(), q.y(), c);
        }
      }
    }
    f.legend.push_back({c, s.names[k] + " (" + std::to_string(s.bodies[k].cloud.size()) + " points)"});
  }
  if (overlay != nullptr) {
    const Rgb orange{240, 140, 20}, green{20, 160, 60};
    for (const reg::Point& p : overlay->visit) set(static_cast<double>(p.x()), static_cast<double>(p.y()), orange);
    for (const auto& body : overlay->moved) {
      for (const reg::Point& p : body) set(static_cast<double>(p.x()), static_cast<double>(p.y()), green);
    }
    f.legend.push_back({orange, "the visit, placed by the surroundings"});
    f.legend.push_back({green, "the objects moved as estimated"});
  }
  f.metres_per_pixel = res;
  f.north_up = false;
  if (const Status st = write_map_figure(path, rgb, w, h, f); !st.is_ok()) {
    std::fprintf(stderr, "%s: cannot write %s: %s\n", who, path.c_str(), st.message().c_str());
    return 1;
  }
  return 0;
}

int run_teach(const TeachOptions& o) {
  const char* who = "trailnav station teach";
  const reg::FlaserLog log = reg::read_flaser_log(o.log, o.from, o.to);
  if (!log.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, log.error.c_str());
    return 1;
  }
  std::vector<reg::StationScan> scans;
  for (const reg::LaserScan2& s : log.scans) {
    reg::StationScan st;
    st.points.reserve(s.ranges.size());
    reg::scan_points(s, o.max_range, 0.05f, st.points);
    st.pose = reg::to_isometry(s.pose);
    scans.push_back(std::move(st));
  }
  const reg::StationConfig config;
  if (scans.size() < 2 || scans.size() > config.max_scans) {
    std::fprintf(stderr, "%s: scans %ld to %ld of %s: %zu FLASER scans; a teach-in takes 2 to %zu\n", who, o.from, o.to,
                 o.log.c_str(), scans.size(), config.max_scans);
    return 1;
  }
  const std::vector<reg::StationObject> objects = o.objects.empty() ? std::vector<reg::StationObject>{} : read_objects(o.objects);
  const reg::TeachResult t = reg::teach(scans, config);
  const reg::BuiltStation built = reg::build_station(scans, objects, config);
  if (!built.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, built.error.c_str());
    return 1;
  }
  if (const std::string e = reg::save_station(reg::station_file_of(built.station, o.name), o.out); !e.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, e.c_str());
    return 1;
  }
  std::printf("station '%s' taught from %zu scans of %s: %d joint-registration rounds%s, poses moved by up to %.1f mm\n",
              o.name.c_str(), scans.size(), o.log.c_str(), t.rounds, t.converged ? "" : " (not converged)",
              1000.0 * t.largest_correction);
  for (std::size_t k = 0; k < built.station.bodies.size(); ++k) {
    std::printf("  %-14s %zu points (%zu before the %.0f cm voxels)\n", built.station.names[k].c_str(),
                built.station.bodies[k].cloud.size(), built.station.taught_points[k], 100.0 * static_cast<double>(config.voxel));
  }
  std::printf("wrote %s\n", o.out.c_str());
  if (!o.png.empty()) {
    if (write_station_png(o.png, built.station, "station: " + o.name,
                          std::to_string(scans.size()) + " teach-in scans, jointly registered", who) != 0) return 1;
    std::printf("wrote %s\n", o.png.c_str());
  }
  return 0;
}

struct LocateOptions {
  std::string station;
  std::string log;
  long from = 0, to = -1;
  std::string report;
  std::string png;
  float max_range = 20.0f;
};

// A visit from a recording against a taught station: the scans registered
// into a local model from the recording's poses (the first one as the
// regular localisation's, the steps between them as odometry), then every
// body at once. What moved since the teach-in, and by how much.
int run_locate(const LocateOptions& o) {
  const char* who = "trailnav station locate";
  if (o.report != "" && o.report != "json") {
    std::fprintf(stderr, "%s: --report takes json, not '%s'\n", who, o.report.c_str());
    return 2;
  }
  const reg::LoadedStation loaded = reg::load_station(o.station);
  if (!loaded.station) {
    std::fprintf(stderr, "%s: %s\n", who, loaded.error.c_str());
    return 1;
  }
  const reg::StationConfig config;
  const reg::BuiltStation built = reg::station_from_file(*loaded.station, config);
  if (!built.error.empty()) {
    std::fprintf(stderr, "%s: %s: %s\n", who, o.station.c_str(), built.error.c_str());
    return 1;
  }
  const reg::FlaserLog log = reg::read_flaser_log(o.log, o.from, o.to);
  if (!log.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, log.error.c_str());
    return 1;
  }
  const std::vector<reg::LaserScan2>& scans = log.scans;
  if (scans.empty() || scans.size() > static_cast<std::size_t>(config.local_scans)) {
    std::fprintf(stderr, "%s: scans %ld to %ld of %s: %zu FLASER scans; a visit takes 1 to %d\n", who, o.from, o.to,
                 o.log.c_str(), scans.size(), config.local_scans);
    return 1;
  }
  reg::StationLocaliser localiser(built.station, config);
  localiser.begin(reg::to_isometry(scans.front().pose));
  std::vector<reg::Point> pts;
  for (std::size_t k = 0; k < scans.size(); ++k) {
    pts.clear();
    pts.reserve(scans[k].ranges.size());
    reg::scan_points(scans[k], o.max_range, 0.05f, pts);
    const Eigen::Isometry3d odometry = k == 0 ? Eigen::Isometry3d::Identity()
                                              : Eigen::Isometry3d(reg::to_isometry(scans[k - 1].pose).inverse() *
                                                                  reg::to_isometry(scans[k].pose));
    localiser.add(pts, odometry);
  }
  const reg::StationFix fix = localiser.localise();
  const reg::Station& st = built.station;
  auto yaw_deg = [](const Eigen::Isometry3d& t) { return reg::to_pose2(t).theta * 180.0 / 3.14159265358979323846; };
  // How far each body's centre (reg::body_centre: its polygon's centroid) moved, as trailnavd reports it.
  auto centre_shift = [&](std::size_t k) {
    const Eigen::Vector3d c = reg::body_centre(st, k);
    return Eigen::Vector3d(fix.moved(k) * c - c);
  };
  if (!o.png.empty()) {
    Overlay ov;
    const Eigen::Isometry3f world = fix.bodies[0].transform.cast<float>();
    for (const reg::Point& p : localiser.local_points().points) ov.visit.push_back(world * p);
    ov.moved.resize(st.bodies.size());
    for (std::size_t k = 1; k < st.bodies.size(); ++k) {
      const Eigen::Isometry3f m = fix.moved(k).cast<float>();
      for (const reg::Point& p : st.bodies[k].cloud.points) ov.moved[k].push_back(m * p);
    }
    if (write_station_png(o.png, st, "station " + loaded.station->name + ": a visit",
                          "a visit of " + std::to_string(scans.size()) + " scans, located", who, &ov) != 0) return 1;
  }
  if (o.report == "json") {
    const Eigen::Isometry3d& r = fix.bodies[0].transform;
    std::printf("{\"station\": \"%s\", \"scans\": %zu, \"local_points\": %zu, \"robot\": {\"x\": %.4f, \"y\": %.4f, "
                "\"yaw_deg\": %.3f}, \"bodies\": [",
                loaded.station->name.c_str(), scans.size(), fix.local_points, r.translation().x(), r.translation().y(),
                yaw_deg(r));
    for (std::size_t k = 0; k < st.bodies.size(); ++k) {
      const Eigen::Isometry3d m = fix.moved(k);
      const Eigen::Vector3d d = centre_shift(k);
      std::printf("%s{\"name\": \"%s\", \"observed\": %s, \"correspondences\": %zu, \"moved_x\": %.4f, \"moved_y\": %.4f, "
                  "\"turned_deg\": %.3f}",
                  k ? ", " : "", st.names[k].c_str(), fix.bodies[k].observed ? "true" : "false", fix.bodies[k].correspondences,
                  d.x(), d.y(), yaw_deg(m));
    }
    std::printf("]}\n");
    return 0;
  }
  const Eigen::Isometry3d& r = fix.bodies[0].transform;
  std::printf("station '%s', a visit of %zu scans (%zu points in its local model), %d iterations\n",
              loaded.station->name.c_str(), scans.size(), fix.local_points, fix.iterations);
  std::printf("  robot in the station frame: (%.3f, %.3f) m, %.2f deg\n", r.translation().x(), r.translation().y(), yaw_deg(r));
  for (std::size_t k = 1; k < st.bodies.size(); ++k) {
    const Eigen::Isometry3d m = fix.moved(k);
    const Eigen::Vector3d d = centre_shift(k);
    if (!fix.bodies[k].observed) {
      std::printf("  %-14s not in view (%zu associations)\n", st.names[k].c_str(), fix.bodies[k].correspondences);
      continue;
    }
    std::printf("  %-14s its centre moved by (%+.3f, %+.3f) m, turned by %+.2f deg since the teach-in (%zu associations)\n",
                st.names[k].c_str(), d.x(), d.y(), yaw_deg(m), fix.bodies[k].correspondences);
  }
  if (!o.png.empty()) std::printf("wrote %s\n", o.png.c_str());
  return 0;
}

}  // namespace

// `trailnav station play`: a recording's 2D scans out as sensor_msgs/LaserScan,
// what a safety laser's ROS 2 driver sends to a trailnavd whose station input
// is `laserscan`: the bench's way to run the station task on a real log.
struct PlayOptions {
  std::string log;
  long from = 0, to = -1;
  std::string topic = "scan";
  std::string frame = "laser";
  double rate = 0.0;   // scans a second; 0: the log's own timing
  double speed = 1.0;  // with the log's timing: faster or slower
  float max_range = 20.0f;
  std::uint32_t domain = 0;
  std::string cyclone_config;
  double wait = 10.0;  // s for a reader to match
  bool quiet = false;
};

int run_play(const PlayOptions& o) {
  const reg::FlaserLog log = reg::read_flaser_log(o.log, o.from, o.to);
  if (!log.error.empty()) {
    std::fprintf(stderr, "trailnav station play: %s\n", log.error.c_str());
    return 1;
  }
  if (log.scans.empty()) {
    std::fprintf(stderr, "trailnav station play: %s: no FLASER scans numbered %ld to %ld%s%s\n", o.log.c_str(), o.from, o.to,
                 log.first_error.empty() ? "" : "; the first refused: ", log.first_error.c_str());
    return 1;
  }
  const dds::ConfigText config = dds::cyclone_config_or_loopback(o.cyclone_config);
  if (!config.error.empty()) {
    std::fprintf(stderr, "trailnav station play: %s\n", config.error.c_str());
    return 2;
  }
  const std::string& xml = config.xml;
  auto domain = dds::Domain::create(o.domain, xml);
  if (!domain.domain) {
    std::fprintf(stderr, "trailnav station play: %s\n", domain.error.c_str());
    return 1;
  }
  // Best effort, keep last 1: a laser driver's sensor-data QoS.
  auto writer = dds::Writer::create(*domain.domain, sensor_msgs_msg_dds__LaserScan__desc, o.topic, {false, 1});
  if (!writer.writer) {
    std::fprintf(stderr, "trailnav station play: %s\n", writer.error.c_str());
    return 1;
  }
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(o.wait);
  for (;;) {
    dds_publication_matched_status_t m{};
    dds_get_publication_matched_status(writer.writer->handle(), &m);
    if (m.current_count > 0) break;
    if (std::chrono::steady_clock::now() >= until) {
      std::fprintf(stderr, "trailnav station play: no reader on %s after %.0f s (is trailnavd running with "
                           "station.input: laserscan and station.topic: %s, on DDS domain %u?)\n",
                   writer.writer->topic().c_str(), o.wait, o.topic.c_str(), o.domain);
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::vector<float> ranges;
  char frame[64];
  std::snprintf(frame, sizeof frame, "%s", o.frame.c_str());
  sensor_msgs_msg_dds__LaserScan_ msg{};
  msg.header.frame_id = frame;
  std::optional<ProgressBar> progress;
  if (!o.quiet) progress.emplace("trailnav station play", static_cast<double>(log.scans.size()), "scans");
  auto next = std::chrono::steady_clock::now();
  for (std::size_t i = 0; i < log.scans.size(); ++i) {
    const reg::LaserScan2& scan = log.scans[i];
    const std::size_t n = scan.ranges.size();
    // The log's beams (carmen.hpp): 181 and 361 from -90 deg to +90 deg, 180
    // and 360 by 180/n deg from -90 deg; at or beyond the range no return.
    const double step = n % 2 == 1 ? M_PI / static_cast<double>(n - 1) : M_PI / static_cast<double>(n);
    ranges.assign(scan.ranges.begin(), scan.ranges.end());
    for (float& r : ranges) {
      if (!(r < o.max_range)) r = std::numeric_limits<float>::infinity();
    }
    msg.angle_min = static_cast<float>(-M_PI / 2.0);
    msg.angle_increment = static_cast<float>(step);
    msg.angle_max = static_cast<float>(-M_PI / 2.0 + static_cast<double>(n - 1) * step);
    msg.range_min = 0.05f;
    msg.range_max = o.max_range;
    msg.ranges._buffer = ranges.data();
    msg.ranges._length = msg.ranges._maximum = static_cast<std::uint32_t>(n);
    msg.ranges._release = false;
    const std::int64_t stamp =
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
    msg.header.stamp.sec = static_cast<std::int32_t>(stamp / 1'000'000'000);
    msg.header.stamp.nanosec = static_cast<std::uint32_t>(stamp % 1'000'000'000);
    if (!writer.writer->write(&msg)) {
      std::fprintf(stderr, "trailnav station play: writing scan %zu failed\n", i);
      return 1;
    }
    if (progress) progress->update(static_cast<double>(i + 1));
    if (i + 1 == log.scans.size()) break;
    const double gap = o.rate > 0.0 ? 1.0 / o.rate
                                    : std::clamp((log.scans[i + 1].timestamp - scan.timestamp) / o.speed, 0.0, 10.0);
    next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(gap));
    std::this_thread::sleep_until(next);
  }
  if (progress) progress->finish();
  std::printf("%zu scans sent on %s (FLASER %ld to %ld of %s)\n", log.scans.size(), writer.writer->topic().c_str(), o.from,
              o.from + static_cast<long>(log.scans.size()) - 1, o.log.c_str());
  return 0;
}

void add_station_commands(CLI::App& app) {
  auto* station = app.add_subcommand(
      "station",
      "Localisation relative to objects that move (thesis chapter 4): a station (a table, a shelf, a box that\n"
      "people push around) taught once and localised against at every visit, relative to each object at once\n"
      "by Generalized ICP for multiple rigid bodies.");
  station->require_subcommand(1);
  static TeachOptions t;
  auto* teach = station->add_subcommand(
      "teach",
      "Teaches a station from a recording (section 4.2.1): the scans around it, their poses refined by joint\n"
      "registration, split into the surroundings and the objects marked in --objects (a YAML list of polygons\n"
      "or boxes in the recording's frame), written to --out. Without --objects the station holds only the\n"
      "surroundings: look at --png and mark the objects. Recordings: CARMEN logs (FLASER lines; plain or gzip).");
  teach->add_option("recording", t.log, "CARMEN log (.log or .log.gz)")->required();
  teach->add_option("--from", t.from, "First FLASER scan of the teach-in (0: the log's first)")->capture_default_str();
  teach->add_option("--to", t.to, "Last FLASER scan of the teach-in (-1: the log's last)")->capture_default_str();
  teach->add_option("--objects", t.objects,
                    "YAML: objects: [{name: table, polygon: [[x, y], ...]}, {name: box, box: {centre: [x, y], size: [l, w], "
                    "heading_deg: 0}}]")
      ->check(CLI::ExistingFile);
  teach->add_option("--out", t.out, "The station file to write (written whole or not at all)")->required();
  teach->add_option("--png", t.png, "A picture of the taught station: each body's points, the objects' polygons, a scale");
  teach->add_option("--name", t.name, "The station's name (kept in the file)")->capture_default_str();
  teach->callback([] { std::exit(run_teach(t)); });
  static LocateOptions l;
  auto* locate = station->add_subcommand(
      "locate",
      "A visit from a recording against a taught station (section 4.2.2): the scans --from..--to registered into\n"
      "a local model (the recording's first pose as the regular localisation's, its steps as odometry), then the\n"
      "surroundings and every object at once. Prints where the robot is in the station frame and how far each\n"
      "object moved and turned since the teach-in. The recording's frame must be the teach-in's.");
  locate->add_option("station", l.station, "The station file (trailnav station teach --out)")->required();
  locate->add_option("recording", l.log, "CARMEN log (.log or .log.gz)")->required();
  locate->add_option("--from", l.from, "First FLASER scan of the visit")->required();
  locate->add_option("--to", l.to, "Last FLASER scan of the visit (at most 10 scans in all)")->required();
  locate->add_option("--report", l.report, "json: robot {x, y, yaw_deg}, bodies[] {name, observed, correspondences, moved_x, moved_y (its centre's shift, m), turned_deg}");
  locate->add_option("--png", l.png, "A picture: the station, the visit placed by the surroundings, the objects moved as estimated");
  locate->callback([] { std::exit(run_locate(l)); });
  static PlayOptions p;
  auto* play = station->add_subcommand(
      "play",
      "Sends a recording's 2D scans as sensor_msgs/LaserScan over DDS (loopback only unless --cyclone-config says\n"
      "otherwise), as a safety laser's ROS 2 driver would: the bench's way to run trailnavd's station task\n"
      "(station.input: laserscan) on a real log. Waits for trailnavd's reader, then paces the scans by the log's\n"
      "own times (or --rate). Recordings: CARMEN logs (FLASER lines; plain or gzip).");
  play->add_option("recording", p.log, "CARMEN log (.log or .log.gz)")->required();
  play->add_option("--from", p.from, "First FLASER scan (0: the log's first)")->capture_default_str();
  play->add_option("--to", p.to, "Last FLASER scan (-1: the log's last)")->capture_default_str();
  play->add_option("--topic", p.topic, "Topic without the rt/ prefix (trailnavd's station.topic)")->capture_default_str();
  play->add_option("--frame", p.frame, "header.frame_id of the scans")->capture_default_str();
  play->add_option("--rate", p.rate, "Scans a second (0: the log's own timing)")->capture_default_str()->check(CLI::Range(0.0, 1000.0));
  play->add_option("--speed", p.speed, "With the log's timing: this many times as fast")->capture_default_str()->check(CLI::Range(0.01, 100.0));
  play->add_option("--max-range", p.max_range, "Ranges at or beyond are sent as no return (m)")->capture_default_str()->check(CLI::Range(0.1, 1000.0));
  play->add_option("--domain", p.domain, "DDS domain id")->capture_default_str()->check(CLI::Range(0, 232));
  play->add_option("--cyclone-config", p.cyclone_config, "Cyclone DDS XML configuration (default: loopback only: interface lo, no multicast)");
  play->add_option("--wait", p.wait, "Seconds to wait for a reader")->capture_default_str()->check(CLI::PositiveNumber);
  play->add_flag("--quiet", p.quiet, "No progress bar");
  play->callback([] { std::exit(run_play(p)); });
  static Options o;
  auto* ev = station->add_subcommand(
      "eval",
      "The thesis' simulation experiment (section 4.3.1) on its 8 m x 6 m floor: a box, a U-shaped shelf and a\n"
      "four-legged table, each taught from an arc of 2D laser scans (180 deg, 0.5 deg steps, 1 cm noise) with\n"
      "noisy odometry, then visited --runs times per move set (0.05 m, 0.1 m, 5 deg, 10 deg, and both twice).\n"
      "Prints the error of the robot's pose relative to each object (mean, std, max) for the multi-body\n"
      "registration and for one GICP over the whole reference. Truth is simulated.");
  ev->add_flag("--sim", o.sim, "Run on the thesis' simulated floor");
  ev->add_option("--carmen", o.carmen,
                 "Cases constructed from a real CARMEN log (FLASER lines; plain or gzip): places passed twice, an object\n"
                 "picked in the first pass and moved in the second by the thesis' real sets (0.1 m, 10 deg, both), the\n"
                 "occlusion cast again beam by beam");
  ev->add_option("--places", o.places, "Places of the CARMEN log to use at most")->capture_default_str()->check(CLI::Range(1, 64));
  ev->add_option("--report", o.report, "json: one JSON object (objects[].sets[].translation_mm, rotation_deg, single_body)");
  ev->add_option("--runs", o.runs, "Visits per object and move set")->capture_default_str()->check(CLI::Range(1, 1000));
  ev->add_option("--seed", o.seed, "Seed of the simulation (moves, drives, noise)")->capture_default_str();
  ev->add_option("--local-scans", o.local_scans, "N: scans of a visit's local model")->capture_default_str()->check(CLI::Range(1, 100));
  ev->add_option("--teach-scans", o.teach_scans, "Scans of each teach-in")->capture_default_str()->check(CLI::Range(2, 256));
  ev->add_option("--metric", o.metric, "point-to-plane (the thesis') or plane-to-plane")->capture_default_str();
  const perception::registration::StationConfig d;
  ev->add_option("--voxel", o.voxel, "Voxel size of the reference and the local model (m; default " + std::to_string(d.voxel) + ")");
  ev->add_option("--neighbours", o.neighbours, "k for the covariances and normals (default " + std::to_string(d.neighbours) + ")");
  ev->add_option("--teach-rounds", o.teach_rounds, "Joint-registration rounds of the teach-in at most (default " + std::to_string(d.teach_rounds) + ")");
  ev->add_option("--fine-gate", o.fine_gate, "The second pass's gate (m; default " + std::to_string(d.fine_gate) + ")");
  ev->add_option("--max-correspondence", o.gate, "Associations farther are dropped (m; default " + std::to_string(d.gicp.max_correspondence_distance) + ")");
  ev->add_option("--noise", o.noise, "Scales every simulated noise: the laser's 1 cm, the odometry's 0.1 m/s and 0.1 rad/s, the start's 3 cm and 1.1 deg (0: none)")
      ->capture_default_str()->check(CLI::Range(0.0, 10.0));
  ev->add_flag("--teach-graph", o.teach_graph, "Teach-in as a pose graph over every pair of scans (instead of Gauss-Seidel rounds)");
  ev->add_flag("--teach-truth", o.teach_truth, "Take the teach-in's poses from the simulated truth (the visits' own error alone)");
  ev->add_option("--png", o.png_dir,
                 "Directory for one picture per object (station-NAME.png, 5 m around it): the taught surroundings and\n"
                 "object, the last visit placed by the surroundings, and the taught object moved as estimated")
      ->check(CLI::ExistingDirectory);
  ev->add_flag("--quiet", o.quiet, "No progress bar");
  ev->callback([] { std::exit(run(o)); });
}

}  // namespace trailnav::cli
