// `trailnav pose-eval`: the pose estimate (gyro-aided odometry and its UTM
// alignment) scored on simulated recordings against their truth.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "commands.hpp"
#include "pose_eval.hpp"
#include "terminal.hpp"

namespace trailnav::cli {
namespace {

struct PoseEvalCliOptions {
  std::vector<std::string> recordings;
  double segment = 100.0;
  std::string csv;
  double gate = 16.0;
  double min_baseline = 5.0;
  bool quiet = false;
};

void print(const eval::PoseEvalResult& r, double segment) {
  std::printf("%s: %.1f s, %.1f m driven (odometry %.1f m)\n", r.recording.c_str(), r.duration, r.distance,
              r.odometry_distance);
  std::printf("  local frame (gyro-aided odometry):\n");
  if (r.drift_segments > 0) {
    std::printf("    drift per %.0f m   mean %.2f m (%.2f %%), max %.2f m; heading mean %.2f deg, max %.2f deg (%llu stretches)\n",
                segment, r.drift_mean, 100.0 * r.drift_mean / segment, r.drift_max, r.yaw_drift_mean_deg,
                r.yaw_drift_max_deg, static_cast<unsigned long long>(r.drift_segments));
  } else {
    std::printf("    drift per %.0f m   (route shorter than one stretch)\n", segment);
  }
  std::printf("    whole run        %.2f m at the end (%.2f %% of the distance)\n", r.end_error,
              r.distance > 0 ? 100.0 * r.end_error / r.distance : 0.0);
  std::printf("  UTM (GPS aligned odometry):\n");
  if (r.utm_samples == 0) {
    std::printf("    never aligned (the robot did not move %.0f m?)\n", 0.0);
  } else {
    std::printf("    heading known after %.1f m\n", r.aligned_after_m);
    std::printf("    position error   mean %.2f m, RMS %.2f m, p95 %.2f m, max %.2f m; truth within 2 sigma %.0f %%\n",
                r.utm_mean, r.utm_rms, r.utm_p95, r.utm_max, 100.0 * r.within_2sigma);
    std::printf("    heading error    mean %.2f deg, max %.2f deg\n", r.heading_mean_deg, r.heading_max_deg);
  }
  std::printf("    raw GPS fixes    mean %.2f m, RMS %.2f m (%llu fixes)\n", r.gps_mean, r.gps_rms,
              static_cast<unsigned long long>(r.gps_fixes));
  const pose::UtmAlignmentCounters& c = r.utm_counters;
  std::printf("    fixes: %llu offered, %llu used, %llu outliers, %llu jumps, %llu without odometry, %llu dropped by the initial fit\n",
              static_cast<unsigned long long>(c.fixes), static_cast<unsigned long long>(c.used),
              static_cast<unsigned long long>(c.outliers), static_cast<unsigned long long>(c.jumps),
              static_cast<unsigned long long>(c.no_odometry), static_cast<unsigned long long>(c.initial_fit_rejected));
  std::printf("  per %.0f m driven:   UTM mean   UTM max   raw GPS   heading\n", segment);
  for (const eval::PoseSegmentRow& row : r.rows) {
    std::printf("    %6.0f-%-6.0f   %7.2f m  %7.2f m  %7.2f m  %6.2f deg\n", row.from, row.to, row.utm_mean,
                row.utm_max, row.gps_mean, row.heading_mean_deg);
  }
}

int run(const PoseEvalCliOptions& o) {
  int status = 0;
  for (const std::string& rec : o.recordings) {
    eval::PoseEvalOptions eo;
    eo.segment = o.segment;
    eo.csv = o.recordings.size() == 1 ? o.csv : "";
    eo.estimator.utm.gate = o.gate;
    eo.estimator.utm.min_baseline = o.min_baseline;
    ProgressBar progress("pose " + rec, 100.0, "%");
    if (!o.quiet) eo.progress = [&](double part) { progress.update(part * 100.0); };
    const eval::PoseEvalResult r = eval::evaluate_pose(rec, eo);
    if (!o.quiet) progress.finish();
    if (!r.error.empty()) {
      std::fprintf(stderr, "trailnav pose-eval: %s\n", r.error.c_str());
      status = 2;
      continue;
    }
    print(r, o.segment);
  }
  return status;
}

}  // namespace

void add_pose_eval_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "pose-eval",
      "Score the pose estimate on simulated recordings: the recording's GPS, IMU and CAN streams go through\n"
      "the drivers' decoders, the attitude filter, wheel odometry and the pose estimator (gyro-aided odometry,\n"
      "GPS aligned to UTM), and the result is compared with truth/trajectory.csv. Prints the local frame's\n"
      "drift per 100 m (start of each stretch put on the truth, as KITTI scores odometry), the UTM position and\n"
      "heading error per 100 m driven next to the raw fixes' error, and how often the truth lies within the\n"
      "estimate's own 2-sigma ellipse. The robot (wheel track, antenna) comes from truth/scenario.yaml.\n"
      "Examples:\n"
      "  trailnav sim --scenario mixed-route --no-lidar --out /tmp/mixed && trailnav pose-eval /tmp/mixed\n"
      "  trailnav pose-eval /tmp/mixed --csv /tmp/mixed-pose.csv");
  static PoseEvalCliOptions o;
  cmd->add_option("recordings", o.recordings, "Simulated recording directories")->required();
  cmd->add_option("--segment", o.segment, "Stretch length for drift and the table, m")
      ->capture_default_str()
      ->check(CLI::Range(10.0, 10000.0));
  cmd->add_option("--csv", o.csv, "Write the per-sample comparison (one recording only)");
  cmd->add_option("--gate", o.gate, "Outlier gate: squared Mahalanobis distance of a fix")->capture_default_str();
  cmd->add_option("--min-baseline", o.min_baseline, "Metres driven before the heading is estimated")->capture_default_str();
  cmd->add_flag("--quiet", o.quiet, "No progress bar");
  cmd->callback([&] { std::exit(run(o)); });
}

}  // namespace trailnav::cli
