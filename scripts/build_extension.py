#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Build the extension zips with Blender's own builder (shipped inside the ``bpy`` wheel).

* ``dist/eegt_blender-<version>.zip``: the pure package (NumPy only, every platform), with
  the pure-Python wheels every zip bundles: ``blender_manifest.toml``'s ``wheels`` (meshio
  and rich, for solver meshes; docs/engineers.md).
* ``--platforms``: per-platform zips that also bundle pyopencl and its dependencies for
  CPython 3.11 (Blender 4.2-5.0) and 3.13 (Blender 5.1+).
* ``--stage-wheels DIR``: only copy the manifest's wheels into DIR (a source folder that
  Blender's own ``extension build`` is run on, as the e2e tests do).

Wheels are downloaded unmodified from the package index into ``build/wheels/`` (git-ignored;
never NumPy: Blender ships it) once: later builds take them from there, offline.
Every zip is built from a copy of the package with its wheels and checked with the
builder's ``validate``.
"""

from __future__ import annotations

import argparse
import glob
import os
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Blender platform -> pip --platform tags (newest first is fine; pip takes any match).
PLATFORMS: dict[str, list[str]] = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
    "windows-x64": ["win_amd64"],
    "macos-x64": ["macosx_10_15_x86_64", "macosx_11_0_x86_64", "macosx_10_9_x86_64"],
    "macos-arm64": ["macosx_11_0_arm64", "macosx_12_0_arm64", "macosx_14_0_arm64"],
}
PYTHONS = ("3.11", "3.13")
BINARY = ("pyopencl", "siphash24")  # per platform and Python
PURE = ("pytools", "platformdirs", "typing_extensions")  # pyopencl's pure dependencies
WHEEL_DIR = os.path.join(ROOT, "build", "wheels")
# Copied into the package copy a zip is built from (everything else the manifest excludes).
IGNORE = shutil.ignore_patterns(".git", ".venv", "__pycache__", "tests", "bench", "docs",
                                "dist", "out", "build", "wheels", ".e2e-root", "scripts",
                                ".*cache*", ".hypothesis")
_WHEELS_ENTRY = re.compile(r"^wheels = \[.*?\]\n", re.MULTILINE | re.DOTALL)


def blender_ext() -> str:
    """Path of blender_ext.py inside the installed bpy wheel."""
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        sys.exit("build: the bpy module is not installed (make venv)")
    hits = glob.glob(os.path.join(os.path.dirname(spec.origin), "*", "scripts", "addons_core",
                                  "bl_pkg", "cli", "blender_ext.py"))
    if not hits:
        sys.exit("build: blender_ext.py not found in the bpy wheel")
    return sorted(hits)[-1]


def run_ext(*args: str) -> None:
    """Run the builder/validator; exit on failure."""
    cmd = [sys.executable, blender_ext(), *args]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout + proc.stderr)
        sys.exit(f"build: {' '.join(args[:1])} failed")


def manifest() -> dict:
    """The source manifest."""
    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as fh:
        return tomllib.load(fh)


def bundled_wheels(wheel_dir: str = WHEEL_DIR) -> list[str]:
    """The manifest's wheels (every zip bundles them) as files in `wheel_dir`, each
    downloaded there (the exact version its file name pins) unless already present. Exits
    with one line when one is absent and cannot be downloaded (no network)."""
    os.makedirs(wheel_dir, exist_ok=True)
    paths = []
    for entry in manifest().get("wheels", []):
        name = os.path.basename(entry)
        path = os.path.join(wheel_dir, name)
        if not os.path.isfile(path):
            dist, version = name.split("-")[:2]
            cmd = [sys.executable, "-m", "pip", "download", "-q", "--no-deps",
                   "--only-binary=:all:", "-d", wheel_dir, f"{dist}=={version}"]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if not os.path.isfile(path):
                last = (proc.stderr.strip().splitlines() or ["not found"])[-1]
                sys.exit(f"build: the bundled wheel {name} is not in {wheel_dir} and could not "
                         f"be downloaded ({last}): run scripts/build_extension.py once with "
                         "network access, or put the file there")
        paths.append(path)
    return paths


def stage_wheels(dest: str, wheels: list[str]) -> list[str]:
    """Copy `wheels` into `dest`; their manifest entries (``./wheels/NAME``)."""
    os.makedirs(dest, exist_ok=True)
    for w in wheels:
        shutil.copy2(w, dest)
    return ["./wheels/" + os.path.basename(w) for w in wheels]


def _package_copy(tmp: str, wheels: list[str], extra: str = "") -> str:
    """A copy of the package in `tmp` with `wheels` in its wheels/ folder, the manifest's
    ``wheels`` listing them and `extra` (TOML) added; its path."""
    src = os.path.join(tmp, manifest()["id"])
    shutil.copytree(ROOT, src, ignore=IGNORE)
    rel = stage_wheels(os.path.join(src, "wheels"), wheels)
    text = open(os.path.join(ROOT, "blender_manifest.toml"), encoding="utf-8").read()
    text = _WHEELS_ENTRY.sub("", text)
    head, sep, tail = text.partition("\n[permissions]")
    with open(os.path.join(src, "blender_manifest.toml"), "w", encoding="utf-8") as fh:
        fh.write(head + extra + f"\nwheels = {_toml_list(rel)}\n" + sep + tail)
    return src


def build_pure(out_dir: str, wheel_dir: str = WHEEL_DIR) -> str:
    """Build and validate the pure zip (with the manifest's wheels); returns its path."""
    m = manifest()
    path = os.path.join(out_dir, f"{m['id']}-{m['version']}.zip")
    if os.path.exists(path):
        os.remove(path)
    wheels = bundled_wheels(wheel_dir)
    with tempfile.TemporaryDirectory() as tmp:
        run_ext("build", "--source-dir", _package_copy(tmp, wheels), "--output-filepath", path)
    run_ext("validate", path)
    return path


def download_wheels(wheel_dir: str) -> list[str]:
    """pip download the pyopencl closure for every platform and Python (binary only)."""
    os.makedirs(wheel_dir, exist_ok=True)
    for py in PYTHONS:
        for plat, tags in PLATFORMS.items():
            cmd = [sys.executable, "-m", "pip", "download", "-q", "--no-deps",
                   "--only-binary=:all:", "--python-version", py,
                   "--implementation", "cp", "-d", wheel_dir]
            for tag in tags:
                cmd += ["--platform", tag]
            proc = subprocess.run(cmd + list(BINARY), capture_output=True, text=True)
            if proc.returncode != 0:
                last = (proc.stderr.strip().splitlines() or ["?"])[-1]
                print(f"build: no pyopencl wheels for {plat} / Python {py}: {last}")
    cmd = [sys.executable, "-m", "pip", "download", "-q", "--no-deps", "--only-binary=:all:",
           "-d", wheel_dir, *PURE]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr)
        sys.exit("build: cannot download " + ", ".join(PURE))
    return sorted(glob.glob(os.path.join(wheel_dir, "*.whl")))


def _toml_list(values: list[str]) -> str:
    return "[\n" + "".join(f'  "{v}",\n' for v in values) + "]"


def build_platforms(out_dir: str, wheel_dir: str) -> list[str]:
    """Per-platform zips bundling the wheels; returns their paths."""
    bundled = bundled_wheels(wheel_dir)
    names = {os.path.basename(w) for w in bundled}
    wheels = bundled + [w for w in download_wheels(wheel_dir)
                        if "numpy" not in os.path.basename(w)
                        and os.path.basename(w) not in names]
    m = manifest()
    with tempfile.TemporaryDirectory() as tmp:
        src = _package_copy(tmp, wheels, f"\nplatforms = {_toml_list(list(PLATFORMS))}\n")
        before = set(glob.glob(os.path.join(out_dir, "*.zip")))
        run_ext("build", "--source-dir", src, "--output-dir", out_dir, "--split-platforms")
        made = sorted(set(glob.glob(os.path.join(out_dir, "*.zip"))) - before
                      | set(glob.glob(os.path.join(out_dir, f"{m['id']}-{m['version']}-*.zip"))))
    for path in made:
        run_ext("validate", path)
    return made


def main(argv: list[str] | None = None) -> int:
    """Command line: build [--platforms] [--out DIR]."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "dist"))
    ap.add_argument("--platforms", action="store_true", help="also per-platform zips (network)")
    ap.add_argument("--wheels", default=WHEEL_DIR, help="the wheel download folder")
    ap.add_argument("--stage-wheels", metavar="DIR",
                    help="only copy the manifest's wheels into DIR (downloaded if needed)")
    ns = ap.parse_args(argv)
    if ns.stage_wheels:
        for rel in stage_wheels(ns.stage_wheels, bundled_wheels(ns.wheels)):
            print(rel)
        return 0
    os.makedirs(ns.out, exist_ok=True)
    print(build_pure(ns.out, ns.wheels))
    if ns.platforms:
        for path in build_platforms(ns.out, ns.wheels):
            print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
