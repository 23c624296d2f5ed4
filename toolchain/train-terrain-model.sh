#!/usr/bin/env bash
# Rebuilds board/models/terrain-sim.tnrf, the terrain model trained on the
# simulator's terrain (docs/terrain.md), and evaluates it on layouts and seeds
# it never saw. Needs a release build (cmake --workflow --preset release).
# Takes about two minutes on two cores; the result is the same bytes each time.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=build/release/bin/trailnav
data=build/terrain-data
mkdir -p "$data"
for s in urban forest-track meadow-block; do
  [ -d "$data/$s-1" ] || "$bin" sim --scenario "$s" --seed 1 --quiet --out "$data/$s-1"
done
for s in mixed-route junctions; do
  [ -d "$data/$s-2" ] || "$bin" sim --scenario "$s" --seed 2 --quiet --out "$data/$s-2"
done
"$bin" terrain-train "$data/urban-1" "$data/forest-track-1" "$data/meadow-block-1" --seed 1 \
  --out board/models/terrain-sim.tnrf
"$bin" terrain-eval "$data/mixed-route-2" "$data/junctions-2" --model board/models/terrain-sim.tnrf --quiet
