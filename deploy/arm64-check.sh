#!/usr/bin/env bash
# Does reckon install and run on the Pi's system? An emulated check: a Debian arm64 root
# filesystem (debootstrap; the arm64 binaries run through qemu-user-static and binfmt_misc),
# reckon installed there by deploy/install.sh --no-units from aarch64 wheels only, then a short
# simulated session played through the hub and one edge per chair over Zenoh on loopback.
#
#   sudo deploy/arm64-check.sh [--root DIR] [--work DIR] [--rebuild] [--suite NAME] [--mirror URL]
#                              [--players N] [--duration S]
#
#   --root DIR    the arm64 root filesystem, built once and reused (default out/arm64-root;
#                 env RECKON_ARM64_ROOT). Its pip cache and /opt/reckon/venv stay in it, so a
#                 second run only updates them, as `install.sh` does on a Pi.
#   --work DIR    logs, the session log and the hub's recording (default out/arm64-check)
#   --rebuild     build the root filesystem again
#   --suite NAME  the Debian release (default bookworm: Python 3.11, what Raspberry Pi OS has)
#   --mirror URL  the Debian mirror (default http://deb.debian.org/debian; env RECKON_ARM64_MIRROR)
#   --players N, --duration S   the simulated game (default 2 chairs, 10 s)
#
# Runs as root (debootstrap, chroot, mounts in a private mount namespace). Installs debootstrap
# and qemu-user-static with apt-get when they are missing and registers the aarch64 binfmt
# handler when it is not (mounting binfmt_misc if needed). On an aarch64 machine nothing is
# emulated. The session is simulated on this machine (the simulator, reckon[eval], is not part of
# a venue install), with `python3 dev.py sim`. pip runs with PIP_ONLY_BINARY=:all:, so a
# dependency without an aarch64 wheel on PyPI fails the check, named. Exit 0 only when the hub
# put out live poses for every chair. deploy/README.md, "Checking the arm64 install".
set -euo pipefail

repo=$(cd "$(dirname "$0")/.." && pwd)
root=${RECKON_ARM64_ROOT:-$repo/out/arm64-root}
work=$repo/out/arm64-check
suite=bookworm
mirror=${RECKON_ARM64_MIRROR:-http://deb.debian.org/debian}
rebuild=no
players=2
duration=10

usage() {
    sed -n '7,8p' "$0" | sed 's/^#  *//' >&2
    echo "(the options: the comment at the top of $0)" >&2
    exit 2
}
while [ $# -gt 0 ]; do
    case $1 in
        --root) [ $# -ge 2 ] || usage; root=$2; shift ;;
        --work) [ $# -ge 2 ] || usage; work=$2; shift ;;
        --rebuild) rebuild=yes ;;
        --suite) [ $# -ge 2 ] || usage; suite=$2; shift ;;
        --mirror) [ $# -ge 2 ] || usage; mirror=$2; shift ;;
        --players) [ $# -ge 2 ] || usage; players=$2; shift ;;
        --duration) [ $# -ge 2 ] || usage; duration=$2; shift ;;
        -h|--help) sed -n '2,25p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) usage ;;
    esac
    shift
done
case $players in ''|*[!0-9]*) echo "$0: --players takes a number" >&2; exit 2 ;; esac
case $duration in ''|*[!0-9.]*) echo "$0: --duration takes seconds" >&2; exit 2 ;; esac

started=$SECONDS
step=setup
steps=""  # "name Ns" of every step done, for the summary

say() { printf '[%4ds] %s\n' $((SECONDS - started)) "$*"; }
fail() {  # fail REASON [LOG]: name the step and the reason, show the log's end
    echo "arm64-check: FAILED at step '$step': $1" >&2
    if [ $# -ge 2 ] && [ -s "$2" ]; then
        echo "--- last lines of $2:" >&2
        tail -n 25 "$2" >&2
        echo "---" >&2
    fi
    trap - EXIT
    exit 1
}
on_exit() {
    local rc=$?
    [ $rc -eq 0 ] || echo "arm64-check: FAILED at step '$step' (exit $rc)" >&2
}
trap on_exit EXIT
begin() { step=$1; step_started=$SECONDS; say "$1: $2"; }
done_step() { steps="$steps $step $((SECONDS - step_started))s"; }
logged() {  # logged LOG CMD...: CMD with its output in LOG
    local log=$1 rc=0
    shift
    "$@" >"$log" 2>&1 || rc=$?
    return $rc
}

[ "$(id -u)" -eq 0 ] || { echo "$0: run as root (sudo): debootstrap, chroot and mounts need it" >&2; exit 1; }
mkdir -p "$work/logs"
work=$(cd "$work" && pwd)
logs=$work/logs
root=$(mkdir -p "$(dirname "$root")" && cd "$(dirname "$root")" && pwd)/$(basename "$root")

# ----------------------------------------------------------------------------------------------
begin tools "debootstrap, qemu-user-static"
native=no
[ "$(uname -m)" = aarch64 ] && native=yes
missing=""
command -v debootstrap >/dev/null || missing="$missing debootstrap"
[ -f /usr/share/keyrings/debian-archive-keyring.gpg ] || missing="$missing debian-archive-keyring"
[ $native = yes ] || [ -x /usr/bin/qemu-aarch64-static ] || missing="$missing qemu-user-static"
command -v unshare >/dev/null || missing="$missing util-linux"
if [ -n "$missing" ]; then
    say "installing$missing"
    logged "$logs/apt.log" apt-get update -q || fail "apt-get update failed" "$logs/apt.log"
    DEBIAN_FRONTEND=noninteractive logged "$logs/apt.log" apt-get install -y -q --no-install-recommends $missing \
        || fail "apt-get install$missing failed" "$logs/apt.log"
fi
command -v python3 >/dev/null || fail "no python3 on this machine (the session is simulated here: python3 dev.py sim)"
done_step

# ----------------------------------------------------------------------------------------------
begin binfmt "aarch64 binaries through qemu-aarch64-static"
binfmt=/proc/sys/fs/binfmt_misc
if [ $native = yes ]; then
    say "this machine is aarch64: nothing to emulate"
else
    if [ ! -e $binfmt/register ]; then
        mount -t binfmt_misc binfmt_misc $binfmt 2>"$logs/binfmt.log" \
            || fail "binfmt_misc is not mounted and cannot be (a container without privileges?): on the host, \
apt-get install qemu-user-static binfmt-support, or run the container with --privileged" "$logs/binfmt.log"
    fi
    if [ -e $binfmt/qemu-aarch64 ]; then
        grep -qx enabled $binfmt/qemu-aarch64 || echo 1 >$binfmt/qemu-aarch64
    else
        # Debian's entry, flags F (the interpreter is opened now, so it works inside the chroot)
        conf=/usr/lib/binfmt.d/qemu-aarch64.conf
        [ -f $conf ] || fail "$conf is missing: is qemu-user-static installed?"
        cat $conf >$binfmt/register 2>"$logs/binfmt.log" \
            || fail "cannot register the qemu-aarch64 binfmt handler (binfmt_misc is read-only here?)" "$logs/binfmt.log"
    fi
    say "$(tr '\n' ' ' <$binfmt/qemu-aarch64 | cut -c1-80)"
fi
done_step

# ----------------------------------------------------------------------------------------------
# The root filesystem's mounts live in a mount namespace of their own (unshare): they go when the
# command ends, whatever happens, so the cached root never keeps /proc or /dev mounted and
# `rm -rf` of it can never reach the host's /dev.
in_root() {  # in_root DIR [VAR=value...] CMD...: CMD inside the arm64 root DIR
    local dir=$1
    shift
    unshare --mount --propagation private /bin/sh -euc '
        dir=$1; shift
        mount -t proc proc "$dir/proc"
        mount -t tmpfs -o mode=0755,size=8m dev "$dir/dev"
        for node in null zero full random urandom tty; do
            touch "$dir/dev/$node"; mount --bind "/dev/$node" "$dir/dev/$node"
        done
        ln -s /proc/self/fd "$dir/dev/fd"
        mkdir "$dir/dev/shm" "$dir/dev/pts"
        mount -t tmpfs -o mode=1777 shm "$dir/dev/shm"
        mount -t tmpfs -o mode=1777 tmp "$dir/tmp"
        exec chroot "$dir" /usr/bin/env -i HOME=/root LANG=C.UTF-8 TERM=dumb \
            PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin DEBIAN_FRONTEND=noninteractive "$@"
    ' sh "$dir" "$@"
}
mounted_under() { grep -q " $1[/ ]" /proc/mounts; }

begin root "Debian $suite arm64 in $root"
if [ $rebuild = yes ] && [ -e "$root" ]; then
    mounted_under "$root" && fail "something is mounted under $root: unmount it first"
    rm -rf "$root"
fi
if [ -f "$root/.reckon-arm64-root" ]; then
    say "reusing it (built $(cat "$root/.reckon-arm64-root"); --rebuild for a new one)"
else
    partial=$root.partial
    mounted_under "$partial" && fail "something is mounted under $partial: unmount it first"
    rm -rf "$partial" "$root"
    # minbase: apt, dpkg, coreutils, passwd (useradd); what install.sh installs comes along so its
    # apt-get finds it there. First stage here, second stage inside, emulated.
    say "debootstrap, first stage (downloads from $mirror)"
    logged "$logs/debootstrap.log" debootstrap --foreign --arch=arm64 --variant=minbase \
        --keyring=/usr/share/keyrings/debian-archive-keyring.gpg \
        --include=python3,python3-venv,logrotate,ca-certificates "$suite" "$partial" "$mirror" \
        || fail "debootstrap (first stage) failed" "$logs/debootstrap.log"
    if [ $native = no ]; then
        # for a binfmt entry without the F flag, which looks for its interpreter inside the root
        install -D -m 0755 /usr/bin/qemu-aarch64-static "$partial/usr/bin/qemu-aarch64-static"
    fi
    unshare --mount --propagation private chroot "$partial" /bin/true 2>"$logs/binfmt.log" \
        || fail "the root's arm64 /bin/true does not run: the qemu-aarch64 binfmt handler is not working" "$logs/binfmt.log"
    say "debootstrap, second stage (emulated: a few minutes)"
    logged "$logs/debootstrap-2.log" unshare --mount --propagation private \
        chroot "$partial" /debootstrap/debootstrap --second-stage \
        || fail "debootstrap (second stage) failed" "$logs/debootstrap-2.log"
    date -u +%Y-%m-%dT%H:%MZ >"$partial/.reckon-arm64-root"
    mv "$partial" "$root"
fi
python_version=$(in_root "$root" python3 -c 'import platform, sys; print(platform.machine(), platform.python_version()); sys.exit(sys.version_info < (3, 11))') \
    || fail "the root's python3 is older than 3.11 ($python_version): choose a newer --suite"
say "the root's python3: $python_version"
done_step

# ----------------------------------------------------------------------------------------------
begin session "a ${duration} s game of $players chairs, simulated on this machine"
session=$work/session.mcap
rm -f "$session"
logged "$logs/sim.log" python3 "$repo/dev.py" sim wheelchair --players "$players" --duration "$duration" --seed 1 \
    -o "$session" || fail "the simulator failed (python3 dev.py sim: it installs reckon[test] into .venv)" "$logs/sim.log"
say "$(tr '\r' '\n' <"$logs/sim.log" | grep -m 1 ' chairs, ' || true)"
done_step

# ----------------------------------------------------------------------------------------------
begin copy "the repository into the root (/root/reckon)"
rm -rf "$root/root/reckon" "$root/root/run"
mkdir -p "$root/root/reckon" "$root/root/run"
if git -C "$repo" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    # what git would commit: tracked and new files, not .venv, out/ or recordings (.gitignore)
    git -C "$repo" ls-files -z --cached --others --exclude-standard \
        | (cd "$repo" && while IFS= read -r -d '' file; do [ -e "$file" ] && printf '%s\0' "$file"; done) \
        | tar -C "$repo" --null -T - -cf - | tar -C "$root/root/reckon" -xf -
else
    tar -C "$repo" --exclude=./.venv --exclude=./out --exclude=./build --exclude=.git --exclude=__pycache__ \
        -cf - . | tar -C "$root/root/reckon" -xf -
fi
[ -f "$root/root/reckon/pyproject.toml" ] || fail "the copy has no pyproject.toml"
cp "$session" "$root/root/run/session.mcap"
cp /etc/resolv.conf "$root/etc/resolv.conf"  # pip resolves pypi.org from inside the root
# This machine's certificate authorities go in too: behind a TLS-inspecting proxy the root's own
# Debian bundle does not trust the package index's certificate.
host_ca=${PIP_CERT:-${SSL_CERT_FILE:-/etc/ssl/certs/ca-certificates.crt}}
[ -f "$host_ca" ] && install -D -m 0644 "$host_ca" "$root/etc/ssl/certs/reckon-host-ca.crt"
done_step

# ----------------------------------------------------------------------------------------------
begin install "deploy/install.sh --no-units, wheels only (emulated: pip takes minutes)"
install_log=$logs/install.log
ca=/etc/ssl/certs/ca-certificates.crt
[ -f "$root/etc/ssl/certs/reckon-host-ca.crt" ] && ca=/etc/ssl/certs/reckon-host-ca.crt
if ! in_root "$root" PIP_ONLY_BINARY=:all: PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_PROGRESS_BAR=off \
        PIP_ROOT_USER_ACTION=ignore PIP_CERT="$ca" SSL_CERT_FILE="$ca" \
        /bin/sh /root/reckon/deploy/install.sh --no-units >"$install_log" 2>&1; then
    # a package index that could not be reached also ends in "No matching distribution"
    if grep -q -e 'Could not fetch URL' -e 'SSLError' -e 'NewConnectionError' "$install_log"; then
        fail "pip could not reach the package index from inside the root (network or certificates)" "$install_log"
    fi
    # pip with --only-binary :all: says "No matching distribution found for NAME" for a package
    # that has no wheel for this platform (only its source)
    nowheel=$(sed -n 's/.*No matching distribution found for \([^ ;]*\).*/\1/p' "$install_log" | sort -u | tr '\n' ' ')
    [ -z "$nowheel" ] || fail "no aarch64 wheel for: ${nowheel% } (pip would have to build it from source)" "$install_log"
    fail "deploy/install.sh --no-units failed" "$install_log"
fi
# every installed distribution, and which of them are built for aarch64 (the rest are pure Python)
wheels=$(in_root "$root" /opt/reckon/venv/bin/python -c '
import importlib.metadata as metadata
names, built = set(), set()
for dist in metadata.distributions():
    name = dist.metadata["Name"]
    names.add(name)
    tags = [line.split(":", 1)[1].strip() for line in (dist.read_text("WHEEL") or "").splitlines() if line.startswith("Tag:")]
    if any("aarch64" in tag for tag in tags):
        built.add(name)
print(len(names), "distributions,", len(built), "of them built for aarch64:", *sorted(built, key=str.lower))
') || fail "cannot list the installed distributions"
say "$wheels"
echo "$wheels" >"$logs/wheels.txt"
done_step

# ----------------------------------------------------------------------------------------------
begin play "the session through the hub and $players edges inside the root, Zenoh on loopback"
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
cat >"$root/root/run/play.sh" <<'EOF'
# Inside the arm64 root: the hub listens on 127.0.0.1 (explicit endpoint, no scouting), every chair
# of the session gets an edge replaying its sensors in real time; then the hub is stopped and its
# recording checked for each chair's live poses.
set -eu
cd /root/run
bin=/opt/reckon/venv/bin
endpoint=tcp/127.0.0.1:$PORT
agents=$($bin/python -c 'import sys; from protocol.session_log import read_description; print(" ".join(a.id for a in read_description(sys.argv[1]).agents))' session.mcap)
rm -f hub.mcap ./*.log
$bin/reckon hub --venue session.mcap -o hub.mcap --listen "$endpoint" >hub.log 2>&1 &
hub=$!
edges=""
for agent in $agents; do
    timeout 900 $bin/reckon edge --agent "$agent" --source mcap://session.mcap --connect "$endpoint" \
        --wait-for 1 --wait-timeout 300 >"edge-$agent.log" 2>&1 &
    edges="$edges $!"
done
failed=""
set -- $agents
for pid in $edges; do
    wait "$pid" || failed="$failed $1"
    shift
done
kill -INT "$hub" 2>/dev/null || true
wait "$hub" || failed="$failed hub"
echo "hub: $(tail -n 1 hub.log)"
for agent in $agents; do echo "edge $agent: $(tail -n 1 "edge-$agent.log")"; done
[ -z "$failed" ] || { echo "exited with an error:$failed (their logs: out/arm64-check/logs)"; exit 1; }
poses=$($bin/python /root/reckon/deploy/arm64-poses.py session.mcap hub.mcap) || { echo "live poses: $poses"; exit 1; }
echo "live poses: $poses"
EOF
play_rc=0
in_root "$root" PORT="$port" /bin/sh /root/run/play.sh >"$logs/play.log" 2>&1 || play_rc=$?
cp "$root"/root/run/*.log "$logs/" 2>/dev/null || true
cp "$root/root/run/hub.mcap" "$work/hub.mcap" 2>/dev/null || true
[ $play_rc -eq 0 ] || fail "the session did not come through (hub and edge logs in $logs)" "$logs/play.log"
poses=$(sed -n 's/^live poses: //p' "$logs/play.log")
say "live poses per chair in the hub's recording: $poses"
done_step

trap - EXIT
echo "arm64-check: OK: Debian $suite arm64 ($python_version), reckon[hub,edge] from wheels only," \
    "live poses through the hub: $poses; $((SECONDS - started)) s ($steps )"
