#include "trailnav/perception/registration/station.hpp"

#include "trailnav/perception/registration/carmen.hpp"

#include <algorithm>
#include <cmath>

namespace trailnav::perception::registration {

std::string check_station_config(const StationConfig& c) {
  if (const char* e = check_gicp_config(c.gicp); *e != '\0') return std::string("gicp: ") + e;
  if (!(c.voxel > 0.0f) || !std::isfinite(c.voxel)) return "voxel: a positive number of metres";
  if (c.neighbours < 3 || c.neighbours > 64) return "neighbours: 3 to 64";
  if (c.teach_rounds < 1 || c.teach_rounds > 100) return "teach_rounds: 1 to 100";
  if (c.local_scans < 1 || c.local_scans > 100) return "local_scans: 1 to 100";
  if (c.max_points < 16) return "max_points: at least 16";
  if (c.max_scans < 2) return "max_scans: at least 2";
  if (!(c.fine_gate > 0.0f) || !(c.fine_gate <= c.gicp.max_correspondence_distance)) {
    return "fine_gate: positive, at most gicp's max_correspondence_distance";
  }
  if (!(c.max_thickness >= 0.0f) || !(c.max_thickness <= 1.0f)) return "max_thickness: 0 (off) to 1";
  return "";
}

GicpConfig fine_config(const StationConfig& c) noexcept {
  GicpConfig f = c.gicp;
  f.max_correspondence_distance = c.fine_gate;
  return f;
}

GicpResult StationLocaliser::align_twice(Gicp& coarse, Gicp& fine, const Cloud& source, const Target& target,
                                         const Eigen::Isometry3d& initial) noexcept {
  const GicpResult r = coarse.align(source, target, initial);
  if (!r.transform.matrix().allFinite() || r.correspondences < 6) return r;
  const GicpResult f = fine.align(source, target, r.transform);
  return f.transform.matrix().allFinite() && f.correspondences >= 6 ? f : r;
}

namespace {

void transform_into(std::span<const Point> in, const Eigen::Isometry3d& t, std::vector<Point>& out) {
  const Eigen::Isometry3f tf = t.cast<float>();
  for (const Point& p : in) out.push_back(tf * p);
}

double angle_of(const Eigen::Isometry3d& t) { return Eigen::AngleAxisd(t.linear()).angle(); }

}  // namespace

namespace {

// (x, y, θ) of a planar transform as a vector (the graph's unknowns) and back.
Eigen::Vector3d planar_of(const Eigen::Isometry3d& t) {
  const Pose2 p = to_pose2(t);
  return {p.x, p.y, p.theta};
}
Eigen::Isometry3d from_planar(const Eigen::Vector3d& v) { return to_isometry(Pose2{v.x(), v.y(), v.z()}); }

// The teach-in as the thesis' dense graph (Fig. 4.5) made a pose graph:
// every pair of scans registered (j onto i, from their current poses), each
// result an edge weighted by its associations, and the planar poses solved
// for by Gauss–Newton with the first one fixed; twice, the pairs registered
// again from the solved poses.
void teach_graph(std::span<StationScan> scans, std::size_t n, const StationConfig& config, TeachResult& result) {
  VoxelFilter filter(config.max_points);
  CovarianceEstimator covariances(config.neighbours, 1e-3f, config.planar, config.max_thickness);
  std::vector<Target> single(n);
  for (std::size_t k = 0; k < n; ++k) {
    const std::span<const Point> own(scans[k].points.data(), std::min(scans[k].points.size(), config.max_points));
    single[k].cloud.points.reserve(own.size());
    filter.filter(own, config.voxel, single[k].cloud);
    prepare_target(single[k], covariances);
  }
  Gicp gicp(config.gicp, config.max_points), fine(fine_config(config), config.max_points);
  struct Edge {
    std::size_t i, j;
    Eigen::Vector3d z;  // j in i's frame
    double weight;
  };
  constexpr double kLever2 = 4.0;  // m²: a turn's weight against a shift's (points some 2 m away)
  for (int outer = 0; outer < 2; ++outer) {
    std::vector<Edge> edges;
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t j = i + 1; j < n; ++j) {
        const Eigen::Isometry3d guess = scans[i].pose.inverse() * scans[j].pose;
        const GicpResult r = StationLocaliser::align_twice(gicp, fine, single[j].cloud, single[i], guess);
        if (!r.transform.matrix().allFinite() || r.correspondences < single[j].cloud.size() / 3) continue;
        // A pair that moved far from its guess found a wrong match (two
        // scans of a corridor seen from far apart): no edge.
        const Eigen::Vector3d moved = planar_of(guess.inverse() * r.transform);
        if (moved.head<2>().norm() > 0.2 || std::abs(moved.z()) > 0.1) continue;
        edges.push_back({i, j, planar_of(r.transform), static_cast<double>(r.correspondences)});
      }
    }
    // Gauss–Newton over poses 1..n-1 (pose 0 fixed), numeric Jacobians.
    std::vector<Eigen::Vector3d> x(n);
    for (std::size_t k = 0; k < n; ++k) x[k] = planar_of(scans[k].pose);
    const auto m = static_cast<Eigen::Index>(3 * (n - 1));
    auto residual = [&](const Edge& e, const Eigen::Vector3d& xi, const Eigen::Vector3d& xj) {
      Eigen::Vector3d r = planar_of(from_planar(e.z).inverse() * from_planar(xi).inverse() * from_planar(xj));
      return r;
    };
    result.converged = false;
    for (int it = 0; it < 10; ++it) {
      Eigen::MatrixXd h = Eigen::MatrixXd::Zero(m, m);
      Eigen::VectorXd g = Eigen::VectorXd::Zero(m);
      for (const Edge& e : edges) {
        const Eigen::Vector3d r0 = residual(e, x[e.i], x[e.j]);
        Eigen::Matrix<double, 3, 6> jac;
        for (int d = 0; d < 6; ++d) {
          constexpr double kStep = 1e-6;
          Eigen::Vector3d xi = x[e.i], xj = x[e.j];
          (d < 3 ? xi : xj)(d % 3) += kStep;
          jac.col(d) = (residual(e, xi, xj) - r0) / kStep;
        }
        const Eigen::Vector3d w(e.weight, e.weight, e.weight * kLever2);
        const std::size_t idx[2] = {e.i, e.j};
        for (int a = 0; a < 2; ++a) {
          if (idx[a] == 0) continue;
          const Eigen::Index ra = static_cast<Eigen::Index>(3 * (idx[a] - 1));
          const Eigen::Matrix3d ja = jac.middleCols<3>(3 * a);
          g.segment<3>(ra) += ja.transpose() * w.asDiagonal() * r0;
          for (int b = 0; b < 2; ++b) {
            if (idx[b] == 0) continue;
            const Eigen::Index rb = static_cast<Eigen::Index>(3 * (idx[b] - 1));
            h.block<3, 3>(ra, rb) += ja.transpose() * w.asDiagonal() * jac.middleCols<3>(3 * b);
          }
        }
      }
      h.diagonal().array() += 1e-9;
      const Eigen::VectorXd delta = -h.ldlt().solve(g);
      if (!delta.allFinite()) break;
      for (std::size_t k = 1; k < n; ++k) x[k] += delta.segment<3>(static_cast<Eigen::Index>(3 * (k - 1)));
      if (delta.norm() < 1e-9) {
        result.converged = true;  // the last solve's step vanished
        break;
      }
    }
    for (std::size_t k = 1; k < n; ++k) {
      Eigen::Isometry3d t = from_planar(x[k]);
      t.translation().z() = scans[k].pose.translation().z();
      scans[k].pose = t;
    }
    result.rounds = outer + 1;
  }
}

}  // namespace

TeachResult teach(std::span<StationScan> scans, const StationConfig& config) {
  TeachResult result;
  const std::size_t n = std::min(scans.size(), config.max_scans);
  if (n < 2) {
    result.converged = true;
    return result;
  }
  if (config.teach_graph) {
    std::vector<Eigen::Isometry3d> first(n);
    for (std::size_t k = 0; k < n; ++k) first[k] = scans[k].pose;
    teach_graph(scans, n, config, result);
    for (std::size_t k = 0; k < n; ++k) {
      result.largest_correction = std::max(result.largest_correction, (first[k].inverse() * scans[k].pose).translation().norm());
    }
    return result;
  }
  std::size_t total = 0;
  for (std::size_t k = 0; k < n; ++k) total += std::min(scans[k].points.size(), config.max_points);
  VoxelFilter filter(std::max(total, config.max_points));
  CovarianceEstimator covariances(config.neighbours, 1e-3f, config.planar, config.max_thickness);
  Gicp gicp(config.gicp, config.max_points), fine(fine_config(config), config.max_points);
  std::vector<Eigen::Isometry3d> first(n);
  for (std::size_t k = 0; k < n; ++k) first[k] = scans[k].pose;
  std::vector<Point> merged;
  merged.reserve(total);
  Target target;
  target.cloud.points.reserve(total);
  Cloud source;
  source.points.reserve(config.max_points);
  KdTree scratch;
  std::vector<Point> normals;
  for (int round = 0; round < config.teach_rounds; ++round) {
    double largest_step = 0.0, largest_turn = 0.0;
    for (std::size_t k = 1; k < n; ++k) {
      // The first round: scan k against the scans before it (x_{k-1} .. x_1,
      // Fig. 4.5); later rounds: against all the others.
      merged.clear();
      const std::size_t others = round == 0 ? k : n;
      for (std::size_t j = 0; j < others; ++j) {
        if (j == k) continue;
        const std::span<const Point> pts(scans[j].points.data(), std::min(scans[j].points.size(), config.max_points));
        transform_into(pts, scans[j].pose, merged);
      }
      filter.filter(merged, config.voxel, target.cloud);
      if (target.cloud.size() < 6) continue;
      prepare_target(target, covariances);
      // In the first round scan k starts from scan k − 1's refined pose and
      // the odometry's step between them, not from the odometry's whole
      // chain (whose error grows with every step).
      if (round == 0) scans[k].pose = scans[k - 1].pose * first[k - 1].inverse() * first[k];
      const std::span<const Point> own(scans[k].points.data(), std::min(scans[k].points.size(), config.max_points));
      filter.filter(own, config.voxel, source);
      if (config.gicp.metric == Metric::plane_to_plane) prepare_source(source, covariances, scratch, normals);
      const GicpResult r = StationLocaliser::align_twice(gicp, fine, source, target, scans[k].pose);
      if (!r.transform.matrix().allFinite() || r.correspondences < 6) continue;
      const Eigen::Isometry3d step = scans[k].pose.inverse() * r.transform;
      largest_step = std::max(largest_step, step.translation().norm());
      largest_turn = std::max(largest_turn, angle_of(step));
      scans[k].pose = r.transform;
    }
    result.rounds = round + 1;
    // Converged when a whole round moved no pose by more than ten times the
    // registration's own thresholds.
    if (round > 0 && largest_step < 10.0 * config.gicp.translation_epsilon &&
        largest_turn < 10.0 * config.gicp.rotation_epsilon) {
      result.converged = true;
      break;
    }
  }
  for (std::size_t k = 0; k < n; ++k) {
    result.largest_correction = std::max(result.largest_correction, (first[k].inverse() * scans[k].pose).translation().norm());
  }
  return result;
}

bool inside(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& p) noexcept {
  // Even-odd rule: a ray towards +x crosses the edges an odd number of times.
  bool in = false;
  const std::size_t n = polygon.size();
  for (std::size_t i = 0, j = n - 1; i < n; j = i++) {
    const Eigen::Vector2d& a = polygon[i];
    const Eigen::Vector2d& b = polygon[j];
    if ((a.y() > p.y()) != (b.y() > p.y()) && p.x() < (b.x() - a.x()) * (p.y() - a.y()) / (b.y() - a.y()) + a.x()) in = !in;
  }
  return in;
}

BuiltStation build_station(std::span<const StationScan> scans, std::span<const StationObject> objects,
                           const StationConfig& config) {
  BuiltStation built;
  Station& s = built.station;
  for (const StationObject& o : objects) {
    if (o.polygon.size() < 3) {
      built.error = "object '" + o.name + "': a polygon needs at least 3 corners";
      return built;
    }
  }
  const std::size_t nb = objects.size() + 1;
  std::vector<std::vector<Point>> points(nb);
  for (const StationScan& scan : scans) {
    const Eigen::Isometry3f t = scan.pose.cast<float>();
    const std::size_t m = std::min(scan.points.size(), config.max_points);
    for (std::size_t i = 0; i < m; ++i) {
      const Point p = t * scan.points[i];
      if (!p.allFinite()) continue;
      std::size_t body = 0;
      for (std::size_t k = 0; k < objects.size(); ++k) {
        if (inside(objects[k].polygon, p.head<2>().cast<double>())) {
          body = k + 1;
          break;
        }
      }
      points[body].push_back(p);
    }
  }
  s.names.push_back("surroundings");
  for (const StationObject& o : objects) s.names.push_back(o.name);
  s.polygons.emplace_back();
  for (const StationObject& o : objects) s.polygons.push_back(o.polygon);
  s.bodies = std::vector<Target>(nb);
  CovarianceEstimator covariances(config.neighbours, 1e-3f, config.planar, config.max_thickness);
  for (std::size_t k = 0; k < nb; ++k) {
    s.taught_points.push_back(points[k].size());
    if (points[k].size() < 6) {
      built.error = k == 0 ? std::string("the teach-in's scans hold no surroundings outside the objects")
                           : "object '" + s.names[k] + "': the teach-in saw " + std::to_string(points[k].size()) +
                                 " points inside its polygon (at least 6 are needed): is it marked where the object stood?";
      return built;
    }
    VoxelFilter filter(points[k].size());
    s.bodies[k].cloud.points.reserve(points[k].size());
    filter.filter(points[k], config.voxel, s.bodies[k].cloud);
    prepare_target(s.bodies[k], covariances);
  }
  return built;
}

Eigen::Vector3d body_centre(const Station& station, std::size_t k) noexcept {
  // The polygon's area centroid (the shoelace sums); a degenerate one falls back.
  if (k < station.polygons.size() && station.polygons[k].size() >= 3) {
    const std::vector<Eigen::Vector2d>& poly = station.polygons[k];
    double area = 0.0;
    Eigen::Vector2d c = Eigen::Vector2d::Zero();
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const Eigen::Vector2d& a = poly[i];
      const Eigen::Vector2d& b = poly[(i + 1) % poly.size()];
      const double cross = a.x() * b.y() - b.x() * a.y();
      area += cross;
      c += cross * (a + b);
    }
    if (std::abs(area) > 1e-12) return {c.x() / (3.0 * area), c.y() / (3.0 * area), 0.0};
  }
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  if (k >= station.bodies.size() || station.bodies[k].cloud.points.empty()) return sum;
  for (const Point& p : station.bodies[k].cloud.points) sum += p.cast<double>();
  return sum / static_cast<double>(station.bodies[k].cloud.points.size());
}

StationFile station_file_of(const Station& station, const std::string& name) {
  StationFile f;
  f.name = name;
  for (std::size_t k = 0; k < station.bodies.size(); ++k) {
    StationBodyFile b;
    b.name = station.names[k];
    if (k < station.polygons.size()) b.polygon = station.polygons[k];
    b.points = station.bodies[k].cloud.points;
    f.bodies.push_back(std::move(b));
  }
  return f;
}

BuiltStation station_from_file(const StationFile& file, const StationConfig& config) {
  BuiltStation built;
  Station& s = built.station;
  CovarianceEstimator covariances(config.neighbours, 1e-3f, config.planar, config.max_thickness);
  for (const StationBodyFile& b : file.bodies) {
    if (b.points.size() < 6) {
      built.error = "body '" + b.name + "' holds " + std::to_string(b.points.size()) + " points (at least 6 are needed)";
      return built;
    }
    s.names.push_back(b.name);
    s.polygons.push_back(b.polygon);
    s.taught_points.push_back(b.points.size());
  }
  s.bodies = std::vector<Target>(file.bodies.size());
  for (std::size_t k = 0; k < file.bodies.size(); ++k) {
    s.bodies[k].cloud.points = file.bodies[k].points;
    prepare_target(s.bodies[k], covariances);
  }
  return built;
}

StationLocaliser::StationLocaliser(const Station& station, const StationConfig& config)
    : station_(station),
      config_(config),
      filter_(config.max_points * static_cast<std::size_t>(config.local_scans)),
      covariances_(config.neighbours, 1e-3f, config.planar, config.max_thickness),
      gicp_(config.gicp, config.max_points * static_cast<std::size_t>(config.local_scans)),
      fine_(fine_config(config), config.max_points * static_cast<std::size_t>(config.local_scans)),
      multi_(config.gicp, config.max_points * static_cast<std::size_t>(config.local_scans), station.bodies.size()),
      multi_fine_(fine_config(config), config.max_points * static_cast<std::size_t>(config.local_scans),
                  station.bodies.size()),
      ring_(static_cast<std::size_t>(config.local_scans)) {
  const std::size_t local = config.max_points * static_cast<std::size_t>(config.local_scans);
  for (auto& r : ring_) r.reserve(config.max_points);
  scan_.points.reserve(config.max_points);
  merged_.reserve(local);
  local_.cloud.points.reserve(local);
  query_.points.reserve(local);
  std::size_t all = 0;
  for (const Target& b : station.bodies) all += b.cloud.size();
  whole_.cloud.points.reserve(all);
  for (const Target& b : station.bodies) {
    whole_.cloud.points.insert(whole_.cloud.points.end(), b.cloud.points.begin(), b.cloud.points.end());
  }
  CovarianceEstimator whole_cov(config.neighbours, 1e-3f, config.planar, config.max_thickness);
  prepare_target(whole_, whole_cov);
  const std::size_t nb = station.bodies.size();
  for (const Target& b : station.bodies) body_ptrs_.push_back(&b);
  initial_.resize(nb);
  coarse_.resize(nb);
  fine_results_.resize(nb);
}

void StationLocaliser::begin(const Eigen::Isometry3d& pose) {
  pose_ = pose;
  count_ = 0;
  next_ = 0;
  for (auto& r : ring_) r.clear();
}

Eigen::Isometry3d StationLocaliser::add(std::span<const Point> scan, const Eigen::Isometry3d& odometry) {
  const std::span<const Point> own = scan.first(std::min(scan.size(), config_.max_points));
  if (count_ > 0) {
    // The local model of the previous scans (station frame) as the target;
    // only the current pose is free (Fig. 4.6).
    const Eigen::Isometry3d predicted = pose_ * odometry;
    merged_.clear();
    const std::size_t held = std::min(count_, ring_.size());
    for (std::size_t j = 0; j < held; ++j) merged_.insert(merged_.end(), ring_[j].begin(), ring_[j].end());
    filter_.filter(merged_, config_.voxel, local_.cloud);
    pose_ = predicted;
    if (local_.cloud.size() >= 6) {
      prepare_target(local_, covariances_);
      filter_.filter(own, config_.voxel, scan_);
      if (config_.gicp.metric == Metric::plane_to_plane) prepare_source(scan_, covariances_, scratch_, normals_);
      const GicpResult r = align_twice(gicp_, fine_, scan_, local_, predicted);
      if (r.transform.matrix().allFinite() && r.correspondences >= 6) pose_ = r.transform;
    }
  }
  std::vector<Point>& slot = ring_[next_];
  next_ = (next_ + 1) % ring_.size();
  slot.clear();
  transform_into(own, pose_, slot);
  ++count_;
  return pose_;
}

void StationLocaliser::correct(const Eigen::Isometry3d& pose) {
  const Eigen::Isometry3f shift = (pose * pose_.inverse()).cast<float>();
  const std::size_t held = std::min(count_, ring_.size());
  for (std::size_t j = 0; j < held; ++j) {
    for (Point& p : ring_[j]) p = shift * p;
  }
  pose_ = pose;
}

void StationLocaliser::local_model(Cloud& out) {
  merged_.clear();
  const Eigen::Isometry3f to_robot = pose_.inverse().cast<float>();
  const std::size_t held = std::min(count_, ring_.size());
  for (std::size_t j = 0; j < held; ++j) {
    for (const Point& p : ring_[j]) merged_.push_back(to_robot * p);
  }
  filter_.filter(merged_, config_.voxel, out);
  prepare_source(out, covariances_, scratch_, normals_);
}

StationFix StationLocaliser::localise() {
  StationFix fix;
  local_model(query_);
  fix.local_points = query_.size();
  const std::size_t nb = station_.bodies.size();
  fix.bodies.resize(nb);
  for (std::size_t k = 0; k < nb; ++k) initial_[k] = pose_;
  fix.iterations = multi_.align(query_, body_ptrs_, initial_, fix.bodies);
  // From there with the fine gate; a body it loses keeps the coarse answer.
  for (std::size_t k = 0; k < nb; ++k) coarse_[k] = fix.bodies[k].transform;
  fix.iterations += multi_fine_.align(query_, body_ptrs_, coarse_, fine_results_);
  for (std::size_t k = 0; k < nb; ++k) {
    if (fine_results_[k].observed && fine_results_[k].transform.matrix().allFinite()) fix.bodies[k] = fine_results_[k];
  }
  return fix;
}

GicpResult StationLocaliser::localise_single() {
  local_model(query_);
  return align_twice(gicp_, fine_, query_, whole_, pose_);
}

}  // namespace trailnav::perception::registration
