"""The OpenCL device of a process: which one (`select_device`, EEGT_OPENCL_DEVICE), and its
context, queue and built programs, made once (`runtime()`).

Device choice: "platform:device" indices or a substring of the device or platform name;
otherwise "auto" prefers a GPU, then a CPU device, each with float64. pyopencl is imported
on first use (`import_cl`): without it, or without a usable device, `unavailable_reason()`
says why and the caller falls back to NumPy.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field

from .build import build_error, eegt_options, eegt_source

__all__ = [
    "ENV_DEVICE",
    "LOCK",
    "NO_PLATFORM_HINT",
    "Runtime",
    "import_cl",
    "list_devices",
    "pick_device",
    "runtime",
    "runtimes",
    "select_device",
    "unavailable_reason",
]

ENV_DEVICE = "EEGT_OPENCL_DEVICE"
NO_PLATFORM_HINT = (
    "install an OpenCL driver (e.g. pocl-opencl-icd), or register one with an .icd file "
    "in /etc/OpenCL/vendors or a folder named by OCL_ICD_VENDORS"
)

_device_override: str | None = None
runtimes: dict[str, Runtime] = {}  # one per device, made by `runtime()`
# A kernel every usable device compiles (`_build_fault`), and what each device said.
PROBE_SOURCE = "__kernel void probe(__global double *a) { a[get_global_id(0)] *= 2.0; }"
_build_faults: dict[str, str | None] = {}
# Runtimes, programs and solvers are made once per process; a warm-up thread
# (backends.warm_up) may be making them while a run asks for them: the run waits.
LOCK = threading.RLock()


def import_cl():
    """pyopencl, imported on first use (ImportError / OSError when it is missing or broken)."""
    import pyopencl as cl

    return cl


def select_device(spec: str | None) -> None:
    """Choose the device for later runs ("auto"/None: automatic; else as EEGT_OPENCL_DEVICE)."""
    global _device_override
    _device_override = spec or None


def _has_fp64(dev) -> bool:
    return "cl_khr_fp64" in dev.extensions.split() or bool(getattr(dev, "double_fp_config", 0))


def _all_devices(cl) -> list[tuple[str, object, object]]:
    """(id "p:d", platform, device) for every device of every platform."""
    out = []
    for pi, plat in enumerate(cl.get_platforms()):
        try:
            devs = plat.get_devices()
        except cl.Error:  # a platform with no devices raises DEVICE_NOT_FOUND
            continue
        out.extend((f"{pi}:{di}", plat, d) for di, d in enumerate(devs))
    return out


def _label(cl, plat, dev) -> str:
    kind = cl.device_type.to_string(dev.type).replace("ALL | ", "")
    extra = "" if _has_fp64(dev) else ", no float64"
    return f"{dev.name.strip()} ({plat.name.strip()}, {kind}{extra})"


def list_devices() -> list[tuple[str, str]]:
    """[(id, description)] of every OpenCL device, for a preferences menu ([] without OpenCL)."""
    try:
        cl = import_cl()
        return [(i, _label(cl, p, d)) for i, p, d in _all_devices(cl)]
    except Exception:  # no pyopencl, no loader, no platform: nothing to list
        return []


def pick_device(cl):
    """((id, platform, device), None) or (None, reason). May raise when no platform exists."""
    spec = (_device_override or os.environ.get(ENV_DEVICE, "")).strip()
    devs = _all_devices(cl)
    if not devs:
        return None, f"no OpenCL device found ({NO_PLATFORM_HINT}); using NumPy"
    if spec and spec.lower() != "auto":
        hits = [e for e in devs if e[0] == spec] or [
            e for e in devs if spec.lower() in f"{e[2].name} {e[1].name}".lower()
        ]
        if not hits:
            names = "; ".join(f"{i} {_label(cl, p, d)}" for i, p, d in devs)
            return None, f"OpenCL device {spec!r} not found (devices: {names}); using NumPy"
        entry = hits[0]
        if not _has_fp64(entry[2]):
            return None, (
                f"OpenCL device {entry[2].name.strip()} has no float64 (cl_khr_fp64), "
                "which the backend needs; using NumPy"
            )
        fault = _build_fault(cl, entry)
        return (None, _cannot_build(entry, fault)) if fault else (entry, None)
    good = [e for e in devs if _has_fp64(e[2])]
    if not good:
        names = ", ".join(d.name.strip() for _, _, d in devs)
        return None, f"no OpenCL device with float64 (cl_khr_fp64) among {names}; using NumPy"
    gpu, cpu = cl.device_type.GPU, cl.device_type.CPU
    good.sort(key=lambda e: (not e[2].type & gpu, not e[2].type & cpu))
    first = None  # the first device's fault, when none builds
    for entry in good:  # in that order, up to the first whose compiler works
        fault = _build_fault(cl, entry)
        if fault is None:
            return entry, None
        first = first or (entry, fault)
    return None, _cannot_build(*first)


def _build_fault(cl, entry) -> str | None:
    """Why this device's compiler cannot build a small float64 kernel (None: it can), tried
    once per process and device, in the device's runtime (`_runtime_of`): a driver whose
    compiler does not know the CPU it runs on lists a device that builds nothing."""
    key = _key(entry)
    with LOCK:
        if key not in _build_faults:
            try:
                cl.Program(_runtime_of(cl, entry).ctx, PROBE_SOURCE).build()
                _build_faults[key] = None
            except Exception as exc:
                _build_faults[key] = build_error(exc)
    return _build_faults[key]


def _cannot_build(entry, fault: str) -> str:
    """The one-line reason for a device whose compiler fails (`_build_fault`)."""
    dev = entry[2]
    hint = ("; the driver's compiler does not know this CPU: a newer OpenCL driver is needed"
            if "unknown target CPU" in fault else "")
    return f"OpenCL device {dev.name.strip()} cannot build kernels ({fault}{hint}); using NumPy"


def unavailable_reason() -> str | None:
    """Why no float64 OpenCL device is usable (one line), or None when one is."""
    try:
        cl = import_cl()
    except Exception as exc:  # ImportError, or OSError from a broken libOpenCL
        return f"OpenCL backend unavailable (pyopencl: {exc}); using NumPy"
    try:
        _, why = pick_device(cl)
    except Exception as exc:  # clGetPlatformIDs fails when no ICD is registered at all
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return f"no OpenCL platform ({first}; {NO_PLATFORM_HINT}); using NumPy"
    return why


@dataclass
class Runtime:
    """Context, queue and built programs of one device, shared by every run in the process."""

    cl: object
    device: object
    name: str
    ctx: object
    queue: object
    programs: dict = field(default_factory=dict)

    @property
    def is_cpu(self) -> bool:
        """A CPU device (pocl and the like), where single work-item kernels pay off."""
        return bool(self.device.type & self.cl.device_type.CPU)

    def build(self, key: str, source: str, options: list[str], what: str = "kernel"):
        """`source` built for this device once per process and `key`; a failed build is
        remembered too, so it is reported, not retried, on later runs (RuntimeError)."""
        with LOCK:
            prg = self.programs.get(key)
            if prg is None:
                try:
                    prg = self.cl.Program(self.ctx, source).build(options=options)
                except Exception as exc:
                    prg = RuntimeError(f"{what} build failed on {self.name}: {build_error(exc)}")
                self.programs[key] = prg
        if isinstance(prg, RuntimeError):
            raise prg
        return prg

    def program(self, maxn: int):
        """The EEGT kernels, built once per n-gon size class (`build.program_size`)."""
        return self.build(f"eegt MAXN={maxn}", eegt_source(), eegt_options(maxn))


def runtime() -> Runtime:
    """The cached runtime of the chosen device; RuntimeError when there is none."""
    cl = import_cl()
    try:
        entry, why = pick_device(cl)
    except Exception as exc:
        raise RuntimeError(f"no OpenCL platform ({exc})") from exc
    if entry is None:
        raise RuntimeError(why)
    return _runtime_of(cl, entry)


def _key(entry) -> str:
    """A device's key in `runtimes` and `_build_faults`."""
    dev_id, plat, dev = entry
    return f"{dev_id} {dev.name} {plat.name}"


def _runtime_of(cl, entry) -> Runtime:
    """The device's runtime, made on first use."""
    dev_id, _, dev = entry
    key = _key(entry)
    with LOCK:
        rt = runtimes.get(key)
        if rt is None:
            ctx = cl.Context([dev])
            rt = Runtime(cl, dev, f"{dev.name.strip()} [{dev_id}]", ctx, cl.CommandQueue(ctx))
            runtimes[key] = rt
    return rt
