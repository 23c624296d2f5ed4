#include "velodyne_odometry.hpp"

#include <chrono>
#include <cmath>
#include <limits>
#include <optional>

#include "motion.hpp"
#include "revolution_source.hpp"
#include "pose_eval.hpp"
#include "sim_truth.hpp"
#include "trailnav/perception/pose_track.hpp"

namespace trailnav::eval {

namespace reg = perception::registration;

namespace {

constexpr double kKeep = 0.9;

Eigen::Isometry3d isometry_of(const perception::Pose& p) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = sim::rotation(p.roll, p.pitch, p.yaw);  // the simulator's own convention
  t.translation() = Eigen::Vector3d(p.x, p.y, p.z);
  return t;
}

}  // namespace

VelodyneOdometryReport run_velodyne_odometry(const VelodyneOdometryOptions& options) {
  VelodyneOdometryReport report;
  report.end_error_m = std::numeric_limits<double>::quiet_NaN();
  auto opened = RevolutionSource::open(options.inputs.empty() ? std::vector<std::string>{options.input} : options.inputs,
                                       options.calibration);
  if (!opened.source) {
    report.error = opened.error;
    return report;
  }
  RevolutionSource& source = *opened.source;
  report.lidar = std::string(source.lidar_model());
  // The reference: the simulated truth, moved from the robot to the lidar.
  std::optional<perception::PoseTrack> truth;
  Eigen::Isometry3d mount = Eigen::Isometry3d::Identity();
  if (source.truth()) {
    truth.emplace(source.truth()->trajectory.size() + 1);
    fill_pose_track(*source.truth(), *truth);
    const auto m = source.mount_translation();
    mount.translation() = Eigen::Vector3d(m[0], m[1], m[2]);
  }
  // The wheel prior: the recording's odometry-frame poses at every IMU sample.
  std::optional<perception::PoseTrack> wheels;
  if (options.wheel_prior) {
    if (!source.truth()) {
      report.error = "--wheel-prior needs a simulated recording (a directory with truth/, CAN and IMU streams)";
      return report;
    }
    std::vector<perception::Pose> samples;
    PoseEvalOptions po;
    po.on_odometry = [&](const pose::LocalPose& p) {
      samples.push_back({p.time_ns, p.x, p.y, p.z, p.roll, p.pitch, p.yaw, p.translation_valid});
    };
    const PoseEvalResult pr = evaluate_pose(options.input, po);
    if (!pr.error.empty()) {
      report.error = "--wheel-prior: " + pr.error;
      return report;
    }
    wheels.emplace(samples.size() + 1);
    for (const perception::Pose& p : samples) wheels->push(p);
  }
  reg::OdometryConfig config = options.odometry;
  const velodyne::RangeImageShape shape = source.shape();
  config.max_points = static_cast<std::size_t>(shape.rings) * static_cast<std::size_t>(shape.max_columns);
  reg::LidarOdometry odometry(config);
  std::vector<reg::Point> points;
  std::vector<float> fraction;
  points.reserve(config.max_points);
  fraction.reserve(config.max_points);
  Eigen::Isometry3d start = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d wheel_start = Eigen::Isometry3d::Identity(), wheel_last = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d smoothed = Eigen::Isometry3d::Identity();
  double busy_s = 0.0;
  const auto on_image = [&](const velodyne::RangeImage& image) -> bool {
    if (options.max_revolutions > 0 && static_cast<long>(report.revolutions) >= options.max_revolutions) return false;
    const auto t0 = std::chrono::steady_clock::now();
    points.clear();
    fraction.clear();
    const double span = static_cast<double>(image.end_ns - image.start_ns);
    for (int c = 0; c < image.columns(); ++c) {
      if (image.column_state(c) != velodyne::ColumnState::received) continue;
      const std::int64_t t = image.column_time_ns(c);
      const float s = span > 0.0 && t != velodyne::RangeImage::kNoTime
                          ? static_cast<float>(static_cast<double>(t - image.start_ns) / span)
                          : 1.0f;
      for (int r = 0; r < image.rings(); ++r) {
        const velodyne::RangeCell& cell = image.at(0, r, c);
        if (!cell.valid() || cell.distance < options.min_range || cell.distance > options.max_range) continue;
        if (points.size() == config.max_points) break;
        points.emplace_back(cell.x, cell.y, cell.z);
        fraction.push_back(s);
      }
    }
    // The lidar's pose by the wheels at this revolution's end, and its
    // motion since the last one's.
    const std::int64_t at = image.end_ns + image.clock_offset_ns;
    std::optional<Eigen::Isometry3d> measured;
    if (wheels) {
      perception::Pose w;
      wheels->at(at, w);
      const Eigen::Isometry3d lidar = isometry_of(w) * mount;
      if (report.revolutions == 0) wheel_start = lidar;
      if (report.revolutions >= 1) measured = wheel_last.inverse() * lidar;
      wheel_last = lidar;
    }
    // The motion over this revolution: the wheels', or the last one's (the
    // revolutions follow each other without a gap).
    if (options.deskew && measured) {
      reg::deskew(points, fraction, *measured);
    } else if (options.deskew && report.revolutions >= 2) {
      reg::deskew(points, fraction, smoothed);
    }
    const Eigen::Isometry3d pose = odometry.add(points, measured ? &*measured : nullptr);
    if (report.revolutions >= 1) {
      // The motion de-skewing assumes: the scan-to-scan motions smoothed
      // (translation and rotation vector, each new one weighing
      // 1 − kKeep). The last motion alone made it worse than none: one
      // registration's error bends the next scan, whose error bends the one
      // after (docs/registration.md).
      const double keep = kKeep;
      const Eigen::Isometry3d m = odometry.last_motion();
      const Eigen::AngleAxisd a(m.linear()), b(smoothed.linear());
      const Eigen::Vector3d w = keep * b.angle() * b.axis() + (1.0 - keep) * a.angle() * a.axis();
      smoothed.translation() = keep * smoothed.translation() + (1.0 - keep) * m.translation();
      smoothed.linear() = w.norm() > 1e-12 ? Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix()
                                           : Eigen::Matrix3d::Identity();
    }
    busy_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    report.points += points.size();
    if (truth) {
      perception::Pose p;
      truth->at(at, p);
      const Eigen::Isometry3d ref = isometry_of(p) * mount;
      if (report.revolutions == 0) start = ref;
      report.reference.push_back(ref);
    }
    report.estimate.push_back(start * pose);
    if (options.on_revolution) options.on_revolution(report.estimate.back(), truth ? &report.reference.back() : nullptr, points);
    if (wheels) report.wheels.push_back(start * wheel_start.inverse() * wheel_last);
    report.conditioning.push_back(odometry.last_conditioning());
    // (Into the reference's frame, as the estimate.)
    report.conditioning.back().direction = start.linear() * report.conditioning.back().direction;
    report.times_ns.push_back(at);
    ++report.revolutions;
    return true;
  };
  if (std::string e = source.run(on_image, options.progress); !e.empty()) {
    report.error = e;
    return report;
  }
  if (report.revolutions < 2) {
    report.error = options.input + ": " + std::to_string(report.revolutions) + " revolution(s); at least 2 are needed";
    return report;
  }
  report.counters = odometry.counters();
  report.ms_per_revolution = 1000.0 * busy_s / static_cast<double>(report.revolutions);
  if (!report.reference.empty()) {
    report.rpe = reg::relative_pose_error(report.reference, report.estimate, 10.0);
    if (!report.wheels.empty()) report.rpe_wheels = reg::relative_pose_error(report.reference, report.wheels, 10.0);
    report.path_m = reg::path_length(report.reference);
    report.end_error_m = (report.estimate.back().translation() - report.reference.back().translation()).norm();
  } else {
    report.path_m = reg::path_length(report.estimate);
  }
  return report;
}

}  // namespace trailnav::eval
