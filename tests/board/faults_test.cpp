// The replayer's fault injection (board/replay/faults.hpp), on its own: spec
// parsing and its errors, the NMEA position shift on real receiver logs, and
// what each fault does to a stream of events, counted.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include "faults.hpp"
#include "trailnav/drivers/gps/nmea.hpp"

using namespace trailnav;
using replay::FaultInjector;
using replay::FaultKind;
using replay::FaultSpec;
using replay::parse_fault_spec;

namespace {

FaultSpec spec(const std::string& text) {
  const auto r = parse_fault_spec(text);
  EXPECT_TRUE(r.spec) << r.error;
  return r.spec.value_or(FaultSpec{});
}

std::string error_of(const std::string& text) {
  const auto r = parse_fault_spec(text);
  EXPECT_FALSE(r.spec) << text;
  return r.error;
}

// What came out of the injector, in order.
struct Sent {
  int stream;
  std::int64_t time_ns;
  std::vector<std::uint8_t> bytes;
  recording::CanFrame can{};
};

struct Bench {
  std::vector<recording::StreamInfo> streams;
  std::unique_ptr<FaultInjector> injector;
  std::vector<Sent> out;
  FaultInjector::Emit emit = [this](const recording::Event& e) {
    Sent s{e.stream, e.time_ns, {e.payload.begin(), e.payload.end()}, {}};
    if (e.can != nullptr) s.can = *e.can;
    out.push_back(std::move(s));
  };

  Bench(const std::vector<std::string>& faults, std::uint64_t seed = 1) {
    streams = {{"lidar", recording::StreamKind::udp, "udp.pcap", 2368, "", 0, ""},
               {"gps", recording::StreamKind::serial, "serial/gps.log", 0, "", 115200, ""},
               {"wheels", recording::StreamKind::can, "can.log", 0, "can0", 0, ""},
               {"estop", recording::StreamKind::gpio, "gpio/estop.log", 0, "", 0, ""}};
    std::vector<FaultSpec> specs;
    for (const auto& f : faults) specs.push_back(spec(f));
    auto made = FaultInjector::create(specs, streams, seed);
    EXPECT_TRUE(made.injector) << made.error;
    injector = std::move(made.injector);
  }

  // n events of `stream`, one every `period` s, the event's index in its first bytes.
  void feed(int stream, int n, double period, std::size_t size = 8) {
    for (int i = 0; i < n; ++i) {
      std::vector<std::uint8_t> bytes(size, 0);
      for (std::size_t b = 0; b < std::min<std::size_t>(size, 4); ++b) bytes[b] = static_cast<std::uint8_t>(i >> (8 * b));
      recording::Event e;
      e.stream = stream;
      e.kind = streams[static_cast<std::size_t>(stream)].kind;
      e.time_ns = std::llround(i * period * 1e9);
      e.payload = bytes;
      recording::CanFrame frame{};
      if (e.kind == recording::StreamKind::can) {
        frame.id = 0x120;
        frame.length = 8;
        for (int b = 0; b < 8; ++b) frame.data[static_cast<std::size_t>(b)] = bytes[static_cast<std::size_t>(b)];
        e.can = &frame;
      }
      injector->process(e, e.time_ns, emit);
    }
    injector->flush(emit);
  }

  int index_of(const Sent& s) const {
    return static_cast<int>(s.bytes[0] | s.bytes[1] << 8 | s.bytes[2] << 16 | s.bytes[3] << 24);
  }
};

// The sentences of a real receiver's log that trailnav decodes.
std::vector<std::string> real_sentences() {
  std::ifstream in("../shared/data/nmea/bu353s4.log");
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    gps::NmeaSentence parsed;
    if (line.rfind('$', 0) == 0 && gps::parse_nmea(line, parsed) == gps::NmeaError::none) lines.push_back(line);
  }
  return lines;
}

}  // namespace

TEST(Faults, SpecsParse) {
  FaultSpec f = spec("lidar:loss=0.05,burst=10@5+10");
  EXPECT_EQ(f.stream, "lidar");
  EXPECT_EQ(f.kind, FaultKind::loss);
  EXPECT_DOUBLE_EQ(f.probability, 0.05);
  EXPECT_EQ(f.burst, 10);
  EXPECT_DOUBLE_EQ(f.from_s, 5.0);
  EXPECT_DOUBLE_EQ(f.for_s, 10.0);
  f = spec("gps:outage=10,jump=50@8");
  EXPECT_EQ(f.kind, FaultKind::outage);
  EXPECT_DOUBLE_EQ(f.seconds, 10.0);
  EXPECT_DOUBLE_EQ(f.jump_m, 50.0);
  EXPECT_LT(f.for_s, 0.0);
  f = spec("lidar:clock-step=-2.5@20");
  EXPECT_DOUBLE_EQ(f.seconds, -2.5);
  f = spec("wheels:bus-off=3@12");
  EXPECT_EQ(f.kind, FaultKind::bus_off);
  f = spec("imu:reorder=0.01,depth=3");
  EXPECT_EQ(f.depth, 3);
  EXPECT_DOUBLE_EQ(f.from_s, 0.0);
}

TEST(Faults, BadSpecsSayWhatIsWrong) {
  EXPECT_NE(error_of("loss=0.1").find("expected STREAM:FAULT"), std::string::npos);
  EXPECT_NE(error_of("lidar:lose=0.1").find("unknown fault 'lose'"), std::string::npos);
  EXPECT_NE(error_of("lidar:loss").find("loss needs a number"), std::string::npos);
  EXPECT_NE(error_of("lidar:loss=1.5").find("probability"), std::string::npos);
  EXPECT_NE(error_of("lidar:loss=0").find("probability"), std::string::npos);
  EXPECT_NE(error_of("lidar:loss=nan").find("needs a number"), std::string::npos);
  EXPECT_NE(error_of("lidar:loss=0.1,depth=2").find("'depth' is not an option of loss"), std::string::npos);
  EXPECT_NE(error_of("lidar:loss=0.1,burst=0").find("burst"), std::string::npos);
  EXPECT_NE(error_of("lidar:reorder=0.1,depth=65").find("depth"), std::string::npos);
  EXPECT_NE(error_of("lidar:silence=-1").find("seconds"), std::string::npos);
  EXPECT_NE(error_of("lidar:silence=5@3+2").find("takes no +FOR"), std::string::npos);
  EXPECT_NE(error_of("lidar:loss=0.1@-1").find("@FROM"), std::string::npos);
  EXPECT_NE(error_of("lidar:loss=0.1@1+0").find("+FOR"), std::string::npos);
  EXPECT_NE(error_of("lidar:clock-step=3600").find("less than an hour"), std::string::npos);
  EXPECT_NE(error_of("gps:jump=0").find("not 0"), std::string::npos);
  EXPECT_NE(error_of("gps:outage=5,jump").find("NAME=VALUE"), std::string::npos);
}

TEST(Faults, SpecsMustFitTheirStream) {
  const std::vector<recording::StreamInfo> streams = {{"lidar", recording::StreamKind::udp, "", 2368, "", 0, ""},
                                                      {"wheels", recording::StreamKind::can, "", 0, "can0", 0, ""},
                                                      {"estop", recording::StreamKind::gpio, "", 0, "", 0, ""}};
  auto error = [&](const std::string& text) {
    auto made = FaultInjector::create({spec(text)}, streams, 1);
    EXPECT_FALSE(made.injector) << text;
    return made.error;
  };
  EXPECT_NE(error("gps:loss=0.1").find("no stream 'gps' in the recording (it has lidar, wheels, estop)"), std::string::npos);
  EXPECT_NE(error("wheels:truncate=0.1").find("is can"), std::string::npos);
  EXPECT_NE(error("estop:corrupt=0.1").find("GPIO"), std::string::npos);
  EXPECT_NE(error("lidar:outage=3").find("NMEA"), std::string::npos);
  EXPECT_NE(error("lidar:bus-off=3").find("CAN"), std::string::npos);
  EXPECT_NE(error("wheels:clock-step=1").find("Velodyne"), std::string::npos);
}

// Every GGA and RMC of a real receiver's log, moved 50 m north: still a valid
// sentence of the same length, 50 m further north (to a centimetre plus the
// log's own rounding of 0.0001' = 18 cm), the rest of it unchanged.
TEST(Faults, NmeaPositionsMoveNorthOnRealReceiverSentences) {
  const std::vector<std::string> lines = real_sentences();
  ASSERT_GT(lines.size(), 20u);
  int shifted = 0;
  for (const std::string& original : lines) {
    std::string line = original;
    gps::NmeaSentence before, after;
    if (gps::parse_nmea(original, before) != gps::NmeaError::none) continue;
    const bool moved = replay::shift_nmea_north(line, 50.0);
    const bool has_position = before.type == gps::SentenceType::gga || before.type == gps::SentenceType::rmc ||
                              before.type == gps::SentenceType::gll || before.type == gps::SentenceType::gns;
    if (!moved) {
      EXPECT_EQ(line, original);
      continue;
    }
    ASSERT_TRUE(has_position) << original;
    ASSERT_EQ(gps::parse_nmea(line, after), gps::NmeaError::none) << line;
    EXPECT_EQ(line.size(), original.size());
    const double lat0 = before.type == gps::SentenceType::gga ? before.gga.lat : before.rmc.lat;
    const double lat1 = after.type == gps::SentenceType::gga ? after.gga.lat : after.rmc.lat;
    const double lon0 = before.type == gps::SentenceType::gga ? before.gga.lon : before.rmc.lon;
    const double lon1 = after.type == gps::SentenceType::gga ? after.gga.lon : after.rmc.lon;
    EXPECT_NEAR((lat1 - lat0) * 110'950.0, 50.0, 0.3) << original << " -> " << line;  // ~111 km per degree at 37.8 S
    EXPECT_EQ(lon1, lon0);
    ++shifted;
  }
  EXPECT_GT(shifted, 20);
  // Across the equator and a minute's carry.
  std::string line = "$GPGGA,120000.00,0000.00100,S,00750.00000,E,1,08,1.0,280.0,M,47.0,M,,";
  line += "*" + [&] {
    char cs[3];
    std::snprintf(cs, sizeof cs, "%02X", gps::nmea_checksum(line.substr(1)));
    return std::string(cs);
  }();
  ASSERT_TRUE(replay::shift_nmea_north(line, 50.0));
  gps::NmeaSentence s;
  ASSERT_EQ(gps::parse_nmea(line, s), gps::NmeaError::none) << line;
  EXPECT_NEAR(s.gga.lat * 110'574.0, 50.0 - 1.853, 0.02) << line;  // 0.001' south was 1.853 m
  EXPECT_NE(line.find(",N,"), std::string::npos);
}

TEST(Faults, LossDropsAboutItsShareInBurstsAndIsReproducible) {
  Bench a({"lidar:loss=0.05,burst=10"}, 7);
  a.feed(0, 20000, 0.001);
  const auto& c = a.injector->counters()[0];
  EXPECT_EQ(c.events, 20000u);
  EXPECT_EQ(c.sent + c.lost, c.events);
  EXPECT_EQ(a.out.size(), c.sent);
  // A burst starts on 5 % of the events that could start one.
  EXPECT_GT(c.lost, 20000u * 0.25);
  EXPECT_LT(c.lost, 20000u * 0.45);
  // Lost in runs of ten (bursts may follow each other; the last may be cut).
  int gaps = 0;
  int expected = 0;
  for (const Sent& s : a.out) {
    const int i = a.index_of(s);
    if (i != expected) {
      EXPECT_EQ((i - expected) % 10, 0) << "a gap of " << i - expected;
      ++gaps;
    }
    expected = i + 1;
  }
  EXPECT_GT(gaps, 50);
  Bench b({"lidar:loss=0.05,burst=10"}, 7);
  b.feed(0, 20000, 0.001);
  ASSERT_EQ(b.out.size(), a.out.size());
  for (std::size_t i = 0; i < a.out.size(); ++i) ASSERT_EQ(a.index_of(a.out[i]), b.index_of(b.out[i]));
  Bench other({"lidar:loss=0.05,burst=10"}, 8);
  other.feed(0, 20000, 0.001);
  EXPECT_NE(other.injector->counters()[0].lost, c.lost);
}

TEST(Faults, WindowsLimitAFault) {
  Bench b({"lidar:duplicate=1@2+1"});
  b.feed(0, 500, 0.01);  // 5 s
  const auto& c = b.injector->counters()[0];
  EXPECT_EQ(c.duplicated, 100u);  // 2.00 .. 2.99 s
  EXPECT_EQ(c.sent, 600u);
}

TEST(Faults, ReorderSendsAnEventAfterTheNextOnes) {
  Bench b({"lidar:reorder=0.1,depth=3"}, 3);
  b.feed(0, 5000, 0.001);
  const auto& c = b.injector->counters()[0];
  EXPECT_EQ(c.sent, 5000u);  // nothing lost
  EXPECT_GT(c.reordered, 400u);
  EXPECT_LT(c.reordered, 600u);
  std::vector<int> seen;
  for (const Sent& s : b.out) seen.push_back(b.index_of(s));
  int out_of_order = 0;
  for (std::size_t i = 1; i < seen.size(); ++i) out_of_order += seen[i] < seen[i - 1];
  EXPECT_GT(out_of_order, 400);
  std::sort(seen.begin(), seen.end());
  for (int i = 0; i < 5000; ++i) ASSERT_EQ(seen[static_cast<std::size_t>(i)], i);
}

TEST(Faults, TruncateCutsShortAndCorruptChangesBytes) {
  Bench b({"lidar:truncate=0.2", "lidar:corrupt=0.2,bytes=2"}, 5);
  b.feed(0, 2000, 0.001, 1206);
  const auto& c = b.injector->counters()[0];
  std::uint64_t shorter = 0;
  for (const Sent& s : b.out) {
    EXPECT_GE(s.bytes.size(), 1u);
    shorter += s.bytes.size() < 1206;
  }
  EXPECT_EQ(shorter, c.truncated);
  EXPECT_GT(c.truncated, 300u);
  EXPECT_GT(c.corrupted, 300u);
}

// Corrupting a real NMEA stream: every corrupted read breaks exactly the
// sentences it touches, so the parser rejects at least one sentence per
// corrupted read and never more than the corrupted reads.
TEST(Faults, CorruptedNmeaFailsItsChecksum) {
  Bench b({"gps:corrupt=0.3"}, 11);
  const std::vector<std::string> lines = real_sentences();
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string bytes = lines[i] + "\r\n";
    recording::Event e;
    e.stream = 1;
    e.kind = recording::StreamKind::serial;
    e.time_ns = static_cast<std::int64_t>(i) * 100'000'000;
    e.payload = std::span(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
    b.injector->process(e, e.time_ns, b.emit);
  }
  const auto& c = b.injector->counters()[1];
  ASSERT_GT(c.corrupted, 5u);
  std::uint64_t rejected = 0;
  for (const Sent& s : b.out) {
    gps::NmeaSentence out;
    const std::string_view line(reinterpret_cast<const char*>(s.bytes.data()), s.bytes.size());
    rejected += gps::parse_nmea(line, out) != gps::NmeaError::none;
  }
  EXPECT_EQ(rejected, c.corrupted);  // one sentence per read here
}

TEST(Faults, GpsOutageThenJump) {
  Bench b({"gps:outage=2,jump=50@1"});
  const std::vector<std::string> lines = real_sentences();
  std::vector<std::int64_t> times;
  for (std::size_t i = 0; i < 40 && i < lines.size(); ++i) {
    // Each sentence in two reads, split mid-line as a serial port does.
    const std::string bytes = lines[i] + "\r\n";
    const std::size_t cut = bytes.size() / 2;
    for (int part = 0; part < 2; ++part) {
      const std::string chunk = part == 0 ? bytes.substr(0, cut) : bytes.substr(cut);
      recording::Event e;
      e.stream = 1;
      e.kind = recording::StreamKind::serial;
      e.time_ns = static_cast<std::int64_t>(i) * 100'000'000 + part * 1'000'000;
      e.payload = std::span(reinterpret_cast<const std::uint8_t*>(chunk.data()), chunk.size());
      b.injector->process(e, e.time_ns, b.emit);
    }
  }
  const auto& c = b.injector->counters()[1];
  EXPECT_EQ(c.silenced, 40u);  // 1.0 .. 2.999 s: sentences 10..29, two reads each
  std::uint64_t positions_after = 0;
  for (const Sent& s : b.out) {
    EXPECT_TRUE(s.time_ns < 1'000'000'000 || s.time_ns >= 3'000'000'000) << s.time_ns;
    const std::string text(s.bytes.begin(), s.bytes.end());
    EXPECT_EQ(text.back(), '\n');  // re-chunked into whole lines
    gps::NmeaSentence n;
    ASSERT_EQ(gps::parse_nmea(text, n), gps::NmeaError::none) << text;
    if (s.time_ns >= 3'000'000'000 && (n.type == gps::SentenceType::gga || n.type == gps::SentenceType::rmc)) ++positions_after;
  }
  EXPECT_EQ(c.shifted, positions_after);
  EXPECT_GT(c.shifted, 5u);
}

TEST(Faults, BusOffSendsErrorFramesAndSilencesTheBus) {
  Bench b({"wheels:bus-off=1@2"});
  b.feed(2, 500, 0.01);  // 5 s at 100 Hz
  const auto& c = b.injector->counters()[2];
  EXPECT_EQ(c.injected, 2u);
  EXPECT_EQ(c.silenced, 100u);
  int errors = 0;
  for (const Sent& s : b.out) {
    if (s.can.id & recording::kCanErrFlag) {
      ++errors;
      EXPECT_EQ(s.can.id & 0x1FFFFFFFu, errors == 1 ? 0x40u : 0x100u);  // bus-off, then restarted
    }
  }
  EXPECT_EQ(errors, 2);
  EXPECT_EQ(c.sent, 400u + 2u);
}

TEST(Faults, ClockStepMovesVelodyneTimestampsAndWrapsAtTheHour) {
  Bench b({"lidar:clock-step=-3@1"});
  for (int i = 0; i < 300; ++i) {
    std::vector<std::uint8_t> packet(1206, 0);
    const std::uint32_t us = static_cast<std::uint32_t>(1'000'000 + i * 10'000);  // 1.00 s past the hour on
    for (int k = 0; k < 4; ++k) packet[static_cast<std::size_t>(1200 + k)] = static_cast<std::uint8_t>(us >> (8 * k));
    recording::Event e;
    e.stream = 0;
    e.kind = recording::StreamKind::udp;
    e.time_ns = static_cast<std::int64_t>(i) * 10'000'000;
    e.payload = packet;
    b.injector->process(e, e.time_ns, b.emit);
  }
  ASSERT_EQ(b.out.size(), 300u);
  EXPECT_EQ(b.injector->counters()[0].stepped, 200u);
  auto stamp = [](const Sent& s) {
    return static_cast<std::uint32_t>(s.bytes[1200] | s.bytes[1201] << 8 | s.bytes[1202] << 16 | s.bytes[1203] << 24);
  };
  EXPECT_EQ(stamp(b.out[99]), 1'990'000u);
  EXPECT_EQ(stamp(b.out[100]), 3'600'000'000u - 1'000'000u);  // 2 s - 3 s: 59:59 of the hour before
  EXPECT_EQ(stamp(b.out[299]), 990'000u);
}

TEST(Faults, SilenceDropsOnlyItsStream) {
  Bench b({"estop:silence=1@0.5"});
  b.feed(3, 200, 0.01);
  b.feed(0, 200, 0.01);
  EXPECT_EQ(b.injector->counters()[3].silenced, 100u);
  EXPECT_EQ(b.injector->counters()[0].silenced, 0u);
  EXPECT_EQ(b.injector->counters()[0].sent, 200u);
}
