#!/usr/bin/env bash
# Pose-graph solvers side by side: trailnav's exact solver, trailnav's SMF
# (parts of 500) and Ceres Solver (tests/bench/ceres_pose_graph.hpp), each in
# a process of its own pinned to one core, on the thesis' graphs
# (../shared/data/g2o) and on generated Manhattan worlds; one row per graph
# and solver: chi2, iterations, seconds, peak resident memory. With --cap-mb
# every solve runs in a memory cgroup of that size (the thesis' Fig. 3.6
# protocol: a machine with that much memory); a solver the kernel kills
# there is reported as killed.
#
# Usage: toolchain/slam-side-by-side.sh [--sizes "20000 200000"] [--thesis] [--cap-mb M] [--cpu C] [--seed S]
#   --sizes   generated Manhattan worlds (poses), default none
#   --thesis  also the thesis' graphs (default when --sizes is not given)
#   --cap-mb  memory cap per solve, MiB (cgroup v1 memory or v2 memory.max; needs root)
#   --cpu     the core to pin to (default 1)
# Needs the release tree (trailnav, trailnav_ceres_pose_graph). Generated
# worlds are cached in build/slam-worlds/. Rows go to build/slam-side-by-side.md.
set -euo pipefail
cd "$(dirname "$0")/.."
sizes="" thesis=0 cap="" cpu=1 seed=1
while [ $# -gt 0 ]; do
  case "$1" in
    --sizes) sizes=$2; shift 2 ;;
    --thesis) thesis=1; shift ;;
    --cap-mb) cap=$2; shift 2 ;;
    --cpu) cpu=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    -h|--help) sed -n '2,19p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "slam-side-by-side: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[ -n "$sizes" ] || thesis=1
bin=build/release/bin
for b in trailnav trailnav_ceres_pose_graph; do
  [ -x "$bin/$b" ] || { echo "slam-side-by-side: $bin/$b is missing (cmake --workflow --preset release; Ceres: libceres-dev)" >&2; exit 2; }
done
graphs=()
if [ "$thesis" = 1 ]; then
  for f in intel_suger ETHCampus_suger m3500 sphere2500 tinyGrid3D; do graphs+=("../shared/data/g2o/se-sync_$f.g2o"); done
fi
mkdir -p build/slam-worlds
for n in $sizes; do
  w=build/slam-worlds/manhattan-$n-seed$seed.g2o
  [ -s "$w" ] || "$bin/trailnav" pose-graph generate --world manhattan --nodes "$n" --seed "$seed" --out "$w" >&2
  graphs+=("$w")
done

# The cgroup a capped solve runs in.
group=""
if [ -n "$cap" ]; then
  if [ -f /sys/fs/cgroup/cgroup.controllers ]; then
    group=/sys/fs/cgroup/trailnav-slam-cap
    mkdir -p "$group"
    echo "${cap}M" > "$group/memory.max"
    echo 0 > "$group/memory.swap.max" 2>/dev/null || true
    procs=$group/cgroup.procs
  else
    group=/sys/fs/cgroup/memory/trailnav-slam-cap
    mkdir -p "$group"
    echo "${cap}M" > "$group/memory.limit_in_bytes"
    procs=$group/tasks
  fi
fi

run() {  # prints the solver's JSON line, or {"killed": true}
  local out rc
  if [ -n "$group" ]; then
    out=$(sh -c 'echo $$ > "$1"; shift; exec "$@"' sh "$procs" taskset -c "$cpu" "$@" 2>/dev/null) && rc=0 || rc=$?
  else
    out=$(taskset -c "$cpu" "$@" 2>/dev/null) && rc=0 || rc=$?
  fi
  if [ "$rc" -ne 0 ] || [ -z "$out" ]; then echo "{\"killed\": true, \"rc\": $rc}"; else echo "$out"; fi
}

table=build/slam-side-by-side.md
{
  echo "| graph | solver | chi2 | iterations | seconds | peak MiB |"
  echo "|---|---|---|---|---|---|"
} | tee "$table"
for g in "${graphs[@]}"; do
  name=$(basename "$g" .g2o)
  for solver in exact smf ceres; do
    if [ "$solver" = ceres ]; then
      line=$(run "$bin/trailnav_ceres_pose_graph" "$g")
    else
      line=$(run "$bin/trailnav" pose-graph optimize "$g" --method "$solver" --report json --quiet)
    fi
    echo "$line" | python3 -c '
import json, sys
name, solver, cap = sys.argv[1], sys.argv[2], sys.argv[3]
d = json.loads(sys.stdin.read())
if d.get("killed"):
    where = ", cap %s MiB" % cap if cap else ""
    print("| %s | %s | killed (exit %d%s) | | | |" % (name, solver, d["rc"], where))
else:
    print("| %s | %s | %.4f | %d | %.2f | %.1f |" % (name, solver, d["chi2"], d["iterations"], d["seconds"], d["peak_bytes"] / 1048576))
' "$name" "$solver" "$cap" | tee -a "$table"
  done
done
[ -z "$group" ] || rmdir "$group" 2>/dev/null || true
echo "slam-side-by-side: rows in $table" >&2
