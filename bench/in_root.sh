#!/usr/bin/env bash
# Run one command inside the e2e Blender root (Debian 13, Blender 4.3.2, Python 3.13) with
# this repository mounted at /work: the same root, lock and mounts as tests/e2e/run_e2e.sh
# (no display). Used by the batch benchmark; needs root.
#   bench/in_root.sh python3 /work/bench/batch_bench.py --files 200
set -uo pipefail
cd "$(dirname "$0")/.."
REPO=$PWD
CACHE=$REPO/.e2e-root
R=$CACHE/rootfs
[[ $(id -u) == 0 ]] || { echo "in_root: needs root (chroot, mount)"; exit 1; }
[[ $# -gt 0 ]] || { echo "usage: bench/in_root.sh CMD [ARGS...]"; exit 2; }
mkdir -p "$CACHE"
exec 9>"$CACHE/lock"  # one user of the root at a time on this machine
flock -w 3600 9 || { echo "in_root: another run holds $CACHE/lock"; exit 1; }
tests/e2e/setup_root.sh "$R" || { echo "in_root: setting the Blender root up failed"; exit 1; }

MOUNTS=()
teardown() {
    local i
    for ((i = ${#MOUNTS[@]} - 1; i >= 0; i--)); do
        umount -R "${MOUNTS[i]}" 2>/dev/null || umount -lR "${MOUNTS[i]}" 2>/dev/null ||
            echo "in_root: could not unmount ${MOUNTS[i]}"
    done
    MOUNTS=()
}
trap teardown EXIT
trap 'exit 130' INT TERM
mnt() {
    local target=$1; shift
    mountpoint -q "$target" && echo "in_root: $target already mounted (stale run?)"
    mount "$@" "$target" && MOUNTS+=("$target")
}
mkdir -p "$R/work"
mnt "$R/proc" -t proc proc
mnt "$R/sys" -t sysfs sys
mnt "$R/dev" --rbind /dev && mount --make-rslave "$R/dev"
mnt "$R/work" --bind "$REPO"
ln -sf /proc/self/mounts "$R/etc/mtab"
chmod 1777 "$R/tmp"
chroot "$R" env -i PATH=/usr/local/bin:/usr/bin:/bin LANG=C.UTF-8 HOME=/tmp "$@"
