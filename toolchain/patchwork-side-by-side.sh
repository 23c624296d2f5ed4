#!/usr/bin/env bash
# trailnav's obstacle answers and Patchwork++'s ground segmentation side by
# side on the same labelled scan (docs/obstacles.md "On real labelled
# lidar"): both scored per point by the same code (`trailnav score-labels`:
# ground = road, parking, sidewalk, other-ground, terrain; obstacles =
# building, fence, car, truck, other-vehicle, person, bicyclist, pole,
# traffic-sign, trunk; Patchwork++'s non-ground points are its obstacles),
# and timed per scan on one core in one run, interleaved.
#
# Patchwork++ is built here from a source tree you give (its C++ core only:
# two files and Eigen, its own -O3 flags), outside the repository, with a
# small driver this script writes: it reads the .bin (x, y, z, intensity),
# runs patchwork::PatchWorkpp with its default parameters (verbose off) on a
# fresh instance per scan, and writes one answer per point.
#
# Usage: toolchain/patchwork-side-by-side.sh --source DIR [--scan SCAN.bin] [--labels L.label]
#                                            [--cpu C] [--repetitions N] [--work DIR]
#   --source       a Patchwork++ tree (its cpp/ folder inside), e.g.
#                  git -C MIRROR archive b608129 cpp | tar -x -C /tmp/patchwork-src
#   --scan/--labels default ../shared/data/semantickitti/000000.bin and .label
#   --cpu          the core both run on (default 0)
#   --repetitions  timing rounds, each both tools in turn (default 3)
#   --work         where the peer is built (default /tmp/trailnav-patchwork)
set -euo pipefail
cd "$(dirname "$0")/.."
source_dir="" scan=../shared/data/semantickitti/000000.bin labels="" cpu=0 reps=3 work=/tmp/trailnav-patchwork
while [ $# -gt 0 ]; do
  case "$1" in
    --source) source_dir=$2; shift 2 ;;
    --scan) scan=$2; shift 2 ;;
    --labels) labels=$2; shift 2 ;;
    --cpu) cpu=$2; shift 2 ;;
    --repetitions) reps=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    -h|--help) sed -n '2,22p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "patchwork-side-by-side: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[ -n "$labels" ] || labels=${scan%.bin}.label
core=$source_dir/cpp/patchworkpp
[ -f "$core/src/patchworkpp.cpp" ] && [ -f "$core/include/patchwork/patchworkpp.h" ] ||
  { echo "patchwork-side-by-side: --source DIR must hold cpp/patchworkpp/src/patchworkpp.cpp (a Patchwork++ tree)" >&2; exit 2; }
case "$(realpath "$work")/" in "$(realpath .)"/*) echo "patchwork-side-by-side: --work must be outside the repository" >&2; exit 2 ;; esac
for f in build/release/bin/trailnav build/release/bin/trailnav_cloud_bench; do
  [ -x "$f" ] || { echo "patchwork-side-by-side: no $f: build the release tree first" >&2; exit 2; }
done
[ -f /usr/include/eigen3/Eigen/Dense ] || { echo "patchwork-side-by-side: needs Eigen (apt-get install libeigen3-dev)" >&2; exit 2; }
mkdir -p "$work"

# The driver: ours, written here, linked with the peer's core.
cat > "$work/patchwork_answers.cpp" <<'CPP'
// Runs Patchwork++ on a KITTI .bin scan: one line per point, in the file's
// order, "1" for its non-ground points, "0" for its ground; and the time of
// estimateGround per scan (a fresh instance each run), median of the runs.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <vector>

#include "patchwork/patchworkpp.h"

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: patchwork_answers SCAN.bin ANSWERS.txt RUNS\n");
    return 2;
  }
  std::ifstream in(argv[1], std::ios::binary | std::ios::ate);
  if (!in) return 2;
  const auto bytes = static_cast<std::size_t>(in.tellg());
  std::vector<float> raw(bytes / 4);
  in.seekg(0);
  in.read(reinterpret_cast<char*>(raw.data()), static_cast<std::streamsize>(raw.size() * 4));
  const long n = static_cast<long>(raw.size() / 4);
  Eigen::MatrixXf cloud(n, 4);
  for (long i = 0; i < n; ++i)
    for (int k = 0; k < 4; ++k) cloud(i, k) = raw[static_cast<std::size_t>(i * 4 + k)];
  const int runs = std::max(1, std::atoi(argv[3]));
  std::vector<double> ms;
  std::vector<int> answer(static_cast<std::size_t>(n), 1);
  std::streambuf* out = std::cout.rdbuf();
  std::ostringstream quiet;
  for (int r = 0; r < runs; ++r) {
    patchwork::Params params;
    params.verbose = false;
    std::cout.rdbuf(quiet.rdbuf());  // its constructor prints
    patchwork::PatchWorkpp pw(params);
    std::cout.rdbuf(out);
    const auto t0 = std::chrono::steady_clock::now();
    pw.estimateGround(cloud);
    const Eigen::VectorXi ground = pw.getGroundIndices();
    const auto t1 = std::chrono::steady_clock::now();
    ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    if (r == 0) {
      for (Eigen::Index k = 0; k < ground.size(); ++k) answer[static_cast<std::size_t>(ground[k])] = 0;
    }
  }
  std::FILE* f = std::fopen(argv[2], "w");
  if (!f) return 2;
  for (int a : answer) std::fprintf(f, "%d\n", a);
  std::fclose(f);
  std::sort(ms.begin(), ms.end());
  std::printf("%.3f\n", ms[ms.size() / 2]);
  return 0;
}
CPP
flags="-std=c++20 -O3 -DNDEBUG -I$core/include -I/usr/include/eigen3"
if [ ! -x "$work/patchwork_answers" ] || [ "$core/src/patchworkpp.cpp" -nt "$work/patchwork_answers" ]; then
  echo "patchwork-side-by-side: building Patchwork++'s core from $source_dir in $work"
  g++ $flags -c "$core/src/patchworkpp.cpp" -o "$work/patchworkpp.o"
  g++ $flags "$work/patchwork_answers.cpp" "$work/patchworkpp.o" -o "$work/patchwork_answers"
fi

build/release/bin/trailnav obstacles "$scan" --config board/robots/kitti-car.yaml --labels-out "$work/trailnav.answers" --quiet > /dev/null
peer_ms=() ours_ms=() ours_map_ms=()
for r in $(seq 1 "$reps"); do
  peer_ms+=("$(taskset -c "$cpu" "$work/patchwork_answers" "$scan" "$work/patchwork.answers" 20)")
  line=$(taskset -c "$cpu" build/release/bin/trailnav_cloud_bench --benchmark_filter='BM_ScanToAnswers/map:./image:0' \
         --benchmark_format=csv 2>/dev/null | grep 'BM_ScanToAnswers')
  ours_ms+=("$(echo "$line" | awk -F, '/map:0/ {printf "%.3f", $3}')")
  ours_map_ms+=("$(echo "$line" | awk -F, '/map:1/ {printf "%.3f", $3}')")
done
echo
echo "scan $scan, labels $labels; both on core $cpu, $reps rounds each in turn"
echo
build/release/bin/trailnav score-labels "$work/patchwork.answers" "$labels" --title "Patchwork++ (non-ground)"
echo
build/release/bin/trailnav score-labels "$work/trailnav.answers" "$labels" --title "trailnav (board/robots/kitti-car.yaml)"
echo
cells() { printf ' %s |' "$@"; }
echo "| per scan, ms (round) |$(cells $(seq 1 "$reps"))"
echo "|---|$(printf -- '---|%.0s' $(seq 1 "$reps"))"
echo "| Patchwork++: estimateGround, median of 20 (its input already a matrix) |$(cells "${peer_ms[@]}")"
echo "| trailnav: the file's bytes to every point's answer |$(cells "${ours_ms[@]}")"
echo "| trailnav: the same and the obstacle map |$(cells "${ours_map_ms[@]}")"
