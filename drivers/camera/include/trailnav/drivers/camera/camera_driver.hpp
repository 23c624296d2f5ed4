// The camera driver task (issue 41): a V4L2 device opened at its first run
// and reopened after `reconnect_s` whenever it fails or stays silent for
// `silence_s` (unplugged, reset, a stalled USB link); each dequeued frame
// converted to grey, reduced to out_width x out_height and published through
// a mailbox with the kernel's timestamp in host time; counters of frames,
// frames the kernel dropped (gaps in its sequence numbers), frames marked
// damaged or not decodable, opens and losses, readable from any thread. Runs
// periodically (the preset: 30 Hz, at least a camera's frame rate) and takes
// every frame ready then; it does not watch a descriptor (the device's is
// opened after the scheduler starts, and a tunnel's readiness per fragment
// would wake the thread for each of a frame's fragments).
//
// With `input: tunnel` the frames come over UDP on loopback instead
// (image_tunnel.hpp), grey and of the configured size, stamped when their
// last fragment arrived; health follows them the same way.
//
// The scheduler's threads are all watched by the allocation guard, this one
// (normal scheduling) too: opening the device, reopening it and reporting
// errors allocate nothing (v4l2_camera.hpp), nor do frames: MJPEG's decoder
// takes its memory from the converter's block (frame.hpp).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "trailnav/drivers/camera/frame.hpp"
#include "trailnav/drivers/camera/image_tunnel.hpp"
#include "trailnav/drivers/camera/v4l2_camera.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"

namespace trailnav::udp {
class UdpReceiver;
}

namespace trailnav::drivers::camera {

struct CameraFrame {
  CameraFrame(int w, int h) : width(w), height(h), pixels(static_cast<std::size_t>(w) * static_cast<std::size_t>(h)) {}
  int width, height;
  std::vector<std::uint8_t> pixels;  // grey, row-major
  std::int64_t stamp_ns = 0;         // host time (runtime/host_clock.hpp) of the kernel's timestamp
  std::int64_t receive_ns = 0;       // host time when dequeued
  std::uint32_t sequence = 0;        // the kernel's
  bool start_of_exposure = false;    // the stamp is the exposure's start (else the frame's end, as the device says)
};

enum class CameraHealth : std::uint8_t { no_device, streaming, silent };
const char* camera_health_name(CameraHealth h) noexcept;

struct CameraCounters {
  std::uint64_t frames = 0;      // dequeued
  std::uint64_t published = 0;
  std::uint64_t dropped = 0;     // gaps in the kernel's sequence numbers
  std::uint64_t damaged = 0;     // V4L2_BUF_FLAG_ERROR, not published
  std::uint64_t corrupt = 0;     // not convertible (short, or an MJPEG that does not decode), not published
  std::uint64_t jpeg_warnings = 0;  // MJPEG frames decoded with libjpeg's warnings, published
  std::uint64_t opens = 0;
  std::uint64_t open_failures = 0;
  std::uint64_t lost = 0;        // streaming stopped by an error or silence
  AssemblerCounters tunnel;      // input: tunnel
};

struct CameraStatus {
  CameraHealth health = CameraHealth::no_device;
  CameraCounters counters;
  double fps = 0.0;  // what the device accepted
  std::uint16_t tunnel_port = 0;  // input: tunnel: the port bound
  std::array<char, 200> last_error{};
};

class CameraDriver final : public Task {
 public:
  struct Created;
  // Checks the options (check_camera_options) and allocates the converter
  // and the mailbox; the device is opened by the first run.
  static Created create(const CameraOptions& options);

  void run(const TaskTick& tick) override;
  ~CameraDriver() override;

  Mailbox<CameraFrame>& frames() noexcept { return frames_; }
  CameraStatus status() const noexcept { return shared_.read(); }
  const CameraOptions& options() const noexcept { return options_; }

 private:
  explicit CameraDriver(const CameraOptions& options);
  void run_tunnel(Nanos now) noexcept;
  void note_error(const char* e) noexcept;
  void lose(Nanos now, const char* why) noexcept;

  CameraOptions options_;
  V4l2Camera camera_;
  FrameConverter converter_;
  std::unique_ptr<udp::UdpReceiver> tunnel_;
  std::unique_ptr<ImageAssembler> assembler_;
  Mailbox<CameraFrame> frames_;
  Nanos next_open_ = 0;
  Nanos last_frame_ = 0;
  bool have_sequence_ = false;
  std::uint32_t last_sequence_ = 0;
  CameraStatus local_;
  StatusBoard<CameraStatus> shared_;
};

struct CameraDriver::Created {
  std::unique_ptr<CameraDriver> driver;
  std::string error;
};

}  // namespace trailnav::drivers::camera
