// The navigation thread: a thin scheduler task around Navigator. Each run
// takes the newest pose snapshot (its own mailbox from the pose task, both
// frames of one instant) and, when the terrain thread published one, the
// newest terrain-class map (its own Broadcast reader); steps the navigator;
// and hands a NavigationSnapshot to the DDS publisher through a mailbox.
// Orders from outside (goals, cancel) arrive through a queue filled by the
// DDS command reader, a plain thread; each run takes what is queued before it
// steps. It never allocates after construction and never waits.
#pragma once

#include <array>
#include <cstdint>

#include "trailnav/navigation/navigator/navigator.hpp"
#include "trailnav/navigation/pose/pose_estimator.hpp"
#include "trailnav/runtime/broadcast.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/spsc_queue.hpp"
#include "trailnav/runtime/status_board.hpp"
#include "trailnav/runtime/wakeup.hpp"

namespace trailnav::nav {

// An order for the navigator.
struct NavCommand {
  enum class Kind : std::uint8_t { goal, cancel };
  Kind kind = Kind::goal;
  GoalRequest goal;
};
inline constexpr std::size_t kNavCommandCapacity = 64;
using NavCommandQueue = SpscQueue<NavCommand, kNavCommandCapacity>;
// The status after each order, to the publisher.
inline constexpr std::size_t kNavStatusQueueCapacity = 64;
using NavStatusQueue = SpscQueue<NavigationStatusReport, kNavStatusQueueCapacity>;

struct NavigationTaskStatus {
  std::uint64_t runs = 0;
  std::uint64_t poses = 0;         // new pose snapshots seen
  std::uint64_t terrain_maps = 0;  // new class maps seen
  std::uint64_t published = 0;     // snapshots handed to the publisher
  std::uint64_t commands = 0;      // orders taken from the queue
  std::uint64_t answers_dropped = 0;  // statuses after an order the publisher's queue had no room for
  NavState state = NavState::idle;
  std::size_t subgoals = 0, active = 0;
  double route_length = 0.0, progress = 0.0, cross_track = 0.0;
  NavigationCounters navigator;
  double remaining = 0.0;
  const char* message = "";
  std::array<char, 160> refusal{};
};

class NavigationTask final : public Task {
 public:
  // `terrain` may be null (no terrain thread: the subgoals stay raw).
  NavigationTask(Navigator& navigator, Mailbox<pose::PoseSnapshot>& poses,
                 Broadcast<perception::TerrainClassMap>::Reader* terrain, Mailbox<NavigationSnapshot>& out);

  // Woken after each published snapshot (the DDS publisher). Before the scheduler starts.
  void set_notify(Wakeup* wakeup) noexcept { notify_ = wakeup; }
  // Where orders come from (the DDS command reader), and where the status
  // after each goes (the publisher; may be null). Before the scheduler starts.
  void set_commands(NavCommandQueue* commands, NavStatusQueue* answers = nullptr) noexcept {
    commands_ = commands;
    answers_ = answers;
  }

  void run(const TaskTick& tick) override;
  NavigationTaskStatus status() const noexcept { return shared_.read(); }

 private:
  Navigator& navigator_;
  Mailbox<pose::PoseSnapshot>& poses_;
  Broadcast<perception::TerrainClassMap>::Reader* terrain_;
  Mailbox<NavigationSnapshot>& out_;
  Wakeup* notify_ = nullptr;
  NavCommandQueue* commands_ = nullptr;
  NavStatusQueue* answers_ = nullptr;
  NavigationStatusReport answer_;
  std::uint64_t last_active_revision_ = 0, last_path_revision_ = 0;
  NavState last_state_ = NavState::idle;
  std::uint64_t last_goal_revision_ = 0;
  NavigationTaskStatus local_;
  StatusBoard<NavigationTaskStatus> shared_;
};

}  // namespace trailnav::nav
