// A connected UDP socket for the bench tools (replayer, simulator): sends
// datagrams to one destination. Tools only send to loopback (127.0.0.0/8);
// open() refuses any other destination.
#pragma once

#include <netinet/in.h>

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "trailnav/drivers/udp/udp_receiver.hpp"

namespace trailnav::udp {

class UdpSender {
 public:
  struct Opened;
  static Opened open(const Endpoint& destination, int send_buffer_bytes = 1 << 20);
  ~UdpSender();
  UdpSender(const UdpSender&) = delete;
  UdpSender& operator=(const UdpSender&) = delete;

  // False when the kernel refused the datagram (counted in failures()).
  bool send(std::span<const std::uint8_t> payload) noexcept;

  const Endpoint& destination() const noexcept { return destination_; }
  std::uint64_t sent() const noexcept { return sent_; }
  std::uint64_t bytes() const noexcept { return bytes_; }
  std::uint64_t failures() const noexcept { return failures_; }

 private:
  UdpSender() = default;
  int fd_ = -1;
  Endpoint destination_;
  sockaddr_in address_{};
  std::uint64_t sent_ = 0;
  std::uint64_t bytes_ = 0;
  std::uint64_t failures_ = 0;
};

struct UdpSender::Opened {
  std::unique_ptr<UdpSender> sender;
  std::string error;
};

}  // namespace trailnav::udp
