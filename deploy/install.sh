#!/bin/sh
# Install reckon on a Raspberry Pi OS (64-bit) hub or edge machine, from a clone of the repository.
#
#   sudo deploy/install.sh [--hub] [--edge] [--serial] [--ble] [--no-units]
#
#   --hub       this machine runs the hub: reckon[hub] (neither --hub nor --edge: both)
#   --edge      this machine runs edges (devices, phones): reckon[edge]
#   --serial    this machine has USB serial IMUs (x-IMU3, TSND): the reckon user joins dialout
#   --ble       this machine talks to BLE IMUs or scans beacons: BlueZ, and the bluetooth group
#   --no-units  do not install the systemd units and the logrotate file (a test install)
#
# What it does (deploy/README.md says why and what comes next):
#   system user and group `reckon` (no login, home /var/lib/reckon)
#   /opt/reckon/venv       a virtual environment with reckon[hub], reckon[edge] or both from this clone
#   /opt/reckon/src        a copy of this clone's deploy/ folder (the docs the units point to)
#   /etc/reckon            venue file, zenoh/ configs, tls/ certificates, edge/<agent>.env
#   /var/lib/reckon        recordings/, spool/ (the services' only writable place)
#   /etc/systemd/system    reckon-hub.service, reckon-edge@.service, zenohd.service
#   /etc/logrotate.d/reckon, /etc/systemd/journald.conf.d/reckon.conf (the journal's bounds)
# Nothing is started: the venue file, certificates and passwords come first. Re-running updates
# the installed package and units and keeps everything under /etc/reckon and /var/lib/reckon.
set -eu

hub=no
edge=no
serial=no
ble=no
units=yes
for arg in "$@"; do
    case $arg in
        --hub) hub=yes ;;
        --edge) edge=yes ;;
        --serial) serial=yes ;;
        --ble) ble=yes ;;
        --no-units) units=no ;;
        *) echo "usage: $0 [--hub] [--edge] [--serial] [--ble] [--no-units]" >&2; exit 2 ;;
    esac
done
[ $hub = yes ] || [ $edge = yes ] || { hub=yes; edge=yes; }
if [ $edge = no ] && { [ $serial = yes ] || [ $ble = yes ]; }; then
    echo "$0: --serial and --ble are for a machine that runs edges: add --edge" >&2; exit 2
fi
# The runtime extras only (pyproject.toml): no simulator, evaluation or plotting on a venue machine.
extras=""
[ $hub = no ] || extras="hub"
[ $edge = no ] || extras="${extras:+$extras,}edge"

[ "$(id -u)" -eq 0 ] || { echo "$0: run as root (sudo)" >&2; exit 1; }
clone=$(cd "$(dirname "$0")/.." && pwd)
[ -f "$clone/pyproject.toml" ] || { echo "$0: $clone is not a reckon clone (no pyproject.toml)" >&2; exit 1; }
prefix=/opt/reckon

python3 -c 'import sys; sys.exit(sys.version_info < (3, 11))' \
    || { echo "$0: reckon needs Python 3.11 or newer (Raspberry Pi OS bookworm has 3.11)" >&2; exit 1; }

# python3-venv: the venv module; on bookworm it is a separate package
packages="python3-venv logrotate"
[ $ble = no ] || packages="$packages bluez"
# an edge's chair kernels are compiled ahead of time at install (reckon/kernels.py): numba.pycc checks for C and C++ compilers, and needs Python's headers
[ $edge = no ] || packages="$packages g++ python3-dev"
apt-get install -y --no-install-recommends $packages

if ! getent passwd reckon >/dev/null; then
    useradd --system --user-group --home-dir /var/lib/reckon --no-create-home --shell /usr/sbin/nologin reckon
fi
[ $serial = no ] || usermod -a -G dialout reckon
[ $ble = no ] || usermod -a -G bluetooth reckon

install -d -m 0755 "$prefix"
[ -x "$prefix/venv/bin/python" ] || python3 -m venv "$prefix/venv"
"$prefix/venv/bin/pip" install --upgrade pip
"$prefix/venv/bin/pip" install --upgrade "$clone[$extras]"
rm -rf "$prefix/src"
install -d -m 0755 "$prefix/src"
cp -R "$clone/deploy" "$prefix/src/deploy"

install -d -m 0750 -o root -g reckon /etc/reckon /etc/reckon/zenoh /etc/reckon/tls /etc/reckon/edge
install -d -m 0750 -o reckon -g reckon /var/lib/reckon /var/lib/reckon/recordings /var/lib/reckon/spool
[ -e /etc/reckon/edge/example.env ] || install -m 0640 -o root -g reckon "$clone/deploy/edge/example.env" /etc/reckon/edge/

if [ $units = yes ]; then
    install -m 0644 "$clone/deploy/systemd/reckon-hub.service" "$clone/deploy/systemd/reckon-edge@.service" \
        "$clone/deploy/systemd/zenohd.service" /etc/systemd/system/
    install -m 0644 "$clone/deploy/logrotate/reckon" /etc/logrotate.d/reckon
    install -d -m 0755 /etc/systemd/journald.conf.d
    install -m 0644 "$clone/deploy/journald/reckon.conf" /etc/systemd/journald.conf.d/reckon.conf
    systemctl try-restart systemd-journald.service
    systemctl daemon-reload
fi

"$prefix/venv/bin/reckon" --help >/dev/null
if [ $edge = yes ]; then
    # the services cannot write the venv: without this module each chair's edge would compile its filter itself
    "$prefix/venv/bin/python" -m reckon.kernels || echo "install.sh: the chair filter was not compiled ahead of time; chair edges will compile it at each start (about 150 MiB more each)" >&2
fi
echo "installed reckon[$extras] into $prefix/venv; next: deploy/README.md, 'Venue file, certificates, passwords'"
