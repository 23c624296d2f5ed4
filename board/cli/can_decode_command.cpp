// `trailnav can-decode`: a candump log (or a recording's CAN stream) decoded
// with a DBC into one CSV row per signal value: time,message,signal,value.
// Frames of ids the DBC does not know, unparsable lines and signals that
// cannot be decoded are counted on stderr, never silently dropped.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "commands.hpp"
#include "trailnav/drivers/can/dbc.hpp"
#include "trailnav/drivers/recording/recording.hpp"

namespace trailnav::cli {
namespace {

struct CanDecodeOptions {
  std::string input;
  std::string dbc;
  std::vector<std::string> messages;
  std::string format = "csv";
  std::string stream;
};

struct Decoder {
  explicit Decoder(const can::Dbc& d) : dbc(d) {}
  const can::Dbc& dbc;
  std::set<const can::DbcMessage*> wanted;  // empty: all
  std::uint64_t frames = 0, decoded_frames = 0, values = 0, error_frames = 0, remote_frames = 0;
  std::map<std::uint32_t, std::uint64_t> unknown;  // id (with EFF flag) -> frames
  std::map<std::string, std::uint64_t> signal_errors;  // "MSG.SIG: reason" -> count

  void frame(const can::Frame& f) {
    ++frames;
    if (f.error()) {
      ++error_frames;
      return;
    }
    if (f.remote()) {
      ++remote_frames;
      return;
    }
    const can::DbcMessage* m = dbc.message(f.identifier(), f.extended());
    if (!m) {
      ++unknown[f.id & (can::kEffFlag | can::kEffMask)];
      return;
    }
    if (!wanted.empty() && !wanted.count(m)) return;
    ++decoded_frames;
    char time[32];
    std::snprintf(time, sizeof time, "%lld.%06lld", static_cast<long long>(f.time_ns / 1'000'000'000),
                  static_cast<long long>((f.time_ns % 1'000'000'000) / 1000));
    for (const can::DbcSignal& s : m->signals) {
      double v = 0.0;
      const can::SignalError e = can::decode_signal(s, f.payload(), v);
      if (e != can::SignalError::none) {
        ++signal_errors[m->name + "." + s.name + ": " + can::signal_error_name(e)];
        continue;
      }
      ++values;
      std::printf("%s,%s,%s,%.10g\n", time, m->name.c_str(), s.name.c_str(), v);
    }
  }
};

int run(const CanDecodeOptions& o) {
  if (o.format != "csv") {
    std::fprintf(stderr, "trailnav can-decode: --format must be csv, not '%s'\n", o.format.c_str());
    return 2;
  }
  auto loaded = can::load_dbc(o.dbc);
  if (!loaded.dbc) {
    std::fprintf(stderr, "trailnav can-decode: %s\n", loaded.error.c_str());
    return 1;
  }
  for (const std::string& w : loaded.dbc->warnings) std::fprintf(stderr, "trailnav can-decode: warning: %s\n", w.c_str());
  Decoder d(*loaded.dbc);
  for (const std::string& name : o.messages) {
    const can::DbcMessage* m = loaded.dbc->message(name);
    if (!m) {
      std::fprintf(stderr, "trailnav can-decode: %s has no message '%s' (--message)\n", o.dbc.c_str(), name.c_str());
      return 2;
    }
    d.wanted.insert(m);
  }
  std::printf("time,message,signal,value\n");
  std::uint64_t lines = 0, bad_lines = 0;
  std::string first_bad;
  std::error_code ec;
  if (std::filesystem::is_directory(o.input, ec)) {
    auto opened = recording::RecordingReader::open(o.input);
    if (!opened.reader) {
      std::fprintf(stderr, "trailnav can-decode: %s\n", opened.error.c_str());
      return 1;
    }
    while (auto e = opened.reader->next()) {
      if (e->kind != recording::StreamKind::can) continue;
      if (!o.stream.empty() && opened.reader->streams()[static_cast<std::size_t>(e->stream)].name != o.stream) continue;
      ++lines;
      d.frame(*e->can);
    }
    bad_lines = opened.reader->counters().bad_lines;
    first_bad = opened.reader->first_problem();
  } else {
    std::ifstream in(o.input);
    if (!in) {
      std::fprintf(stderr, "trailnav can-decode: cannot open %s\n", o.input.c_str());
      return 1;
    }
    std::string line, interface, error;
    std::uint64_t number = 0;
    while (std::getline(in, line)) {
      ++number;
      if (line.empty() || line[0] == '#') continue;
      ++lines;
      can::Frame f;
      if (!recording::parse_candump_line(line, f, interface, error)) {
        if (bad_lines++ == 0) first_bad = o.input + ":" + std::to_string(number) + ": " + error;
        continue;
      }
      d.frame(f);
    }
  }
  std::fprintf(stderr,
               "trailnav can-decode: %llu frames (%llu lines unreadable), %llu decoded into %llu values, "
               "%llu error frames, %llu remote frames, %llu frames of %zu ids not in %s\n",
               static_cast<unsigned long long>(d.frames), static_cast<unsigned long long>(bad_lines),
               static_cast<unsigned long long>(d.decoded_frames), static_cast<unsigned long long>(d.values),
               static_cast<unsigned long long>(d.error_frames), static_cast<unsigned long long>(d.remote_frames),
               static_cast<unsigned long long>([&] {
                 std::uint64_t n = 0;
                 for (const auto& [id, c] : d.unknown) n += c;
                 return n;
               }()),
               d.unknown.size(), std::filesystem::path(o.dbc).filename().c_str());
  if (!first_bad.empty()) std::fprintf(stderr, "  first unreadable line: %s\n", first_bad.c_str());
  std::vector<std::pair<std::uint64_t, std::uint32_t>> top;
  for (const auto& [id, c] : d.unknown) top.emplace_back(c, id);
  std::sort(top.rbegin(), top.rend());
  for (std::size_t i = 0; i < std::min<std::size_t>(top.size(), 5); ++i) {
    const std::uint32_t id = top[i].second;
    if (id & can::kEffFlag) {
      std::fprintf(stderr, "  unknown id %08X (extended) %llu frames\n", id & can::kEffMask,
                   static_cast<unsigned long long>(top[i].first));
    } else {
      std::fprintf(stderr, "  unknown id %03X %llu frames\n", id, static_cast<unsigned long long>(top[i].first));
    }
  }
  for (const auto& [what, c] : d.signal_errors) {
    std::fprintf(stderr, "  not decoded %s (%llu frames)\n", what.c_str(), static_cast<unsigned long long>(c));
  }
  return bad_lines > 0 ? 1 : 0;
}

}  // namespace

void add_can_decode_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "can-decode",
      "Decode CAN frames with a DBC file: one CSV row per signal, time,message,signal,value (physical value:\n"
      "raw * factor + offset, in the DBC's unit). Input: a candump log ('(time) can0 123#DEADBEEF', classic\n"
      "and FD frames) or a recording directory's CAN stream. Frames of unknown ids, error frames, signals\n"
      "that do not fit their frame and multiplexed signals (unsupported) are counted on stderr; the exit\n"
      "status is 1 when a line could not be read.\n"
      "Examples:\n"
      "  trailnav can-decode build/sim/meadow --dbc board/sim/trailnav-robot.dbc --message WHEEL_SPEEDS\n"
      "  trailnav can-decode drive.log --dbc ../shared/data/can/dbc/opendbc__toyota_2017.dbc --message WHEEL_SPEEDS");
  static CanDecodeOptions o;
  cmd->add_option("input", o.input, "candump log file or recording directory")->required();
  cmd->add_option("--dbc", o.dbc, "DBC file describing the messages")->required();
  cmd->add_option("--message", o.messages, "Only these messages (by DBC name; repeatable)");
  cmd->add_option("--format", o.format, "Output format: csv")->capture_default_str();
  cmd->add_option("--stream", o.stream, "The CAN stream of a recording directory (default: all)");
  cmd->callback([&] { std::exit(run(o)); });
}

}  // namespace trailnav::cli
