// `trailnav imu-decode`: an IMU's byte stream (Xsens MT binary or trailnav's
// $TNIMU lines, from a log file or a recording's serial stream) or a CSV of
// x-io's format, decoded sample by sample and run through the attitude
// filter: CSV or JSON lines on stdout, counters and a summary on stderr.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "trailnav/drivers/gps/fix.hpp"
#include "trailnav/drivers/imu/attitude.hpp"
#include "trailnav/drivers/imu/line_format.hpp"
#include "trailnav/drivers/imu/xsens.hpp"
#include "trailnav/drivers/recording/recording.hpp"

namespace trailnav::cli {
namespace {

constexpr double kDeg = 180.0 / M_PI;

struct ImuDecodeOptions {
  std::string input;
  std::string protocol = "auto";
  std::string format = "csv";
  std::string stream = "imu";
  int every = 1;
  bool filter_only = false;
};

struct Summary {
  std::uint64_t samples = 0, printed = 0;
  std::array<std::uint64_t, imu::kXsensErrors> xsens_errors{};
  std::array<std::uint64_t, imu::kLineErrors> line_errors{};
  std::uint64_t device_errors = 0, other_messages = 0, csv_bad_rows = 0;
  double min_roll = 1e9, max_roll = -1e9, min_pitch = 1e9, max_pitch = -1e9;
};

class Decoder {
 public:
  explicit Decoder(const ImuDecodeOptions& o) : o_(o), filter_(options(o)) {
    if (o_.format == "csv") {
      std::printf("time,counter,source,roll_deg,pitch_deg,yaw_deg,yaw_rate_dps,gx,gy,gz,ax,ay,az,standstill\n");
    }
  }
  static imu::AttitudeOptions options(const ImuDecodeOptions& o) {
    imu::AttitudeOptions a;
    a.use_device_orientation = !o.filter_only;
    return a;
  }

  void sample(const imu::ImuSample& s) {
    const imu::Attitude& a = filter_.update(s);
    ++summary_.samples;
    if (a.source == imu::AttitudeSource::none) return;
    summary_.min_roll = std::min(summary_.min_roll, a.roll);
    summary_.max_roll = std::max(summary_.max_roll, a.roll);
    summary_.min_pitch = std::min(summary_.min_pitch, a.pitch);
    summary_.max_pitch = std::max(summary_.max_pitch, a.pitch);
    if ((summary_.samples - 1) % static_cast<std::uint64_t>(o_.every) != 0) return;
    ++summary_.printed;
    const double t = s.time_ns != 0 ? static_cast<double>(s.time_ns) * 1e-9
                     : s.has(imu::kSampleTime)      ? s.sample_time
                                                    : static_cast<double>(s.sample_time_fine) * 1e-4;
    const char* source = a.source == imu::AttitudeSource::device ? "device" : "filter";
    if (o_.format == "csv") {
      std::printf("%.6f,%u,%s,%.4f,%.4f,%.4f,%.4f,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%d\n", t, s.packet_counter, source,
                  a.roll * kDeg, a.pitch * kDeg, a.yaw * kDeg, a.yaw_rate * kDeg, s.rate_of_turn[0],
                  s.rate_of_turn[1], s.rate_of_turn[2], s.acceleration[0], s.acceleration[1], s.acceleration[2],
                  a.standstill ? 1 : 0);
    } else {
      std::printf("{\"time\":%.6f,\"counter\":%u,\"source\":\"%s\",\"roll\":%.4f,\"pitch\":%.4f,\"yaw\":%.4f,"
                  "\"yaw_rate\":%.4f,\"gyro\":[%.6g,%.6g,%.6g],\"accel\":[%.6g,%.6g,%.6g],\"standstill\":%s}\n",
                  t, s.packet_counter, source, a.roll * kDeg, a.pitch * kDeg, a.yaw * kDeg, a.yaw_rate * kDeg,
                  s.rate_of_turn[0], s.rate_of_turn[1], s.rate_of_turn[2], s.acceleration[0], s.acceleration[1],
                  s.acceleration[2], a.standstill ? "true" : "false");
    }
  }

  void xsens(std::span<const std::uint8_t> bytes, std::int64_t time_ns) {
    xbus_.feed(bytes, [&](const imu::XbusMessage& m) {
      if (m.mid == imu::mid::kError) {
        ++summary_.device_errors;
        const std::uint8_t code = m.payload.empty() ? 0 : m.payload[0];
        std::fprintf(stderr, "device error 0x%02X: %s\n", code, imu::xsens_device_error_text(code));
        return;
      }
      if (m.mid != imu::mid::kMtData2) {
        ++summary_.other_messages;
        return;
      }
      imu::ImuSample s;
      s.time_ns = time_ns;
      const imu::XsensError e = imu::decode_mtdata2(m.payload, s, &items_);
      if (e != imu::XsensError::none) {
        ++summary_.xsens_errors[static_cast<std::size_t>(e)];
        return;
      }
      sample(s);
    });
  }

  void lines(std::span<const std::uint8_t> bytes, std::int64_t time_ns) {
    framer_.feed(bytes, [&](std::string_view line) {
      imu::ImuSample s;
      s.time_ns = time_ns;
      const imu::LineError e = imu::parse_imu_line(line, s);
      if (e != imu::LineError::none) {
        ++summary_.line_errors[static_cast<std::size_t>(e)];
        return;
      }
      sample(s);
    });
  }

  // x-io's CSV: time (s), gyroscope (deg/s), accelerometer (g), magnetometer.
  void xio_row(const std::string& row) {
    double v[7];
    if (std::sscanf(row.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf,%lf", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5], &v[6]) != 7) {
      ++summary_.csv_bad_rows;
      return;
    }
    imu::ImuSample s;
    s.sample_time = v[0];
    s.rate_of_turn = {v[1] / kDeg, v[2] / kDeg, v[3] / kDeg};
    s.acceleration = {v[4] * imu::kStandardGravity, v[5] * imu::kStandardGravity, v[6] * imu::kStandardGravity};
    s.fields = imu::kSampleTime | imu::kRateOfTurn | imu::kAcceleration;
    sample(s);
  }

  void report(const char* protocol) const {
    const imu::AttitudeCounters& c = filter_.counters();
    const imu::Attitude& a = filter_.attitude();
    std::fprintf(stderr, "trailnav imu-decode: %s: %llu samples, %llu printed", protocol,
                 static_cast<unsigned long long>(summary_.samples), static_cast<unsigned long long>(summary_.printed));
    if (xbus_.counters().bytes > 0) {
      const imu::XbusCounters& x = xbus_.counters();
      std::fprintf(stderr, "; %llu messages, %llu bad checksums, %llu oversize, %llu bytes skipped, %llu other messages",
                   static_cast<unsigned long long>(x.messages), static_cast<unsigned long long>(x.bad_checksum),
                   static_cast<unsigned long long>(x.oversize), static_cast<unsigned long long>(x.skipped_bytes),
                   static_cast<unsigned long long>(summary_.other_messages));
    }
    std::fprintf(stderr, "\n");
    for (std::size_t i = 1; i < summary_.xsens_errors.size(); ++i) {
      if (summary_.xsens_errors[i] == 0) continue;
      std::fprintf(stderr, "  rejected MTData2 %-15s %llu\n", imu::xsens_error_name(static_cast<imu::XsensError>(i)),
                   static_cast<unsigned long long>(summary_.xsens_errors[i]));
    }
    for (std::size_t i = 2; i < summary_.line_errors.size(); ++i) {  // not_imu lines are other sentences
      if (summary_.line_errors[i] == 0) continue;
      std::fprintf(stderr, "  rejected line    %-15s %llu\n", imu::line_error_name(static_cast<imu::LineError>(i)),
                   static_cast<unsigned long long>(summary_.line_errors[i]));
    }
    if (summary_.csv_bad_rows > 0) {
      std::fprintf(stderr, "  unreadable CSV rows %llu\n", static_cast<unsigned long long>(summary_.csv_bad_rows));
    }
    if (summary_.samples == 0) return;
    std::fprintf(stderr,
                 "  attitude (%s): roll %.1f .. %.1f deg, pitch %.1f .. %.1f deg; standstill %.1f %% of samples; "
                 "gyro bias (%.3f, %.3f, %.3f) deg/s; %llu time gaps\n",
                 a.source == imu::AttitudeSource::device ? "device orientation" : "complementary filter",
                 summary_.min_roll * kDeg, summary_.max_roll * kDeg, summary_.min_pitch * kDeg,
                 summary_.max_pitch * kDeg, 100.0 * static_cast<double>(c.standstill_samples) / static_cast<double>(c.samples),
                 a.gyro_bias[0] * kDeg, a.gyro_bias[1] * kDeg, a.gyro_bias[2] * kDeg,
                 static_cast<unsigned long long>(c.gaps));
  }

 private:
  const ImuDecodeOptions& o_;
  imu::AttitudeFilter filter_;
  imu::XbusFramer xbus_;
  imu::MtData2Counters items_;
  gps::LineFramer framer_;
  Summary summary_;
};

// What the first bytes look like.
std::string sniff(std::span<const std::uint8_t> head) {
  const std::string_view text(reinterpret_cast<const char*>(head.data()), head.size());
  if (text.substr(0, 9) == "Time (s),") return "xio-csv";
  if (std::find(head.begin(), head.end(), imu::kXbusPreamble) != head.end() &&
      text.find("$TNIMU") == std::string_view::npos) {
    return "xsens";
  }
  return "line";
}

int run(const ImuDecodeOptions& o) {
  if (o.format != "csv" && o.format != "jsonl") {
    std::fprintf(stderr, "trailnav imu-decode: --format must be csv or jsonl, not '%s'\n", o.format.c_str());
    return 2;
  }
  if (o.protocol != "auto" && o.protocol != "xsens" && o.protocol != "line" && o.protocol != "xio-csv") {
    std::fprintf(stderr, "trailnav imu-decode: --protocol must be auto, xsens, line or xio-csv, not '%s'\n",
                 o.protocol.c_str());
    return 2;
  }
  if (o.every < 1) {
    std::fprintf(stderr, "trailnav imu-decode: --every must be 1 or more\n");
    return 2;
  }
  Decoder decoder(o);
  std::string protocol = o.protocol;
  std::error_code ec;
  if (std::filesystem::is_directory(o.input, ec)) {
    auto opened = recording::RecordingReader::open(o.input);
    if (!opened.reader) {
      std::fprintf(stderr, "trailnav imu-decode: %s\n", opened.error.c_str());
      return 1;
    }
    const int stream = opened.reader->stream_index(o.stream, recording::StreamKind::serial);
    if (stream < 0) {
      std::fprintf(stderr, "trailnav imu-decode: %s has no serial stream named '%s' (--stream)\n", o.input.c_str(),
                   o.stream.c_str());
      return 1;
    }
    if (protocol == "xio-csv") {
      std::fprintf(stderr, "trailnav imu-decode: a recording's serial stream is xsens or line, not xio-csv\n");
      return 2;
    }
    while (auto e = opened.reader->next()) {
      if (e->stream != stream) continue;
      if (protocol == "auto") protocol = sniff(e->payload);
      if (protocol == "xsens") {
        decoder.xsens(e->payload, e->time_ns);
      } else {
        decoder.lines(e->payload, e->time_ns);
      }
    }
  } else {
    std::ifstream in(o.input, std::ios::binary);
    if (!in) {
      std::fprintf(stderr, "trailnav imu-decode: cannot open %s\n", o.input.c_str());
      return 1;
    }
    std::vector<char> buf(1 << 16);
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    std::size_t got = static_cast<std::size_t>(in.gcount());
    const std::span<const std::uint8_t> head(reinterpret_cast<const std::uint8_t*>(buf.data()), std::min<std::size_t>(got, 512));
    if (protocol == "auto") protocol = sniff(head);
    if (protocol == "xio-csv") {
      in.clear();
      in.seekg(0);
      std::string row;
      std::getline(in, row);  // header
      while (std::getline(in, row)) decoder.xio_row(row);
    } else {
      while (got > 0) {
        const std::span<const std::uint8_t> bytes(reinterpret_cast<const std::uint8_t*>(buf.data()), got);
        if (protocol == "xsens") {
          decoder.xsens(bytes, 0);
        } else {
          decoder.lines(bytes, 0);
        }
        in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
        got = static_cast<std::size_t>(in.gcount());
      }
      const std::uint8_t eol = '\n';
      if (protocol == "line") decoder.lines(std::span(&eol, 1), 0);
    }
  }
  decoder.report(protocol.c_str());
  return 0;
}

}  // namespace

void add_imu_decode_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "imu-decode",
      "Decode an IMU's output and run it through trailnav's attitude filter: roll, pitch and yaw (degrees;\n"
      "the device's own orientation when it sends one, else the complementary filter), the bias-corrected\n"
      "yaw rate, the raw rate of turn (rad/s) and specific force (m/s^2), and whether the IMU stands still.\n"
      "Protocols: Xsens MT binary (MTData2), trailnav's $TNIMU lines (docs/imu.md), and x-io's CSV\n"
      "(gyroscope deg/s, accelerometer g). Bad checksums and malformed items are counted on stderr.\n"
      "Examples:\n"
      "  trailnav imu-decode ../shared/data/imu/xio_fusion_sensor_data.csv --every 100\n"
      "  trailnav imu-decode build/sim/meadow --filter-only --format jsonl");
  static ImuDecodeOptions o;
  cmd->add_option("input", o.input, "IMU log (binary or lines), x-io CSV, or recording directory")->required();
  cmd->add_option("--protocol", o.protocol, "auto, xsens, line or xio-csv")->capture_default_str();
  cmd->add_option("--format", o.format, "csv or jsonl")->capture_default_str();
  cmd->add_option("--stream", o.stream, "The serial stream of a recording directory")->capture_default_str();
  cmd->add_option("--every", o.every, "Print every Nth sample")->capture_default_str();
  cmd->add_flag("--filter-only", o.filter_only, "Ignore the device's orientation: roll and pitch from the filter");
  cmd->callback([&] { std::exit(run(o)); });
}

}  // namespace trailnav::cli
