#include "trailnav/drivers/capture/capture_reader.hpp"

#include <pcap/pcap.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <sys/stat.h>

namespace trailnav::capture {
namespace {

constexpr int kLinkEthernet = DLT_EN10MB;
constexpr int kLinkCooked = DLT_LINUX_SLL;
constexpr int kLinkRaw = DLT_RAW;
constexpr int kLinkIpv4 = 228;  // DLT_IPV4

std::uint16_t be16(const std::uint8_t* p) { return static_cast<std::uint16_t>((p[0] << 8) | p[1]); }
std::uint32_t be32(const std::uint8_t* p) {
  return (static_cast<std::uint32_t>(p[0]) << 24) | (static_cast<std::uint32_t>(p[1]) << 16) |
         (static_cast<std::uint32_t>(p[2]) << 8) | p[3];
}

std::uint64_t file_size(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 ? static_cast<std::uint64_t>(st.st_size) : 0;
}

class PcapReader final : public CaptureReader {
 public:
  PcapReader(pcap_t* handle, std::uint64_t size) : handle_(handle), size_(size), link_(pcap_datalink(handle)) {}
  ~PcapReader() override { pcap_close(handle_); }

  std::optional<UdpDatagram> next() override {
    for (;;) {
      pcap_pkthdr* header = nullptr;
      const u_char* data = nullptr;
      const int rc = pcap_next_ex(handle_, &header, &data);
      if (rc != 1) return std::nullopt;  // end of file (or read error: counted as the end)
      ++counters_.frames;
      position_ += header->caplen + 16;
      if (auto d = parse(header, data)) return d;
    }
  }
  const CaptureCounters& counters() const noexcept override { return counters_; }
  std::uint64_t position() const noexcept override { return position_; }
  std::uint64_t size() const noexcept override { return size_; }

 private:
  std::optional<UdpDatagram> parse(const pcap_pkthdr* header, const std::uint8_t* data) {
    std::size_t length = header->caplen;
    std::size_t offset = 0;
    if (link_ == kLinkEthernet) {
      if (length < 14) return truncated();
      std::uint16_t type = be16(data + 12);
      offset = 14;
      while (type == 0x8100 || type == 0x88A8) {  // VLAN tags
        if (length < offset + 4) return truncated();
        type = be16(data + offset + 2);
        offset += 4;
      }
      if (type != 0x0800) return skip();
    } else if (link_ == kLinkCooked) {
      if (length < 16) return truncated();
      if (be16(data + 14) != 0x0800) return skip();
      offset = 16;
    } else if (link_ != kLinkRaw && link_ != kLinkIpv4) {
      return skip();
    }
    if (length < offset + 20) return truncated();
    const std::uint8_t* ip = data + offset;
    if ((ip[0] >> 4) != 4) return skip();
    const std::size_t ihl = static_cast<std::size_t>(ip[0] & 0x0F) * 4;
    if (ihl < 20 || length < offset + ihl + 8) return truncated();
    if (ip[9] != 17) return skip();
    const std::uint16_t flags_fragment = be16(ip + 6);
    if ((flags_fragment & 0x3FFF) != 0) {  // more-fragments flag or an offset
      ++counters_.fragments;
      return std::nullopt;
    }
    const std::uint8_t* udp = ip + ihl;
    const std::size_t udp_length = be16(udp + 4);
    if (udp_length < 8) return truncated();
    const std::size_t available = length - offset - ihl;
    if (udp_length > available) return truncated();
    UdpDatagram d;
    d.time_ns = static_cast<std::int64_t>(header->ts.tv_sec) * 1'000'000'000 + static_cast<std::int64_t>(header->ts.tv_usec);
    d.source_ip = be32(ip + 12);
    d.destination_ip = be32(ip + 16);
    d.source_port = be16(udp);
    d.destination_port = be16(udp + 2);
    d.payload = std::span<const std::uint8_t>(udp + 8, udp_length - 8);
    ++counters_.udp;
    return d;
  }
  std::optional<UdpDatagram> truncated() {
    ++counters_.truncated;
    return std::nullopt;
  }
  std::optional<UdpDatagram> skip() {
    ++counters_.not_udp;
    return std::nullopt;
  }

  pcap_t* handle_;
  std::uint64_t size_;
  int link_;
  std::uint64_t position_ = 0;
  CaptureCounters counters_;
};

class RawReader final : public CaptureReader {
 public:
  RawReader(const std::string& path, std::uint64_t size, std::uint16_t port)
      : in_(path, std::ios::binary), size_(size), port_(port) {}

  std::optional<UdpDatagram> next() override {
    if (!in_.read(reinterpret_cast<char*>(buffer_.data()), static_cast<std::streamsize>(buffer_.size()))) return std::nullopt;
    ++counters_.frames;
    ++counters_.udp;
    position_ += buffer_.size();
    UdpDatagram d;
    d.source_port = port_;
    d.destination_port = port_;
    d.payload = buffer_;
    return d;
  }
  const CaptureCounters& counters() const noexcept override { return counters_; }
  std::uint64_t position() const noexcept override { return position_; }
  std::uint64_t size() const noexcept override { return size_; }

 private:
  std::ifstream in_;
  std::uint64_t size_;
  std::uint16_t port_;
  std::uint64_t position_ = 0;
  std::array<std::uint8_t, 1206> buffer_{};
  CaptureCounters counters_;
};

}  // namespace

OpenResult open_capture(const std::string& path, std::uint16_t raw_port) {
  OpenResult result;
  std::ifstream probe(path, std::ios::binary);
  if (!probe) {
    result.error = path + ": cannot open the capture file";
    return result;
  }
  std::array<std::uint8_t, 4> magic{};
  probe.read(reinterpret_cast<char*>(magic.data()), 4);
  const std::uint32_t m = static_cast<std::uint32_t>(magic[0]) | (static_cast<std::uint32_t>(magic[1]) << 8) |
                          (static_cast<std::uint32_t>(magic[2]) << 16) | (static_cast<std::uint32_t>(magic[3]) << 24);
  const bool pcap_magic = m == 0xA1B2C3D4 || m == 0xD4C3B2A1 || m == 0xA1B23C4D || m == 0x4D3CB2A1 || m == 0x0A0D0D0A;
  const std::uint64_t size = file_size(path);
  if (!pcap_magic) {
    if (size > 0 && size % 1206 == 0) {
      result.reader = std::make_unique<RawReader>(path, size, raw_port);
      return result;
    }
    result.error = path + ": neither a pcap/pcapng file nor raw 1206-byte Velodyne payloads";
    return result;
  }
  std::array<char, PCAP_ERRBUF_SIZE> error{};
  pcap_t* handle = pcap_open_offline_with_tstamp_precision(path.c_str(), PCAP_TSTAMP_PRECISION_NANO, error.data());
  if (handle == nullptr) {
    result.error = path + ": " + error.data();
    return result;
  }
  result.reader = std::make_unique<PcapReader>(handle, size);
  return result;
}

std::string format_ipv4(std::uint32_t ip) {
  char text[16];
  std::snprintf(text, sizeof text, "%u.%u.%u.%u", (ip >> 24) & 0xFF, (ip >> 16) & 0xFF, (ip >> 8) & 0xFF, ip & 0xFF);
  return text;
}

}  // namespace trailnav::capture
