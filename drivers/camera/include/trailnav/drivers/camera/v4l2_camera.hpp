// A V4L2 video capture device (a USB or CSI camera; the kernel's `vivid` on
// the test machine): opened non-blocking, format, frame rate and exposure
// set from the config and checked against what the device accepted, the
// kernel's buffers memory-mapped at open (`buffers` of them), streamed, and
// each filled buffer handed out with the kernel's timestamp and sequence
// number, then queued again. Nothing is allocated, by open() either (the
// camera thread is watched by the allocation guard, and a camera that was
// unplugged is opened again while the daemon runs): the mappings live in a
// fixed table, errors are written into a fixed buffer (error()) naming the
// device and what it refused.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "trailnav/drivers/camera/frame.hpp"

namespace trailnav::drivers::camera {

// Where frames come from: a V4L2 device, or the image tunnel on a bench
// (image_tunnel.hpp; `trailnav replay --image-tunnel`).
enum class CameraInput : std::uint8_t { v4l2, tunnel };

struct CameraOptions {
  CameraInput input = CameraInput::v4l2;
  std::string device = "/dev/video0";
  std::uint16_t tunnel_port = 29538;  // tunnel: the loopback port listened on (0: the kernel picks)
  PixelFormat format = PixelFormat::yuyv;
  int width = 640, height = 480;
  double fps = 10.0;         // asked of the device (VIDIOC_S_PARM); 0: the device's own
  int buffers = 4;           // kernel buffers, memory-mapped (2-32)
  int exposure_us = 0;       // 0: the device's automatic exposure; else manual, in µs
  int out_width = 64, out_height = 32;  // the grey image handed on (place recognition's size)
  double reconnect_s = 1.0;  // between attempts to open
  double silence_s = 2.0;    // streaming without a frame this long: the device is reopened
};

// Checks the options' ranges; "" or what is wrong.
std::string check_camera_options(const CameraOptions& o);

struct Dequeued {
  int index = -1;
  std::span<const std::uint8_t> bytes;
  std::int64_t monotonic_ns = 0;  // the kernel's timestamp (CLOCK_MONOTONIC)
  std::uint32_t sequence = 0;     // the kernel's frame counter
  bool error_flag = false;        // V4L2_BUF_FLAG_ERROR: the driver says the data may be damaged
  bool start_of_exposure = false; // V4L2_BUF_FLAG_TSTAMP_SRC_SOE; else the end of the frame
};

class V4l2Camera {
 public:
  V4l2Camera() = default;
  ~V4l2Camera();
  V4l2Camera(const V4l2Camera&) = delete;
  V4l2Camera& operator=(const V4l2Camera&) = delete;

  // Opens and configures the device and starts streaming. False with error()
  // set when it cannot (the device left closed).
  bool open(const CameraOptions& options) noexcept;
  // What went wrong last (open, dequeue, requeue); "" before.
  const char* error() const noexcept { return error_; }
  void close() noexcept;
  bool is_open() const noexcept { return fd_ >= 0; }
  int fd() const noexcept { return fd_; }

  // What the device accepted.
  int width() const noexcept { return width_; }
  int height() const noexcept { return height_; }
  int bytes_per_line() const noexcept { return bytes_per_line_; }
  double fps() const noexcept { return fps_; }
  const char* card() const noexcept { return card_; }

  enum class Got : std::uint8_t { frame, none, lost };
  // The next filled buffer, `none` when none is ready, `lost` when the device
  // failed (unplugged: ENODEV, EIO), with error() set.
  Got dequeue(Dequeued& out) noexcept;
  bool requeue(int index) noexcept;

 private:
  struct Mapping {
    void* start = nullptr;
    std::size_t length = 0;
  };
  bool fail(const char* format, ...) noexcept __attribute__((format(printf, 2, 3)));

  int fd_ = -1;
  std::array<Mapping, 32> maps_{};  // camera.buffers is at most 32
  std::size_t mapped_ = 0;
  int width_ = 0, height_ = 0, bytes_per_line_ = 0;
  double fps_ = 0.0;
  char device_[128] = {};
  char card_[32] = {};
  char error_[256] = {};
  bool streaming_ = false;
};

}  // namespace trailnav::drivers::camera
