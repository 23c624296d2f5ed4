// Byte-stream links for serial sensors: a serial port (termios, raw, at a
// configured baud rate; pseudo-terminals on the bench), a UDP port, or a TCP
// connection. Every link is polled without blocking by its driver task and
// runs one explicit state machine:
//
//   closed --open ok--> open --no bytes for silence_timeout--> (reopen)
//     ^   <--failed, after a back-off (doubling up to max_backoff)--'
//
// A link that fails or falls silent is closed and reopened after the
// back-off, so a receiver that is unplugged and plugged in again, a replayer
// restarted, or a TCP server that comes back is picked up on its own. All
// buffers are allocated by create(); poll() and write() never allocate.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "trailnav/drivers/udp/udp_receiver.hpp"
#include "trailnav/runtime/clock.hpp"

namespace trailnav::link {

enum class LinkKind : std::uint8_t { serial, udp, tcp };
const char* link_kind_name(LinkKind kind) noexcept;

struct LinkOptions {
  LinkKind kind = LinkKind::serial;
  std::string device;        // serial: /dev/ttyUSB0, a pseudo-terminal or a symlink to one
  int baud = 115200;         // serial
  udp::Endpoint endpoint;    // udp: address and port to bind; tcp: server to connect to
  double silence_timeout = 2.0;  // s without a byte before the link is reopened (0: never)
  double backoff = 0.5;          // s before the first reopen attempt
  double max_backoff = 8.0;      // s, the longest wait between attempts
  std::size_t buffer_bytes = 4096;  // read per poll at most
  std::size_t max_datagram_bytes = 1472;  // udp: longer datagrams are cut (counted as truncated)
};

// "serial:/dev/ttyUSB0@115200", "udp:127.0.0.1:10110", "udp::10110",
// "tcp:127.0.0.1:2947". nullopt with `error` naming the problem.
std::optional<LinkOptions> parse_link(std::string_view text, std::string& error);
std::string format_link(const LinkOptions& options);
// Baud rates termios knows (50 .. 4000000); false for others.
bool supported_baud(int baud) noexcept;

enum class LinkState : std::uint8_t { closed, connecting, open };
const char* link_state_name(LinkState state) noexcept;

struct LinkCounters {
  std::uint64_t opens = 0;          // successful opens (and TCP connects)
  std::uint64_t open_failures = 0;
  std::uint64_t closes = 0;         // by error, end of stream or silence
  std::uint64_t silences = 0;       // of those: no bytes for silence_timeout
  std::uint64_t read_errors = 0;
  std::uint64_t bytes = 0;
  std::uint64_t truncated = 0;     // udp: datagrams longer than max_datagram_bytes, cut short
  std::uint64_t writes = 0;
  std::uint64_t write_errors = 0;
};

class ByteLink {
 public:
  struct Created;
  // Checks the options and allocates; does not open yet (poll() does).
  static Created create(const LinkOptions& options);
  ~ByteLink();
  ByteLink(const ByteLink&) = delete;
  ByteLink& operator=(const ByteLink&) = delete;

  // Advances the state machine and returns the bytes that arrived (valid
  // until the next call). `now`: a monotonic clock, for timeouts and back-off.
  std::span<const std::uint8_t> poll(Nanos now) noexcept;
  // Sends bytes when open (serial and tcp); false otherwise or on error.
  bool write(std::span<const std::uint8_t> bytes) noexcept;
  void close() noexcept;

  LinkState state() const noexcept { return state_; }
  const LinkCounters& counters() const noexcept { return counters_; }
  const LinkOptions& options() const noexcept { return options_; }
  // The last failure ("open /dev/ttyUSB0: No such file or directory"); empty if none.
  const char* last_error() const noexcept { return error_.data(); }
  Nanos last_byte() const noexcept { return last_byte_; }
  // When the bytes just returned arrived (host time, runtime/host_clock.hpp):
  // for udp the kernel's stamp of the newest datagram among them (SO_TIMESTAMPNS),
  // so a task that reads late still stamps them right; for serial and tcp,
  // which carry no such stamp, the time of the read.
  std::int64_t receive_ns() const noexcept { return receive_ns_; }
  // The UDP port bound (chosen by the kernel when 0); 0 for other kinds.
  std::uint16_t bound_port() const noexcept { return bound_port_; }
  // True when the most recent poll() just opened the link (to send start-up commands).
  bool just_opened() const noexcept { return just_opened_; }

 private:
  explicit ByteLink(const LinkOptions& options);
  void try_open(Nanos now) noexcept;
  void fail(Nanos now, const char* what, int err) noexcept;
  void set_error(const char* what, int err) noexcept;

  LinkOptions options_;
  LinkState state_ = LinkState::closed;
  int fd_ = -1;
  Nanos next_attempt_ = 0;
  double current_backoff_ = 0.0;
  Nanos last_byte_ = 0;
  Nanos opened_at_ = 0;
  std::int64_t receive_ns_ = 0;
  std::uint16_t bound_port_ = 0;
  bool just_opened_ = false;
  std::unique_ptr<std::uint8_t[]> buffer_;
  LinkCounters counters_;
  std::array<char, 160> error_{};
};

struct ByteLink::Created {
  std::unique_ptr<ByteLink> link;
  std::string error;
};

}  // namespace trailnav::link
