// The global stage's L-BFGS (core/global_untangle.py: _lbfgs with _Energy or _LiftEnergy)
// as many-work-item float64 kernels, bit-identical to the host solver on any work-group
// size, lane count and device. The host (core/lbfgs_parallel.py) enqueues the kernels of an
// iteration and reads back one small status block per line-search trial; every scalar of
// the solver (step, slope, alphas, ring state) lives in the device buffer S.
//
// Same numbers as NumPy: every floating-point operation is the NumPy code's, same operands,
// same order, FP contraction off. np.bincount is a per-row gather in index order (CSR built
// on the host), np.add.reduce is NumPy's pairwise summation split over work-items:
//   - a vector of n terms is cut like NumPy cuts it: chunks of 8192, each halved (at n / 2
//     rounded down to a multiple of 8) down to leaves of at most 128 terms;
//   - a leaf is 8 partial sums r[j] (terms j, j + 8, ..., in order), combined as
//     ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)), then the n % 8 tail terms in order
//     (a leaf under 8 terms: 0.0 + its terms in order). A work-item computes LPW = 8 / LANES
//     of those partial sums: LANES 1 finishes the leaf itself, LANES > 1 writes its lanes'
//     partial sums and tail terms, which the next stage combines in that fixed order;
//   - one work-item per chunk adds its leaves along the same binary tree (chunk_sums), and
//     a single-work-item finish kernel adds the chunk sums in order, from 0.0.
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
//   trial:     trial_point (vt = v + q step), fold_corner or lift_corner + lift_element
//              (leaf partials of the energy terms, min det), finish_trial (Armijo test)
//   accepted:  fold_grad or lift_grad (dF/dE per corner), update (gradient gather per free
//              coordinate, s and y into the spare ring slot, v = vt, g = gt, partials of
//              s.y, s.s, y.y, y.dpre y), finish_pair (L-BFGS memory update)

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#ifndef M
#define M 4  // LBFGS_MEMORY (the host passes it)
#endif
#ifndef LANES
#define LANES 1  // work-items per leaf of 128 terms: 1, 2, 4 or 8 (the host passes it)
#endif
#if LANES != 1 && LANES != 2 && LANES != 4 && LANES != 8
#error "LANES must be 1, 2, 4 or 8"
#endif
#define SLOTS (M + 1)  // ring slots: M pairs and a spare for the candidate pair
#define LPW (8 / LANES)  // leaf partial sums per work-item
#define PPL ((LANES == 1) ? 1 : 16)  // partials per leaf and sum: the sum, or 8 lanes + 8 tails
#define THETA 0.0625  // global_untangle.THETA
#define PENALTY 1000.0  // LIFT_PENALTY
#define BARRIER 0.01  // LIFT_BARRIER
#define CHUNK 8192  // NumPy's reduction buffer size
#define PW_BLOCK 128  // NumPy's pairwise block

#define SQRT(x) __builtin_sqrt(x)
#define FABS(x) __builtin_fabs(x)
#define MIN_NAN(m, d) ((isnan(m) || (m) <= (d)) ? (m) : (d))  // np.minimum: NaN wins

// ---- scalars in S (doubles; counts stored as exact small integers) --------------------------
// 0..7 are the status block the host reads back after each trial.
#define S_STATUS 0  // 0 trial rejected (step halved), 1 accepted, 2 not a descent direction
#define S_ET 1  // the trial's energy
#define S_DMIN 2  // the trial's smallest corner det
#define S_LEN 3  // pairs in memory
#define S_E 4  // energy of the current point
#define S_START 5  // ring slot of the oldest pair
#define S_SLOPE 6
#define S_STEP 7
#define S_EPS 8
#define S_QC 9
#define S_H0 10
#define S_GUARD 11
#define S_OK 12  // the first evaluation may have a gradient (lift: every det > 0)
#define S_BAD 13  // the direction is not a descent direction
#define S_COEF 14  // the second loop's coefficient al - rho y.q
#define S_ALPHA 16  // [M]
#define S_RHO (S_ALPHA + M)  // [SLOTS] per ring slot: 1 / s.y
#define S_SY (S_RHO + SLOTS)  // [SLOTS] s.y
#define S_YDY (S_SY + SLOTS)  // [SLOTS] y.(dpre y)
#define S_LEN_ALL (S_YDY + SLOTS)

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

#define COMBINE8(r) ((((r)[0] + (r)[1]) + ((r)[2] + (r)[3])) + (((r)[4] + (r)[5]) + ((r)[6] + (r)[7])))

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
        __global double *pp = (pl).P + 16 * leaf + j0;                    \
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
    __global const double *r = P + 16 * leaf;
    const int full = m - m % 8;
    double res = full ? COMBINE8(r) : 0.0;
    for (int t = 0; t < m - full; ++t)
        res = res + r[8 + t];
    return res;
#endif
}

// NumPy's pairwise sum of one chunk of m terms whose leaves start at `first`: the recursion
// pairwise(m) = m <= 128 ? leaf : pairwise(m2) + pairwise(m - m2), unrolled on a stack
static double chunk_sum(__global const double *P, const int first, const int m)
{
    int fn[10], fs[10];
    double fl[10];
    int sp = 0, leaf = first;
    double ret = 0.0;
    fn[0] = m;
    fs[0] = 0;
    while (sp >= 0) {
        const int k = fn[sp];
        int k2 = k / 2;
        k2 -= k2 % 8;
        if (fs[sp] == 0) {
            if (k <= PW_BLOCK) {
                ret = leaf_sum(P, leaf, k);
                ++leaf;
                --sp;
            } else {
                fs[sp] = 1;
                ++sp;
                fn[sp] = k2;
                fs[sp] = 0;
            }
        } else if (fs[sp] == 1) {
            fl[sp] = ret;
            fs[sp] = 2;
            ++sp;
            fn[sp] = k - k2;
            fs[sp] = 0;
        } else {
            ret = fl[sp] + ret;
            --sp;
        }
    }
    return ret;
}

// One work-item per chunk: the chunk's pairwise sum of each of the first `sums` sums, and
// (mins != 0) the minimum of its work-items' minima
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

// np.add.reduce of sum s: the chunk sums in order from 0.0 (one chunk: its tree here)
static double total(const Plan *pl, const int s)
{
    double acc = 0.0;
    if (pl->nch == 1)
        return acc + chunk_sum(pl->P + s * pl->ps, 0, pl->n);
    for (int c = 0; c < pl->nch; ++c)
        acc = acc + pl->CS[s * pl->nch + c];
    return acc;
}

static double total_min(const Plan *pl)
{
    double mn = INFINITY;
    if (pl->nch == 1) {
        for (int k = 0; k < pl->nl * LANES; ++k)
            mn = MIN_NAN(mn, pl->PMIN[k]);
    } else {
        for (int c = 0; c < pl->nch; ++c)
            mn = MIN_NAN(mn, pl->CM[c]);
    }
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
// z = [trial point v (n2) | fixed coordinates]; CI = the z positions of each corner's
// [x1 | y1 | x2 | y2 | x0 | y0] (blocks of nc).

__kernel void trial_point(__global const double *S, __global double *z,
                          __global const double *v, __global const double *q, const int n2)
{
    const int i = get_global_id(0);
    if (i < n2)
        z[i] = v[i] + q[i] * S[S_STEP];
}

#define JACOBIAN                                                              \
    const double x0 = z[CI[4 * nc + k]], y0 = z[CI[5 * nc + k]];             \
    const double e1x = z[CI[k]] - x0, e1y = z[CI[nc + k]] - y0;              \
    const double e2x = z[CI[2 * nc + k]] - x0, e2y = z[CI[3 * nc + k]] - y0; \
    const double w00 = W[k], w01 = W[nc + k], w11 = W[2 * nc + k];           \
    const double j00 = e1x * w00, j10 = e1y * w00;                           \
    const double j01 = e1x * w01 + e2x * w11, j11 = e1y * w01 + e2y * w11;   \
    const double d = j00 * j11 - j01 * j10;                                  \
    const double tf = ((j00 * j00 + j01 * j01) + j10 * j10) + j11 * j11;

// W = [w00 | w01 | w11 | weight] (blocks of nc)
#define FOLD_TERMS                                                           \
    const double eps = S[S_EPS], dd = d * d;                                 \
    const double root = SQRT(dd + eps * eps);                                \
    const double chi = (d >= 0.0) ? 0.5 * (d + root) : ((0.5 * eps) * eps) / (root + FABS(d)); \
    const double num = (1.0 - THETA) * tf + THETA * (dd + 1.0);              \
    const double inv_chi = W[3 * nc + k] / chi;

// _Energy._eval (power 1): partials of the terms num / chi w and the minimum det
__kernel void fold_corner(__global const double *S, __global const int *PI,
                          __global double *PD, __global const double *z,
                          __global const int *CI, __global const double *W)
{
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    const int nc = pl.n;
    double mn = INFINITY;
    LEAF_SUMS(1, pl,
        JACOBIAN
        FOLD_TERMS
        mn = MIN_NAN(mn, d);
        t[0] = num * inv_chi;)
    pl.PMIN[w] = mn;
}

// dF/dE = dF/dJ W^-T of corner k into G = [ge1x | ge2x | ge1y | ge2y] (blocks of nc)
#define CORNER_GRAD(a, b)                                                    \
    const double g00 = a * j00 + b * j11, g10 = a * j10 - b * j01;           \
    const double g01 = a * j01 - b * j10, g11 = a * j11 + b * j00;           \
    G[k] = g00 * w00 + g01 * w01;                                            \
    G[nc + k] = g01 * w11;                                                   \
    G[2 * nc + k] = g10 * w00 + g11 * w01;                                   \
    G[3 * nc + k] = g11 * w11;

__kernel void fold_grad(__global const double *S, __global const double *z,
                        __global const int *CI, __global const double *W, __global double *G,
                        const int nc)
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

// _LiftEnergy._eval, corners: R = 1 / u = q_corner, partials of weight u, minimum det
__kernel void lift_corner(__global const double *S, __global const int *PI,
                          __global double *PD, __global const double *z,
                          __global const int *CI, __global const double *W,
                          __global double *R)
{
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    const int nc = pl.n;
    double mn = INFINITY;
    LEAF_SUMS(1, pl,
        JACOBIAN
        const double u = (0.5 * tf) / d;
        R[k] = 1.0 / u;
        mn = MIN_NAN(mn, d);
        t[0] = W[3 * nc + k] * u;)
    pl.PMIN[w] = mn;
}

// _LiftEnergy._eval, elements: q_e (its corners' R in index order / corners), the floor
// term's partials, dF/dq_e into DQ. EI = [eptr (ne + 1) | corners by element]; EN = [corner
// count | -1 / corner count] per element.
__kernel void lift_element(__global const double *S, __global const int *PI,
                           __global double *PD, __global const double *R,
                           __global const int *EI, __global const double *EN,
                           __global double *DQ)
{
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    const int ne = pl.n;
    const double qc = S[S_QC], kq = (2.0 * PENALTY) / qc;
    __global const int *ec = EI + ne + 1;
    LEAF_SUMS(1, pl,
        double sq = 0.0;
        for (int p = EI[k]; p < EI[k + 1]; ++p)
            sq = sq + R[ec[p]];
        const double qe = sq / EN[k];
        double gap = qc - qe;
        gap = (isnan(gap) || gap >= 0.0) ? gap : 0.0;
        gap = gap / qc;
        DQ[k] = -1.0 - kq * gap;
        t[0] = (PENALTY * gap) * gap - qe;)
}

// eid: each corner's element
__kernel void lift_grad(__global const double *z, __global const int *CI,
                        __global const double *W, __global double *G, const int nc,
                        __global const int *eid, __global const double *EN,
                        __global const double *DQ, const int ne)
{
    const int k = get_global_id(0);
    if (k >= nc)
        return;
    JACOBIAN
    const double u = (0.5 * tf) / d;
    const int e = eid[k];
    double de_du = (DQ[e] * EN[ne + e]) / (u * u);
    de_du = de_du + BARRIER * W[3 * nc + k];
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
        S[S_STATUS] = 2.0;
        return;
    }
    const double step = S[S_STEP];
    const int guard = S[S_GUARD] != 0.0;
    if (isfinite(et) && et <= S[S_E] + (1e-4 * step) * S[S_SLOPE] && !(guard && dmin <= 0.0)) {
        S[S_STATUS] = 1.0;
        S[S_E] = et;
    } else {
        S[S_STATUS] = 0.0;
        S[S_STEP] = step * 0.5;
    }
}

// ---- gradient gather and the memory pair ------------------------------------------------

// np.bincount of the corner gradients at free coordinate k: its row of GI = [row starts
// (nf + 1) | positions], a position p < 2 nc names ge1 (p < nc) or ge2 of corner p mod nc,
// p >= 2 nc the third node's -(ge1 + ge2) of corner p - 2 nc
static double gather(const int k, const int nf, const int nc, __global const int *GI,
                     __global const double *G)
{
    const int f = (k < nf) ? k : k - nf;
    __global const double *gc = G + ((k < nf) ? 0 : 2 * nc);
    __global const int *pos = GI + nf + 1;
    double s = 0.0;
    for (int p = GI[f]; p < GI[f + 1]; ++p) {
        const int c = pos[p];
        s = s + ((c < 2 * nc) ? gc[c] : -(gc[c - 2 * nc] + gc[c - nc]));
    }
    return s;
}

__kernel void gather_init(__global const double *S, __global double *g,
                          __global const int *GI, __global const double *G, const int nf,
                          const int nc)
{
    const int k = get_global_id(0);
    if (k < 2 * nf)
        g[k] = (S[S_OK] != 0.0) ? gather(k, nf, nc, GI, G) : 0.0;
}

// The accepted trial point vt = z: gt gathered, s = vt - v and y = gt - g into the spare
// ring slot, v = vt, g = gt, partials of s.y, s.s, y.y, y.(dpre y)
__kernel void update(__global const double *S, __global const int *PI, __global double *PD,
                     __global const double *z, __global double *v, __global double *g,
                     __global const double *dpre, __global double *hs, __global double *hy,
                     __global const int *GI, __global const double *G, const int nc)
{
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    const int n2 = pl.n, nf = n2 / 2;
    const int spare = SLOT((int)S[S_LEN]);
    __global double *sn = hs + spare * n2, *yn = hy + spare * n2;
    LEAF_SUMS(4, pl,
        const double gk = gather(k, nf, nc, GI, G);
        const double vt = z[k];
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
    if (sy > 1e-12 * SQRT(ss * yy)) {
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
