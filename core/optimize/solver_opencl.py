"""The global stage's L-BFGS on an OpenCL device, bit-identical to the host solver.

`OpenCLLbfgs` is a drop-in for `solver.lbfgs` (same arguments, same result to the
last bit): the energy tables are uploaded once per energy object, the whole solve runs in
one single-work-item kernel (core/opencl/lbfgs_single.cl), and only the solution comes back. The
kernel pauses every `en.tick_every` iterations when the caller passes a progress tick, so
progress and cancelling work as on the host. Meant for CPU devices (`device_solver` gives
none elsewhere), where one compiled loop beats NumPy's per-call overhead at every mesh size;
a GPU would run it on one thread.
"""

from __future__ import annotations

import numpy as np

from ..mesh.csr import bincount_csr
from ..opencl.build import cl_defines, fpmath_options, kernel_file, program_source
from ..opencl.runtime import LOCK, runtime
from .dispatch import TooLarge, on_host, single_kernel_corners
from .energy import FoldoverEnergy, LiftEnergy, energy_defines
from .solver import lbfgs
from .state import LBFGS_MEMORY, REL_TOL, State, Tick, line_search_defines, stops

__all__ = ["KERNEL_FILE", "OpenCLLbfgs", "build_options", "device_solver", "kernel_source"]

KERNEL_FILE = kernel_file("lbfgs_single.cl")
# T (int32): the kernel's counters, problem sizes and settings, a slot each (T_* defines)
_T = {name: k for k, name in enumerate((
    "T_IT", "T_LEN", "T_START", "T_NHIST", "T_FRESH", "T_STATUS", "T_NN", "T_NF", "T_NC",
    "T_NE", "T_MODE", "T_MAXIT", "T_GUARD", "T_TICK"))}
_ST = {"ST_DONE": 0, "ST_TICK": 1}  # T_STATUS: finished, or paused for a progress tick
# S (double): eps, qc, h0, rel_tol, the energy e, the last E_WINDOW energies (solver.lbfgs's
# stop test compares e with the energy E_WINDOW - 1 iterations back), rho [M], then v, g and
# the memory pairs (S_* defines)
_E_WINDOW = 6
_S = {"S_EPS": 0, "S_QC": 1, "S_H0": 2, "S_REL_TOL": 3, "S_E": 4, "S_EHIST": 5,
      "S_RHO": 5 + _E_WINDOW, "S_V": 5 + _E_WINDOW + LBFGS_MEMORY}
_solvers: dict[str, OpenCLLbfgs] = {}


def kernel_source() -> str:
    """The OpenCL C source of the single-work-item L-BFGS kernel (with the shared header)."""
    return program_source(KERNEL_FILE)


def build_options() -> list[str]:
    """The kernel's defines: core.fpmath's (NumPy's summation cut points), the energies'
    constants, the line search's and the layout of its state buffers."""
    return [*fpmath_options(), *cl_defines({
        "M": LBFGS_MEMORY, **line_search_defines(), "E_WINDOW": _E_WINDOW, **energy_defines(),
        **_T, **_ST, **_S})]


def device_solver() -> OpenCLLbfgs | None:
    """The solver of the chosen OpenCL device, made once per process and device (a kernel
    object costs ~0.5 ms); None on a non-CPU device (one work-item would run on one GPU
    thread: `dispatch.single_kernel_corners`); RuntimeError when there is no device or the
    kernel does not build."""
    rt = runtime()
    if not single_kernel_corners(rt.is_cpu):
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
            raise TooLarge("mesh too large for the device solver's 32-bit indices")
        self.ints = solver._buffer(flat.astype(np.int32))
        self.dbls = solver._buffer(np.concatenate([np.asarray(a, np.float64) for a in dbls]))
        n2 = 2 * st.nf
        self.sizes = (nn, st.nf, nc, ne, int(lift))
        self.v_at = _S["S_V"]  # where v starts in the state (see lbfgs_run)
        self.state_len = self.v_at + 2 * n2 + 2 * LBFGS_MEMORY * n2
        self.work = solver._empty(8 * (2 * nn + 5 * n2 + 6 * nc4 + 3 * ne))
        self.n2 = n2


class OpenCLLbfgs:
    """`_lbfgs` for `untangle_global` / `lift_min_quality`, run by an OpenCL kernel."""

    def __init__(self) -> None:
        rt = runtime()
        self.cl, self.ctx, self.queue = rt.cl, rt.ctx, rt.queue
        self.device_name = rt.name
        prg = rt.build(
            f"lbfgs M={LBFGS_MEMORY}", kernel_source(), build_options(), what="L-BFGS kernel"
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
        rel_tol: float = REL_TOL,
        tick: Tick | None = None,
    ) -> tuple[np.ndarray, int]:
        kw = {"max_it": max_it, "guard": guard, "rel_tol": rel_tol, "tick": tick}
        if on_host(en, st):  # not in the kernel: the host's
            return lbfgs(en, st, v0, eps, **kw)
        try:
            tb = self._tables_for(en, st)
        except TooLarge:  # the host solver, same result
            return lbfgs(en, st, v0, eps, **kw)
        cl, queue = self.cl, self.queue
        state = np.zeros(tb.state_len, dtype=np.float64)
        for name, value in (("S_EPS", eps), ("S_QC", getattr(en, "qc", 0.0)),
                            ("S_H0", 0.1 * en.h_mean), ("S_REL_TOL", rel_tol)):
            state[_S[name]] = value
        state[tb.v_at : tb.v_at + tb.n2] = v0
        S = self._buffer(state)
        flags = np.zeros(len(_T), np.int32)
        settings = dict(zip(("T_NN", "T_NF", "T_NC", "T_NE", "T_MODE"), tb.sizes), T_FRESH=1,
                        T_MAXIT=max_it, T_GUARD=bool(guard),
                        T_TICK=en.tick_every if tick is not None else 0)
        for name, value in settings.items():
            flags[_T[name]] = value
        T = self._buffer(flags)
        for i, buf in enumerate((tb.ints, tb.dbls, S, T, tb.work)):
            self.kernel.set_arg(i, buf)

        def point() -> np.ndarray:
            v = np.empty(tb.n2, dtype=np.float64)
            cl.enqueue_copy(queue, v, S, src_offset=8 * tb.v_at)
            return v

        while True:
            cl.enqueue_nd_range_kernel(queue, self.kernel, (1,), (1,))
            cl.enqueue_copy(queue, flags, T)
            if flags[_T["T_STATUS"]] != _ST["ST_TICK"] or stops(
                    tick(int(flags[_T["T_IT"]]), point)):
                break
        return point(), int(flags[_T["T_IT"]])
