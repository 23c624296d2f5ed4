#include "station_eval.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "random.hpp"
#include "station_world.hpp"

namespace trailnav::eval {

namespace reg = perception::registration;
namespace st = sim::station;

namespace {

ErrorStats stats_of(const std::vector<double>& v) {
  ErrorStats s;
  if (v.empty()) return s;
  double sum = 0.0;
  for (double x : v) sum += x;
  s.mean = sum / static_cast<double>(v.size());
  double var = 0.0;
  for (double x : v) var += (x - s.mean) * (x - s.mean);
  s.std = std::sqrt(var / static_cast<double>(v.size()));
  s.max = *std::max_element(v.begin(), v.end());
  return s;
}

// The error of an estimated pose against the true one, its translation
// taken at `at` (in the frame the poses map into): for an object, where the
// robot believes the object's centre is against where it is — the figure a
// docking or loading task needs, and not the object's rotation error times
// the robot's distance from it.
void error_of(const Eigen::Isometry3d& truth, const Eigen::Isometry3d& estimate, double& mm, double& deg,
              const Eigen::Vector3d& at = Eigen::Vector3d::Zero()) {
  mm = 1000.0 * (estimate.inverse() * at - truth.inverse() * at).norm();
  deg = Eigen::AngleAxisd((truth.inverse() * estimate).linear()).angle() * 180.0 / std::numbers::pi;
}

// The rigid motion D (world -> taught frame) that best lays the true teach
// poses onto the refined ones (least squares over their positions, 2D):
// the taught station frame is the teach-in's own, anchored by its first
// scan, and may sit a few millimetres from the world's as a whole. Truth
// is compared in the taught frame, as trajectories are aligned before an
// absolute trajectory error is taken.
Eigen::Isometry3d taught_frame(const std::vector<st::Pose2>& truth, const std::vector<reg::StationScan>& scans) {
  const std::size_t n = std::min(truth.size(), scans.size());
  Eigen::Vector2d tq = Eigen::Vector2d::Zero(), tp = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    tq += Eigen::Vector2d(truth[i].x, truth[i].y);
    tp += scans[i].pose.translation().head<2>();
  }
  tq /= static_cast<double>(n);
  tp /= static_cast<double>(n);
  double sxx = 0.0, sxy = 0.0, syx = 0.0, syy = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d q = Eigen::Vector2d(truth[i].x, truth[i].y) - tq;
    const Eigen::Vector2d p = scans[i].pose.translation().head<2>() - tp;
    sxx += q.x() * p.x();
    sxy += q.x() * p.y();
    syx += q.y() * p.x();
    syy += q.y() * p.y();
  }
  const double angle = std::atan2(sxy - syx, sxx + syy);
  Eigen::Isometry3d d = Eigen::Isometry3d::Identity();
  d.linear() = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector2d t = tp - d.linear().topLeftCorner<2, 2>() * tq;
  d.translation() = Eigen::Vector3d(t.x(), t.y(), 0.0);
  return d;
}

}  // namespace

StationEvalResult evaluate_station_sim(const StationEvalOptions& options) {
  StationEvalResult result;
  if (const std::string e = reg::check_station_config(options.station); !e.empty()) {
    result.error = "station: " + e;
    return result;
  }
  if (options.runs < 1 || options.teach_scans < 2 || options.visit_scans < 1) {
    result.error = "runs and visit scans at least 1, teach scans at least 2";
    return result;
  }
  const st::World world = st::thesis_world();
  st::LaserConfig laser;
  laser.sigma *= options.noise;
  std::vector<st::Pose2> taught;
  for (const st::ObjectShape& o : world.objects) taught.push_back(o.pose);
  const double total = static_cast<double>(world.objects.size() * st::kThesisSets.size()) * options.runs;
  double done = 0.0;

  for (std::size_t k = 0; k < world.objects.size(); ++k) {
    const st::ObjectShape& object = world.objects[k];
    StationObjectResult obj;
    obj.name = object.name;
    const std::uint64_t object_key = sim::hash(options.seed, 0x57A7, k);

    // Teach-in: the true first pose anchors the station frame (the world's);
    // the others follow the noisy odometry until the joint registration.
    std::vector<st::Segment> segments = world.walls;
    const std::vector<st::Segment> objects_taught = st::object_segments(world, taught);
    segments.insert(segments.end(), objects_taught.begin(), objects_taught.end());
    const st::Drive teach = st::teach_drive(object, options.teach_scans, sim::hash(object_key, 1), options.noise);
    std::vector<reg::StationScan> scans(teach.truth.size());
    st::Pose2 guess = teach.truth.front();
    for (std::size_t i = 0; i < teach.truth.size(); ++i) {
      if (i > 0) guess = st::compose(guess, teach.odometry[i]);
      scans[i].points = st::cast(segments, teach.truth[i], laser, sim::hash(object_key, 2, i));
      scans[i].pose = st::to_isometry(guess);
    }
    reg::TeachResult t;
    if (options.teach_truth) {
      for (std::size_t i = 0; i < scans.size(); ++i) scans[i].pose = st::to_isometry(teach.truth[i]);
    } else {
      t = reg::teach(scans, options.station);
    }
    obj.teach_rounds = t.rounds;
    obj.teach_converged = t.converged;
    obj.teach_largest_correction = t.largest_correction;
    const Eigen::Isometry3d frame = taught_frame(teach.truth, scans);
    for (std::size_t i = 0; i < scans.size(); ++i) {
      double mm = 0.0, deg = 0.0;
      error_of((frame * st::to_isometry(teach.truth[i])).inverse(), scans[i].pose.inverse(), mm, deg);
      obj.teach_error_mm = std::max(obj.teach_error_mm, mm);
      obj.teach_error_deg = std::max(obj.teach_error_deg, deg);
    }
    reg::StationObject marked{object.name, {object.mark.begin(), object.mark.end()}};
    reg::BuiltStation built = reg::build_station(scans, std::span<const reg::StationObject>(&marked, 1), options.station);
    if (!built.error.empty()) {
      result.error = object.name + ": " + built.error;
      return result;
    }
    obj.surroundings_points = built.station.taught_points[0];
    obj.object_points = built.station.taught_points[1];
    reg::StationLocaliser localiser(built.station, options.station);

    for (std::size_t s = 0; s < st::kThesisSets.size(); ++s) {
      const st::MoveSet& set = st::kThesisSets[s];
      StationSetResult sr;
      sr.set = static_cast<int>(s + 1);
      sr.translation = set.translation;
      sr.rotation = set.rotation;
      std::vector<double> tm, rd, stm, srd;
      for (int run = 0; run < options.runs; ++run) {
        const std::uint64_t key = sim::hash(object_key, 100 + s, static_cast<std::uint64_t>(run));
        const st::Pose2 move = st::move_of(object, set, sim::hash(key, 1));
        std::vector<st::Pose2> now = taught;
        now[k] = st::compose(move, object.pose);
        std::vector<st::Segment> seen = world.walls;
        const std::vector<st::Segment> objects_now = st::object_segments(world, now);
        seen.insert(seen.end(), objects_now.begin(), objects_now.end());
        const st::Drive visit = st::visit_drive(object, options.visit_scans, sim::hash(key, 2), options.noise);
        sim::Rng rng(key, 3);
        const st::Pose2 start{visit.truth.front().x + options.noise * options.start_sigma_xy * rng.normal(),
                              visit.truth.front().y + options.noise * options.start_sigma_xy * rng.normal(),
                              visit.truth.front().theta + options.noise * options.start_sigma_theta * rng.normal()};
        localiser.begin(st::to_isometry(start));
        for (std::size_t i = 0; i < visit.truth.size(); ++i) {
          const std::vector<Eigen::Vector3f> pts = st::cast(seen, visit.truth[i], laser, sim::hash(key, 4, i));
          localiser.add(pts, st::to_isometry(visit.odometry[i]));
        }
        // Truth: the object's reference frame is the station's as taught;
        // it moved by M, so the robot's pose in it is M⁻¹ · R.
        const Eigen::Isometry3d truth = frame * st::to_isometry(st::inverse(move)) * st::to_isometry(visit.truth.back());
        const reg::StationFix fix = localiser.localise();
        if (!fix.bodies[1].observed) ++sr.unobserved;
        double mm = 0.0, deg = 0.0;
        const Eigen::Vector3d centre = frame * Eigen::Vector3d(object.pose.x, object.pose.y, 0.0);  // taught frame
        error_of(truth, fix.bodies[1].transform, mm, deg, centre);
        tm.push_back(mm);
        rd.push_back(deg);
        const reg::GicpResult single = localiser.localise_single();
        error_of(truth, single.transform, mm, deg, centre);
        stm.push_back(mm);
        srd.push_back(deg);
        done += 1.0;
        if (options.progress) options.progress(done / total);
      }
      sr.runs = options.runs;
      sr.translation_mm = stats_of(tm);
      sr.rotation_deg = stats_of(rd);
      sr.single_translation_mm = stats_of(stm);
      sr.single_rotation_deg = stats_of(srd);
      obj.sets.push_back(sr);
    }
    result.objects.push_back(std::move(obj));
  }
  return result;
}

}  // namespace trailnav::eval
