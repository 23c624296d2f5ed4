#include "sensors.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>

#include "trailnav/drivers/gps/nmea.hpp"

namespace trailnav::sim {
namespace {

// "$...": appends the checksum and CR LF.
std::string finish(const char* body) {
  char tail[8];
  std::snprintf(tail, sizeof tail, "*%02X\r\n", gps::nmea_checksum(body + 1));
  return std::string(body) + tail;
}

struct Utc {
  int hour, minute, day, month, year;
  double second;
};

Utc split(std::int64_t utc_ns) {
  const std::int64_t s = utc_ns / 1'000'000'000;
  const auto t = static_cast<std::time_t>(s);
  std::tm tm{};
  gmtime_r(&t, &tm);
  return {tm.tm_hour, tm.tm_min, tm.tm_mday, tm.tm_mon + 1, tm.tm_year + 1900,
          tm.tm_sec + static_cast<double>(utc_ns % 1'000'000'000) * 1e-9};
}

// "ddmm.mmmmm,N" (latitude, 2 degree digits) or "dddmm.mmmmm,E" (longitude, 3).
std::string coordinate(double value, int degree_digits, char positive, char negative) {
  const double a = std::abs(value);
  const int d = static_cast<int>(a);
  char buf[32];
  std::snprintf(buf, sizeof buf, "%0*d%08.5f,%c", degree_digits, d, (a - d) * 60.0, value >= 0 ? positive : negative);
  return buf;
}

std::string latitude(double lat) { return coordinate(lat, 2, 'N', 'S'); }
std::string longitude(double lon) { return coordinate(lon, 3, 'E', 'W'); }

std::string clock(const Utc& u) {
  char buf[48];
  // Centiseconds, as most receivers send.
  const int cs = static_cast<int>(std::lround(u.second * 100.0));
  std::snprintf(buf, sizeof buf, "%02d%02d%02d.%02d", u.hour, u.minute, cs / 100, cs % 100);
  return buf;
}

void put_be32(std::uint8_t* p, std::uint32_t v) {
  p[0] = static_cast<std::uint8_t>(v >> 24);
  p[1] = static_cast<std::uint8_t>(v >> 16);
  p[2] = static_cast<std::uint8_t>(v >> 8);
  p[3] = static_cast<std::uint8_t>(v);
}

void put_float(std::uint8_t* p, float f) {
  std::uint32_t v = 0;
  std::memcpy(&v, &f, 4);
  put_be32(p, v);
}

}  // namespace

std::string nmea_gga(const GnssFix& f, const char* talker) {
  const Utc u = split(f.utc_ns);
  char buf[160];
  std::snprintf(buf, sizeof buf, "$%sGGA,%s,%s,%s,%d,%02d,%.1f,%.2f,M,%.2f,M,,", talker, clock(u).c_str(),
                latitude(f.lat).c_str(), longitude(f.lon).c_str(), f.quality, f.satellites, f.hdop, f.altitude,
                f.separation);
  return finish(buf);
}

std::string nmea_rmc(const GnssFix& f, const char* talker) {
  const Utc u = split(f.utc_ns);
  char buf[160];
  std::snprintf(buf, sizeof buf, "$%sRMC,%s,A,%s,%s,%.3f,%.2f,%02d%02d%02d,,,%c", talker, clock(u).c_str(),
                latitude(f.lat).c_str(), longitude(f.lon).c_str(), f.speed / 0.514444, f.course, u.day, u.month,
                u.year % 100, f.quality == 2 ? 'D' : 'A');
  return finish(buf);
}

std::string nmea_gst(const GnssFix& f, const char* talker) {
  const Utc u = split(f.utc_ns);
  const double major = std::max(f.sigma_lat, f.sigma_lon);
  const double minor = std::min(f.sigma_lat, f.sigma_lon);
  const double orientation = f.sigma_lat >= f.sigma_lon ? 0.0 : 90.0;
  char buf[160];
  std::snprintf(buf, sizeof buf, "$%sGST,%s,%.2f,%.2f,%.2f,%.1f,%.2f,%.2f,%.2f", talker, clock(u).c_str(), f.rms, major,
                minor, orientation, f.sigma_lat, f.sigma_lon, f.sigma_alt);
  return finish(buf);
}

std::string nmea_vtg(const GnssFix& f, const char* talker) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "$%sVTG,%.2f,T,,M,%.3f,N,%.3f,K,%c", talker, f.course, f.speed / 0.514444,
                f.speed * 3.6, f.quality == 2 ? 'D' : 'A');
  return finish(buf);
}

std::array<std::uint8_t, velodyne::kPositionPacketSize> position_packet(std::uint32_t us_past_hour, std::uint8_t pps,
                                                                         const std::string& rmc) {
  std::array<std::uint8_t, velodyne::kPositionPacketSize> p{};
  p[198] = static_cast<std::uint8_t>(us_past_hour);
  p[199] = static_cast<std::uint8_t>(us_past_hour >> 8);
  p[200] = static_cast<std::uint8_t>(us_past_hour >> 16);
  p[201] = static_cast<std::uint8_t>(us_past_hour >> 24);
  p[202] = pps;
  const std::size_t n = std::min(rmc.size(), p.size() - 206);
  std::memcpy(p.data() + 206, rmc.data(), n);
  return p;
}

std::array<std::uint8_t, kXsensMtData2Size> xsens_mtdata2(const XsensSample& s) {
  std::array<std::uint8_t, kXsensMtData2Size> m{};
  m[0] = 0xFA;  // preamble
  m[1] = 0xFF;  // bus identifier: master
  m[2] = 0x36;  // MTData2
  m[3] = 68;    // payload length
  std::size_t o = 4;
  auto item = [&](std::uint16_t id, std::uint8_t size) {
    m[o++] = static_cast<std::uint8_t>(id >> 8);
    m[o++] = static_cast<std::uint8_t>(id);
    m[o++] = size;
  };
  item(0x1020, 2);  // PacketCounter
  m[o++] = static_cast<std::uint8_t>(s.counter >> 8);
  m[o++] = static_cast<std::uint8_t>(s.counter);
  item(0x1060, 4);  // SampleTimeFine
  put_be32(&m[o], s.sample_time_fine);
  o += 4;
  item(0x2010, 16);  // Quaternion, float32, ENU
  for (float q : s.quaternion) {
    put_float(&m[o], q);
    o += 4;
  }
  item(0x4020, 12);  // Acceleration
  for (float a : s.acceleration) {
    put_float(&m[o], a);
    o += 4;
  }
  item(0x8020, 12);  // RateOfTurn
  for (float w : s.rate_of_turn) {
    put_float(&m[o], w);
    o += 4;
  }
  item(0xE020, 4);  // StatusWord
  put_be32(&m[o], s.status);
  o += 4;
  // Checksum: all bytes after the preamble sum to zero.
  std::uint8_t sum = 0;
  for (std::size_t i = 1; i < o; ++i) sum = static_cast<std::uint8_t>(sum + m[i]);
  m[o] = static_cast<std::uint8_t>(0x100 - sum);
  return m;
}

}  // namespace trailnav::sim
