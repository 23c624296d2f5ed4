// Wheel odometry from CAN frames: the robot's wheel speeds (or cumulative
// encoder ticks) decoded with its DBC and integrated into a planar pose in
// the odometry frame, for differential-drive robots and car-like (Ackermann)
// platforms. Configured per robot by naming the DBC messages and signals.
//
//   differential  v = (vl + vr) / 2,  yaw rate = (vr - vl) / track
//   ackermann     the same from the rear (unsteered) wheels, or, with a
//                 steering signal, yaw rate = v tan(delta) / wheelbase
//
// create() resolves the names (and allocates); on_frame() does not allocate.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "trailnav/drivers/can/dbc.hpp"
#include "trailnav/drivers/can/frame.hpp"

namespace trailnav::can {

enum class Platform : std::uint8_t { differential, ackermann };
enum class WheelInput : std::uint8_t { speed, ticks };

struct SignalRef {
  std::string message;  // DBC message name
  std::string signal;   // signal name in it
  bool empty() const noexcept { return message.empty(); }
};

struct WheelOdometryOptions {
  Platform platform = Platform::differential;
  WheelInput input = WheelInput::speed;
  SignalRef left, right;        // ackermann: the rear wheels
  double speed_scale = 1.0;     // signal unit to m/s (km/h: 1/3.6)
  double ticks_per_metre = 0.0; // ticks input
  double track = 0.5;           // m between the left and right wheels used
  SignalRef steering;           // ackermann, optional: road-wheel angle
  double steering_scale = 0.0;  // signal unit to rad
  double wheelbase = 0.0;       // m, with steering
  double max_speed = 30.0;      // m/s; faster wheel readings are implausible and skipped
  double max_gap = 0.5;         // s; a longer gap between readings is not integrated
};

struct OdometryState {
  std::int64_t time_ns = 0;
  double x = 0.0, y = 0.0, yaw = 0.0;  // odometry frame: starts at the origin, heading 0
  double speed = 0.0;                  // m/s, forward positive
  double yaw_rate = 0.0;               // rad/s, counter-clockwise positive
  double distance = 0.0;               // m driven (absolute)
  std::uint64_t updates = 0;
};

struct OdometryCounters {
  std::uint64_t frames = 0;         // frames of the configured messages
  std::uint64_t decode_errors = 0;  // signals that could not be decoded
  std::uint64_t implausible = 0;    // readings beyond max_speed: skipped
  std::uint64_t gaps = 0;           // readings after more than max_gap: not integrated
  std::uint64_t time_back = 0;      // readings stamped before the one before (the host clock stepped back): not integrated
  std::uint64_t updates = 0;
};

class WheelOdometry {
 public:
  struct Created;
  // Errors name the DBC file and the missing message or signal.
  static Created create(const Dbc& dbc, const WheelOdometryOptions& options);

  // True when the frame completed a reading and the pose moved on.
  bool on_frame(const Frame& frame) noexcept;
  const OdometryState& state() const noexcept { return state_; }
  const OdometryCounters& counters() const noexcept { return counters_; }
  const WheelOdometryOptions& options() const noexcept { return options_; }
  // Frame ids the odometry uses (for SocketCAN filters); count in `n`.
  std::size_t ids(std::uint32_t* out, std::size_t capacity) const noexcept;

 private:
  struct Bound {
    std::uint32_t id = 0;  // with kEffFlag for extended ids
    DbcSignal signal;
    bool used = false;
    double value = 0.0;
    bool fresh = false;
    double last_ticks = 0.0;
    bool have_ticks = false;
    double range = 0.0;  // ticks: the signal's span, for wrap-around
  };
  WheelOdometry() = default;
  void integrate(std::int64_t time_ns) noexcept;

  WheelOdometryOptions options_;
  Bound left_, right_, steering_;
  OdometryState state_;
  OdometryCounters counters_;
  std::int64_t last_reading_ = 0;
  bool have_reading_ = false;
};

struct WheelOdometry::Created {
  std::unique_ptr<WheelOdometry> odometry;
  std::string error;
};

}  // namespace trailnav::can
