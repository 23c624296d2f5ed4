#include "trailnav/drivers/gps/fix.hpp"

#include <cmath>
#include <cstdarg>
#include <cstdio>

namespace trailnav::gps {

FixStatus status_from_gga_quality(int quality) noexcept {
  switch (quality) {
    case 1: return FixStatus::gps;
    case 2: return FixStatus::dgps;
    case 3: return FixStatus::gps;  // PPS fix
    case 4: return FixStatus::rtk_fixed;
    case 5: return FixStatus::rtk_float;
    case 6: return FixStatus::dead_reckoning;
    case 7: return FixStatus::time_only;  // manual input
    case 8: return FixStatus::simulated;
    default: return FixStatus::unknown;
  }
}

std::uint64_t GpsCounters::rejected_total() const noexcept {
  std::uint64_t n = 0;
  for (std::uint64_t r : rejected) n += r;
  return n;
}

std::int64_t days_from_civil(int year, int month, int day) noexcept {
  // Howard Hinnant's algorithm, restated.
  const int y = year - (month <= 2 ? 1 : 0);
  const int era = (y >= 0 ? y : y - 399) / 400;
  const int yoe = y - era * 400;
  const int mp = (month + 9) % 12;
  const int doy = (153 * mp + 2) / 5 + day - 1;
  const int doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return static_cast<std::int64_t>(era) * 146097 + doe - 719468;
}

namespace {

bool finite(double v) noexcept { return std::isfinite(v); }

// Whole milliseconds of a time of day: sentences of one epoch agree on it.
long long epoch_key(double t) noexcept { return std::llround(t * 1000.0); }

void civil_next_day(int& year, int& month, int& day) noexcept {
  static constexpr int kDays[] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  const bool leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
  const int last = month == 2 && leap ? 29 : kDays[month - 1];
  if (++day > last) {
    day = 1;
    if (++month > 12) {
      month = 1;
      ++year;
    }
  }
}

double sentence_time(const NmeaSentence& s) noexcept {
  switch (s.type) {
    case SentenceType::gga: return s.gga.time;
    case SentenceType::rmc: return s.rmc.time;
    case SentenceType::gll: return s.gll.time;
    case SentenceType::gns: return s.gns.time;
    case SentenceType::gst: return s.gst.time;
    case SentenceType::zda: return s.zda.time;
    default: return GpsFix::kNaN;
  }
}

}  // namespace

bool FixAssembler::add_line(std::string_view line, GpsFix& completed) noexcept {
  ++counters_.lines;
  last_error_ = parse_nmea(line, sentence_);
  if (last_error_ == NmeaError::unsupported) {
    ++counters_.unsupported;
    return false;
  }
  if (last_error_ != NmeaError::none) {
    ++counters_.rejected[static_cast<std::size_t>(last_error_)];
    return false;
  }
  return add(sentence_, completed);
}

bool FixAssembler::add(const NmeaSentence& s, GpsFix& completed) noexcept {
  if (s.type == SentenceType::other) return false;
  ++counters_.accepted;
  const double t = sentence_time(s);
  bool closed = false;
  if (finite(t)) {
    // A sentence of the epoch just closed: the receiver (or the link) paused
    // inside the epoch's burst longer than the epoch gap, and the epoch was
    // published without it. Merging it into a new epoch would publish the same
    // time twice, so it is dropped and counted; so are sentences without a
    // time that came after the close and before it.
    if (epoch_key(t) == closed_key_ && (!epoch_.open || !finite(epoch_.time))) {
      counters_.late += 1 + (epoch_.open ? static_cast<std::uint64_t>(epoch_.fix.sentences) : 0u);
      epoch_.open = false;
      return false;
    }
    if (epoch_.open && finite(epoch_.time) && epoch_key(epoch_.time) != epoch_key(t)) closed = close(completed);
    if (!epoch_.open) start(t);
    if (!finite(epoch_.time)) {
      epoch_.time = t;
      epoch_.fix.time_of_day = t;
    }
  } else if (!epoch_.open) {
    start(GpsFix::kNaN);
  }
  merge(s);
  return closed;
}

void FixAssembler::start(double time) noexcept {
  epoch_ = Epoch{};
  epoch_.open = true;
  epoch_.time = time;
  epoch_.fix.time_of_day = time;
}

void FixAssembler::merge(const NmeaSentence& s) noexcept {
  Epoch& e = epoch_;
  GpsFix& f = e.fix;
  ++f.sentences;
  auto set = [](double& dst, double v) {
    if (std::isfinite(v)) dst = v;
  };
  switch (s.type) {
    case SentenceType::gga:
      e.gga_quality = s.gga.quality;
      e.gga_lat = s.gga.lat;
      e.gga_lon = s.gga.lon;
      if (s.gga.quality > 0) {
        set(f.alt_msl, s.gga.altitude);
        set(f.geoid_sep, s.gga.separation);
        set(f.hdop, s.gga.hdop);
      }
      if (s.gga.satellites >= 0) f.satellites_used = s.gga.satellites;
      break;
    case SentenceType::rmc:
      e.rmc_valid = s.rmc.valid ? 1 : 0;
      e.rmc_lat = s.rmc.lat;
      e.rmc_lon = s.rmc.lon;
      if (s.rmc.year > 0) {
        e.date_seen = true;
        e.day = s.rmc.day;
        e.month = s.rmc.month;
        e.year = s.rmc.year;
      }
      if (s.rmc.valid) {
        set(f.speed, s.rmc.speed_knots * kKnot);
        set(f.track, s.rmc.course);
      }
      set(f.magvar, s.rmc.magnetic_variation);
      break;
    case SentenceType::gll:
      e.gll_valid = s.gll.valid ? 1 : 0;
      if (s.gll.valid && !finite(e.other_lat)) {
        e.other_lat = s.gll.lat;
        e.other_lon = s.gll.lon;
      }
      break;
    case SentenceType::gns:
      e.gns_fix = s.gns.any_fix() ? 1 : 0;
      if (s.gns.any_fix()) {
        e.other_lat = s.gns.lat;
        e.other_lon = s.gns.lon;
        if (!finite(f.alt_msl)) set(f.alt_msl, s.gns.altitude);
        if (!finite(f.geoid_sep)) set(f.geoid_sep, s.gns.separation);
      }
      break;
    case SentenceType::gst:
      set(f.sigma_lat, s.gst.sigma_lat);
      set(f.sigma_lon, s.gst.sigma_lon);
      set(f.sigma_alt, s.gst.sigma_alt);
      break;
    case SentenceType::vtg:
      if (!finite(f.speed)) set(f.speed, s.vtg.speed_knots * kKnot);
      if (!finite(f.speed)) set(f.speed, s.vtg.speed_kmh / 3.6);
      if (!finite(f.track)) set(f.track, s.vtg.course_true);
      break;
    case SentenceType::gsa:
      // Several GSAs per epoch (one per constellation) agree on the fix.
      if (s.gsa.fix > e.gsa_fix) e.gsa_fix = s.gsa.fix;
      set(f.pdop, s.gsa.pdop);
      set(f.vdop, s.gsa.vdop);
      if (!finite(f.hdop)) set(f.hdop, s.gsa.hdop);
      break;
    case SentenceType::zda:
      if (s.zda.year > 0 && s.zda.month > 0 && s.zda.day > 0) {
        e.date_seen = true;
        e.day = s.zda.day;
        e.month = s.zda.month;
        e.year = s.zda.year;
      }
      break;
    case SentenceType::hdt: set(f.heading, s.hdt.heading); break;
    case SentenceType::other: break;
  }
}

bool FixAssembler::close(GpsFix& completed) noexcept {
  if (!epoch_.open) return false;
  Epoch& e = epoch_;
  GpsFix& f = e.fix;
  // The date: this epoch's own, else the last one, rolled over at midnight.
  if (e.date_seen) {
    have_date_ = true;
    year_ = e.year;
    month_ = e.month;
    day_ = e.day;
  } else if (have_date_ && finite(f.time_of_day) && finite(last_time_) && f.time_of_day < last_time_ - 43200.0) {
    civil_next_day(year_, month_, day_);
    ++counters_.date_rollovers;
  }
  if (finite(f.time_of_day)) last_time_ = f.time_of_day;
  if (finite(f.time_of_day)) {
    if (have_date_) {
      f.has_date = true;
      const double seconds = static_cast<double>(days_from_civil(year_, month_, day_)) * 86400.0 + f.time_of_day;
      f.utc_ns = std::llround(seconds * 1e6) * 1000;
    } else {
      ++counters_.stale_date;
    }
  }
  // The fix: a position from a sentence that says it is valid.
  // A simulator's fix (quality 8) is not a position of this robot, and a
  // fix from zero satellites is none.
  const bool simulated = e.gga_quality == 8;
  if (simulated) ++counters_.simulated;
  const bool gga_ok = e.gga_quality > 0 && !simulated && f.satellites_used != 0 && finite(e.gga_lat) && finite(e.gga_lon);
  const bool rmc_ok = e.rmc_valid == 1 && finite(e.rmc_lat) && finite(e.rmc_lon);
  const bool other_ok = finite(e.other_lat) && finite(e.other_lon);
  const bool said_no_fix = e.gga_quality == 0 || e.rmc_valid == 0 || e.gll_valid == 0 || e.gns_fix == 0 || e.gsa_fix == 1;
  if (!simulated && (gga_ok || rmc_ok || other_ok)) {
    f.lat = gga_ok ? e.gga_lat : rmc_ok ? e.rmc_lat : e.other_lat;
    f.lon = gga_ok ? e.gga_lon : rmc_ok ? e.rmc_lon : e.other_lon;
    if (e.gsa_fix == 2 || e.gsa_fix == 3) {
      f.mode = e.gsa_fix;
    } else {
      f.mode = finite(f.alt_msl) ? 3 : 2;
    }
    if (f.mode == 2) {
      f.alt_msl = GpsFix::kNaN;
      f.geoid_sep = GpsFix::kNaN;
    }
    f.status = e.gga_quality > 0 ? status_from_gga_quality(e.gga_quality) : FixStatus::gps;
    ++counters_.with_position;
  } else {
    f.mode = said_no_fix || simulated ? 1 : 0;
    f.lat = f.lon = f.alt_msl = f.geoid_sep = f.speed = f.track = GpsFix::kNaN;
    f.status = simulated ? FixStatus::simulated : FixStatus::unknown;
  }
  f.receiver_fix = e.gsa_fix;
  if (finite(f.time_of_day)) closed_key_ = epoch_key(f.time_of_day);
  completed = f;
  e.open = false;
  ++counters_.fixes;
  return true;
}

bool FixAssembler::flush(GpsFix& completed) noexcept { return close(completed); }

namespace {

struct Out {
  std::span<char> buffer;
  std::size_t n = 0;
  bool ok = true;
};

[[gnu::format(printf, 2, 3)]] void append(Out& o, const char* fmt, ...) noexcept {
  if (!o.ok) return;
  std::va_list ap;
  va_start(ap, fmt);
  const int w = std::vsnprintf(o.buffer.data() + o.n, o.buffer.size() - o.n, fmt, ap);
  va_end(ap);
  if (w < 0 || static_cast<std::size_t>(w) >= o.buffer.size() - o.n) {
    o.ok = false;
    return;
  }
  o.n += static_cast<std::size_t>(w);
}

}  // namespace

std::size_t write_tpv_json(const GpsFix& f, std::span<char> out) noexcept {
  Out o{out};
#define put(...) append(o, __VA_ARGS__)
  put("{\"class\":\"TPV\",\"mode\":%d", f.mode);
  if (f.status != FixStatus::unknown) put(",\"status\":%d", static_cast<int>(f.status));
  if (f.has_date) {
    const std::int64_t ms = f.utc_ns / 1'000'000;
    std::int64_t days = ms / 86'400'000;
    std::int64_t rem = ms % 86'400'000;
    if (rem < 0) {
      rem += 86'400'000;
      --days;
    }
    // Civil date from days since 1970 (inverse of days_from_civil).
    const std::int64_t z = days + 719468;
    const std::int64_t era = (z >= 0 ? z : z - 146096) / 146097;
    const std::int64_t doe = z - era * 146097;
    const std::int64_t yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
    const std::int64_t doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    const std::int64_t mp = (5 * doy + 2) / 153;
    const int d = static_cast<int>(doy - (153 * mp + 2) / 5 + 1);
    const int m = static_cast<int>(mp < 10 ? mp + 3 : mp - 9);
    const int y = static_cast<int>(yoe + era * 400 + (m <= 2 ? 1 : 0));
    put(",\"time\":\"%04d-%02d-%02dT%02d:%02d:%02d.%03dZ\"", y, m, d, static_cast<int>(rem / 3'600'000),
        static_cast<int>(rem / 60'000 % 60), static_cast<int>(rem / 1000 % 60), static_cast<int>(rem % 1000));
  }
  if (std::isfinite(f.lat)) put(",\"lat\":%.9f,\"lon\":%.9f", f.lat, f.lon);
  if (std::isfinite(f.alt_msl)) {
    if (std::isfinite(f.geoid_sep)) put(",\"altHAE\":%.4f", f.alt_hae());
    put(",\"altMSL\":%.4f", f.alt_msl);
  }
  if (std::isfinite(f.track)) put(",\"track\":%.4f", f.track);
  if (std::isfinite(f.magvar)) put(",\"magvar\":%.1f", f.magvar);
  if (std::isfinite(f.speed)) put(",\"speed\":%.3f", f.speed);
  if (std::isfinite(f.geoid_sep) && std::isfinite(f.alt_msl)) put(",\"geoidSep\":%.3f", f.geoid_sep);
  if (std::isfinite(f.sigma_lon)) put(",\"epx\":%.3f", f.sigma_lon);
  if (std::isfinite(f.sigma_lat)) put(",\"epy\":%.3f", f.sigma_lat);
  if (std::isfinite(f.sigma_alt)) put(",\"epv\":%.3f", f.sigma_alt);
  if (std::isfinite(f.heading)) put(",\"heading\":%.4f", f.heading);
  put("}");
#undef put
  return o.ok ? o.n : 0;
}

}  // namespace trailnav::gps
