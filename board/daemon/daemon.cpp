#include "daemon.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>

#include "trailnav/drivers/velodyne/calibration.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/host_clock.hpp"
#include "trailnav/runtime/log.hpp"

namespace trailnav::daemon {

namespace {

// The lidar's place on the robot (the obstacle map's mount: roll, pitch and
// yaw in degrees, R = Rz Ry Rx), as the transform from its frame to the robot's.
Eigen::Isometry3f mount_transform(const perception::MountParams& m) {
  constexpr double kDeg = 3.14159265358979323846 / 180.0;
  Eigen::Isometry3f t = Eigen::Isometry3f::Identity();
  t.linear() = (Eigen::AngleAxisd(m.rotation_deg[2] * kDeg, Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(m.rotation_deg[1] * kDeg, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(m.rotation_deg[0] * kDeg, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix()
                   .cast<float>();
  t.translation() =
      Eigen::Vector3f(static_cast<float>(m.translation[0]), static_cast<float>(m.translation[1]), static_cast<float>(m.translation[2]));
  return t;
}

const TaskSpec* find_task(const std::vector<TaskSpec>& tasks, std::string_view name) {
  for (const TaskSpec& t : tasks) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

// The navigation section as start-up builds it (and `--check` tries it): the
// road network into `graph` (the navigator keeps a reference to it, so it is
// loaded where it will live), then the navigator. Empty error when both are made.
std::string build_navigation(const RobotConfig& config, std::optional<osm::RoadGraph>& graph,
                             std::unique_ptr<nav::Navigator>& navigator) {
  const nav::NavigationSection& n = *config.navigation;
  auto loaded = osm::load_road_graph(n.osm, n.profile, {}, config.pose ? config.pose->utm.zone : 0);
  if (!loaded.graph) return "navigation: " + loaded.error;
  graph = std::move(loaded.graph);
  const perception::TerrainMapShape shape = config.terrain ? config.terrain->map : perception::TerrainMapShape{};
  auto made = nav::Navigator::create(*graph, n.navigator, shape);
  if (!made.navigator) return "navigation: " + made.error;
  navigator = std::move(made.navigator);
  return {};
}

// One line on the loaded network and where the goal lies on it.
std::string navigation_summary(const nav::NavigationSection& n, const osm::RoadGraph& g) {
  if (std::isnan(n.navigator.goal_lat)) {
    char text[300];
    std::snprintf(text, sizeof text,
                  "navigation: %s: %zu vertices, %zu segments, UTM zone %d%c; no goal yet: idle until one arrives on DDS",
                  n.osm.c_str(), g.vertex_count(), g.segments().size(), g.zone(), g.north() ? 'N' : 'S');
    return text;
  }
  double gx = 0.0, gy = 0.0;
  g.to_utm(n.navigator.goal_lat, n.navigator.goal_lon, gx, gy);
  const auto goal = g.project(gx, gy);
  char text[400];
  std::snprintf(text, sizeof text,
                "navigation: %s: %zu vertices, %zu segments, UTM zone %d%c; goal %.6f, %.6f lies %.1f m from the nearest routable way",
                n.osm.c_str(), g.vertex_count(), g.segments().size(), g.zone(), g.north() ? 'N' : 'S', n.navigator.goal_lat,
                n.navigator.goal_lon, goal ? goal->distance : 0.0);
  return text;
}

}  // namespace

Daemon::Daemon(const RobotConfig& config) : config_(config) {}

Daemon::~Daemon() { stop(); }

Daemon::Created Daemon::create(const RobotConfig& config) {
  Created result;
  std::unique_ptr<Daemon> d(new Daemon(config));
  auto fail = [&](const std::string& what) {
    result.error = what;
    return std::move(result);
  };
  d->scheduler_ = std::make_unique<Scheduler>(d->clock_, config.runtime.scheduler);

  // The DDS domain first: a point-cloud lidar's input comes through it.
  auto domain = dds::Domain::create(config.dds.domain, dds::with_small_receive_buffer(config.dds.cyclone_xml));
  if (!domain.domain) {
    return fail(domain.error + (config.dds.cyclone_config.empty() ? "" : " (" + config.dds.cyclone_config + ")"));
  }
  d->domain_ = std::move(domain.domain);

  if (config.lidar && config.lidar->cloud) {
    auto reader = dds::CloudReader::create(*d->domain_, *config.lidar->cloud);
    if (!reader.reader) return fail("lidar: " + reader.error);
    d->cloud_reader_ = std::move(reader.reader);
  } else if (config.lidar) {
    const LidarSection& l = *config.lidar;
    std::optional<velodyne::Calibration> calibration;
    if (l.calibration.empty()) {
      calibration = velodyne::builtin_calibration(l.model);
    } else {
      auto c = velodyne::load_calibration(l.calibration);
      if (!c.calibration) return fail("lidar: " + c.error);
      calibration = std::move(c.calibration);
    }
    velodyne::DecoderOptions dopt;
    dopt.selection = velodyne::ReturnSelection::strongest;
    auto decoder = velodyne::PacketDecoder::create(l.model, *calibration, dopt);
    if (!decoder.decoder) return fail("lidar: " + decoder.error);
    auto driver = velodyne::VelodyneDriver::create(std::move(*decoder.decoder), l.driver);
    if (!driver.driver) return fail(driver.error);
    d->lidar_ = std::move(driver.driver);
  }
  if (config.gps) {
    auto g = gps::GpsDriver::create(*config.gps);
    if (!g.driver) return fail("gps: " + g.error);
    d->gps_ = std::move(g.driver);
  }
  if (config.imu) {
    auto i = imu::ImuDriver::create(*config.imu);
    if (!i.driver) return fail("imu: " + i.error);
    d->imu_ = std::move(i.driver);
  }
  if (config.can) {
    auto dbc = can::load_dbc(config.can->dbc);
    if (!dbc.dbc) return fail("can: " + dbc.error);
    d->dbc_ = std::move(*dbc.dbc);
    auto c = can::CanDriver::create(*d->dbc_, config.can->driver);
    if (!c.driver) return fail("can: " + c.error);
    d->can_ = std::move(c.driver);
  }
  if (config.gpio) {
    auto g = gpio::GpioDriver::create(*config.gpio);
    if (!g.driver) return fail("gpio: " + g.error);
    d->gpio_ = std::move(g.driver);
  }
  if (config.camera) {
    auto c = drivers::camera::CameraDriver::create(*config.camera);
    if (!c.driver) return fail("camera: " + c.error);
    d->camera_ = std::move(c.driver);
  }
  if (config.place) {
    // The database: its descriptors must be of the camera's reduced frames.
    const PlaceSection& p = *config.place;
    auto loaded = perception::place::load_place_database(p.database);
    if (!loaded.database) return fail("place: " + loaded.error);
    const perception::place::PlaceDatabase& db = *loaded.database;
    if (db.width != config.camera->out_width || db.height != config.camera->out_height) {
      return fail("place: " + p.database + " describes " + std::to_string(db.width) + " x " + std::to_string(db.height) +
                  " frames, the camera reduces its frames to " + std::to_string(config.camera->out_width) + " x " +
                  std::to_string(config.camera->out_height) + " (camera.out_width, out_height)");
    }
    perception::place::OnlineConfig oc;
    oc.hog = db.hog;
    oc.transition = p.transition;
    oc.width = db.width;
    oc.height = db.height;
    oc.capacity = db.entries.size();
    oc.prior_queries = p.prior_queries;
    oc.lag = p.lag;
    oc.sequence = p.sequence;
    oc.peak_radius = p.peak_radius;
    try {
      d->place_online_ = std::make_unique<perception::place::OnlinePlace>(oc);
    } catch (const std::exception& e) {
      return fail("place: " + p.database + ": " + e.what());
    }
    if (d->place_online_->descriptor_length() != db.length) return fail("place: " + p.database + ": descriptors of another length");
    for (const perception::place::PlaceEntry& e : db.entries) d->place_online_->add_database_code(e.code, e.norm);
    d->place_online_->finish_database();
    if (!d->place_online_->set_whitening(db.whitening)) return fail("place: " + p.database + ": a whitening of another size");
    d->place_out_ = std::make_unique<Mailbox<perception::place::PlaceSnapshot>>();
    d->place_ = std::make_unique<perception::place::PlaceTask>(db, *d->place_online_, d->camera_->frames(), *d->place_out_,
                                                               p.task);
    if (p.pose.use != pose::PlaceUse::off) {
      d->place_pose_in_ = std::make_unique<Mailbox<perception::place::PlaceSnapshot>>();
      d->place_->set_second_output(d->place_pose_in_.get());
    }
    TN_LOG_INFO("place: %s: %zu images of %d x %d frames (%d-pixel patches), %s, poses in frame '%s', answers %d frames "
                "back in sequences of %d; the pose thread takes them %s",
                p.database.c_str(), db.entries.size(), db.width, db.height, db.hog.patch,
                db.whitening.rank > 0 ? "ZCA from the database" : "Eq. 5.3 (no ZCA in the database)", p.frame.c_str(), p.lag,
                p.sequence.min_length,
                p.pose.use == pose::PlaceUse::off        ? "never (place.pose_measurement: off)"
                : p.pose.use == pose::PlaceUse::gps_poor ? "when GPS is poor"
                                                         : "always");
  }
  // The road network first: the pose's UTM frame must be the network's zone.
  std::optional<pose::PoseEstimatorOptions> pose_options = config.pose;
  if (config.navigation) {
    if (std::string e = build_navigation(config, d->graph_, d->navigator_); !e.empty()) return fail(e);
    pose_options->utm.zone = d->graph_->zone();
    d->navigation_out_ = std::make_unique<Mailbox<nav::NavigationSnapshot>>(config.navigation->navigator.path_poses);
    TN_LOG_INFO("%s", navigation_summary(*config.navigation, *d->graph_).c_str());
  }
  if (config.pose) {
    d->pose_ = std::make_unique<pose::PoseTask>(*pose_options, d->imu_ ? &d->imu_->readings() : nullptr,
                                                d->can_ ? &d->can_->readings() : nullptr,
                                                d->gps_ ? &d->gps_->fixes() : nullptr);
    if (d->place_pose_in_) d->pose_->set_place_input(d->place_pose_in_.get(), config.place->pose);
  }
  if (config.mapping) {
    // The mapping thread: every pose and every fix the alignment used, in
    // queues of their own; the map's storage and the solver's arenas now.
    const slam::MappingOptions& m = *config.mapping;
    d->mapping_poses_ = std::make_unique<perception::PoseQueue>();
    d->pose_->add_pose_output(d->mapping_poses_.get());
    if (m.use_gps) {
      d->mapping_fixes_ = std::make_unique<pose::MappingFixQueue>();
      d->pose_->set_fix_output(d->mapping_fixes_.get());
    }
    d->mapping_out_ = std::make_unique<Mailbox<slam::MappingSnapshot>>(m.keyframes.max_keyframes);
    d->mapping_ = std::make_unique<slam::MappingTask>(m, *d->mapping_poses_, d->mapping_fixes_.get(), *d->mapping_out_);
    if (m.loops) {
      // The keyframes' clouds: the lidar's revolutions in the robot frame (the obstacle map's mount).
      const Eigen::Isometry3f mount =
          config.obstacles ? mount_transform(config.obstacles->mount) : Eigen::Isometry3f::Identity();
      d->mapping_->set_revolutions(&d->lidar_revolutions(config.revolution_reader(RobotConfig::Reader::mapping)), mount, 2.0f, 60.0f);
      TN_LOG_INFO("mapping: loop closures from the lidar's revolutions (voxel %.2f m, %zu points a keyframe, "
                  "candidates within %.1f m and %.0f m of driving back, %.0f MB for the clouds)",
                  static_cast<double>(m.loops->voxel), m.loops->max_points, m.loops->search_radius, m.loops->min_path,
                  static_cast<double>(m.keyframes.max_keyframes * m.loops->max_points * sizeof(perception::registration::Point)) / 1e6);
    }
    if (m.use_gps) {
      d->map_corrections_ = std::make_unique<Mailbox<pose::MapCorrection>>();
      d->mapping_->set_corrections(d->map_corrections_.get());
      d->pose_->set_map_correction(d->map_corrections_.get());
    }
  }
  if (config.station) {
    // The station: its file, its bodies' covariances and trees now; the
    // task's arena and the localiser's buffers in its constructor below.
    namespace reg = perception::registration;
    const StationSection& sc = *config.station;
    auto loaded = reg::load_station(sc.file);
    if (!loaded.station) return fail("station: " + loaded.error);
    reg::BuiltStation built = reg::station_from_file(*loaded.station, sc.config);
    if (!built.error.empty()) return fail("station: " + sc.file + ": " + built.error);
    for (const std::string& name : built.station.names) {
      // Each body's name becomes a topic (trailnav/station/<name>) and a frame.
      const bool usable = !name.empty() && std::all_of(name.begin(), name.end(), [](char ch) {
        return (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '_';
      });
      if (!usable) {
        return fail("station: " + sc.file + ": body '" + name + "': its name names a DDS topic and a frame, so it may " +
                    "hold only letters, digits and '_' (teach it again with another name in the objects' YAML)");
      }
    }
    d->station_ = std::move(built.station);
    d->station_name_ = loaded.station->name;
    d->station_out_ = std::make_unique<Mailbox<reg::StationSnapshot>>(d->station_->bodies.size());
    if (sc.input == StationSection::Input::laserscan) {
      d->station_scans_ = std::make_unique<Mailbox<reg::PlanarScan>>(sc.config.max_points);
    }
    if (d->pose_ && sc.use_pose) {
      d->station_poses_ = std::make_unique<perception::PoseQueue>();
      d->pose_->add_pose_output(d->station_poses_.get());
    }
    d->station_task_ = std::make_unique<reg::StationTask>(*d->station_, sc.config, sc.task, d->station_scans_.get(),
                                                          d->station_poses_.get(), *d->station_out_);
    if (sc.input == StationSection::Input::velodyne) {
      reg::RingBand band = sc.band;
      // The lidar's own mount, as the obstacle map takes it.
      if (!sc.band_mount_given && config.obstacles) band.mount = mount_transform(config.obstacles->mount);
      d->station_task_->set_revolutions(&d->lidar_revolutions(config.revolution_reader(RobotConfig::Reader::station)), band);
    }
    std::size_t points = 0;
    for (std::size_t k = 0; k < d->station_->bodies.size(); ++k) points += d->station_->bodies[k].cloud.size();
    TN_LOG_INFO("station: %s ('%s'): %zu bodies, %zu reference points; planar scans from %s; a visit begins at (%.2f, "
                "%.2f) in the frame '%s', a fix every %d scan(s) once %d are in; odometry between scans %s",
                sc.file.c_str(), d->station_name_.c_str(), d->station_->bodies.size(), points,
                sc.input == StationSection::Input::laserscan ? dds::ros_topic(sc.laser.topic).c_str()
                                                             : "the Velodyne's ring band",
                sc.task.start.translation().x(), sc.task.start.translation().y(), sc.frame.c_str(), sc.task.every,
                sc.config.local_scans, d->station_poses_ ? "from the pose thread" : "from the last step (constant velocity)");
  }
  if (config.obstacles) {
    const velodyne::RangeImageShape shape = d->lidar_shape();
    auto made = perception::ObstaclePipeline::create(*config.obstacles, shape);
    if (!made.pipeline) return fail("obstacles: " + made.error);
    d->pipeline_ = std::move(made.pipeline);
    const int n = config.obstacles->map.size;
    d->obstacle_out_ = std::make_unique<Mailbox<perception::ObstacleSnapshot>>(n, n);
    if (d->pose_ && config.obstacles_use_pose) {
      d->pose_queue_ = std::make_unique<perception::PoseQueue>();
      d->pose_->add_pose_output(d->pose_queue_.get());
    }
  }
  // The terrain thread: the obstacle thread's aligned revolutions (or, on
  // its own, its own reader of the revolutions and its own pose queue); its
  // class maps go to the obstacle fusion (reader 0), the publisher (reader 1)
  // and navigation (reader 2).
  if (config.terrain) {
    auto model = perception::RandomForest::load(config.terrain->model);
    if (!model.forest) return fail("terrain: " + model.error);
    if (std::string e = perception::check_forest_lidar(*model.forest, velodyne::model_info(config.lidar->model).name,
                                                       config.terrain->model);
        !e.empty()) {
      return fail("terrain: " + e);
    }
    if (std::string e = perception::check_forest_settings(*model.forest, *config.terrain, config.terrain->model); !e.empty()) {
      return fail("terrain: " + e);
    }
    d->forest_ = std::move(model.forest);
    const perception::MountParams mount = config.obstacles ? config.obstacles->mount : perception::MountParams{};
    const perception::FeatureParams alignment = config.obstacles ? config.obstacles->features : perception::FeatureParams{};
    const velodyne::RangeImageShape shape = d->lidar_shape();
    auto made = perception::TerrainMapper::create(*config.terrain, mount, shape, &*d->forest_, alignment);
    if (!made.mapper) return fail("terrain: " + made.error);
    d->terrain_mapper_ = std::move(made.mapper);
    d->terrain_out_ = std::make_unique<Broadcast<perception::TerrainClassMap>>(config.navigation ? 3 : 2, config.terrain->map);
    if (config.terrain_shares_alignment()) {
      d->aligned_ = std::make_unique<Mailbox<perception::AlignedRevolution>>(
          perception::CloudShape{shape.rings, shape.max_columns});
      d->terrain_ = std::make_unique<perception::TerrainTask>(*d->terrain_mapper_, *d->aligned_, *d->terrain_out_);
    } else {
      if (d->pose_ && config.terrain_use_pose) {
        d->terrain_pose_queue_ = std::make_unique<perception::PoseQueue>();
        d->pose_->add_pose_output(d->terrain_pose_queue_.get());
      }
      d->terrain_ = std::make_unique<perception::TerrainTask>(*d->terrain_mapper_,
                                                             d->lidar_revolutions(config.revolution_reader(RobotConfig::Reader::terrain)),
                                                             d->terrain_pose_queue_.get(), *d->terrain_out_, 512,
                                                             config.pose_wait);
    }
  }
  // The traversability layer rides on the terrain thread's steps (the
  // mapper's sums sink) and writes each cell's P(trav) into the class maps
  // it publishes; a demonstration trains the model on a thread of its own.
  if (config.traversability) {
    namespace trav = perception::trav;
    const trav::TraversabilityConfig& tc = *config.traversability;
    auto start = trav::load_start_models(tc);
    if (!start.models) return fail("traversability: " + start.error);
    d->trav_models_ = std::move(start.models);
    const perception::TerrainMapShape& map = config.terrain->map;
    auto layer = trav::TravLayer::create(*d->trav_models_, tc.method, tc.local_map_distance, tc.max_range, map.size_x,
                                         map.size_y, map.resolution);
    if (!layer.layer) return fail("traversability: " + layer.error);
    d->trav_layer_ = std::move(layer.layer);
    if (tc.demonstration) {
      trav::RecorderConfig rc;
      rc.local_map_distance = tc.local_map_distance;
      rc.max_range = tc.max_range;
      rc.footprint = tc.footprint;
      rc.max_words = tc.max_words;
      const trav::Vocabulary& v = d->trav_models_->vocabulary();
      d->trav_recorder_ = std::make_unique<trav::TravRecorder>(rc, v, map.size_x, map.size_y, map.resolution);
      d->trav_local_maps_ = std::make_unique<Mailbox<trav::LocalMapWords>>(v.size());
      d->trav_models_out_ = std::make_unique<Mailbox<trav::TravModels>>(v, d->trav_models_->config());
      d->trav_trainer_ = std::make_unique<trav::TravTrainer>(*d->trav_models_, tc.profile, tc.model,
                                                             *d->trav_local_maps_, *d->trav_models_out_);
      d->trav_training_ = std::make_unique<trav::TravTrainingTask>(*d->trav_trainer_);
      TN_LOG_INFO("traversability: demonstration for the '%s' profile: %s %s%s", tc.profile.c_str(),
                  start.created ? "a new model, saved to" : "training further", tc.model.c_str(),
                  start.other_sets > 0 ? " (its NoRe/NoRS ablation sets are not trained online and are left out when "
                                         "it is saved)"
                                       : "");
    }
    d->trav_online_ = std::make_unique<trav::TravOnline>(*d->trav_layer_, d->trav_recorder_.get(),
                                                         d->trav_local_maps_.get(), d->trav_models_out_.get());
    d->terrain_mapper_->set_sums_sink(d->trav_online_.get());
  }
  if (config.obstacles) {
    d->obstacles_ = std::make_unique<perception::ObstacleTask>(
        *d->pipeline_, d->lidar_revolutions(config.revolution_reader(RobotConfig::Reader::obstacles)), d->pose_queue_.get(),
        d->terrain_out_ ? &d->terrain_out_->reader(0) : nullptr, *d->obstacle_out_, 512, config.pose_wait);
    d->obstacles_->set_aligned(d->aligned_.get());
    d->obstacles_->set_streaming(config.obstacles->streaming);
    if (d->lidar_) d->lidar_->set_revolution_event(&d->revolution_event_);
    if (d->cloud_reader_) d->cloud_reader_->set_revolution_event(&d->revolution_event_, d->clock_);
  }

  if (d->navigator_) {
    d->navigation_ = std::make_unique<nav::NavigationTask>(*d->navigator_, d->pose_->navigation_poses(),
                                                           d->terrain_out_ ? &d->terrain_out_->reader(2) : nullptr,
                                                           *d->navigation_out_);
  }

  dds::PublisherInputs inputs;
  inputs.obstacles = d->obstacle_out_.get();
  inputs.poses = d->pose_ ? &d->pose_->poses() : nullptr;
  if (d->terrain_out_) {
    inputs.terrain = &d->terrain_out_->reader(1);
    inputs.terrain_cost = config.terrain->cost;
    inputs.unknown_cost = config.terrain->unknown_cost;
    inputs.traversability = config.traversability.has_value();
  }
  inputs.navigation = d->navigation_out_.get();
  inputs.mapping = d->mapping_out_.get();
  inputs.place = d->place_out_.get();
  inputs.station = d->station_out_.get();
  if (d->obstacles_ && config.dds.publisher.points_rate_hz > 0.0) {
    // Viewers' points: every point a revolution can have, allocated now.
    const velodyne::RangeImageShape shape = d->lidar_shape();
    const auto capacity = static_cast<std::size_t>(shape.rings) * static_cast<std::size_t>(shape.max_columns);
    d->points_out_ = std::make_unique<Mailbox<perception::PointsSnapshot>>(capacity);
    d->obstacles_->set_points(d->points_out_.get(), static_cast<std::int64_t>(1e9 / config.dds.publisher.points_rate_hz));
    inputs.points = d->points_out_.get();
  }
  if (d->navigation_) {
    d->answers_ = std::make_unique<nav::NavStatusQueue>();
    inputs.navigation_answers = d->answers_.get();
  }
  Daemon* self = d.get();
  inputs.health = [self](dds::DiagnosticsMessage& m, Nanos now) { self->fill_health(m, now); };
  dds::PublisherOptions popt = config.dds.publisher;
  if (config.place) popt.place_frame = config.place->frame;
  if (d->station_) {
    popt.station_name = d->station_name_;
    popt.station_frame = config.station->frame;
    popt.station_bodies = d->station_->names;
  }
  // tf_static: where each sensor sits on the robot (the config's mounts).
  constexpr double kDeg = 3.14159265358979323846 / 180.0;
  if (config.lidar) {
    const perception::MountParams m = config.obstacles ? config.obstacles->mount : perception::MountParams{};
    popt.static_frames.push_back({popt.frames.lidar,
                                  {m.translation[0], m.translation[1], m.translation[2], m.rotation_deg[0] * kDeg,
                                   m.rotation_deg[1] * kDeg, m.rotation_deg[2] * kDeg}});
  }
  if (config.imu) {
    popt.static_frames.push_back({popt.frames.imu, {config.imu_position[0], config.imu_position[1], config.imu_position[2]}});
  }
  if (config.gps && config.pose) {
    const auto& a = config.pose->utm.antenna;
    popt.static_frames.push_back({popt.fix_frame, {a[0], a[1], a[2]}});
  }
  popt.map_instant_tf = config.obstacles && config.pose && config.obstacles_use_pose;
  if (config.obstacles) {
    popt.occupied_percent = static_cast<int>(config.obstacles->map.occupied * 100.0f);
    popt.map_resolution = config.obstacles->map.resolution;
  }
  auto pub = dds::DdsPublisher::create(*d->domain_, d->clock_, popt, std::move(inputs));
  if (!pub.publisher) return fail("dds: " + pub.error);
  d->publisher_ = std::move(pub.publisher);
  if (d->navigation_) {
    // Orders from outside: read off the real-time path, checked by the navigator.
    d->commands_ = std::make_unique<nav::NavCommandQueue>();
    dds::CommandReaderOptions copt = config.dds.commands;
    copt.odom_frame = popt.odom_frame;
    copt.map_frame = popt.frames.map;
    copt.zone = d->graph_->zone();
    copt.north = d->graph_->north();
    auto reader = dds::CommandReader::create(*d->domain_, copt, *d->commands_);
    if (!reader.reader) return fail("dds: " + reader.error);
    d->command_reader_ = std::move(reader.reader);
    d->navigation_->set_commands(d->commands_.get(), d->answers_.get());
  }
  if (d->obstacles_) d->obstacles_->set_notify(&d->publisher_->wakeup());
  if (d->terrain_) d->terrain_->set_notify(&d->publisher_->wakeup());
  if (d->navigation_) d->navigation_->set_notify(&d->publisher_->wakeup());
  if (d->mapping_) d->mapping_->set_notify(&d->publisher_->wakeup());
  if (d->place_) d->place_->set_notify(&d->publisher_->wakeup());
  if (d->station_task_) d->station_task_->set_notify(&d->publisher_->wakeup());
  if (d->station_scans_) {
    auto reader = dds::LaserScanReader::create(*d->domain_, config.station->laser, *d->station_scans_);
    if (!reader.reader) return fail("station: " + reader.error);
    d->scan_reader_ = std::move(reader.reader);
  }

  // The task table, in a fixed order.
  auto add = [&](const char* name, Task* task, TaskEvent* event) -> bool {
    if (task == nullptr) return true;
    const TaskSpec* spec = find_task(config.tasks, name);
    if (Status st = d->scheduler_->add(*spec, *task, event); !st) {
      result.error = st.message();
      return false;
    }
    return true;
  };
  if (!add("lidar", d->lidar_.get(), nullptr) || !add("gps", d->gps_.get(), nullptr) ||
      !add("imu", d->imu_.get(), nullptr) || !add("can", d->can_.get(), nullptr) ||
      !add("gpio", d->gpio_.get(), nullptr) || !add("pose", d->pose_.get(), nullptr) ||
      !add("obstacles", d->obstacles_.get(), &d->revolution_event_) || !add("terrain", d->terrain_.get(), nullptr) ||
      !add("navigation", d->navigation_.get(), nullptr) || !add("mapping", d->mapping_.get(), nullptr) ||
      !add("demonstration", d->trav_training_.get(), nullptr) || !add("camera", d->camera_.get(), nullptr) ||
      !add("place", d->place_.get(), nullptr) || !add("station", d->station_task_.get(), nullptr)) {
    return result;
  }
  d->last_runs_.assign(d->scheduler_->task_count(), 0);
  result.daemon = std::move(d);
  return result;
}

Status Daemon::start() {
  publisher_->start();
  if (command_reader_) command_reader_->start();
  if (cloud_reader_) cloud_reader_->start();
  if (scan_reader_) scan_reader_->start();
  if (Status st = scheduler_->start(); !st) {
    publisher_->stop();
    return st;
  }
  if (gpio_) gpio_->set_ready(true);
  // From here on the real-time tasks are watched for heap use.
  alloc_guard::reset_counters();
  armed_.store(alloc_guard::arm(), std::memory_order_release);
  return Status::ok();
}

void Daemon::stop() {
  if (gpio_) gpio_->set_ready(false);
  if (command_reader_) command_reader_->stop();
  if (cloud_reader_) cloud_reader_->stop();
  if (scan_reader_) scan_reader_->stop();
  const bool was_running = scheduler_ && scheduler_->running();
  if (was_running) scheduler_->stop();
  if (was_running && trav_trainer_) {
    // The demonstration's last stretch (the tasks have ended): the local map
    // under way is learnt from and the model saved, so that a drive cut
    // short keeps what it showed.
    trav_online_->finish_partial();
    while (trav_trainer_->poll()) {
    }
    const perception::trav::TrainerCounters t = trav_trainer_->counters();
    if (t.save_errno != 0) {
      TN_LOG_ERROR("traversability: the model could not be saved to %s: %s", trav_trainer_->path().c_str(),
                   std::strerror(t.save_errno));
    } else {
      TN_LOG_INFO("traversability: %llu local maps learnt, %u terrain models, saved to %s",
                  static_cast<unsigned long long>(t.trained), t.models, trav_trainer_->path().c_str());
    }
  }
  if (publisher_) publisher_->stop();
  if (armed_.load(std::memory_order_acquire)) {
    alloc_guard::disarm();
    armed_.store(false, std::memory_order_release);
  }
}

bool Daemon::alive() noexcept {
  // Periodic real-time tasks must have run since the last call; event tasks
  // may idle, and so may a task on normal scheduling (the mapping thread's
  // solve of a large map takes seconds: it must not restart the service).
  bool ok = scheduler_->running();
  for (std::size_t i = 0; i < scheduler_->task_count(); ++i) {
    const std::uint64_t runs = scheduler_->stats(i).runs;
    const TaskSpec& spec = scheduler_->spec(i);
    if (spec.kind == TaskKind::periodic && spec.priority > 0 && runs == last_runs_[i]) ok = false;
    last_runs_[i] = runs;
  }
  return ok;
}

Daemon::NavigationCheck Daemon::check_navigation(const RobotConfig& config) {
  NavigationCheck out;
  if (!config.navigation) return out;
  std::optional<osm::RoadGraph> graph;
  std::unique_ptr<nav::Navigator> navigator;
  out.error = build_navigation(config, graph, navigator);
  if (out.error.empty()) out.summary = navigation_summary(*config.navigation, *graph);
  return out;
}

DaemonSummary Daemon::summary() const {
  DaemonSummary s;
  if (obstacles_) s.revolutions = obstacles_->status().revolutions;
  s.maps_published = publisher_ ? publisher_->stats().maps : 0;
  for (std::size_t i = 0; i < scheduler_->task_count(); ++i) {
    const TaskStats st = scheduler_->stats(i);
    s.overruns += st.overruns;
    s.stalls += st.stalls;
  }
  s.rt_allocations = alloc_guard::total_allocations();
  s.realtime = scheduler_->realtime_active();
  s.memory_locked = scheduler_->memory_locked();
  return s;
}

std::string Daemon::status_line() const {
  const DaemonSummary s = summary();
  char text[240];
  std::snprintf(text, sizeof text,
                "%llu revolutions, %llu maps published, %llu overruns, %llu stalls, %llu real-time allocations",
                static_cast<unsigned long long>(s.revolutions), static_cast<unsigned long long>(s.maps_published),
                static_cast<unsigned long long>(s.overruns), static_cast<unsigned long long>(s.stalls),
                static_cast<unsigned long long>(s.rt_allocations));
  return text;
}

std::optional<Daemon::TaskFigures> Daemon::task_figures(std::string_view name) const {
  for (std::size_t i = 0; i < scheduler_->task_count(); ++i)
    if (scheduler_->spec(i).name == name) return TaskFigures{scheduler_->stats(i), nanos_to_seconds(scheduler_->spec(i).budget) * 1e3};
  return std::nullopt;
}

std::string Daemon::task_report() const {
  std::string out;
  for (std::size_t i = 0; i < scheduler_->task_count(); ++i) {
    const TaskStats st = scheduler_->stats(i);
    char line[300];
    std::snprintf(line, sizeof line,
                  "  %-10s runs %8llu  overruns %llu  stalls %llu  slips %llu  rested %llu  exec p50 %.3f p99 %.3f max %.3f ms  "
                  "cpu/period p99 %.3f max %.3f ms  latency p99 %.3f ms\n",
                  scheduler_->spec(i).name.c_str(), static_cast<unsigned long long>(st.runs),
                  static_cast<unsigned long long>(st.overruns), static_cast<unsigned long long>(st.stalls),
                  static_cast<unsigned long long>(st.slips), static_cast<unsigned long long>(st.rested_periods),
                  nanos_to_seconds(st.execution.p50) * 1e3, nanos_to_seconds(st.execution.p99) * 1e3,
                  nanos_to_seconds(st.execution.max) * 1e3, nanos_to_seconds(st.cpu_per_period.p99) * 1e3, nanos_to_seconds(st.cpu_per_period.max) * 1e3,
                  nanos_to_seconds(st.latency.p99) * 1e3);
    out += line;
  }
  if (obstacles_) {
    const DurationSummary d = obstacles_->map_delay();
    const perception::ObstacleTaskCounters c = obstacles_->status();
    char line[300];
    std::snprintf(line, sizeof line,
                  "  obstacle maps: %llu, from the completing packet's receipt to the snapshot p50 %.3f p99 %.3f max %.3f ms; "
                  "%llu taken while they arrived (%llu block steps early), %llu dropped by the lidar half-way\n",
                  static_cast<unsigned long long>(d.count), nanos_to_seconds(d.p50) * 1e3, nanos_to_seconds(d.p99) * 1e3,
                  nanos_to_seconds(d.max) * 1e3, static_cast<unsigned long long>(c.streamed),
                  static_cast<unsigned long long>(c.early_blocks), static_cast<unsigned long long>(c.abandoned));
    out += line;
  }
  return out;
}

void Daemon::fill_health(dds::DiagnosticsMessage& m, Nanos now) const {
  using L = dds::DiagnosticsMessage;
  const std::int64_t utc = host_now_ns();  // the drivers' receive times are on it
  const double stale_after = config_.dds.publisher.stale_after;
  {
    // Steps of the system clock since start: taken out of every stamp inside
    // (host time) and put back on the way out (runtime/host_clock.hpp).
    const std::uint64_t steps = host_clock_steps();
    const double step_s = nanos_to_seconds(host_clock_step_ns());
    char msg[120];
    if (steps == 0) {
      std::snprintf(msg, sizeof msg, "the system clock has not been set since start");
    } else {
      std::snprintf(msg, sizeof msg, "the system clock was set %llu time(s) since start, %+.3f s in all: stamps carry on",
                    static_cast<unsigned long long>(steps), step_s);
    }
    m.begin(L::ok, "trailnavd: clock", msg, "");
    m.value("host_clock_steps", steps);
    m.value("host_clock_step_s", step_s, 3);
  }
  // The lidar's silence: seconds since `last_ns` (-1: nothing yet), stale
  // past dds.stale_after_s, and the message for either.
  struct Silence {
    double seconds;
    bool stale;
  };
  const auto silence = [&](std::int64_t last_ns) {
    const double silent = last_ns > 0 ? static_cast<double>(utc - last_ns) * 1e-9 : -1.0;
    return Silence{silent, silent < 0.0 || silent > stale_after};
  };
  const auto stale_text = [](const Silence& q, char* msg, std::size_t size) {
    std::snprintf(msg, size, "silent for %.1f s: obstacle map stale", q.seconds);
  };
  if (lidar_) {
    const velodyne::DriverCounters c = lidar_->counters();
    const Silence q = silence(c.last_packet_ns);
    const bool stale = q.stale;
    char msg[96];
    if (q.seconds < 0.0) {
      std::snprintf(msg, sizeof msg, "no data packet yet");
    } else if (stale) {
      stale_text(q, msg, sizeof msg);
    } else {
      std::snprintf(msg, sizeof msg, "receiving");
    }
    m.begin(stale ? L::error : L::ok, "trailnavd: lidar", msg,
            lidar_->decoder().model().name);
    m.value("stale", stale ? std::string_view("true") : std::string_view("false"));
    m.value("packets", c.data.datagrams);
    m.value("revolutions", c.assembler.revolutions);
    m.value("lost_packets", c.assembler.lost_packets);
    m.value("discontinuities", c.assembler.discontinuities);
    m.value("malformed", c.assembler.malformed + c.wrong_size);
    m.value("kernel_drops", c.data.kernel_drops);
    m.value("position_packets", c.position_packets);
    m.value("time_source", velodyne::time_source_name(c.time_source));
    // The lidar's clock against the reference clock (docs/dds.md, "One clock").
    m.value("clock_offset_s", static_cast<double>(c.reference.offset_ns) * 1e-9, 6);
    m.value("clock_spread_ms", static_cast<double>(c.reference.spread_ns) * 1e-6, 3);
    m.value("clock_max_spread_ms", static_cast<double>(c.reference.max_spread_ns) * 1e-6, 3);
    m.value("clock_settled", c.reference.settled ? std::string_view("true") : std::string_view("false"));
    m.value("clock_steps", c.reference.steps);
  }
  if (cloud_reader_) {
    const dds::CloudReaderStats c = cloud_reader_->stats();
    const Silence q = silence(c.last_receive_ns);
    const bool stale = q.stale;
    char msg[160];
    if (q.seconds < 0.0) {
      std::snprintf(msg, sizeof msg, "no point cloud yet on %s", dds::ros_topic(cloud_reader_->options().topic).c_str());
    } else if (stale) {
      stale_text(q, msg, sizeof msg);
    } else if (c.refused > 0 && c.published == 0) {
      std::snprintf(msg, sizeof msg, "every point cloud refused");
    } else {
      std::snprintf(msg, sizeof msg, "receiving point clouds");
    }
    const bool bad = stale || (c.refused > 0 && c.published == 0);
    m.begin(bad ? L::error : L::ok, "trailnavd: lidar", msg, cloud_reader_->options().layout.name);
    m.value("stale", stale ? std::string_view("true") : std::string_view("false"));
    m.value("input", std::string_view("pointcloud2"));
    m.value("clouds", c.messages);
    m.value("revolutions", c.published);
    m.value("refused", c.refused);
    m.value("last_error", c.last_error);
    m.value("points", c.points);
    m.value("second_points", c.image.second);
    m.value("points_not_placed", c.image.collisions + c.image.bad_ring);
    m.value("points_without_return", c.image.invalid);
  }
  if (gps_) {
    const gps::GpsDriverStatus s = gps_->status();
    const bool ok = s.health == gps::GpsHealth::fix;
    m.begin(ok ? L::ok : (s.health == gps::GpsHealth::no_fix ? L::warn : L::error), "trailnavd: gps",
            gps::gps_health_name(s.health), config_.gps->link.device);
    m.value("stale", s.health == gps::GpsHealth::no_data || s.health == gps::GpsHealth::no_link ? std::string_view("true")
                                                                                              : std::string_view("false"));
    m.value("lines", s.gps.lines);
    m.value("fixes", s.published);
    m.value("rejected", s.gps.rejected_total());
    m.value("late_sentences", s.gps.late);
  }
  if (imu_) {
    const imu::ImuDriverStatus s = imu_->status();
    m.begin(s.health == imu::ImuHealth::ok ? L::ok : L::error, "trailnavd: imu", imu::imu_health_name(s.health),
            config_.imu->link.device);
    m.value("stale", s.health == imu::ImuHealth::ok ? std::string_view("false") : std::string_view("true"));
    m.value("samples", s.stream.samples);
    m.value("queue_drops", s.queue_drops);
    m.value("bytes", s.stream.xbus.bytes);
    m.value("bad_checksum", s.stream.xbus.bad_checksum);
    m.value("skipped_bytes", s.stream.xbus.skipped_bytes);
    m.value("link_closes", s.link.closes);
    m.value("link_silences", s.link.silences);
    m.value("link_read_errors", s.link.read_errors);
    m.value("last_link_error", std::string_view(s.last_link_error.data()));
    if (s.device_clock.valid) {
      // Readings are stamped on the device's clock related to the host's;
      // the spread is how late their bytes arrived.
      m.value("clock_offset_s", static_cast<double>(s.device_clock.offset_ns) * 1e-9, 6);
      m.value("clock_spread_ms", static_cast<double>(s.device_clock.spread_ns) * 1e-6, 3);
      m.value("clock_max_spread_ms", static_cast<double>(s.device_clock.max_spread_ns) * 1e-6, 3);
      m.value("clock_steps", s.device_clock.steps);
    }
  }
  if (can_) {
    const can::CanDriverStatus s = can_->status();
    m.begin(s.health == can::CanHealth::ok ? L::ok : L::error, "trailnavd: can", can::can_health_name(s.health),
            can::can_transport_name(config_.can->driver.transport));
    m.value("stale", s.health == can::CanHealth::ok ? std::string_view("false") : std::string_view("true"));
    m.value("frames", s.frames);
    m.value("malformed", s.malformed);
    m.value("bus_off", s.bus_off);
    m.value("restarted", s.restarted);
    m.value("error_frames", s.error_frames);
    // Readings the odometry did not integrate: after a gap, or stamped before
    // the one before (the host clock stepped back).
    m.value("odometry_gaps", s.odometry_counters.gaps);
    m.value("time_back", s.odometry_counters.time_back);
    m.value("distance_m", s.odometry.distance, 2);
  }
  if (gpio_) {
    const gpio::GpioDriverStatus s = gpio_->status();
    const bool released = s.estop == gpio::EstopState::released;
    m.begin(s.health != gpio::GpioHealth::ok ? L::error : (released ? L::ok : L::warn), "trailnavd: gpio",
            released ? "e-stop released" : "e-stop engaged or unknown",
            gpio::gpio_transport_name(config_.gpio->transport));
    m.value("estop", gpio::estop_state_name(s.estop));
    m.value("engagements", s.estop_counters.engagements);
  }
  if (camera_) {
    const drivers::camera::CameraStatus s = camera_->status();
    const bool tunnel = config_.camera->input == drivers::camera::CameraInput::tunnel;
    m.begin(s.health == drivers::camera::CameraHealth::streaming ? L::ok : L::error, "trailnavd: camera",
            s.health == drivers::camera::CameraHealth::streaming ? "streaming"
            : s.last_error[0] != '\0'                            ? s.last_error.data()
                                                                 : drivers::camera::camera_health_name(s.health),
            tunnel ? "tunnel" : config_.camera->device.c_str());
    m.value("health", drivers::camera::camera_health_name(s.health));
    m.value("frames", s.counters.frames);
    m.value("published", s.counters.published);
    m.value("dropped", s.counters.dropped);
    m.value("damaged", s.counters.damaged);
    m.value("corrupt", s.counters.corrupt);
    m.value("opens", s.counters.opens);
    m.value("lost", s.counters.lost);
    if (tunnel) {
      m.value("tunnel_incomplete", s.counters.tunnel.incomplete);
      m.value("tunnel_malformed", s.counters.tunnel.malformed);
    }
  }
  if (station_task_) {
    const perception::registration::StationCounters c = station_task_->counters();
    const char* text = c.scans == 0 ? "no scan yet" : c.fixes == 0 ? "filling the local model" : "localising";
    const bool bad = c.arena_failures > 0 || (c.fixes > 0 && c.lost == c.fixes);
    m.begin(bad ? L::error : (c.fixes == 0 || c.lost > 0 ? L::warn : L::ok), "trailnavd: station", text,
            config_.station->file);
    m.value("scans", c.scans);
    m.value("fixes", c.fixes);
    m.value("lost", c.lost);
    m.value("visits", c.visits);
    m.value("without_odometry", c.without_odometry);
    m.value("arena_failures", c.arena_failures);
    m.value("dropped_points", c.dropped_points);
    m.value("arena_high_water_kb", static_cast<std::uint64_t>(c.arena_high_water / 1024));
    m.value("arena_kb", static_cast<std::uint64_t>(c.arena_capacity / 1024));
    if (scan_reader_) {
      const dds::LaserScanStats l = scan_reader_->stats();
      m.value("laser_scans", l.messages);
      m.value("laser_refused", l.refused);
      m.value("laser_last_error", l.last_error);
      m.value("laser_returns", l.returns);
    }
  }
  if (place_) {
    const perception::place::PlaceCounters c = place_->counters();
    m.begin(c.steps == 0 ? L::warn : L::ok, "trailnavd: place", c.steps == 0 ? "no camera frame yet" : "localising",
            config_.place->database);
    m.value("database_images", static_cast<std::uint64_t>(place_online_->size()));
    m.value("frames", c.frames);
    m.value("steps", c.steps);
    if (c.last_index >= 0) m.value("last_index", static_cast<std::uint64_t>(c.last_index));
    m.value("last_probability", c.last_probability, 4);
    m.value("in_sequence", c.in_sequence);
    m.value("lag_frames", static_cast<std::uint64_t>(config_.place->lag));
  }
  if (pose_) {
    const pose::PoseTaskStatus s = pose_->status();
    // A pose whose motion went unmeasured (wheel speeds lost, or the IMU lost
    // once heard) is not mapped with; health says which.
    const bool degraded = !s.local.translation_valid || !s.local.rotation_valid;
    m.begin(s.local.source == pose::PoseSource::none || degraded ? L::warn : L::ok, "trailnavd: pose",
            !s.local.translation_valid ? "wheel speeds lost: the position is not measured, not mapping"
            : !s.local.rotation_valid  ? "IMU lost: the wheels alone turn the pose, not mapping"
                                       : pose::pose_source_name(s.local.source),
            "");
    m.value("source", pose::pose_source_name(s.local.source));
    m.value("translation_valid", s.local.translation_valid ? std::string_view("true") : std::string_view("false"));
    m.value("rotation_valid", s.local.rotation_valid ? std::string_view("true") : std::string_view("false"));
    m.value("utm_valid", s.utm.position_valid ? std::string_view("true") : std::string_view("false"));
    m.value("heading_valid", s.utm.heading_valid ? std::string_view("true") : std::string_view("false"));
    m.value("sigma_m", s.utm.position_valid ? s.utm.sigma_position() : 0.0, 2);
    m.value("distance_m", s.local.distance, 2);
    m.value("queue_drops", s.pose_queue_drops);
    // How the odometry stepped: with the IMU's yaw rate, with the wheels'
    // alone (the IMU silent), and the steps it could not integrate.
    m.value("imu_steps", s.odometry_counters.imu_steps);
    m.value("wheel_steps", s.odometry_counters.wheel_steps);
    m.value("odometry_gaps", s.odometry_counters.gaps);
    m.value("wheels_held", s.wheels_held);
    m.value("wheels_released_early", s.wheels_released_early);
    // What became of the GPS fixes: used, rejected as outliers, and how often
    // agreeing outliers meant the GPS itself had jumped (re-anchored).
    m.value("gps_fixes_used", s.utm_counters.used);
    if (mapping_) m.value("map_corrections", s.map_corrections);
    m.value("gps_outliers", s.utm_counters.outliers);
    m.value("gps_jumps", s.utm_counters.jumps);
    if (config_.place && config_.place->pose.use != pose::PlaceUse::off) {
      // The place task's answers: offered to the alignment (GPS poor and
      // the answer strong enough), used, gated out.
      m.value("place_answers", s.place_answers);
      m.value("place_offered", s.utm_counters.place_offered);
      m.value("place_used", s.utm_counters.place_used);
      m.value("place_outliers", s.utm_counters.place_outliers);
      m.value("place_gps_good", s.place_gps_good);
      m.value("place_weak", s.place_weak);
    }
    // IMU and wheels are stamped with their host receive times (offset 0 by
    // construction); GPS fixes at the receiver's UTC when it agrees with the host.
    m.value("gps_fixes_at_utc", s.gps_fixes_at_utc);
    m.value("gps_fixes_at_receive", s.gps_fixes_at_receive);
    if (s.gps_has_utc) m.value("gps_receive_minus_utc_s", static_cast<double>(s.gps_receive_minus_utc_ns) * 1e-9, 3);
  }
  if (obstacles_) {
    const perception::ObstacleTaskCounters c = obstacles_->status();
    m.begin(c.odometry_lost ? L::error : c.pose_behind || c.skipped > 0 ? L::warn : L::ok, "trailnavd: obstacles",
            c.odometry_lost ? "odometry lost (wheel speeds or IMU silent): not mapping, map stale"
            : c.pose_behind ? "the pose thread is behind the lidar: not mapping until it catches up"
            : c.skipped > 0 ? "revolutions skipped (too slow)"
                            : "ok",
            "");
    m.value("revolutions", c.revolutions);
    m.value("skipped", c.skipped);
    m.value("no_odometry", c.no_odometry);
    m.value("map_resets", c.map_resets);
    m.value("pose_waits", c.pose_waits);
    m.value("pose_late", c.pose_late);
    m.value("pose_wait_max_ms", static_cast<double>(c.pose_wait_max_ns) * 1e-6, 1);
    m.value("poses", c.poses);
    m.value("terrain_maps", c.terrain_maps);
    const DurationSummary delay = obstacles_->map_delay();
    m.value("map_delay_p50_ms", nanos_to_seconds(delay.p50) * 1e3, 3);
    m.value("map_delay_p99_ms", nanos_to_seconds(delay.p99) * 1e3, 3);
    m.value("map_delay_max_ms", nanos_to_seconds(delay.max) * 1e3, 3);
    m.value("streamed", c.streamed);
    m.value("early_blocks", c.early_blocks);
    m.value("abandoned", c.abandoned);
  }
  if (terrain_) {
    const perception::TerrainTaskCounters c = terrain_->status();
    const bool idle = c.published == 0;
    m.begin(idle ? L::warn : L::ok, "trailnavd: terrain", idle ? "no class map yet (the robot must move d metres)" : "ok", "");
    m.value("revolutions", c.revolutions);
    m.value("skipped", c.skipped);
    if (c.intact_until_ns >= 0) m.value("intact_until_s", static_cast<double>(c.intact_until_ns) * 1e-9, 6);
    m.value("no_odometry", c.no_odometry);
    m.value("pose_waits", c.pose_waits);
    m.value("pose_late", c.pose_late);
    m.value("pose_wait_max_ms", static_cast<double>(c.pose_wait_max_ns) * 1e-6, 1);
    m.value("steps", c.mapper.steps);
    m.value("features", c.mapper.features);
    m.value("known_cells", c.mapper.known_cells);
    m.value("classified_cells", c.mapper.classified_cells);
    m.value("poses", c.poses);
  }
  if (trav_online_) {
    const perception::trav::OnlineCounters c = trav_online_->status();
    const char* text = c.models == 0 ? "no terrain model yet: every cell unknown until a demonstrated local map is learnt"
                                     : "ok";
    m.begin(c.models == 0 ? L::warn : L::ok, "trailnavd: traversability", text, config_.traversability->model);
    m.value("method", perception::trav::method_name(trav_layer_->method()));
    m.value("models", static_cast<std::uint64_t>(c.models));
    m.value("words", c.layer.words);
    m.value("restarted", c.layer.restarted);
    m.value("too_far", c.layer.too_far);
    m.value("model_updates", c.model_updates);
    if (trav_trainer_) {
      const perception::trav::TrainerCounters t = trav_trainer_->status();
      m.value("demonstration_local_maps", c.handed);
      m.value("footprint_cells", c.recorder.footprint_cells);
      m.value("positive_words", c.recorder.positive_words);
      m.value("dropped_words", c.recorder.dropped);
      m.value("trained", t.trained);
      m.value("without_positive", t.without_positive);
      m.value("lost", t.lost);
      m.value("created", t.created);
      m.value("forced", t.forced);
      m.value("saves", t.saves);
      m.value("save_failures", t.save_failures);
      if (t.save_errno != 0) m.value("save_error", std::string_view(std::strerror(t.save_errno)));
    }
  }
  if (navigation_) {
    const nav::NavigationTaskStatus s = navigation_->status();
    const bool bad = s.state == nav::NavState::failed;
    const char* text = bad && s.message[0] != '\0' ? s.message : (s.refusal[0] != '\0' ? s.refusal.data() : nav::nav_state_name(s.state));
    m.begin(bad ? L::error : (s.state == nav::NavState::planning || s.refusal[0] != '\0' ? L::warn : L::ok),
            "trailnavd: navigation", text, config_.navigation->osm);
    m.value("state", nav::nav_state_name(s.state));
    m.value("goals", s.navigator.goals);
    m.value("goals_refused", s.navigator.goals_refused);
    m.value("cancels", s.navigator.cancels);
    m.value("remaining_m", s.remaining, 1);
    if (command_reader_) {
      const dds::CommandReaderStats c = command_reader_->stats();
      m.value("goal_samples", c.goals + c.geo_goals);
      m.value("cancel_samples", c.cancels);
      m.value("orders_dropped", c.queue_full);
    }
    m.value("subgoals", static_cast<std::uint64_t>(s.subgoals));
    m.value("active", static_cast<std::uint64_t>(s.active));
    m.value("route_m", s.route_length, 1);
    m.value("progress_m", s.progress, 1);
    m.value("cross_track_m", s.cross_track, 2);
    m.value("plans", s.navigator.plans);
    m.value("replans", s.navigator.replans);
    m.value("plan_failures", s.navigator.plan_failures);
    m.value("plan_ms", s.navigator.last_plan_ms, 2);
    m.value("aligner_updates", s.navigator.updates);
    m.value("aligner_catch_up_updates", s.navigator.catch_up_updates);
    m.value("terrain_maps", s.terrain_maps);
  }
  if (mapping_) {
    const slam::MappingTaskStatus s = mapping_->status();
    const bool waiting = s.state == slam::MappingState::waiting_alignment;
    const bool full = s.state == slam::MappingState::full;
    m.begin(full || waiting || s.error[0] != '\0' ? L::warn : L::ok, "trailnavd: mapping",
            full                 ? "full: the map no longer grows (max_keyframes); map -> odom held at its last keyframe"
            : s.error[0] != '\0' ? s.error.data()
                                 : slam::mapping_state_name(s.state),
            "");
    m.value("state", slam::mapping_state_name(s.state));
    m.value("nodes", static_cast<std::uint64_t>(s.vertices));
    m.value("edges", static_cast<std::uint64_t>(s.edges));
    m.value("capacity_nodes", static_cast<std::uint64_t>(s.capacity_vertices));
    m.value("keyframes", s.keyframes.keyframes);
    m.value("gps_edges", s.keyframes.gps_edges);
    m.value("loop_closures", s.keyframes.loop_closures);
    m.value("refused_full", s.keyframes.refused_full);
    m.value("gps_unattached", s.keyframes.gps_unattached);
    m.value("optimisations", s.optimisations);
    m.value("failures", s.failures);
    m.value("levels", static_cast<std::uint64_t>(s.levels));
    m.value("chi2", s.chi2, 3);
    m.value("solve_ms", s.solve_ms, 1);
    m.value("solve_max_ms", s.solve_max_ms, 1);
    m.value("correction_m", s.correction_m, 2);
    m.value("correction_rad", s.correction_rad, 4);
    // The solver's arenas: reserved at start-up and their high-water marks.
    m.value("memory_high_water_bytes", static_cast<std::uint64_t>(s.hierarchy_high_water + s.part_high_water));
    m.value("memory_reserved_bytes", static_cast<std::uint64_t>(s.hierarchy_capacity + s.part_capacity));
    m.value("poses", s.poses);
    m.value("poses_unmeasured", s.poses_unmeasured);
    m.value("poses_before_start", s.poses_before_start);
    m.value("fixes", s.fixes);
    if (pose_) m.value("fix_queue_drops", pose_->status().fix_queue_drops);
    if (config_.mapping->loops) {
      // Loop closures: the verifications and why they were refused.
      m.value("loop_candidates", s.loops.candidates);
      m.value("loop_accepted", s.loops.accepted);
      m.value("loop_rejected_overlap", s.loops.low_overlap);
      m.value("loop_rejected_rms", s.loops.high_rms);
      m.value("loop_rejected_jump", s.loops.jumped);
      m.value("loop_not_converged", s.loops.not_converged);
      m.value("loop_no_cloud", s.loop_no_cloud);
      m.value("loop_arena_failures", s.loop_arena_failures);
      m.value("loop_ms_max", s.loop_ms_max, 1);
      m.value("loop_memory_high_water_bytes", static_cast<std::uint64_t>(s.loop_arena_high_water));
      m.value("loop_memory_reserved_bytes", static_cast<std::uint64_t>(s.loop_arena_capacity));
    }
  }
  for (std::size_t i = 0; i < scheduler_->task_count(); ++i) {
    const TaskStats st = scheduler_->stats(i);
    char name[64];
    std::snprintf(name, sizeof name, "trailnavd: task %s", scheduler_->spec(i).name.c_str());
    m.begin(st.overruns > 0 ? L::warn : L::ok, name, st.overruns > 0 ? "overruns" : "on time", "");
    m.value("runs", st.runs);
    m.value("overruns", st.overruns);
    m.value("stalls", st.stalls);
    m.value("slips", st.slips);
    m.value("rested_periods", st.rested_periods);
    m.value("exec_p99_ms", nanos_to_seconds(st.execution.p99) * 1e3, 3);
    m.value("exec_max_ms", nanos_to_seconds(st.execution.max) * 1e3, 3);
    m.value("cpu_per_period_p99_ms", nanos_to_seconds(st.cpu_per_period.p99) * 1e3, 3);
    m.value("cpu_per_period_max_ms", nanos_to_seconds(st.cpu_per_period.max) * 1e3, 3);
    m.value("cpu_max_ms", nanos_to_seconds(st.cpu_max) * 1e3, 3);
  }
  m.begin(alloc_guard::total_allocations() > 0 ? L::error : L::ok, "trailnavd: memory",
          armed_.load(std::memory_order_acquire) ? "real-time threads watched" : "allocation guard not armed", "");
  m.value("rt_allocations", alloc_guard::total_allocations());
  (void)now;
}

}  // namespace trailnav::daemon
