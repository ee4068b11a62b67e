// The global stage's L-BFGS (core/optimize/solver.py: lbfgs with FoldoverEnergy or LiftEnergy)
// as many-work-item float64 kernels, bit-identical to the host solver on any work-group
// size, lane count and device. The host (solver_parallel.py) enqueues the kernels of an
// iteration and reads back one small status block per line-search trial; every scalar of
// the solver (step, slope, alphas, ring state) lives in the device buffer S.
//
// Same numbers as NumPy: every floating-point operation is the NumPy code's, same operands,
// same order, FP contraction off. np.bincount is a per-row gather in index order (CSR built
// on the host), np.add.reduce is NumPy's pairwise summation split over work-items:
//   - a vector of n terms is cut like NumPy cuts it: chunks of CHUNK (8192), each halved (at n / 2
//     rounded down to a multiple of 8) down to leaves of at most PW_BLOCK (128) terms;
//   - a leaf is 8 partial sums r[j] (terms j, j + 8, ..., in order), combined as
//     ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)), then the n % 8 tail terms in order
//     (a leaf under 8 terms: 0.0 + its terms in order). A work-item computes LPW = 8 / LANES
//     of those partial sums: LANES 1 finishes the leaf itself, LANES > 1 writes its lanes'
//     partial sums and tail terms, which the next stage combines in that fixed order;
//   - one work-item per chunk adds its leaves along the same binary tree (chunk_sums; with
//     LANES > 1 a work-group of WG_CHUNK per chunk, one work-item per leaf, then one walks the
//     tree), and a single-work-item finish kernel adds the chunk sums in order, from 0.0.
// The partition is fixed by n alone, so the bits do not depend on the work-group size or on
// LANES. min/max reductions keep NumPy's NaN semantics (a NaN wins; otherwise the order does
// not matter).
//
// Kernels of one iteration (n2 = 2 x free nodes, nc corners, ne elements; "leaf" kernels
// run one work-item per leaf lane and leave leaf partials; each reduction is followed by
// chunk_sums when the vector has more than one chunk, then its finish kernel):
//   direction: loop1[h] (h = len-1 .. 0)  q -= y alpha (or q = -g), partials of s.q
//              mid                        q -= y0 alpha0, q *= dpre gamma, partials of y0.q
//                                         (no memory: q = -g dpre, partials of g.q, max |q|)
//              loop2[h] (h = 0 .. len-1)  q += s c, partials of the next y.q (or g.q)
//   trial:     trial_point (vt = v + q step into the node coordinates), fold_corner or
//              lift_corner (terms and dets, one work-item per corner), corner_sum (their
//              leaf partials and minimum), lift_element (lift: per-element terms),
//              finish_trial (the Armijo test)
//   accepted:  fold_grad or lift_grad (dF/dE per corner, written in the gather's order;
//              fold_corner can write it with the trial instead),
//              gather_grad (the gradient, one work-item per free node), update (s and y into the spare ring slot,
//              v = vt, g = gt, partials of s.y, s.s, y.y, y.dpre y), finish_pair (the
//              L-BFGS memory update)

// Host-side defines (solver_parallel.build_options(); a missing one stops the build):
//   M, TRIALS, ARMIJO, CURVATURE, LIMIT_MARGIN  LBFGS_MEMORY, the line search's and the
//               memory update's (core/optimize/state.py)
//   LANES, PPL  work-items per leaf of PW_BLOCK terms (1, 2, 4 or 8) and partials per leaf
//               and sum (the sum, or 8 lane partials + 8 tails)
//   WG_CHUNK  chunk_sums' work-group size (LANES > 1)
//   THETA, PENALTY, BARRIER  energy.py's THETA, LIFT_PENALTY, LIFT_BARRIER
//   S_*, ST_*  the slots of the scalars in S and the status codes (solver_parallel._S, _ST)
//   PW_BLOCK, CHUNK, ...  core.fpmath's (common.cl, which the loader puts in front of this
//                         file: fp64, FP_CONTRACT off, NumPy's pairwise sums)
#if !defined(M) || !defined(TRIALS) || !defined(ARMIJO) || !defined(CURVATURE) || \
    !defined(LIMIT_MARGIN) || !defined(LANES) || \
    !defined(PPL) || !defined(WG_CHUNK) || !defined(THETA) || !defined(PENALTY) || \
    !defined(BARRIER) || !defined(S_LEN_ALL) || !defined(ST_NOT_DESCENT) || \
    !defined(PW_BLOCK) || !defined(CHUNK)
#error "build with core.optimize.solver_parallel.build_options(lanes)"
#endif
#if LANES != 1 && LANES != 2 && LANES != 4 && LANES != 8
#error "LANES must be 1, 2, 4 or 8"
#endif
#define SLOTS (M + 1)  // ring slots: M pairs and a spare for the candidate pair
#define LPW (8 / LANES)  // leaf partial sums per work-item

// ---- scalars in S (doubles; counts stored as exact small integers) --------------------------
// Slots S_* as solver_parallel._S lays them out; S[0:8] is the status block the host reads
// back after each trial, S_STATUS one of ST_REJECTED (step halved), ST_ACCEPTED,
// ST_NOT_DESCENT. Per ring slot: S_RHO 1 / s.y, S_SY s.y, S_YDY y.(dpre y); S_ALPHA [M].

// ---- reduction plans --------------------------------------------------------------------
// PI (int): n, leaves, chunks, sums | leaf bounds [leaves + 1] | first leaf of each chunk
// [chunks + 1]. PD (double): leaf partials [sums][leaves * PPL] | per-work-item minima
// [leaves * LANES] | chunk sums [sums][chunks] | chunk minima [chunks].

typedef struct {
    int n, nl, nch, ps;
    __global const int *lb, *cl;
    __global double *P, *PMIN, *CS, *CM;
} Plan;

static Plan plan_of(__global const int *PI, __global double *PD)
{
    Plan p;
    p.n = PI[0];
    p.nl = PI[1];
    p.nch = PI[2];
    const int sums = PI[3];
    p.ps = p.nl * PPL;
    p.lb = PI + 4;
    p.cl = p.lb + p.nl + 1;
    p.P = PD;
    p.PMIN = p.P + sums * p.ps;
    p.CS = p.PMIN + p.nl * LANES;
    p.CM = p.CS + sums * p.nch;
    return p;
}

// The leaf and lanes of this work-item: elements o + i + j0 + jj (i = 0, 8, ... < full,
// jj < LPW), then its tail elements. Returns from the kernel past the last leaf.
#define LEAF_HEAD(pl)                                             \
    const int w = get_global_id(0);                               \
    if (w >= (pl).nl * LANES)                                     \
        return;                                                   \
    const int leaf = w / LANES, j0 = (w % LANES) * LPW;           \
    const int o = (pl).lb[leaf], n = (pl).lb[leaf + 1] - o;       \
    const int full = n - n % 8;

// Runs the statement list BODY (reads the element index k, sets t[0 .. K-1]) on each of
// this work-item's elements and stores the leaf partials of the K sums.
#if LANES == 1
#define LEAF_SUMS(K, pl, ...)                                             \
    {                                                                     \
        double r[K][8], t[K], res[K];                                     \
        for (int i = 0; i < full; i += 8)                                 \
            for (int jj = 0; jj < 8; ++jj) {                              \
                const int k = o + i + jj;                                 \
                __VA_ARGS__                                               \
                for (int s = 0; s < K; ++s)                               \
                    r[s][jj] = (i == 0) ? t[s] : r[s][jj] + t[s];         \
            }                                                             \
        for (int s = 0; s < K; ++s)                                       \
            res[s] = full ? COMBINE8(r[s]) : 0.0;                         \
        for (int k = o + full; k < o + n; ++k) {                          \
            __VA_ARGS__                                                   \
            for (int s = 0; s < K; ++s)                                   \
                res[s] = res[s] + t[s];                                   \
        }                                                                 \
        for (int s = 0; s < K; ++s)                                       \
            (pl).P[s * (pl).ps + leaf] = res[s];                          \
    }
#else
#define LEAF_SUMS(K, pl, ...)                                             \
    {                                                                     \
        double r[K][LPW], t[K];                                           \
        for (int i = 0; i < full; i += 8)                                 \
            for (int jj = 0; jj < LPW; ++jj) {                            \
                const int k = o + i + j0 + jj;                            \
                __VA_ARGS__                                               \
                for (int s = 0; s < K; ++s)                               \
                    r[s][jj] = (i == 0) ? t[s] : r[s][jj] + t[s];         \
            }                                                             \
        __global double *pp = (pl).P + PPL * leaf + j0;                   \
        for (int jj = 0; jj < LPW; ++jj) {                                \
            for (int s = 0; s < K; ++s)                                   \
                pp[s * (pl).ps + jj] = full ? r[s][jj] : 0.0;             \
            if (j0 + jj < n - full) {                                     \
                const int k = o + full + j0 + jj;                         \
                __VA_ARGS__                                               \
                for (int s = 0; s < K; ++s)                               \
                    pp[s * (pl).ps + 8 + jj] = t[s];                      \
            }                                                             \
        }                                                                 \
    }
#endif

// The sum of leaf `leaf` (m terms) from its partials
static double leaf_sum(__global const double *P, const int leaf, const int m)
{
#if LANES == 1
    return P[leaf];
#else
    __global const double *r = P + PPL * leaf;
    const int full = m - m % 8;
    double res = full ? COMBINE8(r) : 0.0;
    for (int t = 0; t < m - full; ++t)
        res = res + r[8 + t];
    return res;
#endif
}

// NumPy's pairwise sum of one chunk of m terms whose leaves start at `first` (common.cl)
static double chunk_sum(__global const double *P, const int first, const int m)
{
    double r;
    PAIRWISE_TREE(r, int, m, leaf_sum(P, first + pw_k, pw_len));
    return r;
}

// The pairwise tree of one chunk of m terms over its leaf sums L[0 ..] (local memory)
static double chunk_tree(__local const double *L, const int m)
{
    double r;
    PAIRWISE_TREE(r, int, m, L[pw_k]);
    return r;
}

#if LANES == 1
// One work-item per chunk (the leaf sums are final): the chunk's pairwise sum of each of the
// first `sums` sums, and (mins != 0) the minimum of its work-items' minima
__kernel void chunk_sums(__global const int *PI, __global double *PD, const int sums,
                         const int mins)
{
    const Plan pl = plan_of(PI, PD);
    const int c = get_global_id(0);
    if (c >= pl.nch)
        return;
    const int m = min(CHUNK, pl.n - c * CHUNK);
    for (int s = 0; s < sums; ++s)
        pl.CS[s * pl.nch + c] = chunk_sum(pl.P + s * pl.ps, pl.cl[c], m);
    if (mins) {
        double mn = INFINITY;
        for (int k = pl.cl[c] * LANES; k < pl.cl[c + 1] * LANES; ++k)
            mn = MIN_NAN(mn, pl.PMIN[k]);
        pl.CM[c] = mn;
    }
}
#else
// One work-group of WG_CHUNK work-items per chunk: they combine the lane partials of the
// chunk's leaves (up to 2 CHUNK / PW_BLOCK of them: leaves of a split chunk have PW_BLOCK / 2
// to PW_BLOCK terms), then one adds the leaves along the chunk's tree (the same sums and
// minima as above; always run, even for one chunk, so that no single work-item walks a
// whole chunk)
#define MAX_LEAVES (2 * CHUNK / PW_BLOCK)
__kernel __attribute__((reqd_work_group_size(WG_CHUNK, 1, 1)))
void chunk_sums(__global const int *PI, __global double *PD, const int sums, const int mins)
{
    __local double L[MAX_LEAVES];
    const Plan pl = plan_of(PI, PD);
    const int c = get_group_id(0), l = get_local_id(0);
    const int on = c < pl.nch;
    const int first = on ? pl.cl[c] : 0, leaves = on ? pl.cl[c + 1] - first : 0;
    const int m = on ? min(CHUNK, pl.n - c * CHUNK) : 0;
    for (int s = 0; s < sums; ++s) {
        for (int j = l; j < leaves; j += WG_CHUNK)
            L[j] = leaf_sum(pl.P + s * pl.ps, first + j, pl.lb[first + j + 1] - pl.lb[first + j]);
        barrier(CLK_LOCAL_MEM_FENCE);
        if (l == 0 && on)
            pl.CS[s * pl.nch + c] = chunk_tree(L, m);
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (mins) {
        double mn = INFINITY;
        for (int j = l; j < leaves; j += WG_CHUNK)
            for (int k = (first + j) * LANES; k < (first + j + 1) * LANES; ++k)
                mn = MIN_NAN(mn, pl.PMIN[k]);
        L[l] = mn;
        barrier(CLK_LOCAL_MEM_FENCE);
        if (l == 0 && on) {
            for (int k = 1; k < WG_CHUNK; ++k)
                mn = MIN_NAN(mn, L[k]);
            pl.CM[c] = mn;
        }
    }
}
#endif

// np.add.reduce of sum s: the chunk sums in order from 0.0 (one chunk and final leaf sums:
// its tree here)
static double total(const Plan *pl, const int s)
{
    double acc = 0.0;
#if LANES == 1
    if (pl->nch == 1)
        return acc + chunk_sum(pl->P + s * pl->ps, 0, pl->n);
#endif
    for (int c = 0; c < pl->nch; ++c)
        acc = acc + pl->CS[s * pl->nch + c];
    return acc;
}

static double total_min(const Plan *pl)
{
    double mn = INFINITY;
#if LANES == 1
    if (pl->nch == 1) {
        for (int k = 0; k < pl->nl; ++k)
            mn = MIN_NAN(mn, pl->PMIN[k]);
        return mn;
    }
#endif
    for (int c = 0; c < pl->nch; ++c)
        mn = MIN_NAN(mn, pl->CM[c]);
    return mn;
}

#define SLOT(h) ((((int)S[S_START]) + (h)) % SLOTS)

// ---- direction: the two-loop recursion --------------------------------------------------

// First loop, pair h (newest first): the previous step's q -= y alpha (or q = -g for the
// newest pair), then partials of s_h . q
__kernel void loop1(__global double *S, __global const int *PI, __global double *PD,
                    __global double *q, __global const double *g, __global const double *hs,
                    __global const double *hy, const int h)
{
    const int len = (int)S[S_LEN];
    if (h >= len)
        return;
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    const int n2 = pl.n, first = (h == len - 1);
    __global const double *sh = hs + SLOT(h) * n2;
    __global const double *yp = hy + SLOT(first ? h : h + 1) * n2;
    const double al = first ? 0.0 : S[S_ALPHA + h + 1];
    LEAF_SUMS(1, pl,
        const double qk = first ? -g[k] : q[k] - yp[k] * al;
        q[k] = qk;
        t[0] = sh[k] * qk;)
}

__kernel void finish_alpha(__global double *S, __global const int *PI, __global double *PD,
                           const int h)
{
    if (get_global_id(0) != 0 || h >= (int)S[S_LEN])
        return;
    const Plan pl = plan_of(PI, PD);
    S[S_ALPHA + h] = S[S_RHO + SLOT(h)] * total(&pl, 0);
}

// With memory: the first loop's last q -= y0 alpha0, q *= dpre gamma, partials of y0 . q.
// Without: q = -g dpre, partials of g . q and the minimum of -|q| (= -max |q|).
__kernel void mid(__global double *S, __global const int *PI, __global double *PD,
                  __global double *q, __global const double *g, __global const double *dpre,
                  __global const double *hy)
{
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    const int len = (int)S[S_LEN];
    double mn = INFINITY;
    if (len > 0) {
        __global const double *y0 = hy + SLOT(0) * pl.n;
        const int newest = SLOT(len - 1);
        const double al = S[S_ALPHA], gamma = S[S_SY + newest] / S[S_YDY + newest];
        LEAF_SUMS(1, pl,
            double qk = q[k] - y0[k] * al;
            qk = qk * (dpre[k] * gamma);
            q[k] = qk;
            t[0] = y0[k] * qk;)
    } else {
        LEAF_SUMS(1, pl,
            const double qk = -g[k] * dpre[k];
            q[k] = qk;
            mn = MIN_NAN(mn, -FABS(qk));
            t[0] = g[k] * qk;)
    }
    pl.PMIN[w] = mn;
}

__kernel void finish_mid(__global double *S, __global const int *PI, __global double *PD)
{
    if (get_global_id(0) != 0)
        return;
    const Plan pl = plan_of(PI, PD);
    const double dot = total(&pl, 0);
    if ((int)S[S_LEN] > 0) {
        S[S_COEF] = S[S_ALPHA] - S[S_RHO + SLOT(0)] * dot;
    } else {
        const double qmax = -total_min(&pl);
        S[S_SLOPE] = dot;
        S[S_STEP] = (qmax > 0.0) ? S[S_H0] / qmax : 0.0;
        S[S_BAD] = !(dot < 0.0);
    }
}

// Second loop, pair h (oldest first): q += s_h c, then partials of y_{h+1} . q, or of g . q
// (the slope) after the newest pair
__kernel void loop2(__global double *S, __global const int *PI, __global double *PD,
                    __global double *q, __global const double *g, __global const double *hs,
                    __global const double *hy, const int h)
{
    const int len = (int)S[S_LEN];
    if (h >= len)
        return;
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    const int n2 = pl.n, last = (h == len - 1);
    __global const double *sh = hs + SLOT(h) * n2;
    __global const double *yn = last ? g : hy + SLOT(h + 1) * n2;
    const double c = S[S_COEF];
    LEAF_SUMS(1, pl,
        const double qk = q[k] + sh[k] * c;
        q[k] = qk;
        t[0] = yn[k] * qk;)
}

__kernel void finish_coef(__global double *S, __global const int *PI, __global double *PD,
                          const int h)
{
    const int len = (int)S[S_LEN];
    if (get_global_id(0) != 0 || h >= len)
        return;
    const Plan pl = plan_of(PI, PD);
    const double dot = total(&pl, 0);
    if (h < len - 1) {
        S[S_COEF] = S[S_ALPHA + h + 1] - S[S_RHO + SLOT(h + 1)] * dot;
    } else {
        S[S_SLOPE] = dot;
        S[S_STEP] = 1.0;
        S[S_BAD] = !(dot < 0.0);
    }
}

// A restart from preconditioned descent: no pairs
__kernel void forget(__global double *S)
{
    if (get_global_id(0) == 0) {
        S[S_LEN] = 0.0;
        S[S_START] = 0.0;
    }
}

// ---- energies ---------------------------------------------------------------------------
// Corner kernels run over the corners in a sweep order (a space-filling curve over their
// positions) and node coordinates live in Z, (x, y) pairs in the order the sweep first
// touches the nodes, so that neighbouring work-items read and write neighbouring memory
// whatever the mesh's numbering; results that are summed go to their place in NumPy's order.
// Z: the fixed nodes' coordinates set once, the free nodes' written by trial_point.
// Per corner of the sweep: CI = (i1, i2, i0) places in Z and the corner's place in the sum,
// W = (w00, w01, w11, weight), SL = its gather slots.

// Free node f of the trial point v + q step (init: of v) into its place zf[f] in Z
__kernel void trial_point(__global const double *S, __global double *Z,
                          __global const double *v, __global const double *q,
                          __global const int *zf, const int nf, const int init)
{
    const int f = get_global_id(0);
    if (f >= nf)
        return;
    const int node = zf[f];
    if (init) {
        Z[2 * node] = v[f];
        Z[2 * node + 1] = v[nf + f];
    } else {
        const double step = S[S_STEP];
        Z[2 * node] = v[f] + q[f] * step;
        Z[2 * node + 1] = v[nf + f] + q[nf + f] * step;
    }
}

#define JACOBIAN                                                              \
    const int4 ci = vload4(k, CI);                                           \
    __global const double *wk = W + 4 * k;                                   \
    const double2 p0 = vload2(ci.z, Z), p1 = vload2(ci.x, Z), p2 = vload2(ci.y, Z); \
    const double x0 = p0.x, y0 = p0.y;                                       \
    const double e1x = p1.x - x0, e1y = p1.y - y0;                           \
    const double e2x = p2.x - x0, e2y = p2.y - y0;                           \
    const double w00 = wk[0], w01 = wk[1], w11 = wk[2];                      \
    const double j00 = e1x * w00, j10 = e1y * w00;                           \
    const double j01 = e1x * w01 + e2x * w11, j11 = e1y * w01 + e2y * w11;   \
    const double d = j00 * j11 - j01 * j10;                                  \
    const double tf = ((j00 * j00 + j01 * j01) + j10 * j10) + j11 * j11;

#define FOLD_TERMS                                                           \
    const double eps = S[S_EPS], dd = d * d;                                 \
    const double root = SQRT(dd + eps * eps);                                \
    const double chi = (d >= 0.0) ? 0.5 * (d + root) : ((0.5 * eps) * eps) / (root + FABS(d)); \
    const double num = (1.0 - THETA) * tf + THETA * (dd + 1.0);              \
    const double inv_chi = wk[3] / chi;

// _Energy.evaluate (power 1): partials of the terms num / chi w and the minimum det
// Leaf partials of the corner terms (in the sum's order) and the minimum det: TD holds a
// record of rec doubles per corner, (term, det, ...)
__kernel void corner_sum(__global const int *PI, __global double *PD,
                         __global const double *TD, const int rec)
{
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    double mn = INFINITY;
    LEAF_SUMS(1, pl,
        const double d = TD[rec * k + 1];
        mn = MIN_NAN(mn, d);
        t[0] = TD[rec * k];)
    pl.PMIN[w] = mn;
}

// dF/dE = dF/dJ W^-T of corner k, written where the gradient gather reads it: GS holds
// (x, y) pairs in the gather's order (each free node's terms, in np.bincount's order), SL
// the slots of each corner's (i1 (e1), i2 (e2), i0 (-(e1 + e2))) (-1: a fixed node)
static inline void put(__global double *GS, const int s, const double x, const double y)
{
    if (s >= 0) {
        GS[2 * s] = x;
        GS[2 * s + 1] = y;
    }
}

#define CORNER_GRAD(a, b)                                                    \
    const double g00 = a * j00 + b * j11, g10 = a * j10 - b * j01;           \
    const double g01 = a * j01 - b * j10, g11 = a * j11 + b * j00;           \
    const double ge1x = g00 * w00 + g01 * w01, ge1y = g10 * w00 + g11 * w01; \
    const double ge2x = g01 * w11, ge2y = g11 * w11;                         \
    put(GS, SL[3 * k], ge1x, ge1y);                                          \
    put(GS, SL[3 * k + 1], ge2x, ge2y);                                      \
    put(GS, SL[3 * k + 2], -(ge1x + ge2x), -(ge1y + ge2y));

// _Energy.evaluate (power 1), corner k of the sweep: its term num / chi w and det into TD at
// its place in the sum (CI.w); with_grad: _grad's dF/dE into GS too (one pass when the
// trial is accepted; the host asks for it when the first trial usually is)
__kernel void fold_corner(__global const double *S, __global const double *Z,
                          __global const int *CI, __global const double *W,
                          __global double *TD, const int nc, __global const int *SL,
                          __global double *GS, const int with_grad)
{
    const int k = get_global_id(0);
    if (k >= nc)
        return;
    JACOBIAN
    FOLD_TERMS
    vstore2((double2)(num * inv_chi, d), ci.w, TD);
    if (with_grad) {
        const double a = (2.0 * (1.0 - THETA)) * inv_chi;
        const double b = inv_chi * ((2.0 * THETA) * d - num / root);
        CORNER_GRAD(a, b)
    }
}

// _Energy.gradient at the last trial point (accepted after a trial without the gradient)
__kernel void fold_grad(__global const double *S, __global const double *Z,
                        __global const int *CI, __global const double *W,
                        __global const int *SL, __global double *GS, const int nc)
{
    const int k = get_global_id(0);
    if (k >= nc)
        return;
    JACOBIAN
    FOLD_TERMS
    const double a = (2.0 * (1.0 - THETA)) * inv_chi;
    const double b = inv_chi * ((2.0 * THETA) * d - num / root);
    CORNER_GRAD(a, b)
}

// _LiftEnergy.evaluate, corner k of the sweep: (its term weight u, det, 1 / u = q_corner) into
// TD at its place in the sum (CI.w)
__kernel void lift_corner(__global const double *S, __global const double *Z,
                          __global const int *CI, __global const double *W,
                          __global double *TD, const int nc)
{
    const int k = get_global_id(0);
    if (k >= nc)
        return;
    JACOBIAN
    const double u = (0.5 * tf) / d;
    vstore3((double3)(wk[3] * u, d, 1.0 / u), ci.w, TD);
}

// _LiftEnergy.evaluate, elements: q_e (its corners' q_corner in index order / corners), the
// floor term's partials, and dF/dq_e dq_e/du_k u_k^2 = (-1 - k gap) (-1 / n_e) into DQ at
// each of its corners' places in the sweep. EI = [eptr (ne + 1) | corners by element (sum
// order) | the same corners' places in the sweep]; EN = [corner count | -1 / corner count].
__kernel void lift_element(__global const double *S, __global const int *PI,
                           __global double *PD, __global const double *TD,
                           __global const int *EI, __global const double *EN,
                           __global double *DQ)
{
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    const int ne = pl.n;
    const double qc = S[S_QC], kq = (2.0 * PENALTY) / qc;
    __global const int *ec = EI + ne + 1, *es = ec + EI[ne];
    LEAF_SUMS(1, pl,
        double sq = 0.0;
        for (int p = EI[k]; p < EI[k + 1]; ++p)
            sq = sq + TD[3 * ec[p] + 2];
        const double qe = sq / EN[k];
        double gap = qc - qe;
        gap = (isnan(gap) || gap >= 0.0) ? gap : 0.0;
        gap = gap / qc;
        const double dq = (-1.0 - kq * gap) * EN[ne + k];
        for (int p = EI[k]; p < EI[k + 1]; ++p)
            DQ[es[p]] = dq;
        t[0] = (PENALTY * gap) * gap - qe;)
}

// _LiftEnergy.gradient, corner k of the sweep (DQ from lift_element)
__kernel void lift_grad(__global const double *Z, __global const int *CI,
                        __global const double *W, __global const int *SL, __global double *GS,
                        const int nc, __global const double *DQ)
{
    const int k = get_global_id(0);
    if (k >= nc)
        return;
    JACOBIAN
    const double u = (0.5 * tf) / d;
    double de_du = DQ[k] / (u * u);
    de_du = de_du + BARRIER * wk[3];
    const double a = de_du / d;
    const double b = (-de_du * u) / d;
    CORNER_GRAD(a, b)
}

// Energy, min det and the Armijo test of the trial point (init: the starting point's
// energy and whether it has a gradient). ne = 0: the foldover-free energy.
__kernel void finish_trial(__global double *S, __global const int *PIc,
                           __global double *PDc, __global const int *PIe,
                           __global double *PDe, const int ne, const int init)
{
    if (get_global_id(0) != 0)
        return;
    const Plan pc = plan_of(PIc, PDc);
    const double dmin = total_min(&pc);
    double et;
    if (ne == 0) {
        et = total(&pc, 0);
    } else if (!(dmin > 0.0)) {
        et = INFINITY;
    } else {
        const Plan pe = plan_of(PIe, PDe);
        et = total(&pe, 0);
        et = et + BARRIER * total(&pc, 0);
    }
    S[S_ET] = et;
    S[S_DMIN] = dmin;
    if (init) {
        S[S_E] = et;
        S[S_OK] = (ne == 0) || dmin > 0.0;
        return;
    }
    if (S[S_BAD] != 0.0) {
        S[S_STATUS] = (double)ST_NOT_DESCENT;
        return;
    }
    const double step = S[S_STEP];
    const int guard = S[S_GUARD] != 0.0;
    if (isfinite(et) && et <= S[S_E] + (ARMIJO * step) * S[S_SLOPE] && !(guard && dmin <= 0.0)) {
        S[S_STATUS] = (double)ST_ACCEPTED;
        S[S_E] = et;
    } else {
        S[S_STATUS] = (double)ST_REJECTED;
        S[S_STEP] = step * 0.5;
    }
}

// ---- the step limit (guarded runs): trial steps that would make a det <= 0 -----------------
// The direction q of free node f into its place zf[f] of DZ (node (x, y) pairs in Z order;
// the fixed nodes' entries stay 0)
__kernel void direction_z(__global const double *q, __global const int *zf,
                          __global double *DZ, const int nf)
{
    const int f = get_global_id(0);
    if (f >= nf)
        return;
    DZ[2 * zf[f]] = q[f];
    DZ[2 * zf[f] + 1] = q[nf + f];
}

// FoldoverEnergy.step_limit, operation for operation: corner k of the sweep, at the point in
// Z (the current point v: the accepted trial, or v placed again) along DZ; its det is
// cc + bb t + aa t^2. LIM[k] = the step t1 past which the det is <= 0 up to the first trial
// step s0 (INFINITY: none, or the det stays positive up to 2 s0).
__kernel void limit_corner(__global const double *S, __global const double *Z,
                           __global const double *DZ, __global const int *CI,
                           __global const double *W, __global double *LIM, const int nc)
{
    const int k = get_global_id(0);
    if (k >= nc)
        return;
    const int4 ci = vload4(k, CI);
    const double2 p0 = vload2(ci.z, Z), p1 = vload2(ci.x, Z), p2 = vload2(ci.y, Z);
    const double2 d0 = vload2(ci.z, DZ), d1 = vload2(ci.x, DZ), d2 = vload2(ci.y, DZ);
    __global const double *wk = W + 4 * k;
    const double w00 = wk[0], w01 = wk[1], w11 = wk[2];
    const double e1x = p1.x - p0.x, e1y = p1.y - p0.y, e2x = p2.x - p0.x, e2y = p2.y - p0.y;
    const double f1x = d1.x - d0.x, f1y = d1.y - d0.y, f2x = d2.x - d0.x, f2y = d2.y - d0.y;
    const double j00 = e1x * w00, j10 = e1y * w00;
    const double j01 = e1x * w01 + e2x * w11, j11 = e1y * w01 + e2y * w11;
    const double k00 = f1x * w00, k10 = f1y * w00;
    const double k01 = f1x * w01 + f2x * w11, k11 = f1y * w01 + f2y * w11;
    const double cc = j00 * j11 - j01 * j10;
    const double bb = (j00 * k11 + k00 * j11) - (j01 * k10 + k01 * j10);
    const double aa = k00 * k11 - k01 * k10;
    const double s0 = S[S_STEP];
    const double s1 = 2.0 * s0;  // det positive on [0, 2 s0]: no limit below s0
    double t1 = INFINITY;
    if (cc + MIN_NAN(bb, 0.0) * s1 + MIN_NAN(aa, 0.0) * (s1 * s1) > 0.0) {  // np.minimum
        LIM[k] = t1;
        return;
    }
    if (cc > 0.0 && aa == 0.0 && bb < 0.0)
        t1 = -cc / bb;
    const double disc = bb * bb - (4.0 * aa) * cc;
    if (cc > 0.0 && aa != 0.0 && disc >= 0.0) {
        const double sq = SQRT(disc);
        const double qq = -0.5 * (bb + ((bb >= 0.0) ? sq : -sq));
        const double r1 = qq / aa, r2 = cc / qq;
        const double lo = (r1 < r2) ? r1 : r2, hi = (r1 < r2) ? r2 : r1;
        if (aa < 0.0)
            t1 = hi;
        else if (bb < 0.0 && hi * (1.0 - LIMIT_MARGIN) >= s0)
            t1 = lo;
    }
    LIM[k] = t1;
}

// The minimum of LIM over a leaf (its first lane; order does not matter for a minimum)
__kernel void limit_leaf(__global const int *PI, __global double *PD, __global const double *LIM)
{
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    double mn = INFINITY;
    if (j0 == 0)
        for (int k = o; k < o + n; ++k)
            mn = MIN_NAN(mn, LIM[k]);
    pl.PMIN[w] = mn;
}

// solver.skipped_trials: the first trial step below the limit (with the margin), and how
// many halvings that skips; nothing in unguarded runs or for a direction that is no descent
__kernel void finish_limit(__global double *S, __global const int *PI, __global double *PD)
{
    if (get_global_id(0) != 0)
        return;
    S[S_SKIP] = 0.0;
    if (S[S_GUARD] == 0.0 || S[S_BAD] != 0.0)
        return;
    const Plan pl = plan_of(PI, PD);
    const double bound = total_min(&pl) * (1.0 + LIMIT_MARGIN);
    double step = S[S_STEP];
    int k = 0;
    while (k < TRIALS && step > bound) {
        step = step * 0.5;
        ++k;
    }
    S[S_STEP] = step;
    S[S_SKIP] = (double)k;
}

// ---- gradient gather and the memory pair ------------------------------------------------

// np.bincount of the corner gradients, row r: its free node's GS pairs in order, from 0.0,
// into out[f] (x) and out[nf + f] (y), f = the row's free node. rows = [row starts (nf + 1)
// | free node of each row] (rows in Z order); init: 0 where the first point has none
__kernel void gather_grad(__global const double *S, __global double *out,
                          __global const int *rows, __global const double *GS, const int nf,
                          const int init)
{
    const int r = get_global_id(0);
    if (r >= nf)
        return;
    const int f = rows[nf + 1 + r];
    double gx = 0.0, gy = 0.0;
    for (int j = rows[r]; j < rows[r + 1]; ++j) {
        gx = gx + GS[2 * j];
        gy = gy + GS[2 * j + 1];
    }
    if (init && S[S_OK] == 0.0)
        gx = gy = 0.0;
    out[f] = gx;
    out[nf + f] = gy;
}

// The accepted trial point vt = v + q step with its gradient gt: s = vt - v and y = gt - g into the
// spare ring slot, v = vt, g = gt, partials of s.y, s.s, y.y, y.(dpre y)
__kernel void update(__global const double *S, __global const int *PI, __global double *PD,
                     __global const double *q, __global const double *gt,
                     __global double *v, __global double *g, __global const double *dpre,
                     __global double *hs, __global double *hy)
{
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    const int n2 = pl.n;
    const int spare = SLOT((int)S[S_LEN]);
    const double step = S[S_STEP];
    __global double *sn = hs + spare * n2, *yn = hy + spare * n2;
    LEAF_SUMS(4, pl,
        const double gk = gt[k];
        const double vt = v[k] + q[k] * step;
        const double sk = vt - v[k], yk = gk - g[k];
        sn[k] = sk;
        yn[k] = yk;
        v[k] = vt;
        g[k] = gk;
        t[0] = sk * yk;
        t[1] = sk * sk;
        t[2] = yk * yk;
        t[3] = yk * (dpre[k] * yk);)
}

__kernel void finish_pair(__global double *S, __global const int *PI, __global double *PD)
{
    if (get_global_id(0) != 0)
        return;
    const Plan pl = plan_of(PI, PD);
    const double sy = total(&pl, 0), ss = total(&pl, 1), yy = total(&pl, 2);
    const double ydy = total(&pl, 3);
    if (sy > CURVATURE * SQRT(ss * yy)) {
        const int len = (int)S[S_LEN], spare = SLOT(len);
        S[S_RHO + spare] = 1.0 / sy;
        S[S_SY + spare] = sy;
        S[S_YDY + spare] = ydy;
        if (len < M)
            S[S_LEN] = len + 1;
        else
            S[S_START] = (double)((((int)S[S_START]) + 1) % SLOTS);
    }
}
