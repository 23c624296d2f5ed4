#include "trailnav/drivers/imu/line_format.hpp"

#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>

#include "trailnav/drivers/gps/nmea.hpp"

namespace trailnav::imu {
namespace {

constexpr std::string_view kTag = "$TNIMU,";

int hex_digit(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

}  // namespace

const char* line_error_name(LineError e) noexcept {
  switch (e) {
    case LineError::none: return "none";
    case LineError::not_imu: return "not_imu";
    case LineError::bad_checksum: return "bad_checksum";
    case LineError::field_count: return "field_count";
    case LineError::bad_number: return "bad_number";
    case LineError::bad_quaternion: return "bad_quaternion";
  }
  return "unknown";
}

LineError parse_imu_line(std::string_view line, ImuSample& sample) noexcept {
  while (!line.empty() && (line.back() == '\r' || line.back() == '\n' || line.back() == ' ')) line.remove_suffix(1);
  if (line.substr(0, kTag.size()) != kTag) return LineError::not_imu;
  std::string_view body = line.substr(1);
  if (const std::size_t star = body.find('*'); star != std::string_view::npos) {
    const std::string_view sum = body.substr(star + 1);
    if (sum.size() != 2 || hex_digit(sum[0]) < 0 || hex_digit(sum[1]) < 0) return LineError::bad_checksum;
    body = body.substr(0, star);
    if (gps::nmea_checksum(body) != hex_digit(sum[0]) * 16 + hex_digit(sum[1])) return LineError::bad_checksum;
  }
  body.remove_prefix(kTag.size() - 1);  // "TNIMU,"
  std::array<double, 11> v{};
  std::size_t n = 0;
  while (true) {
    const std::size_t comma = body.find(',');
    const std::string_view field = body.substr(0, comma);
    if (n == v.size()) return LineError::field_count;
    const char* end = field.data() + field.size();
    const auto r = std::from_chars(field.data(), end, v[n]);
    if (field.empty() || r.ec != std::errc() || r.ptr != end || !std::isfinite(v[n])) return LineError::bad_number;
    ++n;
    if (comma == std::string_view::npos) break;
    body.remove_prefix(comma + 1);
  }
  if (n != 7 && n != 11) return LineError::field_count;
  // A device clock beyond 10^12 s (31,700 years) is a corrupt field, and
  // format_imu_line could not write it back in a line.
  if (std::abs(v[0]) > kMaxSampleTime) return LineError::bad_number;
  std::uint32_t fields = kSampleTime | kRateOfTurn | kAcceleration;
  if (n == 11) {
    const double norm = std::sqrt(v[7] * v[7] + v[8] * v[8] + v[9] * v[9] + v[10] * v[10]);
    if (std::abs(norm - 1.0) > 0.01) return LineError::bad_quaternion;
    sample.orientation = {v[7] / norm, v[8] / norm, v[9] / norm, v[10] / norm};
    fields |= kOrientation;
  }
  sample.sample_time = v[0];
  sample.rate_of_turn = {v[1], v[2], v[3]};
  sample.acceleration = {v[4], v[5], v[6]};
  sample.fields = fields;
  return LineError::none;
}

std::size_t format_imu_line(const ImuSample& s, char* out, std::size_t capacity) noexcept {
  std::array<char, 200> body{};
  int n = std::snprintf(body.data(), body.size(), "TNIMU,%.6f,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g", s.sample_time,
                        s.rate_of_turn[0], s.rate_of_turn[1], s.rate_of_turn[2], s.acceleration[0],
                        s.acceleration[1], s.acceleration[2]);
  if (n > 0 && s.has(kOrientation)) {
    n += std::snprintf(body.data() + n, body.size() - static_cast<std::size_t>(n), ",%.9g,%.9g,%.9g,%.9g",
                       s.orientation[0], s.orientation[1], s.orientation[2], s.orientation[3]);
  }
  if (n <= 0 || static_cast<std::size_t>(n) >= body.size()) return 0;
  const std::string_view b(body.data(), static_cast<std::size_t>(n));
  const int written = std::snprintf(out, capacity, "$%s*%02X\r\n", body.data(), gps::nmea_checksum(b));
  if (written <= 0 || static_cast<std::size_t>(written) >= capacity) return 0;
  return static_cast<std::size_t>(written);
}

}  // namespace trailnav::imu
