// `trailnav imu-decode`: an IMU's byte stream (Xsens MT binary or trailnav's
// $TNIMU lines, from a log file or a recording's serial stream) or a CSV of
// x-io's format, decoded sample by sample and run through the attitude
// filter: CSV or JSON lines on stdout, counters and a summary on stderr.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "commands.hpp"
#include "trailnav/drivers/imu/attitude.hpp"
#include "trailnav/drivers/imu/stream_decoder.hpp"
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
  std::uint64_t csv_bad_rows = 0;
  double min_roll = 1e9, max_roll = -1e9, min_pitch = 1e9, max_pitch = -1e9;
};

class Decoder {
 public:
  Decoder(const ImuDecodeOptions& o, imu::ImuProtocol protocol) : o_(o), filter_(options(o)), stream_(protocol) {
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

  // Xsens binary or $TNIMU lines, by the decoder's protocol.
  void bytes(std::span<const std::uint8_t> bytes, std::int64_t time_ns) {
    const std::uint64_t device_errors = stream_.counters().device_errors;
    stream_.feed(bytes, time_ns, [&](const imu::ImuSample& s) { sample(s); });
    if (stream_.counters().device_errors != device_errors) {
      const std::uint8_t code = stream_.counters().last_device_error;
      std::fprintf(stderr, "device error 0x%02X: %s\n", code, imu::xsens_device_error_text(code));
    }
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
    const imu::ImuStreamCounters& k = stream_.counters();
    if (k.xbus.bytes > 0) {
      std::fprintf(stderr, "; %llu messages, %llu bad checksums, %llu oversize, %llu bytes skipped, %llu other messages",
                   static_cast<unsigned long long>(k.xbus.messages), static_cast<unsigned long long>(k.xbus.bad_checksum),
                   static_cast<unsigned long long>(k.xbus.oversize), static_cast<unsigned long long>(k.xbus.skipped_bytes),
                   static_cast<unsigned long long>(k.other_messages));
    }
    std::fprintf(stderr, "\n");
    for (std::size_t i = 1; i < k.xsens_rejected.size(); ++i) {
      if (k.xsens_rejected[i] == 0) continue;
      std::fprintf(stderr, "  rejected MTData2 %-15s %llu\n", imu::xsens_error_name(static_cast<imu::XsensError>(i)),
                   static_cast<unsigned long long>(k.xsens_rejected[i]));
    }
    for (std::size_t i = 2; i < k.line_rejected.size(); ++i) {  // not_imu lines are other sentences
      if (k.line_rejected[i] == 0) continue;
      std::fprintf(stderr, "  rejected line    %-15s %llu\n", imu::line_error_name(static_cast<imu::LineError>(i)),
                   static_cast<unsigned long long>(k.line_rejected[i]));
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
  imu::ImuStreamDecoder stream_;
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
  std::string protocol = o.protocol;
  std::unique_ptr<Decoder> decoder;
  auto make = [&] {
    if (!decoder) decoder = std::make_unique<Decoder>(o, protocol == "xsens" ? imu::ImuProtocol::xsens : imu::ImuProtocol::line);
  };
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
      make();
      decoder->bytes(e->payload, e->time_ns);
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
    make();
    if (protocol == "xio-csv") {
      in.clear();
      in.seekg(0);
      std::string row;
      std::getline(in, row);  // header
      while (std::getline(in, row)) decoder->xio_row(row);
    } else {
      while (got > 0) {
        const std::span<const std::uint8_t> bytes(reinterpret_cast<const std::uint8_t*>(buf.data()), got);
        decoder->bytes(bytes, 0);
        in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
        got = static_cast<std::size_t>(in.gcount());
      }
      const std::uint8_t eol = '\n';
      if (protocol == "line") decoder->bytes(std::span(&eol, 1), 0);
    }
  }
  make();  // an empty recording stream still gets its (empty) report
  decoder->report(protocol.c_str());
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
