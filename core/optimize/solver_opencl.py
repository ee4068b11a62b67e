"""The global stage's L-BFGS on an OpenCL device, bit-identical to the host solver.

`OpenCLLbfgs` is a drop-in for `solver.lbfgs` (same arguments, same result to the
last bit): the energy tables are uploaded once per energy object, the whole solve runs in
one single-work-item kernel (solver_opencl.cl), and only the solution comes back. The
kernel pauses every `en.tick_every` iterations when the caller passes a progress tick, so
progress and cancelling work as on the host. Meant for CPU devices (`device_solver` gives
none elsewhere), where one compiled loop beats NumPy's per-call overhead at every mesh size;
a GPU would run it on one thread.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..csr import bincount_csr
from ..engine_opencl import LOCK, _runtime
from .energy import FoldoverEnergy, LiftEnergy
from .solver import lbfgs
from .state import LBFGS_MEMORY, State, stops

__all__ = ["KERNEL_FILE", "OpenCLLbfgs", "device_solver"]

KERNEL_FILE = Path(__file__).with_name("solver_opencl.cl")
_ST_TICK = 1  # kernel status: paused for a progress tick
_solvers: dict[str, OpenCLLbfgs] = {}


def device_solver() -> OpenCLLbfgs | None:
    """The solver of the chosen OpenCL device, made once per process and device (a kernel
    object costs ~0.5 ms); None on a non-CPU device (one work-item would run on one GPU
    thread); RuntimeError when there is no device or the kernel does not build."""
    rt = _runtime()
    if not rt.is_cpu:
        return None
    with LOCK:
        solver = _solvers.get(rt.name)
        if solver is None:
            solver = _solvers[rt.name] = OpenCLLbfgs()
    return solver


class _Tables:
    """One energy's constant arrays on the device."""

    def __init__(self, solver: OpenCLLbfgs, en: FoldoverEnergy, st: State):
        lift = isinstance(en, LiftEnergy)
        nn, nc = en.n_nodes, en.i0.size
        ne = en.n_elem if lift else 0
        pad = np.minimum(np.arange(-(-nc // 4) * 4), nc - 1)  # corner arrays: 4-wide, padded
        nc4 = pad.size
        gptr, gpos = bincount_csr(en.idx, nn)
        part, corner = np.divmod(gpos, nc)  # entry of [e1, e2, -(e1 + e2)], coded for gather
        gpos = np.where(part == 0, corner, np.where(part == 1, nc4 + corner, -1 - corner))
        ints = [st.fidx, en.i0[pad], en.i1[pad], en.i2[pad], gptr, gpos]
        dbls = [st.x, st.y, en.w00[pad], en.w01[pad], en.w11[pad], en.weight[pad]]
        dbls.append(np.tile(en.precond[st.fidx], 2))
        if lift:
            eptr, ecorn = bincount_csr(en.eid, ne)
            ints += [en.eid[pad], eptr, ecorn]
            dbls.append(en.n_corners)
        flat = np.concatenate([np.asarray(a, dtype=np.int64) for a in ints])
        if flat.size and flat.max() >= 2**31:
            raise ValueError("mesh too large for the device solver's 32-bit indices")
        self.ints = solver._buffer(flat.astype(np.int32))
        self.dbls = solver._buffer(np.concatenate([np.asarray(a, np.float64) for a in dbls]))
        n2 = 2 * st.nf
        self.sizes = (nn, st.nf, nc, ne, int(lift))
        self.state_len = 11 + LBFGS_MEMORY + 2 * n2 + 2 * LBFGS_MEMORY * n2
        self.v_at = 11 + LBFGS_MEMORY  # where v starts in the state (see lbfgs_run)
        self.work = solver._empty(8 * (2 * nn + 5 * n2 + 6 * nc4 + 3 * ne))
        self.n2 = n2


class OpenCLLbfgs:
    """`_lbfgs` for `untangle_global` / `lift_min_quality`, run by an OpenCL kernel."""

    def __init__(self) -> None:
        rt = _runtime()
        self.cl, self.ctx, self.queue = rt.cl, rt.ctx, rt.queue
        self.device_name = rt.name
        prg = rt.build(
            f"lbfgs M={LBFGS_MEMORY}",
            KERNEL_FILE.read_text(),
            [f"-DM={LBFGS_MEMORY}"],
            what="L-BFGS kernel",
        )
        self.kernel = self.cl.Kernel(prg, "lbfgs_run")
        self._last: tuple[FoldoverEnergy, State, _Tables] | None = None  # reused per round

    def release(self) -> None:
        """Forget the uploaded tables (and the energy they came from): end of a run."""
        self._last = None

    def _buffer(self, a: np.ndarray):
        mf = self.cl.mem_flags
        return self.cl.Buffer(self.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=a)

    def _empty(self, nbytes: int):
        return self.cl.Buffer(self.ctx, self.cl.mem_flags.READ_WRITE, max(int(nbytes), 8))

    def _tables_for(self, en: FoldoverEnergy, st: State) -> _Tables:
        """The device tables of (en, st): untangle_global solves one energy many times; each
        lift round makes a new one, solved once."""
        if self._last is None or self._last[0] is not en or self._last[1] is not st:
            self._last = (en, st, _Tables(self, en, st))
        return self._last[2]

    def __call__(
        self,
        en: FoldoverEnergy,
        st: State,
        v0: np.ndarray,
        eps: float,
        *,
        max_it: int,
        guard: bool,
        rel_tol: float = 1e-7,
        tick: Callable[[int], bool] | None = None,
    ) -> tuple[np.ndarray, int]:
        kw = {"max_it": max_it, "guard": guard, "rel_tol": rel_tol, "tick": tick}
        if en.power != 1.0 or en.i0.size == 0 or st.nf == 0:  # not in the kernel: the host's
            return lbfgs(en, st, v0, eps, **kw)
        try:
            tb = self._tables_for(en, st)
        except ValueError:  # indices beyond 32 bits: the host solver, same result
            return lbfgs(en, st, v0, eps, **kw)
        cl, queue = self.cl, self.queue
        state = np.zeros(tb.state_len, dtype=np.float64)
        state[:4] = eps, getattr(en, "qc", 0.0), 0.1 * en.h_mean, rel_tol
        state[tb.v_at : tb.v_at + tb.n2] = v0
        S = self._buffer(state)
        ticks = en.tick_every if tick is not None else 0
        flags = np.array([0, 0, 0, 0, 1, 0, *tb.sizes, max_it, bool(guard), ticks], np.int32)
        T = self._buffer(flags)
        for i, buf in enumerate((tb.ints, tb.dbls, S, T, tb.work)):
            self.kernel.set_arg(i, buf)
        while True:
            cl.enqueue_nd_range_kernel(queue, self.kernel, (1,), (1,))
            cl.enqueue_copy(queue, flags, T)
            if flags[5] != _ST_TICK or stops(tick(int(flags[0]))):
                break
        v = np.empty(tb.n2, dtype=np.float64)
        cl.enqueue_copy(queue, v, S, src_offset=8 * tb.v_at)
        return v, int(flags[0])
