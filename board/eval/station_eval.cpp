#include "station_eval.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <numbers>

#include "random.hpp"
#include "station_world.hpp"
#include "trailnav/perception/registration/carmen.hpp"

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

void finish_set(StationSetResult& sr, int runs, const std::vector<double>& tm, const std::vector<double>& rd,
                const std::vector<double>& stm, const std::vector<double>& srd) {
  sr.runs = runs;
  sr.translation_mm = stats_of(tm);
  sr.rotation_deg = stats_of(rd);
  sr.single_translation_mm = stats_of(stm);
  sr.single_rotation_deg = stats_of(srd);
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

void picture_of(const reg::Station& station, const reg::StationLocaliser& localiser, const reg::StationFix& fix,
                StationObjectResult& obj) {
  auto flat = [](const std::vector<reg::Point>& in, const Eigen::Isometry3d& t, std::vector<Eigen::Vector2f>& out) {
    out.clear();
    const Eigen::Isometry3f tf = t.cast<float>();
    for (const reg::Point& p : in) out.push_back((tf * p).head<2>());
  };
  flat(station.bodies[0].cloud.points, Eigen::Isometry3d::Identity(), obj.taught_surroundings);
  flat(station.bodies[1].cloud.points, Eigen::Isometry3d::Identity(), obj.taught_object);
  flat(localiser.local_points().points, fix.bodies[0].transform, obj.last_visit);
  flat(station.bodies[1].cloud.points, fix.moved(1), obj.object_moved);
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
        if (s + 1 == st::kThesisSets.size() && run + 1 == options.runs) {
          picture_of(built.station, localiser, fix, obj);
          obj.centre = centre.head<2>();
          obj.last_error_mm = mm;
          obj.last_error_deg = deg;
        }
        const reg::GicpResult single = localiser.localise_single();
        error_of(truth, single.transform, mm, deg, centre);
        stm.push_back(mm);
        srd.push_back(deg);
        done += 1.0;
        if (options.progress) options.progress(done / total);
      }
      finish_set(sr, options.runs, tm, rd, stm, srd);
      obj.sets.push_back(sr);
    }
    result.objects.push_back(std::move(obj));
  }
  return result;
}

}  // namespace trailnav::eval

// --- cases constructed from a real CARMEN log ---

namespace trailnav::eval {

namespace {

// The real experiment's sets (§4.3.2): 0.1 m, 10°, both.
constexpr st::MoveSet kRealSets[] = {{0.10, 0.0}, {0.0, 10.0 * std::numbers::pi / 180.0}, {0.10, 10.0 * std::numbers::pi / 180.0}};

Eigen::Isometry3d planar(double x, double y, double theta) { return reg::to_isometry(reg::Pose2{x, y, theta}); }


struct Cluster {
  Eigen::Vector2d lo{1e9, 1e9}, hi{-1e9, -1e9};
  std::size_t points = 0;
};

// Connected groups of returns on a 5 cm grid (8-neighbourhood): walls are
// long groups, free-standing things short ones.
std::vector<Cluster> clusters_of(const std::vector<reg::Point>& points) {
  constexpr double kCell = 0.05;
  std::map<std::pair<long, long>, std::vector<std::size_t>> cells;
  for (std::size_t i = 0; i < points.size(); ++i) {
    cells[{std::lround(std::floor(static_cast<double>(points[i].x()) / kCell)),
           std::lround(std::floor(static_cast<double>(points[i].y()) / kCell))}]
        .push_back(i);
  }
  std::map<std::pair<long, long>, int> label;
  std::vector<Cluster> out;
  for (const auto& [key, idx] : cells) {
    if (label.count(key) != 0) continue;
    const int id = static_cast<int>(out.size());
    out.emplace_back();
    std::vector<std::pair<long, long>> todo{key};
    label[key] = id;
    while (!todo.empty()) {
      const auto c = todo.back();
      todo.pop_back();
      for (std::size_t i : cells[c]) {
        const Eigen::Vector2d p = points[i].head<2>().cast<double>();
        out[static_cast<std::size_t>(id)].lo = out[static_cast<std::size_t>(id)].lo.cwiseMin(p);
        out[static_cast<std::size_t>(id)].hi = out[static_cast<std::size_t>(id)].hi.cwiseMax(p);
        ++out[static_cast<std::size_t>(id)].points;
      }
      for (long dx = -1; dx <= 1; ++dx) {
        for (long dy = -1; dy <= 1; ++dy) {
          const std::pair<long, long> n{c.first + dx, c.second + dy};
          if (cells.count(n) != 0 && label.count(n) == 0) {
            label[n] = id;
            todo.push_back(n);
          }
        }
      }
    }
  }
  return out;
}

// One visit scan with the object's returns moved by `move` (log frame) and
// the occlusion cast again beam by beam.
std::vector<reg::Point> moved_scan(const reg::LaserScan2& scan, const Eigen::Isometry3d& pose, float max_range,
                                   const std::vector<Eigen::Vector2d>& polygon, const Eigen::Isometry3d& move) {
  const std::size_t n = scan.ranges.size();
  const double step = (n % 2 == 1 ? std::numbers::pi / static_cast<double>(n - 1) : std::numbers::pi / static_cast<double>(n));
  std::vector<reg::Point> all;
  all.reserve(n);
  reg::scan_points(scan, max_range, 0.05f, all);
  auto beam_of = [&](const reg::Point& p) {
    return std::lround((std::atan2(static_cast<double>(p.y()), static_cast<double>(p.x())) + 0.5 * std::numbers::pi) / step);
  };
  std::vector<float> background(n, std::numeric_limits<float>::infinity());
  std::vector<reg::Point> kept, object;
  const Eigen::Isometry3d back = pose.inverse() * move * pose;  // laser frame -> moved -> laser frame
  for (const reg::Point& p : all) {
    const Eigen::Vector3d w = pose * p.cast<double>();
    if (reg::inside(polygon, w.head<2>())) {
      object.push_back((back * p.cast<double>()).cast<float>());
    } else {
      kept.push_back(p);
      const long b = beam_of(p);
      if (b >= 0 && b < static_cast<long>(n)) background[static_cast<std::size_t>(b)] = p.head<2>().norm();
    }
  }
  constexpr float kMargin = 0.02f;
  std::vector<float> nearest_object(n, std::numeric_limits<float>::infinity());
  std::vector<reg::Point> out;
  out.reserve(all.size());
  for (const reg::Point& p : object) {
    const long b = beam_of(p);
    if (b < 0 || b >= static_cast<long>(n)) continue;  // moved out of the field of view
    const float r = p.head<2>().norm();
    if (background[static_cast<std::size_t>(b)] < r - kMargin) continue;  // behind what the beam hit
    nearest_object[static_cast<std::size_t>(b)] = std::min(nearest_object[static_cast<std::size_t>(b)], r);
    out.push_back(p);
  }
  for (const reg::Point& p : kept) {
    const long b = beam_of(p);
    if (b >= 0 && b < static_cast<long>(n) && nearest_object[static_cast<std::size_t>(b)] < p.head<2>().norm() - kMargin) {
      continue;  // now hidden by the moved object
    }
    out.push_back(p);
  }
  return out;
}

}  // namespace

StationEvalResult evaluate_station_carmen(const StationCarmenOptions& options) {
  StationEvalResult result;
  if (const std::string e = reg::check_station_config(options.station); !e.empty()) {
    result.error = "station: " + e;
    return result;
  }
  reg::FlaserLog log = reg::read_flaser_log(options.log);
  if (!log.error.empty()) {
    result.error = log.error;
    return result;
  }
  const std::vector<reg::LaserScan2>& scans = log.scans;
  const int teach_n = options.teach_scans, visit_n = options.visit_scans;
  if (scans.size() < static_cast<std::size_t>(teach_n + visit_n) * 2) {
    result.error = options.log + " holds " + std::to_string(scans.size()) + " FLASER scans: too few for a teach-in and a visit";
    return result;
  }
  auto pose_of = [&](std::size_t i) { return reg::to_isometry(scans[i].pose); };

  // Places passed twice: a teach-in block and, a minute or more later, a
  // scan within 0.4 m and 20° of its middle.
  struct Place {
    std::size_t teach, visit;
  };
  std::vector<Place> places;
  for (std::size_t i = 0; i + static_cast<std::size_t>(teach_n) < scans.size() && places.size() < 64; i += 40) {
    const reg::LaserScan2& mid = scans[i + static_cast<std::size_t>(teach_n / 2)];
    double best = 0.4;
    std::size_t at = 0;
    for (std::size_t j = static_cast<std::size_t>(visit_n); j + static_cast<std::size_t>(visit_n) < scans.size(); ++j) {
      if (std::abs(scans[j].timestamp - mid.timestamp) < 60.0) continue;
      const double d = std::hypot(scans[j].pose.x - mid.pose.x, scans[j].pose.y - mid.pose.y);
      const double a = std::abs(std::remainder(scans[j].pose.theta - mid.pose.theta, 2.0 * std::numbers::pi));
      if (d < best && a < 0.35) {
        best = d;
        at = j;
      }
    }
    if (at != 0) places.push_back({i, at + 1 - static_cast<std::size_t>(visit_n)});
  }
  const double total = static_cast<double>(std::min<std::size_t>(places.size(), static_cast<std::size_t>(options.places))) *
                       std::size(kRealSets) * options.runs;
  double done = 0.0;
  for (const Place& place : places) {
    if (result.objects.size() >= static_cast<std::size_t>(options.places)) break;
    const std::uint64_t key = sim::hash(options.seed, 0xCA73, place.teach);
    // The teach-in: the log's steps with odometry noise, refined.
    std::vector<reg::StationScan> teach(static_cast<std::size_t>(teach_n));
    std::vector<Eigen::Isometry3d> logged(teach.size());
    sim::Rng rng(key, 1);
    for (std::size_t k = 0; k < teach.size(); ++k) {
      const std::size_t i = place.teach + k;
      logged[k] = pose_of(i);
      teach[k].points.reserve(scans[i].ranges.size());
      reg::scan_points(scans[i], options.max_range, 0.05f, teach[k].points);
      teach[k].pose = k == 0 ? logged[0]
                             : Eigen::Isometry3d(teach[k - 1].pose * logged[k - 1].inverse() * logged[k] *
                                                 planar(options.odometry_sigma_xy * rng.normal(),
                                                        options.odometry_sigma_xy * rng.normal(),
                                                        options.odometry_sigma_theta * rng.normal()));
    }
    const reg::TeachResult taught = reg::teach(teach, options.station);
    // The taught frame against the log's: D (log -> taught), as in the simulation.
    std::vector<st::Pose2> log_poses;
    for (const auto& l : logged) {
      const reg::Pose2 p = reg::to_pose2(l);
      log_poses.push_back({p.x, p.y, p.theta});
    }
    const Eigen::Isometry3d frame = taught_frame(log_poses, teach);
    // The object: the free-standing cluster with the most returns.
    std::vector<reg::Point> merged;
    for (const auto& s : teach) {
      for (const reg::Point& p : s.points) merged.push_back((s.pose * p.cast<double>()).cast<float>());
    }
    const Eigen::Vector2d middle = teach[teach.size() / 2].pose.translation().head<2>();
    const Cluster* chosen = nullptr;
    const std::vector<Cluster> groups = clusters_of(merged);
    for (const Cluster& c : groups) {
      const double extent = (c.hi - c.lo).maxCoeff(), width = (c.hi - c.lo).minCoeff();
      const double distance = (0.5 * (c.lo + c.hi) - middle).norm();
      // Not a line (a wall's piece slides along itself): at least 0.2 m
      // across both ways, as the thesis' box, shelf and table.
      if (width < 0.2 || extent > 1.5 || c.points < 60 || distance < 0.7 || distance > 4.0) continue;
      if (chosen == nullptr || c.points > chosen->points) chosen = &c;
    }
    if (chosen == nullptr) continue;  // no free-standing object at this place
    constexpr double kPad = 0.04;
    const std::vector<Eigen::Vector2d> polygon_taught{{chosen->lo.x() - kPad, chosen->lo.y() - kPad},
                                                      {chosen->hi.x() + kPad, chosen->lo.y() - kPad},
                                                      {chosen->hi.x() + kPad, chosen->hi.y() + kPad},
                                                      {chosen->lo.x() - kPad, chosen->hi.y() + kPad}};
    std::vector<Eigen::Vector2d> polygon_log;
    for (const auto& c : polygon_taught) polygon_log.push_back((frame.inverse() * Eigen::Vector3d(c.x(), c.y(), 0.0)).head<2>());
    const reg::StationObject object{"object", polygon_taught};
    const reg::BuiltStation built = reg::build_station(teach, std::span<const reg::StationObject>(&object, 1), options.station);
    if (!built.error.empty()) continue;
    // Seen again in the visit?
    std::size_t seen_again = 0;
    for (int k = 0; k < visit_n; ++k) {
      const std::size_t j = place.visit + static_cast<std::size_t>(k);
      std::vector<reg::Point> pts;
      pts.reserve(scans[j].ranges.size());
      reg::scan_points(scans[j], options.max_range, 0.05f, pts);
      for (const reg::Point& p : pts) seen_again += reg::inside(polygon_log, (pose_of(j) * p.cast<double>()).head<2>()) ? 1u : 0u;
    }
    if (seen_again < 60) continue;

    StationObjectResult obj;
    const Eigen::Vector2d centre_t = 0.5 * (chosen->lo + chosen->hi);
    const Eigen::Vector3d centre_taught(centre_t.x(), centre_t.y(), 0.0);
    const Eigen::Vector3d centre_log = frame.inverse() * centre_taught;
    char where[200];
    std::snprintf(where, sizeof where, "scans %zu-%zu (%.0f s) and %zu-%zu (%.0f s); object at (%.2f, %.2f) m, %.2f x %.2f m",
                  place.teach, place.teach + teach.size() - 1, scans[place.teach].timestamp, place.visit,
                  place.visit + static_cast<std::size_t>(visit_n) - 1, scans[place.visit].timestamp, centre_log.x(),
                  centre_log.y(), chosen->hi.x() - chosen->lo.x(), chosen->hi.y() - chosen->lo.y());
    obj.name = "place " + std::to_string(result.objects.size() + 1);
    obj.where = where;
    obj.teach_rounds = taught.rounds;
    obj.teach_converged = taught.converged;
    obj.teach_largest_correction = taught.largest_correction;
    obj.teach_error_mm = obj.teach_error_deg = -1.0;  // no truth for the poses of a real log
    obj.surroundings_points = built.station.taught_points[0];
    obj.object_points = built.station.taught_points[1];
    reg::StationLocaliser localiser(built.station, options.station);
    // A visit as it was (nothing moved by us): a real object may have been
    // moved by people between the two passes, minutes apart, and then the
    // applied motion is not the truth. Such a place is left out.
    auto visit = [&](const Eigen::Isometry3d& move, std::uint64_t rk) {
      sim::Rng noise(rk, 3);
      const Eigen::Isometry3d start = frame * pose_of(place.visit) *
                                      planar(options.start_sigma_xy * noise.normal(), options.start_sigma_xy * noise.normal(),
                                             options.start_sigma_theta * noise.normal());
      localiser.begin(start);
      for (int k = 0; k < visit_n; ++k) {
        const std::size_t j = place.visit + static_cast<std::size_t>(k);
        const std::vector<reg::Point> pts = moved_scan(scans[j], pose_of(j), options.max_range, polygon_log, move);
        const Eigen::Isometry3d odometry =
            k == 0 ? Eigen::Isometry3d::Identity()
                   : Eigen::Isometry3d(pose_of(j - 1).inverse() * pose_of(j) *
                                       planar(options.odometry_sigma_xy * noise.normal(), options.odometry_sigma_xy * noise.normal(),
                                              options.odometry_sigma_theta * noise.normal()));
        localiser.add(pts, odometry);
      }
      return localiser.localise();
    };
    {
      // Judged by the log's own poses, not by the registration under test:
      // the object's returns of the second pass must lie within 5 cm of the
      // taught object's, nine in ten of them.
      std::size_t near = 0, all = 0;
      for (int k = 0; k < visit_n; ++k) {
        const std::size_t j = place.visit + static_cast<std::size_t>(k);
        std::vector<reg::Point> pts;
        pts.reserve(scans[j].ranges.size());
        reg::scan_points(scans[j], options.max_range, 0.05f, pts);
        for (const reg::Point& p : pts) {
          const Eigen::Vector3d w = pose_of(j) * p.cast<double>();
          if (!reg::inside(polygon_log, w.head<2>())) continue;
          std::uint32_t at = 0;
          float d2 = 0.0f;
          ++all;
          if (built.station.bodies[1].tree.nearest((frame * w).cast<float>(), at, d2) && d2 < 0.05f * 0.05f) ++near;
        }
      }
      if (10 * near < 9 * all) {
        ++result.places_changed;
        continue;
      }
    }
    for (std::size_t s = 0; s < std::size(kRealSets); ++s) {
      const st::MoveSet& set = kRealSets[s];
      StationSetResult sr;
      sr.set = static_cast<int>(s + 1);
      sr.translation = set.translation;
      sr.rotation = set.rotation;
      std::vector<double> tm, rd, stm, srd;
      for (int run = 0; run < options.runs; ++run) {
        const std::uint64_t rk = sim::hash(key, 100 + s, static_cast<std::uint64_t>(run));
        // The motion about the object's centre (log frame), direction and sign drawn.
        const double direction = 2.0 * std::numbers::pi * sim::unit(sim::hash(rk, 1));
        const double phi = (sim::unit(sim::hash(rk, 2)) < 0.5 ? -1.0 : 1.0) * set.rotation;
        const Eigen::Isometry3d move = Eigen::Translation3d(centre_log + Eigen::Vector3d(set.translation * std::cos(direction),
                                                                                           set.translation * std::sin(direction), 0.0)) *
                                       Eigen::AngleAxisd(phi, Eigen::Vector3d::UnitZ()) * Eigen::Translation3d(-centre_log);
        const reg::StationFix fix = visit(move, rk);
        const Eigen::Isometry3d truth = frame * move * frame.inverse();  // the motion in the taught frame
        const Eigen::Isometry3d estimate = fix.moved(1);
        tm.push_back(1000.0 * (estimate * centre_taught - truth * centre_taught).norm());
        rd.push_back(Eigen::AngleAxisd((truth.inverse() * estimate).linear()).angle() * 180.0 / std::numbers::pi);
        if (s + 1 == std::size(kRealSets) && run + 1 == options.runs) {
          picture_of(built.station, localiser, fix, obj);
          obj.centre = centre_taught.head<2>();
          obj.last_error_mm = tm.back();
          obj.last_error_deg = rd.back();
        }
        // One body: its transform for the object too; the motion it implies
        // against the surroundings' transform of the multi-body answer.
        const reg::GicpResult single = localiser.localise_single();
        const Eigen::Isometry3d single_moved = fix.bodies[0].transform * single.transform.inverse();
        stm.push_back(1000.0 * (single_moved * centre_taught - truth * centre_taught).norm());
        srd.push_back(Eigen::AngleAxisd((truth.inverse() * single_moved).linear()).angle() * 180.0 / std::numbers::pi);
        if (!fix.bodies[1].observed) ++sr.unobserved;
        done += 1.0;
        if (options.progress) options.progress(done / total);
      }
      finish_set(sr, options.runs, tm, rd, stm, srd);
      obj.sets.push_back(sr);
    }
    result.objects.push_back(std::move(obj));
  }
  if (result.objects.empty()) result.error = options.log + ": no place passed twice with a free-standing object in view";
  return result;
}

}  // namespace trailnav::eval
