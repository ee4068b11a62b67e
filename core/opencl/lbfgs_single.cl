// The global stage's L-BFGS (core/optimize/solver.py: lbfgs with energy.py's FoldoverEnergy or
// LiftEnergy) as one resumable single-work-item kernel, float64.
//
// Every floating-point operation is the NumPy code's, on the same operands in the same order,
// with FP contraction off: elementwise formulas as written there, scatters (np.bincount) as
// sequential sums in index order, and every sum or dot product (np.sum / np.add.reduce) as
// NumPy's pairwise summation (blocks of 8 partial sums, halving above 128 terms, chunks of
// 8192), so the result is bit-identical to the host solver. One work-item runs the whole
// optimization: on a CPU device a compiled loop over a few thousand corners costs microseconds
// per iteration where NumPy pays its per-call overhead tens of times.
//
// Layout (nc4 = nc rounded up to a multiple of 4). I (int): fidx[nf] | i0 i1 i2 [nc4] |
// gptr[nn+1] gpos[3nc] | eid[nc4] eptr[ne+1] ecorn[nc] (lift only); gpos entries are coded
// (see gather). D (double): x y [nn] | w00 w01 w11 weight [nc4] | dpre[2nf] | ncorn[ne] (lift
// only). S and T: parameters and solver state (see lbfgs_run). W (scratch, double): X Y [nn] |
// vt gt q s y [2nf] | corner arrays e1x e2x e1y e2y, terms, 1/u [nc4] | element terms, de_dq,
// -1/n [ne].
//
// Host-side defines (solver_opencl.build_options(); a missing one stops the build): M
// (LBFGS_MEMORY), TRIALS, ARMIJO, CURVATURE (line-search halvings, sufficient decrease, the
// memory update's curvature test: core/optimize/state.py), THETA, PENALTY, BARRIER (energy.py's THETA,
// LIFT_PENALTY, LIFT_BARRIER), E_WINDOW (the stop test's energy window), the slots of T and S
// (T_*, S_*) and the status codes (ST_*), and core.fpmath's (common.cl, which the loader
// puts in front of this file: fp64, FP_CONTRACT off, NumPy's pairwise sums).

#if !defined(M) || !defined(TRIALS) || !defined(ARMIJO) || !defined(CURVATURE) || \
    !defined(THETA) || !defined(PENALTY) || \
    !defined(BARRIER) || !defined(E_WINDOW) || !defined(T_TICK) || !defined(S_V) || \
    !defined(ST_TICK) || !defined(PW_BLOCK) || !defined(CHUNK)
#error "build with core.optimize.solver_opencl.build_options()"
#endif

// ---- NumPy's pairwise summation of terms TERM(i), i in [0, n) -----------------------------
// kind 0: a[i]; 1: a[i] * b[i]; 2: a[i] * (b[i] * c[i])

static inline double term(__global const double *a, __global const double *b,
                          __global const double *c, const int kind, const long i)
{
    if (kind == 0)
        return a[i];
    if (kind == 1)
        return a[i] * b[i];
    return a[i] * (b[i] * c[i]);
}

// pairwise_sum's base case over the n terms from o
static double np_leaf(__global const double *a, __global const double *b,
                      __global const double *c, const int kind, const long o, const long n)
{
    double r;
    PAIRWISE_LEAF(r, long, n, term(a, b, c, kind, o + pw_i));
    return r;
}

// np.add.reduce: the chunks in order from 0.0, each by pairwise_sum (common.cl)
static double np_sum(__global const double *a, __global const double *b,
                     __global const double *c, const int kind, const long n)
{
    double acc = 0.0;
    for (long s = 0; s < n; s += CHUNK) {
        double r;
        PAIRWISE_TREE(r, long, (n - s < CHUNK) ? n - s : CHUNK,
                      np_leaf(a, b, c, kind, s + pw_off, pw_len));
        acc += r;
    }
    return acc;
}

#define DOT(a, b, n) np_sum((a), (b), (b), 1, (n))

// ---- energies ------------------------------------------------------------------------------

// Corner loops run four corners at a time (double4: one vector division serves four
// corners); corner arrays are padded to a multiple of 4 with copies of the last corner, whose
// results are never read (sums stop at nc, gathers name real corners, and a copy cannot
// change a minimum).
typedef double4 V;
typedef long4 VL;

typedef struct {
    int nf, nc, nc4, ne, mode;
    __global const int *fidx, *i0, *i1, *i2, *gptr, *gpos, *eid, *eptr, *ecorn;
    __global const double *w00, *w01, *w11, *weight, *dpre, *ncorn;
    __global double *X, *Y, *c1x, *c1y, *c2x, *c2y, *ct, *cr, *et, *edq, *eni;
    double eps, qc;
} Problem;

static inline V gather4(__global const double *a, __global const int *idx, const int c)
{
    return (V)(a[idx[c]], a[idx[c + 1]], a[idx[c + 2]], a[idx[c + 3]]);
}

static inline void jac(const Problem *P, const int c, V *j00, V *j01, V *j10, V *j11)
{
    const V x0 = gather4(P->X, P->i0, c), y0 = gather4(P->Y, P->i0, c);
    const V e1x = gather4(P->X, P->i1, c) - x0, e1y = gather4(P->Y, P->i1, c) - y0;
    const V e2x = gather4(P->X, P->i2, c) - x0, e2y = gather4(P->Y, P->i2, c) - y0;
    const V w00 = vload4(0, P->w00 + c), w01 = vload4(0, P->w01 + c);
    const V w11 = vload4(0, P->w11 + c);
    *j00 = e1x * w00;
    *j10 = e1y * w00;
    *j01 = e1x * w01 + e2x * w11;
    *j11 = e1y * w01 + e2y * w11;
}

static inline void corner_grad(const Problem *P, const int c, const V a, const V b, const V j00,
                               const V j01, const V j10, const V j11)
{
    const V g00 = a * j00 + b * j11;
    const V g01 = a * j01 - b * j10;
    const V g10 = a * j10 - b * j01;
    const V g11 = a * j11 + b * j00;
    const V w00 = vload4(0, P->w00 + c), w01 = vload4(0, P->w01 + c);
    const V w11 = vload4(0, P->w11 + c);
    vstore4(g00 * w00 + g01 * w01, 0, P->c1x + c);
    vstore4(g10 * w00 + g11 * w01, 0, P->c1y + c);
    vstore4(g01 * w11, 0, P->c2x + c);
    vstore4(g11 * w11, 0, P->c2y + c);
}

// np.min over the dets: NaN wins, otherwise the order does not matter
static inline V vmin_nan(const V m, const V d)
{
    return select(d, m, isnan(m) | (m <= d));
}

static inline double hmin_nan(const V m)
{
    double r = m.s0;
    const double o[3] = {m.s1, m.s2, m.s3};
    for (int k = 0; k < 3; ++k)
        r = (isnan(r) || r <= o[k]) ? r : o[k];
    return r;
}

static inline double np_max_step(const int i, const double m, const double d)
{
    return (i == 0) ? d : ((isnan(m) || m >= d) ? m : d);  // np.max: NaN wins
}

// np.bincount over [e1, e2, -(e1 + e2)] at idx = [i1, i2, i0], read back for the free nodes;
// gpos holds each entry as c (e1 of corner c), nc4 + c (e2) or -1 - c (the third node's)
static void gather(const Problem *P, __global double *G)
{
    __global const double *cx = P->c1x, *cy = P->c1y;  // c2x = c1x + nc4, c2y = c1y + nc4
    const int nc = P->nc4;
    for (int f = 0; f < P->nf; ++f) {
        const int k = P->fidx[f];
        double gx = 0.0, gy = 0.0;
        for (int p = P->gptr[k]; p < P->gptr[k + 1]; ++p) {
            const int pos = P->gpos[p];
            if (pos >= 0) {
                gx += cx[pos];
                gy += cy[pos];
            } else {
                const int c = -1 - pos;
                gx += -(cx[c] + cx[nc + c]);
                gy += -(cy[c] + cy[nc + c]);
            }
        }
        G[f] = gx;
        G[P->nf + f] = gy;
    }
}

// FoldoverEnergy.value_grad (power 1): F_eps, its gradient into G (packed), min det into *dmin
static double fold_value_grad(const Problem *P, __global double *G, double *dmin)
{
    const double eps = P->eps;
    const V ee = (V)(eps * eps), he = (V)((0.5 * eps) * eps);
    V m = (V)(INFINITY);
    for (int c = 0; c < P->nc4; c += 4) {
        V j00, j01, j10, j11;
        jac(P, c, &j00, &j01, &j10, &j11);
        const V d = j00 * j11 - j01 * j10;
        const V t = j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11;
        const V root = sqrt(ee + d * d);
        const V chi = select(he / (root + fabs(d)), 0.5 * (d + root), d >= 0.0);
        const V num = (1.0 - THETA) * t + THETA * (d * d + 1.0);
        const V inv_chi = vload4(0, P->weight + c) / chi;
        vstore4(num * inv_chi, 0, P->ct + c);
        const V a = (2.0 * (1.0 - THETA)) * inv_chi;
        const V b = inv_chi * ((2.0 * THETA) * d - num / root);
        corner_grad(P, c, a, b, j00, j01, j10, j11);
        m = (c == 0) ? d : vmin_nan(m, d);
    }
    *dmin = hmin_nan(m);
    const double energy = np_sum(P->ct, P->ct, P->ct, 0, P->nc);
    gather(P, G);
    return energy;
}

// LiftEnergy.value_grad, value part: inf unless every corner det is positive
static double lift_value(const Problem *P, double *dmin)
{
    V m = (V)(INFINITY);
    for (int c = 0; c < P->nc4; c += 4) {  // u = 1 / q_corner (in c1x), 1 / u (cr), det (c1y)
        V j00, j01, j10, j11;
        jac(P, c, &j00, &j01, &j10, &j11);
        const V d = j00 * j11 - j01 * j10;
        const V t = j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11;
        const V u = (0.5 * t) / select((V)(INFINITY), d, d > 0.0);
        vstore4(u, 0, P->c1x + c);
        vstore4(1.0 / u, 0, P->cr + c);
        vstore4(d, 0, P->c1y + c);
        vstore4(vload4(0, P->weight + c) * u, 0, P->ct + c);
        m = (c == 0) ? d : vmin_nan(m, d);
    }
    *dmin = hmin_nan(m);
    if (!(*dmin > 0.0))
        return INFINITY;
    const double qc = P->qc, k = (2.0 * PENALTY) / qc;
    for (int e = 0; e < P->ne; ++e) {
        double s = 0.0;
        for (int p = P->eptr[e]; p < P->eptr[e + 1]; ++p)
            s += P->cr[P->ecorn[p]];
        const double q = s / P->ncorn[e];
        double gap = qc - q;
        gap = (isnan(gap) || gap >= 0.0) ? gap : 0.0;
        gap = gap / qc;
        P->et[e] = (PENALTY * gap) * gap - q;
        P->edq[e] = -1.0 - k * gap;
        P->eni[e] = -1.0 / P->ncorn[e];
    }
    double energy = np_sum(P->et, P->et, P->et, 0, P->ne);
    energy += BARRIER * np_sum(P->ct, P->ct, P->ct, 0, P->nc);
    return energy;
}

// _LiftEnergy.value_grad, gradient part, from lift_value's arrays (only for accepted points:
// a rejected trial's gradient is never used)
static void lift_grad(const Problem *P, __global double *G)
{
    for (int c = 0; c < P->nc4; c += 4) {
        V j00, j01, j10, j11;
        jac(P, c, &j00, &j01, &j10, &j11);
        const V u = vload4(0, P->c1x + c), d = vload4(0, P->c1y + c);
        const V dq = gather4(P->edq, P->eid, c), ni = gather4(P->eni, P->eid, c);
        V de_du = (dq * ni) / (u * u);
        de_du = de_du + BARRIER * vload4(0, P->weight + c);
        const V a = de_du / d;
        const V b = (-de_du * u) / d;
        corner_grad(P, c, a, b, j00, j01, j10, j11);
    }
    gather(P, G);
}

// F at v; its gradient into G too unless this is a lift trial point (see lift_grad)
static double evaluate(const Problem *P, __global const double *v, __global double *G,
                       double *dmin, const int trial)
{
    for (int f = 0; f < P->nf; ++f) {  // _State.unpack
        P->X[P->fidx[f]] = v[f];
        P->Y[P->fidx[f]] = v[P->nf + f];
    }
    if (!P->mode)
        return fold_value_grad(P, G, dmin);
    const double e = lift_value(P, dmin);
    if (!trial && isfinite(e))
        lift_grad(P, G);
    return e;
}

// ---- the solver ----------------------------------------------------------------------------

// Scalars travel in the state buffers (pyopencl's scalar arguments cost ~10 us each):
// T = counters, sizes and settings (T_*), S = [eps, qc, h0, rel_tol, e, ehist[E_WINDOW],
// rho[M], v, g, hs, hy] (S_*), both laid out by the host.
__kernel void lbfgs_run(__global const int *I, __global const double *D, __global double *S,
                        __global int *T, __global double *W)
{
    const int nn = T[T_NN], nf = T[T_NF], nc = T[T_NC], ne = T[T_NE], nc4 = (nc + 3) & ~3;
    const int max_it = T[T_MAXIT], guard = T[T_GUARD], tick_every = T[T_TICK];
    const double h0 = S[S_H0], rel_tol = S[S_REL_TOL];
    Problem P;
    P.nf = nf;
    P.nc = nc;
    P.nc4 = nc4;
    P.ne = ne;
    P.mode = T[T_MODE];
    P.eps = S[S_EPS];
    P.qc = S[S_QC];
    P.fidx = I;
    P.i0 = I + nf;
    P.i1 = P.i0 + nc4;
    P.i2 = P.i1 + nc4;
    P.gptr = P.i2 + nc4;
    P.gpos = P.gptr + nn + 1;
    P.eid = P.gpos + 3 * nc;
    P.eptr = P.eid + nc4;
    P.ecorn = P.eptr + ne + 1;
    __global const double *x0 = D, *y0 = D + nn;
    P.w00 = D + 2 * nn;
    P.w01 = P.w00 + nc4;
    P.w11 = P.w01 + nc4;
    P.weight = P.w11 + nc4;
    P.dpre = P.weight + nc4;
    P.ncorn = P.dpre + 2 * nf;
    const int n2 = 2 * nf;
    __global double *pe = S + S_E, *ehist = S + S_EHIST, *rho = S + S_RHO, *v = S + S_V;
    __global double *g = v + n2, *hs = g + n2, *hy = hs + M * n2;
    P.X = W;
    P.Y = W + nn;
    __global double *vt = W + 2 * nn, *gt = vt + n2, *q = gt + n2, *sb = q + n2, *yb = sb + n2;
    P.c1x = yb + n2;
    P.c2x = P.c1x + nc4;
    P.c1y = P.c2x + nc4;
    P.c2y = P.c1y + nc4;
    P.ct = P.c2y + nc4;
    P.cr = P.ct + nc4;
    P.et = P.cr + nc4;
    P.edq = P.et + ne;
    P.eni = P.edq + ne;
    __global const double *dpre = P.dpre;

    for (int k = 0; k < nn; ++k) {
        P.X[k] = x0[k];
        P.Y[k] = y0[k];
    }
    double e, dmin_t = 0.0;
    if (T[T_FRESH]) {
        e = evaluate(&P, v, g, &dmin_t, 0);
        T[T_IT] = 0;
        T[T_LEN] = 0;
        T[T_START] = 0;
        T[T_NHIST] = 1;
        ehist[0] = e;
        T[T_FRESH] = 0;
    } else {
        e = *pe;
    }
    int it = T[T_IT], len = T[T_LEN], start = T[T_START], nh = T[T_NHIST];
    int status = ST_DONE;
    double alphas[M];
    while (it < max_it) {
        ++it;
        for (int i = 0; i < n2; ++i)
            q[i] = -g[i];
        double step;
        for (int h = len - 1; h >= 0; --h) {  // newest first
            const int r = (start + h) % M;
            const double al = rho[r] * DOT(hs + r * n2, q, n2);
            alphas[h] = al;
            for (int i = 0; i < n2; ++i)
                q[i] = q[i] - al * hy[r * n2 + i];
        }
        if (len) {
            const int r = (start + len - 1) % M;
            const double gamma = DOT(hs + r * n2, hy + r * n2, n2) /
                                 np_sum(hy + r * n2, dpre, hy + r * n2, 2, n2);
            for (int i = 0; i < n2; ++i)
                q[i] = q[i] * (dpre[i] * gamma);
            for (int h = 0; h < len; ++h) {  // oldest first
                const int r2 = (start + h) % M;
                const double cf = alphas[h] - rho[r2] * DOT(hy + r2 * n2, q, n2);
                for (int i = 0; i < n2; ++i)
                    q[i] = q[i] + cf * hs[r2 * n2 + i];
            }
            step = 1.0;
        } else {
            double qmax = 0.0;
            for (int i = 0; i < n2; ++i) {
                q[i] = q[i] * dpre[i];
                const double aq = FABS(q[i]);
                qmax = np_max_step(i, qmax, aq);
            }
            step = (qmax > 0.0) ? h0 / qmax : 0.0;
        }
        double slope = DOT(g, q, n2);
        if (!(slope < 0.0)) {  // restart from preconditioned descent
            len = 0;
            start = 0;
            double qmax = 0.0;
            for (int i = 0; i < n2; ++i) {
                q[i] = -dpre[i] * g[i];
                const double aq = FABS(q[i]);
                qmax = np_max_step(i, qmax, aq);
            }
            slope = DOT(g, q, n2);
            step = (qmax > 0.0) ? h0 / qmax : 0.0;
            if (!(slope < 0.0))
                break;
        }
        int accepted = 0;
        double et = 0.0;
        for (int ls = 0; ls < TRIALS; ++ls) {
            for (int i = 0; i < n2; ++i)
                vt[i] = v[i] + step * q[i];
            et = evaluate(&P, vt, gt, &dmin_t, 1);
            if (isfinite(et) && et <= e + (ARMIJO * step) * slope && !(guard && dmin_t <= 0.0)) {
                accepted = 1;
                if (P.mode)
                    lift_grad(&P, gt);
                break;
            }
            step *= 0.5;
        }
        if (!accepted) {
            if (len) {
                len = 0;
                start = 0;
                continue;
            }
            break;
        }
        for (int i = 0; i < n2; ++i) {
            sb[i] = vt[i] - v[i];
            yb[i] = gt[i] - g[i];
        }
        const double sy = DOT(sb, yb, n2);
        if (sy > CURVATURE * SQRT(DOT(sb, sb, n2) * DOT(yb, yb, n2))) {
            const int slot = (len < M) ? (start + len) % M : start;  // full: drop the oldest
            for (int i = 0; i < n2; ++i) {
                hs[slot * n2 + i] = sb[i];
                hy[slot * n2 + i] = yb[i];
            }
            rho[slot] = 1.0 / sy;
            if (len < M)
                ++len;
            else
                start = (start + 1) % M;
        }
        for (int i = 0; i < n2; ++i) {
            v[i] = vt[i];
            g[i] = gt[i];
        }
        e = et;
        if (!guard && dmin_t > 0.0)
            break;
        ehist[nh % E_WINDOW] = e;
        ++nh;
        if (nh > E_WINDOW - 1) {
            const double old = ehist[(nh - E_WINDOW) % E_WINDOW];
            if (old - e <= rel_tol * FABS(old))
                break;
        }
        if (tick_every > 0 && it % tick_every == 0) {
            status = ST_TICK;
            break;
        }
    }
    T[T_IT] = it;
    T[T_LEN] = len;
    T[T_START] = start;
    T[T_NHIST] = nh;
    T[T_STATUS] = status;
    *pe = e;
}
