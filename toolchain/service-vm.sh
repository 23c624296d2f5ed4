#!/usr/bin/env bash
# Runs trailnavd as the shipped systemd unit under a real systemd, as PID 1 of
# a virtual machine (the kernel tests' pinned Debian kernel under qemu), and
# checks what the unit must still allow with all its hardening: the service
# comes up (Type=notify), its threads get SCHED_FIFO (CAP_SYS_NICE,
# LimitRTPRIO, the sched_* calls let through the system call filter) and its
# memory is locked (CAP_IPC_LOCK, LimitMEMLOCK, mlockall). Prints the
# exposure score of the same unit as well.
#
# Usage: toolchain/service-vm.sh [--bin DIR] [--keep]
#   --bin DIR  where trailnavd is (default build/release/bin)
#   --keep     keep the machine's folder and say where
#
# The machine's root is assembled from this machine's own Debian packages:
# systemd 252 (systemd, systemctl, libnss-systemd for DynamicUser), busybox,
# and trailnavd with the libraries ldd names; the daemon runs the bench robot
# (board/robots/bench.yaml: every sensor over loopback, none sending, so it
# runs and reports them stale).
set -euo pipefail
cd "$(dirname "$0")/.."

bin=build/release/bin keep=0
while [ $# -gt 0 ]; do
  case "$1" in
    --bin) bin=$2; shift 2 ;;
    --keep) keep=1; shift ;;
    -h|--help) sed -n '2,19p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "service-vm: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[ -x "$bin/trailnavd" ] || { echo "service-vm: no trailnavd in $bin: build it first" >&2; exit 2; }
for c in /lib/systemd/systemd /bin/systemctl systemd-analyze; do
  command -v "$c" > /dev/null || { echo "service-vm: needs systemd's $c (apt-get install systemd)" >&2; exit 2; }
done
cache=$(toolchain/kernel-tests.sh --prepare | tail -1)
kernel=$(ls "$cache"/image/boot/vmlinuz-*)

vm=$(mktemp -d /tmp/trailnav-service-vm.XXXXXX)
[ $keep -eq 1 ] || trap 'rm -rf "$vm"' EXIT
root=$vm/root
mkdir -p "$root"/{bin,sbin,usr/bin,proc,sys,dev,run,tmp,var/tmp,newroot,etc/systemd/system,etc/trailnav/robots,etc/trailnav/sim,etc/trailnav/models,lib/systemd,lib/x86_64-linux-gnu}
chmod 1777 "$root/tmp" "$root/var/tmp"
cp /usr/bin/busybox "$root/bin/"
for a in sh mount mkdir cp cat ls grep awk sleep poweroff switch_root echo; do ln -s busybox "$root/bin/$a"; done
cp -a /lib/systemd/systemd "$root/lib/systemd/"
# Only the units the service's default dependencies name, without what the
# host's .wants folders add to them: no journald, logind, udev or D-Bus.
mkdir -p "$root/lib/systemd/system"
for u in sysinit.target basic.target shutdown.target system.slice network-online.target network.target \
         final.target poweroff.target; do
  [ -e "/lib/systemd/system/$u" ] && cp "/lib/systemd/system/$u" "$root/lib/systemd/system/"
done
cp /bin/systemctl "$root/bin/"
cp "$bin/trailnavd" "$root/usr/bin/"
cp /lib/x86_64-linux-gnu/libnss_systemd.so.2 /lib/x86_64-linux-gnu/libnss_files.so.2 "$root/lib/x86_64-linux-gnu/" 2>/dev/null || true
for exe in "$root/lib/systemd/systemd" "$root/bin/systemctl" "$root/usr/bin/trailnavd" "$root/lib/x86_64-linux-gnu/libnss_systemd.so.2"; do
  for lib in $(ldd "$exe" | grep -o '/[^ ]*'); do
    mkdir -p "$root$(dirname "$lib")"
    [ -e "$root$lib" ] || cp -L "$lib" "$root$lib"
  done
done
# systemd's own libraries live in /lib/x86_64-linux-gnu/systemd or /usr/lib/...; ldd found them above.
cp board/robots/bench.yaml "$root/etc/trailnav/robots/"
cp board/sim/trailnav-robot.dbc "$root/etc/trailnav/sim/"
# Every model the bench configuration names (../models/X), so a new section's model is never left behind.
for m in $(grep -o '\.\./models/[^ ]*' board/robots/bench.yaml | sort -u); do
  cp "board/models/${m#../models/}" "$root/etc/trailnav/models/"
done
printf 'root:x:0:0:root:/root:/bin/sh\n' > "$root/etc/passwd"
printf 'root:x:0:\ndialout:x:20:\n' > "$root/etc/group"
printf 'passwd: files systemd\ngroup: files systemd\n' > "$root/etc/nsswitch.conf"
: > "$root/etc/machine-id"
printf 'ID=debian\nVERSION_ID=12\nPRETTY_NAME="trailnav service check"\n' > "$root/etc/os-release"

# The shipped unit, for this machine's paths.
sed -e 's|@TRAILNAVD_PATH@|/usr/bin/trailnavd|g' -e 's|@TRAILNAV_ROBOT_CONFIG@|/etc/trailnav/robots/bench.yaml|g' \
  board/systemd/trailnavd.service.in > "$root/etc/systemd/system/trailnavd.service"
echo "service-vm: exposure of the unit: $(systemd-analyze security --offline=true "$root/etc/systemd/system/trailnavd.service" | tail -n1)"

# What the machine checks, once the service has been up for a few seconds.
cat > "$root/check.sh" <<'EOF'
#!/bin/sh
out() { echo "service-vm: $*"; }
for i in $(seq 1 120); do
  [ "$(systemctl is-active trailnavd)" = active ] && break
  sleep 1
done
sleep 5
state=$(systemctl show -p ActiveState --value trailnavd)
pid=$(systemctl show -p MainPID --value trailnavd)
restarts=$(systemctl show -p NRestarts --value trailnavd)
out "trailnavd: $state, main pid $pid, restarts $restarts, status '$(systemctl show -p StatusText --value trailnavd)'"
rc=0
if [ "$state" != active ]; then
  rc=1
  # Why: the unit's own check, run by hand, prints the daemon's error (there is no journal in this machine).
  out "trailnavd --check says:"
  /usr/bin/trailnavd --config /etc/trailnav/robots/bench.yaml --check 2>&1 | sed 's/^/service-vm:   /'
fi
if [ -n "$pid" ] && [ "$pid" != 0 ]; then
  out "user: $(awk '/^Uid:/ {print $2}' /proc/$pid/status) (DynamicUser), capabilities in effect: $(awk '/^CapEff:/ {print $2}' /proc/$pid/status)"
  fifo=0 all=0
  for t in /proc/$pid/task/*; do
    all=$((all + 1))
    # stat: field 40 rt_priority, 41 policy (1 = SCHED_FIFO); the name in () has no spaces here
    set -- $(cat $t/stat)
    name=$2 prio=${40} policy=${41}
    if [ "$policy" = 1 ]; then fifo=$((fifo + 1)); out "  thread $name: SCHED_FIFO priority $prio"; fi
  done
  out "threads: $all, of them SCHED_FIFO: $fifo"
  [ $fifo -gt 0 ] || rc=1
  lck=$(awk '/^VmLck:/ {print $2}' /proc/$pid/status)
  rss=$(awk '/^VmRSS:/ {print $2}' /proc/$pid/status)
  out "locked memory: $lck kB of $rss kB resident"
  [ "${lck:-0}" -gt 0 ] || rc=1
else
  rc=1
fi
echo "@@TEST_RC=$rc@@"
poweroff -f
EOF
chmod +x "$root/check.sh"
cat > "$root/etc/systemd/system/trailnav-check.service" <<'EOF'
[Unit]
Description=checks trailnavd under its unit
After=trailnavd.service
[Service]
Type=oneshot
ExecStart=/check.sh
StandardOutput=tty
StandardError=tty
TTYPath=/dev/console
EOF
cat > "$root/etc/systemd/system/trailnav-test.target" <<'EOF'
[Unit]
Description=trailnavd and its check
Wants=trailnavd.service trailnav-check.service
EOF
# The initramfs's /init: systemd needs a root it can pivot away from, so
# everything moves to a tmpfs first.
cat > "$root/init" <<'EOF'
#!/bin/sh
mount -t tmpfs -o mode=0755 tmpfs /newroot
for d in bin sbin usr lib lib64 etc check.sh tmp var; do [ -e /$d ] && cp -a /$d /newroot/; done
mkdir -p /newroot/proc /newroot/sys /newroot/dev /newroot/run
exec switch_root /newroot /lib/systemd/systemd
EOF
chmod +x "$root/init"
(cd "$root" && find . | cpio -o -H newc 2> /dev/null | gzip -1 > "$vm/initramfs.gz")

echo "service-vm: booting $(basename "$kernel") with systemd under qemu"
set +e
timeout 900 qemu-system-x86_64 -accel tcg -m 1024 -smp 1 -nographic -no-reboot -kernel "$kernel" \
  -initrd "$vm/initramfs.gz" -append "console=ttyS0 panic=-1 quiet systemd.unit=trailnav-test.target systemd.show_status=0" < /dev/null 2>&1 |
  tr -d '\r' | tee "$vm/console.log" | grep -e 'service-vm:' -e 'trailnavd\[' -e 'Failed' -e '@@TEST_RC'
set -e
rc=$(sed -n 's/.*@@TEST_RC=\([0-9]*\)@@.*/\1/p' "$vm/console.log" | tail -1)
[ $keep -eq 0 ] || echo "service-vm: kept $vm (console.log, root/)"
[ -n "$rc" ] || { echo "service-vm: the machine stopped without a verdict (console: $vm/console.log)" >&2; exit 1; }
echo "service-vm: exit status $rc"
exit "$rc"
