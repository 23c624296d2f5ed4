#!/usr/bin/env bash
# Measures what each of trailnavd's tasks needs per lidar model, for the task
# presets (board/daemon/task_presets.cpp, docs/performance.md "Task presets"):
# `trailnav demo --lidar MODEL --scenario mixed-route` replayed into trailnavd
# at real time, RUNS times per model, nothing else running. Prints, per model
# and task, the largest CPU time of one run per period of input over all runs
# (the need; a periodic task's run longer than 90 % of its period is listed
# apart, as the VM's stall it is), the largest 99th percentile, and the overruns against the
# budgets in use (the presets' at the time of the run); per
# model the daemon's CPU over the replay (% of one core) and the map latency.
#
# Usage: toolchain/measure-task-presets.sh [--models "VLP-16 HDL-64E"] [--runs N] [--seconds S] [--summary-only]
# (--summary-only: the tables of the runs already in build/task-presets, none made)
# Needs the release tree (the README's first command builds it). Each run's
# whole output stays in build/task-presets/MODEL-RUN.txt.
set -euo pipefail
cd "$(dirname "$0")/.."

models="VLP-16 HDL-64E" runs=3 seconds=60 summary_only=0
while [ $# -gt 0 ]; do
  case "$1" in
    --models) models=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --seconds) seconds=$2; shift 2 ;;
    --summary-only) summary_only=1; shift ;;
    -h|--help) sed -n "2,13p" "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "measure-task-presets: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
case "$runs$seconds" in *[!0-9]*) echo "measure-task-presets: --runs and --seconds take whole numbers" >&2; exit 2 ;; esac
bin=build/release/bin/trailnav
[ -x "$bin" ] || { echo "measure-task-presets: $bin is missing: build the release tree first" >&2; exit 2; }
out=build/task-presets
mkdir -p "$out"

for m in $models; do
  if [ "$summary_only" = 0 ]; then
    rm -f "$out/$m"-[0-9]*.txt  # an earlier measurement's runs must not join this one's
    for ((r = 1; r <= runs; r++)); do
      f=$out/$m-$r.txt
      echo "measure-task-presets: $m, run $r of $runs ($seconds s)" >&2
      "$bin" demo --lidar "$m" --scenario mixed-route --seconds "$seconds" --png-every 0 --out "$out/$m-$r" > "$f" 2>&1 || {
        echo "measure-task-presets: the demo failed; see $f" >&2
        exit 1
      }
    done
  fi
  echo
  echo "### $m ($runs runs of $seconds s, mixed-route)"
  echo
  echo "| task | need: largest CPU of one run per period of input [ms] | largest CPU per period, p99 [ms] | longer than 90 % of the period: the VM's stalls, not needs [ms] | overruns (all runs) |"
  echo "|---|---|---|---|---|"
  # Task lines of the daemon's report: "<name> runs N overruns N ... cpu p99 X max Y ms ...".
  # A periodic task's run that took more CPU than 90 % of its period (the most
  # a preset can grant it) is not a need: on this VM it is the hypervisor
  # keeping the core while the thread ran (a 10 us task charged 28 ms), and
  # it is listed apart. The periods are the presets' rates
  # (board/daemon/task_presets.cpp, kTasks); obstacles run on events.
  cat "$out/$m"-[0-9]*.txt | awk '
    BEGIN { period["gpio"] = 5; period["lidar"] = 1; period["imu"] = 10; period["can"] = 10; period["gps"] = 10
            period["pose"] = 10; period["navigation"] = 100; period["terrain"] = 50 }
    $2 == "runs" && $4 == "overruns" {
      name = $1; ov[name] += $5
      for (i = 1; i < NF; ++i) if ($i == "cpu/period" && $(i + 1) == "p99") { p = $(i + 2); x = $(i + 4) }
      if ((name in period) && x + 0 > 0.9 * period[name]) {
        prior = (name in stall) ? stall[name] ", " : ""
        stall[name] = prior x
      } else if (!(name in need) || x + 0 > need[name] + 0) {
        need[name] = x
      }
      if (!(name in p99) || p + 0 > p99[name] + 0) p99[name] = p
      if (!(name in seen)) { seen[name] = 1; order[n++] = name }
    }
    END { for (i = 0; i < n; ++i) { t = order[i]; printf "| %s | %s | %s | %s | %d |\n", t, need[t], p99[t], (t in stall) ? stall[t] : "", ov[t] } }'
  echo
  grep -h "CPU over the replay" "$out/$m"-[0-9]*.txt | sed 's/^ */- /'
  grep -h "^4. received" "$out/$m"-[0-9]*.txt | sed -n 's/.*(latency from the revolution.s last packet: \([^)]*\)).*/- map latency \1/p'
done
