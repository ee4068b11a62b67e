"""The global stage's L-BFGS as many-work-item OpenCL kernels, bit-identical to the host.

`ParallelLbfgs` is a drop-in for `solver.lbfgs` (same arguments, same result to
the last bit) that scales with the mesh and suits GPUs: energy terms and corner gradients
run one work-item per corner (along a locality-preserving sweep), the gradient is a
per-node gather in np.bincount's order, vector updates are elementwise, and every dot
product and energy sum is NumPy's pairwise summation split into fixed leaves and chunks
(core/opencl/lbfgs_parallel.cl), so neither the work-group size nor the number of lanes per leaf
changes a bit. The solver's scalars stay on the device; the host enqueues an iteration's
kernels and reads back one 64-byte status block per line-search trial (one per iteration
when the first step is accepted). Tables are uploaded once per energy and kernel arguments
bound once per table set; nothing is allocated per iteration. docs/opencl.md describes the
kernels and the measurements.
"""

from __future__ import annotations

import numpy as np

from ..fpmath import PAIRWISE_BLOCK, REDUCE_CHUNK
from ..mesh.csr import bincount_csr, point_morton
from ..opencl.build import cl_defines, fpmath_options, kernel_file, program_source
from ..opencl.runtime import LOCK, runtime
from .dispatch import SMALL_CORNERS, Solver, TooLarge, route, single_kernel_corners
from .energy import FoldoverEnergy, LiftEnergy, energy_defines
from .solver import lbfgs
from .state import (
    LBFGS_MEMORY,
    LIMIT_MARGIN,
    REL_TOL,
    TRIALS,
    State,
    Tick,
    folded_trial,
    line_search_defines,
    stops,
)

__all__ = ["KERNEL_FILE", "SMALL_CORNERS", "ParallelLbfgs", "build_options", "device_solver",
           "kernel_source", "reduction_plan"]

KERNEL_FILE = kernel_file("lbfgs_parallel.cl")
CHUNK = REDUCE_CHUNK  # fpmath.add_reduce's chunk
BLOCK = PAIRWISE_BLOCK  # NumPy's pairwise base block
WG_CHUNK = 64  # work-group size of chunk_sums with lanes > 1 (a work-item per leaf)
LOCAL_SIZE = 64  # work-group size (any value gives the same bits; 64 was fastest on pocl)
INDEX_LIMIT = 2**31  # the kernels' indices are 32-bit: larger tables use the host solver
# S, the solver's scalars on the device (doubles; counts as exact small integers), one slot
# each (S_* defines). S[0:8] is the status block the host reads back after each trial:
# STATUS (a ST_* code), ET and DMIN (the trial's energy and smallest corner det), LEN (pairs
# in memory), E (the current point's energy), START (ring slot of the oldest pair), SLOPE,
# STEP. Then EPS, QC, H0, GUARD (set by the host), OK (the first point has a gradient),
# BAD (not a descent direction), COEF (the second loop's al - rho y.q), SKIP (trial steps the
# step limit skipped), and per pair or ring slot (M pairs and a spare): ALPHA [M], RHO = 1 /
# s.y, SY = s.y, YDY = y.(dpre y) [M + 1]; LEN_ALL: the length.
_S = {name: k for k, name in enumerate((
    "S_STATUS", "S_ET", "S_DMIN", "S_LEN", "S_E", "S_START", "S_SLOPE", "S_STEP", "S_EPS",
    "S_QC", "S_H0", "S_GUARD", "S_OK", "S_BAD", "S_COEF", "S_SKIP", "S_ALPHA"))}
_S["S_RHO"] = _S["S_ALPHA"] + LBFGS_MEMORY
_S["S_SY"] = _S["S_RHO"] + LBFGS_MEMORY + 1
_S["S_YDY"] = _S["S_SY"] + LBFGS_MEMORY + 1
_S["S_LEN_ALL"] = _S["S_YDY"] + LBFGS_MEMORY + 1
_STATUS, _ET, _DMIN, _LEN = _S["S_STATUS"], _S["S_ET"], _S["S_DMIN"], _S["S_LEN"]
_S_EPS, _S_QC, _S_H0, _S_GUARD = _S["S_EPS"], _S["S_QC"], _S["S_H0"], _S["S_GUARD"]
_SKIP = _S["S_SKIP"]
# S_STATUS after a trial: the step was halved, the trial accepted, or no descent direction
_ST = {"ST_REJECTED": 0, "ST_ACCEPTED": 1, "ST_NOT_DESCENT": 2}
_REJECTED, _ACCEPTED, _NOT_DESCENT = _ST["ST_REJECTED"], _ST["ST_ACCEPTED"], _ST["ST_NOT_DESCENT"]
_solvers: dict[tuple, ParallelLbfgs] = {}


def device_solver(
    lanes: int | None = None,
    local_size: int | None = LOCAL_SIZE,
    small_corners: int | None = None,
) -> ParallelLbfgs:
    """The parallel solver of the chosen OpenCL device, made once per process, device and
    settings; RuntimeError when there is no device or the kernels do not build.

    Problems with fewer than `small_corners` energy corners (None: the device's share,
    `dispatch.single_kernel_corners`) go to the single-work-item kernel (solver_opencl.py).
    Either way the result is the host's."""
    rt = runtime()
    if small_corners is None:
        small_corners = single_kernel_corners(rt.is_cpu)
    key = (rt.name, lanes, local_size, small_corners)
    with LOCK:
        solver = _solvers.get(key)
        if solver is None:
            small = None
            if small_corners > 0:
                from .solver_opencl import OpenCLLbfgs

                small = OpenCLLbfgs()
            solver = ParallelLbfgs(lanes, local_size, small=small, small_corners=small_corners)
            _solvers[key] = solver
    return solver


def _partials_per_leaf(lanes: int) -> int:
    """Leaf partials per sum (PPL): the leaf's sum (one lane), or its 8 partial sums and 8
    tail slots (several lanes, combined by the next stage)."""
    return 1 if lanes == 1 else 16


def kernel_source() -> str:
    """The OpenCL C source of the parallel L-BFGS kernels (with the shared header)."""
    return program_source(KERNEL_FILE)


def build_options(lanes: int) -> list[str]:
    """The kernels' defines for `lanes` work-items per leaf: core.fpmath's (NumPy's
    summation cut points), the energies' constants, the line search's and the layout of S."""
    return [*fpmath_options(), *cl_defines({
        "M": LBFGS_MEMORY, "LANES": lanes, "PPL": _partials_per_leaf(lanes),
        **line_search_defines(), "LIMIT_MARGIN": LIMIT_MARGIN, "WG_CHUNK": WG_CHUNK,
        **energy_defines(), **_S, **_ST})]


def reduction_plan(n: int) -> tuple[np.ndarray, np.ndarray]:
    """How np.add.reduce cuts n terms: (leaf bounds, first leaf of each chunk + the end).

    Chunks of CHUNK terms in order; each is halved at half its length rounded down to a
    multiple of 8 until the pieces have at most BLOCK terms (the leaves)."""
    bounds = [0]
    first = []

    def tree(off: int, m: int) -> None:
        if m <= BLOCK:
            bounds.append(off + m)
            return
        m2 = m // 2 - (m // 2) % 8
        tree(off, m2)
        tree(off + m2, m - m2)

    n_full = n // CHUNK
    per = CHUNK // BLOCK  # a full chunk: CHUNK / BLOCK leaves of BLOCK terms
    if n_full:
        bounds.extend(np.arange(1, n_full * per + 1) * BLOCK)
        first.extend(range(0, n_full * per, per))
    if n % CHUNK:
        first.append(len(bounds) - 1)
        tree(n_full * CHUNK, n % CHUNK)
    first.append(len(bounds) - 1)
    return np.asarray(bounds, dtype=np.int64), np.asarray(first, dtype=np.int64)


RUN_BREAK = 30.0  # a run of the sweep ends where a corner lies this many median steps away


def _sweep_order(x: np.ndarray, y: np.ndarray, *corner_nodes: np.ndarray) -> np.ndarray:
    """A permutation of the corners that keeps neighbours in space near each other in the
    sequence and keeps the mesh's own order where it is already local: the corners are cut
    into runs where consecutive corners lie near each other (a jump of more than RUN_BREAK
    median steps between centroids starts a new run) and the runs are ordered along a
    Z-order curve through their first corners. Neighbouring corners of a run also sit
    together in the sums, so their terms are written together."""
    cx, cy = x.take(corner_nodes[0]), y.take(corner_nodes[0])  # corner sums (x2: the
    for i in corner_nodes[1:]:  # same order as their centroids)
        cx += x.take(i)
        cy += y.take(i)
    if cx.size < 2:
        return np.arange(cx.size)
    dx, dy = np.diff(cx), np.diff(cy)
    step2 = dx * dx + dy * dy  # squared steps (any order would give the same results)
    far = RUN_BREAK * RUN_BREAK * np.median(step2)
    breaks = np.flatnonzero(~(step2 <= far)) + 1  # NaN: a break
    first = np.concatenate([[0], breaks])
    length = np.diff(np.append(first, cx.size))
    by_key = np.argsort(point_morton(np.stack([cx[first], cy[first]], axis=1)), kind="stable")
    start, length = first[by_key], length[by_key]
    to = np.cumsum(length) - length  # where each run goes
    return np.arange(cx.size) + np.repeat(start - to, length)  # runs in their own order


def _first_touch(nodes: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(position of each of n nodes, node at each position) in the order of their first
    occurrence in `nodes`; nodes that never occur come last, in index order. (Only memory
    locality depends on the order: any permutation gives the same results.)"""
    at = np.arange(nodes.size)
    when = np.full(n, nodes.size, dtype=np.int64)
    when[nodes[::-1]] = at[::-1]  # the earliest occurrence (NumPy assigns in order)
    order = np.concatenate([nodes[when[nodes] == at], np.flatnonzero(when == nodes.size)])
    pos = np.empty(n, dtype=np.int64)
    pos[order] = np.arange(n)
    return pos, order


class _Plan:
    """A reduction plan on the device: PI (sizes, leaf bounds, chunk starts) and PD (leaf
    partials, minima, chunk sums)."""

    def __init__(self, solver: ParallelLbfgs, n: int, sums: int):
        bounds, first = reduction_plan(n)
        self.n, self.n_leaves, self.n_chunks = n, bounds.size - 1, first.size - 1
        head = np.array([n, self.n_leaves, self.n_chunks, sums], dtype=np.int64)
        self.ints = np.concatenate([head, bounds, first])
        per_leaf = _partials_per_leaf(solver.lanes)
        self.pd_len = (sums * per_leaf + solver.lanes) * self.n_leaves + (sums + 1) * self.n_chunks
        self.leaf_items = self.n_leaves * solver.lanes


class _Tables:
    """One energy's arrays on the device, and the solver's kernels bound to them."""

    def __init__(self, solver: ParallelLbfgs, en: FoldoverEnergy, st: State):
        self.lift = lift = isinstance(en, LiftEnergy)
        nn, nc, nf = en.n_nodes, en.i0.size, st.nf
        n2 = 2 * nf
        ne = en.n_elem if lift else 0
        self.n2, self.nc, self.ne = n2, nc, ne
        # Corner kernels run along a sweep (a space-filling curve over the corners), node
        # coordinates live in Z in the order the sweep first touches them, and the gradient
        # rows of the free nodes follow Z: neighbouring work-items touch neighbouring memory
        # whatever the mesh's numbering (see the kernel source).
        sweep = _sweep_order(st.x, st.y, en.i0, en.i1, en.i2)
        i1, i2, i0 = en.i1.take(sweep), en.i2.take(sweep), en.i0.take(sweep)
        zpos, order = _first_touch(np.stack([i1, i2, i0], axis=1).ravel(), nn)
        self.zpos = zpos
        vpos = np.full(nn, -1, dtype=np.int64)
        vpos[st.fidx] = np.arange(nf)
        rowf = vpos[order[vpos[order] >= 0]]  # row r (Z order): free node fidx[rowf[r]]
        # each row's terms: np.bincount's order over idx = [i1, i2, i0]
        ptr, by_node = bincount_csr(en.idx, nn)
        nodes = st.fidx[rowf]
        cnt = ptr[nodes + 1] - ptr[nodes]
        rows = np.zeros(nf + 1, dtype=np.int64)
        np.cumsum(cnt, out=rows[1:])
        take = np.repeat(ptr[nodes] - rows[:-1], cnt) + np.arange(rows[-1])
        slot = np.full(3 * nc, -1, dtype=np.int64)  # [e1 | e2 | -(e1 + e2)] -> gather slot
        slot[by_node[take]] = np.arange(rows[-1])
        self.n_slots = int(rows[-1])
        del ptr, by_node, take, nodes, order
        ints = [
            np.stack([zpos.take(i1), zpos.take(i2), zpos.take(i0), sweep], axis=1).ravel(),
            # per corner of the sweep: its three gather slots
            np.stack([r.take(sweep) for r in slot.reshape(3, nc)], axis=1).ravel(),
            np.concatenate([rows, rowf]),  # row starts, each row's free node
            zpos[st.fidx],  # each free node's place in Z
        ]
        del i0, i1, i2, slot
        if lift:
            at = np.empty(nc, dtype=np.int64)
            at[sweep] = np.arange(nc)  # each corner's place in the sweep
            eptr, ecorn = bincount_csr(en.eid, ne)
            ints.append(np.concatenate([eptr, ecorn, at[ecorn]]))
        self.plans = [_Plan(solver, n2, 4), _Plan(solver, nc, 1)]
        if lift:
            self.plans.append(_Plan(solver, ne, 1))
        ints += [p.ints for p in self.plans]
        sizes = [6 * nc, (LBFGS_MEMORY + 1) * n2, 2 * nn]  # the largest offsets used
        top = max([int(a.max()) for a in ints if a.size] + sizes)
        if top >= INDEX_LIMIT:
            raise TooLarge("mesh too large for the parallel solver's 32-bit indices")
        buf, empty = solver._buffer, solver._empty
        self.CI, self.SL, self.rows, self.zfree = (buf(a) for a in ints[:4])
        if lift:
            self.EI = buf(ints[4])
            self.EN = buf(np.concatenate([en.n_corners, -1.0 / en.n_corners]))
            self.DQ = empty(8 * nc)  # per corner of the sweep
        self.PI = [buf(p.ints) for p in self.plans]
        self.PD = [empty(8 * p.pd_len) for p in self.plans]
        self.W = buf(np.stack([w.take(sweep) for w in (en.w00, en.w01, en.w11, en.weight)],
                              axis=1).ravel())
        self.rec = 3 if lift else 2  # per corner, in the sum's order: (term, det[, 1 / u])
        self.TD = empty(8 * self.rec * nc)
        self.dpre = buf(np.tile(en.precond[st.fidx], 2))
        xy = np.empty((nn, 2))
        xy[zpos, 0], xy[zpos, 1] = st.x, st.y
        self.Z = buf(xy.ravel())  # node (x, y) pairs in Z order; the free ones: trial points
        self.DZ = buf(np.zeros(2 * nn))  # the direction in Z's layout (fixed nodes: 0)
        self.LIM = empty(8 * nc)  # per corner of the sweep: its step limit
        self.v, self.g, self.q, self.gt = (empty(8 * n2) for _ in range(4))
        ring = 8 * n2 * (LBFGS_MEMORY + 1)  # M pairs and the candidate's spare slot
        self.hs, self.hy = empty(ring), empty(ring)
        self.GS = empty(16 * self.n_slots)

    def bind(self, k: dict) -> None:
        """Set the arguments of the solver's kernels (once per table switch)."""
        S = self.S
        i32 = np.int32
        (pv, pc, *pe), (dv, dc, *de) = self.PI, self.PD
        vec = (S, pv, dv)
        for h in range(LBFGS_MEMORY):
            k["loop1"][h].set_args(*vec, self.q, self.g, self.hs, self.hy, i32(h))
            k["loop2"][h].set_args(*vec, self.q, self.g, self.hs, self.hy, i32(h))
            k["finish_alpha"][h].set_args(*vec, i32(h))
            k["finish_coef"][h].set_args(*vec, i32(h))
        k["mid"].set_args(*vec, self.q, self.g, self.dpre, self.hy)
        k["finish_mid"].set_args(*vec)
        k["chunk_v1"].set_args(pv, dv, i32(1), i32(1))  # a dot (+ the mid's max |q|)
        k["chunk_v4"].set_args(pv, dv, i32(4), i32(0))
        k["chunk_c"].set_args(pc, dc, i32(1), i32(1))
        k["chunk_m"].set_args(pc, dc, i32(0), i32(1))  # the step limit: a minimum only
        k["forget"].set_args(S)
        nf = i32(self.n2 // 2)
        k["direction_z"].set_args(self.q, self.zfree, self.DZ, nf)
        k["limit_corner"].set_args(S, self.Z, self.DZ, self.CI, self.W, self.LIM, i32(self.nc))
        k["limit_leaf"].set_args(pc, dc, self.LIM)
        k["finish_limit"].set_args(S, pc, dc)
        k["trial_point"].set_args(S, self.Z, self.v, self.q, self.zfree, nf, i32(0))
        k["place"].set_args(S, self.Z, self.v, self.q, self.zfree, nf, i32(1))
        corner = (S, self.Z, self.CI, self.W, self.TD, i32(self.nc))
        k["corner_sum"].set_args(pc, dc, self.TD, i32(self.rec))
        pe, de = (pe[0], de[0]) if self.lift else (pc, dc)
        for name, init in (("finish_trial", 0), ("finish_init", 1)):
            k[name].set_args(S, pc, dc, pe, de, i32(self.ne), i32(init))
        if self.lift:
            k["lift_corner"].set_args(*corner)
            k["lift_element"].set_args(S, pe, de, self.TD, self.EI, self.EN, self.DQ)
            k["chunk_e"].set_args(pe, de, i32(1), i32(0))
            k["lift_grad"].set_args(
                self.Z, self.CI, self.W, self.SL, self.GS, i32(self.nc), self.DQ
            )
        else:
            k["fold_corner"].set_args(*corner, self.SL, self.GS, i32(0))
            k["fold_corner_grad"].set_args(*corner, self.SL, self.GS, i32(1))
            k["fold_grad"].set_args(S, self.Z, self.CI, self.W, self.SL, self.GS, i32(self.nc))
        k["gather_init"].set_args(S, self.g, self.rows, self.GS, nf, i32(1))
        k["gather_grad"].set_args(S, self.gt, self.rows, self.GS, nf, i32(0))
        k["update"].set_args(*vec, self.q, self.gt, self.v, self.g, self.dpre, self.hs, self.hy)
        k["finish_pair"].set_args(*vec)


class ParallelLbfgs:
    """`solver.lbfgs` for `untangle_global` / `lift_min_quality`, run by many-work-item kernels.

    lanes: work-items per leaf of 128 terms in the reductions (1: one work-item sums a leaf,
    best on CPUs; 8: one per partial sum, more parallelism for GPUs; None: 1 on CPU devices,
    8 elsewhere). local_size: the work-group size (None: the implementation's choice).
    Neither changes the result. small: a solver with the same contract (the single-work-item
    kernel) for problems with fewer than small_corners energy corners."""

    def __init__(
        self,
        lanes: int | None = None,
        local_size: int | None = LOCAL_SIZE,
        *,
        small: Solver | None = None,
        small_corners: int = 0,
    ):
        self.small, self.small_corners = small, int(small_corners) if small else 0
        rt = runtime()
        self.cl, self.ctx, self.queue = rt.cl, rt.ctx, rt.queue
        self.device_name = rt.name
        self.lanes = int(lanes or (1 if rt.is_cpu else 8))
        if self.lanes not in (1, 2, 4, 8):
            raise ValueError("lanes must be 1, 2, 4 or 8")
        self.local_size = local_size
        prg = rt.build(
            f"lbfgs_parallel M={LBFGS_MEMORY} LANES={self.lanes}",
            kernel_source(),
            build_options(self.lanes),
            what="parallel L-BFGS kernels",
        )

        def kern(name: str):
            return self.cl.Kernel(prg, name)

        m = LBFGS_MEMORY
        self._k: dict = {name: [kern(name) for _ in range(m)]
                         for name in ("loop1", "loop2", "finish_alpha", "finish_coef")}
        self._k["trial_point"], self._k["place"] = kern("trial_point"), kern("trial_point")
        self._k["fold_corner_grad"] = kern("fold_corner")
        for name in ("mid", "finish_mid", "forget", "fold_corner", "fold_grad",
                     "lift_corner", "lift_element", "lift_grad", "update", "finish_pair",
                     "corner_sum", "direction_z", "limit_corner", "limit_leaf", "finish_limit"):
            self._k[name] = kern(name)
        for name in ("chunk_v1", "chunk_v4", "chunk_c", "chunk_e", "chunk_m"):
            self._k[name] = kern("chunk_sums")
        self._k["gather_grad"] = kern("gather_grad")
        self._k["gather_init"] = kern("gather_grad")
        self._k["finish_trial"] = kern("finish_trial")
        self._k["finish_init"] = kern("finish_trial")
        s_len = _S["S_LEN_ALL"]
        self._S_host = np.zeros(s_len)
        self.S = self._empty(8 * s_len)
        self._rb = np.zeros(_SKIP + 1)  # S[0:16]: the status block and the skip count
        self._last: tuple[FoldoverEnergy, State, _Tables] | None = None

    def release(self) -> None:
        """Forget the uploaded tables (and the energy they came from): end of a run."""
        self._last = None
        if self.small is not None and hasattr(self.small, "release"):
            self.small.release()

    def _buffer(self, a: np.ndarray):
        mf = self.cl.mem_flags
        a = np.ascontiguousarray(a, dtype=np.int32 if a.dtype.kind in "iub" else np.float64)
        if a.size == 0:
            return self._empty(8)
        return self.cl.Buffer(self.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=a)

    def _empty(self, nbytes: int):
        return self.cl.Buffer(self.ctx, self.cl.mem_flags.READ_WRITE, max(int(nbytes), 8))

    def _tables_for(self, en: FoldoverEnergy, st: State) -> _Tables:
        """The device tables of (en, st), with the kernels bound to them."""
        if self._last is None or self._last[0] is not en or self._last[1] is not st:
            self._last = None  # free the old tables first
            tb = _Tables(self, en, st)
            tb.S = self.S
            tb.bind(self._k)
            self._last = (en, st, tb)
        return self._last[2]

    # -- enqueue helpers -------------------------------------------------------------------
    def _go(self, name: str | object, items: int) -> None:
        kernel = self._k[name] if isinstance(name, str) else name
        ls = self.local_size
        if ls is None:
            self.cl.enqueue_nd_range_kernel(self.queue, kernel, (max(items, 1),), None)
        else:
            gs = max(ls, -(-items // ls) * ls)
            self.cl.enqueue_nd_range_kernel(self.queue, kernel, (gs,), (ls,))

    def _one(self, name: str | object) -> None:
        kernel = self._k[name] if isinstance(name, str) else name
        self.cl.enqueue_nd_range_kernel(self.queue, kernel, (1,), (1,))

    def _chunks(self, chunk: str, plan: _Plan) -> None:
        """The chunk sums of a plan: one work-item per chunk when there are several chunks
        (one chunk: its finish kernel walks it); with lanes > 1 a work-group of WG_CHUNK per
        chunk, always (see chunk_sums in the kernel source)."""
        if self.lanes > 1:
            self.cl.enqueue_nd_range_kernel(
                self.queue, self._k[chunk], (WG_CHUNK * plan.n_chunks,), (WG_CHUNK,)
            )
        elif plan.n_chunks > 1:
            self._go(chunk, plan.n_chunks)

    def _reduce(self, kernel, chunk: str, plan: _Plan, finish) -> None:
        """A leaf kernel, its chunk sums and its finish."""
        self._go(kernel, plan.leaf_items)
        self._chunks(chunk, plan)
        self._one(finish)

    def _direction(self, tb: _Tables, pairs: int) -> None:
        """The two-loop recursion over at most `pairs` pairs (the device knows how many),
        the slope and the first step."""
        k, pv = self._k, tb.plans[0]
        for h in range(pairs - 1, -1, -1):
            self._reduce(k["loop1"][h], "chunk_v1", pv, k["finish_alpha"][h])
        self._reduce(k["mid"], "chunk_v1", pv, "finish_mid")
        for h in range(pairs):
            self._reduce(k["loop2"][h], "chunk_v1", pv, k["finish_coef"][h])

    def _energy(self, tb: _Tables, finish: str, grad: bool = False) -> None:
        """Energy and min det at the point in Z (`finish`: the Armijo test, or the starting
        point's); grad: the foldover-free energy's gradient terms too."""
        pc = tb.plans[1]
        if tb.lift:
            self._go("lift_corner", tb.nc)
        else:
            self._go("fold_corner_grad" if grad else "fold_corner", tb.nc)
        if tb.lift:
            self._go("corner_sum", pc.leaf_items)
            self._chunks("chunk_c", pc)
            pe = tb.plans[2]
            self._go("lift_element", pe.leaf_items)
            self._chunks("chunk_e", pe)
            self._one(finish)
        else:
            self._reduce(self._k["corner_sum"], "chunk_c", pc, finish)

    def _trial(self, tb: _Tables, grad: bool) -> np.ndarray:
        """One line-search trial (grad: with the foldover-free energy's gradient terms, for
        a trial that is likely accepted); the status block."""
        self._go("trial_point", tb.n2 // 2)
        self._energy(tb, "finish_trial", grad)
        self.cl.enqueue_copy(self.queue, self._rb, self.S)
        return self._rb

    def _limit(self, tb: _Tables) -> int:
        """The step limit of the current direction (`FoldoverEnergy.step_limit`) at the point
        in Z (which must be v): moves the first trial step below it on the device; returns
        the halvings skipped."""
        self._go("direction_z", tb.n2 // 2)
        self._go("limit_corner", tb.nc)
        pc = tb.plans[1]
        self._go("limit_leaf", pc.leaf_items)
        self._chunks("chunk_m", pc)
        self._one("finish_limit")
        self.cl.enqueue_copy(self.queue, self._rb, self.S)
        return int(self._rb[_SKIP])

    def _gradient(self, tb: _Tables) -> None:
        """dF/dE per corner at the last evaluated point."""
        self._go("lift_grad" if tb.lift else "fold_grad", tb.nc)

    def _accept(self, tb: _Tables, have_grad: bool) -> None:
        """Gradient at the accepted point, the new pair and the memory update."""
        if not have_grad:
            self._gradient(tb)
        self._go("gather_grad", tb.n2 // 2)
        self._reduce(self._k["update"], "chunk_v4", tb.plans[0], "finish_pair")

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
        where = route(en, st, self.small_corners)
        if where != "parallel":  # solved elsewhere: the last problem's tables are done (the
            self._last = None  # lift's rounds after its whole-mesh run, for instance)
            return (lbfgs if where == "host" else self.small)(en, st, v0, eps, **kw)
        try:
            tb = self._tables_for(en, st)
        except TooLarge:  # the host solver, same result
            return lbfgs(en, st, v0, eps, **kw)
        e_hist = [self._start(tb, en, v0, eps, guard)]
        it, pairs = 0, 0  # pairs: the most the device may hold
        trial = False  # the current point is the accepted trial in Z (not yet in v)
        # The foldover-free energy's gradient terms cost a third of a trial and serve only
        # the accepted one: computed with the first trial while first trials get accepted
        # (one pass), else in a pass of their own after the accepted trial. Bits unchanged.
        first_ok = not tb.lift
        folded = 0  # trial steps the last iteration rejected for a det <= 0 (or skipped)
        while it < max_it:
            it += 1
            found = self._search(tb, pairs, first_ok, bool(guard and folded), guard)
            if found is None:  # no descent direction, not even from plain descent
                break
            rb, n_pairs, trials, folded, grad = found
            first_ok = not tb.lift and trials == 1
            if rb[_STATUS] != _ACCEPTED:
                if n_pairs:  # drop the memory and retry once from plain descent
                    self._one("forget")
                    self._go("place", tb.n2 // 2)  # Z = v again (the step limit reads Z)
                    pairs = 0
                    continue
                break
            trial = True
            e, dmin_t = float(rb[_ET]), float(rb[_DMIN])
            if not guard and dmin_t > 0.0:  # just became valid
                break
            e_hist.append(e)
            if len(e_hist) > 5 and e_hist[-6] - e <= rel_tol * abs(e_hist[-6]):
                break
            if tick is not None and it % en.tick_every == 0 and stops(
                    tick(it, lambda: self._solution(tb, en, st, True))):
                break
            if it < max_it:
                self._accept(tb, grad)
                pairs = min(n_pairs + 1, LBFGS_MEMORY)
                trial = False
        return self._solution(tb, en, st, trial), it

    def _start(self, tb: _Tables, en: FoldoverEnergy, v0: np.ndarray, eps: float,
               guard: bool) -> float:
        """The solve's settings and v0 on the device, the energy and gradient there; the
        energy."""
        cl, queue = self.cl, self.queue
        s = self._S_host
        s[:] = 0.0
        s[_S_EPS], s[_S_QC] = eps, getattr(en, "qc", 0.0)
        s[_S_H0], s[_S_GUARD] = 0.1 * en.h_mean, float(bool(guard))
        v0 = np.ascontiguousarray(v0, dtype=np.float64)
        cl.enqueue_copy(queue, self.S, s)
        cl.enqueue_copy(queue, tb.v, v0)
        self._go("place", tb.n2 // 2)
        self._energy(tb, "finish_init", grad=True)
        if tb.lift:
            self._gradient(tb)
        self._go("gather_init", tb.n2 // 2)
        cl.enqueue_copy(queue, self._rb, self.S)
        return float(self._rb[_ET])

    def _search(self, tb: _Tables, pairs: int, grad: bool, limit: bool, guard: bool
                ) -> tuple[np.ndarray, int, int, int, bool] | None:
        """One iteration's direction (over at most `pairs` pairs) and line search, the step
        limit first when `limit`: (status block, pairs held, trials, trials skipped or
        rejected as `state.folded_trial`, whether the last trial computed the gradient
        terms); None when neither the memory's direction nor plain descent descends."""
        self._direction(tb, pairs)
        skip = self._limit(tb) if limit else 0
        if skip >= TRIALS:  # every trial step makes a det <= 0: all rejected
            rb = self._rb
            rb[_STATUS] = _REJECTED
        else:
            rb = self._trial(tb, grad)
        if rb[_STATUS] == _NOT_DESCENT:  # restart from preconditioned descent
            self._one("forget")
            self._direction(tb, 0)
            skip = 0
            rb = self._trial(tb, grad)
            if rb[_STATUS] == _NOT_DESCENT:
                return None
        n_pairs = int(rb[_LEN])
        trials, folded = 1 + skip, skip
        while rb[_STATUS] == _REJECTED and trials <= TRIALS:  # a trial's status (not the
            # limit's "every step fails", which leaves trials above TRIALS)
            folded += folded_trial(float(rb[_ET]), float(rb[_DMIN]), guard)
            if trials == TRIALS:
                break
            grad = False
            rb = self._trial(tb, grad)
            trials += 1
        return rb, n_pairs, trials, folded, grad

    def _solution(self, tb: _Tables, en: FoldoverEnergy, st: State, trial: bool) -> np.ndarray:
        """The solve's last accepted point: the free rows of Z after an accepted trial that
        was not moved into v, else v."""
        if trial:
            xy = np.empty(2 * en.n_nodes, dtype=np.float64)
            self.cl.enqueue_copy(self.queue, xy, tb.Z)
            zf = 2 * tb.zpos[st.fidx]
            return np.concatenate([xy[zf], xy[zf + 1]])
        v = np.empty(tb.n2, dtype=np.float64)
        self.cl.enqueue_copy(self.queue, v, tb.v)
        return v
