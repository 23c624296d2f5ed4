#!/usr/bin/env bash
# trailnav's GICP and PCL's (pcl::GeneralizedIterativeClosestPoint, Debian's
# libpcl-dev) side by side on the same real KITTI pairs, in one process
# pinned to one core (tests/bench/registration_peers_bench.cpp;
# docs/registration.md "Side by side"). PCL is large (about 490 packages with
# VTK and Qt), so the project's setup does not install it and CI never builds
# the peer: this script installs it (as root, from Debian's registry),
# reconfigures the release tree with -DTRAILNAV_PEERS=ON so that the peer's
# target appears, builds it, runs it, and configures the tree back.
#
# Usage: toolchain/registration-side-by-side.sh [--cpu C] [--repetitions N]
set -euo pipefail
cd "$(dirname "$0")/.."
cpu=0 reps=3
while [ $# -gt 0 ]; do
  case "$1" in
    --cpu) cpu=$2; shift 2 ;;
    --repetitions) reps=$2; shift 2 ;;
    -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
    *) echo "registration-side-by-side: unknown argument '$1' (--cpu C, --repetitions N)" >&2; exit 2 ;;
  esac
done
if ! dpkg -s libpcl-dev >/dev/null 2>&1; then
  echo "registration-side-by-side: installing Debian's libpcl-dev (the peer)" >&2
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends libpcl-dev >/dev/null
fi
cmake --preset release -DTRAILNAV_PEERS=ON >/dev/null
cmake --build build/release -j2 --target trailnav_registration_peers_bench
# The release tree back to its usual configuration after the run.
trap 'cmake --preset release -DTRAILNAV_PEERS=OFF >/dev/null' EXIT
taskset -c "$cpu" build/release/bin/trailnav_registration_peers_bench \
  --benchmark_repetitions="$reps" --benchmark_report_aggregates_only=true
