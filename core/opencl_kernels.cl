// EEGT iteration kernels (float64). Every formula is written in the same operation order as
// the NumPy reference (core/quality.py, core/transform.py, core/engine_numpy.py) and FP
// contraction is off, so results match NumPy to the last bits wherever the math library
// calls (hypot, pow) agree. Faces come in arity groups laid out like NumPy's (n, F) arrays:
// corner k of face j of a group is nodes[k * F + j]. Host-side defines:
//   MAXN  largest arity of a generic n-gon group (private array size)
// Parameters are kernel arguments (one build per device serves every parameter set); the
// pow modes say how NumPy evaluates x ** c and x ** eta (0 pow, 1 square, 2 identity, 3 ones,
// 4 sqrt, 5 reciprocal), mirroring ndarray.__pow__'s fast paths for scalar exponents.

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#ifndef MAXN
#define MAXN 8
#endif

// ---- NumPy-compatible helpers ----------------------------------------------------------

static inline double np_pow(const double x, const double e, const int mode)
{
    switch (mode) {
    case 1: return x * x;
    case 2: return x;
    case 3: return 1.0;
    case 4: return sqrt(x);
    case 5: return 1.0 / x;
    default: return pow(x, e);
    }
}

static inline void load_face(const int n, __global const int *nodes, const int F, const int j,
                             __global const double2 *P, double *X, double *Y)
{
    for (int k = 0; k < n; ++k) {
        const double2 p = P[nodes[k * F + j]];
        X[k] = p.x;
        Y[k] = p.y;
    }
}

// Mean ratio of one face (quality.py: group_quality). cos_a, inv_sin: regular n-gon corner.
static inline double mean_ratio(const int n, const double *X, const double *Y,
                                const double cos_a, const double inv_sin, const double two_sqrt3)
{
    double EX[MAXN], EY[MAXN];
    for (int k = 0; k < n; ++k) {
        const int k1 = (k + 1 == n) ? 0 : k + 1;
        EX[k] = X[k1] - X[k];
        EY[k] = Y[k1] - Y[k];
    }
    if (n == 3) {
        const double two_area = EX[0] * EY[1] - EY[0] * EX[1];
        double ssq = EX[0] * EX[0] + EY[0] * EY[0];
        ssq = ssq + (EX[1] * EX[1] + EY[1] * EY[1]);
        ssq = ssq + (EX[2] * EX[2] + EY[2] * EY[2]);
        return (two_area > 0.0 && ssq > 0.0) ? (two_sqrt3 * two_area) / ssq : 0.0;
    }
    const double scale = 2.0 * inv_sin;
    double sum = 0.0;
    int ok = 1;
    for (int k = 0; k < n; ++k) {
        const int km = (k == 0) ? n - 1 : k - 1;
        const double PX = EX[km], PY = EY[km];
        const double det = PX * EY[k] - PY * EX[k];
        const double e1sq = EX[k] * EX[k] + EY[k] * EY[k];
        double fro, qk;
        if (n == 4) {
            fro = (e1sq + PX * PX) + PY * PY;
            qk = det > 0.0 ? (2.0 * det) / fro : 0.0;
        } else {
            const double mx = (-PX - cos_a * EX[k]) * inv_sin;
            const double my = (-PY - cos_a * EY[k]) * inv_sin;
            fro = (e1sq + mx * mx) + my * my;
            qk = det > 0.0 ? (scale * det) / fro : 0.0;
        }
        ok = ok && det > 0.0 && fro > 0.0;
        sum = (k == 0) ? qk : sum + qk;
    }
    return ok ? sum / (double)n : 0.0;
}

static inline double sum_of(const int n, const double *V)
{
    double s = V[0];
    for (int k = 1; k < n; ++k) s = s + V[k];
    return s;
}

static inline double mean_of(const int n, const double *V) { return sum_of(n, V) / (double)n; }

// p^s - p for every corner of one face (transform.py: group_transform_delta), times w.
static inline void transform_moves(const int n, const int R, const double *X, const double *Y,
                                   const double lam, const double w, const int area,
                                   __global double2 *cmove, const int co, const int F,
                                   const int j)
{
    double NX[MAXN], NY[MAXN], SX[MAXN], SY[MAXN], L[MAXN];
    for (int k = 0; k < n; ++k) {
        double nx = 0.0, ny = 0.0;
        for (int r = 1; r <= R; ++r) {
            const int kp = (k + r) % n;
            const int km = (k - r + n) % n;
            nx = nx + (Y[kp] - Y[km]);
            ny = ny + (X[km] - X[kp]);
        }
        NX[k] = nx * lam;  // lambda n_k
        NY[k] = ny * lam;
        SX[k] = X[k] + NX[k];
        SY[k] = Y[k] + NY[k];
    }
    double before, after;
    if (area) {  // sqrt of the absolute shoelace area
        for (int k = 0; k < n; ++k) {
            const int k1 = (k + 1 == n) ? 0 : k + 1;
            L[k] = X[k] * Y[k1] - X[k1] * Y[k];
        }
        before = sqrt(0.5 * fabs(sum_of(n, L)));
        for (int k = 0; k < n; ++k) {
            const int k1 = (k + 1 == n) ? 0 : k + 1;
            L[k] = SX[k] * SY[k1] - SX[k1] * SY[k];
        }
        after = sqrt(0.5 * fabs(sum_of(n, L)));
    } else {  // mean edge length (paper): the ratio of edge-length sums
        for (int k = 0; k < n; ++k) {
            const int k1 = (k + 1 == n) ? 0 : k + 1;
            const double ex = X[k1] - X[k], ey = Y[k1] - Y[k];
            L[k] = sqrt(ex * ex + ey * ey);
        }
        before = sum_of(n, L);
        for (int k = 0; k < n; ++k) {
            const int k1 = (k + 1 == n) ? 0 : k + 1;
            const double ex = SX[k1] - SX[k], ey = SY[k1] - SY[k];
            L[k] = sqrt(ex * ex + ey * ey);
        }
        after = sum_of(n, L);
    }
    const double s = after > 0.0 ? before / after : 1.0;
    const double CX = mean_of(n, X);
    const double CY = mean_of(n, Y);
    const double oms = 1.0 - s;
    for (int k = 0; k < n; ++k) {
        const double DX = oms * (CX - X[k]) + s * NX[k];
        const double DY = oms * (CY - Y[k]) + s * NY[k];
        cmove[co + k * F + j] = (double2)(DX * w, DY * w);
    }
}

// ---- nearest boundary node (distance.py: NearestBoundary.query) -------------------------
// The exact minimum of dx * dx + dy * dy over the query's quadtree leaf list (which holds
// the nearest node for every point of the leaf cell), or over all nodes outside the tree.
// Per-face cache (temporal coherence, still exact): the last full search's position q0,
// leaf cell, its NCACHE nearest nodes of the leaf list and G = the distance from q0 to the
// next one. While the centroid q stays in that leaf and min_cached |q - b| < G - |q - q0|
// (with round-off margins), no other node of the list can be nearer, so the cached minimum
// is the value the full search would return, bit for bit.

#define NCACHE 4
#define GAP_MARGIN 1e-9

static inline double brute_d2(const double qx, const double qy, __global const double2 *bxy,
                              const int n_bnd)
{
    double best = INFINITY;
    for (int e = 0; e < n_bnd; ++e) {
        const double2 b = bxy[e];
        const double dx = b.x - qx, dy = b.y - qy;
        best = fmin(best, dx * dx + dy * dy);
    }
    return best;
}

static inline double nearest_d(const double qx, const double qy,
                               __global const int *tree_int, __global const double2 *bxy,
                               const double ox, const double oy, const double scale,
                               const double lim, const double top, const int depth,
                               const int n_levels, const int n_bnd,
                               __global int4 *restrict cache_k, __global int2 *restrict cache_l,
                               __global long2 *restrict cache_c,
                               __global double4 *restrict cache_d, const int gj)
{
    // tree_int: [level_off (n_levels + 1)] then child, leaf_start, leaf_len (each total long),
    // then the leaf candidate lists
    const int total = tree_int[n_levels];
    __global const int *child = tree_int + n_levels + 1;
    __global const int *lstart = child + total;
    __global const int *llen = lstart + total;
    __global const int *cand = llen + total;
    const int inside = (qx >= ox) && (qx - ox < lim) && (qy >= oy) && (qy - oy < lim);
    if (!inside) {  // outside the tree's square: brute force, like NumPy
        cache_l[gj] = (int2)(-1, 0);
        return sqrt(brute_d2(qx, qy, bxy, n_bnd));
    }
    const long ix = (long)fmin(fmax(floor((qx - ox) * scale), 0.0), top);
    const long iy = (long)fmin(fmax(floor((qy - oy) * scale), 0.0), top);
    const int2 cl = cache_l[gj];
    if (cl.x >= 0) {
        const int shift = depth - cl.x;
        const long2 cell = cache_c[gj];
        if ((ix >> shift) == cell.x && (iy >> shift) == cell.y) {
            const int4 ck = cache_k[gj];
            const int ks[4] = {ck.x, ck.y, ck.z, ck.w};
            double m = INFINITY;
            for (int i = 0; i < NCACHE; ++i) {
                if (ks[i] < 0) break;
                const double2 b = bxy[ks[i]];
                const double dx = b.x - qx, dy = b.y - qy;
                m = fmin(m, dx * dx + dy * dy);
            }
            const double4 cd = cache_d[gj];
            const double mx = qx - cd.x, my = qy - cd.y;
            const double d = sqrt(m);
            if ((d + sqrt(mx * mx + my * my)) * (1.0 + GAP_MARGIN) < cd.z * (1.0 - GAP_MARGIN))
                return d;
        }
    }
    int start = 0, len = 0, level = 0, node = 0;
    for (; level < n_levels; ++level) {
        const int at = tree_int[level] + node;
        const int ch = child[at];
        if (ch < 0) {
            start = lstart[at];
            len = llen[at];
            break;
        }
        const int shift = depth - level - 1;
        node = ch + (int)((ix >> shift) & 1) + 2 * (int)((iy >> shift) & 1);
    }
    // the NCACHE + 1 smallest d2 of the leaf list, ascending (bd[0] is the exact minimum)
    double bd[NCACHE + 1];
    int bk[NCACHE + 1];
    for (int i = 0; i <= NCACHE; ++i) {
        bd[i] = INFINITY;
        bk[i] = -1;
    }
    for (int e = start; e < start + len; ++e) {
        const int k = cand[e];
        const double2 b = bxy[k];
        const double dx = b.x - qx, dy = b.y - qy;
        const double d2 = dx * dx + dy * dy;
        if (d2 < bd[NCACHE]) {
            int p = NCACHE;
            while (p > 0 && bd[p - 1] > d2) {
                bd[p] = bd[p - 1];
                bk[p] = bk[p - 1];
                --p;
            }
            bd[p] = d2;
            bk[p] = k;
        }
    }
    if (bk[0] < 0) {  // an empty leaf cannot happen; stay exact anyway
        cache_l[gj] = (int2)(-1, 0);
        return sqrt(brute_d2(qx, qy, bxy, n_bnd));
    }
    const int shift = depth - level;
    cache_k[gj] = (int4)(bk[0], bk[1], bk[2], bk[3]);
    cache_l[gj] = (int2)(level, 0);
    cache_c[gj] = (long2)(ix >> shift, iy >> shift);
    cache_d[gj] = (double4)(qx, qy, sqrt(bd[NCACHE]), 0.0);
    return sqrt(bd[0]);
}

// ---- kernels ---------------------------------------------------------------------------

#define GROUP_ARGS                                                                           \
    __global const int *restrict nodes, const int F, const int fo, const int co, const int n, \
        const int R, const double cos_a, const double inv_sin
#define TREE_ARGS                                                                            \
    __global const int *restrict tree_int, __global const double2 *restrict bxy,            \
        const double ox, const double oy, const double scale, const double lim,              \
        const double top, const int depth, const int n_levels, const int n_bnd,              \
        const double lbar, const double dfloor, const double c, const int pow_c,              \
        __global int4 *restrict cache_k, __global int2 *restrict cache_l,                    \
        __global long2 *restrict cache_c, __global double4 *restrict cache_d

#define MAKE_KERNELS(SUF, NN)                                                                \
    __kernel void quality_##SUF(GROUP_ARGS, __global const double2 *restrict P,              \
                                __global double *restrict q, const double two_sqrt3)         \
    {                                                                                        \
        const int j = get_global_id(0);                                                      \
        if (j >= F) return;                                                                  \
        double X[MAXN], Y[MAXN];                                                             \
        load_face(NN, nodes, F, j, P, X, Y);                                                 \
        q[fo + j] = mean_ratio(NN, X, Y, cos_a, inv_sin, two_sqrt3);                         \
    }                                                                                        \
    /* refresh != 0: the distance weight f_j first (nearest node to the centroid) */      \
    __kernel void move_##SUF(GROUP_ARGS, __global const double2 *restrict P,                 \
                             __global const double *restrict q,                              \
                             __global double *restrict fdist,                                \
                             __global double2 *restrict cmove, __global double *restrict wf, \
                             const double a, const double eta, const int pow_eta,            \
                             const double inv_weight, const int area, const int refresh,     \
                             TREE_ARGS)                                                      \
    {                                                                                        \
        const int j = get_global_id(0);                                                      \
        if (j >= F) return;                                                                  \
        double X[MAXN], Y[MAXN];                                                             \
        load_face(NN, nodes, F, j, P, X, Y);                                                 \
        double fj;                                                                           \
        if (refresh) {                                                                       \
            const double d = nearest_d(mean_of(NN, X), mean_of(NN, Y), tree_int, bxy, ox,    \
                                       oy, scale, lim, top, depth, n_levels, n_bnd, cache_k, \
                                       cache_l, cache_c, cache_d, fo + j);                   \
            fj = np_pow(lbar / fmax(d, dfloor), c, pow_c);                                   \
            fdist[fo + j] = fj;                                                              \
        } else {                                                                             \
            fj = fdist[fo + j];                                                              \
        }                                                                                    \
        const double qj = q[fo + j];                                                         \
        const double lam = a * (1.0 - qj);                                                   \
        const double g = qj > 0.0 ? np_pow(1.0 - qj, eta, pow_eta) : inv_weight;             \
        const double w = fj * g;                                                             \
        wf[fo + j] = w;                                                                      \
        transform_moves(NN, R, X, Y, lam, w, area, cmove, co, F, j);                         \
    }                                                                                        \
    __kernel void mark_##SUF(GROUP_ARGS, __global const double *restrict q,                  \
                             __global int *restrict flag)                                    \
    {                                                                                        \
        const int j = get_global_id(0);                                                      \
        if (j >= F) return;                                                                  \
        if (q[fo + j] == 0.0)                                                                \
            for (int k = 0; k < NN; ++k) flag[nodes[k * F + j]] = 1;                         \
    }

MAKE_KERNELS(tri, 3)
MAKE_KERNELS(quad, 4)
MAKE_KERNELS(ngon, n)

// Stitching (eq. 18) as a gather: node i sums its incident corners in the order NumPy's
// bincount meets them (CSR rows built on the host), then moves by sum(w d) / sum(w).
__kernel void stitch(const int N, __global const int *restrict row,
                     __global const int *restrict ccorner, __global const int *restrict cface,
                     __global const double2 *restrict cmove, __global const double *restrict wf,
                     __global double2 *restrict P, __global double2 *restrict old)
{
    const int i = get_global_id(0);
    if (i >= N) return;
    const double2 p = P[i];
    old[i] = p;
    const int e0 = row[i], e1 = row[i + 1];
    if (e0 == e1) return;
    double sx = 0.0, sy = 0.0, sw = 0.0;
    for (int e = e0; e < e1; ++e) {
        const double2 m = cmove[ccorner[e]];
        sx += m.x;
        sy += m.y;
        sw += wf[cface[e]];
    }
    if (sw > 0.0) {
        const double dx = sx / sw, dy = sy / sw;
        if (dx != 0.0 || dy != 0.0) P[i] = (double2)(p.x + dx, p.y + dy);
    }
}

// Smoothing: every marked node that moved this iteration goes back; flags are cleared;
// out[3] (zeroed by stats_final) becomes 1 when some node went back.
__kernel void revert(const int N, __global int *restrict flag, __global double2 *restrict P,
                     __global const double2 *restrict old, __global double *restrict out)
{
    const int i = get_global_id(0);
    if (i >= N || !flag[i]) return;
    flag[i] = 0;
    const double2 p = P[i], o = old[i];
    if (p.x != o.x || p.y != o.y) {
        P[i] = o;
        out[3] = 1.0;
    }
}

// Stats, stage 1: work-item g reduces the contiguous chunk [g * chunk, (g + 1) * chunk).
__kernel void stats_partial(const int F, const int chunk, __global const double *restrict q,
                            __global int *restrict pcount, __global double *restrict pmin,
                            __global double *restrict psum)
{
    const int g = get_global_id(0);
    const int a = g * chunk;
    const int b = min(a + chunk, F);
    int cnt = 0;
    double mn = INFINITY, s = 0.0;
    for (int j = a; j < b; ++j) {
        const double v = q[j];
        cnt += (v == 0.0);
        mn = fmin(mn, v);
        s += v;
    }
    pcount[g] = cnt;
    pmin[g] = mn;
    psum[g] = s;
}

// Stats, stage 2: one work-item folds the partials in order; out = (count, min, sum, 0).
__kernel void stats_final(const int G, __global const int *restrict pcount,
                          __global const double *restrict pmin,
                          __global const double *restrict psum, __global double *restrict out)
{
    if (get_global_id(0) != 0) return;
    int cnt = 0;
    double mn = INFINITY, s = 0.0;
    for (int g = 0; g < G; ++g) {
        cnt += pcount[g];
        mn = fmin(mn, pmin[g]);
        s += psum[g];
    }
    out[0] = (double)cnt;
    out[1] = mn;
    out[2] = s;
    out[3] = 0.0;
}
