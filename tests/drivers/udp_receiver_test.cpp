#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <set>
#include <thread>
#include <vector>

#include "trailnav/drivers/udp/udp_receiver.hpp"
#include "trailnav/drivers/udp/udp_sender.hpp"
#include "trailnav/runtime/alloc_guard.hpp"

namespace trailnav::udp {
namespace {

constexpr std::uint32_t kLoopback = 0x7F000001u;

std::unique_ptr<UdpReceiver> listen(ReceiverOptions options = {}) {
  options.bind = {kLoopback, 0};  // the kernel picks a free port
  auto opened = UdpReceiver::open(options);
  EXPECT_TRUE(opened.receiver) << opened.error;
  return std::move(opened.receiver);
}

std::unique_ptr<UdpSender> sender_to(const UdpReceiver& r) {
  auto opened = UdpSender::open(r.local());
  EXPECT_TRUE(opened.sender) << opened.error;
  return std::move(opened.sender);
}

std::int64_t now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

TEST(UdpReceiver, ReceivesBatchesWithKernelTimestamps) {
  auto r = listen();
  ASSERT_TRUE(r);
  EXPECT_NE(r->local().port, 0);
  EXPECT_GE(r->granted_buffer_bytes(), 100'000);
  auto s = sender_to(*r);
  const std::int64_t before = now_ns();
  std::vector<std::uint8_t> payload(1206);
  for (int i = 0; i < 100; ++i) {
    payload[0] = static_cast<std::uint8_t>(i);
    ASSERT_TRUE(s->send(payload));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  int received = 0;
  int calls = 0;
  std::vector<std::int64_t> stamps;
  while (received < 100 && calls < 100) {
    for (const Datagram& d : r->receive(100)) {
      stamps.push_back(d.receive_ns);
      EXPECT_EQ(d.payload.size(), 1206u);
      EXPECT_EQ(d.payload[0], received);  // in order on loopback
      EXPECT_GE(d.receive_ns, before);
      EXPECT_EQ(d.source.ip, kLoopback);
      ++received;
    }
    ++calls;
  }
  EXPECT_EQ(received, 100);
  EXPECT_LE(stamps.back(), now_ns());
  // The kernel's own arrival times: one per datagram, not one per read call.
  EXPECT_GT(std::set<std::int64_t>(stamps.begin(), stamps.end()).size(), 50u);
  EXPECT_LE(r->counters().calls, 3u) << "64 datagrams per call";
  EXPECT_EQ(r->counters().datagrams, 100u);
  EXPECT_EQ(r->counters().bytes, 120600u);
  EXPECT_TRUE(r->receive(0).empty());
}

// A plain socket bound to a port of its own, so the test knows the source port.
struct BoundSocket {
  int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  Endpoint local;
  BoundSocket() {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(kLoopback);
    bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
    socklen_t n = sizeof a;
    getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
    local = {ntohl(a.sin_addr.s_addr), ntohs(a.sin_port)};
  }
  ~BoundSocket() { close(fd); }
  void send_to(const Endpoint& to, const std::vector<std::uint8_t>& payload) const {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(to.ip);
    a.sin_port = htons(to.port);
    sendto(fd, payload.data(), payload.size(), 0, reinterpret_cast<sockaddr*>(&a), sizeof a);
  }
};

TEST(UdpReceiver, OnlyTheConfiguredSenderIsAccepted) {
  const BoundSocket sensor;
  ASSERT_GE(sensor.fd, 0);
  ReceiverOptions mine;
  mine.source_ip = kLoopback;
  mine.source_port = sensor.local.port;
  ReceiverOptions someone_elses = mine;
  someone_elses.source_port = static_cast<std::uint16_t>(sensor.local.port + 1);
  auto accepting = listen(mine);
  auto refusing = listen(someone_elses);
  const std::vector<std::uint8_t> payload(10, 1);
  for (int i = 0; i < 5; ++i) {
    sensor.send_to(accepting->local(), payload);
    sensor.send_to(refusing->local(), payload);
  }
  std::size_t accepted = 0;
  for (int i = 0; i < 10 && accepted < 5; ++i) accepted += accepting->receive(200).size();
  for (int i = 0; i < 10 && refusing->counters().foreign < 5; ++i) refusing->receive(200);
  EXPECT_EQ(accepted, 5u);
  EXPECT_EQ(accepting->counters().foreign, 0u);
  EXPECT_EQ(refusing->counters().foreign, 5u);
  EXPECT_EQ(refusing->counters().datagrams, 0u);
}

TEST(UdpReceiver, OversizedDatagramsAreCountedNotDelivered) {
  ReceiverOptions options;
  options.max_datagram_bytes = 1206;
  auto r = listen(options);
  auto s = sender_to(*r);
  ASSERT_TRUE(s->send(std::vector<std::uint8_t>(1500, 7)));
  ASSERT_TRUE(s->send(std::vector<std::uint8_t>(1206, 7)));
  std::size_t delivered = 0;
  for (int i = 0; i < 10 && r->counters().truncated + r->counters().datagrams < 2; ++i) delivered += r->receive(100).size();
  EXPECT_EQ(r->counters().truncated, 1u);
  EXPECT_EQ(delivered, 1u);
}

TEST(UdpReceiver, KernelDropsAreCountedWhenTheBufferOverflows) {
  ReceiverOptions options;
  options.receive_buffer_bytes = 4096;  // the kernel's minimum holds only a few datagrams
  auto r = listen(options);
  auto s = sender_to(*r);
  const std::vector<std::uint8_t> payload(1206, 3);
  for (int i = 0; i < 500; ++i) s->send(payload);
  std::uint64_t got = 0;
  for (int i = 0; i < 20; ++i) got += r->receive(10).size();
  // The kernel attaches its drop count to the next datagram it queues.
  s->send(payload);
  for (int i = 0; i < 20; ++i) got += r->receive(10).size();
  EXPECT_GT(r->counters().kernel_drops, 0u);
  EXPECT_EQ(got + r->counters().kernel_drops, 501u) << "every datagram is either received or counted as dropped";
}

TEST(UdpReceiver, SeveralSensorsOnTheirOwnPorts) {
  auto a = listen();
  auto b = listen();
  ASSERT_NE(a->local().port, b->local().port);
  auto sa = sender_to(*a);
  auto sb = sender_to(*b);
  sa->send(std::vector<std::uint8_t>(100, 0xA));
  sb->send(std::vector<std::uint8_t>(200, 0xB));
  sb->send(std::vector<std::uint8_t>(200, 0xB));
  const auto ra = a->receive(500);
  ASSERT_EQ(ra.size(), 1u);
  EXPECT_EQ(ra[0].payload[0], 0xA);
  std::size_t nb = b->receive(500).size();
  if (nb < 2) nb += b->receive(500).size();
  EXPECT_EQ(nb, 2u);
}

TEST(UdpReceiver, ReceivingDoesNotTouchTheHeap) {
  auto r = listen();
  auto s = sender_to(*r);
  const std::vector<std::uint8_t> payload(1206, 1);
  for (int i = 0; i < 50; ++i) s->send(payload);
  ASSERT_TRUE(alloc_guard::hook_installed());
  alloc_guard::reset_counters();
  std::size_t got = 0;
  std::thread rt([&] {
    alloc_guard::mark_realtime_thread("udp-receive");
    alloc_guard::arm();
    for (int i = 0; i < 50 && got < 50; ++i) got += r->receive(100).size();
    alloc_guard::disarm();
    alloc_guard::unmark_current_thread();
  });
  rt.join();
  EXPECT_EQ(got, 50u);
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
}

TEST(UdpReceiver, BadOptionsAndEndpoints) {
  std::string error;
  EXPECT_FALSE(parse_endpoint("127.0.0.1", error));
  EXPECT_FALSE(parse_endpoint("localhost:2368", error));
  EXPECT_FALSE(parse_endpoint("127.0.0.1:70000", error));
  const auto e = parse_endpoint(":2368", error);
  ASSERT_TRUE(e);
  EXPECT_EQ(e->ip, 0u);
  EXPECT_EQ(format_endpoint({kLoopback, 2368}), "127.0.0.1:2368");
  ReceiverOptions options;
  options.batch = 0;
  EXPECT_NE(UdpReceiver::open(options).error.find("batch"), std::string::npos);
  // Tools never send anywhere but loopback.
  auto refused = UdpSender::open({0x0A000001u, 2368});
  EXPECT_FALSE(refused.sender);
  EXPECT_NE(refused.error.find("loopback"), std::string::npos);
  // A port already taken is a clear error.
  auto a = listen();
  ReceiverOptions same;
  same.bind = a->local();
  auto taken = UdpReceiver::open(same);
  EXPECT_FALSE(taken.receiver);
  EXPECT_NE(taken.error.find("cannot listen on 127.0.0.1:"), std::string::npos) << taken.error;
}

}  // namespace
}  // namespace trailnav::udp
