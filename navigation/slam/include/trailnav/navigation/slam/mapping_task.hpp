// The online mapping thread of trailnavd (thesis chapter 3, run on the
// robot): a thin scheduler task around KeyframeGraph and SmfSolver.
//
// Each run drains the pose thread's poses (every local pose, in time order)
// and the fixes the GPS alignment used, merged by time: the poses make
// keyframes every few metres with their odometry edges, each fix becomes a
// virtual anchor -> keyframe constraint (keyframes.hpp). Every
// `optimize_period` seconds a graph that changed is optimised with SMF in
// place (the previous solution is the warm start), and a MappingSnapshot
// goes to the publisher: the optimised keyframes as a path and the map ->
// odom correction of the newest keyframe,
//
//     T_map←odom = x̂_k ∘ o_k⁻¹,
//
// x̂_k the keyframe's optimised pose, o_k its odometry pose. With GPS the
// GPS alignment (navigation/pose) has its own odometry -> UTM, A_k at that
// keyframe; the map's correction of it, Δ = T_map←odom ∘ A_k⁻¹, goes to the
// pose task, which hands out every UTM pose as Δ ∘ (the alignment's): the
// navigation, the pose topics and tf's utm -> odom then all have the
// optimised map's frame, one map -> odom. The fixes' error is modelled as
// the alignment models it, a white part and a wandering bias
// (keyframes.hpp: bias vertices), so fixes a few metres apart show the
// map's heading.
//
// The map frame. With GPS (`use_gps`), it is the UTM zone's frame: mapping
// starts at the first fix the alignment takes once it knows the heading
// (before that, poses are counted and not mapped), the first keyframe is
// placed by the alignment's odometry -> UTM transform, and the graph's
// coordinates are UTM minus an origin (that fix's easting and northing
// rounded to 100 m, so the solver's numbers stay small); snapshots carry
// UTM. Gauge: the GPS edges; a graph is optimised once two keyframes have
// one. Without GPS, the map frame is the odometry frame at start: the first
// keyframe is held at its odometry pose, and the graph changes only with
// loop closures (their entry: add_loop_closure(), for lidar registration,
// a later capability); until then the path is the odometry's and map ->
// odom the identity.
//
// Poses whose motion went unmeasured (wheel speeds or IMU lost) are not
// mapped: they are counted, and the edge across the gap spans what the
// odometry did meanwhile.
//
// At capacity (KeyframeOptions::max_keyframes) the graph stops growing: no
// keyframe is added (counted), the graph built stays and is still optimised
// with what reaches it, and the correction stays that of the last keyframe;
// health says `full`.
//
// Loop closures (`loops`, with a lidar's revolutions: set_revolutions()):
// each keyframe keeps a voxel-filtered cloud of the revolution the task takes
// next (its points moved into the keyframe's frame by the odometry between
// the two, at most `loop_max_gap` apart), and at each new keyframe the
// earlier ones the map's current poses put near it are verified by GICP
// (perception/registration/loop_closure.hpp); an accepted closure becomes an
// edge, and the graph is solved at the next period as after a fix. Without
// GPS the first closure is what starts the optimisation. The clouds' pool is
// allocated here; the k-d trees a verification builds come from an arena of
// its own behind a heap redirect (runtime/heap_redirect.hpp).
//
// Memory: the keyframe graph, the solver's hierarchy arena
// (smf_hierarchy_bytes) and one part's arena (smf_part_arena_bytes) are
// allocated in the constructor; a run never allocates (the scheduler's
// allocation guard watches this thread as every task's).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "trailnav/drivers/velodyne/range_image.hpp"
#include "trailnav/navigation/pose/pose_estimator.hpp"
#include "trailnav/perception/registration/loop_closure.hpp"
#include "trailnav/runtime/broadcast.hpp"
#include "trailnav/navigation/slam/arena.hpp"
#include "trailnav/navigation/slam/keyframes.hpp"
#include "trailnav/navigation/slam/smf.hpp"
#include "trailnav/perception/pose_track.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"
#include "trailnav/runtime/wakeup.hpp"

namespace trailnav::slam {

struct MappingOptions {
  KeyframeOptions keyframes;     // spacing, odometry noise, capacity (max_keyframes)
  int max_part = 500;            // SMF's part size (the thesis: 500)
  int max_iterations = 100;      // LM steps of each part's solve
  double optimize_period = 5.0;  // s: a graph that changed is optimised at most this often
  bool use_gps = true;           // false: the map is the odometry frame at start (above)
  // The GPS error's white part and the correlation time of its wandering
  // bias (keyframes.hpp; trailnavd takes the GPS alignment's: pose.*).
  double gps_white_sigma = 1.5;
  double gps_bias_time = 120.0;
  // Loop closures from the lidar's revolutions (above); off without.
  std::optional<perception::registration::LoopClosureConfig> loops;
  double loop_max_gap = 1.0;                         // s between a keyframe and the revolution it takes
  std::size_t loop_arena_bytes = std::size_t{32} << 20;  // the verifications' k-d trees
};

// Checks the options; empty when fine, else names the field.
std::string check_mapping_options(const MappingOptions& options);

struct MapPathPose {
  std::int64_t time_ns = 0;
  double x = 0.0, y = 0.0, yaw = 0.0;
};

struct MappingSnapshot {
  explicit MappingSnapshot(std::size_t capacity) : path(capacity) {}
  std::int64_t time_ns = 0;  // the newest keyframe's pose time
  bool georeferenced = false;  // UTM (zone, north) below; else the odometry frame at start
  int zone = 0;
  bool north = true;
  bool optimised = false;      // the poses are a solve's (else the odometry's, as placed)
  // map -> odom: where the odometry frame lies in the map frame (UTM metres when georeferenced).
  double x = 0.0, y = 0.0, yaw = 0.0;
  std::vector<MapPathPose> path;  // the keyframes, oldest first; capacity max_keyframes
  std::size_t path_count = 0;
};

enum class MappingState : std::uint8_t { waiting_alignment, mapping, full };
const char* mapping_state_name(MappingState s) noexcept;

struct MappingTaskStatus {
  MappingState state = MappingState::waiting_alignment;
  std::uint64_t runs = 0;
  std::uint64_t poses = 0, poses_unmeasured = 0, poses_before_start = 0;
  std::uint64_t fixes = 0, fixes_before_start = 0;
  KeyframeCounters keyframes;
  std::size_t vertices = 0, edges = 0, capacity_vertices = 0, capacity_edges = 0;
  std::uint64_t optimisations = 0, failures = 0, published = 0;
  int levels = 0, iterations = 0;
  double initial_chi2 = 0.0, chi2 = 0.0;
  double solve_ms = 0.0, solve_max_ms = 0.0;
  // Bytes: the solver's arenas, reserved and their high-water marks.
  std::size_t hierarchy_capacity = 0, hierarchy_high_water = 0, part_capacity = 0, part_high_water = 0;
  std::array<char, 160> error{};  // the last solve's message when it failed; empty once one succeeds
  // The newest correction of the GPS alignment at the newest keyframe: how
  // far the optimised map moved the robot there, and turned it.
  double correction_m = 0.0, correction_rad = 0.0;
  // Loop closures: the verifications' counters, keyframes that found no
  // revolution within loop_max_gap (kept without a cloud), verifications
  // the arena could not serve, and its high-water mark.
  perception::registration::LoopCounters loops;
  std::uint64_t loop_no_cloud = 0, loop_arena_failures = 0;
  double loop_ms_max = 0.0;
  std::size_t loop_arena_capacity = 0, loop_arena_high_water = 0;
};

class MappingTask final : public Task {
 public:
  // `fixes` may be null (no GPS: use_gps must be false).
  MappingTask(const MappingOptions& options, perception::PoseQueue& poses, pose::MappingFixQueue* fixes,
              Mailbox<MappingSnapshot>& out);
  ~MappingTask() override;
  MappingTask(const MappingTask&) = delete;
  MappingTask& operator=(const MappingTask&) = delete;

  // Woken after each published snapshot (the DDS publisher). Before the scheduler starts.
  void set_notify(Wakeup* wakeup) noexcept { notify_ = wakeup; }
  // Where each solve's correction of the GPS alignment goes (the pose
  // task's, which applies it to every UTM pose). Before the scheduler starts.
  void set_corrections(Mailbox<pose::MapCorrection>* corrections) noexcept { corrections_ = corrections; }
  // The entry for lidar registration's loop closures (a later capability):
  // an edge between two keyframes (indices ≥ 1, as in the path) measured in
  // the first's frame, with its information. Call on this task's thread.
  bool add_loop_closure(std::int32_t from, std::int32_t to, const Se2& measurement, const Se2::Matrix& information);
  // With options.loops: the lidar's revolutions (a reader of its own), the
  // sensor's mount on the robot and the returns kept. Before the scheduler starts.
  void set_revolutions(Broadcast<velodyne::RangeImage>::Reader* revolutions, const Eigen::Isometry3f& mount,
                       float min_range, float max_range) noexcept {
    revolutions_ = revolutions;
    mount_ = mount;
    min_range_ = min_range;
    max_range_ = max_range;
  }

  void run(const TaskTick& tick) override;
  MappingTaskStatus status() const noexcept { return shared_.read(); }

 private:
  void take_pose(const perception::Pose& p);
  void take_fix(const pose::MappingFix& f);
  void optimise();
  void publish();
  Se2 correction() const noexcept;  // map -> odom in graph coordinates
  // Loop closures: the keyframes waiting for a revolution, and one taken.
  void take_revolution(const velodyne::RangeImage& image);
  void give_up_waiting(std::int64_t now_ns);
  void pop_waiting(std::span<const perception::registration::Point> cloud);  // the oldest, to the closer
  void close_loops();

  MappingOptions options_;
  perception::PoseQueue& poses_;
  pose::MappingFixQueue* fixes_;
  Mailbox<MappingSnapshot>& out_;
  Wakeup* notify_ = nullptr;
  Mailbox<pose::MapCorrection>* corrections_ = nullptr;
  KeyframeGraph graph_;
  std::unique_ptr<Arena> part_arena_;
  SmfSolver<Se2> solver_;
  std::vector<Se2> keyframe_odometry_;     // per vertex (0: the anchor)
  std::vector<std::int64_t> keyframe_time_;
  std::vector<Se2> backup_;                // the poses before a solve, put back if it fails
  std::array<perception::Pose, perception::kPoseQueueCapacity> pose_batch_{};
  std::array<pose::MappingFix, pose::kMappingFixCapacity> fix_batch_{};
  bool started_ = false;
  Se2 start_transform_{};                  // odometry -> map (graph coordinates) at the start
  Se2 alignment_{};                        // the newest fix's odometry -> UTM (absolute)
  Se2 alignment_at_keyframe_{};            // ... when the newest keyframe was made
  double origin_e_ = 0.0, origin_n_ = 0.0;
  int zone_ = 0;
  bool north_ = true;
  std::size_t solved_vertices_ = 0, solved_edges_ = 0;  // the graph at the last solve (or publish)
  std::int64_t last_optimise_ = -1;
  MappingTaskStatus local_;
  StatusBoard<MappingTaskStatus> shared_;
  // Loop closures.
  std::unique_ptr<perception::registration::LoopCloser> loops_;
  Broadcast<velodyne::RangeImage>::Reader* revolutions_ = nullptr;
  Eigen::Isometry3f mount_ = Eigen::Isometry3f::Identity();
  float min_range_ = 1.0f, max_range_ = 60.0f;
  std::unique_ptr<Arena> loop_arena_;
  std::unique_ptr<perception::PoseTrack> recent_;  // the odometry of the last seconds, for a revolution's pose
  struct Waiting {
    std::int64_t t_ns = 0;
    Se2 odometry{};
    double path = 0.0;
  };
  std::array<Waiting, 16> waiting_{};  // keyframes without a cloud yet, oldest first
  std::size_t waiting_count_ = 0;
  double path_ = 0.0;                  // m driven, by the odometry
  bool have_last_ = false;
  Se2 last_pose_{};
  std::vector<perception::registration::Point> cloud_;
  std::vector<Eigen::Isometry3d> estimates_;
};

}  // namespace trailnav::slam
