// Localisation relative to objects that move (thesis chapter 4): a station
// is a place the robot returns to — a docking spot with a table, a shelf, a
// box that people push around between visits. It is taught once and then
// localised against at every visit, relative to each object at once.
//
// Teach-in (§4.2.1): the robot is driven around the station and records
// scans; their poses are refined by registering the scans jointly: every
// scan against all the others (the dense graph of Fig. 4.5), by rounds in
// which each scan in turn, from its current pose, is registered onto the
// union of all the others under theirs, until no pose moves by more than
// the convergence thresholds (Gauss–Seidel on the joint objective; the
// associations are found again in every registration, as the thesis'
// iterative bundle adjustment does). The first scan stays where it is: it
// defines the station's frame. The user then marks the objects (polygons
// in the station frame); the points inside one are that object's reference,
// the rest the static surroundings (body 0).
//
// A visit (§4.2.2): starting from a pose in the station frame (the regular
// localisation's), each scan is registered onto the local model of the
// previous `local_scans` scans from the pose the odometry predicts (only
// the current pose is free); `localise()` then takes the local model into
// the current robot frame and registers it onto the surroundings and every
// object at once (Eq. 4.1–4.4, multi_body.hpp): one transform per body, the
// robot's pose in that body's reference frame. An object moved by M (in
// the station frame) since the teach-in gives T_object = M⁻¹ · T_world, so
// M = T_world · T_object⁻¹ (`moved()`).
//
// 2D laser scans are points at z = 0 (`planar`): covariances of lines, and
// the solution stays in the plane. Buffers are sized at construction; a
// registration's k-d trees allocate (nanoflann's node pool) and localise()
// returns its answer in a vector, so a visit runs on a normal-priority
// thread, not a real-time one.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "trailnav/perception/registration/cloud.hpp"
#include "trailnav/perception/registration/gicp.hpp"
#include "trailnav/perception/registration/multi_body.hpp"
#include "trailnav/perception/registration/station_file.hpp"

namespace trailnav::perception::registration {

struct StationConfig {
  GicpConfig gicp{Metric::point_to_plane, 60, 0.35f, 2e-6, 5e-6, 0.0};  // the thesis' point to plane
  // Each registration runs twice: with gicp's gate (0.35 m: an object moved
  // by 10 cm and turned by 10° about its centre moves its ends by up to
  // 0.2 m, and a narrower gate lost such objects in the real cases), then
  // from there with this one (3 σ of a 1 cm
  // laser): points beyond the end of what the reference saw no longer pull
  // on the last point of a wall with its wrong normal.
  float fine_gate = 0.03f;
  float max_thickness = 0.0f;  // CovarianceEstimator: corners get no normal (0: off)
  float voxel = 0.01f;    // m, the reference and the local model
  int neighbours = 10;    // k for the covariances and normals (a table's leg holds few points)
  int teach_rounds = 10;  // at most; fewer when the poses stop moving
  bool teach_graph = false;  // the teach-in as a pose graph over every pair of scans instead
  int local_scans = 10;   // N: scans in a visit's local model
  bool planar = true;     // 2D laser scans at z = 0
  std::size_t max_points = 2048;  // per scan
  std::size_t max_scans = 256;    // teach-in scans
};
// "" if usable, else what is wrong.
std::string check_station_config(const StationConfig& c);
GicpConfig fine_config(const StationConfig& c) noexcept;  // gicp with the fine gate

// One recorded scan (sensor frame) and its pose (station frame; at teach-in
// the odometry's first guess, refined by teach()).
struct StationScan {
  std::vector<Point> points;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
};

struct TeachResult {
  int rounds = 0;                 // joint-registration rounds run
  bool converged = false;         // the last round moved no pose beyond the thresholds
  double largest_correction = 0;  // m, the largest distance a pose moved from its first guess
};
// Refines the scans' poses in place (the first one stays).
TeachResult teach(std::span<StationScan> scans, const StationConfig& config);

// A polygon (station frame, metres) around one object, as the user marks it.
struct StationObject {
  std::string name;
  std::vector<Eigen::Vector2d> polygon;  // at least 3 corners
};
bool inside(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& p) noexcept;

// The taught station: body 0 the surroundings, body k the k-th object.
struct Station;
// A body's centre in the station frame, the point whose shift says how far
// an object moved: the centroid of the polygon it was marked by (the user
// drew it round the whole object, where its taught points are only the faces
// the teach-in saw), else the mean of its taught points (the surroundings).
Eigen::Vector3d body_centre(const Station& station, std::size_t body) noexcept;
struct Station {
  std::vector<std::string> names;  // names[0] == "surroundings"
  std::vector<Target> bodies;
  std::vector<std::size_t> taught_points;  // per body, before the voxel filter
  std::vector<std::vector<Eigen::Vector2d>> polygons;  // per body as marked; [0] empty
};
// The teach-in's scans under their refined poses, split by the objects'
// polygons, voxel filtered, with covariances, normals and trees. Empty
// `error` when usable; an object without points is an error (it was marked
// where the teach-in saw nothing).
struct BuiltStation {
  Station station;
  std::string error;
};
BuiltStation build_station(std::span<const StationScan> scans, std::span<const StationObject> objects,
                           const StationConfig& config);

// The station as a file (station_file.hpp) and back: the covariances,
// normals and trees are worked out again on the way in.
StationFile station_file_of(const Station& station, const std::string& name);
BuiltStation station_from_file(const StationFile& file, const StationConfig& config);

struct StationFix {
  std::vector<BodyResult> bodies;  // per body: the robot's pose in its reference frame
  int iterations = 0;
  std::size_t local_points = 0;
  // The object's motion in the station frame since the teach-in.
  Eigen::Isometry3d moved(std::size_t body) const noexcept {
    return bodies[0].transform * bodies[body].transform.inverse();
  }
};

class StationLocaliser {
 public:
  StationLocaliser(const Station& station, const StationConfig& config);

  // A visit begins at `pose` (station frame, the regular localisation's).
  void begin(const Eigen::Isometry3d& pose);
  // One scan (sensor frame) after the robot moved by `odometry` (in the
  // previous scan's frame) since the previous one; returns its pose in the
  // station frame, registered onto the local model of the previous scans.
  Eigen::Isometry3d add(std::span<const Point> scan, const Eigen::Isometry3d& odometry);
  // The local model against the surroundings and every object at once.
  StationFix localise();
  // Moves the local model so that the current pose becomes `pose` (station
  // frame): after localise(), the surroundings' answer re-anchors a visit
  // that goes on for longer than its local model, so that its scan-to-scan
  // drift does not add up.
  void correct(const Eigen::Isometry3d& pose);
  // One body only: the whole reference as one rigid body (for comparison:
  // chapter 4's reason to be).
  GicpResult localise_single();
  // One registration, coarse then fine (StationConfig::fine_gate).
  static GicpResult align_twice(Gicp& coarse, Gicp& fine, const Cloud& source, const Target& target,
                                const Eigen::Isometry3d& initial) noexcept;

  const Eigen::Isometry3d& pose() const noexcept { return pose_; }
  // The local model of the last localise() or localise_single(), in the
  // robot frame (for pictures and diagnostics).
  const Cloud& local_points() const noexcept { return query_; }
  std::size_t scans() const noexcept { return count_; }

 private:
  void local_model(Cloud& out);  // the last N scans in the current robot frame

  const Station& station_;
  StationConfig config_;
  VoxelFilter filter_;
  CovarianceEstimator covariances_;
  Gicp gicp_, fine_;
  MultiBodyGicp multi_, multi_fine_;
  Target whole_;  // every body in one, for localise_single()
  std::vector<std::vector<Point>> ring_;  // the last N scans, station frame (their estimated poses)
  std::size_t next_ = 0, count_ = 0;
  Eigen::Isometry3d pose_ = Eigen::Isometry3d::Identity();
  Cloud scan_;
  std::vector<Point> merged_;
  Target local_;  // the previous scans, a visit's registration target
  Cloud query_;   // the local model in the robot frame, localise()'s
  KdTree scratch_;
  // localise()'s per-body scratch, sized by the station's bodies.
  std::vector<const Target*> body_ptrs_;
  std::vector<Eigen::Isometry3d> initial_, coarse_;
  std::vector<BodyResult> fine_results_;
  std::vector<Point> normals_;
};

}  // namespace trailnav::perception::registration
