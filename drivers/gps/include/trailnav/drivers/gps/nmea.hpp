// NMEA 0183 sentences from GNSS receivers: framing ($ or !, *hh checksum,
// length limit), any two-letter talker (GP, GN, GL, GA, GB, BD, ...), and the
// sentences a navigation stack needs: GGA, RMC, GLL, GNS, GST, VTG, GSA, ZDA, HDT.
// A pure parser: no allocation, no I/O. Empty fields are NaN (numbers) or
// absent (flags), never a made-up default.
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

namespace trailnav::gps {

// NMEA 0183 allows 82 characters including $ and CR LF; receivers exceed it
// with high-precision fields, so up to this many are accepted.
inline constexpr std::size_t kMaxSentenceLength = 160;
inline constexpr int kMaxFields = 40;

enum class NmeaError : std::uint8_t {
  none,
  empty,             // nothing but whitespace
  no_start,          // does not start with '$' or '!'
  too_long,          // longer than kMaxSentenceLength
  missing_checksum,  // no "*hh" at the end
  bad_checksum,      // "*hh" does not match
  bad_address,       // not a talker + sentence address like "GPGGA"
  too_few_fields,    // a field the sentence must have is missing
  bad_field,         // a field that does not parse (text in a number, ...)
  bad_coordinate,    // latitude or longitude out of range (minutes >= 60, beyond 90 / 180 degrees, bad hemisphere)
  unsupported,       // a valid sentence of a type we do not decode
};
inline constexpr std::size_t kNmeaErrors = static_cast<std::size_t>(NmeaError::unsupported) + 1;
const char* nmea_error_name(NmeaError e) noexcept;
// What a rejection means, for diagnostics ("checksum does not match ...").
const char* nmea_error_explanation(NmeaError e) noexcept;

enum class SentenceType : std::uint8_t { gga, rmc, gll, gns, gst, vtg, gsa, zda, hdt, other };
const char* sentence_type_name(SentenceType t) noexcept;

struct Gga {
  double time = 0.0;        // s of the UTC day, NaN when empty
  double lat = 0.0;         // degrees, north positive; NaN when empty
  double lon = 0.0;         // degrees, east positive
  int quality = 0;          // 0 invalid, 1 GPS, 2 DGPS, 4 RTK fixed, 5 RTK float, 6 dead reckoning, 8 simulator
  int satellites = -1;      // -1 when empty
  double hdop = 0.0;        // NaN when empty
  double altitude = 0.0;    // m above mean sea level, NaN when empty
  double separation = 0.0;  // m, geoid above the WGS84 ellipsoid, NaN when empty
  double dgps_age = 0.0;    // s, NaN when empty
};

struct Rmc {
  double time = 0.0;
  bool valid = false;       // status A
  double lat = 0.0;
  double lon = 0.0;
  double speed_knots = 0.0; // NaN when empty
  double course = 0.0;      // degrees true, NaN when empty
  int day = 0, month = 0, year = 0;  // year with century (80..99 -> 19xx); 0 when empty
  double magnetic_variation = 0.0;   // degrees, east positive; NaN when empty
  char mode = 0;            // NMEA 2.3 mode: A autonomous, D differential, E estimated, N not valid, ...; 0 when absent
};

struct Gll {
  double lat = 0.0;   // NaN when empty
  double lon = 0.0;
  double time = 0.0;  // NaN when empty
  bool valid = false; // status A
  char mode = 0;      // NMEA 2.3 mode; 0 when absent
};

struct Gns {
  double time = 0.0;
  double lat = 0.0;
  double lon = 0.0;
  std::array<char, 5> modes{};  // one mode letter per constellation (N: no fix); empty when absent
  int satellites = -1;
  double hdop = 0.0;
  double altitude = 0.0;    // m above mean sea level, NaN when empty
  double separation = 0.0;  // NaN when empty
  bool any_fix() const noexcept {
    for (char c : modes) {
      if (c != 0 && c != 'N') return true;
    }
    return false;
  }
};

struct Gst {
  double time = 0.0;
  double rms = 0.0;           // m, range residual RMS; all NaN when empty
  double sigma_major = 0.0;   // m, error ellipse
  double sigma_minor = 0.0;
  double orientation = 0.0;   // degrees from true north
  double sigma_lat = 0.0;     // m
  double sigma_lon = 0.0;
  double sigma_alt = 0.0;
};

struct Vtg {
  double course_true = 0.0;      // degrees, NaN when empty
  double course_magnetic = 0.0;
  double speed_knots = 0.0;
  double speed_kmh = 0.0;
  char mode = 0;
};

struct Gsa {
  char selection = 0;  // M manual, A automatic
  int fix = 0;         // 1 none, 2 2D, 3 3D; 0 when empty
  std::array<int, 12> satellites{};  // PRNs, 0 where empty
  double pdop = 0.0, hdop = 0.0, vdop = 0.0;
};

struct Zda {
  double time = 0.0;
  int day = 0, month = 0, year = 0;
  int zone_hours = 0, zone_minutes = 0;
};

struct Hdt {
  double heading = 0.0;  // degrees true, NaN when empty
};

struct NmeaSentence {
  std::array<char, 3> talker{};  // "GP", "GN", ...; "P" for proprietary
  std::array<char, 8> address{}; // the sentence formatter, e.g. "GGA"
  SentenceType type = SentenceType::other;
  Gga gga;
  Rmc rmc;
  Gll gll;
  Gns gns;
  Gst gst;
  Vtg vtg;
  Gsa gsa;
  Zda zda;
  Hdt hdt;
};

// XOR of the characters between the start character and '*'.
std::uint8_t nmea_checksum(std::string_view body) noexcept;

// Parses one sentence; trailing CR/LF and surrounding whitespace are ignored.
NmeaError parse_nmea(std::string_view line, NmeaSentence& out) noexcept;

}  // namespace trailnav::gps
