#!/usr/bin/env bash
# The fuzzing campaign: each libFuzzer target for 10 million executions or
# one hour, whichever comes first, outside CI. Each starts from the inputs
# its 20-second CTest run uses (the real captures and logs, the seeds) plus
# the campaign corpus kept in the repository (tests/fuzz/corpus/TARGET), and
# what it finds new is merged back there, minimised (-merge=1 keeps only
# inputs that add coverage beyond the real files, the seeds and the corpus
# kept so far), so the kept corpus stays small. Prints, per
# target: executions, seconds, coverage (edges) and features at the end,
# the corpus kept, and findings (crashes, leaks, timeouts: the artifacts,
# left in build/fuzz-campaign/TARGET/).
#
# Usage: toolchain/fuzz-campaign.sh [--targets "A B ..."] [--runs N] [--seconds S] [--cpu C] [--jobs J]
#   --targets  which (default: every target CTest knows, label fuzz)
#   --jobs     targets run at once, each pinned to its own CPU (default 1)
#   --runs     executions per target (default 10000000)
#   --seconds  time per target (default 3600)
#   --cpu      pin to this CPU (default: none)
# Needs the release tree with its fuzzers (the README's test command builds
# them). The table goes to build/fuzz-campaign/summary.md as well.
set -euo pipefail
cd "$(dirname "$0")/.."

runs=10000000 seconds=3600 cpu="" targets="" jobs=1 summary=""
while [ $# -gt 0 ]; do
  case "$1" in
    --targets) targets=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --seconds) seconds=$2; shift 2 ;;
    --cpu) cpu=$2; shift 2 ;;
    --jobs) jobs=$2; shift 2 ;;
    --summary) summary=$2; shift 2 ;;  # (internal: one job's rows)
    -h|--help) sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "fuzz-campaign: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
case "$runs$seconds$cpu$jobs" in *[!0-9]*) echo "fuzz-campaign: --runs, --seconds, --cpu and --jobs take whole numbers" >&2; exit 2 ;; esac
tree=build/release
[ -d "$tree/fuzz" ] || { echo "fuzz-campaign: no fuzzers in $tree/fuzz: build the release tree first" >&2; exit 2; }
if [ -z "$targets" ]; then
  targets=$(ctest --test-dir "$tree" -N -L fuzz | sed -n 's/.*Test *#[0-9]*: fuzz\.\(.*\)$/\1/p' | tr '\n' ' ')
fi
[ -n "$targets" ] || { echo "fuzz-campaign: CTest knows no fuzz targets in $tree" >&2; exit 2; }

out=build/fuzz-campaign
mkdir -p "$out"
header() {
  echo "| target | executions | seconds | exec/s | cov (edges) | features | corpus kept | findings |"
  echo "|---|---|---|---|---|---|---|---|"
}
if [ "$jobs" -gt 1 ]; then
  # Deal the targets out to J jobs, job j pinned to CPU j, then one table.
  read -r -a all <<< "$targets"
  pids=()
  for ((j = 0; j < jobs; j++)); do
    mine=""
    for ((i = j; i < ${#all[@]}; i += jobs)); do mine+="${all[i]} "; done
    [ -n "$mine" ] || continue
    "$0" --targets "$mine" --runs "$runs" --seconds "$seconds" --cpu "$j" --summary "$out/summary-$j.md" &
    pids+=($!)
  done
  for p in "${pids[@]}"; do wait "$p"; done
  { header; cat "$out"/summary-[0-9]*.md; } > "$out/summary.md"
  rm -f "$out"/summary-[0-9]*.md
  cat "$out/summary.md"
  exit 0
fi
if [ -z "$summary" ]; then
  summary=$out/summary.md
  header > "$summary"
else
  : > "$summary"
fi
pin=()
[ -z "$cpu" ] || pin=(taskset -c "$cpu")

for t in $targets; do
  # The CTest command line, with the campaign's limits and corpus.
  line=$(ctest --test-dir "$tree" -N -V -R "^fuzz\.$t\$" | sed -n 's/.*Test command: //p')
  [ -n "$line" ] || { echo "fuzz-campaign: CTest has no fuzz.$t" >&2; exit 2; }
  eval "args=($line)"
  bin=${args[0]}
  work=$out/$t
  kept=tests/fuzz/corpus/$t
  rm -rf "$work" && mkdir -p "$work/corpus" "$kept"
  flags=() inputs=()
  for a in "${args[@]:1}"; do
    case "$a" in
      -max_total_time=*|-artifact_prefix=*|-seed=*) ;;
      -*) flags+=("$a") ;;
      *) [ "$a" = "$PWD/$tree/fuzz/corpus-$t" ] || [ "$a" = "$PWD/$kept" ] || inputs+=("$a") ;;
    esac
  done
  echo "fuzz-campaign: $t: $runs executions or $seconds s"
  start=$(date +%s)
  "${pin[@]}" "$bin" "${flags[@]}" -runs="$runs" -max_total_time="$seconds" -seed=1 -print_final_stats=1 \
    -artifact_prefix="$work/" "$work/corpus" "$kept" "${inputs[@]}" > "$work/log" 2>&1 || true
  took=$(( $(date +%s) - start ))
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$work/log" | tail -1)
  last=$(grep -E '^#[0-9]+' "$work/log" | tail -1)
  cov=$(echo "$last" | sed -n 's/.* cov: \([0-9]*\).*/\1/p')
  ft=$(echo "$last" | sed -n 's/.* ft: \([0-9]*\).*/\1/p')
  findings=$(find "$work" -maxdepth 1 -type f \( -name 'crash-*' -o -name 'leak-*' -o -name 'timeout-*' -o -name 'oom-*' \) | wc -l)
  # Keep what adds coverage beyond the inputs the CTest run has anyway (the
  # real files, the seeds) and the corpus kept so far: merge into a copy of
  # those, then keep only the files the merge added.
  base=$work/merge-base
  rm -rf "$base" && mkdir -p "$base"
  for i in "$kept" "${inputs[@]}"; do
    if [ -d "$i" ]; then find "$i" -type f -exec cp -t "$base" {} + ; elif [ -f "$i" ]; then cp "$i" "$base"; fi
  done
  ls "$base" | sort > "$work/before"
  # Edges only (-use_counters=0): a new hit count of a known edge is no reason to keep a file.
  "$bin" "${flags[@]}" -merge=1 -use_counters=0 "$base" "$work/corpus" > "$work/merge.log" 2>&1 || true
  ls "$base" | sort | comm -13 "$work/before" - | while read -r f; do cp "$base/$f" "$kept/"; done
  rm -rf "$base"
  size=$(find "$kept" -type f | wc -l)
  bytes=$(du -sk "$kept" | cut -f1)
  rate=$(( ${execs:-0} / (took > 0 ? took : 1) ))
  echo "| \`$t\` | ${execs:-?} | $took | $rate | ${cov:-?} | ${ft:-?} | $size files, ${bytes} KiB | $findings |" | tee -a "$summary"
done
echo "fuzz-campaign: summary in $summary; findings (if any) in $out/*/"
