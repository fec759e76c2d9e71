/*
 * The lens model's remap grids and its layered defocus blur (simbench/optics.py), the
 * projector's DMD layout and 8-bit transfer (simbench/projector.py) and the camera's EMVA model's
 * deterministic steps (simbench/sim/camera.py), in C: compiled into the same
 * library as simbench/_ckernels.c (pyproject.toml), with the same flags and the same contract
 * (every loop gives the bits of the numpy expression it replaces; tests/test_optics.py compares
 * them).
 *
 * A file of its own because recordings and projector drives depend on it: simbench.sim.keys puts
 * this file's digest, and not the decoder's loops, in every recording's and drive's cache key.
 */
#include <float.h>
#include <stddef.h>
#include <math.h>
#include <stdint.h>

/* Row helpers stay out of line, as in _ckernels.c. */
#define ROW_FN static __attribute__((noinline))

/* Brown-Conrady lens model on the pixel grid of a camera (simbench.optics: distort_normalized,
 * undistort_normalized), in float64 and in numpy's operation order, so the maps are the bits
 * numpy gives; one row at a time so that every loop runs over contiguous pixels.
 * grid x = (j - cx) / f, y = (i - cy) / f; map = (float)(model(x, y) * f + c). */
ROW_FN void brown_forward_row(int64_t w, const double *restrict x, double y, const double *restrict d,
                             double *restrict xd, double *restrict yd) {
    const double k1 = d[0], k2 = d[1], p1 = d[2], p2 = d[3], k3 = d[4];
    for (int64_t j = 0; j < w; j++) {
        const double r2 = x[j] * x[j] + y * y;
        const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        xd[j] = x[j] * radial + 2.0 * p1 * x[j] * y + p2 * (r2 + 2.0 * x[j] * x[j]);
        yd[j] = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x[j] * y;
    }
}

ROW_FN void brown_inverse_step(int64_t w, const double *restrict xd, double yd, const double *restrict d,
                              double *restrict x, double *restrict y) {
    const double k1 = d[0], k2 = d[1], p1 = d[2], p2 = d[3], k3 = d[4];
    for (int64_t j = 0; j < w; j++) {
        const double r2 = x[j] * x[j] + y[j] * y[j];
        const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        const double dx = 2.0 * p1 * x[j] * y[j] + p2 * (r2 + 2.0 * x[j] * x[j]);
        const double dy = p1 * (r2 + 2.0 * y[j] * y[j]) + 2.0 * p2 * x[j] * y[j];
        x[j] = (xd[j] - dx) / radial;
        y[j] = (yd - dy) / radial;
    }
}

ROW_FN void to_pixels(int64_t w, const double *restrict u, double f, double c, float *restrict out) {
    for (int64_t j = 0; j < w; j++) out[j] = (float)(u[j] * f + c);
}

/* inverse = 0: where each ideal pixel is recorded, K D(K^-1 q); inverse = 1: where each
 * recorded pixel's light comes from, K D^-1(K^-1 p) by `iterations` fixed-point steps (OpenCV's
 * method).  scratch: 3 w doubles. */
void brown_maps(int64_t h, int64_t w, double f, double cx, double cy, const double *restrict d, int64_t inverse,
                int64_t iterations, double *restrict scratch, float *restrict map_x, float *restrict map_y) {
    double *gx = scratch, *a = scratch + w, *b = scratch + 2 * w;
    for (int64_t j = 0; j < w; j++) gx[j] = ((double)j - cx) / f;
    for (int64_t i = 0; i < h; i++) {
        const double gy = ((double)i - cy) / f;
        if (!inverse) {
            brown_forward_row(w, gx, gy, d, a, b);
        } else {
            for (int64_t j = 0; j < w; j++) {
                a[j] = gx[j];
                b[j] = gy;
            }
            for (int64_t k = 0; k < iterations; k++) brown_inverse_step(w, gx, gy, d, a, b);
        }
        to_pixels(w, a, f, cx, map_x + i * w);
        to_pixels(w, b, f, cy, map_y + i * w);
    }
}

/* One level of simbench.optics.depth_varying_blur, added to out over the box of rows r0..r1-1
 * and columns c0..c1-1: a pixel whose lower level lo is k weighs the level's image cur by
 * 1 - frac, one whose lo is k - 1 by frac, any other by 0; out += weight * cur, channel by
 * channel (numpy's float32 operations: the weight as the sum of the two where()s, the product,
 * then the sum).  lo, frac: (H, w_full); cur, out: (H, w_full, c). */
void blur_level_add(int64_t w_full, int64_t c, int64_t r0, int64_t r1, int64_t c0, int64_t c1, int64_t k,
                    const int32_t *restrict lo, const float *restrict frac, const float *restrict cur,
                    float *restrict out) {
    for (int64_t i = r0; i < r1; i++) {
        for (int64_t j = c0; j < c1; j++) {
            const int64_t at = i * w_full + j, l = lo[at];
            const float f = frac[at];
            const float w = (l == k ? 1.0f - f : 0.0f) + (l == k - 1 ? f : 0.0f);
            for (int64_t ch = 0; ch < c; ch++) out[at * c + ch] += w * cur[at * c + ch];
        }
    }
}

/* The layered blur's level map (simbench.optics.depth_varying_blur), in float64 as numpy
 * computes it: sigma with NaN and +inf as 0 and -inf as -DBL_MAX (np.nan_to_num); its largest
 * value (at least 0) from blur_sigma_max; then pos = clip(sigma / step, 0, top), lo = floor(pos),
 * frac = (float)(pos - lo), the count of pixels per lo (used, top + 2 entries, zeroed here) and
 * each row's and column's lowest and highest lo. */
static inline double finite_sigma(double v) {
    if (v != v) return 0.0;
    if (v > DBL_MAX) return 0.0;
    if (v < -DBL_MAX) return -DBL_MAX;
    return v;
}

double blur_sigma_max(int64_t n, const double *restrict sigma) {
    double m = 0.0;
    for (int64_t i = 0; i < n; i++) {
        const double v = finite_sigma(sigma[i]);
        if (v > m) m = v;
    }
    return m;
}

void blur_levels(int64_t h, int64_t w, const double *restrict sigma, double step, double top, int32_t *restrict lo,
                 float *restrict frac, int64_t *restrict used, int32_t *restrict row_lo, int32_t *restrict row_hi,
                 int32_t *restrict col_lo, int32_t *restrict col_hi) {
    const int64_t levels = (int64_t)top + 1;
    for (int64_t k = 0; k <= levels; k++) used[k] = 0;
    for (int64_t j = 0; j < w; j++) {
        col_lo[j] = INT32_MAX;
        col_hi[j] = INT32_MIN;
    }
    for (int64_t i = 0; i < h; i++) {
        int32_t rlo = INT32_MAX, rhi = INT32_MIN;
        for (int64_t j = 0; j < w; j++) {
            const int64_t at = i * w + j;
            double pos = finite_sigma(sigma[at]) / step;
            pos = pos < 0.0 ? 0.0 : pos;
            pos = pos > top ? top : pos;
            const double fl = floor(pos);
            const int32_t l = (int32_t)fl;
            lo[at] = l;
            frac[at] = (float)(pos - fl);
            used[l]++;
            rlo = l < rlo ? l : rlo;
            rhi = l > rhi ? l : rhi;
            col_lo[j] = l < col_lo[j] ? l : col_lo[j];
            col_hi[j] = l > col_hi[j] ? l : col_hi[j];
        }
        row_lo[i] = rlo;
        row_hi[i] = rhi;
    }
}

/* The DMD's diamond layout (simbench.projector.dmd_layout): even rows show the mean of column
 * pairs (0, 1), (2, 3), ...; odd rows of pairs (1, 2), (3, 4), ..., their first and last columns
 * the edge mirrors' own values; out = 0.5f * (a + b) in float32, as numpy.  (h, w, c), w even. */
void dmd_diamond(int64_t h, int64_t w, int64_t c, const float *restrict in, float *restrict out) {
    for (int64_t i = 0; i < h; i++) {
        const float *src = in + i * w * c;
        float *dst = out + i * w * c;
        const int64_t first = i % 2;  /* the row's first paired column */
        if (first) {
            for (int64_t ch = 0; ch < c; ch++) {
                dst[ch] = src[ch];
                dst[(w - 1) * c + ch] = src[(w - 1) * c + ch];
            }
        }
        for (int64_t j = first; j + 1 < w - first; j += 2) {
            for (int64_t ch = 0; ch < c; ch++) {
                const float pair = 0.5f * (src[j * c + ch] + src[(j + 1) * c + ch]);
                dst[j * c + ch] = pair;
                dst[(j + 1) * c + ch] = pair;
            }
        }
    }
}

/* A per-channel lookup table applied to an 8-bit image: out[p, ch] = table[code[p, ch], ch];
 * code (n, c) uint8, table (256, c) float32. */
void lut_u8(int64_t n, int64_t c, const uint8_t *restrict code, const float *restrict table, float *restrict out) {
    for (int64_t p = 0; p < n; p++)
        for (int64_t ch = 0; ch < c; ch++) out[p * c + ch] = table[code[p * c + ch] * c + ch];
}

/* The EMVA 1288 camera's deterministic steps (simbench.sim.camera.emva_camera), in float64 and in
 * numpy's operation order, so the recorded frames are the bits of the numpy form
 * (tests/numpy_reference.py).  chan (4 values, or NULL): the colour filter's channel at
 * (y % 2, x % 2) in raster order, one value per pixel out; NULL: every channel, three per pixel.
 *
 * emva_mean: out = max((double)radiance, 0) * scale[c] (* gain_fp, when given) + dark_e, the
 * mean electrons of each recorded value, from float32 radiance (f64 == 0) or float64; returns how
 * many radiance values are not finite (nothing is written then: the caller refuses the image), or
 * minus how many means are not (finite radiance times an infinite scale, or 0 x inf: numpy's form
 * went on with NaN into the ADC and recorded 0 there). */
int64_t emva_mean(int64_t h, int64_t w, const void *restrict radiance, int64_t f64, const double *restrict scale,
                  const int64_t *restrict chan, const double *restrict gain_fp, double dark_e,
                  double *restrict out) {
    const float *r32 = (const float *)radiance;
    const double *r64 = (const double *)radiance;
    int64_t bad = 0;
    for (int64_t p = 0; p < h * w * 3; p++) bad += f64 ? !isfinite(r64[p]) : !isfinite(r32[p]);
    if (bad) return bad;
    for (int64_t y = 0; y < h; y++) {
        const int64_t row = y * w * 3;
        if (chan) {
            double *o = out + y * w;
            const double *g = gain_fp ? gain_fp + y * w : NULL;
            for (int64_t x = 0; x < w; x++) {
                const int64_t c = chan[(y & 1) * 2 + (x & 1)];
                const double v = f64 ? r64[row + x * 3 + c] : (double)r32[row + x * 3 + c];
                double e = (v >= 0.0 ? v : 0.0) * scale[c];
                if (g) e = e * g[x];
                o[x] = e + dark_e;
                bad += !isfinite(o[x]);
            }
        } else {
            double *o = out + row;
            const double *g = gain_fp ? gain_fp + row : NULL;
            for (int64_t x = 0; x < w * 3; x++) {
                const double v = f64 ? r64[row + x] : (double)r32[row + x];
                double e = (v >= 0.0 ? v : 0.0) * scale[x % 3];
                if (g) e = e * g[x];
                o[x] = e + dark_e;
                bad += !isfinite(o[x]);
            }
        }
    }
    return -bad;
}

/* emva_dn: the digital number of each value, clip(rint(gain[c] * min(e + dark_fp, full_well) +
 * offset), 0, max_dn) (rint: to nearest, ties to even, as numpy's), dark_fp per value or NULL
 * (0.0), into uint8 (bits8 != 0) or uint16. */
void emva_dn(int64_t h, int64_t w, const double *restrict e, const double *restrict dark_fp,
             const int64_t *restrict chan, const double *restrict gain, double full_well, double offset,
             double max_dn, int64_t bits8, void *restrict out) {
    const int64_t per = chan ? 1 : 3;
    for (int64_t y = 0; y < h; y++) {
        for (int64_t k = 0; k < w * per; k++) {
            const int64_t p = y * w * per + k;
            const int64_t c = chan ? chan[(y & 1) * 2 + (k & 1)] : k % 3;
            double v = e[p] + (dark_fp ? dark_fp[p] : 0.0);
            v = v < full_well ? v : full_well;
            double dn = nearbyint(gain[c] * v + offset);
            dn = dn > 0.0 ? dn : 0.0;
            dn = dn < max_dn ? dn : max_dn;
            if (bits8)
                ((uint8_t *)out)[p] = (uint8_t)dn;
            else
                ((uint16_t *)out)[p] = (uint16_t)dn;
        }
    }
}
