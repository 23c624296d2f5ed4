// The byte links and the GPS and IMU driver tasks on real file descriptors:
// pseudo-terminals as serial ports, loopback UDP and TCP. Covers the state
// machine (open, silence, loss of the device, back-off, reopen), the drivers'
// output against the offline decoders on real receiver logs, and that the
// armed drivers never touch the heap.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "test_data.hpp"
#include "xsens_vectors.hpp"
#include "trailnav/drivers/gps/gps_driver.hpp"
#include "trailnav/drivers/imu/imu_driver.hpp"
#include "trailnav/drivers/link/byte_link.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/host_clock.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "../support/no_allocations.hpp"

using namespace trailnav;
namespace fs = std::filesystem;

namespace {

// A pseudo-terminal whose slave is reached through a stable symlink, as the
// replayer provides them.
class Pty {
 public:
  explicit Pty(const std::string& link) : link_(link) { open(); }
  ~Pty() { close(); }
  void open() {
    master_ = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    ASSERT_GE(master_, 0);
    ASSERT_EQ(grantpt(master_), 0);
    ASSERT_EQ(unlockpt(master_), 0);
    char name[128];
    ASSERT_EQ(ptsname_r(master_, name, sizeof name), 0);
    fs::remove(link_);
    fs::create_symlink(name, link_);
  }
  void close() {
    if (master_ >= 0) ::close(master_);
    master_ = -1;
    fs::remove(link_);
  }
  void write(std::string_view bytes) {
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::write(master_, bytes.data() + done, bytes.size() - done);
      if (n > 0) {
        done += static_cast<std::size_t>(n);
      } else {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
    }
  }
  void write(const std::vector<std::uint8_t>& b) { write(std::string_view(reinterpret_cast<const char*>(b.data()), b.size())); }
  std::string read_all() {
    std::string out;
    char buf[256];
    ssize_t n;
    while ((n = ::read(master_, buf, sizeof buf)) > 0) out.append(buf, static_cast<std::size_t>(n));
    return out;
  }

 private:
  std::string link_;
  int master_ = -1;
};

std::string temp_dir(const std::string& name) {
  const std::string dir = (fs::temp_directory_path() / ("trailnav-link-" + name + "-" + std::to_string(getpid()))).string();
  fs::create_directories(dir);
  return dir;
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

Nanos ms(int v) { return static_cast<Nanos>(v) * kNanosPerMilli; }

// Polls until bytes arrive or `tries` polls of 1 ms have passed.
std::string poll_bytes(link::ByteLink& l, Nanos& now, int tries = 200) {
  std::string got;
  for (int i = 0; i < tries; ++i) {
    const auto b = l.poll(now);
    got.append(reinterpret_cast<const char*>(b.data()), b.size());
    if (!got.empty() && b.empty()) break;
    now += ms(1);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return got;
}

}  // namespace

TEST(ByteLink, LinkTextsParseAndBadOnesSayWhy) {
  std::string error;
  auto s = link::parse_link("serial:/dev/ttyUSB0@9600", error);
  ASSERT_TRUE(s) << error;
  EXPECT_EQ(s->kind, link::LinkKind::serial);
  EXPECT_EQ(s->device, "/dev/ttyUSB0");
  EXPECT_EQ(s->baud, 9600);
  EXPECT_EQ(link::format_link(*s), "serial:/dev/ttyUSB0@9600");
  auto u = link::parse_link("udp:127.0.0.1:10110", error);
  ASSERT_TRUE(u) << error;
  EXPECT_EQ(u->endpoint.port, 10110);
  EXPECT_FALSE(link::parse_link("serial:/dev/ttyS0@9601", error));
  EXPECT_NE(error.find("9601"), std::string::npos);
  EXPECT_FALSE(link::parse_link("tcp::2947", error));
  EXPECT_NE(error.find("server"), std::string::npos);
  EXPECT_FALSE(link::parse_link("usb:/dev/x", error));
  EXPECT_NE(error.find("'usb'"), std::string::npos);
  EXPECT_FALSE(link::parse_link("/dev/ttyUSB0", error));
}

TEST(ByteLink, SerialPortOnAPtyReadsReopensAfterLossAndBacksOff) {
  const std::string dir = temp_dir("serial");
  const std::string path = dir + "/gps0";
  Pty pty(path);
  link::LinkOptions o;
  o.device = path;
  o.baud = 9600;
  o.silence_timeout = 0.2;
  o.backoff = 0.05;
  o.max_backoff = 0.2;
  auto made = link::ByteLink::create(o);
  ASSERT_TRUE(made.link) << made.error;
  link::ByteLink& l = *made.link;
  Nanos now = ms(1000);
  EXPECT_TRUE(l.poll(now).empty());
  EXPECT_EQ(l.state(), link::LinkState::open);
  EXPECT_TRUE(l.just_opened());
  pty.write("$GPGGA,hello\r\n");
  EXPECT_EQ(poll_bytes(l, now), "$GPGGA,hello\r\n");
  EXPECT_GT(l.receive_ns(), 0);
  // Writing reaches the other end (commands to the device).
  const std::uint8_t cmd[] = {0xFA, 0xFF, 0x30, 0x00, 0xD1};
  EXPECT_TRUE(l.write(cmd));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_EQ(pty.read_all(), std::string("\xFA\xFF\x30\x00\xD1", 5));

  // The device goes away: the read fails, the link closes and names the path.
  pty.close();
  for (int i = 0; i < 50 && l.state() == link::LinkState::open; ++i) {
    l.poll(now += ms(1));
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_EQ(l.state(), link::LinkState::closed);
  EXPECT_EQ(l.counters().closes, 1u);
  // Within 50 ms, far inside the 0.2 s silence timeout: FIONREAD's EIO said so.
  EXPECT_NE(std::string(l.last_error()).find("hung up"), std::string::npos) << l.last_error();
  EXPECT_EQ(l.counters().silences, 0u);
  // Reopen attempts fail, with a growing back-off: 50, 100, 200, 200 ms.
  const std::uint64_t before = l.counters().open_failures;
  for (int i = 0; i < 700; ++i) l.poll(now += ms(1));
  EXPECT_EQ(l.counters().open_failures - before, 4u);
  EXPECT_NE(std::string(l.last_error()).find(path), std::string::npos) << l.last_error();
  EXPECT_NE(std::string(l.last_error()).find("No such file"), std::string::npos) << l.last_error();
  // It comes back.
  pty.open();
  for (int i = 0; i < 300 && l.state() != link::LinkState::open; ++i) l.poll(now += ms(1));
  ASSERT_EQ(l.state(), link::LinkState::open);
  EXPECT_EQ(l.counters().opens, 2u);
  pty.write("$GPRMC,again\r\n");
  EXPECT_EQ(poll_bytes(l, now), "$GPRMC,again\r\n");
  // Silence for longer than the timeout closes it too.
  for (int i = 0; i < 30; ++i) l.poll(now += ms(10));
  EXPECT_EQ(l.counters().silences, 1u);
  fs::remove_all(dir);
}

TEST(ByteLink, MissingDeviceAndNonSerialFileGiveClearErrors) {
  link::LinkOptions o;
  o.device = "/dev/trailnav-no-such-gps";
  auto made = link::ByteLink::create(o);
  ASSERT_TRUE(made.link);
  made.link->poll(0);
  EXPECT_EQ(made.link->state(), link::LinkState::closed);
  EXPECT_STREQ(made.link->last_error(), "open /dev/trailnav-no-such-gps: No such file or directory");
  const std::string dir = temp_dir("notserial");
  std::ofstream(dir + "/plain") << "x";
  o.device = dir + "/plain";
  made = link::ByteLink::create(o);
  made.link->poll(0);
  EXPECT_EQ(made.link->state(), link::LinkState::closed);
  EXPECT_NE(std::string(made.link->last_error()).find("not a serial port"), std::string::npos) << made.link->last_error();
  o.baud = 12345;
  EXPECT_NE(link::ByteLink::create(o).error.find("12345"), std::string::npos);
  fs::remove_all(dir);
}

TEST(ByteLink, UdpAndTcpOnLoopback) {
  // UDP: datagrams are concatenated into the byte stream.
  link::LinkOptions u;
  u.kind = link::LinkKind::udp;
  u.endpoint = {0x7F000001u, 0};
  auto made = link::ByteLink::create(u);
  ASSERT_TRUE(made.link);
  Nanos now = 0;
  made.link->poll(now);
  ASSERT_EQ(made.link->state(), link::LinkState::open) << made.link->last_error();
  const int tx = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_addr.s_addr = htonl(0x7F000001u);
  to.sin_port = htons(made.link->bound_port());
  for (const char* d : {"$GPGGA,1\r\n", "$GPRMC,2\r\n"}) {
    sendto(tx, d, std::strlen(d), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(poll_bytes(*made.link, now), "$GPGGA,1\r\n$GPRMC,2\r\n");
  // A datagram longer than max_datagram_bytes is cut to it, and counted.
  const std::string big(2000, 'x');
  sendto(tx, big.data(), big.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(poll_bytes(*made.link, now).size(), made.link->options().max_datagram_bytes);
  EXPECT_EQ(made.link->counters().truncated, 1u);
  ::close(tx);

  // TCP: connects, reads, notices the server closing, reconnects.
  const int server = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(0x7F000001u);
  ASSERT_EQ(bind(server, reinterpret_cast<const sockaddr*>(&a), sizeof a), 0);
  socklen_t len = sizeof a;
  getsockname(server, reinterpret_cast<sockaddr*>(&a), &len);
  ASSERT_EQ(listen(server, 2), 0);
  link::LinkOptions t;
  t.kind = link::LinkKind::tcp;
  t.endpoint = {0x7F000001u, ntohs(a.sin_port)};
  t.backoff = 0.01;
  made = link::ByteLink::create(t);
  ASSERT_TRUE(made.link);
  link::ByteLink& l = *made.link;
  for (int i = 0; i < 100 && l.state() != link::LinkState::open; ++i) {
    l.poll(now += ms(1));
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_EQ(l.state(), link::LinkState::open) << l.last_error();
  int peer = accept(server, nullptr, nullptr);
  ASSERT_GE(peer, 0);
  ASSERT_EQ(::write(peer, "$GPZDA,x\r\n", 10), 10);
  EXPECT_EQ(poll_bytes(l, now), "$GPZDA,x\r\n");
  ::close(peer);
  for (int i = 0; i < 100 && l.state() == link::LinkState::open; ++i) {
    l.poll(now += ms(1));
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_EQ(l.counters().closes, 1u);
  EXPECT_NE(std::string(l.last_error()).find("closed by"), std::string::npos) << l.last_error();
  for (int i = 0; i < 200 && l.counters().opens < 2; ++i) {
    l.poll(now += ms(1));
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_EQ(l.counters().opens, 2u);
  ::close(server);
}

TEST(ByteLink, UdpBytesAreStampedWithTheKernelsArrivalNotTheRead) {
  // An IMU or GPS over UDP read 200 ms late (a busy core, a stalled task)
  // must still be stamped when its datagram came: the clock relations and
  // the pose take these stamps as the data's time. On loopback the kernel
  // stamps a datagram inside the sender's sendto() (net.core.
  // netdev_tstamp_prequeue, on by default), so the stamp lies between the
  // host times read around that call.
  link::LinkOptions u;
  u.kind = link::LinkKind::udp;
  u.endpoint = {0x7F000001u, 0};
  auto made = link::ByteLink::create(u);
  ASSERT_TRUE(made.link);
  Nanos now = 0;
  made.link->poll(now);
  ASSERT_EQ(made.link->state(), link::LinkState::open) << made.link->last_error();
  const int tx = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_addr.s_addr = htonl(0x7F000001u);
  to.sin_port = htons(made.link->bound_port());
  // The kernel turns its receive stamps on for the first socket that asks
  // (net_enable_timestamp) from a work queue, a moment later: until then a
  // datagram is stamped when read. Probe until it is on.
  bool stamping = false;
  for (int i = 0; i < 200 && !stamping; ++i) {
    sendto(tx, "probe", 5, 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
    const std::int64_t probe_sent = host_now_ns();
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (!poll_bytes(*made.link, now).empty() && made.link->receive_ns() <= probe_sent) stamping = true;
  }
  ASSERT_TRUE(stamping) << "no datagram in 2 s carried a kernel stamp from before its read";
  std::int64_t sent_after = 0;
  for (const char* d : {"$TNIMU,1\r\n", "$TNIMU,2\r\n"}) {
    sendto(tx, d, std::strlen(d), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
    sent_after = host_now_ns();  // the newest datagram's stamp is before this
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const std::int64_t read_from = host_now_ns();
  EXPECT_EQ(poll_bytes(*made.link, now), "$TNIMU,1\r\n$TNIMU,2\r\n");
  EXPECT_LE(made.link->receive_ns(), sent_after);
  EXPECT_GE(read_from - made.link->receive_ns(), 200'000'000) << "stamped when read, not when it arrived";
  ::close(tx);
}

namespace {

// Runs a task by hand with a fake clock.
template <typename T>
void tick(T& task, Nanos now) {
  TaskTick t;
  t.scheduled = t.started = now;
  task.run(t);
}

}  // namespace

TEST(GpsDriver, RealReceiverLogThroughAPtyGivesTheOfflineFixes) {
  const std::string dir = temp_dir("gps");
  const std::string path = dir + "/gps";
  const std::string log = read_file(test::shared_data("nmea/telit-he910.log"));
  ASSERT_FALSE(log.empty());
  // The offline decoder's fixes.
  std::vector<gps::GpsFix> expected;
  {
    gps::LineFramer f;
    gps::FixAssembler a;
    gps::GpsFix fix;
    f.feed({reinterpret_cast<const std::uint8_t*>(log.data()), log.size()}, [&](std::string_view line) {
      if (a.add_line(line, fix)) expected.push_back(fix);
    });
    if (a.flush(fix)) expected.push_back(fix);
  }
  ASSERT_GT(expected.size(), 100u);

  Pty pty(path);
  gps::GpsDriverOptions o;
  o.link.device = path;
  o.link.baud = 115200;
  auto made = gps::GpsDriver::create(o);
  ASSERT_TRUE(made.driver) << made.error;
  gps::GpsDriver& d = *made.driver;
  Nanos now = ms(1);
  tick(d, now);
  EXPECT_EQ(d.status().health, gps::GpsHealth::no_data);
  // Line by line, as a receiver would send them, 1 ms apart on the driver's
  // clock. The pseudo-terminal may hand a line over late when the machine is
  // busy; the driver's clock waits for it (a microsecond a poll), so no
  // silence of epoch_gap ever falls inside an epoch and the epochs are the
  // offline decoder's whatever the load (a late line on the driver's clock
  // would end the epoch early: a fix split in two).
  std::vector<gps::GpsFix> got;
  std::size_t start = 0;
  gps::LineFramer written_framer;
  std::uint64_t lines_written = 0;
  while (start < log.size()) {
    std::size_t end = log.find('\n', start);
    end = end == std::string::npos ? log.size() : end + 1;
    const std::string_view chunk = std::string_view(log).substr(start, end - start);
    pty.write(chunk);
    written_framer.feed({reinterpret_cast<const std::uint8_t*>(chunk.data()), chunk.size()}, [&](std::string_view) { ++lines_written; });
    start = end;
    tick(d, now += ms(1));
    for (int spin = 0; spin < 25000 && d.status().gps.lines < lines_written; ++spin) {  // at most 5 s
      std::this_thread::sleep_for(std::chrono::microseconds(200));
      tick(d, now += 1000);
      if (const gps::GpsReading* r = d.fixes().try_read()) got.push_back(r->fix);
    }
    ASSERT_EQ(d.status().gps.lines, lines_written) << "the pseudo-terminal did not deliver a line within 5 s";
    if (const gps::GpsReading* r = d.fixes().try_read()) got.push_back(r->fix);
  }
  for (int i = 0; i < 100; ++i) {
    tick(d, now += ms(10));
    if (const gps::GpsReading* r = d.fixes().try_read()) got.push_back(r->fix);
  }
  const gps::GpsDriverStatus st = d.status();
  EXPECT_EQ(st.published, expected.size());
  // The mailbox keeps the newest: every fix read was one of the offline ones, in order.
  ASSERT_FALSE(got.empty());
  std::size_t k = 0;
  for (const gps::GpsFix& f : got) {
    while (k < expected.size() && !(expected[k].time_of_day == f.time_of_day && expected[k].sentences == f.sentences)) ++k;
    ASSERT_LT(k, expected.size()) << "a fix the offline decoder did not produce";
    EXPECT_EQ(f.lat, expected[k].lat);
    EXPECT_EQ(f.lon, expected[k].lon);
  }
  EXPECT_EQ(st.gps.fixes, expected.size());
  EXPECT_EQ(st.link_state, link::LinkState::open);
  fs::remove_all(dir);
}

namespace {

using test::hex;
using test::xbus;

const char* kMti300 =
    "10 20 02 46 82 10 60 04 01 C4 FC 3E 20 10 10 3F 71 CE 6C BE A5 6B CF 3C 61 3B D8 BD 69 1D 25 80 20 0C BB B1 7D "
    "81 BB 96 32 00 3C 01 E8 41 40 20 0C BD A2 1A F8 BE 2A 8E 96 41 1D 27 A2 E0 20 04 00 40 00 03";

}  // namespace

TEST(ImuDriver, XsensOverAPtyStartsTheDeviceDecodesAndReportsDeviceErrors) {
  const std::string dir = temp_dir("imu");
  const std::string path = dir + "/imu";
  Pty pty(path);
  imu::ImuDriverOptions o;
  o.link.device = path;
  o.xsens_start = true;
  o.xsens_outputs[0] = {imu::xdi::kQuaternion, 100};
  o.xsens_output_count = 1;
  auto made = imu::ImuDriver::create(o);
  ASSERT_TRUE(made.driver) << made.error;
  imu::ImuDriver& d = *made.driver;
  Nanos now = ms(1);
  tick(d, now);
  // On connection: GoToConfig, SetOutputConfiguration, GoToMeasurement.
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_EQ(pty.read_all(), std::string("\xFA\xFF\x30\x00\xD1", 5) +
                                std::string("\xFA\xFF\xC0\x04\x20\x10\x00\x64\xA9", 9) +
                                std::string("\xFA\xFF\x10\x00\xF1", 5));
  std::vector<std::uint8_t> stream;
  for (int k = 0; k < 10; ++k) {
    auto p = hex(kMti300);
    p[3] = static_cast<std::uint8_t>(0x46 + k);  // packet counter
    const auto m = xbus(imu::mid::kMtData2, p);
    stream.insert(stream.end(), m.begin(), m.end());
  }
  stream[40] ^= 0x10;  // one corrupt message
  pty.write(stream);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  tick(d, now += ms(5));
  imu::ImuDriverStatus st = d.status();
  EXPECT_EQ(st.stream.samples, 9u);
  EXPECT_EQ(st.stream.xbus.bad_checksum, 1u);
  EXPECT_EQ(st.health, imu::ImuHealth::ok);
  imu::ImuReading r;
  int queued = 0;
  while (d.readings().try_pop(r)) ++queued;
  EXPECT_EQ(queued, 9);
  EXPECT_EQ(r.sample.packet_counter, 0x4682 + 0x900);
  EXPECT_EQ(r.attitude.source, imu::AttitudeSource::device);
  EXPECT_NEAR(r.sample.acceleration[2], 9.82217598, 1e-6);
  const imu::ImuReading* latest = d.latest().try_read();
  ASSERT_NE(latest, nullptr);
  EXPECT_EQ(latest->sample.packet_counter, r.sample.packet_counter);
  // The device complains: health says so, with the code.
  pty.write(xbus(imu::mid::kError, {0x1E}));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  tick(d, now += ms(5));
  st = d.status();
  EXPECT_EQ(st.health, imu::ImuHealth::device_error);
  EXPECT_EQ(st.stream.last_device_error, 0x1E);
  // No samples for longer than data_timeout: no_data.
  tick(d, now += ms(600));
  EXPECT_EQ(d.status().health, imu::ImuHealth::no_data);
  fs::remove_all(dir);
}

TEST(ImuDriver, LineFormatOverUdp) {
  imu::ImuDriverOptions o;
  o.link.kind = link::LinkKind::udp;
  o.link.endpoint = {0x7F000001u, 0};
  o.protocol = imu::ImuProtocol::line;
  o.attitude.use_device_orientation = false;
  auto made = imu::ImuDriver::create(o);
  ASSERT_TRUE(made.driver);
  Nanos now = ms(1);
  tick(*made.driver, now);
  imu::ImuDriverStatus st = made.driver->status();
  ASSERT_EQ(st.link_state, link::LinkState::open);
  ASSERT_NE(st.udp_port, 0);
  EXPECT_EQ(st.health, imu::ImuHealth::no_data);
  const int tx = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_addr.s_addr = htonl(0x7F000001u);
  to.sin_port = htons(st.udp_port);
  // Level and still, 5 degrees of roll; one line corrupt, one not ours.
  const double g = imu::kStandardGravity, r = 5.0 * M_PI / 180.0;
  for (int k = 0; k < 100; ++k) {
    imu::ImuSample s;
    s.sample_time = k * 0.01;
    s.acceleration = {0.0, g * std::sin(r), g * std::cos(r)};
    s.fields = imu::kSampleTime | imu::kRateOfTurn | imu::kAcceleration;
    char line[200];
    std::size_t n = imu::format_imu_line(s, line, sizeof line);
    if (k == 50) line[10] = '7';
    sendto(tx, line, n, 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
  }
  const char* other = "$GPGGA,1,2*00\r\n";
  sendto(tx, other, std::strlen(other), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
  ::close(tx);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  // About 7 kB: two polls of the 4 kB buffer, no datagram cut in two.
  tick(*made.driver, now += ms(5));
  tick(*made.driver, now += ms(5));
  st = made.driver->status();
  EXPECT_EQ(st.link.truncated, 0u);
  EXPECT_EQ(st.stream.samples, 99u);
  EXPECT_EQ(st.stream.line_rejected[static_cast<std::size_t>(imu::LineError::bad_checksum)], 1u);
  EXPECT_EQ(st.stream.line_rejected[static_cast<std::size_t>(imu::LineError::not_imu)], 1u);
  EXPECT_EQ(st.health, imu::ImuHealth::ok);
  EXPECT_NEAR(st.attitude.roll, r, 1e-9);
  EXPECT_NEAR(st.attitude.pitch, 0.0, 1e-9);
}

// The drivers under the real scheduler, armed: fed through pseudo-terminals
// for a second, including losing and regaining the GPS, they never allocate.
TEST(SerialDrivers, ArmedDriversNeverTouchTheHeapEvenAcrossReconnection) {
  ASSERT_TRUE(alloc_guard::hook_installed());
  alloc_guard::set_fatal(false);
  alloc_guard::reset_counters();
  const std::string dir = temp_dir("armed");
  Pty gps_pty(dir + "/gps");
  Pty imu_pty(dir + "/imu");
  gps::GpsDriverOptions go;
  go.link.device = dir + "/gps";
  go.link.backoff = 0.02;
  go.link.max_backoff = 0.05;
  imu::ImuDriverOptions io;
  io.link.device = dir + "/imu";
  io.xsens_start = true;
  io.attitude.use_device_orientation = false;
  auto g = gps::GpsDriver::create(go);
  auto i = imu::ImuDriver::create(io);
  ASSERT_TRUE(g.driver && i.driver);
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  ASSERT_TRUE(scheduler.add({"gps", TaskKind::periodic, 200.0, 2 * kNanosPerMilli, 0, -1}, *g.driver));
  ASSERT_TRUE(scheduler.add({"imu", TaskKind::periodic, 400.0, 2 * kNanosPerMilli, 0, -1}, *i.driver));
  // Everything the test thread sends is prepared before arming.
  const std::string log = read_file(test::shared_data("nmea/telit-he910.log"));
  std::vector<std::uint8_t> imu_bytes;
  for (int k = 0; k < 400; ++k) {
    const auto m = xbus(imu::mid::kMtData2, hex(kMti300));
    imu_bytes.insert(imu_bytes.end(), m.begin(), m.end());
  }
  ASSERT_TRUE(scheduler.start());
  ASSERT_TRUE(alloc_guard::arm());
  const std::size_t half = log.size() / 2;
  std::size_t sent = 0;
  for (int step = 0; step < 100; ++step) {
    const std::size_t n = std::min(log.size() / 100 + 1, log.size() - sent);
    gps_pty.write(std::string_view(log).substr(sent, n));
    sent += n;
    imu_pty.write(std::vector<std::uint8_t>(imu_bytes.begin() + step * 4 * 73, imu_bytes.begin() + (step + 1) * 4 * 73));
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    if (sent >= half && step == 50) {
      gps_pty.close();  // unplugged ...
      std::this_thread::sleep_for(std::chrono::milliseconds(60));
      gps_pty.open();   // ... and back
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  scheduler.stop();
  alloc_guard::disarm();
  const gps::GpsDriverStatus gs = g.driver->status();
  const imu::ImuDriverStatus is = i.driver->status();
  EXPECT_GE(gs.link.opens, 2u);
  EXPECT_GE(gs.link.closes, 1u);
  EXPECT_GT(gs.published, 50u);
  EXPECT_GE(is.stream.samples, 390u);
  test::expect_no_realtime_allocations();
  fs::remove_all(dir);
}
