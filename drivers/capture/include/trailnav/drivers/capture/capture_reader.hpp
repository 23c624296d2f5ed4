// Reads recorded UDP traffic: pcap and pcapng files through libpcap
// (Ethernet, 802.1Q VLAN, Linux cooked and raw-IP link types; IPv4 UDP), and
// the raw format of back-to-back 1206-byte Velodyne payloads without framing
// or timestamps. Offline tooling: allocates freely, never on a real-time thread.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "trailnav/runtime/status.hpp"

namespace trailnav::capture {

struct UdpDatagram {
  std::int64_t time_ns = 0;   // capture time, ns since the epoch (0 in raw files)
  std::uint32_t source_ip = 0;       // host order
  std::uint32_t destination_ip = 0;  // host order
  std::uint16_t source_port = 0;
  std::uint16_t destination_port = 0;
  std::span<const std::uint8_t> payload;  // valid until the next call to next()
};

struct CaptureCounters {
  std::uint64_t frames = 0;         // frames read from the file
  std::uint64_t udp = 0;            // IPv4 UDP datagrams delivered
  std::uint64_t not_udp = 0;        // other protocols, skipped
  std::uint64_t truncated = 0;      // frames cut short by the capture's snap length or broken headers
  std::uint64_t fragments = 0;      // IP fragments, skipped
};

class CaptureReader {
 public:
  virtual ~CaptureReader() = default;
  // The next UDP datagram; nullopt at the end of the file.
  virtual std::optional<UdpDatagram> next() = 0;
  virtual const CaptureCounters& counters() const noexcept = 0;
  // Bytes read so far and in all (for progress bars).
  virtual std::uint64_t position() const noexcept = 0;
  virtual std::uint64_t size() const noexcept = 0;
};

struct OpenResult {
  std::unique_ptr<CaptureReader> reader;
  std::string error;
};

// Opens a pcap or pcapng file, or a raw file of 1206-byte payloads (chosen
// when the file's size is a multiple of 1206 and it has no pcap magic).
// Raw payloads are delivered as if sent to port `raw_port`.
OpenResult open_capture(const std::string& path, std::uint16_t raw_port = 2368);

std::string format_ipv4(std::uint32_t ip);

}  // namespace trailnav::capture
