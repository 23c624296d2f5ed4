// `trailnav gps-decode`: NMEA 0183 from a log file or a recording's serial
// GPS stream to one fix per measurement epoch, as gpsd TPV JSON lines or CSV,
// with every rejected sentence counted and explained on stderr.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "commands.hpp"
#include "trailnav/drivers/gps/fix.hpp"
#include "trailnav/drivers/recording/recording.hpp"

namespace trailnav::cli {
namespace {

struct GpsDecodeOptions {
  std::string input;
  std::string format = "jsonl";
  std::string stream = "gps";
  bool fixes_only = false;
  bool explain = false;
};

class Printer {
 public:
  Printer(const GpsDecodeOptions& o) : o_(o) {
    if (o_.format == "csv") std::printf("time,mode,status,lat,lon,alt_msl,speed,track,epx,epy,epv\n");
  }
  void fix(const gps::GpsFix& f) {
    if (o_.fixes_only && !f.has_fix()) return;
    ++printed_;
    if (o_.format == "jsonl") {
      char line[512];
      const std::size_t n = gps::write_tpv_json(f, line);
      std::fwrite(line, 1, n, stdout);
      std::fputc('\n', stdout);
      return;
    }
    auto num = [](double v, int decimals) {
      if (!std::isfinite(v)) return std::string();
      char b[40];
      std::snprintf(b, sizeof b, "%.*f", decimals, v);
      return std::string(b);
    };
    std::printf("%s,%d,%d,%s,%s,%s,%s,%s,%s,%s,%s\n",
                f.has_date ? num(static_cast<double>(f.utc_ns) * 1e-9, 3).c_str() : "", f.mode,
                static_cast<int>(f.status), num(f.lat, 9).c_str(), num(f.lon, 9).c_str(),
                num(f.alt_msl, 3).c_str(), num(f.speed, 3).c_str(), num(f.track, 3).c_str(),
                num(f.sigma_lon, 3).c_str(), num(f.sigma_lat, 3).c_str(), num(f.sigma_alt, 3).c_str());
  }
  std::uint64_t printed() const { return printed_; }

 private:
  const GpsDecodeOptions& o_;
  std::uint64_t printed_ = 0;
};

int run(const GpsDecodeOptions& o) {
  if (o.format != "jsonl" && o.format != "csv") {
    std::fprintf(stderr, "trailnav gps-decode: --format must be jsonl or csv, not '%s'\n", o.format.c_str());
    return 2;
  }
  gps::FixAssembler assembler;
  gps::LineFramer framer;
  Printer printer(o);
  gps::GpsFix fix;
  std::uint64_t line_no = 0;
  auto on_line = [&](std::string_view line) {
    ++line_no;
    if (!line.empty() && line[0] == '#') return;  // comments in logs
    if (assembler.add_line(line, fix)) printer.fix(fix);
    const gps::NmeaError e = assembler.last_error();
    if (o.explain && e != gps::NmeaError::none && e != gps::NmeaError::unsupported) {
      std::fprintf(stderr, "line %llu: rejected (%s: %s): %.*s\n", static_cast<unsigned long long>(line_no),
                   gps::nmea_error_name(e), gps::nmea_error_explanation(e), static_cast<int>(std::min<std::size_t>(line.size(), 100)),
                   line.data());
    }
  };
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::is_directory(o.input, ec)) {
    auto opened = recording::RecordingReader::open(o.input);
    if (!opened.reader) {
      std::fprintf(stderr, "trailnav gps-decode: %s\n", opened.error.c_str());
      return 1;
    }
    const int stream = opened.reader->stream_index(o.stream, recording::StreamKind::serial);
    if (stream < 0) {
      std::fprintf(stderr, "trailnav gps-decode: %s has no serial stream named '%s' (--stream)\n", o.input.c_str(),
                   o.stream.c_str());
      return 1;
    }
    while (auto e = opened.reader->next()) {
      if (e->stream == stream) framer.feed(e->payload, on_line);
    }
  } else {
    std::ifstream in(o.input, std::ios::binary);
    if (!in) {
      std::fprintf(stderr, "trailnav gps-decode: cannot open %s\n", o.input.c_str());
      return 1;
    }
    char buf[4096];
    while (in.read(buf, sizeof buf) || in.gcount() > 0) {
      framer.feed(std::span(reinterpret_cast<const std::uint8_t*>(buf), static_cast<std::size_t>(in.gcount())), on_line);
    }
    const std::uint8_t eol = '\n';
    framer.feed(std::span(&eol, 1), on_line);
  }
  if (assembler.flush(fix)) printer.fix(fix);

  const gps::GpsCounters& c = assembler.counters();
  std::fprintf(stderr,
               "trailnav gps-decode: %llu lines, %llu sentences used, %llu not decoded (GSV, proprietary, ...), "
               "%llu rejected; %llu epochs, %llu with a position, %llu printed\n",
               static_cast<unsigned long long>(c.lines), static_cast<unsigned long long>(c.accepted),
               static_cast<unsigned long long>(c.unsupported), static_cast<unsigned long long>(c.rejected_total()),
               static_cast<unsigned long long>(c.fixes), static_cast<unsigned long long>(c.with_position),
               static_cast<unsigned long long>(printer.printed()));
  for (std::size_t i = 0; i < c.rejected.size(); ++i) {
    if (c.rejected[i] == 0) continue;
    const auto e = static_cast<gps::NmeaError>(i);
    std::fprintf(stderr, "  rejected %-16s %6llu  (%s)\n", gps::nmea_error_name(e),
                 static_cast<unsigned long long>(c.rejected[i]), gps::nmea_error_explanation(e));
  }
  if (framer.overlong() > 0) {
    std::fprintf(stderr, "  dropped  overlong lines   %6llu  (no line end within %zu bytes)\n",
                 static_cast<unsigned long long>(framer.overlong()), gps::kMaxSentenceLength);
  }
  if (c.stale_date > 0) {
    std::fprintf(stderr, "  %llu epochs before any date (RMC or ZDA) was seen carry no time\n",
                 static_cast<unsigned long long>(c.stale_date));
  }
  return 0;
}

}  // namespace

void add_gps_decode_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "gps-decode",
      "Decode NMEA 0183 (GGA, RMC, GLL, GNS, GST, VTG, GSA, ZDA, HDT from any talker) into one fix per\n"
      "measurement epoch: the sentences with the same UTC time merged, as gpsd would report it. Prints gpsd\n"
      "TPV objects (class, time, mode, status, lat, lon, altHAE, altMSL, track, magvar, speed, geoidSep,\n"
      "and epx/epy/epv from GST, 1 sigma in metres) one per line, or CSV. Rejected sentences are counted\n"
      "by reason on stderr (--explain lists each). Input: an NMEA log (one sentence per line, '#' comments)\n"
      "or a recording directory's serial GPS stream.\n"
      "Examples:\n"
      "  trailnav gps-decode ../shared/data/nmea/ublox-zed-f9p-nmea.log\n"
      "  trailnav gps-decode build/sim/meadow --format csv");
  static GpsDecodeOptions o;
  cmd->add_option("input", o.input, "NMEA log file or recording directory")->required();
  cmd->add_option("--format", o.format, "jsonl (gpsd TPV objects) or csv")->capture_default_str();
  cmd->add_option("--stream", o.stream, "The serial stream of a recording directory")->capture_default_str();
  cmd->add_flag("--fixes-only", o.fixes_only, "Only epochs with a 2D or 3D fix");
  cmd->add_flag("--explain", o.explain, "List every rejected sentence with its reason on stderr");
  cmd->callback([&] { std::exit(run(o)); });
}

}  // namespace trailnav::cli
