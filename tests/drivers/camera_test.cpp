// The camera driver on this machine: the frame conversions (grey with its
// line stride, YUYV's Y bytes, Motion-JPEG through libturbojpeg on a real
// Nordland frame, the area reduction) with no heap on the uncompressed paths,
// the options' checks, and the device's errors where there is no camera. The
// V4L2 path itself runs against the kernel's `vivid` in the kernel tests'
// virtual machine (tests/kernel/kernel_devices_test.cpp, KernelCamera).
#include <gtest/gtest.h>

#include <turbojpeg.h>

#include <cstdlib>
#include <numeric>

#include "test_data.hpp"
#include "trailnav/drivers/camera/camera_driver.hpp"
#include "trailnav/drivers/camera/frame.hpp"
#include "trailnav/drivers/camera/image_file.hpp"
#include "trailnav/runtime/alloc_guard.hpp"

namespace trailnav::drivers::camera {
namespace {

TEST(CameraFrame, GreyAndYuyvWithTheirStridesAndNoHeap) {
  const int w = 8, h = 4, stride = 12;
  std::vector<std::uint8_t> grey(static_cast<std::size_t>(stride * h), 0xEE);  // padding 0xEE
  std::vector<std::uint8_t> yuyv(static_cast<std::size_t>(2 * w * h + 8), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      grey[static_cast<std::size_t>(y * stride + x)] = static_cast<std::uint8_t>(10 * y + x);
      yuyv[static_cast<std::size_t>(y * 2 * w + 2 * x)] = static_cast<std::uint8_t>(10 * y + x);
      yuyv[static_cast<std::size_t>(y * 2 * w + 2 * x + 1)] = 0x80;  // U or V
    }
  FrameConverter g(PixelFormat::grey, w, h, w, h);
  FrameConverter v(PixelFormat::yuyv, w, h, w, h);
  FrameConverter reduce(PixelFormat::grey, w, h, 4, 2);
  ASSERT_TRUE(g.convert(grey, stride));  // first touch
  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("camera");
  ASSERT_TRUE(alloc_guard::arm());
  EXPECT_TRUE(g.convert(grey, stride));
  EXPECT_TRUE(v.convert(yuyv, 2 * w));
  EXPECT_TRUE(reduce.convert(grey, stride));
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      EXPECT_EQ(g.grey()[static_cast<std::size_t>(y * w + x)], 10 * y + x);
      EXPECT_EQ(v.grey()[static_cast<std::size_t>(y * w + x)], 10 * y + x);
    }
  // 2 x 2 blocks averaged: the top-left block holds 0, 1, 10, 11.
  EXPECT_EQ(reduce.grey()[0], 6);  // 22 / 4 = 5.5, rounded up
  EXPECT_EQ(reduce.grey()[7], (26 + 27 + 36 + 37 + 2) / 4);
  // Too few bytes for the size.
  EXPECT_FALSE(g.convert(std::span(grey).first(30), stride));
  EXPECT_NE(std::string(g.error()).find("short of 8 x 4 pixels"), std::string::npos) << g.error();
  EXPECT_THROW(FrameConverter(PixelFormat::grey, 8, 4, 16, 4), std::invalid_argument);
}

TEST(CameraFrame, MotionJpegOfARealFrameDecodesToGreyAndBadJpegIsRefused) {
  const ImageRead frame = read_grey_image(test::shared_data("nordland/summer/images-05000.png"));
  ASSERT_TRUE(frame.ok()) << frame.error;
  // A camera's MJPEG of it: 4:2:0 colour JPEG of the grey picture, 128 x 64.
  const int w = 128, h = 64;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w * h * 3));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c)
        rgb[static_cast<std::size_t>((y * w + x) * 3 + c)] = frame.image.pixels[static_cast<std::size_t>((y / 2) * 64 + x / 2)];
  tjhandle enc = tjInitCompress();
  unsigned char* jpeg = nullptr;
  unsigned long size = 0;
  ASSERT_EQ(tjCompress2(enc, rgb.data(), w, 0, h, TJPF_RGB, &jpeg, &size, TJSAMP_420, 95, 0), 0);
  std::vector<std::uint8_t> bytes(jpeg, jpeg + size);
  tjFree(jpeg);
  tjDestroy(enc);
  FrameConverter m(PixelFormat::mjpeg, w, h, 64, 32);
  ASSERT_TRUE(m.convert(bytes, 0)) << m.error();
  double diff = 0.0;
  for (std::size_t k = 0; k < m.grey().size(); ++k) diff += std::abs(m.grey()[k] - frame.image.pixels[k]);
  EXPECT_LT(diff / static_cast<double>(m.grey().size()), 2.0);  // JPEG's loss, averaged over 2 x 2
  EXPECT_EQ(m.jpeg_warnings(), 0u);
  // Not a JPEG; a JPEG of another size; a JPEG cut short (decodes with a warning).
  std::vector<std::uint8_t> junk(600, 0x55);
  EXPECT_FALSE(m.convert(junk, 0));
  EXPECT_NE(std::string(m.error()).find("no readable JPEG header"), std::string::npos) << m.error();
  FrameConverter other(PixelFormat::mjpeg, 64, 32, 64, 32);
  EXPECT_FALSE(other.convert(bytes, 0));
  EXPECT_NE(std::string(other.error()).find("128 x 64 pixels where 64 x 32 were set"), std::string::npos) << other.error();
  const std::vector<std::uint8_t> cut(bytes.begin(), bytes.begin() + static_cast<long>(bytes.size() * 2 / 3));
  const bool decoded = m.convert(cut, 0);
  EXPECT_TRUE(!decoded || m.jpeg_warnings() == 1u);
}

TEST(CameraOptions, EachBadValueIsNamed) {
  CameraOptions o;
  EXPECT_EQ(check_camera_options(o), "");
  o.buffers = 1;
  EXPECT_NE(check_camera_options(o).find("camera.buffers"), std::string::npos);
  o = {};
  o.out_width = 1000;
  EXPECT_NE(check_camera_options(o).find("camera.out_width"), std::string::npos);
  o = {};
  o.fps = -1;
  EXPECT_NE(check_camera_options(o).find("camera.fps"), std::string::npos);
  o = {};
  o.device = "";
  EXPECT_NE(check_camera_options(o).find("camera.device"), std::string::npos);
  PixelFormat f{};
  EXPECT_TRUE(parse_pixel_format("mjpeg", f));
  EXPECT_EQ(f, PixelFormat::mjpeg);
  EXPECT_FALSE(parse_pixel_format("rgb24", f));
}

TEST(CameraDevice, NoDeviceAndAFileThatIsNoCameraAreExplainedAndRetried) {
  V4l2Camera cam;
  CameraOptions o;
  o.device = "/dev/trailnav-no-such-camera";
  std::string e = cam.open(o);
  EXPECT_NE(e.find("/dev/trailnav-no-such-camera: cannot open"), std::string::npos) << e;
  EXPECT_FALSE(cam.is_open());
  o.device = "/dev/null";
  e = cam.open(o);
  EXPECT_NE(e.find("/dev/null: not a V4L2 device"), std::string::npos) << e;
  EXPECT_FALSE(cam.is_open());

  o.device = "/dev/trailnav-no-such-camera";
  o.reconnect_s = 0.5;
  auto created = CameraDriver::create(o);
  ASSERT_TRUE(created.driver) << created.error;
  CameraDriver& d = *created.driver;
  TaskTick t;
  t.started = 1'000'000'000;
  d.run(t);
  t.started += 100'000'000;  // before reconnect_s: no second attempt
  d.run(t);
  CameraStatus s = d.status();
  EXPECT_EQ(s.health, CameraHealth::no_device);
  EXPECT_EQ(s.counters.open_failures, 1u);
  EXPECT_NE(std::string(s.last_error.data()).find("no-such-camera"), std::string::npos);
  t.started += 500'000'000;
  d.run(t);
  EXPECT_EQ(d.status().counters.open_failures, 2u);
  EXPECT_EQ(d.frames().try_read(), nullptr);
  o.buffers = 0;
  EXPECT_FALSE(CameraDriver::create(o).error.empty());
}

}  // namespace
}  // namespace trailnav::drivers::camera
