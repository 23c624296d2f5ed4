// An IMU's byte stream to samples, whichever protocol it speaks: Xsens MT
// (Xbus framing, MTData2, device Error messages) or $TNIMU lines. Counts
// every rejection by reason. Used by the driver task and by `trailnav
// imu-decode`, so both see the same samples and counters. Pure: no I/O, no
// allocation.
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "trailnav/drivers/gps/fix.hpp"
#include "trailnav/drivers/imu/line_format.hpp"
#include "trailnav/drivers/imu/xsens.hpp"

namespace trailnav::imu {

enum class ImuProtocol : std::uint8_t { xsens, line };
const char* imu_protocol_name(ImuProtocol p) noexcept;

struct ImuStreamCounters {
  XbusCounters xbus;
  MtData2Counters items;
  std::array<std::uint64_t, kXsensErrors> xsens_rejected{};
  std::array<std::uint64_t, kLineErrors> line_rejected{};  // not_imu: other sentences on the line
  std::uint64_t device_errors = 0;   // Xsens Error messages
  std::uint8_t last_device_error = 0;
  std::uint64_t other_messages = 0;  // acknowledgements and replies
  std::uint64_t samples = 0;
  std::uint64_t overlong_lines = 0;
};

class ImuStreamDecoder {
 public:
  explicit ImuStreamDecoder(ImuProtocol protocol) noexcept : protocol_(protocol) {}

  // Calls on_sample(ImuSample&) for every decoded sample, stamped `time_ns`.
  template <typename F>
  void feed(std::span<const std::uint8_t> bytes, std::int64_t time_ns, F&& on_sample) {
    if (protocol_ == ImuProtocol::xsens) {
      xbus_.feed(bytes, [&](const XbusMessage& m) {
        if (m.mid == mid::kError) {
          ++counters_.device_errors;
          counters_.last_device_error = m.payload.empty() ? 0 : m.payload[0];
          return;
        }
        if (m.mid != mid::kMtData2) {
          ++counters_.other_messages;
          return;
        }
        ImuSample s;
        s.time_ns = time_ns;
        const XsensError e = decode_mtdata2(m.payload, s, &counters_.items);
        if (e != XsensError::none) {
          ++counters_.xsens_rejected[static_cast<std::size_t>(e)];
          return;
        }
        ++counters_.samples;
        on_sample(s);
      });
      counters_.xbus = xbus_.counters();
    } else {
      lines_.feed(bytes, [&](std::string_view line) {
        ImuSample s;
        s.time_ns = time_ns;
        const LineError e = parse_imu_line(line, s);
        if (e != LineError::none) {
          ++counters_.line_rejected[static_cast<std::size_t>(e)];
          return;
        }
        ++counters_.samples;
        on_sample(s);
      });
      counters_.overlong_lines = lines_.overlong();
    }
  }

  ImuProtocol protocol() const noexcept { return protocol_; }
  const ImuStreamCounters& counters() const noexcept { return counters_; }

 private:
  ImuProtocol protocol_;
  XbusFramer xbus_;
  gps::LineFramer lines_;
  ImuStreamCounters counters_;
};

}  // namespace trailnav::imu
