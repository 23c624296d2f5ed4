#include "publisher.hpp"

#include <algorithm>
#include <cstdio>
#include <ctime>

#include "trailnav/runtime/host_clock.hpp"
#include "trailnav/runtime/log.hpp"

namespace trailnav::dds {

DdsPublisher::DdsPublisher(Clock& clock, const PublisherOptions& options, PublisherInputs inputs)
    : clock_(clock), options_(options), inputs_(std::move(inputs)), pose_msg_(options.odom_frame),
      subgoal_msg_(options.odom_frame), utm_msg_(options.fix_frame) {}

DdsPublisher::Created DdsPublisher::create(const Domain& domain, Clock& clock, const PublisherOptions& options,
                                           PublisherInputs inputs) {
  Created result;
  std::unique_ptr<DdsPublisher> p(new DdsPublisher(clock, options, std::move(inputs)));
  auto make = [&](std::unique_ptr<Writer>& out, const dds_topic_descriptor_t& type, const std::string& name,
                  EndpointQos qos) {
    if (!result.error.empty()) return;
    auto w = Writer::create(domain, type, name, qos);
    if (!w.writer) {
      result.error = w.error;
      return;
    }
    out = std::move(w.writer);
  };
  if (p->inputs_.obstacles != nullptr) {
    // Every slot of the mailbox was built with the map's size; the reader's
    // own slot can be looked at before the writer starts.
    const perception::ObstacleSnapshot& shape = p->inputs_.obstacles->last_read();
    p->grid_.emplace(shape.size_x, shape.size_y, options.odom_frame);
    // Transient local: offered durability at least what is requested, so both
    // volatile readers and the transient-local ones map consumers use match.
    // Keep last 3: a reader that lost fragments of a map (a small socket
    // buffer) has three map periods, not one, to get them again before the
    // map leaves the writer's history (docs/dds.md, "Use with ROS 2": with
    // 1, a Fast DDS reader got 97 % of the maps in 96 kB bursts; with 2,
    // 99.3-100 %; with 3, 100 % also with two CPU hogs).
    make(p->map_writer_, nav_msgs_msg_dds__OccupancyGrid__desc, options.topics.obstacle_map, {true, 3, Durability::transient_local});
    if (options.coarse_factor > 0) {
      const double side = options.coarse_window > 0.0 ? options.coarse_window : shape.size_x * options.map_resolution;
      const int blocks = std::max(1, static_cast<int>(std::lround(side / (options.map_resolution * options.coarse_factor))));
      p->coarse_.emplace(blocks, blocks, options.odom_frame);
      make(p->coarse_writer_, nav_msgs_msg_dds__OccupancyGrid__desc, options.topics.coarse_map, {true, 2, Durability::transient_local});
    }
  }
  if (p->inputs_.points != nullptr) {
    // Reliable like the other topics (RViz's default); keep last 1: a slow
    // viewer gets the newest cloud, never a queue of old ones.
    p->points_msg_.emplace(p->inputs_.points->last_read().points.size(), options.odom_frame);
    make(p->points_writer_, sensor_msgs_msg_dds__PointCloud2__desc, options.topics.points, {true, 1});
  }
  if (p->inputs_.terrain != nullptr) {
    const perception::TerrainClassMap& shape = p->inputs_.terrain->last_read();
    const auto w = shape.grid().size_x(), h = shape.grid().size_y();
    p->terrain_msg_.emplace(w, h, options.odom_frame);
    p->cost_msg_.emplace(w, h, options.odom_frame);
    make(p->terrain_writer_, trailnav_msgs_msg_dds__TerrainClassMap__desc, options.topics.terrain_map, {true, 1, Durability::transient_local});
    make(p->cost_writer_, nav_msgs_msg_dds__OccupancyGrid__desc, options.topics.terrain_cost, {true, 1, Durability::transient_local});
    if (p->inputs_.traversability) {
      p->trav_msg_.emplace(w, h, options.odom_frame);
      make(p->trav_writer_, nav_msgs_msg_dds__OccupancyGrid__desc, options.topics.traversability,
           {true, 1, Durability::transient_local});
    }
  }
  if (p->inputs_.poses != nullptr) {
    make(p->pose_writer_, geometry_msgs_msg_dds__PoseStamped__desc, options.topics.pose, {true, 1});
    make(p->utm_writer_, geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc, options.topics.utm_pose, {true, 1});
    make(p->fix_writer_, sensor_msgs_msg_dds__NavSatFix__desc, options.topics.fix, {true, 1});
  }
  if (p->inputs_.navigation != nullptr) {
    p->path_msg_.emplace(p->inputs_.navigation->last_read().path.size(), options.odom_frame);
    make(p->subgoal_writer_, geometry_msgs_msg_dds__PoseStamped__desc, options.topics.subgoal, {true, 1, Durability::transient_local});
    make(p->path_writer_, nav_msgs_msg_dds__Path__desc, options.topics.subgoal_path, {true, 1, Durability::transient_local});
    make(p->status_writer_, trailnav_msgs_msg_dds__NavigationStatus__desc, options.topics.navigation_status,
         {true, 1, Durability::transient_local});
  }
  if (p->inputs_.mapping != nullptr) {
    p->keyframe_path_msg_.emplace(p->inputs_.mapping->last_read().path.size(), "map");
    make(p->keyframe_path_writer_, nav_msgs_msg_dds__Path__desc, options.topics.keyframe_path,
         {true, 1, Durability::transient_local});
  }
  if (p->inputs_.place != nullptr) {
    // Reliable, keep last 1: the newest answer, as the pose topics.
    p->place_msg_.emplace(options.place_frame);
    make(p->place_match_writer_, trailnav_msgs_msg_dds__PlaceMatch__desc, options.topics.place_match, {true, 1});
    make(p->place_pose_writer_, geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc, options.topics.place_pose, {true, 1});
  }
  if (p->inputs_.station != nullptr) {
    // Reliable, keep last 1: the newest fix, as the pose topics.
    p->station_msg_.emplace(options.station_name, options.station_frame, options.station_bodies);
    make(p->station_writer_, trailnav_msgs_msg_dds__StationFix__desc, options.topics.station_fix, {true, 1});
    p->station_pose_writers_.resize(options.station_bodies.size());
    for (std::size_t k = 0; k < options.station_bodies.size(); ++k) {
      make(p->station_pose_writers_[k], geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc,
           options.topics.station_pose_prefix + options.station_bodies[k], {true, 1});
    }
  }
  make(p->health_writer_, diagnostic_msgs_msg_dds__DiagnosticArray__desc, options.topics.health, {true, 4});
  if (options.publish_tf) {
    // As ROS 2's tf2 does: rt/tf reliable, volatile, keep last 100;
    // rt/tf_static reliable, transient local, keep last 1 (one message holds
    // every static transform, so a late joiner gets them all).
    make(p->tf_writer_, tf2_msgs_msg_dds__TFMessage__desc, options.topics.tf, {true, 100});
    make(p->tf_static_writer_, tf2_msgs_msg_dds__TFMessage__desc, options.topics.tf_static, {true, 1, Durability::transient_local});
    p->tf_static_msg_.emplace(std::max<std::size_t>(options.static_frames.size(), 1));
    if (p->inputs_.poses != nullptr) {
      p->odometry_msg_.emplace(options.odom_frame, options.frames.base_link);
      make(p->odometry_writer_, nav_msgs_msg_dds__Odometry__desc, options.topics.odometry, {true, 10});
    }
  }
  if (!result.error.empty()) return result;
  result.publisher = std::move(p);
  return result;
}

DdsPublisher::~DdsPublisher() { stop(); }

void DdsPublisher::start() {
  if (running_.exchange(true)) return;
  thread_ = std::thread([this] { loop(); });
}

void DdsPublisher::stop() {
  if (!running_.exchange(false)) return;
  wakeup_.notify();
  if (thread_.joinable()) thread_.join();
}

PublisherStats DdsPublisher::stats() const noexcept {
  PublisherStats s;
  s.maps = maps_.load(std::memory_order_relaxed);
  s.stale_maps = stale_maps_.load(std::memory_order_relaxed);
  s.terrain_maps = terrain_maps_.load(std::memory_order_relaxed);
  s.traversability_maps = trav_maps_.load(std::memory_order_relaxed);
  s.poses = poses_.load(std::memory_order_relaxed);
  s.fixes = fixes_.load(std::memory_order_relaxed);
  s.health = health_.load(std::memory_order_relaxed);
  s.write_failures = failures_.load(std::memory_order_relaxed);
  s.subgoals = subgoals_.load(std::memory_order_relaxed);
  s.paths = paths_.load(std::memory_order_relaxed);
  s.transforms = transforms_.load(std::memory_order_relaxed);
  s.odometry = odometry_.load(std::memory_order_relaxed);
  s.statuses = statuses_.load(std::memory_order_relaxed);
  s.point_clouds = point_clouds_.load(std::memory_order_relaxed);
  s.keyframe_paths = keyframe_paths_.load(std::memory_order_relaxed);
  s.place_matches = place_matches_.load(std::memory_order_relaxed);
  s.station_fixes = station_fixes_.load(std::memory_order_relaxed);
  s.lidar_stale = lidar_stale_.load(std::memory_order_relaxed);
  return s;
}

void DdsPublisher::publish_health(Nanos now) noexcept {
  health_msg_.clear(host_now_ns());
  if (inputs_.health) inputs_.health(health_msg_, now);
  const PublisherStats s = stats();
  const bool stale = s.lidar_stale;
  health_msg_.begin(stale ? DiagnosticsMessage::warn : DiagnosticsMessage::ok, "trailnavd: publisher",
                    stale ? "obstacle map stale: free cells sent as unknown" : "publishing", "trailnavd");
  health_msg_.value("obstacle_maps", s.maps);
  health_msg_.value("stale_maps", s.stale_maps);
  if (terrain_writer_) health_msg_.value("terrain_maps", s.terrain_maps);
  if (trav_writer_) health_msg_.value("traversability_maps", s.traversability_maps);
  health_msg_.value("poses", s.poses);
  health_msg_.value("fixes", s.fixes);
  if (subgoal_writer_) {
    health_msg_.value("subgoals", s.subgoals);
    health_msg_.value("paths", s.paths);
    health_msg_.value("navigation_statuses", s.statuses);
  }
  if (points_writer_) health_msg_.value("point_clouds", s.point_clouds);
  if (keyframe_path_writer_) health_msg_.value("keyframe_paths", s.keyframe_paths);
  if (place_match_writer_) health_msg_.value("place_matches", s.place_matches);
  if (station_writer_) health_msg_.value("station_fixes", s.station_fixes);
  if (tf_writer_) {
    health_msg_.value("tf_messages", s.transforms);
    health_msg_.value("odometry", s.odometry);
  }
  health_msg_.value("write_failures", s.write_failures);
  if (health_msg_.dropped() > 0 && !health_overflow_said_) {
    // Said once: a config with more parts than the sample holds loses their last values.
    health_overflow_said_ = true;
    TN_LOG_WARN("diagnostics: %zu statuses and values did not fit the sample (%zu statuses of %zu values) and were "
                "left out", health_msg_.dropped(), DiagnosticsMessage::kStatuses, DiagnosticsMessage::kValues);
  }
  if (health_writer_->write(&health_msg_.sample())) {
    health_.fetch_add(1, std::memory_order_relaxed);
  } else {
    failures_.fetch_add(1, std::memory_order_relaxed);
  }
}

void DdsPublisher::count(bool written, std::atomic<std::uint64_t>& counter) noexcept {
  (written ? counter : failures_).fetch_add(1, std::memory_order_relaxed);
}

void DdsPublisher::publish_static_frames() noexcept {
  if (!tf_static_writer_) return;
  // Stamped once, at start-up: static transforms hold for every time.
  const std::int64_t now = host_now_ns();
  tf_static_msg_->clear();
  for (const StaticFrame& f : options_.static_frames) {
    tf_static_msg_->add(now, options_.frames.base_link, f.frame, f.transform);
  }
  if (tf_static_msg_->size() > 0) count(tf_static_writer_->write(&tf_static_msg_->sample()), transforms_);
}

void DdsPublisher::publish_pose(const pose::PoseSnapshot& p) noexcept {
  if (p.local.source != pose::PoseSource::none) {
    pose_msg_.fill(p.local);
    count(pose_writer_->write(&pose_msg_.sample()), poses_);
    if (odometry_writer_) {
      odometry_msg_->fill(p.local);
      count(odometry_writer_->write(&odometry_msg_->sample()), odometry_);
    }
    if (tf_writer_) {
      // odom -> base_link at the pose's time; map (UTM) -> odom of the same
      // instant once the GPS alignment has a position and a heading.
      tf_msg_.clear();
      tf_msg_.add(p.local.time_ns, options_.odom_frame, options_.frames.base_link,
                  {p.local.x, p.local.y, p.local.z, p.local.roll, p.local.pitch, p.local.yaw});
      if (odom_parent_.valid) {
        // A map without GPS (the mapping thread's): odom's parent.
        tf_msg_.add(p.local.time_ns, odom_parent_.frame.data(), options_.odom_frame, odom_parent_.transform);
      } else if (p.utm.position_valid && p.utm.heading_valid) {
        map_frame_name(options_.frames.map, p.utm.zone, p.utm.north, map_frame_);
        tf_msg_.add(p.local.time_ns, map_frame_.data(), options_.odom_frame, utm_to_odom(p.local, p.utm));
      }
      count(tf_writer_->write(&tf_msg_.sample()), transforms_);
    }
  }
  if (utm_msg_.fill(p.utm)) {
    const bool a = utm_writer_->write(&utm_msg_.utm());
    const bool b = fix_writer_->write(&utm_msg_.fix());
    count(a && b, fixes_);
  }
}

void DdsPublisher::publish_mapping(const slam::MappingSnapshot& m) noexcept {
  // Georeferenced: the UTM zone's frame, as the GPS alignment names it;
  // else the odometry frame at start, "map" (or the configured name when it
  // is not "utm").
  const std::string_view configured = options_.frames.map;
  map_frame_name(!m.georeferenced && configured == "utm" ? std::string_view("map") : configured, m.zone, m.north,
                 odom_parent_.frame);
  // A map tied to GPS corrects the alignment inside the pose thread (every
  // UTM pose, and so utm -> odom, is already the map's); a map without GPS
  // is odom's parent here: the odometry frame at start until loop closures
  // move it.
  if (!m.georeferenced) {
    odom_parent_.valid = true;
    odom_parent_.transform = RigidTransform{m.x, m.y, 0.0, 0.0, 0.0, m.yaw};
  }
  keyframe_path_msg_->set_frame(odom_parent_.frame.data());
  keyframe_path_msg_->clear(m.time_ns);
  for (std::size_t i = 0; i < m.path_count; ++i) {
    const slam::MapPathPose& p = m.path[i];
    keyframe_path_msg_->add(p.time_ns, p.x, p.y, p.yaw);
  }
  count(keyframe_path_writer_->write(&keyframe_path_msg_->sample()), keyframe_paths_);
}

void DdsPublisher::publish_coarse(const perception::ObstacleSnapshot& s, bool stale) noexcept {
  if (!coarse_writer_) return;
  coarse_->fill_coarse(s, options_.coarse_factor, stale, options_.occupied_percent);
  if (!coarse_writer_->write(&coarse_->sample(), stale ? 0 : s.received_ns)) failures_.fetch_add(1, std::memory_order_relaxed);
}

void DdsPublisher::publish_map_instant(const perception::ObstacleSnapshot& s) noexcept {
  tf_msg_.clear();
  tf_msg_.add(s.time_ns, options_.odom_frame, options_.frames.base_link,
              {s.robot_x, s.robot_y, s.robot_z, s.robot_roll, s.robot_pitch, s.robot_yaw});
  count(tf_writer_->write(&tf_msg_.sample()), transforms_);
}

void DdsPublisher::publish_status(const nav::NavigationStatusReport& r) noexcept {
  map_frame_name(options_.frames.map, r.zone, r.north, map_frame_);
  status_msg_.fill(r, map_frame_.data());
  count(status_writer_->write(&status_msg_.sample()), statuses_);
}

void DdsPublisher::publish_navigation(const nav::NavigationSnapshot& n) noexcept {
  // The status with every snapshot (each is a change: state, goal, subgoal or path).
  publish_status(n.report);
  // Stamped with the pose's time, like the pose topic.
  if (n.has_active && n.active_revision != last_active_revision_) {
    last_active_revision_ = n.active_revision;
    subgoal_msg_.fill(n.time_ns, n.active_pose.x, n.active_pose.y, 0.0, 0.0, 0.0, n.active_pose.yaw);
    if (subgoal_writer_->write(&subgoal_msg_.sample())) {
      subgoals_.fetch_add(1, std::memory_order_relaxed);
    } else {
      failures_.fetch_add(1, std::memory_order_relaxed);
    }
    // Its own odom -> base_link at its stamp, as each map has: the pose-rate
    // transforms are a sample of the poses and need not hold the one the
    // subgoal was placed from (after the pose thread catches up on held
    // readings, several poses pass between two of them).
    if (tf_writer_) {
      tf_msg_.clear();
      tf_msg_.add(n.time_ns, options_.odom_frame, options_.frames.base_link,
                  {n.robot.x, n.robot.y, n.robot.z, n.robot.roll, n.robot.pitch, n.robot.yaw});
      count(tf_writer_->write(&tf_msg_.sample()), transforms_);
    }
  }
  if (n.path_revision != last_path_revision_) {
    last_path_revision_ = n.path_revision;
    path_msg_->clear(n.time_ns);
    for (std::size_t i = 0; i < n.path_count; ++i) path_msg_->add(n.time_ns, n.path[i].x, n.path[i].y, n.path[i].yaw);
    if (path_writer_->write(&path_msg_->sample())) {
      paths_.fetch_add(1, std::memory_order_relaxed);
    } else {
      failures_.fetch_add(1, std::memory_order_relaxed);
    }
  }
}

void DdsPublisher::loop() noexcept {
  publish_static_frames();
  const Nanos health_period = seconds_to_nanos(options_.health_period);
  const Nanos pose_period = options_.pose_rate_hz > 0.0 ? seconds_to_nanos(1.0 / options_.pose_rate_hz) : 0;
  const Nanos stale_after = seconds_to_nanos(options_.stale_after);
  Nanos next_health = clock_.now();
  Nanos next_pose = clock_.now();
  Nanos last_map = 0, last_stale = 0;
  bool any_map = false;
  while (running_.load(std::memory_order_acquire)) {
    Nanos now = clock_.now();
    Nanos wait = next_health - now;
    if (pose_writer_ && pose_period > 0) wait = std::min(wait, next_pose - now);
    if (map_writer_ && any_map) wait = std::min(wait, std::max<Nanos>(last_map + stale_after - now, 0) + kNanosPerMilli);
    if (wait > 0) wakeup_.wait_for(std::min<Nanos>(wait, 100 * kNanosPerMilli));
    if (!running_.load(std::memory_order_acquire)) break;
    now = clock_.now();

    if (map_writer_) {
      if (const perception::ObstacleSnapshot* snap = inputs_.obstacles->try_read()) {
        grid_->fill(*snap, false, options_.occupied_percent);
        if (map_writer_->write(&grid_->sample(), snap->received_ns)) {
          maps_.fetch_add(1, std::memory_order_relaxed);
        } else {
          failures_.fetch_add(1, std::memory_order_relaxed);
        }
        publish_coarse(*snap, false);
        if (tf_writer_ && options_.map_instant_tf) publish_map_instant(*snap);
        any_map = true;
        last_map = now;
        lidar_stale_.store(false, std::memory_order_relaxed);
      } else if (any_map && now - last_map > stale_after && now - last_stale >= kNanosPerSecond) {
        grid_->fill(inputs_.obstacles->last_read(), true, options_.occupied_percent);
        if (map_writer_->write(&grid_->sample())) stale_maps_.fetch_add(1, std::memory_order_relaxed);
        publish_coarse(inputs_.obstacles->last_read(), true);
        last_stale = now;
        lidar_stale_.store(true, std::memory_order_relaxed);
      }
    }
    if (points_writer_) {
      if (const perception::PointsSnapshot* pts = inputs_.points->try_read()) {
        points_msg_->fill(*pts);
        count(points_writer_->write(&points_msg_->sample()), point_clouds_);
      }
    }
    if (terrain_writer_) {
      if (const perception::TerrainClassMap* t = inputs_.terrain->try_read()) {
        terrain_msg_->fill(*t);
        cost_msg_->fill_cost(*t, inputs_.terrain_cost, inputs_.unknown_cost);
        const bool a = terrain_writer_->write(&terrain_msg_->sample());
        const bool b = cost_writer_->write(&cost_msg_->sample());
        if (a && b) {
          terrain_maps_.fetch_add(1, std::memory_order_relaxed);
        } else {
          failures_.fetch_add(1, std::memory_order_relaxed);
        }
        if (trav_writer_) {
          trav_msg_->fill_traversability(*t);
          count(trav_writer_->write(&trav_msg_->sample()), trav_maps_);
        }
      }
    }
    if (subgoal_writer_) {
      // The answer to each order first, then the newest state.
      if (inputs_.navigation_answers != nullptr) {
        while (inputs_.navigation_answers->try_pop(answer_)) publish_status(answer_);
      }
      if (const nav::NavigationSnapshot* n = inputs_.navigation->try_read()) publish_navigation(*n);
    }
    if (place_match_writer_) {
      if (const perception::place::PlaceSnapshot* ps = inputs_.place->try_read()) {
        place_msg_->fill(*ps);
        const bool a = place_match_writer_->write(&place_msg_->match());
        const bool b = place_pose_writer_->write(&place_msg_->pose());
        count(a && b, place_matches_);
      }
    }
    if (station_writer_) {
      if (const perception::registration::StationSnapshot* ss = inputs_.station->try_read()) {
        station_msg_->fill(*ss);
        bool ok = station_writer_->write(&station_msg_->fix());
        for (std::size_t k = 0; k < station_pose_writers_.size(); ++k) {
          ok = station_pose_writers_[k]->write(&station_msg_->pose(k)) && ok;
        }
        count(ok, station_fixes_);
      }
    }
    if (keyframe_path_writer_) {
      if (const slam::MappingSnapshot* m = inputs_.mapping->try_read()) publish_mapping(*m);
    }
    if (pose_writer_ && now >= next_pose) {
      next_pose = std::max(next_pose + pose_period, now);
      if (const pose::PoseSnapshot* p = inputs_.poses->try_read()) publish_pose(*p);
    }
    if (now >= next_health) {
      next_health = std::max(next_health + health_period, now);
      publish_health(now);
    }
  }
}

}  // namespace trailnav::dds
