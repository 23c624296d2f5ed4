#include "trailnav/drivers/velodyne/sensor_clock.hpp"

#include <algorithm>
#include <array>

namespace trailnav::velodyne {
namespace {

constexpr std::int64_t kHourUs = 3'600'000'000;
constexpr std::int64_t kHourNs = kHourUs * 1000;

// Days from 1970-01-01 to a civil date (proleptic Gregorian).
constexpr std::int64_t days_from_civil(std::int64_t y, unsigned m, unsigned d) noexcept {
  y -= m <= 2 ? 1 : 0;
  const std::int64_t era = (y >= 0 ? y : y - 399) / 400;
  const auto yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m > 2 ? m - 3 : m + 9) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<std::int64_t>(doe) - 719468;
}

int hex_digit(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

bool digits(std::string_view s, std::size_t at, std::size_t count, int& value) noexcept {
  if (at + count > s.size()) return false;
  value = 0;
  for (std::size_t i = at; i < at + count; ++i) {
    if (s[i] < '0' || s[i] > '9') return false;
    value = value * 10 + (s[i] - '0');
  }
  return true;
}

std::int64_t floor_div(std::int64_t a, std::int64_t b) noexcept {
  const std::int64_t q = a / b;
  return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

}  // namespace

std::optional<std::int64_t> rmc_utc_ns(std::string_view s) noexcept {
  // $ttRMC,hhmmss.sss,A,llll.ll,a,yyyyy.yy,a,x.x,x.x,ddmmyy,...*hh
  if (s.size() < 12 || s[0] != '$' || s.substr(3, 4) != "RMC,") return std::nullopt;
  const std::size_t star = s.rfind('*');
  if (star == std::string_view::npos || star + 3 > s.size()) return std::nullopt;
  std::uint8_t sum = 0;
  for (std::size_t i = 1; i < star; ++i) sum = static_cast<std::uint8_t>(sum ^ static_cast<std::uint8_t>(s[i]));
  const int hi = hex_digit(s[star + 1]);
  const int lo = hex_digit(s[star + 2]);
  if (hi < 0 || lo < 0 || sum != hi * 16 + lo) return std::nullopt;

  std::array<std::string_view, 10> fields{};
  std::size_t field = 0;
  std::size_t begin = 7;
  for (std::size_t i = begin; i <= star && field < fields.size(); ++i) {
    if (i == star || s[i] == ',') {
      fields[field++] = s.substr(begin, i - begin);
      begin = i + 1;
    }
  }
  if (field < 9) return std::nullopt;
  const std::string_view time = fields[0];
  const std::string_view date = fields[8];
  int hh = 0, mm = 0, ss = 0, day = 0, month = 0, year = 0;
  if (!digits(time, 0, 2, hh) || !digits(time, 2, 2, mm) || !digits(time, 4, 2, ss)) return std::nullopt;
  if (date.size() != 6 || !digits(date, 0, 2, day) || !digits(date, 2, 2, month) || !digits(date, 4, 2, year)) {
    return std::nullopt;
  }
  if (hh > 23 || mm > 59 || ss > 60 || day < 1 || day > 31 || month < 1 || month > 12) return std::nullopt;
  std::int64_t fraction_ns = 0;
  if (time.size() > 6) {
    if (time[6] != '.') return std::nullopt;
    std::int64_t scale = 100'000'000;
    for (std::size_t i = 7; i < time.size(); ++i) {
      if (time[i] < '0' || time[i] > '9') return std::nullopt;
      fraction_ns += (time[i] - '0') * scale;
      scale /= 10;
    }
  }
  // Two-digit years: 80..99 are 1980..1999, the rest 2000..2079 (GPS began in 1980).
  const int full_year = year >= 80 ? 1900 + year : 2000 + year;
  const std::int64_t days = days_from_civil(full_year, static_cast<unsigned>(month), static_cast<unsigned>(day));
  return ((days * 24 + hh) * 3600 + mm * 60 + ss) * 1'000'000'000LL + fraction_ns;
}

const char* time_source_name(TimeSource source) noexcept {
  switch (source) {
    case TimeSource::none: return "none";
    case TimeSource::host: return "host";
    case TimeSource::gps: return "gps";
  }
  return "?";
}

std::int64_t SensorClock::unwrap(std::uint32_t counter) noexcept {
  if (!have_counter_) {
    have_counter_ = true;
    last_counter_ = counter;
    last_continuous_us_ = counter;
    return counter;
  }
  // The reading of the counter nearest the newest one so far: a counter far
  // below it has passed the top of the hour, one far above is a late packet
  // from before it.
  const std::int64_t delta = hour_clock_delta_us(counter, last_counter_);
  const std::int64_t continuous = last_continuous_us_ + delta;
  if (delta < -kStepBackUs) {
    // Half a second is no late packet: the clock was set back. Follow it, and
    // let the outputs go back with it (held at the old time, every revolution
    // of the next seconds would have one time).
    ++steps_back_;
    last_counter_ = counter;
    last_continuous_us_ = continuous;
    last_out_ns_ = 0;
    return continuous;
  }
  if (delta > 0) {
    if (counter < last_counter_) ++rollovers_;
    last_counter_ = counter;
    last_continuous_us_ = continuous;
  }
  return continuous;
}

void SensorClock::on_position_packet(const PositionPacket& packet) noexcept {
  const std::int64_t continuous_us = unwrap(packet.timestamp_us);
  if (!options_.use_gps || packet.pps != PpsStatus::locked) return;
  const auto utc = rmc_utc_ns(packet.nmea);
  if (!utc) return;
  // The sensor's counter is UTC's position in the hour: the hour comes from
  // the sentence, taken so that the packet lies nearest the sentence's time.
  std::int64_t packet_utc = floor_div(*utc, kHourNs) * kHourNs + static_cast<std::int64_t>(packet.timestamp_us) * 1000;
  if (packet_utc - *utc > kHourNs / 2) packet_utc -= kHourNs;
  if (*utc - packet_utc > kHourNs / 2) packet_utc += kHourNs;
  gps_epoch_ns_ = packet_utc - continuous_us * 1000;
  if (source_ != TimeSource::gps) {
    // The one step allowed: from the host's estimate to GPS time.
    if (source_ == TimeSource::host) ++steps_;
    last_out_ns_ = 0;
    source_ = TimeSource::gps;
  }
}

std::int64_t SensorClock::resolve(std::uint32_t us_past_hour, std::int64_t host_receive_ns) noexcept {
  const std::int64_t sensor_ns = unwrap(us_past_hour) * 1000;
  if (source_ == TimeSource::gps) return monotonic(gps_epoch_ns_ + sensor_ns);

  source_ = TimeSource::host;
  const std::int64_t offset = host_receive_ns - sensor_ns;
  if (!have_offset_) {
    have_offset_ = true;
    offset_ns_ = window_min_ns_ = offset;
    window_start_ns_ = host_receive_ns;
    window_open_ = true;  // the first window: follow every new minimum at once
  } else {
    window_min_ns_ = std::min(window_min_ns_, offset);
    if (window_open_) offset_ns_ = std::min(offset_ns_, offset);
    if (host_receive_ns - window_start_ns_ >= options_.offset_window_ns) {
      offset_ns_ = window_min_ns_;
      window_min_ns_ = offset;
      window_start_ns_ = host_receive_ns;
      window_open_ = false;
    }
  }
  return monotonic(sensor_ns + offset_ns_);
}

std::int64_t SensorClock::monotonic(std::int64_t t) noexcept {
  if (t < last_out_ns_) {
    ++clamped_;
    return last_out_ns_;
  }
  last_out_ns_ = t;
  return t;
}

}  // namespace trailnav::velodyne
