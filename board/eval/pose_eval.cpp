#include "pose_eval.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "sim_truth.hpp"
#include "simulator.hpp"
#include "trailnav/drivers/can/dbc.hpp"
#include "trailnav/drivers/gps/fix.hpp"
#include "trailnav/drivers/gps/gps_driver.hpp"
#include "trailnav/drivers/imu/attitude.hpp"
#include "trailnav/drivers/imu/stream_decoder.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/navigation/pose/angles.hpp"

namespace trailnav::eval {
namespace {

namespace fs = std::filesystem;
using pose::kPi;
using pose::wrap_angle;
constexpr double kRad2Deg = 180.0 / kPi;

// The true pose at time t, interpolated.
struct Sample {
  std::int64_t t = 0;
  double ex = 0, ey = 0, eyaw = 0;  // estimate, odometry frame
  TruthAt truth;
  bool utm = false;
  double ue = 0, un = 0, uyaw = 0;  // estimate, UTM
  double te = 0, tn = 0;            // truth, UTM
  double utm_err = 0, heading_err = 0;
  bool in_2sigma = false;
};

}  // namespace

PoseEvalResult evaluate_pose(const std::string& recording, const PoseEvalOptions& options) {
  PoseEvalResult r;
  r.recording = recording;
  auto loaded = load_sim_truth((fs::path(recording) / "truth").string());
  if (!loaded.truth) {
    r.error = "pose evaluation needs a simulated recording's truth: " + loaded.error;
    return r;
  }
  const SimTruth& truth = *loaded.truth;
  if (!std::isfinite(truth.trajectory.front().lat)) {
    r.error = recording + ": truth/trajectory.csv has no lat,lon columns (recorded by an older simulator)";
    return r;
  }
  auto opened = recording::RecordingReader::open(recording);
  if (!opened.reader) {
    r.error = opened.error;
    return r;
  }
  recording::RecordingReader& reader = *opened.reader;
  const int gps_stream = reader.stream_index("gps", recording::StreamKind::serial);
  const int imu_stream = reader.stream_index("imu", recording::StreamKind::serial);
  const int can_stream = reader.stream_index("wheels", recording::StreamKind::can);
  if (gps_stream < 0 || imu_stream < 0 || can_stream < 0) {
    r.error = recording + ": needs the serial streams 'gps' and 'imu' and the CAN stream 'wheels'";
    return r;
  }

  // The robot as the scenario built it.
  const sim::Scenario& sc = truth.scenario;
  pose::PoseEstimatorOptions eo = options.estimator;
  eo.utm.antenna = {sc.robot.gps_antenna.x(), sc.robot.gps_antenna.y(), sc.robot.gps_antenna.z()};
  auto dbc = can::parse_dbc(sim::robot_dbc_text(), "trailnav-robot.dbc");
  if (!dbc.dbc) {
    r.error = dbc.error;
    return r;
  }
  can::WheelOdometryOptions wo;
  wo.left = {"WHEEL_SPEEDS", "SpeedLeft"};
  wo.right = {"WHEEL_SPEEDS", "SpeedRight"};
  wo.track = sc.robot.track;
  auto wheels = can::WheelOdometry::create(*dbc.dbc, wo);
  if (!wheels.odometry) {
    r.error = wheels.error;
    return r;
  }
  pose::PoseEstimator estimator(eo);
  imu::AttitudeFilter filter;
  imu::ImuStreamDecoder imu_decoder(imu::ImuProtocol::xsens);
  gps::LineFramer framer;
  gps::FixAssembler assembler;
  gps::GpsFix fix;
  std::int64_t gps_last = -1;
  bool epoch_open = false;
  // An epoch ends when its burst has been quiet as long as the GPS driver waits.
  const std::int64_t epoch_gap = seconds_to_nanos(gps::GpsDriverOptions{}.epoch_gap);

  // Raw fixes, for their own error.
  struct RawFix {
    std::int64_t t;
    double lat, lon;
  };
  std::vector<RawFix> raw;
  auto take_fix = [&](const gps::GpsFix& f, std::int64_t receive) {
    estimator.add_gps(f, receive);
    if (f.has_fix()) raw.push_back({estimator.fix_time(f, receive), f.lat, f.lon});
  };
  std::vector<Sample> samples;
  std::uint64_t events = 0;
  while (auto e = reader.next()) {
    if (epoch_open && e->time_ns - gps_last > epoch_gap) {
      if (assembler.flush(fix)) take_fix(fix, gps_last);
      epoch_open = false;
    }
    if (e->stream == gps_stream) {
      gps_last = e->time_ns;
      framer.feed(e->payload, [&](std::string_view line) {
        if (assembler.add_line(line, fix)) take_fix(fix, e->time_ns);
        epoch_open = true;
      });
    } else if (e->stream == imu_stream) {
      imu_decoder.feed(e->payload, e->time_ns, [&](const imu::ImuSample& s) {
        const imu::Attitude& a = filter.update(s);
        estimator.add_imu(a);
        Sample smp;
        smp.t = a.time_ns;
        const pose::LocalPose& p = estimator.odometry().pose();
        if (options.on_odometry) options.on_odometry(p);
        smp.ex = p.x;
        smp.ey = p.y;
        smp.eyaw = p.yaw;
        if (!truth_at(truth.trajectory, smp.t, smp.truth)) return;
        const pose::UtmPose u = estimator.alignment().utm(p);
        if (u.heading_valid) {
          if (options.on_utm) options.on_utm(u);
          smp.utm = true;
          smp.ue = u.easting;
          smp.un = u.northing;
          smp.uyaw = u.yaw;
          double gamma = 0;
          estimator.alignment().forward(smp.truth.lat, smp.truth.lon, smp.te, smp.tn, gamma);
          const double de = smp.ue - smp.te, dn = smp.un - smp.tn;
          smp.utm_err = std::hypot(de, dn);
          const Eigen::Matrix2d c = u.covariance.topLeftCorner<2, 2>();
          const Eigen::Vector2d d(de, dn);
          smp.in_2sigma = d.dot(c.inverse() * d) <= 6.18;  // 2-D chi-square at 95.4 %
        }
        samples.push_back(smp);
      });
    } else if (e->stream == can_stream && e->can != nullptr) {
      if (wheels.odometry->on_frame(*e->can)) {
        can::OdometryState w = wheels.odometry->state();
        estimator.add_wheels(w);
      }
    }
    if (options.progress && (++events % 4096) == 0 && reader.size() > 0) {
      options.progress(static_cast<double>(reader.position()) / static_cast<double>(reader.size()));
    }
  }
  if (epoch_open && assembler.flush(fix)) take_fix(fix, gps_last);
  if (samples.size() < 2) {
    r.error = recording + ": fewer than two IMU samples within the truth's time span";
    return r;
  }
  r.duration = static_cast<double>(samples.back().t - samples.front().t) * 1e-9;
  const double arc0 = samples.front().truth.arc;
  r.distance = samples.back().truth.arc - arc0;
  r.odometry_distance = estimator.odometry().pose().distance;
  r.utm_counters = estimator.alignment().counters();
  r.odometry_counters = estimator.odometry().counters();

  // Local drift over stretches of `segment` metres starting every tenth of it.
  auto predict = [](const Sample& s, const Sample& e, double& px, double& py, double& yaw_err) {
    const double dx = e.ex - s.ex, dy = e.ey - s.ey;
    const double rot = s.truth.yaw - s.eyaw;
    px = s.truth.x + std::cos(rot) * dx - std::sin(rot) * dy;
    py = s.truth.y + std::sin(rot) * dx + std::cos(rot) * dy;
    yaw_err = wrap_angle((e.eyaw - s.eyaw) - (e.truth.yaw - s.truth.yaw));
  };
  {
    double px = 0, py = 0, ye = 0;
    predict(samples.front(), samples.back(), px, py, ye);
    r.end_error = std::hypot(px - samples.back().truth.x, py - samples.back().truth.y);
  }
  double drift_sum = 0, yaw_sum = 0;
  std::size_t end = 0;
  for (std::size_t s = 0; s < samples.size(); ++s) {
    const double start_arc = samples[s].truth.arc;
    if (s > 0 && std::floor((start_arc - arc0) / (options.segment / 10)) ==
                     std::floor((samples[s - 1].truth.arc - arc0) / (options.segment / 10))) {
      continue;
    }
    end = std::max(end, s);
    while (end < samples.size() && samples[end].truth.arc < start_arc + options.segment) ++end;
    if (end >= samples.size()) break;
    double px = 0, py = 0, ye = 0;
    predict(samples[s], samples[end], px, py, ye);
    const double err = std::hypot(px - samples[end].truth.x, py - samples[end].truth.y);
    ++r.drift_segments;
    drift_sum += err;
    yaw_sum += std::abs(ye) * kRad2Deg;
    r.drift_max = std::max(r.drift_max, err);
    r.yaw_drift_max_deg = std::max(r.yaw_drift_max_deg, std::abs(ye) * kRad2Deg);
  }
  if (r.drift_segments > 0) {
    r.drift_mean = drift_sum / static_cast<double>(r.drift_segments);
    r.yaw_drift_mean_deg = yaw_sum / static_cast<double>(r.drift_segments);
  }

  // The rotation from the simulator's local frame to UTM grid, from the truth itself.
  double num = 0, den = 0;
  {
    const TruthPose& a = truth.trajectory.front();
    double e0 = 0, n0 = 0, g = 0;
    const bool ok0 = estimator.alignment().forward(a.lat, a.lon, e0, n0, g);
    for (std::size_t k = 1; ok0 && k < truth.trajectory.size(); k += 10) {
      const TruthPose& b = truth.trajectory[k];
      double e = 0, n = 0;
      if (!estimator.alignment().forward(b.lat, b.lon, e, n, g)) continue;
      const double lx = b.x - a.x, ly = b.y - a.y, ux = e - e0, uy = n - n0;
      num += lx * uy - ly * ux;
      den += lx * ux + ly * uy;
    }
  }
  const double grid_rotation = std::atan2(num, den);

  // UTM error, whole run and per stretch.
  std::vector<double> errors;
  double heading_sum = 0;
  std::uint64_t inside = 0;
  auto row_of = [&](double arc) {
    const auto k = static_cast<std::size_t>(std::max(0.0, std::floor((arc - arc0) / options.segment)));
    while (r.rows.size() <= k) {
      PoseSegmentRow row;
      row.from = static_cast<double>(r.rows.size()) * options.segment;
      row.to = row.from + options.segment;
      r.rows.push_back(row);
    }
    return k;
  };
  for (Sample& s : samples) {
    if (!s.utm) continue;
    if (r.aligned_after_m < 0) r.aligned_after_m = s.truth.arc - arc0;
    s.heading_err = wrap_angle(s.uyaw - (s.truth.yaw + grid_rotation));
    errors.push_back(s.utm_err);
    heading_sum += std::abs(s.heading_err) * kRad2Deg;
    r.heading_max_deg = std::max(r.heading_max_deg, std::abs(s.heading_err) * kRad2Deg);
    if (s.in_2sigma) ++inside;
    PoseSegmentRow& row = r.rows[row_of(s.truth.arc)];
    row.utm_mean += s.utm_err;
    row.utm_max = std::max(row.utm_max, s.utm_err);
    row.heading_mean_deg += std::abs(s.heading_err) * kRad2Deg;
    ++row.samples;
  }
  r.utm_samples = errors.size();
  if (!errors.empty()) {
    double sum = 0, sq = 0;
    for (double e : errors) {
      sum += e;
      sq += e * e;
    }
    r.utm_mean = sum / static_cast<double>(errors.size());
    r.utm_rms = std::sqrt(sq / static_cast<double>(errors.size()));
    r.utm_max = *std::max_element(errors.begin(), errors.end());
    std::vector<double> sorted = errors;
    const auto k95 = static_cast<std::size_t>(0.95 * static_cast<double>(sorted.size() - 1));
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(k95), sorted.end());
    r.utm_p95 = sorted[k95];
    r.heading_mean_deg = heading_sum / static_cast<double>(errors.size());
    r.within_2sigma = static_cast<double>(inside) / static_cast<double>(errors.size());
  }
  for (PoseSegmentRow& row : r.rows) {
    if (row.samples > 0) {
      row.utm_mean /= static_cast<double>(row.samples);
      row.heading_mean_deg /= static_cast<double>(row.samples);
    }
  }

  // Raw fixes against the true antenna position.
  std::vector<std::uint64_t> row_fixes(r.rows.size(), 0);
  double gsum = 0, gsq = 0;
  for (const RawFix& f : raw) {
    TruthAt t;
    if (!truth_at(truth.trajectory, f.t, t)) continue;
    double te = 0, tn = 0, fe = 0, fn = 0, g = 0;
    if (!estimator.alignment().forward(t.lat, t.lon, te, tn, g) || !estimator.alignment().forward(f.lat, f.lon, fe, fn, g)) {
      continue;
    }
    const double yaw = t.yaw + grid_rotation;
    te += std::cos(yaw) * eo.utm.antenna[0] - std::sin(yaw) * eo.utm.antenna[1];
    tn += std::sin(yaw) * eo.utm.antenna[0] + std::cos(yaw) * eo.utm.antenna[1];
    const double err = std::hypot(fe - te, fn - tn);
    ++r.gps_fixes;
    gsum += err;
    gsq += err * err;
    const std::size_t k = row_of(t.arc);
    row_fixes.resize(r.rows.size(), 0);
    r.rows[k].gps_mean += err;
    ++row_fixes[k];
  }
  if (r.gps_fixes > 0) {
    r.gps_mean = gsum / static_cast<double>(r.gps_fixes);
    r.gps_rms = std::sqrt(gsq / static_cast<double>(r.gps_fixes));
  }
  for (std::size_t k = 0; k < r.rows.size(); ++k) {
    if (k < row_fixes.size() && row_fixes[k] > 0) r.rows[k].gps_mean /= static_cast<double>(row_fixes[k]);
  }

  if (!options.csv.empty()) {
    if (std::FILE* f = std::fopen(options.csv.c_str(), "w")) {
      std::fprintf(f, "utc_ns,arc,odom_x,odom_y,odom_yaw,true_x,true_y,true_yaw,utm_valid,utm_e,utm_n,utm_yaw,true_e,true_n,utm_error\n");
      for (const Sample& s : samples) {
        std::fprintf(f, "%lld,%.3f,%.4f,%.4f,%.5f,%.4f,%.4f,%.5f,%d,%.3f,%.3f,%.5f,%.3f,%.3f,%.3f\n",
                     static_cast<long long>(s.t), s.truth.arc - arc0, s.ex, s.ey, s.eyaw, s.truth.x, s.truth.y,
                     s.truth.yaw, s.utm ? 1 : 0, s.ue, s.un, s.uyaw, s.te, s.tn, s.utm_err);
      }
      std::fclose(f);
    } else {
      r.error = "cannot write " + options.csv;
    }
  }
  return r;
}

}  // namespace trailnav::eval
