// The Xsens MT low-level communication protocol (Xbus), as the MTi family
// speaks it over a serial line, written from Xsens' public "MT Low Level
// Communication Protocol" documentation:
//
//   0xFA  BID  MID  LEN  [EXTLEN_hi EXTLEN_lo]  DATA...  CHECKSUM
//
// LEN 0xFF announces a two-byte big-endian length (extended message). The
// checksum makes every byte from BID to CHECKSUM sum to zero modulo 256.
// Measurements arrive as MTData2 (MID 0x36): a sequence of items, each a
// 16-bit data identifier, a one-byte size and the value, big-endian.
//
// Pure: no I/O, no allocation; the framer's buffer lives inside it.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "trailnav/drivers/imu/imu_sample.hpp"

namespace trailnav::imu {

inline constexpr std::uint8_t kXbusPreamble = 0xFA;
inline constexpr std::uint8_t kXbusMaster = 0xFF;    // the bus identifier of a single device
inline constexpr std::size_t kXbusMaxPayload = 2048;  // longest DATA an MT sends or accepts
inline constexpr std::size_t kXbusMaxMessage = kXbusMaxPayload + 7;

// Message identifiers used by the driver. A device acknowledges a request
// with MID + 1.
namespace mid {
inline constexpr std::uint8_t kReqDeviceId = 0x00;
inline constexpr std::uint8_t kDeviceId = 0x01;
inline constexpr std::uint8_t kInitMt = 0x02;
inline constexpr std::uint8_t kInitMtResults = 0x03;
inline constexpr std::uint8_t kGoToMeasurement = 0x10;
inline constexpr std::uint8_t kGoToMeasurementAck = 0x11;
inline constexpr std::uint8_t kReqFirmwareRevision = 0x12;
inline constexpr std::uint8_t kFirmwareRevision = 0x13;
inline constexpr std::uint8_t kReqBaudrate = 0x18;
inline constexpr std::uint8_t kReqProductCode = 0x1C;
inline constexpr std::uint8_t kProductCode = 0x1D;
inline constexpr std::uint8_t kGoToConfig = 0x30;
inline constexpr std::uint8_t kGoToConfigAck = 0x31;
inline constexpr std::uint8_t kMtData2 = 0x36;
inline constexpr std::uint8_t kWakeUp = 0x3E;
inline constexpr std::uint8_t kWakeUpAck = 0x3F;
inline constexpr std::uint8_t kReset = 0x40;
inline constexpr std::uint8_t kError = 0x42;
inline constexpr std::uint8_t kSetOutputConfiguration = 0xC0;
inline constexpr std::uint8_t kOutputConfiguration = 0xC1;
}  // namespace mid

// A complete, checksum-verified message. `payload` points into the framer
// and is valid during the callback only.
struct XbusMessage {
  std::uint8_t bid = kXbusMaster;
  std::uint8_t mid = 0;
  std::span<const std::uint8_t> payload;
};

struct XbusCounters {
  std::uint64_t bytes = 0;
  std::uint64_t messages = 0;      // checksum correct
  std::uint64_t bad_checksum = 0;  // dropped; the framer searches on after the preamble
  std::uint64_t oversize = 0;      // announced length over kXbusMaxPayload: dropped
  std::uint64_t skipped_bytes = 0; // bytes that were not part of a good message
};

// Splits a byte stream into Xbus messages, resynchronising after garbage or
// a corrupt message without losing the good message that follows. Only
// messages of the master bus identifier (0xFF, what a single MTi sends) are
// taken, so a stray 0xFA cannot hold up the stream by announcing a length.
class XbusFramer {
 public:
  template <typename F>
  void feed(std::span<const std::uint8_t> bytes, F&& on_message) {
    counters_.bytes += bytes.size();
    while (!bytes.empty()) {
      const std::size_t n = std::min(bytes.size(), buffer_.size() - length_);
      std::copy_n(bytes.begin(), n, buffer_.begin() + static_cast<std::ptrdiff_t>(length_));
      length_ += n;
      bytes = bytes.subspan(n);
      drain(on_message);
    }
  }
  const XbusCounters& counters() const noexcept { return counters_; }
  std::size_t pending() const noexcept { return length_; }  // bytes of an unfinished message

 private:
  enum class Scan : std::uint8_t { need_more, message, drop };
  // Looks at buffer_[start..length_): a message, too little, or bytes to drop.
  Scan scan(std::size_t start, std::size_t& total) noexcept;

  template <typename F>
  void drain(F& on_message) {
    std::size_t start = 0;
    while (start < length_) {
      if (buffer_[start] != kXbusPreamble) {
        ++start;
        ++counters_.skipped_bytes;
        continue;
      }
      std::size_t total = 0;
      const Scan s = scan(start, total);
      if (s == Scan::need_more) break;
      if (s == Scan::drop) {  // not a message after all: search on behind this preamble
        ++start;
        ++counters_.skipped_bytes;
        continue;
      }
      ++counters_.messages;
      XbusMessage m;
      m.bid = buffer_[start + 1];
      m.mid = buffer_[start + 2];
      const std::size_t header = buffer_[start + 3] == 0xFF ? 6 : 4;
      m.payload = std::span<const std::uint8_t>(buffer_.data() + start + header, total - header - 1);
      on_message(m);
      start += total;
    }
    // Keep the unfinished tail at the front.
    if (start > 0) {
      std::copy(buffer_.begin() + static_cast<std::ptrdiff_t>(start),
                buffer_.begin() + static_cast<std::ptrdiff_t>(length_), buffer_.begin());
      length_ -= start;
    }
  }

  std::array<std::uint8_t, kXbusMaxMessage> buffer_{};
  std::size_t length_ = 0;
  XbusCounters counters_;
};

// Writes a complete message into `out` (header, payload, checksum); returns
// its length, or 0 when `out` is too small or the payload too long.
std::size_t encode_xbus(std::uint8_t message_id, std::span<const std::uint8_t> payload, std::span<std::uint8_t> out,
                        std::uint8_t bid = kXbusMaster) noexcept;

// MTData2 data identifiers (XDI). The low nibble selects the number format
// (bits 0-1) and, for orientation, velocity and free acceleration, the
// earth frame (bits 2-3).
namespace xdi {
inline constexpr std::uint16_t kTemperature = 0x0810;
inline constexpr std::uint16_t kUtcTime = 0x1010;
inline constexpr std::uint16_t kPacketCounter = 0x1020;
inline constexpr std::uint16_t kSampleTimeFine = 0x1060;
inline constexpr std::uint16_t kSampleTimeCoarse = 0x1070;
inline constexpr std::uint16_t kQuaternion = 0x2010;
inline constexpr std::uint16_t kRotationMatrix = 0x2020;
inline constexpr std::uint16_t kEulerAngles = 0x2030;
inline constexpr std::uint16_t kBaroPressure = 0x3010;
inline constexpr std::uint16_t kDeltaV = 0x4010;
inline constexpr std::uint16_t kAcceleration = 0x4020;
inline constexpr std::uint16_t kFreeAcceleration = 0x4030;
inline constexpr std::uint16_t kRateOfTurn = 0x8020;
inline constexpr std::uint16_t kDeltaQ = 0x8030;
inline constexpr std::uint16_t kMagneticField = 0xC020;
inline constexpr std::uint16_t kStatusByte = 0xE010;
inline constexpr std::uint16_t kStatusWord = 0xE020;

inline constexpr std::uint16_t kTypeMask = 0xFFF0;
inline constexpr std::uint16_t kFormatMask = 0x0003;  // 0 float32, 1 fixed 12.20, 2 fixed 16.32, 3 float64
inline constexpr std::uint16_t kFrameMask = 0x000C;   // 0 ENU, 4 NED, 8 NWU
}  // namespace xdi

enum class XsensError : std::uint8_t {
  none,
  truncated_item,  // an item's header or value runs past the payload
  bad_item_size,   // a known item whose size does not match its number format
  bad_frame,       // earth-frame bits 0xC: not ENU, NED or NWU
  no_data,         // no item the driver uses
};
inline constexpr std::size_t kXsensErrors = 5;
const char* xsens_error_name(XsensError e) noexcept;

struct MtData2Counters {
  std::uint64_t items = 0;
  std::uint64_t unused_items = 0;  // valid but not used by trailnav (delta q, pressure, ...)
};

// Decodes an MTData2 payload. Orientation in NED or NWU is turned into ENU;
// Euler angles become a quaternion; everything else keeps the sensor frame.
// `sample.time_ns` is left as it was.
XsensError decode_mtdata2(std::span<const std::uint8_t> payload, ImuSample& sample,
                          MtData2Counters* counters = nullptr) noexcept;

// The device's Error message (MID 0x42): its code and what it means.
const char* xsens_device_error_text(std::uint8_t code) noexcept;

// SetOutputConfiguration's payload: (data identifier, rate in Hz) pairs,
// rate 0xFFFF for "every sample" items such as the packet counter.
struct OutputItem {
  std::uint16_t id = 0;
  std::uint16_t rate_hz = 0;
};
// Writes the complete message; returns its length (0 when `out` is small).
std::size_t encode_output_configuration(std::span<const OutputItem> items, std::span<std::uint8_t> out) noexcept;

}  // namespace trailnav::imu
