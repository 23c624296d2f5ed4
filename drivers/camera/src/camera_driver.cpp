#include "trailnav/drivers/camera/camera_driver.hpp"

#include <time.h>

#include <algorithm>
#include <cstdio>
#include <cstring>

#include "trailnav/drivers/udp/udp_receiver.hpp"
#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::drivers::camera {

const char* camera_health_name(CameraHealth h) noexcept {
  switch (h) {
    case CameraHealth::no_device: return "no_device";
    case CameraHealth::streaming: return "streaming";
    case CameraHealth::silent: return "silent";
  }
  return "?";
}

CameraDriver::Created CameraDriver::create(const CameraOptions& options) {
  Created c;
  c.error = check_camera_options(options);
  if (!c.error.empty()) return c;
  try {
    c.driver.reset(new CameraDriver(options));
  } catch (const std::exception& e) {
    c.error = e.what();
    return c;
  }
  if (options.input == CameraInput::tunnel) {
    udp::ReceiverOptions r;
    r.bind = {0x7F000001u, options.tunnel_port};  // loopback only
    r.max_datagram_bytes = static_cast<int>(kImageTunnelHeader + kFragmentBytes);
    r.batch = 64;
    auto opened = udp::UdpReceiver::open(r);
    if (!opened.receiver) {
      c.error = "camera tunnel: " + opened.error;
      c.driver.reset();
      return c;
    }
    c.driver->tunnel_ = std::move(opened.receiver);
    c.driver->local_.tunnel_port = c.driver->tunnel_->local().port;
    c.driver->shared_.post(c.driver->local_);
  }
  return c;
}

CameraDriver::~CameraDriver() = default;

void CameraDriver::run_tunnel(Nanos now) noexcept {
  for (const udp::Datagram& d : tunnel_->receive()) {
    if (!assembler_->add(d.payload)) continue;
    ++local_.counters.frames;
    last_frame_ = now;
    local_.health = CameraHealth::streaming;
    if (assembler_->width() != options_.width || assembler_->height() != options_.height) {
      ++local_.counters.corrupt;
      char b[160];
      std::snprintf(b, sizeof b, "a tunnel frame of %d x %d pixels where camera.width x height is %d x %d",
                    assembler_->width(), assembler_->height(), options_.width, options_.height);
      note_error(b);
      continue;
    }
    if (have_sequence_ && assembler_->sequence() > last_sequence_ + 1)
      local_.counters.dropped += assembler_->sequence() - last_sequence_ - 1;
    have_sequence_ = true;
    last_sequence_ = assembler_->sequence();
    converter_.convert(assembler_->frame(), options_.width);
    CameraFrame& f = frames_.write_slot();
    std::copy(converter_.grey().begin(), converter_.grey().end(), f.pixels.begin());
    f.receive_ns = d.receive_ns;
    f.stamp_ns = d.receive_ns;
    f.sequence = assembler_->sequence();
    f.start_of_exposure = false;
    frames_.publish();
    ++local_.counters.published;
  }
  local_.counters.tunnel = assembler_->counters();
  if (local_.health == CameraHealth::streaming && now - last_frame_ > static_cast<Nanos>(options_.silence_s * 1e9)) {
    local_.health = CameraHealth::silent;
    ++local_.counters.lost;
  }
  shared_.post(local_);
}

CameraDriver::CameraDriver(const CameraOptions& options)
    : options_(options),
      // The tunnel carries grey frames whatever the camera's format was.
      converter_(options.input == CameraInput::tunnel ? PixelFormat::grey : options.format, options.width, options.height,
                 options.out_width, options.out_height),
      frames_(options.out_width, options.out_height) {
  if (options.input == CameraInput::tunnel) assembler_ = std::make_unique<ImageAssembler>(options.width, options.height);
}

void CameraDriver::note_error(const char* e) noexcept {
  const std::size_t n = std::min(std::strlen(e), local_.last_error.size() - 1);
  std::memcpy(local_.last_error.data(), e, n);
  local_.last_error[n] = '\0';
}

void CameraDriver::lose(Nanos now, const char* why) noexcept {
  note_error(why);
  camera_.close();
  ++local_.counters.lost;
  local_.health = CameraHealth::no_device;
  next_open_ = now + static_cast<Nanos>(options_.reconnect_s * 1e9);
  have_sequence_ = false;
}

void CameraDriver::run(const TaskTick& tick) {
  const Nanos now = tick.started;
  if (tunnel_) {
    run_tunnel(now);
    return;
  }
  if (!camera_.is_open()) {
    if (now >= next_open_) {
      if (camera_.open(options_)) {
        ++local_.counters.opens;
        local_.health = CameraHealth::streaming;
        local_.fps = camera_.fps();
        last_frame_ = now;
      } else {
        ++local_.counters.open_failures;
        note_error(camera_.error());
        next_open_ = now + static_cast<Nanos>(options_.reconnect_s * 1e9);
      }
    }
    shared_.post(local_);
    return;
  }
  // Every frame the kernel has filled: counted, the newest converted and
  // published (a late run does not publish stale frames one after another).
  Dequeued d, newest;
  bool have = false;
  for (;;) {
    const V4l2Camera::Got got = camera_.dequeue(d);
    if (got == V4l2Camera::Got::none) break;
    if (got == V4l2Camera::Got::lost) {
      if (have) camera_.requeue(newest.index);
      lose(now, camera_.error());
      shared_.post(local_);
      return;
    }
    ++local_.counters.frames;
    if (have_sequence_ && d.sequence > last_sequence_ + 1) local_.counters.dropped += d.sequence - last_sequence_ - 1;
    have_sequence_ = true;
    last_sequence_ = d.sequence;
    if (d.error_flag) {
      ++local_.counters.damaged;
      camera_.requeue(d.index);
      continue;
    }
    if (have) camera_.requeue(newest.index);
    newest = d;
    have = true;
  }
  if (have) {
    last_frame_ = now;
    local_.health = CameraHealth::streaming;
    if (converter_.convert(newest.bytes, camera_.bytes_per_line())) {
      CameraFrame& f = frames_.write_slot();
      std::copy(converter_.grey().begin(), converter_.grey().end(), f.pixels.begin());
      timespec mono{};
      ::clock_gettime(CLOCK_MONOTONIC, &mono);
      const std::int64_t mono_now = static_cast<std::int64_t>(mono.tv_sec) * 1'000'000'000LL + mono.tv_nsec;
      f.receive_ns = host_now_ns();
      f.stamp_ns = f.receive_ns - (mono_now - newest.monotonic_ns);
      f.sequence = newest.sequence;
      f.start_of_exposure = newest.start_of_exposure;
      frames_.publish();
      ++local_.counters.published;
    } else {
      ++local_.counters.corrupt;
      note_error(converter_.error());
    }
    local_.counters.jpeg_warnings = converter_.jpeg_warnings();
    if (!camera_.requeue(newest.index)) {
      lose(now, camera_.error());
      shared_.post(local_);
      return;
    }
  } else if (now - last_frame_ > static_cast<Nanos>(options_.silence_s * 1e9)) {
    local_.health = CameraHealth::silent;
    char why[200];
    std::snprintf(why, sizeof why, "%.120s: no frame for %.2f s while streaming", options_.device.c_str(), options_.silence_s);
    lose(now, why);
  }
  shared_.post(local_);
}

}  // namespace trailnav::drivers::camera
