// The station task of trailnavd (thesis chapter 4 on the robot): each new
// planar scan — a 2D safety laser's sensor_msgs/LaserScan received over DDS,
// or a band of the Velodyne's rings flattened into the plane — is added to
// a visit's local model (StationLocaliser::add, §4.2.2), and once the model
// holds its N scans, every `every` scans the model is registered onto the
// taught surroundings and every object at once (Eq. 4.1–4.4). The answer
// goes out as a snapshot: per body, the robot's pose in that body's frame
// with its covariance, and per object how far it moved and turned since
// the teach-in. The surroundings' answer then re-anchors the local model
// (StationLocaliser::correct), so a robot that stays at the station for an
// hour does not carry an hour of scan-to-scan drift.
//
// Motion between scans: the pose thread's odometry at the two scans' stamps
// when it is there, else the last registered step again (constant velocity;
// a docking robot moves slowly against a 10–40 Hz laser). A visit begins at
// `start` (the robot's pose in the station frame where it is expected, e.g.
// at the docking approach) with the first scan, and again after the scans
// fall silent for `silence_s`.
//
// Memory: the localiser's buffers are sized at construction; the k-d trees
// it builds each scan (nanoflann's node pool) and its answer's vector are
// served by a heap redirect from an arena allocated here (runtime/
// heap_redirect.hpp), so the task's thread never touches the heap once the
// runtime is armed. An arena too small is counted (`arena_failures`) and
// the scan is dropped, never served from the heap.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Geometry>

#include "trailnav/drivers/velodyne/range_image.hpp"
#include "trailnav/perception/pose_track.hpp"
#include "trailnav/perception/registration/station.hpp"
#include "trailnav/runtime/arena.hpp"
#include "trailnav/runtime/broadcast.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"
#include "trailnav/runtime/wakeup.hpp"

namespace trailnav::perception::registration {

// One planar scan in the robot frame (z = 0), as the inputs hand it over.
struct PlanarScan {
  explicit PlanarScan(std::size_t capacity) { points.reserve(capacity); }
  std::int64_t stamp_ns = 0;  // the reference (host) clock
  std::uint64_t sequence = 0;
  std::uint64_t dropped = 0;  // returns beyond the capacity, left out
  std::vector<Point> points;  // never beyond its capacity
};

// A band of a spinning lidar's rings flattened into the plane (the
// Velodyne input): every valid return of rings [first_ring, last_ring]
// (layer 0), within [min_range, max_range] of the sensor, taken into the
// robot frame by `mount` and put at z = 0. Rings near the horizontal see the
// walls and furniture a 2D laser would.
struct RingBand {
  int first_ring = 7;  // a VLP-16's two middle rings (-1° and +1°)
  int last_ring = 8;
  float min_range = 0.3f;
  float max_range = 20.0f;
  Eigen::Isometry3f mount = Eigen::Isometry3f::Identity();  // sensor -> robot
};
// Fills `out` (within its capacity; the rest counted in out.dropped).
void band_scan(const velodyne::RangeImage& image, const RingBand& band, PlanarScan& out) noexcept;

struct StationTaskOptions {
  Eigen::Isometry3d start = Eigen::Isometry3d::Identity();  // a visit's first pose, station frame
  int every = 1;             // scans between two localisations once the local model is full
  double silence_s = 2.0;    // a gap in the scans this long ends a visit; the next scan begins one
  std::size_t arena_bytes = std::size_t{16} << 20;  // the k-d trees' and answers' memory (the thesis box used 367 kB)
};

// Per body, in the snapshot.
struct StationBodyFix {
  double x = 0.0, y = 0.0, yaw = 0.0;  // the robot's pose in this body's frame (m, rad)
  // Its covariance in x, y, yaw (row-major 3 x 3): GICP's (the inverse of
  // the final normal matrix), taken from the left perturbation to the pose.
  std::array<double, 9> covariance{};
  double moved_x = 0.0, moved_y = 0.0, turned = 0.0;  // the object's motion since the teach-in (station frame); 0 for body 0
  double centre_moved = 0.0;  // m, how far its centre (body_centre(): its polygon's centroid) went by that motion
  std::uint32_t correspondences = 0;
  bool observed = false;
  double fitness = 0.0;  // m², mean squared distance of its associations
};

struct StationSnapshot {
  explicit StationSnapshot(std::size_t count) : bodies(count) {}
  std::int64_t stamp_ns = 0;   // the newest scan's (reference clock)
  std::uint64_t number = 0;    // fixes published so far
  std::uint64_t scan_sequence = 0;
  std::uint64_t visit = 0;     // visits begun so far (1: the first)
  std::size_t local_points = 0;
  int iterations = 0;
  std::vector<StationBodyFix> bodies;  // [0]: the surroundings
};

struct StationCounters {
  std::uint64_t scans = 0;           // scans taken
  std::uint64_t fixes = 0;           // snapshots published
  std::uint64_t lost = 0;            // localisations in which the surroundings were not observed
  std::uint64_t visits = 0;          // visits begun
  std::uint64_t without_odometry = 0;  // scans whose motion came from the last step (no pose at their stamps)
  std::uint64_t arena_failures = 0;  // scans dropped: the arena could not serve them
  std::uint64_t dropped_points = 0;  // returns beyond a scan's capacity
  std::size_t arena_high_water = 0;  // bytes
  std::size_t arena_capacity = 0;
};

class StationTask final : public Task {
 public:
  // `station` must outlive the task. Exactly one input: `scans` (a 2D
  // laser's) or, via set_revolutions() before the scheduler starts, a
  // lidar's revolutions and a ring band. `poses` (may be null): the pose
  // thread's odometry.
  StationTask(const Station& station, const StationConfig& config, const StationTaskOptions& options,
              Mailbox<PlanarScan>* scans, PoseQueue* poses, Mailbox<StationSnapshot>& out);
  ~StationTask() override;
  StationTask(const StationTask&) = delete;
  StationTask& operator=(const StationTask&) = delete;

  void set_revolutions(Broadcast<velodyne::RangeImage>::Reader* revolutions, const RingBand& band) noexcept {
    revolutions_ = revolutions;
    band_ = band;
  }
  void set_notify(Wakeup* wakeup) noexcept { notify_ = wakeup; }
  void run(const TaskTick& tick) override;
  // A consistent copy, for health (StatusBoard: the task never waits on a reader).
  StationCounters counters() const noexcept { return board_.read(); }

 private:
  void step(const PlanarScan& scan) noexcept;
  Eigen::Isometry3d motion(std::int64_t stamp_ns) noexcept;
  void publish(const StationFix& fix, const PlanarScan& scan) noexcept;

  const Station& station_;
  StationConfig config_;
  StationTaskOptions options_;
  Mailbox<PlanarScan>* scans_;
  PoseQueue* poses_;
  Mailbox<StationSnapshot>& out_;
  Broadcast<velodyne::RangeImage>::Reader* revolutions_ = nullptr;
  RingBand band_;
  PlanarScan band_scan_;
  Wakeup* notify_ = nullptr;
  Arena arena_;
  std::vector<Eigen::Vector3d> centres_;  // per body: body_centre()
  std::optional<StationLocaliser> localiser_;
  PoseTrack track_;
  bool in_visit_ = false;
  std::int64_t last_stamp_ns_ = 0;
  Pose last_pose_{};
  bool have_last_pose_ = false;
  Eigen::Isometry3d last_step_ = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d last_registered_ = Eigen::Isometry3d::Identity();
  int since_fix_ = 0;
  StationCounters c_;
  StatusBoard<StationCounters> board_;
};

}  // namespace trailnav::perception::registration
