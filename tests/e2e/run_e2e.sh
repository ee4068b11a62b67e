#!/usr/bin/env bash
# End-to-end tests in a real Blender 4.3.2 binary (Debian 13 root, used with chroot).
# Entry point of `make e2e`:
#   1. build or reuse the root in .e2e-root/rootfs (tests/e2e/setup_root.sh),
#   2. mount /proc, /dev, /sys and this repository (as /work) into it,
#   3. start Xvfb, run tests/e2e/e2e_tests.py with the root's python3 (3.13, NumPy 2.2),
#   4. tear everything down (stop Xvfb and wait, unmount in reverse), even on failure.
# Prints a summary ending with "N passed, M failed"; exit status 0 only when nothing failed.
# Needs root. Artifacts (screenshots, reports, logs) go to tests/e2e/artifacts/ (gitignored).
set -uo pipefail
cd "$(dirname "$0")/../.."
REPO=$PWD
CACHE=$REPO/.e2e-root
R=$CACHE/rootfs
ART=$REPO/tests/e2e/artifacts
T_START=$SECONDS

[[ $(id -u) == 0 ]] || { echo "e2e: needs root (debootstrap, chroot, mount)"; echo "0 passed, 1 failed"; exit 1; }
mkdir -p "$CACHE"

# One e2e run at a time on this machine (the root, its mounts and the display are shared).
exec 9>"$CACHE/lock"
if ! flock -w 900 9; then echo "e2e: another run holds $CACHE/lock"; echo "0 passed, 1 failed"; exit 1; fi

MOUNTS=()        # mounted paths, in mount order (unmounted in reverse)
XVFB_PID=""

teardown() {
    if [[ -n $XVFB_PID ]]; then
        kill "$XVFB_PID" 2>/dev/null; wait "$XVFB_PID" 2>/dev/null; XVFB_PID=""
    fi
    local i m
    for ((i = ${#MOUNTS[@]} - 1; i >= 0; i--)); do
        m=${MOUNTS[i]}
        umount -R "$m" 2>/dev/null || umount -lR "$m" 2>/dev/null || echo "e2e: could not unmount $m"
    done
    MOUNTS=()
}
trap teardown EXIT
trap 'exit 130' INT TERM

# --- 1. root -------------------------------------------------------------------------------
t0=$SECONDS
if [[ -n ${E2E_FRESH:-} ]]; then  # E2E_FRESH=1: throw the cached root away (time a CI run)
    grep -q " $R/" /proc/self/mounts && { echo "e2e: $R has mounts, not removing"; exit 1; }
    rm -rf "$R" "$R".*.log
fi
if ! tests/e2e/setup_root.sh "$R"; then
    echo "e2e: setting the Blender root up failed"; echo "0 passed, 1 failed"; exit 1
fi
T_SETUP=$((SECONDS - t0))

# --- 2. mounts -----------------------------------------------------------------------------
mnt() {  # mnt TARGET MOUNT-ARGS...: mount unless already mounted, remember for teardown
    local target=$1; shift
    if mountpoint -q "$target"; then echo "e2e: $target already mounted (stale run?)"; fi
    mount "$@" "$target" && MOUNTS+=("$target")
}
mkdir -p "$R/work"
mnt "$R/proc" -t proc proc
mnt "$R/sys" -t sysfs sys
mnt "$R/dev" --rbind /dev && mount --make-rslave "$R/dev"
mnt "$R/work" --bind "$REPO"
ln -sf /proc/self/mounts "$R/etc/mtab"
chmod 1777 "$R/tmp"

# Work area inside the root, fresh each run: sandboxed HOME, the source copy, outputs.
W=/tmp/eegt-e2e
rm -rf "${R:?}$W" && mkdir -p "$R$W/home"
rm -rf "$ART" && mkdir -p "$ART"
# The extension is built from the files git would ship (tracked + untracked, not ignored),
# so nothing of .venv, .e2e-root or build outputs can leak into the zip.
mkdir -p "$R$W/src"
git -c safe.directory="$REPO" ls-files -z -co --exclude-standard | while IFS= read -r -d '' f; do
    [[ -e $f ]] && printf '%s\0' "$f"; done | xargs -0 cp --parents -t "$R$W/src"
# The wheels every zip bundles (blender_manifest.toml's `wheels`) and the solver meshes made
# by Gmsh: the root has neither network nor gmsh, so both come from the host (the wheels from
# build/wheels, downloaded there once).
HOSTPY=$REPO/.venv/bin/python
if ! "$HOSTPY" scripts/build_extension.py --stage-wheels "$R$W/src/wheels" >/dev/null; then
    echo "e2e: the bundled wheels are not in build/wheels (see above)"; echo "0 passed, 1 failed"; exit 1
fi
if ! "$HOSTPY" tests/e2e/make_solver_meshes.py "$R$W/solver" >"$ART/solver_meshes.log" 2>&1; then
    echo "e2e: making the solver meshes failed (tests/e2e/artifacts/solver_meshes.log)"
fi

# --- 3. display ----------------------------------------------------------------------------
# Pick a free display: X sockets live in the (shared) abstract namespace, so check the host too.
DISP=""
for n in $(seq 91 120); do
    [[ -e /tmp/.X$n-lock || -e $R/tmp/.X$n-lock || -e /tmp/.X11-unix/X$n ]] && continue
    DISP=$n; break
done
if [[ -n $DISP ]]; then
    chroot "$R" Xvfb ":$DISP" -screen 0 1600x900x24 +extension GLX -nolisten tcp \
        >"$ART/xvfb.log" 2>&1 &
    XVFB_PID=$!
    for _ in $(seq 50); do  # wait until it answers (at most ~10 s)
        chroot "$R" env DISPLAY=":$DISP" xdotool getdisplaygeometry >/dev/null 2>&1 && break
        sleep 0.2
    done
fi

# --- 4. tests ------------------------------------------------------------------------------
t0=$SECONDS
chroot "$R" env -i PATH=/usr/local/bin:/usr/bin:/bin LANG=C.UTF-8 \
    E2E_WORK=$W E2E_DISPLAY="${DISP:+:$DISP}" E2E_ONLY="${E2E_ONLY:-}" E2E_GUI_DEBUG="${E2E_GUI_DEBUG:-}" \
    python3 -u /work/tests/e2e/e2e_tests.py 2>&1 | tee "$ART/e2e.log"
RC=${PIPESTATUS[0]}
T_TESTS=$((SECONDS - t0))

# Keep the reports and outputs of this run with the artifacts (small files only).
cp -r "$R$W/out" "$ART/out" 2>/dev/null
teardown
echo "e2e timings: root set-up ${T_SETUP} s, tests ${T_TESTS} s, total $((SECONDS - T_START)) s"
# e2e_tests.py printed "N passed, M failed" as its last line; repeat it last for CI.
tail -n 1 "$ART/e2e.log" | grep -E '^[0-9]+ passed, [0-9]+ failed$' || echo "0 passed, 1 failed"
exit "$RC"
