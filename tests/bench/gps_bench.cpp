// The GPS driver's hot path: bytes of a real receiver log through the framer,
// the parser and the fix assembler. Run from the repository root:
// build/release/bin/trailnav_gps_bench
#include <benchmark/benchmark.h>

#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

#include "trailnav/drivers/gps/fix.hpp"

namespace trailnav {
namespace {

std::vector<std::uint8_t> read_log(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Items are sentences; bytes are the log's bytes.
void BM_GpsBytesToFixes(benchmark::State& state, const char* path) {
  const std::vector<std::uint8_t> bytes = read_log(path);
  std::uint64_t lines = 0, fixes = 0;
  for (auto _ : state) {
    gps::LineFramer framer;
    gps::FixAssembler assembler;
    gps::GpsFix fix;
    framer.feed(bytes, [&](std::string_view line) {
      if (assembler.add_line(line, fix)) ++fixes;
    });
    if (assembler.flush(fix)) ++fixes;
    lines += assembler.counters().lines;
    benchmark::DoNotOptimize(fix);
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(lines));
  state.SetBytesProcessed(static_cast<std::int64_t>(bytes.size()) * state.iterations());
  state.counters["fixes_per_pass"] = static_cast<double>(fixes) / static_cast<double>(state.iterations());
}
BENCHMARK_CAPTURE(BM_GpsBytesToFixes, ublox_zed_f9p, "../shared/data/nmea/ublox-zed-f9p-nmea.log");
BENCHMARK_CAPTURE(BM_GpsBytesToFixes, telit_he910, "../shared/data/nmea/telit-he910.log");

// One TPV JSON line per fix (the gps-decode output path).
void BM_GpsTpvJson(benchmark::State& state) {
  gps::GpsFix f;
  f.mode = 3;
  f.has_date = true;
  f.utc_ns = 1'782'036'840'051'597'000;
  f.lat = 48.0172;
  f.lon = 7.8425;
  f.alt_msl = 281.67;
  f.geoid_sep = 47.0;
  f.speed = 1.2;
  f.track = 87.2;
  f.sigma_lat = f.sigma_lon = 3.0;
  f.sigma_alt = 5.4;
  char buf[512];
  for (auto _ : state) benchmark::DoNotOptimize(gps::write_tpv_json(f, buf));
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_GpsTpvJson);

}  // namespace
}  // namespace trailnav

BENCHMARK_MAIN();
