// EEGT iteration kernels (float64). Every formula is written in the same operation order as
// the NumPy reference (core/metrics/face_quality.py, core/eegt/transform.py, core/eegt/engine_numpy.py) and FP
// contraction is off, so results match NumPy to the last bit (no math library calls: powers
// are core.fpmath's algorithm, sums are added in NumPy's order; both are in common.cl,
// which the loader puts in front of this file). Faces come in arity groups laid out like
// NumPy's (n, F) arrays: corner k of face j of a group is nodes[k * F + j].
// Host-side defines (core.opencl.build.eegt_options; a missing one stops the build):
//   MAXN    largest arity of a generic n-gon group (private array size)
//   NCACHE  nearest boundary nodes cached per face (the distance refresh)
//   FP_*, POW_*, PW_BLOCK, CHUNK  core.fpmath's constants (fpmath_options(); common.cl)
// Parameters are kernel arguments (one build per device serves every parameter set); the
// pow codes (core.fpmath.POW_CODES) say how core.fpmath.power evaluates x ** c and x ** eta:
// NumPy's exact fast paths for e in {2, 1, 0, 0.5, -1}, else exp(e log x).
// The paper's terms: step_size (lambda, eq. 17), stretch_vector / TRI_PAPER_STRETCH (the
// stretch), transform_moves (stretch and shrink), distance_weight (f, eq. 20),
// quality_weight (g, eq. 21), FACE_WEIGHT (w = f g), stitch (eq. 18); NumPy's twins in
// core/eegt/engine_numpy.py (same names) and core/eegt/transform.py.
// Per-face targets (core/metrics/targets.py): the *_tgt kernels read a group's (6, n, F) target
// array tg (fields x, y, c_n K_x, c_n K_y, cos_a, inv_sin; corner k of face j of field m is
// tg[(m * n + k) * F + j]) and take the general formulas for every arity (triangles written
// out with scalars, quads and n-gons by the generic functions).

#ifndef MAXN
#error "build with MAXN (core.opencl.build.eegt_options)"
#endif

static inline void load_face(const int n, __global const int *nodes, const int F, const int j,
                             __global const double2 *P, double *X, double *Y)
{
    for (int k = 0; k < n; ++k) {
        const double2 p = P[nodes[k * F + j]];
        X[k] = p.x;
        Y[k] = p.y;
    }
}

// ---- NumPy's float64 add.reduce order -------------------------------------------------
// A sum over the corners of an (n, F) arity group (axis 0) runs the corners as NumPy's outer
// loop when F > 1: sequential. With F == 1 (a group of one face) NumPy's iterator drops the
// size-1 axis and the corners become its inner loop: pairwise_sum, whose base case adds 8
// interleaved partial sums once n >= 8, and which halves runs longer than PW_BLOCK (at n / 2
// rounded down to a multiple of 8). Result: 0 + pairwise(V[0..n)) (n <= CHUNK, NumPy's
// buffer size, beyond which it would also fold buffer-sized blocks in order).

// pairwise_sum's base case (n <= PW_BLOCK) of V[0..n)
static inline double np_block_sum(const double *V, const int n)
{
    double r;
    PAIRWISE_LEAF(r, int, n, V[pw_i]);
    return r;
}

// NumPy's pairwise_sum of V[0..n) (common.cl: PAIRWISE_TREE)
static inline double np_pairwise(const double *V, const int n)
{
#if MAXN > PW_BLOCK
    double r;
    PAIRWISE_TREE(r, int, n, np_block_sum(V + pw_off, pw_len));
    return r;
#else
    return np_block_sum(V, n);
#endif
}

// X.sum(axis=0) of a group of F faces, for one face's n values
static inline double sum_axis0(const int n, const double *V, const int F)
{
    if (F == 1) return 0.0 + np_pairwise(V, n);
    double s = V[0];
    for (int k = 1; k < n; ++k) s = s + V[k];
    return s;
}

// X.mean(axis=0): the sum, then one division
static inline double mean_axis0(const int n, const double *V, const int F)
{
    return sum_axis0(n, V, F) / (double)n;
}

// a loop `total += V[k]` from zeros (transform.py: edge_sum): sequential for any F
static inline double sum_of(const int n, const double *V)
{
    double s = V[0];
    for (int k = 1; k < n; ++k) s = s + V[k];
    return s;
}

// Mean ratio of one face (quality.py: group_quality). cos_a, inv_sin: regular n-gon corner;
// F: the group's face count (the corner mean's summation order depends on it).
static inline double mean_ratio(const int n, const double *X, const double *Y,
                                const double cos_a, const double inv_sin, const double two_sqrt3,
                                const int F)
{
    double EX[MAXN], EY[MAXN], QK[MAXN];
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
        QK[k] = qk;
    }
    return ok ? mean_axis0(n, QK, F) : 0.0;
}

// Mean ratio of one face against its target (quality.py: _target_quality): corner k's
// cos_a = tg[(4 n + k) F + j], inv_sin = tg[(5 n + k) F + j].
static inline double target_ratio(const int n, const double *X, const double *Y,
                                  __global const double *tg, const int F, const int j)
{
    double EX[MAXN], EY[MAXN], QK[MAXN];
    for (int k = 0; k < n; ++k) {
        const int k1 = (k + 1 == n) ? 0 : k + 1;
        EX[k] = X[k1] - X[k];
        EY[k] = Y[k1] - Y[k];
    }
    int ok = 1;
    for (int k = 0; k < n; ++k) {
        const int km = (k == 0) ? n - 1 : k - 1;
        const double PX = EX[km], PY = EY[km];
        const double ca = tg[(4 * n + k) * F + j], ci = tg[(5 * n + k) * F + j];
        const double det = PX * EY[k] - PY * EX[k];
        const double e1sq = EX[k] * EX[k] + EY[k] * EY[k];
        const double mx = (-PX - ca * EX[k]) * ci;
        const double my = (-PY - ca * EY[k]) * ci;
        const double fro = (e1sq + mx * mx) + my * my;
        ok = ok && det > 0.0 && fro > 0.0;
        QK[k] = det > 0.0 ? ((2.0 * ci) * det) / fro : 0.0;
    }
    return ok ? mean_axis0(n, QK, F) : 0.0;
}

// ---- the paper's terms (engine_numpy.py / transform.py, same names) ----------------------

// lambda = a (1 - q), the element's step size (eq. 17; engine_numpy.step_size)
static inline double step_size(const double q, const double a) { return a * (1.0 - q); }

// The distance weight f(d) = (lbar / d)^c (eq. 20; engine_numpy.distance_weight), d clamped
// to dfloor = DIST_FLOOR lbar (the host's); pow_c = core.fpmath.power_code(c)
static inline double distance_weight(const double d, const double lbar, const double dfloor,
                                     const double c, const int pow_c)
{
    return np_pow(lbar / FMAX(d, dfloor), c, pow_c);
}

// The quality weight g(q) = (1 - q)^eta, inverted_weight for an inverted element (q = 0)
// (eq. 21; engine_numpy.quality_weight); 1 - q clamped at 0 (q may round to 1 + 1 ulp)
static inline double quality_weight(const double q, const double eta, const int pow_eta,
                                    const double inverted_weight)
{
    return q > 0.0 ? np_pow(FMAX(1.0 - q, 0.0), eta, pow_eta) : inverted_weight;
}

// The paper's stretch vector of corner k (transform.py: _stretch):
// n_k = sum_{r=1..R} rot(p_{k+r} - p_{k-r}), rot(x, y) = (y, -x)
static inline double2 stretch_vector(const int n, const int R, const int k, const double *X,
                                     const double *Y)
{
    double nx = 0.0, ny = 0.0;
    for (int r = 1; r <= R; ++r) {
        const int kp = (k + r) % n;
        const int km = (k - r + n) % n;
        nx = nx + (Y[kp] - Y[km]);
        ny = ny + (X[km] - X[kp]);
    }
    return (double2)(nx, ny);
}

#define NO_TARGET ((__global const double *)0)

// p^s - p for every corner of one face (transform.py: group_transform_delta), times w: the
// stretch p' = p + lambda n_k, then the shrink about the centroid c by s = before / after.
// tg: the group's targets (transform.py: _target_stretch), or NO_TARGET (the paper's stretch).
static inline void transform_moves(const int n, const int R, const double *X, const double *Y,
                                   const double lam, const double w, const int area,
                                   __global double2 *cmove, const int co, const int F,
                                   const int j, __global const double *tg)
{
    double NX[MAXN], NY[MAXN], SX[MAXN], SY[MAXN], L[MAXN];
    if (tg) {  // c_n cof(M) t_k, c_n M = P_centred (c_n K) summed corner by corner
        const double CX0 = mean_axis0(n, X, F);
        const double CY0 = mean_axis0(n, Y, F);
        double m00 = 0.0, m01 = 0.0, m10 = 0.0, m11 = 0.0;
        for (int k = 0; k < n; ++k) {
            const double xh = X[k] - CX0, yh = Y[k] - CY0;
            const double kx = tg[(2 * n + k) * F + j], ky = tg[(3 * n + k) * F + j];
            m00 = m00 + xh * kx;
            m01 = m01 + xh * ky;
            m10 = m10 + yh * kx;
            m11 = m11 + yh * ky;
        }
        for (int k = 0; k < n; ++k) {
            const double tx = tg[k * F + j], ty = tg[(n + k) * F + j];
            NX[k] = (m11 * tx - m10 * ty) * lam;
            NY[k] = (m00 * ty - m01 * tx) * lam;
            SX[k] = X[k] + NX[k];
            SY[k] = Y[k] + NY[k];
        }
    } else {
        for (int k = 0; k < n; ++k) {
            const double2 nk = stretch_vector(n, R, k, X, Y);
            NX[k] = nk.x * lam;  // lambda n_k
            NY[k] = nk.y * lam;
            SX[k] = X[k] + NX[k];
            SY[k] = Y[k] + NY[k];
        }
    }
    double before, after;
    if (area) {  // sqrt of the absolute shoelace area
        for (int k = 0; k < n; ++k) {
            const int k1 = (k + 1 == n) ? 0 : k + 1;
            L[k] = X[k] * Y[k1] - X[k1] * Y[k];
        }
        before = SQRT(0.5 * FABS(sum_axis0(n, L, F)));
        for (int k = 0; k < n; ++k) {
            const int k1 = (k + 1 == n) ? 0 : k + 1;
            L[k] = SX[k] * SY[k1] - SX[k1] * SY[k];
        }
        after = SQRT(0.5 * FABS(sum_axis0(n, L, F)));
    } else {  // mean edge length (paper): the ratio of edge-length sums
        for (int k = 0; k < n; ++k) {
            const int k1 = (k + 1 == n) ? 0 : k + 1;
            const double ex = X[k1] - X[k], ey = Y[k1] - Y[k];
            L[k] = SQRT(ex * ex + ey * ey);
        }
        before = sum_of(n, L);
        for (int k = 0; k < n; ++k) {
            const int k1 = (k + 1 == n) ? 0 : k + 1;
            const double ex = SX[k1] - SX[k], ey = SY[k1] - SY[k];
            L[k] = SQRT(ex * ex + ey * ey);
        }
        after = sum_of(n, L);
    }
    const double s = after > 0.0 ? before / after : 1.0;
    const double CX = mean_axis0(n, X, F);
    const double CY = mean_axis0(n, Y, F);
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

#ifndef NCACHE
#error "build with NCACHE (core.opencl.build.eegt_options)"
#endif
#define GAP_MARGIN 1e-9

static inline double brute_d2(const double qx, const double qy, __global const double2 *bxy,
                              const int n_bnd)
{
    double best = INFINITY;
    for (int e = 0; e < n_bnd; ++e) {
        const double2 b = bxy[e];
        const double dx = b.x - qx, dy = b.y - qy;
        best = FMIN(best, dx * dx + dy * dy);
    }
    return best;
}

// cxy: the leaf lists' node coordinates (cxy[e] = bxy[cand[e]], scanned contiguously);
// cache_k: NCACHE boundary node indices per face (the hit test reads the small bxy); cache_l: (leaf level or -1, leaf list start, leaf
// list length, 0); cache_c: leaf cell; cache_d: (q0x, q0y, G, 0).
// The full search of nearest_d (a cache miss): descend to the leaf unless level >= 0 gives
// it, scan its list, refill the cache. Kept out of line so that the cache-hit path stays a
// short loop body (inlined, it made every hit several times slower on pocl).
static double __attribute__((noinline))
nearest_full(const double qx, const double qy, const long ix, const long iy, int level,
             int start, int len, __global const int *tree_int, __global const double2 *bxy,
             __global const double2 *restrict cxy, const int depth, const int n_levels,
             const int n_bnd, __global int *restrict cache_k, __global int4 *restrict cache_l,
             __global long2 *restrict cache_c, __global double4 *restrict cache_d, const int gj)
{
    // tree_int: [level_off (n_levels + 1)] then child, leaf_start, leaf_len (each total long),
    // then the leaf candidate lists
    const int total = tree_int[n_levels];
    __global const int *child = tree_int + n_levels + 1;
    __global const int *lstart = child + total;
    __global const int *llen = lstart + total;
    int node = 0;
    if (level < 0) {
        for (level = 0; level < n_levels; ++level) {
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
    }
    // the NCACHE + 1 smallest d2 of the leaf list, ascending (bd[0] is the exact minimum)
    double bd[NCACHE + 1];
    int bk[NCACHE + 1];
    for (int i = 0; i <= NCACHE; ++i) {
        bd[i] = INFINITY;
        bk[i] = -1;
    }
    for (int e = start; e < start + len; ++e) {
        const int k = e;  // a leaf-list position while scanning (cxy[e] = bxy[cand[e]])
        const double2 b = cxy[k];
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
        cache_l[gj] = (int4)(-1, 0, 0, 0);
        return SQRT(brute_d2(qx, qy, bxy, n_bnd));
    }
    const int shift = depth - level;
    __global int *ck = cache_k + (long)gj * NCACHE;
    __global const int *cand = llen + total;
    for (int i = 0; i < NCACHE; ++i) ck[i] = bk[i] >= 0 ? cand[bk[i]] : -1;
    cache_l[gj] = (int4)(level, start, len, 0);
    cache_c[gj] = (long2)(ix >> shift, iy >> shift);
    cache_d[gj] = (double4)(qx, qy, SQRT(bd[NCACHE]), 0.0);
    return SQRT(bd[0]);
}

static inline double nearest_d(const double qx, const double qy,
                               __global const int *tree_int, __global const double2 *bxy,
                               __global const double2 *restrict cxy,
                               const double ox, const double oy, const double scale,
                               const double lim, const double top, const int depth,
                               const int n_levels, const int n_bnd,
                               __global int *restrict cache_k, __global int4 *restrict cache_l,
                               __global long2 *restrict cache_c,
                               __global double4 *restrict cache_d, const int gj)
{
    const int inside = (qx >= ox) && (qx - ox < lim) && (qy >= oy) && (qy - oy < lim);
    if (!inside) {  // outside the tree's square: brute force, like NumPy
        cache_l[gj] = (int4)(-1, 0, 0, 0);
        return SQRT(brute_d2(qx, qy, bxy, n_bnd));
    }
    const long ix = (long)FMIN(FMAX(FLOOR((qx - ox) * scale), 0.0), top);
    const long iy = (long)FMIN(FMAX(FLOOR((qy - oy) * scale), 0.0), top);
    const int4 cl = cache_l[gj];
    int start = 0, len = 0, level = -1;
    if (cl.x >= 0) {
        const int shift = depth - cl.x;
        const long2 cell = cache_c[gj];
        if ((ix >> shift) == cell.x && (iy >> shift) == cell.y) {
            __global const int *ck = cache_k + (long)gj * NCACHE;
            double m = INFINITY;
            for (int i = 0; i < NCACHE; ++i) {
                const int k = ck[i];
                if (k < 0) break;
                const double2 b = bxy[k];
                const double dx = b.x - qx, dy = b.y - qy;
                m = FMIN(m, dx * dx + dy * dy);
            }
            const double4 cd = cache_d[gj];
            const double mx = qx - cd.x, my = qy - cd.y;
            const double d = SQRT(m);
            if ((d + SQRT(mx * mx + my * my)) * (1.0 + GAP_MARGIN) < cd.z * (1.0 - GAP_MARGIN))
                return d;
            level = cl.x;  // same leaf, the gap test failed: rescan its list, no descent
            start = cl.y;
            len = cl.z;
        }
    }
    return nearest_full(qx, qy, ix, iy, level, start, len, tree_int, bxy, cxy, depth, n_levels,
                        n_bnd, cache_k, cache_l, cache_c, cache_d, gj);
}

// ---- kernels ---------------------------------------------------------------------------

#define GROUP_ARGS                                                                           \
    __global const int *restrict nodes, const int F, const int fo, const int co, const int n, \
        const int R, const double cos_a, const double inv_sin
#define TREE_ARGS                                                                            \
    __global const int *restrict tree_int, __global const double2 *restrict bxy,            \
        __global const double2 *restrict cxy,                                                \
        const double ox, const double oy, const double scale, const double lim,              \
        const double top, const int depth, const int n_levels, const int n_bnd,              \
        const double lbar, const double dfloor, const double c, const int pow_c,              \
        __global int *restrict cache_k, __global int4 *restrict cache_l,                     \
        __global long2 *restrict cache_c, __global double4 *restrict cache_d

// Quality: work-item g computes q of the faces [bounds[g], bounds[g + 1]) of its group, one
// of the blocks (<= PW_BLOCK faces) into which NumPy's pairwise q.sum() splits the group (the
// host's _SumPlan), and writes (count q == 0, min q, the block's sum, 0) to part[ro + g]:
// the sum as pairwise_sum's base case adds it (common.cl: PAIRWISE_LEAF, streamed here:
// 8 interleaved partial sums over the first m - m % 8 faces once m >= 8, a fixed tree of
// them, then the rest in order), so the host can finish q.sum() in NumPy's order. The
// partial sums rotate through r0..r7 (face t adds to r0, then r0 moves to r7), which keeps
// them in registers. QUALITY_BODY(j) defines v.
#define QUALITY_KERNEL(SUF, QUALITY_BODY) QUALITY_KERNEL_X(SUF, QUALITY_BODY, )
// EXTRA: more kernel arguments (a leading comma), or nothing
#define QUALITY_KERNEL_X(SUF, QUALITY_BODY, EXTRA)                                           \
    __kernel void quality_##SUF(GROUP_ARGS, __global const double2 *restrict P,              \
                                __global double *restrict q, const double two_sqrt3,         \
                                __global double4 *restrict part, const int ro,               \
                                __global const int *restrict bounds, const int n_blocks      \
                                EXTRA)                                                       \
    {                                                                                        \
        const int g = get_global_id(0);                                                      \
        if (g >= n_blocks) return;                                                           \
        const int j0 = bounds[g], j1 = bounds[g + 1];                                        \
        const int jb = j1 - j0 >= 8 ? j1 - (j1 - j0) % 8 : j0;                               \
        double cnt = 0.0, mn = INFINITY, s = -0.0;                                           \
        double r0 = 0.0, r1 = 0.0, r2 = 0.0, r3 = 0.0, r4 = 0.0, r5 = 0.0, r6 = 0.0;          \
        double r7 = 0.0;                                                                     \
        for (int j = j0; j < j1; ++j) {                                                      \
            QUALITY_BODY(j)                                                                  \
            q[fo + j] = v;                                                                   \
            cnt += (v == 0.0) ? 1.0 : 0.0;                                                   \
            mn = FMIN(mn, v);                                                                \
            if (j < jb) {                                                                    \
                const double acc = j - j0 < 8 ? v : r0 + v;                                  \
                r0 = r1;                                                                     \
                r1 = r2;                                                                     \
                r2 = r3;                                                                     \
                r3 = r4;                                                                     \
                r4 = r5;                                                                     \
                r5 = r6;                                                                     \
                r6 = r7;                                                                     \
                r7 = acc;                                                                    \
                if (j + 1 == jb) s = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7));       \
            } else {                                                                         \
                s = s + v;                                                                   \
            }                                                                                \
        }                                                                                    \
        part[ro + g] = (double4)(cnt, mn, s, 0.0);                                           \
    }

#define GENERIC_QUALITY(NN)                                                                  \
    double X[MAXN], Y[MAXN];                                                                 \
    load_face(NN, nodes, F, j, P, X, Y);                                                     \
    const double v = mean_ratio(NN, X, Y, cos_a, inv_sin, two_sqrt3, F);
#define QUALITY_QUAD(j) GENERIC_QUALITY(4)
#define QUALITY_NGON(j) GENERIC_QUALITY(n)

// Triangles written out with scalars (pocl compiles the generic array code several times
// slower); same operations in the same order as mean_ratio / transform_moves with n = 3.
#define TRI_LOAD(j)                                                                          \
    const double2 p0 = P[nodes[j]], p1 = P[nodes[F + j]], p2 = P[nodes[2 * F + j]];
#define QUALITY_TRI(j)                                                                       \
    TRI_LOAD(j)                                                                              \
    const double e0x = p1.x - p0.x, e0y = p1.y - p0.y;                                       \
    const double e1x = p2.x - p1.x, e1y = p2.y - p1.y;                                       \
    const double e2x = p0.x - p2.x, e2y = p0.y - p2.y;                                       \
    const double two_area = e0x * e1y - e0y * e1x;                                           \
    double ssq = e0x * e0x + e0y * e0y;                                                      \
    ssq = ssq + (e1x * e1x + e1y * e1y);                                                     \
    ssq = ssq + (e2x * e2x + e2y * e2y);                                                     \
    const double v = (two_area > 0.0 && ssq > 0.0) ? (two_sqrt3 * two_area) / ssq : 0.0;

QUALITY_KERNEL(tri, QUALITY_TRI)
QUALITY_KERNEL(quad, QUALITY_QUAD)
QUALITY_KERNEL(ngon, QUALITY_NGON)

// per-face targets: one generic kernel for every arity (the group's target array last)
#define TGT_ARG , __global const double *restrict tgt
#define TARGET_QUALITY(NN)                                                                   \
    double X[MAXN], Y[MAXN];                                                                 \
    load_face(NN, nodes, F, j, P, X, Y);                                                     \
    const double v = target_ratio(NN, X, Y, tgt, F, j);
#define QUALITY_TGT(j) TARGET_QUALITY(n)
#define QUALITY_TGT_QUAD(j) TARGET_QUALITY(4)
// target_ratio for n = 3 with scalars (the generic code is several times slower on pocl);
// the mean of three q_k >= 0 is ((q0 + q1) + q2) / 3 for any F (pairwise for F == 1 adds
// them in order too, from -0.0, then to 0.0: the same value for non-negative terms)
#define TGT_TRI_CORNER(K, PX, PY, EX, EY)                                                    \
    const double ca##K = tgt[(12 + K) * F + j], ci##K = tgt[(15 + K) * F + j];             \
    const double det##K = (PX) * (EY) - (PY) * (EX);                                         \
    const double e1sq##K = (EX) * (EX) + (EY) * (EY);                                        \
    const double mx##K = (-(PX) - ca##K * (EX)) * ci##K;                                     \
    const double my##K = (-(PY) - ca##K * (EY)) * ci##K;                                     \
    const double fro##K = (e1sq##K + mx##K * mx##K) + my##K * my##K;                         \
    const double q##K = det##K > 0.0 ? ((2.0 * ci##K) * det##K) / fro##K : 0.0;
#define QUALITY_TGT_TRI(j)                                                                   \
    TRI_LOAD(j)                                                                              \
    const double e0x = p1.x - p0.x, e0y = p1.y - p0.y;                                       \
    const double e1x = p2.x - p1.x, e1y = p2.y - p1.y;                                       \
    const double e2x = p0.x - p2.x, e2y = p0.y - p2.y;                                       \
    TGT_TRI_CORNER(0, e2x, e2y, e0x, e0y)                                                    \
    TGT_TRI_CORNER(1, e0x, e0y, e1x, e1y)                                                    \
    TGT_TRI_CORNER(2, e1x, e1y, e2x, e2y)                                                    \
    const int ok = det0 > 0.0 && fro0 > 0.0 && det1 > 0.0 && fro1 > 0.0 && det2 > 0.0 &&     \
                   fro2 > 0.0;                                                               \
    const double v = ok ? ((q0 + q1) + q2) / 3.0 : 0.0;
QUALITY_KERNEL_X(tgt, QUALITY_TGT, TGT_ARG)
QUALITY_KERNEL_X(tgt_tri, QUALITY_TGT_TRI, TGT_ARG)
QUALITY_KERNEL_X(tgt_quad, QUALITY_TGT_QUAD, TGT_ARG)

#define MOVE_ARGS                                                                            \
    GROUP_ARGS, __global const double2 *restrict P, __global const double *restrict q,      \
        __global double *restrict fdist, __global double2 *restrict cmove,                   \
        __global double *restrict wf, const double a, const double eta, const int pow_eta,   \
        const double inv_weight, const int area, const int refresh_arg, TREE_ARGS

// The face weight w = f(d_j) g(q_j) (eq. 20-21) and lambda (eq. 17); refresh != 0: f first
// (d_j: nearest boundary node to the centroid CXm, CYm), else the stored one
#define FACE_WEIGHT(CXm, CYm)                                                                \
    double fj;                                                                               \
    if (refresh) {                                                                           \
        const double d = nearest_d(CXm, CYm, tree_int, bxy, cxy, ox, oy, scale, lim, top, depth,  \
                                   n_levels, n_bnd, cache_k, cache_l, cache_c, cache_d,      \
                                   fo + j);                                                  \
        fj = distance_weight(d, lbar, dfloor, c, pow_c);                                     \
        fdist[fo + j] = fj;                                                                  \
    } else {                                                                                 \
        fj = fdist[fo + j];                                                                  \
    }                                                                                        \
    const double qj = q[fo + j];                                                             \
    const double lam = step_size(qj, a);                                                     \
    const double w = fj * quality_weight(qj, eta, pow_eta, inv_weight);                      \
    wf[fo + j] = w;

// move_SUF: plain; move_SUF_d: the distance refresh first (separate builds of the body,
// so the plain one carries none of the search code)
#define MOVE_KERNEL(NAME, NN, RF) MOVE_KERNEL_X(NAME, NN, RF, , NO_TARGET)
// EXTRA: more kernel arguments (a leading comma) or nothing; TG: the target array or NO_TARGET
#define MOVE_KERNEL_X(NAME, NN, RF, EXTRA, TG)                                               \
    __kernel void NAME(MOVE_ARGS EXTRA)                                                      \
    {                                                                                        \
        const int refresh = RF;                                                              \
        const int j = get_global_id(0);                                                      \
        if (j >= F) return;                                                                  \
        double X[MAXN], Y[MAXN];                                                             \
        load_face(NN, nodes, F, j, P, X, Y);                                                 \
        FACE_WEIGHT(mean_axis0(NN, X, F), mean_axis0(NN, Y, F))                              \
        transform_moves(NN, R, X, Y, lam, w, area, cmove, co, F, j, TG);                     \
    }
#define MAKE_KERNELS(SUF, NN)                                                                \
    MOVE_KERNEL(move_##SUF, NN, 0)                                                           \
    MOVE_KERNEL(move_##SUF##_d, NN, 1)                                                       \
    MARK_KERNEL(SUF, NN)

#define MARK_KERNEL(SUF, NN)                                                                 \
    __kernel void mark_##SUF(GROUP_ARGS, __global const double *restrict q,                  \
                             __global int *restrict flag)                                    \
    {                                                                                        \
        const int j = get_global_id(0);                                                      \
        if (j >= F) return;                                                                  \
        if (q[fo + j] == 0.0)                                                                \
            for (int k = 0; k < NN; ++k) flag[nodes[k * F + j]] = 1;                         \
    }

MAKE_KERNELS(quad, 4)
MAKE_KERNELS(ngon, n)
MARK_KERNEL(tri, 3)
MOVE_KERNEL_X(move_tgt, n, 0, TGT_ARG, tgt)
MOVE_KERNEL_X(move_tgt_d, n, 1, TGT_ARG, tgt)
MOVE_KERNEL_X(move_tgt_quad, 4, 0, TGT_ARG, tgt)
MOVE_KERNEL_X(move_tgt_quad_d, 4, 1, TGT_ARG, tgt)

// transform_moves for n = 3 (R = 1), scalar: lambda n_k, p^s - p for corner k. The paper's
// stretch of a triangle: TRI_PAPER_STRETCH (stretch_vector with n = 3).
#define TRI_EDGE_LEN(AX, AY, BX, BY) SQRT(((BX) - (AX)) * ((BX) - (AX)) + ((BY) - (AY)) * ((BY) - (AY)))
#define TRI_CROSS(AX, AY, BX, BY) ((AX) * (BY) - (BX) * (AY))
// corner k: kp = k + 1, km = k - 1 (mod 3); nx = 0 + (Y[kp] - Y[km]), ny = 0 + (X[km] - X[kp])
#define TRI_PAPER_STRETCH                                                                    \
    const double NX0 = (0.0 + (Y1 - Y2)) * lam, NY0 = (0.0 + (X2 - X1)) * lam;               \
    const double NX1 = (0.0 + (Y2 - Y0)) * lam, NY1 = (0.0 + (X0 - X2)) * lam;               \
    const double NX2 = (0.0 + (Y0 - Y1)) * lam, NY2 = (0.0 + (X1 - X0)) * lam;
// transform_moves' target stretch for n = 3: c_n M = sum_k (p_k - c) (c_n K_k), then
// lambda c_n cof(M) t_k
#define TGT_TRI_M(K)                                                                         \
    const double xh##K = X##K - CX, yh##K = Y##K - CY;                                       \
    const double kx##K = tgt[(6 + K) * F + j], ky##K = tgt[(9 + K) * F + j];                \
    m00 = m00 + xh##K * kx##K;                                                               \
    m01 = m01 + xh##K * ky##K;                                                               \
    m10 = m10 + yh##K * kx##K;                                                               \
    m11 = m11 + yh##K * ky##K;
#define TGT_TRI_N(K)                                                                         \
    const double tx##K = tgt[K * F + j], ty##K = tgt[(3 + K) * F + j];                      \
    const double NX##K = (m11 * tx##K - m10 * ty##K) * lam;                                  \
    const double NY##K = (m00 * ty##K - m01 * tx##K) * lam;
#define TRI_TARGET_STRETCH                                                                   \
    double m00 = 0.0, m01 = 0.0, m10 = 0.0, m11 = 0.0;                                       \
    TGT_TRI_M(0)                                                                             \
    TGT_TRI_M(1)                                                                             \
    TGT_TRI_M(2)                                                                             \
    TGT_TRI_N(0)                                                                             \
    TGT_TRI_N(1)                                                                             \
    TGT_TRI_N(2)
#define MOVE_TRI_KERNEL(NAME, RF) MOVE_TRI_KERNEL_X(NAME, RF, , TRI_PAPER_STRETCH)
// EXTRA: more kernel arguments (a leading comma) or nothing; STRETCH defines NX0 .. NY2
#define MOVE_TRI_KERNEL_X(NAME, RF, EXTRA, STRETCH)                                          \
__kernel void NAME(MOVE_ARGS EXTRA)                                                          \
{                                                                                            \
    const int refresh = RF;                                                                  \
    const int j = get_global_id(0);                                                          \
    if (j >= F) return;                                                                      \
    TRI_LOAD(j)                                                                              \
    const double X0 = p0.x, X1 = p1.x, X2 = p2.x, Y0 = p0.y, Y1 = p1.y, Y2 = p2.y;           \
    const double CX = ((X0 + X1) + X2) / 3.0;                                                \
    const double CY = ((Y0 + Y1) + Y2) / 3.0;                                                \
    FACE_WEIGHT(CX, CY)                                                                      \
    STRETCH                                                                                  \
    const double SX0 = X0 + NX0, SX1 = X1 + NX1, SX2 = X2 + NX2;                             \
    const double SY0 = Y0 + NY0, SY1 = Y1 + NY1, SY2 = Y2 + NY2;                             \
    double before, after;                                                                    \
    if (area) {                                                                              \
        double t = TRI_CROSS(X0, Y0, X1, Y1);                                                \
        t = t + TRI_CROSS(X1, Y1, X2, Y2);                                                   \
        t = t + TRI_CROSS(X2, Y2, X0, Y0);                                                   \
        before = SQRT(0.5 * FABS(t));                                                        \
        t = TRI_CROSS(SX0, SY0, SX1, SY1);                                                   \
        t = t + TRI_CROSS(SX1, SY1, SX2, SY2);                                               \
        t = t + TRI_CROSS(SX2, SY2, SX0, SY0);                                               \
        after = SQRT(0.5 * FABS(t));                                                         \
    } else {                                                                                 \
        before = TRI_EDGE_LEN(X0, Y0, X1, Y1);                                               \
        before = before + TRI_EDGE_LEN(X1, Y1, X2, Y2);                                      \
        before = before + TRI_EDGE_LEN(X2, Y2, X0, Y0);                                      \
        after = TRI_EDGE_LEN(SX0, SY0, SX1, SY1);                                            \
        after = after + TRI_EDGE_LEN(SX1, SY1, SX2, SY2);                                    \
        after = after + TRI_EDGE_LEN(SX2, SY2, SX0, SY0);                                    \
    }                                                                                        \
    const double s = after > 0.0 ? before / after : 1.0;                                     \
    const double oms = 1.0 - s;                                                              \
    cmove[co + j] = (double2)((oms * (CX - X0) + s * NX0) * w, (oms * (CY - Y0) + s * NY0) * w); \
    cmove[co + F + j] =                                                                      \
        (double2)((oms * (CX - X1) + s * NX1) * w, (oms * (CY - Y1) + s * NY1) * w);         \
    cmove[co + 2 * F + j] =                                                                  \
        (double2)((oms * (CX - X2) + s * NX2) * w, (oms * (CY - Y2) + s * NY2) * w);         \
}
MOVE_TRI_KERNEL(move_tri, 0)
MOVE_TRI_KERNEL(move_tri_d, 1)
MOVE_TRI_KERNEL_X(move_tgt_tri, 0, TGT_ARG, TRI_TARGET_STRETCH)
MOVE_TRI_KERNEL_X(move_tgt_tri_d, 1, TGT_ARG, TRI_TARGET_STRETCH)

// Stitching (eq. 18) as a gather: node i sums its incident corners in the order NumPy's
// bincount meets them (CSR rows built on the host), then moves by sum(w d) / sum(w).
// mv (NULL without sliding nodes): 1 where the node moves by NumPy's rule (a nonzero move),
// else 0, for slide_project.
__kernel void stitch(const int N, __global const int *restrict row,
                     __global const int *restrict ccorner, __global const int *restrict cface,
                     __global const double2 *restrict cmove, __global const double *restrict wf,
                     __global double2 *restrict P, __global double2 *restrict old,
                     __global int *restrict mv)
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
    int moved = 0;
    if (sw > 0.0) {
        const double dx = sx / sw, dy = sy / sw;
        if (dx != 0.0 || dy != 0.0) {
            P[i] = (double2)(p.x + dx, p.y + dy);
            moved = 1;
        }
    }
    if (mv) mv[i] = moved;
}

// ---- boundary sliding (boundary.py: Slide.project) --------------------------------------
// Slot s is sliding node snode[s] on curve scurve[s]; its loop neighbours are slots
// (prev_slot / next_slot >= 0, parameters from tau_old) or fixed at prev_tau / next_tau.
// Curves: first segment, segment count, periodic flag; segments: seg[5 k ..] = (ax, ay, dx,
// dy, len2). A node that moved goes to the nearest point of its curve within
// tau -/+ reach times the gaps to its neighbours (the first nearest segment on ties); a
// result not strictly between them keeps tau. Same operations as NumPy, in its order.

__kernel void slide_save(const int S, __global const double *restrict tau,
                         __global double *restrict tau_old)
{
    const int s = get_global_id(0);
    if (s < S) tau_old[s] = tau[s];
}

__kernel void slide_project(const int S, __global const int *restrict snode,
                            __global const int *restrict scurve,
                            __global const int *restrict prev_slot,
                            __global const int *restrict next_slot,
                            __global const double *restrict prev_tau,
                            __global const double *restrict next_tau,
                            __global const int *restrict seg_first,
                            __global const int *restrict n_seg,
                            __global const int *restrict periodic,
                            __global const double *restrict seg, __global const int *restrict mv,
                            __global double2 *restrict P, __global double *restrict tau,
                            __global const double *restrict tau_old, const double reach,
                            const double min_gap)
{
    const int s = get_global_id(0);
    if (s >= S) return;
    const int i = snode[s];
    if (!mv[i]) return;
    const double t = tau_old[s];
    const int c = scurve[s];
    const double n = (double)n_seg[c];
    const int per = periodic[c];
    const int base = seg_first[c];
    const double tp = prev_slot[s] >= 0 ? tau_old[prev_slot[s]] : prev_tau[s];
    const double tn = next_slot[s] >= 0 ? tau_old[next_slot[s]] : next_tau[s];
    double dp = t - tp;
    if (per && dp <= 0.0) dp = dp + n;
    double dn = tn - t;
    if (per && dn <= 0.0) dn = dn + n;
    const double lo = t - reach * FMAX(dp - min_gap, 0.0);
    const double hi = t + reach * FMAX(dn - min_gap, 0.0);
    const double kf = FLOOR(lo);
    double kl = FLOOR(hi);
    if (!per) kl = FMIN(kl, n - 1.0);
    long cnt = (long)(kl - kf) + 1;
    if (cnt < 1) cnt = 1;
    const double2 p = P[i];
    double best = 0.0, bk = 0.0, bu = 0.0;
    for (long j = 0; j < cnt; ++j) {
        const double k = kf + (double)j;
        const double kw = per ? k - FLOOR(k / n) * n : k;
        const long g = 5 * (long)(base + (long)kw);
        const double ax = seg[g], ay = seg[g + 1], dx = seg[g + 2], dy = seg[g + 3];
        const double len2 = seg[g + 4];
        const double ulo = FMAX(lo - k, 0.0);
        const double uhi = FMIN(hi - k, 1.0);
        const double num = (p.x - ax) * dx + (p.y - ay) * dy;
        double u = len2 > 0.0 ? num / len2 : 0.0;
        u = FMIN(FMAX(u, ulo), uhi);
        const double fx = (ax + u * dx) - p.x;
        const double fy = (ay + u * dy) - p.y;
        const double d2 = fx * fx + fy * fy;
        if (j == 0 || d2 < best) {
            best = d2;
            bk = kw;
            bu = u;
        }
    }
    double tnew = bk + bu;
    if (per && tnew >= n) tnew = tnew - n;
    double a = tnew - tp;
    if (per && a < 0.0) a = a + n;
    double b = tn - tp;
    if (per && b <= 0.0) b = b + n;
    if (!(a > 0.0 && a < b)) tnew = t;
    const double k2 = FLOOR(tnew);
    const long g2 = 5 * (long)(base + (long)k2);
    const double u2 = tnew - k2;
    tau[s] = tnew;
    P[i] = (double2)(seg[g2] + u2 * seg[g2 + 2], seg[g2 + 1] + u2 * seg[g2 + 3]);
}

// Smoothing: every marked node that moved this iteration goes back; flags are cleared;
// out[3] (the first stats row's last slot, zeroed by the quality kernels) becomes 1 when some
// node went back. slot (NULL without sliding nodes): a node's slot, whose parameter goes
// back too.
__kernel void revert(const int N, __global int *restrict flag, __global double2 *restrict P,
                     __global const double2 *restrict old, __global double *restrict out,
                     __global const int *restrict slot, __global double *restrict tau,
                     __global const double *restrict tau_old)
{
    const int i = get_global_id(0);
    if (i >= N || !flag[i]) return;
    flag[i] = 0;
    const double2 p = P[i], o = old[i];
    if (p.x != o.x || p.y != o.y) {
        P[i] = o;
        out[3] = 1.0;
        if (slot && slot[i] >= 0) tau[slot[i]] = tau_old[slot[i]];
    }
}
