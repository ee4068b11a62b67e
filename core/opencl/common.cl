// What every OpenCL program of the core shares, put in front of each program's own source
// by the Python loader (core.opencl.build.program_source): float64 with FP contraction off,
// inline IEEE operations, core.fpmath's log / exp / power operation for operation, and
// NumPy's pairwise summation. With these a kernel gives NumPy's bits on a CPU device.
//
// Host-side defines (core.opencl.build.fpmath_options(), given to every build; a missing
// one stops the build):
//   FP_LOG_C, FP_EXP_C  core.fpmath's polynomial coefficients, lowest order first
//   FP_SQRT_HALF, FP_LN2_HI, FP_LN2_LO, FP_INV_LN2, FP_EXP_MAX, FP_EXP_MIN  its constants
//       (all hex floats: the exact doubles the host uses)
//   POW_*  core.fpmath.POW_CODES: how np_pow evaluates x ** e
//   PW_BLOCK, CHUNK  core.fpmath.PAIRWISE_BLOCK, REDUCE_CHUNK: NumPy's pairwise block and
//       reduction buffer

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#if !defined(FP_LOG_C) || !defined(FP_EXP_C) || !defined(FP_SQRT_HALF) || \
    !defined(FP_LN2_HI) || !defined(FP_LN2_LO) || !defined(FP_INV_LN2) || \
    !defined(FP_EXP_MAX) || !defined(FP_EXP_MIN) || !defined(POW_GENERAL) || \
    !defined(POW_SQUARE) || !defined(POW_IDENTITY) || !defined(POW_ONE) || \
    !defined(POW_SQRT) || !defined(POW_RECIPROCAL) || !defined(PW_BLOCK) || !defined(CHUNK)
#error "build with core.opencl.build.fpmath_options()"
#endif

// Inline IEEE operations (correctly rounded, like NumPy's): pocl otherwise calls its
// library functions for sqrt / fabs / fmin / floor, which blocks inlining and vectorization.
#define SQRT(x) __builtin_sqrt(x)
#define FABS(x) __builtin_fabs(x)
#define FMIN(x, y) __builtin_fmin((x), (y))
#define FMAX(x, y) __builtin_fmax((x), (y))
#define FLOOR(x) __builtin_floor(x)
#define MIN_NAN(m, d) ((isnan(m) || (m) <= (d)) ? (m) : (d))  // np.minimum: NaN wins

// ---- core.fpmath ---------------------------------------------------------------------------
// log / exp / power, operation for operation: +, -, *, / (FP_CONTRACT off), exact bit-level
// frexp / ldexp and rint only, so these give core.fpmath's bits on every device.

__constant double fp_log_c[] = {FP_LOG_C};
__constant double fp_exp_c[] = {FP_EXP_C};
#define FP_N_LOG ((int)(sizeof(fp_log_c) / sizeof(double)))
#define FP_N_EXP ((int)(sizeof(fp_exp_c) / sizeof(double)))

// 2^e for -1022 <= e <= 1023, exactly
static inline double fp_pow2(const int e) { return as_double((long)(e + 1023) << 52); }

// p 2^k rounded once (like C's ldexp), for p a positive normal double near 1 and
// -1100 < k < 1100: one exact scaling, then at most one rounding (subnormal or overflow)
static inline double fp_ldexp(const double p, const int k)
{
    if (k > 1000) return (p * fp_pow2(k - 100)) * fp_pow2(100);
    if (k < -1000) return (p * fp_pow2(k + 100)) * fp_pow2(-100);
    return p * fp_pow2(k);
}

// fpmath.log: x = m 2^e (frexp, 0.5 <= m < 1), m doubled below sqrt(1/2), then
// log(m) = 2 f sum_k s^k / (2k + 1) with f = (m - 1) / (m + 1), s = f^2 (Horner)
static inline double fp_log(const double x)
{
    if (!(x > 0.0)) return x == 0.0 ? -INFINITY : NAN;
    if (isinf(x)) return INFINITY;
    double xs = x;
    int bias = 0;
    if (xs < 0x1p-1022) {  // subnormal: scale into the normal range first (exact)
        xs = xs * 0x1p54;
        bias = 54;
    }
    const long bits = as_long(xs);
    const int e = (int)((bits >> 52) & 0x7ff) - 1022 - bias;
    double m = as_double((bits & 0x800fffffffffffffL) | (1022L << 52));
    const int low = m < FP_SQRT_HALF;
    if (low) m = m * 2.0;
    const double k = (double)(e - low);
    const double f = (m - 1.0) / (m + 1.0);
    const double s = f * f;
    double p = fp_log_c[FP_N_LOG - 1];
    for (int i = FP_N_LOG - 2; i >= 0; --i) p = p * s + fp_log_c[i];
    return k * FP_LN2_HI + (k * FP_LN2_LO + (2.0 * f) * p);
}

// fpmath.exp: k = rint(x / ln 2), r = x - k ln 2 (two parts), e^r by Taylor (Horner), 2^k
static inline double fp_exp(const double x)
{
    if (isnan(x)) return x;
    if (x > FP_EXP_MAX) return INFINITY;
    if (x < FP_EXP_MIN) return 0.0;
    const double k = __builtin_rint(x * FP_INV_LN2);
    const double r = (x - k * FP_LN2_HI) - k * FP_LN2_LO;
    double p = fp_exp_c[FP_N_EXP - 1];
    for (int i = FP_N_EXP - 2; i >= 0; --i) p = p * r + fp_exp_c[i];
    return fp_ldexp(p, (int)k);
}

// fpmath.power: mode is core.fpmath.power_code(e)
static inline double np_pow(const double x, const double e, const int mode)
{
    switch (mode) {
    case POW_SQUARE: return x * x;
    case POW_IDENTITY: return x;
    case POW_ONE: return 1.0;
    case POW_SQRT: return SQRT(x);
    case POW_RECIPROCAL: return 1.0 / x;
    default: return fp_exp(e * fp_log(x));  // POW_GENERAL
    }
}

// ---- NumPy's pairwise summation ------------------------------------------------------------
// np.add.reduce of n float64 values adds buffers of CHUNK values in order, each by
// pairwise_sum: a run of more than PW_BLOCK values is halved at PW_SPLIT(n) (n / 2 rounded
// down to a multiple of 8) and the halves' sums added, left + right; a leaf of at most
// PW_BLOCK values is summed as PAIRWISE_LEAF says. The programs' sums (the EEGT kernels'
// corner sums, the L-BFGS kernels' dot products and energies) are these macros over their
// own terms; lbfgs_parallel.cl splits the leaves over work-items the same way (LEAF_SUMS).

#define PW_SPLIT(n) ((n) / 2 - ((n) / 2) % 8)
#define PW_STACK 32  // the walk's depth: any int n (a chunk needs 8)

// the fixed tree that adds pairwise_sum's 8 partial sums r[0 .. 7]
#define COMBINE8(r) \
    ((((r)[0] + (r)[1]) + ((r)[2] + (r)[3])) + (((r)[4] + (r)[5]) + ((r)[6] + (r)[7])))

// RET = pairwise_sum's base case over the N <= PW_BLOCK terms TERM, an expression of the term
// index pw_i (type IDX): under 8 terms, -0.0 + the terms in order; else 8 partial sums of the
// terms j, j + 8, ... (in order) added by COMBINE8, then the N % 8 remaining terms in order.
#define PAIRWISE_LEAF(RET, IDX, N, TERM)                                                     \
    do {                                                                                     \
        const IDX pw_n = (N);                                                                \
        double pw_res = -0.0;                                                                \
        IDX pw_b = 0;                                                                        \
        if (pw_n >= 8) {                                                                     \
            double pw_r[8];                                                                  \
            for (IDX pw_i = 0; pw_i < 8; ++pw_i) pw_r[pw_i] = (TERM);                        \
            for (pw_b = 8; pw_b < pw_n - pw_n % 8; pw_b += 8)                                \
                for (IDX pw_j = 0; pw_j < 8; ++pw_j) {                                       \
                    const IDX pw_i = pw_b + pw_j;                                            \
                    pw_r[pw_j] = pw_r[pw_j] + (TERM);                                        \
                }                                                                            \
            pw_res = COMBINE8(pw_r);                                                         \
        }                                                                                    \
        for (IDX pw_i = pw_b; pw_i < pw_n; ++pw_i) pw_res = pw_res + (TERM);                 \
        RET = pw_res;                                                                        \
    } while (0)

// RET = pairwise_sum over N terms (N <= CHUNK for NumPy's bits): the recursion walked depth
// first, left half first, with an explicit stack (OpenCL C has no recursion). LEAF is an
// expression giving the sum of one leaf from pw_off, pw_len (its first term and length, type
// IDX) and pw_k (how many leaves came before it).
#define PAIRWISE_TREE(RET, IDX, N, LEAF)                                                     \
    do {                                                                                     \
        IDX pw_offs[PW_STACK], pw_lens[PW_STACK];                                            \
        double pw_left[PW_STACK];                                                            \
        int pw_right[PW_STACK];                                                              \
        int pw_sp = 0, pw_k = 0;                                                             \
        pw_offs[0] = 0;                                                                      \
        pw_lens[0] = (N);                                                                    \
        for (;;) {                                                                           \
            while (pw_lens[pw_sp] > PW_BLOCK) { /* into the left half */                     \
                pw_right[pw_sp] = 0;                                                         \
                pw_offs[pw_sp + 1] = pw_offs[pw_sp];                                         \
                pw_lens[pw_sp + 1] = PW_SPLIT(pw_lens[pw_sp]);                               \
                ++pw_sp;                                                                     \
            }                                                                                \
            const IDX pw_off = pw_offs[pw_sp], pw_len = pw_lens[pw_sp];                      \
            double pw_sum = (LEAF);                                                          \
            ++pw_k;                                                                          \
            while (pw_sp > 0 && pw_right[pw_sp - 1]) { /* a right half: left + right */      \
                --pw_sp;                                                                     \
                pw_sum = pw_left[pw_sp] + pw_sum;                                            \
            }                                                                                \
            if (pw_sp == 0) {                                                                \
                RET = pw_sum;                                                                \
                break;                                                                       \
            }                                                                                \
            --pw_sp; /* a left half: kept until its right sibling is done */                 \
            pw_left[pw_sp] = pw_sum;                                                         \
            pw_right[pw_sp] = 1;                                                             \
            pw_offs[pw_sp + 1] = pw_offs[pw_sp] + PW_SPLIT(pw_lens[pw_sp]);                  \
            pw_lens[pw_sp + 1] = pw_lens[pw_sp] - PW_SPLIT(pw_lens[pw_sp]);                  \
            ++pw_sp;                                                                         \
        }                                                                                    \
    } while (0)
