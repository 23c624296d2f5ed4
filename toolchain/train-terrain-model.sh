#!/usr/bin/env bash
# Rebuilds the terrain models trained on the simulator's terrain (docs/terrain.md)
# and evaluates each on layouts and seeds it never saw:
#   board/models/terrain-sim.tnrf          VLP-16 (the simulator's default lidar)
#   board/models/terrain-sim-vlp32c.tnrf   VLP-32C
#   board/models/terrain-sim-hdl32e.tnrf   HDL-32E
#   board/models/terrain-sim-hdl64e.tnrf   HDL-64E (the thesis' lidar)
# A model learns one lidar's remissions; the tools refuse it for another.
# Needs a release build (cmake --workflow --preset release). The VLP-16 part
# takes about two minutes on two cores, each 32-laser one a few more, the
# HDL-64E part (simulating 64 lasers) about fifteen; the results are the same
# bytes each time.
# Usage: toolchain/train-terrain-model.sh [vlp16|vlp32c|hdl32e|hdl64e|all]   (default: all)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=build/release/bin/trailnav
which=${1:-all}

train() {  # data-directory lidar model-file [terrain-train options...]
  local data=$1 lidar=$2 model=$3
  shift 3
  mkdir -p "$data"
  for s in urban forest-track meadow-block; do
    [ -d "$data/$s-1" ] || "$bin" sim --scenario "$s" --seed 1 --lidar "$lidar" --quiet --out "$data/$s-1"
  done
  for s in mixed-route junctions; do
    [ -d "$data/$s-2" ] || "$bin" sim --scenario "$s" --seed 2 --lidar "$lidar" --quiet --out "$data/$s-2"
  done
  "$bin" terrain-train "$data/urban-1" "$data/forest-track-1" "$data/meadow-block-1" --seed 1 "$@" --out "$model"
  # Without --config: the cells the model says it learnt from.
  "$bin" terrain-eval "$data/mixed-route-2" "$data/junctions-2" --model "$model" --quiet
}

case "$which" in
  vlp16|all) train build/terrain-data VLP-16 board/models/terrain-sim.tnrf ;;&
  vlp32c|all) train build/terrain-data-vlp32c VLP-32C board/models/terrain-sim-vlp32c.tnrf ;;&
  hdl32e|all) train build/terrain-data-hdl32e HDL-32E board/models/terrain-sim-hdl32e.tnrf ;;&
  hdl64e|all)
    # Cells of at least 10 points within 15 m (bench-hdl64e.yaml's terrain
    # section) and 50,000 `other` cells against 40,000 of each other class:
    # chosen on the seed-2 layouts (docs/terrain.md "HDL-64E"), then checked
    # once on the seed-3 layouts below, which nothing was chosen on.
    train build/terrain-data-hdl64e HDL-64E board/models/terrain-sim-hdl64e.tnrf \
      --config board/robots/bench-hdl64e.yaml --class-cells other=50000
    for s in mixed-route junctions; do
      d=build/terrain-data-hdl64e/$s-3
      [ -d "$d" ] || "$bin" sim --scenario "$s" --seed 3 --lidar HDL-64E --quiet --out "$d"
    done
    "$bin" terrain-eval build/terrain-data-hdl64e/mixed-route-3 build/terrain-data-hdl64e/junctions-3 \
      --model board/models/terrain-sim-hdl64e.tnrf --quiet ;;
  vlp16|vlp32c|hdl32e) ;;
  *) echo "usage: $0 [vlp16|vlp32c|hdl32e|hdl64e|all]" >&2; exit 2 ;;
esac
