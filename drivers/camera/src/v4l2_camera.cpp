#include "trailnav/drivers/camera/v4l2_camera.hpp"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
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

std::string fourcc_text(std::uint32_t f) {
  char s[5] = {static_cast<char>(f & 0xff), static_cast<char>((f >> 8) & 0xff), static_cast<char>((f >> 16) & 0xff),
               static_cast<char>((f >> 24) & 0xff), 0};
  return s;
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
  for (const Mapping& m : maps_)
    if (m.start != nullptr && m.start != MAP_FAILED) ::munmap(m.start, m.length);
  maps_.clear();
  ::close(fd_);
  fd_ = -1;
}

std::string V4l2Camera::open(const CameraOptions& o) {
  close();
  const std::string dev = o.device;
  const auto fail = [&](const std::string& what) {
    const std::string message = dev + ": " + what;
    close();
    return message;
  };
  fd_ = ::open(dev.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) return dev + ": cannot open (" + std::strerror(errno) + ")";
  v4l2_capability cap{};
  if (xioctl(fd_, VIDIOC_QUERYCAP, &cap) < 0) return fail(std::string("not a V4L2 device (VIDIOC_QUERYCAP: ") + std::strerror(errno) + ")");
  card_ = reinterpret_cast<const char*>(cap.card);
  const std::uint32_t caps = (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  if ((caps & V4L2_CAP_VIDEO_CAPTURE) == 0) return fail("'" + card_ + "' does not capture video (a single-planar capture device is needed)");
  if ((caps & V4L2_CAP_STREAMING) == 0) return fail("'" + card_ + "' cannot stream through memory-mapped buffers");
  // The format.
  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fmt.fmt.pix.width = static_cast<std::uint32_t>(o.width);
  fmt.fmt.pix.height = static_cast<std::uint32_t>(o.height);
  fmt.fmt.pix.pixelformat = fourcc_of(o.format);
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (xioctl(fd_, VIDIOC_S_FMT, &fmt) < 0) return fail(std::string("VIDIOC_S_FMT refused: ") + std::strerror(errno));
  if (fmt.fmt.pix.pixelformat != fourcc_of(o.format) || static_cast<int>(fmt.fmt.pix.width) != o.width ||
      static_cast<int>(fmt.fmt.pix.height) != o.height) {
    char b[200];
    std::snprintf(b, sizeof b, "offers %u x %u %s where %d x %d %s was set (camera.width, height, format)", fmt.fmt.pix.width,
                  fmt.fmt.pix.height, fourcc_text(fmt.fmt.pix.pixelformat).c_str(), o.width, o.height,
                  fourcc_text(fourcc_of(o.format)).c_str());
    return fail(b);
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
      return fail(std::string("VIDIOC_S_PARM (camera.fps) refused: ") + std::strerror(errno));
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
        return fail("'" + card_ + "' does not take a manual exposure (camera.exposure_us; 0 leaves it automatic)");
    }
  }
  // Buffers.
  v4l2_requestbuffers req{};
  req.count = static_cast<std::uint32_t>(o.buffers);
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  if (xioctl(fd_, VIDIOC_REQBUFS, &req) < 0) return fail(std::string("VIDIOC_REQBUFS refused: ") + std::strerror(errno));
  if (req.count < 2) return fail("gave " + std::to_string(req.count) + " buffers; at least 2 are needed");
  maps_.assign(req.count, Mapping{});
  for (std::uint32_t i = 0; i < req.count; ++i) {
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = i;
    if (xioctl(fd_, VIDIOC_QUERYBUF, &buf) < 0) return fail(std::string("VIDIOC_QUERYBUF: ") + std::strerror(errno));
    void* p = ::mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, buf.m.offset);
    if (p == MAP_FAILED) return fail(std::string("mmap of a buffer: ") + std::strerror(errno));
    maps_[i] = {p, buf.length};
    if (xioctl(fd_, VIDIOC_QBUF, &buf) < 0) return fail(std::string("VIDIOC_QBUF: ") + std::strerror(errno));
  }
  int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(fd_, VIDIOC_STREAMON, &type) < 0) return fail(std::string("VIDIOC_STREAMON: ") + std::strerror(errno));
  streaming_ = true;
  return "";
}

V4l2Camera::Got V4l2Camera::dequeue(Dequeued& out, std::string& error) noexcept {
  if (fd_ < 0) return Got::none;
  v4l2_buffer buf{};
  buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  buf.memory = V4L2_MEMORY_MMAP;
  if (xioctl(fd_, VIDIOC_DQBUF, &buf) < 0) {
    if (errno == EAGAIN) return Got::none;
    error.assign("VIDIOC_DQBUF: ");
    error.append(std::strerror(errno));
    return Got::lost;
  }
  if (buf.index >= maps_.size()) {
    error.assign("VIDIOC_DQBUF gave an unknown buffer");
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

bool V4l2Camera::requeue(int index, std::string& error) noexcept {
  v4l2_buffer buf{};
  buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  buf.memory = V4L2_MEMORY_MMAP;
  buf.index = static_cast<std::uint32_t>(index);
  if (xioctl(fd_, VIDIOC_QBUF, &buf) < 0) {
    error.assign("VIDIOC_QBUF: ");
    error.append(std::strerror(errno));
    return false;
  }
  return true;
}

}  // namespace trailnav::drivers::camera
