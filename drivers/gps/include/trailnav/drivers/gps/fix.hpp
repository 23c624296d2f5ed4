// From NMEA sentences to fixes: a byte-stream framer (serial, TCP) and an
// assembler that merges the sentences of one measurement epoch (same UTC
// time of day) into one fix, the way gpsd reports them: mode, status,
// position, altitude, speed, track and, with GST, error estimates. Pure: no
// I/O and no allocation, so the driver thread can run them after arm.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>

#include "trailnav/drivers/gps/nmea.hpp"

namespace trailnav::gps {

inline constexpr double kKnot = 1852.0 / 3600.0;  // m/s

// gpsd's TPV `status` values.
enum class FixStatus : std::uint8_t {
  unknown = 0, gps = 1, dgps = 2, rtk_fixed = 3, rtk_float = 4, dead_reckoning = 5, gnss_dr = 6, time_only = 7,
  simulated = 8,
};
FixStatus status_from_gga_quality(int quality) noexcept;

struct GpsFix {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double time_of_day = kNaN;   // s of the UTC day; NaN when no sentence of the epoch carried a time
  bool has_date = false;       // a date is known (RMC, ZDA, or carried over with roll-over)
  std::int64_t utc_ns = 0;     // ns since 1970 when has_date
  int mode = 0;                // gpsd: 0 unknown, 1 no fix, 2 2D, 3 3D
  int receiver_fix = 0;        // what GSA said: 1 none, 2 2D, 3 3D; 0 without GSA. It decides 2D / 3D.
  FixStatus status = FixStatus::unknown;
  double lat = kNaN, lon = kNaN;  // degrees (WGS84)
  double alt_msl = kNaN;          // m above mean sea level
  double geoid_sep = kNaN;        // m, geoid above the ellipsoid
  double speed = kNaN;            // m/s over ground
  double track = kNaN;            // degrees true
  double magvar = kNaN;           // degrees, east positive
  double heading = kNaN;          // degrees true (HDT)
  double hdop = kNaN, pdop = kNaN, vdop = kNaN;
  int satellites_used = -1;
  double sigma_lat = kNaN, sigma_lon = kNaN, sigma_alt = kNaN;  // m, 1 sigma (GST)
  std::uint32_t sentences = 0;  // merged into this fix
  bool has_fix() const noexcept { return mode >= 2; }
  double alt_hae() const noexcept { return alt_msl + geoid_sep; }
};

// Splits a byte stream into sentences: from '$' or '!' to the end of line.
// A line longer than kMaxSentenceLength is dropped whole and counted.
class LineFramer {
 public:
  // Calls `on_line(std::string_view)` for every complete line (without CR LF).
  template <typename F>
  void feed(std::span<const std::uint8_t> bytes, F&& on_line) {
    for (std::uint8_t b : bytes) {
      const char c = static_cast<char>(b);
      if (c == '\n' || c == '\r') {
        if (length_ > 0 && !overflow_) on_line(std::string_view(buffer_.data(), length_));
        length_ = 0;
        overflow_ = false;
        continue;
      }
      if (c == '$' || c == '!') {
        if (length_ > 0 && !overflow_) ++unterminated_;  // a new sentence before the last ended
        length_ = 0;
        overflow_ = false;
      }
      if (overflow_) continue;
      if (length_ == buffer_.size()) {
        overflow_ = true;
        ++overlong_;
        continue;
      }
      buffer_[length_++] = c;
    }
  }
  std::uint64_t overlong() const noexcept { return overlong_; }
  std::uint64_t unterminated() const noexcept { return unterminated_; }

 private:
  std::array<char, kMaxSentenceLength> buffer_{};
  std::size_t length_ = 0;
  bool overflow_ = false;
  std::uint64_t overlong_ = 0;
  std::uint64_t unterminated_ = 0;
};

struct GpsCounters {
  std::uint64_t lines = 0;
  std::uint64_t accepted = 0;  // valid sentences of the kinds we decode (the late ones too)
  std::uint64_t fixes = 0;     // epochs completed
  std::uint64_t with_position = 0;
  std::array<std::uint64_t, kNmeaErrors> rejected{};  // by NmeaError
  std::uint64_t unsupported = 0;             // valid sentences we do not decode (GSV, proprietary, ...)
  std::uint64_t stale_date = 0;              // epochs before any date was known
  std::uint64_t date_rollovers = 0;
  std::uint64_t simulated = 0;               // epochs of a receiver in simulator mode (GGA quality 8): no fix
  std::uint64_t late = 0;                    // sentences of an epoch already closed (a pause inside its burst): dropped
  std::uint64_t rejected_total() const noexcept;
};

class FixAssembler {
 public:
  // Feeds one line. Returns true when this line closed the previous epoch:
  // `completed` then holds it. The line's sentence starts the next epoch.
  bool add_line(std::string_view line, GpsFix& completed) noexcept;
  // Feeds a parsed sentence (already counted by the caller).
  bool add(const NmeaSentence& s, GpsFix& completed) noexcept;
  // Ends the input: true when an epoch was open.
  bool flush(GpsFix& completed) noexcept;

  const GpsCounters& counters() const noexcept { return counters_; }
  const NmeaSentence& last_sentence() const noexcept { return sentence_; }
  NmeaError last_error() const noexcept { return last_error_; }

 private:
  struct Epoch {
    bool open = false;
    double time = GpsFix::kNaN;
    GpsFix fix;
    // What the sentences said about the fix.
    int gga_quality = -1;    // -1: no GGA
    int rmc_valid = -1;      // -1: no RMC, 0 V, 1 A
    int gll_valid = -1;
    int gns_fix = -1;
    int gsa_fix = 0;         // 0: no GSA
    bool date_seen = false;
    int day = 0, month = 0, year = 0;
    double gga_lat = GpsFix::kNaN, gga_lon = GpsFix::kNaN;
    double rmc_lat = GpsFix::kNaN, rmc_lon = GpsFix::kNaN;
    double other_lat = GpsFix::kNaN, other_lon = GpsFix::kNaN;
  };
  bool close(GpsFix& completed) noexcept;
  void start(double time) noexcept;
  // The epoch key of the last closed epoch with a time (INT64_MIN: none).
  long long closed_key_ = std::numeric_limits<long long>::min();
  void merge(const NmeaSentence& s) noexcept;

  NmeaSentence sentence_{};
  NmeaError last_error_ = NmeaError::none;
  Epoch epoch_{};
  // The last date and time of day, for sentences without a date.
  bool have_date_ = false;
  int day_ = 0, month_ = 0, year_ = 0;
  double last_time_ = GpsFix::kNaN;
  GpsCounters counters_{};
};

// Days since 1970-01-01 of a civil date (proleptic Gregorian).
std::int64_t days_from_civil(int year, int month, int day) noexcept;

// One gpsd-style TPV object on one line (no newline), into `out`; returns its
// length (0 when it does not fit). Fields that are unknown are left out.
std::size_t write_tpv_json(const GpsFix& fix, std::span<char> out) noexcept;

}  // namespace trailnav::gps
