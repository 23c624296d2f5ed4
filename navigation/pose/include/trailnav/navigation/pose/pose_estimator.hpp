// The robot's pose: the local odometry frame (gyro_odometry.hpp) and its
// alignment to UTM from GPS (utm_alignment.hpp), fed in time order, and the
// pose task that runs it on the scheduler: it drains the IMU and wheel
// odometry queues and the GPS mailbox of the driver tasks, merges them by
// time and publishes a PoseSnapshot through a mailbox to the perception and
// navigation threads. Everything is allocated at construction.
#pragma once

#include <array>
#include <cstdint>

#include "trailnav/drivers/can/can_driver.hpp"
#include "trailnav/drivers/gps/gps_driver.hpp"
#include "trailnav/drivers/imu/imu_driver.hpp"
#include "trailnav/navigation/pose/gyro_odometry.hpp"
#include "trailnav/navigation/pose/utm_alignment.hpp"
#include "trailnav/perception/place/place_snapshot.hpp"
#include "trailnav/perception/pose_track.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"

namespace trailnav::pose {

struct PoseEstimatorOptions {
  GyroOdometryOptions odometry;
  UtmAlignmentOptions utm;
  // A fix is valid at its UTC time when the receiver gave a date and that time
  // is within this of the host's receive time; otherwise at the receive time
  // minus `gps_latency`.
  double gps_time_tolerance = 2.0;  // s
  double gps_latency = 0.1;         // s
  // How long (host time) wheel readings wait for the IMU readings of their
  // time before the IMU is taken to be silent and the wheels alone step the
  // odometry (PoseTask::run). IMU bytes can come late by hundreds of
  // milliseconds on a loaded machine (a serial port's bytes wait for a
  // kernel worker); longer than GyroOdometryOptions::imu_timeout, which
  // judges the readings' own times.
  double imu_wait = 3.0;  // s
};

struct PoseSnapshot {
  LocalPose local;
  UtmPose utm;
  GyroOdometryCounters odometry_counters;
  UtmAlignmentCounters utm_counters;
  std::uint64_t sequence = 0;
};

class PoseEstimator {
 public:
  explicit PoseEstimator(const PoseEstimatorOptions& options = {});

  void add_imu(const imu::Attitude& attitude) noexcept { odometry_.add_imu(attitude); }
  void add_wheels(const can::OdometryState& wheels) noexcept { odometry_.add_wheels(wheels); }
  // A fix and when its bytes arrived (same clock as the IMU and wheel times).
  void add_gps(const gps::GpsFix& fix, std::int64_t receive_ns) noexcept;

  const GyroOdometry& odometry() const noexcept { return odometry_; }
  const PoseEstimatorOptions& options() const noexcept { return options_; }
  const UtmAlignment& alignment() const noexcept { return alignment_; }
  // The current pose in both frames.
  // `geodetic`: the UTM pose's latitude, longitude and convergence too (UtmAlignment::utm).
  void snapshot(PoseSnapshot& out, bool geodetic = true) const noexcept;
  // A place fix (UtmAlignment::add_place). True when used.
  bool add_place(double lat, double lon, double sigma, std::int64_t time_ns) noexcept {
    return alignment_.add_place(lat, lon, sigma, time_ns, odometry_);
  }
  // The time a fix is valid for (see PoseEstimatorOptions).
  std::int64_t fix_time(const gps::GpsFix& fix, std::int64_t receive_ns) const noexcept;

 private:
  PoseEstimatorOptions options_;
  GyroOdometry odometry_;
  UtmAlignment alignment_;
};

// A fix the alignment used, for the online mapping thread (one queue, one
// reader): the fix, the UTM zone, and the alignment's odometry -> UTM
// transform right after it (easting, northing, rotation; valid once the
// heading is known), which places the map's first keyframe.
struct MappingFix {
  UsedFix fix;
  int zone = 0;
  bool north = true;
  bool aligned = false;
  double east = 0.0, north_m = 0.0, rotation = 0.0;  // odometry -> UTM
};
// A second of fixes at 20 Hz and more: the mapping thread drains it every run.
inline constexpr std::size_t kMappingFixCapacity = 64;
using MappingFixQueue = SpscQueue<MappingFix, kMappingFixCapacity>;

// The online map's correction of the GPS alignment (the mapping thread,
// navigation/slam/mapping_task.hpp): UTM as the optimised map has it is
// Δ ∘ UTM as the alignment has it, Δ a rotation by `yaw` about the zone's
// origin and a shift (x, y). The pose task applies the newest one to every
// UTM pose it hands out (navigation, the DDS topics and so tf's utm -> odom):
// one map -> odom for every consumer. It is applied gradually (PoseTask:
// at most 0.5 m/s at the robot and 0.005 rad/s).
struct MapCorrection {
  bool valid = false;
  std::uint64_t revision = 0;
  double x = 0.0, y = 0.0, yaw = 0.0;
};

// When the pose thread takes the place task's answers as position fixes
// (config place.pose_measurement, docs/place.md "On the robot"): never;
// when GPS is poor (no fix used for `gps_poor_after_s` before the answer's
// time, or the UTM position less certain than `gps_poor_sigma_m`); or
// always. Only answers with a database position (latitude, longitude), at
// least `min_probability` within the window and, when `need_sequence`, in
// a sequence; their standard deviation the larger axis of their covariance.
enum class PlaceUse { off, gps_poor, always };
struct PlaceUseOptions {
  PlaceUse use = PlaceUse::off;
  double min_probability = 0.3;  // Nordland winter in summer through trailnavd: 82 of 84 answers right (docs/place.md)
  bool need_sequence = true;
  double gps_poor_after_s = 2.0;
  double gps_poor_sigma_m = 5.0;
};

struct PoseTaskStatus {
  std::uint64_t runs = 0;
  std::uint64_t imu_readings = 0, wheel_readings = 0, gps_fixes = 0;
  std::uint64_t published = 0;
  std::uint64_t pose_queue_drops = 0;  // samples the perception threads' queue had no room for
  std::uint64_t fix_queue_drops = 0;   // used fixes the mapping thread's queue had no room for
  std::uint64_t map_corrections = 0;   // corrections of the online map taken (MapCorrection)
  // The place task's answers: taken from its mailbox, and passed over: GPS
  // good, too weak (its probability, not in a sequence, no database
  // position). The alignment's counters (utm_counters.place_*) say how many
  // were offered to it and what became of them.
  std::uint64_t place_answers = 0, place_gps_good = 0, place_weak = 0;
  // Wheel readings that came before the IMU readings of their time and were
  // held until those came (see PoseTask::run), and those let go without them
  // because the IMU fell silent or the hold was full.
  std::uint64_t wheels_held = 0;
  std::uint64_t wheels_released_early = 0;
  // The GPS receiver's clock against the reference (host) clock: fixes placed
  // at the receiver's UTC (within gps_time_tolerance of their receive time)
  // or at their receive time minus gps_latency, and receive minus UTC of the
  // newest fix that carried a date (its transfer latency plus any offset).
  std::uint64_t gps_fixes_at_utc = 0, gps_fixes_at_receive = 0;
  std::int64_t gps_receive_minus_utc_ns = 0;
  bool gps_has_utc = false;
  LocalPose local;
  UtmPose utm;
  GyroOdometryCounters odometry_counters;
  UtmAlignmentCounters utm_counters;
};

class PoseTask final : public Task {
 public:
  // Any input may be null (a robot without that sensor).
  PoseTask(const PoseEstimatorOptions& options, SpscQueue<imu::ImuReading, imu::kImuQueueCapacity>* imu,
           SpscQueue<can::OdometryState, can::kOdometryQueueCapacity>* wheels, Mailbox<gps::GpsReading>* gps);

  // Also pushes every new local pose into this queue (the obstacle and
  // terrain threads' motion compensation and registration), at most
  // kMaxPoseOutputs of them. Before the scheduler starts; false when full.
  static constexpr std::size_t kMaxPoseOutputs = 4;
  bool add_pose_output(perception::PoseQueue* queue) noexcept {
    if (queue == nullptr || pose_outputs_ == kMaxPoseOutputs) return false;
    pose_out_[pose_outputs_++] = queue;
    return true;
  }

  // Also pushes every fix the alignment used into this queue (the mapping
  // thread's). Before the scheduler starts.
  void set_fix_output(MappingFixQueue* queue) noexcept { fix_out_ = queue; }
  // The mapping thread's corrections, applied to every UTM pose from the
  // newest on. Before the scheduler starts.
  void set_map_correction(Mailbox<MapCorrection>* corrections) noexcept { corrections_ = corrections; }
  // The place task's answers, used as `options` says. Before the scheduler starts.
  void set_place_input(Mailbox<perception::place::PlaceSnapshot>* place, const PlaceUseOptions& options) noexcept {
    place_ = place;
    place_use_ = options;
  }

  void run(const TaskTick& tick) override;

  // The newest pose in both frames: for the DDS publisher, and a second
  // mailbox for the navigation thread (each mailbox has one reader).
  Mailbox<PoseSnapshot>& poses() noexcept { return poses_; }
  Mailbox<PoseSnapshot>& navigation_poses() noexcept { return navigation_poses_; }
  PoseTaskStatus status() const noexcept { return shared_.read(); }
  const PoseEstimator& estimator() const noexcept { return estimator_; }

 private:
  PoseEstimator estimator_;
  SpscQueue<imu::ImuReading, imu::kImuQueueCapacity>* imu_;
  SpscQueue<can::OdometryState, can::kOdometryQueueCapacity>* wheels_;
  Mailbox<gps::GpsReading>* gps_;
  std::array<imu::Attitude, imu::kImuQueueCapacity> imu_batch_{};
  std::array<can::OdometryState, can::kOdometryQueueCapacity> wheel_batch_{};
  std::size_t wheels_pending_ = 0;   // held at the front of wheel_batch_, in arrival order
  std::int64_t imu_newest_ns_ = -1;  // time of the newest IMU reading taken
  Nanos imu_arrival_ = -1;           // host time of the last run that took IMU readings
  Nanos first_wheels_arrival_ = -1;  // host time of the first run that took wheel readings
  Mailbox<PoseSnapshot> poses_;
  Mailbox<PoseSnapshot> navigation_poses_;
  std::array<perception::PoseQueue*, kMaxPoseOutputs> pose_out_{};
  std::size_t pose_outputs_ = 0;
  MappingFixQueue* fix_out_ = nullptr;
  Mailbox<MapCorrection>* corrections_ = nullptr;
  Mailbox<perception::place::PlaceSnapshot>* place_ = nullptr;
  PlaceUseOptions place_use_;
  bool take_place(const perception::place::PlaceSnapshot& s) noexcept;
  // The newest correction, and the one applied: it moves towards the newest
  // at most kCorrectionShift at the robot and kCorrectionTurn, so a solve of
  // the map never makes the UTM pose jump (a planner's path would jump
  // with it).
  static constexpr double kCorrectionShift = 0.5;   // m/s
  static constexpr double kCorrectionTurn = 0.005;  // rad/s
  MapCorrection target_, applied_;
  Nanos last_correction_ = -1;
  void correct(UtmPose& utm, Nanos now) noexcept;
  std::uint64_t fix_serial_ = 0;  // the newest used fix pushed
  std::int64_t last_out_ns_ = 0;
  PoseTaskStatus local_;
  StatusBoard<PoseTaskStatus> shared_;
};

}  // namespace trailnav::pose
