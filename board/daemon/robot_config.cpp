#include "robot_config.hpp"

#include <algorithm>
#include <filesystem>
#include <thread>

#include "task_presets.hpp"
#include "trailnav/drivers/link/byte_link.hpp"
#include "trailnav/drivers/velodyne/calibration.hpp"
#include "trailnav/perception/random_forest.hpp"
#include "trailnav/perception/terrain_mapper.hpp"

namespace trailnav::daemon {

namespace fs = std::filesystem;

namespace {

std::string resolve(const ConfigNode& node, const std::string& path) {
  if (path.empty() || fs::path(path).is_absolute()) return path;
  return (fs::path(node.file()).parent_path() / path).lexically_normal().string();
}

udp::Endpoint endpoint(const ConfigNode& node, std::string_view key, const std::string& fallback) {
  const std::string text = node.string(key, fallback);
  std::string error;
  auto e = udp::parse_endpoint(text, error);
  if (!e) node.fail(key, "'" + text + "' is not an address:port (" + error + ")");
  return *e;
}

link::LinkOptions link_options(const ConfigNode& node) {
  const std::string text = node.string("link");
  std::string error;
  auto l = link::parse_link(text, error);
  if (!l) node.fail("link", "'" + text + "': " + error);
  l->silence_timeout = node.number("silence_timeout_s", 0.0, 3600.0, l->silence_timeout);
  return *l;
}

can::SignalRef signal_ref(const ConfigNode& node, std::string_view key, bool required) {
  const std::string text = required ? node.string(key) : node.string(key, "");
  if (text.empty()) return {};
  const auto dot = text.find('.');
  if (dot == std::string::npos || dot == 0 || dot + 1 == text.size()) {
    node.fail(key, "'" + text + "' must be MESSAGE.Signal, as named in the DBC file");
  }
  return {text.substr(0, dot), text.substr(dot + 1)};
}

std::array<double, 3> vec3(const ConfigNode& node, std::string_view key, std::array<double, 3> fallback) {
  if (!node.has(key)) return fallback;
  const auto v = node.number_list(key, -100.0, 100.0);
  if (v.size() != 3) node.fail(key, "needs three numbers [x, y, z] in metres");
  return {v[0], v[1], v[2]};
}

// `input: pointcloud2`: the topic, the sensor's ring layout and how rows are found.
LidarSection parse_cloud_input(const ConfigNode& n) {
  LidarSection s;
  dds::CloudReaderOptions o;
  o.topic = n.string("topic", "points");
  if (o.topic.empty()) n.fail("topic", "an empty topic name");
  const std::string layout = n.string("layout");
  const std::string ext = fs::path(layout).extension().string();
  const std::string named = ext == ".yaml" || ext == ".yml" ? resolve(n, layout) : layout;
  std::string error;
  auto l = cloud::ring_layout_named(named, error);
  if (!l) n.fail("layout", error);
  o.layout = std::move(*l);
  if (n.has("columns")) o.layout.columns = static_cast<int>(n.integer("columns", 16, 65535));
  const std::string rings = n.string("rings", "automatic");
  const auto source = cloud::ring_source_named(rings);
  if (!source) n.fail("rings", "'" + rings + "' is not one of automatic, field, elevation, order");
  o.image.rings = *source;
  o.image.intensity_scale = static_cast<float>(n.number("intensity_scale", 0.001, 1000.0, 1.0));
  o.image.period_s = n.number("period_s", 0.02, 1.0, 0.1);
  o.layers = static_cast<int>(n.integer("layers", 1, 2, 2));
  // (Not given: the reader's default, rings x columns x layers.)
  if (n.has("max_points")) {
    o.max_points = static_cast<std::size_t>(n.integer("max_points", 1, static_cast<std::int64_t>(cloud::kMaxPoints)));
  }
  const std::size_t rings_count = o.layout.elevation_deg.size();
  if (n.has("model")) {
    const std::string model = n.string("model");
    const auto m = velodyne::parse_model(model);
    if (!m) n.fail("model", "unknown lidar model '" + model + "' (VLP-16, VLP-32C, HDL-32E, HDL-64E)");
    s.model = *m;
  } else {
    s.model = rings_count <= 16 ? velodyne::Model::vlp16 : rings_count <= 32 ? velodyne::Model::vlp32c : velodyne::Model::hdl64e;
  }
  s.driver.name = "lidar";
  s.cloud = std::move(o);
  n.reject_unknown_keys();
  return s;
}

LidarSection parse_lidar(const ConfigNode& n) {
  const std::string input = n.string("input", "velodyne");
  if (input == "pointcloud2") return parse_cloud_input(n);
  if (input != "velodyne") n.fail("input", "'" + input + "' is not one of velodyne (UDP packets), pointcloud2 (DDS)");
  LidarSection s;
  const std::string model = n.string("model");
  const auto m = velodyne::parse_model(model);
  if (!m) n.fail("model", "unknown lidar model '" + model + "' (VLP-16, VLP-16-HiRes, VLP-32C, HDL-32E, HDL-64E)");
  s.model = *m;
  const std::string calib = n.string("calibration", "builtin");
  if (calib != "builtin") {
    s.calibration = resolve(n, calib);
    if (!fs::exists(s.calibration)) n.fail("calibration", "no such file: " + s.calibration);
  } else if (!velodyne::builtin_calibration(s.model)) {
    n.fail("calibration", "the " + model + " has no built-in calibration: name its calibration file");
  }
  s.driver.name = "lidar";
  s.driver.data.bind = endpoint(n, "data", "127.0.0.1:2368");
  const std::string position = n.string("position", "none");
  if (position == "none") {
    s.driver.position.reset();
  } else {
    udp::ReceiverOptions p;
    std::string error;
    auto e = udp::parse_endpoint(position, error);
    if (!e) n.fail("position", "'" + position + "' is not an address:port or 'none' (" + error + ")");
    p.bind = *e;
    s.driver.position = p;
  }
  s.driver.assembler.rpm = n.number("rpm", 300.0, 1200.0, 600.0);
  s.driver.assembler.min_rpm = std::min(300.0, s.driver.assembler.rpm);
  // Between revolutions' ends the task reads its socket at most this far
  // apart (VelodyneDriver::rest); 0: every period of its rate.
  s.driver.max_rest_ns = static_cast<Nanos>(n.number("max_rest_ms", 0.0, 50.0, 10.0) * 1e6);
  // From this long before a revolution's predicted end the task also wakes
  // at each packet (VelodyneDriver::watching); 0: every period only.
  s.driver.watch_before_end_ns = static_cast<Nanos>(n.number("watch_before_end_ms", 0.0, 20.0, 1.5) * 1e6);
  n.reject_unknown_keys();
  return s;
}

gps::GpsDriverOptions parse_gps(const ConfigNode& n) {
  gps::GpsDriverOptions o;
  o.link = link_options(n);
  o.fix_timeout = n.number("fix_timeout_s", 0.1, 600.0, o.fix_timeout);
  n.reject_unknown_keys();
  return o;
}

imu::ImuDriverOptions parse_imu(const ConfigNode& n, std::array<double, 3>& position) {
  imu::ImuDriverOptions o;
  // Where the IMU sits, for tf_static only: its axes are taken to be the
  // robot's (the driver does not rotate readings).
  position = vec3(n, "position", position);
  o.link = link_options(n);
  o.protocol = n.choice("protocol", {"xsens", "line"}, "xsens") == "xsens" ? imu::ImuProtocol::xsens : imu::ImuProtocol::line;
  o.xsens_start = n.boolean("xsens_start", false);
  o.data_timeout = n.number("data_timeout_s", 0.01, 60.0, o.data_timeout);
  n.reject_unknown_keys();
  return o;
}

CanSection parse_can(const ConfigNode& n) {
  CanSection s;
  s.dbc = resolve(n, n.string("dbc"));
  if (!fs::exists(s.dbc)) n.fail("dbc", "no such file: " + s.dbc);
  can::CanDriverOptions& o = s.driver;
  o.transport = n.choice("transport", {"socketcan", "tunnel"}) == "socketcan" ? can::CanTransport::socketcan
                                                                               : can::CanTransport::tunnel;
  o.interface = n.string("interface", o.interface);
  o.tunnel = endpoint(n, "tunnel", "127.0.0.1:29536");
  o.odometry.left = signal_ref(n, "left", true);
  o.odometry.right = signal_ref(n, "right", true);
  o.odometry.speed_scale = n.number("speed_scale", 1e-6, 1e6, o.odometry.speed_scale);
  o.odometry.track = n.number("track", 0.05, 5.0);
  o.data_timeout = n.number("data_timeout_s", 0.01, 60.0, o.data_timeout);
  n.reject_unknown_keys();
  return s;
}

gpio::GpioDriverOptions parse_gpio(const ConfigNode& n) {
  gpio::GpioDriverOptions o;
  o.transport = n.choice("transport", {"chip", "tunnel"}) == "chip" ? gpio::GpioTransport::chip : gpio::GpioTransport::tunnel;
  o.chip = n.string("chip", o.chip);
  o.tunnel = endpoint(n, "tunnel", "127.0.0.1:29537");
  o.estop_line = n.string("estop_line", o.estop_line);
  o.estop_active_low = n.boolean("estop_active_low", o.estop_active_low);
  o.estop_release_debounce = n.number("estop_release_debounce_s", 0.0, 10.0, o.estop_release_debounce);
  o.heartbeat_line = n.string("heartbeat_line", "");
  o.status_line = n.string("status_line", "");
  o.outputs_active_low = n.boolean("outputs_active_low", o.outputs_active_low);
  o.max_rest = n.number("max_rest_ms", 0.0, 1000.0, o.max_rest * 1e3) * 1e-3;
  n.reject_unknown_keys();
  return o;
}

drivers::camera::CameraOptions parse_camera(const ConfigNode& n) {
  namespace cam = drivers::camera;
  cam::CameraOptions o;
  o.input = n.choice("input", {"v4l2", "tunnel"}, "v4l2") == "v4l2" ? cam::CameraInput::v4l2 : cam::CameraInput::tunnel;
  o.device = n.string("device", o.device);
  const std::string format = n.choice("format", {"grey", "yuyv", "mjpeg"}, "yuyv");
  cam::parse_pixel_format(format, o.format);
  o.width = static_cast<int>(n.integer("width", 1, 8192, o.width));
  o.height = static_cast<int>(n.integer("height", 1, 8192, o.height));
  o.fps = n.number("fps", 0.0, 1000.0, o.fps);
  o.buffers = static_cast<int>(n.integer("buffers", 2, 32, o.buffers));
  o.exposure_us = static_cast<int>(n.integer("exposure_us", 0, 10'000'000, o.exposure_us));
  o.out_width = static_cast<int>(n.integer("out_width", 4, 8192, o.out_width));
  o.out_height = static_cast<int>(n.integer("out_height", 4, 8192, o.out_height));
  o.tunnel_port = static_cast<std::uint16_t>(n.integer("tunnel_port", 0, 65535, o.tunnel_port));
  o.reconnect_s = n.number("reconnect_s", 0.01, 60.0, o.reconnect_s);
  o.silence_s = n.number("silence_s", 0.01, 60.0, o.silence_s);
  if (o.out_width > o.width || o.out_height > o.height)
    n.fail("out_width", "the reduced frame (" + std::to_string(o.out_width) + " x " + std::to_string(o.out_height) +
                            ") must fit the camera's (" + std::to_string(o.width) + " x " + std::to_string(o.height) + ")");
  n.reject_unknown_keys();
  return o;
}

PlaceSection parse_place(const ConfigNode& n) {
  PlaceSection p;
  p.database = resolve(n, n.string("database"));
  if (p.database.empty()) n.fail("database", "a place database file (trailnav place-map --out) is needed");
  p.frame = n.string("frame", p.frame);
  if (auto t = n.optional_map("transition")) {
    p.transition.f = static_cast<int>(t->integer("f", 1, 1000, p.transition.f));
    p.transition.b = static_cast<int>(t->integer("b", 1, 1000, p.transition.b));
    p.transition.c_f = t->number("c_f", 1e-6, 1e9, p.transition.c_f);
    p.transition.c_s = t->number("c_s", 1e-6, 1e9, p.transition.c_s);
    p.transition.c_b = t->number("c_b", 1e-6, 1e9, p.transition.c_b);
    t->reject_unknown_keys();
  }
  p.prior_queries = n.number("prior_queries", 0.0, 1e6, p.prior_queries);
  p.task.window = static_cast<int>(n.integer("window", 0, 10000, p.task.window));
  p.task.position_floor_m = n.number("position_floor_m", 0.0, 1e4, p.task.position_floor_m);
  p.task.yaw_floor_rad = n.number("yaw_floor_deg", 0.0, 180.0, p.task.yaw_floor_rad * 180.0 / 3.14159265358979323846) *
                         3.14159265358979323846 / 180.0;
  p.lag = static_cast<int>(n.integer("lag", 0, 1000, p.lag));
  p.sequence.min_length = static_cast<int>(n.integer("min_sequence", 0, 100000, p.sequence.min_length));
  p.sequence.row_gap = static_cast<int>(n.integer("row_gap", 1, 1000, p.sequence.row_gap));
  p.sequence.column_gap = static_cast<int>(n.integer("column_gap", 0, 100000, p.sequence.column_gap));
  p.peak_radius = static_cast<int>(n.integer("peak_radius", 0, 100000, p.peak_radius));
  const std::string use = n.choice("pose_measurement", {"off", "gps_poor", "always"}, "off");
  p.pose.use = use == "off" ? pose::PlaceUse::off : use == "gps_poor" ? pose::PlaceUse::gps_poor : pose::PlaceUse::always;
  p.pose.min_probability = n.number("min_probability", 0.0, 1.0, p.pose.min_probability);
  p.pose.need_sequence = n.boolean("need_sequence", p.pose.need_sequence);
  p.pose.gps_poor_after_s = n.number("gps_poor_after_s", 0.0, 3600.0, p.pose.gps_poor_after_s);
  p.pose.gps_poor_sigma_m = n.number("gps_poor_sigma_m", 0.0, 1e6, p.pose.gps_poor_sigma_m);
  n.reject_unknown_keys();
  return p;
}

StationSection parse_station(const ConfigNode& n) {
  constexpr double kDeg = 3.14159265358979323846 / 180.0;
  StationSection st;
  st.file = resolve(n, n.string("file"));
  if (st.file.empty()) n.fail("file", "a station file (trailnav station teach --out) is needed");
  st.input = n.choice("input", {"laserscan", "velodyne"}, "laserscan") == "velodyne" ? StationSection::Input::velodyne
                                                                                    : StationSection::Input::laserscan;
  st.frame = n.string("frame", st.frame);
  if (st.frame.empty()) n.fail("frame", "an empty frame name");
  st.config.local_scans = static_cast<int>(n.integer("local_scans", 1, 100, st.config.local_scans));
  st.config.max_points = static_cast<std::size_t>(n.integer("max_points", 16, 65536, static_cast<long long>(st.config.max_points)));
  st.task.every = static_cast<int>(n.integer("every", 1, 1000, st.task.every));
  st.task.silence_s = n.number("silence_s", 0.05, 3600.0, st.task.silence_s);
  st.task.arena_bytes = static_cast<std::size_t>(n.integer("arena_mb", 1, 4096, static_cast<long long>(st.task.arena_bytes >> 20))) << 20;
  st.use_pose = n.boolean("use_pose", st.use_pose);
  if (n.has("start")) {
    const auto v = n.number_list("start", -1e6, 1e6);
    if (v.size() != 3) n.fail("start", "needs [x, y, yaw_deg]: the robot's pose in the station frame where a visit begins");
    st.task.start = Eigen::Isometry3d::Identity();
    st.task.start.linear() = Eigen::AngleAxisd(v[2] * kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    st.task.start.translation() = Eigen::Vector3d(v[0], v[1], 0.0);
  }
  std::array<double, 3> mount{0.0, 0.0, 0.0};
  if (n.has("mount")) {
    const auto v = n.number_list("mount", -100.0, 360.0);
    if (v.size() != 3) n.fail("mount", "needs [x, y, yaw_deg]: the scanner's place on the robot");
    mount = {v[0], v[1], v[2]};
    st.band_mount_given = true;
  }
  const double min_range = n.number("min_range", 0.0, 1000.0, 0.3);
  const double max_range = n.number("max_range", 0.1, 1000.0, 20.0);
  if (max_range <= min_range) n.fail("max_range", "must be larger than min_range");
  if (st.input == StationSection::Input::laserscan) {
    st.laser.topic = n.string("topic", st.laser.topic);
    if (st.laser.topic.empty()) n.fail("topic", "an empty topic name");
    st.laser.max_beams = st.config.max_points;
    st.laser.max_range = static_cast<float>(max_range);
    st.laser.mount_x = mount[0];
    st.laser.mount_y = mount[1];
    st.laser.mount_yaw = mount[2] * kDeg;
  } else {
    const auto rings = n.has("rings") ? n.number_list("rings", 0.0, 255.0) : std::vector<double>{7.0, 8.0};
    if (rings.size() != 2 || rings[1] < rings[0]) n.fail("rings", "needs [first, last]: the band of rings flattened into the plane");
    st.band.first_ring = static_cast<int>(rings[0]);
    st.band.last_ring = static_cast<int>(rings[1]);
    st.band.min_range = static_cast<float>(min_range);
    st.band.max_range = static_cast<float>(max_range);
    st.band.mount = Eigen::Isometry3f::Identity();
    st.band.mount.linear() = Eigen::AngleAxisf(static_cast<float>(mount[2] * kDeg), Eigen::Vector3f::UnitZ()).toRotationMatrix();
    st.band.mount.translation() = Eigen::Vector3f(static_cast<float>(mount[0]), static_cast<float>(mount[1]), 0.0f);
  }
  if (const std::string e = perception::registration::check_station_config(st.config); !e.empty()) n.fail("local_scans", e);
  n.reject_unknown_keys();
  return st;
}

pose::PoseEstimatorOptions parse_pose(const ConfigNode& n, bool& feed_obstacles, bool& feed_terrain,
                                      perception::PoseWait& wait) {
  pose::PoseEstimatorOptions o;
  o.utm.antenna = vec3(n, "antenna", o.utm.antenna);
  o.utm.zone = static_cast<int>(n.integer("utm_zone", 0, 60, 0));
  o.utm.min_baseline = n.number("min_baseline_m", 0.5, 1000.0, o.utm.min_baseline);
  feed_obstacles = n.boolean("feed_obstacles", true);
  feed_terrain = n.boolean("feed_terrain", true);
  o.imu_wait = n.number("imu_wait_ms", 0.0, 5000.0, o.imu_wait * 1e3) * 1e-3;
  // How far the pose may lag behind a revolution's end before the obstacle
  // and terrain threads wait for it, and for how long (docs/obstacles.md).
  wait.max_lag_ns = static_cast<std::int64_t>(n.number("max_lag_ms", 1.0, 500.0, static_cast<double>(wait.max_lag_ns) * 1e-6) * 1e6);
  wait.max_wait_ns = static_cast<std::int64_t>(n.number("max_wait_ms", 0.0, 500.0, static_cast<double>(wait.max_wait_ns) * 1e-6) * 1e6);
  n.reject_unknown_keys();
  return o;
}

DdsSection parse_dds(const ConfigNode& n) {
  DdsSection d;
  d.domain = static_cast<std::uint32_t>(n.integer("domain", 0, 232, 0));
  const std::string config = n.string("cyclone_config", "loopback");
  if (config == "loopback") {
    d.cyclone_xml = dds::loopback_config();
  } else {
    d.cyclone_config = resolve(n, config);
    auto text = dds::read_cyclone_config(d.cyclone_config);
    if (!text.error.empty()) n.fail("cyclone_config", text.error);
    d.cyclone_xml = std::move(text.xml);
  }
  dds::PublisherOptions& p = d.publisher;
  if (auto t = n.optional_map("topics")) {
    auto topic = [&](std::string_view key, std::string& out) {
      out = t->string(key, out);
      if (out.empty() || out.front() == '/' || out.back() == '/' || out.find(' ') != std::string::npos) {
        t->fail(key, "'" + out + "' is not a topic name (ROS 2 style, e.g. trailnav/obstacle_map)");
      }
    };
    topic("obstacle_map", p.topics.obstacle_map);
    topic("terrain_map", p.topics.terrain_map);
    topic("terrain_cost", p.topics.terrain_cost);
    topic("pose", p.topics.pose);
    topic("utm_pose", p.topics.utm_pose);
    topic("fix", p.topics.fix);
    topic("subgoal", p.topics.subgoal);
    topic("subgoal_path", p.topics.subgoal_path);
    topic("health", p.topics.health);
    topic("tf", p.topics.tf);
    topic("tf_static", p.topics.tf_static);
    topic("odometry", p.topics.odometry);
    topic("navigation_status", p.topics.navigation_status);
    topic("coarse_map", p.topics.coarse_map);
    topic("points", p.topics.points);
    topic("keyframe_path", p.topics.keyframe_path);
    topic("goal", d.commands.topics.goal);
    topic("geo_goal", d.commands.topics.geo_goal);
    topic("cancel", d.commands.topics.cancel);
    t->reject_unknown_keys();
  }
  p.odom_frame = n.string("odom_frame", p.odom_frame);
  p.fix_frame = n.string("fix_frame", p.fix_frame);
  p.publish_tf = n.boolean("publish_tf", p.publish_tf);
  if (auto pts = n.optional_map("points")) {
    p.points_rate_hz = pts->number("rate_hz", 0.1, 20.0);
    pts->reject_unknown_keys();
  }
  if (auto c = n.optional_map("coarse_map")) {
    p.coarse_factor = static_cast<int>(c->integer("factor", 1, 20));
    p.coarse_window = c->number("window_m", 0.0, 1000.0, 0.0);
    c->reject_unknown_keys();
  }
  if (auto f = n.optional_map("frames")) {
    auto frame = [&](std::string_view key, std::string& out) {
      out = f->string(key, out);
      if (out.empty() || out.front() == '/' || out.find(' ') != std::string::npos) {
        f->fail(key, "'" + out + "' is not a frame name (tf2 style, no leading '/', e.g. base_link)");
      }
    };
    frame("map", p.frames.map);
    frame("base_link", p.frames.base_link);
    frame("lidar", p.frames.lidar);
    frame("imu", p.frames.imu);
    f->reject_unknown_keys();
  }
  p.pose_rate_hz = n.number("pose_rate_hz", 0.0, 1000.0, p.pose_rate_hz);
  p.health_period = n.number("health_period_s", 0.05, 60.0, p.health_period);
  p.stale_after = n.number("stale_after_s", 0.05, 60.0, p.stale_after);
  n.reject_unknown_keys();
  return d;
}

// The mapping section (docs/trailnavd.md "mapping"): keyframes, their
// odometry noise, the capacity and SMF's part size.
slam::MappingOptions parse_mapping(const ConfigNode& n, bool has_gps, const pose::PoseEstimatorOptions& pose) {
  slam::MappingOptions o;
  // The GPS error model of the alignment (navigation/pose): white part and
  // the wandering bias' correlation time.
  o.gps_white_sigma = pose.utm.gps_white_sigma;
  o.gps_bias_time = pose.utm.gps_bias_time;
  slam::KeyframeOptions& k = o.keyframes;
  // 10 km of keyframes at 2 m: an SMF solve of the whole map within the
  // task's budget on the reference machine (docs/slam.md "Online mapping").
  k.max_keyframes = 5000;
  k.max_keyframes = static_cast<std::size_t>(n.integer("max_keyframes", 2, 10'000'000, static_cast<std::int64_t>(k.max_keyframes)));
  k.spacing_m = n.number("spacing_m", 0.1, 1000.0, k.spacing_m);
  k.spacing_rad = n.number("spacing_rad", 0.01, 6.3, k.spacing_rad);
  k.sigma_per_metre = n.number("sigma_per_metre", 0.0, 10.0, k.sigma_per_metre);
  k.sigma_theta_per_rad = n.number("sigma_theta_per_rad", 0.0, 10.0, k.sigma_theta_per_rad);
  k.sigma_theta_per_metre = n.number("sigma_theta_per_metre", 0.0, 10.0, k.sigma_theta_per_metre);
  k.sigma_floor_m = n.number("sigma_floor_m", 1e-6, 100.0, k.sigma_floor_m);
  k.sigma_floor_rad = n.number("sigma_floor_rad", 1e-6, 10.0, k.sigma_floor_rad);
  k.gps_max_distance = n.number("gps_max_distance_m", 0.0, 100.0, k.gps_max_distance);
  o.max_part = static_cast<int>(n.integer("max_part", 10, 5000, o.max_part));
  o.max_iterations = static_cast<int>(n.integer("max_iterations", 1, 10000, o.max_iterations));
  o.optimize_period = n.number("optimize_period_s", 0.1, 3600.0, o.optimize_period);
  o.use_gps = n.boolean("use_gps", has_gps);
  if (o.use_gps && !has_gps) n.fail("use_gps", "the map is tied to GPS fixes: add a 'gps' section, or set use_gps: false");
  if (!o.use_gps && has_gps) {
    n.fail("use_gps", "with a 'gps' section the GPS alignment is odom's parent on tf; a map without GPS would be a "
                      "second parent: keep use_gps true");
  }
  if (const std::string e = slam::check_mapping_options(o); !e.empty()) n.fail("max_keyframes", e);
  if (auto l = n.optional_map("loops")) {
    // Loop closures from the lidar's revolutions (docs/slam.md "Loop
    // closures"): 3D clouds at 0.3 m, candidates within 8 m of the map's
    // pose and 25 m of driving back, verified by GICP.
    perception::registration::LoopClosureConfig lc = perception::registration::spinning_lidar_loop_config();
    lc.voxel = static_cast<float>(l->number("voxel_m", 0.05, 5.0, static_cast<double>(lc.voxel)));
    lc.max_points = static_cast<std::size_t>(l->integer("points", 100, 100000, static_cast<std::int64_t>(lc.max_points)));
    lc.neighbours = static_cast<int>(l->integer("neighbours", 5, 64, lc.neighbours));
    lc.search_radius = l->number("radius_m", 0.5, 1000.0, lc.search_radius);
    lc.min_path = l->number("min_path_m", 0.0, 100000.0, lc.min_path);
    lc.max_candidates = static_cast<int>(l->integer("candidates", 1, 100, lc.max_candidates));
    lc.min_overlap = l->number("min_overlap", 0.01, 1.0, lc.min_overlap);
    lc.max_rms = l->number("max_rms_m", 0.005, 2.0, lc.max_rms);
    lc.max_jump_m = l->number("max_jump_m", 0.01, 100.0, lc.max_jump_m);
    lc.max_jump_rad = l->number("max_jump_deg", 0.1, 180.0, lc.max_jump_rad * 180.0 / 3.14159265358979323846) *
                      3.14159265358979323846 / 180.0;
    lc.sigma_floor_m = l->number("sigma_floor_m", 1e-4, 10.0, lc.sigma_floor_m);
    lc.sigma_floor_rad = l->number("sigma_floor_deg", 1e-3, 90.0, lc.sigma_floor_rad * 180.0 / 3.14159265358979323846) *
                         3.14159265358979323846 / 180.0;
    lc.capacity = o.keyframes.max_keyframes;
    o.loop_max_gap = l->number("max_gap_s", 0.05, 10.0, o.loop_max_gap);
    o.loop_arena_bytes = static_cast<std::size_t>(l->integer("arena_mb", 1, 4096, static_cast<std::int64_t>(o.loop_arena_bytes >> 20))) << 20;
    if (const std::string e = perception::registration::check_loop_closure_config(lc); !e.empty()) n.fail("loops", e);
    l->reject_unknown_keys();
    o.loops = lc;
  }
  n.reject_unknown_keys();
  return o;
}

}  // namespace

RobotConfig parse_robot_config(const ConfigNode& root) {
  RobotConfig c;
  c.file = root.file();
  if (auto r = root.optional_map("robot")) {
    c.name = r->string("name", "");
    r->reject_unknown_keys();
  }
  c.runtime = parse_runtime_settings(root.map("runtime"));
  if (auto n = root.optional_map("lidar")) c.lidar = parse_lidar(*n);
  if (auto n = root.optional_map("gps")) c.gps = parse_gps(*n);
  if (auto n = root.optional_map("imu")) c.imu = parse_imu(*n, c.imu_position);
  if (auto n = root.optional_map("can")) c.can = parse_can(*n);
  if (auto n = root.optional_map("gpio")) c.gpio = parse_gpio(*n);
  if (auto n = root.optional_map("camera")) c.camera = parse_camera(*n);
  if (auto n = root.optional_map("place")) {
    c.place = parse_place(*n);
    if (!c.camera) root.fail("place", "the place task takes the camera's frames: add a 'camera' section");
  }
  if (auto n = root.optional_map("pose")) c.pose = parse_pose(*n, c.obstacles_use_pose, c.terrain_use_pose, c.pose_wait);
  if (c.place && c.place->pose.use != pose::PlaceUse::off && !c.pose)
    root.fail("place", "place.pose_measurement gives the pose thread the place task's answers: add a 'pose' section, or set it off");
  if (auto n = root.optional_map("obstacles")) {
    c.obstacles = perception::parse_obstacle_config(*n);
    if (!c.lidar) root.fail("obstacles", "the obstacle map needs a lidar: add a 'lidar' section");
    const std::string problem = perception::check_obstacle_config(*c.obstacles);
    if (!problem.empty()) root.fail("obstacles", problem);
  }
  if (auto n = root.optional_map("terrain")) {
    c.terrain = perception::parse_terrain_config(*n);
    if (!c.lidar) root.fail("terrain", "the terrain map needs a lidar: add a 'lidar' section");
    if (c.terrain->model.empty()) n->fail("model", "the terrain classifier needs its model file (trailnav terrain-train)");
    const std::string e =
        perception::check_terrain_alignment(*c.terrain, c.obstacles ? c.obstacles->features : perception::FeatureParams{});
    if (!e.empty()) root.fail("terrain", e);
    if (auto m = perception::RandomForest::load(c.terrain->model); !m.forest) {
      n->fail("model", m.error);
    } else if (c.lidar) {
      const std::string l = perception::check_forest_lidar(*m.forest, velodyne::model_info(c.lidar->model).name, c.terrain->model);
      if (!l.empty()) n->fail("model", l);
      const std::string s = perception::check_forest_settings(*m.forest, *c.terrain, c.terrain->model);
      if (!s.empty()) n->fail("model", s);
    }
  }
  if (auto n = root.optional_map("traversability")) {
    c.traversability = perception::trav::parse_traversability_config(*n);
    if (!c.terrain) {
      root.fail("traversability", "the layer is computed in the terrain thread from its grid: add a 'terrain' section");
    }
    if (c.traversability->demonstration && (!c.pose || !c.terrain_use_pose)) {
      n->fail("demonstration", "the footprint follows the robot's odometry: add a 'pose' section with feed_terrain: true");
    }
    if (const auto start = perception::trav::load_start_models(*c.traversability); !start.models) {
      n->fail("model", start.error);
    }
  }
  if (auto n = root.optional_map("navigation")) {
    c.navigation = nav::parse_navigation_section(*n);
    if (!c.pose || !c.gps) {
      root.fail("navigation", "navigation needs the robot's UTM pose: add 'pose' and 'gps' sections");
    }
    if (c.terrain && !c.terrain_use_pose) {
      root.fail("navigation", "the subgoals are aligned in the odometry frame: set pose.feed_terrain to true so the "
                              "terrain map is registered there");
    }
    if (c.terrain) {
      c.navigation->navigator.aligner.cost = c.terrain->cost;
      c.navigation->navigator.aligner.unknown_cost = c.terrain->unknown_cost;
    }
    if (c.navigation->navigator.aligner.cell_cost == subgoals::AlignerConfig::CellCost::traversability &&
        !c.traversability) {
      n->fail("aligner", "cell_cost: traversability needs the learnt layer: add a 'traversability' section");
    }
  }
  if (auto n = root.optional_map("mapping")) {
    if (!c.pose) root.fail("mapping", "the map is built from the pose thread's odometry: add a 'pose' section");
    c.mapping = parse_mapping(*n, c.gps.has_value(), *c.pose);
    if (c.mapping->loops && (!c.lidar || c.lidar->cloud)) {
      n->fail("loops", "loop closures register the Velodyne's revolutions at the keyframes: add a 'lidar' section with "
                       "Velodyne packets");
    }
  }
  if (auto n = root.optional_map("station")) {
    c.station = parse_station(*n);
    if (c.station->input == StationSection::Input::velodyne) {
      if (!c.lidar || c.lidar->cloud) {
        root.fail("station", "input: velodyne flattens a band of the Velodyne's rings: add a 'lidar' section with "
                             "Velodyne packets (or take input: laserscan)");
      }
      const int rings = velodyne::model_info(c.lidar->model).lasers;
      if (c.station->band.last_ring >= rings) {
        n->fail("rings", "ring " + std::to_string(c.station->band.last_ring) + " is beyond the " +
                             std::string(velodyne::model_info(c.lidar->model).name) + "'s " + std::to_string(rings) +
                             " rings (0 to " + std::to_string(rings - 1) + ")");
      }
    }
  }
  // The terrain thread reads the revolutions itself only without the
  // obstacle thread, or when the two register with different poses (else it
  // takes the obstacle thread's aligned points: RobotConfig::terrain_shares_alignment()).
  if (c.lidar) {
    c.lidar->driver.revolution_readers =
        std::max(1, static_cast<int>(c.revolution_reader(RobotConfig::Reader::count)));
    // The obstacle thread, working on each revolution while it arrives, is
    // woken every quarter turn (every 1/32 in the last quarter, and at its
    // end) with the lidar's progress: each wake-up costs more than the work
    // it spreads (docs/performance.md), and what counts for the latency is
    // how little is left at the end.
    c.lidar->driver.progress_signals = c.obstacles && c.obstacles->streaming ? 4 : 0;
    if (c.lidar->cloud) c.lidar->cloud->readers = static_cast<std::size_t>(c.lidar->driver.revolution_readers);
  }
  if (c.pose && !c.imu && !c.can) root.fail("pose", "the pose needs wheel odometry ('can') or an IMU ('imu')");
  c.dds = parse_dds(root.map("dds"));

  const int cpus = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  // One row per part: is it configured, and how must its task run.
  struct Part {
    const char* name;
    bool configured;
    TaskKind kind;
  };
  // (A point-cloud input reads DDS on a plain thread: no task of its own.)
  const Part parts[] = {{"lidar", c.lidar.has_value() && !c.lidar->cloud, TaskKind::periodic},
                        {"gps", c.gps.has_value(), TaskKind::periodic},
                        {"imu", c.imu.has_value(), TaskKind::periodic},
                        {"can", c.can.has_value(), TaskKind::periodic},
                        {"gpio", c.gpio.has_value(), TaskKind::periodic},
                        {"pose", c.pose.has_value(), TaskKind::periodic},
                        {"obstacles", c.obstacles.has_value(), TaskKind::event},
                        {"terrain", c.terrain.has_value(), TaskKind::periodic},
                        {"navigation", c.navigation.has_value(), TaskKind::periodic},
                        {"mapping", c.mapping.has_value(), TaskKind::periodic},
                        {"demonstration", c.traversability && c.traversability->demonstration, TaskKind::periodic},
                        {"camera", c.camera.has_value(), TaskKind::periodic},
                        {"place", c.place.has_value(), TaskKind::periodic},
                        {"station", c.station.has_value(), TaskKind::periodic}};
  if (root.is_map("tasks")) {
    // A preset: the measured table of a lidar model, for the parts configured.
    const ConfigNode t = root.map("tasks");
    const std::string preset = t.string("preset");
    velodyne::Model model = c.lidar ? c.lidar->model : velodyne::Model::vlp16;
    if (preset != "auto") {
      const auto m = velodyne::parse_model(preset);
      if (!m) t.fail("preset", "unknown preset '" + preset + "' (auto: the lidar's model; VLP-16, VLP-32C, HDL-32E, HDL-64E)");
      model = *m;
    }
    std::vector<std::string_view> names;
    for (const Part& part : parts) {
      if (part.configured) names.push_back(part.name);
    }
    c.tasks = preset_tasks(model, names);
    c.task_preset = std::string(velodyne::model_info(model).name);
    change_task_table(t, "change", cpus, c.tasks);
    t.reject_unknown_keys();
  } else {
    c.tasks = parse_task_table(root, "tasks", cpus);
  }
  if (c.lidar) c.warnings = budget_warnings(c.tasks, c.lidar->model);
  for (const Part& part : parts) {
    if (!part.configured) continue;
    const TaskSpec& t = require_task(c.tasks, part.name, root, "tasks");
    if (t.kind != part.kind) {
      root.fail("tasks", std::string("task '") + part.name + "' must be " +
                             (part.kind == TaskKind::event ? "event-driven (it runs when a revolution is complete)"
                                                           : "periodic (it polls its inputs)"));
    }
  }
  for (const TaskSpec& t : c.tasks) {
    const bool used = std::any_of(std::begin(parts), std::end(parts),
                                  [&](const Part& p) { return p.configured && t.name == p.name; });
    if (!used) {
      root.fail("tasks", "task '" + t.name + "' has nothing to run: its section is missing, or it is not one of "
                         "lidar, gps, imu, can, gpio, pose, obstacles, terrain, navigation, mapping, demonstration, camera, place, station");
    }
  }
  root.reject_unknown_keys();
  return c;
}

RobotConfigResult load_robot_config(const std::string& path) {
  try {
    const ConfigNode root = ConfigNode::load_file(path);
    return {parse_robot_config(root), {}};
  } catch (const ConfigError& e) {
    return {std::nullopt, e.what()};
  }
}

}  // namespace trailnav::daemon
