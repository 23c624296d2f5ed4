#include "trailnav/drivers/camera/v4l2_camera.hpp"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace trailnav::drivers::camera {
namespace {

int xioctl(int fd, unsigned long request, void* arg) noexcept {
  int r;
  do {
    r = ::ioctl(fd, request, arg);
  } while (r < 0 && errno == EINTR);
  return r;
}

void fourcc_text(std::uint32_t f, char (&out)[5]) noexcept {
  for (int i = 0; i < 4; ++i) out[i] = static_cast<char>((f >> (8 * i)) & 0xff);
  out[4] = '\0';
}

}  // namespace

std::string check_camera_options(const CameraOptions& o) {
  if (o.device.empty()) return "camera.device is empty";
  if (o.width < 1 || o.height < 1 || o.width > 8192 || o.height > 8192)
    return "camera.width and camera.height must be 1 to 8192 pixels";
  if (o.out_width < 1 || o.out_height < 1 || o.out_width > o.width || o.out_height > o.height)
    return "camera.out_width x out_height must be at least 1 and at most the frame's width x height";
  if (!(o.fps >= 0.0) || o.fps > 1000.0) return "camera.fps must be 0 (the device's) to 1000";
  if (o.buffers < 2 || o.buffers > 32) return "camera.buffers must be 2 to 32";
  if (o.exposure_us < 0) return "camera.exposure_us must be 0 (automatic) or a positive time";
  if (!(o.reconnect_s > 0.0) || !(o.silence_s > 0.0)) return "camera.reconnect_s and camera.silence_s must be positive";
  return "";
}

V4l2Camera::~V4l2Camera() { close(); }

void V4l2Camera::close() noexcept {
  if (fd_ < 0) return;
  if (streaming_) {
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    xioctl(fd_, VIDIOC_STREAMOFF, &type);
    streaming_ = false;
  }
  for (std::size_t i = 0; i < mapped_; ++i) ::munmap(maps_[i].start, maps_[i].length);
  mapped_ = 0;
  ::close(fd_);
  fd_ = -1;
}

// The error, after the device's name; the device closed. Always false.
bool V4l2Camera::fail(const char* format, ...) noexcept {
  char what[200];
  va_list args;
  va_start(args, format);
  std::vsnprintf(what, sizeof what, format, args);
  va_end(args);
  std::snprintf(error_, sizeof error_, "%.100s: %.150s", device_, what);
  close();
  return false;
}

bool V4l2Camera::open(const CameraOptions& o) noexcept {
  close();
  error_[0] = '\0';
  std::snprintf(device_, sizeof device_, "%s", o.device.c_str());
  fd_ = ::open(device_, O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) return fail("cannot open (%s)", std::strerror(errno));
  v4l2_capability cap{};
  if (xioctl(fd_, VIDIOC_QUERYCAP, &cap) < 0) return fail("not a V4L2 device (VIDIOC_QUERYCAP: %s)", std::strerror(errno));
  std::snprintf(card_, sizeof card_, "%s", reinterpret_cast<const char*>(cap.card));
  const std::uint32_t caps = (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  if ((caps & V4L2_CAP_VIDEO_CAPTURE) == 0)
    return fail("'%s' does not capture video (a single-planar capture device is needed)", card_);
  if ((caps & V4L2_CAP_STREAMING) == 0) return fail("'%s' cannot stream through memory-mapped buffers", card_);
  // The format.
  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fmt.fmt.pix.width = static_cast<std::uint32_t>(o.width);
  fmt.fmt.pix.height = static_cast<std::uint32_t>(o.height);
  fmt.fmt.pix.pixelformat = fourcc_of(o.format);
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (xioctl(fd_, VIDIOC_S_FMT, &fmt) < 0) return fail("VIDIOC_S_FMT refused: %s", std::strerror(errno));
  if (fmt.fmt.pix.pixelformat != fourcc_of(o.format) || static_cast<int>(fmt.fmt.pix.width) != o.width ||
      static_cast<int>(fmt.fmt.pix.height) != o.height) {
    char offered[5], wanted[5];
    fourcc_text(fmt.fmt.pix.pixelformat, offered);
    fourcc_text(fourcc_of(o.format), wanted);
    return fail("offers %u x %u %s where %d x %d %s was set (camera.width, height, format)", fmt.fmt.pix.width,
                fmt.fmt.pix.height, offered, o.width, o.height, wanted);
  }
  width_ = o.width;
  height_ = o.height;
  bytes_per_line_ = static_cast<int>(fmt.fmt.pix.bytesperline);
  // The frame rate.
  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (o.fps > 0.0) {
    parm.parm.capture.timeperframe.numerator = 1000;
    parm.parm.capture.timeperframe.denominator = static_cast<std::uint32_t>(std::lround(o.fps * 1000.0));
    if (xioctl(fd_, VIDIOC_S_PARM, &parm) < 0 && errno != ENOTTY)
      return fail("VIDIOC_S_PARM (camera.fps) refused: %s", std::strerror(errno));
  }
  parm = {};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fps_ = 0.0;
  if (xioctl(fd_, VIDIOC_G_PARM, &parm) == 0 && parm.parm.capture.timeperframe.numerator > 0)
    fps_ = static_cast<double>(parm.parm.capture.timeperframe.denominator) / parm.parm.capture.timeperframe.numerator;
  // Exposure: automatic, or manual in units of 100 µs (V4L2_CID_EXPOSURE_ABSOLUTE).
  {
    v4l2_control c{};
    c.id = V4L2_CID_EXPOSURE_AUTO;
    c.value = o.exposure_us > 0 ? V4L2_EXPOSURE_MANUAL : V4L2_EXPOSURE_AUTO;
    const bool has_auto = xioctl(fd_, VIDIOC_S_CTRL, &c) == 0;
    if (o.exposure_us > 0) {
      v4l2_control e{};
      e.id = V4L2_CID_EXPOSURE_ABSOLUTE;
      e.value = std::max(1, (o.exposure_us + 50) / 100);
      if (!has_auto || xioctl(fd_, VIDIOC_S_CTRL, &e) < 0)
        return fail("'%s' does not take a manual exposure (camera.exposure_us; 0 leaves it automatic)", card_);
    }
  }
  // Buffers.
  v4l2_requestbuffers req{};
  req.count = static_cast<std::uint32_t>(std::min<std::size_t>(static_cast<std::size_t>(o.buffers), maps_.size()));
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  if (xioctl(fd_, VIDIOC_REQBUFS, &req) < 0) return fail("VIDIOC_REQBUFS refused: %s", std::strerror(errno));
  if (req.count < 2 || req.count > maps_.size()) return fail("gave %u buffers; 2 to 32 are needed", req.count);
  for (std::uint32_t i = 0; i < req.count; ++i) {
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = i;
    if (xioctl(fd_, VIDIOC_QUERYBUF, &buf) < 0) return fail("VIDIOC_QUERYBUF: %s", std::strerror(errno));
    void* p = ::mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, buf.m.offset);
    if (p == MAP_FAILED) return fail("mmap of a buffer: %s", std::strerror(errno));
    maps_[i] = {p, buf.length};
    mapped_ = i + 1;
    if (xioctl(fd_, VIDIOC_QBUF, &buf) < 0) return fail("VIDIOC_QBUF: %s", std::strerror(errno));
  }
  int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(fd_, VIDIOC_STREAMON, &type) < 0) return fail("VIDIOC_STREAMON: %s", std::strerror(errno));
  streaming_ = true;
  return true;
}

V4l2Camera::Got V4l2Camera::dequeue(Dequeued& out) noexcept {
  if (fd_ < 0) return Got::none;
  v4l2_buffer buf{};
  buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  buf.memory = V4L2_MEMORY_MMAP;
  if (xioctl(fd_, VIDIOC_DQBUF, &buf) < 0) {
    if (errno == EAGAIN) return Got::none;
    std::snprintf(error_, sizeof error_, "%.100s: VIDIOC_DQBUF: %.100s", device_, std::strerror(errno));
    return Got::lost;
  }
  if (buf.index >= mapped_) {
    std::snprintf(error_, sizeof error_, "%.100s: VIDIOC_DQBUF gave an unknown buffer", device_);
    return Got::lost;
  }
  const Mapping& m = maps_[buf.index];
  out.index = static_cast<int>(buf.index);
  out.bytes = {static_cast<const std::uint8_t*>(m.start), std::min<std::size_t>(buf.bytesused, m.length)};
  out.monotonic_ns = static_cast<std::int64_t>(buf.timestamp.tv_sec) * 1'000'000'000LL +
                     static_cast<std::int64_t>(buf.timestamp.tv_usec) * 1000LL;
  out.sequence = buf.sequence;
  out.error_flag = (buf.flags & V4L2_BUF_FLAG_ERROR) != 0;
  out.start_of_exposure = (buf.flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK) == V4L2_BUF_FLAG_TSTAMP_SRC_SOE;
  return Got::frame;
}

bool V4l2Camera::requeue(int index) noexcept {
  v4l2_buffer buf{};
  buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  buf.memory = V4L2_MEMORY_MMAP;
  buf.index = static_cast<std::uint32_t>(index);
  if (xioctl(fd_, VIDIOC_QBUF, &buf) < 0) {
    std::snprintf(error_, sizeof error_, "%.100s: VIDIOC_QBUF: %.100s", device_, std::strerror(errno));
    return false;
  }
  return true;
}

}  // namespace trailnav::drivers::camera
