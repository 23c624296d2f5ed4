// The CAN, GPIO and camera drivers against real kernel devices: SocketCAN on
// a `vcan` interface (kernel receive filters, kernel timestamps, error
// frames, the interface taken down and up, removed and added back), libgpiod
// on a `gpio-sim` chip (lines found by name, the e-stop debounced, outputs
// driven, the chip removed under the driver) and V4L2 on `vivid` (formats,
// memory-mapped streaming, kernel timestamps, the camera unplugged).
//
// These need the devices, which a developer's machine or a container rarely
// has and must not be changed for a test: they run inside a virtual machine
// that boots Debian's kernel with the modules loaded (toolchain/kernel-tests.sh,
// docs/testing.md "Real kernel devices"), which sets TRAILNAV_KERNEL_VM=1.
// Anywhere else they say so and skip.
#include <gtest/gtest.h>

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/videodev2.h>
#include <fcntl.h>
#include <sys/ioctl.h>
#include <net/if.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <numeric>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "dds.hpp"
#include "diagnostic_msgs.h"
#include "geometry_msgs.h"
#include "subscriber.hpp"
#include "trailnav/drivers/camera/camera_driver.hpp"
#include "trailnav/drivers/can/can_driver.hpp"
#include "trailnav/drivers/gpio/gpio_driver.hpp"
#include "trailnav/runtime/host_clock.hpp"
#include "trailnav/runtime/spawn.hpp"

using namespace trailnav;
namespace camera = trailnav::drivers::camera;
namespace fs = std::filesystem;

namespace {

bool in_vm() { return std::getenv("TRAILNAV_KERNEL_VM") != nullptr; }

#define REQUIRE_VM()                                                                         \
  do {                                                                                       \
    if (!in_vm()) GTEST_SKIP() << "needs the kernel test virtual machine (toolchain/kernel-tests.sh)"; \
  } while (false)

Nanos monotonic() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<Nanos>(ts.tv_sec) * kNanosPerSecond + ts.tv_nsec;
}
Nanos realtime() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<Nanos>(ts.tv_sec) * kNanosPerSecond + ts.tv_nsec;
}

int sh(const std::string& command) {
  const int rc = std::system(command.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

std::string read_file(const fs::path& p) {
  std::ifstream f(p);
  std::string s;
  std::getline(f, s);
  return s;
}

// ---- CAN -------------------------------------------------------------------

can::Dbc robot_dbc() {
  auto r = can::load_dbc("board/sim/trailnav-robot.dbc");
  EXPECT_TRUE(r.dbc) << r.error;
  return *r.dbc;
}

can::CanDriverOptions vcan_options(const std::string& interface) {
  can::CanDriverOptions o;
  o.transport = can::CanTransport::socketcan;
  o.interface = interface;
  o.odometry.left = {"WHEEL_SPEEDS", "SpeedLeft"};
  o.odometry.right = {"WHEEL_SPEEDS", "SpeedRight"};
  o.odometry.track = 0.6;
  o.backoff = 0.05;
  o.max_backoff = 0.2;
  return o;
}

// A vcan interface for one test, removed after it.
class Vcan {
 public:
  explicit Vcan(std::string name) : name_(std::move(name)) {
    ok_ = sh("/sbin/ip link add dev " + name_ + " type vcan && /sbin/ip link set " + name_ + " up") == 0;
  }
  ~Vcan() { sh("/sbin/ip link del dev " + name_ + " 2>/dev/null"); }
  bool ok() const { return ok_; }
  const std::string& name() const { return name_; }

 private:
  std::string name_;
  bool ok_ = false;
};

// A raw socket on the interface, as another node on the bus.
class Node {
 public:
  explicit Node(const std::string& interface) {
    fd_ = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
    sockaddr_can a{};
    a.can_family = AF_CAN;
    a.can_ifindex = static_cast<int>(if_nametoindex(interface.c_str()));
    if (fd_ >= 0 && ::bind(fd_, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0) {
      ::close(fd_);
      fd_ = -1;
    }
  }
  ~Node() {
    if (fd_ >= 0) ::close(fd_);
  }
  bool ok() const { return fd_ >= 0; }
  bool send(std::uint32_t id, const std::uint8_t* data, std::uint8_t length) {
    can_frame f{};
    f.can_id = id;
    f.len = length;
    std::memcpy(f.data, data, length);
    return ::write(fd_, &f, sizeof f) == static_cast<ssize_t>(sizeof f);
  }
  bool send_speeds(const can::Dbc& dbc, double left, double right) {
    const can::DbcMessage& m = *dbc.message("WHEEL_SPEEDS");
    std::array<std::uint8_t, 8> d{};
    if (can::encode_signal(*m.signal("SpeedLeft"), left, d) != can::SignalError::none) return false;
    if (can::encode_signal(*m.signal("SpeedRight"), right, d) != can::SignalError::none) return false;
    return send(m.id, d.data(), 8);
  }

 private:
  int fd_ = -1;
};

void tick(Task& t, Nanos now) {
  TaskTick k;
  k.scheduled = k.started = now;
  t.run(k);
}

// Runs the task every 5 ms until `done` or `seconds` pass.
template <class Done>
bool run_until(Task& t, double seconds, Done done) {
  const Nanos until = monotonic() + static_cast<Nanos>(seconds * 1e9);
  while (monotonic() < until) {
    tick(t, monotonic());
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

}  // namespace

// The kernel hands over only the odometry's frames (the receive filter) and
// stamps each as it arrived (SO_TIMESTAMPNS): frames sent 10 ms apart and
// read in one go keep their 10 ms spacing.
TEST(KernelCan, FiltersPassOnlyTheOdometrysFramesStampedByTheKernel) {
  REQUIRE_VM();
  Vcan bus("vcan-filter");
  ASSERT_TRUE(bus.ok());
  const can::Dbc dbc = robot_dbc();
  auto made = can::CanDriver::create(dbc, vcan_options(bus.name()));
  ASSERT_TRUE(made.driver) << made.error;
  can::CanDriver& d = *made.driver;
  tick(d, monotonic());
  ASSERT_TRUE(d.status().open) << d.status().last_error.data();
  Node node(bus.name());
  ASSERT_TRUE(node.ok());
  const std::uint8_t junk[8] = {1, 2, 3, 4, 5, 6, 7, 8};
  const Nanos before = realtime();
  for (int k = 0; k < 20; ++k) {
    ASSERT_TRUE(node.send_speeds(dbc, 1.0, 1.2));
    ASSERT_TRUE(node.send(0x123, junk, 8));                  // another node's standard frame
    ASSERT_TRUE(node.send(0x18FEF100u | CAN_EFF_FLAG, junk, 8));  // and an extended one
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  const Nanos after = realtime();
  tick(d, monotonic());  // one read of everything queued
  const can::CanDriverStatus s = d.status();
  EXPECT_EQ(s.frames, 20u) << "the kernel filter lets only WHEEL_SPEEDS through";
  EXPECT_EQ(s.odometry_counters.updates, 20u);
  EXPECT_EQ(s.kernel_drops, 0u);
  std::vector<std::int64_t> times;
  can::OdometryState o;
  while (d.readings().try_pop(o)) times.push_back(o.time_ns);
  ASSERT_EQ(times.size(), 20u);
  for (std::size_t k = 0; k < times.size(); ++k) {
    EXPECT_GE(times[k], before);
    EXPECT_LE(times[k], after);
    if (k > 0) {
      EXPECT_GE(times[k] - times[k - 1], 9'000'000) << "kernel stamps keep the sending gaps";
    }
  }
  EXPECT_NEAR(o.speed, 1.1, 0.01);
}

// Error frames (as a controller reports them: CAN_ERR_FLAG with the class in
// the id and the detail in the data) are counted and set health.
TEST(KernelCan, ErrorFramesReportBusOffAndRestart) {
  REQUIRE_VM();
  Vcan bus("vcan-error");
  ASSERT_TRUE(bus.ok());
  const can::Dbc dbc = robot_dbc();
  auto made = can::CanDriver::create(dbc, vcan_options(bus.name()));
  ASSERT_TRUE(made.driver) << made.error;
  can::CanDriver& d = *made.driver;
  tick(d, monotonic());
  Node node(bus.name());
  ASSERT_TRUE(node.ok());
  ASSERT_TRUE(node.send_speeds(dbc, 1.0, 1.0));
  const std::uint8_t none[8] = {};
  ASSERT_TRUE(node.send(CAN_ERR_FLAG | CAN_ERR_BUSOFF, none, CAN_ERR_DLC));
  std::uint8_t passive[8] = {};
  passive[1] = CAN_ERR_CRTL_RX_PASSIVE;
  ASSERT_TRUE(node.send(CAN_ERR_FLAG | CAN_ERR_CRTL, passive, CAN_ERR_DLC));
  ASSERT_TRUE(node.send(CAN_ERR_FLAG | CAN_ERR_RESTARTED, none, CAN_ERR_DLC));
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().error_frames == 3; }));
  const can::CanDriverStatus s = d.status();
  EXPECT_EQ(s.bus_off, 1u);
  EXPECT_EQ(s.error_passive, 1u);
  EXPECT_EQ(s.restarted, 1u);
  EXPECT_EQ(s.health, can::CanHealth::bus_error);
  EXPECT_EQ(s.frames, 4u);
}

// `ip link set down` makes the socket fail with ENETDOWN: the driver closes
// it, says so, and opens it again once the interface is back up.
TEST(KernelCan, InterfaceDownAndUpAgainIsReopened) {
  REQUIRE_VM();
  Vcan bus("vcan-updown");
  ASSERT_TRUE(bus.ok());
  const can::Dbc dbc = robot_dbc();
  auto made = can::CanDriver::create(dbc, vcan_options(bus.name()));
  ASSERT_TRUE(made.driver) << made.error;
  can::CanDriver& d = *made.driver;
  Node node(bus.name());
  ASSERT_TRUE(node.ok());
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().open; }));
  ASSERT_TRUE(node.send_speeds(dbc, 1.0, 1.0));
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().frames == 1; }));
  ASSERT_EQ(sh("/sbin/ip link set " + bus.name() + " down"), 0);
  ASSERT_TRUE(run_until(d, 5.0, [&] { return !d.status().open; }));
  EXPECT_EQ(d.status().health, can::CanHealth::no_link);
  EXPECT_NE(std::string(d.status().last_error.data()).find("down"), std::string::npos) << d.status().last_error.data();
  ASSERT_EQ(sh("/sbin/ip link set " + bus.name() + " up"), 0);
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().open && d.status().opens == 2; }));
  Node again(bus.name());
  ASSERT_TRUE(again.send_speeds(dbc, 2.0, 2.0));
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().frames == 2; }));
  EXPECT_EQ(d.status().health, can::CanHealth::ok);
  EXPECT_GE(d.status().closes, 1u);
}

// An adapter unplugged (the interface removed) and plugged in again.
TEST(KernelCan, InterfaceRemovedAndAddedBackIsReopened) {
  REQUIRE_VM();
  auto bus = std::make_unique<Vcan>("vcan-replug");
  ASSERT_TRUE(bus->ok());
  const can::Dbc dbc = robot_dbc();
  auto made = can::CanDriver::create(dbc, vcan_options("vcan-replug"));
  ASSERT_TRUE(made.driver) << made.error;
  can::CanDriver& d = *made.driver;
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().open; }));
  bus.reset();  // ip link del
  ASSERT_TRUE(run_until(d, 5.0, [&] { return !d.status().open; }));
  // Gone: reopening fails, and says which interface is missing.
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().open_failures > 0; }));
  EXPECT_NE(std::string(d.status().last_error.data()).find("vcan-replug"), std::string::npos) << d.status().last_error.data();
  bus = std::make_unique<Vcan>("vcan-replug");
  ASSERT_TRUE(bus->ok());
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().open; }));
  Node node("vcan-replug");
  ASSERT_TRUE(node.send_speeds(dbc, 1.5, 1.5));
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().frames == 1; }));
  // One socket was open and closed; the attempts while the interface was
  // gone are open failures (they were counted as closes before this test).
  EXPECT_EQ(d.status().closes, 1u);
  EXPECT_EQ(d.status().opens, 2u);
}

// The host's clock stepped (an NTP step at boot, an operator's `date -s`):
// the kernel stamps frames with the new time at once. The virtual machine's
// clock is the test's to step. The driver takes the kernel's stamps into host
// time (runtime/host_clock.hpp), which carries on across the step: the
// odometry integrates straight through, forward and back, with no gap and no
// time going back, and health stays ok.
TEST(KernelClock, HostClockStepsForwardAndBackUnderTheCanDriverGoUnnoticed) {
  REQUIRE_VM();
  Vcan bus("vcan-clock");
  ASSERT_TRUE(bus.ok());
  const can::Dbc dbc = robot_dbc();
  auto made = can::CanDriver::create(dbc, vcan_options(bus.name()));
  ASSERT_TRUE(made.driver) << made.error;
  can::CanDriver& d = *made.driver;
  Node node(bus.name());
  ASSERT_TRUE(node.ok());
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().open; }));
  // Frames every 10 ms at 1 m/s; the host time of the last one sent. On a
  // busy host the emulated machine's sleeps stretch, so the distance
  // expected is the host time between frames, not 10 ms a frame.
  Nanos last_sent = 0;
  auto drive = [&](int frames) {
    for (int k = 0; k < frames; ++k) {
      ASSERT_TRUE(node.send_speeds(dbc, 1.0, 1.0));
      last_sent = host_now_ns();
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      tick(d, monotonic());
    }
  };
  auto step = [](std::int64_t by_ns) {
    timespec now{};
    clock_gettime(CLOCK_REALTIME, &now);
    const std::int64_t t = static_cast<std::int64_t>(now.tv_sec) * 1'000'000'000 + now.tv_nsec + by_ns;
    const timespec to{static_cast<time_t>(t / 1'000'000'000), static_cast<long>(t % 1'000'000'000)};
    return clock_settime(CLOCK_REALTIME, &to) == 0;
  };
  drive(20);
  const double before = d.status().odometry.distance;
  const Nanos sent_before = last_sent;
  const Nanos host_before = host_now_ns();
  const std::uint64_t steps_before = host_clock_steps();
  const Nanos step_before = host_clock_step_ns();
  ASSERT_TRUE(step(5'000'000'000));
  drive(20);
  can::CanDriverStatus s = d.status();
  // The kernel's timestamps jumped 5 s; host time did not (runtime/host_clock.hpp):
  // no gap, and the 20 frames are 20 steps at 1 m/s over the host time they
  // took (0.2 m at 10 ms each), not 5 m more.
  EXPECT_EQ(s.odometry_counters.gaps, 0u);
  EXPECT_NEAR(s.odometry.distance - before, static_cast<double>(last_sent - sent_before) * 1e-9, 0.03);
  EXPECT_GT(s.odometry.distance - before, 0.17);
  EXPECT_LT(host_now_ns() - host_before, 2'000'000'000) << "host time carried on";
  EXPECT_EQ(host_clock_steps(), steps_before + 1);
  ASSERT_TRUE(step(-5'000'000'000));
  drive(20);
  s = d.status();
  EXPECT_EQ(s.odometry_counters.time_back, 0u);
  EXPECT_EQ(s.odometry_counters.gaps, 0u);
  EXPECT_EQ(s.frames, 60u);
  EXPECT_EQ(s.health, can::CanHealth::ok);
  EXPECT_NEAR(s.odometry.distance - before, static_cast<double>(last_sent - sent_before) * 1e-9, 0.06);
  EXPECT_GT(s.odometry.distance - before, 0.34);
  EXPECT_EQ(host_clock_steps(), steps_before + 2);
  EXPECT_LT(std::llabs(host_clock_step_ns() - step_before), 1'000'000) << "+5 s and -5 s";
}

// The whole daemon across steps of the host's clock: trailnavd with its CAN
// driver on a vcan bus and its pose, wheels turning at 1 m/s, the machine's
// clock set 5 s forward and then 5 s back. Checked over DDS, as a planner
// sees it: the daemon keeps running; the pose drives on without standing
// still or jumping; health names each step (`trailnavd: clock`) and neither
// the CAN odometry nor the pose sees a gap or time going back; and every pose
// comes stamped on the system clock of its moment (what a ROS 2 node's now()
// reads), before the steps, between them and after.
TEST(KernelClock, TrailnavdCarriesOnAcrossStepsOfTheHostClock) {
  REQUIRE_VM();
  const char* daemon = std::getenv("TRAILNAVD");
  ASSERT_NE(daemon, nullptr) << "the machine's init sets TRAILNAVD";
  Vcan bus("vcan-daemon");
  ASSERT_TRUE(bus.ok());
  const fs::path dir = "/tmp/trailnavd-clock";
  fs::create_directories(dir);
  const int domain = 7;
  {
    std::ofstream c(dir / "robot.yaml");
    c << "runtime: {realtime: off, lock_memory: false, log_level: warn, log_sink: stderr}\n"
      << "can: {transport: socketcan, interface: " << bus.name() << ", dbc: " << fs::absolute("board/sim/trailnav-robot.dbc").string()
      << ", left: WHEEL_SPEEDS.SpeedLeft, right: WHEEL_SPEEDS.SpeedRight, track: 0.6}\n"
      << "pose: {antenna: [0.0, 0.0, 1.3]}\n"
      << "dds: {domain: " << domain << ", cyclone_config: loopback, pose_rate_hz: 20, health_period_s: 0.5}\n"
      << "tasks:\n"
      << "  - {name: can, kind: periodic, rate_hz: 200, budget_ms: 5.0}\n"
      << "  - {name: pose, kind: periodic, rate_hz: 100, budget_ms: 5.0}\n";
  }
  const std::string err = (dir / "trailnavd.err").string();
  std::string error;
  const pid_t pid = spawn_process({daemon, "--config", (dir / "robot.yaml").string(), "--duration", "120"},
                                  {.stdout_path = "", .stderr_path = err}, error);
  ASSERT_GT(pid, 0) << error;

  auto dds_domain = dds::Domain::create(domain, dds::loopback_config());
  ASSERT_TRUE(dds_domain.domain) << dds_domain.error;
  auto poses = dds::Subscriber::create(*dds_domain.domain, "trailnav/pose", &geometry_msgs_msg_dds__PoseStamped__desc, 0, false, 1000);
  auto health = dds::Subscriber::create(*dds_domain.domain, "diagnostics", &diagnostic_msgs_msg_dds__DiagnosticArray__desc, 0, false, 100);
  ASSERT_TRUE(poses.subscriber && health.subscriber);
  struct Seen {
    Nanos stamp, received;
    double x;
  };
  std::vector<Seen> seen;
  std::map<std::string, std::map<std::string, std::string>> last;  // status name -> key -> value
  auto take = [&] {
    poses.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& p = *static_cast<const geometry_msgs_msg_dds__PoseStamped_*>(r.sample);
      seen.push_back({static_cast<Nanos>(p.header.stamp.sec) * kNanosPerSecond + p.header.stamp.nanosec, realtime(),
                      p.pose.position.x});
    });
    health.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& a = *static_cast<const diagnostic_msgs_msg_dds__DiagnosticArray_*>(r.sample);
      for (std::uint32_t i = 0; i < a.status._length; ++i) {
        const auto& st = a.status._buffer[i];
        auto& values = last[st.name];
        for (std::uint32_t k = 0; k < st.values._length; ++k) values[st.values._buffer[k].key] = st.values._buffer[k].value;
      }
    });
  };
  const can::Dbc dbc = robot_dbc();
  Node node(bus.name());
  ASSERT_TRUE(node.ok());
  auto drive = [&](double seconds) {
    const Nanos until = monotonic() + static_cast<Nanos>(seconds * 1e9);
    while (monotonic() < until) {
      ASSERT_TRUE(node.send_speeds(dbc, 1.0, 1.0));
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      take();
    }
  };
  auto step = [](Nanos by_ns) {
    const Nanos t = realtime() + by_ns;
    const timespec to{static_cast<time_t>(t / kNanosPerSecond), static_cast<long>(t % kNanosPerSecond)};
    return clock_settime(CLOCK_REALTIME, &to) == 0;
  };
  drive(4.0);  // the daemon starts and the pose gets going
  const std::size_t before_steps = seen.size();
  ASSERT_GT(before_steps, 10u) << "poses before the steps";
  ASSERT_TRUE(step(5 * kNanosPerSecond));
  drive(3.0);
  ASSERT_TRUE(step(-5 * kNanosPerSecond));
  drive(3.0);
  for (int i = 0; i < 20; ++i) {  // the last health
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    take();
  }
  ::kill(pid, SIGTERM);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  std::ifstream e(err);
  const std::string stderr_text((std::istreambuf_iterator<char>(e)), std::istreambuf_iterator<char>());
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << stderr_text;

  // Health names the steps; nothing saw a gap or time going back.
  EXPECT_EQ(last["trailnavd: clock"]["host_clock_steps"], "2") << stderr_text;
  EXPECT_EQ(last["trailnavd: can"]["time_back"], "0");
  EXPECT_EQ(last["trailnavd: can"]["odometry_gaps"], "0");
  EXPECT_EQ(last["trailnavd: pose"]["odometry_gaps"], "0");
  EXPECT_EQ(last["trailnavd: pose"]["translation_valid"], "true");
  // The pose drove on at 1 m/s: 6 s after the first step, about 6 m further,
  // never standing still for a second nor jumping metres between two poses
  // 50 ms apart.
  ASSERT_GT(seen.size(), before_steps + 100);
  double largest = 0.0;
  for (std::size_t i = 1; i < seen.size(); ++i) largest = std::max(largest, seen[i].x - seen[i - 1].x);
  EXPECT_LT(largest, 0.5);
  EXPECT_NEAR(seen.back().x - seen[before_steps - 1].x, 6.0, 0.6);
  // Each pose stamped on the system clock of its moment: within half a second
  // of when it arrived, but for the one or two in flight at a step.
  std::size_t off = 0;
  for (const Seen& s : seen) off += std::llabs(s.received - s.stamp) > kNanosPerSecond / 2;
  EXPECT_LE(off, 4u);
  fs::remove_all(dir);
}

// ---- GPIO ------------------------------------------------------------------

namespace {

// A gpio-sim chip made through configfs, with named lines; removed after.
class SimChip {
 public:
  SimChip(const std::string& name, const std::vector<std::string>& lines) : dir_("/sys/kernel/config/gpio-sim/" + name) {
    std::error_code ec;
    fs::create_directory(dir_, ec);
    fs::create_directory(dir_ / "bank0", ec);
    if (ec) return;
    std::ofstream(dir_ / "bank0" / "num_lines") << lines.size();
    for (std::size_t i = 0; i < lines.size(); ++i) {
      const fs::path l = dir_ / "bank0" / ("line" + std::to_string(i));
      fs::create_directory(l, ec);
      std::ofstream(l / "name") << lines[i];
    }
    set_live(true);
    chip_ = read_file(dir_ / "bank0" / "chip_name");
    device_ = read_file(dir_ / "dev_name");
  }
  ~SimChip() {
    set_live(false);
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir_ / "bank0", ec)) {
      if (e.is_directory()) fs::remove(e.path(), ec);
    }
    fs::remove(dir_ / "bank0", ec);
    fs::remove(dir_, ec);
  }
  void set_live(bool live) { std::ofstream(dir_ / "live") << (live ? 1 : 0); }
  bool ok() const { return !chip_.empty(); }
  const std::string& chip() const { return chip_; }  // gpiochipN
  fs::path line(int offset) const {
    return fs::path("/sys/devices/platform") / device_ / chip_ / ("sim_gpio" + std::to_string(offset));
  }
  // What drives an input: the simulated pull.
  void pull(int offset, bool up) const { std::ofstream(line(offset) / "pull") << (up ? "pull-up" : "pull-down"); }
  // What the driver put on an output.
  int value(int offset) const { return std::atoi(read_file(line(offset) / "value").c_str()); }

 private:
  fs::path dir_;
  std::string chip_, device_;
};

gpio::GpioDriverOptions sim_options(const std::string& chip) {
  gpio::GpioDriverOptions o;
  o.transport = gpio::GpioTransport::chip;
  o.chip = chip;
  o.estop_line = "ESTOP";
  o.heartbeat_line = "HEARTBEAT";
  o.status_line = "STATUS";
  o.estop_release_debounce = 0.2;
  o.heartbeat_period = 0.1;
  return o;
}

}  // namespace

TEST(KernelGpio, LinesAreFoundByNameAndAMissingOneIsExplained) {
  REQUIRE_VM();
  SimChip sim("names", {"ESTOP", "HEARTBEAT", "STATUS", "SPARE"});
  ASSERT_TRUE(sim.ok());
  auto made = gpio::GpioDriver::create(sim_options(sim.chip()));
  ASSERT_TRUE(made.driver) << made.error;
  gpio::GpioDriverOptions bad = sim_options(sim.chip());
  bad.estop_line = "E_STOP";
  made.driver.reset();  // the lines are free again
  auto refused = gpio::GpioDriver::create(bad);
  EXPECT_FALSE(refused.driver);
  EXPECT_NE(refused.error.find("E_STOP"), std::string::npos) << refused.error;
  EXPECT_NE(refused.error.find("ESTOP"), std::string::npos) << "the lines the chip has: " << refused.error;
}

// A press engages at once (from the edge); the release waits for the line to
// stay inactive for the debounce time; the status output follows.
TEST(KernelGpio, EstopEngagesAtOnceAndReleasesAfterTheDebounce) {
  REQUIRE_VM();
  SimChip sim("estop", {"ESTOP", "HEARTBEAT", "STATUS"});
  ASSERT_TRUE(sim.ok());
  sim.pull(0, false);
  auto made = gpio::GpioDriver::create(sim_options(sim.chip()));
  ASSERT_TRUE(made.driver) << made.error;
  gpio::GpioDriver& d = *made.driver;
  d.set_ready(true);
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().estop == gpio::EstopState::released; }));
  EXPECT_EQ(sim.value(2), 1) << "ready and released: the status output is on";
  sim.pull(0, true);  // pressed (active high)
  const Nanos pressed = monotonic();
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().estop == gpio::EstopState::engaged; }));
  EXPECT_LT(monotonic() - pressed, 200'000'000) << "a press engages at once";
  EXPECT_GE(d.status().edges, 1u);
  EXPECT_EQ(sim.value(2), 0) << "engaged: the status output is off";
  sim.pull(0, false);
  const Nanos let_go = monotonic();
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().estop == gpio::EstopState::released; }));
  EXPECT_GE(monotonic() - let_go, 200'000'000) << "the release waits for the debounce";
  EXPECT_EQ(sim.value(2), 1);
}

TEST(KernelGpio, TheHeartbeatTogglesOnTheLine) {
  REQUIRE_VM();
  SimChip sim("beat", {"ESTOP", "HEARTBEAT", "STATUS"});
  ASSERT_TRUE(sim.ok());
  auto made = gpio::GpioDriver::create(sim_options(sim.chip()));
  ASSERT_TRUE(made.driver) << made.error;
  gpio::GpioDriver& d = *made.driver;
  int changes = 0, last = -1;
  run_until(d, 1.0, [&] {
    const int v = sim.value(1);
    if (last >= 0 && v != last) ++changes;
    last = v;
    return false;
  });
  EXPECT_GE(changes, 5) << "0.1 s period for 1 s";
  EXPECT_EQ(static_cast<int>(d.status().heartbeat_toggles) % 2 == 1 ? 1 : 0, sim.value(1));
}

// The chip taken away under the driver: health failed, the e-stop unknown
// (which counts as engaged), and the driver does not crash.
TEST(KernelGpio, AChipRemovedUnderTheDriverIsReportedAndTheStopEngages) {
  REQUIRE_VM();
  SimChip sim("removed", {"ESTOP", "HEARTBEAT", "STATUS"});
  ASSERT_TRUE(sim.ok());
  sim.pull(0, false);
  auto made = gpio::GpioDriver::create(sim_options(sim.chip()));
  ASSERT_TRUE(made.driver) << made.error;
  gpio::GpioDriver& d = *made.driver;
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().estop == gpio::EstopState::released; }));
  sim.set_live(false);
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().health == gpio::GpioHealth::failed; }));
  EXPECT_NE(d.status().estop, gpio::EstopState::released);
  EXPECT_NE(std::string(d.status().last_error.data()), "");
}

// --- The camera driver against the kernel's `vivid` test driver (one
// webcam input: 320 x 180, 640 x 360, ... in YUYV, GREY and others, frame
// rates from 1 to 60 Hz), loaded by toolchain/kernel-tests.sh with
// n_devs=1 node_types=0x1 num_inputs=1 input_types=0.

namespace {

camera::CameraOptions vivid_options(camera::PixelFormat format, int width, int height) {
  camera::CameraOptions o;
  o.device = "/dev/video0";
  o.format = format;
  o.width = width;
  o.height = height;
  o.fps = 10.0;
  o.out_width = 64;
  o.out_height = 32;
  o.reconnect_s = 0.2;
  o.silence_s = 1.0;
  return o;
}

// One of vivid's own controls, found by its name ("Disconnect", a button;
// "Timestamp Source", 0 end of frame, 1 start of exposure).
bool set_vivid_control(const std::string& device, const std::string& name, int value) {
  const int fd = ::open(device.c_str(), O_RDWR);
  if (fd < 0) return false;
  v4l2_queryctrl q{};
  q.id = V4L2_CTRL_FLAG_NEXT_CTRL;
  bool pressed = false;
  while (::ioctl(fd, VIDIOC_QUERYCTRL, &q) == 0) {
    if (std::string(reinterpret_cast<const char*>(q.name)) == name) {
      v4l2_control c{};
      c.id = q.id;
      c.value = value;
      pressed = ::ioctl(fd, VIDIOC_S_CTRL, &c) == 0;
      break;
    }
    q.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
  }
  ::close(fd);
  return pressed;
}

}  // namespace

// Frames stream through the memory-mapped buffers in YUYV and GREY, reduced
// to 64 x 32, stamped by the kernel (in host time, just before they were
// dequeued) and numbered by it at 10 Hz. vivid stamps the end of a frame a
// frame period ahead of when it hands the frame over (a simulated sensor);
// set to stamp the start of exposure, as a UVC camera does, its stamps come
// before the frames are dequeued, and the driver says which it got.
TEST(KernelCamera, VividStreamsYuyvAndGreyStampedAndNumberedByTheKernel) {
  REQUIRE_VM();
  ASSERT_TRUE(set_vivid_control("/dev/video0", "Timestamp Source", 1));
  for (camera::PixelFormat format : {camera::PixelFormat::yuyv, camera::PixelFormat::grey}) {
    auto made = camera::CameraDriver::create(vivid_options(format, 320, 180));
    ASSERT_TRUE(made.driver) << made.error;
    camera::CameraDriver& d = *made.driver;
    std::vector<std::int64_t> stamps;
    std::vector<std::uint32_t> sequences;
    double mean_grey = 0.0;
    run_until(d, 2.5, [&] {
      if (const camera::CameraFrame* f = d.frames().try_read()) {
        stamps.push_back(f->stamp_ns);
        sequences.push_back(f->sequence);
        EXPECT_TRUE(f->start_of_exposure);
        EXPECT_LE(f->stamp_ns, f->receive_ns);
        EXPECT_LT(f->receive_ns - f->stamp_ns, 500'000'000);
        mean_grey = std::accumulate(f->pixels.begin(), f->pixels.end(), 0.0) / static_cast<double>(f->pixels.size());
      }
      return stamps.size() >= 15;
    });
    const camera::CameraStatus s = d.status();
    EXPECT_EQ(s.health, camera::CameraHealth::streaming) << s.last_error.data();
    EXPECT_EQ(s.counters.opens, 1u);
    EXPECT_GE(stamps.size(), 15u) << camera::pixel_format_name(format);
    EXPECT_NEAR(s.fps, 10.0, 1e-6);
    for (std::size_t i = 1; i < stamps.size(); ++i) {
      EXPECT_GT(stamps[i], stamps[i - 1]);
      EXPECT_GT(sequences[i], sequences[i - 1]);
    }
    if (stamps.size() > 2) {
      // 10 Hz: a frame every 100 ms.
      const double period = static_cast<double>(stamps.back() - stamps.front()) / static_cast<double>(sequences.back() - sequences.front());
      EXPECT_NEAR(period, 100e6, 10e6);
    }
    EXPECT_GT(mean_grey, 5.0);  // vivid's test pattern, not an empty buffer
    EXPECT_EQ(s.counters.corrupt, 0u);
    EXPECT_GE(s.counters.frames, s.counters.published);
    // Four buffers hold 400 ms of frames; only a stall that long drops one.
    EXPECT_LE(s.counters.dropped, s.counters.frames / 4);
  }
}

// A size or format the device does not offer is refused at open, naming
// what it offered instead; the driver keeps trying and says why.
TEST(KernelCamera, ASizeOrFormatTheDeviceDoesNotOfferIsRefusedNamingItsOffer) {
  REQUIRE_VM();
  camera::V4l2Camera cam;
  EXPECT_FALSE(cam.open(vivid_options(camera::PixelFormat::yuyv, 320, 240)));
  std::string e = cam.error();
  EXPECT_NE(e.find("/dev/video0: offers 320 x 180 YUYV where 320 x 240 YUYV was set"), std::string::npos) << e;
  EXPECT_FALSE(cam.is_open());
  EXPECT_FALSE(cam.open(vivid_options(camera::PixelFormat::mjpeg, 320, 180)));
  e = cam.error();
  EXPECT_NE(e.find("where 320 x 180 MJPG was set"), std::string::npos) << e;
  camera::CameraOptions manual = vivid_options(camera::PixelFormat::yuyv, 320, 180);
  manual.exposure_us = 5000;
  EXPECT_FALSE(cam.open(manual));
  e = cam.error();
  EXPECT_NE(e.find("does not take a manual exposure"), std::string::npos) << e;
  EXPECT_TRUE(cam.open(vivid_options(camera::PixelFormat::yuyv, 640, 360))) << cam.error();
  EXPECT_EQ(cam.width(), 640);
  EXPECT_GE(cam.bytes_per_line(), 1280);
  cam.close();
}

// vivid unplugged under the driver (its Disconnect button: every call then
// fails with ENODEV): reported as lost, then, when the module is loaded again
// and /dev/video0 is back, reopened and streaming.
TEST(KernelCamera, AnUnpluggedCameraIsReportedAndReopenedWhenItReturns) {
  REQUIRE_VM();
  auto made = camera::CameraDriver::create(vivid_options(camera::PixelFormat::yuyv, 320, 180));
  ASSERT_TRUE(made.driver) << made.error;
  camera::CameraDriver& d = *made.driver;
  ASSERT_TRUE(run_until(d, 3.0, [&] { return d.status().counters.published >= 3; }));
  ASSERT_TRUE(set_vivid_control("/dev/video0", "Disconnect", 1));
  ASSERT_TRUE(run_until(d, 3.0, [&] { return d.status().counters.lost >= 1; })) << d.status().last_error.data();
  EXPECT_EQ(d.status().health, camera::CameraHealth::no_device);
  ASSERT_EQ(sh("rmmod vivid && insmod /mods/vivid.ko n_devs=1 node_types=0x1 num_inputs=1 input_types=0"), 0);
  const std::uint64_t before = d.status().counters.published;
  ASSERT_TRUE(run_until(d, 5.0, [&] { return d.status().counters.published >= before + 3; })) << d.status().last_error.data();
  EXPECT_EQ(d.status().counters.opens, 2u);
  EXPECT_EQ(d.status().health, camera::CameraHealth::streaming);
}
