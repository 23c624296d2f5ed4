#include "trailnav/drivers/gps/nmea.hpp"

#include <charconv>
#include <cmath>
#include <limits>

namespace trailnav::gps {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

struct Fields {
  std::array<std::string_view, kMaxFields> f{};
  int n = 0;
  std::string_view operator[](int i) const noexcept { return i < n ? f[static_cast<std::size_t>(i)] : std::string_view{}; }
};

int hex(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

// A number field: NaN when empty; false when it is not a number.
bool number(std::string_view s, double& out) noexcept {
  if (s.empty()) {
    out = kNaN;
    return true;
  }
  const char* b = s.data();
  if (*b == '+') ++b;
  const auto r = std::from_chars(b, s.data() + s.size(), out);
  return r.ec == std::errc() && r.ptr == s.data() + s.size() && std::isfinite(out);
}

bool integer(std::string_view s, int& out, int empty_value) noexcept {
  if (s.empty()) {
    out = empty_value;
    return true;
  }
  const char* b = s.data();
  if (*b == '+' && s.size() > 1) ++b;
  const auto r = std::from_chars(b, s.data() + s.size(), out);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

// hhmmss[.sss] -> seconds of the day.
bool time_of_day(std::string_view s, double& out) noexcept {
  if (s.empty()) {
    out = kNaN;
    return true;
  }
  if (s.size() < 6) return false;
  int h = 0, m = 0;
  double sec = 0;
  if (!integer(s.substr(0, 2), h, 0) || !integer(s.substr(2, 2), m, 0) || !number(s.substr(4), sec)) return false;
  if (h > 23 || m > 59 || sec < 0 || sec >= 61) return false;
  out = h * 3600.0 + m * 60.0 + sec;
  return true;
}

// ddmm.mmmm + hemisphere -> degrees. `degree_digits` is 2 for latitude, 3 for longitude.
bool coordinate(std::string_view value, std::string_view hemisphere, int degree_digits, double& out) noexcept {
  if (value.empty() && hemisphere.empty()) {
    out = kNaN;
    return true;
  }
  if (value.size() < static_cast<std::size_t>(degree_digits) + 2 || hemisphere.size() != 1) return false;
  int deg = 0;
  double minutes = 0;
  const auto dd = static_cast<std::size_t>(degree_digits);
  if (!integer(value.substr(0, dd), deg, 0) || !number(value.substr(dd), minutes)) return false;
  if (minutes < 0 || minutes >= 60) return false;
  out = deg + minutes / 60.0;
  const char h = hemisphere[0];
  const double limit = degree_digits == 2 ? 90.0 : 180.0;
  if (out > limit) return false;
  if (h == 'S' || h == 'W') out = -out;
  else if (!((degree_digits == 2 && h == 'N') || (degree_digits == 3 && h == 'E'))) return false;
  return true;
}

bool date(std::string_view s, int& day, int& month, int& year) noexcept {
  if (s.empty()) {
    day = month = year = 0;
    return true;
  }
  if (s.size() != 6) return false;
  int yy = 0;
  if (!integer(s.substr(0, 2), day, 0) || !integer(s.substr(2, 2), month, 0) || !integer(s.substr(4, 2), yy, 0)) {
    return false;
  }
  if (day < 1 || day > 31 || month < 1 || month > 12) return false;
  year = yy >= 80 ? 1900 + yy : 2000 + yy;
  return true;
}

char flag(std::string_view s) noexcept { return s.size() == 1 ? s[0] : 0; }

}  // namespace

const char* nmea_error_name(NmeaError e) noexcept {
  switch (e) {
    case NmeaError::none: return "none";
    case NmeaError::empty: return "empty";
    case NmeaError::no_start: return "no_start";
    case NmeaError::too_long: return "too_long";
    case NmeaError::missing_checksum: return "missing_checksum";
    case NmeaError::bad_checksum: return "bad_checksum";
    case NmeaError::bad_address: return "bad_address";
    case NmeaError::too_few_fields: return "too_few_fields";
    case NmeaError::bad_field: return "bad_field";
    case NmeaError::bad_coordinate: return "bad_coordinate";
    case NmeaError::unsupported: return "unsupported";
  }
  return "?";
}

const char* nmea_error_explanation(NmeaError e) noexcept {
  switch (e) {
    case NmeaError::none: return "accepted";
    case NmeaError::empty: return "an empty line";
    case NmeaError::no_start: return "does not start with '$' or '!'";
    case NmeaError::too_long: return "longer than the sentence limit";
    case NmeaError::missing_checksum: return "no *hh checksum";
    case NmeaError::bad_checksum: return "checksum does not match (corrupted in transit)";
    case NmeaError::bad_address: return "not a talker + sentence address";
    case NmeaError::too_few_fields: return "fields missing";
    case NmeaError::bad_field: return "a field does not parse or is out of range";
    case NmeaError::bad_coordinate: return "latitude or longitude out of range (bogus position)";
    case NmeaError::unsupported: return "a sentence type not decoded (GSV, proprietary, ...)";
  }
  return "?";
}

const char* sentence_type_name(SentenceType t) noexcept {
  switch (t) {
    case SentenceType::gga: return "GGA";
    case SentenceType::rmc: return "RMC";
    case SentenceType::gll: return "GLL";
    case SentenceType::gns: return "GNS";
    case SentenceType::gst: return "GST";
    case SentenceType::vtg: return "VTG";
    case SentenceType::gsa: return "GSA";
    case SentenceType::zda: return "ZDA";
    case SentenceType::hdt: return "HDT";
    case SentenceType::other: return "other";
  }
  return "?";
}

std::uint8_t nmea_checksum(std::string_view body) noexcept {
  std::uint8_t x = 0;
  for (char c : body) x = static_cast<std::uint8_t>(x ^ static_cast<std::uint8_t>(c));
  return x;
}

NmeaError parse_nmea(std::string_view line, NmeaSentence& out) noexcept {
  while (!line.empty() && (line.back() == '\r' || line.back() == '\n' || line.back() == ' ' || line.back() == '\t')) {
    line.remove_suffix(1);
  }
  while (!line.empty() && (line.front() == ' ' || line.front() == '\t' || line.front() == '\r' || line.front() == '\n')) {
    line.remove_prefix(1);
  }
  if (line.empty()) return NmeaError::empty;
  if (line.size() > kMaxSentenceLength) return NmeaError::too_long;
  if (line[0] != '$' && line[0] != '!') return NmeaError::no_start;
  const std::size_t star = line.rfind('*');
  if (star == std::string_view::npos || star + 3 != line.size()) return NmeaError::missing_checksum;
  const int h1 = hex(line[star + 1]), h2 = hex(line[star + 2]);
  if (h1 < 0 || h2 < 0) return NmeaError::missing_checksum;
  const std::string_view body = line.substr(1, star - 1);
  if (nmea_checksum(body) != static_cast<std::uint8_t>(h1 * 16 + h2)) return NmeaError::bad_checksum;

  Fields f;
  std::size_t pos = 0;
  while (true) {
    if (f.n >= kMaxFields) return NmeaError::too_long;
    const std::size_t comma = body.find(',', pos);
    f.f[static_cast<std::size_t>(f.n++)] = body.substr(pos, comma == std::string_view::npos ? std::string_view::npos : comma - pos);
    if (comma == std::string_view::npos) break;
    pos = comma + 1;
  }
  const std::string_view address = f[0];
  for (char c : address) {
    if (!((c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9'))) return NmeaError::bad_address;
  }
  out = NmeaSentence{};
  std::string_view formatter;
  if (!address.empty() && address[0] == 'P') {
    out.talker = {'P', 0, 0};
    formatter = address.substr(1);
  } else {
    if (address.size() != 5) return NmeaError::bad_address;
    out.talker = {address[0], address[1], 0};
    formatter = address.substr(2);
  }
  if (formatter.empty() || formatter.size() >= out.address.size()) return NmeaError::bad_address;
  for (std::size_t i = 0; i < formatter.size(); ++i) out.address[i] = formatter[i];

  bool ok = true;
  // Coordinates are checked apart, so a bogus position is named as such.
  auto position = [&](int lat_field, double& lat, double& lon) noexcept {
    return coordinate(f[lat_field], f[lat_field + 1], 2, lat) && coordinate(f[lat_field + 2], f[lat_field + 3], 3, lon);
  };
  if (formatter == "GGA") {
    if (f.n < 15) return NmeaError::too_few_fields;
    out.type = SentenceType::gga;
    Gga& g = out.gga;
    if (!position(2, g.lat, g.lon)) return NmeaError::bad_coordinate;
    ok = time_of_day(f[1], g.time) && integer(f[6], g.quality, 0) && integer(f[7], g.satellites, -1) && number(f[8], g.hdop) &&
         number(f[9], g.altitude) && number(f[11], g.separation) && number(f[13], g.dgps_age);
    ok = ok && g.quality >= 0 && g.quality <= 9;
  } else if (formatter == "RMC") {
    if (f.n < 12) return NmeaError::too_few_fields;
    out.type = SentenceType::rmc;
    Rmc& r = out.rmc;
    const char status = flag(f[2]);
    if (!position(3, r.lat, r.lon)) return NmeaError::bad_coordinate;
    ok = (status == 'A' || status == 'V') && time_of_day(f[1], r.time) && number(f[7], r.speed_knots) && number(f[8], r.course) &&
         date(f[9], r.day, r.month, r.year) && number(f[10], r.magnetic_variation);
    r.valid = status == 'A';
    if (ok && !std::isnan(r.magnetic_variation) && flag(f[11]) == 'W') r.magnetic_variation = -r.magnetic_variation;
    r.mode = f.n > 12 ? flag(f[12]) : 0;
  } else if (formatter == "GLL") {
    if (f.n < 7) return NmeaError::too_few_fields;
    out.type = SentenceType::gll;
    Gll& g = out.gll;
    if (!position(1, g.lat, g.lon)) return NmeaError::bad_coordinate;
    const char status = flag(f[6]);
    ok = (status == 'A' || status == 'V') && time_of_day(f[5], g.time);
    g.valid = status == 'A';
    g.mode = f.n > 7 ? flag(f[7]) : 0;
  } else if (formatter == "GNS") {
    if (f.n < 13) return NmeaError::too_few_fields;
    out.type = SentenceType::gns;
    Gns& g = out.gns;
    if (!position(2, g.lat, g.lon)) return NmeaError::bad_coordinate;
    const std::string_view modes = f[6];
    ok = modes.size() <= g.modes.size() && time_of_day(f[1], g.time) && integer(f[7], g.satellites, -1) &&
         number(f[8], g.hdop) && number(f[9], g.altitude) && number(f[10], g.separation);
    for (std::size_t i = 0; ok && i < modes.size(); ++i) g.modes[i] = modes[i];
  } else if (formatter == "GST") {
    if (f.n < 9) return NmeaError::too_few_fields;
    out.type = SentenceType::gst;
    Gst& g = out.gst;
    ok = time_of_day(f[1], g.time) && number(f[2], g.rms) && number(f[3], g.sigma_major) &&
         number(f[4], g.sigma_minor) && number(f[5], g.orientation) && number(f[6], g.sigma_lat) &&
         number(f[7], g.sigma_lon) && number(f[8], g.sigma_alt);
  } else if (formatter == "VTG") {
    if (f.n < 9) return NmeaError::too_few_fields;
    out.type = SentenceType::vtg;
    Vtg& v = out.vtg;
    // NMEA 2.x: course,T,course,M,knots,N,kmh,K[,mode]; older receivers omit the unit letters.
    if (flag(f[2]) == 'T' || f[2].empty()) {
      ok = number(f[1], v.course_true) && number(f[3], v.course_magnetic) && number(f[5], v.speed_knots) &&
           number(f[7], v.speed_kmh);
      v.mode = f.n > 9 ? flag(f[9]) : 0;
    } else {
      ok = number(f[1], v.course_true) && number(f[2], v.course_magnetic) && number(f[3], v.speed_knots) &&
           number(f[4], v.speed_kmh);
    }
  } else if (formatter == "GSA") {
    if (f.n < 18) return NmeaError::too_few_fields;
    out.type = SentenceType::gsa;
    Gsa& g = out.gsa;
    g.selection = flag(f[1]);
    ok = integer(f[2], g.fix, 0) && g.fix >= 0 && g.fix <= 3;
    for (int i = 0; i < 12 && ok; ++i) ok = integer(f[3 + i], g.satellites[static_cast<std::size_t>(i)], 0);
    ok = ok && number(f[15], g.pdop) && number(f[16], g.hdop) && number(f[17], g.vdop);
  } else if (formatter == "ZDA") {
    if (f.n < 7) return NmeaError::too_few_fields;
    out.type = SentenceType::zda;
    Zda& z = out.zda;
    ok = time_of_day(f[1], z.time) && integer(f[2], z.day, 0) && integer(f[3], z.month, 0) && integer(f[4], z.year, 0) &&
         integer(f[5], z.zone_hours, 0) && integer(f[6], z.zone_minutes, 0);
    ok = ok && z.day >= 0 && z.day <= 31 && z.month >= 0 && z.month <= 12 && (z.year == 0 || (z.year >= 1980 && z.year <= 2099));
  } else if (formatter == "HDT") {
    if (f.n < 2) return NmeaError::too_few_fields;
    out.type = SentenceType::hdt;
    ok = number(f[1], out.hdt.heading);
  } else {
    out.type = SentenceType::other;
    return NmeaError::unsupported;
  }
  return ok ? NmeaError::none : NmeaError::bad_field;
}

}  // namespace trailnav::gps
