// Batched UDP reception for sensor drivers: one recvmmsg() call takes every
// queued datagram up to the batch size into buffers allocated when the socket
// is opened, with the kernel's receive timestamp of each and the kernel's
// count of datagrams it dropped because the socket buffer was full. Only the
// configured sender is accepted. Nothing allocates after open().
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace trailnav::udp {

struct Endpoint {
  std::uint32_t ip = 0;  // host order; 0: any
  std::uint16_t port = 0;
};

// "127.0.0.1:2368", "0.0.0.0:2368", ":2368" (any address). nullopt with
// `error` set when malformed.
std::optional<Endpoint> parse_endpoint(std::string_view text, std::string& error);
std::string format_endpoint(const Endpoint& endpoint);
bool is_loopback(std::uint32_t ip) noexcept;  // 127.0.0.0/8

struct ReceiverOptions {
  Endpoint bind;                     // address and port to listen on
  std::optional<std::uint32_t> source_ip;    // accept only this sender address ...
  std::optional<std::uint16_t> source_port;  // ... and port
  int receive_buffer_bytes = 4 << 20;  // SO_RCVBUF asked for (the kernel may grant less: see granted_buffer_bytes)
  int batch = 64;                      // datagrams per recvmmsg call
  int max_datagram_bytes = 2048;       // larger datagrams are counted as truncated and dropped
  bool kernel_timestamps = true;       // SO_TIMESTAMPNS; else the time of the recvmmsg call
  bool reuse_port = false;             // SO_REUSEPORT, for several listeners on one port
};

struct Datagram {
  std::span<const std::uint8_t> payload;
  std::int64_t receive_ns = 0;  // host time (runtime/host_clock.hpp): the kernel timestamp
  Endpoint source;
};

struct ReceiverCounters {
  std::uint64_t datagrams = 0;     // accepted
  std::uint64_t bytes = 0;         // accepted payload bytes
  std::uint64_t calls = 0;         // recvmmsg calls that returned data
  std::uint64_t foreign = 0;       // from another sender: dropped
  std::uint64_t truncated = 0;     // larger than max_datagram_bytes: dropped
  std::uint64_t kernel_drops = 0;  // dropped by the kernel, socket buffer full (SO_RXQ_OVFL)
  std::uint64_t errors = 0;        // failed receive calls
};

class UdpReceiver {
 public:
  struct Opened;
  static Opened open(const ReceiverOptions& options);
  ~UdpReceiver();
  UdpReceiver(const UdpReceiver&) = delete;
  UdpReceiver& operator=(const UdpReceiver&) = delete;

  // Takes what is queued, waiting up to `timeout_ms` for the first datagram
  // (0: do not wait). The datagrams stay valid until the next call.
  std::span<const Datagram> receive(int timeout_ms = 0) noexcept;

  const ReceiverCounters& counters() const noexcept { return counters_; }
  const ReceiverOptions& options() const noexcept { return options_; }
  Endpoint local() const noexcept { return local_; }  // the bound address (port chosen by the kernel when 0)
  int granted_buffer_bytes() const noexcept { return granted_buffer_; }
  int fd() const noexcept { return fd_; }

 private:
  UdpReceiver() = default;
  struct Buffers;

  ReceiverOptions options_;
  int fd_ = -1;
  Endpoint local_;
  int granted_buffer_ = 0;
  std::unique_ptr<Buffers> buffers_;
  std::vector<Datagram> out_;
  ReceiverCounters counters_;
  std::uint32_t last_overflow_ = 0;
};

struct UdpReceiver::Opened {
  std::unique_ptr<UdpReceiver> receiver;
  std::string error;
};

}  // namespace trailnav::udp
