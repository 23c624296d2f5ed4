// The camera driver on this machine: the frame conversions (grey with its
// line stride, YUYV's Y bytes, Motion-JPEG through libturbojpeg on a real
// Nordland frame, the area reduction) with no heap on the uncompressed paths,
// the options' checks, and the device's errors where there is no camera. The
// V4L2 path itself runs against the kernel's `vivid` in the kernel tests'
// virtual machine (tests/kernel/kernel_devices_test.cpp, KernelCamera).
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <turbojpeg.h>
#include <unistd.h>

#include <cstdlib>
#include <numeric>

#include "test_data.hpp"
#include "trailnav/drivers/camera/camera_driver.hpp"
#include "trailnav/drivers/camera/frame.hpp"
#include "trailnav/drivers/camera/image_file.hpp"
#include "trailnav/drivers/camera/image_tunnel.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/heap_redirect.hpp"
#include "trailnav/runtime/host_clock.hpp"

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
  // The decoder's memory comes from the converter's block, not the heap
  // (where the build can redirect it: not under the sanitizers).
  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("camera");
  ASSERT_TRUE(alloc_guard::arm());
  EXPECT_TRUE(m.convert(bytes, 0)) << m.error();
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  if (heap_redirect::supported()) {
    EXPECT_EQ(alloc_guard::total_allocations(), 0u);
    EXPECT_GT(m.jpeg_memory_peak(), 0u);
  }
  alloc_guard::reset_counters();  // the sanitizers' builds counted the decoder's heap
  EXPECT_LT(m.jpeg_memory_peak(), m.jpeg_memory_size());
  std::printf("[ camera ] MJPEG 128 x 64 (4:2:0): the decoder took %zu of its %zu bytes\n", m.jpeg_memory_peak(),
              m.jpeg_memory_size());
  {
    // The largest need: a progressive JPEG keeps every coefficient of the
    // frame; 640 x 480 with full-resolution colour (4:4:4).
    const int bw = 640, bh = 480;
    std::vector<std::uint8_t> big(static_cast<std::size_t>(bw * bh * 3));
    for (int y = 0; y < bh; ++y)
      for (int x = 0; x < bw; ++x)
        for (int c = 0; c < 3; ++c)
          big[static_cast<std::size_t>((y * bw + x) * 3 + c)] =
              static_cast<std::uint8_t>(frame.image.pixels[static_cast<std::size_t>((y / 15) * 64 + x / 10)] + 7 * c);
    tjhandle penc = tjInitCompress();
    unsigned char* pj = nullptr;
    unsigned long psize = 0;
    ASSERT_EQ(tjCompress2(penc, big.data(), bw, 0, bh, TJPF_RGB, &pj, &psize, TJSAMP_444, 90, TJFLAG_PROGRESSIVE), 0);
    const std::vector<std::uint8_t> progressive(pj, pj + psize);
    tjFree(pj);
    tjDestroy(penc);
    FrameConverter p(PixelFormat::mjpeg, bw, bh, 64, 32);
    ASSERT_TRUE(p.convert(progressive, 0)) << p.error();
    EXPECT_LT(p.jpeg_memory_peak(), p.jpeg_memory_size());
    std::printf("[ camera ] progressive 640 x 480 (4:4:4): the decoder took %zu of its %zu bytes\n", p.jpeg_memory_peak(),
                p.jpeg_memory_size());
  }
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
  // libjpeg fills in what is missing and warns (a premature end): published, counted.
  EXPECT_TRUE(decoded) << m.error();
  EXPECT_EQ(m.jpeg_warnings(), 1u);
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
  EXPECT_FALSE(cam.open(o));
  std::string e = cam.error();
  EXPECT_NE(e.find("/dev/trailnav-no-such-camera: cannot open"), std::string::npos) << e;
  EXPECT_FALSE(cam.is_open());
  o.device = "/dev/null";
  EXPECT_FALSE(cam.open(o));
  e = cam.error();
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
  // Retrying, failing and reporting it take nothing from the heap: the
  // camera's thread is watched by the allocation guard in trailnavd.
  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("camera");
  ASSERT_TRUE(alloc_guard::arm());
  for (int k = 0; k < 3; ++k) {
    t.started += 600'000'000;
    d.run(t);
  }
  V4l2Camera other;
  CameraOptions null_device;
  null_device.device = "/dev/null";
  const bool opened = other.open(null_device);
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  EXPECT_FALSE(opened);
  EXPECT_EQ(d.status().counters.open_failures, 5u);
  o.buffers = 0;
  EXPECT_FALSE(CameraDriver::create(o).error.empty());
}

}  // namespace
}  // namespace trailnav::drivers::camera

namespace trailnav::drivers::camera {
namespace {

std::vector<std::uint8_t> pattern(int w, int h, int seed) {
  std::vector<std::uint8_t> p(static_cast<std::size_t>(w * h));
  for (std::size_t k = 0; k < p.size(); ++k) p[k] = static_cast<std::uint8_t>((k * 7 + static_cast<std::size_t>(seed)) & 0xff);
  return p;
}

TEST(ImageTunnel, FramesSurviveReorderingAndLossIsCountedNotPublished) {
  const int w = 100, h = 50;  // 5,000 pixels: 4 fragments
  ASSERT_EQ(fragment_count(w, h), 4u);
  ImageAssembler a(w, h);
  const auto one = pattern(w, h, 1), two = pattern(w, h, 2);
  // Frame 7 in reverse order, one fragment twice.
  for (std::size_t i = 4; i-- > 0;) {
    const TunnelFragment f = encode_fragment(one, w, h, 7, 123456789, i);
    ASSERT_GT(f.size, kImageTunnelHeader);
    EXPECT_EQ(a.add(f.view()), i == 0);
    if (i == 2) {
      EXPECT_FALSE(a.add(f.view()));
    }
  }
  EXPECT_EQ(std::vector<std::uint8_t>(a.frame().begin(), a.frame().end()), one);
  EXPECT_EQ(a.sequence(), 7u);
  EXPECT_EQ(a.time_ns(), 123456789);
  // A late duplicate of the finished frame is stale; frame 8 loses fragment 1
  // and frame 9 arrives whole: 8 is given up.
  EXPECT_FALSE(a.add(encode_fragment(one, w, h, 7, 123456789, 3).view()));
  for (std::size_t i : {0u, 2u, 3u}) EXPECT_FALSE(a.add(encode_fragment(two, w, h, 8, 2, i).view()));
  bool done = false;
  for (std::size_t i = 0; i < 4; ++i) done = a.add(encode_fragment(two, w, h, 9, 3, i).view());
  EXPECT_TRUE(done);
  EXPECT_EQ(std::vector<std::uint8_t>(a.frame().begin(), a.frame().end()), two);
  const AssemblerCounters& c = a.counters();
  EXPECT_EQ(c.frames, 2u);
  EXPECT_EQ(c.incomplete, 1u);
  EXPECT_EQ(c.stale, 1u);
  // Malformed: too short, a wrong magic, an offset that is not its index's, a
  // frame larger than the assembler holds.
  TunnelFragment f = encode_fragment(one, w, h, 10, 0, 1);
  EXPECT_FALSE(a.add(std::span(f.bytes).first(20)));
  f.bytes[20] ^= 1;
  EXPECT_FALSE(a.add(f.view()));
  f = encode_fragment(one, w, h, 10, 0, 1);
  f.bytes[0] = 'X';
  EXPECT_FALSE(a.add(f.view()));
  EXPECT_EQ(a.counters().malformed, 3u);
  const auto big = pattern(200, 100, 3);
  EXPECT_FALSE(a.add(encode_fragment(big, 200, 100, 11, 0, 0).view()));
  EXPECT_EQ(a.counters().too_large, 1u);
  EXPECT_EQ(encode_fragment(one, w, h, 1, 0, 4).size, 0u);  // no fragment 4
}

// The driver with `input: tunnel` on loopback: frames sent as a replay sends
// them are published reduced, a frame of another size is refused by name.
TEST(ImageTunnel, TheDriverTakesFramesFromTheTunnel) {
  CameraOptions o;
  o.input = CameraInput::tunnel;
  o.tunnel_port = 0;  // the kernel picks
  o.width = 128;
  o.height = 64;
  auto made = CameraDriver::create(o);
  ASSERT_TRUE(made.driver) << made.error;
  CameraDriver& d = *made.driver;
  const std::uint16_t port = d.status().tunnel_port;
  ASSERT_NE(port, 0);
  const int s = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(port);
  to.sin_addr.s_addr = htonl(0x7F000001u);
  const auto send_frame = [&](const std::vector<std::uint8_t>& px, int w, int h, std::uint32_t seq) {
    for (std::size_t i = 0; i < fragment_count(w, h); ++i) {
      const TunnelFragment f = encode_fragment(px, w, h, seq, 0, i);
      ::sendto(s, f.bytes.data(), f.size, 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
    }
  };
  const auto frame = pattern(128, 64, 5);
  send_frame(frame, 128, 64, 1);
  send_frame(pattern(64, 32, 6), 64, 32, 2);
  send_frame(frame, 128, 64, 4);
  TaskTick t;
  for (int k = 0; k < 50 && d.status().counters.frames < 3; ++k) {
    t.started = host_now_ns();
    d.run(t);
    ::usleep(2000);
  }
  ::close(s);
  const CameraStatus st = d.status();
  EXPECT_EQ(st.counters.frames, 3u);
  EXPECT_EQ(st.counters.published, 2u);
  EXPECT_EQ(st.counters.corrupt, 1u);
  EXPECT_EQ(st.counters.dropped, 2u);  // 2 (refused) and 3 (never sent) between 1 and 4
  EXPECT_NE(std::string(st.last_error.data()).find("a tunnel frame of 64 x 32 pixels"), std::string::npos);
  const CameraFrame* f = d.frames().try_read();
  ASSERT_NE(f, nullptr);
  EXPECT_EQ(f->sequence, 4u);
  // 2 x 2 averages of the pattern.
  EXPECT_EQ(f->pixels[0], (frame[0] + frame[1] + frame[128] + frame[129] + 2) / 4);
}

}  // namespace
}  // namespace trailnav::drivers::camera
