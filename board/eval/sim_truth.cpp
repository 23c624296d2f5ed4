#include "sim_truth.hpp"

#include <algorithm>
#include <limits>
#include <cmath>
#include <numbers>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>

#include <GeographicLib/UTMUPS.hpp>

#include "png.hpp"
#include "trailnav/drivers/velodyne/packet.hpp"
#include "trailnav/runtime/config.hpp"
#include "world.hpp"

namespace trailnav::eval {

namespace fs = std::filesystem;

std::uint8_t TruthRaster::at(double x, double y, std::uint8_t outside) const noexcept {
  const long i = std::lround((x - x0) / resolution);
  const long j = std::lround((y - y0) / resolution);
  if (i < 0 || j < 0 || i >= width || j >= height) return outside;
  return data[static_cast<std::size_t>(j) * static_cast<std::size_t>(width) + static_cast<std::size_t>(i)];
}

namespace {

Status load_raster(const std::string& path, int width, int height, TruthRaster& out) {
  cli::GreyImage img;
  if (Status st = cli::read_png_grey(path, img); !st) return st;
  if (static_cast<int>(img.width) != width || static_cast<int>(img.height) != height) {
    return Status::error(path + ": " + std::to_string(img.width) + " x " + std::to_string(img.height) +
                         " pixels, rasters.yaml says " + std::to_string(width) + " x " + std::to_string(height));
  }
  out.width = width;
  out.height = height;
  out.data.resize(img.pixels.size());
  // PNG rows are north-up; ours are south-up.
  const auto w = static_cast<std::size_t>(width);
  for (std::size_t j = 0; j < static_cast<std::size_t>(height); ++j) {
    std::copy_n(img.pixels.begin() + static_cast<std::ptrdiff_t>((static_cast<std::size_t>(height) - 1 - j) * w), w,
                out.data.begin() + static_cast<std::ptrdiff_t>(j * w));
  }
  return Status::ok();
}

}  // namespace

SimTruthResult load_sim_truth(const std::string& dir) {
  SimTruth t;
  t.dir = dir;
  auto scenario = sim::load_scenario((fs::path(dir) / "scenario.yaml").string());
  if (!scenario.scenario) return {std::nullopt, scenario.error};
  t.scenario = std::move(*scenario.scenario);
  int width = 0, height = 0;
  try {
    const ConfigNode r = ConfigNode::load_file((fs::path(dir) / "rasters.yaml").string());
    const double res = r.number("resolution", 1e-4, 100.0);
    width = static_cast<int>(r.integer("width", 1, 1'000'000));
    height = static_cast<int>(r.integer("height", 1, 1'000'000));
    const auto sw = r.number_list("south_west", -1e7, 1e7);
    if (sw.size() != 2) r.fail("south_west", "needs [x, y]");
    for (TruthRaster* raster : {&t.terrain, &t.obstacles}) {
      raster->resolution = res;
      raster->x0 = sw[0];
      raster->y0 = sw[1];
    }
  } catch (const ConfigError& e) {
    return {std::nullopt, e.what()};
  }
  if (Status st = load_raster((fs::path(dir) / "terrain.png").string(), width, height, t.terrain); !st) {
    return {std::nullopt, st.message()};
  }
  if (Status st = load_raster((fs::path(dir) / "obstacles.png").string(), width, height, t.obstacles); !st) {
    return {std::nullopt, st.message()};
  }
  const auto n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  for (auto [file, out] : {std::pair{"sightings.u32", &t.sightings}, std::pair{"side_hits.u32", &t.side_hits},
                           std::pair{"side_sightings.u32", &t.side_sightings}, std::pair{"returns.u32", &t.returns}}) {
    const fs::path sight = fs::path(dir) / file;
    if (!fs::exists(sight)) continue;
    std::ifstream s(sight, std::ios::binary);
    std::vector<std::uint8_t> bytes(n * 4);
    if (!s.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size())) || s.peek() != EOF) {
      return {std::nullopt, sight.string() + ": not " + std::to_string(n) + " uint32 values (" + std::to_string(width) +
                                " x " + std::to_string(height) + " pixels)"};
    }
    out->resize(n);
    for (std::size_t i = 0; i < n; ++i) (*out)[i] = velodyne::read_u32(bytes.data() + i * 4);  // little-endian
  }
  // Simulated before side_hits.u32 existed, side_sightings.u32 held every side
  // return within 20 m, which is what side_hits.u32 holds now: no face counts
  // as shown.
  if (t.side_hits.empty()) {
    t.side_hits = std::move(t.side_sightings);
    t.side_sightings.clear();
  }
  const std::string traj = (fs::path(dir) / "trajectory.csv").string();
  std::ifstream in(traj);
  if (!in) return {std::nullopt, traj + ": cannot open"};
  std::string line;
  std::getline(in, line);
  int line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    // time_s,utc_ns,x,y,z,roll,pitch,yaw,speed,yaw_rate,v_left,v_right,route_arc,lat,lon
    double time_s = 0, speed = 0, yaw_rate = 0, vl = 0, vr = 0;
    long long utc = 0;
    TruthPose p;
    const int fields =
        std::sscanf(line.c_str(), "%lf,%lld,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf", &time_s, &utc, &p.x, &p.y,
                    &p.z, &p.roll, &p.pitch, &p.yaw, &speed, &yaw_rate, &vl, &vr, &p.arc, &p.lat, &p.lon);
    if (fields != 13 && fields != 15) {
      return {std::nullopt, traj + ":" + std::to_string(line_no) + ": not a trajectory row"};
    }
    p.utc_ns = utc;
    t.trajectory.push_back(p);
  }
  if (t.trajectory.size() < 2) return {std::nullopt, traj + ": fewer than two poses"};
  return {std::move(t), {}};
}

void fill_pose_track(const SimTruth& truth, perception::PoseTrack& track) {
  for (const TruthPose& p : truth.trajectory) track.push({p.utc_ns, p.x, p.y, p.z, p.roll, p.pitch, p.yaw});
}

void fill_truth_terrain(const SimTruth& truth, perception::TerrainClassMap& map, double window, float epsilon) {
  auto& grid = map.grid();
  const CellIndex o = grid.origin();
  const double res = grid.resolution();
  const double rr = truth.terrain.resolution;
  const int half = std::max(0, static_cast<int>(std::lround((window - res) / 2.0 / rr)));
  const int inner = std::max(1, static_cast<int>(std::lround(res / rr)));
  for (std::int32_t y = 0; y < grid.size_y(); ++y) {
    for (std::int32_t x = 0; x < grid.size_x(); ++x) {
      perception::TerrainCell& cell = grid.at({o.x + x, o.y + y});
      if (cell.known) continue;
      const double cx0 = (o.x + x) * res + 0.5 * rr;  // first truth pixel centre inside the cell
      const double cy0 = (o.y + y) * res + 0.5 * rr;
      std::array<float, perception::kTerrainClasses> count{};
      float total = 0.0f;
      bool solid = false, undergrowth = false;
      for (int j = -half; j < inner + half; ++j) {
        for (int i = -half; i < inner + half; ++i) {
          const double px = cx0 + i * rr, py = cy0 + j * rr;
          const std::uint8_t cls = truth.terrain.at(px, py);
          if (cls >= perception::kTerrainClasses) continue;
          count[cls] += 1.0f;
          total += 1.0f;
          const bool own = i >= 0 && j >= 0 && i < inner && j < inner;
          const std::uint8_t ob = truth.obstacles.at(px, py, 0);
          if (own && ob == static_cast<std::uint8_t>(sim::ObstacleTruth::obstacle)) solid = true;
          if (own && ob == static_cast<std::uint8_t>(sim::ObstacleTruth::vegetation)) undergrowth = true;
        }
      }
      // What the lidar sees in the cell decides: an object makes it `other`,
      // a bush `vegetation`.
      if (solid || undergrowth) {
        count.fill(0.0f);
        count[static_cast<std::size_t>(solid ? perception::TerrainClass::other : perception::TerrainClass::vegetation)] = 1.0f;
        total = 1.0f;
      }
      if (total == 0.0f) continue;  // outside the simulated world: stays unknown
      for (float& v : count) v = (1.0f - epsilon) * v / total + epsilon / perception::kTerrainClasses;
      cell.set(count);
    }
  }
}

std::vector<std::array<double, 2>> utm_errors(const std::vector<TruthPose>& trajectory, const std::string& frame,
                                              const std::vector<StampedPosition>& positions, std::int64_t offset_ns) {
  std::vector<std::array<double, 2>> out;
  int zone = 0;
  char hemisphere = 'N';
  if (std::sscanf(frame.c_str(), "utm_%d%c", &zone, &hemisphere) != 2) return out;
  for (const StampedPosition& p : positions) {
    TruthAt at;
    if (!truth_at(trajectory, p.t - offset_ns, at) || std::isnan(at.lat)) {
      out.push_back({std::nan(""), std::nan("")});
      continue;
    }
    double e = 0.0, n = 0.0, gamma = 0.0, scale = 0.0;
    int z = zone;
    bool north = hemisphere == 'N';
    GeographicLib::UTMUPS::Forward(at.lat, at.lon, z, north, e, n, gamma, scale, zone);
    out.push_back({p.east - e, p.north - n});
  }
  return out;
}

CommonOffset split_common_offset(const std::vector<std::array<double, 2>>& errors) {
  CommonOffset c;
  for (const auto& v : errors) c.count += std::isnan(v[0]) ? 0u : 1u;
  if (c.count == 0) return c;
  const double count = static_cast<double>(c.count);
  for (const auto& v : errors) {
    if (std::isnan(v[0])) continue;
    c.east += v[0] / count;
    c.north += v[1] / count;
  }
  for (const auto& v : errors) {
    if (std::isnan(v[0])) continue;
    c.absolute_mean += std::hypot(v[0], v[1]) / count;
    const double d = std::hypot(v[0] - c.east, v[1] - c.north);
    c.mean += d / count;
    c.max = std::max(c.max, d);
  }
  return c;
}

bool truth_at(const std::vector<TruthPose>& traj, std::int64_t t, TruthAt& out) {
  if (traj.empty() || t < traj.front().utc_ns || t > traj.back().utc_ns) return false;
  auto it = std::lower_bound(traj.begin(), traj.end(), t,
                             [](const TruthPose& p, std::int64_t v) { return p.utc_ns < v; });
  if (it == traj.begin()) ++it;
  if (it == traj.end()) --it;
  const TruthPose& b = *it;
  const TruthPose& a = *(it - 1);
  const double f = b.utc_ns == a.utc_ns ? 0.0 : static_cast<double>(t - a.utc_ns) / static_cast<double>(b.utc_ns - a.utc_ns);
  auto wrap = [](double v) { return std::remainder(v, 2.0 * std::numbers::pi); };
  out.x = a.x + f * (b.x - a.x);
  out.y = a.y + f * (b.y - a.y);
  out.yaw = wrap(a.yaw + f * wrap(b.yaw - a.yaw));
  out.arc = a.arc + f * (b.arc - a.arc);
  out.lat = a.lat + f * (b.lat - a.lat);
  out.lon = a.lon + f * (b.lon - a.lon);
  return true;
}

std::string load_true_route(const std::string& dir, sim::Polyline& out) {
  const std::string file = dir + "/route.csv";
  std::ifstream in(file);
  if (!in) return "cannot read " + file;
  std::string line;
  std::getline(in, line);  // header: arc,x,y,...
  std::vector<sim::Vec2> points;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string arc, x, y;
    if (std::getline(ls, arc, ',') && std::getline(ls, x, ',') && std::getline(ls, y, ',')) {
      points.emplace_back(std::stod(x), std::stod(y));
    }
  }
  if (points.size() < 2) return file + ": fewer than two route points";
  out = sim::Polyline(std::move(points));
  return {};
}

void TrailCheck::add_odometry_pose(std::int64_t t_ns, double x, double y, double yaw) {
  if (!odometry_.empty() && t_ns <= odometry_.back().t) return;
  odometry_.push_back({t_ns, x, y, yaw});
}

bool TrailCheck::to_world(std::int64_t t_ns, double x, double y, double& wx, double& wy) const {
  auto it = std::lower_bound(odometry_.begin(), odometry_.end(), t_ns, [](const Sample& s, std::int64_t t) { return s.t < t; });
  const Sample* best = nullptr;
  if (it != odometry_.end()) best = &*it;
  if (it != odometry_.begin() && (best == nullptr || t_ns - (it - 1)->t < best->t - t_ns)) best = &*(it - 1);
  if (best == nullptr || std::abs(best->t - t_ns) > 200'000'000) return false;
  TruthAt p;
  const std::int64_t t_true = best->t - offset_ns_;
  if (!truth_at(truth_.trajectory, t_true, p)) {
    const auto& traj = truth_.trajectory;
    if (traj.empty() || t_true < traj.back().utc_ns || t_true - traj.back().utc_ns > late_ns_) return false;
    truth_at(traj, traj.back().utc_ns, p);
  }
  // Into the robot's frame through the odometry pose, out through the true pose.
  const double dx = x - best->x, dy = y - best->y;
  const double c0 = std::cos(best->yaw), s0 = std::sin(best->yaw);
  const double rx = c0 * dx + s0 * dy, ry = -s0 * dx + c0 * dy;
  const double c1 = std::cos(p.yaw), s1 = std::sin(p.yaw);
  wx = p.x + c1 * rx - s1 * ry;
  wy = p.y + s1 * rx + c1 * ry;
  return true;
}

double TrailCheck::distance(std::int64_t t_ns, double x, double y) const {
  double wx = 0.0, wy = 0.0;
  if (!to_world(t_ns, x, y, wx, wy)) return std::numeric_limits<double>::quiet_NaN();
  return trail_.project({wx, wy}).distance;
}

}  // namespace trailnav::eval
