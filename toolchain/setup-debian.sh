#!/usr/bin/env bash
# Installs everything trailnav needs to build, test and run, from Debian's own
# package registry only. Idempotent: when every package is already installed it
# asks nothing of apt and returns in well under a second.
set -euo pipefail

packages=(
  # compilers and build
  g++ cmake ninja-build pkg-config git
  # a compiler cache outside the checkout (~/.cache/ccache): a clean clone
  # compiles only what changed since the last build anywhere on the machine
  ccache
  # analysis and fuzzing (clang's libFuzzer runtime)
  clang clang-format clang-tidy libclang-rt-14-dev
  # libraries
  libeigen3-dev
  # the registration's k-d tree (perception/registration)
  libnanoflann-dev
  # Boost.Math, header-only: the χ² test of the traversability terrain models
  libboost-dev
  libsuitesparse-dev libmetis-dev
  # the peer of the pose-graph side-by-side (tests/bench/ceres_pose_graph.hpp)
  libceres-dev
  cyclonedds-dev cyclonedds-tools
  libgeographiclib-dev
  libgpiod-dev gpiod
  libpcap-dev
  # LZF: PCD point clouds' binary_compressed data (drivers/cloud)
  liblzf-dev
  libosmium2-dev libprotozero-dev zlib1g-dev libbz2-dev libexpat1-dev liblz4-dev
  libyaml-cpp-dev
  # camera images: PNG files and the cameras' MJPEG frames (drivers/camera)
  libpng-dev libturbojpeg0-dev
  libcli11-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libsystemd-dev
  # the cross-vendor test: eProsima Fast DDS (ROS 2's default middleware) and
  # its IDL generator (Java, from Debian)
  libfastrtps-dev fastddsgen openjdk-17-jre-headless
  # bench tools: SocketCAN utilities, network namespaces
  can-utils iproute2
  # the kernel tests' virtual machine (toolchain/kernel-tests.sh fetches the
  # pinned kernel itself, into a cache outside the checkout)
  qemu-system-x86 busybox-static cpio
)

missing=()
for pkg in "${packages[@]}"; do
  status=$(dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null || true)
  [[ "$status" == "install ok installed" ]] || missing+=("$pkg")
done

if ((${#missing[@]} == 0)); then
  exit 0
fi

if [[ $(id -u) -ne 0 ]]; then
  echo "setup-debian: missing packages: ${missing[*]}" >&2
  echo "setup-debian: run this script as root (or install them with sudo apt-get install)" >&2
  exit 1
fi

echo "setup-debian: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "setup-debian: done"
