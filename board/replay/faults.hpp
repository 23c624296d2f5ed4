// Fault injection for the bench replayer (`trailnav replay --fault SPEC`): what
// goes wrong between a robot's sensors and its computer, done to a recording's
// events on their way out, reproducibly (one seed, the same faults each time).
//
//   STREAM:FAULT[=VALUE][,OPTION=VALUE]...[@FROM[+FOR]]
//
//   loss=P[,burst=N]     each event lost with probability P; a loss takes N
//                        events in a row (default 1)
//   reorder=P[,depth=N]  an event held back and sent after the next N events
//                        of its stream (default 1, at most 64)
//   duplicate=P          an event sent twice
//   truncate=P           a datagram or serial read cut short (a random length,
//                        at least one byte shorter); not for CAN or GPIO
//   corrupt=P[,bytes=K]  K bytes of an event changed (default 1); in a text
//                        (NMEA) stream only characters inside a sentence,
//                        each to another letter or digit, so every corrupted
//                        read breaks exactly one sentence's checksum
//   silence=S            nothing of the stream for S seconds from FROM
//   outage=S[,jump=M]    serial NMEA only: a GPS outage of S seconds from
//                        FROM; with jump, every position after it is M metres
//                        further north (a receiver that re-acquired elsewhere,
//                        a multipath jump)
//   jump=M               serial NMEA only: positions from FROM on moved M
//                        metres north
//   bus-off=S            CAN only: a bus-off error frame at FROM, no frame for
//                        S seconds, then a "restarted" error frame
//   clock-step=S         Velodyne UDP streams only: from FROM on, the sensor's
//                        timestamps (microseconds past the hour, data and
//                        position packets) S seconds later (S may be
//                        negative; wraps at the hour like the sensor's)
//
// FROM and FOR are seconds of recording time from where the replay starts
// (after --skip); without @ a probabilistic fault applies throughout, and a
// timed one (silence, outage, jump, bus-off, clock-step) at 0. A step of the
// host's clock is not a replay fault: the kernel tests step the clock of a
// virtual machine (docs/testing.md).
//
// Offline tooling: allocates freely (the held-back events, rewritten lines).
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "trailnav/drivers/recording/recording.hpp"

namespace trailnav::replay {

enum class FaultKind : std::uint8_t { loss, reorder, duplicate, truncate, corrupt, silence, outage, jump, bus_off, clock_step };
const char* fault_kind_name(FaultKind kind) noexcept;

struct FaultSpec {
  std::string stream;
  FaultKind kind = FaultKind::loss;
  double probability = 0.0;  // loss, reorder, duplicate, truncate, corrupt
  int burst = 1;             // loss
  int depth = 1;             // reorder
  int bytes = 1;             // corrupt
  double seconds = 0.0;      // silence, outage, bus-off: how long; clock-step: the step
  double jump_m = 0.0;       // outage (after it), jump
  double from_s = 0.0;
  double for_s = -1.0;       // < 0: to the end
  std::string text;          // the spec as given
};

struct FaultSpecResult {
  std::optional<FaultSpec> spec;
  std::string error;
};
// Parses one spec; errors quote it and say what is wrong.
FaultSpecResult parse_fault_spec(std::string_view text);

// What was done to one stream (all loops).
struct FaultCounters {
  std::string stream;
  std::uint64_t events = 0;       // events of the recording seen
  std::uint64_t sent = 0;         // events handed on (duplicates and injected ones included)
  std::uint64_t lost = 0;         // dropped by loss
  std::uint64_t silenced = 0;     // dropped by silence, outage and bus-off
  std::uint64_t reordered = 0;    // held back and sent later
  std::uint64_t duplicated = 0;   // sent a second time
  std::uint64_t truncated = 0;
  std::uint64_t corrupted = 0;    // events with changed bytes
  std::uint64_t shifted = 0;      // NMEA sentences whose position was moved
  std::uint64_t stepped = 0;      // Velodyne packets whose timestamp was stepped
  std::uint64_t injected = 0;     // error frames made up (bus-off, restarted)
};

// Moves an NMEA sentence's position `metres` north (GGA, RMC, GLL, GNS; the
// others are left alone) and writes a new checksum. The sentence keeps its
// length and number formats. False when the line is not one of those with a
// position.
bool shift_nmea_north(std::string& line, double metres);

class FaultInjector {
 public:
  using Emit = std::function<void(const recording::Event&)>;
  struct Created;
  // Checks every spec against the recording's streams (names, kinds).
  static Created create(const std::vector<FaultSpec>& specs, const std::vector<recording::StreamInfo>& streams,
                        std::uint64_t seed);

  // One event of the recording, `offset_ns` after the replay's start: hands
  // on what goes out (none, one, several; changed or not) through `emit`.
  void process(const recording::Event& event, std::int64_t offset_ns, const Emit& emit);
  // The end of a loop: events still held back go out.
  void flush(const Emit& emit);
  // The next loop starts from recording time 0 again.
  void restart_loop() noexcept;

  const std::vector<FaultCounters>& counters() const noexcept { return counters_; }
  bool active(int stream) const noexcept;

 private:
  struct Held {
    recording::Event event;
    std::vector<std::uint8_t> payload;
    recording::CanFrame can{};
    int after = 0;  // events of its stream still to pass before it goes
  };
  struct StreamState {
    std::vector<const FaultSpec*> faults;
    std::uint64_t rng = 0;
    int burst_left = 0;
    bool text = false;                      // NMEA: first byte '$'
    bool decided_text = false;
    bool line_mode = false;                 // re-chunked into whole lines (jump)
    std::string partial;                    // line mode: bytes of the unfinished line
    bool bus_off_sent = false, restarted_sent = false;
    std::deque<Held> held;
  };
  FaultInjector() = default;
  double uniform(StreamState& s) noexcept;
  std::uint64_t below(StreamState& s, std::uint64_t n) noexcept;
  void send(int stream, const recording::Event& e, const Emit& emit);
  void send_held(StreamState& s, int stream, const Emit& emit, bool all);
  void emit_lines(int stream, const recording::Event& e, double jump_m, const Emit& emit);

  std::vector<FaultSpec> specs_;
  std::vector<StreamState> states_;
  std::vector<FaultCounters> counters_;
  std::vector<std::uint8_t> scratch_;
  std::vector<std::uint8_t> scratch2_;
};

struct FaultInjector::Created {
  std::unique_ptr<FaultInjector> injector;
  std::string error;
};

}  // namespace trailnav::replay
