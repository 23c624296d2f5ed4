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
# With --small-gicp DIR (a source tree of koide3/small_gicp, e.g.
#   git -C MIRROR archive HEAD | tar -x -C /tmp/small_gicp-src)
# small_gicp is built and installed outside the repository (--work, default
# /tmp/trailnav-small-gicp) with its own flags and joins the run, on one
# thread like the others.
#
# Usage: toolchain/registration-side-by-side.sh [--small-gicp DIR] [--cpu C] [--repetitions N] [--work DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
cpu=0 reps=3 small_gicp="" work=/tmp/trailnav-small-gicp
while [ $# -gt 0 ]; do
  case "$1" in
    --cpu) cpu=$2; shift 2 ;;
    --repetitions) reps=$2; shift 2 ;;
    --small-gicp) small_gicp=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    -h|--help) sed -n '2,18p' "$0"; exit 0 ;;
    *) echo "registration-side-by-side: unknown argument '$1' (--small-gicp DIR, --cpu C, --repetitions N, --work DIR)" >&2; exit 2 ;;
  esac
done
if ! dpkg -s libpcl-dev >/dev/null 2>&1; then
  echo "registration-side-by-side: installing Debian's libpcl-dev (the peer)" >&2
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends libpcl-dev >/dev/null
fi
prefix=""
if [ -n "$small_gicp" ]; then
  [ -f "$small_gicp/include/small_gicp/registration/registration_helper.hpp" ] ||
    { echo "registration-side-by-side: $small_gicp is not a small_gicp source tree" >&2; exit 2; }
  cmake -S "$small_gicp" -B "$work/build" -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX="$work/install" \
    -DBUILD_HELPER=ON >/dev/null
  cmake --build "$work/build" -j2 >/dev/null
  cmake --install "$work/build" >/dev/null
  prefix="$work/install"
fi
cmake --preset release -DTRAILNAV_PEERS=ON -DTRAILNAV_SMALL_GICP_PREFIX="$prefix" >/dev/null
cmake --build build/release -j2 --target trailnav_registration_peers_bench
# The release tree back to its usual configuration after the run.
trap 'cmake --preset release -DTRAILNAV_PEERS=OFF -DTRAILNAV_SMALL_GICP_PREFIX= >/dev/null' EXIT
taskset -c "$cpu" build/release/bin/trailnav_registration_peers_bench \
  --benchmark_repetitions="$reps" --benchmark_report_aggregates_only=true
