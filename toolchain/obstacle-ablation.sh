#!/usr/bin/env bash
# The ablation of the obstacle detection's cues on a labelled scan
# (docs/obstacles.md "On real labelled lidar"): each cue on its own and
# together, scored per point against SemanticKITTI labels by
# `trailnav obstacles --score-labels` (ground: road, parking, sidewalk,
# other-ground, terrain; obstacles: building, fence, car, truck,
# other-vehicle, person, bicyclist, pole, traffic-sign, trunk). Prints a
# Markdown table: precision, recall, F1, the share of each obstacle class
# found and of the ground classes taken for obstacles.
#
# Usage: toolchain/obstacle-ablation.sh [SCAN.bin LABELS.label]
#   default: ../shared/data/semantickitti/000000.bin and .label
# Needs the release tree (the README's commands build it).
set -euo pipefail
cd "$(dirname "$0")/.."
scan=${1:-../shared/data/semantickitti/000000.bin}
labels=${2:-${scan%.bin}.label}
case "${1:-}" in -h|--help) sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;; esac
bin=build/release/bin/trailnav
[ -x "$bin" ] || { echo "obstacle-ablation: no $bin: build the release tree first" >&2; exit 2; }
[ -f "$scan" ] && [ -f "$labels" ] || { echo "obstacle-ablation: need $scan and $labels" >&2; exit 2; }
dir=$(mktemp -d /tmp/trailnav-ablation.XXXXXX)
trap 'rm -rf "$dir"' EXIT

range='  features: {max_range: 80}
  map: {size: 1100}'
car='  classes: {other: {max_step_height: 0.10}}'
ground='  ground: {cell: 0.5, radius: 2.0, max_slope: 0.2, height: 0.2}'
raise_only='  ground: {cell: 0.5, radius: 2.0, max_slope: 0.2, height: 0.2, cut: false}'
cut_only='  ground: {cell: 0.5, radius: 2.0, max_slope: 0.2, height: 0.2, raise: false}'

row() {  # name, then the config's lines
  local name=$1; shift
  { echo "obstacles:"; echo "  model: PW"; for l in "$@"; do [ -n "$l" ] && echo "$l"; done; } > "$dir/c.yaml"
  "$bin" obstacles "$scan" --config "$dir/c.yaml" --score-labels "$labels" --quiet > "$dir/out.txt"
  awk -v name="$name" '
    /^\| [a-z-]+ \([0-9]+\) \|/ { split($0, f, "|"); gsub(/ /, "", f[2]); sub(/\(.*/, "", f[2]); share[f[2]] = f[6] + 0 }
    /^precision/ { p = $2; r = $4; f1 = $6; gsub(/,/, "", p); gsub(/,/, "", r); gsub(/ .*/, "", f1) }
    END {
      printf "| %s | %s | %s | **%s** | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.3f | %.3f |\n", name, p, r, f1,
        share["fence"], share["pole"], share["trunk"], share["building"], share["car"], share["traffic-sign"],
        share["terrain"], share["sidewalk"]
    }' "$dir/out.txt"
}

echo "| cues | precision | recall | F1 | fence | pole | trunk | building | car | sign | terrain taken | sidewalk taken |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|"
row "the thesis' features alone (defaults: 40 m, 5 cm steps)"
row "+ the whole scan (80 m)" "$range"
row "+ a car's 10 cm steps" "$car"
row "+ raised by the height above the ground" "$raise_only"
row "+ cut to the height above the ground" "$cut_only"
row "+ both (the height above the ground)" "$ground"
row "+ 80 m, 10 cm steps" "$range" "$car"
row "+ 80 m, the ground" "$range" "$ground"
row "+ 10 cm steps, the ground" "$car" "$ground"
row "all (board/robots/kitti-car.yaml)" "$range" "$car" "$ground"
