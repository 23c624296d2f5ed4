#include "messages.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>

#include "trailnav/navigation/navigator/navigator.hpp"
#include "trailnav/navigation/pose/gyro_odometry.hpp"
#include "trailnav/navigation/pose/utm_alignment.hpp"
#include "trailnav/perception/obstacle_task.hpp"
#include "trailnav/runtime/host_clock.hpp"
#include "trailnav/perception/terrain_class_map.hpp"

namespace trailnav::dds {

template <std::size_t N>
void FixedString<N>::set(std::string_view s) noexcept {
  const std::size_t n = std::min(s.size(), N - 1);
  std::memcpy(text.data(), s.data(), n);
  text[n] = '\0';
}

// A stamp in host time, on the system clock of this moment
// (runtime/host_clock.hpp): what other nodes compare with their own now().
builtin_interfaces_msg_dds__Time_ to_time(std::int64_t host_ns) noexcept {
  const std::int64_t utc_ns = host_ns == 0 ? 0 : host_to_realtime(host_ns);
  std::int64_t sec = utc_ns / 1'000'000'000;
  std::int64_t nsec = utc_ns % 1'000'000'000;
  if (nsec < 0) {
    nsec += 1'000'000'000;
    --sec;
  }
  return {static_cast<std::int32_t>(sec), static_cast<std::uint32_t>(nsec)};
}

void utm_frame_name(int zone, bool north, std::span<char> out) noexcept {
  std::snprintf(out.data(), out.size(), "utm_%d%c", zone, north ? 'N' : 'S');
}

void map_frame_name(std::string_view configured, int zone, bool north, std::span<char> out) noexcept {
  if (configured == "utm") {
    utm_frame_name(zone, north, out);
  } else {
    std::snprintf(out.data(), out.size(), "%.*s", static_cast<int>(configured.size()), configured.data());
  }
}

geometry_msgs_msg_dds__Quaternion_ to_quaternion(double roll, double pitch, double yaw) noexcept {
  const double cr = std::cos(0.5 * roll), sr = std::sin(0.5 * roll);
  const double cp = std::cos(0.5 * pitch), sp = std::sin(0.5 * pitch);
  const double cy = std::cos(0.5 * yaw), sy = std::sin(0.5 * yaw);
  geometry_msgs_msg_dds__Quaternion_ q;
  q.w = cr * cp * cy + sr * sp * sy;
  q.x = sr * cp * cy - cr * sp * sy;
  q.y = cr * sp * cy + sr * cp * sy;
  q.z = cr * cp * sy - sr * sp * cy;
  return q;
}

// --- OccupancyGrid ---

OccupancyGridMessage::OccupancyGridMessage(std::int32_t width, std::int32_t height, std::string_view frame_id)
    : data_(static_cast<std::size_t>(width) * static_cast<std::size_t>(height), std::int8_t{-1}) {
  frame_.set(frame_id);
  msg_.header.frame_id = frame_.c_str();
  msg_.info.width = static_cast<std::uint32_t>(width);
  msg_.info.height = static_cast<std::uint32_t>(height);
  msg_.info.origin.orientation.w = 1.0;
  msg_.data._buffer = data_.data();
  msg_.data._length = static_cast<std::uint32_t>(data_.size());
  msg_.data._maximum = static_cast<std::uint32_t>(data_.size());
  msg_.data._release = false;
}

void OccupancyGridMessage::fill(const perception::ObstacleSnapshot& s, bool stale, int occupied_percent) noexcept {
  msg_.header.stamp = to_time(s.time_ns);
  msg_.info.map_load_time = msg_.header.stamp;
  msg_.info.resolution = static_cast<float>(s.resolution);
  msg_.info.origin.position.x = s.origin_x;
  msg_.info.origin.position.y = s.origin_y;
  msg_.info.origin.position.z = 0.0;
  const std::size_t n = std::min(data_.size(), s.occupancy.size());
  if (!stale) {
    std::memcpy(data_.data(), s.occupancy.data(), n);
    return;
  }
  for (std::size_t i = 0; i < n; ++i) {
    const std::int8_t v = s.occupancy[i];
    data_[i] = v > occupied_percent ? v : std::int8_t{-1};
  }
}

namespace {
// A terrain layer's grid (the class map's cells, row-major from its origin)
// as a cost per cell: `cost(cell)` gives 0..100 or -1.
template <typename Cost>
void fill_terrain_layer(nav_msgs_msg_dds__OccupancyGrid_& msg, std::vector<std::int8_t>& data,
                        const perception::TerrainClassMap& map, const Cost& cost) noexcept {
  const auto& g = map.grid();
  msg.header.stamp = to_time(map.time_ns);
  msg.info.map_load_time = msg.header.stamp;
  msg.info.resolution = static_cast<float>(g.resolution());
  msg.info.origin.position.x = g.origin().x * g.resolution();
  msg.info.origin.position.y = g.origin().y * g.resolution();
  msg.info.origin.position.z = 0.0;
  const CellIndex o = g.origin();
  const auto w = static_cast<std::int32_t>(msg.info.width), h = static_cast<std::int32_t>(msg.info.height);
  for (std::int32_t y = 0; y < std::min(h, g.size_y()); ++y) {
    for (std::int32_t x = 0; x < std::min(w, g.size_x()); ++x) {
      data[static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x)] = cost(g.at({o.x + x, o.y + y}));
    }
  }
}
}  // namespace

void OccupancyGridMessage::fill_cost(const perception::TerrainClassMap& map,
                                     const std::array<float, perception::kTerrainClasses>& cost, float unknown_cost) noexcept {
  fill_terrain_layer(msg_, data_, map, [&](const perception::TerrainCell& c) {
    const float v = perception::terrain_cost(c, cost, unknown_cost);
    return c.known ? static_cast<std::int8_t>(std::lround(100.0f * std::clamp(v, 0.0f, 1.0f))) : std::int8_t{-1};
  });
}

void OccupancyGridMessage::fill_traversability(const perception::TerrainClassMap& map) noexcept {
  fill_terrain_layer(msg_, data_, map, [](const perception::TerrainCell& c) {
    return c.traversable < 0.0f ? std::int8_t{-1}
                                : static_cast<std::int8_t>(std::lround(100.0f * (1.0f - std::min(c.traversable, 1.0f))));
  });
}

// --- PoseStamped ---

PoseStampedMessage::PoseStampedMessage(std::string_view frame_id) {
  frame_.set(frame_id);
  msg_.header.frame_id = frame_.c_str();
  msg_.pose.orientation.w = 1.0;
}

void PoseStampedMessage::fill(std::int64_t utc_ns, double x, double y, double z, double roll, double pitch,
                              double yaw) noexcept {
  msg_.header.stamp = to_time(utc_ns);
  msg_.pose.position = {x, y, z};
  msg_.pose.orientation = to_quaternion(roll, pitch, yaw);
}

void PoseStampedMessage::fill(const pose::LocalPose& p) noexcept {
  fill(p.time_ns, p.x, p.y, p.z, p.roll, p.pitch, p.yaw);
}

// --- UTM pose and NavSatFix ---

PlaceMessages::PlaceMessages(std::string_view frame_id) {
  frame_.set(frame_id);
  match_.header.frame_id = frame_.c_str();
  pose_.header.frame_id = frame_.c_str();
  pose_.pose.pose.orientation.w = 1.0;
}

void PlaceMessages::fill(const perception::place::PlaceSnapshot& s) noexcept {
  match_.header.stamp = to_time(s.stamp_ns);
  match_.database_index = static_cast<std::uint32_t>(s.index);
  // The database image's own time: a UTC stamp from the drive it was taken on.
  match_.database_stamp = {static_cast<std::int32_t>(s.database_stamp_ns / 1'000'000'000),
                           static_cast<std::uint32_t>(s.database_stamp_ns % 1'000'000'000)};
  match_.probability = s.probability;
  match_.peak = s.peak;
  match_.frame_sequence = s.frame_sequence;
  match_.steps = s.number;
  match_.lag_frames = static_cast<std::uint32_t>(s.lag);
  match_.chain_length = static_cast<std::uint32_t>(s.chain);
  match_.in_sequence = s.in_sequence;
  pose_.header.stamp = match_.header.stamp;
  pose_.pose.pose.position = {s.x, s.y, 0.0};
  pose_.pose.pose.orientation = to_quaternion(0.0, 0.0, s.yaw);
  std::fill(std::begin(pose_.pose.covariance), std::end(pose_.pose.covariance), 0.0);
  pose_.pose.covariance[0] = s.cov_xx;
  pose_.pose.covariance[1] = s.cov_xy;
  pose_.pose.covariance[6] = s.cov_xy;
  pose_.pose.covariance[7] = s.cov_yy;
  pose_.pose.covariance[14] = 1e6;  // z, roll, pitch: not measured
  pose_.pose.covariance[21] = 1e6;
  pose_.pose.covariance[28] = 1e6;
  pose_.pose.covariance[35] = s.var_yaw;
}

// --- Station ---

StationMessages::StationMessages(std::string_view station, std::string_view frame,
                                 const std::vector<std::string>& body_names)
    : names_(body_names.size()),
      frames_(body_names.size()),
      objects_(body_names.empty() ? 0 : body_names.size() - 1),
      poses_(body_names.size()) {
  station_.set(station);
  frame_.set(frame);
  fix_.header.frame_id = frame_.c_str();
  fix_.station = station_.c_str();
  for (std::size_t k = 0; k < body_names.size(); ++k) {
    names_[k].set(body_names[k]);
    frames_[k].set(k == 0 ? std::string(frame) : std::string(frame) + "/" + body_names[k]);
    poses_[k] = {};
    poses_[k].header.frame_id = frames_[k].c_str();
    poses_[k].pose.pose.orientation.w = 1.0;
    if (k > 0) {
      objects_[k - 1] = {};
      objects_[k - 1].name = names_[k].c_str();
      objects_[k - 1].frame_id = frames_[k].c_str();
    }
  }
  fix_.objects._buffer = objects_.data();
  fix_.objects._length = fix_.objects._maximum = static_cast<std::uint32_t>(objects_.size());
  fix_.objects._release = false;
}

void StationMessages::fill(const perception::registration::StationSnapshot& s) noexcept {
  fix_.header.stamp = to_time(s.stamp_ns);
  fix_.fix_number = s.number;
  fix_.visit = s.visit;
  fix_.local_points = static_cast<std::uint32_t>(s.local_points);
  const std::size_t n = std::min(s.bodies.size(), poses_.size());
  if (n > 0) {
    const perception::registration::StationBodyFix& w = s.bodies[0];
    fix_.surroundings_observed = w.observed;
    fix_.robot_x = w.x;
    fix_.robot_y = w.y;
    fix_.robot_yaw = w.yaw;
  }
  for (std::size_t k = 0; k < n; ++k) {
    const perception::registration::StationBodyFix& b = s.bodies[k];
    geometry_msgs_msg_dds__PoseWithCovarianceStamped_& p = poses_[k];
    p.header.stamp = fix_.header.stamp;
    p.pose.pose.position = {b.x, b.y, 0.0};
    p.pose.pose.orientation = to_quaternion(0.0, 0.0, b.yaw);
    // Row-major 6 x 6 over (x, y, z, roll, pitch, yaw): the measured x, y
    // and yaw block, the rest not measured.
    std::fill(std::begin(p.pose.covariance), std::end(p.pose.covariance), 0.0);
    constexpr int at[3] = {0, 1, 5};
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        p.pose.covariance[6 * at[i] + at[j]] = b.covariance[static_cast<std::size_t>(3 * i + j)];
      }
    }
    p.pose.covariance[14] = p.pose.covariance[21] = p.pose.covariance[28] = 1e6;
    if (k == 0) continue;
    trailnav_msgs_msg_dds__StationObject_& o = objects_[k - 1];
    o.observed = b.observed;
    o.correspondences = b.correspondences;
    o.fitness = b.fitness;
    o.moved_x = b.moved_x;
    o.moved_y = b.moved_y;
    o.turned = b.turned;
    o.centre_moved = b.centre_moved;
  }
}

UtmFixMessages::UtmFixMessages(std::string_view fix_frame_id) {
  fix_frame_.set(fix_frame_id);
  utm_frame_.set("utm");
  utm_.header.frame_id = utm_frame_.c_str();
  fix_.header.frame_id = fix_frame_.c_str();
  utm_.pose.pose.orientation.w = 1.0;
}

bool UtmFixMessages::fill(const pose::UtmPose& u) noexcept {
  if (!u.position_valid) return false;
  char frame[16];
  utm_frame_name(u.zone, u.north, frame);
  utm_frame_.set(frame);
  utm_.header.stamp = to_time(u.time_ns);
  utm_.pose.pose.position = {u.easting, u.northing, u.altitude};
  utm_.pose.pose.orientation = to_quaternion(0.0, 0.0, u.yaw);
  // Row-major 6x6 over (x, y, z, roll, pitch, yaw). The alignment estimates
  // easting, northing and yaw; z, roll and pitch get a variance of 1e6 (unknown).
  std::fill(std::begin(utm_.pose.covariance), std::end(utm_.pose.covariance), 0.0);
  const auto& c = u.covariance;
  utm_.pose.covariance[0] = c(0, 0);
  utm_.pose.covariance[1] = c(0, 1);
  utm_.pose.covariance[6] = c(1, 0);
  utm_.pose.covariance[7] = c(1, 1);
  utm_.pose.covariance[5] = c(0, 2);
  utm_.pose.covariance[11] = c(1, 2);
  utm_.pose.covariance[30] = c(2, 0);
  utm_.pose.covariance[31] = c(2, 1);
  utm_.pose.covariance[35] = u.heading_valid ? c(2, 2) : 1e6;
  utm_.pose.covariance[14] = 1e6;  // z, roll, pitch: not estimated
  utm_.pose.covariance[21] = 1e6;
  utm_.pose.covariance[28] = 1e6;

  fix_.header.stamp = utm_.header.stamp;
  fix_.status.status = 0;   // STATUS_FIX
  fix_.status.service = 1;  // SERVICE_GPS
  fix_.latitude = u.latitude;
  fix_.longitude = u.longitude;
  fix_.altitude = u.altitude;
  // East, north, up in m^2 (ENU, as NavSatFix defines it); grid and true
  // east/north differ by the convergence, negligible for the variance.
  std::fill(std::begin(fix_.position_covariance), std::end(fix_.position_covariance), 0.0);
  fix_.position_covariance[0] = c(0, 0);
  fix_.position_covariance[1] = c(0, 1);
  fix_.position_covariance[3] = c(1, 0);
  fix_.position_covariance[4] = c(1, 1);
  fix_.position_covariance[8] = std::max(c(0, 0), c(1, 1)) * 4.0;
  fix_.position_covariance_type = 3;  // COVARIANCE_TYPE_KNOWN
  return true;
}

// --- PointCloud2 ---

PointCloudMessage::PointCloudMessage(std::size_t capacity, std::string_view frame_id) : data_(capacity * kPointStep) {
  frame_.set(frame_id);
  msg_.header.frame_id = frame_.c_str();
  struct Field {
    const char* name;
    std::uint32_t offset;
    std::uint8_t datatype;
  };
  static constexpr Field kFields[] = {{"x", 0, 7},         {"y", 4, 7},      {"z", 8, 7},
                                      {"intensity", 12, 7}, {"time", 16, 7},  {"p_obstacle", 20, 7},
                                      {"ring", 24, 4},      {"obstacle", 26, 2}, {"terrain", 27, 2}};
  static_assert(std::size(kFields) == 9);
  for (std::size_t i = 0; i < fields_.size(); ++i) {
    names_[i].set(kFields[i].name);
    fields_[i].name = names_[i].c_str();
    fields_[i].offset = kFields[i].offset;
    fields_[i].datatype = kFields[i].datatype;
    fields_[i].count = 1;
  }
  msg_.fields._buffer = fields_.data();
  msg_.fields._length = msg_.fields._maximum = static_cast<std::uint32_t>(fields_.size());
  msg_.fields._release = false;
  msg_.height = 1;
  msg_.is_bigendian = false;
  msg_.point_step = kPointStep;
  msg_.is_dense = true;
  msg_.data._buffer = data_.data();
  msg_.data._maximum = static_cast<std::uint32_t>(data_.size());
  msg_.data._length = 0;
  msg_.data._release = false;
}

void PointCloudMessage::fill(const perception::PointsSnapshot& s) noexcept {
  msg_.header.stamp = to_time(s.time_ns);
  const std::size_t step = msg_.point_step;
  const std::size_t n = std::min(s.count, data_.size() / step);
  for (std::size_t i = 0; i < n; ++i) {
    const perception::CloudPoint& p = s.points[i];
    std::uint8_t* d = data_.data() + i * step;
    const float f[6] = {p.x, p.y, p.z, p.intensity, p.time, p.p_obstacle};
    std::memcpy(d, f, sizeof f);  // this machine is little endian, as the message says
    std::memcpy(d + 24, &p.ring, 2);
    d[26] = p.obstacle;
    d[27] = p.terrain;
  }
  msg_.width = static_cast<std::uint32_t>(n);
  msg_.row_step = static_cast<std::uint32_t>(n * step);
  msg_.data._length = static_cast<std::uint32_t>(n * step);
}

// --- NavigationStatus ---

NavigationStatusMessage::NavigationStatusMessage() {
  frame_.set("");
  state_.set("");
  message_.set("");
  msg_.header.frame_id = frame_.c_str();
  msg_.state_name = state_.c_str();
  msg_.message = message_.c_str();
}

void NavigationStatusMessage::fill(const nav::NavigationStatusReport& n, std::string_view map_frame) noexcept {
  frame_.set(map_frame);
  msg_.header.stamp = to_time(n.time_ns);
  msg_.state = static_cast<std::uint8_t>(n.state);
  state_.set(nav::nav_state_name(n.state));
  // The newest refusal first (the robot kept its route), else why planning failed.
  message_.set(n.refusal[0] != '\0' ? std::string_view(n.refusal.data()) : std::string_view(n.message));
  msg_.has_goal = n.has_goal;
  msg_.goal.latitude = n.goal_lat;
  msg_.goal.longitude = n.goal_lon;
  msg_.goal.altitude = 0.0;
  msg_.goal_easting = n.goal_easting;
  msg_.goal_northing = n.goal_northing;
  msg_.distance_remaining = n.remaining;
  msg_.route_length = n.route_length;
  msg_.subgoals = static_cast<std::uint32_t>(n.subgoals);
  msg_.active_subgoal = static_cast<std::uint32_t>(n.active);
  msg_.goals_received = n.counters.goals;
  msg_.goals_refused = n.counters.goals_refused;
  msg_.cancels = n.counters.cancels;
  msg_.plans = n.counters.plans;
}

// --- Path ---

PathMessage::PathMessage(std::size_t capacity, std::string_view frame_id) : poses_(capacity) {
  frame_.set(frame_id);
  msg_.header.frame_id = frame_.c_str();
  for (auto& p : poses_) {
    p.header.frame_id = frame_.c_str();
    p.pose.orientation.w = 1.0;
  }
  msg_.poses._buffer = poses_.data();
  msg_.poses._maximum = static_cast<std::uint32_t>(poses_.size());
  msg_.poses._length = 0;
  msg_.poses._release = false;
}

void PathMessage::set_frame(std::string_view frame_id) noexcept {
  frame_.set(frame_id);  // in place: the header and the poses point at it
}

void PathMessage::clear(std::int64_t utc_ns) noexcept {
  msg_.header.stamp = to_time(utc_ns);
  msg_.poses._length = 0;
}

bool PathMessage::add(std::int64_t utc_ns, double x, double y, double yaw) noexcept {
  if (msg_.poses._length >= poses_.size()) return false;
  geometry_msgs_msg_dds__PoseStamped_& p = poses_[msg_.poses._length++];
  p.header.stamp = to_time(utc_ns);
  p.pose.position = {x, y, 0.0};
  p.pose.orientation = to_quaternion(0.0, 0.0, yaw);
  return true;
}

void OccupancyGridMessage::fill_coarse(const perception::ObstacleSnapshot& s, int factor, bool stale,
                                       int occupied_percent) noexcept {
  msg_.header.stamp = to_time(s.time_ns);
  msg_.info.map_load_time = msg_.header.stamp;
  const double res = s.resolution;
  msg_.info.resolution = static_cast<float>(res * factor);
  // Cell indices in the odometry frame's grid (the snapshot's origin is a
  // whole number of cells), and the robot's block.
  const auto ox = static_cast<std::int64_t>(std::llround(s.origin_x / res));
  const auto oy = static_cast<std::int64_t>(std::llround(s.origin_y / res));
  const auto block = [&](double v) { return static_cast<std::int64_t>(std::floor(v / (res * factor))); };
  const auto w = static_cast<std::int64_t>(msg_.info.width), h = static_cast<std::int64_t>(msg_.info.height);
  const std::int64_t bx0 = block(s.robot_x) - w / 2, by0 = block(s.robot_y) - h / 2;
  msg_.info.origin.position.x = static_cast<double>(bx0 * factor) * res;
  msg_.info.origin.position.y = static_cast<double>(by0 * factor) * res;
  msg_.info.origin.position.z = 0.0;
  for (std::int64_t j = 0; j < h; ++j) {
    for (std::int64_t i = 0; i < w; ++i) {
      std::int8_t best = -1;
      for (std::int64_t fy = (by0 + j) * factor - oy, ey = fy + factor; fy < ey; ++fy) {
        if (fy < 0 || fy >= s.size_y) continue;
        for (std::int64_t fx = (bx0 + i) * factor - ox, ex = fx + factor; fx < ex; ++fx) {
          if (fx < 0 || fx >= s.size_x) continue;
          const std::int8_t v = s.occupancy[static_cast<std::size_t>(fy * s.size_x + fx)];
          if (stale && v <= occupied_percent) continue;  // free cells of a stale map are unknown
          best = std::max(best, v);
        }
      }
      data_[static_cast<std::size_t>(j * w + i)] = best;
    }
  }
}

// --- TFMessage ---

TfMessage::TfMessage(std::size_t capacity) : names_(capacity), transforms_(capacity) {
  for (std::size_t i = 0; i < capacity; ++i) {
    transforms_[i].header.frame_id = names_[i].parent.c_str();
    transforms_[i].child_frame_id = names_[i].child.c_str();
    transforms_[i].transform.rotation.w = 1.0;
  }
  msg_.transforms._buffer = transforms_.data();
  msg_.transforms._maximum = static_cast<std::uint32_t>(transforms_.size());
  msg_.transforms._length = 0;
  msg_.transforms._release = false;
}

void TfMessage::clear() noexcept { msg_.transforms._length = 0; }

bool TfMessage::add(std::int64_t utc_ns, std::string_view parent, std::string_view child,
                    const RigidTransform& t) noexcept {
  if (msg_.transforms._length >= transforms_.size()) return false;
  const std::size_t i = msg_.transforms._length++;
  names_[i].parent.set(parent);
  names_[i].child.set(child);
  geometry_msgs_msg_dds__TransformStamped_& s = transforms_[i];
  s.header.stamp = to_time(utc_ns);
  s.transform.translation = {t.x, t.y, t.z};
  s.transform.rotation = to_quaternion(t.roll, t.pitch, t.yaw);
  return true;
}

RigidTransform utm_to_odom(const pose::LocalPose& local, const pose::UtmPose& utm) noexcept {
  // utm = Rz(theta) * odom + (e, n): the robot's two positions of one instant give both.
  RigidTransform t;
  t.yaw = std::remainder(utm.yaw - local.yaw, 2.0 * std::numbers::pi);
  const double c = std::cos(t.yaw), s = std::sin(t.yaw);
  t.x = utm.easting - (c * local.x - s * local.y);
  t.y = utm.northing - (s * local.x + c * local.y);
  t.z = utm.altitude - local.z;
  return t;
}

// --- Odometry ---

OdometryMessage::OdometryMessage(std::string_view frame_id, std::string_view child_frame_id, const OdometryNoise& noise)
    : noise_(noise) {
  frame_.set(frame_id);
  child_.set(child_frame_id);
  msg_.header.frame_id = frame_.c_str();
  msg_.child_frame_id = child_.c_str();
  msg_.pose.pose.orientation.w = 1.0;
}

void OdometryMessage::fill(const pose::LocalPose& p) noexcept {
  msg_.header.stamp = to_time(p.time_ns);
  msg_.pose.pose.position = {p.x, p.y, p.z};
  msg_.pose.pose.orientation = to_quaternion(p.roll, p.pitch, p.yaw);
  // Row-major 6x6 over (x, y, z, roll, pitch, yaw): the drift model grows
  // with the distance driven; z is held by the gravity-aligned odometry no
  // better than the position.
  std::fill(std::begin(msg_.pose.covariance), std::end(msg_.pose.covariance), 0.0);
  const double sp = noise_.position_sigma_min + noise_.position_sigma_per_m * p.distance;
  const double sy = noise_.attitude_sigma + noise_.yaw_sigma_per_m * p.distance;
  msg_.pose.covariance[0] = msg_.pose.covariance[7] = msg_.pose.covariance[14] = sp * sp;
  msg_.pose.covariance[21] = msg_.pose.covariance[28] = noise_.attitude_sigma * noise_.attitude_sigma;
  msg_.pose.covariance[35] = sy * sy;
  // The twist in the robot frame (REP 105: child_frame_id).
  msg_.twist.twist.linear = {p.speed, 0.0, 0.0};
  msg_.twist.twist.angular = {0.0, 0.0, p.yaw_rate};
  std::fill(std::begin(msg_.twist.covariance), std::end(msg_.twist.covariance), 0.0);
  const double lat = noise_.lateral_sigma * noise_.lateral_sigma;
  msg_.twist.covariance[0] = noise_.speed_sigma * noise_.speed_sigma;
  msg_.twist.covariance[7] = msg_.twist.covariance[14] = lat;
  msg_.twist.covariance[21] = msg_.twist.covariance[28] = noise_.yaw_rate_sigma * noise_.yaw_rate_sigma;
  msg_.twist.covariance[35] = noise_.yaw_rate_sigma * noise_.yaw_rate_sigma;
}

// --- TerrainClassMap ---

TerrainClassMapMessage::TerrainClassMapMessage(std::int32_t width, std::int32_t height, std::string_view frame_id)
    : class_id_(static_cast<std::size_t>(width) * static_cast<std::size_t>(height), std::uint8_t{255}),
      confidence_(class_id_.size(), std::uint8_t{0}) {
  frame_.set(frame_id);
  msg_.header.frame_id = frame_.c_str();
  msg_.info.width = static_cast<std::uint32_t>(width);
  msg_.info.height = static_cast<std::uint32_t>(height);
  msg_.info.origin.orientation.w = 1.0;
  for (std::size_t i = 0; i < names_.size(); ++i) {
    names_[i].set(perception::terrain_class_name(static_cast<perception::TerrainClass>(i)));
    name_ptrs_[i] = names_[i].c_str();
  }
  msg_.class_names._buffer = name_ptrs_.data();
  msg_.class_names._length = msg_.class_names._maximum = static_cast<std::uint32_t>(name_ptrs_.size());
  msg_.class_names._release = false;
  msg_.class_id._buffer = class_id_.data();
  msg_.class_id._length = msg_.class_id._maximum = static_cast<std::uint32_t>(class_id_.size());
  msg_.class_id._release = false;
  msg_.confidence._buffer = confidence_.data();
  msg_.confidence._length = msg_.confidence._maximum = static_cast<std::uint32_t>(confidence_.size());
  msg_.confidence._release = false;
}

void TerrainClassMapMessage::set_header(std::int64_t utc_ns, double resolution, double origin_x,
                                        double origin_y) noexcept {
  msg_.header.stamp = to_time(utc_ns);
  msg_.info.map_load_time = msg_.header.stamp;
  msg_.info.resolution = static_cast<float>(resolution);
  msg_.info.origin.position = {origin_x, origin_y, 0.0};
}

void TerrainClassMapMessage::fill(const perception::TerrainClassMap& map) noexcept {
  const auto& g = map.grid();
  set_header(map.time_ns + map.clock_offset_ns, g.resolution(), g.origin().x * g.resolution(), g.origin().y * g.resolution());
  map.export_classes(class_id_, confidence_);
}

// --- DiagnosticArray ---

DiagnosticsMessage::DiagnosticsMessage() : store_(kStatuses), statuses_(kStatuses) {
  frame_.set("");
  msg_.header.frame_id = frame_.c_str();
  for (std::size_t i = 0; i < kStatuses; ++i) {
    Status& s = store_[i];
    diagnostic_msgs_msg_dds__DiagnosticStatus_& d = statuses_[i];
    d.name = s.name.c_str();
    d.message = s.message.c_str();
    d.hardware_id = s.hardware_id.c_str();
    for (std::size_t k = 0; k < kValues; ++k) {
      s.pairs[k].key = s.keys[k].c_str();
      s.pairs[k].value = s.values[k].c_str();
    }
    d.values._buffer = s.pairs.data();
    d.values._maximum = static_cast<std::uint32_t>(kValues);
    d.values._length = 0;
    d.values._release = false;
  }
  msg_.status._buffer = statuses_.data();
  msg_.status._maximum = static_cast<std::uint32_t>(kStatuses);
  msg_.status._length = 0;
  msg_.status._release = false;
}

void DiagnosticsMessage::clear(std::int64_t utc_ns) noexcept {
  msg_.header.stamp = to_time(utc_ns);
  msg_.status._length = 0;
  open_ = false;
  dropped_ = 0;
}

bool DiagnosticsMessage::begin(Level level, std::string_view name, std::string_view message,
                               std::string_view hardware_id) noexcept {
  open_ = msg_.status._length < kStatuses;
  if (!open_) {
    ++dropped_;
    return false;
  }
  const std::size_t i = msg_.status._length++;
  Status& s = store_[i];
  s.name.set(name);
  s.message.set(message);
  s.hardware_id.set(hardware_id);
  statuses_[i].level = level;
  statuses_[i].values._length = 0;
  return true;
}

void DiagnosticsMessage::value(std::string_view key, std::string_view value) noexcept {
  const std::size_t i = msg_.status._length - 1;
  if (!open_ || statuses_[i].values._length >= kValues) {
    ++dropped_;
    return;
  }
  auto& seq = statuses_[i].values;
  store_[i].keys[seq._length].set(key);
  store_[i].values[seq._length].set(value);
  ++seq._length;
}

void DiagnosticsMessage::value(std::string_view key, std::uint64_t v) noexcept {
  char text[24];
  std::snprintf(text, sizeof text, "%llu", static_cast<unsigned long long>(v));
  value(key, std::string_view(text));
}

void DiagnosticsMessage::value(std::string_view key, double v, int decimals) noexcept {
  char text[40];
  std::snprintf(text, sizeof text, "%.*f", decimals, v);
  value(key, std::string_view(text));
}

}  // namespace trailnav::dds
