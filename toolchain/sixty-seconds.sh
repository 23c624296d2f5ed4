#!/usr/bin/env bash
# Issue 42's acceptance runs, back to back: the 60 s daemon tests (label
# `slow`) replay a simulated mixed-route drive into trailnavd at real time and
# check the whole process's CPU, map latency, overruns, real-time allocations
# and the maps bit for bit against the offline pipeline. This runs one of
# them RUNS times in a row and prints one line per run and a last line with
# how many passed, so that "0 overruns in 5 consecutive runs" is one command.
#
# Usage: toolchain/sixty-seconds.sh [--model VLP-16|HDL-64E] [--runs N]
#   --model  VLP-16: Trailnavd.SixtySecondsAtTheLidarRate (its own checks:
#            0 overruns, 0 real-time allocations, maps identical);
#            HDL-64E: Trailnavd.SixtySecondsOfTheHdl64eAtTheLidarRate (the same
#            and <= 15 % of one core, map latency p99 <= 5 ms). Default VLP-16.
#   --runs   how many in a row (default 5)
# Each run's whole output stays in build/sixty-seconds/MODEL-N.log. Needs the
# release tree (the README's first command builds it); nothing else should run.
set -euo pipefail
cd "$(dirname "$0")/.."
model=VLP-16 runs=5
while [ $# -gt 0 ]; do
  case "$1" in
    --model) model=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    -h|--help) sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "sixty-seconds: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
case "$model" in
  VLP-16) test=Trailnavd.SixtySecondsAtTheLidarRate ;;
  HDL-64E) test=Trailnavd.SixtySecondsOfTheHdl64eAtTheLidarRate ;;
  *) echo "sixty-seconds: --model is VLP-16 or HDL-64E, got '$model'" >&2; exit 2 ;;
esac
case "$runs" in ''|*[!0-9]*) echo "sixty-seconds: --runs takes a whole number, got '$runs'" >&2; exit 2 ;; esac
[ -d build/release ] || { echo "sixty-seconds: no build/release: build the release tree first (README)" >&2; exit 2; }
out=build/sixty-seconds
mkdir -p "$out"
passed=0
for ((r = 1; r <= runs; r++)); do
  log=$out/$model-$r.log
  if TRAILNAV_LONG_TESTS=1 ctest --test-dir build/release -R "^$test\$" -V > "$log" 2>&1; then
    verdict=passed
    passed=$((passed + 1))
  else
    verdict=FAILED
  fi
  cpu=$(grep -o "CPU over the replay [0-9.]* %" "$log" | grep -o "[0-9.]* %" || echo "? %")
  latency=$(grep -o "subscriber p50 [0-9.]* ms p99 [0-9.]* ms max [0-9.]* ms" "$log" | head -1 || echo "latency ?")
  stopped=$(grep -o "[0-9]* overruns, [0-9]* stalls, [0-9]* real-time allocations" "$log" | head -1 || echo "?")
  over=$(grep -E "^[0-9]+:   [a-z]+ +runs" "$log" | awk '{for (i = 1; i <= NF; ++i) if ($i == "overruns" && $(i + 1) > 0) printf "%s %s ", $2, $(i + 1)}')
  echo "$model run $r: $verdict; trailnavd $cpu of one core; latency $latency; $stopped${over:+ (overruns: $over)}"
done
echo "$model: $passed of $runs runs passed"
[ "$passed" = "$runs" ]
