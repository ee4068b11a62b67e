"""The OpenCL backend: the NumPy engine's iteration as float64 kernels (pyopencl).

Positions live on the device for the whole run (one upload, one download); per iteration
only per-block stats (count, min, partial sums of q) and a "something was reverted" flag
come back. Kernels follow the NumPy reference's operation order with FP contraction off
(powers by core.fpmath's algorithm, no math library calls), stitching is a gather over each
node's incident corners in NumPy's bincount order (no float atomics), and every sum is added
in NumPy's order: a one-face group's corner sums pairwise like NumPy's reduction over a
size-1 axis, q_avg from the blocks of NumPy's pairwise q.sum() (`_SumPlan`). Two runs on one
device are bit-identical, and on a CPU device the results are NumPy's bits. The initial
state (mean edge length, distance quadtree, first weights) is the NumPy engine's own, built
on the host once and uploaded.

Device choice: `select_device(spec)` (the extension's preferences) or the environment
variable EEGT_OPENCL_DEVICE, as "platform:device" indices or a substring of the device or
platform name; otherwise "auto" prefers a GPU, then a CPU device. pyopencl is imported
lazily: without it (or without a usable device) `available()` says why and the caller
falls back to NumPy.
"""

from __future__ import annotations

import numpy as np

from .. import fpmath
from ..choices import OPENCL_ENGINE
from ..mesh.csr import bincount_csr
from ..mesh.faces import FaceSet
from ..metrics.face_quality import Stats
from ..metrics.mean_ratio import corner_constants
from ..metrics.targets import Targets
from ..opencl.build import NCACHE, program_size
from ..opencl.runtime import ENV_DEVICE, list_devices, runtime, select_device, unavailable_reason
from ..params import EEGTParams
from .boundary import SLIDE_GAP, SLIDE_REACH, BoundaryMotion
from .distance import NearestBoundary
from .engine_numpy import DIST_FLOOR, NumpyEngine, edge_lengths
from .transform import stretch_radius

__all__ = [
    "ENV_DEVICE",
    "OpenCLEngine",
    "available",
    "list_devices",
    "program_size",
    "select_device",
]

_WG = 64  # work-group size for face and node kernels
_TREE_LBAR = 8  # where lbar sits in OpenCLEngine.tree_args (the distance floor follows it)


def available():
    """(OpenCLEngine, None) when a float64 OpenCL device is usable, else (None, reason)."""
    why = unavailable_reason()
    return (None, why) if why else (OpenCLEngine, None)


class _SumPlan:
    """`fpmath.add_reduce` of a contiguous float64 array of n values, split for the device:
    chunks of fpmath.REDUCE_CHUNK values in order, each by NumPy's pairwise_sum: halves
    (at n / 2 rounded down to a multiple of 8) down to blocks of <= 128 values, which it adds
    with 8 interleaved partial sums. `bounds` delimits those blocks (the quality kernel sums
    one per work-item, the same way); `total(block_sums)` adds the block sums in NumPy's
    order: the result is `add_reduce(q)`'s bits."""

    def __init__(self, n: int, bufsize: int | None = None):
        bufsize = int(bufsize or fpmath.REDUCE_CHUNK)
        bounds = [0]

        def tree(off: int, m: int):  # a block's index, or (left, right)
            if m <= fpmath.PAIRWISE_BLOCK:
                bounds.append(off + m)
                return len(bounds) - 2
            m2 = m // 2 - (m // 2) % 8
            return tree(off, m2), tree(off + m2, m - m2)

        chunks = [tree(o, min(bufsize, n - o)) for o in range(0, n, bufsize)]
        self.bounds = np.array(bounds, dtype=np.int32)
        self.n_blocks = len(bounds) - 1
        # the additions level by level (each level's are independent): (dst, left, right)
        # slots, blocks first
        levels: dict[int, list[tuple[int, int, int]]] = {}
        n_slots = self.n_blocks

        def schedule(node) -> tuple[int, int]:  # (slot, height)
            nonlocal n_slots
            if isinstance(node, int):
                return node, 0
            (a, ha), (b, hb) = schedule(node[0]), schedule(node[1])
            h = max(ha, hb) + 1
            levels.setdefault(h, []).append((n_slots, a, b))
            n_slots += 1
            return n_slots - 1, h

        self.roots = [schedule(c)[0] for c in chunks]
        self.levels = [np.array(levels[h], dtype=np.int64).T for h in sorted(levels)]
        self.n_slots = n_slots

    def total(self, block_sums: np.ndarray) -> float:
        v = np.empty(self.n_slots)
        v[: self.n_blocks] = block_sums
        for dst, a, b in self.levels:
            v[dst] = v[a] + v[b]
        out = 0.0
        for r in self.roots:  # the chunks in order, from 0 (the reduction's identity)
            out = out + float(v[r])
        return out


def _roundup(n: int, m: int) -> int:
    return max(m, (n + m - 1) // m * m)


class OpenCLEngine:
    """Holds one run's mesh state on an OpenCL device: an `Engine` (core/eegt/engine.py), the
    same bits as NumpyEngine."""

    name = OPENCL_ENGINE

    def __init__(
        self,
        points: np.ndarray,
        faces: FaceSet,
        free: np.ndarray,
        params: EEGTParams,
        targets: Targets | None = None,
        motion: BoundaryMotion | None = None,
    ):
        rt = runtime()
        self.cl, self.rt, self.queue = rt.cl, rt, rt.queue
        self.device_name = rt.name
        self.params = params
        self.faces = faces
        self.free, self.motion = free, motion
        self.targets = targets
        self.iteration = 0
        self._stale = False  # the first step refreshes the distances first (`restarted`)
        # The reference engine builds the initial state: lbar, quadtree, q; the first step
        # computes the distance weights on the device (the host's bits, without a host query)
        ref = NumpyEngine.initial_state(points, faces, free, params, targets, motion)
        self.lbar = ref.lbar
        self.n_nodes = ref.n_nodes
        groups = faces.groups
        self.n_faces = sum(g.size for g in groups)
        self.prg = rt.program(program_size(max(g.n for g in groups)))
        self._upload_state(ref)
        self._upload_incidence(ref, groups)
        self._upload_distance_tree(ref, params)
        self._setup_stats(groups)
        self._setup_kernels(groups, params, ref.group_targets)
        self._setup_slide(ref)
        self._stats = ref.stats()

    def _buf(self, a: np.ndarray):
        """A read-write device buffer holding `a`."""
        mf = self.cl.mem_flags
        return self.cl.Buffer(self.rt.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=a)

    def _empty(self, nbytes: int):
        """A read-write device buffer of `nbytes` (at least 8)."""
        return self.cl.Buffer(self.rt.ctx, self.cl.mem_flags.READ_WRITE, max(int(nbytes), 8))

    def _upload_state(self, ref: NumpyEngine) -> None:
        """Positions (current, before the step, best), qualities, distance weights (when
        known: else the first step computes them), face weights and corner moves."""
        n, nf = self.n_nodes, self.n_faces
        pts = np.empty((n, 2), dtype=np.float64)
        pts[:, 0], pts[:, 1] = ref.x, ref.y
        self.P = self._buf(pts)
        self.old = self._empty(pts.nbytes)
        self.best = self._empty(pts.nbytes)
        self.cl.enqueue_copy(self.queue, self.best, self.P)
        self.q = self._buf(np.ascontiguousarray(np.concatenate(ref.q), dtype=np.float64))
        if ref.inv_d_pow is None:
            self.fdist = self._empty(8 * nf)
            self._stale = True
        else:
            self.fdist = self._buf(np.ascontiguousarray(np.concatenate(ref.inv_d_pow),
                                                        dtype=np.float64))
        self.wf = self._empty(8 * nf)
        self.cmove = self._empty(16 * int(ref.corner_nodes.size))
        self.flag = self._buf(np.zeros(n, dtype=np.int32))

    def _upload_incidence(self, ref: NumpyEngine, groups) -> None:
        """CSR node -> incident corners of free nodes, in NumPy's bincount order (stitching
        gathers them)."""
        corner_face = np.concatenate(
            [np.tile(np.arange(g.size, dtype=np.int64) + fo, g.n) for g, fo in self._fo(groups)]
        )
        kept = np.flatnonzero(ref.free[ref.corner_nodes])
        row, order = bincount_csr(ref.corner_nodes[kept], self.n_nodes)
        order = kept[order]
        self.row = self._buf(row.astype(np.int32))
        self.ccorner = self._buf(np.ascontiguousarray(order, dtype=np.int32))
        self.cface = self._buf(np.ascontiguousarray(corner_face[order], dtype=np.int32))

    def _upload_distance_tree(self, ref: NumpyEngine, params: EEGTParams) -> None:
        """The distance quadtree (boundary nodes never move): the reference's, flattened;
        without anchors (uniform weights) a one-node stand-in that the kernels never search.
        `tree_args`: the move kernels' tree and distance arguments."""
        nb = ref.nearest
        self.uniform = nb is None
        if nb is None:
            nb = NearestBoundary(np.zeros(1), np.zeros(1))
        lv_len = [c.size for c in nb.child]
        level_off = np.concatenate([[0], np.cumsum(lv_len)])
        tree = np.concatenate([level_off, *nb.child, *nb.leaf_start, *nb.leaf_len, nb.cand]).astype(
            np.int64
        )
        if tree.size and tree.max() >= 2**31:
            raise RuntimeError("mesh too large for 32-bit indices on the device")
        self.tree = self._buf(tree.astype(np.int32))
        self.bxy = self._buf(np.column_stack([nb.bx, nb.by]))
        self.cxy = self._buf(np.column_stack([nb.bx[nb.cand], nb.by[nb.cand]]))
        nf = self.n_faces
        self.tree_args = (
            np.float64(nb.origin[0]),
            np.float64(nb.origin[1]),
            np.float64((1 << nb.depth) / nb.side),
            np.float64(nb.side * (1 - 1e-12)),
            np.float64((1 << nb.depth) - 1),
            np.int32(nb.depth),
            np.int32(len(lv_len)),
            np.int32(nb.bx.size),
            np.float64(self.lbar),
            np.float64(DIST_FLOOR * self.lbar),
            np.float64(params.c),
            np.int32(fpmath.power_code(params.c)),
            # per-face nearest-node cache: nodes, leaf level (-1: empty), leaf cell, q0 and gap
            self._empty(4 * NCACHE * nf),
            self._buf(np.full((nf, 4), -1, dtype=np.int32)),
            self._empty(16 * nf),
            self._empty(32 * nf),
        )

    def _setup_stats(self, groups) -> None:
        """Stats: one (count, min, block sum, 0) row per quality work-item (a block of
        NumPy's pairwise q.sum() of its group), folded on the host in NumPy's order; row 0's
        last slot is the smoothing's "reverted" flag."""
        self._plans = [_SumPlan(g.size) for g in groups]
        self.n_rows = sum(plan.n_blocks for plan in self._plans)
        self.part = self._empty(32 * self.n_rows)
        self._host_part = np.zeros((self.n_rows, 4), dtype=np.float64)

    @staticmethod
    def _fo(groups):
        """(group, first face index in the concatenated order) pairs."""
        fo = 0
        for g in groups:
            yield g, fo
            fo += g.size

    def _setup_kernels(self, groups, params: EEGTParams, group_targets) -> None:
        """Kernel objects with their arguments bound, per arity group (`_group_kernels`),
        and the node kernels (stitch, revert)."""
        self._group_calls: list[tuple] = []
        co = ro = 0
        for (g, fo), tg in zip(self._fo(groups), group_targets):
            rows = self._plans[len(self._group_calls)].n_blocks
            self._group_calls.append(self._group_kernels(g, fo, co, ro, tg, params))
            ro += rows
            co += g.n * g.size
        n = np.int32(self.n_nodes)
        self.k_stitch = self.cl.Kernel(self.prg, "stitch")
        self.k_stitch.set_args(
            n, self.row, self.ccorner, self.cface, self.cmove, self.wf, self.P, self.old, None
        )
        self.k_revert = self.cl.Kernel(self.prg, "revert")
        self.k_revert.set_args(n, self.flag, self.P, self.old, self.part, None, None, None)

    def _ro_buffer(self, a: np.ndarray, dtype):
        """A read-only device buffer holding `a` as `dtype`."""
        mf = self.cl.mem_flags
        return self.cl.Buffer(self.rt.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                              hostbuf=np.ascontiguousarray(a, dtype=dtype))

    def _group_kernels(self, g, fo: int, co: int, ro: int, tg, params: EEGTParams) -> tuple:
        """One arity group's kernels with their arguments bound, as ((global size, kernel)
        for quality, move, move with the distance refresh and mark, then the buffers they
        hold): `fo`, `co`, `ro` its first face, corner and stats row. A group with targets
        (a GroupTargets) runs the generic *_tgt kernels with its (6, n, F) target array."""

        def kernel(name: str):  # a fresh kernel object: its arguments are this run's
            return self.cl.Kernel(self.prg, name)

        suf = {3: "tri", 4: "quad"}.get(g.n, "ngon")
        extra: tuple = ()
        if tg is not None:
            suf = {3: "tgt_tri", 4: "tgt_quad"}.get(g.n, "tgt")
            fields = (tg.x, tg.y, tg.kx, tg.ky, tg.cos_a, tg.inv_sin)
            extra = (self._ro_buffer(np.stack(fields), np.float64),)
        cos_a, inv_sin = corner_constants(g.n)
        nodes = self._ro_buffer(g.nodes, np.int32)
        gargs = (
            nodes,
            np.int32(g.size),
            np.int32(fo),
            np.int32(co),
            np.int32(g.n),
            np.int32(stretch_radius(g.n)),
            np.float64(cos_a),
            np.float64(inv_sin),
        )
        plan = self._plans[len(self._group_calls)]
        rows = plan.n_blocks
        mf = self.cl.mem_flags
        bounds = self.cl.Buffer(self.rt.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=plan.bounds)
        kq = kernel(f"quality_{suf}")
        kq.set_args(
            *gargs, self.P, self.q, np.float64(2.0 * np.sqrt(3.0)), self.part, np.int32(ro),
            bounds, np.int32(rows), *extra,
        )
        moves = []
        for refresh in (0, 1):  # plain move, and move with the distance refresh fused
            km = kernel(f"move_{suf}_d" if refresh else f"move_{suf}")
            head = (
                *gargs,
                self.P,
                self.q,
                self.fdist,
                self.cmove,
                self.wf,
                np.float64(params.a),
                np.float64(params.eta),
                np.int32(fpmath.power_code(params.eta)),
                np.float64(params.inverted_weight),
                np.int32(params.scaling == "area"),
                np.int32(refresh),
                self.tree,
                self.bxy,
                self.cxy,
            )
            self._lbar_arg = len(head) + _TREE_LBAR
            km.set_args(*head, *self.tree_args, *extra)
            moves.append(km)
        kk = kernel("mark_ngon" if tg is not None else f"mark_{suf}")
        kk.set_args(*gargs, self.q, self.flag)
        gs = _roundup(g.size, _WG)
        return ((_roundup(rows, _WG), kq), (gs, moves[0]), (gs, moves[1]), (gs, kk), nodes,
                bounds, *extra)

    def _setup_slide(self, ref: NumpyEngine) -> None:
        """Buffers and kernels of the sliding nodes (none: `self.slide` is None)."""
        self.slide = s = ref.slide
        if s is None:
            return
        mf, ctx = self.cl.mem_flags, self.rt.ctx

        def ro(a: np.ndarray, dtype):
            return self.cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                                  hostbuf=np.ascontiguousarray(a, dtype=dtype))

        def rw(a: np.ndarray, dtype):
            return self.cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR,
                                  hostbuf=np.ascontiguousarray(a, dtype=dtype))

        seg = np.stack([s.ax, s.ay, s.dx, s.dy, s.len2], axis=1)
        self.tau = rw(ref.tau, np.float64)
        self.tau_old = rw(ref.tau, np.float64)
        self.mv = rw(np.zeros(self.n_nodes), np.int32)
        self._slide_bufs = [
            ro(s.node, np.int32), ro(s.curve, np.int32), ro(s.prev_slot, np.int32),
            ro(s.next_slot, np.int32), ro(s.prev_tau, np.float64), ro(s.next_tau, np.float64),
            ro(s.seg_first, np.int32), ro(s.n_seg, np.int32), ro(s.periodic, np.int32),
            ro(seg, np.float64), ro(ref.slot, np.int32),
        ]
        n_slots = np.int32(s.size)
        self.k_slide_save = self.cl.Kernel(self.prg, "slide_save")
        self.k_slide_save.set_args(n_slots, self.tau, self.tau_old)
        self.k_slide_project = self.cl.Kernel(self.prg, "slide_project")
        self.k_slide_project.set_args(n_slots, *self._slide_bufs[:10], self.mv, self.P, self.tau,
                                      self.tau_old, np.float64(SLIDE_REACH),
                                      np.float64(SLIDE_GAP))
        self.k_stitch.set_arg(8, self.mv)
        self.k_revert.set_arg(5, self._slide_bufs[10])
        self.k_revert.set_arg(6, self.tau)
        self.k_revert.set_arg(7, self.tau_old)

    def restarted(self, points: np.ndarray) -> OpenCLEngine:
        """A fresh engine for the same run at new positions (fixed nodes where they are
        here), equal to a new OpenCLEngine and to NumpyEngine.restarted bit for bit: it
        keeps the device tables and kernels (this engine must not be stepped again), uploads
        the positions and lets its first step refresh the distances on the device instead
        of a host query. With sliding nodes (their curve parameters come from the host) it
        is a new engine."""
        if self.slide is not None:
            return OpenCLEngine(points, self.faces, self.free, self.params, self.targets,
                                self.motion)
        engine = OpenCLEngine.__new__(OpenCLEngine)
        engine.__dict__.update(self.__dict__)
        n = self.n_nodes
        pts = np.empty((n, 2), dtype=np.float64)
        pts[:, 0], pts[:, 1] = points[:, 0], points[:, 1]
        engine.lbar, _ = edge_lengths(pts[:, 0], pts[:, 1], self.faces.groups)
        lbar, floor = np.float64(engine.lbar), np.float64(DIST_FLOOR * engine.lbar)
        args = list(self.tree_args)
        args[_TREE_LBAR], args[_TREE_LBAR + 1] = lbar, floor
        engine.tree_args = tuple(args)
        for call in self._group_calls:
            for _gsize, km in call[1:3]:
                km.set_arg(self._lbar_arg, lbar)
                km.set_arg(self._lbar_arg + 1, floor)
        self.cl.enqueue_copy(self.queue, engine.P, pts)
        self.cl.enqueue_copy(self.queue, engine.best, engine.P)
        engine.iteration = 0
        engine._stale = not self.uniform
        engine._faces(1)
        engine._stats = engine._to_stats(engine._read_part())
        return engine

    # -- enqueue helpers -----------------------------------------------------------------
    def _run(self, kernel, gsize: int) -> None:
        self.cl.enqueue_nd_range_kernel(self.queue, kernel, (gsize,), (_WG,))

    def _faces(self, which: int) -> None:
        """Enqueue one per-group kernel for all groups: 1 quality (+ stats rows), 2 move,
        3 move with the distance refresh first, 4 mark."""
        for call in self._group_calls:
            gsize, kern = call[which - 1]
            self._run(kern, gsize)

    def _read_part(self) -> np.ndarray:
        """The stats rows (one blocking read; it waits for the queue)."""
        self.cl.enqueue_copy(self.queue, self._host_part, self.part)
        return self._host_part

    def _to_stats(self, part: np.ndarray) -> Stats:
        """Fold the rows like quality.stats_of: exact count and min; each group's q.sum() in
        NumPy's pairwise order from its block sums, the groups added in order."""
        cnt = int(part[:, 0].sum())
        sums, ro = [], 0
        for plan in self._plans:
            sums.append(plan.total(part[ro : ro + plan.n_blocks, 2]))
            ro += plan.n_blocks
        return Stats(cnt, float(part[:, 1].min()), sum(sums) / self.n_faces)

    # -- the iteration -------------------------------------------------------------------
    def stats(self) -> Stats:
        """Stats of the current positions."""
        return self._stats

    def step(self, phase: str) -> Stats:
        """One transform + stitch iteration; in 'smooth', nodes of new inverted faces go back."""
        self.iteration += 1
        refresh = self._stale or (
            self.iteration > 1 and (self.iteration - 1) % self.params.distance_refresh == 0
        )
        self._stale = False
        self._faces(3 if refresh and not self.uniform else 2)
        self._run(self.k_stitch, _roundup(self.n_nodes, _WG))
        if self.slide is not None:
            slots = _roundup(self.slide.size, _WG)
            self._run(self.k_slide_save, slots)
            self._run(self.k_slide_project, slots)
        self._faces(1)
        if phase != "smooth":
            self._stats = self._to_stats(self._read_part())
            return self._stats
        while True:
            self._faces(4)
            self._run(self.k_revert, _roundup(self.n_nodes, _WG))
            part = self._read_part()
            if part[0, 3] == 0.0:  # nothing went back: the stats are those of the final state
                self._stats = self._to_stats(part)
                return self._stats
            self._faces(1)

    # -- best iterate --------------------------------------------------------------------
    def save_best(self) -> None:
        self.cl.enqueue_copy(self.queue, self.best, self.P)

    def _download(self, buf) -> np.ndarray:
        out = np.empty((self.n_nodes, 2), dtype=np.float64)
        self.cl.enqueue_copy(self.queue, out, buf)
        return out

    def best_points(self) -> np.ndarray:
        return self._download(self.best)

    def points(self) -> np.ndarray:
        return self._download(self.P)
