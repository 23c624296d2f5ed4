#!/usr/bin/env bash
# Where trailnavd's CPU goes, thread by thread: runs `trailnav demo` with a
# lidar model and reads the exact run time of each of trailnavd's threads
# (/proc/PID/task/*/schedstat) over a window of its replay. Figures in
# docs/performance.md came from it; to compare two builds, give each its bin
# directory and alternate the runs (this VM's noise is as large as most
# differences).
#
# Usage: toolchain/thread-cpu.sh [MODEL] [WINDOW_S] [BIN_DIR] [OUT_DIR]
#   MODEL     VLP-16, VLP-32C, HDL-32E or HDL-64E (default HDL-64E)
#   WINDOW_S  seconds measured, from 8 s into the replay (default 20)
#   BIN_DIR   where trailnav and trailnavd are (default build/release/bin)
#   OUT_DIR   the demo's output (default build/thread-cpu)
# Prints one line per thread name (ms of CPU in the window, and the share of
# one core), then the demo's own whole-process figure.
set -euo pipefail
cd "$(dirname "$0")/.."
case "${1:-}" in -h|--help) sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;; esac
model=${1:-HDL-64E}
window=${2:-20}
bin=${3:-build/release/bin}
out=${4:-build/thread-cpu}
[ -x "$bin/trailnav" ] && [ -x "$bin/trailnavd" ] || { echo "thread-cpu: no trailnav and trailnavd in $bin (cmake --workflow --preset release)" >&2; exit 2; }
[[ "$window" =~ ^[0-9]+$ ]] && [ "$window" -ge 1 ] || { echo "thread-cpu: WINDOW_S must be a whole number of seconds, got '$window'" >&2; exit 2; }
seconds=$((window + 20))
rm -rf "$out"
mkdir -p "$(dirname "$out")"
"$bin/trailnav" demo --lidar "$model" --scenario mixed-route --seconds "$seconds" --png-every 0 --out "$out" > "$out.log" 2>&1 &
demo=$!
pid=""
for _ in $(seq 1 300); do
  pid=$(pgrep -f "trailnavd --config $(realpath -m "$out")" | head -1 || true)
  [ -z "$pid" ] && pid=$(pgrep -f "trailnavd --config $out" | head -1 || true)
  [ -n "$pid" ] && break
  kill -0 "$demo" 2>/dev/null || { echo "thread-cpu: the demo stopped before trailnavd started; see $out.log" >&2; exit 1; }
  sleep 1
done
[ -n "$pid" ] || { echo "thread-cpu: trailnavd did not start within 300 s; see $out.log" >&2; exit 1; }
sleep 8
sample() {  # name run-time-ns, summed over threads of one name
  for t in /proc/"$pid"/task/*; do
    printf '%s %s\n' "$(tr ' ' '_' < "$t/comm")" "$(cut -d' ' -f1 "$t/schedstat")"
  done | awk '{s[$1] += $2} END {for (k in s) print k, s[k]}'
}
before=$(sample)
sleep "$window"
after=$(sample)
wait "$demo" || true
join <(sort <<< "$before") <(sort <<< "$after") |
  awk -v w="$window" '{ms = ($3 - $2) / 1e6; total += ms; printf "%-12s %8.0f ms  %5.2f %% of one core\n", $1, ms, ms / w / 10} END {printf "%-12s %8.0f ms  %5.2f %% of one core\n", "all", total, total / w / 10}' |
  sort -k2 -n -r
grep -E "CPU over the replay|latency from" "$out.log" || true
