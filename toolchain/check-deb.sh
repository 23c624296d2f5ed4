#!/usr/bin/env bash
# Installs the trailnav Debian package into a fresh, empty root with
# `dpkg --root`, checks its files, the unit and the config, removes and purges
# it, and checks that nothing of it is left. Touches nothing outside a
# temporary directory. Usage: toolchain/check-deb.sh [build/package/trailnav_*.deb]
set -euo pipefail

deb=${1:-$(ls build/package/trailnav_*.deb 2>/dev/null | tail -n1)}
[[ -f "$deb" ]] || { echo "check-deb: no package; build it with: cmake --workflow --preset package" >&2; exit 1; }
root=$(mktemp -d)
trap 'rm -rf "$root"' EXIT
mkdir -p "$root/var/lib/dpkg/updates" "$root/var/lib/dpkg/info" "$root/var/log"
touch "$root/var/lib/dpkg/status"

echo "check-deb: $deb"
dpkg-deb --field "$deb" Package Version Architecture Depends
# A fresh root has none of the shared libraries the package depends on: dpkg
# is told to install anyway; apt resolves them on a real system.
log=$(mktemp)
trap 'rm -rf "$root" "$log"' EXIT
dpkg --root="$root" --log=/dev/null --force-depends --force-not-root -i "$deb" >"$log" 2>&1 || { cat "$log" >&2; exit 1; }
status=$(dpkg-query --admindir="$root/var/lib/dpkg" -W -f='${Status}' trailnav)
[[ "$status" == "install ok installed" ]] || { echo "check-deb: status after install: $status" >&2; exit 1; }
for f in usr/bin/trailnavd usr/bin/trailnav usr/lib/systemd/system/trailnavd.service etc/trailnav/robot.yaml \
         etc/trailnav/cyclone.xml etc/trailnav/trailnav-robot.dbc usr/share/trailnav/robots/bench.yaml; do
  [[ -e "$root/$f" ]] || { echo "check-deb: missing /$f" >&2; exit 1; }
done
grep -q "ExecStart=/usr/bin/trailnavd --config /etc/trailnav/robot.yaml" "$root/usr/lib/systemd/system/trailnavd.service"
conffiles=$(cat "$root/var/lib/dpkg/info/trailnav.conffiles")
[[ "$conffiles" == *"/etc/trailnav/robot.yaml"* ]] || { echo "check-deb: robot.yaml is not a conffile" >&2; exit 1; }
# The unit passes systemd-analyze verify (with ExecStart pointed at the
# installed binary, which lives in the temporary root) and its exposure score.
unitdir="$root/unit-check"
mkdir -p "$unitdir"
sed "s|/usr/bin/trailnavd|$root/usr/bin/trailnavd|g" "$root/usr/lib/systemd/system/trailnavd.service" >"$unitdir/trailnavd.service"
systemd-analyze verify "$unitdir/trailnavd.service"
systemd-analyze security --offline=true "$unitdir/trailnavd.service" | tail -n1
# Fails above 2.0 (the threshold is the score times ten).
systemd-analyze security --offline=true --threshold=20 "$unitdir/trailnavd.service" >/dev/null ||
  { echo "check-deb: the unit's exposure is above 2.0" >&2; exit 1; }
rm -rf "$unitdir"
# The installed binary validates the installed config (its absolute paths,
# the terrain model's, moved under the temporary root).
sed "s|/usr/share/trailnav/|$root/usr/share/trailnav/|g" "$root/etc/trailnav/robot.yaml" >"$root/etc/trailnav/robot-check.yaml"
"$root/usr/bin/trailnavd" --config "$root/etc/trailnav/robot-check.yaml" --check
rm -f "$root/etc/trailnav/robot-check.yaml"
files=$(dpkg --root="$root" -L trailnav | wc -l)
echo "check-deb: installed $files paths"

dpkg --root="$root" --log=/dev/null --force-not-root --purge trailnav >/dev/null
left=$(cd "$root" && find . -mindepth 1 -not -path './var/lib/dpkg*' -not -path './var/log*' -type f | head)
if [[ -n "$left" ]]; then
  echo "check-deb: left after purge:" >&2
  echo "$left" >&2
  exit 1
fi
status=$(dpkg-query --admindir="$root/var/lib/dpkg" -W -f='${Status}' trailnav 2>/dev/null || echo "not known")
echo "check-deb: after purge: $status; no files left"
echo "check-deb: ok"
