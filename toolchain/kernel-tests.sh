#!/usr/bin/env bash
# Runs the drivers against real kernel devices: boots Debian's kernel under
# qemu-system-x86_64 (software emulation: no KVM needed) with an initramfs
# that holds busybox, the modules vcan, can-raw, gpio-sim and the V4L2 test
# driver vivid (with the media modules it needs), iproute2's `ip`
# the test binary and trailnavd, runs the binary there and returns its exit
# status.
#
# Usage: toolchain/kernel-tests.sh [--binary PATH] [--daemon PATH] [--filter GTEST_FILTER] [--keep] [--prepare]
#   --binary PATH  the test binary (default build/release/bin/trailnav_kernel_tests)
#   --daemon PATH  trailnavd, which the host clock test runs (default build/release/bin/trailnavd)
#   --filter F     run only these tests (--gtest_filter)
#   --keep         keep the machine's folder (initramfs, console log) and say where
#   --prepare      only fetch and build what the machine needs, print the cache
#                  folder and stop (toolchain/service-vm.sh uses it)
#
# Everything comes from Debian's packages, pinned and cached outside the
# repository ($TRAILNAV_KERNEL_CACHE, default /var/cache/trailnav/kernel):
#   - the kernel: linux-image-6.1.0-50-amd64 6.1.176-1 (bookworm 12.13), only
#     unpacked there, never installed on this machine;
#   - gpio-sim, which Debian's kernel does not build (CONFIG_GPIO_SIM off):
#     compiled out of tree from linux-source-6.1 of the same version against
#     linux-headers-6.1.0-50-amd64 (installed: headers only), with the
#     interrupt simulator it needs (CONFIG_IRQ_SIM, also off) compiled into
#     the same module;
#   - qemu-system-x86, busybox-static, cpio, iproute2 (installed).
# A first run downloads 220 MB and takes a minute or two; a cached one boots
# in about ten seconds. Set TRAILNAV_KERNEL_VERSION=ABI:VERSION (e.g.
# 6.1.0-50:6.1.176-1) for another kernel of bookworm's archive.
set -euo pipefail
cd "$(dirname "$0")/.."

binary=build/release/bin/trailnav_kernel_tests daemon=build/release/bin/trailnavd filter="" keep=0 prepare=0
while [ $# -gt 0 ]; do
  case "$1" in
    --binary) binary=$2; shift 2 ;;
    --daemon) daemon=$2; shift 2 ;;
    --filter) filter=$2; shift 2 ;;
    --keep) keep=1; shift ;;
    --prepare) prepare=1; shift ;;
    -h|--help) sed -n '2,27p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "kernel-tests: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[ $prepare -eq 1 ] || [ -x "$binary" ] || { echo "kernel-tests: no test binary at $binary: build it first (cmake --build build/release)" >&2; exit 2; }
[ $prepare -eq 1 ] || [ -x "$daemon" ] || { echo "kernel-tests: no trailnavd at $daemon: build it first (cmake --build build/release)" >&2; exit 2; }

pin=${TRAILNAV_KERNEL_VERSION:-6.1.0-50:6.1.176-1}
abi=${pin%%:*} version=${pin#*:}
kver=$abi-amd64
cache=${TRAILNAV_KERNEL_CACHE:-/var/cache/trailnav/kernel}/$kver-$version
say() { echo "kernel-tests: $*"; }

# Packages on this machine (as root, like the project's setup script).
need=()
for p in qemu-system-x86:qemu-system-x86_64 busybox-static:busybox cpio:cpio iproute2:ip; do
  command -v "${p#*:}" > /dev/null || need+=("${p%%:*}")
done
if [ ${#need[@]} -gt 0 ]; then
  [ "$(id -u)" -eq 0 ] || { echo "kernel-tests: needs ${need[*]} (apt-get install, as root)" >&2; exit 2; }
  say "installing ${need[*]}"
  DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${need[@]}" > /dev/null
fi

# The pinned kernel, headers and source: downloaded once.
mkdir -p "$cache/debs"
debs=("linux-image-$kver=$version" "linux-headers-$kver=$version" "linux-headers-$abi-common=$version"
      "linux-kbuild-6.1=$version" "linux-source-6.1=$version")
if [ ! -f "$cache/debs/complete" ]; then
  say "downloading Debian's kernel $kver $version (once)"
  (cd "$cache/debs" && apt-get download "${debs[@]}" 2> >(grep -v "unsandboxed" >&2)) || {
    echo "kernel-tests: Debian's archive does not have $kver $version (any more?): set TRAILNAV_KERNEL_VERSION to one it has (apt-cache madison linux-image-amd64)" >&2
    exit 2
  }
  touch "$cache/debs/complete"
fi
if [ ! -f "$cache/image/boot/vmlinuz-$kver" ]; then
  dpkg-deb -x "$cache"/debs/linux-image-"$kver"_*.deb "$cache/image"
fi
modules=$cache/image/lib/modules/$kver/kernel

# gpio-sim, built out of tree once.
if [ ! -f "$cache/gpio-sim/gpio-sim.ko" ]; then
  if [ ! -d "/usr/src/linux-headers-$kver" ]; then
    [ "$(id -u)" -eq 0 ] || { echo "kernel-tests: needs linux-headers-$kver (as root)" >&2; exit 2; }
    say "installing linux-headers-$kver (headers only)"
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
      "$cache"/debs/linux-headers-*.deb "$cache"/debs/linux-kbuild-*.deb > /dev/null
  fi
  say "building gpio-sim from linux-source-6.1 $version"
  rm -rf "$cache/src" "$cache/gpio-sim" && mkdir -p "$cache/src" "$cache/gpio-sim"
  dpkg-deb --fsys-tarfile "$cache"/debs/linux-source-6.1_*.deb | tar -xO ./usr/src/linux-source-6.1.tar.xz |
    tar -xJ -C "$cache/src" linux-source-6.1/drivers/gpio/gpio-sim.c linux-source-6.1/drivers/gpio/gpiolib.h \
      linux-source-6.1/kernel/irq/irq_sim.c
  cp "$cache/src/linux-source-6.1/drivers/gpio/gpio-sim.c" "$cache/gpio-sim/gpio-sim-main.c"
  cp "$cache/src/linux-source-6.1/drivers/gpio/gpiolib.h" "$cache/src/linux-source-6.1/kernel/irq/irq_sim.c" "$cache/gpio-sim/"
  # irq_to_desc() is not exported to modules; generic_handle_irq() does the same from a module.
  sed -i 's/handle_simple_irq(irq_to_desc(irqnum));/generic_handle_irq(irqnum);/' "$cache/gpio-sim/irq_sim.c"
  grep -q 'generic_handle_irq(irqnum);' "$cache/gpio-sim/irq_sim.c" || { echo "kernel-tests: irq_sim.c of $version is not as expected" >&2; exit 1; }
  printf 'obj-m := gpio-sim.o\ngpio-sim-y := gpio-sim-main.o irq_sim.o\n' > "$cache/gpio-sim/Kbuild"
  make -s -C "/usr/src/linux-headers-$kver" M="$cache/gpio-sim" modules > "$cache/gpio-sim/build.log" 2>&1 || {
    cat "$cache/gpio-sim/build.log" >&2; exit 1; }
fi

if [ $prepare -eq 1 ]; then
  echo "$cache"
  exit 0
fi

# The machine's root: busybox, modules, ip, the test binary and their libraries.
vm=$(mktemp -d /tmp/trailnav-kernel-vm.XXXXXX)
[ $keep -eq 1 ] || trap 'rm -rf "$vm"' EXIT
root=$vm/root
mkdir -p "$root"/{bin,sbin,proc,sys,dev,tmp,mods,work/board/sim}
cp /usr/bin/busybox "$root/bin/"
for a in sh mount mkdir cat echo insmod rmmod poweroff sleep; do ln -s busybox "$root/bin/$a"; done
cp "$modules/fs/configfs/configfs.ko" "$modules/net/can/can.ko" "$modules/net/can/can-raw.ko" \
   "$modules/drivers/net/can/dev/can-dev.ko" "$modules/drivers/net/can/vcan.ko" "$cache/gpio-sim/gpio-sim.ko" "$root/mods/"
# vivid and what it needs, in the order they are loaded below.
media="mc videodev videobuf2-common videobuf2-v4l2 videobuf2-memops videobuf2-vmalloc videobuf2-dma-contig v4l2-dv-timings v4l2-tpg rc-core cec vivid"
for m in $media; do
  f=$(find "$modules/drivers/media" -name "$m.ko" | head -1)
  [ -n "$f" ] || { echo "kernel-tests: $kver has no $m.ko" >&2; exit 1; }
  cp "$f" "$root/mods/"
done
cp "$(command -v ip)" "$root/sbin/ip"
cp "$binary" "$root/bin/trailnav_kernel_tests"
cp "$daemon" "$root/bin/trailnavd"
cp board/sim/trailnav-robot.dbc "$root/work/board/sim/"
for exe in "$root/sbin/ip" "$root/bin/trailnav_kernel_tests" "$root/bin/trailnavd"; do
  for lib in $(ldd "$exe" | grep -o '/[^ ]*'); do
    mkdir -p "$root$(dirname "$lib")"
    [ -e "$root$lib" ] || cp -L "$lib" "$root$lib"
  done
done
cat > "$root/init" <<EOF
#!/bin/sh
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t devtmpfs dev /dev
for m in configfs can can-raw can-dev vcan gpio-sim $media; do
  args=""
  [ "\$m" = vivid ] && args="n_devs=1 node_types=0x1 num_inputs=1 input_types=0"
  insmod /mods/\$m.ko \$args || { echo "kernel-tests: insmod \$m failed"; echo "@@TEST_RC=3@@"; poweroff -f; }
done
mount -t configfs none /sys/kernel/config
mount -t tmpfs tmp /tmp
/sbin/ip link set lo up
cd /work
TRAILNAV_KERNEL_VM=1 TRAILNAVD=/bin/trailnavd /bin/trailnav_kernel_tests --gtest_color=no ${filter:+--gtest_filter=$filter}
echo "@@TEST_RC=\$?@@"
poweroff -f
EOF
chmod +x "$root/init"
(cd "$root" && find . | cpio -o -H newc 2> /dev/null | gzip -1 > "$vm/initramfs.gz")

say "booting $kver under qemu (software emulation)"
set +e
timeout 600 qemu-system-x86_64 -accel tcg -m 512 -smp 1 -nographic -no-reboot \
  -kernel "$cache/image/boot/vmlinuz-$kver" -initrd "$vm/initramfs.gz" \
  -append "console=ttyS0 quiet panic=-1" < /dev/null 2>&1 | tr -d '\r' | tee "$vm/console.log" |
  grep -v -e '^Booting from' -e 'reboot: Power down' | sed -e 's/\x1b\[[0-9;?]*[a-zA-Z]//g' -e 's/^c//'
set -e
rc=$(sed -n 's/.*@@TEST_RC=\([0-9]*\)@@.*/\1/p' "$vm/console.log" | tail -1)
[ $keep -eq 0 ] || say "kept $vm (console.log, initramfs.gz, root/)"
if [ -z "$rc" ]; then
  echo "kernel-tests: the machine stopped without the tests' exit status (console: $vm/console.log)" >&2
  exit 1
fi
say "exit status $rc"
exit "$rc"
