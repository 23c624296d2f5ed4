// Fuzzes the IMU byte formats: Xbus framing (fed in chunks whose size the
// input chooses), MTData2 decoding, the attitude filter on whatever decodes,
// and the $TNIMU line format with its round trip.
#include <cmath>
#include <cstdint>
#include <string_view>
#include <vector>

#include "check.hpp"

#include "trailnav/drivers/gps/fix.hpp"
#include "trailnav/drivers/imu/attitude.hpp"
#include "trailnav/drivers/imu/line_format.hpp"
#include "trailnav/drivers/imu/xsens.hpp"

using namespace trailnav;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::size_t chunk = 1 + data[0] % 64;
  const std::span<const std::uint8_t> bytes(data + 1, size - 1);

  imu::XbusFramer framer;
  imu::AttitudeFilter filter;
  std::vector<std::uint8_t> again(imu::kXbusMaxMessage);
  std::size_t framed = 0;
  for (std::size_t i = 0; i < bytes.size(); i += chunk) {
    framer.feed(bytes.subspan(i, std::min(chunk, bytes.size() - i)), [&](const imu::XbusMessage& m) {
      ++framed;
      check(m.bid == imu::kXbusMaster);
      check(m.payload.size() <= imu::kXbusMaxPayload);
      // A framed message re-encodes to a message that frames to the same.
      const std::size_t n = imu::encode_xbus(m.mid, m.payload, again);
      check(n == m.payload.size() + (m.payload.size() >= 0xFF ? 7 : 5));
      imu::XbusFramer second;
      int seen = 0;
      second.feed(std::span<const std::uint8_t>(again.data(), n), [&](const imu::XbusMessage& m2) {
        check(m2.mid == m.mid && m2.payload.size() == m.payload.size());
        check(std::equal(m2.payload.begin(), m2.payload.end(), m.payload.begin()));
        ++seen;
      });
      check(seen == 1);
      if (m.mid == imu::mid::kMtData2) {
        imu::ImuSample s;
        imu::MtData2Counters c;
        const imu::XsensError e = imu::decode_mtdata2(m.payload, s, &c);
        check(static_cast<std::size_t>(e) < imu::kXsensErrors);
        if (e == imu::XsensError::none) {
          check(s.fields != 0);
          const imu::Attitude& a = filter.update(s);
          if (a.source == imu::AttitudeSource::filter) {
            const double n2 = a.orientation[0] * a.orientation[0] + a.orientation[1] * a.orientation[1] +
                              a.orientation[2] * a.orientation[2] + a.orientation[3] * a.orientation[3];
            check(!std::isfinite(n2) || std::abs(n2 - 1.0) < 1e-6);
          }
        }
      }
    });
  }
  const imu::XbusCounters& c = framer.counters();
  check(c.messages == framed);
  check(c.bytes == bytes.size());
  check(framer.pending() <= imu::kXbusMaxMessage);

  // The same bytes as text lines.
  gps::LineFramer lines;
  lines.feed(bytes, [&](std::string_view line) {
    imu::ImuSample s;
    if (imu::parse_imu_line(line, s) != imu::LineError::none) return;
    char out[200];
    const std::size_t n = imu::format_imu_line(s, out, sizeof out);
    check(n > 0);
    imu::ImuSample back;
    check(imu::parse_imu_line(std::string_view(out, n), back) == imu::LineError::none);
    check(back.fields == s.fields);
    for (std::size_t i = 0; i < 3; ++i) {
      check(std::abs(back.rate_of_turn[i] - s.rate_of_turn[i]) <= 1e-8 * std::max(1.0, std::abs(s.rate_of_turn[i])));
    }
  });
  return 0;
}
