#!/usr/bin/env bash
# Runs the README's test suite several times back to back while other
# processes burn every CPU they can get, and fails if any run has a failure.
# A test that passes only on an idle machine is a defect (docs/testing.md);
# this is the proof that none is left.
#
# Usage: toolchain/loaded-suite.sh [--runs N] [--hogs N] [--preset P] [--same-session]
#   --runs N    suite runs, back to back (default 5)
#   --hogs N    CPU-burning processes beside the suite (default 2: both cores
#               of the reference machine are then contended)
#   --preset P  the CTest preset (default release: the README's command)
#   --same-session  start the hogs in the suite's own session (see below)
# The hogs run in a session of their own (setsid), as another user's job or
# a service would: the kernel schedules each session as a group. Put in the
# suite's own session, they share its group with the kernel's pseudo-terminal
# worker starved for seconds (docs/testing.md, "Loaded machine").
# Needs a built tree of that preset (cmake --workflow --preset release, or the
# README's test command). Each run's CTest log goes to build/loaded-suite/.
set -euo pipefail
cd "$(dirname "$0")/.."

runs=5 hogs=2 preset=release launcher=setsid
while [ $# -gt 0 ]; do
  case "$1" in
    --same-session) launcher=""; shift ;;
    --runs) runs=$2; shift 2 ;;
    --hogs) hogs=$2; shift 2 ;;
    --preset) preset=$2; shift 2 ;;
    -h|--help) sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "loaded-suite: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
case "$runs$hogs" in *[!0-9]*) echo "loaded-suite: --runs and --hogs take whole numbers" >&2; exit 2 ;; esac
[ -d "build/$preset" ] || { echo "loaded-suite: build/$preset is missing: build it first (cmake --workflow --preset $preset)" >&2; exit 2; }

logs=build/loaded-suite
mkdir -p "$logs"
pids=()
stop_hogs() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap stop_hogs EXIT
for _ in $(seq 1 "$hogs"); do
  # A shell loop that never sleeps: one busy process per hog.
  $launcher bash -c 'while :; do :; done' &
  pids+=("$!")
done
echo "loaded-suite: $runs runs of 'ctest --preset $preset' beside $hogs CPU hogs on $(nproc) CPUs (${launcher:-same session})"

failed_runs=0 total_failures=0
for r in $(seq 1 "$runs"); do
  start=$(date +%s)
  if ctest --preset "$preset" > "$logs/run-$r.log" 2>&1; then status=passed; else status=FAILED; fi
  took=$(( $(date +%s) - start ))
  summary=$(grep -E '^[0-9]+% tests passed' "$logs/run-$r.log" || echo "no summary")
  echo "run $r: $status in ${took}s: $summary"
  if [ "$status" = FAILED ]; then
    failed_runs=$((failed_runs + 1))
    n=$(grep -cE '^\s+[0-9]+ - .*\((Failed|Timeout|SEGFAULT|Subprocess aborted|Exception|Not Run)' "$logs/run-$r.log" || true)
    total_failures=$((total_failures + n))
    grep -E '^\s+[0-9]+ - ' "$logs/run-$r.log" | sed 's/^/    /' || true
  fi
done
echo "loaded-suite: $failed_runs of $runs runs failed, $total_failures failed tests in all (logs in $logs/)"
[ "$failed_runs" -eq 0 ]
