#!/usr/bin/env bash
# The soak: trailnavd on the bench config fed a simulated drive replayed again
# and again in real time, its RSS, file descriptors, threads, CPU, overruns,
# real-time allocations and map latency sampled every 10 s (trailnav demo
# --soak-minutes; docs/testing.md, figures in docs/performance.md). Fails
# unless RSS and descriptors stay constant after the first minute, with no
# real-time allocation, no overrun and map latency p99 <= 5 ms.
#
# Usage: toolchain/soak.sh [MINUTES] [SCENARIO]   (default: 60 mixed-route)
# Needs a release build (cmake --workflow --preset release). Writes
# build/soak/: the recording, trailnavd's log, soak.csv. Run it on an
# otherwise quiet machine: it measures real-time behaviour.
set -euo pipefail
cd "$(dirname "$0")/.."
minutes=${1:-60}
scenario=${2:-mixed-route}
bin=build/release/bin/trailnav
[ -x "$bin" ] || { echo "soak: $bin is missing: build the release tree first (cmake --workflow --preset release)" >&2; exit 2; }
# A 120 s drive, looped: long enough that each loop holds every kind of
# ground, the junctions and the maps' full rolling memory.
exec "$bin" demo --scenario "$scenario" --seconds 120 --out build/soak --png-every 0 --domain 77 \
  --soak-minutes "$minutes" --sample-every 10
