#!/usr/bin/env bash
# Build (or reuse) a Debian 13 "trixie" root with Blender 4.3.2 for the e2e tests.
# Usage: tests/e2e/setup_root.sh ROOTDIR
# The root is cached: a finished root carries a stamp naming its package list, and a second
# run with the same list does nothing but return. Needs root (debootstrap, chroot).
# Mounting is NOT done here: see mounts.sh (mounted only while tests run).
set -euo pipefail
R=${1:?usage: setup_root.sh ROOTDIR}
MIRROR=${E2E_MIRROR:-http://deb.debian.org/debian}
PKGS="blender python3-numpy xvfb xauth libgl1-mesa-dri mesa-utils imagemagick xdotool
python3-pyopencl pocl-opencl-icd python3-dask python3-distributed"
PKGS=$(echo $PKGS)   # one line
STAMP="$R/.eegt-ready"

log() { echo "[setup $(date +%H:%M:%S)] $*"; }

# retry N CMD...: run CMD up to N times, waiting a little longer each time (network steps).
retry() {
    local n=$1 i; shift
    for ((i = 1; i <= n; i++)); do
        "$@" && return 0
        log "attempt $i/$n failed: $*"; sleep $((5 * i))
    done
    return 1
}

if [[ -f $STAMP && "$(cat "$STAMP")" == "$PKGS" ]]; then
    log "reusing cached root $R"; exit 0
fi
[[ $(id -u) == 0 ]] || { echo "setup_root.sh needs root (debootstrap, chroot)" >&2; exit 1; }

t0=$SECONDS
if ! command -v debootstrap >/dev/null; then
    log "installing debootstrap"
    retry 3 apt-get update -q >/dev/null
    retry 3 env DEBIAN_FRONTEND=noninteractive apt-get install -y -q debootstrap >/dev/null
fi

# A half-made root (interrupted debootstrap) is thrown away; a finished base is kept.
if [[ ! -f $R/.eegt-base ]]; then
    # never delete through a live mount
    if grep -q " $(realpath -m "$R")/" /proc/self/mounts; then
        echo "refusing to clear $R: something is mounted below it" >&2; exit 1
    fi
    rm -rf "$R"; mkdir -p "$R"
    log "debootstrap trixie (minbase) into $R"
    # debootstrap cannot resume a failed run: clear the directory before each try
    retry 3 bash -c 'rm -rf "$1"/* && debootstrap --variant=minbase trixie "$1" "$2" >"$1.debootstrap.log" 2>&1 \
        || { tail -5 "$1.debootstrap.log"; exit 1; }' _ "$R" "$MIRROR"
    touch "$R/.eegt-base"
    log "base done in $((SECONDS - t0)) s"
fi

# apt inside the chroot needs /proc and a resolv.conf; nothing else is mounted here.
cp -L /etc/resolv.conf "$R/etc/resolv.conf" 2>/dev/null || true
chmod 1777 "$R/tmp"
mountpoint -q "$R/proc" || mount -t proc proc "$R/proc"
trap 'umount "$R/proc" 2>/dev/null || true' EXIT
log "apt-get install in the root: $PKGS"
retry 3 chroot "$R" apt-get update -q >/dev/null
# (dpkg --configure -a first: a retry after an interrupted install must not trip over it)
retry 3 chroot "$R" bash -c "dpkg --configure -a && DEBIAN_FRONTEND=noninteractive \
    apt-get install -y -q --no-install-recommends $PKGS" >"$R.apt.log" 2>&1 || { tail -20 "$R.apt.log"; exit 1; }
chroot "$R" apt-get clean
chroot "$R" blender --version | head -1
echo "$PKGS" > "$STAMP"
log "root ready in $((SECONDS - t0)) s"
