#include "faults.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <numbers>

#include "trailnav/drivers/can/frame.hpp"
#include "trailnav/drivers/gps/nmea.hpp"

namespace trailnav::replay {
namespace {

using recording::StreamKind;

constexpr std::size_t kVelodyneDataPacket = 1206;
constexpr std::size_t kVelodyneDataTimestamp = 1200;
constexpr std::size_t kVelodynePositionPacket = 512;
constexpr std::size_t kVelodynePositionTimestamp = 198;
constexpr std::int64_t kMicrosPerHour = 3'600'000'000;

// SocketCAN's error classes (linux/can/error.h), as the driver reads them.
constexpr std::uint32_t kCanErrBusOff = 0x00000040U;
constexpr std::uint32_t kCanErrRestarted = 0x00000100U;

bool parse_number(std::string_view text, double& value) {
  if (text.empty()) return false;
  if (text.front() == '+') text.remove_prefix(1);
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  return ec == std::errc() && end == text.data() + text.size() && std::isfinite(value);
}

bool parse_count(std::string_view text, int& value) {
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  return ec == std::errc() && end == text.data() + text.size();
}

bool is_probabilistic(FaultKind k) {
  return k == FaultKind::loss || k == FaultKind::reorder || k == FaultKind::duplicate || k == FaultKind::truncate ||
         k == FaultKind::corrupt;
}

std::optional<FaultKind> fault_kind_from(std::string_view name) {
  for (int k = 0; k <= static_cast<int>(FaultKind::clock_step); ++k) {
    if (name == fault_kind_name(static_cast<FaultKind>(k))) return static_cast<FaultKind>(k);
  }
  return std::nullopt;
}

bool is_alnum(std::uint8_t c) { return (c >= '0' && c <= '9') || (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z'); }

std::uint8_t alnum_at(std::uint64_t i) {
  static constexpr char kAlnum[] = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz";
  return static_cast<std::uint8_t>(kAlnum[i % 62]);
}

std::uint64_t splitmix(std::uint64_t& state) noexcept {
  std::uint64_t z = (state += 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

std::uint32_t read_u32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 | static_cast<std::uint32_t>(p[2]) << 16 |
         static_cast<std::uint32_t>(p[3]) << 24;
}

void write_u32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// Metres of meridian arc per degree of latitude at `lat_deg` (the usual
// series for the WGS 84 ellipsoid; good to centimetres over 50 m).
double metres_per_degree_latitude(double lat_deg) {
  const double phi = lat_deg * std::numbers::pi / 180.0;
  return 111132.954 - 559.822 * std::cos(2.0 * phi) + 1.175 * std::cos(4.0 * phi);
}

std::vector<std::string_view> split_fields(std::string_view body) {
  std::vector<std::string_view> fields;
  std::size_t start = 0;
  for (std::size_t i = 0; i <= body.size(); ++i) {
    if (i == body.size() || body[i] == ',') {
      fields.push_back(body.substr(start, i - start));
      start = i + 1;
    }
  }
  return fields;
}

}  // namespace

const char* fault_kind_name(FaultKind kind) noexcept {
  switch (kind) {
    case FaultKind::loss: return "loss";
    case FaultKind::reorder: return "reorder";
    case FaultKind::duplicate: return "duplicate";
    case FaultKind::truncate: return "truncate";
    case FaultKind::corrupt: return "corrupt";
    case FaultKind::silence: return "silence";
    case FaultKind::outage: return "outage";
    case FaultKind::jump: return "jump";
    case FaultKind::bus_off: return "bus-off";
    case FaultKind::clock_step: return "clock-step";
  }
  return "?";
}

FaultSpecResult parse_fault_spec(std::string_view text) {
  FaultSpecResult r;
  const std::string quoted = "fault '" + std::string(text) + "': ";
  auto fail = [&](const std::string& why) {
    r.error = quoted + why;
    return r;
  };
  FaultSpec f;
  f.text = std::string(text);
  const std::size_t colon = text.find(':');
  if (colon == std::string_view::npos || colon == 0) return fail("expected STREAM:FAULT[=VALUE][,OPTION=VALUE]...[@FROM[+FOR]]");
  f.stream = std::string(text.substr(0, colon));
  std::string_view rest = text.substr(colon + 1);
  std::string_view window;
  if (const std::size_t at = rest.find('@'); at != std::string_view::npos) {
    window = rest.substr(at + 1);
    rest = rest.substr(0, at);
  }
  const std::vector<std::string_view> items = split_fields(rest);
  std::string_view name = items.front(), value;
  if (const std::size_t eq = name.find('='); eq != std::string_view::npos) {
    value = name.substr(eq + 1);
    name = name.substr(0, eq);
  }
  const auto kind = fault_kind_from(name);
  if (!kind) {
    return fail("unknown fault '" + std::string(name) +
                "' (loss, reorder, duplicate, truncate, corrupt, silence, outage, jump, bus-off, clock-step)");
  }
  f.kind = *kind;
  double v = 0.0;
  if (value.empty() || !parse_number(value, v)) return fail(std::string(name) + " needs a number (" + std::string(name) + "=...)");
  if (is_probabilistic(f.kind)) {
    if (!(v > 0.0 && v <= 1.0)) return fail(std::string(name) + " is a probability: more than 0, at most 1");
    f.probability = v;
  } else if (f.kind == FaultKind::jump) {
    if (v == 0.0 || std::abs(v) > 100'000.0) return fail("jump is metres north: not 0, at most 100 km either way");
    f.jump_m = v;
  } else if (f.kind == FaultKind::clock_step) {
    if (v == 0.0 || std::abs(v) >= 3600.0) return fail("clock-step is seconds: not 0, less than an hour either way");
    f.seconds = v;
  } else {
    if (!(v > 0.0 && v <= 1e6)) return fail(std::string(name) + " is seconds: more than 0, at most 1e6");
    f.seconds = v;
  }
  for (std::size_t i = 1; i < items.size(); ++i) {
    const std::string_view item = items[i];
    const std::size_t eq = item.find('=');
    if (eq == std::string_view::npos) return fail("option '" + std::string(item) + "' wants NAME=VALUE");
    const std::string_view key = item.substr(0, eq), val = item.substr(eq + 1);
    int n = 0;
    if (key == "burst" && f.kind == FaultKind::loss) {
      if (!parse_count(val, n) || n < 1 || n > 1'000'000) return fail("burst is a count of events, 1 to 1000000");
      f.burst = n;
    } else if (key == "depth" && f.kind == FaultKind::reorder) {
      if (!parse_count(val, n) || n < 1 || n > 64) return fail("depth is a count of events, 1 to 64");
      f.depth = n;
    } else if (key == "bytes" && f.kind == FaultKind::corrupt) {
      if (!parse_count(val, n) || n < 1 || n > 64) return fail("bytes is a count, 1 to 64");
      f.bytes = n;
    } else if (key == "jump" && f.kind == FaultKind::outage) {
      if (!parse_number(val, v) || v == 0.0 || std::abs(v) > 100'000.0) {
        return fail("jump is metres north: not 0, at most 100 km either way");
      }
      f.jump_m = v;
    } else {
      return fail("'" + std::string(key) + "' is not an option of " + std::string(name) +
                  " (loss: burst; reorder: depth; corrupt: bytes; outage: jump)");
    }
  }
  if (!window.empty()) {
    std::string_view from = window, length;
    if (const std::size_t plus = window.find('+'); plus != std::string_view::npos) {
      from = window.substr(0, plus);
      length = window.substr(plus + 1);
    }
    if (!parse_number(from, v) || v < 0.0) return fail("@FROM is seconds from the replay's start, 0 or more");
    f.from_s = v;
    if (!length.empty() || window.find('+') != std::string_view::npos) {
      if (!is_probabilistic(f.kind)) {
        return fail(std::string(name) + " takes no +FOR: its value is " +
                    (f.kind == FaultKind::jump || f.kind == FaultKind::clock_step ? "a change from FROM on" : "how long it lasts"));
      }
      if (!parse_number(length, v) || !(v > 0.0)) return fail("+FOR is seconds, more than 0");
      f.for_s = v;
    }
  }
  r.spec = std::move(f);
  return r;
}

bool shift_nmea_north(std::string& line, double metres) {
  if (line.size() < 10 || line[0] != '$') return false;
  const std::size_t star = line.rfind('*');
  if (star == std::string::npos || star + 3 > line.size()) return false;
  const std::string_view body(line.data() + 1, star - 1);
  const std::vector<std::string_view> fields = split_fields(body);
  if (fields[0].size() != 5) return false;
  const std::string_view type = fields[0].substr(2);
  std::size_t lat_field = 0;
  if (type == "GGA" || type == "GNS") {
    lat_field = 2;
  } else if (type == "RMC") {
    lat_field = 3;
  } else if (type == "GLL") {
    lat_field = 1;
  } else {
    return false;
  }
  if (fields.size() <= lat_field + 1) return false;
  const std::string_view lat = fields[lat_field], hemi = fields[lat_field + 1];
  if (lat.size() < 4 || (hemi != "N" && hemi != "S")) return false;
  const std::size_t dot = lat.find('.');
  if (dot != 4) return false;
  const int decimals = static_cast<int>(lat.size() - dot - 1);
  double deg = 0.0, minutes = 0.0;
  if (!parse_number(lat.substr(0, 2), deg) || !parse_number(lat.substr(2), minutes)) return false;
  double value = (deg + minutes / 60.0) * (hemi == "S" ? -1.0 : 1.0);
  value += metres / metres_per_degree_latitude(value);
  if (std::abs(value) >= 90.0) return false;
  const bool south = value < 0.0;
  const double a = std::abs(value);
  double whole = std::floor(a);
  const double scale = std::pow(10.0, decimals);
  double m = std::round((a - whole) * 60.0 * scale) / scale;
  if (m >= 60.0) {
    m -= 60.0;
    whole += 1.0;
  }
  char buffer[32];
  const int n = std::snprintf(buffer, sizeof buffer, "%02d%0*.*f", static_cast<int>(whole), decimals + 3, decimals, m);
  if (n != static_cast<int>(lat.size())) return false;
  const std::size_t lat_pos = static_cast<std::size_t>(lat.data() - line.data());
  const std::size_t hemi_pos = static_cast<std::size_t>(hemi.data() - line.data());
  line.replace(lat_pos, lat.size(), buffer, static_cast<std::size_t>(n));
  line[hemi_pos] = south ? 'S' : 'N';
  const std::uint8_t sum = gps::nmea_checksum(std::string_view(line).substr(1, star - 1));
  static constexpr char kHex[] = "0123456789ABCDEF";
  line[star + 1] = kHex[sum >> 4];
  line[star + 2] = kHex[sum & 0xF];
  return true;
}

FaultInjector::Created FaultInjector::create(const std::vector<FaultSpec>& specs,
                                             const std::vector<recording::StreamInfo>& streams, std::uint64_t seed) {
  Created r;
  std::unique_ptr<FaultInjector> inj(new FaultInjector());
  inj->specs_ = specs;
  inj->states_.resize(streams.size());
  inj->counters_.resize(streams.size());
  for (std::size_t i = 0; i < streams.size(); ++i) {
    inj->counters_[i].stream = streams[i].name;
    std::uint64_t s = seed ^ (0xA5A5A5A5ULL * (i + 1));
    inj->states_[i].rng = splitmix(s);
  }
  std::string names;
  for (const auto& s : streams) names += (names.empty() ? "" : ", ") + s.name;
  for (const FaultSpec& f : inj->specs_) {
    const auto it = std::find_if(streams.begin(), streams.end(), [&](const auto& s) { return s.name == f.stream; });
    if (it == streams.end()) {
      r.error = "fault '" + f.text + "': no stream '" + f.stream + "' in the recording (it has " + names + ")";
      return r;
    }
    const StreamKind k = it->kind;
    const char* kind = recording::stream_kind_name(k);
    const std::string head = "fault '" + f.text + "': stream '" + f.stream + "' is " + kind + ": ";
    if (f.kind == FaultKind::truncate && k != StreamKind::udp && k != StreamKind::serial) {
      r.error = head + "only datagrams and serial reads can be cut short";
      return r;
    }
    if (f.kind == FaultKind::corrupt && k == StreamKind::gpio) {
      r.error = head + "a GPIO level has no bytes to corrupt (loss, silence, duplicate or reorder it)";
      return r;
    }
    if ((f.kind == FaultKind::outage || f.kind == FaultKind::jump) && k != StreamKind::serial) {
      r.error = head + "outage and jump are for a GPS receiver's NMEA serial stream";
      return r;
    }
    if (f.kind == FaultKind::bus_off && k != StreamKind::can) {
      r.error = head + "bus-off is for a CAN stream";
      return r;
    }
    if (f.kind == FaultKind::clock_step && k != StreamKind::udp) {
      r.error = head + "clock-step is for a Velodyne's UDP streams";
      return r;
    }
    const std::size_t index = static_cast<std::size_t>(it - streams.begin());
    inj->states_[index].faults.push_back(&f);
    if (f.jump_m != 0.0) inj->states_[index].line_mode = true;
  }
  r.injector = std::move(inj);
  return r;
}

bool FaultInjector::active(int stream) const noexcept {
  return !states_[static_cast<std::size_t>(stream)].faults.empty();
}

double FaultInjector::uniform(StreamState& s) noexcept {
  return static_cast<double>(splitmix(s.rng) >> 11) * 0x1.0p-53;
}

std::uint64_t FaultInjector::below(StreamState& s, std::uint64_t n) noexcept { return n == 0 ? 0 : splitmix(s.rng) % n; }

void FaultInjector::restart_loop() noexcept {
  for (StreamState& s : states_) {
    s.bus_off_sent = s.restarted_sent = false;
    s.burst_left = 0;
    s.partial.clear();
  }
}

void FaultInjector::send(int stream, const recording::Event& e, const Emit& emit) {
  StreamState& s = states_[static_cast<std::size_t>(stream)];
  emit(e);
  ++counters_[static_cast<std::size_t>(stream)].sent;
  if (!s.held.empty()) send_held(s, stream, emit, false);
}

void FaultInjector::send_held(StreamState& s, int stream, const Emit& emit, bool all) {
  for (Held& h : s.held) --h.after;
  while (!s.held.empty() && (all || s.held.front().after <= 0)) {
    Held h = std::move(s.held.front());
    s.held.pop_front();
    h.event.payload = h.payload;
    if (h.event.kind == StreamKind::can) h.event.can = &h.can;
    emit(h.event);
    ++counters_[static_cast<std::size_t>(stream)].sent;
  }
}

void FaultInjector::flush(const Emit& emit) {
  for (std::size_t i = 0; i < states_.size(); ++i) {
    if (!states_[i].held.empty()) send_held(states_[i], static_cast<int>(i), emit, true);
  }
}

void FaultInjector::emit_lines(int stream, const recording::Event& e, double jump_m, const Emit& emit) {
  StreamState& s = states_[static_cast<std::size_t>(stream)];
  FaultCounters& c = counters_[static_cast<std::size_t>(stream)];
  s.partial.append(reinterpret_cast<const char*>(e.payload.data()), e.payload.size());
  scratch2_.clear();
  std::size_t start = 0;
  for (std::size_t nl = s.partial.find('\n'); nl != std::string::npos; nl = s.partial.find('\n', start)) {
    std::string line = s.partial.substr(start, nl + 1 - start);
    if (jump_m != 0.0) {
      std::size_t end = line.size() - 1;
      if (end > 0 && line[end - 1] == '\r') --end;
      std::string sentence = line.substr(0, end);
      if (shift_nmea_north(sentence, jump_m)) {
        line.replace(0, end, sentence);
        ++c.shifted;
      }
    }
    scratch2_.insert(scratch2_.end(), line.begin(), line.end());
    start = nl + 1;
  }
  s.partial.erase(0, start);
  if (scratch2_.empty()) return;
  recording::Event out = e;
  out.payload = scratch2_;
  send(stream, out, emit);
}

void FaultInjector::process(const recording::Event& event, std::int64_t offset_ns, const Emit& emit) {
  const int stream = event.stream;
  StreamState& s = states_[static_cast<std::size_t>(stream)];
  FaultCounters& c = counters_[static_cast<std::size_t>(stream)];
  ++c.events;
  if (s.faults.empty()) {
    send(stream, event, emit);
    return;
  }
  if (!s.decided_text && event.kind == StreamKind::serial && !event.payload.empty()) {
    s.text = event.payload.front() == '$';
    s.decided_text = true;
  }
  const double t = static_cast<double>(offset_ns) * 1e-9;
  auto in_window = [&](const FaultSpec& f) { return t >= f.from_s && (f.for_s < 0.0 || t < f.from_s + f.for_s); };

  // A working copy the faults may change.
  scratch_.assign(event.payload.begin(), event.payload.end());
  recording::CanFrame frame{};
  if (event.kind == StreamKind::can && event.can != nullptr) frame = *event.can;
  recording::Event e = event;
  auto refresh = [&] {
    e.payload = scratch_;
    if (e.kind == StreamKind::can) e.can = &frame;
  };
  refresh();

  // Losses first: what never arrives is not changed, duplicated or held.
  auto drop = [&](std::uint64_t& counter) {
    ++counter;
    if (s.line_mode) s.partial.clear();  // the rest of a line broken by the gap is lost with it
  };
  double jump = 0.0;
  for (const FaultSpec* f : s.faults) {
    switch (f->kind) {
      case FaultKind::silence:
        if (t >= f->from_s && t < f->from_s + f->seconds) return drop(c.silenced);
        break;
      case FaultKind::outage:
        if (t >= f->from_s && t < f->from_s + f->seconds) return drop(c.silenced);
        if (f->jump_m != 0.0 && t >= f->from_s + f->seconds) jump += f->jump_m;
        break;
      case FaultKind::jump:
        if (t >= f->from_s) jump += f->jump_m;
        break;
      case FaultKind::bus_off: {
        auto error_frame = [&](std::uint32_t cls) {
          recording::CanFrame err{};
          err.id = recording::kCanErrFlag | cls;
          err.length = 8;
          recording::Event out = event;
          out.can = &err;
          out.payload = {};
          ++c.injected;
          send(stream, out, emit);
        };
        if (t >= f->from_s && !s.bus_off_sent) {
          s.bus_off_sent = true;
          error_frame(kCanErrBusOff);
        }
        if (t >= f->from_s && t < f->from_s + f->seconds) return drop(c.silenced);
        if (t >= f->from_s + f->seconds && !s.restarted_sent) {
          s.restarted_sent = true;
          error_frame(kCanErrRestarted);
        }
        break;
      }
      case FaultKind::loss:
        if (!in_window(*f)) break;
        if (s.burst_left > 0) {
          --s.burst_left;
          return drop(c.lost);
        }
        if (uniform(s) < f->probability) {
          s.burst_left = f->burst - 1;
          return drop(c.lost);
        }
        break;
      default: break;
    }
  }

  // Then what changes the bytes.
  for (const FaultSpec* f : s.faults) {
    switch (f->kind) {
      case FaultKind::clock_step: {
        if (t < f->from_s) break;
        std::size_t at = 0;
        if (scratch_.size() == kVelodyneDataPacket) {
          at = kVelodyneDataTimestamp;
        } else if (scratch_.size() == kVelodynePositionPacket) {
          at = kVelodynePositionTimestamp;
        } else {
          break;
        }
        const std::int64_t us = static_cast<std::int64_t>(read_u32(scratch_.data() + at));
        if (us >= kMicrosPerHour) break;  // not a valid timestamp: left for the driver to reject
        std::int64_t stepped = (us + std::llround(f->seconds * 1e6)) % kMicrosPerHour;
        if (stepped < 0) stepped += kMicrosPerHour;
        write_u32(scratch_.data() + at, static_cast<std::uint32_t>(stepped));
        ++c.stepped;
        break;
      }
      case FaultKind::truncate:
        if (!in_window(*f)) break;
        if (uniform(s) < f->probability && scratch_.size() > 1) {
          scratch_.resize(1 + below(s, scratch_.size() - 1));
          ++c.truncated;
        }
        break;
      case FaultKind::corrupt: {
        if (!in_window(*f)) break;
        if (!(uniform(s) < f->probability)) break;
        bool changed = false;
        if (e.kind == StreamKind::can) {
          for (int k = 0; k < f->bytes && frame.length > 0; ++k) {
            frame.data[below(s, frame.length)] ^= static_cast<std::uint8_t>(1 + below(s, 255));
            changed = true;
          }
        } else if (s.text) {
          // Letters and digits only, each to a different one: inside a
          // sentence (or its checksum) that always breaks the checksum, and
          // framing characters ($, *, CR, LF) stay where they were.
          std::vector<std::size_t> candidates;
          for (std::size_t i = 0; i < scratch_.size(); ++i) {
            if (is_alnum(scratch_[i])) candidates.push_back(i);
          }
          for (int k = 0; k < f->bytes && !candidates.empty(); ++k) {
            const std::size_t i = candidates[below(s, candidates.size())];
            std::uint8_t b = scratch_[i];
            while (b == scratch_[i]) b = alnum_at(below(s, 62));
            scratch_[i] = b;
            changed = true;
          }
        } else {
          for (int k = 0; k < f->bytes && !scratch_.empty(); ++k) {
            scratch_[below(s, scratch_.size())] ^= static_cast<std::uint8_t>(1 + below(s, 255));
            changed = true;
          }
        }
        if (changed) ++c.corrupted;
        break;
      }
      default: break;
    }
  }
  refresh();

  // Then duplicates and reordering.
  bool twice = false;
  for (const FaultSpec* f : s.faults) {
    if (!in_window(*f)) continue;
    if (f->kind == FaultKind::duplicate && uniform(s) < f->probability) twice = true;
    if (f->kind == FaultKind::reorder && uniform(s) < f->probability) {
      Held h;
      h.event = e;
      h.payload = scratch_;
      h.can = frame;
      h.after = f->depth;
      s.held.push_back(std::move(h));
      ++c.reordered;
      return;
    }
  }
  if (s.line_mode) {
    emit_lines(stream, e, jump, emit);
    return;
  }
  send(stream, e, emit);
  if (twice) {
    ++c.duplicated;
    refresh();
    send(stream, e, emit);
  }
}

}  // namespace trailnav::replay
