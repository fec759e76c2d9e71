/*
 * simbench's compiled loops, in C (loaded by simbench/native.py): the decoder's fused per-pixel
 * loops (wrappers in simbench/decode/_kernels.py), the projector-column triangulation
 * (simbench/rig.py) and the plane fit's centred points (simbench/metrics.py).  The lens model's
 * remap grids are in simbench/_lens.c, built into the same library: recordings depend on them
 * alone (simbench.sim.keys hashes that file), so an edit here re-records nothing.
 *
 * Every loop evaluates the same IEEE operations, in the same order and precision, as the numpy
 * expression it replaces (tests/numpy_reference.py; tests/test_kernels.py compares the bits).
 * That holds because the build (pyproject.toml) compiles with -ffp-contract=off (no fused
 * multiply-add) and without -ffast-math (no reassociation): vectorising a loop across pixels
 * then changes no result, whatever the machine's vector width.  -fno-math-errno only lets sqrtf
 * be a single instruction (its value is the same).
 *
 * All arrays are C-contiguous; the Python wrappers check dtypes, shapes and contiguity before
 * calling, so nothing here validates its pointers.  The functions hold no state and ctypes
 * releases the GIL around each call, so the decoder's row-band threads run them in parallel.
 *
 * A module init function is included only so that the interpreter can locate the built file
 * through the import system (importlib.util.find_spec); the module itself is empty.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

/* Row helpers stay out of line: inlined, their restrict parameters would be lost and the
 * vectoriser would give up on the alias checks their loops need. */
#define ROW_FN static __attribute__((noinline))
/* The Gabor fit's per-pixel row loops in the widest vectors the machine has (GCC otherwise
 * prefers 256 bits on AVX-512 machines): the fit is compute-bound (single-thread fit of a
 * 1280x960 band: -0.7 ms on a Sapphire Rapids).  Not the decoder's last stages: their gathers
 * and masked stores were slower at 512 bits there.  Lane-wise IEEE arithmetic, the same bits. */
#define FIT_ROW_FN static __attribute__((noinline, target("prefer-vector-width=512")))

#define PI_F ((float)3.14159265358979323846)
#define TWO_PI_F ((float)6.28318530717958647692)
#define TWO_PI_D 6.28318530717958647692

/* Weighted least-squares fringe fit of one pixel from its nine window sums: data b0 = G*(cI),
 * b1 = G*(cI cos), b2 = G*(cI sin), e2 = G*(cI I); certainty s1 = G*c, sc = G*(c cos),
 * ss = G*(c sin), sc2 = G*(c cos2), ss2 = G*(c sin2).  The normal equations M p = b with
 * M = [[s1, sc, ss], [sc, scc, scs], [ss, scs, sss]] are solved by the adjugate, in the operation
 * order of the numpy form (_solver and gabor_phase in tests/numpy_reference.py).
 *
 * In two steps: the solver's rows from the certainty sums alone (fit_solver: k (offset), p (re),
 * q (im), 1/s1, all 0 where the window is too thin or the system near-singular), then their
 * products with the data (fit_apply).  A window wholly certain has the certainty sums of an
 * all-ones band, so its solver can be made once (gabor_band's table). */
enum { SOLVER = 10 }; /* k0 k1 k2 p0 p1 p2 q0 q1 q2 inv_s1 */
static inline void fit_solver(float s1, float sc, float ss, float sc2, float ss2, float c, float s, float s_min,
                              float *restrict k) {
    const float half = 0.5f, zero = 0.0f, one = 1.0f, det_min = 1e-4f;
    const float scc = half * (s1 + sc2);
    const float sss = half * (s1 - sc2);
    const float scs = half * ss2;
    const float c00 = scc * sss - scs * scs;
    const float c01 = ss * scs - sc * sss;
    const float c02 = sc * scs - ss * scc;
    const float c11 = s1 * sss - ss * ss;
    const float c12 = sc * ss - s1 * scs;
    const float c22 = s1 * scc - sc * sc;
    const float det = s1 * c00 + sc * c01 + ss * c02;
    const int good = (s1 > s_min) & (det > det_min * s1 * s1 * s1);
    const float inv = good ? one / det : zero;
    k[9] = good ? one / s1 : zero;
    k[0] = c00 * inv, k[1] = c01 * inv, k[2] = c02 * inv;
    k[3] = (c01 * c + c02 * s) * inv;
    k[4] = (c11 * c + c12 * s) * inv;
    k[5] = (c12 * c + c22 * s) * inv;
    k[6] = (c01 * s - c02 * c) * inv;
    k[7] = (c11 * s - c12 * c) * inv;
    k[8] = (c12 * s - c22 * c) * inv;
}

/* The fit of one pixel from its solver k (fit_solver; good where k[9] = 1/s1 is not 0) and data
 * sums: offset a0, re, im, amplitude (0 where not good) and the RMS residual relative to
 * amp/sqrt 2 (inf where not good or amp is 0). */
static inline void fit_apply(const float *restrict k, float c, float s, float d0, float d1, float d2, float e2,
                             float *restrict re, float *restrict im, float *restrict a0, float *restrict amp,
                             float *restrict residual) {
    const float zero = 0.0f;
    const float rms = (float)0.70710678118654752440;
    const int good = k[9] != zero;
    const float a = k[0] * d0 + k[1] * d1 + k[2] * d2;
    const float r = k[3] * d0 + k[4] * d1 + k[5] * d2;
    const float i = k[6] * d0 + k[7] * d1 + k[8] * d2;
    *a0 = a;
    *re = r;
    *im = i;
    const float m = sqrtf(r * r + i * i);
    float e = e2 - a * d0;
    e = e - (c * d1 + s * d2) * r;
    e = e - (s * d1 - c * d2) * i;
    e = e < zero ? zero : e; /* np.maximum(e, 0): NaN stays NaN */
    e = sqrtf(e * k[9]);
    const float t = m * rms;
    *amp = good ? m : zero;
    *residual = (good & (m > zero)) ? e / t : INFINITY;
}

/* Float lanes (GCC/Clang vector extension): sixteen where the machine has AVX-512 (one zmm
 * register), eight otherwise (AVX, or two SSE halves).  The arithmetic is lane-wise IEEE, so every
 * width, and the scalar tails, give the same bits.  Loads and stores go through memcpy:
 * unaligned. */
#if defined(__AVX512F__)
#define LANES 16
#else
#define LANES 8
#endif
typedef float vf __attribute__((vector_size(4 * LANES)));
static inline vf ldv(const float *p) {
    vf v;
    memcpy(&v, p, sizeof v);
    return v;
}
static inline void stv(float *p, vf v) { memcpy(p, &v, sizeof v); }

/* Horizontal Gaussian-window sums of one zero-padded row p (p[-r..w+r) readable) with the half
 * kernels g (even), gc = g cos(w k) (even) and gs = g sin(w k) (odd):
 *   G = sum g_k p(x-k),  C = sum gc_k p(x-k),  S = sum gs_k p(x-k)
 * the last two only when C is not NULL.  A vector of pixels at a time, the sums held in registers
 * over the kernel taps, in the tap order of the scalar tail. */
ROW_FN void row_sums(int64_t w, int64_t r, const float *restrict p, const float *restrict g,
                     const float *restrict gc, const float *restrict gs, float *restrict G, float *restrict C,
                     float *restrict S) {
    /* four vectors per block: twelve independent sums hide the adds' latency; then single vectors */
    enum { NV = 4 };
    int64_t x = 0;
    if (C == NULL) {
        for (; x + LANES * NV <= w; x += LANES * NV) {
            vf acc[NV];
            for (int v = 0; v < NV; v++) acc[v] = g[0] * ldv(p + x + LANES * v);
            for (int64_t k = 1; k <= r; k++)
                for (int v = 0; v < NV; v++)
                    acc[v] += g[k] * (ldv(p + x + LANES * v - k) + ldv(p + x + LANES * v + k));
            for (int v = 0; v < NV; v++) stv(G + x + LANES * v, acc[v]);
        }
        for (; x + LANES <= w; x += LANES) {
            vf acc = g[0] * ldv(p + x);
            for (int64_t k = 1; k <= r; k++) acc += g[k] * (ldv(p + x - k) + ldv(p + x + k));
            stv(G + x, acc);
        }
        for (; x < w; x++) {
            float acc = g[0] * p[x];
            for (int64_t k = 1; k <= r; k++) acc += g[k] * (p[x - k] + p[x + k]);
            G[x] = acc;
        }
        return;
    }
    for (; x + LANES * NV <= w; x += LANES * NV) {
        vf a[NV], c[NV], s[NV];
        for (int v = 0; v < NV; v++) {
            const vf mid = ldv(p + x + LANES * v);
            a[v] = g[0] * mid;
            c[v] = gc[0] * mid;
            s[v] = (vf){0};
        }
        for (int64_t k = 1; k <= r; k++) {
            const float gk = g[k], ck = gc[k], sk = gs[k];
            for (int v = 0; v < NV; v++) {
                const vf lo = ldv(p + x + LANES * v - k), hi = ldv(p + x + LANES * v + k);
                const vf sum = lo + hi, dif = lo - hi;
                a[v] += gk * sum;
                c[v] += ck * sum;
                s[v] += sk * dif;
            }
        }
        for (int v = 0; v < NV; v++) {
            stv(G + x + LANES * v, a[v]);
            stv(C + x + LANES * v, c[v]);
            stv(S + x + LANES * v, s[v]);
        }
    }
    for (; x + LANES <= w; x += LANES) {
        const vf mid = ldv(p + x);
        vf a = g[0] * mid, c = gc[0] * mid, s = (vf){0};
        for (int64_t k = 1; k <= r; k++) {
            const vf lo = ldv(p + x - k), hi = ldv(p + x + k);
            const vf sum = lo + hi, dif = lo - hi;
            a += g[k] * sum;
            c += gc[k] * sum;
            s += gs[k] * dif;
        }
        stv(G + x, a);
        stv(C + x, c);
        stv(S + x, s);
    }
    for (; x < w; x++) {
        float a = g[0] * p[x], c = gc[0] * p[x], s = 0.0f;
        for (int64_t k = 1; k <= r; k++) {
            const float sum = p[x - k] + p[x + k], dif = p[x - k] - p[x + k];
            a += g[k] * sum;
            c += gc[k] * sum;
            s += gs[k] * dif;
        }
        G[x] = a;
        C[x] = c;
        S[x] = s;
    }
}

/* The vertical window sum of one plane at one output row, columns [x0, x1): out = ky0 row[0] +
 * sum ky_k (row[-k] + row[k]), rows given by pointers (a zero row beyond the image); four
 * vectors per block, then single vectors, then single pixels (lane-wise, so a column's bits do
 * not depend on the range it is summed in). */
ROW_FN void column_sums(int64_t x0, int64_t x1, int64_t r, const float *const *rows, const float *restrict ky,
                        float *restrict out) {
    enum { NV = 4 };
    int64_t x = x0;
    for (; x + LANES * NV <= x1; x += LANES * NV) {
        vf acc[NV];
        for (int v = 0; v < NV; v++) acc[v] = ky[0] * ldv(rows[0] + x + LANES * v);
        for (int64_t k = 1; k <= r; k++) {
            const float *up = rows[-k] + x, *down = rows[k] + x;
            for (int v = 0; v < NV; v++) acc[v] += ky[k] * (ldv(up + LANES * v) + ldv(down + LANES * v));
        }
        for (int v = 0; v < NV; v++) stv(out + x + LANES * v, acc[v]);
    }
    for (; x + LANES <= x1; x += LANES) {
        vf acc = ky[0] * ldv(rows[0] + x);
        for (int64_t k = 1; k <= r; k++) acc += ky[k] * (ldv(rows[-k] + x) + ldv(rows[k] + x));
        stv(out + x, acc);
    }
    for (; x < x1; x++) {
        float acc = ky[0] * rows[0][x];
        for (int64_t k = 1; k <= r; k++) acc += ky[k] * (rows[-k][x] + rows[k][x]);
        out[x] = acc;
    }
}

/* atan2(y, x) in (-pi, pi], vectorisable (no library call, selects instead of branches): the
 * octant reduction and polynomial of Cephes' atanf (S. L. Moshier), error ~1e-7 rad (tested
 * through the Gabor fit of a known fringe); atan2(0, 0) = 0. */
static inline float atan2_poly(float y, float x) {
    const float ax = fabsf(x), ay = fabsf(y);
    const float mx = ax > ay ? ax : ay, mn = ax > ay ? ay : ax;
    /* t = mn / mx in [0, 1]; above tan(pi/8), atan t = pi/4 + atan((t - 1) / (t + 1)), which is
     * (mn - mx) / (mn + mx): one division either way */
    const int big = mn > 0.41421356237309504880f * mx;
    const float base = big ? 0.78539816339744830962f : 0.0f;
    const float num = big ? mn - mx : mn, den = big ? mn + mx : mx;
    const float a = den > 0.0f ? num / den : 0.0f;
    const float z = a * a;
    float r = base + ((((8.05374449538e-2f * z - 1.38776856032e-1f) * z + 1.99777106478e-1f) * z -
                       3.33329491539e-1f) * z * a + a);
    r = ay > ax ? 1.57079632679489661923f - r : r;
    r = x < 0.0f ? PI_F - r : r;
    return y < 0.0f ? -r : r;
}


/* The x sums of f cos and f sin from the window-carried sums C, S (see gabor_band):
 * out_c = cos C + sin S, out_s = sin C - cos S; and the plain sum copied. */
FIT_ROW_FN void carrier_row(int64_t w, const float *restrict G, const float *restrict C, const float *restrict S,
                        const float *restrict cs, const float *restrict sn, float *restrict out_g,
                        float *restrict out_c, float *restrict out_s) {
    for (int64_t x = 0; x < w; x++) {
        if (out_g != NULL) out_g[x] = G[x];
        out_c[x] = cs[x] * C[x] + sn[x] * S[x];
        out_s[x] = sn[x] * C[x] - cs[x] * S[x];
    }
}

FIT_ROW_FN void copy_row(int64_t w, const float *restrict src, float *restrict dst) {
    for (int64_t x = 0; x < w; x++) dst[x] = src[x];
}

/* The products c I, c I^2 of one row. */
FIT_ROW_FN void input_rows(int64_t w, const float *restrict I, const float *restrict c, float *restrict p_ci,
                       float *restrict p_cii) {
    for (int64_t x = 0; x < w; x++) {
        const float ci = c[x] * I[x];
        p_ci[x] = ci;
        p_cii[x] = ci * I[x];
    }
}

/* psi = atan2(im, re) in [-pi, pi): I ~ a0 + R cos(w x - theta), the local phase w x - theta */
static inline float phase_of(float re, float im) {
    const float psi = atan2_poly(im, re);
    return psi >= PI_F ? psi - TWO_PI_F : psi;
}

/* The fit and the phase of one output row (see gabor_band) from its certainty sums m0..m4. */
FIT_ROW_FN void fit_row(int64_t w, const float *restrict m0, const float *restrict m1, const float *restrict m2,
                    const float *restrict m3, const float *restrict m4, const float *restrict cos1,
                    const float *restrict sin1, float s_min, const float *restrict v0, const float *restrict v1,
                    const float *restrict v2, const float *restrict v3, float *restrict wrapped,
                    float *restrict amp, float *restrict a0, float *restrict residual, float *restrict support) {
    for (int64_t x = 0; x < w; x++) {
        float k[SOLVER], re, im;
        fit_solver(m0[x], m1[x], m2[x], m3[x], m4[x], cos1[x], sin1[x], s_min, k);
        fit_apply(k, cos1[x], sin1[x], v0[x], v1[x], v2[x], v3[x], &re, &im, a0 + x, amp + x, residual + x);
        wrapped[x] = phase_of(re, im);
        support[x] = m0[x];
    }
}

/* fit_row from solver rows made before (SOLVER planes of stride `stride`) and the s1 row: the
 * all-ones band's, for a row whose every window is wholly certain, or the row's own, the table's
 * with the uncertain runs' written over them. */
FIT_ROW_FN void fit_row_solved(int64_t w, const float *restrict solver, int64_t stride, const float *restrict m0,
                           const float *restrict cos1, const float *restrict sin1, const float *restrict v0,
                           const float *restrict v1, const float *restrict v2, const float *restrict v3,
                           float *restrict wrapped, float *restrict amp, float *restrict a0,
                           float *restrict residual, float *restrict support) {
    for (int64_t x = 0; x < w; x++) {
        float k[SOLVER], re, im;
        for (int j = 0; j < SOLVER; j++) k[j] = solver[j * stride + x];
        fit_apply(k, cos1[x], sin1[x], v0[x], v1[x], v2[x], v3[x], &re, &im, a0 + x, amp + x, residual + x);
        wrapped[x] = phase_of(re, im);
        support[x] = m0[x];
    }
}

/* The solver rows (fit_solver, SOLVER planes of stride `stride`) of one row's certainty sums. */
FIT_ROW_FN void solver_row(int64_t w, const float *restrict m0, const float *restrict m1, const float *restrict m2,
                       const float *restrict m3, const float *restrict m4, const float *restrict cos1,
                       const float *restrict sin1, float s_min, int64_t stride, float *restrict solver) {
    for (int64_t x = 0; x < w; x++) {
        float k[SOLVER];
        fit_solver(m0[x], m1[x], m2[x], m3[x], m4[x], cos1[x], sin1[x], s_min, k);
        for (int j = 0; j < SOLVER; j++) solver[j * stride + x] = k[j];
    }
}

/* The row of the all-certain table (see gabor_band) that holds output row y of an h-row band:
 * the certainty moments of an all-ones band differ only within ry rows of its top and bottom, so
 * min(h, 2 ry + 1) rows hold them all (the top ry, one interior row, the bottom ry). */
static inline int64_t table_row(int64_t y, int64_t h, int64_t ry) {
    const int64_t n = h < 2 * ry + 1 ? h : 2 * ry + 1;
    if (n == h || y < ry) return y;
    return y >= h - ry ? y - (h - n) : ry;
}

/* The certainty's window sums (s1, sc, ss, sc2, ss2: rows 4-8 of B) of pixels [a, b) of one
 * output row from the column sums of c in the zero-padded row v_c (columns [a - rx, b + rx)
 * current); T: row temporaries. */
static void certainty_sums(int64_t a, int64_t b, int64_t w, int64_t rx, const float *restrict v_c,
                           const float *restrict kx, const float *restrict kc1, const float *restrict ks1,
                           const float *restrict kc2, const float *restrict ks2, const float *restrict cos1,
                           const float *restrict sin1, const float *restrict cos2, const float *restrict sin2,
                           float *restrict T, float *restrict B) {
    float *Gc = T + 4 * w, *Cc = T + 5 * w, *Sc = T + 6 * w, *C2 = T + 7 * w, *S2 = T + 8 * w;
    float *G2 = B + 3 * w; /* the same as Gc, unused */
    float *s1 = B + 4 * w, *sc = B + 5 * w, *ss = B + 6 * w, *sc2 = B + 7 * w, *ss2 = B + 8 * w;
    const int64_t n = b - a;
    row_sums(n, rx, v_c + a, kx, kc1, ks1, Gc + a, Cc + a, Sc + a);
    row_sums(n, rx, v_c + a, kx, kc2, ks2, G2 + a, C2 + a, S2 + a);
    carrier_row(n, Gc + a, Cc + a, Sc + a, cos1 + a, sin1 + a, s1 + a, sc + a, ss + a);
    carrier_row(n, NULL, C2 + a, S2 + a, cos2 + a, sin2 + a, NULL, sc2 + a, ss2 + a);
}

/* Normalised-convolution Gabor fit of one band (paper Eq. 10-11; simbench.decode.phase.gabor_phase
 * documents the model): h rows of intensity and certainty in, the fit for rows [y0, y1) out.
 *
 * The window sums of c I, c I cos, c I sin, c I^2 and of c, c cos, c sin, c cos2, c sin2 are
 * separable Gaussian sums with zero outside the image, taken along y first: the products c I,
 * c I^2 of the rows within ry of a block of KB output rows live in a ring of 2 ry + KB rows
 * (cache-resident; c is read where it is), and the column sums of c I, c I^2, c make KB padded
 * rows each (see KB below).  Along
 * x, the sums of f cos(w x') and f sin(w x') come from sums of f itself with the window carrying
 * the carrier
 * (cos(w (x - k)) = cos wx cos wk + sin wx sin wk), so one row feeds three sums.  Then the
 * per-pixel fit (fit_solver, fit_apply) and the phase psi = atan2(im, re) in [-pi, pi).
 *
 * The certainty's five sums are half the work, and wherever c is exactly 1 across a pixel's
 * whole window (inside the image) they are the sums of an all-ones band at that row: the same
 * operations on the same values, so the same bits.  `table` (TABLE_PLANES planes of
 * min(h, 2 ry + 1) rows, see table_row) holds those (planes 0-4) and their solver (fit_solver,
 * planes 5-14); with it, and fill_table 0, only the pixels whose window holds a c != 1 get their
 * certainty sums and solver computed (a per-column count of such rows in the y window, and its
 * running count over the x window, find them); every other pixel is fitted with the table's
 * solver.  With fill_table 1 every sum is computed and the certainty sums and solver are
 * written into the table (made from an all-ones band).  table NULL: every sum computed,
 * nothing written.
 *
 * kx, kc1, ks1, kc2, ks2: half kernels (rx + 1) of the x window g, g cos(w k), g sin(w k),
 * g cos(2 w k), g sin(2 w k); ky (ry + 1).  basis: cos1, sin1, cos2, sin2 (w each).
 * scratch: gabor_scratch_floats(w, rx, ry) floats.
 * Outputs (y1 - y0) rows: wrapped, amp, a0 (NULL: not written), residual, support (= s1). */
enum { TABLE_PLANES = 5 + SOLVER };
int64_t gabor_table_planes(void) { return TABLE_PLANES; }

/* The column sums are made for blocks of KB output rows, in tiles of TW columns: a tile's
 * 2 ry + KB product rows stay in L1 while its KB sums read them, where one output row at a time
 * over the whole width read its 2 ry + 1 rows from L2 for every row (L2-bound: ~2.5 of a band's
 * ~9 ms).  The same operations on the same values per column, so the same bits. */
enum { KB = 8, TW = 256 };

int64_t gabor_scratch_floats(int64_t w, int64_t rx, int64_t ry) {
    return 2 * (2 * ry + KB) * w + 3 * KB * (w + 2 * rx) + 18 * w + w + 2 * w + 1 + SOLVER * w + w;
}

/* rowp[-ry..ry]: the rows of output row y's y window, zero_row beyond the image; rows of the
 * ring (n_slots rows of w) when ring is not NULL, else of the image `base`. */
static inline void window_rows(const float **rowp, int64_t y, int64_t ry, int64_t h, const float *ring,
                               int64_t n_slots, const float *base, int64_t w, const float *zero_row) {
    /* the first ring row's slot by one division, then steps (rows above the image are zero rows) */
    int64_t slot = ring != NULL && y - ry >= 0 ? (y - ry) % n_slots : 0;
    for (int64_t k = -ry; k <= ry; k++) {
        const int64_t r = y + k;
        if (r < 0 || r >= h) {
            rowp[k] = zero_row;
            continue;
        }
        if (ring == NULL) {
            rowp[k] = base + r * w;
            continue;
        }
        rowp[k] = ring + slot * w;
        slot = slot + 1 == n_slots ? 0 : slot + 1;
    }
}

void gabor_band(int64_t h, int64_t w, const float *restrict intensity, const float *restrict certainty,
                int64_t y0, int64_t y1, int64_t rx, const float *restrict kx, const float *restrict kc1,
                const float *restrict ks1, const float *restrict kc2, const float *restrict ks2, int64_t ry,
                const float *restrict ky, const float *restrict cos1, const float *restrict sin1,
                const float *restrict cos2, const float *restrict sin2, float *restrict table, int64_t fill_table,
                float s_min, float *restrict scratch, float *restrict wrapped, float *restrict amp, float *restrict a0,
                float *restrict residual, float *restrict support) {
    const int skip = table != NULL && !fill_table; /* certain windows' sums from the table */
    const int64_t R = 2 * ry + 1;
    const int64_t RR = R + KB - 1; /* product rows a block of KB output rows reads */
    const int64_t pw = w + 2 * rx;
    const int64_t tw = (h < R ? h : R) * w; /* one table plane */
    float *ring = scratch;               /* 2 rings of RR product rows: c I, c I^2 */
    float *pad = ring + 2 * RR * w;      /* 3 planes of KB zero-padded column-sum rows: c I, c I^2, c */
    float *T = pad + 3 * KB * pw;        /* 9 row temporaries of the x sums */
    float *B = T + 9 * w;                /* the 9 window sums of the output row */
    float *zero_row = B + 9 * w;         /* w zeros: the rows beyond the image */
    int32_t *uncertain = (int32_t *)(zero_row + w); /* per column: rows with c != 1 in the y window */
    int32_t *before = uncertain + w;     /* w + 1: columns with such rows left of x */
    float *K = (float *)(before + w + 1); /* SOLVER rows: the solver of a row with uncertain windows */
    float *a0_sink = K + SOLVER * w;      /* a0's row when a0 is NULL (not asked for) */
    for (int64_t j = 0; j < 3 * KB * pw; j++) pad[j] = 0.0f;
    for (int64_t x = 0; x < w; x++) zero_row[x] = 0.0f, uncertain[x] = 0;
    float *G = T, *C = T + w, *S = T + 2 * w, *E = T + 3 * w;
    float *b0 = B, *b1 = B + w, *b2 = B + 2 * w;
    float *s1 = B + 4 * w, *sc = B + 5 * w, *ss = B + 6 * w, *sc2 = B + 7 * w, *ss2 = B + 8 * w;
    const float *rowp[2 * ry + 1]; /* the rows of one column sum */
    int32_t in_row[2 * ry + 1]; /* per slot (row % R): the row's pixels with c != 1 */
    int64_t in_window = 0;      /* their sum over the rows in the y window */
    const int64_t first = y0 - ry < 0 ? 0 : y0 - ry;
    int64_t next = first;    /* the next row whose products are due */
    int64_t counted = first; /* the next row whose uncertain pixels are due */
    for (int64_t yb = y0; yb < y1; yb += KB) {
        const int64_t kb = y1 - yb < KB ? y1 - yb : KB;
        const int64_t last_b = yb + kb - 1 + ry < h ? yb + kb - 1 + ry : h - 1;
        for (; next <= last_b; next++) {
            const int64_t slot = (next % RR) * w;
            input_rows(w, intensity + next * w, certainty + next * w, ring + slot, ring + RR * w + slot);
        }
        for (int64_t q = 0; q < 3; q++) { /* c I and c I^2 from their rings, c from the input */
            if (q == 2 && skip) break;    /* c only where a window is uncertain, per row below */
            for (int64_t x0 = 0; x0 < w; x0 += TW) {
                const int64_t x1 = x0 + TW < w ? x0 + TW : w;
                for (int64_t k = 0; k < kb; k++) {
                    window_rows(rowp + ry, yb + k, ry, h, q < 2 ? ring + q * RR * w : NULL, RR, certainty, w,
                                zero_row);
                    column_sums(x0, x1, ry, rowp + ry, ky, pad + (q * KB + k) * pw + rx);
                }
            }
        }
        for (int64_t k = 0; k < kb; k++) {
            const int64_t y = yb + k;
            const int64_t last = y + ry < h ? y + ry : h - 1;
            float *v_ci = pad + k * pw + rx, *v_cii = pad + (KB + k) * pw + rx, *v_c = pad + (2 * KB + k) * pw + rx;
            if (skip) {
                if (y - ry - 1 >= first && in_row[(y - ry - 1) % R] > 0) {
                    const float *c = certainty + (y - ry - 1) * w;
                    for (int64_t x = 0; x < w; x++) uncertain[x] -= c[x] != 1.0f;
                    in_window -= in_row[(y - ry - 1) % R];
                }
                for (; counted <= last; counted++) {
                    const float *c = certainty + counted * w;
                    int32_t n = 0;
                    for (int64_t x = 0; x < w; x++) {
                        const int32_t u = c[x] != 1.0f;
                        uncertain[x] += u;
                        n += u;
                    }
                    in_row[counted % R] = n;
                    in_window += n;
                }
            }
            row_sums(w, rx, v_ci, kx, kc1, ks1, G, C, S);
            row_sums(w, rx, v_cii, kx, NULL, NULL, E, NULL, NULL);
            carrier_row(w, G, C, S, cos1, sin1, b0, b1, b2);
            const int64_t o = (y - y0) * w;
            float *a0_out = a0 != NULL ? a0 + o : a0_sink;
            if (!skip) {
                certainty_sums(0, w, w, rx, v_c, kx, kc1, ks1, kc2, ks2, cos1, sin1, cos2, sin2, T, B);
                if (table != NULL) {
                    const int64_t t = table_row(y, h, ry) * w;
                    for (int64_t q = 0; q < 5; q++) copy_row(w, B + (4 + q) * w, table + q * tw + t);
                    solver_row(w, s1, sc, ss, sc2, ss2, cos1, sin1, s_min, tw, table + 5 * tw + t);
                }
                fit_row(w, s1, sc, ss, sc2, ss2, cos1, sin1, s_min, b0, b1, b2, E, wrapped + o, amp + o, a0_out,
                        residual + o, support + o);
                continue;
            }
            const int64_t t = table_row(y, h, ry) * w;
            if (in_window == 0) {
                fit_row_solved(w, table + 5 * tw + t, tw, table + t, cos1, sin1, b0, b1, b2, E, wrapped + o, amp + o,
                               a0_out, residual + o, support + o);
                continue;
            }
            /* the table's sums and solver, then those of the runs of uncertain windows */
            window_rows(rowp + ry, y, ry, h, NULL, 0, certainty, w, zero_row);
            for (int64_t q = 0; q < 5; q++) copy_row(w, table + q * tw + t, B + (4 + q) * w);
            for (int64_t q = 0; q < SOLVER; q++) copy_row(w, table + (5 + q) * tw + t, K + q * w);
            before[0] = 0;
            for (int64_t x = 0; x < w; x++) before[x + 1] = before[x] + (uncertain[x] > 0);
            /* runs [a, b) of pixels whose x window [x - rx, x + rx] meets such a column */
            int64_t done = 0; /* columns of v_c summed so far: [.., done) */
            for (int64_t a = 0; a < w;) {
                while (a < w && before[a + rx + 1 < w ? a + rx + 1 : w] == before[a - rx > 0 ? a - rx : 0]) a++;
                if (a == w) break;
                int64_t b = a + 1;
                while (b < w && before[b + rx + 1 < w ? b + rx + 1 : w] != before[b - rx > 0 ? b - rx : 0]) b++;
                const int64_t lo = a - rx > done ? a - rx : done, hi = b + rx < w ? b + rx : w;
                if (lo < hi) column_sums(lo, hi, ry, rowp + ry, ky, v_c);
                done = hi;
                certainty_sums(a, b, w, rx, v_c, kx, kc1, ks1, kc2, ks2, cos1, sin1, cos2, sin2, T, B);
                solver_row(b - a, s1 + a, sc + a, ss + a, sc2 + a, ss2 + a, cos1 + a, sin1 + a, s_min, w, K + a);
                a = b;
            }
            fit_row_solved(w, K, w, s1, cos1, sin1, b0, b1, b2, E, wrapped + o, amp + o, a0_out, residual + o,
                           support + o);
        }
    }
}

/* out[j] = per_stripe[labels[j]], fill where the label is negative; items of any size. */
void gather(int64_t n, int64_t itemsize, const void *restrict per_stripe, const int32_t *restrict labels,
            const void *restrict fill, void *restrict out) {
    const char *src = (const char *)per_stripe;
    char *dst = (char *)out;
    if (itemsize == 4) {
        const int32_t *s4 = (const int32_t *)per_stripe;
        int32_t f4;
        memcpy(&f4, fill, 4);
        int32_t *d4 = (int32_t *)out;
        for (int64_t j = 0; j < n; j++) d4[j] = labels[j] >= 0 ? s4[labels[j]] : f4;
        return;
    }
    if (itemsize == 1) {
        const int8_t *s1 = (const int8_t *)per_stripe;
        const int8_t f1 = *(const int8_t *)fill;
        int8_t *d1 = (int8_t *)out;
        for (int64_t j = 0; j < n; j++) d1[j] = labels[j] >= 0 ? s1[labels[j]] : f1;
        return;
    }
    for (int64_t j = 0; j < n; j++) {
        const int32_t s = labels[j];
        memcpy(dst + j * itemsize, s >= 0 ? src + (int64_t)s * itemsize : (const char *)fill, (size_t)itemsize);
    }
}

/* col0 = (psi + pi) * (t / 2 pi) + W t - 0.5, k = rint((expected - col0) / span); where W >= 0 and
 * k is finite: column = col0 + k span, index = W + L k; else NaN and -1. */
static inline void column_of_pixel(int32_t p, float wrapped, float expected, float t, float scale, float span,
                                   uint32_t ucycle, float *restrict column, int32_t *restrict index) {
    const float c0 = (wrapped + PI_F) * scale + (float)p * t - 0.5f;
    const float k = rintf((expected - c0) / span);
    /* branch-free so that the loop vectorises: W + L k in wrapping int32 arithmetic, with
     * x86's conversion of an out-of-range k (INT32_MIN), as the numpy form computes it */
    const int ok = (p >= 0) & (fabsf(k) <= FLT_MAX);
    const int in_range = fabsf(k) < 2147483648.0f;
    const int32_t ki = (int32_t)(in_range ? k : 0.0f);
    const uint32_t uk = in_range ? (uint32_t)ki : 0x80000000u;
    *column = ok ? c0 + k * span : NAN;
    *index = ok ? (int32_t)((uint32_t)p + ucycle * uk) : -1;
}

void absolute_column(int64_t n, const int32_t *restrict position, const float *restrict wrapped,
                     const float *restrict expected, float t, float span, int64_t cycle, float *restrict column,
                     int32_t *restrict index) {
    const float scale = t / TWO_PI_F;
    for (int64_t j = 0; j < n; j++)
        column_of_pixel(position[j], wrapped[j], expected[j], t, scale, span, (uint32_t)cycle, column + j, index + j);
}

/* Linear look-up of each pixel's column in its row of the inverse table (h rows of tw entries, the
 * last one NaN); a column outside [0, tw - 2] (or NaN) gives NaN. */
static inline float lookup(const float *restrict row, int64_t width, float c) {
    const float fw = (float)width;
    const int ok = (c >= 0.0f) & (c <= fw);
    const float cc = ok ? c : 0.0f;
    /* floor by truncation (cc >= 0) and the clamp in int32: no floorf and no float compare
     * feeding the index, so the loops vectorise (gathers); the bits of floorf and a float clamp */
    int32_t i = (int32_t)cc;
    i = i > (int32_t)(width - 1) ? (int32_t)(width - 1) : i;
    const float f = cc - (float)i;
    const float x0 = row[i], x1 = row[i + 1];
    return ok ? x0 + f * (x1 - x0) : NAN;
}

void match_reference(int64_t h, int64_t w, int64_t tw, const float *restrict column, const float *restrict table,
                     float *restrict out) {
    for (int64_t y = 0; y < h; y++)
        for (int64_t x = 0; x < w; x++) out[y * w + x] = lookup(table + y * tw, tw - 2, column[y * w + x]);
}

/* z = 1 / (1/Z0 + (x - x_ref) / (f B)), NaN unless z > 0. */
void depth_from_disparity(int64_t h, int64_t w, const float *restrict x_ref, float inv_z0, float inv_fb,
                          float *restrict out) {
    for (int64_t y = 0; y < h; y++)
        for (int64_t x = 0; x < w; x++) {
            const float d = (float)x - x_ref[y * w + x];
            const float z = 1.0f / (inv_z0 + d * inv_fb);
            out[y * w + x] = z > 0.0f ? z : NAN;
        }
}

/* Linked stripes before (left) and after (right) each stripe in its chain. */
void chain_extent(int64_t n, const uint8_t *restrict linked_prev, int64_t *restrict left, int64_t *restrict right) {
    int64_t start = 0;
    for (int64_t j = 0; j < n; j++) {
        if (!linked_prev[j]) start = j;
        left[j] = j - start;
    }
    int64_t end = n - 1;
    for (int64_t j = n - 1; j >= 0; j--) {
        right[j] = end - j;
        if (!linked_prev[j]) end = j - 1;
    }
}

static inline int64_t pymod(int64_t a, int64_t m) {
    if (a >= 0 && a < m) return a; /* the common case here, without a division */
    if (a < 0 && a >= -m) return a + m;
    const int64_t r = a % m;
    return r < 0 ? r + m : r;
}

/* W of each stripe from its window of `order` binary codes (simbench.decode.debruijn
 * window_positions_of_stripes): stripes j - hw .. j - hw + order - 1, hw = (order - 1) / 2, all in
 * j's chain (left/right: chain_extent), read as a binary number into `table`; -1 where the
 * window leaves the chain or the table does not hold it. */
void window_positions(int64_t n, const uint8_t *restrict code, const int64_t *restrict left,
                      const int64_t *restrict right, int64_t order, const int32_t *restrict table, int64_t cycle,
                      int32_t *restrict out) {
    const int64_t hw = (order - 1) / 2;
    for (int64_t j = 0; j < n; j++) {
        if (left[j] < hw || right[j] < order - 1 - hw) {
            out[j] = -1;
            continue;
        }
        int64_t c = 0;
        for (int64_t k = 0; k < order; k++) c = 2 * c + code[j - hw + k];
        const int64_t q = table[c];
        out[j] = q >= 0 ? (int32_t)((q + hw) % cycle) : -1;
    }
}

/* Both stripes of every link whose positions do not follow each other (W[j] != W[j-1] + 1 mod
 * cycle, both known) set to -1 (simbench.decode.debruijn.drop_broken_links); the rule is read on
 * the positions as given. */
void drop_broken_links(int64_t n, const int32_t *restrict positions, const uint8_t *restrict linked_prev,
                       int64_t cycle, int32_t *restrict out) {
    for (int64_t j = 0; j < n; j++) out[j] = positions[j];
    for (int64_t j = 1; j < n; j++) {
        const int64_t prev = positions[j - 1], cur = positions[j];
        if (linked_prev[j] && prev >= 0 && cur >= 0 && pymod(cur - prev, cycle) != 1) out[j] = out[j - 1] = -1;
    }
}

/* Plurality of the positions predicted by the stripe and its linked neighbours within reach
 * (W[j + o] - o mod L); kept when it has min_support votes and beats every other candidate,
 * else -1.  counts: scratch of cycle entries. */
void neighbour_correct(int64_t n, const int32_t *restrict positions, const int64_t *restrict left,
                       const int64_t *restrict right, int64_t cycle, int64_t reach, int64_t min_support,
                       int64_t *restrict counts, int32_t *restrict out, int32_t *restrict support) {
    for (int64_t j = 0; j < n; j++) {
        /* fast path, the same decision: when the stripe's own W has a strict majority of the
         * predictions it is the plurality, with every rival below it */
        const int32_t p0 = positions[j];
        if (p0 >= 0 && p0 < cycle) {
            int64_t agree = 0, total = 0;
            for (int64_t off = -reach; off <= reach; off++) {
                const int64_t src = j + off;
                const int ok = off < 0 ? (left[j] >= -off) : (right[j] >= off);
                if (ok && src >= 0 && src < n && positions[src] >= 0) {
                    total += 1;
                    agree += pymod((int64_t)positions[src] - off, cycle) == p0;
                }
            }
            if (2 * agree > total) {
                const int keep = agree >= min_support;
                out[j] = keep ? p0 : -1;
                support[j] = keep ? (int32_t)agree : 0;
                continue;
            }
        }
        for (int64_t v = 0; v < cycle; v++) counts[v] = 0;
        for (int64_t off = -reach; off <= reach; off++) {
            const int64_t src = j + off;
            const int ok = off < 0 ? (left[j] >= -off) : (right[j] >= off);
            if (ok && src >= 0 && src < n) {
                const int32_t p = positions[src];
                if (p >= 0) counts[pymod((int64_t)p - off, cycle)] += 1;
            }
        }
        int64_t best = 0;
        for (int64_t v = 1; v < cycle; v++)
            if (counts[v] > counts[best]) best = v;
        const int64_t votes = counts[best];
        int64_t rival = -1;
        for (int64_t v = 0; v < cycle; v++)
            if (v != best && counts[v] > rival) rival = counts[v];
        if (votes >= min_support && votes > rival) {
            out[j] = (int32_t)best;
            support[j] = (int32_t)votes;
        } else {
            out[j] = -1;
            support[j] = 0;
        }
    }
}

/* simbench.decode.color.pool_code_rows: out[y][x] (rows y of [y0, y0 + h_out) of the ext
 * images, w columns) = the sign of the pixel's own vote (2 code - 1) plus those of the pixels
 * (y + d, x), 0 < |d| <= k, inside the ext rows, that are valid and whose wrapped phase lies
 * within tol of the pixel's own (the difference wrapped into [-pi, pi)); a tie is 1. */
void pool_code_rows(int64_t h_ext, int64_t w, int64_t y0, int64_t h_out, const uint8_t *restrict code,
                    const float *restrict wrapped, const uint8_t *restrict valid, int64_t k, float tol,
                    int32_t *restrict sum, uint8_t *restrict out) {
    /* row by row over x (contiguous, branch-free: the compiler vectorises it); sum: w int32 */
    for (int64_t y = 0; y < h_out; y++) {
        const int64_t yc = y0 + y;
        const float *psi = wrapped + yc * w;
        const uint8_t *own = code + yc * w;
        for (int64_t x = 0; x < w; x++) sum[x] = own[x] ? 1 : -1;
        for (int64_t d = -k; d <= k; d++) {
            const int64_t yy = yc + d;
            if (d == 0 || yy < 0 || yy >= h_ext) continue;
            const float *pw = wrapped + yy * w;
            const uint8_t *pc = code + yy * w, *pv = valid + yy * w;
            for (int64_t x = 0; x < w; x++) {
                float diff = pw[x] - psi[x];
                diff = diff >= PI_F ? diff - 2.0f * PI_F : diff;
                diff = diff < -PI_F ? diff + 2.0f * PI_F : diff;
                const int32_t vote = pc[x] ? 1 : -1;
                sum[x] += (pv[x] && diff < tol && diff > -tol) ? vote : 0;
            }
        }
        for (int64_t x = 0; x < w; x++) out[y * w + x] = sum[x] >= 0;
    }
}

/* simbench.decode.debruijn.contested_positions: out[j] = 1 where the kept position kept[j]
 * has a rival h != kept[j] that the linked stripes within reach predict (positions[j + o] - o
 * mod cycle) on both sides, at least once on each and min_support times in all.
 * counts: 2 cycle int64 of scratch. */
void contested_positions(int64_t n, const int32_t *restrict positions, const int32_t *restrict kept,
                         const int64_t *restrict left, const int64_t *restrict right, int64_t cycle, int64_t reach,
                         int64_t min_support, int64_t *restrict counts, uint8_t *restrict out) {
    int64_t *cl = counts, *cr = counts + cycle;
    for (int64_t j = 0; j < n; j++) {
        out[j] = 0;
        const int32_t w = kept[j];
        if (w < 0) continue;
        for (int64_t v = 0; v < 2 * cycle; v++) counts[v] = 0;
        for (int64_t off = -reach; off <= reach; off++) {
            const int64_t src = j + off;
            const int ok = off < 0 ? (left[j] >= -off) : (right[j] >= off);
            if (off == 0 || !ok || src < 0 || src >= n || positions[src] < 0) continue;
            const int64_t h = pymod((int64_t)positions[src] - off, cycle);
            if (h != w) (off < 0 ? cl : cr)[h] += 1;
        }
        for (int64_t h = 0; h < cycle; h++)
            if (cl[h] >= 1 && cr[h] >= 1 && cl[h] + cr[h] >= min_support) {
                out[j] = 1;
                break;
            }
    }
}

/* Wraps (0 or 1) across the invalid gap between pixels xl and x of one row, or -1
 * (simbench.decode._kernels documents the rule). */
static int64_t bridge(const float *restrict wr, const uint8_t *restrict valid, int64_t w, int64_t xl, int64_t x,
                      int64_t first, float lo, float hi, double omega, double tol) {
    int64_t steps = xl - first;
    double acc = (double)wr[xl] - (double)wr[first];
    int64_t j = x;
    while (j + 1 < w && valid[j + 1]) {
        const float d = wr[j + 1] - wr[j];
        if (d < -PI_F || !(d > lo && d < hi)) break;
        j += 1;
    }
    steps += j - x;
    acc += (double)wr[j] - (double)wr[x];
    const double slope = steps >= 2 ? acc / (double)steps : omega;
    if (!(slope > (double)lo && slope < (double)hi)) return -1;
    const double advance = slope * (double)(x - xl);
    const double d = (double)wr[x] - (double)wr[xl];
    const double k = floor((advance - d) / TWO_PI_D + 0.5);
    if ((k == 0.0 || k == 1.0) && fabs(d + TWO_PI_D * k - advance) <= tol) return (int64_t)k;
    return -1;
}

/* What the step from pixel x - 1 to x of one row says (segment_stripes): the stripe continues,
 * the next starts linked (a plausible wrap) or unlinked (an implausible step), x ends a gap (or
 * starts the row) and may be bridged, or x is invalid. */
enum { STEP_CONT = 0, STEP_LINK, STEP_NEW, STEP_GAP, STEP_INVALID };
ROW_FN void step_classes(int64_t w, const float *restrict wr, const uint8_t *restrict va, float lo, float hi,
                         uint8_t *restrict cls) {
    cls[0] = va[0] ? STEP_GAP : STEP_INVALID;
    for (int64_t x = 1; x < w; x++) {
        const float d = wr[x] - wr[x - 1];
        const int wrap = d < -PI_F;
        const float step = wrap ? d + TWO_PI_F : d;
        const uint8_t both = (step > lo && step < hi) ? (wrap ? STEP_LINK : STEP_CONT) : STEP_NEW;
        cls[x] = !va[x] ? STEP_INVALID : va[x - 1] ? both : STEP_GAP;
    }
}

/* The end of the run of bytes equal to 0 (STEP_CONT) starting at x: eight at a time. */
static inline int64_t run_end(const uint8_t *restrict cls, int64_t x, int64_t w) {
    for (; x + 8 <= w; x += 8) {
        uint64_t v;
        memcpy(&v, cls + x, 8);
        if (v != 0) return x + __builtin_ctzll(v) / 8; /* little-endian: the first byte is lowest */
    }
    while (x < w && cls[x] == STEP_CONT) x++;
    return x;
}

/* Row-wise stripe segmentation; returns the number of stripes (simbench.decode._kernels
 * documents the rule).  row/start/stop/linked_prev hold one entry per possible stripe; cls: w
 * bytes of scratch.  Each row's steps are classified first (step_classes, across pixels), then
 * runs of continuing pixels are labelled at once. */
int64_t segment_stripes(int64_t h, int64_t w, const float *restrict wrapped, const uint8_t *restrict valid, float lo,
                        float hi, int64_t max_gap, double omega, double tol, int32_t *restrict labels,
                        int32_t *restrict row, int32_t *restrict start, int32_t *restrict stop,
                        uint8_t *restrict linked_prev, uint8_t *restrict cls) {
    int64_t s = -1;
    if (w == 0) return 0;
    for (int64_t y = 0; y < h; y++) {
        const float *wr = wrapped + y * w;
        const uint8_t *va = valid + y * w;
        int32_t *lab = labels + y * w;
        step_classes(w, wr, va, lo, hi, cls);
        for (int64_t x = 0; x < w;) {
            const uint8_t c = cls[x];
            if (c == STEP_CONT) { /* x - 1 is labelled s */
                const int64_t e = run_end(cls, x + 1, w);
                for (int64_t j = x; j < e; j++) lab[j] = (int32_t)s;
                stop[s] = (int32_t)e;
                x = e;
                continue;
            }
            if (c == STEP_INVALID) {
                lab[x++] = -1;
                continue;
            }
            int cont = 0, link = c == STEP_LINK;
            if (c == STEP_GAP && max_gap > 0 && s >= 0 && row[s] == y && x - stop[s] <= max_gap) {
                const int64_t k = bridge(wr, va, w, stop[s] - 1, x, start[s], lo, hi, omega, tol);
                cont = k == 0;
                link = k == 1;
            }
            if (!cont) {
                s += 1;
                row[s] = (int32_t)y;
                start[s] = (int32_t)x;
                linked_prev[s] = (uint8_t)link;
            }
            lab[x] = (int32_t)s;
            stop[s] = (int32_t)(x + 1);
            x++;
        }
    }
    return s + 1;
}

/* Per stripe: share of its pixels with code 1 (float64; pixels of a bridged gap are not its own);
 * the code is the majority (ties give 1) or, without voting, the middle pixel's; agreement =
 * share agreeing with it; votes = its own pixels. */
void vote_codes(int64_t n, int64_t w, const uint8_t *restrict code, const int32_t *restrict labels,
                const int32_t *restrict row, const int32_t *restrict start, const int32_t *restrict stop,
                int64_t voting, uint8_t *restrict out, float *restrict agreement, int32_t *restrict votes) {
    for (int64_t s = 0; s < n; s++) {
        const int64_t o = (int64_t)row[s] * w;
        int32_t ones = 0, count = 0; /* branch-free int32 sums: the loop vectorises */
        for (int64_t x = start[s]; x < stop[s]; x++) {
            const int32_t m = labels[o + x] == (int32_t)s;
            ones += m & code[o + x];
            count += m;
        }
        const double frac = count > 0 ? (double)ones / (double)count : 0.5;
        uint8_t c;
        if (voting)
            c = frac >= 0.5 ? 1 : 0;
        else
            c = code[o + ((int64_t)start[s] + stop[s] - 1) / 2] ? 1 : 0;
        out[s] = c;
        agreement[s] = (float)(c == 1 ? frac : 1.0 - frac);
        votes[s] = count;
    }
}

/* One band of a capture (h rows of w interleaved 3-channel pixels: dtype 0 = uint8, 1 = uint16,
 * 2 = float32; the channels read as R = code 1, G = code 0, B = fringe are ch[0..2]) to the
 * decoder's first images, in one pass (simbench.decode.pipeline's default path):
 *   float conversion   v / 255 or v / 65535 as v * (float)(1/255) (numpy's multiply in float32)
 *   intensity          paper Eq. 9 (R + G + B) / 2 as (0.5 R + 0.5 G) + 0.5 B (cv2.transform's
 *                      float32 sum), or B alone (mode 1)
 *   code               paper Eq. 13: R >= G
 *   lit, certainty     certainty_map: the channel peak's maximum over a row window of `width`
 *                      pixels (clamped at the row's ends: cv2.dilate with a replicated border)
 *                      >= dark_level; certain = lit and the peak < saturation_level
 * scratch: front_end_scratch_floats(w, width) floats.  Thresholds are float32, as numpy compares
 * float32 images with a Python float. */
#define FRONT_END_ROW(T, SCALE, C0, C1, C2)                                                                \
    for (int64_t x = 0; x < w; x++) {                                                                  \
        const T *p = (const T *)image + (y * w + x) * 3;                                                \
        const float R = (float)p[C0] SCALE, G = (float)p[C1] SCALE, B = (float)p[C2] SCALE;             \
        const float m = R > G ? R : G;                                                                  \
        const float pk = m > B ? m : B;                                                                 \
        peak[x] = pk;                                                                                   \
        inten[x] = mode == 0 ? (half * R + half * G) + half * B : B;                                    \
        cd[x] = R >= G;                                                                                 \
        const int b = pk >= dark_level;                                                                 \
        li[x] = (uint8_t)b;                                                                             \
        bright += b;                                                                                    \
    }
/* the channels in the capture's order as constants (the deinterleaving vectorises), else as read */
#define FRONT_END_ROWS(T, SCALE)                                                                           \
    if (ch0 == 0 && ch1 == 1 && ch2 == 2) {                                                            \
        FRONT_END_ROW(T, SCALE, 0, 1, 2)                                                               \
    } else {                                                                                           \
        FRONT_END_ROW(T, SCALE, ch0, ch1, ch2)                                                         \
    }

int64_t front_end_scratch_floats(int64_t w, int64_t width) { return w + (2 * (w + 2 * (width / 2)) + 3) / 4 + 1; }

void front_end(int64_t h, int64_t w, const void *restrict image, int64_t dtype, int64_t ch0, int64_t ch1,
               int64_t ch2, int64_t mode, int64_t width, float dark_level, float saturation_level,
               float *restrict intensity, float *restrict certainty, uint8_t *restrict lit, uint8_t *restrict code,
               float *restrict scratch) {
    const float k8 = (float)(1.0 / 255.0), k16 = (float)(1.0 / 65535.0), half = 0.5f;
    const int64_t r = width / 2, n = w + 2 * r, span = 2 * r + 1;
    float *restrict peak = scratch;
    uint8_t *A = (uint8_t *)(scratch + w), *Bf = A + n; /* the padded row and its doubling */
    for (int64_t i = 0; i < n; i++) A[i] = 0;
    for (int64_t y = 0; y < h; y++) {
        float *restrict inten = intensity + y * w;
        uint8_t *restrict cd = code + y * w;
        uint8_t *restrict li = lit + y * w;
        int64_t bright = 0;
        if (dtype == 0) {
            FRONT_END_ROWS(uint8_t, *k8)
        } else if (dtype == 1) {
            FRONT_END_ROWS(uint16_t, *k16)
        } else {
            FRONT_END_ROWS(float, )
        }
        /* lit: the peak's maximum over [x - r, x + r] clipped to the row (with a replicated
         * border the values beyond the ends repeat the end pixels, which the clipped window holds
         * already) >= dark_level, i.e. some pixel of the window is bright (for finite captures,
         * the only ones the decoder takes): the OR of the bright flags over the window, zero
         * beyond the row, by doubling (after step p, each flag is the OR of the p from it on),
         * then two overlapping spans of the largest such p cover the window. */
        if (bright > 0 && bright < w) {
            uint8_t *src = A, *dst = Bf;
            for (int64_t x = 0; x < w; x++) src[r + x] = li[x];
            int64_t p = 1;
            for (; 2 * p <= span; p *= 2) {
                for (int64_t i = 0; i + p < n; i++) dst[i] = src[i] | src[i + p];
                for (int64_t i = n - p > 0 ? n - p : 0; i < n; i++) dst[i] = src[i];
                uint8_t *t = src;
                src = dst;
                dst = t;
            }
            for (int64_t x = 0; x < w; x++) li[x] = src[x] | src[x + span - p];
            for (int64_t i = 0; i < n; i++) A[i] = 0; /* the padding zero again for the next row */
        } /* else every window holds bright pixels (li all 1) or none does (all 0) */
        float *restrict cert = certainty + y * w;
        for (int64_t x = 0; x < w; x++) cert[x] = (li[x] & (peak[x] < saturation_level)) ? 1.0f : 0.0f;
    }
}

/* The phase-valid mask: lit, window support, fringe amplitude and fit residual within their
 * limits (float32 thresholds). */
void validity(int64_t n, const uint8_t *restrict lit, const float *restrict support, const float *restrict amplitude,
              const float *restrict residual, float min_support, float min_amplitude, float max_residual,
              uint8_t *restrict valid) {
    for (int64_t j = 0; j < n; j++)
        valid[j] = lit[j] & (support[j] >= min_support) & (amplitude[j] >= min_amplitude) &
                   (residual[j] <= max_residual);
}

/* Camera z where the ray (rx, ry, 1) meets the plane of ideal projector column u: n = R (1, 0, -a),
 * a = (u - cx_p) / f_p, n.(X - t) = 0 (simbench.rig.triangulate_columns' numpy form, in its
 * operation order).  R row-major 3x3, t the projector's position. */
static inline double plane_depth(double u, double rx, double ry, double fp, double cxp, const double *restrict R,
                                 const double *restrict t) {
    const double a = (u - cxp) / fp;
    const double nx = R[0] - a * R[2], ny = R[3] - a * R[5], nz = R[6] - a * R[8];
    return (nx * t[0] + ny * t[1] + nz * t[2]) / (nx * rx + ny * ry + nz);
}

/* The plane fit's centred points (simbench.metrics.plane_fit_error): for the pixels that count
 * (finite depth, and mask[j] where a mask is given), in row-major order, the point p = ray *
 * depth; the centroid c = (sum of p) / count with the sums taken row after row (as numpy's sum
 * over axis 0 of an (N, 3) array adds them); q = p - c written to points (N x 3).  Returns N. */
int64_t centred_points(int64_t n, const double *restrict depth, const double *restrict rays,
                       const uint8_t *restrict mask, double *restrict points) {
    int64_t m = 0;
    double s0 = 0.0, s1 = 0.0, s2 = 0.0;
    for (int64_t j = 0; j < n; j++) {
        const double d = depth[j];
        if (!isfinite(d) || (mask != NULL && !mask[j])) continue;
        double *p = points + 3 * m++;
        p[0] = rays[3 * j] * d, p[1] = rays[3 * j + 1] * d, p[2] = rays[3 * j + 2] * d;
        if (m == 1) {
            s0 = p[0], s1 = p[1], s2 = p[2];
        } else {
            s0 += p[0], s1 += p[1], s2 += p[2];
        }
    }
    if (m == 0) return 0;
    const double c0 = s0 / (double)m, c1 = s1 / (double)m, c2 = s2 / (double)m;
    for (int64_t i = 0; i < m; i++) {
        double *p = points + 3 * i;
        p[0] -= c0, p[1] -= c1, p[2] -= c2;
    }
    return m;
}

/* depth_errors' per-pixel pass (simbench.metrics): in row-major order, a pixel counts (region)
 * where region[j] and the ground truth is finite, is valid where it counts and the depth is
 * finite, and is scored where valid and not excluded (exclude may be NULL); the errors of the
 * scored pixels, ((double)depth - (double)gt) * 1000 (millimetres: numpy's float64 operations on
 * the gathered values), go to err in order.  Maps are float32 (f32 = 1) or float64.  counts:
 * pixels that count, valid ones.  Returns the number scored. */
int64_t scored_errors(int64_t n, const void *restrict depth, int64_t depth_f32, const void *restrict gt,
                      int64_t gt_f32, const uint8_t *restrict region, const uint8_t *restrict exclude,
                      uint8_t *restrict valid, double *restrict err, int64_t *restrict counts) {
    int64_t n_region = 0, n_valid = 0, m = 0;
    for (int64_t j = 0; j < n; j++) {
        const double g = gt_f32 ? (double)((const float *)gt)[j] : ((const double *)gt)[j];
        const double d = depth_f32 ? (double)((const float *)depth)[j] : ((const double *)depth)[j];
        const int counts_here = region[j] && isfinite(g);
        const int v = counts_here && isfinite(d);
        valid[j] = (uint8_t)v;
        n_region += counts_here;
        n_valid += v;
        if (v && !(exclude != NULL && exclude[j])) err[m++] = (d - g) * 1000.0;
    }
    counts[0] = n_region;
    counts[1] = n_valid;
    return m;
}

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_ckernels", NULL, -1, NULL};

PyMODINIT_FUNC PyInit__ckernels(void) { return PyModule_Create(&module); }

/* Lanes of the projector-column triangulation: pixels processed together, so that every step
 * is a loop over the lanes that the compiler vectorises. */
enum { TL = 8 };

/* a == b, or both NaN: a further step from a gives b's result again */
static inline int settled(double a, double b) { return (a == b) | ((a != a) & (b != b)); }

/* The ideal (pinhole) normalised x of TL DMD columns, each on the projector row of normalised y:
 * Newton's method on fx D_x(x, y) + cx = u_d from x = the distorted target (0 where that is not
 * finite), `steps` steps (simbench.optics.undistort_projector_columns, in its operation order).
 * A step that leaves every lane's x unchanged leaves them unchanged forever, so stopping there
 * gives the same bits; Newton gets there in 3-5 steps for a measurement lens. */
ROW_FN void undistort_lanes(const double *restrict target, const double *restrict y, const double *restrict d,
                            int64_t steps, double *restrict x) {
    const double k1 = d[0], k2 = d[1], p1 = d[2], p2 = d[3], k3 = d[4];
    for (int l = 0; l < TL; l++) x[l] = fabs(target[l]) <= DBL_MAX ? target[l] : 0.0;
    for (int64_t i = 0; i < steps; i++) {
        double next[TL];
        int moved = 0;
        for (int l = 0; l < TL; l++) {
            const double r2 = x[l] * x[l] + y[l] * y[l];
            const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
            const double dradial = 2.0 * x[l] * (k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3));
            const double f = x[l] * radial + 2.0 * p1 * x[l] * y[l] + p2 * (r2 + 2.0 * x[l] * x[l]) - target[l];
            const double fp = radial + x[l] * dradial + 2.0 * p1 * y[l] + 6.0 * p2 * x[l];
            next[l] = x[l] - f / fp;
        }
        for (int l = 0; l < TL; l++) moved |= !settled(next[l], x[l]);
        for (int l = 0; l < TL; l++) x[l] = next[l];
        if (!moved) break;
    }
}

/* plane_depth of TL lanes */
ROW_FN void plane_depth_lanes(const double *restrict u, const double *restrict rx, const double *restrict ry,
                              double fp, double cxp, const double *restrict R, const double *restrict t,
                              double *restrict z) {
    for (int l = 0; l < TL; l++) z[l] = plane_depth(u[l], rx[l], ry[l], fp, cxp, R, t);
}

/* TL pixels of triangulate_columns (below): camera z from DMD columns u at rays rx, ry. */
static void triangulate_lanes(const double *restrict u, const double *restrict rx, const double *restrict ry,
                              const double *restrict rig, int64_t distorted, int64_t newton_steps,
                              int64_t refine_steps, double *restrict depth) {
    const double fp = rig[3], cxp = rig[4];
    const double *R = rig + 5, *t = rig + 14, *d = rig + 17;
    double ideal[TL], z[TL];
    for (int l = 0; l < TL; l++) ideal[l] = u[l];
    if (distorted) {
        double target[TL], x[TL], y[TL];
        for (int l = 0; l < TL; l++) target[l] = (u[l] - cxp) / fp;
        undistort_lanes(target, ry, d, newton_steps, x);
        for (int l = 0; l < TL; l++) ideal[l] = fabs(u[l]) <= DBL_MAX ? x[l] * fp + cxp : NAN;
        /* a rig that is not rectified: the projector row where the point lands, from the depth
         * so far; stopped, like the Newton steps, once a step changes no lane */
        for (int64_t s = 0; s < refine_steps; s++) {
            plane_depth_lanes(ideal, rx, ry, fp, cxp, R, t, z);
            for (int l = 0; l < TL; l++) {
                const double x0 = z[l] * rx[l] - t[0], x1 = z[l] * ry[l] - t[1], x2 = z[l] - t[2];
                /* R^T (X - t): the projector-frame y and z, term by term */
                const double yp = x0 * R[1] + x1 * R[4] + x2 * R[7];
                const double zp = x0 * R[2] + x1 * R[5] + x2 * R[8];
                const double yr = yp / zp;
                y[l] = fabs(yr) <= DBL_MAX ? yr : ry[l];
            }
            undistort_lanes(target, y, d, newton_steps, x);
            int moved = 0;
            for (int l = 0; l < TL; l++) {
                const double next = fabs(u[l]) <= DBL_MAX ? x[l] * fp + cxp : NAN;
                moved |= !settled(next, ideal[l]);
                ideal[l] = next;
            }
            if (!moved) break;
        }
    }
    plane_depth_lanes(ideal, rx, ry, fp, cxp, R, t, z);
    for (int l = 0; l < TL; l++) depth[l] = (fabs(z[l]) <= DBL_MAX && z[l] > 0.0) ? z[l] : NAN;
}

/* simbench.rig.triangulate_columns for n camera pixels: column (DMD columns, NaN = unknown) in,
 * camera z out (NaN where the ray is parallel to the plane or meets it behind).  The pixels are
 * rows[j], cols[j], or with rows NULL the grid of rows row0.. and columns 0..grid_w-1 in row-major
 * order.  rig: f_c, cx_c, cy_c, f_p, cx_p, R (row-major 3x3), t (3), k1, k2, p1, p2, k3 of the
 * projector.  distorted: undo the projector's lens (newton_steps Newton steps) on the projector
 * row of the camera row (exact in a rectified rig), then refine_steps times on the row where the
 * point lands (any other rig).  Unknown columns give NaN without being computed (every step
 * keeps a NaN); the others go TL at a time. */
void triangulate_columns(int64_t n, const double *restrict column, const double *restrict rows,
                         const double *restrict cols, int64_t row0, int64_t grid_w, const double *restrict rig,
                         int64_t distorted, int64_t newton_steps, int64_t refine_steps, double *restrict depth) {
    const double fc = rig[0], cxc = rig[1], cyc = rig[2];
    double u[TL], rx[TL], ry[TL], z[TL];
    int64_t at[TL];
    int m = 0;
    for (int64_t j = 0, gx = 0, gy = row0; j < n; j++) {
        if (isnan(column[j])) {
            depth[j] = NAN;
        } else {
            u[m] = column[j];
            rx[m] = ((rows == NULL ? (double)gx : cols[j]) - cxc) / fc;
            ry[m] = ((rows == NULL ? (double)gy : rows[j]) - cyc) / fc;
            at[m++] = j;
        }
        if (++gx == grid_w) gx = 0, gy++;
        if (m == TL || (j == n - 1 && m > 0)) {
            for (int l = m; l < TL; l++) u[l] = NAN, rx[l] = ry[l] = 0.0; /* idle lanes */
            triangulate_lanes(u, rx, ry, rig, distorted, newton_steps, refine_steps, z);
            for (int l = 0; l < m; l++) depth[at[l]] = z[l];
            m = 0;
        }
    }
}

/* The decoder's last stages for a band in one pass per row (simbench.decode.pipeline), the same
 * bits as the steps it fuses (tests/test_kernels.py):
 *   1. the stripe position W of each pixel (labels into stripe_position, -1 without a stripe)
 *      and its projector column and stripe index (absolute_column, paper Eq. 14);
 *   2. depth: with a table, reference matching (match_reference + depth_from_disparity, paper
 *      Sec. 5.4) and the columns the reference row does not show triangulated; without (NULL),
 *      every column triangulated (triangulate_columns: rig, distorted, newton_steps and
 *      refine_steps as it takes them);
 *   3. the outputs: valid = zmin <= depth <= zmax (float32), and depth, confidence (the fringe
 *      amplitude), column and stripe index where valid, NaN / 0 / NaN / -1 elsewhere.
 * Pixels to triangulate wait in lanes of TL (across rows) and get their outputs when the lanes
 * are full.  scratch: 4 w floats. */
static inline void emit(int64_t j, float z, float amplitude, float column, int32_t index, float zmin, float zmax,
                        float *restrict depth_out, uint8_t *restrict valid_out, float *restrict conf_out,
                        float *restrict col_out, int32_t *restrict index_out) {
    const int v = (z >= zmin) & (z <= zmax);
    valid_out[j] = (uint8_t)v;
    depth_out[j] = v ? z : NAN;
    conf_out[j] = v ? amplitude : 0.0f;
    col_out[j] = v ? column : NAN;
    index_out[j] = v ? index : -1;
}

typedef struct {
    double u[TL], rx[TL], ry[TL];
    int64_t at[TL];
    int32_t index[TL];
    int m;
} Pending;

static void flush(Pending *q, const float *restrict amplitude, const double *restrict rig, int64_t distorted,
                  int64_t newton_steps, int64_t refine_steps, float zmin, float zmax, float *restrict depth_out,
                  uint8_t *restrict valid_out, float *restrict conf_out, float *restrict col_out,
                  int32_t *restrict index_out) {
    if (q->m == 0) return;
    double z[TL];
    for (int l = q->m; l < TL; l++) q->u[l] = NAN, q->rx[l] = q->ry[l] = 0.0; /* idle lanes */
    triangulate_lanes(q->u, q->rx, q->ry, rig, distorted, newton_steps, refine_steps, z);
    for (int l = 0; l < q->m; l++) {
        const int64_t j = q->at[l];
        /* u holds the float32 column exactly */
        emit(j, (float)z[l], amplitude[j], (float)q->u[l], q->index[l], zmin, zmax, depth_out, valid_out, conf_out,
             col_out, index_out);
    }
    q->m = 0;
}

/* index[x] = stripe_position[labels[x]], -1 without a stripe; scalar: the vectorised form is a
 * gather, slower than scalar loads on the AMD cores measured (Zen 4). */
ROW_FN __attribute__((optimize("no-tree-vectorize"))) void positions_of_row(int64_t w, const int32_t *restrict labels,
                                                                           const int32_t *restrict stripe_position,
                                                                           int32_t *restrict index) {
    for (int64_t x = 0; x < w; x++) index[x] = labels[x] >= 0 ? stripe_position[labels[x]] : -1;
}

ROW_FN void columns_of_row(int64_t w, const int32_t *restrict labels, const int32_t *restrict stripe_position,
                           const float *restrict wrapped, const float *restrict expected, float t, float span,
                           int64_t cycle, float *restrict column, int32_t *restrict index) {
    const float scale = t / TWO_PI_F;
    /* the look-up first, into index: the column loop then vectorises */
    positions_of_row(w, labels, stripe_position, index);
    for (int64_t x = 0; x < w; x++)
        column_of_pixel(index[x], wrapped[x], expected[x], t, scale, span, (uint32_t)cycle, column + x, index + x);
}

/* depth by reference matching of one row; beyond: the reference row does not show the column */
ROW_FN void reference_depth_row(int64_t w, const float *restrict table_row, int64_t width,
                                const float *restrict column, float inv_z0, float inv_fb, float *restrict depth,
                                uint8_t *restrict beyond) {
    for (int64_t x = 0; x < w; x++) depth[x] = lookup(table_row, width, column[x]); /* x_ref for now */
    for (int32_t x = 0; x < (int32_t)w; x++) {
        const float xr = depth[x];
        const float d = (float)x - xr;
        const float zz = 1.0f / (inv_z0 + d * inv_fb);
        depth[x] = zz > 0.0f ? zz : NAN;
        beyond[x] = isnan(xr) & (fabsf(column[x]) <= FLT_MAX);
    }
}

/* calibrated mode: no depth yet; every known column is triangulated */
ROW_FN void unknown_depth_row(int64_t w, const float *restrict column, float *restrict depth, uint8_t *restrict beyond) {
    for (int64_t x = 0; x < w; x++) {
        depth[x] = NAN;
        beyond[x] = !isnan(column[x]);
    }
}

ROW_FN void emit_row(int64_t w, const float *restrict depth, const float *restrict amplitude,
                     const float *restrict column, const int32_t *restrict index, float zmin, float zmax,
                     float *restrict depth_out, uint8_t *restrict valid_out, float *restrict conf_out,
                     float *restrict col_out, int32_t *restrict index_out) {
    for (int64_t x = 0; x < w; x++)
        emit(x, depth[x], amplitude[x], column[x], index[x], zmin, zmax, depth_out, valid_out, conf_out, col_out,
             index_out);
}

void decode_tail(int64_t h, int64_t w, int64_t row0, const int32_t *restrict labels,
                 const int32_t *restrict stripe_position, const float *restrict wrapped,
                 const float *restrict expected, const float *restrict amplitude, float t, float span, int64_t cycle,
                 int64_t tw, const float *restrict table, float inv_z0, float inv_fb, const double *restrict rig,
                 int64_t distorted, int64_t newton_steps, int64_t refine_steps, float zmin, float zmax,
                 float *restrict scratch, float *restrict depth_out, uint8_t *restrict valid_out,
                 float *restrict conf_out, float *restrict col_out, int32_t *restrict index_out) {
    const double fc = rig[0], cxc = rig[1], cyc = rig[2];
    float *column = scratch, *depth = scratch + w;
    int32_t *index = (int32_t *)(scratch + 2 * w);
    uint8_t *beyond = (uint8_t *)(scratch + 3 * w);
    Pending q;
    q.m = 0;
    for (int64_t y = 0; y < h; y++) {
        const int64_t o = y * w;
        columns_of_row(w, labels + o, stripe_position, wrapped + o, expected + o, t, span, cycle, column, index);
        if (table != NULL)
            reference_depth_row(w, table + y * tw, tw - 2, column, inv_z0, inv_fb, depth, beyond);
        else
            unknown_depth_row(w, column, depth, beyond);
        /* the pixels to triangulate get their outputs again when their lanes are done */
        emit_row(w, depth, amplitude + o, column, index, zmin, zmax, depth_out + o, valid_out + o, conf_out + o,
                 col_out + o, index_out + o);
        const double ry = ((double)(row0 + y) - cyc) / fc;
        for (int64_t x = 0; x < w; x++) {
            uint64_t eight;
            if (x + 8 <= w && (memcpy(&eight, beyond + x, 8), eight == 0)) {
                x += 7; /* eight pixels at a time through the (long) runs with none */
                continue;
            }
            if (!beyond[x]) continue;
            q.u[q.m] = column[x];
            q.rx[q.m] = ((double)x - cxc) / fc;
            q.ry[q.m] = ry;
            q.at[q.m] = o + x;
            q.index[q.m] = index[x];
            if (++q.m == TL)
                flush(&q, amplitude, rig, distorted, newton_steps, refine_steps, zmin, zmax, depth_out, valid_out,
                      conf_out, col_out, index_out);
        }
    }
    flush(&q, amplitude, rig, distorted, newton_steps, refine_steps, zmin, zmax, depth_out, valid_out, conf_out,
          col_out, index_out);
}

/* Mean of `width` values along each row of an (h, w) float32 image, the window centred on the
 * pixel but kept within [s0, s1) (simbench.decode.color._bounded_mean): n = min(width, s1 - s0),
 * start = min(max(x - width / 2, s0), s1 - n), prefix sums in double taken from the row's start
 * in order, as numpy's cumsum(dtype=float64); `square` sums the squares (the value widened to
 * double first).  cs: scratch of w + 1 doubles. */
void bounded_mean(int64_t h, int64_t w, const float *restrict values, const int64_t *restrict s0,
                  const int64_t *restrict s1, int64_t width, int64_t square, double *restrict cs,
                  double *restrict out) {
    for (int64_t y = 0; y < h; y++) {
        const float *v = values + y * w;
        const int64_t *a = s0 + y * w, *b = s1 + y * w;
        double *o = out + y * w;
        cs[0] = 0.0;
        for (int64_t x = 0; x < w; x++) {
            const double d = (double)v[x];
            cs[x + 1] = cs[x] + (square ? d * d : d);
        }
        for (int64_t x = 0; x < w; x++) {
            const int64_t span = b[x] - a[x];
            const int64_t n = width < span ? width : span;
            int64_t start = x - width / 2;
            if (start < a[x]) start = a[x];
            if (start > b[x] - n) start = b[x] - n;
            o[x] = (cs[start + n] - cs[start]) / (double)n;
        }
    }
}

/* The channel normalisation's per-row work holds, per pixel, eight floats: the three channels'
 * running minima and a fourth lane, then their maxima and a fourth lane (two vectors). */
#define EXT 8
typedef float v4f_n __attribute__((vector_size(16)));
typedef double v4d_n __attribute__((vector_size(32)));
static inline v4d_n ld4d(const float *p) {
    v4f_n f;
    memcpy(&f, p, sizeof f);
    return __builtin_convertvector(f, v4d_n);
}

/* A pixel's three channels and the next value (any) as one vector, and the lane-wise minimum and
 * maximum of two such vectors with the scalar forms' selection, a < b ? a : b and a > b ? a : b
 * (the same value for any finite input, the same operand kept on a tie). */
typedef int32_t v4i_n __attribute__((vector_size(16)));
static inline v4f_n ld4f(const float *p) {
    v4f_n f;
    memcpy(&f, p, sizeof f);
    return f;
}
static inline void st4f(float *p, v4f_n v) { memcpy(p, &v, sizeof v); }
static inline v4f_n vmin4(v4f_n a, v4f_n b) {
    const v4i_n m = a < b;
    return (v4f_n)(((v4i_n)a & m) | ((v4i_n)b & ~m));
}
static inline v4f_n vmax4(v4f_n a, v4f_n b) {
    const v4i_n m = a > b;
    return (v4f_n)(((v4i_n)a & m) | ((v4i_n)b & ~m));
}

/* Running extrema of k = 2 r + 1 values along a row of w pixels of three interleaved channels,
 * the row's ends replicated (cv2.erode / cv2.dilate with a 1 x k kernel and BORDER_REPLICATE: the
 * window clipped to the row holds the same values), by van Herk / Gil-Werman: over the padded
 * row of n = w + 2 r pixels, per block of k pixels the running extremum from the block's start
 * (g) and from its end (e), then the window [i, i + k) is e[i] against g[i + k - 1].  Exact for
 * finite values (a minimum is a minimum in any order).  A pixel's three channels are the first
 * three lanes of a vector (the fourth, the next value, is carried along and dropped).  pad: n x 3
 * + 1 floats; g, e: n x EXT; ext: w x EXT (the three minima and 0, then the three maxima and 0). */
ROW_FN void running_extrema(int64_t w, int64_t r, const float *restrict v, float *restrict pad, float *restrict g,
                            float *restrict e, float *restrict ext) {
    const int64_t k = 2 * r + 1, n = w + 2 * r;
    for (int64_t i = 0; i < r; i++)
        for (int c = 0; c < 3; c++) {
            pad[3 * i + c] = v[c];
            pad[3 * (r + w + i) + c] = v[3 * (w - 1) + c];
        }
    memcpy(pad + 3 * r, v, (size_t)(3 * w) * sizeof(float));
    pad[3 * n] = 0.0f; /* the last pixel's fourth lane */
    for (int64_t b = 0; b < n; b += k) {
        const int64_t end = b + k < n ? b + k : n;
        v4f_n lo = ld4f(pad + 3 * b), hi = lo;
        for (int64_t i = b; i < end; i++) {
            const v4f_n p = ld4f(pad + 3 * i);
            lo = vmin4(p, lo), hi = vmax4(p, hi);
            st4f(g + EXT * i, lo), st4f(g + EXT * i + 4, hi);
        }
        lo = hi = ld4f(pad + 3 * (end - 1));
        for (int64_t i = end - 1; i >= b; i--) {
            const v4f_n p = ld4f(pad + 3 * i);
            lo = vmin4(p, lo), hi = vmax4(p, hi);
            st4f(e + EXT * i, lo), st4f(e + EXT * i + 4, hi);
        }
    }
    const v4i_n m = {-1, -1, -1, 0}; /* the fourth lane to 0 */
    for (int64_t x = 0; x < w; x++) {
        const float *a = e + EXT * x, *b = g + EXT * (x + k - 1);
        st4f(ext + EXT * x, (v4f_n)((v4i_n)vmin4(ld4f(b), ld4f(a)) & m));
        st4f(ext + EXT * x + 4, (v4f_n)((v4i_n)vmax4(ld4f(b + 4), ld4f(a + 4)) & m));
    }
}

/* The box means of a row's running extrema (w x EXT) over k = 2 r + 1 pixels, the ends
 * replicated, as cv2.blur does for float32: a double sum started over the first k padded values
 * in order, then s += (double)p[i + k] - (double)p[i], each mean (float)(s * (1.0 / k)) (for a
 * window of 3 or 5, OpenCV's RowSum adds the window afresh at every pixel, and a window of 1 is a
 * copy: so here), into lo
 * and hi (w x 3 each).  A pixel's chains are the lanes of two vectors: lane-wise IEEE double
 * arithmetic, the same bits. */
ROW_FN void box_means(int64_t w, int64_t r, const float *restrict ext, float *restrict lo, float *restrict hi) {
    const int64_t k = 2 * r + 1;
    const double sc = 1.0 / (double)k;
    const v4d_n scale = {sc, sc, sc, sc};
    v4d_n a = {0, 0, 0, 0}, b = {0, 0, 0, 0};
    for (int64_t i = 0; i < k; i++) {
        /* the padded row p[i] = ext[clamp(i - r, 0, w - 1)] */
        int64_t x = i - r;
        x = x < 0 ? 0 : (x > w - 1 ? w - 1 : x);
        a += ld4d(ext + EXT * x);
        b += ld4d(ext + EXT * x + 4);
    }
    const int direct = k <= 5; /* k = 1, 3, 5 */
    for (int64_t x = 0; x < w; x++) {
        if (direct) {
            /* OpenCV adds a window of 3 or 5 afresh at every pixel, from its first value (its RowSum),
             * and copies for a window of 1 */
            const int64_t x0 = x - r < 0 ? 0 : x - r;
            a = ld4d(ext + EXT * x0);
            b = ld4d(ext + EXT * x0 + 4);
            for (int64_t i = 1; i < k; i++) {
                const int64_t xi = x - r + i < 0 ? 0 : (x - r + i > w - 1 ? w - 1 : x - r + i);
                a += ld4d(ext + EXT * xi);
                b += ld4d(ext + EXT * xi + 4);
            }
        }
        const v4f_n fa = __builtin_convertvector(a * scale, v4f_n), fb = __builtin_convertvector(b * scale, v4f_n);
        lo[3 * x] = fa[0], lo[3 * x + 1] = fa[1], lo[3 * x + 2] = fa[2];
        hi[3 * x] = fb[0], hi[3 * x + 1] = fb[1], hi[3 * x + 2] = fb[2];
        if (!direct && x + 1 < w) {
            const int64_t in = x + 1 + r < w - 1 ? x + 1 + r : w - 1, out = x - r > 0 ? x - r : 0;
            a += ld4d(ext + EXT * in) - ld4d(ext + EXT * out);
            b += ld4d(ext + EXT * in + 4) - ld4d(ext + EXT * out + 4);
        }
    }
}

/* The colour-robust decoder's channel normalisation (simbench.decode.color.normalize_channels)
 * of an (h, w, 3) float32 image: per row and channel the running minimum and maximum over
 * k = 2 r + 1 pixels (running_extrema), each box-averaged over k pixels (box_means); then
 * span = mean_max - mean_min, out = (v - mean_min) / span where span >= min_span, else 0, and
 * span_out (NULL: not written) the span there, else 0; with a per-pixel gain ((h, w); NULL: none)
 * v is each channel times it.  clamp_ends (with w > 4 r): within 2 r pixels of the row's ends the
 * means are those of pixel 2 r (w - 1 - 2 r), the first (last) whose mean reads only extrema of
 * whole windows - the window moved inward instead of cut by the row's end.
 * scratch: normalize_scratch_floats(w, r) floats. */
int64_t normalize_scratch_floats(int64_t w, int64_t r) { return (3 + 2 * EXT) * (w + 2 * r) + 1 + (EXT + 9) * w; }

void normalize_channels(int64_t h, int64_t w, const float *restrict rgb, const float *restrict gain, int64_t r,
                        float min_span, int64_t clamp_ends, float *restrict out, float *restrict span_out,
                        float *restrict scratch) {
    const int64_t n = w + 2 * r, m = 3 * w;
    float *pad = scratch, *g = pad + 3 * n + 1, *e = g + EXT * n, *ext = e + EXT * n;
    float *restrict lo = ext + EXT * w, *restrict hi = lo + m, *restrict scaled = hi + m;
    for (int64_t y = 0; y < h; y++) {
        const float *v = rgb + y * m; /* not restrict: it may point at scaled, written just before */
        if (gain) {
            /* each channel times the pixel's gain first, in float32 (numpy's rgb * gain[..., None]) */
            const float *restrict gy = gain + y * w;
            for (int64_t x = 0; x < w; x++)
                for (int c = 0; c < 3; c++) scaled[3 * x + c] = v[3 * x + c] * gy[x];
            v = scaled;
        }
        running_extrema(w, r, v, pad, g, e, ext);
        box_means(w, r, ext, lo, hi);
        if (clamp_ends && w > 4 * r) {
            const int64_t q = 2 * r;
            for (int64_t x = 0; x < q; x++)
                for (int c = 0; c < 3; c++) {
                    lo[3 * x + c] = lo[3 * q + c], hi[3 * x + c] = hi[3 * q + c];
                    lo[3 * (w - 1 - x) + c] = lo[3 * (w - 1 - q) + c];
                    hi[3 * (w - 1 - x) + c] = hi[3 * (w - 1 - q) + c];
                }
        }
        float *restrict o = out + y * m;
        for (int64_t i = 0; i < m; i++) {
            const float span = hi[i] - lo[i];
            o[i] = span >= min_span ? (v[i] - lo[i]) / span : 0.0f;
        }
        if (span_out) {
            float *restrict so = span_out + y * m;
            for (int64_t i = 0; i < m; i++) {
                const float span = hi[i] - lo[i];
                so[i] = span >= min_span ? span : 0.0f;
            }
        }
    }
}

/* The albedo proxy of simbench.decode.color.albedo_gain, per pixel from the unmixed capture and
 * its local ranges k (both (n, 3) float32), in the float32 operations of the numpy form: a
 * channel counts where k >= 0.1 k_max and k > 0; norm = max(v, 0) / k there; the code pair's
 * weight 1 / (1 / k_R^2 + 1 / k_G^2) where both count, the fringe's k_B^2 where it counts;
 * proxy = (w_pair (norm_R + norm_G) + w_fringe norm_B) / (w_pair + w_fringe) where that sum is
 * > 0 (defined = 1), else 0. */
void albedo_proxy(int64_t n, const float *restrict rgb, const float *restrict k, float share,
                  float *restrict proxy, uint8_t *restrict defined) {
    const float tiny = (float)1e-12;
    for (int64_t i = 0; i < n; i++) {
        const float *v = rgb + 3 * i, *s = k + 3 * i;
        float m = s[0] > s[1] ? s[0] : s[1];
        m = m > s[2] ? m : s[2];
        const float thr = share * m;
        float norm[3], inv2[3];
        int has[3];
        for (int c = 0; c < 3; c++) {
            has[c] = (s[c] >= thr) & (s[c] > 0.0f);
            const float pos = v[c] > 0.0f ? v[c] : 0.0f, kk = s[c] > tiny ? s[c] : tiny;
            norm[c] = has[c] ? pos / s[c] : 0.0f;
            inv2[c] = has[c] ? 1.0f / (kk * kk) : 0.0f;
        }
        const int both = has[0] & has[1];
        const float w_pair = both ? 1.0f / (inv2[0] + inv2[1]) : 0.0f;
        const float w_fringe = has[2] ? s[2] * s[2] : 0.0f;
        const float total = w_pair + w_fringe;
        proxy[i] = total > 0.0f ? (w_pair * (norm[0] + norm[1]) + w_fringe * norm[2]) / total : 0.0f;
        defined[i] = total > 0.0f;
    }
}

/* Albedo steps along the rows of an (h, w) proxy (simbench.decode.color.albedo_edges after its
 * row average): per row, prefix sums in double over the row padded by m = 2 t values each side
 * (its ends replicated; numpy's cumsum order), the means of the m values left and right of each
 * pixel, a = left + eps, b = right + eps with eps = 1e-3 + 0.02 max(left, right), the step's
 * ratio q = max(a, b) / min(a, b); a cut where q > ratio_min and q is the largest within t
 * pixels either side (ends replicated), never within m - 1 columns of the left end or m of the
 * right.  Each cut is then moved to the column within t of it (inside the same limits) where the
 * ratio of the t values either side is the largest (the first of equals): a segment narrower than
 * m lies wholly inside one of the m-wide windows along a plateau of q, and only the narrower
 * windows' ratio peaks at its edge.  Beside each cut so placed, on its darker side between
 * t / 2 + 1 and t columns away, the far edge of a dark strip narrower than a period (a seam
 * between two faces, a thin shadow or line: the step test's maximum rule keeps one cut of
 * such a strip) is cut too: the column there whose narrow ratio rises back towards the light
 * (the other way than the cut's), exceeds strip_min and is the largest within t / 2 either side
 * (the first such of the largest).  The ratio in double is compared directly (a logarithm would
 * be monotone in it and add only its last-bit differences between machines' libraries).  cs:
 * w + 2 m + 1 doubles, q: w + 2 t doubles, pos: w int64 of scratch. */
static inline double step_ratio(const double *cs, int64_t c, int64_t k) {
    /* the ratio of the means of the k values left (ending at c - 1 of the padded row) and right */
    const double left = (cs[c] - cs[c - k]) / (double)k;
    const double right = (cs[c + k] - cs[c]) / (double)k;
    const double eps = 1e-3 + 0.02 * (left > right ? left : right);
    const double a = left + eps, b = right + eps;
    return a > b ? a / b : b / a;
}

static inline int rises(const double *cs, int64_t c, int64_t k) {
    /* the mean of the k values right of the step over those left of it is the larger */
    return cs[c + k] - cs[c] > cs[c] - cs[c - k];
}

void albedo_edges(int64_t h, int64_t w, const float *restrict g, int64_t t, double ratio_min, double strip_min,
                  double *restrict cs, double *restrict q, int64_t *restrict pos, uint8_t *restrict cuts) {
    const int64_t m = 2 * t, np_ = w + 2 * m;
    for (int64_t y = 0; y < h; y++) {
        const float *row = g + y * w;
        uint8_t *cut = cuts + y * w;
        cs[0] = 0.0;
        for (int64_t i = 0; i < np_; i++) {
            int64_t x = i - m;
            x = x < 0 ? 0 : (x > w - 1 ? w - 1 : x);
            cs[i + 1] = cs[i] + (double)row[x];
        }
        double *qq = q + t; /* q[-t .. w + t) with the ends replicated */
        for (int64_t x = 0; x < w; x++) qq[x] = step_ratio(cs, x + m + 1, m);
        for (int64_t i = 0; i < t; i++) {
            q[i] = qq[0];
            qq[w + i] = qq[w - 1];
        }
        for (int64_t x = 0; x < w; x++) cut[x] = 0;
        const int64_t x1 = w - m;
        int64_t n = 0;
        for (int64_t x = m - 1; x < x1; x++) {
            const double v = qq[x];
            if (!(v > ratio_min)) continue;
            int top = 1;
            for (int64_t j = x - t; j <= x + t; j++)
                if (qq[j] > v) {
                    top = 0;
                    break;
                }
            if (top) pos[n++] = x;
        }
        for (int64_t k = 0; k < n; k++) {
            const int64_t j0 = pos[k] - t < m - 1 ? m - 1 : pos[k] - t;
            const int64_t j1 = pos[k] + t > x1 - 1 ? x1 - 1 : pos[k] + t;
            int64_t best = j0;
            double top = -1.0;
            for (int64_t j = j0; j <= j1; j++) {
                const double v = step_ratio(cs, j + m + 1, t);
                if (v > top) {
                    top = v;
                    best = j;
                }
            }
            cut[best] = 1;
            /* the strip's far edge: on the darker side, rising back the other way */
            const int up = rises(cs, best + m + 1, t);
            const int64_t half = t / 2;
            const int64_t a0 = up ? best - t : best + half + 1, a1 = up ? best - half - 1 : best + t;
            int64_t far = -1;
            double ftop = strip_min;
            for (int64_t j = a0 < m - 1 ? m - 1 : a0; j <= (a1 > x1 - 1 ? x1 - 1 : a1); j++) {
                if (rises(cs, j + m + 1, t) == up) continue;
                const double v = step_ratio(cs, j + m + 1, t);
                if (!(v > ftop)) continue;
                int peak = 1;
                for (int64_t i = j - half; i <= j + half && peak; i++)
                    if (i >= 0 && i < w && step_ratio(cs, i + m + 1, t) > v) peak = 0;
                if (peak) {
                    ftop = v;
                    far = j;
                }
            }
            if (far >= 0) cut[far] = 1;
        }
    }
}

static inline v4d_n ld3d(const float *p) {
    const v4f_n f = {p[0], p[1], p[2], 0.0f};
    return __builtin_convertvector(f, v4d_n);
}

/* The noise level of simbench.decode.color.overlay_weights: each channel of an (h, w, 3) float32
 * image averaged over k = 2 r + 1 pixels along its row (cv2.blur's float32 box filter: the ends
 * replicated, double running sums, (float)(s * (1.0 / k))), then max(mean, 0) + floor.  A
 * pixel's three sums are the lanes of one vector (lane-wise IEEE double, the same bits). */
void box_level(int64_t h, int64_t w, const float *restrict raw, int64_t r, float floor_,
               float *restrict level) {
    const int64_t k = 2 * r + 1;
    const double sc = 1.0 / (double)k;
    const v4d_n scale = {sc, sc, sc, sc};
    const int direct = k <= 5; /* as box_means */
    for (int64_t y = 0; y < h; y++) {
        const float *row = raw + y * w * 3;
        float *restrict out = level + y * w * 3;
        v4d_n s = {0, 0, 0, 0};
        for (int64_t i = 0; i < k; i++) {
            int64_t x = i - r;
            x = x < 0 ? 0 : (x > w - 1 ? w - 1 : x);
            s += ld3d(row + 3 * x);
        }
        for (int64_t x = 0; x < w; x++) {
            if (direct) {
                s = ld3d(row + 3 * (x - r < 0 ? 0 : x - r));
                for (int64_t i = 1; i < k; i++) {
                    const int64_t xi = x - r + i < 0 ? 0 : (x - r + i > w - 1 ? w - 1 : x - r + i);
                    s += ld3d(row + 3 * xi);
                }
            }
            const v4f_n m = __builtin_convertvector(s * scale, v4f_n);
            for (int c = 0; c < 3; c++) out[3 * x + c] = (m[c] > 0.0f ? m[c] : 0.0f) + floor_;
            if (!direct && x + 1 < w) {
                const int64_t in = x + 1 + r < w - 1 ? x + 1 + r : w - 1, gone = x - r > 0 ? x - r : 0;
                s += ld3d(row + 3 * in) - ld3d(row + 3 * gone);
            }
        }
    }
}

/* The inverse noise variances of simbench.decode.color.overlay_weights from the unmixed
 * channels' variances var and their local ranges span ((n, 3) float32 each): rel = var /
 * max(span, 1e-12)^2 where span > 0, else inf; w_code = 1 / (rel_R + rel_G), w_fringe =
 * 1 / rel_B, in float32. */
void noise_weights(int64_t n, const float *restrict var, const float *restrict span, float *restrict w_code,
                   float *restrict w_fringe) {
    const float tiny = (float)1e-12;
    for (int64_t i = 0; i < n; i++) {
        const float s0 = span[3 * i], s1 = span[3 * i + 1], s2 = span[3 * i + 2];
        const float m0 = s0 > tiny ? s0 : tiny, m1 = s1 > tiny ? s1 : tiny, m2 = s2 > tiny ? s2 : tiny;
        const float r0 = var[3 * i] / (m0 * m0), r1 = var[3 * i + 1] / (m1 * m1), r2 = var[3 * i + 2] / (m2 * m2);
        const float rel0 = s0 > 0.0f ? r0 : INFINITY, rel1 = s1 > 0.0f ? r1 : INFINITY;
        const float rel2 = s2 > 0.0f ? r2 : INFINITY;
        w_code[i] = 1.0f / (rel0 + rel1);
        w_fringe[i] = 1.0f / rel2;
    }
}

/* The colour-robust decoder's fringe and code from normalised channels rgb and their ranges span
 * ((n, 3) float32 each, R = code 1, G = code 0, B = fringe): intensity = (w_code (R + G) +
 * w_fringe B) / (w_code + w_fringe) where that sum is > 0, else 0 (simbench.decode.phase's
 * "weighted" mode; NULL weights: not written), and code = simbench.decode.color.
 * normalized_color_code (a code channel without range compared with half the fringe, 0.25
 * where the fringe has none either). */
void robust_fringe_code(int64_t n, const float *restrict rgb, const float *restrict span,
                        const float *restrict w_code, const float *restrict w_fringe, float *restrict intensity,
                        uint8_t *restrict code) {
    if (w_code)
        for (int64_t i = 0; i < n; i++) {
            const float *v = rgb + 3 * i;
            const float num = w_code[i] * (v[0] + v[1]) + w_fringe[i] * v[2], den = w_code[i] + w_fringe[i];
            intensity[i] = den > 0.0f ? num / den : 0.0f;
        }
    if (code)
        for (int64_t i = 0; i < n; i++) {
            const float *v = rgb + 3 * i, *s = span + 3 * i;
            const int has_r = s[0] > 0.0f, has_g = s[1] > 0.0f;
            const float half = s[2] > 0.0f ? 0.5f * v[2] : 0.25f;
            const float r = (has_r | !has_g) ? v[0] : half, g = (has_g | !has_r) ? v[1] : half;
            code[i] = r >= g;
        }
}

/* The column flattening's segments raised into its gain (simbench.decode.color.column_albedo_gain):
 * for segment i, rows y0[i] + sign r, r = 0 .. len[i] - 1, of column x0[i], gain = max(gain, g[i])
 * as np.maximum.at does it (a NaN on either side wins; of +0.0 and -0.0 the second, as numpy 2 does);
 * gain (h, w) float32.  The rows lie
 * inside the image (checked by the wrapper). */
void segments_max(int64_t n, int64_t w, const int64_t *restrict y0, const int64_t *restrict x0,
                  const int64_t *restrict len, const float *restrict g, int64_t sign, float *restrict gain) {
    for (int64_t i = 0; i < n; i++) {
        const float v = g[i];
        for (int64_t r = 0; r < len[i]; r++) {
            float *p = gain + (y0[i] + sign * r) * w + x0[i];
            const float a = *p;
            /* np.maximum's: NaN either side wins, and a tie (+0.0 against -0.0) takes the second */
            *p = (a != a) ? a : (a > v ? a : v);
        }
    }
}

/* A phase wrapped to [-pi, pi) as simbench.decode.phase._wrap does it in float32 numpy:
 * a - 2 pi rint(a / 2 pi), then pi itself folded to -pi. */
static inline float wrap_f(float a) {
    const float r = a - TWO_PI_F * rintf(a / TWO_PI_F);
    return r >= PI_F ? r - TWO_PI_F : r;
}

/* The window-centroid correction's rate sums (simbench.decode.phase.centroid_corrected, the bits
 * of its numpy form): per row of ps ((nr, wb) float32, the widest fit's phase) the step
 * wrap(ps[x + 1] - ps[x - 1]) / 2 at x = 1 .. wb - 2, counted where cr (uint8) holds at x - 1, x,
 * x + 1 and the step is finite, in fixed point rint(step 2^20) (int64); sq and sn ((nr, wb + 1)
 * int64) the prefix sums of those steps and of their count, from 0. */
void centroid_rate_sums(int64_t nr, int64_t wb, const float *restrict ps, const uint8_t *restrict cr,
                        float scale, int64_t *restrict sq, int64_t *restrict sn) {
    for (int64_t y = 0; y < nr; y++) {
        const float *p = ps + y * wb;
        const uint8_t *c = cr + y * wb;
        int64_t *q = sq + y * (wb + 1), *n = sn + y * (wb + 1);
        q[0] = n[0] = 0;
        for (int64_t x = 0; x < wb; x++) {
            int64_t v = 0, g = 0;
            if (x >= 1 && x < wb - 1 && c[x - 1] && c[x] && c[x + 1]) {
                const float step = wrap_f(p[x + 1] - p[x - 1]) * 0.5f;
                if (isfinite(step)) {
                    v = (int64_t)rintf(step * scale);
                    g = 1;
                }
            }
            q[x + 1] = q[x] + v;
            n[x + 1] = n[x] + g;
        }
    }
}

/* The correction itself at the block's pixels `need` ((nb, wb) uint8; dx their window centre's
 * offset, (nb, wb) float32): the mean step over [x, x + reach] (dx > 0, cut at the block's right
 * end) or [x - reach, x] (cut at 0) from the rate sums of row row_of[y] (sq, sn: (nr, wb + 1)),
 * as double over 2^20 and a count of at least 1, to float32; the bias (rate - omega) dx where a
 * step was counted, else 0; out[y0 + y, a + x] = wrap(psi[y0 + y, a + x] - bias) (psi, out: (h, w)
 * float32).  The bits of the numpy form. */
void centroid_apply(int64_t nb, int64_t wb, int64_t w, const uint8_t *restrict need, const float *restrict dx,
                    const int64_t *restrict row_of, const int64_t *restrict sq, const int64_t *restrict sn,
                    int64_t reach, float omega, double scale, int64_t y0, int64_t a, const float *restrict psi,
                    float *restrict out) {
    for (int64_t y = 0; y < nb; y++) {
        const int64_t r = row_of[y];
        if (r < 0) continue;
        const int64_t *q = sq + r * (wb + 1), *n = sn + r * (wb + 1);
        for (int64_t x = 0; x < wb; x++) {
            if (!need[y * wb + x]) continue;
            const float d = dx[y * wb + x];
            const int64_t lo = d > 0.0f ? x : (x - reach > 0 ? x - reach : 0);
            const int64_t hi = d > 0.0f ? (x + reach + 1 < wb ? x + reach + 1 : wb) : x + 1;
            const double sv = (double)(q[hi] - q[lo]) / scale;
            const int64_t sc = n[hi] - n[lo];
            const float rate = (float)(sv / (sc > 1 ? (double)sc : 1.0));
            const float bias = sc > 0 ? (rate - omega) * d : 0.0f;
            const int64_t i = (y0 + y) * w + a + x;
            out[i] = wrap_f(psi[i] - bias);
        }
    }
}

/* Each channel's mean over the k rows above and below n boundaries (simbench.decode.color.
 * column_albedo_gain's per-channel copy test): for boundary i between rows y = yb[i] and y + 1 at
 * column x = xs[i], up[3 i + c] = the sum in double of src rows y - 1, y - 2, .. y - k (in that
 * order, from 0.0) over k, dn[3 i + c] that of rows y + 2 .. y + k + 1 - the bits of numpy's
 * src[rows, cols, c].mean(axis=1, dtype=np.float64) over those rows, which sums k < 8 values in
 * order.  src: (h, w, 3) float32; the rows must lie inside it (checked by the wrapper). */
void column_side_means(int64_t n, int64_t w, const float *restrict src, const int64_t *restrict yb,
                       const int64_t *restrict xs, int64_t k, double *restrict up, double *restrict dn) {
    for (int64_t i = 0; i < n; i++) {
        const float *col = src + xs[i] * 3;
        for (int64_t c = 0; c < 3; c++) {
            /* from numpy's +0.0 identity: k values of -0.0 sum to +0.0 there (a review) */
            double su = 0.0, sd = 0.0;
            for (int64_t j = 1; j <= k; j++) {
                su += (double)col[(yb[i] - j) * w * 3 + c];
                sd += (double)col[(yb[i] + 1 + j) * w * 3 + c];
            }
            up[3 * i + c] = su / (double)k;
            dn[3 * i + c] = sd / (double)k;
        }
    }
}

/* The segments down (sign 1) or up (-1) the columns x0 from rows y0 (simbench.decode.color.
 * _column_segments, whose numpy form this replaces: the same results), walked one start at a time
 * instead of every start one row at a time: for r = 0 .. longest - 1 at row y = y0 + sign r (the
 * walk ends outside [0, h)), the boundary read is y's own (sign 1) or the one above it (-1,
 * clamped to 0; never a step at y = 0); a step there (stop) ends the walk, with length r + 1 where
 * it is a print edge (edge), or where frame marks its boundary (rim set too); otherwise the image's
 * last (sign 1) or first row ends it with length r + 1 and rim set.  end: -1 where no such end;
 * stop and edge (h + 1, w), frame h + 1, uint8. */
void column_segments(int64_t n, const int64_t *restrict y0, const int64_t *restrict x0, int64_t sign, int64_t h,
                     int64_t w, const uint8_t *restrict stop, const uint8_t *restrict edge,
                     const uint8_t *restrict frame, int64_t longest, int64_t *restrict end, uint8_t *restrict rim) {
    const int64_t last = sign == 1 ? h - 1 : 0;
    for (int64_t i = 0; i < n; i++) {
        end[i] = -1;
        rim[i] = 0;
        for (int64_t r = 0; r < longest; r++) {
            const int64_t y = y0[i] + sign * r;
            if (y < 0 || y >= h) break;
            const int64_t ya = sign == 1 ? y : (y > 1 ? y - 1 : 0);
            const int64_t a = ya * w + x0[i];
            if (stop[a] && (y > 0 || sign == 1)) {
                if (edge[a]) {
                    end[i] = r + 1;
                } else if (frame[ya]) {
                    end[i] = r + 1;
                    rim[i] = 1;
                }
                break;
            }
            if (y == last) {
                end[i] = r + 1;
                rim[i] = 1;
                break;
            }
        }
    }
}

/* Per group g < m of the n values v (the groups contiguous: grp non-decreasing), the
 * ((c - 1) / 2)-th of its c values in the order of numpy's lexsort((v, grp)): ascending, NaN
 * last, equal values (and NaNs) in their index order, so that the very element lexsort puts there
 * is found (a -0.0 beside a 0.0 included); out[g] = that value, NaN where the group is empty.  By
 * quickselect (median-of-three pivots) over the group's indices, O(c) on average instead of a
 * sort.  idx: n int64 of scratch. */
static inline int lex_less(const double *restrict v, int64_t i, int64_t j) {
    const double a = v[i], b = v[j];
    const int na = a != a, nb = b != b;
    if (na | nb) return na == nb ? i < j : nb;
    return a < b || (a == b && i < j);
}

static inline void swap_i64(int64_t *restrict a, int64_t i, int64_t j) {
    const int64_t t = a[i];
    a[i] = a[j];
    a[j] = t;
}

void group_median(int64_t n, const double *restrict v, const int64_t *restrict grp, int64_t m,
                  int64_t *restrict idx, double *restrict out) {
    for (int64_t g = 0; g < m; g++) out[g] = NAN;
    int64_t s = 0;
    while (s < n) {
        const int64_t g = grp[s];
        int64_t e = s;
        while (e < n && grp[e] == g) e++;
        for (int64_t i = s; i < e; i++) idx[i] = i;
        const int64_t k = s + (e - s - 1) / 2;
        int64_t lo = s, hi = e - 1;
        while (lo < hi) {
            const int64_t mid = lo + (hi - lo) / 2;
            if (lex_less(v, idx[mid], idx[lo])) swap_i64(idx, mid, lo);
            if (lex_less(v, idx[hi], idx[lo])) swap_i64(idx, hi, lo);
            if (lex_less(v, idx[hi], idx[mid])) swap_i64(idx, hi, mid);
            swap_i64(idx, mid, hi);
            const int64_t p = idx[hi];
            int64_t store = lo;
            for (int64_t i = lo; i < hi; i++)
                if (lex_less(v, idx[i], p)) swap_i64(idx, i, store++);
            swap_i64(idx, store, hi);
            if (store == k) break;
            if (k < store)
                hi = store - 1;
            else
                lo = store + 1;
        }
        out[g] = v[idx[k]];
        s = e;
    }
}

/* The means of the m values left and right of n steps (simbench.decode.color.fringe_confirmed):
 * g is (h, w, 3) float32, ys and xs the steps' rows and columns in row-major order (xs[i]: between
 * columns x and x + 1).  Per row holding a step, prefix sums in double over each channel's row
 * padded by m values each side (its ends replicated; numpy's cumsum order, the bits of the numpy
 * form in tests/numpy_reference.py); out[6 i + 2 c] = the mean of channel c over columns
 * x - m + 1 .. x, out[6 i + 2 c + 1] over x + 1 .. x + m.  cs: 3 (w + 2 m + 1) doubles. */
void side_means(int64_t h, int64_t w, const float *restrict g, int64_t n, const int64_t *restrict ys,
                const int64_t *restrict xs, int64_t m, double *restrict cs, double *restrict out) {
    const int64_t np_ = w + 2 * m;
    int64_t row = -1;
    (void)h;
    for (int64_t i = 0; i < n; i++) {
        if (ys[i] != row) {
            row = ys[i];
            const float *r = g + row * w * 3;
            for (int64_t c = 0; c < 3; c++) {
                double *p = cs + c * (np_ + 1);
                p[0] = 0.0;
                for (int64_t j = 0; j < np_; j++) {
                    int64_t x = j - m;
                    x = x < 0 ? 0 : (x > w - 1 ? w - 1 : x);
                    p[j + 1] = p[j] + (double)r[3 * x + c];
                }
            }
        }
        const int64_t cc = xs[i] + m + 1;
        for (int64_t c = 0; c < 3; c++) {
            const double *p = cs + c * (np_ + 1);
            out[6 * i + 2 * c] = (p[cc] - p[cc - m]) / (double)m;
            out[6 * i + 2 * c + 1] = (p[cc + m] - p[cc]) / (double)m;
        }
    }
}

/* The albedo flattening's per-segment measures (simbench.decode.color.albedo_gain), one row at a
 * time from the steps `cuts` (cuts[x]: between columns x and x + 1): each pixel's segment
 * [s0, s1); mean (float32) = the mean of `width` values of `proxy` centred on the pixel, kept
 * inside the segment (bounded_mean); vis (float32) = the standard deviation over the mean of `pv`
 * (the proxy averaged over rows) over the same window kept inside the segment narrowed by
 * `margin` at each end where it is longer than 2 margin + 2 (the sum of squares' mean less the
 * squared mean, in double; 0 where the mean is not > 0); short_ = the segment is shorter than
 * min_len.  The bits of the numpy form (_segment_bounds, _bounded_mean; segment_visibility in
 * tests/numpy_reference.py).
 * scratch: 3 (w + 1) doubles. */
void albedo_segments(int64_t h, int64_t w, const float *restrict proxy, const float *restrict pv,
                     const uint8_t *restrict cuts, int64_t width, int64_t margin, double min_len,
                     double *restrict scratch, float *restrict mean, float *restrict vis, uint8_t *restrict short_) {
    double *cp = scratch, *cv = cp + (w + 1), *cq = cv + (w + 1);
    for (int64_t y = 0; y < h; y++) {
        const float *p = proxy + y * w, *q = pv + y * w;
        const uint8_t *cut = cuts + y * w;
        cp[0] = cv[0] = cq[0] = 0.0;
        for (int64_t x = 0; x < w; x++) {
            const double a = (double)p[x], b = (double)q[x];
            cp[x + 1] = cp[x] + a;
            cv[x + 1] = cv[x] + b;
            cq[x + 1] = cq[x] + b * b;
        }
        int64_t s0 = 0;
        while (s0 < w) {
            int64_t s1 = s0;
            while (s1 < w - 1 && !cut[s1]) s1++;
            s1++; /* one past the segment's last column */
            const int64_t len = s1 - s0;
            const int room = len > 2 * margin + 2;
            const int64_t a0 = room ? s0 + margin : s0, a1 = room ? s1 - margin : s1;
            for (int64_t x = s0; x < s1; x++) {
                int64_t n = width < len ? width : len, start = x - width / 2;
                if (start < s0) start = s0;
                if (start > s1 - n) start = s1 - n;
                mean[y * w + x] = (float)((cp[start + n] - cp[start]) / (double)n);
                n = width < a1 - a0 ? width : a1 - a0;
                start = x - width / 2;
                if (start < a0) start = a0;
                if (start > a1 - n) start = a1 - n;
                const double mu = (cv[start + n] - cv[start]) / (double)n;
                const double var = (cq[start + n] - cq[start]) / (double)n - mu * mu;
                vis[y * w + x] = mu > 0.0 ? (float)(sqrt(var > 0.0 ? var : 0.0) / mu) : 0.0f;
                short_[y * w + x] = (double)len < min_len;
            }
            s0 = s1;
        }
    }
}

/* A row's confidence capped by a bias (the crease and edge terms): k = fminf(k, kappa / o) where
 * ok, without fminf's call (q = kappa / o is never NaN; kappa / 0 = inf leaves k), branch-free so
 * that it vectorises. */
static inline void cap_confidence_row(int64_t w, const float *restrict o, float kappa, const uint8_t *restrict ok,
                                      float *restrict k) {
    for (int64_t x = 0; x < w; x++) {
        const float q = kappa / o[x], kx = k[x];
        k[x] = (ok[x] && (q < kx || kx != kx)) ? q : kx;
    }
}

/* The predicted bias at concave creases (simbench.decode.depth.crease_bias) of an (h, w) float32
 * column map.  Per row, into signed (scratch, h x w): v = factor d2 with d2 = (c[x + L] - 2 c[x]) +
 * c[x - L] (factor = -sign(d column / d depth) * bias ratio), NaN where one of the 2 L steps between
 * neighbours from x - L to x + L is over max_step or NaN or has an end not trusted (trusted: NULL =
 * every pixel; a running count of such steps) and within L of the row's ends.  Then down each column, out = the mean of the finite v within rows_reach
 * rows either side (double running sums, rows entering and leaving the window in order) where the
 * pixel's own v is finite and that mean is > 0, else 0.  With conf (NULL: not written): conf =
 * fminf(conf, kappa / out) where valid (the pipeline's confidence cap, in the same call).
 * Scratch: broken, w bytes; sums, w doubles; counts, w int64. */
void crease_bias(int64_t h, int64_t w, const float *restrict col, int64_t reach, float factor, float max_step,
                 int64_t rows_reach, const uint8_t *restrict trusted, float *restrict signed_d2, float *restrict out,
                 float kappa, const uint8_t *restrict valid, float *restrict conf, uint8_t *restrict broken,
                 double *restrict sums, int64_t *restrict counts) {
    for (int64_t r = 0; r < h; r++) {
        const float *c = col + r * w;
        float *v = signed_d2 + r * w;
        for (int64_t x = 0; x < w; x++)
            v[x] = NAN;
        if (reach < 1 || w <= 2 * reach)
            continue;
        for (int64_t j = 0; j < w - 1; j++)
            broken[j] = !(fabsf(c[j + 1] - c[j]) <= max_step);
        if (trusted) {
            const uint8_t *t = trusted + r * w;
            for (int64_t j = 0; j < w - 1; j++)
                broken[j] |= !(t[j] && t[j + 1]);
        }
        int64_t count = 0;
        for (int64_t j = 0; j < 2 * reach; j++)
            count += broken[j];
        for (int64_t x = reach; x < w - reach; x++) {
            if (x > reach)
                count += (int64_t)broken[x + reach - 1] - (int64_t)broken[x - reach - 1];
            if (!count)
                v[x] = factor * ((c[x + reach] - 2.0f * c[x]) + c[x - reach]);
        }
    }
    for (int64_t x = 0; x < w; x++) {
        sums[x] = 0.0;
        counts[x] = 0;
    }
    for (int64_t r = 0; r < h && r <= rows_reach; r++)
        for (int64_t x = 0; x < w; x++) {
            const float a = signed_d2[r * w + x];
            if (a == a) {
                sums[x] += (double)a;
                counts[x]++;
            }
        }
    for (int64_t r = 0; r < h; r++) {
        if (r > 0) {
            const int64_t enter = r + rows_reach, leave = r - rows_reach - 1;
            if (enter < h)
                for (int64_t x = 0; x < w; x++) {
                    const float a = signed_d2[enter * w + x];
                    if (a == a) {
                        sums[x] += (double)a;
                        counts[x]++;
                    }
                }
            if (leave >= 0)
                for (int64_t x = 0; x < w; x++) {
                    const float a = signed_d2[leave * w + x];
                    if (a == a) {
                        sums[x] -= (double)a;
                        counts[x]--;
                    }
                }
        }
        const float *v = signed_d2 + r * w;
        float *o = out + r * w;
        for (int64_t x = 0; x < w; x++) {
            const float m = counts[x] > 0 ? (float)(sums[x] / (double)counts[x]) : 0.0f;
            o[x] = (v[x] == v[x] && m > 0.0f) ? m : 0.0f;
        }
        if (conf)
            cap_confidence_row(w, o, kappa, valid + r * w, conf + r * w);
    }
}

/* edge_bend's pass over n_lines lines of len pixels each, element x of line l at l * ls + x * ps
 * (rows: ls = w, ps = 1; columns: ls = 1, ps = w): out = the larger of out and each pixel's bend
 * (out zeroed by the caller). */
static inline void edge_bend_lines(int64_t n_lines, int64_t len, int64_t ls, int64_t ps, const float *restrict col,
                                   int64_t reach, int64_t fit, float max_step, float *restrict out) {
    if (reach < 1 || fit < 2)
        return;
    /* the fit's abscissae are u = 0 .. fit - 1 counted from the fit's end nearest the edge */
    const double n = (double)fit, su = n * (n - 1.0) / 2.0, suu = (n - 1.0) * n * (2.0 * n - 1.0) / 6.0;
    const double det = n * suu - su * su;
    for (int64_t l = 0; l < n_lines; l++) {
        const float *c = col + l * ls;
        float *o = out + l * ls;
        int64_t s = 0;
        while (s < len) {
            if (!(c[s * ps] == c[s * ps])) {
                s++;
                continue;
            }
            int64_t e = s;
            while (e + 1 < len && fabsf(c[(e + 1) * ps] - c[e * ps]) <= max_step)
                e++;
            /* the run [s, e]; its ends: e (dir -1: the fit lies before it) if a hole or a step
             * follows, s (dir +1) if one precedes */
            if (e - s + 1 >= reach + fit) {
                for (int side = 0; side < 2; side++) {
                    const int64_t end = side == 0 ? e : s, dir = side == 0 ? -1 : 1;
                    if ((side == 0 && e + 1 >= len) || (side == 1 && s == 0))
                        continue;
                    const int64_t f0 = end + dir * reach; /* the fit's first pixel (u = 0) */
                    double sy = 0.0, suy = 0.0;
                    for (int64_t u = 0; u < fit; u++) {
                        const double y = (double)c[(f0 + dir * u) * ps];
                        sy += y;
                        suy += (double)u * y;
                    }
                    const double slope = (n * suy - su * sy) / det, icpt = (sy - slope * su) / n;
                    for (int64_t k = 1; k <= reach; k++) {
                        const int64_t x = (f0 - dir * k) * ps; /* u = -k */
                        const float d = fabsf((float)((double)c[x] - (icpt - slope * (double)k)));
                        if (d > o[x])
                            o[x] = d;
                    }
                }
            }
            s = e + 1;
        }
    }
}

/* The bend of an (h, w) float32 column map beside its depth edges and holes
 * (simbench.decode.depth.edge_bend_bias).  Per row, the runs of finite columns whose steps between
 * neighbours are at most max_step; at each end of a run that a hole or a larger step ends (not the
 * row's end), when the run is at least reach + fit long: the least-squares line through the fit
 * columns reach to reach + fit - 1 pixels from the end (in double, sums in order from the end),
 * extrapolated to the reach columns nearest the end; out = |column - line| there as float (the
 * larger where both ends of a run reach a pixel), 0 elsewhere.  Then the same down each image
 * column with reach_y and fit_y (a depth edge across the rows; reach_y 0: not read), out the
 * larger of the two.  With conf (NULL: not written): conf = fminf(conf, kappa / out) where valid
 * (the pipeline's confidence cap, in the same call). */
void edge_bend(int64_t h, int64_t w, const float *restrict col, int64_t reach, int64_t fit, int64_t reach_y,
               int64_t fit_y, float max_step, float *restrict out, float kappa, const uint8_t *restrict valid,
               float *restrict conf) {
    for (int64_t i = 0; i < h * w; i++)
        out[i] = 0.0f;
    edge_bend_lines(h, w, w, 1, col, reach, fit, max_step, out);
    edge_bend_lines(w, h, 1, w, col, reach_y, fit_y, max_step, out);
    if (conf)
        for (int64_t r = 0; r < h; r++)
            cap_confidence_row(w, out + r * w, kappa, valid + r * w, conf + r * w);
}
