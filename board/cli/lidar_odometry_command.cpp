// `trailnav lidar-odometry INPUT [--report json]`: lidar odometry by
// scan-to-local-map GICP (perception/registration/odometry.hpp) over a
// CARMEN log's 2D laser scans (FLASER lines, plain or gzip), scored against
// the log's own poses (SLAM-corrected in ../shared/data/carmen) by the
// relative pose error per 10 m of travel. docs/registration.md.
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "commands.hpp"
#include "terminal.hpp"
#include "trailnav/perception/registration/carmen.hpp"
#include "trailnav/perception/registration/odometry.hpp"
#include "loop_eval.hpp"
#include "velodyne_odometry.hpp"

namespace trailnav::cli {
namespace {

namespace reg = trailnav::perception::registration;

struct Options {
  std::string input;
  std::vector<std::string> more;  // further point-cloud files of a sequence
  std::string report;
  std::string poses_out;
  float voxel = 0.05f;
  int local_scans = 20;
  double keyframe_distance = 0.3;
  double max_correspondence = 0.5;
  float max_range = 40.0f;
  long max_scans = 0;
  int max_iterations = 100;
  bool quiet = false;
  bool no_prediction = false;
  bool one_start = false;
  bool no_deskew = false;
  bool wheel_prior = false;
  bool loops = false;
  double loop_radius = 0.0, loop_min_path = 0.0, loop_max_rms = 0.0;  // 0: the defaults
  std::string calibration;
  // Which of the tuning options the user gave (the 3D input has its own
  // defaults; the command's callback reads them off the parser).
  bool set_voxel = false, set_local = false, set_keyframe = false, set_gate = false, set_range = false;
};

// A number for JSON, or null when it is not finite (JSON has no NaN).
std::string num(double value, int digits) {
  if (!std::isfinite(value)) return "null";
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, value);
  return b;
}

// The loop closures' options from the command line over a default.
eval::LoopEvalOptions loop_options(const Options& o, eval::LoopEvalOptions lo);

// The loop closures' JSON member (", \"loops\": {...}") and text lines.
std::string loops_json(const eval::LoopEvalResult& lr) {
  const perception::registration::LoopCounters& l = lr.counters;
  const bool ref = !lr.reference.empty();
  // The keyframes' errors by the odometry alone ("before") and with the
  // closures ("after"), under the same names and meaning as the report's own.
  auto errors = [&](const perception::registration::RelativePoseError& rpe, double end, double ate) {
    if (!ref) return std::string("null");
    return "{\"rpe_translation_percent\": " + num(rpe.translation_percent, 4) +
           ", \"rpe_rotation_deg_per_100m\": " + num(rpe.rotation_deg_per_100m, 4) + ", \"end_error_m\": " + num(end, 3) +
           ", \"ate_rmse_m\": " + num(ate, 3) + "}";
  };
  char text[800];
  std::snprintf(text, sizeof text,
                ", \"loops\": {\"keyframes\": %zu, \"candidates\": %llu, \"accepted\": %llu, \"false\": %s, "
                "\"rejected_overlap\": %llu, \"rejected_rms\": %llu, \"rejected_jump\": %llu, \"not_converged\": %llu, "
                "\"optimisations\": %d, \"solve_ms_max\": %s, \"close_ms_max\": %s, ",
                lr.keyframes, static_cast<unsigned long long>(l.candidates), static_cast<unsigned long long>(l.accepted),
                ref ? std::to_string(lr.false_closures).c_str() : "null", static_cast<unsigned long long>(l.low_overlap),
                static_cast<unsigned long long>(l.high_rms), static_cast<unsigned long long>(l.jumped),
                static_cast<unsigned long long>(l.not_converged), lr.optimisations, num(lr.solve_ms_max, 2).c_str(),
                num(lr.close_ms_max, 2).c_str());
  return text + ("\"before\": " + errors(lr.rpe_odometry, lr.end_odometry_m, lr.ate_odometry_m) + ", \"after\": " +
                 errors(lr.rpe_loops, lr.end_loops_m, lr.ate_loops_m) + "}");
}

void print_loops(const eval::LoopEvalResult& lr, const eval::LoopEvalOptions& lo) {
  const perception::registration::LoopCounters& l = lr.counters;
  std::printf("loop closures over %zu keyframes (every %.1f m or %.2f rad): %llu candidates verified by GICP, %llu "
              "accepted",
              lr.keyframes, lo.keyframes.spacing_m, lo.keyframes.spacing_rad, static_cast<unsigned long long>(l.candidates),
              static_cast<unsigned long long>(l.accepted));
  if (!lr.reference.empty()) std::printf(" (%zu false against the reference poses)", lr.false_closures);
  std::printf(", rejected: %llu overlap, %llu RMS, %llu jump, %llu not converged; %d SMF solves (the longest %.1f ms), "
              "the longest search and verification %.1f ms\n",
              static_cast<unsigned long long>(l.low_overlap), static_cast<unsigned long long>(l.high_rms),
              static_cast<unsigned long long>(l.jumped), static_cast<unsigned long long>(l.not_converged), lr.optimisations,
              lr.solve_ms_max, lr.close_ms_max);
  if (lr.reference.empty()) return;
  std::printf("  keyframes, odometry -> with loops: RPE %.3f %% -> %.3f %%, %.2f -> %.2f deg/100 m; end %.2f -> %.2f m; "
              "absolute RMS %.2f -> %.2f m\n",
              lr.rpe_odometry.translation_percent, lr.rpe_loops.translation_percent, lr.rpe_odometry.rotation_deg_per_100m,
              lr.rpe_loops.rotation_deg_per_100m, lr.end_odometry_m, lr.end_loops_m, lr.ate_odometry_m, lr.ate_loops_m);
}

// A spinning lidar's recording or capture: a directory, or a capture file.
bool is_lidar_input(const std::string& input) {
  namespace fs = std::filesystem;
  if (fs::is_directory(input)) return true;
  const std::string ext = fs::path(input).extension().string();
  return ext == ".pcap" || ext == ".pcapng" || ext == ".bin" || ext == ".pcd" || ext == ".ply";
}

eval::LoopEvalOptions loop_options(const Options& o, eval::LoopEvalOptions lo) {
  if (o.loop_radius > 0.0) lo.loops.search_radius = o.loop_radius;
  if (o.loop_min_path > 0.0) lo.loops.min_path = o.loop_min_path;
  if (o.loop_max_rms > 0.0) lo.loops.max_rms = o.loop_max_rms;
  return lo;
}

int run_lidar(const Options& o) {
  const char* who = "trailnav lidar-odometry";
  eval::VelodyneOdometryOptions v;
  v.input = o.input;
  if (!o.more.empty()) {
    v.inputs.push_back(o.input);
    v.inputs.insert(v.inputs.end(), o.more.begin(), o.more.end());
  }
  v.calibration = o.calibration;
  v.deskew = !o.no_deskew;
  v.wheel_prior = o.wheel_prior;
  v.max_revolutions = o.max_scans;
  reg::OdometryConfig& config = v.odometry;
  config.planar = false;
  config.voxel = o.set_voxel ? o.voxel : 0.25f;
  config.local_scans = o.set_local ? o.local_scans : 10;
  config.keyframe_distance = o.set_keyframe ? o.keyframe_distance : 1.0;
  config.gicp.max_correspondence_distance = static_cast<float>(o.set_gate ? o.max_correspondence : 1.0);
  config.gicp.max_iterations = o.max_iterations;
  config.constant_velocity = !o.no_prediction;
  config.two_starts = !o.one_start;
  if (o.set_range) v.max_range = o.max_range;
  std::unique_ptr<ProgressBar> bar;
  if (!o.quiet) {
    bar = std::make_unique<ProgressBar>("lidar odometry", 100.0, "%");
    v.progress = [&](double f) { bar->update(100.0 * f); };
  }
  // Loop closures as the revolutions come (their clouds are not kept).
  const eval::LoopEvalOptions lo = loop_options(o, eval::default_loop_eval_options_3d());
  std::unique_ptr<eval::LoopMapper> mapper;
  if (o.loops) {
    mapper = std::make_unique<eval::LoopMapper>(lo);
    if (!mapper->error().empty()) {
      std::fprintf(stderr, "%s: %s\n", who, mapper->error().c_str());
      return 2;
    }
    v.on_revolution = [&](const Eigen::Isometry3d& estimate, const Eigen::Isometry3d* reference,
                          std::span<const reg::Point> points) {
      mapper->add(estimate, reference, [&](std::vector<reg::Point>& cloud) { cloud.assign(points.begin(), points.end()); });
    };
  }
  const eval::VelodyneOdometryReport r = eval::run_velodyne_odometry(v);
  eval::LoopEvalResult lr;
  if (mapper) lr = mapper->finish();
  if (bar) bar->finish();
  if (!r.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, r.error.c_str());
    return 1;
  }
  if (!o.poses_out.empty()) {
    std::FILE* out = std::fopen(o.poses_out.c_str(), "w");
    if (out == nullptr) {
      std::fprintf(stderr, "%s: cannot write %s\n", who, o.poses_out.c_str());
      return 1;
    }
    std::fprintf(out, "timestamp,x,y,z,yaw,ref_x,ref_y,ref_z,ref_yaw,weakest,strongest,weak_x,weak_y,weak_z\n");
    for (std::size_t i = 0; i < r.estimate.size(); ++i) {
      const Eigen::Isometry3d& e = r.estimate[i];
      std::fprintf(out, "%.6f,%.4f,%.4f,%.4f,%.5f", static_cast<double>(r.times_ns[i]) * 1e-9, e.translation().x(),
                   e.translation().y(), e.translation().z(), std::atan2(e.linear()(1, 0), e.linear()(0, 0)));
      if (i < r.reference.size()) {
        const Eigen::Isometry3d& f = r.reference[i];
        std::fprintf(out, ",%.4f,%.4f,%.4f,%.5f", f.translation().x(), f.translation().y(), f.translation().z(),
                     std::atan2(f.linear()(1, 0), f.linear()(0, 0)));
      } else {
        std::fprintf(out, ",,,,");
      }
      if (i < r.conditioning.size()) {
        const auto& k = r.conditioning[i];
        std::fprintf(out, ",%.4g,%.4g,%.3f,%.3f,%.3f\n", k.weakest, k.strongest, k.direction.x(), k.direction.y(),
                     k.direction.z());
      } else {
        std::fprintf(out, ",,,,,\n");
      }
    }
    std::fclose(out);
  }
  const bool ref = !r.reference.empty();
  const bool wheels = ref && !r.wheels.empty();
  const auto& c = r.counters;
  if (o.report == "json") {
    std::printf(
        "{\"input\": \"%s\", \"lidar\": \"%s\", \"scans\": %zu, \"points\": %zu, \"deskew\": %s, \"wheel_prior\": %s, \"path_m\": %s, "
        "\"keyframes\": %llu, \"not_converged\": %llu, \"second_start\": %llu, \"rejected\": %llu, "
        "\"rpe_translation_percent\": %s, \"rpe_rotation_deg_per_100m\": %s, \"segments\": %zu, \"end_error_m\": %s, "
        "\"prior_kept\": %llu, \"rpe_wheels_translation_percent\": %s, \"rpe_wheels_rotation_deg_per_100m\": %s, "
        "\"ms_per_scan\": %s%s}\n",
        o.input.c_str(), r.lidar.c_str(), r.revolutions, r.points, v.deskew ? "true" : "false",
        v.wheel_prior ? "true" : "false", num(r.path_m, 3).c_str(),
        static_cast<unsigned long long>(c.keyframes), static_cast<unsigned long long>(c.not_converged),
        static_cast<unsigned long long>(c.second_start), static_cast<unsigned long long>(c.rejected),
        ref ? num(r.rpe.translation_percent, 4).c_str() : "null", ref ? num(r.rpe.rotation_deg_per_100m, 4).c_str() : "null",
        r.rpe.segments, num(r.end_error_m, 3).c_str(), static_cast<unsigned long long>(c.prior_kept),
        wheels ? num(r.rpe_wheels.translation_percent, 4).c_str() : "null",
        wheels ? num(r.rpe_wheels.rotation_deg_per_100m, 4).c_str() : "null", num(r.ms_per_revolution, 3).c_str(),
        mapper ? loops_json(lr).c_str() : "");
    return 0;
  }
  std::printf("lidar odometry (%s revolutions, %s, %s, scan to the last %d keyframes, GICP, voxel %.2f m) over %s\n",
              r.lidar.c_str(), v.deskew ? "de-skewed" : "not de-skewed",
              v.wheel_prior ? "predicted by the wheels and IMU" : "constant velocity", config.local_scans,
              static_cast<double>(config.voxel), o.input.c_str());
  std::printf("  %zu revolutions, %zu points, %.1f m of %s path, %llu keyframes, %llu not converged, %llu answers from the "
              "second start, %llu rejected\n",
              r.revolutions, r.points, r.path_m, ref ? "the true" : "the estimated", static_cast<unsigned long long>(c.keyframes),
              static_cast<unsigned long long>(c.not_converged), static_cast<unsigned long long>(c.second_start),
              static_cast<unsigned long long>(c.rejected));
  if (ref) {
    std::printf("  relative pose error per 10 m against the simulated truth (%zu segments): %.3f %% translation, "
                "%.3f deg/100 m; end point %.2f m off\n",
                r.rpe.segments, r.rpe.translation_percent, r.rpe.rotation_deg_per_100m, r.end_error_m);
    if (wheels) {
      std::printf("  the wheels and IMU alone: %.3f %% translation, %.3f deg/100 m; %llu scans took their motion where "
                  "the scene pinned it weakly\n",
                  r.rpe_wheels.translation_percent, r.rpe_wheels.rotation_deg_per_100m,
                  static_cast<unsigned long long>(c.prior_kept));
    }
  } else {
    std::printf("  no reference poses (not a simulated recording): no relative pose error\n");
  }
  std::printf("  %.2f ms a revolution (de-skew and registration)\n", r.ms_per_revolution);
  if (mapper) print_loops(lr, lo);
  return 0;
}

int run(const Options& o) {
  const char* who = "trailnav lidar-odometry";
  if (o.report != "" && o.report != "json") {
    std::fprintf(stderr, "%s: --report takes json, not '%s'\n", who, o.report.c_str());
    return 2;
  }
  if (!(o.voxel > 0.0f) || o.local_scans < 1 || !(o.max_correspondence > 0.0) || !(o.keyframe_distance >= 0.0) ||
      o.max_iterations < 1 || o.max_iterations > 1000) {
    std::fprintf(stderr, "%s: --voxel, --max-correspondence must be positive, --local-scans at least 1, --max-iterations 1 to 1000\n", who);
    return 2;
  }
  if (is_lidar_input(o.input)) return run_lidar(o);
  if (!o.more.empty()) {
    std::fprintf(stderr, "%s: one CARMEN log at a time (more inputs are for a sequence of point-cloud files)\n", who);
    return 2;
  }
  // The scans first (the progress bar needs their count).
  reg::FlaserLog log = reg::read_flaser_log(o.input, 0, o.max_scans > 0 ? o.max_scans - 1 : -1);
  if (!log.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, log.error.c_str());
    return 1;
  }
  const std::vector<reg::LaserScan2>& scans = log.scans;
  const long refused = log.refused;
  const std::string& first_error = log.first_error;
  if (scans.size() < 2) {
    std::fprintf(stderr, "%s: %s holds %zu FLASER scans; at least 2 are needed%s%s\n", who, o.input.c_str(), scans.size(),
                 first_error.empty() ? "" : "; ", first_error.c_str());
    return 1;
  }

  reg::OdometryConfig config;
  config.planar = true;
  config.voxel = o.voxel;
  config.local_scans = o.local_scans;
  config.keyframe_distance = o.keyframe_distance;
  config.gicp.max_correspondence_distance = static_cast<float>(o.max_correspondence);
  config.max_points = 4096;
  config.gicp.max_iterations = o.max_iterations;
  config.constant_velocity = !o.no_prediction;
  config.two_starts = !o.one_start;
  reg::LidarOdometry odometry(config);
  std::vector<Eigen::Isometry3d> reference, estimate;
  std::vector<reg::Point> points;
  points.reserve(config.max_points);
  std::unique_ptr<ProgressBar> bar;
  if (!o.quiet) bar = std::make_unique<ProgressBar>("lidar odometry", static_cast<double>(scans.size()), "scans");
  const auto t0 = std::chrono::steady_clock::now();
  const Eigen::Isometry3d start = reg::to_isometry(scans.front().pose);
  std::size_t no_room = 0;  // returns beyond a scan's point buffer (none while scans have at most 4096 beams)
  for (std::size_t i = 0; i < scans.size(); ++i) {
    points.clear();
    no_room += reg::scan_points(scans[i], o.max_range, 0.05f, points);
    estimate.push_back(start * odometry.add(points));
    reference.push_back(reg::to_isometry(scans[i].pose));
    if (bar) bar->update(static_cast<double>(i + 1));
  }
  if (bar) bar->finish();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const reg::RelativePoseError rpe = reg::relative_pose_error(reference, estimate, 10.0);
  if (!o.poses_out.empty()) {
    std::FILE* out = std::fopen(o.poses_out.c_str(), "w");
    if (out == nullptr) {
      std::fprintf(stderr, "%s: cannot write %s\n", who, o.poses_out.c_str());
      return 1;
    }
    std::fprintf(out, "timestamp,x,y,theta,ref_x,ref_y,ref_theta\n");
    for (std::size_t i = 0; i < estimate.size(); ++i) {
      const Eigen::Isometry3d& e = estimate[i];
      const Eigen::Isometry3d& r = reference[i];
      std::fprintf(out, "%.6f,%.4f,%.4f,%.5f,%.4f,%.4f,%.5f\n", scans[i].timestamp, e.translation().x(), e.translation().y(),
                   std::atan2(e.linear()(1, 0), e.linear()(0, 0)), r.translation().x(), r.translation().y(),
                   std::atan2(r.linear()(1, 0), r.linear()(0, 0)));
    }
    std::fclose(out);
  }
  const double path = reg::path_length(reference);
  const double end_error = (estimate.back().translation() - reference.back().translation()).norm();
  const auto& c = odometry.counters();
  // Loop closures over the odometry's keyframes, the graph solved by SMF.
  std::string loops;
  eval::LoopEvalResult lr;
  const eval::LoopEvalOptions lo = loop_options(o, eval::default_loop_eval_options());
  if (o.loops) {
    std::unique_ptr<ProgressBar> lbar;
    eval::LoopEvalOptions with_bar = lo;
    if (!o.quiet) {
      lbar = std::make_unique<ProgressBar>("loop closures", 1.0, "");
      with_bar.progress = [&](double f) { lbar->update(f); };
    }
    lr = eval::evaluate_loops(scans, estimate, with_bar);
    if (lbar) lbar->finish();
    if (!lr.error.empty()) {
      std::fprintf(stderr, "%s: %s\n", who, lr.error.c_str());
      return 2;
    }
    loops = loops_json(lr);
  }
  if (o.report == "json") {
    std::printf(
        "{\"input\": \"%s\", \"scans\": %zu, \"refused_lines\": %ld, \"returns_dropped\": %zu, \"path_m\": %s, \"keyframes\": %llu, "
        "\"not_converged\": %llu, \"second_start\": %llu, \"rejected\": %llu, \"rpe_translation_percent\": %s, \"rpe_rotation_deg_per_100m\": %s, "
        "\"segments\": %zu, \"end_error_m\": %s, \"ms_per_scan\": %s%s}\n",
        o.input.c_str(), scans.size(), refused, no_room, num(path, 3).c_str(), static_cast<unsigned long long>(c.keyframes),
        static_cast<unsigned long long>(c.not_converged), static_cast<unsigned long long>(c.second_start),
        static_cast<unsigned long long>(c.rejected), num(rpe.translation_percent, 4).c_str(), num(rpe.rotation_deg_per_100m, 4).c_str(), rpe.segments,
        num(end_error, 3).c_str(), num(1000.0 * seconds / static_cast<double>(scans.size()), 3).c_str(), loops.c_str());
    return 0;
  }
  std::printf("lidar odometry (scan to the last %d keyframes, GICP, voxel %.2f m) over %s\n", o.local_scans,
              static_cast<double>(o.voxel), o.input.c_str());
  std::printf("  %zu scans, %.1f m of the log's path, %llu keyframes, %llu registrations not converged, %llu answers "
              "from the second start (the last pose), %llu rejected\n",
              scans.size(), path, static_cast<unsigned long long>(c.keyframes),
              static_cast<unsigned long long>(c.not_converged), static_cast<unsigned long long>(c.second_start),
              static_cast<unsigned long long>(c.rejected));
  if (refused > 0) std::printf("  %ld FLASER lines refused, the first: %s\n", refused, first_error.c_str());
  if (no_room > 0) std::printf("  %zu returns dropped: more beams than a scan's buffer holds\n", no_room);
  std::printf("  relative pose error per 10 m against the log's poses (%zu segments): %.3f %% translation, %.3f deg/100 m\n",
              rpe.segments, rpe.translation_percent, rpe.rotation_deg_per_100m);
  std::printf("  end point %.2f m from the log's; %.2f ms a scan\n", end_error, 1000.0 * seconds / static_cast<double>(scans.size()));
  if (o.loops) print_loops(lr, lo);
  return 0;
}

}  // namespace

void add_lidar_odometry_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "lidar-odometry",
      "Lidar odometry by scan-to-local-map Generalized ICP (thesis section 2.5) over a CARMEN log's 2D laser\n"
      "scans (FLASER lines; plain or gzip), scored against the log's own poses, or over a spinning lidar's\n"
      "recording (a directory), capture (.pcap, .pcapng, raw .bin) or sequence of point-cloud files (KITTI\n"
      ".bin, PCD, PLY; a revolution each): each revolution de-skewed with the\n"
      "last motion and the columns' firing times, scored against a simulated recording's truth. The measure:\n"
      "the relative pose error per 10 m of travel (translation in percent, rotation in degrees per 100 m), as\n"
      "KITTI's benchmark defines it. The 3D input's defaults: --voxel 0.25, --local-scans 10,\n"
      "--keyframe-distance 1, --max-correspondence 1, --max-range 80.\n"
      "Examples:\n"
      "  trailnav lidar-odometry ../shared/data/carmen/freiburg-079-corrected.log.gz --report json\n"
      "  trailnav sim --scenario urban --out build/sim/urban && trailnav lidar-odometry build/sim/urban");
  static Options o;
  cmd->add_option("input", o.input, "CARMEN log (.log or .log.gz), a lidar recording directory or capture, or the first of a sequence of point-cloud files (KITTI .bin, PCD, PLY)")->required();
  cmd->add_option("more", o.more, "The rest of a sequence of point-cloud files, in order");
  cmd->add_option("--report", o.report, "json: one JSON object (rpe_translation_percent, rpe_rotation_deg_per_100m, ...)");
  // The 3D input has its own defaults for these, where the user gave none.
  CLI::Option* voxel = cmd->add_option("--voxel", o.voxel, "Voxel size of the scans and the local map (m)")->capture_default_str();
  CLI::Option* local = cmd->add_option("--local-scans", o.local_scans, "Keyframes in the local map")->capture_default_str();
  CLI::Option* keyframe =
      cmd->add_option("--keyframe-distance", o.keyframe_distance, "Travel between keyframes (m)")->capture_default_str();
  CLI::Option* gate =
      cmd->add_option("--max-correspondence", o.max_correspondence, "Associations farther are dropped (m)")->capture_default_str();
  CLI::Option* range =
      cmd->add_option("--max-range", o.max_range, "Ranges at or beyond are no return (m; the SICK's 81.91 m is none)")
          ->capture_default_str();
  cmd->add_option("--calibration", o.calibration,
                  "A lidar input's calibration (a file, or builtin); default: the recording's or the model's");
  cmd->add_flag("--no-deskew", o.no_deskew, "A lidar input's revolutions as they are, without motion compensation");
  cmd->add_flag("--wheel-prior", o.wheel_prior,
                "A simulated recording's wheel and IMU odometry (its CAN and IMU streams through the pose estimator, as "
                "trailnavd's pose thread) predicts each registration and de-skews each revolution, instead of the last "
                "motion repeated: what pins the motion where the scene does not (a straight street across an open square)");
  cmd->add_option("--max-iterations", o.max_iterations, "GICP iterations per scan at most")->capture_default_str();
  cmd->add_option("--max-scans", o.max_scans, "Use only the first N scans (0: all)")->capture_default_str();
  cmd->add_option("--poses-out", o.poses_out, "CSV of every scan's estimated and reference pose (CARMEN: timestamp,x,y,theta,ref_x,ref_y,ref_theta; a lidar: timestamp,x,y,z,yaw,ref_x,ref_y,ref_z,ref_yaw and how well the registration pinned the translation: weakest,strongest (the largest and smallest eigenvalues of the covariance of the sensor's position) and weak_x,weak_y,weak_z (the direction of the largest; a straight street between flat sides leaves its length unpinned))");
  cmd->add_flag("--no-prediction", o.no_prediction, "Start each registration at the last pose instead of the last motion repeated");
  cmd->add_flag("--one-start", o.one_start,
                "Register from the prediction only (by default a second registration starts at the last pose when the "
                "prediction moved away from it, and the answer with the smaller truncated cost is kept)");
  cmd->add_flag("--loops", o.loops,
                "Also close loops: keyframes (a CARMEN log's every metre, a lidar's every 2 m) in a pose graph, each new one registered by GICP onto "
                "earlier ones the map puts near it (verified by overlap, RMS and the jump from the map's guess), the "
                "graph solved by SMF after each closure; reports the keyframes' errors before and after (JSON \"loops\": its counts, and \"before\" and \"after\" with rpe_translation_percent, rpe_rotation_deg_per_100m, end_error_m, ate_rmse_m)");
  cmd->add_option("--loop-radius", o.loop_radius, "Candidates within this of the new keyframe by the map's poses (m; default 4, a lidar's 8)");
  cmd->add_option("--loop-min-path", o.loop_min_path, "Driving between a candidate and the new keyframe at least (m; default 15, a lidar's 25)");
  cmd->add_option("--loop-max-rms", o.loop_max_rms, "A closure's points' RMS distance from the surfaces they joined (along their normals) at most (m; default 0.04, a lidar's 0.1)");
  cmd->add_flag("--quiet", o.quiet, "No progress bar");
  cmd->callback([=] {
    o.set_voxel = voxel->count() > 0;
    o.set_local = local->count() > 0;
    o.set_keyframe = keyframe->count() > 0;
    o.set_gate = gate->count() > 0;
    o.set_range = range->count() > 0;
    std::exit(run(o));
  });
}

}  // namespace trailnav::cli
